"""What the motion and airspace stages put in the outputs: report.json's ``motion``,
``tracks``, ``visual_interference`` and ``airspace``; one ``track_<name>.csv`` per
moving observer (irradiance and exposure against time); the tracks' rows of
observers.csv and the fixed observers' ``motion_*`` columns.

Positions are world coordinates (the scene file's), as everywhere in the report; with a
``[site]``, the track tables also give latitude, longitude and height of the true
positions (the refraction rise taken off, as observers.csv does)."""

from __future__ import annotations

import re

import numpy as np

from hazard.outputs.csv_text import GEO_COLUMNS, column_text, observer_geodetic

__all__ = ["motion_sections", "track_files", "track_file_name", "track_columns", "motion_columns", "TRACK_CSV_COLUMNS"]

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


def _track_dict(result, p) -> dict:
    s = dict(p.summary)
    s["peak_effective_irradiance_w_m2"], s["visual_levels_reached"] = visual_levels(result, s["peak_irradiance_w_m2"])
    s["worst_point_m"] = _world(result, s["worst_point_m"]).tolist()
    s["csv"] = track_file_name(p.name)
    s["group"] = result.scene.spec.observers[p.group].name
    return s


def motion_sections(result) -> dict:
    """The report sections of the motion and airspace stages (absent stages: None, said)."""
    m = result.motion
    vi = result.visual_interference
    out = {"visual_interference": None if vi is None else vi.to_dict(), "airspace": None if result.airspace is None else result.airspace.to_dict()}
    if m is None:
        out.update(motion=None, tracks=[])
        return out
    run = m.run
    out["motion"] = {
        "time_span_s": list(m.span_s), "beam_states": m.beam_states, "beam_state_step": m.key_step_text,
        "aim_track": None if run.motion.aim is None else run.motion.aim.describe(),
        "windows_s": None if run.motion.windows.intervals is None else run.motion.windows.intervals.tolist(),
        "target_tracks": [tt.name for tt in run.motion.target_tracks],
        "time_step_s": run.motion.spec.time_step_s, "adaptive": run.motion.spec.adaptive,
        "samples_per_width": run.motion.spec.samples_per_width,
        "fixed_observers": [_track_dict(result, p) | {"csv": None} for p in m.fixed()],
        "notes": list(m.notes), "seconds": m.seconds,
        "method": "see hazard.pipeline.motion: the direct beam and the reflections at each sample time; the step refined "
                  "within 5 1/e radii of each beam axis (samples_per_width per radius) and where the irradiance changes by "
                  "more than 25 % between samples; the verdict over every window length up to the exposure duration",
    }
    out["tracks"] = [_track_dict(result, p) for p in m.tracks()]
    return out


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

    def col(key, default=np.nan):
        return np.array([x.get(key, default) if x.get(key) is not None else default for x in s], float)

    mpe_h = np.array([x["worst_window"]["mpe_radiant_exposure_j_m2"] for x in s], float)
    return {
        "labels": [p.name for p in tracks],
        "position_m": _world(result, np.array([x["worst_point_m"] for x in s], float).reshape(n, 3)),
        "peak_irradiance_w_m2": col("peak_irradiance_w_m2"), "direct_irradiance_w_m2": col("peak_direct_w_m2"),
        "direct_at_aim_irradiance_w_m2": col("peak_direct_w_m2"), "reflected_irradiance_w_m2": col("peak_reflected_w_m2"),
        "peak_time_s": col("peak_time_s"), "static_irradiance_w_m2": np.zeros(n),
        "radiant_exposure_j_m2": col("radiant_exposure_j_m2"), "static_radiant_exposure_j_m2": np.zeros(n),
        "angular_subtense_rad": np.full(n, np.nan), "c_e": np.ones(n), "mpe_w_m2": np.full(n, float(mpe_w_m2)),
        "mpe_radiant_exposure_j_m2": mpe_h, "hazard_ratio": col("exposure_ratio"),  # a moving eye: the verdict's ratio
        "exposure_ratio": col("exposure_ratio"), "hazardous": np.array([x["hazardous"] for x in s], bool),
        "hazardous_static": np.zeros(n, bool), "first_exceedance_s": col("first_exceedance_s"),
        "line_of_sight": np.ones(n, bool), "far_field": np.zeros(n, bool),
        "direct_point_irradiance_w_m2": col("peak_direct_point_w_m2"), "aperture_diameter_m": col("aperture_diameter_m"),
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
            out[k] = np.array([np.nan if p.summary[key] is None else p.summary[key] for p in fixed], float)
    own = {"motion_peak_irradiance_w_m2": tracks["peak_irradiance_w_m2"], "motion_radiant_exposure_j_m2": tracks["radiant_exposure_j_m2"],
           "motion_first_exceedance_s": tracks["first_exceedance_s"]}
    return {k: np.concatenate([out[k], own[k]]) for k in MOTION_COLUMNS}
