"""Stage ``motion`` run: every moving observer's path (and, when the beam or a target
moves, every fixed observer's) sampled, refined and summarised (see
:mod:`hazard.pipeline.motion` for the physics and the time steps)."""

from __future__ import annotations

import functools
import math
import time
from dataclasses import dataclass, field, replace

import numpy as np

from hazard.physics import mpe as _mpe
from hazard.pipeline.motion import (FIXED_OBSERVERS_MAX, WINDOW_DURATIONS, MotionRun, PathResult, SummarisedPath, base_grid, beam_states,
                                    evaluate)
from hazard.pipeline.motion_results import PathSummary, PathUv24h, WorstWindow
from hazard.pipeline.motion_steps import crossing_times, refine_by_change

__all__ = ["MotionResult", "run_motion", "path_summary"]


@dataclass(frozen=True)
class MotionResult:
    """Stage ``motion``: the paths evaluated over time, how, and what was left out.

    Attributes
    ----------
    paths : tuple of SummarisedPath
        The moving observers' tracks (in the scene's order), then the fixed observers
        evaluated over time; each with its samples and :class:`~hazard.pipeline.motion_results.PathSummary`.
    span_s : tuple of 2 float
        The analysed span [s] (``[motion] time_start_s``, ``time_end_s``).
    beam_states : int
        Number of beam states traced (key times).
    key_step_text : str
        How the key times were chosen, in words.
    notes : tuple of str
        What the evaluation left out or assumed (report.json ``motion.notes``).
    seconds : float
        The stage's wall-clock run time [s] (time.perf_counter; masked when outputs are compared).
    run : MotionRun or None
        The run's shared state (its beam states serve the airspace and visual checks).
    """

    paths: tuple[SummarisedPath, ...]
    span_s: tuple[float, float]
    beam_states: int
    key_step_text: str
    notes: tuple[str, ...] = ()
    seconds: float = 0.0
    run: MotionRun | None = field(default=None, repr=False, compare=False)

    def tracks(self) -> list[SummarisedPath]:
        """The moving observers' paths."""
        return [p for p in self.paths if p.kind == "track"]

    def fixed(self) -> list[SummarisedPath]:
        """The fixed observers' paths (the beam or a target moves)."""
        return [p for p in self.paths if p.kind == "fixed"]


def _richardson_j_m2(t, e) -> float:
    """Error estimate of the trapezoid integral: a third of its difference from the sum
    over every second sample (exact for a quadratic; 0 for fewer than 3 samples)."""
    if len(t) < 3:
        return 0.0
    full = float(np.sum(0.5 * (e[1:] + e[:-1]) * np.diff(t)))
    ts, es = t[::2], e[::2]
    if ts[-1] != t[-1]:
        ts, es = np.append(ts, t[-1]), np.append(es, e[-1])
    half = float(np.sum(0.5 * (es[1:] + es[:-1]) * np.diff(ts)))
    return abs(full - half) / 3.0


def _hot(e, floor_w_m2: float) -> np.ndarray:
    """Samples where E is above ``floor_w_m2`` (and 1e-12 of its peak), and their
    neighbours: the only places a window's largest exposure need start or end, or an
    exceedance first happen (elsewhere the integral grows by less than the floor per
    second)."""
    if not len(e) or not e.max() > 0:
        return np.zeros(0, int)
    hot = e > max(1e-12 * e.max(), floor_w_m2)
    hot[1:] |= hot[:-1]
    hot[:-1] |= hot[1:]
    return np.flatnonzero(hot)


def _lengths(t, duration_s, base_step_s) -> np.ndarray:
    """Window lengths [s]: log-spaced from the smallest step (not the zero-width pairs at
    the windows' edges) to the exposure duration."""
    dt = np.diff(t)
    dt = dt[dt > 1e-9 * base_step_s]
    t_min = max(float(dt.min()) if len(dt) else duration_s, _mpe.DURATION_MIN_S)
    return np.unique(np.append(np.geomspace(min(t_min, duration_s), duration_s, WINDOW_DURATIONS), duration_s))


def _windows(t, cum, lengths, idx):
    """Largest exposure [J/m^2] over windows of each length, starting or ending at the
    samples ``idx`` (:func:`_hot`); and the times and exposures of the windows ending at
    those samples, per length."""
    span = t[-1] - t[0]
    th, ch = t[idx], cum[idx]
    best, ends = [], []
    for T in lengths:
        if not len(idx):
            best.append(0.0)
            ends.append(np.zeros(0))
            continue
        start = np.interp(np.minimum(th + T, t[-1]), t, cum) - ch
        end = ch - np.interp(np.maximum(th - T, t[0]), t, cum)
        best.append(max(float(start.max()), float(end.max())) if span > 0 else float(cum[-1]))
        ends.append(end)
    return np.asarray(best), (th, ends)


def _uv_limits_j_m2(wavelength_nm, standard, on_s) -> np.ndarray:
    """The day's limit H(T) (:func:`hazard.physics.mpe.uv_24h_mpe`) for each exposed time T [s],
    T rounded down to 1 % log bins (H never decreases with T in the UV rows, so the limit
    is never raised by it; at most 1 % low where H grows as T, 0.25 % where as T^0.25)."""
    on = np.asarray(on_s, float)
    pos = on > 0
    k = np.floor(np.log(np.maximum(on[pos], _mpe.DURATION_MIN_S) / _mpe.DURATION_MIN_S) / math.log(1.01))
    k = np.minimum(k, np.floor(np.log(_mpe.UV_ACCUMULATION_S / _mpe.DURATION_MIN_S) / math.log(1.01)))  # <= 24 h
    k = np.where(_mpe.DURATION_MIN_S * 1.01**k > on[pos], k - 1, k)  # the edge never above T (float rounding)
    uniq, inv = np.unique(k.astype(np.int64), return_inverse=True)
    h_u = np.array([_uv_day_h_j_m2(float(wavelength_nm), int(b), standard) for b in uniq])
    out = np.full(on.shape, np.inf)
    out[pos] = h_u[inv]
    return out


@functools.lru_cache(maxsize=65536)
def _uv_day_h_j_m2(wavelength_nm, bin_k, standard) -> float:
    """H of :func:`hazard.physics.mpe.uv_24h_mpe` at the lower edge of 1 % log bin ``bin_k`` (cached:
    the paths of one run share their bins)."""
    return _mpe.uv_24h_mpe(wavelength_nm, _mpe.DURATION_MIN_S * 1.01**bin_k, standard=standard).radiant_exposure_j_m2


def _uv_24h(t, e, cum, wavelength_nm, standard, rel_err) -> PathUv24h:
    """UV (180-400 nm): the largest dose of the path within any 24 h against the limit for
    the time exposed in that 24 h (the exposures of a day add up: :func:`hazard.physics.mpe.uv_24h_mpe`).

    Exposed time counts the steps with irradiance at both ends (never more than the true
    time, so the limit is never raised; a 24 h lit only at isolated samples counts the
    steps with irradiance at either end). Windows of 24 h end at every sample (the first
    exceedance is the first such end over the limit) and, for paths longer than 24 h,
    start at every sample."""
    dt = np.diff(t)
    both = (e[1:] > 0) & (e[:-1] > 0)
    either = (e[1:] > 0) | (e[:-1] > 0)
    x = np.concatenate([[0.0], np.cumsum(np.where(both, dt, 0.0))])
    xe = np.concatenate([[0.0], np.cumsum(np.where(either, dt, 0.0))])
    day = _mpe.UV_ACCUMULATION_S
    lo = np.maximum(t - day, t[0])
    ends, doses = t, cum - np.interp(lo, t, cum)  # the 24 h up to each sample
    on, on_e = x - np.interp(lo, t, x), xe - np.interp(lo, t, xe)
    if t[-1] - t[0] > day:  # and from each sample on
        hi = np.minimum(t + day, t[-1])
        ends = np.concatenate([ends, hi])
        doses = np.concatenate([doses, np.interp(hi, t, cum) - cum])
        on = np.concatenate([on, np.interp(hi, t, x) - x])
        on_e = np.concatenate([on_e, np.interp(hi, t, xe) - xe])
    on = np.where(on > 0, on, on_e)  # lit only at isolated samples: the steps touching them
    h = _uv_limits_j_m2(wavelength_nm, standard, on)
    ratio = np.where(doses > 0, doses * (1.0 + rel_err) / h, 0.0)
    w = int(np.argmax(ratio))
    over = ratio >= 1.0
    return PathUv24h(dose_j_m2=float(doses[w]), exposed_s=float(on[w]), limit_j_m2=float(h[w]), ratio=float(ratio[w]),
                     window_end_s=float(ends[w]), first_exceedance_s=float(ends[over].min()) if over.any() else None,
                     label="[M] UV 24 h accumulation (ANSI Z136.1-2014 8.2, IEC 60825-1:2014 A.3; unverified)")


def path_summary(pr: PathResult, duration_s, wavelength_nm, standard, pulse_limit_w_m2=None) -> PathSummary:
    """Peak, radiant exposure (largest over windows of ``duration_s``), the whole path's,
    the verdict over every window length and the first exceedance of one path; in the UV
    also the largest dose within 24 h against the day's limit (``uv_24h``, :func:`_uv_24h`),
    which counts in ``exposure_ratio`` and ``hazardous``."""
    t, e = pr.times_s, pr.irradiance_w_m2
    cum = pr.cumulative_j_m2
    err = _richardson_j_m2(t, e)
    k = int(np.argmax(e)) if len(e) else 0
    lengths = _lengths(t, duration_s, pr.base_step_s)
    mpe_h = np.array([_mpe.ocular_mpe(wavelength_nm, float(np.clip(T, _mpe.DURATION_MIN_S, _mpe.DURATION_MAX_S)),
                                      standard=standard).radiant_exposure_j_m2 for T in lengths])
    # windows need only start or end where E is above 1e-9 of the lowest MPE irradiance of any window length
    best, (t_end, ends) = _windows(t, cum, lengths, _hot(e, 1e-9 * float(np.min(mpe_h / lengths))))
    rel_err = err / cum[-1] if cum[-1] > 0 else 0.0  # the integral's relative error, applied to every window
    ratio = best * (1.0 + rel_err) / mpe_h
    w = int(np.argmax(ratio))
    first = [t_end[np.argmax(end > m)] for end, m in zip(ends, mpe_h) if np.any(end > m)]
    if pulse_limit_w_m2 is not None and np.any(e >= pulse_limit_w_m2):
        first.append(t[np.argmax(e >= pulse_limit_w_m2)])
    hazardous = bool(ratio[w] >= 1.0 or (pulse_limit_w_m2 is not None and e[k] >= pulse_limit_w_m2))
    uv = _uv_24h(t, e, cum, wavelength_nm, standard, rel_err) if wavelength_nm < 400 and len(t) > 1 else None
    if uv is not None and uv.ratio >= 1.0:
        hazardous = True
        first.append(uv.first_exceedance_s)
    dt = np.diff(t)
    steps = dt[dt > 1e-9 * pr.base_step_s]  # not the zero-width pairs at the windows' edges
    x, y, z = (float(c) for c in pr.positions_m[k])
    return PathSummary(
        name=pr.name, kind=pr.kind,
        peak_irradiance_w_m2=float(e[k]), peak_time_s=float(t[k]), worst_point_m=(x, y, z),
        peak_direct_w_m2=float(pr.direct_w_m2[k]), peak_reflected_w_m2=float(pr.reflected_w_m2[k]),
        radiant_exposure_j_m2=float(best[lengths == duration_s][0]), path_exposure_j_m2=float(cum[-1]),
        exposure_error_estimate_j_m2=err,
        worst_window=WorstWindow(duration_s=float(lengths[w]), exposure_j_m2=float(best[w]), mpe_radiant_exposure_j_m2=float(mpe_h[w]),
                                 ratio=float(ratio[w])),
        exposure_ratio=float(max(ratio[w], 0.0 if uv is None else uv.ratio)), hazardous=hazardous,
        uv_24h=uv,  # UV: the day's summed dose against its limit (None outside 180-400 nm)
        first_exceedance_s=float(min(first)) if first else None,
        time_span_s=(float(t[0]), float(t[-1])), samples=int(len(t)), base_step_s=pr.base_step_s,
        min_step_s=float(steps.min()) if len(steps) else pr.base_step_s, adaptive=pr.adaptive,
        lased_s=float(np.sum(dt * (pr.lased[1:] & pr.lased[:-1]))) if len(t) > 1 else 0.0,
    )


def _floor_w_m2(run: MotionRun) -> float:
    """Irradiance below which the a-posteriori refinement stops: far under the MPE and the
    laser-free level."""
    return min(1e-3 * run.mpe_w_m2, 5e-5)


def _sample_path(run: MotionRun, name, group, kind, at, span, optics) -> PathResult | None:
    ms = run.motion.spec
    t0, t1 = max(span[0], run.motion.t_start_s), min(span[1], run.motion.t_end_s)
    if t1 < t0:
        return None
    t = base_grid(run.motion, t0, t1) if t1 > t0 else np.array([t0])
    if ms.adaptive and len(t) > 1:
        t = np.unique(np.concatenate([t, crossing_times(run, at, t, ms.samples_per_width)]))

    def parts_at(ts):
        return np.stack(evaluate(run, at(ts), ts, optics))

    parts = parts_at(t)
    if ms.adaptive and len(t) > 1:
        t, parts, _ = refine_by_change(t, parts, parts_at, _floor_w_m2(run))
    return PathResult(name, group, kind, t, at(t), run.motion.windows.lased(t), parts[0], parts[1], ms.time_step_s, ms.adaptive,
                      tuple(run.bias_rad))


BIAS_CANDIDATES = 8  # closest approaches of a track to the aim tried as the pointing bias's direction


def _bias_candidates(run: MotionRun, pr: PathResult, b: float) -> list:
    """Constant pointing biases (across the aim, within the buffer ``b``) that turn the
    beam onto the track where it comes closest to the aim: at each local minimum of its
    angular offset within b plus five 1/e beam radii, the offset clipped to b."""
    from hazard.pipeline.motion import bias_frame

    u = run.nominal_direction(pr.times_s)
    q = pr.positions_m - np.asarray(run.scene.laser_position_m, dtype=float)
    z = np.einsum("ij,ij->i", q, u)
    e1, e2 = bias_frame(u)
    a, c = np.arctan2(np.einsum("ij,ij->i", q, e1), z), np.arctan2(np.einsum("ij,ij->i", q, e2), z)
    delta = np.hypot(a, c)
    la = run.scene.spec.laser
    reach = b + 5 * (la.beam_diameter_m / np.maximum(z, 1e-9) + la.divergence_rad) / 2
    interior = np.r_[True, delta[1:] <= delta[:-1]] & np.r_[delta[:-1] <= delta[1:], True]
    idx = np.flatnonzero(interior & (z > 0) & (delta < reach))
    idx = idx[np.argsort(delta[idx])][:BIAS_CANDIDATES]
    return [(float(a[i] * s), float(c[i] * s)) for i in idx for s in (min(1.0, b / max(float(delta[i]), 1e-300)),)]


def _worst_over_bias(run: MotionRun, pr: PathResult, sample, summarise) -> SummarisedPath:
    """The track under the worst constant pointing bias within ``[laser]`` pointing buffer
    (a bias, not jitter: the beam may sit anywhere within its error, and a track passing
    within it may be crossed through the axis). ``sample()`` samples the path under
    ``run.bias_rad``; ``summarise(path)`` gives its summary. The nominal aim is one candidate
    (the first of equal ratios is kept); the summary then says the bias and the buffer."""
    b = run.scene.spec.laser.pointing_buffer_rad
    best = SummarisedPath.of(pr, summarise(pr))
    if b <= 0:
        return best
    for bias in _bias_candidates(run, pr, b):
        run.bias_rad = bias
        try:
            cand = sample()
        finally:
            run.bias_rad = (0.0, 0.0)
        s = summarise(cand)
        if s.exposure_ratio > best.summary.exposure_ratio:
            best = SummarisedPath.of(cand, s)
    bx, by = best.bias_rad
    return SummarisedPath.of(best, replace(best.summary, pointing_bias_rad=(bx, by), pointing_buffer_rad=b))


def _track_notes(run: MotionRun, tr, p: PathResult | None) -> list:
    """What a track's evaluation left out, said: times outside the analysed span
    (``[motion] time_start_s`` / ``time_end_s``), and samples under the terrain (the
    terrain blocks the beam there: a height in the wrong unit or datum would read safe)."""
    a, b = run.motion.t_start_s, run.motion.t_end_s
    if p is None:
        return [f"track {tr.name} ([{tr.span_s[0]:g}, {tr.span_s[1]:g}] s) lies outside the analysed span [{a:g}, {b:g}] s: "
                f"NOT evaluated"]
    out = []
    if tr.span_s[0] < a or tr.span_s[1] > b:
        out.append(f"track {tr.name}: only [{max(tr.span_s[0], a):g}, {min(tr.span_s[1], b):g}] s of its "
                   f"[{tr.span_s[0]:g}, {tr.span_s[1]:g}] s lie in the analysed span: the rest is NOT evaluated")
    terrain = run.scene.terrain
    if terrain is not None:
        x, y, z = p.positions_m.T
        inside = terrain.contains_xy(x, y)
        under = inside & (z < terrain.height_at(x, y))
        if under.any():
            out.append(f"track {tr.name}: {int(under.sum())} of {len(z)} samples lie under the terrain (first at t = "
                       f"{p.times_s[np.argmax(under)]:.6g} s), where the terrain blocks every beam: check its heights")
    return out


def _fixed_paths(run: MotionRun, notes) -> list[PathResult]:
    """The fixed observers' paths when the beam or a target moves."""
    obs = run.scene.observers
    m = len(obs) if obs is not None else 0
    if obs is None or not run.motion.beam_moves or m == 0:
        return []
    if m > FIXED_OBSERVERS_MAX:
        notes.append(f"the {m} fixed observers are not evaluated over time (more than {FIXED_OBSERVERS_MAX}): their verdicts "
                     f"are the static analysis's, with the beam held at any aim of the aim track (the direct stage)")
        return []
    pos, labels = obs.positions_m, obs.labels()
    out = []
    span = (run.motion.t_start_s, run.motion.t_end_s)
    for i in range(m):
        p = pos[i]
        optics = obs.optics[obs.group[i]]
        path = _sample_path(run, labels[i], int(obs.group[i]), "fixed",
                            lambda ts, p=p: np.broadcast_to(p, (len(np.atleast_1d(ts)), 3)).copy(), span, optics)
        if path is not None:  # never None: the span is the run's own
            out.append(path)
    return out


def _aperture_reach_m(scene, motion) -> float:
    """The largest radius [m] over which an eye or an aid of any path collects the direct
    beam (:mod:`hazard.physics.aperture`): the crossing refinement reaches that much farther."""
    from hazard.physics.aperture import observer_apertures

    optics = list(scene.observers.optics) + [tr.optics for tr in motion.tracks] + [None]  # None: the naked eye
    ap = observer_apertures(optics, np.arange(len(optics)), scene.spec.laser.wavelength_nm, scene.spec.exposure.duration_s)
    return ap.reach_m


def run_motion(scene, motion, first, states, history_times_s, mu, limits, backend, threads) -> MotionResult:
    """Evaluate every path (see the module notes). ``first``: (traced, tracer, ray_scene)
    of the static analysis; ``limits``: its :class:`~hazard.pipeline.limits.ExposureLimits`."""
    t_start = time.perf_counter()
    spec = scene.spec
    pulse = None if limits.pulse is None else limits.pulse.per_pulse_radiant_exposure_j_m2 * spec.laser.prf_hz
    run = MotionRun(scene, motion, mu, limits.irradiance_w_m2, pulse, states, np.asarray(history_times_s, float),
                    [], np.zeros(1), backend, threads, beam=first[0].beam)
    run.aperture_reach_m = _aperture_reach_m(scene, motion)
    grid = base_grid(motion, motion.t_start_s, motion.t_end_s)
    beam_states(run, grid, first)
    notes = []

    def summarise(p):
        return path_summary(p, spec.exposure.duration_s, spec.laser.wavelength_nm, spec.exposure.standard, pulse)

    paths = []
    for tr in motion.tracks:
        def sample(tr=tr):
            return _sample_path(run, tr.name, tr.group, "track", tr.at, tr.span_s, tr.optics)
        p = sample()
        notes += _track_notes(run, tr, p)
        if p is not None:
            paths.append(_worst_over_bias(run, p, sample, summarise))
    for p in _fixed_paths(run, notes):  # their pointing error is the static analysis's (the beam held anywhere in it)
        paths.append(SummarisedPath.of(p, summarise(p)))
    if spec.laser.pointing_buffer_rad > 0 and motion.tracks:
        notes.append(f"tracks under the worst constant pointing bias within {spec.laser.pointing_buffer_rad:.3g} rad (toward "
                     f"each track's closest approaches to the aim; reflections at the nominal aim)")
    if states and len(history_times_s) and _max_dwell(run) > history_times_s[-1]:
        notes.append(f"lased time beyond the history's end ({history_times_s[-1]:g} s): the last state is held")
    if math.isfinite(run.mpe_w_m2) and spec.laser.pulse_energy_j is not None:
        notes.append("pulsed laser: tracks take the average-power rule over every window and the per-pulse rule on the peak")
    return MotionResult(tuple(paths), (motion.t_start_s, motion.t_end_s), len(run.states_list), run.key_step_text, tuple(notes),
                        time.perf_counter() - t_start, run)


def _max_dwell(run: MotionRun) -> float:
    from hazard.pipeline.motion import lased_time_s

    return float(lased_time_s(run, np.array([run.motion.t_end_s]))[0])
