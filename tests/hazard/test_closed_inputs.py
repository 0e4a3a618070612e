"""Closed inputs (issue 30, items 3 and 5): every limit bounds time, and ``hazard
validate`` refuses exactly what ``run`` and ``risk`` would, before any work.

Each case of the issue is written as a scene file and given to ``validate``, ``run`` and
``risk``: all three exit 2 with the same one-line message naming the field (and, for a
limit, its ``HAZARD_MAX_*`` variable). The expected words come from the issue, not from
the engine. The accepted counterparts (just inside each limit) are checked to load.
"""

from __future__ import annotations

import copy
import io
import math
import shutil
import tomllib

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import scenes
from hazard.cli import main
from scenes.motion import AimSchedule, check_aim_aperture
from scenes.spec import uncertain_inputs
from tests.fuzz.test_fuzz_scenes import to_toml

FAST = settings(max_examples=25, derandomize=True, deadline=None, database=None)
SLOW = settings(max_examples=400, derandomize=True, deadline=None, database=None)


def _example(name):
    return tomllib.loads(scenes.example_path(name).read_text())


PLATE, RISK, MELT = _example("plate"), _example("risk"), _example("stainless_melt")


def _with(base, changes):
    d = copy.deepcopy(base)
    for path, value in changes.items():
        node = d
        for k in path[:-1]:
            node = node.setdefault(k, {}) if isinstance(k, str) else node[k]
        node[path[-1]] = value
    return d


def _targets(n):
    t = PLATE["targets"][0]
    return [dict(t, name=f"p{i}", center_m=[0.0, 2.0 * i, 0.0]) for i in range(n)]


def _points(n):
    return [{"name": "many", "points_m": [[10.0 + 1e-3 * i, -17.0, 0.0] for i in range(n)]}]


AIM_THROUGH = {"times_s": [0.0, 10.0], "aim_m": [[0.0, -60.0, 0.0], [0.0, -40.0, 0.0]]}  # the laser is at y = -50
SLEW = {"times_s": [0.0, 10.0], "aim_m": [[-1.0, 0.0, 0.0], [1.0, 0.0, 0.0]]}
TABLE = {"model": "table", "file": "samples.csv", "grid_deg": [0.1, 0.1, 0.1]}

# case -> (base, changes, environment, words the message must hold)
CASES = {
    "beam_samples = 1e6": (PLATE, {("analysis", "beam_samples"): 1_000_000}, {}, ["beam_samples", "HAZARD_MAX_BEAM_SAMPLES"]),
    "2000 targets": (PLATE, {("targets",): _targets(2000)}, {}, ["targets = 2000", "HAZARD_MAX_TARGETS"]),
    "explicit points over the limit": (PLATE, {("observers",): _points(6)}, {"HAZARD_MAX_POINTS": "5"},
                                       ["points_m", "HAZARD_MAX_POINTS"]),
    "sensitivity_draws = 1e7": (RISK, {("uncertainty", "sensitivity_draws"): 10_000_000}, {},
                                ["uncertainty", "HAZARD_MAX_RISK_EVALUATIONS"]),
    "draws = 1e8": (RISK, {("uncertainty", "draws"): 100_000_000}, {}, ["uncertainty", "HAZARD_MAX_RISK_EVALUATIONS"]),
    "an empty [uncertainty]": (RISK, {("uncertainty",): {}}, {}, ["uncertainty", "nothing is random"]),
    "an [uncertainty] with only a bias": (RISK, {("uncertainty",): {"pointing_bias_rad": [1e-4, 0.0]}}, {},
                                          ["uncertainty", "nothing is random"]),
    "divergence_rad = 1e-308, dynamic": (MELT, {("laser", "divergence_rad"): 1e-308}, {}, ["laser.divergence_rad", "1e-308"]),
    "time_end_s = 1e-308": (MELT, {("analysis", "time_end_s"): 1e-308}, {}, ["analysis.time_end_s", "1e-308"]),
    "motion steps": (PLATE, {("laser", "aim_track"): SLEW, ("motion",): {"time_step_s": 1e-6}}, {},
                     ["motion", "time_step_s", "HAZARD_MAX_MOTION_SAMPLES"]),
    "an aim track through the aperture": (PLATE, {("laser", "aim_track"): AIM_THROUGH}, {}, ["laser.aim_track", "aperture"]),
    "a missing file under [uncertainty]": (RISK, {("uncertainty", "materials"): [{"target": "panel", "materials": [
        {"file": "no_such_material.json"}]}]}, {}, ["uncertainty.materials['panel'].materials[0]", "cannot read"]),
    "/dev/zero under [uncertainty]": (RISK, {("uncertainty", "materials"): [{"target": "panel", "materials": [
        {"file": "/dev/zero"}]}]}, {}, ["uncertainty.materials['panel'].materials[0]", "not a regular file"]),
    "a 0.1 deg table grid": (PLATE, {("targets", 0, "material"): TABLE}, {}, ["grid_deg", "HAZARD_MAX_TABLE_NODES"]),
    "a scene text over the limit": (PLATE, {}, {"HAZARD_MAX_SCENE_MB": "1e-4"}, ["scene text size", "HAZARD_MAX_SCENE_MB"]),
    # 10 s / 1e-5 s = 1e6 steps of the heating history (the limit 1e5)
    "time steps over the limit": (MELT, {("analysis", "time_step_s"): 1e-5}, {},
                                  ["time steps (time_end_s 10 s / time_step_s 1e-05 s)", "HAZARD_MAX_TIME_STEPS"]),
    # (90/2)(360/2) 4^3 = 518 400 cells x 10 s / 1e-3 s = 1e4 steps: 5.2e9 > 2e9 (it ran past 10 min at 1e4 steps,
    # and at 1e5, the time-step limit, past 6.6 GB)
    "a dynamic keep-out of 1e4 steps": (MELT, {("analysis", "time_step_s"): 1e-3}, {},
                                        ["keep-out cells x time steps (518400 x 10000", "HAZARD_MAX_KEEPOUT_STATE_CELLS"]),
    # (90/0.0565)(360/0.0565) = 1593 x 6372 = 1.015e7 cells, all evaluated at once at refine_levels = 0: over 1e7
    # (at 1e7 a run took 5.15 GB; at 5e7, the limit before, it passed 9.3 GB and was killed)
    "a keep-out grid of 1.015e7 cells": (PLATE, {("analysis",): {"direction_grid_deg": 0.0565, "refine_levels": 0}}, {},
                                         [f"keep-out cells at direction_grid_deg=0.0565, refine_levels=0 = {1593 * 6372:.4g}",
                                          "HAZARD_MAX_KEEPOUT_CELLS"]),
    # 49 + 65 + 400 observer points x 10 s / 0.05 s = 200 steps: 102 800 > 1e5
    "observer points x time steps over the limit": (MELT, {}, {"HAZARD_MAX_OBSERVER_STEPS": "1e5"},
                                                    ["observer points x time steps (514 x 200)", "HAZARD_MAX_OBSERVER_STEPS"]),
}


def _write(tmp_path, data) -> str:
    for f in scenes.example_path("plate").parent.iterdir():  # the material files the examples name
        if f.suffix == ".json":
            shutil.copy(f, tmp_path / f.name)
    path = tmp_path / "scene.toml"
    path.write_text(to_toml(data))
    return str(path)


def _cli(*argv):
    out, err = io.StringIO(), io.StringIO()
    code = main(list(argv), stdout=out, stderr=err)
    lines = [ln for ln in err.getvalue().splitlines() if not ln.startswith("hazard: warning:")]
    return code, lines


@pytest.mark.parametrize("case", sorted(CASES))
def test_validate_run_and_risk_refuse_alike(case, tmp_path, monkeypatch):
    base, changes, env, words = CASES[case]
    for k, v in env.items():
        monkeypatch.setenv(k, v)
    f = _write(tmp_path, _with(base, changes))
    messages = {}
    for verb, extra in (("validate", []), ("run", ["-o", str(tmp_path / "out"), "--quiet"]),
                        ("risk", ["-o", str(tmp_path / "risk"), "--serial", "--quiet"])):
        code, lines = _cli(verb, f, *extra)
        assert code == 2 and len(lines) == 1, f"{case}: {verb} exit {code}: {lines}"
        assert lines[0].startswith(f"hazard {verb}: error: ")
        messages[verb] = lines[0].removeprefix(f"hazard {verb}: error: ")
        for w in words:
            assert w in messages[verb], f"{case}: {verb}: {w!r} not in {messages[verb]!r}"
    assert messages["validate"] == messages["run"] == messages["risk"]
    assert not (tmp_path / "out").exists() and not (tmp_path / "risk").exists()  # refused before any work


def test_just_inside_the_limits_loads(tmp_path, monkeypatch):
    """The counterparts the limits accept: 100 targets, 5 points at HAZARD_MAX_POINTS = 5, a
    1e-9 rad divergence, a 1e-13 s window, 2e6 motion samples, an aim passing 1 mm from the
    aperture, the bundled risk example (3.1e7 point evaluations), a dynamic keep-out of 3858
    steps (2.0e9 cell-steps), a 1 deg x 1 deg x 2 deg table, a keep-out grid of 9.97e6 cells and
    hazard convergence's finest refine_levels (5 at 2 deg: 8.3e6)."""
    monkeypatch.setenv("HAZARD_MAX_POINTS", "5")
    near = {"times_s": [0.0, 10.0], "aim_m": [[0.001, -60.0, 0.0], [0.001, -40.0, 0.0]]}
    for base, changes in ((PLATE, {("targets",): _targets(100)}), (PLATE, {("observers",): _points(5)}),
                          (MELT, {("laser", "divergence_rad"): 1e-9}), (MELT, {("analysis", "time_end_s"): 1e-13}),
                          (PLATE, {("laser", "aim_track"): SLEW, ("motion",): {"time_step_s": 10.0 / 1_999_999}}),
                          (PLATE, {("laser", "aim_track"): near}), (RISK, {}),
                          (MELT, {("analysis", "time_step_s"): 10.0 / 3858}),  # 518 400 x 3858 = 2.0e9
                          (PLATE, {("analysis",): {"direction_grid_deg": 0.0570, "refine_levels": 0}}),  # 1579 x 6316 = 9.97e6
                          (PLATE, {("analysis",): {"direction_grid_deg": 2.0, "refine_levels": 5}})):  # 45 x 180 x 4^5 = 8.3e6
        scenes.load(_write(tmp_path, _with(base, changes)))
    d = _with(PLATE, {("targets", 0, "material"): dict(TABLE, grid_deg=[1.0, 1.0, 2.0])})
    with pytest.raises(scenes.SceneError, match="samples.csv"):  # past the node count: the missing file is the error
        scenes.load(_write(tmp_path, d))


def test_risk_overrides_are_checked_before_work(tmp_path):
    f = _write(tmp_path, RISK)
    for opt, value in (("--sensitivity-draws", "10000000"), ("--draws", "100000000")):
        code, lines = _cli("risk", f, "-o", str(tmp_path / "out"), "--serial", "--quiet", opt, value)
        assert code == 2 and len(lines) == 1 and "HAZARD_MAX_RISK_EVALUATIONS" in lines[0] and opt in lines[0], lines
        assert not (tmp_path / "out").exists()


def _risk_variant(pointing, scale, tilt, shape, visibility, scint, spread, observers):
    d = copy.deepcopy(RISK)
    if shape == "sphere":
        d["targets"][0] = {"name": "panel", "shape": "sphere", "center_m": [0.0, 0.0, 2.0], "size_m": [0.2],
                           "material": {"model": "lambertian", "reflectance": 0.5}}
    if not observers:
        d["observers"] = []
    u = {"draws": 64, "pointing_sigma_rad": pointing, "brdf_scale_sigma": scale, "normal_tilt_sigma_deg": tilt,
         "observer_position_sigma_m": spread}
    if visibility:
        u["visibility"] = {"distribution": "uniform", "low_km": 5.0, "high_km": 20.0}
    if scint:
        u["scintillation"] = {"turbulence": "weak"}
    d["uncertainty"] = u
    return d


@FAST
@given(pointing=st.sampled_from([0.0, 1e-4]), scale=st.sampled_from([0.0, 0.3]), tilt=st.sampled_from([0.0, 0.5]),
       shape=st.sampled_from(["plate", "sphere"]), visibility=st.booleans(), scint=st.booleans(),
       spread=st.sampled_from([0.0, 0.5]), observers=st.booleans())
def test_uncertain_inputs_are_the_risk_models(pointing, scale, tilt, shape, visibility, scint, spread, observers):
    """The load-time rule (scenes.spec.uncertain_inputs) names the inputs the risk model
    draws (hazard.drivers.risk.inputs.InputModel.active), and refuses exactly when it names none."""
    from hazard.drivers.risk.inputs import input_model

    d = _risk_variant(pointing, scale, tilt, shape, visibility, scint, spread, observers)
    expect = [g for g, on in (("pointing", pointing > 0), ("material", scale > 0), ("tilt", tilt > 0 and shape == "plate"),
                              ("visibility", visibility), ("scintillation", scint),
                              ("observer_position", spread > 0 and observers)) if on]
    if not expect:
        with pytest.raises(scenes.SceneError, match="nothing is random"):
            scenes.loads(to_toml(d))
        return
    sc = scenes.loads(to_toml(d))
    n = len(sc.observers)
    assert uncertain_inputs(sc.spec) == expect == input_model(sc, n, n, np.array([0.0, 10.0])).active()


def _aim_check(a, b, laser):
    check_aim_aperture(AimSchedule(np.asarray(laser, float), np.array([0.0, 1.0]), np.array([a, b], float)))


def _aperture_property(a, b, t, side):
    a, b = np.asarray(a, float), np.asarray(b, float)
    if np.linalg.norm(b - a) < 1.0:
        return
    on = a + t * (b - a)  # a laser on the segment between the aim points
    with pytest.raises(ValueError, match="aperture"):
        _aim_check(a, b, on)
    u = (b - a) / np.linalg.norm(b - a)
    n = np.cross(u, [0.0, 0.0, 1.0] if abs(u[2]) < 0.9 else [1.0, 0.0, 0.0])
    off = on + side * n / np.linalg.norm(n)  # moved across the segment by `side` metres
    if side >= 1e-5:
        _aim_check(a, b, off)
    # the closest approach is the distance to the segment: beyond its ends the nearer end counts
    beyond = b + 2.0 * u
    _aim_check(a, b, beyond)


VEC = st.lists(st.floats(-1e3, 1e3, allow_nan=False), min_size=3, max_size=3)


@FAST
@given(a=VEC, b=VEC, t=st.floats(0.0, 1.0), side=st.floats(1e-5, 10.0))
def test_an_aim_segment_through_the_aperture_is_refused(a, b, t, side):
    _aperture_property(a, b, t, side)


@pytest.mark.slow
@SLOW
@given(a=VEC, b=VEC, t=st.floats(0.0, 1.0), side=st.floats(1e-5, 10.0))
def test_an_aim_segment_through_the_aperture_is_refused_many(a, b, t, side):
    _aperture_property(a, b, t, side)


def test_motion_samples_count_is_the_base_step_formula(tmp_path, monkeypatch):
    """floor(span / step) + 1 samples: at HAZARD_MAX_MOTION_SAMPLES = 101 a 0.1 s step over
    [0, 10] s (101 samples) loads and a 0.099 s step (102) is refused."""
    monkeypatch.setenv("HAZARD_MAX_MOTION_SAMPLES", "101")
    ok = _with(PLATE, {("laser", "aim_track"): SLEW, ("motion",): {"time_step_s": 0.1}})
    scenes.load(_write(tmp_path, ok))
    bad = _with(PLATE, {("laser", "aim_track"): SLEW, ("motion",): {"time_step_s": 0.099}})
    with pytest.raises(scenes.SceneError, match="= 102 exceeds the limit 101"):
        scenes.load(_write(tmp_path, bad))
    assert math.floor(10.0 / 0.099) + 1 == 102


def test_every_limit_is_in_the_readme_table_with_its_default():
    """The README's limits table lists every limit of brdfmodels.fileio.LIMITS at its default."""
    import re
    from pathlib import Path

    from brdfmodels.fileio import LIMITS

    text = (Path(__file__).resolve().parents[2] / "README.md").read_text()
    rows = dict(re.findall(r"^\| `HAZARD_MAX_([A-Z_]+)` \| ([0-9.e+]+) \|", text, flags=re.M))
    assert set(rows) == set(LIMITS)
    for name, (default, _) in LIMITS.items():
        assert float(rows[name]) == float(default), name


def test_validate_checks_a_study_as_study_does(tmp_path):
    """A study file given to validate goes through the study's own checks before work:
    a grid of 50 x 50 = 2500 scenarios is over HAZARD_MAX_SCENARIOS (1000) for both."""
    study = tmp_path / "big.toml"
    values = ", ".join(f"{100.0 + i:.1f}" for i in range(50))
    diameters = ", ".join(f"{0.001 * (i + 1):.3f}" for i in range(50))
    study.write_text(f'name = "big"\nscene = "plate"\n[sweep]\nkind = "grid"\n'
                     f'[[sweep.parameters]]\npath = "laser.power_w"\nvalues = [{values}]\n'
                     f'[[sweep.parameters]]\npath = "laser.beam_diameter_m"\nvalues = [{diameters}]\n')
    messages = {}
    for verb, extra in (("validate", []), ("study", ["-o", str(tmp_path / "out"), "--serial", "--quiet"])):
        code, lines = _cli(verb, str(study), *extra)
        assert code == 2 and len(lines) == 1 and "HAZARD_MAX_SCENARIOS" in lines[0] and "2500" in lines[0], lines
        messages[verb] = lines[0].removeprefix(f"hazard {verb}: error: ")
    assert messages["validate"] == messages["study"]
    assert not (tmp_path / "out").exists()
    code, lines = _cli("validate", "power_sweep")
    assert code == 0 and not lines


@pytest.mark.parametrize("limit, what", [("1000", "_ps.npy values"), ("3000", "_frames.npz[frames] size (8-byte values)")])
def test_screen_test_images_are_bounded(limit, what, tmp_path, monkeypatch):
    """HAZARD_MAX_SAMPLES bounds each image of a witness-screen test (48 x 48 = 2304 values in
    the point-source image, 2 x 48 x 48 = 4608 in the frames, read from the zip member's
    declared size before it is unpacked): over it, ``hazard fit screen`` refuses in one line
    naming the file and the variable, before any fit."""
    from brdfmodels import validation
    from tests.hazard.test_cli_fit import write_test

    test = write_test(tmp_path, "t0", validation.SyntheticGroovedMetal(), *validation.FIT_TESTS[0])
    monkeypatch.setenv("HAZARD_MAX_SAMPLES", limit)
    code, lines = _cli("fit", "screen", str(test), "-o", str(tmp_path / "m.json"))
    assert code == 2 and len(lines) == 1, lines
    assert "t0.toml" in lines[0] and what in lines[0] and "HAZARD_MAX_SAMPLES" in lines[0], lines[0]
    assert not (tmp_path / "m.json").exists()


@pytest.mark.parametrize("kind", ["history", "brdf table"])
def test_csv_lines_are_counted_before_parsing(kind, tmp_path, monkeypatch):
    """HAZARD_MAX_FILE_MB (256) alone let a 250 MB history CSV of 1.04e7 rows through:
    validate passed 4.4 GB before it was stopped. HAZARD_MAX_CSV_ROWS counts the lines
    first: over it, validate and run refuse in one line naming the file and the variable."""
    from tests.fuzz._file_corpus import HISTORY, MATERIAL, _with_material

    if kind == "history":
        (tmp_path / "h.csv").write_text("time_s,reflectance_factor\n0,1\n4,0.8\n10,0.6\n")  # 5 lines with the last newline
        text, name = _with_material(MATERIAL + HISTORY), "h.csv"
    else:
        (tmp_path / "t.csv").write_text("theta_i_deg,phi_i_deg,theta_r_deg,phi_r_deg,brdf_per_sr\n10,0,10,180,0.159\n"
                                        "20,0,20,180,0.159\n30,0,30,180,0.159\n")
        text, name = _with_material('material = { model = "table", file = "t.csv" }'), "t.csv"
    (tmp_path / "s.toml").write_text(text)
    monkeypatch.setenv("HAZARD_MAX_CSV_ROWS", "4")
    for verb, extra in (("validate", []), ("run", ["-o", str(tmp_path / "out"), "--quiet"])):
        code, lines = _cli(verb, str(tmp_path / "s.toml"), *extra)
        assert code == 2 and len(lines) == 1, lines
        assert f"{name}: lines = 5 exceeds the limit 4" in lines[0] and "HAZARD_MAX_CSV_ROWS" in lines[0], lines[0]
    monkeypatch.setenv("HAZARD_MAX_CSV_ROWS", "5")
    assert _cli("validate", str(tmp_path / "s.toml"))[0] == 0
