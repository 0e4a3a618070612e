"""Outlines of the keep-out lobes for the plan and elevation views (issue 18).

A spot's keep-out lobe is the region ``L = {c + r w : 0 <= r <= R(w)}`` with ``c`` the
spot's centroid and ``R(w)`` the NOHD in the reflection direction ``w``
(:mod:`hazard.physics.keepout`: the range at which the reflected irradiance falls to the MPE;
the dynamic lobe is the maximum over the history). ``L`` is star-shaped about ``c``.
Two cuts of it are drawn:

Projection along ``n`` onto the plane of ``a``, ``b`` (the plan view of a scene without
ground, the elevation view). The projection is star-shaped about ``c``'s projection and
its radius at the in-plane angle ``alpha`` is::

    rho(alpha) = max over |beta| < 90 deg of R(w) cos(beta),
    w = cos(beta) (cos(alpha) a + sin(alpha) b) + sin(beta) n

(the point ``rho u + t n`` is in ``L`` iff ``rho <= R(w) cos(beta)``, ``tan(beta) = t / rho``).

Section by the surface at eye height above the terrain (the plan view of a scene with
ground): the points ``P`` at height ``terrain(x, y) + h`` with ``|P - c| <= R(w)``,
``w = (P - c) / |P - c|``. The section need not be star-shaped about ``c`` (a lobe
aimed upward and out crosses the eye-height surface in a band or a blob away from it),
so it is sampled on a polar grid about ``c``'s plan position.

Sampling, drawn outward (never toward "safe"): angles on a uniform grid plus the
azimuths of the lobe's maximum and of the mirror direction (where narrow lobes peak). In
a projection the best out-of-plane angle is refined on a grid ten times finer about the
best sample, and the curvature margin (second difference / 8) is added, so a smooth
maximum between samples is not missed; between two sampled in-plane angles the wedge
takes the larger of its two edges plus the same margin, on an arc of radius
``rho / cos(step / 2)`` (the chord never cuts inside). In a section every hazardous run
of radii is widened by one radial step on each side, and a wedge is hazardous where
either of its edges is. What is left is a
lobe narrower than the angle step *and* away from the lobe's own maximum: the outline's
``angle_step_deg`` says how fine the grid was.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from hazard.physics.engine import mirror_axis
from hazard.physics.keepout import nohd_range_fn

__all__ = ["Outline", "View", "projected_outline", "section_outline", "lobe_outlines", "plan_view_frame", "elevation_frame"]

ANGLE_STEP_DEG = 1.0  # in-plane angle step of the outlines (plan and elevation views)
BETA_STEP_DEG = 0.5  # out-of-plane angle step of a projection
RADIAL_SAMPLES = 320  # log-spaced radii of a section, from RADIAL_SPAN x the lobe's reach to it (2.2 % steps)
RADIAL_SPAN = 1e-3
REFINE = 10  # a projection's best out-of-plane angle is refined on a grid this many times finer
CHUNK = 20000  # directions per evaluation (bounded memory for large bases)


@dataclass(frozen=True)
class View:
    """A 2-D view of the scene: coordinates ``((P - origin) . a, (P - origin) . b)`` [m],
    looking along ``n`` (a, b, n orthonormal)."""

    origin_m: np.ndarray
    a: np.ndarray
    b: np.ndarray
    n: np.ndarray
    name: str

    def to_2d(self, points_m) -> np.ndarray:
        d = np.asarray(points_m, float) - self.origin_m
        return np.stack([d @ self.a, d @ self.b], axis=-1)


def plan_view_frame(origin_m=(0.0, 0.0, 0.0)) -> View:
    """Top-down: x (east), y (north), looking down z."""
    return View(np.asarray(origin_m, float), np.array([1.0, 0, 0]), np.array([0, 1.0, 0]), np.array([0, 0, 1.0]), "plan")


def elevation_frame(laser_m, aim_direction) -> View:
    """Side view: horizontal distance along the aim's azimuth from the laser, and height
    z (the frame's, not above the laser); looking across the aim (a vertical aim falls
    back to +y)."""
    d = np.asarray(aim_direction, float)
    u = np.array([d[0], d[1], 0.0])
    u = u / np.linalg.norm(u) if np.linalg.norm(u) > 1e-9 else np.array([0.0, 1.0, 0.0])
    z = np.array([0.0, 0.0, 1.0])
    origin = np.array([float(laser_m[0]), float(laser_m[1]), 0.0])  # heights stay heights (z of the frame)
    return View(origin, u, z, np.cross(z, u), "elevation")


@dataclass
class Outline:
    """The outline of one lobe in one view: a shapely (Multi)Polygon in the view's 2-D
    coordinates [m], empty where the lobe does not reach the cut."""

    target: str
    kind: str  # "static" or "dynamic"
    cut: str  # "projection" or "section at <h> m eye height"
    geometry: object
    angle_step_deg: float
    radial_step_rel: float = 0.0  # a section's radial step, relative (0 for a projection: exact in radius)

    def rings(self) -> list:
        """Exterior rings (K, 2) of the outline's polygons [m] (holes: :meth:`holes`)."""
        return [np.asarray(p.exterior.coords) for p in _polygons(self.geometry)]

    def holes(self) -> list:
        return [np.asarray(r.coords) for p in _polygons(self.geometry) for r in p.interiors]

    @property
    def area_m2(self) -> float:
        return float(self.geometry.area)


def _polygons(geom) -> list:
    if geom.is_empty:
        return []
    return list(geom.geoms) if hasattr(geom, "geoms") else [geom]


def _local_range_fn(spot, mpe_w_m2, mu, states):
    """NOHD [m] for world directions (N, 3): 0 below the spot's surface."""
    fn = nohd_range_fn(spot, mpe_w_m2, mu, 1.0, states)
    frame = spot.mean_frame

    def world_fn(w):
        out = np.zeros(len(w))
        for s in range(0, len(w), CHUNK):
            loc = w[s:s + CHUNK] @ frame.T
            up = loc[:, 2] > 1e-12
            if up.any():
                out[s:s + CHUNK][up] = fn(loc[up])
        return out

    return world_fn


def _angles(view, special, step_deg) -> np.ndarray:
    """Uniform angles in [-pi, pi) plus the in-plane angles of ``special`` directions."""
    base = np.radians(np.arange(-180.0, 180.0, step_deg))
    extra = [math.atan2(float(d @ view.b), float(d @ view.a)) for d in special
             if math.hypot(float(d @ view.a), float(d @ view.b)) > 1e-9]
    return np.unique(np.concatenate([base, extra]))


def _star_polygon(alpha, rho, centre_2d):
    """The star-shaped polygon of radii ``rho`` at angles ``alpha`` (sorted, periodic),
    each wedge at the larger of its edges on an arc that never cuts inside."""
    from shapely.geometry import Polygon

    a_next = np.append(alpha[1:], alpha[0] + 2 * np.pi)
    ext = np.concatenate([rho[-1:], rho, rho[:2]])  # periodic, for the second differences
    margin = np.abs(np.diff(ext, 2))[:-1] / 8.0  # at each angle; a wedge takes both of its ends'
    margin = np.maximum(margin, np.roll(margin, -1))
    r_wedge = (np.maximum(rho, np.roll(rho, -1)) + margin) / np.cos((a_next - alpha) / 2)
    if not np.any(r_wedge > 0):
        return Polygon()
    ang = np.stack([alpha, a_next], 1).ravel()
    r = np.repeat(r_wedge, 2)
    pts = centre_2d + r[:, None] * np.stack([np.cos(ang), np.sin(ang)], 1)
    return Polygon(pts).buffer(0)


def projected_outline(spot, mpe_w_m2, mu, states, view, *, special=(), kind="static",
                      angle_step_deg=ANGLE_STEP_DEG, beta_step_deg=BETA_STEP_DEG) -> Outline:
    """The lobe projected along ``view.n`` (see the module notes): exact in radius at
    each sampled (alpha, beta), drawn outward between angles."""
    fn = _local_range_fn(spot, mpe_w_m2, mu, states)
    special = [np.asarray(d, float) / np.linalg.norm(d) for d in special] + [mirror_axis(spot)]
    alpha = _angles(view, special, angle_step_deg)
    beta = np.radians(np.arange(-90.0 + beta_step_deg, 90.0, beta_step_deg))
    beta = np.unique(np.concatenate([beta, [math.asin(float(np.clip(d @ view.n, -1, 1))) for d in special]]))
    ca, sa = np.cos(alpha)[:, None, None], np.sin(alpha)[:, None, None]
    cb, sb = np.cos(beta)[None, :, None], np.sin(beta)[None, :, None]
    w = cb * (ca * view.a + sa * view.b) + sb * view.n  # (A, B, 3)
    r = fn(w.reshape(-1, 3)).reshape(len(alpha), len(beta))
    rho = _refined_max(fn, view, alpha, beta, r * np.cos(beta)[None, :])
    geom = _star_polygon(alpha, rho, view.to_2d(spot.centroid))
    return Outline(spot.target.name, kind, "projection", geom, float(angle_step_deg))


def _curvature_margin(f) -> np.ndarray:
    """Bound on how far a smooth sampled function's maximum between its samples exceeds
    the larger sample: the second difference / 8 (the maximum is within half a step of a
    sample and ``f - f(sample) <= f'' (h/2)^2 / 2``), at each sample (rows: last axis)."""
    d2 = np.abs(np.diff(f, 2, axis=-1)) / 8.0
    pad = np.zeros(f.shape[:-1] + (1,))
    d2 = np.concatenate([pad, d2, pad], axis=-1)
    return np.maximum(d2, np.maximum(np.roll(d2, 1, axis=-1), np.roll(d2, -1, axis=-1)))


def _refined_max(fn, view, alpha, beta, g) -> np.ndarray:
    """max over beta of ``g`` (A, B) per alpha, refined: a grid ``REFINE`` times finer over
    the step either side of each row's best sample, plus the curvature margin of the
    fine grid (so the answer is not below the true maximum of a smooth ``g``)."""
    j = np.argmax(g, axis=1)
    lo = beta[np.maximum(j - 1, 0)]
    hi = beta[np.minimum(j + 1, len(beta) - 1)]
    t = np.linspace(0.0, 1.0, 2 * REFINE + 1)
    b = lo[:, None] + (hi - lo)[:, None] * t[None, :]  # (A, F)
    ca, sa = np.cos(alpha)[:, None, None], np.sin(alpha)[:, None, None]
    w = np.cos(b)[..., None] * (ca * view.a + sa * view.b) + np.sin(b)[..., None] * view.n
    fine = fn(w.reshape(-1, 3)).reshape(b.shape) * np.cos(b)
    k = np.argmax(fine, axis=1)
    rows = np.arange(len(alpha))
    best = fine[rows, k] + _curvature_margin(fine)[rows, k]
    return np.maximum(best, g.max(axis=1))


def section_outline(spot, mpe_w_m2, mu, states, height_fn, eye_height_m, reach_m, *, special=(), kind="static",
                    angle_step_deg=ANGLE_STEP_DEG, radial_samples=RADIAL_SAMPLES) -> Outline:
    """The lobe cut by the surface ``height_fn(x, y) + eye_height_m`` (plan coordinates,
    the scene's local frame), sampled on a polar grid about the spot out to ``reach_m``
    (the lobe's longest NOHD; see the module notes)."""
    from shapely.geometry import Polygon
    from shapely.ops import unary_union

    view = plan_view_frame()
    fn = _local_range_fn(spot, mpe_w_m2, mu, states)
    special = [np.asarray(d, float) / np.linalg.norm(d) for d in special] + [mirror_axis(spot)]
    alpha = _angles(view, special, angle_step_deg)
    c = np.asarray(spot.centroid, float)
    step = RADIAL_SPAN ** (-1.0 / (radial_samples - 1))
    rho = reach_m * RADIAL_SPAN * step ** np.arange(radial_samples)  # ends at reach_m
    x = c[0] + np.cos(alpha)[:, None] * rho[None, :]
    y = c[1] + np.sin(alpha)[:, None] * rho[None, :]
    z = np.asarray(height_fn(x.ravel(), y.ravel()), float).reshape(x.shape) + eye_height_m
    d = np.stack([x - c[0], y - c[1], z - c[2]], -1).reshape(-1, 3)
    dist = np.linalg.norm(d, axis=1)
    hot = (dist <= fn(d / np.maximum(dist, 1e-300)[:, None])).reshape(x.shape)
    edges = np.concatenate([[0.0], rho, [rho[-1] * step]])  # run k..l drawn from rho[k-1] to rho[l+1]
    a_next = np.append(alpha[1:], alpha[0] + 2 * np.pi)
    pieces, eps = [], 1e-9 * reach_m
    for i in range(len(alpha)):
        either = hot[i] | hot[(i + 1) % len(alpha)]
        for lo, hi in _runs(either):
            r0, r1 = edges[lo], edges[hi + 2] / math.cos((a_next[i] - alpha[i]) / 2)
            arc = np.linspace(alpha[i], a_next[i], 3)
            ring = np.concatenate([np.stack([np.cos(arc), np.sin(arc)], 1) * r1,
                                   np.stack([np.cos(arc[::-1]), np.sin(arc[::-1])], 1) * r0]) + c[:2]
            pieces.append(Polygon(ring).buffer(eps, join_style="mitre"))  # outward: adjacent wedges overlap, never gap
    geom = unary_union(pieces) if pieces else Polygon()
    return Outline(spot.target.name, kind, f"section at {eye_height_m:g} m eye height", geom, float(angle_step_deg),
                   float(step - 1.0))


def _runs(mask) -> list:
    """(first, last) indices of the runs of True in a 1-D mask."""
    m = np.concatenate([[False], np.asarray(mask, bool), [False]])
    d = np.diff(m.astype(np.int8))
    return list(zip(np.flatnonzero(d == 1), np.flatnonzero(d == -1) - 1))


def lobe_outlines(result, view=None) -> list:
    """Outlines of every target's static and dynamic lobe in ``view``: the section at
    ``analysis.footprint_eye_height_m`` over the terrain for the plan view of a scene with
    ground, else the projection. Lobes with no reach are left out (nothing to draw).
    The plan view's (``view`` None) are made once per result: the plan picture and the map
    outputs both draw them (2 s for ``stainless_melt``)."""
    if view is None:
        if getattr(result, "_plan_lobe_outlines", None) is None:
            result._plan_lobe_outlines = _outlines(result, plan_view_frame())
        return list(result._plan_lobe_outlines)
    return _outlines(result, view)


def _outlines(result, view) -> list:
    scene = result.scene
    rows = {t.name: t for t in result.targets}
    out = []
    for sp in result.spots:
        row = rows.get(sp.target.name)
        if row is None or row.static_lobe is None:
            continue
        states = result.states.get(sp.target.index)
        kinds = [("static", None if states is None else states[:1], row.static_lobe)]
        if states is not None:
            kinds.append(("dynamic", states, row.dynamic_lobe))
        for kind, st, lobe in kinds:
            if lobe is None or not lobe.max_range_m > 0:
                continue
            special = [lobe.max_direction_world]
            if view.name == "plan" and scene.terrain is not None:
                eye = scene.spec.analysis.footprint_eye_height_m
                out.append(section_outline(sp, result.mpe_w_m2, result.attenuation_per_m, st, scene.terrain.height_at, eye,
                                           lobe.max_range_m, special=special, kind=kind))
            else:
                out.append(projected_outline(sp, result.mpe_w_m2, result.attenuation_per_m, st, view, special=special,
                                             kind=kind))
    return out
