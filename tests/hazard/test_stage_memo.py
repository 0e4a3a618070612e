"""The stage memo (hazard.pipeline.stages.StageMemo): a stage's result is reused only for
the same inputs, every stage a change reaches runs again, and a run with the memo gives
what a fresh hazard.analyze() gives, to the bit.

The expected reuse of each change is written here from the stages' declared needs and
what each reads (hazard.pipeline.analysis), not taken from the memo's own tables; the fresh run is
the oracle of the values, compared by an independent walk (arrays by their bytes)."""

from __future__ import annotations

import contextlib
import copy
import dataclasses
import math
import threading

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

import hazard
import scenes
from brdfmodels.fileio import read_toml
from hazard.pipeline.analysis import run_pipeline
from hazard.pipeline.stages import REGISTRY, StageMemo, Unfingerprintable, derive_plan, fingerprint, run_stages, stage

FAST = settings(max_examples=15, derandomize=True, deadline=None, database=None)
SLOW = settings(max_examples=300, derandomize=True, deadline=None, database=None)
FAST_FEW = settings(max_examples=2, derandomize=True, deadline=None, database=None)  # whole analyses: ~1 s each
SLOW_FEW = settings(max_examples=20, derandomize=True, deadline=None, database=None)

PLATE = scenes.example_path("plate")
ALL = set(REGISTRY)
BEFORE_KEEPOUT = {"mpe", "rays", "beam", "crossings", "direct", "spill", "sdz", "history", "irradiance_map"}
BEFORE_HISTORY = {"mpe", "rays", "beam", "crossings", "direct", "spill", "sdz"}
NEAR_FIELD = "; near-field lobe:"  # the keepout detail's clause on the near-field work of this run


def _scene(change=(), data=None):
    """The plate scene with ``change`` ((table, key, value), ...) applied."""
    d = copy.deepcopy(read_toml(PLATE) if data is None else data)
    for table, key, value in change:
        d.setdefault(table, {})[key] = value
    return scenes.from_data(d, source=str(PLATE), base_dir=PLATE.parent)


def _same(a, b, where="result", seen=None):
    """Assert ``a`` and ``b`` equal by value, floats and arrays to the bit."""
    seen = set() if seen is None else seen
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        assert isinstance(a, np.ndarray) and isinstance(b, np.ndarray), where
        assert (a.dtype, a.shape) == (b.dtype, b.shape), where
        if a.dtype.hasobject:
            return _same(a.tolist(), b.tolist(), where, seen)
        assert np.ascontiguousarray(a).tobytes() == np.ascontiguousarray(b).tobytes(), where
        return None
    assert type(a) is type(b), f"{where}: {type(a).__name__} != {type(b).__name__}"
    if isinstance(a, float):
        assert a == b and math.copysign(1, a) == math.copysign(1, b) or (math.isnan(a) and math.isnan(b)), f"{where}: {a!r} != {b!r}"
    elif a is None or isinstance(a, (bool, int, str, bytes, np.generic)):
        assert a == b, f"{where}: {a!r} != {b!r}"
    elif isinstance(a, (list, tuple)):
        assert len(a) == len(b), where
        for i, (x, y) in enumerate(zip(a, b)):
            _same(x, y, f"{where}[{i}]", seen)
    elif isinstance(a, dict):
        assert list(a) == list(b), where
        for k in a:
            _same(a[k], b[k], f"{where}[{k!r}]", seen)
    elif id(a) in seen:
        return None
    elif dataclasses.is_dataclass(a):
        seen.add(id(a))
        for f in dataclasses.fields(a):
            x, y = getattr(a, f.name), getattr(b, f.name)
            if f.name.startswith("_") and (x is None or y is None):
                continue  # a private lazy cache (Observers._cache) filled on first use: compared where both are filled
            _same(x, y, f"{where}.{f.name}", seen)
    elif hasattr(a, "model_dump"):
        _same(a.model_dump(), b.model_dump(), where, seen)
    return None


def _check_against_fresh(res, fresh, reused_keepout_grids):
    """``res`` (a run with the memo) equals ``fresh`` (hazard.analyze): every field but the
    stage records' seconds; with stages reused (``reused_keepout_grids``) keepout's
    near-field clause may name the grids its spots brought from an earlier run."""
    for f in dataclasses.fields(res):
        if f.name not in ("stages", "scene"):
            _same(getattr(res, f.name), getattr(fresh, f.name), f.name)
    _same(res.scene.spec, fresh.scene.spec, "scene.spec")
    _same(res.observers.observers.positions_m, fresh.observers.observers.positions_m, "observers.observers")
    _same(res.scene.observers.positions_m, fresh.scene.observers.positions_m, "scene.observers")
    _same(res.scene.observers.labels(), fresh.scene.observers.labels(), "scene.observers")
    assert [s.name for s in res.stages] == [s.name for s in fresh.stages]
    for s, t in zip(res.stages, fresh.stages):
        if s.name == "keepout" and reused_keepout_grids:  # its spots may come from an earlier run, with their grids
            assert s.detail.split(NEAR_FIELD)[0] == t.detail.split(NEAR_FIELD)[0]
            assert s.detail == t.detail or "integrated in an earlier run on the same spots (grids reused" in s.detail
        else:
            assert (s.ran, s.detail) == (t.ran, t.detail), s.name


def _graph_ids(obj, out=None, depth=0):
    """ids of the objects reachable from ``obj`` (dataclasses, containers, __dict__)."""
    out = set() if out is None else out
    if id(obj) in out or depth > 60 or isinstance(obj, (np.ndarray, str, bytes, int, float, type(None))):
        return out
    out.add(id(obj))
    if isinstance(obj, dict):
        items = list(obj.values())
    elif isinstance(obj, (list, tuple, set, frozenset)):
        items = list(obj)
    elif dataclasses.is_dataclass(obj):
        items = [getattr(obj, f.name) for f in dataclasses.fields(obj)]
    else:
        items = list(getattr(obj, "__dict__", {}).values())
    for x in items:
        _graph_ids(x, out, depth + 1)
    return out


@pytest.fixture(scope="module")
def primed():
    """A memo holding the plate's default run, and that run's scene."""
    memo, scene = StageMemo(), _scene()
    hazard.analyze(scene, memo=memo)
    assert memo.reused == [] and set(memo.computed) == ALL and memo.uncached == {}
    return memo, scene


@pytest.mark.parametrize("change, reused", [
    ((("analysis", "direction_grid_deg", 4.0),), BEFORE_KEEPOUT),
    pytest.param((("analysis", "refine_levels", 1),), BEFORE_KEEPOUT, marks=pytest.mark.slow),
    ((("analysis", "time_step_s", 0.05),), BEFORE_HISTORY),  # read by the history stage (the analysis times)
    pytest.param((("analysis", "beam_samples", 64),), set(), marks=pytest.mark.slow),
    pytest.param((("analysis", "footprint_eye_height_m", 1.5),), set(), marks=pytest.mark.slow),  # not proven unread: all run
    ((("laser", "power_w", 80.0),), set()),
    ((), ALL),  # the same scene loaded again
], ids=["direction_grid", "refine_levels", "time_step", "beam_samples", "eye_height", "power", "same"])
def test_memo_runs_again_what_a_change_reaches_and_equals_a_fresh_run(primed, change, reused):
    memo, first = primed
    scene = _scene(change)
    n = len(memo.reused)
    res = hazard.analyze(scene, memo=memo)
    assert {name for name, _ in memo.reused[n:]} == reused
    fresh = hazard.analyze(_scene(change))
    _check_against_fresh(res, fresh, reused_keepout_grids=bool(reused))
    # nothing of the earlier run's scene (its spec holds the other knobs) reaches this result
    ids = _graph_ids(res)
    assert id(first.spec) not in ids and id(first.spec.analysis) not in ids and id(first) not in ids


def test_a_crossings_result_reused_carries_the_new_scene():
    """A line across the beam gets a crossing point (the crossings stage's new scene); a
    keep-out knob's run reuses the point but its scene is the new one (its knob)."""
    data = read_toml(PLATE)
    data["observers"].append({"name": "across", "start_m": [-3.0, -30.0, 0.0], "end_m": [3.0, -30.0, 0.0], "count": 2})
    memo = StageMemo()
    r1, _ = run_pipeline(_scene(data=data), memo=memo)
    assert len(r1["crossings"].scene.observers) == 5  # the crossing was added
    scene = _scene((("analysis", "direction_grid_deg", 4.0),), data=data)
    res = hazard.analyze(scene, memo=memo)
    assert "crossings" in {name for name, _ in memo.reused}
    assert res.scene.spec is scene.spec and res.scene.observers is r1["crossings"].scene.observers
    _check_against_fresh(res, hazard.analyze(_scene((("analysis", "direction_grid_deg", 4.0),), data=data)), True)


def test_an_input_that_cannot_be_fingerprinted_runs_every_stage_again():
    memo = StageMemo()
    hazard.analyze(_scene(), memo=memo)
    scene = _scene()
    scene.site = threading.Lock()  # a C object: no state to compare by value (the plate's analysis never reads it)
    with pytest.raises(Unfingerprintable):
        fingerprint(scene.site)
    n = len(memo.reused)
    res = hazard.analyze(scene, memo=memo)
    assert len(memo.reused) == n and set(memo.uncached) == ALL
    _check_against_fresh(res, hazard.analyze(_scene()), reused_keepout_grids=False)


# -- run_stages with a toy registry ----------------------------------------------------------
@dataclasses.dataclass(frozen=True)
class Out:
    value: float


def _toy(calls):
    reg = {}

    @stage("a", needs=("scene",), result=Out, registry=reg)
    def _a(log, scene):
        calls.append("a")
        with log.run("a") as s:
            s.detail = f"a of {scene.spec.x}"
        return Out(scene.spec.x * 2)

    @stage("b", needs=("a", "threads"), result=Out, registry=reg)
    def _b(log, a, threads):
        calls.append("b")
        log.skip("b", f"why {a.value}")
        return Out(a.value + 1)

    return reg


@dataclasses.dataclass
class _Spec:
    x: float


@dataclasses.dataclass
class _Scene:
    spec: object


class _Log:
    """The stage log's interface, keeping (name, ran, detail) in order."""

    def __init__(self):
        self.records = []

    @contextlib.contextmanager
    def run(self, name, detail=""):
        rec = dataclasses.make_dataclass("Rec", [("detail", str), ("seconds", float)])(detail, 0.0)
        yield rec
        self.records.append((name, True, rec.detail))

    def ran(self, name, detail, seconds):
        self.records.append((name, True, detail))

    def skip(self, name, why):
        self.records.append((name, False, why))


@FAST
@given(xs=st.lists(st.floats(allow_nan=False, allow_infinity=False, width=64), min_size=1, max_size=6),
       threads=st.integers(1, 4))
def test_run_stages_reuses_exactly_the_repeated_inputs(xs, threads):
    """Over a random sequence of inputs, a stage runs again exactly when its inputs are new,
    and its result and log records are those of its first run with them."""
    calls, memo, first = [], StageMemo(), {}
    reg = _toy(calls)
    order = derive_plan(reg)
    for x in xs:
        calls.clear()
        log = _Log()
        out = run_stages(reg, order, {"scene": _Scene(_Spec(x)), "threads": threads}, log, memo)
        key = (repr(x), threads)
        assert calls == ([] if key in first else ["a", "b"])
        assert (out["a"].value, out["b"].value) == (x * 2, x * 2 + 1)
        assert log.records == first.setdefault(key, log.records) == [("a", True, f"a of {x}"), ("b", False, f"why {x * 2}")]


# -- the fingerprint --------------------------------------------------------------------------
_LEAF = st.one_of(st.none(), st.booleans(), st.integers(-10**6, 10**6), st.floats(width=64), st.text(max_size=5))
_TREE = st.recursive(_LEAF, lambda kids: st.one_of(st.lists(kids, max_size=4), st.dictionaries(st.text(max_size=3), kids, max_size=4)),
                     max_leaves=12)


def _changed(tree):
    """``tree`` with its first number replaced by the next float up (None: no number)."""
    if isinstance(tree, bool):
        return None
    if isinstance(tree, (int, float)):
        return float(np.nextafter(float(tree), math.inf)) if isinstance(tree, float) else tree + 1
    if isinstance(tree, list):
        for i, x in enumerate(tree):
            y = _changed(x)
            if y is not None:
                return tree[:i] + [y] + tree[i + 1:]
    if isinstance(tree, dict):
        for k, x in tree.items():
            y = _changed(x)
            if y is not None:
                return {**tree, k: y}
    return None


@FAST
@given(tree=_TREE)
def test_fingerprint_is_by_value_and_sees_one_ulp(tree):
    assert fingerprint(tree) == fingerprint(copy.deepcopy(tree))
    other = _changed(tree)
    if other is not None and repr(other) != repr(tree):
        assert fingerprint(other) != fingerprint(tree)


@FAST
@given(a=st.lists(st.floats(width=64, allow_nan=False, allow_infinity=False), min_size=1, max_size=8), i=st.integers(0, 7))
def test_fingerprint_of_arrays_and_closures(a, i):
    x = np.array(a)
    with np.errstate(over="ignore"):
        assert fingerprint(x) == fingerprint(x.copy()) != fingerprint(x.astype(np.float32))  # the dtype counts
    y = x.copy()
    y[i % len(y)] = np.nextafter(y[i % len(y)], -np.inf)  # one ulp down: finite
    assert fingerprint(y) != fingerprint(x)
    assert fingerprint(x.reshape(1, -1)) != fingerprint(x)  # the shape counts
    assert fingerprint(_points(x)) == fingerprint(_points(x.copy())) != fingerprint(_points(y))  # a closure by what it captured


class _Plain:
    def __init__(self, x):
        self.x = x


@FAST
@given(xs=st.lists(st.floats(width=64, allow_nan=False, allow_infinity=False), min_size=2, max_size=6), i=st.integers(0, 5))
def test_fingerprint_of_plain_objects_walks_each_one(xs, i):
    """Objects by their __dict__ (a temporary copy per object: each one's values count)."""
    ys = list(xs)
    ys[i % len(ys)] = float(np.nextafter(ys[i % len(ys)], -np.inf))  # one ulp down: finite
    assert fingerprint([_Plain(x) for x in xs]) == fingerprint([_Plain(x) for x in xs])
    assert fingerprint([_Plain(x) for x in xs]) != fingerprint([_Plain(y) for y in ys])


def _points(p):
    return lambda rows: p[rows]


def test_fingerprint_drops_only_the_named_spec_fields():
    a, b = _scene().spec, _scene((("analysis", "refine_levels", 1),)).spec
    assert fingerprint(a) != fingerprint(b)
    assert fingerprint(a, drop=("analysis.refine_levels",)) == fingerprint(b, drop=("analysis.refine_levels",))
    assert fingerprint(a, drop=("analysis.direction_grid_deg",)) != fingerprint(b, drop=("analysis.direction_grid_deg",))
    assert fingerprint(-0.0) != fingerprint(0.0) and fingerprint(1) != fingerprint(1.0) and fingerprint([1]) != fingerprint((1,))


def test_memo_tables_name_registered_stages():
    from hazard.pipeline.stages import CARRIES_SCENE, UNREAD_SPEC

    assert set(UNREAD_SPEC) <= ALL and set(CARRIES_SCENE) <= ALL
    # the keep-out knobs are read by keepout (and after): never dropped from its key
    assert "keepout" not in UNREAD_SPEC and "airspace" not in UNREAD_SPEC


@pytest.mark.slow
@SLOW_FEW
@given(grid=st.sampled_from([8.0, 4.0, 2.0, 1.0]), refine=st.integers(0, 3), step=st.floats(0.01, 1.0),
       samples=st.sampled_from([16, 64, 256]), power=st.floats(1.0, 500.0))
def test_memo_over_random_changes_equals_fresh_runs(grid, refine, step, samples, power):
    """Random sequences of knob and input changes through one memo: each run equals a fresh one."""
    memo = StageMemo()
    for change in [(), (("analysis", "direction_grid_deg", grid), ("analysis", "refine_levels", refine)),
                   (("analysis", "time_step_s", step),), (("analysis", "beam_samples", samples),), (("laser", "power_w", power),),
                   (("analysis", "direction_grid_deg", grid), ("analysis", "refine_levels", refine))]:
        n = len(memo.reused)
        res = hazard.analyze(_scene(change), memo=memo)
        reused = {name for name, _ in memo.reused[n:]}
        _check_against_fresh(res, hazard.analyze(_scene(change)), reused_keepout_grids=bool(reused))


# -- a serial study shares a memo ----------------------------------------------------------------
def _without_time(row):
    return {k: v for k, v in row.items() if k != "run_time_s"}


def _study_rows(study, memo):
    from hazard.drivers.study import base_data, run_scenario, scenarios

    base, base_dir = base_data(study)
    mc = dataclasses.asdict(study.montecarlo)
    return [run_scenario(base, str(base_dir), s, mc, memo=memo) for s in scenarios(study)]


def test_study_scenarios_through_one_memo_give_the_rows_of_fresh_runs(tmp_path):
    from hazard.drivers.study import MonteCarlo, Parameter, Study

    scene = tmp_path / "plate.toml"  # the plate with an [analysis] table for the sweep's path
    scene.write_text(PLATE.read_text() + "[analysis]\ndirection_grid_deg = 2.0\n")
    sweep = Study(name="t", scene=str(scene), kind="grid", parameters=(Parameter("analysis.direction_grid_deg", values=(4.0, 2.0)),))
    memo = StageMemo(max_entries=40)
    rows = _study_rows(sweep, memo)
    assert [_without_time(r) for r in rows] == [_without_time(r) for r in _study_rows(sweep, None)]
    assert all(r["error"] is None for r in rows) and rows[0]["keepout_volume_static_m3"] != rows[1]["keepout_volume_static_m3"]
    assert {name for name, _ in memo.reused} == BEFORE_KEEPOUT and len(memo._entries) <= 40
    # Monte Carlo: each draw scales the targets' materials, part of every stage's scene: nothing reused
    mc = Study(name="t", scene=str(scene), kind="grid", parameters=(Parameter("analysis.direction_grid_deg", values=(4.0,)),),
               montecarlo=MonteCarlo(samples=2, brdf_scale_sigma=0.3))
    memo = StageMemo(max_entries=40)
    rows = _study_rows(mc, memo)
    assert all(r["error"] is None for r in rows) and len({tuple(r["brdf_scales"]) for r in rows}) == len(rows) == 2
    assert [_without_time(r) for r in rows] == [_without_time(r) for r in _study_rows(mc, None)] and memo.reused == []


def test_memo_keeps_at_most_max_entries():
    memo = StageMemo(max_entries=3)
    reg = _toy([])
    for x in (1.0, 2.0, 3.0):
        run_stages(reg, derive_plan(reg), {"scene": _Scene(_Spec(x)), "threads": 1}, _Log(), memo)
    assert len(memo._entries) == 3  # the last two runs' a and b, less the oldest
    with pytest.raises(ValueError, match="max_entries=0: expected a positive integer or None"):
        StageMemo(max_entries=0)


def test_dask_study_workers_reuse_stages_like_the_serial_study(tmp_path, monkeypatch):
    """A Dask study's worker keeps a stage memo over the scenarios it runs (one in-process
    worker here, so the memo can be read): a sweep of the keep-out grid reuses every stage
    before the keep-out lobes, the rows equal the serial study's, and the memo is dropped
    at the run's end (a second run starts its own)."""
    from distributed import LocalCluster

    import hazard.drivers.study as hs
    from hazard.drivers.study import Parameter, Study, run_study

    scene = tmp_path / "plate.toml"
    scene.write_text(PLATE.read_text() + "[analysis]\ndirection_grid_deg = 2.0\n")
    sweep = Study(name="t", scene=str(scene), kind="grid", parameters=(Parameter("analysis.direction_grid_deg", values=(4.0, 2.0, 3.0)),))
    memos = {}  # the run's token -> the memo its process kept (read after the run dropped it)
    real = hs.process_memo

    def recording(token):  # called in the worker: in this process (an in-process cluster)
        memos[token] = real(token)
        return memos[token]

    monkeypatch.setattr(hs, "process_memo", recording)
    serial = run_study(sweep, tmp_path / "serial", serial=True)
    with LocalCluster(n_workers=1, threads_per_worker=1, processes=False, dashboard_address=None) as cluster:
        dask = run_study(sweep, tmp_path / "dask", scheduler=cluster.scheduler_address)
    assert [_without_time(r) for r in dask.rows] == [_without_time(r) for r in serial.rows] and len(dask.rows) == 3
    assert len(memos) == 2  # the serial run's and the worker's: a new memo per run
    for memo in memos.values():
        assert {name for name, _ in memo.reused} == BEFORE_KEEPOUT
        assert memo.computed.count("keepout") == 3 and memo.computed.count("mpe") == 1
    assert hs._MEMOS == {}


def test_a_memo_filling_does_not_change_the_key():
    """The observers keep their generated points once analysed (a memo): the scene's key is
    the same before and after, so a study or a convergence run re-using the scene hits its
    memo instead of running the stages again; a point moved still changes the key."""
    scene = scenes.load(scenes.example_path("plate"))
    before = fingerprint(scene.observers)
    assert scene.observers.keep_points()
    assert fingerprint(scene.observers) == before
    path = scenes.example_path("plate")
    moved = scenes.loads(path.read_text().replace("[[10.0, -17.0", "[[10.5, -17.0"), base_dir=path.parent)
    assert fingerprint(moved.observers) != before
