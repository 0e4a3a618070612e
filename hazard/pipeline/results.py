"""What an analysis produces: stage records, per-target and per-observer results."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from hazard.physics.keepout import Footprint, Lobe
from hazard.physics.specular import MirrorBeamSteps

if TYPE_CHECKING:  # annotations only (no import at run time: no cycle through the pipeline, `import hazard` stays light)
    from scenes.observers import Observers
    from scenes.scene import Scene

    from hazard.physics.beam import BeamGeometry
    from hazard.physics.engine import Spot
    from hazard.physics.mpe import MPEResult, RepetitivePulseResult, UV24hResult
    from hazard.physics.visual import VisualInterference
    from hazard.pipeline.airspace import AirspaceCheck
    from hazard.pipeline.sdz import DangerZone
    from hazard.pipeline.extended_source import ExtendedSourceSummary
    from hazard.pipeline.motion_stage import MotionResult
    from hazard.pipeline.spill import SpillSummary
    from hazard.pipeline.spots import BeamSampling

__all__ = ["Stage", "TargetResult", "ObserverResults", "HazardResult"]


@dataclass
class Stage:
    """One step of an analysis: whether it ran, what it did or why it was skipped, its time [s]."""

    name: str
    ran: bool
    detail: str
    seconds: float = 0.0

    def to_dict(self):
        return {"name": self.name, "ran": self.ran, "detail": self.detail, "seconds": self.seconds}


@dataclass
class TargetResult:
    """Per-target outcome: the spot, the static and dynamic lobes, the specular NOHD."""

    name: str
    spot_power_w: float
    spot_size_m: float
    static_lobe: Lobe | None
    dynamic_lobe: Lobe | None
    specular_nohd_static_m: float | None
    specular_nohd_dynamic_m: float | None
    specular_direction: list[float] | None  # unit vector of the mirror beam (None: no mirror part)
    state_name: str | list[str] | None  # the dynamic material's state(s); None: static
    state_range: list[float] | list[list[float]] | None  # [lo, hi] of the state over the run, one pair per state of two
    spot_power_error_w: float = 0.0  # bound on the spot power's error (already added to it: conservative)
    spot_power_exact: bool = False  # spot power is the exact outline integral
    peak_irradiance_w_m2: float = 0.0  # highest incident irradiance on the lit part (normal to the beam, attenuated)
    mean_irradiance_w_m2: float = 0.0  # spot power over its lit area normal to the beam
    lit_side: str = "front"
    aided: list[dict[str, Any]] = field(default_factory=list)  # NOHDs through each optical aid of the scene (hazard.pipeline.lobes)
    beam_profile_fraction: float = 1.0  # hottest incident irradiance / the beam's on-axis value there (hazard.pipeline.lobes)
    melt: dict[str, float | None] | None = None  # melt onset and full-melt times [s] where the history knows them (hazard.pipeline.history)
    slump: dict[str, Any] | None = None  # the slump the dynamic lobe covers, with its sampling (hazard.pipeline.lobes)
    specular_steps: MirrorBeamSteps | None = None  # the numbers behind specular_nohd_static_m (review page)

    def to_dict(self):
        def lobe(lb):  # a target without a spot reflects nothing: an empty lobe, said in lit_side
            return {"max_nohd_m": 0.0, "max_direction": None, "volume_m3": 0.0, "volume_error_m3": 0.0, "cells": 0,
                    "evaluations": 0, "near_field": None} if lb is None else lb.summary()

        return {
            "name": self.name,
            "spot_power_w": self.spot_power_w,
            "spot_power_error_w": self.spot_power_error_w,
            "spot_power_exact": self.spot_power_exact,
            "peak_irradiance_w_m2": self.peak_irradiance_w_m2,
            "mean_irradiance_w_m2": self.mean_irradiance_w_m2,
            "lit_side": self.lit_side,
            "spot_size_m": self.spot_size_m,
            "nohd_static_m": 0.0 if self.static_lobe is None else self.static_lobe.max_range_m,  # no spot: nothing reflected
            "nohd_dynamic_m": 0.0 if self.dynamic_lobe is None else self.dynamic_lobe.max_range_m,
            "keepout_static": lobe(self.static_lobe),
            "keepout_dynamic": lobe(self.dynamic_lobe),
            "specular_nohd_static_m": self.specular_nohd_static_m,
            "specular_nohd_dynamic_m": self.specular_nohd_dynamic_m,
            "specular_direction": self.specular_direction,
            "state_name": self.state_name,
            "state_range": self.state_range,
            "melt": self.melt,
            "slump": self.slump,
            "aided": list(self.aided),
            "specular_steps": None if self.specular_steps is None else self.specular_steps.to_dict(),
        }


@dataclass
class ObserverResults:
    """Arrays over the M observer points (file coordinates)."""

    observers: Observers  # scenes.Observers (names are built on demand: 1e6 strings cost 0.5 s)
    offset_m: np.ndarray  # world = local + offset_m (positions are generated on demand: scenes.observers)
    static_irradiance_w_m2: np.ndarray
    peak_irradiance_w_m2: np.ndarray
    peak_time_s: np.ndarray
    radiant_exposure_j_m2: np.ndarray
    static_radiant_exposure_j_m2: np.ndarray
    first_exceedance_s: np.ndarray
    line_of_sight: np.ndarray
    far_field: np.ndarray
    irradiance_w_m2: np.ndarray | None  # (M, T) total irradiance history (None if not kept)
    # extended sources (hazard.pipeline.extended_source, set by analyze()): the spot's angular
    # subtense [rad], C_E and the MPE per observer (C_E = 1 and the scalar MPE unless
    # [exposure] extended_source = true); None on results built without analyze()
    angular_subtense_rad: np.ndarray | None = None
    c_e: np.ndarray | None = None
    mpe_w_m2: np.ndarray | None = None
    mpe_radiant_exposure_j_m2: np.ndarray | None = None
    # highest irradiance of the mirror (delta) lobes alone [W/m^2] per observer: > 0 where
    # an observer sees the beam's image (a point source: C_E = 1); None if not computed
    specular_irradiance_w_m2: np.ndarray | None = None
    # the laser's own beam [W/m^2] (constant in time) and the peak of the reflected part
    # (peak_irradiance_w_m2 = direct + reflected peak); None if not computed
    direct_irradiance_w_m2: np.ndarray | None = None
    reflected_irradiance_w_m2: np.ndarray | None = None
    # the direct beam at the nominal aim [W/m^2]; direct_irradiance_w_m2 is the worst over
    # the pointing error / sector when the scene gives one (else the two are equal)
    direct_at_aim_irradiance_w_m2: np.ndarray | None = None
    # the direct beam's point value at the eye [W/m^2] (no aperture, no aid; the worst over
    # the pointing error when given) and the aperture its verdict value is collected over
    # (diameter [m]: D_f, or an aid's min(D_o, 7 mm M); hazard.physics.aperture); None if not computed
    direct_point_irradiance_w_m2: np.ndarray | None = None
    aperture_diameter_m: np.ndarray | None = None

    def __len__(self):
        return len(self.observers)

    @property
    def position_m(self) -> np.ndarray:
        """Every observer's position (M, 3), world coordinates [m] (made on first use)."""
        if not hasattr(self, "_position_m"):
            self._position_m = self.observers.positions_m + self.offset_m if len(self.observers) else np.zeros((0, 3))
        return self._position_m

    def position_at(self, rows) -> np.ndarray:
        """The positions (n, 3) [m], world, of the rows ``rows`` only (int array or slice):
        :attr:`position_m`'s values without making the whole table (240 MB at 1e7 points)."""
        if hasattr(self, "_position_m"):
            return self._position_m[rows]
        if isinstance(rows, slice):
            a0, a1, step = rows.indices(len(self.observers))
            return (self.observers.block(a0, a1) + self.offset_m)[::step]
        return self.observers.take(rows) + self.offset_m

    @property
    def labels(self) -> ObserverLabels:
        """The observers' names by row (made when read: a 1e7-point grid's as one list are 0.7 GB)."""
        return ObserverLabels(self.observers)


class ObserverLabels(Sequence):
    """Observer names by row (:meth:`scenes.observers.Observers.labels_at`): an int gives
    one name, a slice a list; equal to a list of the same names."""

    def __init__(self, observers):
        self._obs = observers

    def __len__(self):
        return len(self._obs)

    @property
    def observers(self):
        """The observer table the names are made from (its groups and indices)."""
        return self._obs

    def __getitem__(self, k):
        if isinstance(k, slice):
            return self._obs.labels_at(np.arange(len(self))[k])
        n = len(self)
        if not -n <= k < n:
            raise IndexError(f"observer row {k} of {n}")
        return self._obs.labels_at([k % n])[0]

    def take(self, rows) -> list:
        """The names of the rows ``rows`` (int array, any order), made together."""
        return self._obs.labels_at(rows)

    def __iter__(self):
        for a0 in range(0, len(self), 65536):
            yield from self._obs.labels_at(np.arange(a0, min(a0 + 65536, len(self))))

    def __eq__(self, other):
        return isinstance(other, (list, tuple, ObserverLabels)) and len(other) == len(self) and list(self) == list(other)


@dataclass
class HazardResult:
    """Everything an analysis produced, with the stages that ran."""

    scene: Scene  # the scene analysed (with the observer points the crossings stage added)
    mpe: MPEResult  # the ocular MPE with its steps (hazard.physics.mpe.ocular_mpe)
    mpe_w_m2: float
    mpe_radiant_exposure_j_m2: float
    pulse: RepetitivePulseResult | None  # the repetitive-pulse rules (hazard.physics.mpe.repetitive_pulse_mpe); None: a CW laser
    attenuation_per_m: float
    times_s: np.ndarray
    stages: list[Stage]  # the stage log: ran or skipped, why, the run time [s]
    targets: list[TargetResult]
    observers: ObserverResults
    spill_w: float
    blocked_w: float
    beam_power_w: float
    footprint_static: Footprint | None = None
    footprint_dynamic: Footprint | None = None
    notes: list[str] = field(default_factory=list)
    spots: list[Spot] = field(default_factory=list)  # the beam's spots (for renders and re-evaluation)
    beam: BeamGeometry | None = None  # the laser's beam (hazard.physics.beam); None only on results built by hand
    states: dict[int, np.ndarray] = field(default_factory=dict)  # target index -> states over times_s ((T,) or (T, k))
    extended_source: ExtendedSourceSummary | None = None  # C_E summary for the report (hazard.pipeline.extended_source); None: not run
    beam_sampling: BeamSampling | None = None  # rays, levels, error bound, exact targets (hazard.pipeline.spots.beam_sampling); None: not traced
    spill: SpillSummary | None = None  # the beam past the targets: where it goes, its NOHD (hazard.pipeline.spill); None: not run
    sdz: DangerZone | None = None  # the laser surface danger zone of the direct beam (hazard.pipeline.sdz), mirror beams merged in
    motion: MotionResult | None = None  # hazard.pipeline.motion_stage.MotionResult: tracks and fixed observers over time (None: nothing moves)
    visual_interference: VisualInterference | None = None  # FAA levels' distances per path (hazard.physics.visual); None: the airspace stage has not run
    airspace: AirspaceCheck | None = None  # the flight zones' checks (hazard.pipeline.airspace); None: no [airspace] zones
    uv_24h: UV24hResult | None = None  # 180-400 nm: the day's summed-dose limit (hazard.physics.mpe.uv_24h_mpe, [M]), else None

    @property
    def motion_hazardous(self) -> np.ndarray | None:
        """Per fixed observer: hazardous over time (a moving beam or target); None when not evaluated."""
        fixed = [] if self.motion is None else self.motion.fixed()
        if not fixed:
            return None
        return np.array([p.summary.hazardous for p in fixed], bool)

    @property
    def observer_mpe_w_m2(self):
        """MPE [W/m^2] per observer (with C_E when applied), else the scalar MPE."""
        per = self.observers.mpe_w_m2
        return self.mpe_w_m2 if per is None else per

    @property
    def hazard_ratio(self) -> np.ndarray:
        return self.observers.peak_irradiance_w_m2 / self.observer_mpe_w_m2

    @property
    def hazardous(self) -> np.ndarray:
        """Per observer: over the MPE in the static analysis, or over time (a moving beam)."""
        h = self.hazard_ratio >= 1.0
        over_time = self.motion_hazardous
        return h if over_time is None or len(over_time) != len(h) else h | over_time

    @property
    def hazardous_static(self) -> np.ndarray:
        return self.observers.static_irradiance_w_m2 / self.observer_mpe_w_m2 >= 1.0

    @property
    def any_hazard(self) -> bool:
        """A hazard anywhere: a hazardous observer, a target's diffuse lobe or mirror beam
        with a NOHD > 0, or the direct beam hazardous past the aperture (its NOHD > 0),
        contained or not (so true for practically every scene). Kept for compatibility
        (report.json ``any_hazard``); :func:`hazard.pipeline.verdict.verdict` separates a hazard
        at the listed observers from hazard zones not contained."""
        def positive(x):
            return x is not None and x > 0

        tracks = [] if self.motion is None else self.motion.tracks()
        zones = () if self.airspace is None else self.airspace.zones
        return bool(np.any(self.hazardous)) or positive(None if self.sdz is None else self.sdz.nohd_m) or any(
            p.summary.hazardous for p in tracks) or any(not z.holds for z in zones) or any(
            (t.static_lobe is not None and t.static_lobe.max_range_m > 0) or (t.dynamic_lobe is not None and t.dynamic_lobe.max_range_m > 0)
            or positive(t.specular_nohd_static_m) or positive(t.specular_nohd_dynamic_m)
            for t in self.targets
        )

    def stage(self, name) -> Stage:
        return next(s for s in self.stages if s.name == name)

    def verdict_changes(self) -> list:
        """Observers whose verdict differs between the static and the dynamic analysis."""
        changed = np.flatnonzero(self.hazardous != self.hazardous_static)
        return self.observers.labels.take(np.asarray(changed, np.int64))
