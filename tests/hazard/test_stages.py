"""Declared stages (hazard.pipeline.stages): the plan derived from what each stage needs,
clear errors for a missing input or a cycle, frozen results, no stage changing another's."""

from __future__ import annotations

import dataclasses
import random
import shutil
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

import scenes
from hazard.pipeline.analysis import hazard_result, run_pipeline
from hazard.pipeline.log import StageLog
from hazard.pipeline.plan import plan
from hazard.pipeline.stages import INPUTS, REGISTRY, StagePlanError, derive_plan, run_stages, stage, stage_records, value_fields
from tests._bundled import bundled
from tests._scene_text import PLATE_AT_50M

# report.json's stage list as the README and the reports show it (typed here, not read from the code)
REPORT_STAGES = ("mpe", "rays", "beam", "crossings", "direct", "spill", "sdz", "history", "specular", "line_of_sight",
                 "static", "dynamic", "exposure", "keepout", "mirror_beams", "footprint", "motion", "airspace",
                 "extended_source")

FAST = settings(max_examples=15, derandomize=True, deadline=None, database=None)
SLOW = settings(max_examples=300, derandomize=True, deadline=None, database=None)
FAST_FEW = settings(max_examples=2, derandomize=True, deadline=None, database=None)  # whole analyses: ~1 s each
SLOW_FEW = settings(max_examples=25, derandomize=True, deadline=None, database=None)


@dataclasses.dataclass(frozen=True)
class Out:
    value: int


def _toy(needs: dict) -> dict:
    """A registry of stages named as ``needs``' keys (in that order), each returning Out."""
    reg = {}
    for name, n in needs.items():
        stage(name, needs=n, result=Out, registry=reg)(lambda log, **kw: Out(len(kw)))
    return reg


def _is_topological(order, reg, inputs=()) -> bool:
    seen = set(inputs)
    for name in order:
        if not all(x in seen for x in reg[name].needs):
            return False
        seen.add(name)
    return sorted(order) == sorted(reg)


# -- the analysis's own registry ---------------------------------------------------------
def test_registry_plan_is_topological_and_gives_the_report_stage_list():
    order = derive_plan(REGISTRY)
    assert _is_topological(order, REGISTRY, INPUTS)
    # the records the stages write, in the plan's order, are the report's stage list
    assert tuple(r for n in order for r in REGISTRY[n].records) == stage_records() == REPORT_STAGES
    with pytest.raises(StagePlanError, match="no stage is declared"):
        stage_records({})


def test_every_stage_result_is_frozen_and_documented():
    for d in REGISTRY.values():
        assert d.result.__dataclass_params__.frozen, d.name
        assert d.doc, f"stage {d.name} has no docstring"
        assert d.result.__doc__, f"{d.result.__name__} has no docstring"
        assert set(d.needs) <= set(INPUTS) | set(REGISTRY), d.name


@pytest.fixture(scope="module")
def plate_run():
    """run_pipeline of the bundled plate (read only)."""
    return run_pipeline(scenes.load(scenes.example_path("plate")))


def test_frozen_result_refuses_assignment(plate_run):
    res, _ = plate_run
    with pytest.raises(dataclasses.FrozenInstanceError):
        res["mpe"].attenuation_per_m = 0.0
    with pytest.raises(TypeError):
        res["mpe"] = None  # the mapping itself is read-only


# -- derive_plan on toy registries --------------------------------------------------------
def test_declaration_order_kept_where_free_and_fixed_where_not():
    reg = _toy({"c": ("b",), "a": (), "b": ("a",), "d": ()})
    assert derive_plan(reg, ()) == ("a", "b", "c", "d")
    reg = _toy({"x": (), "y": (), "z": ()})
    assert derive_plan(reg, ()) == ("x", "y", "z")


def test_missing_input_names_the_stage_and_the_input():
    reg = _toy({"a": ("scene",), "b": ("a", "weather")})
    with pytest.raises(StagePlanError, match=r"stage 'b' needs \['weather'\]"):
        derive_plan(reg, ("scene",))


def test_cycle_names_the_stages_in_it():
    reg = _toy({"a": (), "b": ("a", "d"), "c": ("b",), "d": ("c",)})
    with pytest.raises(StagePlanError, match=r"\['b', 'c', 'd'\] need each other") as e:
        derive_plan(reg, ())
    assert "b needs ['d']" in str(e.value) and "'a'" not in str(e.value).split("need each other")[0]


def test_self_cycle():
    with pytest.raises(StagePlanError, match="cycle"):
        derive_plan(_toy({"a": ("a",)}), ())


def test_stage_refuses_mutable_result_and_double_registration():
    @dataclasses.dataclass
    class Mutable:
        v: int

    with pytest.raises(ValueError, match="not a frozen dataclass"):
        stage("m", needs=(), result=Mutable, registry={})
    with pytest.raises(ValueError, match="not a frozen dataclass"):
        stage("m", needs=(), result=dict, registry={})
    reg = _toy({"a": ()})
    with pytest.raises(ValueError, match="registered twice"):
        stage("a", needs=(), result=Out, registry=reg)(lambda log: Out(0))


def test_run_stages_passes_only_the_declared_needs_and_checks_the_type():
    reg = {}
    stage("a", needs=("k",), result=Out, registry=reg)(lambda log, k: Out(k + 1))
    stage("b", needs=("a",), result=Out, registry=reg)(lambda log, a: Out(a.value * 10))
    res = run_stages(reg, derive_plan(reg, ("k", "unused")), {"k": 1, "unused": 0}, None)
    assert dict(res) == {"a": Out(2), "b": Out(20)}
    stage("c", needs=(), result=Out, registry=reg)(lambda log: 3)
    with pytest.raises(TypeError, match="stage 'c' returned int, expected Out"):
        run_stages(reg, derive_plan(reg, ("k",)), {"k": 1}, None)


def _random_dag(seed: int, n: int, p: float):
    """n stages with random needs among the earlier ones (and the inputs), declared in a
    shuffled order: a DAG nobody arranged."""
    rng = random.Random(seed)
    names = [f"s{i}" for i in range(n)]
    needs = {nm: tuple(x for x in names[:i] + ["in0", "in1"] if rng.random() < p) for i, nm in enumerate(names)}
    order = names[:]
    rng.shuffle(order)
    return _toy({nm: needs[nm] for nm in order}), names, needs


def _check_random_dag(seed, n, p):
    reg, names, needs = _random_dag(seed, n, p)
    order = derive_plan(reg, ("in0", "in1"))
    assert _is_topological(order, reg, ("in0", "in1"))
    ran = []
    reg2 = {}
    for nm, d in reg.items():
        stage(nm, needs=d.needs, result=Out, registry=reg2)(lambda log, _nm=nm, **kw: (ran.append(_nm), Out(0))[1])
    run_stages(reg2, order, {"in0": 0, "in1": 1}, None)
    assert ran == list(order)
    # a back edge from the first stage to one that (transitively) needs it closes a cycle
    deps = [nm for nm in names if names[0] in needs[nm]]
    if deps:
        cyc = _toy({nm: (needs[nm] + (deps[-1],) if nm == names[0] else needs[nm]) for nm in reg})
        with pytest.raises(StagePlanError, match="need each other"):
            derive_plan(cyc, ("in0", "in1"))


@FAST
@given(st.integers(0, 2**32 - 1), st.integers(1, 12), st.floats(0.0, 0.8))
def test_random_dags_plan_in_dependency_order(seed, n, p):
    _check_random_dag(seed, n, p)


@pytest.mark.slow
@SLOW
@given(st.integers(0, 2**32 - 1), st.integers(1, 40), st.floats(0.0, 0.9))
def test_random_dags_plan_in_dependency_order_many(seed, n, p):
    _check_random_dag(seed, n, p)


# -- no stage changes another's result ----------------------------------------------------
def _small_melt(tmp_path):
    """stainless_melt with one observer and coarse grids (a dynamic target, ~10 s)."""
    src = Path(scenes.example_path("stainless_melt"))
    text = src.read_text().split("[[observers]]")[0]
    text += ('[analysis]\ntime_step_s = 5.0\ndirection_grid_deg = 15.0\nrefine_levels = 0\n'
             '[[observers]]\nname = "mast"\npoints_m = [[35.355, -42.131, 8.0]]\n')
    shutil.copy(src.parent / "stainless_melt_brdf.json", tmp_path)
    (tmp_path / "melt.toml").write_text(text)
    return scenes.load(tmp_path / "melt.toml")


@pytest.mark.slow
def test_history_makes_a_new_trace(tmp_path):
    """A dynamic (slumping) target: the beam stage's trace keeps its spots; the history's
    is a new object, and the result is built from it."""
    res, log = run_pipeline(_small_melt(tmp_path))
    beam, hist = res["beam"].traced, res["history"].traced
    assert res["history"].states and hist is not beam and hist.built is not beam.built
    assert hist.beam is beam.beam and len(hist.built.spots) == len(beam.built.spots)
    assert [sp.slump for sp in beam.built.spots] == [None]  # the beam's spots: as traced
    assert hist.built.spots[0].slump is not None
    final = hazard_result(res, log.stages() + [res["extended_source"].record])
    assert final.spots is hist.built.spots


def test_extended_source_builds_new_observers(plate_run):
    """The map's observers are not given C_E: the result's are a new object."""
    res, log = plate_run
    assert res["irradiance_map"].observers.mpe_w_m2 is None
    final = hazard_result(res, log.stages() + [res["extended_source"].record])
    assert final.observers is not res["irradiance_map"].observers
    assert final.observers.mpe_w_m2 is res["extended_source"].mpe_w_m2
    np.testing.assert_array_equal(final.observers.peak_irradiance_w_m2, res["irradiance_map"].observers.peak_irradiance_w_m2)


def test_mirror_beams_do_not_change_the_sdz_result():
    res, log = run_pipeline(scenes.load(scenes.example_path("mirror_window")))
    assert res["mirror_beams"].beams is not None
    assert res["sdz"].zone.mirror_beams is None and "mirror_beams" not in res["sdz"].zone.to_dict()
    final = hazard_result(res, log.stages())
    assert final.sdz.mirror_beams is res["mirror_beams"].beams
    assert dataclasses.replace(final.sdz, mirror_beams=None) == res["sdz"].zone


def test_analyze_is_the_assembled_stage_results(plate_run):
    a = bundled("plate")
    res, log = plate_run
    b = hazard_result(res, log.stages() + [res["extended_source"].record])
    assert [s.name for s in a.stages] == [s.name for s in b.stages] == list(REPORT_STAGES)
    np.testing.assert_array_equal(a.observers.peak_irradiance_w_m2, b.observers.peak_irradiance_w_m2)
    np.testing.assert_array_equal(a.observers.mpe_w_m2, b.observers.mpe_w_m2)
    assert a.notes == b.notes and a.sdz == b.sdz and a.spill == b.spill
    assert [t.to_dict() for t in a.targets] == [t.to_dict() for t in b.targets]


# -- property: on random scenes, no stage result changes after its stage returned ---------
GLOSSY = ('{ model = "sum", models = [{ type = "lambertian", params = { reflectance = 0.5 } }, '
          '{ type = "specular", params = { reflectance = 0.1 } }] }')


def _fingerprint(x, depth=0):
    """A comparable picture of a value: arrays by content, containers and dataclasses by
    their members (4 levels deep; not a memo, :func:`hazard.pipeline.stages.value_fields`,
    which may fill later), any other object by identity."""
    if isinstance(x, (bool, int, float, str, type(None))):
        return x if not (isinstance(x, float) and x != x) else "nan"
    if isinstance(x, np.ndarray):
        return ("array", x.shape, x.dtype.str, x.tobytes())
    if depth >= 4:
        return ("id", id(x))
    if isinstance(x, dict):
        return ("dict", tuple((repr(k), _fingerprint(v, depth + 1)) for k, v in x.items()))
    if isinstance(x, (list, tuple)):
        return (type(x).__name__, tuple(_fingerprint(v, depth + 1) for v in x))
    if dataclasses.is_dataclass(x) and not isinstance(x, type):
        return (type(x).__name__, tuple((f.name, _fingerprint(getattr(x, f.name), depth + 1)) for f in value_fields(x)))
    return ("id", id(x))


def _random_scene(tilt_deg, azimuth_deg, distance_m, mirror, line_z_m):
    t, a = np.radians(tilt_deg), np.radians(azimuth_deg)
    normal = [float(np.sin(t) * np.sin(a)), float(-np.cos(t)), float(np.sin(t) * np.cos(a))]
    text = PLATE_AT_50M.replace("position_m = [0.0, -50.0, 1.0]", f"position_m = [0.0, {-distance_m}, 1.0]")
    text = text.replace("normal = [0.0, -1.0, 0.0]", f"normal = {normal}").replace("tangent = [1.0, 0.0, 0.0]", "")
    if mirror:
        text = text.replace('material = { model = "lambertian", reflectance = 0.5 }', f"material = {GLOSSY}")
    text += ('[analysis]\ndirection_grid_deg = 10.0\nrefine_levels = 1\n'
             f'[[observers]]\nname = "line"\nstart_m = [-20.0, -30.0, {line_z_m}]\nend_m = [20.0, -30.0, {line_z_m}]\ncount = 9\n'
             '[[observers]]\nname = "eye"\npoints_m = [[5.0, -20.0, 1.5]]\n')
    return scenes.loads(text)


def _check_no_stage_changes_an_earlier_result(tilt_deg, azimuth_deg, distance_m, mirror, line_z_m):
    scene = _random_scene(tilt_deg, azimuth_deg, distance_m, mirror, line_z_m)
    taken = {}
    reg = {}
    for name, d in REGISTRY.items():
        def run(log, _d=d, **kw):
            out = _d.run(log, **kw)
            taken[_d.name] = _fingerprint(out)  # as the stage returned it
            return out
        stage(name, needs=d.needs, result=d.result, records=d.records, registry=reg)(run)
    log = StageLog()
    inputs = {"scene": scene, "plan": plan(scene), "backend": "embree", "threads": 1, "keep_history": None}
    res = run_stages(reg, derive_plan(reg, inputs), inputs, log)
    final = hazard_result(res, log.stages() + [res["extended_source"].record])
    for name, out in res.items():
        assert _fingerprint(out) == taken[name], f"stage {name}'s result changed after it returned"
    assert final.observers.mpe_w_m2 is not None and res["irradiance_map"].observers.mpe_w_m2 is None


@FAST_FEW
@given(st.floats(0.0, 60.0), st.floats(0.0, 360.0), st.floats(5.0, 80.0), st.booleans(), st.floats(0.0, 3.0))
def test_no_stage_changes_an_earlier_result(tilt_deg, azimuth_deg, distance_m, mirror, line_z_m):
    _check_no_stage_changes_an_earlier_result(tilt_deg, azimuth_deg, distance_m, mirror, line_z_m)


@pytest.mark.slow
@SLOW_FEW
@given(st.floats(0.0, 80.0), st.floats(0.0, 360.0), st.floats(2.0, 200.0), st.booleans(), st.floats(-1.0, 10.0))
def test_no_stage_changes_an_earlier_result_many(tilt_deg, azimuth_deg, distance_m, mirror, line_z_m):
    _check_no_stage_changes_an_earlier_result(tilt_deg, azimuth_deg, distance_m, mirror, line_z_m)
