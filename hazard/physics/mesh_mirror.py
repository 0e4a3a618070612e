"""Mirror reflection from curved meshes: a smooth surface, averaged over the eye's aperture.

Sources: spec `range-safety.md` section 4 ("Concave mirror": a focus where the irradiance
can exceed the incident one by orders of magnitude; "Pitfall": a flat-facet formula
understates a concave focus) and section 10 ("Focusing mirrors": the compared quantity is
the power through the limiting aperture; a faceted mesh is a smooth surface with
interpolated vertex normals). Ray differentials: Igehy, *Tracing ray differentials*,
SIGGRAPH 1999 (a ray tube's cross-section from neighbouring rays).

* **The surface.** A mesh file's triangles stand for a smooth surface: at a hit the normal
  is the barycentric interpolation of the corner normals
  (:meth:`scenes.geometry.Mesh.corner_normals`: Max's weights over the triangles at the
  vertex, exact for vertices on a sphere; edges sharper than ``CREASE_ANGLE_DEG`` kept). Facets whose corner normals equal
  their own normal are flat and keep the exact unfolded beam (:mod:`hazard.physics.specular`);
  the others ("curved facets") are traced here.
* **The rays.** A regular grid in the beam's transverse coordinates ``s`` over the part of
  the beam that lands on the target (``MESH_MIRROR_RAYS`` rays on the lit part), each ray
  carrying the exact Gaussian power of its grid cell after the laser -> mirror
  attenuation, traced to the curved facets and reflected on the interpolated normal.
* **Aperture average.** The MPE is compared with the power through the limiting aperture
  (radius ``a``) over its area. Here the aperture is a ball of radius ``a`` about the eye
  (every ray passing within ``a`` of it counts): that holds at least the power through a
  disk of radius ``a`` facing any way, so it is the worst orientation or above (by at most
  ``1 / cos`` of the half-angle of the converging cone). Where at least
  ``MIN_RAYS_IN_APERTURE`` rays cross the ball the binned sum is used, with its sampling
  (Poisson) error ``sqrt(sum q^2) / sum q`` over the rays' weights ``q``; the value returned
  adds two of those (the upper end).
* **Ray tubes.** Where fewer rays cross it (the reflected beam spread wider than the ray
  spacing: far from any focus), the irradiance is the ray tube's: power of a grid cell over
  the tube's cross-section at the eye, from the ray's two grid neighbours (a ray
  differential; exact for a smooth wavefront as the grid refines). The eye takes the
  largest tube among the rays whose tube (one grid step either way) holds it, capped by
  all the reflected power through the aperture and by the rays that do cross it with a
  Poisson allowance, ``(n + 3 sqrt(n) + 3)`` rays of the heaviest weight near the eye (a
  thin zone's own caustic, like a mesh rim's, cannot put more in it). Where the reflected wavefront folds on itself (beyond a caustic) the
  sheets' tubes are not summed, the largest is taken: only met by mirrors with several
  foci, far from them.
* Not modelled: a second bounce on the same mesh (the reflected rays are not traced
  again), diffraction (the focal spot is geometric: at least the spot the beam's
  divergence and the mirror's aberrations give, never the smaller diffraction limit that
  would raise the focus; spec section 4 asks for the divergence/aberration spot).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

__all__ = ["MESH_MIRROR_RAYS", "MIN_RAYS_IN_APERTURE", "MirrorRays", "ApertureIrradiance",
           "is_curved_mesh", "curved_face_mask", "mirror_rays", "aperture_irradiance", "smooth_normals_at"]

MESH_MIRROR_RAYS = 1 << 18  # rays on the lit curved facets of one target
MIN_RAYS_IN_APERTURE = 100  # below this the ray tubes give the irradiance (sampling error 1/sqrt(100) = 10 %)
_PAIRS_PER_CHUNK = 4_000_000  # (observer, ray) pairs handled at once


def is_curved_mesh(target) -> bool:
    """True for a mesh-file target with at least one curved facet."""
    spec = getattr(target, "spec", None)
    return getattr(spec, "shape", None) == "mesh" and bool(np.any(target.mesh.curved_faces()))


def curved_face_mask(target) -> np.ndarray:
    """Per target triangle: curved (traced here) or flat (unfolded by :mod:`hazard.physics.specular`)."""
    if getattr(getattr(target, "spec", None), "shape", None) != "mesh":
        return np.zeros(len(target.mesh.faces), bool)
    return target.mesh.curved_faces()


def smooth_normals_at(mesh, faces, points) -> np.ndarray:
    """Unit normals (N, 3) at ``points`` (N, 3) on the mesh's triangles ``faces`` (N,):
    barycentric interpolation of the corner normals (:meth:`scenes.geometry.Mesh.corner_normals`)."""
    tri = mesh.vertices[mesh.faces[faces]]
    e1, e2 = tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]
    q = points - tri[:, 0]
    d11, d12, d22 = (e1 * e1).sum(1), (e1 * e2).sum(1), (e2 * e2).sum(1)
    q1, q2 = (q * e1).sum(1), (q * e2).sum(1)
    det = np.maximum(d11 * d22 - d12 * d12, 1e-300)
    b1 = np.clip((d22 * q1 - d12 * q2) / det, 0.0, 1.0)
    b2 = np.clip((d11 * q2 - d12 * q1) / det, 0.0, 1.0)
    b0 = np.clip(1.0 - b1 - b2, 0.0, 1.0)
    cn = mesh.corner_normals()[faces]
    n = b0[:, None] * cn[:, 0] + b1[:, None] * cn[:, 1] + b2[:, None] * cn[:, 2]
    return n / np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-300)


@dataclass
class MirrorRays:
    """The reflected rays of a spot's curved facets.

    ``points`` (N, 3) hit points [m], ``directions`` (N, 3) reflected unit directions,
    ``incoming`` (N, 3) incident unit directions, ``normals`` (N, 3) the interpolated
    normals of the lit side, ``power_w`` (N,) the grid cell's power after the laser ->
    mirror attenuation [W], ``neighbours`` (N, 2) the next ray along each grid axis (-1:
    none on the curved facets), ``centre_m`` and ``radius_m`` a ball holding the points,
    ``spread_rad`` the largest angle between a ray and a neighbour, ``step_m`` the largest
    distance between a ray's hit point and a neighbour's, ``grid_step_s`` the grid spacing
    in units of the beam's 1/e radius.
    """

    points: np.ndarray
    directions: np.ndarray
    incoming: np.ndarray
    normals: np.ndarray
    power_w: np.ndarray
    neighbours: np.ndarray
    centre_m: np.ndarray
    radius_m: float
    spread_rad: float
    step_m: float
    grid_step_s: float

    @property
    def count(self) -> int:
        return int(len(self.power_w))


def _target_scene(target):
    """A ray scene of the target's own triangles (Embree if installed, else numpy)."""
    from hazard.physics.rays import RayScene

    meshes = [(target.mesh.vertices, target.mesh.faces, target.index)]
    try:
        return RayScene(meshes, backend="embree")
    except ImportError:
        return RayScene(meshes, backend="numpy")


def _grid(spot, n_rays):
    """Grid centres (n_i, n_j, 2) over the beam cells that touch the target, and the step."""
    cells, k = spot.cells, spot.target.index
    rows = np.flatnonzero(np.any(cells.labels == k, axis=1))
    s0, s1, t0, t1 = cells.bounds(rows)
    area = float(np.sum((s1 - s0) * (t1 - t0)))
    lo, hi = np.array([s0.min(), t0.min()]), np.array([s1.max(), t1.max()])
    h = math.sqrt(area / n_rays)
    h = max(h, math.sqrt(float(np.prod(hi - lo)) / (8 * n_rays)))  # a sparse lit region: at most 8 n grid points
    ni, nj = (np.ceil((hi - lo) / h).astype(int) + 1).tolist()
    gi, gj = np.meshgrid(lo[0] + h * np.arange(ni), lo[1] + h * np.arange(nj), indexing="ij")
    return np.stack([gi, gj], axis=-1), h


def mirror_rays(spot, attenuation_per_m, lit, n_rays=None) -> MirrorRays | None:
    """The reflected rays of a spot's curved facets (:class:`MirrorRays`), None if the
    beam lands on none; about ``n_rays`` (default ``MESH_MIRROR_RAYS``) on the lit part.
    ``lit(s)``: whether the beam cells at transverse coordinates s (N, 2) reach the
    target (:func:`hazard.physics.specular._lit`): rays in cells that do not (an occluder or
    another target in front) are left out; the cells the target shares with them are
    kept whole (conservative)."""
    from hazard.physics.beam import rectangle_fraction

    target, beam = spot.target, spot.beam
    curved = curved_face_mask(target)
    grid, h = _grid(spot, MESH_MIRROR_RAYS if n_rays is None else int(n_rays))
    shape = grid.shape[:2]
    s = grid.reshape(-1, 2)
    keep = np.flatnonzero(lit(s))
    o, d = beam.rays(s[keep])
    hits = _target_scene(target).first_hit(o, d)
    ok = hits.hit & curved[np.maximum(hits.face, 0)]
    if spot.side == "back":
        ok &= np.einsum("ij,ij->i", d, target.mesh.face_normals[np.maximum(hits.face, 0)]) > 0
    else:
        ok &= np.einsum("ij,ij->i", d, target.mesh.face_normals[np.maximum(hits.face, 0)]) < 0
    idx = keep[ok]
    if not len(idx):
        return None
    unit_d = d[ok] / np.linalg.norm(d[ok], axis=1, keepdims=True)
    pts = hits.point[ok]
    n = smooth_normals_at(target.mesh, hits.face[ok], pts)
    n = np.where(((n * unit_d).sum(1) > 0)[:, None], -n, n)  # the lit side
    refl = unit_d - 2 * (unit_d * n).sum(1)[:, None] * n
    sc = s[idx]
    power = beam.power_w * rectangle_fraction(sc[:, 0] - h / 2, sc[:, 0] + h / 2, sc[:, 1] - h / 2, sc[:, 1] + h / 2)
    power = power * np.exp(-attenuation_per_m * hits.t[ok])
    return _assemble(pts, refl, unit_d, n, power, idx, shape, h)


def _assemble(pts, refl, inc, nrm, power, idx, shape, h) -> MirrorRays:
    """:class:`MirrorRays` with the grid neighbours, bounding ball and ray spreads."""
    where = np.full(shape[0] * shape[1], -1, np.int64)
    where[idx] = np.arange(len(idx))
    gi, gj = np.unravel_index(idx, shape)
    nb = np.full((len(idx), 2), -1, np.int64)
    nb[:, 0] = np.where(gi + 1 < shape[0], where[np.ravel_multi_index((np.minimum(gi + 1, shape[0] - 1), gj), shape)], -1)
    nb[:, 1] = np.where(gj + 1 < shape[1], where[np.ravel_multi_index((gi, np.minimum(gj + 1, shape[1] - 1)), shape)], -1)
    centre = pts.mean(0)
    radius = float(np.linalg.norm(pts - centre, axis=1).max())
    spread, step = 0.0, 0.0
    for k in range(2):
        has = nb[:, k] >= 0
        if np.any(has):
            cosang = np.clip((refl[has] * refl[nb[has, k]]).sum(1), -1.0, 1.0)
            spread = max(spread, float(np.arccos(cosang).max()))
            step = max(step, float(np.linalg.norm(pts[has] - pts[nb[has, k]], axis=1).max()))
    return MirrorRays(pts, refl, inc, nrm, power, nb, centre, radius, spread, step, h)


@dataclass
class ApertureIrradiance:
    """Aperture-averaged irradiance at observers from one spot's curved facets.

    ``irradiance_w_m2`` (M,) or (M, T): the upper value used for the hazard (estimate plus
    its error); ``estimate_w_m2`` the estimate; ``error_w_m2`` the stated error (two
    sampling standard deviations where binned, the spread of the tubes that hold the
    observer where the ray tubes are used); ``rays_in_aperture`` (M,) the rays that cross
    the aperture; ``binned`` (M,) which observers were binned (else ray tubes).
    """

    irradiance_w_m2: np.ndarray
    estimate_w_m2: np.ndarray
    error_w_m2: np.ndarray
    rays_in_aperture: np.ndarray
    binned: np.ndarray


_FEW_OBSERVERS = 64  # a shell with at most this many observers is searched without a KD-tree
_SHELL = 0.03  # observers are grouped in shells of this width in log distance from the rays' centre


def _pairs(rays: MirrorRays, obs, aperture_r):
    """(observer, ray) pairs that can matter: every ray that passes within reach of the
    observer's aperture or of a tube holding it (a superset).

    Observers within three mirror radii get every ray. The others are grouped in thin
    shells of distance L from the rays' centre C; in each, every ray's crossing of the
    sphere of radius L_mid about C is a unit vector f_i, and a ray passing within
    ``reach`` of an observer at O = C + L u crosses the sphere |X - C| = L within
    ``2 reach / cos(gamma)`` of O (gamma: the ray's angle to the radial direction, largest
    at the shell's inner radius), then drifts by at most ``sin(gamma) ln(L_hi / L_lo)`` in
    angle across the shell: the rays with f_i within that angle of u (KD-tree) are kept.
    """
    from scipy.spatial import cKDTree

    rel = obs - rays.centre_m
    dist = np.linalg.norm(rel, axis=1)
    u = rel / np.maximum(dist, 1e-300)[:, None]
    big_r = rays.radius_m + 2 * aperture_r + 2 * rays.step_m
    near = dist <= 3 * big_r
    rows = [np.repeat(np.flatnonzero(near), rays.count)]
    idx = [np.tile(np.arange(rays.count), int(near.sum()))]
    far = np.flatnonzero(~near)
    if len(far):
        shell = np.floor(np.log(dist[far]) / _SHELL).astype(np.int64)
        p = rays.points - rays.centre_m
        pr, pp = (p * rays.directions).sum(1), (p * p).sum(1)
        for sh in np.unique(shell):
            members = far[shell == sh]
            lo, hi = math.exp(sh * _SHELL), math.exp((sh + 1) * _SHELL)
            f_lo = _crossing(p, pr, pp, rays.directions, lo)
            cos_g = (rays.directions * f_lo).sum(1)
            cg = max(float(cos_g.min()), 1e-6)
            sg = math.sqrt(max(0.0, 1 - cg * cg))
            reach = aperture_r + 2 * (rays.step_m + hi * rays.spread_rad)
            chord = 2 * reach / (cg * lo)  # |X - O| / L on the sphere: the angle is 2 asin(chord / 2) <= 1.05 chord below 1
            theta = (1.05 * chord if chord < 1 else math.pi) + sg * _SHELL * 1.001 + 1e-12
            f_mid = _crossing(p, pr, pp, rays.directions, math.sqrt(lo * hi))
            theta = min(theta, 2.0)
            # first the rays within theta of the cap holding the shell's observers
            u0 = u[members].sum(0)
            u0 = u0 / max(float(np.linalg.norm(u0)), 1e-300)
            cap = float(np.arccos(np.clip((u[members] @ u0).min(), -1.0, 1.0))) + 2 * math.asin(theta / 2)
            sub = np.flatnonzero(f_mid @ u0 >= math.cos(min(cap, math.pi)))
            if not len(sub):
                continue
            if len(members) <= _FEW_OBSERVERS:  # a few observers: one dot product per ray and observer
                ray_i, obs_i = np.nonzero(f_mid[sub] @ u[members].T >= 1 - theta * theta / 2)
                rows.append(members[obs_i])
                idx.append(sub[ray_i])
                continue
            found = cKDTree(f_mid[sub]).query_ball_point(u[members], theta)
            counts = np.fromiter((len(x) for x in found), np.int64, len(found))
            if counts.sum():
                rows.append(np.repeat(members, counts))
                idx.append(sub[np.concatenate([np.asarray(x, np.int64) for x in found])])
    return np.concatenate(rows), np.concatenate(idx)


def _crossing(p, pr, pp, dirs, radius):
    """Unit vectors (N, 3) to where rays from p (relative to the centre, |p| < radius)
    along dirs cross the sphere of ``radius`` about the centre."""
    t = -pr + np.sqrt(np.maximum(pr * pr - pp + radius * radius, 0.0))
    x = p + t[:, None] * dirs
    return x / np.maximum(np.linalg.norm(x, axis=1, keepdims=True), 1e-300)


def _tube_irradiance(rays, o, ray, v, t):
    """Per pair: the tube's irradiance factor [1/m^2] (cell power over the tube's
    cross-section at the observer, before reflectance and attenuation) and whether the
    observer lies within one grid step of the ray in the tube's coordinates."""
    nb = rays.neighbours[ray]
    has = np.all(nb >= 0, axis=1)
    r_i = rays.directions[ray]
    y_i = rays.points[ray] + t[:, None] * r_i
    edges = []
    for k in range(2):
        j = np.maximum(nb[:, k], 0)
        r_j = rays.directions[j]
        t_j = ((o - rays.points[j]) * r_i).sum(1) / np.maximum((r_j * r_i).sum(1), 1e-12)
        edges.append(rays.points[j] + t_j[:, None] * r_j - y_i)
    e1, e2 = edges
    g11, g12, g22 = (e1 * e1).sum(1), (e1 * e2).sum(1), (e2 * e2).sum(1)
    det = g11 * g22 - g12 * g12
    delta = o - y_i
    b1, b2 = (delta * e1).sum(1), (delta * e2).sum(1)
    safe = np.maximum(det, 1e-300)
    alpha = (g22 * b1 - g12 * b2) / safe
    beta = (g11 * b2 - g12 * b1) / safe
    inside = has & (det > 0) & (np.abs(alpha) <= 1) & (np.abs(beta) <= 1) & (t > 0)
    nb0 = np.maximum(nb, 0)
    w = np.maximum(rays.power_w[ray], np.maximum(rays.power_w[nb0[:, 0]], rays.power_w[nb0[:, 1]]))
    area = np.sqrt(np.maximum(det, 0.0))
    factor = np.where(inside, w / np.maximum(area, 1e-300), 0.0)
    return factor, inside


def aperture_irradiance(rays: MirrorRays, rho, observers_m, gain, attenuation_per_m, aperture_m) -> ApertureIrradiance:
    """Irradiance [W/m^2] averaged over the limiting aperture (diameter ``aperture_m``)
    at observers (M, 3) from reflected rays (module notes).

    ``rho`` (N,) or (N, T): each ray's reflectance (per state); ``gain`` (M,) the
    observers' optical gain. Mirror -> observer attenuation per ray, ``exp(-mu |O - P|)``.
    """
    obs = np.asarray(observers_m, float)
    m = len(obs)
    rho = np.asarray(rho, float)
    rho2 = rho.reshape(len(rho), -1)
    cols = rho2.shape[1]
    a = aperture_m / 2
    sums = {"binned": np.zeros((m, cols)), "tube": np.zeros((m, cols)), "tube_lo": np.full((m, cols), np.inf),
            "count": np.zeros(m, np.int64), "q1": np.zeros(m), "q2": np.zeros(m), "wmax": np.zeros((m, cols))}
    for block in _observer_blocks(rays, obs):
        local, ray = _pairs(rays, obs[block], a)
        rows = block[local]
        _bin_pairs(rays, rho2, obs, rows, ray, a, attenuation_per_m, sums)
        sel = (sums["count"] < MIN_RAYS_IN_APERTURE)[rows]
        _tube_pairs(rays, rho2, obs, rows[sel], ray[sel], attenuation_per_m, sums)
    return _combine(rays, rho2, obs, np.asarray(gain, float), attenuation_per_m, math.pi * a * a, sums, rho.ndim == 1)


def _observer_blocks(rays: MirrorRays, obs):
    """Observer indices in blocks (nearest the rays' centre first, so a block holds whole
    distance shells of :func:`_pairs`) of at most ``_PAIRS_PER_CHUNK // rays.count``: each
    observer pairs with every ray at most once, so a block never holds more than
    ``_PAIRS_PER_CHUNK`` pairs (an icosphere mirror with 2000 observers made 13.8 M at once
    and ran out of memory). Every pair of an observer is in its block, so the binned counts
    that choose the tubes are complete before its tubes are taken."""
    order = np.argsort(np.linalg.norm(obs - rays.centre_m, axis=1), kind="stable")
    size = max(1, _PAIRS_PER_CHUNK // max(rays.count, 1))
    return [order[c0:c0 + size] for c0 in range(0, len(order), size)]


def _bin_pairs(rays, rho2, obs, r_, k_, a, mu, sums):
    """Add the rays crossing each observer's aperture ball to the binned sums."""
    m = len(obs)
    v = obs[r_] - rays.points[k_]
    t = (v * rays.directions[k_]).sum(1)
    d2 = (v * v).sum(1)
    ball = ((d2 - t * t <= a * a) & (t > 0)) | (d2 <= a * a)
    r_, k_ = r_[ball], k_[ball]
    q = rays.power_w[k_] * np.exp(-mu * np.sqrt(d2[ball]))
    sums["count"] += np.bincount(r_, minlength=m)
    sums["q1"] += np.bincount(r_, q, m)
    sums["q2"] += np.bincount(r_, q * q, m)
    for c in range(rho2.shape[1]):
        sums["binned"][:, c] += np.bincount(r_, q * rho2[k_, c], m)
        np.maximum.at(sums["wmax"][:, c], r_, q * rho2[k_, c])


def _tube_pairs(rays, rho2, obs, r_, k_, mu, sums):
    """Take the largest (and smallest) tube irradiance among the rays whose tube holds
    each observer."""
    v = obs[r_] - rays.points[k_]
    t = (v * rays.directions[k_]).sum(1)
    reach = 2 * (rays.step_m + np.abs(t) * rays.spread_rad) * (1 + 1e-6)  # a tube's half-diagonal at t, bounded above
    near = ((v * v).sum(1) - t * t <= reach * reach) & (t > 0)
    r_, k_, v, t = r_[near], k_[near], v[near], t[near]
    factor, inside = _tube_irradiance(rays, obs[r_], k_, v, t)
    att = np.exp(-mu * np.linalg.norm(v, axis=1))
    for c in range(rho2.shape[1]):
        val = factor[inside] * att[inside] * rho2[k_[inside], c]
        np.maximum.at(sums["tube"][:, c], r_[inside], val)
        np.maximum.at(sums["wmax"][:, c], r_[inside], rays.power_w[k_[inside]] * att[inside] * rho2[k_[inside], c])
        np.minimum.at(sums["tube_lo"][:, c], r_[inside], val)


def _combine(rays, rho2, obs, gain, mu, area, sums, flat) -> ApertureIrradiance:
    """The binned value where enough rays cross the aperture, else the ray tubes' (capped by
    all the reflected power through the aperture); errors; the upper values."""
    count, q1, q2, tube, tube_lo = sums["count"], sums["q1"], sums["q2"], sums["tube"], sums["tube_lo"]
    dist = np.maximum(np.linalg.norm(obs - rays.centre_m, axis=1) - rays.radius_m, 0.0)
    cap = (rays.power_w[:, None] * rho2).sum(0)[None, :] * np.exp(-mu * dist)[:, None] / area
    use_bin = (count >= MIN_RAYS_IN_APERTURE) | ((tube.max(axis=1) <= 0) & (count > 0))
    rel = np.where(q1 > 0, 2 * np.sqrt(q2) / np.maximum(q1, 1e-300), 0.0)
    est_bin = sums["binned"] / area
    # a tube cannot put more through the aperture than the rays that cross it carry, with a
    # Poisson allowance for the few counted (n + 3 sqrt(n) + 3 rays of the heaviest weight)
    few = (count + 3 * np.sqrt(count) + 3)[:, None] * sums["wmax"] / area
    tube_c = np.minimum(np.minimum(tube, cap), few)
    est = np.where(use_bin[:, None], est_bin, tube_c)
    err = np.where(use_bin[:, None], est_bin * rel[:, None], np.where(np.isfinite(tube_lo), tube_c - np.minimum(tube_lo, tube_c), 0.0))
    g = gain.reshape(-1, 1)
    upper = np.where(use_bin[:, None], est_bin * (1 + rel[:, None]), tube_c) * g
    est, err = est * g, err * g
    if flat:
        upper, est, err = upper[:, 0], est[:, 0], err[:, 0]
    return ApertureIrradiance(upper, est, err, count, use_bin)


_NOHD_RAYS = 8192  # rays whose tubes are followed for the NOHD (evenly spaced, plus the hottest)
_NOHD_GRID = np.geomspace(1e-3, 1e9, 241)  # distances [m] the tubes are evaluated at (20 per decade)
_NOHD_PROBES = 6  # probe points per distance and kind (hottest tubes, heaviest rays; twice that spread over the rest)
_NOHD_RTOL = 2e-3  # bisection tolerance of the NOHD (relative; the upper end is returned)


class _Tubes:
    """The ray tubes followed for the NOHD: ``pick`` (rays with both grid neighbours, every
    k-th plus the heaviest), their directions ``r``, tube edges (transverse parts of the
    neighbours' offsets and direction differences: the edge at D is ``dp + D dr``) and
    weights ``q`` (the largest of the three rays' power x reflectance x gain)."""

    def __init__(self, rays: MirrorRays, weight, gain):
        has = np.flatnonzero(np.all(rays.neighbours >= 0, axis=1))
        pick = has[:: max(1, len(has) // _NOHD_RAYS)]
        self.pick = np.unique(np.concatenate([pick, has[np.argsort(weight[has])[-_NOHD_RAYS // 8:]]])).astype(np.int64)
        r = self.r = rays.directions[self.pick]
        self.edges = []
        for k in range(2):
            j = rays.neighbours[self.pick, k]
            dp = rays.points[j] - rays.points[self.pick]
            dr = rays.directions[j] - r
            self.edges.append((dp - (dp * r).sum(1)[:, None] * r, dr - (dr * r).sum(1)[:, None] * r))
        nb = rays.neighbours[self.pick]
        self.q = np.maximum(weight[self.pick], np.maximum(weight[nb[:, 0]], weight[nb[:, 1]])) * gain

    def level(self, dist, cap_w, mu):
        """(tubes, distances): the tube irradiance along each ray, capped at ``cap_w``."""
        d = np.asarray(dist, float)[None, :, None]
        (p1, v1), (p2, v2) = self.edges
        area = np.linalg.norm(np.cross(p1[:, None, :] + d * v1[:, None, :], p2[:, None, :] + d * v2[:, None, :]), axis=2)
        return np.minimum(self.q[:, None] / np.maximum(area, 1e-300), cap_w) * np.exp(-mu * d[..., 0])

    def foci(self, count=64):
        """Distances [m] where the heaviest tubes' edges are shortest (their focal lines)."""
        top = np.argsort(self.q)[-count:]
        out = [-(p[top] * v[top]).sum(1) / np.maximum((v[top] * v[top]).sum(1), 1e-300) for p, v in self.edges]
        d = np.concatenate(out)
        return d[np.isfinite(d) & (d > _NOHD_GRID[0]) & (d < _NOHD_GRID[-1])]


def tube_nohd(rays: MirrorRays, rho, mpe_w_m2, attenuation_per_m, aperture_m, gain=1.0):
    """Farthest distance [m] beyond the mirror, along the reflected rays, at which the
    aperture-averaged irradiance still reaches ``mpe_w_m2``, and the direction there.

    Along ray i the irradiance is at most its tube's, ``q_i rho_i exp(-mu D) / A_i(D)``
    (A_i the tube's cross-section from the two grid neighbours: zero at a focus), and at
    most all the reflected power over the aperture's area: the smaller of the two,
    maximised over the rays, is evaluated at 20 distances per decade from 1 mm to 1e9 m
    and at the focal lines of the heaviest tubes. From the farthest of these where it
    reaches the MPE inwards, the aperture average (:func:`aperture_irradiance`, its upper
    value) is computed at probe points (:func:`_probes_exceed`); the first distance where
    it reaches the MPE brackets the NOHD with the next one, refined by bisection to
    ``_NOHD_RTOL`` (upper end returned). ``inf`` when still reached at 1e9 m. If no probe
    reaches the MPE where the bound does, the bound's farthest distance is returned
    (conservative). ``rho`` (N,): the largest reflectance over states.
    """
    weight = rays.power_w * rho
    if not np.any(np.all(rays.neighbours >= 0, axis=1)):
        return 0.0, None
    tubes = _Tubes(rays, weight, gain)
    cap_w = float(weight.sum()) * gain / (math.pi * (aperture_m / 2) ** 2)
    dists = np.unique(np.concatenate([_NOHD_GRID, tubes.foci()]))
    best = tubes.level(dists, cap_w, attenuation_per_m).max(axis=0)
    above = np.flatnonzero(best >= mpe_w_m2)

    def exceeds(dist):
        return _probes_exceed(rays, rho, tubes, dist, mpe_w_m2, cap_w, attenuation_per_m, aperture_m, gain)

    for k in above[::-1]:
        ok, direction = exceeds(dists[k])
        if not ok:
            continue
        if k == len(dists) - 1:
            return math.inf, direction
        lo, hi = dists[k], dists[k + 1]
        while hi / lo - 1 > _NOHD_RTOL:
            mid = math.sqrt(lo * hi)
            up, d_mid = exceeds(mid)
            lo, hi, direction = (mid, hi, d_mid) if up else (lo, mid, direction)
        return float(hi), direction
    if not len(above):
        return 0.0, None
    k = int(above[-1])
    far = dists[min(k + 1, len(dists) - 1)]
    i = int(np.argmax(tubes.level([dists[k]], cap_w, attenuation_per_m)[:, 0]))
    return (math.inf if k == len(dists) - 1 else float(far)), tubes.r[i]


def _probes_exceed(rays, rho, tubes, dist, mpe_w_m2, cap_w, mu, aperture_m, gain):
    """Whether the aperture average reaches the MPE at ``dist`` along the probed rays, and
    the direction of the hottest probe: the ``_NOHD_PROBES`` hottest tubes, as many of the
    heaviest rays and twice as many spread over the rest, among the rays whose bound
    reaches the MPE (a rim's thin caustic has hot tubes and little power, a focus both).
    The probes are a sample of the points at that distance, not all of them."""
    lv = tubes.level([dist], cap_w, mu)[:, 0]
    hot = np.flatnonzero(lv >= mpe_w_m2)
    if not len(hot):
        return False, None
    by_level = hot[np.argsort(lv[hot])]
    top = np.unique(np.concatenate([by_level[-_NOHD_PROBES:], hot[np.argsort(tubes.q[hot])[-_NOHD_PROBES:]],
                                    by_level[np.linspace(0, len(hot) - 1, 2 * _NOHD_PROBES).astype(int)]]))
    pts = rays.points[tubes.pick[top]] + dist * tubes.r[top]
    e = aperture_irradiance(rays, rho, pts, np.full(len(top), float(gain)), mu, aperture_m).irradiance_w_m2
    return bool(e.max() >= mpe_w_m2), tubes.r[top[int(np.argmax(e))]]
