"""``hazard.analyze(scene)``: the whole analysis as a plan of stages.

:func:`hazard.pipeline.plan.plan` decides from the scene which stages run and why the
others are left out; each stage is a function of explicit inputs in its own module of
:mod:`hazard.pipeline`; :func:`analyze` runs them in order and the report's stage list
(``result.stages``: ran or skipped, the reason, the run time) comes from that plan:

``mpe`` (:mod:`~hazard.pipeline.limits`) -> ``rays`` and ``beam``
(:mod:`~hazard.pipeline.spots`) -> ``crossings`` (:mod:`~hazard.pipeline.crossings`) -> ``direct`` (:mod:`~hazard.pipeline.direct`) -> ``spill``
(:mod:`~hazard.pipeline.spill`) -> ``sdz`` (:mod:`~hazard.pipeline.sdz`) -> ``history`` (:mod:`~hazard.pipeline.history`) ->
``specular`` -> ``line_of_sight``, ``static`` | ``dynamic``, ``exposure``
(:mod:`~hazard.pipeline.irradiance_map`) -> ``keepout`` (:mod:`~hazard.pipeline.lobes`)
-> ``mirror_beams`` (:mod:`~hazard.pipeline.mirror_reach`) -> ``footprint`` (:mod:`~hazard.pipeline.ground`) -> ``extended_source``
(:mod:`hazard.extended_source`).
"""

from __future__ import annotations

import platform

import numpy as np

from brdfmodels.parallel import default_threads, thread_limit

from . import near_field, near_field_lobe
from .aperture import limiting_aperture_m, observer_apertures
from .nohd import group_gains
from .specular import describe_apertures
from .pipeline import crossings, direct, ground, history, irradiance_map, limits, lobes, mirror_reach, sdz, spill, spots as beam_stage
from .pipeline.irradiance_map import HISTORY_KEEP_MAX, MAP_CHUNK, MapInputs  # noqa: F401 (tunable, re-exported)
from .pipeline.log import StageLog
from .pipeline.plan import plan
from .results import HazardResult, ObserverResults, Stage, TargetResult

__all__ = ["analyze", "HazardResult", "Stage", "TargetResult", "ObserverResults"]


def analyze(scene, *, backend="embree", progress=None, keep_history=None, threads=None) -> HazardResult:
    """Run the hazard analysis of a loaded scene (see the module notes for the stages).

    Parameters
    ----------
    scene : scenes.Scene
    backend : {"embree", "numpy"}
        Ray engine when rays are needed.
    progress : callable, optional
        Called with a short message at each stage (the CLI prints them on stderr).
    keep_history : bool, optional
        Keep the full irradiance history E(observer, t) in the result. Default: only
        when it has at most ``HISTORY_KEEP_MAX`` values; peaks, exposures and verdicts
        are computed either way.
    threads : int, optional
        Threads for the irradiance map, the BRDF evaluations and the ray queries
        (default: :func:`brdfmodels.parallel.default_threads`, the CPUs this process may
        use). Results do not depend on it.

    The last stage, ``extended_source``, sets the MPE per observer: the point-source MPE
    by default, C_E from the diffuse spot's angular subtense with ``[exposure]
    extended_source = true`` (:func:`hazard.extended_source.apply_extended_source`).
    """
    from .extended_source import apply_extended_source

    if threads is None:
        return apply_extended_source(_run(scene, backend, progress, keep_history, default_threads()))
    with thread_limit(threads):  # checks it; caps every hot loop called from here
        return apply_extended_source(_run(scene, backend, progress, keep_history, threads))


def _trace(scene, the_plan, log, backend, threads, mu):
    """Stages ``rays`` and ``beam``: the ray scene (or analytic hits) and the spots."""
    ray_scene = None
    if the_plan.rays:
        with log.run("rays") as st:
            ray_scene = beam_stage.ray_scene(scene, backend, threads)
            st.detail = f"{backend}: {ray_scene.n_triangles} triangles"
    else:
        log.skip("rays", the_plan.skipped("rays"))
    tracer = ray_scene if ray_scene is not None else beam_stage.FlatScene(scene.targets)
    with log.run("beam") as st:
        traced = beam_stage.trace_beam(scene, tracer, mu)
        st.detail = traced.detail
    return ray_scene, tracer, traced


def _crossings(scene, traced, tracer, mu, mpe_w_m2, log, the_plan):
    """Stage ``crossings``: observer points added where a beam crosses a line between its
    points (the scene is returned with them; the caller's is not changed)."""
    if the_plan.skipped("crossings"):
        log.skip("crossings", the_plan.skipped("crossings"))
        return scene
    with log.run("crossings") as st:
        spill_s = spill.hottest_spill_s(traced, len(scene.targets))
        scene, st.detail = crossings.add_crossings(scene, traced.beam, traced.built.spots, mu, mpe_w_m2, tracer, spill_s)
    return scene


def _direct(scene, traced, tracer, mu, log, the_plan, ray_scene):
    """Stage ``direct``: the laser's own beam at the observers, at its worst over the
    pointing error or sector when the scene gives one (None without observers)."""
    if the_plan.skipped("direct"):
        log.skip("direct", the_plan.skipped("direct"))
        return None
    with log.run("direct") as st:
        laser = scene.spec.laser
        apertures = _apertures(scene)
        d = direct.direct_beam(traced.beam, scene.observers, tracer, mu, apertures)
        if laser.pointing_buffer_rad > 0 or laser.sector is not None or laser.aim_track is not None:
            d = direct.with_pointing(d, scene, traced.beam, scene.observers, mu, ray_scene, apertures)
        st.detail = d.detail
    return d


def _apertures(scene):
    """Per observer the limiting aperture and the aid's collecting disk (:mod:`hazard.aperture`)."""
    return observer_apertures(scene.observers.optics, scene.observers.group, scene.spec.laser.wavelength_nm,
                              scene.spec.exposure.duration_s)


def _spill(scene, traced, mu, exposure, log) -> dict:
    """Stage ``spill``: where the beam that misses every target goes, and its NOHD."""
    with log.run("spill") as st:
        out = spill.spill_summary(scene, traced, mu, exposure.irradiance_w_m2, lobes.scene_aids(scene))
        stopped = "; ".join(f"{d['power_w']:.4g} W stopped by {d['object']} at {d['range_m']:.4g} m, {d['reflected']}" for d in out["stopped"])
        st.detail = (f"{out['leaves_scene_w']:.4g} W leaves the scene past the targets, direct-beam NOHD along it "
                     f"{out['nohd_m']:.4g} m (the spill's highest point of the beam profile: {out['peak_profile']:.3g})"
                     + (f"; {stopped}" if stopped else "")
                     + (f"; {out['shared_w']:.4g} W in beam cells shared by a target and a stopper (it lands on one of them)"
                        if out["shared_w"] > 0 else ""))
    return out


def _sdz(scene, exposure, mu, log, ray_scene) -> dict:
    """Stage ``sdz``: the laser surface danger zone of the direct beam over its pointing
    cone or sector."""
    with log.run("sdz") as st:
        out = sdz.danger_zone(scene, exposure.irradiance_w_m2, mu, lobes.scene_aids(scene), ray_scene)
        d = out["directions"]
        st.detail = (f"{d['count']} direction(s) ({d['kind']}, buffer {d['buffer_rad']:.3g} rad, step {d['step_rad']:.3g} rad); "
                     f"{out['area_m2']:.4g} m^2 out to {out['max_range_m']:.4g} m; "
                     + ("contained by backstops" if out["contained"] else f"{out['escaping_directions']} direction(s) reach their NOHD "
                        f"({out['nohd_m']:.4g} m) without a backstop" + (", some above the horizon" if out["above_horizon"] else "")))
    return out


def _histories(scene, traced, log, the_plan):
    """Stage ``history``: analysis times, the dynamic spots' states over them and their
    melting (the spots of slumping targets get their tilt over the times)."""
    dynamic = any(sp.material.is_dynamic for sp in traced.built.spots)
    times = history.analysis_times(scene.spec, dynamic, history.series_nodes(scene.targets))
    if not dynamic:
        log.skip("history", the_plan.skipped("history") or "no lit target has a dynamic material")
        return times, {}, {}
    with log.run("history") as st:
        traced.built.spots, hist, notes = history.spot_states(scene.spec, traced.built.spots, times)
        st.detail = "; ".join([hist.detail] + notes)
    return times, hist.states, hist.melt


def _map_inputs(scene, traced, states, times, mu, exposure, ray_scene, keep_history, threads, the_plan) -> MapInputs:
    obs = scene.observers
    m = len(obs)
    n_t = len(times)
    keep = (m * n_t <= HISTORY_KEEP_MAX) if keep_history is None else bool(keep_history)
    spots = traced.built.spots
    los_scene = ray_scene if (the_plan.line_of_sight and spots) else None
    spec = scene.spec
    return MapInputs(spots, traced.beam, states, times, obs, group_gains(obs.optics, obs.group), mu,
                     spec.exposure.duration_s, spec.laser.wavelength_nm, spec.exposure.standard, exposure.irradiance_w_m2,
                     los_scene, keep, threads, MAP_CHUNK)


def _log_map(log, inp, out, the_plan):
    """Records of ``specular``, ``line_of_sight``, the map and ``exposure``."""
    spots, m, n_t = inp.spots, len(inp.points), len(inp.times_s)
    spec_spots = [sp for sp in spots if sp.material.has_specular]
    if spec_spots:
        log.ran("specular", f"{len(spec_spots)} mirror lobe(s) by geometric optics (unfolded beam on flat facets, Coddington "
                            f"spread on spheres and cylinders) from the lit part of each mirror, inside the irradiance map; "
                            f"{describe_apertures(out.apertures)}", 0.0)
    else:
        log.skip("specular", the_plan.skipped("specular") or "no lit target has an ideal-mirror (delta) lobe")
    if inp.ray_scene is not None:
        log.ran("line_of_sight", f"{out.los_segments} segments against {inp.ray_scene.n_triangles} triangles "
                                 f"({len(spots) * m - out.los_segments} observers behind the surface need none); "
                                 f"{int((~out.line_of_sight).sum())} without line of sight (per block inside the map)",
                out.los_seconds)
    else:
        log.skip("line_of_sight", the_plan.skipped("line_of_sight") or ("no observers" if not m else "no spot"))
    far = int(out.far_field.sum())
    name, other = ("dynamic", "static") if inp.states else ("static", "dynamic")
    log.ran(name, f"{m} observers x {n_t} time(s) in blocks of {out.chunk} on {out.workers} thread(s); {far} far-field "
                  f"(spot as a point source), {m - far} summed over hits; {near_field.describe(out.near_field)}",
            out.map_seconds - out.exposure_seconds - out.los_seconds)
    log.skip(other, the_plan.skipped(other) or "no lit target has a dynamic material: no time loop")
    log.ran("exposure", f"window {inp.duration_s:g} s over {n_t} time(s) (computed per block inside the map; "
                        f"its time is the per-thread share of the map's wall time)", out.exposure_seconds)


def _observers(scene, out, direct_beam) -> ObserverResults:
    obs, m = scene.observers, len(scene.observers)
    direct_w_m2 = np.zeros(m) if direct_beam is None else direct_beam.irradiance_w_m2
    at_aim = direct_w_m2 if direct_beam is None or direct_beam.at_aim_w_m2 is None else direct_beam.at_aim_w_m2
    return ObserverResults(
        observers=obs, offset_m=np.asarray(scene.offset_m, float),
        static_irradiance_w_m2=out.static_w_m2, peak_irradiance_w_m2=out.peak_w_m2, peak_time_s=out.peak_time_s,
        radiant_exposure_j_m2=out.exposure_j_m2, static_radiant_exposure_j_m2=out.static_w_m2 * scene.spec.exposure.duration_s,
        first_exceedance_s=out.first_exceedance_s,
        line_of_sight=out.line_of_sight.any(axis=0) if len(out.line_of_sight) else np.ones(m, bool),
        far_field=out.far_field, irradiance_w_m2=out.history_w_m2, specular_irradiance_w_m2=out.specular_w_m2,
        direct_irradiance_w_m2=direct_w_m2, reflected_irradiance_w_m2=np.maximum(out.peak_w_m2 - direct_w_m2, 0.0),
        direct_at_aim_irradiance_w_m2=at_aim,
        direct_point_irradiance_w_m2=None if direct_beam is None else direct_beam.point_w_m2,
        aperture_diameter_m=None if direct_beam is None else direct_beam.aperture_m,
    )


def _targets(scene, traced, states, exposure, mu, log):
    """Stage ``keepout`` and a row for every target (lit or not)."""
    a, spots = scene.spec.analysis, traced.built.spots
    with log.run("keepout") as st:
        aids = lobes.scene_aids(scene)
        before = near_field_lobe.STATS.snapshot()
        rows = lobes.target_results(spots, states, exposure.irradiance_w_m2, mu, a, aids)
        st.detail = (f"{len(spots)} lobe(s) at {a.direction_grid_deg:g} deg, {a.refine_levels} refinement levels"
                     + (f"; each also through {len(aids)} optical aid(s)" if aids and spots else "")
                     + f"; {near_field_lobe.describe_since(before)}")
    return rows + beam_stage.unlit_targets(scene.targets, spots, traced.built.unreflected)


def _mirror_beams(scene, rows, spots, ray_scene, zone, log, the_plan) -> None:
    """Stage ``mirror_beams``: each mirror beam's reach and containment, into ``zone``
    (report.json ``sdz.mirror_beams``)."""
    if the_plan.skipped("mirror_beams"):
        log.skip("mirror_beams", the_plan.skipped("mirror_beams"))
        return
    with log.run("mirror_beams") as st:
        zone["mirror_beams"] = mirror_reach.mirror_beams(scene, rows, spots, ray_scene)
        st.detail = mirror_reach.summary(zone["mirror_beams"])


def _footprints(scene, traced, ray_scene, states, exposure, mu, rows, log, the_plan):
    spots = traced.built.spots
    if not the_plan.footprint or not spots:
        log.skip("footprint", the_plan.skipped("footprint") or "no spot")
        return None
    with log.run("footprint") as st:
        fps = ground.footprints(spots, traced.beam, scene.terrain, ray_scene, exposure.irradiance_w_m2, mu,
                                scene.spec.analysis.footprint_eye_height_m, states, rows,
                                aperture_m=limiting_aperture_m(scene.spec.laser.wavelength_nm, scene.spec.exposure.duration_s))
        st.detail = fps.detail
    return fps


def _motion(scene, first, states, times, mu, exposure, backend, threads, log):
    """Stage ``motion``: moving observers, a moving beam or targets, firing windows
    (:mod:`hazard.pipeline.motion`); None when nothing moves."""
    from scenes.motion import motion_of

    motion = motion_of(scene)
    if motion is None:
        log.skip("motion", "nothing moves and lasing never stops (no track, aim_track, target track or windows)")
        return None
    from .pipeline.motion_stage import run_motion

    with log.run("motion") as st:
        out = run_motion(scene, motion, first, states, times, mu, exposure, backend, threads)
        st.detail = (f"{len(out.tracks())} track(s), {len(out.fixed())} fixed observer(s) over [{out.span_s[0]:g}, "
                     f"{out.span_s[1]:g}] s; {out.key_step_text}; {sum(p.summary['samples'] for p in out.paths)} samples"
                     + "".join(f"; {n}" for n in out.notes))
    return out


def _airspace(result, log, first):
    """Stage ``airspace``: the visual-interference distances (visible lasers) and the
    flight zones' checks (:mod:`hazard.visual`, :mod:`hazard.pipeline.airspace`)."""
    from .visual import visual_interference

    spec = result.scene.spec
    with log.run("airspace") as st:
        result.visual_interference = visual_interference(result)
        d = result.visual_interference["direct"]
        st.detail = (("visual levels apply: " if result.visual_interference["applies"] else "not a visible laser: ")
                     + ", ".join(f"{k} {v:.4g}" for k, v in d.items() if v is not None))
        if spec.airspace is not None and spec.airspace.zones:
            from .pipeline.airspace import check_zones

            result.airspace = check_zones(result, first)
            held = sum(z["holds"] for z in result.airspace["zones"])
            st.detail += f"; {held} of {len(result.airspace['zones'])} flight zone(s) hold their limit"


def _run(scene, backend, progress, keep_history, threads) -> HazardResult:
    the_plan, log = plan(scene), StageLog(progress)
    with log.run("mpe") as st:
        exposure = limits.exposure_limits(scene.spec)
        st.detail = exposure.detail
    mu = limits.attenuation_per_m(scene.spec)
    ray_scene, tracer, traced = _trace(scene, the_plan, log, backend, threads, mu)
    notes = list(getattr(scene, "notes", None) or []) + list(traced.notes)  # the beam's convention first (scenes.conventions)
    notes.extend(beam_stage.tail_notes(scene, traced.beam, traced.built.spots, exposure.irradiance_w_m2, mu))
    scene = _crossings(scene, traced, tracer, mu, exposure.irradiance_w_m2, log, the_plan)
    direct_beam = _direct(scene, traced, tracer, mu, log, the_plan, ray_scene)
    spill_part = _spill(scene, traced, mu, exposure, log)
    zone = _sdz(scene, exposure, mu, log, ray_scene)
    times, states, melts = _histories(scene, traced, log, the_plan)
    inp = _map_inputs(scene, traced, states, times, mu, exposure, ray_scene, keep_history, threads, the_plan)
    if direct_beam is not None and direct_beam.irradiance_w_m2.any():
        inp.direct_w_m2 = direct_beam.irradiance_w_m2
    if any(sp.material.has_specular for sp in inp.spots):
        inp.apertures = _apertures(scene)
    if exposure.pulse is not None:
        inp.pulse_limit_w_m2 = exposure.pulse.per_pulse_radiant_exposure_j_m2 * scene.spec.laser.prf_hz
    if not inp.keep_history:
        notes.append(f"irradiance history not kept ({len(inp.points)} x {len(times)} values); pass keep_history=True to keep it")
    out = irradiance_map.irradiance_map(inp)
    _log_map(log, inp, out, the_plan)
    rows = _targets(scene, traced, states, exposure, mu, log)
    notes.extend(lobes.near_field_lobe_notes(traced.built.spots, rows))
    melt_by_name = {scene.targets[k].name: m for k, m in melts.items()}
    for row in rows:
        row.melt = melt_by_name[row.name].summary() if row.name in melt_by_name else None
    _mirror_beams(scene, rows, traced.built.spots, ray_scene, zone, log, the_plan)
    fps = _footprints(scene, traced, ray_scene, states, exposure, mu, rows, log, the_plan)
    moving = _motion(scene, (traced, tracer, ray_scene), states, times, mu, exposure, backend, threads, log)
    built = traced.built
    result = HazardResult(scene, exposure.mpe, exposure.irradiance_w_m2, exposure.radiant_exposure_j_m2, exposure.pulse, mu, times,
                          [], rows, _observers(scene, out, direct_beam),
                          built.spill_w, built.blocked_w, traced.beam.power_w,
                          None if fps is None else fps.static, None if fps is None else fps.dynamic, notes, built.spots,
                          traced.beam, states, beam_sampling=beam_stage.beam_sampling(traced.cells, built, scene.spec.analysis.beam_rtol, traced.square),
                          spill=spill_part, sdz=zone, motion=moving)
    _airspace(result, log, (traced, tracer, ray_scene))
    result.stages = log.stages()
    return result


def versions() -> dict:
    """Versions of the tool and the libraries its numbers depend on (for the report)."""
    import scipy

    import brdfmodels

    from . import __version__

    return {
        "laser-hazard": __version__,
        "python": platform.python_version(),
        "numpy": np.__version__,
        "scipy": scipy.__version__,
        "brdfmodels": brdfmodels.__version__,
    }
