"""`hazard run` answers first (issue 12, item 3): hazardous observers with their hazard
ratio, distance and cause, the NOHDs, what was not modelled; the stage log only with
--verbose; --json unchanged. Also: convergence columns carry their unit."""

import io
import json
import math
import re

import numpy as np
import pytest

import hazard
from hazard.drivers import convergence as conv
from hazard.cli import main
from hazard.outputs.report import ANSWER_MAX_OBSERVERS
from tests._bundled import bundled


def run(*argv):
    out, err = io.StringIO(), io.StringIO()
    code = main([str(a) for a in argv], stdout=out, stderr=err)
    return code, out.getvalue(), err.getvalue()


def analyse(name):
    return bundled(name)


def observer_rows(out):
    """Rows of the hazardous-observer table: (name, ratio, distance from the spot [m], spot,
    cause, distance from the laser [m])."""
    rows = []
    for line in out.splitlines():
        m = re.match(r"^  (\S+)\s+([0-9.e+-]+)\s+([0-9.e+-]+)\s+([0-9.e+-]+)  (\S+)\s+(.+)$", line)
        if m and not line.startswith("  observer "):
            rows.append((m[1], float(m[2]), float(m[4]), m[5], m[6], float(m[3])))
    return rows


@pytest.fixture(scope="module")
def binoculars():
    return analyse("binoculars")


def test_binoculars_answer_comes_first_and_names_the_hazard(tmp_path, binoculars):
    code, out, err = run("run", "binoculars", "-o", tmp_path / "o", "--quiet")
    assert code == 0 and err == ""
    lines = out.splitlines()
    assert lines[0].startswith("Scene 'binoculars': HAZARD at the observers and in the zones: 1 of 2 observer point(s) "
                               "at or above the MPE; ")
    assert lines[1] == "  MPE 50 W/m^2, ansi-z136.1-2014, 10 s"
    # the beam convention the NOHDs used is said at the top (issue 31 item 2), not only in the notes below
    assert lines[2] == ("  beam: 1/e-irradiance diameter and 1/e full-angle divergence, the standards' form "
                        "(default, not given in the scene)")
    rows = observer_rows(out)
    assert [r[0] for r in rows] == ["binoculars-7x50"]  # the naked eye is safe: not listed
    k = binoculars.observers.labels.index("binoculars-7x50")
    expected = binoculars.hazard_ratio[k]
    assert expected > 1 and binoculars.hazard_ratio[binoculars.observers.labels.index("naked-eye")] < 1
    name, ratio, distance, spot, cause, _ = rows[0]
    assert ratio == pytest.approx(expected, rel=1e-3)  # printed with 4 significant digits
    # the observer stands 1 km from the panel, outside its mirror beam, material static
    assert distance == pytest.approx(1000.0, abs=1.0) and spot == "copper-panel"
    assert binoculars.observers.specular_irradiance_w_m2[k] == 0 and cause == "diffuse 100 %, static"
    t = binoculars.targets[0]
    assert (f"copper-panel: diffuse static {t.static_lobe.max_range_m:.4g} m, dynamic {t.dynamic_lobe.max_range_m:.4g} m; "
            f"specular static {t.specular_nohd_static_m:.4g} m, dynamic {t.specular_nohd_dynamic_m:.4g} m") in out
    # the answer, then the files written; no stage log without --verbose
    assert out.index("Skipped in this run") < out.index("wrote ")
    assert "Stages:" not in out and "ran     mpe" not in out


def test_verbose_adds_the_stage_log_after_the_answer(tmp_path):
    _, quiet, _ = run("run", "binoculars", "-o", tmp_path / "a", "--quiet")
    code, out, err = run("run", "binoculars", "-o", tmp_path / "b", "--quiet", "--verbose")
    assert code == 0 and err == ""
    answer = quiet[: quiet.index("wrote ")]
    assert out.startswith(answer.replace(str(tmp_path / "a"), str(tmp_path / "b")))  # the same answer, first
    log = out[len(answer):]
    assert log.startswith("Stages:\n") and "  ran     mpe" in log and "  ran     keepout" in log
    assert log.index("Stages:") < log.index("wrote ")


def test_no_hazard_is_said_plainly_with_the_nohds(tmp_path):
    code, out, _ = run("run", "plate", "-o", tmp_path / "o", "--quiet", "--fail-on-hazard")
    assert code == 0  # no observer is hazardous (the default: fail on the observers)
    code, out, _ = run("run", "plate", "-o", tmp_path / "o", "--quiet", "--force", "--fail-on-hazard=zones")
    assert code == 3  # but the beam past the plate is not stopped (a target is no backstop), nor the keep-out zone
    first = out.splitlines()[0]
    assert first == ("Scene 'plate': HAZARD in the zones: no listed observer at or above its limit (0 of 2 observer point(s) "
                     "at or above the MPE), but 2 hazard zone(s) NOT contained or beyond the range boundary.")
    nohd = (math.sqrt(4 * 100.0 / (math.pi * 50.0)) - 0.005) / 0.001  # ANSI eq. B: P 100 W, a 5 mm, phi 1 mrad, MPE 50 W/m^2
    assert f"  zone: the direct beam's danger zone (NOHD {nohd:.4g} m) is NOT contained: 1 of 1 direction(s) toward bearing 0 deg, " \
           "elevation 0 deg reach the NOHD without a backstop: at the aim the beam meets target(s) 'plate' (100 % of the " \
           "beam), but a target is not a backstop" in out  # the plate is due north of the laser: bearing 0
    assert "  zone: the keep-out lobe of 'plate' (diffuse NOHD 0.5642 m) is not bounded: the scene has no [range]" in out
    assert observer_rows(out) == []
    r0 = hazard.nohd_diffuse(100.0, 50.0, 0.5).nohd_m  # the analytic Lambertian NOHD, 0.564 m
    assert f"plate: diffuse static {r0:.4g} m, dynamic {r0:.4g} m; no mirror beam" in out
    assert "  skipped history: no dynamic material" in out and "never modelled: multiple bounces" in out


def test_big_lists_are_cut_and_sorted_by_hazard_ratio(tmp_path):
    res = analyse("steel_vs_copper")
    code, out, _ = run("run", "steel_vs_copper", "-o", tmp_path / "o", "--quiet")
    rows = observer_rows(out)
    n = int(res.hazardous.sum())
    assert code == 0 and n > ANSWER_MAX_OBSERVERS and len(rows) == ANSWER_MAX_OBSERVERS
    assert f"... and {n - ANSWER_MAX_OBSERVERS} more hazardous observer point(s)" in out
    top = np.sort(res.hazard_ratio[res.hazardous])[::-1][:ANSWER_MAX_OBSERVERS]
    assert [r[1] for r in rows] == pytest.approx(top, rel=1e-3)
    labels = res.observers.labels
    for name, _, _, _, cause, _ in rows:
        i = labels.index(name)
        raised = res.observers.peak_irradiance_w_m2[i] > res.observers.static_irradiance_w_m2[i]
        assert ("dynamic (static material: ratio" in cause) == raised and cause.endswith("static") != raised
    stainless, copper = res.targets
    assert f"copper: diffuse static {copper.static_lobe.max_range_m:.4g} m, dynamic {copper.dynamic_lobe.max_range_m:.4g} m" in out
    assert copper.dynamic_lobe.max_range_m > copper.static_lobe.max_range_m


def test_json_output_is_the_report(tmp_path):
    code, out, _ = run("run", "binoculars", "-o", tmp_path / "o", "--quiet", "--json", "--verbose")
    doc = json.loads(out)  # nothing but the report on stdout
    assert code == 0 and doc["format"] == "laser-hazard.report" and doc["any_hazard"] is True
    written = json.loads((tmp_path / "o" / "report.json").read_text())
    written.pop("warnings", None)  # the file also holds the scene's plausibility warnings
    doc.pop("warnings", None)
    assert doc == written


# -- convergence columns carry their unit (issue 12, item 3) --------------------------------
def test_convergence_columns_name_their_unit():
    rep = conv.convergence("plate", knobs=["refine_levels"], levels={"refine_levels": (0, 1)})
    keys = set(rep.rows[0])
    assert {"max_nohd_m", "keepout_volume_m3", "peak_irradiance_w_m2", "spot_power_w", "time_s"} <= keys
    assert {"rel_error_max_nohd", "rel_error_keepout_volume", "rel_error_peak_irradiance", "rel_error_spot_power"} <= keys
    assert not [k for k in keys if k.startswith("error_")]
    r = rep.rows[0]
    assert r["rel_error_max_nohd"] == pytest.approx(abs(r["max_nohd_m"] - rep.rows[1]["max_nohd_m"]) / rep.rows[1]["max_nohd_m"])
    assert rep.rows[1]["rel_error_max_nohd"] == 0.0
    # a relative error has no unit even when the reference is zero: 0 or inf, never |q| in metres
    assert conv._rel_error(0.0, 0.0) == 0.0 and conv._rel_error(0.3, 0.0) == math.inf
    assert conv._rel_error(1.1, 1.0) == pytest.approx(0.1)


def test_a_closed_pipe_stops_quietly(tmp_path):
    """`hazard run ... | head`: the reader goes away and the next write raises
    BrokenPipeError; the outputs are already written, and the command ends with 141
    (128 + SIGPIPE) and without an 'internal error' line (it said "internal error:
    Broken pipe", exit 1)."""

    class ClosedPipe(io.StringIO):
        def write(self, text):
            raise BrokenPipeError(32, "Broken pipe")

    err = io.StringIO()
    code = main(["run", "plate", "-o", str(tmp_path / "o"), "--quiet"], stdout=ClosedPipe(), stderr=err)
    assert code == 141 and err.getvalue() == ""
    assert (tmp_path / "o" / "report.json").exists() and (tmp_path / "o" / "observers.csv").exists()
