"""``hazard.analyze(scene)``: the whole analysis as a plan of declared stages.

:func:`hazard.pipeline.plan.plan` decides from the scene which stages run and why the
others are left out. Each stage below is registered with
:func:`hazard.pipeline.stages.stage`: the names it needs and the frozen result it provides
(:mod:`hazard.pipeline.stages`); the run order is derived from those declarations
(:func:`~hazard.pipeline.stages.derive_plan`), each stage calls the physics of its module
of :mod:`hazard.pipeline` and records in the stage log what it did or why it was skipped
(``result.stages``: ran or skipped, the reason, the run time). No stage changes another's
result; :func:`hazard_result` assembles the :class:`HazardResult` by keyword:

``mpe`` (:mod:`~hazard.pipeline.limits`) -> ``rays`` and ``beam``
(:mod:`~hazard.pipeline.spots`) -> ``crossings`` (:mod:`~hazard.pipeline.crossings`) -> ``direct`` (:mod:`~hazard.pipeline.direct`) -> ``spill``
(:mod:`~hazard.pipeline.spill`) -> ``sdz`` (:mod:`~hazard.pipeline.sdz`) -> ``history`` (:mod:`~hazard.pipeline.history`) ->
``irradiance_map`` (records ``specular``, ``line_of_sight``, ``static`` | ``dynamic``, ``exposure``;
:mod:`~hazard.pipeline.irradiance_map`) -> ``keepout`` (:mod:`~hazard.pipeline.lobes`)
-> ``mirror_beams`` (:mod:`~hazard.pipeline.mirror_reach`) -> ``footprint`` (:mod:`~hazard.pipeline.ground`) -> ``motion``
(:mod:`~hazard.pipeline.motion_stage`) -> ``airspace`` (:mod:`~hazard.pipeline.airspace`) -> ``extended_source``
(:mod:`hazard.pipeline.extended_source`).
"""

from __future__ import annotations

import platform
from dataclasses import replace

import numpy as np

from brdfmodels.parallel import default_threads, thread_limit

from hazard.physics import near_field, near_field_lobe
from hazard.physics.aperture import limiting_aperture_m, observer_apertures
from hazard.physics.engine import FAR_FIELD_SPOT_SIZES
from hazard.pipeline.extended_source import ExtendedSourceResult, extended_source_of
from hazard.physics.nohd import group_gains
from hazard.physics.specular import describe_apertures
from hazard.pipeline import crossings, direct, ground, history, irradiance_map, limits, lobes, mirror_reach, sdz, spill, spots as beam_stage
from hazard.pipeline.irradiance_map import HISTORY_KEEP_MAX, MAP_CHUNK, MapInputs  # noqa: F401 (tunable, re-exported)
from hazard.pipeline.log import StageLog
from hazard.pipeline.plan import plan
from hazard.pipeline.stages import (REGISTRY, AirspaceResult, BeamResult, CrossingsResult, DirectResult, FootprintResult,
                              HistoryResult, KeepoutResult, LimitsResult, MapResult, MirrorBeamsResult, MotionStageResult,
                              RaysResult, SdzResult, SpillResult, derive_plan, run_stages, stage)
from hazard.pipeline.results import HazardResult, ObserverResults, Stage, TargetResult

__all__ = ["analyze", "run_pipeline", "hazard_result", "HazardResult", "Stage", "TargetResult", "ObserverResults"]


def analyze(scene, *, backend="embree", progress=None, keep_history=None, threads=None, memo=None) -> HazardResult:
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
    memo : hazard.pipeline.stages.StageMemo, optional
        Reuse the stage results of earlier runs whose inputs are the same (the result is
        identical to a fresh run's; see :mod:`hazard.pipeline.stages`).

    The last stage, ``extended_source``, sets the MPE per observer: the point-source MPE
    by default, C_E from the diffuse spot's angular subtense with ``[exposure]
    extended_source = true`` (:func:`hazard.pipeline.extended_source.extended_source_of`).
    """
    if threads is None:
        return _run(scene, backend, progress, keep_history, default_threads(), memo)
    with thread_limit(threads):  # checks it; caps every hot loop called from here
        return _run(scene, backend, progress, keep_history, threads, memo)


def run_pipeline(scene, *, backend="embree", progress=None, keep_history=None, threads=None, memo=None):
    """The stages' results of an analysis: stage name -> frozen result (the types of
    :mod:`hazard.pipeline.stages`, and :class:`hazard.pipeline.extended_source.ExtendedSourceResult`),
    and the stage log. :func:`analyze` assembles its :class:`HazardResult` from them
    (:func:`hazard_result`). ``memo``: a :class:`~hazard.pipeline.stages.StageMemo` whose
    results are reused where the inputs are the same."""
    log = StageLog(progress)
    inputs = {"scene": scene, "plan": plan(scene), "backend": backend,
              "threads": default_threads() if threads is None else threads, "keep_history": keep_history}
    return run_stages(REGISTRY, derive_plan(REGISTRY, inputs), inputs, log, memo), log


def _run(scene, backend, progress, keep_history, threads, memo=None) -> HazardResult:
    results, log = run_pipeline(scene, backend=backend, progress=progress, keep_history=keep_history, threads=threads, memo=memo)
    return hazard_result(results, log.stages() + [results["extended_source"].record])


def hazard_result(r, stages=()) -> HazardResult:
    """The :class:`HazardResult` of the stage results ``r`` (stage name -> result; the
    stages after ``motion`` may be absent: the result is then the one they read), by
    keyword; ``stages``: the stage records."""
    exposure, mu = r["mpe"].exposure, r["mpe"].attenuation_per_m
    hist, scene, ext, air = r["history"], r["crossings"].scene, r.get("extended_source"), r.get("airspace")
    traced = hist.traced
    built = traced.built
    fp, beams = r["footprint"], r["mirror_beams"].beams
    observers = r["irradiance_map"].observers
    notes = [*r["beam"].notes, *r["irradiance_map"].notes, *r["keepout"].notes, *(() if ext is None else ext.notes)]
    return HazardResult(
        scene=scene, mpe=exposure.mpe, mpe_w_m2=exposure.irradiance_w_m2, mpe_radiant_exposure_j_m2=exposure.radiant_exposure_j_m2,
        pulse=exposure.pulse, attenuation_per_m=mu, times_s=hist.times_s, stages=list(stages), targets=list(r["keepout"].targets),
        observers=observers if ext is None else replace(observers, **ext.observer_fields()),
        spill_w=built.spill_w, blocked_w=built.blocked_w, beam_power_w=traced.beam.power_w,
        footprint_static=fp.static, footprint_dynamic=fp.dynamic, notes=notes, spots=built.spots, beam=traced.beam,
        states=hist.states, beam_sampling=beam_stage.beam_sampling(traced.cells, built, scene.spec.analysis.beam_rtol, traced.square),
        spill=r["spill"].summary, sdz=r["sdz"].zone if beams is None else replace(r["sdz"].zone, mirror_beams=beams),
        motion=r["motion"].motion,
        extended_source=None if ext is None else ext.summary,
        visual_interference=None if air is None else air.visual_interference,
        airspace=None if air is None else air.zones,
        uv_24h=exposure.uv_24h,
    )


@stage("mpe", needs=("scene",), result=LimitsResult)
def _limits(log, scene) -> LimitsResult:
    """The MPE and the exposure limits; the attenuation coefficient."""
    with log.run("mpe") as st:
        exposure = limits.exposure_limits(scene.spec)
        st.detail = exposure.detail
    return LimitsResult(exposure, limits.attenuation_per_m(scene.spec))


@stage("rays", needs=("scene", "plan", "backend", "threads"), result=RaysResult)
def _rays(log, scene, plan, backend, threads) -> RaysResult:
    """The ray scene (or analytic hits on flat targets)."""
    ray_scene = None
    if plan.rays:
        with log.run("rays") as st:
            ray_scene = beam_stage.ray_scene(scene, backend, threads)
            st.detail = f"{backend}: {ray_scene.n_triangles} triangles"
    else:
        log.skip("rays", plan.skipped("rays"))
    return RaysResult(ray_scene, ray_scene if ray_scene is not None else beam_stage.FlatScene(scene.targets))


@stage("beam", needs=("scene", "rays", "mpe"), result=BeamResult)
def _beam(log, scene, rays, mpe) -> BeamResult:
    """The beam sampled against every object, the targets' spots, the beam's notes."""
    mu = mpe.attenuation_per_m
    with log.run("beam") as st:
        traced = beam_stage.trace_beam(scene, rays.tracer, mu)
        st.detail = traced.detail
    notes = list(getattr(scene, "notes", None) or []) + list(traced.notes)  # the beam's convention first (scenes.conventions)
    notes.extend(mpe.exposure.notes)  # the UV 24 h accumulation (hazard.pipeline.limits)
    notes.extend(beam_stage.tail_notes(scene, traced.beam, traced.built.spots, mpe.exposure.irradiance_w_m2, mu))
    return BeamResult(traced, tuple(notes))


@stage("crossings", needs=("scene", "plan", "beam", "rays", "mpe"), result=CrossingsResult)
def _crossings(log, scene, plan, beam, rays, mpe) -> CrossingsResult:
    """Observer points added where a beam crosses a line between its points (a new scene;
    the input's is not changed)."""
    if plan.skipped("crossings"):
        log.skip("crossings", plan.skipped("crossings"))
        return CrossingsResult(scene)
    traced = beam.traced
    with log.run("crossings") as st:
        spill_s = spill.hottest_spill_s(traced, len(scene.targets))
        scene, st.detail = crossings.add_crossings(scene, traced.beam, traced.built.spots, mpe.attenuation_per_m,
                                                   mpe.exposure.irradiance_w_m2, rays.tracer, spill_s)
    return CrossingsResult(scene)


@stage("direct", needs=("crossings", "plan", "beam", "rays", "mpe"), result=DirectResult)
def _direct(log, crossings, plan, beam, rays, mpe) -> DirectResult:
    """The laser's own beam at the observers, at its worst over the pointing error or
    sector when the scene gives one (None without observers)."""
    if plan.skipped("direct"):
        log.skip("direct", plan.skipped("direct"))
        return DirectResult(None)
    scene, traced, mu = crossings.scene, beam.traced, mpe.attenuation_per_m
    with log.run("direct") as st:
        laser = scene.spec.laser
        apertures = _apertures(scene)
        scene.observers.keep_points()  # generated once for the direct beam, the map and the subtense (a small table)
        d = direct.direct_beam(traced.beam, scene.observers, rays.tracer, mu, apertures)
        if laser.pointing_buffer_rad > 0 or laser.sector is not None or laser.aim_track is not None:
            d = direct.with_pointing(d, scene, traced.beam, scene.observers, mu, rays.ray_scene, apertures)
        st.detail = d.detail
    return DirectResult(d)


def _apertures(scene):
    """Per observer the limiting aperture and the aid's collecting disk (:mod:`hazard.physics.aperture`)."""
    return observer_apertures(scene.observers.optics, scene.observers.group, scene.spec.laser.wavelength_nm,
                              scene.spec.exposure.duration_s)


@stage("spill", needs=("crossings", "beam", "mpe"), result=SpillResult)
def _spill(log, crossings, beam, mpe) -> SpillResult:
    """Where the beam that misses every target goes, and its NOHD."""
    scene = crossings.scene
    with log.run("spill") as st:
        out = spill.spill_summary(scene, beam.traced, mpe.attenuation_per_m, mpe.exposure.irradiance_w_m2, lobes.scene_aids(scene))
        stopped = "; ".join(f"{d.power_w:.4g} W stopped by {d.object} at {d.range_m:.4g} m, {d.reflected}" for d in out.stopped)
        st.detail = (f"{out.leaves_scene_w:.4g} W leaves the scene past the targets, direct-beam NOHD along it "
                     f"{out.nohd_m:.4g} m (the spill's highest point of the beam profile: {out.peak_profile:.3g})"
                     + (f"; {stopped}" if stopped else "")
                     + (f"; {out.shared_w:.4g} W in beam cells shared by a target and a stopper (it lands on one of them)"
                        if out.shared_w > 0 else ""))
    return SpillResult(out)


@stage("sdz", needs=("crossings", "mpe", "rays"), result=SdzResult)
def _sdz(log, crossings, mpe, rays) -> SdzResult:
    """The laser surface danger zone of the direct beam over its pointing cone or sector."""
    scene = crossings.scene
    with log.run("sdz") as st:
        out = sdz.danger_zone(scene, mpe.exposure.irradiance_w_m2, mpe.attenuation_per_m, lobes.scene_aids(scene), rays.ray_scene)
        d = out.directions
        st.detail = (f"{d.count} direction(s) ({d.kind}, buffer {d.buffer_rad:.3g} rad, step {d.step_rad:.3g} rad); "
                     f"{out.area_m2:.4g} m^2 out to {out.max_range_m:.4g} m; "
                     + ("contained by backstops" if out.contained else f"{out.escaping_directions} direction(s) reach their NOHD "
                        f"({out.nohd_m:.4g} m) without a backstop" + (", some above the horizon" if out.above_horizon else "")))
    return SdzResult(out)


@stage("history", needs=("crossings", "plan", "beam"), result=HistoryResult)
def _histories(log, crossings, plan, beam) -> HistoryResult:
    """Analysis times, the dynamic spots' states over them and their melting (the spots
    of slumping targets get their tilt over the times: a new trace, the beam's unchanged)."""
    scene, traced = crossings.scene, beam.traced
    dynamic = any(sp.material.is_dynamic for sp in traced.built.spots)
    times = history.analysis_times(scene.spec, dynamic, history.series_nodes(scene.targets))
    if not dynamic:
        log.skip("history", plan.skipped("history") or "no lit target has a dynamic material")
        return HistoryResult(times, {}, {}, traced)
    with log.run("history") as st:
        spots, hist, notes = history.spot_states(scene.spec, traced.built.spots, times)
        st.detail = "; ".join([hist.detail] + notes)
    return HistoryResult(times, hist.states, hist.melt, replace(traced, built=replace(traced.built, spots=spots)))


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


@stage("irradiance_map", needs=("crossings", "plan", "history", "rays", "mpe", "direct", "keep_history", "threads"),
       result=MapResult, records=("specular", "line_of_sight", "static", "dynamic", "exposure"))
def _map(log, crossings, plan, history, rays, mpe, direct, keep_history, threads) -> MapResult:
    """The irradiance map: every observer over the analysis times (mirror lobes, lines of
    sight, the static or dynamic pass, the exposure)."""
    scene, exposure, direct_beam = crossings.scene, mpe.exposure, direct.direct_beam
    scene.observers.keep_points()  # no-op when the direct beam kept them
    inp = _map_inputs(scene, history.traced, history.states, history.times_s, mpe.attenuation_per_m, exposure, rays.ray_scene,
                      keep_history, threads, plan)
    if direct_beam is not None and direct_beam.irradiance_w_m2.any():
        inp.direct_w_m2 = direct_beam.irradiance_w_m2
    if any(sp.material.has_specular for sp in inp.spots):
        inp.apertures = _apertures(scene)
    if exposure.pulse is not None:
        inp.pulse_limit_w_m2 = exposure.pulse.per_pulse_radiant_exposure_j_m2 * scene.spec.laser.prf_hz
    if exposure.uv_24h is not None:
        inp.uv_day_limit_j_m2 = exposure.uv_24h.radiant_exposure_j_m2
    notes = () if inp.keep_history else (
        f"irradiance history not kept ({len(inp.points)} x {len(history.times_s)} values); pass keep_history=True to keep it",)
    out = irradiance_map.irradiance_map(inp)
    _log_map(log, inp, out, plan)
    return MapResult(_observers(scene, out, direct_beam), notes)


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


@stage("keepout", needs=("crossings", "history", "mpe"), result=KeepoutResult)
def _targets(log, crossings, history, mpe) -> KeepoutResult:
    """The keep-out lobes and a row for every target (lit or not), with its melt."""
    scene, spots = crossings.scene, history.traced.built.spots
    a = scene.spec.analysis
    with log.run("keepout") as st:
        aids = lobes.scene_aids(scene)
        before = near_field_lobe.STATS.snapshot()
        rows = lobes.target_results(spots, history.states, mpe.exposure.irradiance_w_m2, mpe.attenuation_per_m, a, aids)
        st.detail = (f"{len(spots)} lobe(s) at {a.direction_grid_deg:g} deg, {a.refine_levels} refinement levels"
                     + (f"; each also through {len(aids)} optical aid(s)" if aids and spots else "")
                     + f"; {_near_field_text(before, rows)}")
    rows = rows + beam_stage.unlit_targets(scene.targets, spots, history.traced.built.unreflected)
    notes = lobes.near_field_lobe_notes(spots, rows) + lobes.curved_spot_notes(spots)
    melt_by_name = {scene.targets[k].name: m for k, m in history.melts.items()}
    for row in rows:  # this stage's own rows
        row.melt = melt_by_name[row.name].summary() if row.name in melt_by_name else None
    return KeepoutResult(tuple(rows), tuple(notes))


def _near_field_text(before, rows) -> str:
    """:func:`hazard.physics.near_field_lobe.describe_since` ``before``; when this run integrated
    no direction but the lobes carry near-field grids (cached on spots a
    :class:`~hazard.pipeline.stages.StageMemo` reused from an earlier run), says so
    instead of "no direction ... within the near field"."""
    if near_field_lobe.STATS.snapshot()["directions"] > before["directions"]:
        return near_field_lobe.describe_since(before)
    grids = {id(i): i for r in rows for lobe in (r.static_lobe, r.dynamic_lobe) if lobe is not None and (i := lobe.near_field)}
    n = sum(int(i.get("directions_integrated", 0)) for i in grids.values())
    if not n:
        return near_field_lobe.describe_since(before)
    return (f"near-field lobe: {n} grid direction(s) within {FAR_FIELD_SPOT_SIZES:g} spot sizes integrated "
            f"in an earlier run on the same spots (grids reused: stage memo)")


@stage("mirror_beams", needs=("crossings", "plan", "keepout", "history", "rays"), result=MirrorBeamsResult)
def _mirror_beams(log, crossings, plan, keepout, history, rays) -> MirrorBeamsResult:
    """Each mirror beam's reach and containment (report.json ``sdz.mirror_beams``)."""
    if plan.skipped("mirror_beams"):
        log.skip("mirror_beams", plan.skipped("mirror_beams"))
        return MirrorBeamsResult(None)
    with log.run("mirror_beams") as st:
        beams = mirror_reach.mirror_beams(crossings.scene, list(keepout.targets), history.traced.built.spots, rays.ray_scene)
        st.detail = mirror_reach.summary(beams)
    return MirrorBeamsResult(beams)


@stage("footprint", needs=("crossings", "plan", "history", "rays", "mpe", "keepout"), result=FootprintResult)
def _footprints(log, crossings, plan, history, rays, mpe, keepout) -> FootprintResult:
    """Hazardous ground under the lobes (with terrain)."""
    scene, traced = crossings.scene, history.traced
    spots = traced.built.spots
    if not plan.footprint or not spots:
        log.skip("footprint", plan.skipped("footprint") or "no spot")
        return FootprintResult()
    with log.run("footprint") as st:
        fps = ground.footprints(spots, traced.beam, scene.terrain, rays.ray_scene, mpe.exposure.irradiance_w_m2, mpe.attenuation_per_m,
                                scene.spec.analysis.footprint_eye_height_m, history.states, list(keepout.targets),
                                aperture_m=limiting_aperture_m(scene.spec.laser.wavelength_nm, scene.spec.exposure.duration_s))
        st.detail = fps.detail
    return FootprintResult(fps.static, fps.dynamic)


@stage("motion", needs=("crossings", "history", "rays", "mpe", "backend", "threads"), result=MotionStageResult)
def _motion(log, crossings, history, rays, mpe, backend, threads) -> MotionStageResult:
    """Moving observers, a moving beam or targets, firing windows
    (:mod:`hazard.pipeline.motion`); None when nothing moves."""
    from scenes.motion import motion_of

    scene = crossings.scene
    motion = motion_of(scene)
    if motion is None:
        log.skip("motion", "nothing moves and lasing never stops (no track, aim_track, target track or windows)")
        return MotionStageResult(None)
    from hazard.pipeline.motion_stage import run_motion

    first = (history.traced, rays.tracer, rays.ray_scene)
    with log.run("motion") as st:
        out = run_motion(scene, motion, first, history.states, history.times_s, mpe.attenuation_per_m, mpe.exposure, backend, threads)
        st.detail = (f"{len(out.tracks())} track(s), {len(out.fixed())} fixed observer(s) over [{out.span_s[0]:g}, "
                     f"{out.span_s[1]:g}] s; {out.key_step_text}; {sum(p.summary.samples for p in out.paths)} samples"
                     + "".join(f"; {n}" for n in out.notes))
    return MotionStageResult(out)


_CORE = ("mpe", "crossings", "beam", "rays", "history", "irradiance_map", "keepout", "spill", "sdz", "mirror_beams",
         "footprint", "motion")


@stage("airspace", needs=_CORE, result=AirspaceResult)
def _airspace(log, **r) -> AirspaceResult:
    """The visual-interference distances (visible lasers) and the flight zones' checks
    (:mod:`hazard.physics.visual`, :mod:`hazard.pipeline.airspace`), on the result so far."""
    from hazard.physics.visual import visual_interference

    result = hazard_result(r)
    first = (r["history"].traced, r["rays"].tracer, r["rays"].ray_scene)
    spec, zones = result.scene.spec, None
    with log.run("airspace") as st:
        vi = visual_interference(result)
        st.detail = (("visual levels apply: " if vi.applies else "not a visible laser: ")
                     + ", ".join(f"{k} {v:.4g}" for k, v in vi.direct.to_dict().items() if v is not None))
        if spec.airspace is not None and spec.airspace.zones:
            from hazard.pipeline.airspace import check_zones

            zones = check_zones(replace(result, visual_interference=vi), first)
            held = sum(z.holds for z in zones.zones)
            st.detail += f"; {held} of {len(zones.zones)} flight zone(s) hold their limit"
    return AirspaceResult(vi, zones)


@stage("extended_source", needs=(*_CORE, "airspace"), result=ExtendedSourceResult)
def _extended_source(log, **r) -> ExtendedSourceResult:
    """The MPE per observer: C_E from the diffuse spot's subtense, or the point-source MPE
    (its record is kept in the result: :func:`hazard_result` appends it)."""
    return extended_source_of(hazard_result(r))


def versions() -> dict:
    """Versions of the tool and the libraries its numbers depend on (for the report)."""
    import scipy

    import brdfmodels

    from hazard import __version__

    return {
        "laser-hazard": __version__,
        "python": platform.python_version(),
        "numpy": np.__version__,
        "scipy": scipy.__version__,
        "brdfmodels": brdfmodels.__version__,
    }
