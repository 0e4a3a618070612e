"""Declared stages: what each needs, what it provides, and the plan derived from that.

Each stage of :func:`hazard.analyze` is a function registered with :func:`stage`: it
declares the names it needs (the analysis inputs ``scene``, ``plan``, ``backend``,
``threads``, ``keep_history``, or another stage's name) and provides one frozen result
(the stage's name -> an instance of its declared result type). The stage owns its skip
reason: it records in the :class:`~hazard.pipeline.log.StageLog` what it did or why it
did nothing (``records``: the report's stage-list entries it writes) and still returns
its (empty) result. :func:`derive_plan` orders the stages from their declarations (a
topological sort that keeps the declaration order where it is free), with an error
naming the stage for a missing input or a cycle; :func:`run_stages` runs them, each
with only what it declared, and returns the mapping stage name -> result. A stage never
changes another's result: it makes a new value (``dataclasses.replace``) instead.

The result types are frozen dataclasses (their attributes cannot be reassigned; the
numpy arrays and dicts they hold are owned by the stage that made them and are read,
never written, by the later ones). Units are in the field names (SI; ``wavelength_nm``
the exception).

Cached intermediates (scikit-learn's Pipeline ``memory``): :func:`run_stages` given a
:class:`StageMemo` reuses a stage's result (and replays the stage-log records it wrote)
when a fingerprint of everything it is called with equals an earlier run's. A stage's
key is the SHA-256 of its name and, per need: the scene's content (every field of the
:class:`scenes.Scene`, numpy arrays by their bytes, the spec by value) less the spec
fields :data:`UNREAD_SPEC` proves the stage never reads and the scene fields
:data:`UNREAD_SCENE` proves no stage reads; the other inputs by value; another stage by
that stage's key (and, for a stage whose result carries the scene, :data:`CARRIES_SCENE`,
the scene's content as well). An input that cannot be fingerprinted (a function, a C
object) makes the stage, and every stage after it, run afresh: the memo never guesses.
Module-level settings (``hazard.physics.near_field_lobe.ENABLED``, ``MAP_CHUNK``) are not in the
key: a memo lives for one driver call (one ``hazard convergence``), never across calls.
"""

from __future__ import annotations

import enum
import hashlib
import time
import types
from collections.abc import Callable, Iterable, Mapping
from contextlib import contextmanager
from dataclasses import dataclass, fields, is_dataclass, replace
from pathlib import PurePath
from types import MappingProxyType
from typing import TYPE_CHECKING, Any

import numpy as np
from pydantic import BaseModel

if TYPE_CHECKING:  # annotations only (no import at run time: the stages' modules import this one)
    from scenes.scene import Scene

    from hazard.physics.keepout import Footprint
    from hazard.physics.rays import RayScene
    from hazard.pipeline.results import ObserverResults, TargetResult
    from hazard.pipeline.direct import DirectBeam
    from hazard.pipeline.history import Melt
    from hazard.pipeline.limits import ExposureLimits
    from hazard.pipeline.motion_stage import MotionResult
    from hazard.pipeline.airspace import AirspaceCheck
    from hazard.physics.visual import VisualInterference
    from hazard.pipeline.sdz import DangerZone, MirrorBeam
    from hazard.pipeline.spill import SpillSummary
    from hazard.pipeline.spots import BeamStage, FlatScene

__all__ = ["StageDef", "StagePlanError", "stage", "derive_plan", "run_stages", "REGISTRY", "INPUTS", "value_fields",
           "StageMemo", "Unfingerprintable", "fingerprint", "UNREAD_SPEC", "UNREAD_SCENE", "CARRIES_SCENE",
           "LimitsResult", "RaysResult", "BeamResult", "CrossingsResult", "DirectResult", "SpillResult", "SdzResult",
           "HistoryResult", "MapResult", "KeepoutResult", "MirrorBeamsResult", "FootprintResult", "MotionStageResult",
           "AirspaceResult"]

#: The analysis inputs a stage may need besides other stages' results.
INPUTS = ("scene", "plan", "backend", "threads", "keep_history")


class StagePlanError(ValueError):
    """The declared stages cannot be ordered: an input nobody provides, or a cycle."""


@dataclass(frozen=True)
class StageDef:
    """One declared stage.

    Attributes
    ----------
    name : str
        The stage's name; its result is provided under this name.
    needs : tuple of str
        Names it is called with (keyword arguments): analysis inputs or stage names.
    result : type
        The frozen dataclass it returns.
    run : callable
        ``run(log, **needs) -> result``.
    records : tuple of str
        The report's stage-list entries it writes (ran or skipped, with the reason).
    """

    name: str
    needs: tuple[str, ...]
    result: type
    run: Callable[..., Any]
    records: tuple[str, ...]

    @property
    def doc(self) -> str:
        """First line of the stage function's docstring."""
        return (self.run.__doc__ or "").strip().splitlines()[0] if self.run.__doc__ else ""


#: Every stage of the analysis, in declaration order (filled by :func:`stage`).
REGISTRY: dict[str, StageDef] = {}


def stage(name: str, *, needs: Iterable[str], result: type, records: Iterable[str] | None = None,
          registry: dict[str, StageDef] | None = None):
    """Register the decorated function as stage ``name`` (see the module notes).

    Raises
    ------
    ValueError
        ``name`` already registered, or ``result`` not a frozen dataclass.
    """
    reg = REGISTRY if registry is None else registry
    params = getattr(result, "__dataclass_params__", None)
    if params is None or not params.frozen:
        raise ValueError(f"stage {name!r}: result type {getattr(result, '__name__', result)!r} is not a frozen dataclass")

    def register(fn):
        if name in reg:
            raise ValueError(f"stage {name!r} registered twice")
        reg[name] = StageDef(name, tuple(needs), result, fn, tuple(records) if records is not None else (name,))
        return fn

    return register


def derive_plan(stages: Mapping[str, StageDef], inputs: Iterable[str] = INPUTS) -> tuple[str, ...]:
    """The order to run ``stages`` in: every stage after the stages it needs.

    A topological sort (Kahn's) that, among the stages ready at each step, takes the one
    declared first, so a registry declared in a valid order runs in that order.

    Raises
    ------
    StagePlanError
        A stage needs a name that is neither an input nor a stage (named with the
        stage), or the stages' needs form a cycle (the stages left are named).
    """
    given = set(inputs)
    for d in stages.values():
        missing = [n for n in d.needs if n not in given and n not in stages]
        if missing:
            raise StagePlanError(f"stage {d.name!r} needs {missing}, which no stage provides and is not an input "
                                 f"(inputs: {sorted(given)}; stages: {list(stages)})")
    order: list[str] = []
    left = dict(stages)
    while left:
        ready = next((n for n, d in left.items() if all(x in given or x in order for x in d.needs)), None)
        if ready is None:
            raise StagePlanError(f"the stages {sorted(left)} need each other (a cycle): "
                                 + "; ".join(f"{n} needs {[x for x in d.needs if x in left]}" for n, d in left.items()))
        order.append(ready)
        del left[ready]
    return tuple(order)


def stage_records(stages: Mapping[str, StageDef] | None = None) -> tuple[str, ...]:
    """The names of the stage records (report.json's ``stages`` list), in the order of the
    plan :func:`derive_plan` derives from the declarations (``REGISTRY`` by default: the
    analysis's stages, declared when :mod:`hazard.pipeline.analysis` is imported).

    Raises
    ------
    StagePlanError
        No stage is declared (the registry is empty).
    """
    reg = REGISTRY if stages is None else stages
    if not reg:
        raise StagePlanError("no stage is declared: the analysis's stages are declared by importing hazard.pipeline.analysis")
    return tuple(r for n in derive_plan(reg) for r in reg[n].records)


def run_stages(stages: Mapping[str, StageDef], order: Iterable[str], inputs: Mapping[str, Any], log,
               memo: StageMemo | None = None) -> Mapping[str, Any]:
    """Run the stages in ``order``, each with what it declared; stage name -> result.

    ``memo``: a :class:`StageMemo`; a stage whose inputs' fingerprint it holds is not run:
    its result is reused and its stage-log records written again (see the module notes).

    Raises
    ------
    TypeError
        A stage returned something other than its declared result type.
    """
    values = dict(inputs)
    results: dict[str, Any] = {}
    keys: dict[str, str | None] = {}
    if memo is not None:
        memo.begin(values.get("scene"))
    for name in order:
        d = stages[name]
        key = keys[name] = None if memo is None else memo.key(d, values, keys)
        out = None if memo is None or key is None else memo.reuse(key, name, values.get("scene"), log)
        if out is None:
            rec = _Recorder(log)
            t0 = time.perf_counter()
            out = d.run(log if key is None else rec, **{n: values[n] for n in d.needs})  # without a key: the log itself
            if not isinstance(out, d.result):
                raise TypeError(f"stage {name!r} returned {type(out).__name__}, expected {d.result.__name__}")
            if memo is not None and key is not None:
                memo.store(key, name, out, rec.calls, values.get("scene"), time.perf_counter() - t0)
        values[name] = results[name] = out
    return MappingProxyType(results)


# -- cached intermediates -------------------------------------------------------------------
_KEEPOUT_KNOBS = ("analysis.direction_grid_deg", "analysis.refine_levels")
_TIME_KNOBS = ("analysis.time_step_s", "analysis.time_end_s")

#: Spec fields (dotted paths) each stage is proven not to read: grep of the stage and every
#: function it calls (``direction_grid_deg`` and ``refine_levels`` are read only by
#: ``hazard.pipeline.lobes`` and ``hazard.physics.keepout`` (stage ``keepout``) and
#: ``hazard.physics.visual`` (stage ``airspace``); ``analysis.time_step_s`` and ``time_end_s`` only
#: by ``hazard.pipeline.history`` (stage ``history``) and the scene loader's checks). A
#: stage not listed is keyed on the whole spec.
UNREAD_SPEC: dict[str, tuple[str, ...]] = {
    **{n: _KEEPOUT_KNOBS + _TIME_KNOBS for n in ("mpe", "rays", "beam", "crossings", "direct", "spill", "sdz")},
    **{n: _KEEPOUT_KNOBS for n in ("history", "irradiance_map")},
}
#: Scene fields no stage reads (grep of ``hazard`` less its outputs, ``scenes``, ``brdfmodels``):
#: the text's hash, the keys as given and their units, the plausibility warnings (they
#: repeat the spec's values, knobs included), the source's name (a study names each
#: scenario). Every other field is in the key (``base_dir`` too).
UNREAD_SCENE = ("text_sha256", "source_data", "units_as_written", "warnings", "source")
#: Stages whose result carries the scene (``crossings``: the input scene with observer
#: points added): a stage that needs one is keyed on the scene's content too, and a
#: reused result is given the current scene (only its observers taken from the memo).
CARRIES_SCENE = ("crossings",)


class Unfingerprintable(TypeError):
    """An input the memo cannot fingerprint by value (the stage then runs afresh)."""


def fingerprint(obj, *, drop=()) -> str:
    """SHA-256 (hex) of ``obj`` by value: numbers by their exact repr, numpy arrays by
    dtype, shape and bytes, containers in order, dataclasses by their fields but memos
    (:func:`value_fields`), pydantic
    models by their dump, functions by their code and the values they captured (globals
    and named code as they are in this process), other objects by their ``__dict__`` and
    slots; ``drop``: dotted key paths
    left out of a pydantic model's dump (``"analysis.refine_levels"``).

    Raises
    ------
    Unfingerprintable
        An object with no inspectable state (a C object without ``__dict__``).
    """
    h = hashlib.sha256()
    _feed(h, obj, {}, tuple(p.split(".") for p in drop))
    return h.hexdigest()


def value_fields(obj) -> list:
    """The fields of dataclass ``obj`` that make its value: all but a memo, a private field
    declared ``compare=False`` (a cache of the others, e.g. the observers' generated points,
    that may fill after the object is made without changing what it is)."""
    return [f for f in fields(obj) if f.compare or not f.name.startswith("_")]


def _dropped(data: dict, drop) -> dict:
    """``data`` (a model's dump) less the key paths ``drop`` (tuples of keys)."""
    for path in drop:
        d: Any = data
        for part in path[:-1]:
            d = d.get(part) if isinstance(d, dict) else None
        if isinstance(d, dict):
            d.pop(path[-1], None)
    return data


def _feed(h, obj, seen: dict, drop=()) -> None:
    """Feed ``obj``'s value into ``h`` (``seen``: id -> (index, object) of the objects fed, for
    sharing and cycles)."""
    t = type(obj)
    if obj is None or t in (bool, int, float, complex, str, bytes):
        h.update(f"{t.__name__}:{obj!r};".encode())
        return
    if isinstance(obj, (np.generic, enum.Enum, PurePath)):
        h.update(f"{t.__qualname__}:{obj!r};".encode())
        return
    if id(obj) in seen:
        h.update(f"ref:{seen[id(obj)][0]};".encode())
        return
    seen[id(obj)] = (len(seen), obj)  # held: a temporary's id is not reused during the walk
    h.update(f"<{t.__module__}.{t.__qualname__}>".encode())
    if isinstance(obj, np.ndarray):
        if obj.dtype.hasobject:
            _feed(h, obj.tolist(), seen)
        else:
            h.update(f"{obj.dtype.str}{obj.shape}".encode() + np.ascontiguousarray(obj).tobytes())
    elif isinstance(obj, (list, tuple)):
        for x in obj:
            _feed(h, x, seen)
    elif isinstance(obj, dict):
        for k, v in obj.items():
            _feed(h, k, seen)
            _feed(h, v, seen)
    elif isinstance(obj, (set, frozenset)):
        for x in sorted(fingerprint(x) for x in obj):
            h.update(x.encode())
    elif isinstance(obj, BaseModel):
        _feed(h, _dropped(obj.model_dump(mode="python"), drop), seen)
    elif is_dataclass(obj) and not isinstance(obj, type):
        for f in value_fields(obj):
            h.update(f.name.encode())
            _feed(h, getattr(obj, f.name), seen)
    elif isinstance(obj, types.FunctionType):  # a closure (an observer group's point generator): code and captured values
        c = obj.__code__
        h.update(f"{c.co_filename}:{c.co_firstlineno}:{obj.__qualname__}".encode() + c.co_code)
        _feed(h, (c.co_consts, c.co_names, obj.__defaults__, obj.__kwdefaults__,
                  [cell.cell_contents for cell in obj.__closure__ or ()]), seen)
    elif isinstance(obj, types.CodeType):  # a nested function's or comprehension's code
        h.update(f"{obj.co_filename}:{obj.co_firstlineno}:{obj.co_name}".encode() + obj.co_code)
        _feed(h, (obj.co_consts, obj.co_names), seen)
    elif isinstance(obj, types.MethodType):
        _feed(h, (obj.__func__, obj.__self__), seen)
    elif isinstance(obj, (type, types.BuiltinFunctionType, types.ModuleType)):  # code, named: the same in one process
        h.update(f"{getattr(obj, '__module__', '')}.{getattr(obj, '__qualname__', obj.__name__)}".encode())
        if isinstance(obj, types.BuiltinFunctionType) and not isinstance(obj.__self__, (types.ModuleType, type(None))):
            _feed(h, obj.__self__, seen)
    elif hasattr(obj, "__dict__") or hasattr(type(obj), "__slots__"):
        slots = [n for c in type(obj).__mro__ for n in getattr(c, "__slots__", ()) if hasattr(obj, n)]
        _feed(h, {**{n: getattr(obj, n) for n in slots}, **getattr(obj, "__dict__", {})}, seen)
    else:
        raise Unfingerprintable(f"cannot fingerprint a {t.__module__}.{t.__qualname__} by value")
    h.update(b"</>")


class _Recorder:
    """The stage log as a stage sees it: every record passed on, and kept to replay."""

    def __init__(self, log):
        self._log, self.calls = log, []

    @contextmanager
    def run(self, name, detail=""):
        with self._log.run(name, detail) as st:
            yield st
        self.calls.append(("ran", name, st.detail, st.seconds))

    def ran(self, name, detail, seconds):
        self._log.ran(name, detail, seconds)
        self.calls.append(("ran", name, detail, seconds))

    def skip(self, name, why):
        self._log.skip(name, why)
        self.calls.append(("skip", name, why))


class StageMemo:
    """Stage results of earlier runs keyed by their inputs' fingerprint (module notes).

    Attributes
    ----------
    reused : list of (str, float)
        Each reuse: the stage's name and the seconds the reused run took.
    computed : list of str
        The stages run afresh (keyed, or not: see ``uncached``).
    uncached : dict
        Stage name -> why its inputs could not be fingerprinted (it ran afresh).

    Parameters
    ----------
    max_entries : int, optional
        Keep at most this many stage results, the least recently used dropped first
        (default: all, for a bounded sweep such as ``hazard convergence``).
    """

    def __init__(self, max_entries: int | None = None):
        if max_entries is not None and (isinstance(max_entries, bool) or not isinstance(max_entries, int) or max_entries < 1):
            raise ValueError(f"max_entries={max_entries!r}: expected a positive integer or None")
        self.max_entries = max_entries
        self._entries: dict[str, tuple] = {}
        self._scene_fp: dict[tuple, tuple] = {}
        self.reused: list[tuple[str, float]] = []
        self.computed: list[str] = []
        self.uncached: dict[str, str] = {}

    def begin(self, scene=None) -> None:
        """A new run of ``scene``: its fingerprints computed again, before any stage runs (a
        stage may fill a lazy cache of the scene, e.g. the observers' points)."""
        self._scene_fp.clear()
        for drop in {(), *UNREAD_SPEC.values()}:
            try:
                self._scene(scene, drop)
            except Unfingerprintable:
                pass  # raised again where a stage needs it

    def key(self, d: StageDef, values: Mapping[str, Any], keys: Mapping[str, str | None]) -> str | None:
        """The key of stage ``d`` with these inputs (None: not fingerprintable)."""
        h = hashlib.sha256(f"stage:{d.name};".encode())
        try:
            for n in d.needs:
                h.update(f"need:{n};".encode())
                if n in keys:
                    k = keys[n]
                    if k is None:
                        raise Unfingerprintable(f"its input {n!r} was not fingerprinted")
                    h.update(k.encode())
                if n == "scene" or n in CARRIES_SCENE:
                    h.update(self._scene(values["scene"], UNREAD_SPEC.get(d.name, ())).encode())
                elif n not in keys:
                    h.update(fingerprint(values[n]).encode())
        except Unfingerprintable as exc:
            self.uncached[d.name] = str(exc)
            return None
        return h.hexdigest()

    def _scene(self, scene, drop) -> str:
        held = self._scene_fp.get(drop)
        if held is None or held[0] is not scene:  # the scene itself is held: its id cannot be reused meanwhile
            if not is_dataclass(scene):
                raise Unfingerprintable(f"the scene is a {type(scene).__name__}, not a scenes.Scene")
            parts = {f.name: getattr(scene, f.name) for f in fields(scene) if f.name not in UNREAD_SCENE}
            spec = parts.pop("spec", None)  # by value, less the fields ``drop``
            held = self._scene_fp[drop] = (scene, fingerprint((parts, fingerprint(spec, drop=drop))))
        return held[1]

    def reuse(self, key: str, name: str, scene, log):
        """The stored result for ``key`` (its log records replayed on ``log``), or None."""
        entry = self._entries.pop(key, None)
        if entry is None:
            return None
        self._entries[key] = entry  # the most recently used last
        out, calls, old_scene, seconds = entry
        for c in calls:
            if c[0] == "ran":
                log.ran(*c[1:])
            else:
                log.skip(*c[1:])
        self.reused.append((name, seconds))
        return _rebind(out, old_scene, scene)

    def store(self, key: str, name: str, out, calls, scene, seconds: float) -> None:
        """Keep stage ``name``'s result ``out`` (and its log ``calls``) under ``key``."""
        self.computed.append(name)
        if _rebind(out, scene, scene) is not None:
            self._entries[key] = (out, tuple(calls), scene, seconds)
            while self.max_entries is not None and len(self._entries) > self.max_entries:
                del self._entries[next(iter(self._entries))]

    def reused_seconds(self, since: int = 0) -> float:
        """Seconds the reused stages took when they ran (reuses from index ``since``)."""
        return float(sum(s for _, s in self.reused[since:]))


def _rebind(out, old_scene, scene):
    """``out`` for ``scene``: a result carrying the scene (:class:`CrossingsResult`) gets
    ``scene`` with the observers it had; None when it changed more than the observers
    (then it is not stored)."""
    if not isinstance(out, CrossingsResult) or out.scene is old_scene:
        return out if not isinstance(out, CrossingsResult) else CrossingsResult(scene)
    same = all(getattr(out.scene, f.name) is getattr(old_scene, f.name) for f in fields(old_scene) if f.name != "observers")
    return CrossingsResult(replace(scene, observers=out.scene.observers)) if same else None


# -- the stages' results ------------------------------------------------------------------
@dataclass(frozen=True)
class LimitsResult:
    """Stage ``mpe``: the exposure limits (:class:`hazard.pipeline.limits.ExposureLimits`:
    the MPE with its steps, the irradiance limit [W/m^2], the radiant-exposure limit
    [J/m^2], the pulse result) and the atmospheric attenuation coefficient [1/m]."""

    exposure: ExposureLimits
    attenuation_per_m: float


@dataclass(frozen=True)
class RaysResult:
    """Stage ``rays``: the ray scene (None: hits computed analytically) and the tracer the
    beam and the lines of sight use (the ray scene, or :class:`~hazard.pipeline.spots.FlatScene`)."""

    ray_scene: RayScene | None
    tracer: RayScene | FlatScene


@dataclass(frozen=True)
class BeamResult:
    """Stage ``beam``: the traced beam (:class:`hazard.pipeline.spots.BeamStage`: beam,
    cells, spots before any history) and the notes it leaves (the scene's first, then the
    trace's and the beam tail's)."""

    traced: BeamStage
    notes: tuple[str, ...]


@dataclass(frozen=True)
class CrossingsResult:
    """Stage ``crossings``: the scene with the observer points added where a beam crosses
    a line between its points (the input scene itself when skipped)."""

    scene: Scene


@dataclass(frozen=True)
class DirectResult:
    """Stage ``direct``: the laser's own beam at the observers
    (:class:`hazard.pipeline.direct.DirectBeam`, irradiances [W/m^2]); None when skipped."""

    direct_beam: DirectBeam | None


@dataclass(frozen=True)
class SpillResult:
    """Stage ``spill``: report.json ``beam.spill`` (the beam past the targets: powers [W],
    where it is stopped, its NOHD [m]; :class:`hazard.pipeline.spill.SpillSummary`, the schema's
    ``SpillBlock`` generated from it)."""

    summary: SpillSummary


@dataclass(frozen=True)
class SdzResult:
    """Stage ``sdz``: report.json ``sdz`` without ``mirror_beams`` (the laser surface
    danger zone of the direct beam: area [m^2], reach [m], containment;
    :class:`hazard.pipeline.sdz.DangerZone`, the schema's ``SdzBlock`` generated from it)."""

    zone: DangerZone


@dataclass(frozen=True)
class HistoryResult:
    """Stage ``history``: the analysis times [s], the dynamic targets' states over them
    (target index -> states), their melting (target index -> melt history) and the trace
    with the spots in their states (slumps given; the beam stage's own trace when no spot
    is dynamic; a new object otherwise, the beam stage's result is not changed)."""

    times_s: np.ndarray
    states: dict[int, np.ndarray]
    melts: dict[int, Melt]
    traced: BeamStage


@dataclass(frozen=True)
class MapResult:
    """Stages ``specular``, ``line_of_sight``, ``static`` | ``dynamic``, ``exposure``: the
    per-observer irradiances [W/m^2], exposures [J/m^2] and times [s]
    (:class:`hazard.pipeline.results.ObserverResults`, point-source MPE) and the map's notes."""

    observers: ObserverResults
    notes: tuple[str, ...]


@dataclass(frozen=True)
class KeepoutResult:
    """Stage ``keepout``: a :class:`hazard.pipeline.results.TargetResult` per target (lit or not;
    lobes, NOHDs [m], melt) and the near-field lobe notes."""

    targets: tuple[TargetResult, ...]
    notes: tuple[str, ...]


@dataclass(frozen=True)
class MirrorBeamsResult:
    """Stage ``mirror_beams``: report.json ``sdz.mirror_beams`` (each mirror beam's reach
    [m] and containment, :class:`hazard.pipeline.sdz.MirrorBeam`); None when skipped (the key is then absent)."""

    beams: tuple[MirrorBeam, ...] | None


@dataclass(frozen=True)
class FootprintResult:
    """Stage ``footprint``: hazardous ground with the initial states held (``static``) and
    over the history (``dynamic``), :class:`hazard.physics.keepout.Footprint`; None when skipped."""

    static: Footprint | None = None
    dynamic: Footprint | None = None


@dataclass(frozen=True)
class MotionStageResult:
    """Stage ``motion``: tracks and fixed observers over time
    (:class:`hazard.pipeline.motion_stage.MotionResult`); None when nothing moves."""

    motion: MotionResult | None


@dataclass(frozen=True)
class AirspaceResult:
    """Stage ``airspace``: report.json ``visual_interference`` (FAA levels' distances [m],
    :class:`hazard.physics.visual.VisualInterference`) and ``airspace`` (the flight zones' checks,
    :class:`hazard.pipeline.airspace.AirspaceCheck`; None without ``[airspace]`` zones)."""

    visual_interference: VisualInterference
    zones: AirspaceCheck | None = None
