"""What the benchmarks share: the quick switch, the median-of-5 timer, the goal check, and
the complete floor of the irradiance map written by hand (raw embreex, the basis kernel,
BLAS, exp, exposure), for ``bench_engine`` and ``bench_whole_run``.

``BENCH_QUICK=1`` (``.ci/run``): small sizes and the quick goals, which leave room for
a loaded 2-core CI machine (each set from the spread measured under load; see the README's
benchmark section). Without it: the issues' sizes and goals.
"""

from __future__ import annotations

import contextlib
import math
import os
import statistics
import time
from concurrent.futures import ThreadPoolExecutor

import numpy as np
from threadpoolctl import threadpool_limits

QUICK = os.environ.get("BENCH_QUICK", "0").strip() not in ("", "0")
REPEAT = 5  # every time [s] is the median of 5 runs, the real path's and its floor's alike
MAP_BLOCK = 32768  # observers per block, as the map's (hazard.pipeline.irradiance_map.MAP_CHUNK)
BRDF_BLOCK = 1 << 18  # (row, state) values per BRDF call, as the near field's kernel batches them (hazard.physics.near_field._NODE_BLOCK)


def median_s(fn, repeat=REPEAT):
    """Median wall time [s] of ``repeat`` calls of ``fn``, and its last result."""
    times, out = [], None
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times), out


def cpu_s(fn):
    """CPU time [s] of one call of ``fn`` (``time.process_time``: every thread of this
    process, so a shared machine's load does not enter), and its result."""
    t0 = time.process_time()
    out = fn()
    return time.process_time() - t0, out


@contextlib.contextmanager
def map_cpu():
    """Record the CPU time [s] of every irradiance map made inside (the map stages:
    ``line_of_sight``, ``static`` | ``dynamic``, ``exposure``) in the yielded list, plus
    that of generating the observers' points it reads when they were made before it
    (:meth:`scenes.observers.Observers.keep_points`, before the direct beam: the floor
    makes them too). A scene analysed again keeps its points: time fresh scenes."""
    from hazard.pipeline import irradiance_map as module
    from scenes.observers import Observers

    made, real, real_keep, pending = [], module.irradiance_map, Observers.keep_points, [0.0]

    def keep(self, *args, **kwargs):
        t, out = cpu_s(lambda: real_keep(self, *args, **kwargs))
        pending[0] += t
        return out

    def timed(inp):
        t, out = cpu_s(lambda: real(inp))
        made.append(t + pending[0])
        pending[0] = 0.0
        return out

    module.irradiance_map, Observers.keep_points = timed, keep
    try:
        yield made
    finally:
        module.irradiance_map, Observers.keep_points = real, real_keep


def blas_one_thread():
    """BLAS on one thread (threadpoolctl) while timing CPU: the protocol of issue 37's
    figures (``OPENBLAS_NUM_THREADS=1``) whatever the environment says."""
    return threadpool_limits(1, user_api="blas")


RESULTS: list = []  # (name, ratio, goal) of every check this session: tests/bench/conftest.py prints them


def check_goal(name: str, ratio: float, goal: float) -> None:
    """Assert ``ratio`` (time / floor) <= ``goal``, saying both and the mode."""
    RESULTS.append((name, float(ratio), float(goal)))
    assert np.isfinite(ratio) and ratio > 0, f"{name}: ratio {ratio!r} is not a positive number"
    mode = "quick (BENCH_QUICK=1)" if QUICK else "full"
    assert ratio <= goal, f"{name}: time / floor = {ratio:.3f} > goal {goal:g} ({mode})"


class RawEmbree:
    """The scene's triangles in one embreex scene, queried directly (no wrapper)."""

    def __init__(self, meshes):
        from embreex import mesh_construction, rtcore_scene

        v = np.concatenate([m[0] for m in meshes]).astype(np.float32)
        offsets = np.cumsum([0] + [len(m[0]) for m in meshes[:-1]])
        f = np.concatenate([m[1] + o for m, o in zip(meshes, offsets)]).astype(np.int32)
        self.scene = rtcore_scene.EmbreeScene()
        self.mesh = mesh_construction.TriangleMesh(self.scene, v, f)
        self.scale_m = float(np.ptp(v, axis=0).max())

    def occluded(self, start, end):
        """True where the segment start -> end (its last 1e-6 of the scene size left out) is blocked."""
        vec = end - start
        length = np.sqrt(np.einsum("ij,ij->i", vec, vec))
        frac = 1.0 - 1e-6 * self.scale_m / np.maximum(length, 1e-300)
        res = self.scene.run(start.astype(np.float32), vec.astype(np.float32), dists=frac.astype(np.float32), query="OCCLUDED")
        return res == 0


class MapFloor:
    """The complete floor of the irradiance map of one flat dynamic-SH target: per block of
    observers (on as many threads as the map, BLAS on one thread each) the points, the
    occlusion query from the spot, the directions in the target's frame, the basis, one
    GEMM with the (ln gain - ln cos i) row, exp, the peak and its time, the value at
    t = 0, the exposure (trapezoid over the history) and the first exceedance (the
    accumulated exposure against the MPE of each elapsed time, on the rows whose peak
    could exceed it). Everything the map computes and nothing else; no checks, no near
    field, no sparse bookkeeping."""

    def __init__(self, scene, material, times_s, tracer, threads=None, keep_points=False):
        from brdfmodels.states import interpolation_weights

        self.part = scene.observers.parts[0]
        assert len(scene.observers.parts) == 1, "the floor is written for one observer grid"
        t = scene.targets[0]
        self.centre = np.asarray(t.center_m, float)
        n = np.asarray(t.normal, float) / np.linalg.norm(t.normal)
        u = np.asarray(t.tangent, float)
        u = u - (u @ n) * n
        u /= np.linalg.norm(u)
        self.frame = np.array([u, np.cross(n, u), n])  # rows: tangent, bitangent, normal
        to_laser = np.asarray(scene.spec.laser.position_m, float) - self.centre
        self.wi = self.frame @ (to_laser / np.linalg.norm(to_laser))
        self.start = self.centre + 1e-3 * n
        self.power_w = float(scene.spec.laser.power_w)
        self.basis, self.fanout = material.basis, material.fanout
        k = self.basis.size
        coef = material.coefficients.reshape(-1, k).T @ interpolation_weights(material.states, states_at(scene, times_s))
        self.coef = np.vstack([coef, np.ones((1, coef.shape[1]))])
        times = np.asarray(times_s, float)
        self.trap = np.zeros(len(times))
        self.trap[1:] += 0.5 * np.diff(times)
        self.trap[:-1] += 0.5 * np.diff(times)
        self.times, self.half_dt = times, 0.5 * np.diff(times)
        self.mpe_h_j_m2, self.e_floor_w_m2 = mpe_of_elapsed(scene, times)
        self.tracer = tracer
        self.n = len(scene.observers)
        self.threads = threads or min(2, os.cpu_count() or 1)
        self.peak = np.zeros(self.n)
        self.peak_time = np.zeros(self.n)
        self.static = np.zeros(self.n)
        self.exposure = np.zeros(self.n)
        self.first = np.full(self.n, np.nan)
        self.points = np.empty((self.n, 3)) if keep_points else None  # kept for the direct beam and the subtense (as the real path keeps them)

    def block(self, a0, a1):
        from brdfmodels.geometry import half_diff_parts

        p = self.part.at(np.arange(a0, a1))
        if self.points is not None:
            self.points[a0:a1] = p
        d = p - self.centre
        r = np.sqrt(np.einsum("ij,ij->i", d, d))
        wo = (d / r[:, None]) @ self.frame.T
        live = np.flatnonzero(wo[:, 2] > 0)
        live = live[~self.tracer.occluded(np.broadcast_to(self.start, (len(live), 3)), p[live])]
        m, k = len(live), self.basis.size
        y = np.empty((k + 1, m))
        wo_l = wo[live]
        self.basis.design_transposed(*half_diff_parts(np.broadcast_to(self.wi, (m, 3)), wo_l), self.fanout, self.fanout, out=y[:k])
        # the row factor in the exponent: P cos_o / r^2 (a point source's gain) over cos i
        y[k] = math.log(self.power_w) + np.log(wo_l[:, 2]) - 2.0 * np.log(r[live]) - math.log(self.wi[2])
        ev = y.T @ self.coef
        np.exp(ev, out=ev)
        idx = ev.argmax(axis=1)
        rows = a0 + live
        pk = ev[np.arange(m), idx]
        self.peak[rows], self.peak_time[rows], self.static[rows] = pk, self.times[idx], ev[:, 0]
        self.exposure[rows] = ev @ self.trap
        hot = np.flatnonzero(pk >= self.e_floor_w_m2)
        if len(hot):
            cum = ev[hot, 1:] + ev[hot, :-1]
            cum *= self.half_dt
            over = np.cumsum(cum, axis=1, out=cum) > self.mpe_h_j_m2
            some = over.any(axis=1)
            self.first[rows[hot[some]]] = self.times[1 + over[some].argmax(axis=1)]

    def __call__(self):
        bounds = [(a, min(a + MAP_BLOCK, self.n)) for a in range(0, self.n, MAP_BLOCK)]
        with threadpool_limits(1, user_api="blas"), ThreadPoolExecutor(self.threads) as pool:
            list(pool.map(lambda ab: self.block(*ab), bounds))
        return self.peak


def brdf_blocked(material, wi, wo, states, row_scale=None, reduce=None, group=1, post=None):
    """``projected_brdf`` at rows ``wo`` (N, 3) and ``states`` (T,) in calls of at most
    :data:`BRDF_BLOCK` (row, state) values, whole groups of ``group`` rows each (as the
    real path blocks its evaluations: one huge call is memory-bound and unsteady, 0.79-1.27 s
    CPU for 2.3e7 values against a steady 0.72 s in blocks), each block's values handed to
    ``post`` (the reduction the real path makes of them). Returns the rows evaluated."""
    from hazard.physics.engine import projected_brdf

    k = 1 if states is None else len(states)
    step = max(group, (BRDF_BLOCK // max(k, 1)) // group * group)
    for a in range(0, len(wo), step):
        b = min(len(wo), a + step)
        f = projected_brdf(material, wi[a:b], wo[a:b], states, None if row_scale is None else row_scale[a:b], reduce)
        if post is not None:
            post(f)
    return len(wo)


def mpe_of_elapsed(scene, times_s):
    """The MPE radiant exposure [J/m^2] for each elapsed time of the history after the
    first, and the smallest irradiance [W/m^2] that can reach it (rows below it need no
    accumulation): the map's inputs of its first exceedance, made once."""
    from hazard.physics.mpe import DURATION_MAX_S, DURATION_MIN_S, ocular_mpe

    spec = scene.spec
    elapsed = np.asarray(times_s[1:], float) - times_s[0]
    h = np.array([ocular_mpe(spec.laser.wavelength_nm, t, standard=spec.exposure.standard).radiant_exposure_j_m2
                  for t in np.clip(elapsed, DURATION_MIN_S, DURATION_MAX_S)])
    return h, float(np.min(h / np.maximum(elapsed, 1e-300)))


def states_at(scene, times_s):
    """The target's state at each time of the history (a linear series)."""
    h = scene.spec.targets[0].history
    return np.interp(times_s, h.times_s, h.states)
