"""Work estimates before work (issue 30 item 3): the ground footprint's near-field pairs
(``HAZARD_MAX_FOOTPRINT_WORK``) and the products of the single limits in estimated CPU
seconds (``HAZARD_MAX_WORK_CPU_S``), refused up front by the one acceptance function
(``scenes.load``), so ``hazard validate`` and ``hazard run`` give the same line."""

from __future__ import annotations

import io

import pytest

import scenes
from hazard.cli import main

PLATE = """name = "work"
[laser]
wavelength_nm = 1064.0
power_w = 100.0
beam_diameter_m = 0.005
divergence_rad = 0.001
position_m = [0.0, -50.0, 1.0]
aim_m = [0.0, 0.0, 1.0]
[exposure]
duration_s = 10.0
{targets}
[[observers]]
name = "east"
points_m = [[10.0, -17.0, 1.0]]
[analysis]
{analysis}
{terrain}
"""


def _targets(n):
    return "".join(f'[[targets]]\nname = "p{k}"\nshape = "plate"\ncenter_m = [{2.0 * k}, 0.0, 1.0]\nnormal = [0.0, -1.0, 0.0]\n'
                   f'tangent = [1.0, 0.0, 0.0]\nsize_m = [1.0, 1.0]\nmaterial = {{ model = "lambertian", reflectance = 0.5 }}\n'
                   for k in range(n))


def _scene(n_targets=1, analysis="", terrain=""):
    return PLATE.format(targets=_targets(n_targets), analysis=analysis, terrain=terrain)


FLAT = '[terrain]\nkind = "flat"\nextent_m = 3000.0\nresolution_m = 5.0\n'  # 1201^2 = 1.44e6 nodes, as range_geo at 5 m


def _refusal(text):
    with pytest.raises(scenes.SceneError) as exc:
        scenes.loads(text)
    return str(exc.value)


def test_footprint_work_is_refused_with_its_variable():
    # 1.44e6 nodes x 8192 beam samples x 2 spots (the plate and the ground) = 2.4e10 > 4e9
    msg = _refusal(_scene(analysis="beam_samples = 8192", terrain=FLAT))
    assert "ground footprint work" in msg and "HAZARD_MAX_FOOTPRINT_WORK" in msg and "1442401 x 8192 x 2" in msg
    scenes.loads(_scene(analysis="beam_samples = 1024", terrain=FLAT))  # 2.95e9: accepted


def test_the_product_of_targets_and_keepout_cells_is_refused():
    # 100 targets x 1500 x 6000 = 9e6 keep-out cells each (within HAZARD_MAX_KEEPOUT_CELLS alone):
    # 100 x 9e6 x 1.5e-6 s = 1350 s > 1200 s
    grid = "direction_grid_deg = 0.06\nrefine_levels = 0"
    msg = _refusal(_scene(100, grid))
    assert "estimated CPU seconds" in msg and "HAZARD_MAX_WORK_CPU_S" in msg
    for name in ("HAZARD_MAX_TARGETS", "HAZARD_MAX_KEEPOUT_CELLS", "HAZARD_MAX_OBSERVER_STEPS"):
        assert name in msg  # the limits whose product it is
    scenes.loads(_scene(80, grid))  # 80 x 13.5 s = 1080 s: accepted


def test_the_variable_raises_the_product_limit(monkeypatch):
    monkeypatch.setenv("HAZARD_MAX_WORK_CPU_S", "2000")
    scenes.loads(_scene(100, "direction_grid_deg = 0.06\nrefine_levels = 0"))


def _cli(verb, path, tmp_path):
    extra = {"validate": [], "run": ["-o", str(tmp_path / "out"), "--quiet"]}[verb]
    out, err = io.StringIO(), io.StringIO()
    code = main([verb, str(path), *extra], stdout=out, stderr=err)
    lines = [ln for ln in err.getvalue().splitlines() if not ln.startswith("hazard: warning:")]
    return code, lines


@pytest.mark.parametrize("text", [_scene(analysis="beam_samples = 8192", terrain=FLAT),
                                  _scene(100, "direction_grid_deg = 0.06\nrefine_levels = 0")], ids=["footprint", "product"])
def test_validate_refuses_as_run_does(text, tmp_path):
    path = tmp_path / "work.toml"
    path.write_text(text)
    (cv, lv), (cr, lr) = _cli("validate", path, tmp_path), _cli("run", path, tmp_path)
    assert cv == cr == 2 and len(lv) == len(lr) == 1
    assert lv[0].removeprefix("hazard validate: error: ") == lr[0].removeprefix("hazard run: error: ")
    assert "HAZARD_MAX_" in lv[0]


def test_a_height_maps_footprint_work_is_checked_once_read(tmp_path, monkeypatch):
    # a height map's nodes are known only when read: 41 x 41 = 1681 nodes x 1024 beam samples x 2 spots = 3.4e6
    import numpy as np

    np.save(tmp_path / "ground.npy", np.full((41, 41), -3.0))
    text = _scene(analysis="beam_samples = 1024",
                  terrain='[terrain]\nkind = "heightmap"\nfile = "ground.npy"\norigin_m = [-20.0, -40.0]\nspacing_m = 1.0\n')
    scenes.loads(text, base_dir=tmp_path)
    monkeypatch.setenv("HAZARD_MAX_FOOTPRINT_WORK", "3e6")
    with pytest.raises(scenes.SceneError, match=r"height map nodes x beam_samples x spots \(1681 x 1024 x 2.*"
                                                r"HAZARD_MAX_FOOTPRINT_WORK"):
        scenes.loads(text, base_dir=tmp_path)
