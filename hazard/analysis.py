"""``hazard.analyze(scene)``: the whole analysis, planned from what the scene needs.

Stages (each reported as ran or skipped, with the reason and its run time):

``mpe`` -> ``rays`` (Embree scene; skipped when the targets are flat and nothing can
block a line of sight: beam hits are then computed analytically) -> ``beam`` ->
``history`` (skipped for static materials) -> ``specular`` (delta lobes; skipped if
none) -> ``line_of_sight`` (skipped when nothing can block) -> ``static`` or ``dynamic``
(the map; ``dynamic`` is the time loop, skipped for static materials) -> ``exposure`` ->
``keepout`` -> ``footprint`` (needs terrain).

The map runs in blocks of observers side by side on threads (``threads``); each block
does its own line of sight, irradiance and exposure, so those three stages report their
share of the map's wall time.

Exposure (spec `laser-safety.md` section 4): per observer the irradiance history E(t)
over the analysis window; peak irradiance; the radiant exposure over the exposure
duration as a sliding-window maximum of the integral of E; the hazard ratio peak / MPE;
and the first time at which the accumulated exposure exceeds the MPE for that elapsed
time. "Static" holds the material's initial state for the whole window.
"""

from __future__ import annotations

import math
import platform
import time
from contextlib import contextmanager
from dataclasses import dataclass, field

import numpy as np

import brdfmodels
from brdfmodels.parallel import block_rows, default_threads, map_blocks, thread_limit

from . import mpe as _mpe
from .beam import BeamGeometry, sample_cells
from .engine import FAR_FIELD_SPOT_SIZES, build_spots, flat_outlines, spot_irradiance, specular_irradiance
from .specular import specular_nohd
from .keepout import Footprint, Lobe, ground_footprint, hazard_lobe
from .nohd import attenuation_from_visibility, nohd_direct, optical_gain

__all__ = ["analyze", "HazardResult", "Stage", "TargetResult", "ObserverResults"]


@dataclass
class Stage:
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
    specular_direction: list | None
    state_name: str | None
    state_range: list | None
    spot_power_error_w: float = 0.0  # bound on the spot power's error (already added to it: conservative)
    spot_power_exact: bool = False  # spot power is the exact outline integral
    peak_irradiance_w_m2: float = 0.0  # highest incident irradiance on the lit part (normal to the beam, attenuated)
    mean_irradiance_w_m2: float = 0.0  # spot power over its lit area normal to the beam
    lit_side: str = "front"

    def to_dict(self):
        def lobe(lb):  # a target without a spot reflects nothing: an empty lobe, said in lit_side
            return {"max_nohd_m": 0.0, "max_direction": None, "volume_m3": 0.0, "volume_error_m3": 0.0, "cells": 0,
                    "evaluations": 0} if lb is None else lb.summary()

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
        }


@dataclass
class ObserverResults:
    """Arrays over the M observer points (file coordinates)."""

    observers: object  # scenes.Observers (names are built on demand: 1e6 strings cost 0.5 s)
    position_m: np.ndarray
    static_irradiance_w_m2: np.ndarray
    peak_irradiance_w_m2: np.ndarray
    peak_time_s: np.ndarray
    radiant_exposure_j_m2: np.ndarray
    static_radiant_exposure_j_m2: np.ndarray
    first_exceedance_s: np.ndarray
    line_of_sight: np.ndarray
    far_field: np.ndarray
    irradiance_w_m2: np.ndarray | None  # (M, T) total irradiance history (None if not kept)
    # extended sources (hazard.extended_source, set by analyze()): the spot's angular
    # subtense [rad], C_E and the MPE per observer (C_E = 1 and the scalar MPE unless
    # [exposure] extended_source = true); None on results built without analyze()
    angular_subtense_rad: np.ndarray | None = None
    c_e: np.ndarray | None = None
    mpe_w_m2: np.ndarray | None = None
    mpe_radiant_exposure_j_m2: np.ndarray | None = None
    # highest irradiance of the mirror (delta) lobes alone [W/m^2] per observer: > 0 where
    # an observer sees the beam's image (a point source: C_E = 1); None if not computed
    specular_irradiance_w_m2: np.ndarray | None = None

    def __len__(self):
        return len(self.position_m)

    @property
    def labels(self) -> list:
        if not hasattr(self, "_labels"):
            self._labels = self.observers.labels()
        return self._labels


@dataclass
class HazardResult:
    """Everything an analysis produced, with the stages that ran."""

    scene: object
    mpe: object
    mpe_w_m2: float
    mpe_radiant_exposure_j_m2: float
    pulse: object | None
    attenuation_per_m: float
    times_s: np.ndarray
    stages: list
    targets: list
    observers: ObserverResults
    spill_w: float
    blocked_w: float
    beam_power_w: float
    footprint_static: Footprint | None = None
    footprint_dynamic: Footprint | None = None
    notes: list = field(default_factory=list)
    spots: list = field(default_factory=list)  # the beam's spots (for renders and re-evaluation)
    beam: object | None = None
    states: dict = field(default_factory=dict)  # target index -> states over times_s
    extended_source: dict = field(default_factory=dict)  # C_E summary for the report (hazard.extended_source)
    beam_sampling: dict = field(default_factory=dict)  # rays, levels, error bound, exact targets (the beam stage)

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
        return self.hazard_ratio >= 1.0

    @property
    def hazardous_static(self) -> np.ndarray:
        return self.observers.static_irradiance_w_m2 / self.observer_mpe_w_m2 >= 1.0

    @property
    def any_hazard(self) -> bool:
        return bool(np.any(self.hazardous)) or any(
            (t.static_lobe is not None and t.static_lobe.max_range_m > 0) or (t.dynamic_lobe is not None and t.dynamic_lobe.max_range_m > 0)
            for t in self.targets
        )

    def stage(self, name) -> Stage:
        return next(s for s in self.stages if s.name == name)

    def verdict_changes(self) -> list:
        """Observers whose verdict differs between the static and the dynamic analysis."""
        changed = np.flatnonzero(self.hazardous != self.hazardous_static)
        return [self.observers.labels[i] for i in changed]


# ---------------------------------------------------------------------------------------
class _FlatScene:
    """Beam hits on plates and disks by ray-plane intersection (no ray library)."""

    def __init__(self, targets):
        self.targets = targets
        self.scale_m = 1.0

    def face_normals(self, faces):
        return np.stack([self.targets[f].normal for f in faces]) if len(faces) else np.empty((0, 3))

    def first_hit(self, origins, directions):
        from .rays import Hits

        o = np.asarray(origins, float)
        d = np.asarray(directions, float)
        d = d / np.linalg.norm(d, axis=1, keepdims=True)
        n = len(o)
        best_t = np.full(n, np.inf)
        best = np.full(n, -1)
        for t in self.targets:
            den = d @ t.normal
            with np.errstate(divide="ignore", invalid="ignore"):
                tt = ((t.center_m - o) @ t.normal) / den
            p = o + d * np.where(np.isfinite(tt), tt, 0)[:, None]
            q = p - t.center_m
            x = q @ t.tangent
            y = q @ np.cross(t.normal, t.tangent)
            s = t.spec.size_m
            inside = (np.abs(x) <= s[0] / 2) & (np.abs(y) <= s[1] / 2) if t.spec.shape == "plate" else (x * x + y * y <= (s[0] / 2) ** 2)
            ok = np.isfinite(tt) & (tt > 0) & inside & (tt < best_t)
            best_t[ok] = tt[ok]
            best[ok] = t.index
        hit = best >= 0
        point = np.where(hit[:, None], o + d * np.where(hit, best_t, 0)[:, None], np.nan)
        return Hits(hit, best_t, best, best, point)


def _ray_meshes(scene):
    meshes = [(t.mesh.vertices, t.mesh.faces, t.index) for t in scene.targets]
    base = len(scene.targets)
    meshes += [(m.vertices, m.faces, base + i) for i, m in enumerate(scene.occluders)]
    if scene.terrain is not None:
        tm = scene.terrain.mesh()
        meshes.append((tm.vertices, tm.faces, base + len(scene.occluders)))
    return meshes


def _sliding_max_integral(times, e, window):
    """Max over window positions of the integral of E over [t, t + window] (rows of e)."""
    if len(times) == 1:
        return e[:, 0] * window
    cum = np.concatenate([np.zeros((e.shape[0], 1)), np.cumsum(0.5 * (e[:, 1:] + e[:, :-1]) * np.diff(times), axis=1)], axis=1)
    span = times[-1] - times[0]
    if window >= span:
        return cum[:, -1]
    starts = times[times <= times[-1] - window]
    ends = starts + window
    best = np.zeros(e.shape[0])
    for s, t in zip(starts, ends):
        j = np.searchsorted(times, t)
        # integral up to t: cumulative at node j-1 plus the partial trapezoid
        t0, t1 = times[j - 1], times[min(j, len(times) - 1)]
        frac = 0.0 if t1 == t0 else (t - t0) / (t1 - t0)
        e_t = e[:, j - 1] + frac * (e[:, min(j, len(times) - 1)] - e[:, j - 1])
        c_t = cum[:, j - 1] + 0.5 * (e[:, j - 1] + e_t) * (t - t0)
        i = np.searchsorted(times, s)
        best = np.maximum(best, c_t - cum[:, i])
    return best


def _level0_cells(beam_samples: int) -> int:
    """Cells per side of the beam's coarsest grid: about ``beam_samples`` cells in all (at least 4 x 4)."""
    return max(4, int(round(math.sqrt(beam_samples))))


def _beam_detail(cells, built, power_w) -> str:
    exact = f"; exact outline integrals for {', '.join(built.exact)}" if built.exact else ""
    if built.unreflected:
        exact += "; not reflected: " + ", ".join(f"{n} ({s} face, {p:.4g} W)" if s != "unresolved" else f"{n} (unresolved cells, {p:.4g} W)"
                                                 for n, s, p in built.unreflected)
    return (f"{cells.rays_traced} rays over {cells.levels_used} level(s) of cells; {len(built.spots)} spot(s); "
            f"spill {built.spill_w:.4g} W, blocked {built.blocked_w:.4g} W; intercepted-power error bound "
            f"{built.error_w:.3g} W ({built.error_w / power_w:.2g} of the beam, added to the spots){exact}")


def _beam_sampling(cells, built, rtol) -> dict:
    """The beam stage's accuracy for the report: rays, levels, the bound on the power
    misassigned between objects [W] and which targets got exact outline integrals."""
    return {"rays": int(cells.rays_traced), "levels": int(cells.levels_used), "rtol": float(rtol),
            "error_bound_w": float(built.error_w), "exact_targets": list(built.exact),
            "not_reflected": [{"target": n, "side": s, "power_w": float(p)} for n, s, p in built.unreflected]}


def _unlit_targets(targets, spots, unreflected) -> list:
    """A row for every target without a spot (after the spots' rows, same order as the
    file), so no target disappears from a report: what reached it and why nothing reflects."""
    lit = {sp.target.index for sp in spots}
    why = {}
    for name, side, p in unreflected:
        why.setdefault(name, []).append((side, p))
    rows = []
    for t in targets:
        if t.index in lit:
            continue
        parts = why.get(t.name, [])
        power = float(sum(p for _, p in parts))
        side = "; ".join(f"{s} face lit, not reflected" if s != "unresolved" else "only unresolved beam cells" for s, _ in parts) or "not lit"
        rows.append(TargetResult(t.name, power, 0.0, None, None, None, None, None, None, None, lit_side=side))
    return rows


def _unreflected_notes(unreflected) -> list:
    notes = []
    for name, side, p in unreflected:
        if side == "unresolved":
            notes.append(f"target {name!r}: at most {p:.4g} W reaches it in unresolved beam cells and is not reflected")
        elif side == "back":
            notes.append(f"target {name!r}: the lit side is the back ({p:.4g} W) and it has no back material: "
                         f"nothing was reflected from it (give targets.back to model the back face)")
        else:
            notes.append(f"target {name!r}: {p:.4g} W lands on its {side} faces and is not reflected (mixed sides: the other side carries more)")
    return notes


HISTORY_KEEP_MAX = 20_000_000  # observer x time values kept in memory by default (160 MB)
MAP_CHUNK = 32768  # observers per block of the map (measured with 2 threads: 4096 0.48-0.59 s, 16384 0.36, 32768-131072 0.31-0.33)


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
        return apply_extended_source(_analyze(scene, backend, progress, keep_history, default_threads()))
    with thread_limit(threads):  # checks it; caps every hot loop called from here
        return apply_extended_source(_analyze(scene, backend, progress, keep_history, threads))


def _analyze(scene, backend, progress, keep_history, threads) -> HazardResult:
    spec = scene.spec
    stages = []
    notes = []
    say = progress or (lambda msg: None)

    @contextmanager
    def stage(name, detail=""):
        say(f"{name}...")
        t0 = time.perf_counter()
        st = Stage(name, True, detail)
        yield st
        st.seconds = time.perf_counter() - t0
        stages.append(st)

    def skip(name, why):
        stages.append(Stage(name, False, why))

    laser = spec.laser
    wl, t_exp, std = laser.wavelength_nm, spec.exposure.duration_s, spec.exposure.standard
    with stage("mpe") as st:
        mpe_res = _mpe.ocular_mpe(wl, t_exp, standard=std)
        pulse = None
        mpe_w_m2 = mpe_res.irradiance_w_m2
        if laser.power_w is None:
            pulse = _mpe.repetitive_pulse_mpe(wl, laser.pulse_duration_s, laser.prf_hz, t_exp, standard=std)
            mpe_w_m2 = min(mpe_w_m2, pulse.per_pulse_radiant_exposure_j_m2 * laser.prf_hz)
            st.detail = f"pulsed: per-pulse MPE x PRF = {pulse.per_pulse_radiant_exposure_j_m2 * laser.prf_hz:.6g} W/m^2 average"
        else:
            st.detail = f"{mpe_res.irradiance_w_m2:.6g} W/m^2 for {t_exp:g} s"
        mpe_h = mpe_w_m2 * t_exp
    atm = spec.atmosphere
    if atm.attenuation_per_m is not None:
        mu = atm.attenuation_per_m
    elif atm.visibility_km is not None:
        mu = attenuation_from_visibility(atm.visibility_km, wl)
    else:
        mu = 0.0

    flat_only = all(t.spec.shape in ("plate", "disk") for t in scene.targets)
    need_los = bool(scene.occluders) or scene.terrain is not None or len(scene.targets) > 1 or any(t.spec.shape == "mesh" for t in scene.targets)
    ray_scene = None
    if need_los or not flat_only:
        with stage("rays") as st:
            from .rays import RayScene

            ray_scene = RayScene(_ray_meshes(scene), backend=backend, threads=threads)
            st.detail = f"{backend}: {ray_scene.n_triangles} triangles"
    else:
        skip("rays", "flat targets and nothing to block a line of sight: beam hits computed analytically")
    tracer = ray_scene if ray_scene is not None else _FlatScene(scene.targets)

    with stage("beam") as st:
        beam = BeamGeometry.create(scene.laser_position_m, scene.laser_direction, laser.average_power_w, laser.beam_diameter_m,
                                   laser.divergence_rad)
        outlines = flat_outlines(beam, scene.targets)
        cells = sample_cells(beam, tracer, scene.targets, n0=_level0_cells(spec.analysis.beam_samples), rtol=spec.analysis.beam_rtol,
                             outlines={k: v[1] for k, v in outlines.items()})
        built = build_spots(beam, cells, scene.targets, tracer, mu, outlines)
        spots, spill, blocked = built.spots, built.spill_w, built.blocked_w
        st.detail = _beam_detail(cells, built, laser.average_power_w)
        if spill > 1e-3 * laser.average_power_w:
            notes.append(f"{100 * spill / laser.average_power_w:.3g} % of the beam misses every target (spill)")
        notes.extend(_unreflected_notes(built.unreflected))

    # -- states over time ------------------------------------------------------------------
    t_end = spec.analysis.time_end_s or t_exp
    dt = spec.analysis.time_step_s or t_end / 100.0
    dynamic_spots = [sp for sp in spots if sp.material.is_dynamic]
    if dynamic_spots:
        times = np.arange(0.0, t_end + 0.5 * dt, dt)
        times[-1] = min(times[-1], t_end) if len(times) > 1 else times[-1]
    else:
        times = np.array([0.0])
    states = {}
    if dynamic_spots:
        with stage("history") as st:
            parts = []
            for sp in dynamic_spots:
                t = sp.target
                hist = t.history
                if t.spec.history.kind == "heating":
                    hs = t.spec.history
                    kw = {}
                    if hs.thickness_m is not None:
                        kw["thickness_m"] = hs.thickness_m
                    if hs.initial_reflectance is not None:
                        kw["initial_reflectance"] = hs.initial_reflectance
                    if hs.oxidation is not None:
                        kw["oxidation"] = brdfmodels.OxidationModel(**hs.oxidation.model_dump())
                    plate = getattr(brdfmodels.ThinPlateHeating, hs.plate)(**kw)
                    irr = sp.max_irradiance_w_m2  # the hottest point of the spot (local peak, after attenuation)
                    res = plate.solve(times if len(times) > 1 else np.array([0.0, t_end]), irr, rtol=hs.rtol)
                    hist = res.history(hs.state, extrapolation="clamp")
                    parts.append(f"{t.name}: heating at the spot's peak {irr:.4g} W/m^2 (spot mean {sp.mean_irradiance_w_m2:.4g} W/m^2), "
                                 f"T_max {res.temperature_k.max():.0f} K")
                else:
                    parts.append(f"{t.name}: measured series")
                states[t.index] = hist.state_at(times)
            st.detail = "; ".join(parts)
    else:
        skip("history", "no dynamic material")

    def initial(sp):
        return None if sp.target.index not in states else states[sp.target.index][:1]

    obs = scene.observers
    m = len(obs)
    pos = obs.positions_m
    group_gain = np.array([1.0 if o is None else optical_gain(o.magnification, o.objective_diameter_m, o.transmission)
                           for o in obs.optics])
    gain = group_gain[obs.group] if m else np.ones(0)

    los = np.ones((len(spots), m), bool)
    do_los = bool(need_los and m and spots)
    los_segments = []  # segments traced per block (list.append is atomic: blocks run on threads)

    def line_of_sight(sl):
        """Line of sight from each spot to observers ``sl``: one occlusion query per spot,
        run inside the map's block (single-threaded Embree, in parallel with the other
        blocks' BRDF work). Returns the seconds it took."""
        t0 = time.perf_counter()
        p = pos[sl]
        n_seg = 0
        for k, sp in enumerate(spots):
            c, nrm = sp.centroid, sp.mean_frame[2]
            start = ray_scene.off_surface(c, nrm)
            # far-field observers behind the spot's surface receive nothing whatever is
            # in between (the map evaluates them with the mean frame): no ray needed
            rel = p - c
            far = np.einsum("ij,ij->i", rel, rel) >= (FAR_FIELD_SPOT_SIZES * max(sp.size_m, 1e-9)) ** 2
            need = ~far | (np.einsum("ij,j->i", rel, nrm) > 0) | sp.material.has_specular
            idx = np.flatnonzero(need)
            row = los[k, sl]
            row[~need] = False
            row[idx] = ~ray_scene.occluded(np.broadcast_to(start, (len(idx), 3)), p[idx])
            n_seg += len(idx)
        los_segments.append(n_seg)
        return time.perf_counter() - t0

    spec_spots = [sp for sp in spots if sp.material.has_specular]
    if spec_spots:
        stages.append(Stage("specular", True, f"{len(spec_spots)} mirror lobe(s) by geometric optics "
                                              f"(unfolded beam on flat facets, Coddington spread on spheres and cylinders) from the lit part of each mirror, inside the irradiance map"))
    else:
        skip("specular", "no ideal-mirror (delta) lobe")

    n_t = len(times)
    dynamic = bool(dynamic_spots)
    keep = (m * n_t <= HISTORY_KEEP_MAX) if keep_history is None else bool(keep_history)
    e_t = np.zeros((m, n_t)) if keep else None
    e_static = np.zeros(m)
    if not keep:
        notes.append(f"irradiance history not kept ({m} x {n_t} values); pass keep_history=True to keep it")
    peak = np.zeros(m)
    peak_t = np.zeros(m)
    h = np.zeros(m)
    first = np.full(m, np.nan)
    far_any = np.zeros(m, bool)
    spec_peak = np.zeros(m)  # highest specular (mirror-lobe) irradiance per observer over time
    if dynamic and n_t > 1:
        span = times[-1] - times[0]
        trap = np.zeros(n_t)
        trap[1:] += 0.5 * np.diff(times)
        trap[:-1] += 0.5 * np.diff(times)
        elapsed = np.clip(times[1:] - times[0], _mpe.DURATION_MIN_S, _mpe.DURATION_MAX_S)
        mpe_h_t = np.array([_mpe.ocular_mpe(wl, t, standard=std).radiant_exposure_j_m2 for t in elapsed])
        e_floor = float(np.min(mpe_h_t / np.maximum(times[1:] - times[0], 1e-300)))  # no exceedance below this
    chunk = block_rows(n_t, MAP_CHUNK)  # long histories: fewer observers per block
    one_spot = len(spots) == 1 and not spots[0].material.has_specular

    def post(ec, rows):
        """Peak, exposure and first exceedance of the rows ``rows`` (global indices)."""
        idx = ec.argmax(axis=1)
        pk = ec[np.arange(ec.shape[0]), idx]
        peak[rows] = pk
        peak_t[rows] = times[idx]
        e_static[rows] = ec[:, 0]
        if n_t == 1:
            h[rows] = ec[:, 0] * t_exp
            first[rows] = np.where(ec[:, 0] > mpe_w_m2, times[0], np.nan)
            return
        h[rows] = ec @ trap if t_exp >= span else _sliding_max_integral(times, ec, t_exp)
        hot = np.flatnonzero(pk >= e_floor)
        if len(hot):
            eh = ec[hot]
            cum = np.cumsum(0.5 * (eh[:, 1:] + eh[:, :-1]) * np.diff(times), axis=1)
            over = cum > mpe_h_t
            anyo = over.any(axis=1)
            first[rows[hot[anyo]]] = times[1 + over.argmax(axis=1)[anyo]]

    def map_block(a0, a1):
        """Line of sight, irradiance and exposure of observers [a0, a1); returns
        the seconds spent on line of sight and on exposure. Blocks write disjoint rows,
        so they run on threads (NumPy, BLAS and Embree release the GIL)."""
        sl = slice(a0, a1)
        t_los = line_of_sight(sl) if do_los else 0.0
        if one_spot:
            sp = spots[0]
            sk = states.get(sp.target.index) if dynamic else None
            (live, ev), far = spot_irradiance(sp, pos[sl], gain[sl], mu, sk, los[0, sl], sparse=True)
            far_any[sl] = far
            ev = ev if ev.ndim == 2 else ev[:, None]
            if keep:
                e_t[sl.start + live] = ev
            t0 = time.perf_counter()
            post(ev, sl.start + live)
            return t_los, time.perf_counter() - t0
        ec = np.zeros((sl.stop - sl.start, n_t))
        for k, sp in enumerate(spots):
            sk = states.get(sp.target.index) if dynamic else None
            e, far = spot_irradiance(sp, pos[sl], gain[sl], mu, sk, los[k, sl])
            far_any[sl] |= far
            if sp.material.has_specular:
                es = specular_irradiance(sp, pos[sl], gain[sl], mu, beam, sk) * (los[k, sl] if sk is None else los[k, sl, None])
                spec_peak[sl] = np.maximum(spec_peak[sl], es if es.ndim == 1 else es.max(axis=1))
                e = e + es
            ec += e if e.ndim == 2 else e[:, None]
        if keep:
            e_t[sl] = ec
        t0 = time.perf_counter()
        post(ec, np.arange(sl.start, sl.stop))
        return t_los, time.perf_counter() - t0

    workers = max(1, min(threads, -(-m // chunk)))
    with stage("dynamic" if dynamic else "static") as st:
        parts = map_blocks(map_block, m, chunk, workers)
        # per-thread shares of the wall time (the parts ran side by side on the workers)
        los_s, post_s = (sum(p[i] for p in parts) / workers for i in (0, 1))
        st.detail = (f"{m} observers x {n_t} time(s) in blocks of {chunk} on {workers} thread(s); {int(far_any.sum())} far-field "
                     f"(spot as a point source), {m - int(far_any.sum())} summed over hits")
    map_stage = stages[-1]
    map_stage.seconds -= post_s + los_s  # line of sight and exposure are reported in their own stages
    if do_los:
        n_seg = sum(los_segments)
        stages.insert(len(stages) - 1, Stage(
            "line_of_sight", True, f"{n_seg} segments against {ray_scene.n_triangles} triangles ({len(spots) * m - n_seg} observers "
                                   f"behind the surface need none); {int((~los).sum())} without line of sight (per block inside the map)", los_s))
    else:
        skip("line_of_sight", "nothing can block a line of sight (no occluders, no terrain, one target)" if not need_los else "no observers")
    if dynamic:
        skip("static", "static = the initial-state column of the dynamic map (no separate pass)")
    else:
        skip("dynamic", "no dynamic material: no time loop")
    stages.append(Stage("exposure", True, f"window {t_exp:g} s over {n_t} time(s) (computed per block inside the map; "
                                          f"its time is the per-thread share of the map's wall time)", post_s))

    # -- keep-out ----------------------------------------------------------------------------
    a = spec.analysis
    target_results = []
    with stage("keepout") as st:
        for sp in spots:
            t = sp.target
            dyn_states = None
            if t.index in states:
                s_hist = states[t.index]
                nodes = t.material.state_nodes()
                lo, hi = s_hist.min(), s_hist.max()
                dyn_states = np.unique(np.concatenate([s_hist, nodes[(nodes >= lo) & (nodes <= hi)]]))
            static_lobe = hazard_lobe(sp, mpe_w_m2, mu, states=initial(sp), grid_deg=a.direction_grid_deg, refine_levels=a.refine_levels)
            dynamic_lobe = static_lobe if dyn_states is None else hazard_lobe(
                sp, mpe_w_m2, mu, states=dyn_states, grid_deg=a.direction_grid_deg, refine_levels=a.refine_levels)
            spec_static = spec_dyn = spec_dir = None
            if sp.material.has_specular:
                ns = specular_nohd(sp, mpe_w_m2, mu, initial(sp))
                nd = specular_nohd(sp, mpe_w_m2, mu, dyn_states) if dyn_states is not None else ns
                spec_static, spec_dyn, spec_dir = ns.nohd_m, nd.nohd_m, (nd.direction if nd.nohd_m >= ns.nohd_m else ns.direction)
            target_results.append(TargetResult(
                t.name, sp.total_power_w, sp.size_m, static_lobe, dynamic_lobe, spec_static, spec_dyn, spec_dir,
                t.material.state_name if t.material.is_dynamic else None,
                [float(states[t.index].min()), float(states[t.index].max())] if t.index in states else None,
                sp.power_error_w, sp.exact, sp.max_irradiance_w_m2, sp.mean_irradiance_w_m2, sp.side,
            ))
        st.detail = f"{len(spots)} lobe(s) at {a.direction_grid_deg:g} deg, {a.refine_levels} refinement levels"
    target_results += _unlit_targets(scene.targets, spots, built.unreflected)

    fp_static = fp_dyn = None
    if scene.terrain is not None and spots:
        with stage("footprint") as st:
            eye = a.footprint_eye_height_m
            rmax = max([tr.dynamic_lobe.max_range_m for tr in target_results] + [tr.specular_nohd_dynamic_m or 0.0 for tr in target_results])
            initial_states = {k: v[:1] for k, v in states.items()}
            fp_static = ground_footprint(spots, beam, scene.terrain, ray_scene, mpe_w_m2, mu, eye,
                                         states_by_target=initial_states, max_range_m=rmax)
            if dynamic_spots:
                fp_dyn = ground_footprint(spots, beam, scene.terrain, ray_scene, mpe_w_m2, mu, eye,
                                          states_by_target=states, max_range_m=rmax)
            else:
                fp_dyn = fp_static
            st.detail = f"hazardous ground at {eye:g} m eye height: static {fp_static.area_m2:.4g} m^2, dynamic {fp_dyn.area_m2:.4g} m^2"
    else:
        skip("footprint", "no terrain" if scene.terrain is None else "no spot")

    h_static = e_static * t_exp
    observers = ObserverResults(
        observers=obs,
        position_m=scene.to_world(pos) if m else np.zeros((0, 3)),
        static_irradiance_w_m2=e_static,
        peak_irradiance_w_m2=peak,
        peak_time_s=peak_t,
        radiant_exposure_j_m2=h,
        static_radiant_exposure_j_m2=h_static,
        first_exceedance_s=first,
        line_of_sight=los.any(axis=0) if spots else np.ones(m, bool),
        far_field=far_any,
        irradiance_w_m2=e_t,
        specular_irradiance_w_m2=spec_peak,
    )
    return HazardResult(scene, mpe_res, mpe_w_m2, mpe_h, pulse, mu, times, stages, target_results, observers, spill, blocked,
                        beam.power_w, fp_static, fp_dyn, notes, spots, beam, states,
                        beam_sampling=_beam_sampling(cells, built, spec.analysis.beam_rtol))


def versions() -> dict:
    import scipy

    from . import __version__

    return {
        "laser-hazard": __version__,
        "python": platform.python_version(),
        "numpy": np.__version__,
        "scipy": scipy.__version__,
        "brdfmodels": brdfmodels.__version__,
    }
