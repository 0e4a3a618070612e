"""The slump of a melting target: its surface normal over the analysis times.

Molten metal slumps under gravity and tilts the surface normal (Bailey et al., J. Laser
Appl. 20(1), 2008, Secs. V B 2 and VI A: the specular peak of melting stainless steel moves upward and
wanders). A target's material may declare it (``melt_tilt_deg``, ``melt_tilt_direction``,
``melt_wander_deg``, :class:`scenes.scene.Slump`):

- the mean normal tilts by ``theta(t) = melt_tilt x melt_fraction(t)`` towards the tilt
  direction (a rotation about ``n x d``); the irradiance map and the ground footprint use
  that tilted normal at each analysis time (:func:`slumped_irradiance`);
- once melting has begun the normal may wander anywhere within ``melt_wander`` of the mean
  one; the keep-out lobe covers the union over every normal the surface may take in each
  part of the history, paired with the states of that part (:func:`union_range_fn`). The
  union is sampled (tilts and wander rings every ``step_rad``); the lobe's report gives
  the change of its largest NOHD when the step is halved, the estimate of that sampling's
  error.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

__all__ = ["SpotSlump", "spot_slump", "held_slump", "slumped_irradiance", "union_range_fn", "rotation", "SLUMP_STEP_RAD"]

SLUMP_STEP_RAD = math.radians(2.0)  # default sampling step of the wander disk and tilt range [rad] ([analysis] slump_step_deg)


@dataclass(frozen=True)
class SpotSlump:
    """A spot's slump over the analysis times (T,): mean tilt and wander bound [rad]
    per time, the world rotation axis of the tilt, and the union's sampling step."""

    tilt_rad: np.ndarray
    wander_rad: np.ndarray
    axis: np.ndarray
    step_rad: float = SLUMP_STEP_RAD

    @property
    def moves(self) -> bool:
        return bool(np.any(self.tilt_rad > 0) or np.any(self.wander_rad > 0))


def rotation(axis, angle_rad: float) -> np.ndarray:
    """Rotation matrix (3, 3) by ``angle_rad`` about the unit ``axis`` (Rodrigues)."""
    k = np.asarray(axis, float)
    kx = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    return np.eye(3) + math.sin(angle_rad) * kx + (1.0 - math.cos(angle_rad)) * (kx @ kx)


def spot_slump(target, melt_fraction: np.ndarray, normal: np.ndarray, step_rad: float = SLUMP_STEP_RAD) -> SpotSlump | None:
    """The :class:`SpotSlump` of a target's spot from its melt fraction over the times
    (None when the target's material declares no slump). The wander bound applies in
    full from the first time any of the plate is molten (conservative)."""
    sl = target.slump
    if sl is None:
        return None
    f = np.clip(np.asarray(melt_fraction, float), 0.0, 1.0)
    axis = np.cross(normal, sl.direction)
    norm = np.linalg.norm(axis)
    axis = axis / norm if norm > 1e-12 else np.array(target.tangent, float)
    return SpotSlump(sl.tilt_rad * f, np.where(f > 0, sl.wander_rad, 0.0), axis, step_rad)


def _tilted(spot, angle_rad: float):
    """A copy of ``spot`` with every frame rotated by the tilt (no slump of its own)."""
    r = rotation(spot.slump.axis, angle_rad)
    return replace(spot, frames=spot.frames @ r.T, slump=None)


def held_slump(spot):
    """A slumping spot held in its initial state: its frames tilted by the slump at the
    first analysis time, no slump of its own (the static footprint evaluates the first
    state alone; :func:`slumped_irradiance` needs a state per analysis time)."""
    return _tilted(spot, float(spot.slump.tilt_rad[0]))


def slumped_irradiance(fn, spot, observers_m, gain, attenuation_per_m, states, visible=None, sparse=False):
    """``fn`` (:func:`hazard.physics.engine.spot_irradiance`) with the spot's normal tilted at
    each analysis time: times that share a tilt are evaluated together. Returns what
    ``fn`` returns; with ``sparse`` every row (the tilted spot may light any)."""
    tilt = spot.slump.tilt_rad
    states = np.asarray(states, float)
    if len(states) != len(tilt):
        raise RuntimeError(f"{spot.target.name}: {len(states)} states but a slump over {len(tilt)} times")
    m = len(np.asarray(observers_m))
    out, far = np.zeros((m, len(states))), np.zeros(m, bool)
    for angle in np.unique(tilt):
        idx = np.flatnonzero(tilt == angle)
        e, f = fn(_tilted(spot, float(angle)), observers_m, gain, attenuation_per_m, states[idx], visible)
        out[:, idx] = e
        far |= f
    return ((np.arange(m), out), far) if sparse else (out, far)


def _chunks(slump: SpotSlump) -> list:
    """Index ranges [a, b] of the times (sharing their ends, so the state path stays
    joined) over which the tilt changes by at most one step and the wander bound is one
    value (a range that must hold a change is two times long)."""
    tilt, wander, step = slump.tilt_rad, slump.wander_rad, slump.step_rad
    out, a = [], 0
    for j in range(1, len(tilt)):
        if abs(tilt[j] - tilt[a]) > step or wander[j] != wander[a]:
            end = j - 1 if j - 1 > a else j
            out.append((a, end))
            a = end
    if a < len(tilt) - 1 or not out:
        out.append((a, len(tilt) - 1))
    return out


def _disk_offsets(wander_rad: float, step_rad: float) -> list:
    """(radius, azimuth) samples of a disk of radius ``wander_rad``: the centre and
    rings every ``step_rad`` (the last on the rim) with arc spacing <= ``step_rad``."""
    if wander_rad <= 0:
        return [(0.0, 0.0)]
    rings = max(1, math.ceil(wander_rad / step_rad))
    pts = [(0.0, 0.0)]
    for i in range(1, rings + 1):
        r = wander_rad * i / rings
        n = max(6, math.ceil(2 * math.pi * r / step_rad))
        pts += [(r, 2 * math.pi * k / n) for k in range(n)]
    return pts


def normal_rotations(slump: SpotSlump, normal: np.ndarray, a: int, b: int, step_rad: float) -> np.ndarray:
    """World rotations (S, 3, 3) of the normals the surface may take over times [a, b]:
    tilts across the chunk's range every ``step_rad``, each with the wander disk."""
    lo, hi = float(slump.tilt_rad[a:b + 1].min()), float(slump.tilt_rad[a:b + 1].max())
    tilts = np.linspace(lo, hi, max(2, math.ceil((hi - lo) / step_rad) + 1)) if hi > lo else np.array([lo])
    e1 = slump.axis
    out = []
    for t in tilts:
        r_t = rotation(e1, float(t))
        n_t = r_t @ normal
        e2 = np.cross(n_t, e1)
        for r, az in _disk_offsets(float(slump.wander_rad[a:b + 1].max()), step_rad):
            out.append(rotation(math.cos(az) * e1 + math.sin(az) * e2, r) @ r_t if r > 0 else r_t)
    return np.array(out)


def union_range_fn(spot, states, range_of, path_states, step_rad=None):
    """A lobe function ``fn(wo) -> range [m]`` over directions in the spot's nominal frame:
    the max over the history's chunks of the max over the chunk's normals of
    ``range_of(wi', wo', chunk states)`` with both directions in the rotated frame.

    ``range_of(wi (S, 3), wo (S x N, 3), states)`` gives ranges (S x N,) for each rotated
    incidence repeated over the N directions; ``path_states(chunk states)`` adds what the
    material needs for an exact max over the chunk's path.
    """
    slump = spot.slump
    step = slump.step_rad if step_rad is None else step_rad
    frame = spot.mean_frame
    wi = frame @ (-spot.mean_incoming)
    parts = []
    for a, b in _chunks(slump):
        rots = normal_rotations(slump, frame[2], a, b, step)
        q = np.einsum("ij,sjk,lk->sil", frame, np.transpose(rots, (0, 2, 1)), frame)  # F R^T F^T
        parts.append((q, path_states(np.asarray(states)[a:b + 1])))

    def fn(wo):
        wo = np.asarray(wo, float)
        best = np.zeros(len(wo))
        for q, st in parts:
            wi_k = q @ wi  # (S, 3)
            wo_k = np.einsum("sij,nj->sni", q, wo).reshape(-1, 3)
            r = range_of(np.repeat(wi_k, len(wo), axis=0), wo_k, st).reshape(len(q), len(wo))
            best = np.maximum(best, r.max(axis=0))
        return best

    fn.samples = sum(len(q) for q, _ in parts)
    # the mirror directions of the mean tilted normals (above the nominal horizon): the
    # lobe splits the cells that hold them, as it does for the nominal mirror direction
    mirrors = []
    for t in np.unique(slump.tilt_rad):
        q = frame @ rotation(slump.axis, float(t)).T @ frame.T
        m = q.T @ (q @ wi * np.array([-1.0, -1.0, 1.0]))
        if m[2] > 1e-9:
            mirrors.append(m / np.linalg.norm(m))
    fn.special = np.array(mirrors).reshape(-1, 3)
    return fn
