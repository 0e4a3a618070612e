"""Keep-out lobe near an extended spot: the farthest root of the near-field integral per direction.

The lobe (:mod:`hazard.physics.keepout`) is ``R(w)``, the distance from the spot's **power
centroid** ``c`` (the origin of every lobe distance: lobes, outlines, renders, the
terrain's keep-out distance) along ``w`` to the farthest point where the reflected
irradiance reaches the MPE. The point form ``I(w) exp(-mu R) / R^2`` from ``c`` is that
irradiance only where the whole spot is a point source; the engine uses it for observers
beyond ``FAR_FIELD_SPOT_SIZES`` spot sizes and the exact integral over the spot
(:mod:`hazard.physics.near_field`, range-safety.md section 10) nearer. A spot stretched by
grazing incidence has an elongated zone that the point form misses (a plate at 89.9 deg:
0.52 m from the point form where the integral reaches 6.3 m, 3 deg above the plate).

What is computed. On a fixed grid of directions (polar rows ``THETA_ROWS_DEG`` x
azimuths every ``GRID_PHI_DEG`` in the spot's mean frame), every node whose point-form
range ``r0`` is within ``FAR_FIELD_SPOT_SIZES`` spot sizes gets the farthest root of
``E(c + r w) = MPE`` beyond ``r0``, with ``E`` the engine's near-field integral
(:func:`hazard.physics.engine.near_field_w_m2`: the observers' own computation, each sample a point
source only where its error is proven below 1 % of ``P / d^2``, its triangles integrated
elsewhere). The ray is scanned inward from ``r_start`` in steps ``h`` no larger than the
spot's smallest extent (twice its RMS width across) nor ``r_start / SCAN_MIN_STEPS``; the
first hazardous sample brackets the farthest root, bisected to ``ROOT_RTOL`` (or ``h /
8``); the node's range is the bracket's far end plus ``h`` (the scan's resolution,
added), or ``r0`` where no sample beyond ``r0`` is hazardous; the last sample is
``r0 (1 + FLOOR_RTOL)`` (the point form is kept where the integral's root lies within
0.5 % beyond it: the integral's own 1 % tolerance in irradiance).

Each sample is first tested against a cheap upper bound (the spot's samples as point
sources plus their Taylor remainders, infinite within a sample's radius; for a flat spot
the smaller of that and ``sum_tri E_inc,tri f_max int_tri dA / R^2`` (:meth:`_flat_bound`:
per triangle its own largest incident irradiance, ``f_max`` the material's proven largest
``f_r cos`` where :func:`projected_brdf_max` gives one, else ``FLAT_BOUND_MARGIN I_max /
P``), finite down to the surface: a spot much larger than its lobe, e.g. airspace's board
lit by the beam's far tail, is no longer integrated point by point on its surface, and a
long grazing spot's cold points near it are ruled out without the integral): only where it reaches the
MPE is the integral evaluated. With a history a point is integrated first at its state
of the largest point-form sum alone (hazard there decides), then only at the states whose
own bound reaches the MPE: the same decision as the integral at every state. The integral's work per lobe function is
capped at ``MAX_EVALUATIONS`` kernel evaluations (deterministic); past it the bound alone
decides (never short for a Lambertian spot, looser: ``info["points_by_bound"]`` counts
those points). A call started below the cap stops at ``CEILING_FACTOR`` times it in all,
the points it leaves decided by the bound too (a spot's leaves on a facet edge-on to the
beam map onto triangles kilometres long, each bisected down to every observer's
distance: one call of a scan's 143 first samples cost 674 million evaluations, 391 s).

``r_start``: nothing beyond it can reach the MPE. Every part of the spot is at least
``r - extent`` from ``c + r w`` and seen from it within a cone of half-angle ``asin(extent
/ r)`` (plus the samples' frame tilt) about ``w``, so ``E <= I_cone exp(-mu (r -
extent)) / (r - extent)^2`` with ``I_cone`` the point form's largest intensity in that
cone (sampled on ``CONE_RINGS`` x ``CONE_AZIMUTHS`` directions plus the point form's
peaks inside it): hazard needs ``r <= extent + R_cone(r)``, bisected. ``r_start`` is
also at most where the ray leaves the spot's box widened by the point form's largest
range, and at most the engine's near/far switch (beyond it observers get the point form).

In a cell none of whose four nodes the integral raised past the point form, a direction
keeps its own point form. Elsewhere it takes the largest value of the cell's four nodes
(each never below its point form) plus a curvature margin (the largest negative second difference
of the nodes about the cell / 8 along each axis: a quadratic's rise between two equally
spaced nodes), and never less
than its own point form; nodes whose point form reaches past the near/far switch enter
it capped there, and the envelope is capped at the switch plus the spot's smallest extent
(no near-field root lies beyond). Directions beyond the last polar row (within 0.5 deg of the
spot's plane) take that row's cell.

Not covered (the lobe keeps the point form and the report says so where it matters): a
slumping spot (its union of tilted normals), a spot built without its triangles. With a
history the integral is the largest over the path's states (``path_states``: for a
two-state history its states in time order, not the continuous path between them). The
cone's sampling and the envelope between nodes are not proven for a lobe narrower than
their steps (as the lobe's own grid; measured against the section-10 integral in
``tests/validation/test_near_field_lobes.py``).
"""

from __future__ import annotations

import math
import threading
import time
import weakref

import numpy as np

from brdfmodels import Lambertian, Scaled, StateTable, Sum

from hazard.physics import near_field
from hazard.physics.engine import FAR_FIELD_SPOT_SIZES, frame_groups, near_field_w_m2, to_local, projected_brdf, spot_directions

__all__ = ["NearLobeFn", "near_lobe_fn", "near_field_reach_m", "projected_brdf_max", "ENABLED", "THETA_ROWS_DEG", "GRID_PHI_DEG", "ROOT_RTOL", "FLOOR_RTOL", "SCAN_MIN_STEPS", "MAX_EVALUATIONS",
           "STATS", "describe_since"]

ENABLED = True  # read when a lobe function is made; False: the point form alone (tests of the point-form lobe's machinery)
THETA_ROWS_DEG = (0.0, 15.0, 30.0, 45.0, 60.0, 70.0, 80.0, 85.0, 87.5, 89.0, 89.5)  # polar rows of the grid [deg]
BELOW_ROWS_DEG = tuple(180.0 - t for t in reversed(THETA_ROWS_DEG))  # a curved spot's rows below its mean plane (90.5 ... 180)
GRID_PHI_DEG = 30.0  # azimuth step of the grid [deg]
ROOT_RTOL = 1e-3  # bisection of the farthest root's bracket, relative to its far end (or to 1/8 of the scan step)
FLOOR_RTOL = 0.005  # the point form is kept where the integral's root lies within this of it (its 1 % in irradiance)
SCAN_MIN_STEPS = 8  # the scan's step is at most r_start / this (and at most the spot's smallest extent)
MAX_EVALUATIONS = 500_000  # kernel evaluations of the integral per lobe function; beyond, the samples' bound decides
CEILING_FACTOR = 4  # no call of the integral takes a lobe function's evaluations past this x MAX_EVALUATIONS (its points left: the bound)
CONE_RINGS = (0.25, 0.5, 0.75, 1.0)  # the cone bound's rings, as fractions of its half-angle
CONE_AZIMUTHS = 12  # ... and its azimuths per ring
CONE_BISECTIONS = 8  # bisections of the cone bound's farthest radius
FLAT_BOUND_MARGIN = 4.0  # the flat spot's bound x this where the material's largest f_r cos is not proven (projected_brdf_max): it then rests on the point form's sampled largest intensity
_BOUND_BLOCK = 1 << 22  # (point, sample, state) triples of the samples' bound evaluated at once (bounded memory)


class _Stats:
    """Near-field lobe work in this process: directions integrated, points, seconds."""

    def __init__(self):
        self.directions = self.points = 0
        self.seconds = 0.0

    def snapshot(self) -> dict:
        return dict(directions=self.directions, points=self.points, seconds=self.seconds)


STATS = _Stats()


def describe_since(before: dict) -> str:
    """One line for the keepout stage's detail: the near-field lobe work since ``before``
    (a :meth:`_Stats.snapshot`)."""
    now = STATS.snapshot()
    n = now["directions"] - before["directions"]
    if not n:
        return "near-field lobe: no direction's point-form range within the near field"
    return (f"near-field lobe: {n} grid direction(s) within {FAR_FIELD_SPOT_SIZES:g} spot sizes integrated "
            f"({now['points'] - before['points']} points; its time is in the stage's seconds)")


def _incident_w_m2(spot) -> np.ndarray:
    """Largest irradiance [W/m^2] the beam lays on each of the spot's triangles (K,) (a
    bound): its power density in beam coordinates ``c exp(-|s|^2)`` at its point nearest
    ``s = 0`` times ``area_s / area_x`` (the affine map's), with the spot's current
    powers, raised by the perspective map's largest stretch over the triangle;
    infinite for a triangle of no area on the surface."""
    p = spot.patches
    v = p.tri_s
    d2 = np.full(len(v), np.inf)  # squared distance of s = 0 from each triangle's edges
    for i in range(3):
        a, e = v[:, i], v[:, (i + 1) % 3] - v[:, i]
        t = np.clip(-(a * e).sum(1) / np.maximum((e * e).sum(1), 1e-300), 0.0, 1.0)
        q = a + t[:, None] * e
        d2 = np.minimum(d2, (q * q).sum(1))
    cross = [v[:, i, 0] * v[:, (i + 1) % 3, 1] - v[:, i, 1] * v[:, (i + 1) % 3, 0] for i in range(3)]
    inside = (np.min(cross, axis=0) >= 0) | (np.max(cross, axis=0) <= 0)  # s = 0 on the same side of every edge
    peak = np.where(inside, 1.0, np.exp(-d2))
    e1, e2 = p.tri_s[:, 1] - p.tri_s[:, 0], p.tri_s[:, 2] - p.tri_s[:, 0]
    area_s = 0.5 * np.abs(e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0])
    area_x = 0.5 * np.linalg.norm(np.cross(p.tri_x[:, 1] - p.tri_x[:, 0], p.tri_x[:, 2] - p.tri_x[:, 0]), axis=1)
    built = np.asarray(p.sample_power_w, float)
    ratio = np.where(built > 0, np.asarray(spot.power_w, float) / np.where(built > 0, built, 1.0), 0.0)[p.sample]
    # a diverging beam's map has d(area_x) / d(area_s) ~ 1 / g^3 (g the perspective weight,
    # affine in s): area_s / area_x is its mean, the largest is at most (g_max / g_min)^3 of that
    g = p.weights()
    stretch = (g.max(axis=1) / np.maximum(g.min(axis=1), 1e-300)) ** 3
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(area_x > 0, p.density_w * ratio * peak * stretch * area_s / np.where(area_x > 0, area_x, 1.0), np.inf)


def _largest_incident_w_m2(spot) -> float:
    """Largest irradiance [W/m^2] the beam lays on the spot's surface (a bound): the
    largest of :func:`_incident_w_m2`."""
    e = _incident_w_m2(spot)
    return float(e.max()) if len(e) else 0.0


def projected_brdf_max(model):
    """A proven largest ``f_r cos(theta_r)`` [1/sr] of ``model`` over every pair of
    directions and state, where its form gives one: a Lambertian's ``reflectance / pi``,
    a constant non-negative factor times its model's, a sum's parts' sum; None for any
    other model (the lobe's flat-spot bound then rests on the point form's sampled
    largest intensity, times ``FLAT_BOUND_MARGIN``)."""
    if isinstance(model, Lambertian):
        return model.reflectance / math.pi
    if isinstance(model, Scaled) and not isinstance(model.factor, StateTable):
        inner = projected_brdf_max(model.model)
        return None if inner is None else float(model.factor) * inner
    if isinstance(model, Sum):
        parts = [projected_brdf_max(m) for m in model.models]
        return None if any(p is None for p in parts) else float(sum(parts))
    return None


def _triangle_boxes(tri):
    """Each in-plane triangle (K, 3, 2) [m] in the rectangle along its longest edge:
    origins (K, 2), unit axes ``u`` along that edge and ``v`` across (K, 2) and the box's
    ranges ``l`` along ``u`` and ``t`` along ``v`` (K, 2) [m] (the triangle's own extents:
    its width across is its height over that edge)."""
    e = np.roll(tri, -1, axis=1) - tri
    k = np.argmax((e * e).sum(-1), axis=1)
    u = e[np.arange(len(tri)), k]
    u = u / np.maximum(np.linalg.norm(u, axis=1, keepdims=True), 1e-300)
    v = np.stack([-u[:, 1], u[:, 0]], axis=1)
    o = tri[:, 0]
    lu, tv = ((tri - o[:, None]) * u[:, None]).sum(-1), ((tri - o[:, None]) * v[:, None]).sum(-1)
    return o, u, v, np.stack([lu.min(1), lu.max(1)], 1), np.stack([tv.min(1), tv.max(1)], 1)


def _inverse_square_bound(foot, h2, boxes):
    """Upper bounds (M, K) of ``int_tri dA / R^2`` (dimensionless) from points at in-plane
    positions ``foot`` (M, 2) and squared heights ``h2`` (M,) above a plane holding the
    triangles of ``boxes`` (:func:`_triangle_boxes`). Over a box of ranges ``l`` and
    ``t`` about a foot at ``(l0, t0)``, ``R^2 >= h^2 + dt^2 + (l - l0)^2`` (``dt`` the
    foot's distance outside the ``t`` range), so the integral is at most ``(t_1 - t_0) /
    D [atan((l_1 - l0) / D) - atan((l_0 - l0) / D)]`` with ``D^2 = h^2 + dt^2``, and the
    same with ``l`` and ``t`` exchanged; the smaller is taken (exact for a thin strip
    seen from above its line; infinite only on the box itself)."""
    o, u, v, lr, tr = boxes
    q = foot[:, None, :] - o[None]
    l0, t0 = (q * u[None]).sum(-1), (q * v[None]).sum(-1)

    def one(a0, ar, b0, br):  # integrate along a, the other axis b bounded by its width
        db = np.maximum(np.maximum(br[None, :, 0] - b0, b0 - br[None, :, 1]), 0.0)
        d = np.sqrt(h2[:, None] + db * db)
        with np.errstate(divide="ignore", invalid="ignore"):
            ang = np.where(d > 0, np.arctan((ar[None, :, 1] - a0) / d) - np.arctan((ar[None, :, 0] - a0) / d), math.pi)
            return np.where(d > 0, (br[None, :, 1] - br[None, :, 0]) * ang / np.where(d > 0, d, 1.0), np.inf)

    dl = np.maximum(np.maximum(lr[None, :, 0] - l0, l0 - lr[None, :, 1]), 0.0)
    dt = np.maximum(np.maximum(tr[None, :, 0] - t0, t0 - tr[None, :, 1]), 0.0)
    near2 = h2[:, None] + dl * dl + dt * dt
    far2 = h2[:, None] + np.maximum(np.abs(lr[None, :, 0] - l0), np.abs(lr[None, :, 1] - l0)) ** 2 \
        + np.maximum(np.abs(tr[None, :, 0] - t0), np.abs(tr[None, :, 1] - t0)) ** 2
    with np.errstate(divide="ignore", invalid="ignore"):  # the annulus between the box's nearest and farthest points
        ring = np.where(near2 > 0, math.pi * np.log(far2 / np.where(near2 > 0, near2, 1.0)), np.inf)
    return np.minimum(np.minimum(one(l0, lr, t0, tr), one(t0, tr, l0, lr)), ring)


def _smallest_extent_m(spot, frame) -> float:
    """The spot's smallest extent [m] across its surface: twice the RMS width along the
    minor axis of its power-weighted in-plane covariance (samples and their spread)."""
    rel = (np.asarray(spot.points, float) - spot.centroid) @ frame[:2].T  # in-plane coordinates
    w = np.asarray(spot.power_w, float)
    w = w / w.sum() if w.sum() > 0 else np.full(len(w), 1.0 / len(w))
    cov = (rel * w[:, None]).T @ rel
    lam = float(np.linalg.eigvalsh(cov)[0])
    if spot.spread_m2 is not None:
        lam += 0.5 * float((np.asarray(spot.spread_m2, float) * w).sum())
    return 2.0 * math.sqrt(max(lam, 0.0))


class NearLobeFn:
    """``fn(wo (N, 3)) -> range [m]`` in the spot's mean frame: the point form ``base``,
    raised to the near-field integral's farthest root where the grid of module notes says
    so. ``info`` holds the grid's figures (directions integrated, scan step) and the BRDF
    work its build made (each ``f_r cos`` row counted where it is asked for, and times
    the states it is asked at): the integral's kernel (``kernel_evaluations``,
    ``kernel_state_evaluations``), the samples' bound ((point, sample) pairs:
    ``bound_evaluations``, ``bound_state_evaluations``) and the point form ``base``
    (directions of the grid, the peaks and the scan start's cone:
    ``point_form_evaluations``, ``point_form_state_evaluations``); the directions the
    lobe's users ask for afterwards are not in it (the keep-out lobe counts its own)."""

    def __init__(self, spot, base, mpe_w_m2, mu, gain, states):
        self.spot, self.base, self.mpe, self.mu, self.gain = spot, base, float(mpe_w_m2), float(mu), float(gain)
        self.states = None if states is None else np.asarray(states, float)
        self.samples = getattr(base, "samples", 1)
        self.frame = spot.mean_frame
        self.c = spot.centroid
        self.curved = frame_groups(spot) is not None  # light below its mean plane too: the grid's rows go on to 180 deg
        self.far_m = FAR_FIELD_SPOT_SIZES * max(spot.size_m, 1e-9)
        self._grid = None
        self.info = None
        self.floor = None  # through an aid (gain > 1): the naked eye's lobe, which it never falls below
        self.evaluations = self.bound_points = 0  # kernel evaluations of the integral; points the bound decided
        self.state_evaluations = 0  # those evaluations times the states each was evaluated at
        self.bound_evaluations = 0  # (point, sample) pairs of the samples' bound (_upper: f_r cos at every state of ``states``)
        self.point_form_evaluations = 0  # directions of the point form ``base`` evaluated by the build (grid, peaks, scan start's cone)

    # -- the integral ------------------------------------------------------------------------
    def _setup(self, reach_m, peaks):
        sp = self.spot
        self.smallest_m = max(_smallest_extent_m(sp, self.frame), 1e-9)
        loc = (sp.patches.tri_x.reshape(-1, 3) - self.c) @ self.frame.T
        self.box = (loc.min(0) - reach_m, loc.max(0) + reach_m)
        self.ext_m = float(sp.extent_m)
        rot = np.einsum("nij,kj->nik", np.asarray(sp.frames, float), self.frame)  # each sample's frame in the mean one
        self.tilt_rad = float(np.arccos(np.clip((np.trace(rot, axis1=1, axis2=2).min() - 1) / 2, -1.0, 1.0)))
        self.peaks, self.r_peaks = peaks, np.asarray(self._point_form(peaks), float)
        self.pts, self.p_w = np.asarray(sp.points, float), np.asarray(sp.power_w, float)
        self.a_m = np.asarray(sp.patches.radius_m, float)
        spread = np.zeros(len(self.pts)) if sp.spread_m2 is None else np.asarray(sp.spread_m2, float)
        self.var_m2 = np.minimum(spread, self.a_m ** 2)
        self.wi = to_local(sp.frames, -sp.incoming)
        k_max = reach_m ** 2 * math.exp(min(self.mu * reach_m, 700.0))  # the largest intensity / MPE [m^2]
        self.k_i = k_max * self.p_w / max(float(self.p_w.sum()), 1e-300)
        flat = self.tilt_rad == 0.0 and float(np.abs(loc[:, 2]).max()) <= 1e-9 * max(self.ext_m, 1e-300)
        f_max = projected_brdf_max(sp.material)  # proven, else the point form's sampled largest intensity x the margin
        self.flat_proven = f_max is not None
        per_w = self.gain * f_max / self.mpe if self.flat_proven else FLAT_BOUND_MARGIN * k_max / max(float(self.p_w.sum()), 1e-300)
        g = per_w * _incident_w_m2(sp)  # per triangle, times int dA / R^2: E / MPE (_flat_bound)
        keep = g > 0
        self.g_m2 = float(g.max()) if flat and len(g) and np.all(np.isfinite(g)) else math.inf
        self.g_tri, self.tri_boxes = g[keep], _triangle_boxes(loc.reshape(-1, 3, 3)[keep][..., :2])
        self.r_spot_m = float(np.sqrt((loc[:, :2] ** 2).sum(axis=1)).max())  # the spot's radius about c (the disk form)

    def _flat_bound(self, pts):
        """An upper bound of the integral / MPE at world points ``pts`` (M, 3) from a flat
        spot (infinite otherwise): ``E <= sum_tri E_inc,tri int_tri f_r cos / R^2 dA`` with
        ``E_inc,tri`` the beam's largest irradiance on the triangle
        (:func:`_incident_w_m2`), ``f_r cos`` at most the material's proven largest
        value (:func:`projected_brdf_max`: Lambertian, constant scales and sums of them)
        or else ``I_max / P`` (the point form's sampled largest intensity, which the
        bound then rests on at first order) times ``FLAT_BOUND_MARGIN``, and ``int_tri
        dA / R^2`` bounded per triangle (:func:`_inverse_square_bound`: finite down to
        the surface off the triangle's own area). Finite within a sample's radius, where the samples' bound
        is not: a spot much larger than its lobe, or a long grazing spot. The smaller of
        that sum and the whole spot's disk form (the largest ``E_inc`` over the disk of
        radius ``rho`` about the point's foot, ``int dA / R^2 <= pi ln(1 + rho^2 / h^2)``)."""
        if not math.isfinite(self.g_m2):
            return np.full(len(pts), np.inf)
        step = max(1, (_BOUND_BLOCK // 4) // max(len(self.g_tri), 1))
        if len(pts) > step:
            return np.concatenate([self._flat_bound(pts[a:a + step]) for a in range(0, len(pts), step)])
        loc = (pts - self.c) @ self.frame.T
        h2 = loc[:, 2] ** 2
        with np.errstate(invalid="ignore"):
            b = self.g_tri[None] * _inverse_square_bound(loc[:, :2], h2, self.tri_boxes)
        rho = np.sqrt(loc[:, 0] ** 2 + loc[:, 1] ** 2) + self.r_spot_m  # the whole spot in one disk, at its largest E_inc
        with np.errstate(divide="ignore"):
            disk = np.where(h2 > 0, self.g_m2 * math.pi * np.log1p(rho * rho / np.where(h2 > 0, h2, 1.0)), np.inf)
        return np.minimum(np.where(np.isnan(b), np.inf, b).sum(axis=1), disk)

    def prepare(self, dirs, r0):
        """Set up the bounds from the point form's ranges ``r0`` on directions ``dirs``
        (mean frame): its largest range and peaks (with the mirror and retro directions)."""
        wi = spot_directions(self.spot)
        peaks = np.concatenate([dirs[np.argmax(r0)][None], wi[None] * np.array([[-1.0, -1, 1]]), wi[None]])
        self._setup(float(r0.max()), peaks)

    def _n_states(self) -> int:
        """The states each BRDF evaluation of the build is made at (1 without a history)."""
        return 1 if self.states is None else len(self.states)

    def _point_form(self, w_loc):
        """``base`` at mean-frame directions (N, 3), counted (``point_form_evaluations``)."""
        self.point_form_evaluations += len(w_loc)
        return self.base(w_loc)

    def _upper(self, pts):
        """Upper bounds of the integral / MPE at world points ``pts`` (M, 3): the samples'
        point forms plus their Taylor remainders ``k_i 12 sigma_i^2 / (d_i - a_i)^4``
        (the Lambertian kernel's, as :func:`hazard.physics.near_field.point_form_ok`; ``k_i`` the
        sample's share of the point form's largest intensity over the MPE), infinite
        within a sample's radius. Returns the point forms' sums (M,) without a history,
        else (M, T) (one per state of ``states``, the states the integral is evaluated
        at), and the remainders' sums (M,): the bound is their sum. Points go in blocks of
        at most ``_BOUND_BLOCK`` (point, sample, state) triples."""
        per = len(self.pts) * (1 if self.states is None else len(self.states))
        step = max(1, _BOUND_BLOCK // max(per, 1))
        if len(pts) > step:
            parts = [self._upper(pts[a:a + step]) for a in range(0, len(pts), step)]
            return np.concatenate([p[0] for p in parts]), np.concatenate([p[1] for p in parts])
        sp = self.spot
        self.bound_evaluations += len(pts) * len(self.pts)
        v = pts[:, None, :] - self.pts[None]
        d = np.maximum(np.sqrt((v * v).sum(-1)), 1e-300)  # (M, n)
        wo = np.einsum("nij,mnj->mni", sp.frames, v / d[..., None]).reshape(-1, 3)
        wi = np.broadcast_to(self.wi[None], (len(pts),) + self.wi.shape).reshape(-1, 3)
        scale = (self.p_w[None] * self.gain * np.exp(-self.mu * d) / (d * d) / self.mpe).ravel()
        f = projected_brdf(sp.material, wi, wo, self.states, scale)  # (M n,) or (M n, T)
        gap = d - self.a_m[None]
        with np.errstate(divide="ignore"):
            err = np.where(gap > 0, 12.0 * self.k_i * self.var_m2 / np.where(gap > 0, gap, 1.0) ** 4, np.inf).sum(axis=1)
        return f.reshape(d.shape + (() if self.states is None else (-1,))).sum(axis=1), err

    def _integral_hot(self, pts, states):
        """The integral at world points ``pts`` reaches the MPE at some state of ``states``
        (None: no history); counts its kernel evaluations. The call stops at the
        ceiling, ``CEILING_FACTOR x MAX_EVALUATIONS`` evaluations in all (one call started
        below the budget can cost a thousand times it: a spot's leaves on a facet edge-on
        to the beam make triangles kilometres long, bisected down to each observer's
        distance); the points it leaves are hazardous by the bound (they are candidates:
        the bound reaches the MPE there), counted in ``bound_points``."""
        before = near_field.STATS.snapshot()
        e = near_field_w_m2(self.spot, pts, np.full(len(pts), self.gain), self.mu, states,
                            max_evaluations=CEILING_FACTOR * MAX_EVALUATIONS - self.evaluations)
        n = near_field.stats_since(before)["evaluations"]
        self.evaluations += n
        self.state_evaluations += n * (1 if states is None else len(states))
        top = e if e.ndim == 1 else e.max(axis=1)
        cut = np.isnan(top)  # not integrated: past the ceiling
        self.bound_points += int(cut.sum())
        STATS.points += len(pts) - int(cut.sum())
        return cut | (top >= self.mpe)

    def hazardous(self, pts):
        """True where the spot's near-field integral (:func:`hazard.physics.engine.near_field_w_m2`,
        the observers' own) at world points ``pts`` (M, 3) reaches the MPE (with a
        history: at some state of ``states``); integrated only where the samples' bound
        (:meth:`_upper`) reaches it. With a history, per point first at its state of the
        largest point-form sum alone (reaching the MPE there decides), then only at the states whose
        own bound reaches the MPE (below it at the others: the same decision as every state)."""
        point, err = self._upper(pts)
        up = point + (err if point.ndim == 1 else err[:, None])
        open_ = np.flatnonzero((up if up.ndim == 1 else up.max(axis=1)) >= 1.0)  # the flat bound only where the samples' does not decide
        if len(open_):  # the smaller of two bounds (the flat one covers the point forms too)
            err[open_] = np.minimum(err[open_], self._flat_bound(pts[open_]))
            up = point + (err if point.ndim == 1 else err[:, None])
        top = up if up.ndim == 1 else up.max(axis=1)
        out = top >= 1.0
        cand = np.flatnonzero(out)
        if not len(cand):
            return out
        if self.evaluations >= MAX_EVALUATIONS:  # the budget is spent: the bound decides (never short, looser)
            self.bound_points += len(cand)
            return out
        if self.states is None:
            out[cand] = self._integral_hot(pts[cand], None)
            return out
        up = up[cand]
        best = point[cand].argmax(axis=1)  # the states' remainders are the same (infinite near the spot)
        hot = np.zeros(len(cand), bool)
        for t in np.unique(best):  # the likeliest state first: one state's hazard decides
            k = np.flatnonzero(best == t)
            hot[k] = self._integral_hot(pts[cand[k]], self.states[t:t + 1])
        rest = np.flatnonzero(~hot)
        need = up[rest] >= 1.0
        need[np.arange(len(rest)), best[rest]] = False  # done above
        cols = np.flatnonzero(need.any(axis=0))
        if len(rest) and len(cols):
            rows = rest[need[:, cols].any(axis=1)]
            hot[rows] = self._integral_hot(pts[cand[rows]], self.states[cols])
        out[cand] = hot
        return out

    # -- roots along rays ----------------------------------------------------------------------
    def _r_hi(self, w_loc):
        """Where each ray (mean-frame unit vectors (N, 3)) leaves the widened box, capped at
        the engine's near/far switch."""
        lo, hi = self.box
        with np.errstate(divide="ignore", invalid="ignore"):
            t = np.where(w_loc > 0, hi / w_loc, np.where(w_loc < 0, lo / w_loc, np.inf))
        return np.minimum(t.min(axis=1), self.far_m)

    def _cone_reach(self, w_loc, r):
        """Largest point-form range [m] over the cone of directions from which the spot's
        parts are seen at ``c + r w`` (half-angle ``asin(extent / r)`` plus the samples'
        frame tilt): ``CONE_RINGS`` x ``CONE_AZIMUTHS`` samples, the axis, and the point
        form's peaks (grid maximum, mirror and retro directions) inside the cone."""
        alpha = np.where(r > self.ext_m, np.arcsin(np.clip(self.ext_m / np.maximum(r, 1e-300), 0.0, 1.0)), math.pi)
        alpha = np.minimum(alpha + self.tilt_rad, math.pi)
        ref = np.where(np.abs(w_loc[:, 2:3]) < 0.9, [[0.0, 0.0, 1.0]], [[1.0, 0.0, 0.0]])
        e1 = np.cross(w_loc, ref)
        e1 /= np.linalg.norm(e1, axis=1, keepdims=True)
        e2 = np.cross(w_loc, e1)
        ring = np.asarray(CONE_RINGS)[None, :, None] * alpha[:, None, None]  # (N, R, 1)
        az = np.linspace(0, 2 * math.pi, CONE_AZIMUTHS, endpoint=False)[None, None, :]
        d = (np.cos(ring)[..., None] * w_loc[:, None, None, :]
             + np.sin(ring)[..., None] * (np.cos(az)[..., None] * e1[:, None, None, :] + np.sin(az)[..., None] * e2[:, None, None, :]))
        d = d.reshape(len(w_loc), -1, 3)
        if not self.curved:  # a flat spot sends nothing below its plane
            d[..., 2] = np.maximum(d[..., 2], 0.0)
        d /= np.maximum(np.linalg.norm(d, axis=2, keepdims=True), 1e-300)
        best = np.asarray(self._point_form(d.reshape(-1, 3)), float).reshape(len(w_loc), -1).max(axis=1)
        best = np.maximum(best, np.asarray(self._point_form(w_loc), float))
        inside = np.arccos(np.clip(w_loc @ self.peaks.T, -1.0, 1.0)) <= alpha[:, None]
        return np.maximum(best, np.where(inside, self.r_peaks[None, :], 0.0).max(axis=1))

    def _scan_start(self, w_loc):
        """Farthest radius [m] along each direction where the integral can reach the MPE:
        ``E <= I_cone exp(-mu (r - extent)) / (r - extent)^2`` (every part of the spot is
        at least ``r - extent`` away and seen within the cone), so hazard needs ``r <=
        extent + cone reach``; bisected (``CONE_BISECTIONS``) within the box's exit."""
        hi = self._r_hi(w_loc)
        ok = self.ext_m + self._cone_reach(w_loc, hi) >= hi  # hazard possible out to the box's exit: start there
        out = hi.copy()
        k = np.flatnonzero(~ok)  # the others: bisected (only they are)
        if len(k):
            w, hi = w_loc[k], hi[k]
            lo = np.minimum(np.full(len(k), self.ext_m), hi)
            for _ in range(CONE_BISECTIONS):
                mid = 0.5 * (lo + hi)
                reach = self.ext_m + self._cone_reach(w, mid) >= mid
                lo, hi = np.where(reach, mid, lo), np.where(reach, hi, mid)
            out[k] = hi
        return out

    def roots(self, w_loc, r_floor):
        """Farthest roots [m] beyond ``r_floor`` (N,) along mean-frame directions (N, 3),
        each with the scan's resolution added (0 where no scan sample beyond ``r_floor``
        is hazardous), and the steps [m] (module notes)."""
        w_loc = np.asarray(w_loc, float).reshape(-1, 3)
        if not len(w_loc):
            return np.zeros(0), np.zeros(0)
        r_hi = self._scan_start(w_loc)
        h = np.minimum(self.smallest_m, r_hi / SCAN_MIN_STEPS)
        w = w_loc @ self.frame
        found, prev = np.full(len(w), -1.0), r_hi.copy()  # the first hazardous sample and the cold one before it
        floor = r_floor * (1 + FLOOR_RTOL)
        r = r_hi.copy()
        live = np.flatnonzero(r_hi > floor)
        while len(live):
            hot = self.hazardous(self.c + r[live, None] * w[live])
            found[live[hot]] = r[live[hot]]
            live = live[~hot & (r[live] > floor[live])]
            prev[live] = r[live]
            r[live] = np.maximum(r[live] - h[live], floor[live])  # the last sample: just beyond the point form
        step = np.where((found >= 0) & (prev > found), prev - found, h)  # the scan's resolution at the root (h, or less at the last)
        lo = np.maximum(found, 0.0)
        hi = np.minimum(lo + step, r_hi)
        tol = np.maximum(ROOT_RTOL * r_hi, step / 8)
        live = np.flatnonzero((found >= 0) & (hi - lo > tol))
        while len(live):
            mid = 0.5 * (lo[live] + hi[live])
            hot = self.hazardous(self.c + mid[:, None] * w[live])
            lo[live[hot]], hi[live[~hot]] = mid[hot], mid[~hot]
            live = live[hi[live] - lo[live] > tol[live]]
        return np.where(found >= 0, hi + step, 0.0), step

    # -- the grid and the envelope ---------------------------------------------------------------
    def _build(self):
        t0 = time.perf_counter()
        rows_deg = THETA_ROWS_DEG + (BELOW_ROWS_DEG if self.curved else ())
        th = np.radians(np.asarray(rows_deg))
        ph = np.radians(np.arange(-180.0, 180.0 + 1e-9, GRID_PHI_DEG))
        tt, pp = np.meshgrid(th, ph, indexing="ij")
        dirs = np.stack([np.sin(tt) * np.cos(pp), np.sin(tt) * np.sin(pp), np.cos(tt)], -1).reshape(-1, 3)
        r0 = np.asarray(self._point_form(dirs), float)
        # a lobe that is 0 in every direction (f_r cos P = 0: a pure mirror's, whose beam the mirror
        # stage handles) has no near field either; the scan would end on the spot itself, where the
        # bound's remainders give a 1e-12 m "lobe" and a hazard zone that is not one
        need = (r0 < self.far_m) & bool(np.any(r0 > 0))
        val = np.zeros(len(dirs))
        steps = np.zeros(0)
        if need.any():
            self.prepare(dirs, r0)
            with near_field.shared_subdivisions():  # the scan's points share the spot's bisections (the same sums)
                val[need], steps = self.roots(dirs[need], r0[need])
        self.cap_m = self.far_m + getattr(self, "smallest_m", 0.0)  # no near-field root lies beyond (scan start + step)
        # the lobe at the nodes, never below the point form (capped where the point form is far: the envelope covers the near field)
        v = np.where(need, np.maximum(val, r0), np.minimum(r0, self.cap_m)).reshape(tt.shape)
        raised = (need & (val > r0)).reshape(tt.shape)  # nodes where the integral reaches past the point form
        d2 = np.zeros_like(v)
        d2[1:-1] += np.maximum(-(v[:-2] + v[2:] - 2 * v[1:-1]), 0.0)  # along theta
        vp = np.concatenate([v[:, -2:-1], v, v[:, 1:2]], axis=1)  # phi wraps (first and last columns coincide)
        d2 += np.maximum(-(vp[:, :-2] + vp[:, 2:] - 2 * v), 0.0)
        marg = d2 / 8.0
        cells = [(slice(a, a + v.shape[0] - 1), slice(b, b + v.shape[1] - 1)) for a in (0, 1) for b in (0, 1)]
        top = np.max([v[c] for c in cells], axis=0) + np.max([marg[c] for c in cells], axis=0)
        any_raised = np.any([raised[c] for c in cells], axis=0) & (np.max([v[c] for c in cells], axis=0) > 0)
        # per cell: its four nodes' largest value plus their largest margin, capped; 0 where no node was raised
        self._grid = (th, ph, np.where(any_raised, np.minimum(top, self.cap_m), 0.0))
        dt = time.perf_counter() - t0
        STATS.directions += int(need.sum())
        STATS.seconds += dt
        self.info = {"directions_integrated": int(need.sum()), "directions_raised": int(raised.sum()), "grid_theta_deg": list(rows_deg), "grid_phi_deg": GRID_PHI_DEG,
                     "scan_step_max_m": float(steps.max()) if len(steps) else 0.0, "root_rtol": ROOT_RTOL,
                     "kernel_evaluations": int(self.evaluations),
                     "kernel_state_evaluations": int(self.state_evaluations), "points_by_bound": int(self.bound_points),
                     "bound_evaluations": int(self.bound_evaluations),
                     "bound_state_evaluations": int(self.bound_evaluations * self._n_states()),
                     "point_form_evaluations": int(self.point_form_evaluations),
                     "point_form_state_evaluations": int(self.point_form_evaluations * self._n_states())}

    def envelope(self, wo):
        """The near-field range [m] at mean-frame directions (N, 3) from the grid (0 in
        cells none of whose nodes the integral raised past the point form)."""
        if self._grid is None:
            self._build()
        th, ph, cell = self._grid
        if not cell.any():
            return np.zeros(len(wo))
        t = np.arccos(np.clip(wo[:, 2] / np.linalg.norm(wo, axis=1), -1.0, 1.0))
        p = np.arctan2(wo[:, 1], wo[:, 0])
        i = np.clip(np.searchsorted(th, t, side="right") - 1, 0, len(th) - 2)
        j = np.clip(np.searchsorted(ph, p, side="right") - 1, 0, len(ph) - 2)
        return cell[i, j]

    def __call__(self, wo):
        wo = np.asarray(wo, float)
        r0 = np.asarray(self.base(wo), float)
        out = np.maximum(r0, self.envelope(wo))
        return out if self.floor is None else np.maximum(out, self.floor(wo))

    def max_range(self, wo) -> float:
        """The largest range [m] over directions ``wo`` (N, 3), without integrating where
        the point form's largest range already reaches past every near-field value (the
        near/far switch plus the spot's smallest extent, the largest scan step)."""
        r0 = np.asarray(self.base(np.asarray(wo, float)), float)
        if self._grid is None and r0.max() >= near_field_reach_m(self.spot):
            return float(r0.max())
        return float(self(wo).max())


def near_field_reach_m(spot) -> float:
    """Farthest range [m] the near-field lobe can reach (its envelope's cap: the engine's
    near/far switch plus the spot's smallest extent, the largest scan step): a point-form
    lobe whose largest range reaches it has the near-field lobe's largest range."""
    return FAR_FIELD_SPOT_SIZES * max(spot.size_m, 1e-9) + _smallest_extent_m(spot, spot.mean_frame)


def near_lobe_fn(spot, base, mpe_w_m2, mu, gain, states):
    """The lobe function of ``spot`` with the near field integrated (module notes), or
    ``base`` for a spot built without its triangles. Cached on the spot per (MPE,
    attenuation, gain, states): the static and dynamic lobes, the outlines and the
    renders share one grid."""
    if not ENABLED or spot.patches is None or not len(spot.points) or not spot.total_power_w > 0:
        return base
    key = (float(mpe_w_m2), float(mu), float(gain), None if states is None else np.asarray(states, float).tobytes())
    with _CACHE_LOCK:
        ref, cache = _CACHE.get(id(spot), (None, None))
        if ref is None or ref() is not spot:  # not on the spot itself: a Spot stays picklable
            cache = {}
            _CACHE[id(spot)] = (weakref.ref(spot, _forget(id(spot))), cache)
        if key not in cache:
            cache[key] = NearLobeFn(spot, base, mpe_w_m2, mu, gain, states)
        return cache[key]


_CACHE: dict = {}  # id(spot) -> (weak reference to it, {key: NearLobeFn})
_CACHE_LOCK = threading.Lock()


def _forget(key):
    """Callback of a spot's weak reference: drop its entry (only its own: an id is reused)."""
    def drop(ref):
        cache = _CACHE
        if cache is not None and cache.get(key, (None,))[0] is ref:
            cache.pop(key, None)
    return drop
