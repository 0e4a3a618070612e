"""Error against run time for a scene's accuracy knobs (``hazard convergence SCENE``).

For each knob the scene uses - direction-grid resolution and refinement depth of the
keep-out lobe, beam samples, time step of a dynamic analysis, ODE tolerance of a heating
history, and for things that move the base step and the samples per beam radius of
:mod:`hazard.pipeline.motion` - the analysis runs at increasing cost with the other knobs at the scene's
values. The quantities of interest (max NOHD, keep-out volume, peak irradiance over the
observers, all dynamic) are compared with the finest run; the report recommends the
cheapest setting whose errors are all within the tolerance.

Columns of a row: ``knob``, ``value``, each quantity in its unit (``max_nohd_m``,
``keepout_volume_m3``, ``peak_irradiance_w_m2``, ``spot_power_w``, ``max_path_exposure_j_m2``), its relative error
against the finest run (``rel_error_max_nohd``, ... : unitless, ``|q - q_ref| / |q_ref|``;
0 when both are 0 and inf when only the reference is 0) and the run time ``time_s``.

The runs share one :class:`~hazard.pipeline.stages.StageMemo`: a level reuses the stage
results of an earlier run whose inputs it does not change (a keep-out knob's levels reuse
the rays, beam, map; a level equal to the scene's own setting of another knob reuses
everything), with results identical to a fresh run's. ``time_s`` is the wall time of the
level's run in this sweep (stages reused cost nothing); ``ConvergenceReport.reused`` lists
per row the stages it reused.
"""

from __future__ import annotations

import copy
import math
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from brdfmodels.fileio import read_toml

from hazard.pipeline.stages import StageMemo
from hazard.progress import progress_to, terminal_bar

__all__ = ["convergence", "ConvergenceReport", "KNOB_LEVELS", "QUANTITIES", "REL_ERROR_COLUMNS"]

KNOB_LEVELS = {
    "direction_grid_deg": (8.0, 4.0, 2.0, 1.0, 0.5),
    "refine_levels": (0, 1, 2, 3, 5),
    "beam_samples": (16, 64, 256, 1024, 4096),
    "beam_rtol": (1e-2, 1e-3, 1e-4, 1e-5, 1e-6),
    "time_step_fraction": (0.1, 0.05, 0.02, 0.01, 0.005),  # of the analysis window
    "heating_rtol": (1e-3, 1e-5, 1e-7, 1e-9, 1e-11),
    "slump_step_deg": (4.0, 2.0, 1.0, 0.5, 0.25),
    "motion_samples_per_width": (2, 4, 8, 16, 64),  # [motion] samples per 1/e radius crossed
    "motion_time_step_s": (1.0, 0.3, 0.1, 0.03, 0.01),  # [motion] base step
}
QUANTITIES = ("max_nohd_m", "keepout_volume_m3", "peak_irradiance_w_m2", "spot_power_w", "max_path_exposure_j_m2")
# column of each quantity's relative error against the finest run: unitless, so no unit suffix
REL_ERROR_COLUMNS = {"max_nohd_m": "rel_error_max_nohd", "keepout_volume_m3": "rel_error_keepout_volume",
                     "peak_irradiance_w_m2": "rel_error_peak_irradiance", "spot_power_w": "rel_error_spot_power",
                     "max_path_exposure_j_m2": "rel_error_path_exposure"}


def _rel_error(q, ref) -> float:
    """|q - ref| / |ref| (unitless); 0 when both are 0, inf when only ``ref`` is."""
    if ref:
        return abs(q - ref) / abs(ref)
    return 0.0 if q == 0 else math.inf


@dataclass
class ConvergenceReport:
    rows: list  # knob, value, quantities, errors, time_s
    recommended: dict  # knob -> value
    tolerance: float
    reused: list = field(default_factory=list)  # per row: the stages its run reused from an earlier level (StageMemo)

    def table(self, knob=None):
        return [r for r in self.rows if knob is None or r["knob"] == knob]


def _apply(data, knob, value):
    d = copy.deepcopy(data)
    a = d.setdefault("analysis", {})
    if knob in ("direction_grid_deg", "refine_levels", "beam_samples", "beam_rtol", "slump_step_deg"):
        a[knob] = value
    elif knob == "time_step_fraction":
        t_end = a.get("time_end_s", d["exposure"]["duration_s"])
        a["time_step_s"] = t_end * value
    elif knob.startswith("motion_"):
        d.setdefault("motion", {})[knob[len("motion_"):]] = value
    elif knob == "heating_rtol":
        for t in d["targets"]:
            if t.get("history", {}).get("kind") == "heating":
                t["history"]["rtol"] = value
    return d


def _quantities(res):
    tr = [t.to_dict() for t in res.targets]
    return {
        "max_nohd_m": max([t["nohd_dynamic_m"] for t in tr], default=0.0),
        "keepout_volume_m3": sum(t["keepout_dynamic"]["volume_m3"] for t in tr),
        "peak_irradiance_w_m2": float(np.max(res.observers.peak_irradiance_w_m2)) if len(res.observers) else 0.0,
        "spot_power_w": sum(t["spot_power_w"] for t in tr),
        # the largest radiant exposure along a moving observer's path (or a fixed one under a moving beam)
        "max_path_exposure_j_m2": max((p.summary.radiant_exposure_j_m2 for p in res.motion.paths), default=0.0)
        if res.motion is not None else 0.0,
    }


def knobs_used(data) -> list:
    knobs = ["direction_grid_deg", "refine_levels", "beam_samples", "beam_rtol"]
    dynamic = any("history" in t for t in data.get("targets", []))
    if dynamic:
        knobs.append("time_step_fraction")
    if any(t.get("history", {}).get("kind") == "heating" for t in data.get("targets", [])):
        knobs.append("heating_rtol")
    if any(isinstance(t.get("material"), dict) and (t["material"].get("melt_tilt_deg") or t["material"].get("melt_wander_deg"))
           for t in data.get("targets", [])):
        knobs.append("slump_step_deg")
    laser = data.get("laser", {})
    if ("aim_track" in laser or "windows" in laser or any("track" in t for t in data.get("targets", []))
            or any(o.get("kind") == "track" for o in data.get("observers", []))):
        knobs += ["motion_samples_per_width", "motion_time_step_s"]
    return knobs


def convergence(scene_path, *, knobs=None, levels=None, tolerance=0.01, progress=None) -> ConvergenceReport:
    """Run the scene's accuracy knobs at increasing cost; see the module notes.

    Parameters
    ----------
    scene_path : str or Path
        Scene TOML (or a bundled example's name).
    knobs : list of str, optional
        Default: every knob the scene uses.
    levels : dict, optional
        knob -> increasing-cost values (default ``KNOB_LEVELS``); the last is the reference.
    tolerance : float
        Relative error allowed for the recommendation (unitless).
    progress : callable, optional
        Called with ``"knob = value"`` before each run. On a terminal a bar of the runs
        is drawn on stderr as well (:func:`hazard.progress.terminal_bar`).

    Returns
    -------
    ConvergenceReport
        Rows as in the module notes, the recommended value per knob, the tolerance.
    """
    import scenes

    from hazard.pipeline.analysis import analyze

    path = Path(scene_path)
    if not path.exists() and str(scene_path) in scenes.examples():
        path = scenes.example_path(str(scene_path))
    data = read_toml(path)
    used = knobs_used(data)
    knobs = used if knobs is None else list(knobs)
    for k in knobs:
        if k not in KNOB_LEVELS:
            raise ValueError(f"knob {k!r} is unknown: expected some of {sorted(KNOB_LEVELS)}")
        if k not in used:
            raise ValueError(f"knob {k!r}: the scene does not use it (it uses {used})")
    say = progress or (lambda msg: None)
    plan = {knob: (levels or {}).get(knob, KNOB_LEVELS[knob]) for knob in knobs}
    rows, recommended, reused, memo = [], {}, [], StageMemo()
    with terminal_bar(sum(len(v) for v in plan.values()), "convergence runs", unit="run", leave=True) as bar:
        for knob, values in plan.items():
            runs = []
            for v in values:
                say(f"{knob} = {v}")
                bar.set_description(f"convergence: {knob} = {v}")
                scene = scenes.from_data(_apply(data, knob, v), source=str(path), base_dir=path.parent)
                t0, n0 = time.perf_counter(), len(memo.reused)
                with progress_to(None):  # one bar: not the keep-out bars of every run
                    res = analyze(scene, memo=memo)
                runs.append((v, _quantities(res), time.perf_counter() - t0))
                reused.append(tuple(name for name, _ in memo.reused[n0:]))
                bar.update()
            rows += _rows(knob, runs)
            recommended[knob] = _cheapest(rows[-len(runs):], tolerance)
    return ConvergenceReport(rows, recommended, tolerance, reused)


def _rows(knob, runs) -> list:
    """Rows of one knob's runs [(value, quantities, seconds)], errors against the last run."""
    ref = runs[-1][1]
    return [{"knob": knob, "value": v, **q, **{REL_ERROR_COLUMNS[k]: _rel_error(q[k], ref[k]) for k in QUANTITIES}, "time_s": secs}
            for v, q, secs in runs]


def _cheapest(rows, tolerance):
    """The first (cheapest) value whose relative errors are all within ``tolerance``, short
    of the reference (the last row); the reference when none is."""
    for r in rows[:-1]:
        if all(r[REL_ERROR_COLUMNS[k]] <= tolerance for k in QUANTITIES):
            return r["value"]
    return rows[-1]["value"]


def plot(report: ConvergenceReport, path) -> Path | None:
    """Log-log plot of error vs run time per knob (matplotlib; None if it is missing)."""
    try:
        from hazard.canvas import subplots

        fig, ax = subplots(figsize=(7, 4.5))  # its own Agg canvas: no backend switched, nothing to close
    except ImportError:
        return None
    for knob in sorted({r["knob"] for r in report.rows}):
        rs = report.table(knob)[:-1]  # the reference has zero error
        err = [max(r[REL_ERROR_COLUMNS[q]] for q in QUANTITIES) for r in rs]
        ax.loglog([r["time_s"] for r in rs], np.maximum(err, 1e-16), "o-", label=knob)
    ax.axhline(report.tolerance, ls=":", c="k", label=f"tolerance {report.tolerance:g}")
    ax.set_xlabel("run time [s]")
    ax.set_ylabel("max relative error vs the finest run")
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3, which="both")
    from brdfmodels.fileio import atomic_write

    return atomic_write(Path(path), lambda tmp: fig.savefig(tmp, dpi=100), keep_suffix=True)
