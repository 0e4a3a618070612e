"""The analysis result's annotations (issue 35): every field of :class:`HazardResult`,
:class:`TargetResult` and the stage results it is assembled from has a real type (none typed
only as ``object``, ``list`` or ``dict``), and the values a run puts there are of those
types (checked element by element on bundled and small scenes: pulsed, dynamic, aided,
mirror). The names imported under ``TYPE_CHECKING`` are resolved from the modules' own
``if TYPE_CHECKING:`` blocks (read with ast), so a new annotation is checked too."""

from __future__ import annotations

import ast
import dataclasses
import sys
import types
from pathlib import Path
from typing import Any, Union, get_args, get_origin, get_type_hints

import numpy as np
import pytest

import hazard
import scenes
from hazard.physics import engine
from hazard.pipeline import history, limits, results, spots, stages
from hazard.pipeline.analysis import run_pipeline
from tests._bundled import bundled
from tests._scene_text import PLATE_AT_50M

LOOSE = (object, list, dict, tuple, set)  # a field typed only as one of these says nothing of its values

PULSED = PLATE_AT_50M.replace("power_w = 100.0", "pulse_energy_j = 1.0\npulse_duration_s = 1e-8\nprf_hz = 10.0")
# a measured-series (dynamic) plate: a history over 5 analysis times, ~1 s
SERIES = PLATE_AT_50M.replace(
    'material = { model = "lambertian", reflectance = 0.5 }',
    'material = { file = "copper_glossy.json" }\n[targets.history]\nkind = "series"\nstate = "reflectance_factor"\n'
    'times_s = [0.0, 5.0, 10.0]\nstates = [1.0, 1.3, 0.2]') + "[analysis]\ntime_step_s = 2.5\n"


def _type_checking_names(module) -> dict:
    """The names ``module`` imports under ``if TYPE_CHECKING:`` (imported here, for the hints)."""
    tree = ast.parse(Path(module.__file__).read_text(encoding="utf-8"))
    ns: dict = {}
    for node in tree.body:
        if isinstance(node, ast.If) and "TYPE_CHECKING" in ast.unparse(node.test):
            exec(compile(ast.Module(body=node.body, type_ignores=[]), module.__file__, "exec"), ns)  # noqa: S102 (the module's own imports)
    return ns


def _hints(cls) -> dict:
    module = sys.modules[cls.__module__]
    return get_type_hints(cls, localns=_type_checking_names(module))


def _mismatch(value, hint, where="value") -> str | None:
    """None if ``value`` is of type ``hint`` (containers element by element), else why not."""
    origin, args = get_origin(hint), get_args(hint)
    if hint is Any:
        return None
    if origin in (Union, types.UnionType):
        whys = [_mismatch(value, a, where) for a in args]
        return None if None in whys else f"{where}: {type(value).__name__} is none of {args}"
    if hint is type(None):
        return None if value is None else f"{where}: {type(value).__name__}, expected None"
    if hint is float:  # an int is a float to the type checker (PEP 484); a bool is not meant
        return None if isinstance(value, (float, int)) and not isinstance(value, bool) else f"{where}: {value!r} is not a float"
    if origin is None:
        return None if isinstance(value, hint) else f"{where}: {type(value).__name__}, expected {hint.__name__}"
    if not isinstance(value, origin):
        return f"{where}: {type(value).__name__}, expected {origin.__name__}"
    if origin is dict:
        return next((w for k, v in value.items() for w in (_mismatch(k, args[0], f"{where} key"), _mismatch(v, args[1], f"{where}[{k!r}]"))
                     if w is not None), None)
    if origin is tuple and not (len(args) == 2 and args[1] is Ellipsis):
        if len(value) != len(args):
            return f"{where}: {len(value)} items, expected {len(args)}"
        return next((w for i, (v, a) in enumerate(zip(value, args)) if (w := _mismatch(v, a, f"{where}[{i}]")) is not None), None)
    return next((w for i, v in enumerate(value) if (w := _mismatch(v, args[0], f"{where}[{i}]")) is not None), None)


def _check(obj) -> None:
    hints = _hints(type(obj))
    for f in dataclasses.fields(obj):
        why = _mismatch(getattr(obj, f.name), hints[f.name], f"{type(obj).__name__}.{f.name}")
        assert why is None, why


def test_the_checker_refuses_what_it_should():
    """The element-wise check is not vacuous: wrong values of each kind are refused."""
    assert _mismatch([1.0, 2], list[float]) is None and _mismatch(None, int | None) is None
    assert _mismatch([1.0, "a"], list[float]) is not None
    assert _mismatch({1: np.zeros(2)}, dict[int, np.ndarray]) is None
    assert _mismatch({"1": np.zeros(2)}, dict[int, np.ndarray]) is not None
    assert _mismatch({1: [0.0]}, dict[int, np.ndarray]) is not None
    assert _mismatch((1.0, 2.0), list[float]) is not None
    assert _mismatch(True, float) is not None and _mismatch("x", str | list[str] | None) is None
    assert _mismatch([[0.0, 1.0], [2.0, "3"]], list[float] | list[list[float]] | None) is not None
    assert _mismatch(("a", "b"), tuple[str, ...]) is None and _mismatch(("a", 1), tuple[str, ...]) is not None


@pytest.mark.parametrize("cls", [results.HazardResult, results.TargetResult, results.Stage, results.ObserverResults, limits.ExposureLimits,
                                 history.StateHistories, spots.BeamStage, engine.SpotBuild,
                                 *dict.fromkeys(d.result for d in stages.REGISTRY.values())],
                         ids=lambda c: c.__name__)
def test_no_field_is_typed_only_as_object_list_or_dict(cls):
    hints = _hints(cls)  # resolves every annotation (a name missing from the TYPE_CHECKING block fails here)
    loose = [name for name, h in hints.items()
             if h in LOOSE or any(a in LOOSE for a in get_args(h)) or (get_origin(h) in LOOSE and not get_args(h))]
    assert not loose, f"{cls.__name__}: {loose} typed only as object, list, dict or tuple"


def _assert_typed(res) -> None:
    _check(res)
    _check(res.observers)
    for t in res.targets:
        _check(t)
    for s in res.stages:
        _check(s)


@pytest.mark.parametrize("name", ["plate", "mirror_window", "binoculars"])
def test_a_bundled_run_has_values_of_its_annotated_types(name):
    _assert_typed(bundled(name))


def test_a_pulsed_run_has_its_pulse_result_typed():
    res = hazard.analyze(scenes.loads(PULSED))
    assert res.pulse is not None
    _assert_typed(res)


def test_a_dynamic_run_has_its_states_typed():
    res = hazard.analyze(scenes.loads(SERIES, base_dir=scenes.example_path("plate").parent))
    assert set(res.states) == {0} and res.targets[0].state_range is not None
    _assert_typed(res)


@pytest.mark.slow
@pytest.mark.parametrize("name", ["stainless_melt", "steel_vs_copper", "airspace", "range_terrain"])
def test_a_bundled_run_has_values_of_its_annotated_types_slow(name):
    """The slower examples: melting and slumping (two states), heating next to a series,
    flight zones, terrain."""
    _assert_typed(bundled(name))


def _assert_stages_typed(res) -> None:
    for out in res.values():
        _check(out)
        traced = getattr(out, "traced", None)  # beam, history: the trace and its spots
        if traced is not None:
            _check(traced)
            _check(traced.built)


def test_the_stage_results_have_values_of_their_annotated_types():
    """Every stage's result of a flat-plate run (analytic hits: no ray scene) and of a
    dynamic one, with the trace and the spots inside."""
    res, _ = run_pipeline(scenes.loads(PLATE_AT_50M))
    assert res["rays"].ray_scene is None and res["beam"].traced.square is not None
    _assert_stages_typed(res)


@pytest.mark.slow
@pytest.mark.parametrize("name", ["range_terrain", "steel_vs_copper"])
def test_the_stage_results_have_values_of_their_annotated_types_slow(name):
    """A ray-traced scene (terrain) and a dynamic one (a new trace from the history)."""
    res, _ = run_pipeline(scenes.load(scenes.example_path(name)))
    _assert_stages_typed(res)


def test_limits_of_a_spec_built_around_its_validator_name_the_missing_prf():
    """A pulsed laser without prf_hz (a spec copied past its validator): the error names the field."""
    spec = scenes.loads(PULSED).spec
    bad = spec.model_copy(update={"laser": spec.laser.model_copy(update={"prf_hz": None})})
    with pytest.raises(ValueError, match=r"laser\.prf_hz = None"):
        limits.exposure_limits(bad)


def test_the_stage_limits_are_typed_on_a_pulsed_scene():
    ex = limits.exposure_limits(scenes.loads(PULSED).spec)
    _check(ex)
    assert ex.pulse is not None
