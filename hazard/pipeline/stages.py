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
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:  # annotations only (no import at run time: the stages' modules import this one)
    from ..keepout import Footprint
    from ..results import ObserverResults, TargetResult
    from .direct import DirectBeam
    from .limits import ExposureLimits
    from .motion_stage import MotionResult
    from .spots import BeamStage

__all__ = ["StageDef", "StagePlanError", "stage", "derive_plan", "run_stages", "REGISTRY", "INPUTS",
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


def run_stages(stages: Mapping[str, StageDef], order: Iterable[str], inputs: Mapping[str, Any], log) -> Mapping[str, Any]:
    """Run the stages in ``order``, each with what it declared; stage name -> result.

    Raises
    ------
    TypeError
        A stage returned something other than its declared result type.
    """
    values = dict(inputs)
    results: dict[str, Any] = {}
    for name in order:
        d = stages[name]
        out = d.run(log, **{n: values[n] for n in d.needs})
        if not isinstance(out, d.result):
            raise TypeError(f"stage {name!r} returned {type(out).__name__}, expected {d.result.__name__}")
        values[name] = results[name] = out
    return MappingProxyType(results)


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

    ray_scene: Any
    tracer: Any


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

    scene: Any


@dataclass(frozen=True)
class DirectResult:
    """Stage ``direct``: the laser's own beam at the observers
    (:class:`hazard.pipeline.direct.DirectBeam`, irradiances [W/m^2]); None when skipped."""

    direct_beam: DirectBeam | None


@dataclass(frozen=True)
class SpillResult:
    """Stage ``spill``: report.json ``spill`` (the beam past the targets: powers [W],
    where it is stopped, its NOHD [m])."""

    summary: dict


@dataclass(frozen=True)
class SdzResult:
    """Stage ``sdz``: report.json ``sdz`` without ``mirror_beams`` (the laser surface
    danger zone of the direct beam: area [m^2], reach [m], containment)."""

    zone: dict


@dataclass(frozen=True)
class HistoryResult:
    """Stage ``history``: the analysis times [s], the dynamic targets' states over them
    (target index -> states), their melting (target index -> melt history) and the trace
    with the spots in their states (slumps given; the beam stage's own trace when no spot
    is dynamic; a new object otherwise, the beam stage's result is not changed)."""

    times_s: np.ndarray
    states: dict
    melts: dict
    traced: BeamStage


@dataclass(frozen=True)
class MapResult:
    """Stages ``specular``, ``line_of_sight``, ``static`` | ``dynamic``, ``exposure``: the
    per-observer irradiances [W/m^2], exposures [J/m^2] and times [s]
    (:class:`hazard.results.ObserverResults`, point-source MPE) and the map's notes."""

    observers: ObserverResults
    notes: tuple[str, ...]


@dataclass(frozen=True)
class KeepoutResult:
    """Stage ``keepout``: a :class:`hazard.results.TargetResult` per target (lit or not;
    lobes, NOHDs [m], melt) and the near-field lobe notes."""

    targets: tuple[TargetResult, ...]
    notes: tuple[str, ...]


@dataclass(frozen=True)
class MirrorBeamsResult:
    """Stage ``mirror_beams``: report.json ``sdz.mirror_beams`` (each mirror beam's reach
    [m] and containment); None when skipped (the key is then absent)."""

    beams: list | None


@dataclass(frozen=True)
class FootprintResult:
    """Stage ``footprint``: hazardous ground with the initial states held (``static``) and
    over the history (``dynamic``), :class:`hazard.keepout.Footprint`; None when skipped."""

    static: Footprint | None = None
    dynamic: Footprint | None = None


@dataclass(frozen=True)
class MotionStageResult:
    """Stage ``motion``: tracks and fixed observers over time
    (:class:`hazard.pipeline.motion_stage.MotionResult`); None when nothing moves."""

    motion: MotionResult | None


@dataclass(frozen=True)
class AirspaceResult:
    """Stage ``airspace``: report.json ``visual_interference`` (FAA levels' distances [m])
    and ``airspace`` (the flight zones' checks; empty without ``[airspace]`` zones)."""

    visual_interference: dict
    zones: dict = field(default_factory=dict)
