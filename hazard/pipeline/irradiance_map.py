"""Stages ``line_of_sight``, ``static`` | ``dynamic`` and ``exposure``: the irradiance
map E(observer, t) and what each observer's history means.

The map runs in blocks of observers side by side on threads; each block does its own
line of sight, irradiance (one basis evaluation and one matrix product per spot) and
exposure, so those three stages report their share of the map's wall time.

Exposure (spec `laser-safety.md` section 4): per observer the peak irradiance; the
radiant exposure over the exposure duration as a sliding-window maximum of the integral
of E; and the first time at which the accumulated exposure exceeds the MPE for that
elapsed time. "Static" holds the material's initial state for the whole window.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from brdfmodels.parallel import block_rows, map_blocks

from hazard.physics import mpe as _mpe
from hazard.physics import near_field as _near
from hazard.physics import specular as _specular
from hazard.physics.engine import spot_irradiance, spot_line_of_sight, specular_irradiance

__all__ = ["MapInputs", "MapOutputs", "irradiance_map", "spot_line_of_sight", "sliding_max_integral", "HISTORY_KEEP_MAX", "MAP_CHUNK"]

HISTORY_KEEP_MAX = 20_000_000  # observer x time values kept in memory by default (160 MB)
MAP_CHUNK = 32768  # observers per block of the map (measured with 2 threads: 4096 0.48-0.59 s, 16384 0.36, 32768-131072 0.31-0.33)


@dataclass
class MapInputs:
    """What the map needs: the spots, their states over ``times_s`` (target index ->
    states; empty for a static map), the observers (``points.block(a0, a1)``: their
    positions [m], generated per block: scenes.observers) and optical gains,
    attenuation [1/m], the exposure (duration [s], wavelength [nm], standard, MPE
    [W/m^2]), the ray scene for lines of sight (None: every line is clear) and how to run.
    """

    spots: list
    beam: object
    states: dict
    times_s: np.ndarray
    points: object
    gain: np.ndarray
    attenuation_per_m: float
    duration_s: float
    wavelength_nm: float
    standard: str
    mpe_w_m2: float
    ray_scene: object | None
    keep_history: bool
    threads: int
    chunk: int = MAP_CHUNK
    direct_w_m2: np.ndarray | None = None  # the laser's own beam at each observer (constant in time), added to the map
    pulse_limit_w_m2: float | None = None  # pulsed: per-pulse MPE x PRF (the first pulse above it is an exceedance)
    apertures: object | None = None  # hazard.physics.aperture.Apertures per observer: flat mirrors' beams through them (None: point x gain)
    uv_day_limit_j_m2: float | None = None  # 180-400 nm: the day's summed-dose limit (hazard.pipeline.limits.uv_24h_limit)


@dataclass
class MapOutputs:
    """Per observer: irradiance at t = 0 and peak [W/m^2], time of the peak [s], radiant
    exposure [J/m^2], first exceedance [s] (NaN: none), far-field flag, peak of the mirror
    lobes alone [W/m^2]; per spot and observer the line of sight; the history (M, T) if
    kept; and the seconds spent on lines of sight and on exposure (per-thread shares)."""

    static_w_m2: np.ndarray
    peak_w_m2: np.ndarray
    peak_time_s: np.ndarray
    exposure_j_m2: np.ndarray
    first_exceedance_s: np.ndarray
    far_field: np.ndarray
    specular_w_m2: np.ndarray
    line_of_sight: np.ndarray
    history_w_m2: np.ndarray | None
    los_segments: int = 0
    los_seconds: float = 0.0
    exposure_seconds: float = 0.0
    map_seconds: float = 0.0
    chunk: int = 0  # observers per block
    near_field: dict = field(default_factory=dict)  # hazard.physics.near_field counts of this map
    apertures: dict = field(default_factory=dict)  # hazard.physics.specular.aperture_stats_since: mirror beams averaged over apertures
    workers: int = 1
    segments: list = field(default_factory=list)


def sliding_max_integral(times, e, window):
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


class _Exposure:
    """Peak, exposure and first exceedance of rows of E(t) (the MPE for each elapsed time
    from :func:`hazard.physics.mpe.ocular_mpe`; no exceedance is possible below ``e_floor``)."""

    def __init__(self, inp: MapInputs, out: MapOutputs):
        self.times, self.t_exp, self.mpe_w_m2, self.out = inp.times_s, inp.duration_s, inp.mpe_w_m2, out
        self.pulse_limit = inp.pulse_limit_w_m2
        times = self.times
        if len(times) > 1:
            self.span = times[-1] - times[0]
            self.trap = np.zeros(len(times))
            self.trap[1:] += 0.5 * np.diff(times)
            self.trap[:-1] += 0.5 * np.diff(times)
            elapsed = np.clip(times[1:] - times[0], _mpe.DURATION_MIN_S, _mpe.DURATION_MAX_S)
            self.mpe_h_t = np.array([_mpe.ocular_mpe(inp.wavelength_nm, t, standard=inp.standard).radiant_exposure_j_m2
                                     for t in elapsed])
            if inp.uv_day_limit_j_m2 is not None:  # UV: no part of the day's dose may exceed the day's limit
                self.mpe_h_t = np.minimum(self.mpe_h_t, inp.uv_day_limit_j_m2)
            self.e_floor = float(np.min(self.mpe_h_t / np.maximum(times[1:] - times[0], 1e-300)))

    def post(self, ec, rows):
        out, times = self.out, self.times
        idx = ec.argmax(axis=1)
        pk = ec[np.arange(ec.shape[0]), idx]
        out.peak_w_m2[rows], out.peak_time_s[rows], out.static_w_m2[rows] = pk, times[idx], ec[:, 0]
        if len(times) == 1:
            out.exposure_j_m2[rows] = ec[:, 0] * self.t_exp
            out.first_exceedance_s[rows] = np.where(ec[:, 0] > self.mpe_w_m2, times[0], np.nan)
            return
        out.exposure_j_m2[rows] = ec @ self.trap if self.t_exp >= self.span else sliding_max_integral(times, ec, self.t_exp)
        hot = np.flatnonzero(pk >= self.e_floor)
        if len(hot):
            eh = ec[hot]
            cum = np.cumsum(0.5 * (eh[:, 1:] + eh[:, :-1]) * np.diff(times), axis=1)
            over = cum > self.mpe_h_t
            anyo = over.any(axis=1)
            out.first_exceedance_s[rows[hot[anyo]]] = times[1 + over.argmax(axis=1)[anyo]]
        if self.pulse_limit is not None:
            self._first_pulse_over(ec, pk, rows)

    def _first_pulse_over(self, ec, pk, rows):
        """Pulsed lasers: the first time a pulse's exposure E(t) / PRF reaches the per-pulse
        MPE (rules 1 and 3 for the whole train, as the hazard ratio uses it), if earlier
        than the average rule's exceedance."""
        out = self.out
        hit = np.flatnonzero(pk >= self.pulse_limit)
        if not len(hit):
            return
        t_pulse = self.times[(ec[hit] >= self.pulse_limit).argmax(axis=1)]
        current = out.first_exceedance_s[rows[hit]]
        out.first_exceedance_s[rows[hit]] = np.where(np.isnan(current), t_pulse, np.minimum(current, t_pulse))


class _MapRun:
    """One map: blocks of observers write disjoint rows of the outputs, so they run on
    threads (NumPy, BLAS and Embree release the GIL)."""

    def __init__(self, inp: MapInputs):
        m, n_t = len(inp.points), len(inp.times_s)
        self.inp = inp
        self.out = MapOutputs(np.zeros(m), np.zeros(m), np.zeros(m), np.zeros(m), np.full(m, np.nan), np.zeros(m, bool),
                              np.zeros(m), np.ones((len(inp.spots), m), bool), np.zeros((m, n_t)) if inp.keep_history else None)
        self.exposure = _Exposure(inp, self.out)
        self.dynamic = bool(inp.states)
        self.one_spot = len(inp.spots) == 1 and not inp.spots[0].material.has_specular

    def line_of_sight(self, sl, p):
        """Line of sight from each spot to observers ``sl`` at ``p``: one occlusion query per
        spot. Far-field observers behind a spot's surface receive nothing whatever is in
        between (the map evaluates them with the mean frame): no ray needed. Returns seconds."""
        t0 = time.perf_counter()
        n_seg = 0
        for k, sp in enumerate(self.inp.spots):
            self.out.line_of_sight[k, sl], n = spot_line_of_sight(self.inp.ray_scene, sp, p)
            n_seg += n
        self.out.segments.append(n_seg)  # list.append is atomic: blocks run on threads
        return time.perf_counter() - t0

    def _spot_rows(self, k, sp, sl, p):
        """Irradiance of one spot at observers ``sl`` at ``p``: (rows x T) or (rows,)."""
        inp, out = self.inp, self.out
        sk = inp.states.get(sp.target.index) if self.dynamic else None
        los = out.line_of_sight[k, sl]
        e, far = spot_irradiance(sp, p, inp.gain[sl], inp.attenuation_per_m, sk, los)
        out.far_field[sl] |= far
        if sp.material.has_specular:
            # each observer's line of sight from its own reflection point (not the spot's)
            ap = None if inp.apertures is None else inp.apertures.take(np.arange(sl.start, sl.stop))
            es = specular_irradiance(sp, p, inp.gain[sl], inp.attenuation_per_m, inp.beam, sk, ap, ray_scene=inp.ray_scene)
            out.specular_w_m2[sl] = np.maximum(out.specular_w_m2[sl], es if es.ndim == 1 else es.max(axis=1))
            e = e + es
        return e

    def _with_direct(self, ev, rows, sl):
        """Add the direct beam to the rows the spot reaches, and give the rows only the
        direct beam reaches their own (constant) history."""
        direct = self.inp.direct_w_m2
        if direct is None or not direct[sl].any():
            return ev, rows
        extra = np.setdiff1d(sl.start + np.flatnonzero(direct[sl] > 0), rows)
        ev = np.concatenate([ev + direct[rows, None], np.broadcast_to(direct[extra, None], (len(extra), ev.shape[1]))])
        return ev, np.concatenate([rows, extra])

    def block(self, a0, a1):
        """Line of sight, irradiance and exposure of observers [a0, a1); returns the
        seconds spent on line of sight and on exposure."""
        inp, out, sl = self.inp, self.out, slice(a0, a1)
        p = inp.points.block(a0, a1)  # generated here, in this block's thread
        t_los = self.line_of_sight(sl, p) if inp.ray_scene is not None else 0.0
        if self.one_spot:  # only observers the spot reaches are evaluated
            sp = inp.spots[0]
            sk = inp.states.get(sp.target.index) if self.dynamic else None
            (live, ev), far = spot_irradiance(sp, p, inp.gain[sl], inp.attenuation_per_m, sk,
                                              out.line_of_sight[0, sl], sparse=True)
            out.far_field[sl] = far
            ev, rows = (ev if ev.ndim == 2 else ev[:, None]), sl.start + live
            ev, rows = self._with_direct(ev, rows, sl)
        else:
            ev = np.zeros((a1 - a0, len(inp.times_s)))
            for k, sp in enumerate(inp.spots):
                e = self._spot_rows(k, sp, sl, p)
                ev += e if e.ndim == 2 else e[:, None]
            rows = np.arange(a0, a1)
            if inp.direct_w_m2 is not None and inp.direct_w_m2[sl].any():
                ev += inp.direct_w_m2[sl, None]
        if out.history_w_m2 is not None:
            out.history_w_m2[rows] = ev
        t0 = time.perf_counter()
        self.exposure.post(ev, rows)
        return t_los, time.perf_counter() - t0


def irradiance_map(inp: MapInputs) -> MapOutputs:
    """E(observer, t) summed over the spots, with lines of sight and exposure, in blocks."""
    run = _MapRun(inp)
    m = len(inp.points)
    chunk = block_rows(len(inp.times_s), inp.chunk)  # long histories: fewer observers per block
    workers = max(1, min(inp.threads, -(-m // chunk)))
    t0, before, ap_before = time.perf_counter(), _near.STATS.snapshot(), _specular.APERTURE_STATS.snapshot()
    parts = map_blocks(run.block, m, chunk, workers)
    run.out.near_field = _near.stats_since(before)
    run.out.apertures = _specular.aperture_stats_since(ap_before)
    out = run.out
    out.map_seconds = time.perf_counter() - t0
    # per-thread shares of the wall time (the parts ran side by side on the workers)
    out.los_seconds, out.exposure_seconds = (sum(p[i] for p in parts) / workers for i in (0, 1))
    out.los_segments, out.chunk, out.workers = sum(out.segments), chunk, workers
    return out
