"""Time steps of a moving path (:mod:`hazard.pipeline.motion`, see its notes): the a-priori
refinement near beam axes and the a-posteriori refinement where the irradiance changes
fast."""

from __future__ import annotations

import math

import numpy as np

from hazard.physics.engine import mirror_axis
from scenes.motion import samples_max

from hazard.pipeline.motion import CROSSING_REACH, MIN_STEP_S, REFINE_PASSES, REL_CHANGE

__all__ = ["axes_at", "crossing_times", "refine_by_change"]


def axes_at(run, t) -> list:
    """The beam axes at times ``t``: (origin (N, 3), unit axis (N, 3), 1/e radius at axial
    distance z as a function, range already travelled [m]) for the direct beam and every
    mirror beam of the beam states the times take (flat-mirror widths: a narrower
    estimate than a convex mirror's, so the refinement is not coarser than it needs)."""
    la = run.scene.spec.laser
    a, phi = la.beam_diameter_m, la.divergence_rad
    o = np.broadcast_to(np.asarray(run.scene.laser_position_m, float), (len(t), 3))
    out = [(o, run.direction(t), np.zeros(len(t)))]
    k = run.state_index(t)
    n_mirrors = max((sum(sp.material.has_specular for sp in bs.spots) for bs in run.states_list), default=0)
    for m in range(n_mirrors):
        org, ax, pre = np.full((len(t), 3), np.nan), np.full((len(t), 3), np.nan), np.zeros(len(t))
        for i, bs in enumerate(run.states_list):
            mirrors = [sp for sp in bs.spots if sp.material.has_specular]
            rows = k == i
            if m < len(mirrors) and rows.any():
                sp = mirrors[m]
                org[rows], ax[rows] = sp.centroid, mirror_axis(sp)
                pre[rows] = np.linalg.norm(sp.centroid - run.scene.laser_position_m)
        out.append((org, ax, pre))
    return [(org, ax, (lambda z, pre=pre: (a + (pre + np.maximum(z, 0.0)) * phi) / 2)) for org, ax, pre in out]


def _reach_span(r0, dr, reach) -> tuple[float, float] | None:
    """Fraction range [ta, tb] of a step where |r0 + tau dr| <= reach (None: never)."""
    aa = float(dr @ dr)
    bb = 2.0 * float(r0 @ dr)
    cc = float(r0 @ r0) - reach * reach
    if aa <= 0:
        return (0.0, 1.0) if cc <= 0 else None
    disc = bb * bb - 4 * aa * cc
    if disc < 0:
        return None
    sq = math.sqrt(disc)
    ta, tb = max((-bb - sq) / (2 * aa), 0.0), min((-bb + sq) / (2 * aa), 1.0)
    return (ta, tb) if tb > ta else None


def crossing_times(run, path_at, t, samples_per_width: int) -> np.ndarray:
    """Extra times for a path (``path_at(t)`` -> positions) on grid ``t``: within reach of
    each beam axis, a step of w / (n |dr/dt|) (see the module notes of
    :mod:`hazard.pipeline.motion`)."""
    p = path_at(t)
    extra = []
    for org, ax, width in axes_at(run, t):
        rel = p - org
        z = np.einsum("ij,ij->i", rel, ax)
        r = rel - z[:, None] * ax
        w = width(z)
        ok = np.isfinite(z) & (z > 0)
        seg = np.flatnonzero(ok[:-1] & ok[1:])
        dr = r[seg + 1] - r[seg]
        wmin = np.minimum(w[seg], w[seg + 1])
        reach = CROSSING_REACH * wmin + run.aperture_reach_m  # an aperture collects the beam from that far beside it
        # closest approach of the (linear) transverse offset within each step
        tau = np.clip(-np.einsum("ij,ij->i", r[seg], dr) / np.maximum(np.einsum("ij,ij->i", dr, dr), 1e-300), 0, 1)
        dmin = np.linalg.norm(r[seg] + tau[:, None] * dr, axis=1)
        for j in np.flatnonzero(dmin < reach):
            span = _reach_span(r[seg[j]], dr[j], reach[j])
            if span is None:
                continue
            k = seg[j]
            n = int(math.ceil(np.linalg.norm(dr[j]) * (span[1] - span[0]) * samples_per_width / wmin[j]))
            if n < 1:
                continue
            if n > samples_max():
                raise ValueError(f"motion: crossing a beam at t = {t[k]:.6g} s needs {n} samples (the limit is {samples_max()}, "
                                 f"HAZARD_MAX_MOTION_SAMPLES); lower motion.samples_per_width or time_step_s")
            extra.append(t[k] + (t[k + 1] - t[k]) * np.linspace(span[0], span[1], n + 1))
    return np.concatenate(extra) if extra else np.empty(0)


def refine_by_change(t, parts, evaluate, floor_w_m2: float) -> tuple[np.ndarray, np.ndarray, int]:
    """Halve the steps where the total irradiance of neighbours differs by more than
    ``REL_CHANGE`` (and either is above ``floor_w_m2``), ``REFINE_PASSES`` times.
    ``parts`` (2, N): direct and reflected E at ``t``; ``evaluate(times)`` gives them at
    new times. Returns the times, the parts and the passes that found steps to halve."""
    passes = 0
    for _ in range(REFINE_PASSES):
        e = parts.sum(axis=0)
        hi = np.maximum(e[1:], e[:-1])
        big = (np.abs(e[1:] - e[:-1]) > REL_CHANGE * hi) & (hi > floor_w_m2) & (np.diff(t) > 2 * MIN_STEP_S)
        idx = np.flatnonzero(big)
        if not len(idx) or len(t) + len(idx) > samples_max():
            break
        passes += 1
        tm = 0.5 * (t[idx] + t[idx + 1])
        t = np.concatenate([t, tm])
        parts = np.concatenate([parts, np.asarray(evaluate(tm))], axis=1)
        order = np.argsort(t, kind="stable")
        t, parts = t[order], parts[:, order]
    return t, parts, passes
