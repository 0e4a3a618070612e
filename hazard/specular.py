"""Mirror (delta-lobe) reflections by geometric optics, from what really hits the mirror.

Sources: spec `range-safety.md` section 4 (truncated beams, convex sphere and cylinder,
convex-mirror divergence) and section 1 (beam conventions); Coddington's equations for
reflection at a curved surface (e.g. Born & Wolf, *Principles of Optics*, 7th ed.,
section 4.6; Kingslake, *Lens Design Fundamentals*, the sagittal and tangential foci).

* **Flat facets** (plates, disks, the planar faces of boxes, caps and meshes): the
  reflected field is the incident beam unfolded. An observer O is lit through the facet
  when the incident ray towards its mirror image O' crosses a lit cell of that facet;
  it then receives ``rho(theta) E_beam(O')``: the Gaussian beam at the unfolded path
  length, so a mirror smaller than the beam keeps the full beam's local peak near the
  mirror and its lateral extent is cut by the mirror's outline. No diffraction credit
  (the Fraunhofer spread of a small mirror would lower far irradiance: not taken).
* **Convex sphere and cylinder** (exact normals): the specular point P is found by
  iterating the reflection law from the virtual source to O; the reflected wavefront
  leaves P with vergences (Coddington, reflection: ``1/q = 1/p + 2 kappa_n / cos(theta)``
  tangential, ``1/p + 2 kappa_n cos(theta)`` sagittal, p the incident wavefront radius),
  so ``E(D) = rho E_inc(P) / ((1 + D/q_t)(1 + D/q_s))`` at distance D. Far away this is
  ``rho E r^2 / (4 D^2)`` for a sphere and ``rho E r cos(theta) / (2 D)`` for a cylinder
  whose axis is normal to the plane of incidence (spec section 4). For a cylinder hit
  obliquely only the normal curvature in the plane of incidence, ``cos^2(beta) / r``, is
  applied (tangential), the sagittal spread not: less spread than the true one, the
  conservative side.
* **Curved meshes** (mesh files whose facets approximate a curved surface): a smooth
  surface with interpolated vertex normals, traced by dense rays and averaged over the
  limiting aperture, through any focus or caustic (:mod:`hazard.mesh_mirror`); their flat
  facets, if any, as above. The specular NOHD of such a spot is the larger of its
  samples' and the rays' (through the focus).
* Attenuation once per leg: ``exp(-mu (R1 + D))``, R1 from the aperture to the mirror.
"""

from __future__ import annotations

import math

import numpy as np

from .mesh_mirror import aperture_irradiance, curved_face_mask, is_curved_mesh, mirror_rays, tube_nohd

__all__ = ["specular_irradiance", "specular_nohd", "SpecularNohd", "mirror_directions", "mesh_mirror_irradiance"]

_ITERATIONS = 80
_CONVERGED = 1e-9  # 1 - cos of the angle between the reflected ray and the observer


def _unit(v):
    return v / np.maximum(np.linalg.norm(v, axis=-1, keepdims=True), 1e-300)


def _local(n_side, tangent, v):
    """v (M, 3) in the frames with z = n_side (M, 3) or (3,), x along the tangent."""
    n = np.broadcast_to(n_side, v.shape)
    x = tangent - (n @ tangent)[:, None] * n
    bad = np.linalg.norm(x, axis=1) < 1e-9
    if np.any(bad):
        x[bad] = np.cross(n[bad], [0.0, 0.0, 1.0]) + np.cross(n[bad], [1.0, 0.0, 0.0]) * 1e-3
    x = _unit(x)
    y = np.cross(n, x)
    return np.stack([(v * x).sum(1), (v * y).sum(1), (v * n).sum(1)], axis=1)


def _reflectance(spot, wi_local, states):
    model = spot.material
    if states is None:
        return model.specular_reflectance(wi_local)
    return np.stack([model.specular_reflectance(wi_local, state=s) for s in np.atleast_1d(states)], axis=-1)


def _target_faces(spot):
    """Global ids of the target's triangles in the ray tracer's numbering."""
    cells, k = spot.cells, spot.target.index
    return np.unique(cells.faces[cells.labels == k])


def _planes(spot):
    """The lit flat facets of a spot: list of (side normal (3,), point (3,), face ids)."""
    if getattr(spot, "_planes_cache", None) is not None:
        return spot._planes_cache
    t = spot.target
    d = spot.mean_incoming
    planes = []
    if t.spec.shape in ("plate", "disk"):
        n = t.normal if np.dot(d, t.normal) < 0 else -t.normal
        planes.append((n, t.center_m, _target_faces(spot)))
    elif spot.ray_faces is not None:
        faces, normals, points = spot.ray_faces
        flat = np.isin(faces, _target_faces(spot))  # lit facets only
        flat &= ~curved_face_mask(t)  # a curved mesh's facets are traced by hazard.mesh_mirror
        if t.mesh.analytic is not None:
            if t.mesh.analytic[0] == "sphere":
                flat[:] = False
            else:
                flat &= np.abs(normals @ t.mesh.analytic[2]) > 0.5  # cylinder caps
        faces, normals, points = faces[flat], normals[flat], points[flat]
        if len(faces):
            offset = (normals * points).sum(1)
            scale = max(1.0, float(np.abs(points).max()))
            key = np.column_stack([np.round(normals * 1e6), np.round(offset / scale * 1e6)])
            _, inv = np.unique(key, axis=0, return_inverse=True)
            inv = inv.ravel()
            for g in range(inv.max() + 1):
                sel = inv == g
                n = normals[sel][0]
                if np.dot(d, n) > 0:
                    n = -n
                planes.append((n, points[sel][0], faces[sel]))
    spot._planes_cache = planes
    return planes


def _lit(spot, s, faces=None):
    """Observers whose incident ray (transverse coordinates s) lands on the spot's target
    (on one of ``faces``): any of the five rays of the cell holding s (conservative)."""
    if spot.outline_s is not None:  # a flat target nothing shadows: its exact outline
        from .beam import inside_convex

        return inside_convex(s, spot.outline_s)
    cells = spot.cells
    leaf = cells.leaf_of(s)
    ok = leaf >= 0
    out = np.zeros(len(s), bool)
    if not np.any(ok):
        return out
    lab = cells.labels[leaf[ok]] == spot.target.index
    if faces is not None:
        lab &= np.isin(cells.faces[leaf[ok]], faces)
    out[ok] = lab.any(axis=1)
    return out


def _flat_geometry(spot, plane, obs):
    """Per observer through one flat facet: (mask, E_geo, point X, unit incoming d)."""
    beam = spot.beam
    n, p0, faces = plane
    h = (obs - p0) @ n
    img = obs - 2 * h[:, None] * n
    s, z = beam.to_s(img)
    o, d = beam.rays(np.nan_to_num(s))
    den = d @ n
    with np.errstate(divide="ignore", invalid="ignore"):
        t = ((p0 - o) @ n) / den
    x = o + np.nan_to_num(t)[:, None] * d
    ok = (h > 0) & np.all(np.isfinite(s), axis=1) & (den < 0) & (t > 0) & (z > 0)
    ok &= _lit(spot, np.nan_to_num(s, nan=1e9), faces)
    e = np.where(ok, beam.irradiance_w_m2(np.nan_to_num(s), np.where(ok, z, 1.0)), 0.0)
    return ok, e, x, _unit(d)


def _specular_point(spot, obs):
    """Specular points on a convex sphere or cylinder side: (P, n, d, settled, on_surface,
    near): the reflection law holds at P (to 1e-9 in cosine); P lies within the
    cylinder's length (always for a sphere); P lies within two radii of it (where an
    unsettled iteration must be taken as lit).

    Fixed-point iteration of the reflection law (the normal bisects the directions to
    the source and to the observer) from the virtual source of the ray through P; only
    rows not yet settled are iterated. Plain steps converge fast far away (contraction
    about r / distance); after 20 steps they are halved to settle observers close to
    the surface.
    """
    beam = spot.beam
    an = spot.target.mesh.analytic
    kind, c = an[0], an[1]
    r = an[2] if kind == "sphere" else an[3]
    ax = None if kind == "sphere" else an[2]
    n = _unit(_unit(-beam.axis)[None, :] + _unit(obs - c))
    along = np.zeros(len(obs))
    if ax is not None:
        along = (obs - c) @ ax
        n = _unit(n - (n @ ax)[:, None] * ax)
    active = np.arange(len(obs))
    for it in range(_ITERATIONS):
        if not len(active):
            break
        k = 1.0 if it < 20 else 0.5
        o, na = obs[active], n[active]
        p = c + r * na if ax is None else c + along[active, None] * ax + r * na
        s, _z = beam.to_s(p)
        d = _unit(beam.rays(np.nan_to_num(s))[1])
        u = _unit(-d) + _unit(o - p)
        if ax is not None:
            u = u - (u @ ax)[:, None] * ax
            rel = o - c
            rho_o = np.linalg.norm(rel - (rel @ ax)[:, None] * ax - r * na, axis=1)
            dax = d @ ax
            target = rel @ ax - rho_o * dax / np.sqrt(np.maximum(1 - dax * dax, 1e-300))
            along[active] = (1 - k) * along[active] + k * target
        n_new = _unit((1 - k) * na + k * _unit(u))
        moved = np.max(np.abs(n_new - na), axis=1)
        n[active] = n_new
        active = active[moved > 1e-14]
    p = c + r * n if ax is None else c + along[:, None] * ax + r * n
    s, _z = beam.to_s(p)
    d = _unit(beam.rays(np.nan_to_num(s))[1])
    refl = d - 2 * (d * n).sum(1)[:, None] * n
    settled = (refl * _unit(obs - p)).sum(1) > 1 - _CONVERGED
    on_surface = np.ones(len(obs), bool) if ax is None else np.abs(along) <= an[4]
    near = np.ones(len(obs), bool) if ax is None else np.abs(along) <= an[4] + 2 * r
    return p, n, d, settled, on_surface, near


def _vergences(kind, n, d, p_src, ax=None, r=1.0):
    """Reflected wavefront vergences (1/q_t, 1/q_s) [1/m] (Coddington, reflection)."""
    cos_i = np.clip(-(n * d).sum(1), 1e-12, 1.0)
    v_in = np.where(np.isfinite(p_src), 1.0 / np.where(np.isfinite(p_src), p_src, 1.0), 0.0)
    if kind == "flat":
        return v_in, v_in
    if kind == "sphere":
        return v_in + 2.0 / (r * cos_i), v_in + 2.0 * cos_i / r
    tin = d - (d * n).sum(1)[:, None] * n
    norm = np.linalg.norm(tin, axis=1)
    circ = np.cross(ax, n)
    cos_b = np.where(norm > 1e-12, np.abs((tin * circ).sum(1)) / np.maximum(norm, 1e-300), 1.0)
    return v_in + 2.0 * cos_b**2 / (r * cos_i), v_in


def _curved_geometry(spot, obs):
    """Per observer on a convex sphere / cylinder side: (mask, E_geo at the observer
    before reflectance and attenuation, point P, normal n, incoming d, not settled)."""
    beam = spot.beam
    kind = spot.target.mesh.analytic[0]
    p, n, d, settled, on_surface, near = _specular_point(spot, obs)
    c, r = spot.target.mesh.analytic[1], spot.target.mesh.analytic[2 if kind == "sphere" else 3]
    dist_c = np.linalg.norm(obs - c, axis=1)
    margin = np.ones(len(obs))
    far_fix = ~settled & (dist_c > 20 * r)
    if np.any(far_fix):
        # far away the reflection law is solved by the far-field normal (the bisector of
        # the beam axis and the direction from the centre): its error is O(r / D), taken
        # up by a margin of 4 r / D (conservative); happens near forward grazing
        n0 = _unit(_unit(-beam.axis)[None, :] + _unit(obs[far_fix] - c))
        if kind == "sphere":
            p[far_fix] = c + r * n0
        else:
            ax = spot.target.mesh.analytic[2]
            n0 = _unit(n0 - (n0 @ ax)[:, None] * ax)
            p[far_fix] = c + ((p[far_fix] - c) @ ax)[:, None] * ax + r * n0
        n[far_fix] = n0
        settled = settled | far_fix
        margin[far_fix] += 4 * r / dist_c[far_fix]
        d[far_fix] = _unit(beam.rays(np.nan_to_num(beam.to_s(p[far_fix])[0]))[1])
    s, z = beam.to_s(p)
    front = (n * d).sum(1) < 0
    ok = settled & on_surface & front & _lit(spot, np.nan_to_num(s, nan=1e9)) & (z > 0)
    e_inc = np.where(ok, beam.irradiance_w_m2(np.nan_to_num(s), np.where(ok, z, 1.0)), 0.0)
    p_src = beam.source_distance_m(z) * np.sqrt(1 + (np.nan_to_num(s) ** 2).sum(1) * (beam.divergence_rad / 2) ** 2)
    an = spot.target.mesh.analytic
    vt, vs = _vergences(kind, n, d, p_src, None if kind == "sphere" else an[2], an[2] if kind == "sphere" else an[3])
    dist = np.linalg.norm(obs - p, axis=1)
    geo = margin * e_inc / ((1 + dist * vt) * (1 + dist * vs))
    return ok, geo, p, n, d, ~settled & near


def specular_irradiance(spot, observers_m, gain, attenuation_per_m, states=None):
    """Irradiance [W/m^2] of a spot's mirror lobe at observers: (M,) or (M, T) with states.

    Sum over the spot's lit flat facets and, for a sphere or cylinder, its curved
    surface (module notes). Observers near a curved mirror where the specular point
    cannot be found (the iteration does not converge: within a few radii) get the
    mirror's highest possible irradiance, ``rho E_peak`` (conservative).
    """
    obs = np.asarray(observers_m, float)
    m = len(obs)
    gain = np.broadcast_to(np.asarray(gain, float), (m,))
    out = np.zeros((m,) if states is None else (m, len(np.atleast_1d(states))))
    if m == 0 or not spot.material.has_specular:
        return out
    pos, mu, tangent = spot.beam.position_m, attenuation_per_m, spot.target.tangent
    for plane in _planes(spot):
        ok, e, x, d = _flat_geometry(spot, plane, obs)
        if not np.any(ok):
            continue
        path = np.linalg.norm(x[ok] - pos, axis=1) + np.linalg.norm(obs[ok] - x[ok], axis=1)
        rho = _reflectance(spot, _local(plane[0], tangent, -d[ok]), states)
        geo = e[ok] * np.exp(-mu * path) * gain[ok]
        out[ok] += rho * (geo if states is None else geo[:, None])
    if is_curved_mesh(spot.target):
        out += mesh_mirror_irradiance(spot, obs, gain, mu, states).irradiance_w_m2
    an = spot.target.mesh.analytic
    if an is not None:
        ok, geo, p, n, d, near = _curved_geometry(spot, obs)
        if np.any(ok):
            path = np.linalg.norm(p[ok] - pos, axis=1) + np.linalg.norm(obs[ok] - p[ok], axis=1)
            rho = _reflectance(spot, _local(n[ok], tangent, -d[ok]), states)
            g = geo[ok] * np.exp(-mu * path) * gain[ok]
            out[ok] += rho * (g if states is None else g[:, None])
        if np.any(near):
            rho_max = _reflectance(spot, _local(spot.frames[:, 2], tangent, -spot.incoming), states).max(axis=0)
            cap = spot.max_irradiance_w_m2 * gain[near]
            out[near] = np.maximum(out[near], rho_max * cap if states is None else cap[:, None] * rho_max[None, :])
    return out


def _cached_rays(spot, mu):
    """The spot's curved-facet rays (:func:`hazard.mesh_mirror.mirror_rays`), built once
    per attenuation coefficient and kept on the spot."""
    cache = spot.__dict__.setdefault("_mesh_rays_cache", {})
    if mu not in cache:
        cache[mu] = mirror_rays(spot, mu, lambda s: _lit(spot, s))
    return cache[mu]


def mesh_mirror_irradiance(spot, observers_m, gain, attenuation_per_m, states=None):
    """A curved mesh's mirror reflection at observers (M, 3), averaged over the limiting
    aperture ``spot.aperture_m``: :class:`hazard.mesh_mirror.ApertureIrradiance` (upper
    value, estimate, stated error, rays through the aperture, binned or ray tubes); its
    rays are built once per spot and attenuation coefficient [1/m]. ``gain`` (M,)."""
    obs, mu = np.asarray(observers_m, float), attenuation_per_m
    gain = np.broadcast_to(np.asarray(gain, float), (len(obs),))
    rays = _cached_rays(spot, mu)
    m = len(obs)
    if rays is None:
        from .mesh_mirror import ApertureIrradiance

        z = np.zeros((m,) if states is None else (m, len(np.atleast_1d(states))))
        return ApertureIrradiance(z, z, z, np.zeros(m, np.int64), np.zeros(m, bool))
    rho = _reflectance(spot, _local(rays.normals, spot.target.tangent, -rays.incoming), states)
    return aperture_irradiance(rays, rho, obs, gain, mu, getattr(spot, "aperture_m", 7e-3))


class SpecularNohd:
    """Specular NOHD of a spot: the farthest distance beyond the mirror [m] at which some
    part of the reflected beam still reaches the MPE, and its direction (unit, or None)."""

    def __init__(self, nohd_m, direction):
        self.nohd_m = nohd_m
        self.direction = direction


def _sample_vergences(spot):
    """Per spot sample: the reflected wavefront vergences (1/q_t, 1/q_s)."""
    n, d, p_src = spot.frames[:, 2], spot.incoming, spot.source_distance_m
    an = spot.target.mesh.analytic
    if an is None:
        return _vergences("flat", n, d, p_src)
    if an[0] == "sphere":
        return _vergences("sphere", n, d, p_src, r=an[2])
    vt, vs = _vergences("cylinder", n, d, p_src, an[2], an[3])
    cap = np.abs(n @ an[2]) > 0.5
    fv = _vergences("flat", n, d, p_src)
    return np.where(cap, fv[0], vt), np.where(cap, fv[1], vs)


def specular_nohd(spot, mpe_w_m2, attenuation_per_m, states=None, gain=1.0) -> SpecularNohd:
    """Specular NOHD of a spot (:func:`_samples_nohd`); for a curved mesh also through its
    focus or caustic (:func:`_curved_mesh_nohd`), the larger taken."""
    flat = _samples_nohd(spot, mpe_w_m2, attenuation_per_m, states, gain)
    if flat.nohd_m is None or not is_curved_mesh(spot.target):
        return flat
    return _curved_mesh_nohd(spot, mpe_w_m2, attenuation_per_m, states, gain, flat)


def _samples_nohd(spot, mpe_w_m2, attenuation_per_m, states=None, gain=1.0) -> SpecularNohd:
    """Solve ``rho E_peak,i exp(-mu D) / ((1 + D/q_t)(1 + D/q_s)) = MPE`` for D per spot
    sample (the left side falls monotonically with D for flat and convex mirrors: log
    bisection to 1e-12 relative) and return the largest root. ``E_peak,i`` is the highest
    incident irradiance in the sample's cells (after laser -> mirror attenuation); rho
    the highest reflectance over ``states``. ``inf`` where the beam stays above the MPE
    past 1e9 m (collimated and unattenuated)."""
    if not spot.material.has_specular:
        return SpecularNohd(None, None)
    rho = _reflectance(spot, _local(spot.frames[:, 2], spot.target.tangent, -spot.incoming), states)
    rho = rho if states is None else rho.max(axis=1)
    e0 = rho * spot.peak_irradiance_w_m2 * gain
    vt, vs = _sample_vergences(spot)
    mu = attenuation_per_m

    def level(dist):
        return e0 * np.exp(-mu * dist) / ((1 + dist * vt) * (1 + dist * vs))

    hot = e0 >= mpe_w_m2
    if not np.any(hot):
        return SpecularNohd(0.0, _unit(mirror_directions(spot)[int(np.argmax(e0))]).tolist())
    far = 1e9
    beyond = hot & (level(np.full_like(e0, far)) >= mpe_w_m2)
    lo = np.full_like(e0, 1e-9)
    hi = np.full_like(e0, far)
    for _ in range(200):
        mid = np.sqrt(lo * hi)
        above = level(mid) >= mpe_w_m2
        lo = np.where(above, mid, lo)
        hi = np.where(above, hi, mid)
        if np.all((hi / lo - 1 < 1e-12) | ~hot):
            break
    root = np.where(beyond, np.inf, np.where(hot, lo, 0.0))
    i = int(np.argmax(root))
    return SpecularNohd(float(root[i]), _unit(mirror_directions(spot)[i]).tolist())


def _curved_mesh_nohd(spot, mpe_w_m2, mu, states, gain, flat: SpecularNohd) -> SpecularNohd:
    """The curved facets' ray-tube NOHD (:func:`hazard.mesh_mirror.tube_nohd`: through a
    focus, bounded by the aperture); where the lit part also has flat facets, the larger
    of it and the samples' NOHD (which takes every sample as flat: conservative)."""
    rays = _cached_rays(spot, mu)
    if rays is None:
        return flat
    rho = _reflectance(spot, _local(rays.normals, spot.target.tangent, -rays.incoming), states)
    rho = rho if states is None else rho.max(axis=1)
    dist, direction = tube_nohd(rays, rho, mpe_w_m2, mu, getattr(spot, "aperture_m", 7e-3), gain)
    if _planes(spot) and flat.nohd_m >= dist:  # flat facets lit too
        return flat
    return SpecularNohd(dist, flat.direction if direction is None else _unit(direction).tolist())


def mirror_directions(spot):
    """Reflected directions (N, 3) of a spot's samples: ``d - 2 (d . n) n`` on each
    sample's normal (unit when ``d`` and ``n`` are)."""
    n, d = spot.frames[:, 2], spot.incoming
    return d - 2 * (d * n).sum(1)[:, None] * n
