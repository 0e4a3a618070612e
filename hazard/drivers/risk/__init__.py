"""Probabilistic risk: the chance that an observer's exposure exceeds the MPE
(``hazard risk SCENE -o OUT``; spec `range-safety.md` sections 6 and 8).

A scene's ``[uncertainty]`` names every random input and its distribution
(:mod:`hazard.drivers.risk.inputs`). Each draw is one simulated operation evaluated by the
engine's own beam, reflection and direct-beam pieces (:mod:`hazard.drivers.risk.evaluate`);
rare events are reached by importance sampling toward the hazardous directions
(:mod:`hazard.drivers.risk.importance`); the draws run in chunks on Dask, resumable
(:mod:`hazard.drivers.risk.run`); the statistics (:mod:`hazard.drivers.risk.stats`) give per observer
and map cell the probability with its exact interval, quantiles, the risk over a year's
operations and which input drives it; the files are :mod:`hazard.outputs.risk_outputs`.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

__all__ = ["run_risk", "check_risk_args", "RiskResult"]


@dataclass
class RiskResult:
    """risk.json's content (``doc``), the output folder and the map (None without one)."""

    doc: dict
    outdir: Path
    map: dict | None

    @property
    def observers(self) -> list:
        return self.doc["observers"]


def _describe_inputs(ev) -> list:
    """Every input group with its stated distribution, or why it is off."""
    u, m, scene = ev.scene.spec.uncertainty, ev.model, ev.scene
    names = [t.name for t in scene.targets]
    tilted = [names[k] for k in m.tilt_targets]
    d = {
        "pointing": (f"axis error = bias [{u.pointing_bias_rad[0]:g}, {u.pointing_bias_rad[1]:g}] rad (right, up) + "
                     f"N(0, ({u.pointing_sigma_rad:g} rad)^2) per axis"),
        "material": "; ".join([f"BRDF scale exp(N(0, {u.brdf_scale_sigma:g}^2)) per target (median 1), correlation "
                               f"{u.brdf_scale_correlation:g} between targets"] * (u.brdf_scale_sigma > 0)
                              + [f"{c.target}: one of {len(c.materials)} materials, weights "
                                 f"{[round(x, 4) for x in (c.weights or [1.0] * len(c.materials))]}" for c in u.materials]),
        "tilt": (f"surface normal tilt N(0, ({u.normal_tilt_sigma_deg:g} deg)^2) per axis on {tilted}"
                 + (f", wandering (Ornstein-Uhlenbeck, correlation time {u.normal_wander_correlation_time_s:g} s) at "
                    f"{m.n_nodes} times" if m.wander_times_s else ", one tilt per operation")),
        "visibility": None if u.visibility is None else f"visibility {u.visibility.model_dump(exclude_none=True)} (Kruse attenuation)",
        "scintillation": None if u.scintillation is None else (
            f"log-normal irradiance factor, mean 1, on the direct and mirror beams: {u.scintillation.model_dump(exclude_none=True)}"),
        "observer_position": f"offset N(0, ({u.observer_position_sigma_m:g} m)^2) per horizontal axis, N(0, ({u.observer_height_sigma_m:g} m)^2) in height",
    }
    active = m.active()
    return [{"name": g, "active": g in active, "distribution": d[g] if g in active else "not uncertain (not given)"} for g in d]


def _notes(ev, s, prop) -> tuple[list, list]:
    """What the run says about itself, and what the model leaves out."""
    u, scene, notes = ev.scene.spec.uncertainty, ev.scene, []
    left = ["C_E (extended source) is not credited: the point-source MPE, the smaller (conservative)",
            "the heating history of a dynamic target follows a drawn pointing error, but not a drawn visibility or BRDF scale "
            "(the nominal attenuation's history)",
            "scintillation path lengths and variances are the nominal geometry's (not redrawn with an observer's offset)",
            "the observer's optics multiply the naked eye's value (the direct beam through the 7 mm limiting aperture) by "
            "their fixed gain (tau M^2 or tau (D_o/7 mm)^2): an upper bound in a beam wider than the objective, NOT beside a "
            "beam narrower than it, whose power the aid collects over min(D_o, 7 mm M) (hazard run's verdict does)"]
    if u.normal_tilt_sigma_deg > 0:
        others = [t.name for t in scene.targets if t.index not in ev.model.tilt_targets]
        if others:
            left.append(f"targets {others} are not plates or disks: their normals are not tilted")
    if scene.spec.has_motion:
        left.append("things that move are not simulated: the [laser] aim is held (no aim track, target track or firing "
                    "windows) and moving observers (tracks) are not evaluated; hazard run's motion stage covers them")
    if ev.model.wander_times_s:
        left.append(f"a wandering tilt is evaluated at {ev.model.n_nodes} times; a peak between them is not searched")
    if ev.s2_direct is not None and len(ev.s2_direct):
        big = float(np.expm1(ev.s2_direct).max())
        if big > 1.0:
            notes.append(f"strong turbulence (scintillation index up to {big:.3g}): the log-normal model understates the tails "
                         f"in saturation (gamma-gamma is heavier)")
    if s.sampling == "importance":
        notes.append(f"importance sampling: {len(prop.components)} component(s) toward hazardous directions, "
                     f"{100 * prop.alpha0:g} % of draws from the stated distributions (weights <= {1 / prop.alpha0:g})")
    if s.sensitivity_draws == 0:
        notes.append("no sensitivity sample: " + ("fewer than two uncertain inputs" if len(ev.model.active()) < 2 else
                                                  "sensitivity_draws = 0" if ev.n_observers else "no observers"))
    if ev.n_observers == 0:
        notes.append("the scene has no observers: no per-observer rows")
    if scene.spec.uncertainty.map is None:
        notes.append("no [uncertainty.map]: no probability map")
    return notes, left


def _map_summary(mp) -> dict | None:
    if mp is None:
        return None
    hi = np.asarray(mp["ci_high"])
    return {"shape": list(mp["shape"]), "spacing_m": mp["spacing_m"], "extent_m": mp["extent_m"], "eye_height_m": mp["eye_height_m"],
            "max_probability": float(np.max(mp["probability"])), "method": mp["method"],
            "cells_upper_at_least": {f"{lv:g}": int((hi >= lv).sum()) for lv in (1e-6, 1e-4, 1e-2)}}


def check_risk_args(scene, draws=None, sensitivity_draws=None) -> None:
    """Before any work: the risk analysis ``hazard risk`` asks for (the scene's
    ``[uncertainty]`` with ``--draws`` / ``--sensitivity-draws``) within the limits
    (:func:`scenes.spec.check_risk`, the check the scene passed at load without them)."""
    from scenes.spec import check_risk

    if scene.spec.uncertainty is None:
        raise ValueError(f"{scene.source}: no [uncertainty] table: nothing is random (give pointing_sigma_rad, brdf_scale_sigma, ...)")
    try:
        check_risk(scene.spec, draws, sensitivity_draws)
    except ValueError as exc:
        opts = [o for o, v in (("--draws", draws), ("--sensitivity-draws", sensitivity_draws)) if v is not None]
        raise ValueError(f"{scene.source}: {exc}" + (f" (with {' and '.join(opts)})" if opts else "")) from None


def run_risk(scene, outdir, *, draws=None, seed=None, sampling=None, sensitivity_draws=None, serial=False, workers=2,
             scheduler=None, force=False, progress=None, backend="embree", keep_going=False) -> RiskResult:
    """Run the probabilistic risk analysis of ``scene`` (it needs ``[uncertainty]``) into
    ``outdir``; finished chunks there are reused (resume). A failed chunk of draws stops the
    run (``keep_going``: after the rest) with :class:`hazard.drivers.risk.run.ChunksFailed`, and no
    result file is written or replaced. Arguments override the scene's
    ``[uncertainty]`` (draws, seed, sampling "plain" | "importance" | "auto").
    ``serial``: in this process, without Dask (identical results). The final files are
    switched in as one unit (:mod:`brdfmodels.output_sets`); ``force`` also accepts files in
    ``outdir`` hazard did not write (kept)."""
    from brdfmodels.output_sets import output_unit

    from hazard.outputs.risk_outputs import write_outputs

    check_risk_args(scene, draws, sensitivity_draws)  # [uncertainty] present, something random, the work within the limit
    t0 = time.perf_counter()
    outdir = Path(outdir)
    claims = ("risk.json", "risk.csv", "risk.html", "probability_map.csv", "probability_map.png", "probability_map.tif",
              "probability_map_local_frame.tif", "probability_contours.geojson", "probability_contours_local_frame.json")
    with output_unit(outdir, command="risk", overwrite=True, force=force, working=(".risk",), claims=claims) as unit:
        outdir.mkdir(parents=True, exist_ok=True)
        doc, mp = _risk_doc(scene, outdir, t0, draws=draws, seed=seed, sampling=sampling, sensitivity_draws=sensitivity_draws, serial=serial,
                            workers=workers, scheduler=scheduler, force=force, progress=progress, backend=backend, keep_going=keep_going)
        doc["notes"][:0] = unit.notes  # a crash of an earlier run recovered: said in risk.json and by the CLI
        write_outputs(unit.stage, doc, scene, mp)
        from hazard.outputs.risk_page import write_risk_page

        write_risk_page(doc, unit.stage)  # risk.json, risk.csv, the map files and the page switch in together
    return RiskResult(doc, outdir, mp)


def _risk_doc(scene, outdir, t0, *, draws, seed, sampling, sensitivity_draws, serial, workers, scheduler, force, progress, backend,
              keep_going=False):
    """risk.json's content and the map of :func:`run_risk` (chunks computed or reused in ``outdir/.risk``)."""
    from hazard.drivers.risk.results import map_result, observer_rows, sensitivity
    from hazard.drivers.risk.run import gather, run_chunks, settings, shared

    ev, prop = shared(scene, backend)
    active = ev.model.active()
    s = settings(scene, len(ev.points_m), ev.n_observers, draws=draws, seed=seed, sampling=sampling, sensitivity_draws=sensitivity_draws,
                 active=active, can_import=bool(prop.components))
    chunks = run_chunks(scene, s, outdir, backend=backend, serial=serial, workers=workers, scheduler=scheduler, force=force, progress=progress,
                        keep_going=keep_going)
    got = gather(chunks, s, active, Path(outdir) / ".risk")  # one chunk in memory at a time; observers' arrays on disk
    try:
        sens = sensitivity(got.store, ev.own_gain()[: s.n_observers], active)
        rows = observer_rows(ev, s, got, sens)
    finally:
        if got.store is not None:
            got.store.close()
    mp = map_result(ev, s, got)
    notes, left = _notes(ev, s, prop)
    doc = {"scene": scene.name, "scene_sha256": scene.text_sha256, "mpe_w_m2": ev.mpe_w_m2, "mpe": ev.exposure.detail,
           "standard": scene.spec.exposure.standard, "duration_s": scene.spec.exposure.duration_s,
           "draws": s.draws, "seed": s.seed, "sampling": s.sampling, "sensitivity_draws": s.sensitivity_draws, "chunk_draws": s.chunk_draws,
           "criterion": "per draw the peak irradiance over the analysis times (direct beam + reflections, the observer's optics) >= the MPE",
           "inputs": _describe_inputs(ev), "inputs_active": active,
           "importance": None if s.sampling != "importance" else {"alpha0": prop.alpha0, "components": [c.why for c in prop.components]},
           "operations": scene.spec.uncertainty.operations,
           "observers": rows, "map": _map_summary(mp), "notes": notes, "left_out": left,
           "run": {"chunks": len(chunks.main) + len(chunks.sensitivity), "ran": chunks.ran, "reused": chunks.reused,
                   "mode": "serial" if serial else (f"scheduler {scheduler}" if scheduler else f"LocalCluster, {workers} workers"),
                   "seconds": round(time.perf_counter() - t0, 3)}}
    return doc, mp

