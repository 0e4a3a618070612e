"""Near field of an extended spot: the exact integral over the spot's irradiance.

Spec `range-safety.md` section 10 ("Near field of an extended diffuse spot"): an observer
within a few spot lengths receives

    E = integral over the spot of f_r(wi, wo) cos(theta_r) exp(-mu R) / R^2 dP(x),

with ``dP`` the power landing on the surface element at ``x`` (the incident Gaussian beam
with its footprint stretched by the incidence, clipped by the target's outline) and
``theta_o`` taken as 0 at the eye (worst case). Summing the spot's coarse samples as
point sources (the engine before this module) puts a grazing spot, ``D / cos(i)`` long,
into a few points ``~D / (16 cos(i))`` apart: an observer close beside it got up to
hundreds of times too little.

How it is integrated. The spot is cut into *patches*: the beam's leaf cells (squares in
the beam's transverse coordinates ``s``, units of the 1/e radius) or, for flat targets
hit whole, the exact outline pieces (convex polygons in ``s``), each split into
triangles. In ``s`` the power density is ``c exp(-|s|^2)`` (``c`` makes each patch carry
its exact power) and each triangle maps onto the surface as the beam's rays map it: for
a diverging beam every ray leaves the virtual point source, so the point with
barycentric weights ``l`` in ``s`` lands at ``sum l_i g_i x_i / sum l_i g_i``, ``g_i`` the
inverse of vertex ``i``'s distance from the source along the axis (perspective-correct
interpolation, exact on a flat target or a leaf's tangent plane; ``g`` is affine in
``s``); a collimated beam has equal ``g`` (the affine map). Before, the map was affine
for every beam: a plate at 89.99 deg 200 m from a 0.1 mrad laser, whose rays' grazing
angles differ by 30 % across the beam, got 0.88-1.22 x the integral along its spot. For
each (observer, sample) pair:

* the sample as one point source (its power centroid) when the Taylor remainder of the
  Lambertian kernel ``n.y / |y|^3`` proves the error below ``NEAR_FIELD_RTOL`` of
  ``P / d^2``: ``|Hessian| <= 24 / r^4`` gives ``12 a^2 d^2 / (d - a)^4 <= rtol`` with
  ``a`` the sample's radius on the surface and ``d`` the observer's distance;
* otherwise its triangles with a 7-point degree-5 rule (Dunavant) where the observer is
  at least ``RULE_REACH`` triangle radii away (measured over random triangles and
  directions: error <= 4e-5 of the triangle's ``P / d^2`` for the Lambertian kernel),
  and bisection of the triangle's longest edge on the surface elsewhere (a long thin
  spot is split along its length only), down to ``MAX_DEPTH`` bisections (pairs still
  unresolved there are counted in :data:`STATS`).

Observers behind a triangle's plane (in the sample's material frame) receive nothing
from it and are dropped before any split. The bound is for the Lambertian kernel; a
glossy lobe narrower than the spot's angular size seen from the observer is resolved
by the same splits only as far as ``RULE_REACH`` resolves it (not proven).
"""

from __future__ import annotations

import math
import threading
import time
from contextlib import contextmanager
from dataclasses import dataclass
from functools import cached_property

import numpy as np

__all__ = ["SpotPatches", "patches_from_leaves", "patches_from_pieces", "near_field_irradiance", "point_form_ok",
           "stats_since", "describe", "leaf_corners_s", "perspective_weights", "point_triangle_distance", "NEAR_FIELD_RTOL",
           "RULE_REACH", "MAX_DEPTH", "STATS", "BOUNDED", "shared_subdivisions"]

NEAR_FIELD_RTOL = 1e-2  # point form of a sample: error <= this x P / d^2 (as FAR_FIELD_SPOT_SIZES for the whole spot)
RULE_REACH = 3.0  # the 7-point rule on a triangle only from >= this many triangle radii (error <= 4e-5 P / d^2, measured)
MOMENT_LEVEL = 3  # the point form's centroid and spread: the 7-point rule on 4**this sub-triangles of each triangle
# a triangle whose perspective weights differ by at most this (relative) gets the 7-point rule on itself, not on
# 4**MOMENT_LEVEL sub-triangles: the map is affine within it to that order (its nodes move by at most this x the
# triangle's size, the point form's 1/R^2 by at most ~4 x this where the point form applies), and the rule
# integrates the Gaussian over a triangle small beside the beam. On a sphere lit by a diverging beam 90 % of the
# triangles are below it (ratio - 1: median 6e-6, 99th percentile 1.3e-4); the sub-triangles cost 1.2 s per spot
MOMENT_AFFINE_RTOL = 1e-5
MAX_DEPTH = 40  # bisections of a triangle at most (its area / 1e12)
BOUND_DEPTH = 4  # with a bound of f_r cos (fr_bound_per_sr): bisections before the unresolved pairs are bounded
_NODE_BLOCK = 1 << 18  # quadrature nodes evaluated at once (bounded memory)
_PAIR_BLOCK = 1 << 17  # (observer, sample or triangle) pairs formed at once
_TREE_NODES = 1 << 16  # shared bisections (_Subdivision, 426 bytes a node, ~56 MB doubled) start afresh past this many (between blocks)

# Dunavant degree-5 rule on a triangle: barycentric nodes and weights (sum 1)
_A1, _B1, _W1 = 0.059715871789770, 0.470142064105115, 0.132394152788506
_A2, _B2, _W2 = 0.797426985353087, 0.101286507323456, 0.125939180544827
RULE_BARY = np.array([[1 / 3, 1 / 3, 1 / 3],
                      [_A1, _B1, _B1], [_B1, _A1, _B1], [_B1, _B1, _A1],
                      [_A2, _B2, _B2], [_B2, _A2, _B2], [_B2, _B2, _A2]])
RULE_W = np.array([0.225, _W1, _W1, _W1, _W2, _W2, _W2])


@dataclass(frozen=True)
class SpotPatches:
    """A spot's triangles: vertices in beam coordinates ``tri_s`` (K, 3, 2) [units of
    the 1/e radius] and on the surface ``tri_x`` (K, 3, 3) [m], the density factor
    ``density_w`` (K,) [W per unit s-area at s = 0], the sample each belongs to
    ``sample`` (K,), the samples' powers when built ``sample_power_w`` (n,) [W] (a spot
    whose powers are later rescaled, e.g. for another attenuation, scales its
    triangles alike), each sample's radius on the surface ``radius_m`` (n,) [m] and the
    vertices' perspective weights ``tri_g`` (K, 3) (each vertex's inverse distance from
    the beam's virtual source along its axis, times any common factor; None: equal
    weights, the affine map of a collimated beam)."""

    tri_s: np.ndarray
    tri_x: np.ndarray
    density_w: np.ndarray
    sample: np.ndarray
    sample_power_w: np.ndarray
    radius_m: np.ndarray
    tri_g: np.ndarray | None = None

    def weights(self) -> np.ndarray:
        """The perspective weights (K, 3): ``tri_g``, or ones where the map is affine."""
        return np.ones(self.tri_s.shape[:2]) if self.tri_g is None else self.tri_g

    @cached_property
    def moments(self):
        """Per sample, from its triangles as the beam's rays map them: the power centroid
        (n, 3) [m], the variance about it (n,) [m^2], the largest vertex distance from it
        (n,) [m] and where these exist (n,) (:func:`patch_moments`); computed once."""
        return patch_moments(self)


class _Stats:
    """Counts of the near-field work in this process (read as differences around a stage)."""

    def __init__(self):
        self._lock = threading.Lock()
        self.observers = self.pairs = self.evaluations = self.unresolved = 0
        self.seconds = 0.0

    def add(self, observers, pairs, evaluations, unresolved, seconds):
        with self._lock:
            self.observers += observers
            self.pairs += pairs
            self.evaluations += evaluations
            self.unresolved += unresolved
            self.seconds += seconds

    def snapshot(self) -> dict:
        with self._lock:
            return dict(observers=self.observers, pairs=self.pairs, evaluations=self.evaluations,
                        unresolved=self.unresolved, seconds=self.seconds)


STATS = _Stats()


class _Bounded:
    """Counts of (observer, triangle) pairs given an upper bound instead of the integral
    (``fr_bound`` of :func:`near_field_irradiance`), and of their observers (kept apart
    from :data:`STATS`, whose keys are reported per stage)."""

    def __init__(self):
        self._lock = threading.Lock()
        self.pairs = self.observers = 0

    def add(self, observers, pairs):
        with self._lock:
            self.observers += observers
            self.pairs += pairs

    def snapshot(self) -> dict:
        with self._lock:
            return dict(observers=self.observers, pairs=self.pairs)


BOUNDED = _Bounded()


def stats_since(before: dict) -> dict:
    """The near-field work done since ``before`` (a :meth:`_Stats.snapshot`)."""
    now = STATS.snapshot()
    return {k: now[k] - before[k] for k in now}


def describe(counts: dict) -> str:
    """One line for a stage's detail: how many observers needed the near-field integral and its cost."""
    if not counts["pairs"]:
        return "near field: no observer needed the integral over a spot"
    out = (f"near field: {counts['observers']} observer(s) integrated over the spot ({counts['pairs']} observer-sample "
           f"pairs, {counts['evaluations']} kernel evaluations, {counts['seconds']:.3g} s summed over threads)")
    if counts["unresolved"]:
        out += f"; {counts['unresolved']} pair(s) not resolved after {MAX_DEPTH} splits (an observer on the spot's surface)"
    return out


def _triangle_radius(tri_x):
    """Largest distance [m] of a triangle's vertices from its centroid (K,)."""
    c = (tri_x[:, 0] + tri_x[:, 1] + tri_x[:, 2]) / 3.0  # tri_x.mean(axis=1), bit for bit, without its generic set-up
    return np.sqrt(((tri_x - c[:, None, :]) ** 2).sum(-1)).max(axis=1), c


def _sample_radius(tri_x, sample, centroids):
    """Per sample: largest distance [m] of its triangles' vertices from its point."""
    d = np.sqrt(((tri_x - centroids[sample][:, None, :]) ** 2).sum(-1)).max(axis=1)
    out = np.zeros(len(centroids))
    np.maximum.at(out, sample, d)
    return out


def _erf_box(lo, hi):
    """Integral of exp(-|s|^2) over boxes [lo, hi] (N, 2): (pi / 4) product of erf differences."""
    from scipy.special import erf

    return (math.pi / 4) * (erf(hi[:, 0]) - erf(lo[:, 0])) * (erf(hi[:, 1]) - erf(lo[:, 1]))


def leaf_corners_s(s_lo, s_hi) -> np.ndarray:
    """The four corners (L, 4, 2) of cells ``[s_lo, s_hi]`` (L, 2), counter-clockwise."""
    return np.stack([np.stack([s_lo[:, 0], s_lo[:, 1]], 1), np.stack([s_hi[:, 0], s_lo[:, 1]], 1),
                     np.stack([s_hi[:, 0], s_hi[:, 1]], 1), np.stack([s_lo[:, 0], s_hi[:, 1]], 1)], axis=1)


def patches_from_leaves(centre_x, jac, s_lo, s_hi, power_w, sample, centroids, sample_power_w, corners_x=None,
                        corners_g=None) -> SpotPatches:
    """Triangles of a spot made of leaf cells: leaf ``k`` spans ``[s_lo, s_hi]`` (L, 2)
    in beam coordinates, its centre ray hits ``centre_x`` (L, 3) and ``jac`` (two (L, 3)
    arrays, d x / d s) maps it onto the surface's tangent plane; ``power_w`` (L,) its
    power (attenuated and scaled as the spot's), ``sample`` (L,) its sample.
    ``corners_x`` (L, 4, 3) [m] and ``corners_g`` (L, 4): where the corners' rays meet
    that tangent plane and their perspective weights (:class:`SpotPatches`), for a
    diverging beam; None: the affine map through ``jac``."""
    sc = 0.5 * (s_lo + s_hi)
    corners_s = leaf_corners_s(s_lo, s_hi)
    ds = corners_s - sc[:, None, :]
    if corners_x is None:
        corners_x = centre_x[:, None, :] + ds[:, :, :1] * jac[0][:, None, :] + ds[:, :, 1:] * jac[1][:, None, :]
    mass = _erf_box(s_lo, s_hi)
    dens = np.where(mass > 0, power_w / np.where(mass > 0, mass, 1.0), 0.0)
    tri = np.array([[0, 1, 2], [0, 2, 3]])
    tri_s = corners_s[:, tri].reshape(-1, 3, 2)
    tri_x = corners_x[:, tri].reshape(-1, 3, 3)
    samp = np.repeat(np.asarray(sample, int), 2)
    tri_g = None if corners_g is None else np.asarray(corners_g, float)[:, tri].reshape(-1, 3)
    return SpotPatches(tri_s, tri_x, np.repeat(dens, 2), samp, np.asarray(sample_power_w, float).copy(),
                       _sample_radius(tri_x, samp, centroids), tri_g)


def patches_from_pieces(pieces, fraction, power_w, hit, centroids, source_distance=None) -> SpotPatches:
    """Triangles of a flat target's spot from its exact outline pieces (convex polygons
    in beam coordinates, one per sample): fans from each piece's first vertex, mapped
    onto the surface by ``hit(s (N, 2)) -> points (N, 3)`` (exact ray-plane hits);
    ``fraction`` (n,) the pieces' exact beam power fractions, ``power_w`` (n,) their powers;
    ``source_distance(points (N, 3)) -> (N,)`` [m] the distance of surface points from the
    beam's virtual source along its axis (inf if collimated; None: the affine map)."""
    polys = [np.asarray(poly, float).reshape(-1, 2) for poly in pieces]
    lens = np.array([len(v) for v in polys], int)
    fans = np.maximum(lens - 2, 0)  # triangles (0, k, k + 1), k = 1 .. V - 2, of each piece
    samp = np.repeat(np.arange(len(polys)), fans)
    first = np.repeat(np.cumsum(lens) - lens, fans)  # each triangle's piece's vertex 0 in the stacked vertices
    k = np.arange(len(samp)) - np.repeat(np.cumsum(fans) - fans, fans) + 1
    verts = np.concatenate(polys) if polys else np.zeros((0, 2))
    tri_s = verts[np.stack([first, first + k, first + k + 1], axis=1)].reshape(-1, 3, 2)
    tri_x = hit(tri_s.reshape(-1, 2)).reshape(-1, 3, 3)
    mass = math.pi * np.asarray(fraction, float)
    dens = np.where(mass > 0, np.asarray(power_w, float) / np.where(mass > 0, mass, 1.0), 0.0)[samp]
    tri_g = None if source_distance is None else perspective_weights(source_distance(tri_x.reshape(-1, 3)).reshape(-1, 3))
    return SpotPatches(tri_s, tri_x, dens, samp, np.asarray(power_w, float).copy(), _sample_radius(tri_x, samp, centroids),
                       tri_g)


def perspective_weights(distance_m) -> np.ndarray | None:
    """Perspective weights (K, 3) of triangles whose vertices lie ``distance_m`` (K, 3) [m]
    from the beam's virtual source along its axis: ``1 / d`` scaled by each triangle's
    nearest ``d`` (so 1 at that vertex); None when every distance is infinite (collimated:
    the affine map). A non-positive or non-finite distance in a triangle leaves that
    triangle affine (equal weights)."""
    d = np.asarray(distance_m, float)
    if not len(d) or not np.isfinite(d).any():
        return None
    ok = np.all(np.isfinite(d) & (d > 0), axis=1)
    g = np.ones_like(d)
    g[ok] = d[ok].min(axis=1, keepdims=True) / d[ok]
    return g


def _sub_rule(level=MOMENT_LEVEL):
    """The 7-point rule on each of the ``4**level`` congruent sub-triangles of a triangle:
    barycentric nodes (Q, 3) and weights (Q,) summing to 1."""
    n = 2 ** level
    subs = []
    for i in range(n):
        for j in range(n - i):
            a, b, c = (i, j), (i + 1, j), (i, j + 1)
            subs.append((a, b, c))
            if i + j < n - 1:
                subs.append(((i + 1, j), (i + 1, j + 1), (i, j + 1)))
    corners = np.array([[[1 - (u + v) / n, u / n, v / n] for u, v in tri] for tri in subs])  # (S, 3, 3)
    nodes = np.einsum("qk,skc->sqc", RULE_BARY, corners).reshape(-1, 3)
    return nodes, np.tile(RULE_W, len(subs)) / len(subs)


def patch_moments(patches: SpotPatches):
    """Per sample: the power centroid (n, 3) [m] of its triangles on the surface, the
    power-weighted variance about it (n,) [m^2] and its radius (n,) [m] (largest vertex
    distance from the centroid; the rays map a triangle's edges to straight segments on a
    flat target or a leaf's tangent plane). The power density ``c exp(-|s|^2)`` is
    integrated in ``s`` with the 7-point rule on ``4**MOMENT_LEVEL`` sub-triangles of each
    triangle whose perspective weights differ by more than :data:`MOMENT_AFFINE_RTOL` (on
    the triangle itself for the others: the map is affine within it to that order), its
    nodes mapped as the rays map them (perspective-correct for a diverging beam); these
    are the point form's inputs (a centroid off the power centroid adds a first-order
    error the Taylor bound of :func:`point_form_ok` does not cover). Also returns the mask
    (n,) of samples with power on their triangles (the others' values are 0)."""
    n = len(patches.sample_power_w)
    m = (np.zeros(n), np.zeros((n, 3)), np.zeros(n))
    base = patches.tri_x[_first_of(patches.sample, np.arange(n)), 0] if len(patches.sample) else np.zeros((n, 3))
    g_all = patches.weights()
    curved = g_all.max(axis=1) > g_all.min(axis=1) * (1.0 + MOMENT_AFFINE_RTOL)
    for tris, level in ((np.flatnonzero(curved), MOMENT_LEVEL), (np.flatnonzero(~curved), 0)):
        _add_moments(patches, g_all, base, tris, _sub_rule(level), m)
    m0, m1, m2 = m
    has = m0 > 0
    mean = np.where(has[:, None], m1 / np.where(has, m0, 1.0)[:, None], 0.0)
    var = np.where(has, np.maximum(m2 / np.where(has, m0, 1.0) - (mean * mean).sum(1), 0.0), 0.0)
    centre = np.where(has[:, None], base + mean, 0.0)
    rad = np.sqrt(((patches.tri_x - centre[patches.sample][:, None, :]) ** 2).sum(-1)).max(axis=1)
    radius = np.zeros(n)
    np.maximum.at(radius, patches.sample, np.where(has[patches.sample], rad, 0.0))
    return centre, var, radius, has


def _add_moments(patches: SpotPatches, g_all, base, tris, rule, m) -> None:
    """Add the power moments (0th, 1st about each sample's first vertex, 2nd) of triangles
    ``tris`` to ``m`` = (m0 (n,), m1 (n, 3), m2 (n,)), with the barycentric ``rule``
    (nodes (Q, 3), weights (Q,)) mapped as the rays map it."""
    nb, nw = rule
    ref = patches.tri_x[:, 0, :]  # each triangle's first vertex (its nodes are mapped about it)
    step = max(1, _NODE_BLOCK // len(nw))
    for a in range(0, len(tris), step):
        sl = tris[a:a + step]
        ss, xs, gs = patches.tri_s[sl], patches.tri_x[sl] - ref[sl, None, :], g_all[sl]
        s = np.einsum("qk,pkc->pqc", nb, ss)
        bg = nb[None, :, :] * gs[:, None, :]
        x = bg @ xs / bg.sum(-1, keepdims=True)  # (P, Q, 3) about ref
        w = (_area_s(ss) * patches.density_w[sl])[:, None] * nw[None, :] * np.exp(-(s * s).sum(-1))
        smp = patches.sample[sl]
        x = x + (ref[sl] - base[smp])[:, None, :]  # about the sample's first vertex (no cancellation far from the origin)
        np.add.at(m[0], smp, w.sum(1))
        np.add.at(m[1], smp, np.einsum("pq,pqc->pc", w, x))
        np.add.at(m[2], smp, np.einsum("pq,pq->p", w, (x * x).sum(-1)))


def _first_of(sample, which):
    """Index of the first triangle of each sample in ``which`` (samples without one: 0)."""
    first = np.zeros(int(sample.max()) + 1 if len(sample) else 1, int)
    idx = np.arange(len(sample))[::-1]
    first[sample[::-1]] = idx
    which = np.asarray(which, int)
    return np.where(which < len(first), first[np.minimum(which, len(first) - 1)], 0)


def point_form_ok(radius_m, distance_m, rtol=NEAR_FIELD_RTOL, spread_m2=None):
    """True where a source of radius ``a`` (and power-weighted variance ``sigma^2`` about
    its power centroid, default ``a^2``) seen from ``d`` is a point source to ``rtol`` of
    ``P / d^2``: the Taylor remainder of the Lambertian kernel ``n.y / |y|^3`` about the
    centroid (no first-order term there) is at most ``1/2 max|Hessian| sigma^2 P`` with
    ``|Hessian| <= 24 / (d - a)^4`` over the source, so ``12 sigma^2 d^2 / (d - a)^4 <= rtol``."""
    a, d = np.asarray(radius_m, float), np.asarray(distance_m, float)
    var = a * a if spread_m2 is None else np.minimum(np.asarray(spread_m2, float), a * a)
    gap = np.maximum(d - a, 0.0)
    return (gap > 0) & (12.0 * var * d * d <= rtol * gap ** 4)


def _split(xs, ss, gs):
    """Two children of triangles (P, 3, k) by bisecting each one's longest edge on the
    surface (a spot stretched by grazing incidence is split along its length only):
    (2P, 3, k) each, first children then second children. The new vertex is the edge's
    midpoint in ``s``; on the surface the point the beam's rays map it to (weights
    ``gs`` (P, 3): ``(g_1 x_1 + g_2 x_2) / (g_1 + g_2)``), its weight the mean."""
    edge = np.stack([np.linalg.norm(xs[:, (i + 1) % 3] - xs[:, (i + 2) % 3], axis=1) for i in range(3)], axis=1)
    k = edge.argmax(axis=1)  # the vertex opposite the longest edge goes first
    perm = np.array([[0, 1, 2], [1, 2, 0], [2, 0, 1]])[k]
    rows = np.arange(len(xs))[:, None]
    g = gs[rows, perm]
    t = (g[:, 2] / (g[:, 1] + g[:, 2]))[:, None]  # the s-midpoint's place along the edge on the surface

    def kids(v, m):
        return np.concatenate([np.stack((v[:, 0], v[:, 1], m), axis=1), np.stack((v[:, 0], m, v[:, 2]), axis=1)])
    x, s_ = xs[rows, perm], ss[rows, perm]
    return (kids(x, x[:, 1] + t * (x[:, 2] - x[:, 1])), kids(s_, 0.5 * (s_[:, 1] + s_[:, 2])),
            kids(g, 0.5 * (g[:, 1] + g[:, 2])))


def _area_s(ss):
    e1, e2 = ss[:, 1] - ss[:, 0], ss[:, 2] - ss[:, 0]
    return 0.5 * np.abs(e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0])


def _scatter_add(e, rows, values):
    """``e[rows] += values`` with repeated rows summed (``np.add.at``'s result, several
    times faster): the values sorted by row (stable: each row's values keep their order;
    rows already in order are taken as they are, the same permutation) and summed per
    row with ``np.add.reduceat``. ``e`` (M,) or (M, T); ``values`` (N,) or (N, T)."""
    if not len(rows):
        return
    values = np.asarray(values)
    if np.all(rows[1:] >= rows[:-1]):  # already in order (a rule's nodes of sorted pairs): the stable sort is the identity
        r = rows
    else:
        order = np.argsort(rows, kind="stable")
        r, values = rows[order], values[order]
    starts = np.flatnonzero(np.concatenate(([True], r[1:] != r[:-1])))
    e[r[starts]] += np.add.reduceat(values, starts, axis=0)


def _rule(tree, nd, dens, oi, samp, batch):
    """Add the 7-point rule of the tree's triangles ``nd`` (P,) at observers ``oi`` to
    ``batch`` (a :class:`_Batch`); ``dens`` (P,) already holds the per-pair factors (the
    nodes are the rule's in ``s``, mapped onto the surface as the rays map them:
    :meth:`_Subdivision.rule`). Returns the number of nodes."""
    if not len(oi):
        return 0
    x, area, ex = tree.rule(nd)
    w = (area * dens)[:, None] * RULE_W[None, :] * ex
    batch.add(np.repeat(samp, len(RULE_W)), x, np.repeat(oi, len(RULE_W)), w.ravel())
    return len(w) * len(RULE_W)


class _Subdivision:
    """A spot's triangles and their bisections (:func:`_split`) as a tree of nodes, the
    spot's triangles first (node ``k`` is triangle ``k``): each node's surface, ``s``
    and weight vertices ``xs`` (N, 3, 3), ``ss`` (N, 3, 2), ``gs`` (N, 3), its
    centroid ``c`` (N, 3) and radius ``rad`` (N,) (:func:`_triangle_radius`, :meth:`size`), its
    children ``kids`` (N, 2) (-1: not made yet) and, made when first asked
    (:meth:`rule`), its 7-point rule's surface nodes, ``s``-area and ``exp(-|s|^2)``.
    Every value is a function of the node's vertices alone, computed row by row as the
    per-pair arrays were: sharing a node among observers changes no bit."""

    def __init__(self, patches: SpotPatches):
        self.n = len(patches.tri_x)
        self.xs, self.ss, self.gs = patches.tri_x, patches.tri_s, patches.weights()  # the patches' own (copied when grown)
        self._own = False
        self.rad, self.c, self.sized = np.zeros(self.n), np.zeros((self.n, 3)), np.zeros(self.n, bool)  # made when asked
        self.kids = np.full((self.n, 2), -1)
        self.ruled = np.zeros(self.n, bool)
        self.rule_x, self.area, self.rule_e = np.zeros((self.n, len(RULE_W), 3)), np.zeros(self.n), np.zeros((self.n, len(RULE_W)))

    def children(self, nd):
        """The children of nodes ``nd`` (P,): (2P,), first children then second (as
        :func:`_split` returns them), made where missing."""
        miss = nd[self.kids[nd, 0] < 0]
        if len(miss):
            miss = np.unique(miss)
            xs, ss, gs = _split(self.xs[miss], self.ss[miss], self.gs[miss])
            m, n0 = len(miss), self.n
            rad, c = _triangle_radius(xs)
            self._append(xs, ss, gs, rad, c)
            self.kids[miss, 0], self.kids[miss, 1] = n0 + np.arange(m), n0 + m + np.arange(m)
        k = self.kids[nd]
        return np.concatenate([k[:, 0], k[:, 1]])

    def _append(self, xs, ss, gs, rad, c):
        n0, n1 = self.n, self.n + len(xs)
        if n1 > len(self.xs) or not self._own:
            cap = max(n1, 2 * len(self.xs))

            def grow(a, fill=0):
                out = np.full((cap,) + a.shape[1:], fill, a.dtype)
                out[:n0] = a[:n0]
                return out
            self._own = True
            self.xs, self.ss, self.gs, self.rad, self.c = (grow(a) for a in (self.xs, self.ss, self.gs, self.rad, self.c))
            self.kids, self.ruled, self.sized = grow(self.kids, -1), grow(self.ruled, False), grow(self.sized, False)
            self.rule_x, self.area, self.rule_e = (grow(a) for a in (self.rule_x, self.area, self.rule_e))
        self.xs[n0:n1], self.ss[n0:n1], self.gs[n0:n1], self.rad[n0:n1], self.c[n0:n1] = xs, ss, gs, rad, c
        self.sized[n0:n1] = True
        self.n = n1

    def size(self, nd):
        """Radii (P,) [m] and centroids (P, 3) [m] of nodes ``nd`` (:func:`_triangle_radius`;
        the spot's own triangles made when first asked: a call that needs a few of many
        triangles makes only those)."""
        miss = nd[~self.sized[nd]]
        if len(miss):
            miss = np.unique(miss)
            self.rad[miss], self.c[miss] = _triangle_radius(self.xs[miss])
            self.sized[miss] = True
        return self.rad[nd], self.c[nd]

    def rule(self, nd):
        """The 7-point rule on nodes ``nd`` (P,): surface nodes (7P, 3) [m] (barycentric
        in ``s``, mapped with the perspective weights), ``s``-areas (P,) and ``exp(-|s|^2)``
        at the nodes (P, 7); made once per node."""
        miss = nd[~self.ruled[nd]]
        if len(miss):
            miss = np.unique(miss)
            xs, ss, gs = self.xs[miss], self.ss[miss], self.gs[miss]
            bg = RULE_BARY[None, :, :] * gs[:, None, :]  # (P, 7, 3)
            self.rule_x[miss] = bg @ xs / bg.sum(-1, keepdims=True)  # a batched product (several times einsum's speed here)
            s = RULE_BARY @ ss
            self.area[miss], self.rule_e[miss] = _area_s(ss), np.exp(-(s * s).sum(-1))
            self.ruled[miss] = True
        return self.rule_x[nd].reshape(-1, 3), self.area[nd], self.rule_e[nd]


_SHARED = threading.local()  # .trees: {id(patches): (patches, _Subdivision)} inside shared_subdivisions(), per thread


@contextmanager
def shared_subdivisions():
    """Within the ``with`` block, the calls of :func:`near_field_irradiance` on this thread
    share each spot's bisections (:class:`_Subdivision`; e.g. a keep-out lobe's scan,
    whose rays sample the same spot again and again); outside it, one call shares them
    among its observers. The results are the same bit for bit; memory stays bounded
    (:data:`_TREE_NODES`)."""
    old = getattr(_SHARED, "trees", None)
    if old is None:
        _SHARED.trees = {}
    try:
        yield
    finally:
        if old is None:
            _SHARED.trees = None


def _subdivision(patches: SpotPatches) -> _Subdivision:
    """The tree of ``patches`` shared within :func:`shared_subdivisions` (a fresh one past
    :data:`_TREE_NODES` nodes), else a new one."""
    trees = getattr(_SHARED, "trees", None)
    if trees is None:
        return _Subdivision(patches)
    got = trees.get(id(patches))
    if got is None or got[0] is not patches or got[1].n > _TREE_NODES:
        got = trees[id(patches)] = (patches, _Subdivision(patches))
    return got[1]


class _Batch:
    """Kernel nodes ``(samples, source points, observer rows, scales)`` gathered across
    the rule's depths and the point-form pairs of a block of observers, evaluated in
    calls of at most ``step`` nodes: a kernel call has a fixed cost (the BRDF's input
    checks and set-up), so a few large calls replace one per depth (small parts are
    gathered; a part of a quarter call or more is evaluated alone as it comes, after the
    parts waiting before it, so large parts are not copied). Each added part is
    added to ``e`` in its own pieces of ``step`` nodes, in the order added
    (:func:`_scatter_add`), as a kernel call per piece would: the sums are the same bit
    for bit. At most ``step`` nodes wait (bounded memory)."""

    def __init__(self, e, kernel, obs, step):
        self.e, self.kernel, self.obs, self.step = e, kernel, obs, step
        self.pieces, self.n = [], 0

    def add(self, samples, x, rows, scale):
        for a in range(0, len(rows), self.step):
            b = min(len(rows), a + self.step)
            big = b - a >= self.step // 4  # evaluated alone, after those waiting: not copied
            if big or self.n + b - a > self.step:
                self.flush()
            self.pieces.append((samples[a:b], x[a:b], rows[a:b], scale[a:b]))
            self.n += b - a
            if big:
                self.flush()

    def flush(self):
        if not self.pieces:
            return
        smp, x, o, w = (np.concatenate(v) if len(self.pieces) > 1 else v[0] for v in zip(*self.pieces))
        f = self.kernel(smp, x, self.obs[o], w)
        a = 0
        for piece in self.pieces:
            b = a + len(piece[2])
            _scatter_add(self.e, piece[2], f[a:b])
            a = b
        self.pieces, self.n = [], 0


def _expand(patches, io, is_):
    """Each (observer, sample) pair as (observer, triangle) pairs over the sample's triangles."""
    order = np.argsort(patches.sample, kind="stable")
    counts = np.bincount(patches.sample, minlength=len(patches.sample_power_w))
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
    reps = counts[is_]
    oi = np.repeat(io, reps)
    first = np.repeat(starts[is_], reps)
    offs = np.arange(len(oi)) - np.repeat(np.cumsum(reps) - reps, reps)
    return oi, order[first + offs]


def near_field_irradiance(patches: SpotPatches, points, spread_m2, normals, power_w, obs, weight, kernel, shape,
                          rtol=NEAR_FIELD_RTOL, fr_bound_per_sr=None, max_evaluations=None):
    """Irradiance [W/m^2] of a spot at observers ``obs`` (M, 3), shape ``shape`` ((M,) or
    (M, T)): each (observer, sample) pair by the point form where :func:`point_form_ok`,
    else by the adaptive triangle rule (module notes).

    ``points``, ``spread_m2``, ``normals``, ``power_w``: the samples' power centroids,
    variances about them [m^2], lit-side normals and powers now (for a diverging beam's
    patches the centroids, variances and radii of :attr:`SpotPatches.moments` replace
    them in the point form: the affine ones can sit off the rays' power centroid); ``weight`` (M,) the
    observers' factor (gain x line of sight); ``kernel(samples, x, o, scale)`` gives
    ``f_r cos(theta_r) exp(-mu R) scale / R^2`` for source points ``x`` of ``samples``
    and observers ``o`` (rows, shape (N,) or (N, T)). Observers go in blocks (bounded
    memory whatever the spot's number of triangles).

    ``fr_bound_per_sr``: an upper bound [1/sr] of the BRDF ``f_r`` over every pair of
    directions (``rho / pi`` for a Lambertian material; the kernel's ``cos(theta_r)`` is
    taken about ``normals``). Given, the pairs the point
    form does not serve get an upper bound instead of the adaptive rule
    (:func:`_bound_pairs`): the result is then an upper bound of the irradiance, exact
    where every pair took the point form (counted in :data:`BOUNDED`).

    ``max_evaluations``: the work's ceiling in kernel evaluations (None: none). Checked
    before each block of observers and between the rule's depths within one; once
    reached, the observers not finished get NaN (deterministic: the same observers for
    the same inputs). Below it the result is the same, bit for bit, as without it.
    """
    t0 = time.perf_counter()
    e = np.zeros(shape)
    live = np.flatnonzero(np.asarray(weight) > 0)
    if not len(live) or not len(power_w):
        return e
    ratio = np.where(patches.sample_power_w > 0, power_w / np.where(patches.sample_power_w > 0, patches.sample_power_w, 1.0), 0.0)
    spread = np.zeros(len(points)) if spread_m2 is None else np.asarray(spread_m2, float)
    radius = patches.radius_m
    if patches.tri_g is not None:  # diverging: the point form about the power centroid of the rays' own map
        c, v, r, has = patches.moments
        points = np.where(has[:, None], c, points)
        spread, radius = np.where(has, v, spread), np.where(has, r, radius)
    src = _Sources(patches, points, spread, radius, normals, power_w, ratio, kernel, _subdivision(patches), fr_bound_per_sr)
    if fr_bound_per_sr is not None:
        live = _bound_whole(src, obs, weight, live, e)
    counts = np.zeros(4, int)
    block = max(1, _PAIR_BLOCK // max(len(points), len(patches.sample), 1))
    for a in range(0, len(live), block):
        if max_evaluations is not None and counts[2] >= max_evaluations:  # the ceiling: the rest not integrated
            e[live[a:]] = np.nan
            break
        if src.tree.n > _TREE_NODES:  # bounded memory: the same nodes are made again as needed (the same bits)
            src.tree = _subdivision(patches)
        counts += _near_block(src, obs, weight, live[a:a + block], e, rtol,
                              None if max_evaluations is None else max_evaluations - counts[2])
    STATS.add(int(counts[0]), int(counts[1]), int(counts[2]), int(counts[3]), time.perf_counter() - t0)
    return e


@dataclass
class _Sources:
    """A spot's samples and triangles as :func:`near_field_irradiance` uses them."""

    patches: SpotPatches
    points: np.ndarray
    spread_m2: np.ndarray
    radius_m: np.ndarray
    normals: np.ndarray
    power_w: np.ndarray
    ratio: np.ndarray
    kernel: object
    tree: _Subdivision
    fr_bound_per_sr: float | None = None

    @cached_property
    def sample_mass(self) -> np.ndarray:
        """:func:`_sample_masses` of the patches (bounds only)."""
        return _sample_masses(self.patches)

    @cached_property
    def ball_radius_m(self) -> np.ndarray:
        """Per sample: the largest distance [m] of its triangles' vertices from its point
        (the ball about ``points`` holding its triangles); bounds only."""
        return _sample_radius(self.patches.tri_x, self.patches.sample, self.points)

    @cached_property
    def sample_lowest_m(self) -> np.ndarray:
        """Per sample: the smallest ``n.x`` [m] over its triangles' vertices along its normal
        (so ``n.o - lowest`` is the largest height of an observer ``o`` over them); bounds only."""
        p = self.patches
        low = np.full(len(self.normals), np.inf)
        np.minimum.at(low, p.sample, np.einsum("pvk,pk->pv", p.tri_x, self.normals[p.sample]).min(axis=1))
        return low


def _near_block(src: _Sources, obs, weight, rows, e, rtol, budget=None):
    """Observers ``rows``: the point form for the (observer, sample) pairs it serves, the
    adaptive rule for the rest. Returns counts (observers integrated, pairs integrated,
    kernel evaluations, pairs unresolved at ``MAX_DEPTH``). ``budget``: kernel
    evaluations the block may make (None: any); past it between the rule's depths the
    block stops and its observers get NaN."""
    pt = src.points
    d = np.linalg.norm(obs[rows][:, None, :] - pt[None, :, :], axis=-1)
    ok = point_form_ok(src.radius_m[None, :], d, rtol, src.spread_m2[None, :])
    po, ps = np.nonzero(ok)
    io_local, is_ = np.nonzero(~ok)
    po, io = rows[po], rows[io_local]
    batch = _Batch(e, src.kernel, obs, max(1, _NODE_BLOCK // max(1, e.shape[1] if e.ndim == 2 else 1)))
    if len(po):
        batch.add(ps, pt[ps], po, src.power_w[ps] * weight[po])
    n_eval = len(po)
    if src.fr_bound_per_sr is not None:
        io, is_ = _bound_samples(src, obs, weight, io, is_, d[io_local, is_], e)
    oi, tri = _expand(src.patches, io, is_)
    p = src.patches
    samp = p.sample[tri]
    dens = p.density_w[tri] * src.ratio[samp] * weight[oi]
    stop = MAX_DEPTH if src.fr_bound_per_sr is None else min(BOUND_DEPTH, MAX_DEPTH)
    evals, unresolved, n_bound, cut = _adaptive(src, obs, oi, (tri, samp, dens), e, stop, batch,
                                                None if budget is None else budget - n_eval)
    batch.flush()
    if cut:
        e[rows] = np.nan
    if src.fr_bound_per_sr is not None:  # nothing integrated: counted in BOUNDED
        if n_bound:
            BOUNDED.add(len(np.unique(io)), n_bound)
        return np.array([0, 0, n_eval, 0])
    return np.array([len(np.unique(io)), len(io), n_eval + evals, unresolved])


def _adaptive(src: _Sources, obs, oi, pairs, e, stop, batch, budget=None):
    """The adaptive rule on (observer ``oi``, triangle) pairs, ``pairs`` = (nodes of
    ``src.tree`` (a :class:`_Subdivision`: the spot's triangles first), samples, per-pair
    densities): each pair's triangle takes the 7-point rule once the observer is
    ``RULE_REACH`` radii away, else is bisected; at depth ``stop`` (``MAX_DEPTH``) the
    pairs still unresolved get the rule (counted unresolved), its nodes gathered in
    ``batch`` (a :class:`_Batch`). A triangle's bisections, radii and rule nodes are
    made once in the tree and shared by every observer that needs them (the same
    values as made per pair). With ``src.fr_bound_per_sr`` every pair gets instead an upper
    bound of what the rule and the rest of the recursion would give it
    (:func:`_bound_pairs`): a resolved pair at once, the others after up to ``stop``
    bisections (tighter near the observer). ``budget``: the kernel evaluations it may
    make (None: any); checked before each depth's splits. Returns (kernel evaluations,
    pairs unresolved, pairs bounded, whether it stopped at the budget with pairs left)."""
    nd, samp, dens = pairs
    tree = src.tree
    n_eval = unresolved = n_bound = 0
    for depth in range(stop + 1):
        if not len(oi):
            break
        at = obs[oi]
        above = np.einsum("pvk,pk->pv", at[:, None, :] - tree.xs[nd], src.normals[samp]).max(axis=1) > 0
        if not above.all():  # (most often every pair is: nothing to drop)
            nd, samp, oi, dens, at = (v[above] for v in (nd, samp, oi, dens, at))
        rad, c = tree.size(nd)
        good = np.linalg.norm(at - c, axis=1) >= RULE_REACH * rad
        if src.fr_bound_per_sr is not None:  # bounds only: the resolved pairs, and every pair at the last depth
            good |= depth == stop
            g = nd[good]
            n_bound += _bound_pairs(src, obs, oi[good], tree.xs[g], tree.ss[g], samp[good], dens[good], e)
        elif depth == MAX_DEPTH:
            unresolved += int((~good).sum())
            good[:] = True
        if good.all():
            if src.fr_bound_per_sr is None:
                n_eval += _rule(tree, nd, dens, oi, samp, batch)
            break
        split = ~good
        if src.fr_bound_per_sr is None:
            n_eval += _rule(tree, nd[good], dens[good], oi[good], samp[good], batch)
        if budget is not None and n_eval >= budget:  # pairs left and the work's ceiling reached
            return n_eval, unresolved, n_bound, True
        nd = tree.children(nd[split])
        samp, oi, dens = (np.tile(v[split], 2) for v in (samp, oi, dens))
    return n_eval, unresolved, n_bound, False


def point_triangle_distance(p, tri) -> np.ndarray:
    """Euclidean distance [m] from points ``p`` (N, 3) to the closed triangles ``tri``
    (N, 3, 3): to the plane where the point projects inside the triangle, else to the
    nearest of its three edges (degenerate triangles: their edges alone)."""
    a, b, c = tri[:, 0], tri[:, 1], tri[:, 2]
    e0, e1, v2 = b - a, c - a, p - a
    d00, d01, d11 = (e0 * e0).sum(1), (e0 * e1).sum(1), (e1 * e1).sum(1)
    d20, d21 = (v2 * e0).sum(1), (v2 * e1).sum(1)
    den = d00 * d11 - d01 * d01
    ok = den > 1e-12 * d00 * d11
    safe = np.where(ok, den, 1.0)
    v, w = (d11 * d20 - d01 * d21) / safe, (d00 * d21 - d01 * d20) / safe
    inside = ok & (v >= 0) & (w >= 0) & (v + w <= 1)
    n = np.cross(e0, e1)
    plane = np.abs((v2 * n).sum(1)) / np.maximum(np.linalg.norm(n, axis=1), 1e-300)
    edges = []
    for q0, q1 in ((a, b), (b, c), (c, a)):
        d = q1 - q0
        t = np.clip(((p - q0) * d).sum(1) / np.maximum((d * d).sum(1), 1e-300), 0.0, 1.0)
        edges.append(np.linalg.norm(p - q0 - t[:, None] * d, axis=1))
    return np.where(inside, plane, np.minimum.reduce(edges))


def _sample_masses(patches: SpotPatches) -> np.ndarray:
    """Per sample (n,): the sum over its triangles of the density x the area in ``s`` x the
    largest ``exp(-|s|^2)`` on the triangle's bounding disc in ``s``, at least the mass
    any rule or split puts on them (:func:`_bound_pairs`)."""
    rad_s, c_s = _triangle_radius(patches.tri_s)
    peak = np.exp(-np.maximum(np.sqrt(np.einsum("ij,ij->i", c_s, c_s)) - rad_s, 0.0) ** 2)
    return np.bincount(patches.sample, patches.density_w * _area_s(patches.tri_s) * peak,
                       minlength=len(patches.sample_power_w))


def _bound_whole(src: _Sources, obs, weight, live, e):
    """Observers ``live`` at least 3 radii from the ball holding every sample's ball: an
    upper bound for the whole spot added to ``e`` (``fr_bound x mass / (D - A)^2``, the
    masses of :func:`_sample_masses` summed, ``cos(theta_r) <= 1``). Returns the others."""
    c = src.points.mean(axis=0)
    big = float(np.max(np.linalg.norm(src.points - c, axis=1) + src.ball_radius_m))
    dist = np.linalg.norm(obs[live] - c, axis=1)
    far = dist >= 3.0 * big
    o, dd = live[far], (dist[far] - big) * (1.0 - 1e-9)
    if len(o):
        b = src.fr_bound_per_sr * float((src.sample_mass * src.ratio).sum()) * weight[o] / (dd * dd)
        e[o] += b if e.ndim == 1 else b[:, None]
        BOUNDED.add(len(o), 0)
    return live[~far]


def _bound_samples(src: _Sources, obs, weight, io, is_, dist_m, e):
    """(observer ``io``, sample ``is_``) pairs ``dist_m`` from the sample's point at least 3
    of its radii away: an upper bound of the rule's value added to ``e`` for the whole
    sample (as :func:`_bound_pairs` for one triangle, with the sample's bounding ball:
    ``d = dist - a``; ``h`` over all its vertices, :attr:`_Sources.sample_lowest_m`; its
    mass :func:`_sample_masses`). Returns the other pairs."""
    a = src.ball_radius_m[is_]
    far = dist_m >= 3.0 * a
    o, s, a, dd = io[far], is_[far], a[far], (dist_m[far] - a[far]) * (1.0 - 1e-9)
    if len(o):
        h = np.einsum("ij,ij->i", obs[o], src.normals[s]) - src.sample_lowest_m[s]
        mass = src.sample_mass[s] * src.ratio[s] * weight[o]
        b = np.where((h > 0) & (mass > 0), src.fr_bound_per_sr * mass * np.minimum(1.0, h / dd) / (dd * dd), 0.0)
        _scatter_add(e, o, b if e.ndim == 1 else np.repeat(b[:, None], e.shape[1], axis=1))
        BOUNDED.add(0, len(o))
    return io[~far], is_[~far]


def _bound_pairs(src: _Sources, obs, oi, xs, ss, samp, dens, e) -> int:
    """Add to ``e`` an upper bound of what the adaptive rule would give each (observer
    ``oi``, triangle) pair: ``fr_bound x min(1, h / d) x mass / d^2``. ``d`` is at most the
    observer's distance to the triangle, where every quadrature node of the rule and of
    its splits lies (the rays' map is a convex combination of the vertices): the distance
    to the triangle's bounding ball (centroid, largest vertex distance), or where that is
    under one radius the exact distance to the triangle; shrunk by 1e-9 relative against
    rounding; exp(-mu R) <= 1. ``h`` is the largest height ``n.(o - x)`` of the observer
    over the vertices along the sample's normal ``n`` (affine in ``x``, so ``cos(theta_r) =
    n.(o - x) / |o - x| <= h / d`` on the triangle). ``mass`` is the density x the
    triangle's area in ``s`` x the largest ``exp(-|s|^2)`` on the triangle's bounding disc
    in ``s`` (each node's weight carries ``exp(-|s|^2)`` at a node in the triangle, the
    rule's weights are positive and sum to 1, and splits share the area). Pairs whose
    observer is behind the triangle's plane are dropped as the rule drops them. Returns
    the pairs bounded."""
    if not len(oi):
        return 0
    o = obs[oi]
    height = np.einsum("pvk,pk->pv", o[:, None, :] - xs, src.normals[samp]).max(axis=1)  # n.(o - x) is largest at a vertex
    above = height > 0
    o, xs, ss, dens, oi, height = o[above], xs[above], ss[above], dens[above], oi[above], height[above]
    rad, c = _triangle_radius(xs)
    d = np.sqrt(np.einsum("ij,ij->i", o - c, o - c)) - rad
    close = np.flatnonzero(d < rad)
    d[close] = point_triangle_distance(o[close], xs[close])
    d *= 1.0 - 1e-9
    rad_s, c_s = _triangle_radius(ss)
    peak = np.exp(-np.maximum(np.sqrt(np.einsum("ij,ij->i", c_s, c_s)) - rad_s, 0.0) ** 2)
    mass = dens * _area_s(ss) * peak
    with np.errstate(divide="ignore", over="ignore", invalid="ignore"):  # d = 0 (an observer on the triangle): inf
        b = np.where(mass > 0, src.fr_bound_per_sr * mass * np.minimum(1.0, height / d) / (d * d), 0.0)
    _scatter_add(e, oi, b if e.ndim == 1 else np.repeat(b[:, None], e.shape[1], axis=1))
    return len(oi)
