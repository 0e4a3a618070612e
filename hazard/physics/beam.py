"""The laser beam's cross-section: exact Gaussian powers, adaptive ray sampling, lit lookup.

Beam model (spec `range-safety.md` section 1; `laser-safety.md` section 3.1): a Gaussian
TEM00 profile with 1/e diameter ``D(z) = a + z phi``; irradiance normal to the axis
``E = P / (pi w^2) exp(-|x_perp|^2 / w^2)``, ``w = D / 2``. Every ray leaves the aperture
at ``pos + (a/2) s`` with direction ``axis + (phi/2) s`` for a fixed transverse vector
``s`` (in units of the 1/e radius), so ``s`` is constant along the ray: the beam is a
point source at ``a / phi`` behind the aperture (parallel rays when ``phi = 0``), and the
power through any region of the beam cross-section is the 2-D Gaussian integral over its
image in ``s``, density ``exp(-|s|^2) / pi``.

* A cell ``[s0, s1] x [t0, t1]`` carries ``P/4 (erf s1 - erf s0)(erf t1 - erf t0)``
  (exact).
* A polygon carries the sum over its edges of the Gaussian integral over the triangle
  (origin, A, B): ``(theta_B - theta_A) / (2 pi) - [T(h, t_B/h) - T(h, t_A/h)]`` with
  Owen's T function, ``h`` the distance of the edge's line from the beam axis and ``t``
  the positions along it (both in units of the standard deviation): exact, any position.
  A plate's outline projects to a polygon (central projection maps lines to lines); a
  disk's to an ellipse, bounded above and below by circumscribed and inscribed polygons.
* Meshes, curved shapes, occluders and terrain are sampled by rays, one per cell of a
  quadtree over ``s in [-L, L]^2`` (``L = beam.half_width >= 4``, sized per beam by
  :func:`tail_half_width` so that the beam outside it, after one reflection, stays below
  1 % of the smallest limit; at ``L = 4`` the square holds all but ``1 - erf(4)^2 =
  3.1e-8`` of the power), each cell carrying its exact power. A cell whose centre and four
  corners do not hit the same object is split in four, level by level, until the power
  in such mixed cells is below ``rtol`` of the beam; cells containing a target's projected
  vertices are split until they are smaller than the target's projection, so no target
  inside the footprint is missed. What is left in mixed cells is the error bound.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np

from hazard.physics.rays import CONVEX_SHAPES

__all__ = ["BeamGeometry", "CellSampling", "OutlineCells", "PolygonMoments", "outline_cells", "clip_to_box", "polygon_fraction", "polygon_moments", "r2_min_outside", "rectangle_fraction", "sample_cells", "tail_half_width", "tail_bounds_w_m2", "HALF_WIDTH",
           "TAIL_MARGIN"]

HALF_WIDTH = 4.0  # beam square half-width in units of the 1/e radius (outside: 3.1e-8 of the power)
TAIL_MARGIN = 0.01  # the beam left outside the sampled square stays below this fraction of the smallest limit
MAX_HALF_WIDTH = 8.0  # the largest square (exp(-64) = 1.6e-28 of the peak); where even that is not enough, it is said
MAX_LEVEL = 14  # finest cells: 2 L / n0 / 2^14 (about 1e-5 of the 1/e radius for n0 = 16)


def _erf(x):
    from scipy.special import erf

    return erf(x)


def _erfc(x):
    from scipy.special import erfc

    return erfc(x)


def tail_bounds_w_m2(half_width, power_w, diameter_m, divergence_rad, aperture_m, reflectance=1.0) -> tuple[float, float]:
    """Upper bounds [W/m^2] on what the beam outside the square ``|s_1|, |s_2| < L``
    (``L = half_width`` 1/e radii) can deliver to an eye after one reflection.

    * ``peak``: the point irradiance after a flat or diffuse reflection (no focusing),
      ``rho P / (pi (a/2)^2) exp(-L^2) sqrt(1 + L^2 phi^2 / 4)``: outside the square
      ``|s| >= L``; the incident irradiance (:meth:`BeamGeometry.irradiance_w_m2`) is
      largest at the aperture (``w = a/2``) and, for ``phi < 2.8`` rad, falls with ``|s|``;
      a flat mirror's beam keeps spreading and a BRDF returns at most its directional
      hemispherical reflectance ``<= rho`` times the largest incident irradiance it sees.
    * ``power``: the power through a limiting aperture of diameter ``aperture_m`` for any
      optics (focusing mirrors included): all the power outside the square,
      ``P (1 - erf(L)^2)``, times rho, over the aperture's area.

    Parameters
    ----------
    half_width : float
        L [1/e radii].
    power_w, diameter_m, divergence_rad : float
        The beam's power [W], 1/e diameter at the aperture [m] and full divergence [rad].
    aperture_m : float
        The smallest limiting aperture's diameter [m].
    reflectance : float, optional
        The largest reflectance any surface can have (default 1).

    Returns
    -------
    (peak_w_m2, power_w_m2) : tuple of float
    """
    big_l = float(half_width)
    tilt = math.sqrt(1.0 + big_l * big_l * (divergence_rad / 2) ** 2)
    peak = reflectance * power_w / (math.pi * (diameter_m / 2) ** 2) * math.exp(-big_l * big_l) * tilt
    outside = 2.0 * float(_erfc(big_l)) - float(_erfc(big_l)) ** 2  # 1 - erf(L)^2, without cancellation
    return peak, reflectance * power_w * outside / (math.pi * (aperture_m / 2) ** 2)


def tail_half_width(power_w, diameter_m, divergence_rad, limit_w_m2, aperture_m, *, margin=TAIL_MARGIN, reflectance=1.0) -> float:
    """The smallest half-width L >= ``HALF_WIDTH`` [1/e radii] (at most ``MAX_HALF_WIDTH``)
    at which both :func:`tail_bounds_w_m2` are at most ``margin * limit_w_m2``.

    The peak bound gives ``L^2 = ln(rho P / (pi (a/2)^2 margin limit))`` (plus the tilt
    factor); the power bound is solved by bisection (it falls monotonically with L).

    Parameters
    ----------
    power_w, diameter_m, divergence_rad, aperture_m, reflectance : float
        As :func:`tail_bounds_w_m2`.
    limit_w_m2 : float
        The smallest exposure limit any observer is held to [W/m^2] (the MPE divided by
        the largest optical-aid gain).
    margin : float, optional
        The fraction of the limit the left-out beam must stay below (default ``TAIL_MARGIN``).
    """
    if not (limit_w_m2 > 0 and margin > 0):
        raise ValueError(f"tail_half_width: limit_w_m2 = {limit_w_m2!r} and margin = {margin!r}: expected both > 0")
    if not diameter_m > 0:
        return MAX_HALF_WIDTH  # a point-like aperture: no finite peak bound

    def worst(big_l):
        return max(tail_bounds_w_m2(big_l, power_w, diameter_m, divergence_rad, aperture_m, reflectance))

    target = margin * limit_w_m2
    if worst(HALF_WIDTH) <= target:
        return HALF_WIDTH
    if worst(MAX_HALF_WIDTH) > target:
        return MAX_HALF_WIDTH
    lo, hi = HALF_WIDTH, MAX_HALF_WIDTH
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if worst(mid) > target else (lo, mid)
    return hi


def perp_basis(axis) -> tuple[np.ndarray, np.ndarray]:
    """Two unit vectors completing the unit ``axis`` to a right-handed frame (e1, e2, axis)."""
    axis = np.asarray(axis, float)
    a = np.array([1.0, 0.0, 0.0]) if abs(axis[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    e1 = np.cross(axis, a)
    e1 /= np.linalg.norm(e1)
    return e1, np.cross(axis, e1)


@dataclass
class BeamGeometry:
    """The beam's frame and profile (local scene coordinates, SI).

    ``e1``, ``e2`` span the cross-section; ``s`` coordinates are transverse positions in
    units of the 1/e radius ``w(z) = (a + z phi) / 2``.
    """

    position_m: np.ndarray
    axis: np.ndarray
    e1: np.ndarray
    e2: np.ndarray
    power_w: float
    diameter_m: float
    divergence_rad: float
    half_width: float = HALF_WIDTH  # the sampled square's half-width [1/e radii] (:func:`tail_half_width`)

    @classmethod
    def create(cls, position_m, axis, power_w, diameter_m, divergence_rad, reference=()) -> "BeamGeometry":
        """The beam along ``axis``; its cross-section's e1 is the first of the
        ``reference`` directions not within 1 deg of the axis, made normal to it (the scene's
        own geometry: the sampling grid then turns with a rigidly moved scene), else
        :func:`perp_basis`'s (from the world axes)."""
        axis = np.asarray(axis, float) / np.linalg.norm(axis)
        e1, e2 = perp_basis(axis)
        for ref in reference:
            ref = np.asarray(ref, float)
            side = ref - (ref @ axis) * axis
            if np.linalg.norm(side) > math.sin(math.radians(1.0)) * np.linalg.norm(ref):
                e1 = side / np.linalg.norm(side)
                e2 = np.cross(axis, e1)
                break
        return cls(np.asarray(position_m, float), axis, e1, e2, float(power_w), float(diameter_m), float(divergence_rad))

    def diameter_at(self, range_m):
        """1/e beam diameter [m] at a distance along the axis from the aperture."""
        return self.diameter_m + np.asarray(range_m) * self.divergence_rad

    def rays(self, s) -> tuple[np.ndarray, np.ndarray]:
        """Origins and (non-unit) directions of the rays at transverse coordinates s (N, 2)."""
        tr = s[:, :1] * self.e1 + s[:, 1:] * self.e2
        return self.position_m + tr * (self.diameter_m / 2), self.axis + tr * (self.divergence_rad / 2)

    def to_s(self, points_m) -> tuple[np.ndarray, np.ndarray]:
        """Transverse coordinates s (N, 2) of points and their distance z along the axis [m].

        Points behind the virtual source (``z <= -a/phi``) get NaN.
        """
        rel = np.asarray(points_m, float) - self.position_m
        z = rel @ self.axis
        w = self.diameter_at(z) / 2
        with np.errstate(divide="ignore", invalid="ignore"):
            s = np.stack([rel @ self.e1, rel @ self.e2], axis=1) / np.where(w > 0, w, np.nan)[:, None]
        return s, z

    def irradiance_w_m2(self, s, z) -> np.ndarray:
        """Unattenuated irradiance [W/m^2] normal to the ray through ``s`` at axial distance z.

        ``P / (pi w^2) exp(-|s|^2)`` is the flux across a plane normal to the axis; across a
        plane normal to the (slightly tilted) ray it is larger by ``|dir|`` (exact).
        """
        w = self.diameter_at(z) / 2
        s2 = (s * s).sum(axis=1)
        tilt = np.sqrt(1.0 + s2 * (self.divergence_rad / 2) ** 2)
        return self.power_w / (math.pi * w * w) * np.exp(-s2) * tilt

    def source_distance_m(self, z) -> np.ndarray:
        """Distance from the virtual point source along the axis [m] (inf when collimated):
        the radius of the incident wavefront in geometric optics."""
        if self.divergence_rad <= 0:
            return np.full(np.shape(z), np.inf)
        return np.asarray(z) + self.diameter_m / self.divergence_rad


def rectangle_fraction(s0, s1, t0, t1) -> np.ndarray:
    """Fraction of the beam power in cells [s0, s1] x [t0, t1] (units of the 1/e radius):
    ``(erf s1 - erf s0)(erf t1 - erf t0) / 4`` (spec range-safety.md section 1)."""
    return 0.25 * (_erf(s1) - _erf(s0)) * (_erf(t1) - _erf(t0))


def polygon_fraction(vertices_s) -> float:
    """Fraction of the beam power inside a simple polygon (V, 2) given in s coordinates.

    Sum over edges of the signed Gaussian integral over the triangle (origin, A, B), in
    closed form with Owen's T function (Owen 1956, Ann. Math. Statist. 27:1075, eq. 2.1):
    with u = sqrt(2) s (standard normal), h the distance of the edge's line from the
    origin and t_A < t_B the positions of A and B along it,
    ``F = (theta_B - theta_A) / (2 pi) - [T(h, t_B / h) - T(h, t_A / h)]``,
    ``theta = atan2(t, h)``, signed by the triangle's orientation. Exact for any polygon
    position (inside, outside or around the axis); orientation-free (absolute value).
    """
    return float(polygon_moments([vertices_s]).fraction[0])


def _owen_fractions(a, b, owner, n):
    """Per polygon: the Owen's T sum above over its edges a -> b (s coordinates)."""
    from scipy.special import owens_t

    a, b = np.sqrt(2.0) * a, np.sqrt(2.0) * b
    edge = b - a
    length = np.linalg.norm(edge, axis=1)
    tang = edge / np.where(length > 0, length, 1.0)[:, None]
    ta, tb = (a * tang).sum(1), (b * tang).sum(1)
    h = np.abs(a[:, 0] * tang[:, 1] - a[:, 1] * tang[:, 0])
    cross = a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]
    live = (length > 0) & (h > 1e-300)
    hs = np.where(live, h, 1.0)
    part = (np.arctan2(tb, hs) - np.arctan2(ta, hs)) / (2 * math.pi) - (owens_t(hs, tb / hs) - owens_t(hs, ta / hs))
    return np.abs(np.bincount(owner, np.where(live, np.sign(cross) * part, 0.0), n))


@dataclass
class PolygonMoments:
    """Gaussian moments of polygons in s (density ``exp(-|s|^2) / pi``).

    ``fraction`` of the beam power in each; ``mean`` (n, 2) and ``cov`` (n, 2, 2) of s
    over it; ``r2_min`` the smallest ``|s|^2`` on it (the Gaussian's largest value is
    ``exp(-r2_min)``); ``area`` its area (units of w^2).
    """

    fraction: np.ndarray
    mean: np.ndarray
    cov: np.ndarray
    r2_min: np.ndarray
    area: np.ndarray

    def take(self, rows) -> "PolygonMoments":
        """The moments of the polygons ``rows`` only."""
        return PolygonMoments(self.fraction[rows], self.mean[rows], self.cov[rows], self.r2_min[rows], self.area[rows])


def polygon_moments(polygons) -> PolygonMoments:
    """Exact Gaussian power, mean and covariance of s over convex polygons (each (V, 2)).

    Power: Owen's T sum (:func:`polygon_fraction`). Moments by the divergence theorem
    with the fields ``-e^{-r^2}/2 e_x``, ``-x e^{-r^2}/2 e_x`` (and the same in y):
    ``int x e^{-r^2} dA = -1/2 sum_edges n_x int e^{-r^2} dl``,
    ``int x^2 e^{-r^2} dA = 1/2 int e^{-r^2} dA - 1/2 sum n_x int x e^{-r^2} dl``,
    ``int x y e^{-r^2} dA = -1/2 sum n_x int y e^{-r^2} dl``, with ``n`` the outward
    normal and, along an edge ``q + u tau`` (``q`` the foot of the perpendicular from the
    origin), ``int e^{-r^2} du = e^{-|q|^2} sqrt(pi)/2 [erf u]`` and
    ``int u e^{-r^2} du = -1/2 [e^{-r^2}]``. Moments that cancellation makes meaningless
    (tiny polygons far out) fall back to the polygon's area centroid and the uniform
    covariance of its bounding box.
    """
    polys = [np.asarray(p, float).reshape(-1, 2) for p in polygons]
    n = len(polys)
    counts = np.array([len(p) for p in polys], int)
    owner = np.repeat(np.arange(n), counts)
    a = np.concatenate(polys) if n else np.zeros((0, 2))
    b = a[ring_next(counts)]
    frac = _owen_fractions(a, b, owner, n)
    area2 = np.bincount(owner, a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0], n)
    orient = np.where(area2 >= 0, 1.0, -1.0)[owner]
    edge = b - a
    length = np.linalg.norm(edge, axis=1)
    tau = edge / np.where(length > 0, length, 1.0)[:, None]
    nrm = orient[:, None] * np.stack([tau[:, 1], -tau[:, 0]], axis=1)
    ua, ub = (a * tau).sum(1), (b * tau).sum(1)
    q = a - ua[:, None] * tau
    i0 = np.exp(-(q * q).sum(1)) * (math.sqrt(math.pi) / 2) * (_erf(ub) - _erf(ua))
    i1 = -0.5 * (np.exp(-(b * b).sum(1)) - np.exp(-(a * a).sum(1)))
    line = q * i0[:, None] + tau * i1[:, None]  # int (x, y) e^{-r^2} dl
    first = np.stack([np.bincount(owner, -0.5 * nrm[:, k] * i0, n) for k in range(2)], axis=1) / math.pi
    second = np.empty((n, 2, 2))
    for r in range(2):
        for c in range(2):
            second[:, r, c] = np.bincount(owner, -0.5 * nrm[:, c] * line[:, r], n) / math.pi
    second[:, 0, 0] += 0.5 * frac
    second[:, 1, 1] += 0.5 * frac
    second = 0.5 * (second + np.transpose(second, (0, 2, 1)))
    safe = np.where(frac > 0, frac, 1.0)
    mean = first / safe[:, None]
    cov = second / safe[:, None, None] - mean[:, :, None] * mean[:, None, :]
    return PolygonMoments(frac, *_checked_moments(a, counts, frac, mean, cov), _r2_min(a, b, owner, orient, n), np.abs(area2) / 2)


def ring_next(counts) -> np.ndarray:
    """For polygons of ``counts`` vertices stored one after another: the index of each
    vertex's successor around its own polygon."""
    counts = np.asarray(counts, int)
    nxt = np.arange(int(counts.sum())) + 1
    if len(counts):
        ends = np.cumsum(counts) - 1
        nxt[ends[counts > 0]] = (ends - counts + 1)[counts > 0]
    return nxt


def _checked_moments(vertices, counts, frac, mean, cov):
    """Replace moments lost to cancellation (tiny polygons far out) by the area centroid
    and the uniform covariance of the bounding box; clip the rest into the box."""
    if not len(counts):
        return mean, cov
    starts = np.cumsum(counts) - counts
    lo = np.minimum.reduceat(vertices, starts, axis=0)
    hi = np.maximum.reduceat(vertices, starts, axis=0)
    span = hi - lo
    var = np.stack([cov[:, 0, 0], cov[:, 1, 1]], axis=1)
    ok = ((frac > 0) & np.all(mean >= lo - 1e-9 * (1 + span), axis=1) & np.all(mean <= hi + 1e-9 * (1 + span), axis=1)
          & np.all(var >= -1e-12, axis=1) & np.all(var <= span * span / 4 * (1 + 1e-6) + 1e-300, axis=1))
    if not np.all(ok):
        bad = ~ok
        mean[bad] = np.add.reduceat(vertices, starts, axis=0)[bad] / counts[bad, None]
        cov[bad] = 0.0
        cov[bad, 0, 0], cov[bad, 1, 1] = span[bad, 0] ** 2 / 12, span[bad, 1] ** 2 / 12
    mean[:] = np.clip(mean, lo, hi)
    cov[:, 0, 0] = np.clip(cov[:, 0, 0], 0.0, span[:, 0] ** 2 / 4)
    cov[:, 1, 1] = np.clip(cov[:, 1, 1], 0.0, span[:, 1] ** 2 / 4)
    return mean, cov


def _r2_min(a, b, owner, orient, n):
    """Smallest |s|^2 on each convex polygon (0 when it holds the origin)."""
    edge = b - a
    len2 = (edge * edge).sum(1)
    u = np.clip(-(a * edge).sum(1) / np.where(len2 > 0, len2, 1.0), 0.0, 1.0)
    near = a + u[:, None] * edge
    d2 = (near * near).sum(1)
    r2 = np.full(n, np.inf)
    np.minimum.at(r2, owner, d2)
    outside = orient * (edge[:, 0] * (-a[:, 1]) - edge[:, 1] * (-a[:, 0])) < 0  # origin right of a CCW edge
    holds = np.bincount(owner, outside, n) == 0
    return np.where(holds, 0.0, r2)


def _signed_area2(poly) -> float:
    """Twice the signed area of a polygon (V, 2): > 0 counter-clockwise (shoelace)."""
    nxt = _next(poly)
    return float(np.sum(poly[:, 0] * nxt[:, 1] - nxt[:, 0] * poly[:, 1]))


def _next(a):
    """Each element's successor around a ring (np.roll(a, -1, axis=0), cheaper)."""
    return np.concatenate([a[1:], a[:1]])


def _clip_half_plane(poly, normal, offset, axis=None):
    """Sutherland-Hodgman step: the part of a convex polygon where ``normal . p >= offset``
    (``axis``: the normal is that coordinate axis, and cut points land exactly on it)."""
    v = poly @ normal - offset
    inside = v >= 0
    if inside.all():
        return poly
    if not inside.any():
        return np.zeros((0, 2))
    nxt, vn = _next(poly), _next(v)
    cross = inside != _next(inside)
    f = np.where(cross, v / np.where(cross, v - vn, 1.0), 0.0)
    cut = poly + f[:, None] * (nxt - poly)
    if axis is not None:
        cut[cross, axis] = offset * normal[axis]
    return np.stack([poly, cut], axis=1)[np.stack([inside, cross], axis=1)]


def _ring_points(ring, spacing):
    """Points along a closed polygon's edges, at most ``spacing`` apart (vertices included)."""
    steps = np.concatenate([ring[1:], ring[:1]]) - ring
    lengths = np.sqrt((steps * steps).sum(1))
    per_edge = np.maximum(np.ceil(lengths / max(spacing, 1e-300)).astype(int), 1)
    edge = np.repeat(np.arange(len(ring)), per_edge + 1)
    frac = np.concatenate([np.linspace(0.0, 1.0, k + 1) for k in per_edge])
    return ring[edge] + frac[:, None] * steps[edge], float((lengths / per_edge).max())


def r2_min_outside(piece, holes, n_edge=256, seam=0.0, with_point=False):
    """Smallest |s|^2 over a convex piece minus convex holes, never above the true value
    (with ``with_point``: and the free point found, not lowered; None when none is free).

    ``holes``: (part of a hole inside the piece, the whole hole) pairs. Candidates are
    points on the piece's boundary and on each hole part's boundary, about
    ``1 / n_edge`` of the piece's size apart; a point is covered when it lies strictly
    inside a whole hole, or within ``seam`` of a hole it is not on the edge of (two
    plates meeting edge to edge leave no gap). The nearest free candidate's distance,
    lowered by the spacing, bounds the true one from below.
    """
    origin = np.zeros((1, 2))
    if inside_convex(origin, piece, margin=-1e-12)[0] and not any(inside_convex(origin, w, margin=1e-12)[0] for _, w in holes):
        return (0.0, np.zeros(2)) if with_point else 0.0
    spacing = float(np.ptp(piece, axis=0).max()) / n_edge
    rings = [(np.asarray(piece, float), -1)] + [(np.asarray(p, float), k) for k, (p, _) in enumerate(holes)]
    cand, owner, step = [], [], spacing
    for ring, k in rings:
        pts, sp = _ring_points(ring, spacing)
        cand.append(pts)
        owner.append(np.full(len(pts), k))
        step = max(step, sp)
    pts, owner = np.concatenate(cand), np.concatenate(owner)
    r2 = (pts * pts).sum(1)
    order = np.argsort(r2)
    for a in range(0, len(order), 512):  # nearest candidates first
        batch = order[a:a + 512]
        free = np.ones(len(batch), bool)
        for k, (_, whole) in enumerate(holes):
            mine = owner[batch] == k  # on this hole's own boundary: covered only strictly inside
            strictly = inside_convex(pts[batch], whole, margin=1e-12)
            near = inside_convex(pts[batch], whole, margin=-seam)
            free &= ~np.where(mine, strictly, near)
        if free.any():
            # the free region's nearest point lies on a candidate ring within one spacing
            # of a free candidate: lowered by it, never above the truth
            q = batch[np.argmax(free)]
            r2_low = max(math.sqrt(float(r2[q])) - step, 0.0) ** 2
            return (r2_low, pts[q].copy()) if with_point else r2_low
    return (math.inf, None) if with_point else math.inf  # wholly hidden


def clip_to_box(polygon_s, s0, s1, t0, t1) -> np.ndarray:
    """A convex polygon (V, 2) clipped to the box [s0, s1] x [t0, t1] (Sutherland-Hodgman);
    (0, 2) when they do not overlap."""
    poly = np.asarray(polygon_s, float)
    for axis, bound, sign in ((0, s0, 1.0), (0, s1, -1.0), (1, t0, 1.0), (1, t1, -1.0)):
        normal = np.zeros(2)
        normal[axis] = sign
        poly = _clip_half_plane(poly, normal, sign * bound, axis)
        if len(poly) == 0:
            break
    return poly if len(poly) >= 3 else np.zeros((0, 2))


def clip_convex(polygon_s, window_s) -> np.ndarray:
    """The intersection of two convex polygons (Sutherland-Hodgman); (0, 2) if empty."""
    poly = np.asarray(polygon_s, float)
    win = np.asarray(window_s, float)
    orient = 1.0 if _signed_area2(win) >= 0 else -1.0
    for a, b in zip(win, np.roll(win, -1, axis=0)):
        e = b - a
        normal = orient * np.array([-e[1], e[0]])  # inward
        if not np.any(normal):
            continue
        poly = _clip_half_plane(poly, normal, float(normal @ a))
        if len(poly) == 0:
            break
    return poly if len(poly) >= 3 else np.zeros((0, 2))


# -- adaptive cell sampling ----------------------------------------------------------------
def mixed_rows(labels) -> np.ndarray:
    """Per cell (labels (n, 5) of its five rays): whether its rays meet more than one object
    (-1, nothing, is one)."""
    return np.any(labels != labels[:, :1], axis=1)


@dataclass
class CellSampling:
    """Leaf cells of the beam quadtree and what each one's five rays hit.

    ``level``, ``i``, ``j``: the cell ``[-L + i d, -L + (i+1) d] x [...]`` with
    ``d = 2 L / (n0 2^level)``; ``power_w`` its exact power; ``labels`` (n, 5) the object
    hit by the centre and four corner rays (-1: nothing); ``faces`` (n, 5) the triangles;
    the centre ray's hit ``point``, range ``t`` and unit ``direction``.
    """

    n0: int
    level: np.ndarray
    i: np.ndarray
    j: np.ndarray
    power_w: np.ndarray
    labels: np.ndarray
    faces: np.ndarray
    point: np.ndarray
    t: np.ndarray
    direction: np.ndarray
    rays_traced: int = 0
    levels_used: int = 0
    unresolved_w: float = 0.0  # power in mixed leaves not covered by an exact outline integral
    truncated_w: float = 0.0  # power outside the square
    half_width: float = HALF_WIDTH  # the square's half-width L [1/e radii] (the beam's)
    exact_targets: frozenset = frozenset()  # flat targets whose outline integral is their power
    occluders: dict = field(default_factory=dict)  # exact target -> the exact targets in front of it (outlines subtracted)
    unseen_w: dict = field(default_factory=dict)  # sampled target -> power [W] of leaves its hull meets with no ray on it and one on nothing
    _lookup: dict = field(default_factory=dict, repr=False)

    @property
    def mixed(self) -> np.ndarray:
        return mixed_rows(self.labels)

    def size(self, level=None) -> np.ndarray:
        lv = self.level if level is None else level
        return 2 * self.half_width / (self.n0 * 2.0 ** lv)

    def bounds(self, rows=None):
        """Cell bounds (s0, s1, t0, t1) of the leaves (or rows of them)."""
        sl = slice(None) if rows is None else rows
        d = self.size(self.level[sl])
        s0 = -self.half_width + self.i[sl] * d
        t0 = -self.half_width + self.j[sl] * d
        return s0, s0 + d, t0, t0 + d

    def moments(self, rows=None):
        """Per leaf and axis: the Gaussian-weighted mean and variance of s inside the cell
        (truncated normal of density ~ exp(-s^2) on [a, b]: mean
        ``(e^-a^2 - e^-b^2) / (sqrt(pi) Z)``, second moment
        ``1/2 + (a e^-a^2 - b e^-b^2) / (sqrt(pi) Z)``, ``Z = erf b - erf a``); cells too
        small or too far out for that to be accurate use the uniform mean and ``h^2/12``.
        Returns (mean (n, 2), variance (n, 2))."""
        s0, s1, t0, t1 = self.bounds(rows)
        means, vars_ = [], []
        for a, b in ((s0, s1), (t0, t1)):
            z = _erf(b) - _erf(a)
            ea, eb = np.exp(-a * a), np.exp(-b * b)
            good = z > 1e-6 * (b - a)
            zs = np.where(good, z, 1.0) * math.sqrt(math.pi)
            m = np.where(good, (ea - eb) / zs, 0.5 * (a + b))
            m2 = 0.5 + (a * ea - b * eb) / zs
            v = np.where(good, m2 - m * m, (b - a) ** 2 / 12)
            v = np.where((v >= 0) & (v <= (b - a) ** 2 / 4), v, (b - a) ** 2 / 12)
            m = np.clip(m, a, b)
            means.append(m)
            vars_.append(v)
        return np.stack(means, axis=1), np.stack(vars_, axis=1)

    def max_profile(self, rows=None) -> np.ndarray:
        """``exp(-min |s|^2)`` over each leaf: the Gaussian's largest value in the cell."""
        s0, s1, t0, t1 = self.bounds(rows)
        ds = np.where(s0 > 0, s0, np.where(s1 < 0, -s1, 0.0))
        dt = np.where(t0 > 0, t0, np.where(t1 < 0, -t1, 0.0))
        return np.exp(-(ds * ds + dt * dt))

    def leaf_of(self, s) -> np.ndarray:
        """Index of the leaf containing each point s (N, 2); -1 outside the square."""
        s = np.asarray(s, float)
        out = np.full(len(s), -1)
        if not self._lookup:
            for lv in np.unique(self.level):
                rows = np.flatnonzero(self.level == lv)
                n = self.n0 * 2**int(lv)
                key = self.i[rows].astype(np.int64) * n + self.j[rows]
                order = np.argsort(key)
                self._lookup[int(lv)] = (n, key[order], rows[order])
        half = self.half_width
        inside = np.all(np.isfinite(s), axis=1) & np.all(np.abs(np.nan_to_num(s)) < half, axis=1)
        for _lv, (n, keys, rows) in self._lookup.items():
            todo = np.flatnonzero(inside & (out < 0))
            if not len(todo):
                break
            d = 2 * half / n
            ii = np.floor((s[todo, 0] + half) / d).astype(np.int64)
            jj = np.floor((s[todo, 1] + half) / d).astype(np.int64)
            key = ii * n + jj
            pos = np.clip(np.searchsorted(keys, key), 0, len(keys) - 1)
            found = keys[pos] == key
            out[todo[found]] = rows[pos[found]]
        return out


CELL_OFFSETS = np.array([[0.5, 0.5], [0.0, 0.0], [1.0, 0.0], [0.0, 1.0], [1.0, 1.0]])


def _ray_s(s0, t0, d) -> np.ndarray:
    """The five rays (centre, four corners) of cells with lower corners (s0, t0) and side
    d, as s coordinates (5n, 2), cell by cell."""
    base = np.stack([s0, t0], axis=1)
    return (base[:, None, :] + CELL_OFFSETS[None, :, :] * d).reshape(-1, 2)


def _trace_cells(beam, tracer, s):
    """What the five rays per cell (``_ray_s``) hit: labels and faces (n, 5), the centre
    ray's hit point, range and unit direction, and the axial depth [m] of each ray's hit
    (n, 5; inf where it meets nothing; :func:`hit_depths_m`)."""
    o, dirs = beam.rays(s)
    hits = tracer.first_hit(o, dirs)
    n = len(s) // 5
    labels = np.where(hits.hit, hits.obj, -1).reshape(n, 5)
    faces = np.where(hits.hit, hits.face, -1).reshape(n, 5)
    unit = dirs / np.linalg.norm(dirs, axis=1, keepdims=True)
    c = np.arange(n) * 5
    return labels, faces, hits.point[c], hits.t[c], unit[c], hit_depths_m(beam, tracer, hits).reshape(n, 5)


def hit_depths_m(beam, tracer, hits) -> np.ndarray:
    """Axial depth ``(point - aperture) . axis`` [m] of each hit (inf: none), kept within
    the depths of the hit triangle's vertices (a tracer with ``vertices`` and ``faces``:
    a ray grazing a triangle's plane gets its float64 range from that plane, which may
    lie far from the triangle; the hit itself lies on it)."""
    hit = hits.hit
    depth = np.full(len(hit), np.inf)
    rows = np.flatnonzero(hit)
    depth[rows] = (hits.point[rows] - beam.position_m) @ beam.axis
    verts, tris = getattr(tracer, "vertices", None), getattr(tracer, "faces", None)
    if isinstance(verts, np.ndarray) and isinstance(tris, np.ndarray) and len(rows):
        corner = (verts[tris[hits.face[rows]]] - beam.position_m) @ beam.axis  # (N, 3)
        depth[rows] = np.clip(depth[rows], corner.min(axis=1), corner.max(axis=1))
    return depth


def _seed_cells(seeds, s0, t0, d, cell_i, cell_j, half_width):
    """Cells (lower corners s0 = -half_width + cell_i d, t0 likewise; side d) larger than
    twice a target's projected width that contain one of its projected points or overlap
    the hull of them. Each point is tested against the three cells about its own in each
    axis, with the comparisons of the cell bounds themselves (a loop over the points made
    a 2e4-triangle mesh in the beam take 34 s of CPU in this function alone); the hull by
    separating axes (:func:`_boxes_meet_convex`): a long thin target's middle, far from its
    vertices, may lie between every ray of the cells it crosses."""
    force = np.zeros(len(s0), bool)
    if not seeds or not len(s0):
        return force
    keys = []
    for pts, extent, *hull in seeds:  # (points, width) or a Seed
        if not d > extent / 2:
            continue
        p = np.asarray(pts, float)
        base = np.floor((p + half_width) / d).astype(np.int64)
        for a in (-1, 0, 1):
            for b in (-1, 0, 1):
                ci, cj = base[:, 0] + a, base[:, 1] + b
                lo_s, lo_t = -half_width + ci * d, -half_width + cj * d
                ok = (p[:, 0] >= lo_s) & (p[:, 0] < lo_s + d) & (p[:, 1] >= lo_t) & (p[:, 1] < lo_t + d)
                keys.append(ci[ok] * _KEY + cj[ok])
        if hull and hull[0] is not None:
            force |= _boxes_meet_convex(hull[0], np.asarray(s0, float), np.asarray(t0, float), d)
    if keys:
        force |= np.isin(np.asarray(cell_i, np.int64) * _KEY + np.asarray(cell_j, np.int64), np.concatenate(keys))
    return force


_KEY = np.int64(1) << 32  # cell (i, j) -> i * 2^32 + j: the grid is at most n0 2^MAX_LEVEL cells across


def _boxes_meet_convex(hull, s0, t0, d) -> np.ndarray:
    """Whether the squares [s0, s0 + d] x [t0, t0 + d] (``d`` one side or one per square)
    share a point with the convex polygon ``hull`` (V, 2), closed sets: by separating axes
    (the squares' two and the polygon's edge normals), for the squares in the polygon's
    bounding box."""
    d = np.broadcast_to(np.asarray(d, float), np.shape(s0))
    lo, hi = hull.min(axis=0), hull.max(axis=0)
    out = (s0 <= hi[0]) & (s0 + d >= lo[0]) & (t0 <= hi[1]) & (t0 + d >= lo[1])
    rows = np.flatnonzero(out)
    if not len(rows) or len(hull) < 3:
        return out
    normal = _edge_normals(hull)  # either orientation: both ends of each interval are tested
    proj = hull @ normal.T  # (V, E)
    pmin, pmax = proj.min(axis=0), proj.max(axis=0)
    spread = np.abs(normal).sum(axis=1)
    for a in range(0, len(rows), 4096):
        r = rows[a:a + 4096]
        centre = np.stack([s0[r] + d[r] / 2, t0[r] + d[r] / 2], axis=1) @ normal.T  # (N, E)
        reach = d[r, None] / 2 * spread[None]
        out[r] = np.all((centre - reach <= pmax) & (centre + reach >= pmin), axis=1)
    return out


class Seed(NamedTuple):
    """A target's vertices and centre projected into s (those in the beam square), the
    projection's width (the least over its hull's edges' normals: a tilted strip is as
    thin as it looks), the hull (None when the points span no area), its index and
    whether it is convex (:data:`hazard.physics.rays.CONVEX_SHAPES`: its projection is
    its hull), and the least axial depth [m] of its exact surface (:func:`nearest_depth_m`;
    -inf, the default, makes whatever a ray meets count as possibly behind it)."""

    points: np.ndarray
    extent: float
    hull: np.ndarray | None
    index: int
    convex: bool = True
    near_m: float = -math.inf


def target_seeds(beam: BeamGeometry, targets) -> list[Seed]:
    """A :class:`Seed` per target whose projection reaches the beam square."""
    seeds = []
    square = (np.array([-beam.half_width]), np.array([-beam.half_width]), 2 * beam.half_width)
    for t in targets:
        v = t.mesh.vertices
        pts = np.vstack([v, v.mean(axis=0, keepdims=True), t.center_m[None]])
        s, z = beam.to_s(pts)
        s = s[np.all(np.isfinite(s), axis=1) & (z > 0)]
        if len(s) == 0:
            continue
        inside = s[np.all(np.abs(s) < beam.half_width, axis=1)]
        hull, extent = _hull_and_width(s)
        # a closed shape's projected outline is at least its hull's least width
        if len(inside) or (hull is not None and _boxes_meet_convex(hull, *square)[0]):
            seeds.append(Seed(inside, max(extent, 1e-9), hull, t.index, getattr(t.spec, "shape", None) in CONVEX_SHAPES,
                              nearest_depth_m(beam, t)))
    return seeds


def nearest_depth_m(beam: BeamGeometry, target) -> float:
    """The least axial depth ``(x - aperture) . axis`` [m] over a target's exact surface:
    its mesh vertices' (exact for plates and boxes), lowered to the exact sphere's,
    capped cylinder's or disk's (their meshes are inscribed in them: the surface reaches
    nearer than the vertices)."""
    u, pos = beam.axis, beam.position_m
    depth = float(np.min((np.asarray(target.mesh.vertices, float) - pos) @ u))
    an = target.mesh.analytic
    if an is not None and an[0] == "sphere":
        depth = min(depth, float((np.asarray(an[1], float) - pos) @ u) - float(an[2]))
    elif an is not None and an[0] == "cylinder":
        along = abs(float(np.asarray(an[2], float) @ u))
        reach = float(an[4]) * along + float(an[3]) * math.sqrt(max(1.0 - along * along, 0.0))
        depth = min(depth, float((np.asarray(an[1], float) - pos) @ u) - reach)
    elif getattr(target.spec, "shape", None) == "disk":
        tilt = float(np.asarray(target.normal, float) @ u)
        reach = target.spec.size_m[0] / 2 * math.sqrt(max(1.0 - tilt * tilt, 0.0))
        depth = min(depth, float((target.center_m - pos) @ u) - reach)
    return depth


def _edge_normals(hull) -> np.ndarray:
    """Normals (E, 2) of a polygon's edges, as long as the edges (one orientation)."""
    edge = np.roll(hull, -1, axis=0) - hull
    return np.stack([edge[:, 1], -edge[:, 0]], axis=1)


def _hull_and_width(s) -> tuple:
    """The convex hull (V, 2) of points s (N, 2) and its least width (over its edges'
    normals); (None, the bounding box's smaller side) when they span no area."""
    box = float(np.min(np.ptp(s, axis=0))) if len(s) > 1 else 0.0
    hull = _hull_s(s) if box > 0 else None
    if hull is None or len(hull) < 3:
        return None, box
    normal = _edge_normals(hull)
    proj = hull @ (normal / np.linalg.norm(normal, axis=1)[:, None]).T
    return hull, min(box, float(np.min(proj.max(axis=0) - proj.min(axis=0))))


def inside_convex(points_s, polygon_s, margin=0.0) -> np.ndarray:
    """Points (N, 2) inside a convex polygon (V, 2) by more than ``margin`` (distance from
    every edge's line), either orientation (chunked)."""
    pts = np.asarray(points_s, float)
    poly = np.asarray(polygon_s, float)
    nxt = _next(poly)
    edge = nxt - poly
    length = np.sqrt((edge * edge).sum(1))
    orient = np.sign(_signed_area2(poly))
    # many-sided polygons (disks): settle the points well inside the inscribed circle
    # about the centroid, or outside the circumscribed one, without the edge loop
    c = poly.mean(axis=0)
    rel_c = poly - c
    r_in = float(np.min(orient * (edge[:, 0] * (-rel_c[:, 1]) - edge[:, 1] * (-rel_c[:, 0])) / np.where(length > 0, length, 1.0)))
    r_out = float(np.sqrt((rel_c * rel_c).sum(1).max()))
    d = np.sqrt(((pts - c) ** 2).sum(1))
    out = d < r_in - margin - 1e-12 * (1 + r_out) if r_in > 0 else np.zeros(len(pts), bool)
    todo = np.flatnonzero(~out & (d <= r_out + abs(margin) + 1e-12 * (1 + r_out)))
    for a in range(0, len(todo), 8192):
        q = pts[todo[a:a + 8192]]
        rel = q[:, None, :] - poly[None, :, :]
        cross = edge[None, :, 0] * rel[..., 1] - edge[None, :, 1] * rel[..., 0]
        out[todo[a:a + 8192]] = np.all(cross * orient > margin * length[None, :], axis=1)
    return out


@dataclass
class OutlineCells:
    """A flat target's projected outline cut by the beam's coarsest cells: per piece its
    cell key (``i n0 + j``), vertices in s and exact Gaussian moments
    (:func:`hazard.physics.beam.polygon_moments`)."""

    keys: np.ndarray
    pieces: list
    moments: object


def outline_cells(outline_s, n0, half_width=HALF_WIDTH) -> OutlineCells:
    """Clip a convex outline (V, 2) by the coarsest grid (``n0`` cells per side over the
    beam square of half-width ``half_width`` 1/e radii); pieces carrying no power are dropped."""
    d = 2 * half_width / n0
    lo = np.clip(np.floor((outline_s.min(axis=0) + half_width) / d).astype(int), 0, n0 - 1)
    hi = np.clip(np.floor((outline_s.max(axis=0) + half_width) / d).astype(int), 0, n0 - 1)
    ii, jj = (g.ravel() for g in np.meshgrid(np.arange(lo[0], hi[0] + 1), np.arange(lo[1], hi[1] + 1), indexing="ij"))
    s0, t0 = -half_width + ii * d, -half_width + jj * d
    corners = np.stack([np.stack([s0 + a * d, t0 + b * d], axis=1) for a, b in ((0, 0), (1, 0), (1, 1), (0, 1))], axis=1)
    full = inside_convex(corners.reshape(-1, 2), outline_s).reshape(-1, 4).all(axis=1)
    pieces = [corners[k] if full[k] else clip_to_box(outline_s, s0[k], s0[k] + d, t0[k], t0[k] + d) for k in range(len(s0))]
    live = [k for k, p in enumerate(pieces) if len(p) >= 3]
    m = polygon_moments([pieces[k] for k in live])
    keep = np.flatnonzero(m.fraction > 0)
    rows = np.asarray(live, int)[keep]
    if not len(rows):  # wholly outside the beam square (< 3.1e-8 of the power): one piece
        whole = polygon_moments([outline_s])
        return OutlineCells(np.array([-1]), [np.asarray(outline_s, float)], whole) if whole.fraction[0] > 0 else \
            OutlineCells(np.zeros(0, int), [], whole)
    return OutlineCells((ii * n0 + jj)[rows], [pieces[k] for k in rows], m.take(keep))


def _foreign_hits(beam, targets, outlines, foreign, s, labels, depth):
    """Add to ``foreign[k]`` the objects hit before flat target k's plane by rays (at s
    (5n, 2); labels and the hits' axial depths [m] (n, 5; inf: none), :func:`hit_depths_m`)
    inside k's outline other than k itself (in place). A hit beyond the plane, or none,
    along a ray inside the outline is a float32 graze past k's edge: no evidence of
    anything in front (:func:`before_plane`)."""
    lab, deep = labels.ravel(), depth.ravel()
    for k, poly in outlines.items():
        rows = np.flatnonzero(lab != k)
        if not len(rows):
            continue
        rows = rows[inside_convex(s[rows], poly, margin=1e-6)]  # within 1e-6 w of the outline: a graze either way
        if len(rows):
            foreign[k].update(np.unique(lab[rows][before_plane(beam, targets[k], s[rows], deep[rows])]).tolist())


def before_plane(beam, target, s, depth_m) -> np.ndarray:
    """Whether hits at axial depths ``depth_m`` [m] (:func:`hit_depths_m`; inf: none) along
    the beam's rays through ``s`` (N, 2) lie before flat ``target``'s plane (by more than
    1e-9 of the way to it: a hit beyond it, or on it, is a float32 graze past the target's
    edge)."""
    o, dirs = beam.rays(np.asarray(s, float).reshape(-1, 2))
    unit = dirs / np.linalg.norm(dirs, axis=1, keepdims=True)
    with np.errstate(divide="ignore", invalid="ignore"):
        plane_m = ((target.center_m - o) @ target.normal) / (unit @ target.normal)
        plane_depth = (o - beam.position_m) @ beam.axis + plane_m * (unit @ beam.axis)
        return np.asarray(depth_m) < plane_depth - 1e-9 * np.abs(plane_m)


def _piece_hits(beam, tracer, targets, outlines, n0, foreign) -> int:
    """Add to ``foreign[k]`` what a ray through each piece of flat target k's outline cut
    by the coarsest cells (through the piece's power-weighted mean, inside it) meets before
    k's plane; returns the rays traced. The cells' own rays may never fall inside a part
    of an outline: a thin target whose edges lie on the cells' rays, behind a cell that
    shows another target at all five of its rays. The outline would then look clean where
    that target hides it. (A hit beyond the plane is a float32 graze past k's edge: no
    evidence; nothing else can be there.)"""
    points = {k: outline_cells(poly, n0, beam.half_width).moments.mean for k, poly in outlines.items()}
    points = {k: p[np.all(np.isfinite(p), axis=1)] for k, p in points.items()}
    points = {k: p for k, p in points.items() if len(p)}
    if not points:
        return 0
    s = np.concatenate(list(points.values()))
    hits = tracer.first_hit(*beam.rays(s))
    depth = hit_depths_m(beam, tracer, hits)
    start = 0
    for k, p in points.items():
        rows = slice(start, start + len(p))
        start += len(p)
        front = hits.hit[rows] & (hits.obj[rows] != k) & before_plane(beam, targets[k], s[rows], depth[rows])
        foreign[k].update(np.unique(hits.obj[rows][front]).tolist())
    return len(s)


def exact_classes(foreign) -> dict:
    """Flat targets whose power follows from outlines: k -> the targets in front of it.

    Front targets (nothing else hit inside their outline) map to an empty set; a target
    whose outline shows only front targets (no miss, nothing else) maps to those, whose
    outlines are subtracted from its own. Every other target is sampled by rays.
    """
    front = {k for k, f in foreign.items() if not f}
    out = {k: frozenset() for k in front}
    for k, f in foreign.items():
        if f and f <= front:
            out[k] = frozenset(f)
    return out


def sample_cells(beam: BeamGeometry, tracer, targets, *, n0=16, rtol=1e-4, max_level=MAX_LEVEL, outlines=None) -> CellSampling:
    """Adaptive quadtree over the beam cross-section (see the module notes).

    Refines mixed cells level by level while the power in mixed cells exceeds
    ``rtol * P`` (and seeded cells while they are larger than their target's projection).
    ``outlines`` maps flat targets' indices to their projected outlines (inner bound):
    a cell mixed only between such a target and empty beam needs no refinement while no
    ray inside the outline hits anything else (the outline integral gives the power).
    """
    n0 = max(4, int(n0))
    outlines = outlines or {}
    foreign = {k: set() for k in outlines}
    clean = set(outlines)
    ii, jj = np.meshgrid(np.arange(n0), np.arange(n0), indexing="ij")
    level_i, level_j = ii.ravel(), jj.ravel()
    seeds = target_seeds(beam, targets)
    n_targets = len(targets)
    hit_by_centre = set()
    leaves = {k: [] for k in ("level", "i", "j", "power_w", "labels", "faces", "point", "t", "direction", "depth")}
    rays = _piece_hits(beam, tracer, targets, outlines, n0, foreign)
    lv = 0
    while len(level_i):
        lvl = np.full(len(level_i), lv)
        d = 2 * beam.half_width / (n0 * 2.0**lv)
        s0, t0 = -beam.half_width + level_i * d, -beam.half_width + level_j * d
        s_rays = _ray_s(s0, t0, d)
        labels, faces, point, t, direction, depth = _trace_cells(beam, tracer, s_rays)
        hit_by_centre.update(np.unique(labels[:, 0]).tolist())
        rays += 5 * len(level_i)
        _foreign_hits(beam, targets, outlines, foreign, s_rays, labels, depth)
        clean = set(exact_classes(foreign))
        power = beam.power_w * rectangle_fraction(s0, s0 + d, t0, t0 + d)
        need = _needs_split(labels, clean, seeds, (s0, t0, d))
        split = _seed_cells(seeds, s0, t0, d, level_i, level_j, beam.half_width) | _unseen_cells(labels, hit_by_centre, clean, n_targets)
        if need.any() and power[need].sum() > rtol * beam.power_w:
            split |= need
        if lv >= max_level:
            split[:] = False
        keep = ~split
        for k, v in (("level", lvl), ("i", level_i), ("j", level_j), ("power_w", power), ("labels", labels), ("faces", faces),
                     ("point", point), ("t", t), ("direction", direction), ("depth", depth)):
            leaves[k].append(v[keep])
        level_i = np.concatenate([2 * level_i[split] + a for a in (0, 1, 0, 1)])
        level_j = np.concatenate([2 * level_j[split] + b for b in (0, 0, 1, 1)])
        lv += 1
    cat = {k: np.concatenate(v) for k, v in leaves.items()}
    truncated = beam.power_w * (1.0 - float(_erf(beam.half_width)) ** 2)
    d = 2 * beam.half_width / (n0 * 2.0 ** cat["level"])
    boxes = (-beam.half_width + cat["i"] * d, -beam.half_width + cat["j"] * d, d)
    unresolved = float(cat["power_w"][_needs_split(cat["labels"], clean, seeds, boxes)].sum())
    out = CellSampling(n0, cat["level"], cat["i"], cat["j"], cat["power_w"], cat["labels"], cat["faces"], cat["point"], cat["t"],
                       cat["direction"], rays, lv, unresolved, truncated, half_width=beam.half_width)
    out.exact_targets = frozenset(clean)
    out.occluders = {k: v for k, v in exact_classes(foreign).items() if v}
    out.unseen_w = _unseen_power(seeds, clean, cat["labels"], cat["depth"], beam.power_w, boxes)
    return out


def _unseen_power(seeds, clean, labels, depth, power_w: float, boxes) -> dict:
    """Per convex target the rays sample (not clean): the beam's power [W] in the parts of
    its projected hull inside leaves that have no ray on it and that do not show one
    object in front of all of it at all five rays (exact Gaussian integrals of hull and
    leaf, :func:`polygon_moments`): a ray that meets nothing, or meets something at an
    axial depth beyond the target's nearest point (a wall behind it), passes where the
    target may be, and between two objects there may be a gap; part of the target may
    then lie between the rays. ``labels``, ``depth``: the leaves' objects and the axial
    depths [m] of their hits (n, 5; inf: nothing); ``power_w``: the beam's total [W];
    ``boxes``: the leaves' (s0, t0, d). A mesh's hull also covers its hollows, where rays
    that meet nothing are the truth: it is left out (its rays and the refinement decide,
    as before)."""
    out = {}
    several = mixed_rows(labels)
    s0, t0, d = boxes
    for seed in seeds:
        if seed.hull is None or seed.index in clean or not seed.convex:
            continue
        # conservative: depths within 1e-9 of the target's nearest point count as behind it
        behind = np.any(depth >= seed.near_m - 1e-9 * (abs(seed.near_m) + 1.0), axis=1)
        rows = np.flatnonzero((behind | several) & ~np.any(labels == seed.index, axis=1))
        rows = rows[_boxes_meet_convex(seed.hull, s0[rows], t0[rows], d[rows])]
        parts = [clip_to_box(seed.hull, s0[r], s0[r] + d[r], t0[r], t0[r] + d[r]) for r in rows]
        parts = [p for p in parts if len(p) >= 3]
        out[seed.index] = power_w * float(polygon_moments(parts).fraction.sum()) if parts else 0.0
    return out


def _unseen_cells(labels, hit_by_centre, clean, n_targets) -> np.ndarray:
    """Cells touching a (non-clean) target that no centre ray has hit yet: split them
    until one does, so a target thinner than the cells still gets a spot."""
    unseen = [k for k in np.unique(labels[:, 1:]) if 0 <= k < n_targets and k not in hit_by_centre and k not in clean]
    if not unseen:
        return np.zeros(len(labels), bool)
    return np.any(np.isin(labels, unseen), axis=1)


def _needs_split(labels, clean, seeds=(), boxes=None) -> np.ndarray:
    """Mixed cells, except those mixed only between clean flat targets and empty beam,
    unless such a cell meets the projected hull of a target the rays must sample (one of
    ``seeds`` not clean; ``boxes``: the cells' lower corners and sides (s0, t0, d)): that
    target may lie between its rays (a sphere's rim beside a plate's edge)."""
    mixed = mixed_rows(labels)
    if not clean:
        return mixed
    benign = mixed & np.all(np.isin(labels, list(clean) + [-1]), axis=1)
    rows = np.flatnonzero(benign)
    sampled = [seed.hull for seed in seeds if seed.hull is not None and seed.index not in clean]
    if boxes is not None and len(rows) and sampled:
        s0, t0, d = (np.broadcast_to(np.asarray(x, float), labels.shape[:1])[rows] for x in boxes)
        for hull in sampled:
            benign[rows[_boxes_meet_convex(hull, s0, t0, d)]] = False
    return mixed & ~benign


def flat_outline_s(beam: BeamGeometry, target, n_disk=1024):
    """A flat target's outline in s: (polygon, lower-bound polygon) or None when any part
    is not in front of the aperture (then the ray sampling decides). A plate's polygon is
    exact (both the same); a disk's ellipse lies between the inscribed and circumscribed
    polygons of ``n_disk`` sides (the circumscribed one is returned first: the upper bound).
    """
    spec = target.spec
    x, z = target.tangent, target.normal
    y = np.cross(z, x)
    c = target.center_m
    if spec.shape == "plate":
        hw, hh = spec.size_m[0] / 2, spec.size_m[1] / 2
        corners = [c + sx * hw * x + sy * hh * y for sx, sy in ((-1, -1), (1, -1), (1, 1), (-1, 1))]
        outer = inner = np.array(corners)
    elif spec.shape == "disk":
        r = spec.size_m[0] / 2
        a = 2 * math.pi * np.arange(n_disk) / n_disk
        ring = np.cos(a)[:, None] * x + np.sin(a)[:, None] * y
        inner = c + r * ring
        outer = c + r / math.cos(math.pi / n_disk) * ring
    else:
        return None
    so, zo = beam.to_s(outer)
    si, zi = (so, zo) if inner is outer else beam.to_s(inner)  # a plate: one exact polygon (the same object)
    if np.any(zo <= 0) or np.any(zi <= 0) or not (np.all(np.isfinite(so)) and np.all(np.isfinite(si))):
        return None
    return so, si


def _disk_ring_s(beam: BeamGeometry, centre, normal, radius, n, outer):
    """A disk (centre, unit normal, radius [m]) as a regular n-gon in s: inscribed in its
    projected ellipse (``outer`` False) or circumscribed about it (True: central
    projection keeps lines and tangency). None when any vertex is not ahead of the aperture."""
    x, _ = perp_basis(normal)
    y = np.cross(normal, x)
    a = 2 * math.pi * np.arange(n) / n
    scale = radius / math.cos(math.pi / n) if outer else radius
    ring = centre + scale * (np.cos(a)[:, None] * x + np.sin(a)[:, None] * y)
    s, z = beam.to_s(ring)
    if np.any(z <= 0) or not np.all(np.isfinite(s)):
        return None
    return s


def _hull_s(points_s) -> np.ndarray:
    """Convex hull (V, 2) of points in s, counter-clockwise (Qhull)."""
    from scipy.spatial import ConvexHull

    from scipy.spatial import QhullError

    pts = np.unique(np.asarray(points_s, float), axis=0)
    if len(pts) < 3:
        return pts
    try:
        return pts[ConvexHull(pts).vertices]
    except QhullError:  # collinear (no area)
        return pts[:0]


def _convex_outline_s(beam, analytic, radius, half_length, n, outer):
    """The s-outline (a polygon) of a sphere or capped cylinder of the given radius (and
    half-length) with the analytic shape's centre and axis: the projection of the sphere's
    contour disk as seen from the beam's virtual source, or the hull of the cylinder's two
    end disks (a cylinder is their convex hull; central projection keeps hulls)."""
    c = np.asarray(analytic[1], float)
    if analytic[0] == "sphere":
        if beam.divergence_rad > 0:
            rel = c - (beam.position_m - beam.axis * (beam.diameter_m / beam.divergence_rad))
            dist = float(np.linalg.norm(rel))
            if dist <= radius * (1 + 1e-9):
                return None
            u = rel / dist
            centre, rho = c - (radius * radius / dist) * u, radius * math.sqrt(1.0 - (radius / dist) ** 2)
        else:
            u, centre, rho = beam.axis, c, radius
        return _disk_ring_s(beam, centre, u, rho, n, outer)
    ax = np.asarray(analytic[2], float)
    ends = [_disk_ring_s(beam, c + sgn * half_length * ax, ax, radius, n, outer) for sgn in (-1.0, 1.0)]
    if any(e is None for e in ends):
        return None
    return _hull_s(np.vstack(ends))


def curved_outline_s(beam: BeamGeometry, mesh, n=1024):
    """A sphere's or capped cylinder's outline in s, exact to its polygons, and the
    outline of its triangle mesh: (outer, inner, mesh_outline) or None (not an analytic
    shape, or not wholly ahead of the aperture).

    ``outer`` circumscribes and ``inner`` is inscribed in the exact outline (n-gons of
    the projected contour / end disks: between them ``1/cos^2(pi/n) - 1`` = 9.4e-6 of its
    area for n = 1024). The mesh is a convex polyhedron with its vertices on the surface,
    so its outline is the hull of its projected vertices, inside the exact one: the
    Gaussian power between ``outer`` and it bounds what the faceting loses.
    """
    an = mesh.analytic
    if an is None or an[0] not in ("sphere", "cylinder"):
        return None
    r, h = (float(an[2]), 0.0) if an[0] == "sphere" else (float(an[3]), float(an[4]))
    outer = _convex_outline_s(beam, an, r, h, n, True)
    inner = _convex_outline_s(beam, an, r, h, n, False)
    sv, zv = beam.to_s(mesh.vertices)
    if outer is None or inner is None or np.any(zv <= 0) or not np.all(np.isfinite(sv)):
        return None
    return outer, inner, _hull_s(sv)


def inside_convex_many(points_s, polygon_s) -> np.ndarray:
    """Points (N, 2) inside or on a convex polygon (V, 2) of many sides, in O(N log V):
    the edge facing each point is found by its angle about the vertices' mean (the
    polygon is star-shaped about it), then one cross product decides."""
    pts = np.asarray(points_s, float)
    poly = np.asarray(polygon_s, float)
    if _signed_area2(poly) < 0:
        poly = poly[::-1]
    c = poly.mean(axis=0)
    ang = np.arctan2(poly[:, 1] - c[1], poly[:, 0] - c[0])
    start = int(np.argmin(ang))
    poly, ang = np.roll(poly, -start, axis=0), np.roll(ang, -start)
    q = np.arctan2(pts[:, 1] - c[1], pts[:, 0] - c[0])
    i = (np.searchsorted(ang, q, side="right") - 1) % len(poly)
    a, b = poly[i], poly[(i + 1) % len(poly)]
    cross = (b[:, 0] - a[:, 0]) * (pts[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (pts[:, 0] - a[:, 0])
    return cross >= -1e-12 * (1.0 + np.abs(pts).sum(1))
