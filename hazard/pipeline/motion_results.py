"""What the ``motion`` stage says of one path over time (report.json ``tracks[]`` and
``motion.fixed_observers[]``): frozen result types whose fields carry their units, from
which the report's schema is generated (:mod:`hazard.outputs.report_schema`).

:func:`hazard.pipeline.motion_stage.path_summary` makes them; the outputs read their
attributes (:mod:`hazard.outputs.motion_outputs` adds the report's own keys)."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any, ClassVar

__all__ = ["WorstWindow", "PathUv24h", "PathSummary", "fields_dict"]


def _plain(value: Any) -> Any:
    """A field's value as report.json writes it: a nested result as its dict, a tuple as a list."""
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return value.to_dict()  # type: ignore[attr-defined]
    if isinstance(value, (tuple, list)):
        return [_plain(v) for v in value]
    return value


def fields_dict(obj: Any) -> dict:
    """The fields of a frozen result in their order (a new dict, its lists new), leaving out
    the keys its class lists in ``ABSENT_WHEN_NONE`` when None."""
    absent = getattr(obj, "ABSENT_WHEN_NONE", ())
    return {f.name: _plain(getattr(obj, f.name)) for f in dataclasses.fields(obj)
            if not (f.name in absent and getattr(obj, f.name) is None)}


@dataclass(frozen=True)
class WorstWindow:
    """The exposure window of a path with the largest exposure ratio (report.json ``worst_window``).

    Attributes
    ----------
    duration_s : float
        Its length [s] (one of the log-spaced lengths up to the exposure duration).
    exposure_j_m2 : float
        The largest radiant exposure [J/m^2] over a window of that length.
    mpe_radiant_exposure_j_m2 : float
        The MPE for that length as radiant exposure [J/m^2].
    ratio : float
        ``exposure_j_m2`` x (1 + the integral's relative error estimate) / the MPE (unitless).
    """

    duration_s: float
    exposure_j_m2: float
    mpe_radiant_exposure_j_m2: float
    ratio: float

    def to_dict(self) -> dict:
        return fields_dict(self)


@dataclass(frozen=True)
class PathUv24h:
    """UV (180-400 nm): the largest dose of a path within any 24 h against the day's limit
    for the time exposed in that 24 h (:func:`hazard.pipeline.motion_stage._uv_24h`; report.json ``uv_24h``).

    Attributes
    ----------
    dose_j_m2 : float
        The dose [J/m^2] of the 24 h with the largest ratio.
    exposed_s : float
        The time [s] exposed within it (never more than the true time: the limit is never raised).
    limit_j_m2 : float
        The day's limit [J/m^2] for that exposed time.
    ratio : float
        dose x (1 + the integral's relative error estimate) / limit (unitless).
    window_end_s : float
        The end [s] of that 24 h.
    first_exceedance_s : float or None
        The first end [s] of a 24 h over its limit; None: never.
    label : str
        The rule and its standing ([M]: unverified).
    """

    dose_j_m2: float
    exposed_s: float
    limit_j_m2: float
    ratio: float
    window_end_s: float
    first_exceedance_s: float | None
    label: str

    def to_dict(self) -> dict:
        return fields_dict(self)


@dataclass(frozen=True)
class PathSummary:
    """One path over time (a moving observer's track, or a fixed observer under a moving
    beam or target): :func:`hazard.pipeline.motion_stage.path_summary`.

    Attributes
    ----------
    name, kind : str
        The path's name; ``"track"`` (a moving observer) or ``"fixed"``.
    peak_irradiance_w_m2, peak_time_s : float
        The largest irradiance [W/m^2] of the samples and its time [s].
    worst_point_m : tuple of 3 float
        Where the peak is [m] (the analysis frame here; report.json writes world coordinates).
    peak_direct_w_m2, peak_reflected_w_m2 : float
        The direct beam's and the reflections' parts [W/m^2] of the peak.
    radiant_exposure_j_m2 : float
        The largest radiant exposure [J/m^2] over windows of the exposure duration.
    path_exposure_j_m2 : float
        The whole path's radiant exposure [J/m^2].
    exposure_error_estimate_j_m2 : float
        The trapezoid integral's error estimate [J/m^2] (Richardson, over every second sample).
    worst_window : WorstWindow
        The window length with the largest exposure ratio.
    exposure_ratio : float
        The verdict's ratio (unitless): the worst window's, or the UV day's when larger.
    hazardous : bool
        At or over the MPE by a window, the per-pulse rule on the peak or the UV day's limit.
    uv_24h : PathUv24h or None
        The UV day's summed dose against its limit; None outside 180-400 nm (written as null).
    first_exceedance_s : float or None
        The first time [s] any rule is broken; None: never.
    time_span_s : tuple of 2 float
        The first and last sample times [s].
    samples : int
        Number of samples.
    base_step_s, min_step_s : float
        The base time step [s] and the smallest step taken [s].
    adaptive : bool
        Whether the steps were refined.
    lased_s : float
        The time [s] the laser was on during the path.
    pointing_bias_rad : tuple of 2 float or None
        A track's worst constant pointing bias [rad] (right, up) within the pointing buffer;
        None (the key absent) without a buffer, and for a fixed observer.
    pointing_buffer_rad : float or None
        The pointing buffer [rad] the bias was searched within; None as ``pointing_bias_rad``.
    """

    name: str
    kind: str
    peak_irradiance_w_m2: float
    peak_time_s: float
    worst_point_m: tuple[float, float, float]
    peak_direct_w_m2: float
    peak_reflected_w_m2: float
    radiant_exposure_j_m2: float
    path_exposure_j_m2: float
    exposure_error_estimate_j_m2: float
    worst_window: WorstWindow
    exposure_ratio: float
    hazardous: bool
    uv_24h: PathUv24h | None
    first_exceedance_s: float | None
    time_span_s: tuple[float, float]
    samples: int
    base_step_s: float
    min_step_s: float
    adaptive: bool
    lased_s: float
    pointing_bias_rad: tuple[float, float] | None = None
    pointing_buffer_rad: float | None = None

    ABSENT_WHEN_NONE: ClassVar[tuple[str, ...]] = ("pointing_bias_rad", "pointing_buffer_rad")

    def to_dict(self) -> dict:
        return fields_dict(self)
