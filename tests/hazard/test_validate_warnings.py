"""``hazard validate`` prints the plausibility warnings in its text answer (stdout), not
only on stderr and in ``--json`` (issue 31 leftover), for a scene and for a study's base scene."""

import io
import json

from hazard.cli import main
from tests._scene_text import PLATE_AT_50M

KW_AS_W = "laser.power_w = 0.02 W is under 0.5 W"  # the class 3B power warning (kW typed as W?)


def _validate(path, *extra):
    out, err = io.StringIO(), io.StringIO()
    code = main(["validate", str(path), *extra], stdout=out, stderr=err)
    return code, out.getvalue(), err.getvalue()


def test_validate_text_prints_the_warnings(tmp_path):
    (tmp_path / "s.toml").write_text(PLATE_AT_50M.replace("power_w = 100.0", "power_w = 0.02"))
    code, out, err = _validate(tmp_path / "s.toml")
    assert code == 0
    lines = out.splitlines()
    head = next(i for i, ln in enumerate(lines) if "CHECK FIRST: 1 warning(s)" in ln)
    assert lines[head + 1].startswith("    warning: ") and KW_AS_W in lines[head + 1]
    assert KW_AS_W in err  # and still on stderr, as before
    code, out, _ = _validate(tmp_path / "s.toml", "--json")
    assert code == 0 and any(KW_AS_W in w for w in json.loads(out)["warnings"])


def test_validate_text_of_a_clean_scene_has_no_warning_block(tmp_path):
    (tmp_path / "s.toml").write_text(PLATE_AT_50M)
    code, out, err = _validate(tmp_path / "s.toml")
    assert code == 0 and "valid scene 'plate50'" in out and "CHECK FIRST" not in out and "warning" not in out + err


def test_validate_of_a_study_prints_its_base_scenes_warnings(tmp_path):
    (tmp_path / "s.toml").write_text(PLATE_AT_50M.replace("power_w = 100.0", "power_w = 0.02"))
    (tmp_path / "study.toml").write_text('name = "sweep"\nscene = "s.toml"\nseed = 1\n[sweep]\nkind = "grid"\n'
                                         '[[sweep.parameters]]\npath = "laser.divergence_rad"\nvalues = [0.001, 0.002]\n')
    code, out, _ = _validate(tmp_path / "study.toml")
    assert code == 0 and "valid study 'sweep': 2 scenario(s)" in out
    assert "CHECK FIRST: 1 warning(s) of the base scene" in out and KW_AS_W in out
    code, out, _ = _validate(tmp_path / "study.toml", "--json")
    assert code == 0 and any(KW_AS_W in w for w in json.loads(out)["warnings"])
    (tmp_path / "s.toml").write_text(PLATE_AT_50M)
    code, out, _ = _validate(tmp_path / "study.toml")
    assert code == 0 and "CHECK FIRST" not in out and json.loads(_validate(tmp_path / "study.toml", "--json")[1])["warnings"] == []
