"""What the motion and airspace stages put in the outputs: report.json's ``motion``,
``tracks``, ``visual_interference`` and ``airspace``; one ``track_<name>.csv`` per
moving observer (irradiance and exposure against time); the tracks' rows of
observers.csv and the fixed observers' ``motion_*`` columns.

Positions are world coordinates (the scene file's), as everywhere in the report; with a
``[site]``, the track tables also give latitude, longitude and height of the true
positions (the refraction rise taken off, as observers.csv does)."""

from __future__ import annotations

import re
from dataclasses import dataclass, replace
import numpy as np

from hazard.outputs.csv_text import GEO_COLUMNS, column_text, observer_geodetic
from hazard.pipeline.motion_results import PathSummary, fields_dict
from scenes.motion import AimTrackDescription

__all__ = ["TrackEntry", "MotionSection", "track_entry", "motion_section", "motion_sections", "track_files", "track_file_name",
           "track_columns", "motion_columns", "TRACK_CSV_COLUMNS"]

TRACK_CSV_COLUMNS = ["time_s", "x_m", "y_m", "z_m", "lased", "direct_irradiance_w_m2", "reflected_irradiance_w_m2",
                     "irradiance_w_m2", "cumulative_exposure_j_m2"]


def track_file_name(name: str) -> str:
    """``track_<name>.csv`` with the name's characters outside [A-Za-z0-9._-] as ``_``."""
    return f"track_{re.sub(r'[^A-Za-z0-9._-]', '_', name)}.csv"


def _world(result, p) -> np.ndarray:
    return np.asarray(p, float) + np.asarray(result.scene.offset_m, float)


def visual_levels(result, peak_w_m2: float) -> tuple[float | None, list]:
    """The effective peak VCF x E [W/m^2] of a path and the FAA levels it reaches
    (visible lasers; None and [] otherwise)."""
    vi = result.visual_interference  # hazard.physics.visual.VisualInterference
    if vi is None or not vi.applies:
        return None, []
    eff = vi.vcf * float(peak_w_m2)
    return eff, [k for k in ("szed", "czed", "lfed") if eff >= vi.levels_w_m2[k]]


@dataclass(frozen=True)
class TrackEntry:
    """One path as report.json writes it (``tracks[]``, ``motion.fixed_observers[]``): its
    :class:`~hazard.pipeline.motion_results.PathSummary` (``worst_point_m`` in world
    coordinates [m]), written flat, then the keys below.

    Attributes
    ----------
    summary : PathSummary
        The path over time (its keys first, in their order).
    peak_effective_irradiance_w_m2 : float or None
        VCF x the peak irradiance [W/m^2] (visible lasers; None otherwise).
    visual_levels_reached : tuple of str
        The FAA levels (``szed``, ``czed``, ``lfed``) the effective peak reaches.
    csv : str or None
        Its ``track_<name>.csv`` (None for a fixed observer: no table of its own).
    group : str
        The name of its ``[[observers]]`` group.
    """

    summary: PathSummary
    peak_effective_irradiance_w_m2: float | None
    visual_levels_reached: tuple[str, ...]
    csv: str | None
    group: str

    def to_dict(self) -> dict:
        return {**self.summary.to_dict(), **{k: v for k, v in fields_dict(self).items() if k != "summary"}}


METHOD = ("see hazard.pipeline.motion: the direct beam and the reflections at each sample time; the step refined "
          "within 5 1/e radii of each beam axis (samples_per_width per radius) and where the irradiance changes by "
          "more than 25 % between samples; the verdict over every window length up to the exposure duration")


@dataclass(frozen=True)
class MotionSection:
    """report.json's ``motion``: how the paths were evaluated over time, the fixed observers
    so evaluated, and what was left out (:func:`motion_sections`).

    Attributes
    ----------
    time_span_s : tuple of 2 float
        The analysed span [s].
    beam_states : int
        Number of beam states traced.
    beam_state_step : str
        How their times were chosen, in words.
    aim_track : AimTrackDescription or None
        The aim schedule (``[laser] aim_track``); None: the aim holds.
    windows_s : tuple of (start, end) [s] or None
        The merged lasing windows; None: always on.
    target_tracks : tuple of str
        The moving targets' names.
    time_step_s : float
        The base time step [s] (``[motion] time_step_s``).
    adaptive : bool
        Whether the steps are refined (``[motion] adaptive``).
    samples_per_width : int
        Samples per 1/e beam radius where a path crosses a beam (``[motion] samples_per_width``).
    fixed_observers : tuple of TrackEntry
        The fixed observers evaluated over time (the beam or a target moves).
    notes : tuple of str
        What the evaluation left out or assumed.
    seconds : float
        The stage's run time [s].
    method : str
        The method, in words.
    """

    time_span_s: tuple[float, float]
    beam_states: int
    beam_state_step: str
    aim_track: AimTrackDescription | None
    windows_s: tuple[tuple[float, float], ...] | None
    target_tracks: tuple[str, ...]
    time_step_s: float
    adaptive: bool
    samples_per_width: int
    fixed_observers: tuple[TrackEntry, ...]
    notes: tuple[str, ...]
    seconds: float
    method: str = METHOD

    def to_dict(self) -> dict:
        return fields_dict(self)


def track_entry(result, p, csv: str | None) -> TrackEntry:
    """Path ``p`` (:class:`hazard.pipeline.motion.SummarisedPath`) as report.json writes it."""
    s = p.summary
    x, y, z = (float(c) for c in _world(result, s.worst_point_m))
    eff, reached = visual_levels(result, s.peak_irradiance_w_m2)
    return TrackEntry(replace(s, worst_point_m=(x, y, z)), eff, tuple(reached), csv, result.scene.spec.observers[p.group].name)


def motion_section(result) -> MotionSection | None:
    """report.json's ``motion`` of ``result`` (None: nothing moves)."""
    m = result.motion
    if m is None:
        return None
    mo = m.run.motion  # scenes.motion.Motion
    windows = None if mo.windows.intervals is None else tuple((float(a), float(b)) for a, b in mo.windows.intervals)
    return MotionSection(
        time_span_s=m.span_s, beam_states=m.beam_states, beam_state_step=m.key_step_text,
        aim_track=None if mo.aim is None else mo.aim.describe(), windows_s=windows,
        target_tracks=tuple(tt.name for tt in mo.target_tracks), time_step_s=mo.spec.time_step_s, adaptive=mo.spec.adaptive,
        samples_per_width=mo.spec.samples_per_width, fixed_observers=tuple(track_entry(result, p, None) for p in m.fixed()),
        notes=m.notes, seconds=m.seconds)


def motion_sections(result) -> dict:
    """The report sections of the motion and airspace stages (absent stages: None, said)."""
    vi = result.visual_interference
    motion = motion_section(result)
    tracks = [] if result.motion is None else [track_entry(result, p, track_file_name(p.name)) for p in result.motion.tracks()]
    return {"visual_interference": None if vi is None else vi.to_dict(), "airspace": None if result.airspace is None else result.airspace.to_dict(),
            "motion": None if motion is None else motion.to_dict(), "tracks": [t.to_dict() for t in tracks]}


def _track_text(result, p) -> str:
    """One track's table, each column formatted as observers.csv's (:func:`hazard.outputs.csv_text.column_text`)."""
    pos = _world(result, p.positions_m)
    cols = [p.times_s, pos[:, 0], pos[:, 1], pos[:, 2]]
    names = TRACK_CSV_COLUMNS[:4]
    if getattr(result.scene, "site", None) is not None:
        geo = observer_geodetic(result, pos)
        cols += [geo[:, 0], geo[:, 1], geo[:, 2]]
        names = names + GEO_COLUMNS
    cols += [p.lased, p.direct_w_m2, p.reflected_w_m2, p.irradiance_w_m2, p.cumulative_j_m2]
    text = [column_text(c) for c in cols]
    lines = [",".join(names + TRACK_CSV_COLUMNS[4:])] + [",".join(r) for r in zip(*text)]
    return "\r\n".join(lines) + "\r\n"


def track_files(result) -> dict:
    """``track_<name>.csv`` -> bytes for every moving observer."""
    if result.motion is None:
        return {}
    return {track_file_name(p.name): _track_text(result, p).encode() for p in result.motion.tracks()}


def track_columns(result, mpe_w_m2: float) -> dict:
    """The tracks as rows of the observer table: the same keys as
    :func:`hazard.outputs.report.observer_columns`, at each track's worst point."""
    tracks = [] if result.motion is None else result.motion.tracks()
    s = [p.summary for p in tracks]
    n = len(s)

    def col(key):  # a summary's value, NaN where None
        return np.array([np.nan if getattr(x, key) is None else getattr(x, key) for x in s], float)

    mpe_h = np.array([x.worst_window.mpe_radiant_exposure_j_m2 for x in s], float)
    return {
        "labels": [p.name for p in tracks],
        "position_m": _world(result, np.array([x.worst_point_m for x in s], float).reshape(n, 3)),
        "peak_irradiance_w_m2": col("peak_irradiance_w_m2"), "direct_irradiance_w_m2": col("peak_direct_w_m2"),
        "direct_at_aim_irradiance_w_m2": col("peak_direct_w_m2"), "reflected_irradiance_w_m2": col("peak_reflected_w_m2"),
        "peak_time_s": col("peak_time_s"), "static_irradiance_w_m2": np.zeros(n),
        "radiant_exposure_j_m2": col("radiant_exposure_j_m2"), "static_radiant_exposure_j_m2": np.zeros(n),
        "angular_subtense_rad": np.full(n, np.nan), "c_e": np.ones(n), "mpe_w_m2": np.full(n, float(mpe_w_m2)),
        "mpe_radiant_exposure_j_m2": mpe_h, "hazard_ratio": col("exposure_ratio"),  # a moving eye: the verdict's ratio
        "exposure_ratio": col("exposure_ratio"), "hazardous": np.array([x.hazardous for x in s], bool),
        "hazardous_static": np.zeros(n, bool), "first_exceedance_s": col("first_exceedance_s"),
        "line_of_sight": np.ones(n, bool), "far_field": np.zeros(n, bool),
        # not evaluated along a path (a point source at the aperture, and its diameter): NaN, an empty cell
        "direct_point_irradiance_w_m2": np.full(n, np.nan), "aperture_diameter_m": np.full(n, np.nan),
    }


MOTION_COLUMNS = ["motion_peak_irradiance_w_m2", "motion_radiant_exposure_j_m2", "motion_first_exceedance_s"]


def motion_columns(result, m_fixed: int, tracks: dict) -> dict:
    """``motion_*`` columns for the fixed observers (NaN where not evaluated over time)
    and the tracks (their own values); empty when nothing moves."""
    if result.motion is None:
        return {}
    fixed = result.motion.fixed()
    out = {k: np.full(m_fixed, np.nan) for k in MOTION_COLUMNS}
    if len(fixed) == m_fixed:
        for k, key in zip(MOTION_COLUMNS, ("peak_irradiance_w_m2", "radiant_exposure_j_m2", "first_exceedance_s")):
            out[k] = np.array([np.nan if getattr(p.summary, key) is None else getattr(p.summary, key) for p in fixed], float)
    own = {"motion_peak_irradiance_w_m2": tracks["peak_irradiance_w_m2"], "motion_radiant_exposure_j_m2": tracks["radiant_exposure_j_m2"],
           "motion_first_exceedance_s": tracks["first_exceedance_s"]}
    return {k: np.concatenate([out[k], own[k]]) for k in MOTION_COLUMNS}
