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
  Beyond the beam's sampled square (+-L w, ``beam.half_width``: at least 4, sized so that
  the tail there is below 1 % of the limit), where no cell says what the rays hit, the
  Gaussian's tail lights a box's or mesh's facet within its own outline, unshadowed
  (conservative), facets no cell reached included (:func:`_tail_lit`,
  :func:`_tail_facets`; plates and disks have their exact outline).
* **Convex sphere and cylinder** (exact normals): the specular point P is found by
  iterating the reflection law from the virtual source to O (by bisection in the plane of
  reflection where the iteration diverges, close to a large mirror); the Gaussian's tail
  beyond the beam's sampled square lights the surface too; the reflected wavefront
  leaves P with vergences (Coddington, reflection: ``1/q = 1/p + 2 kappa_n / cos(theta)``
  tangential, ``1/p + 2 kappa_n cos(theta)`` sagittal, p the incident wavefront radius),
  so ``E(D) = rho E_inc(P) / ((1 + D/q_t)(1 + D/q_s))`` at distance D. Far away this is
  ``rho E r^2 / (4 D^2)`` for a sphere and ``rho E r cos(theta) / (2 D)`` for a cylinder
  whose axis is normal to the plane of incidence (spec section 4). A cylinder hit
  obliquely (the plane of incidence at beta to its cross-section) spreads by its one
  curvature 1/r along the circumference: the generalised Coddington equations
  (Deschamps, Proc. IEEE 60:1022 (1972), eq. for reflection Q_r = Q_i + 2 cos_i
  Theta^-1 C Theta^-1) give the ray tube's area factor exactly as
  ``(1 + D/p)(1 + D/p + 2 D (cos^2(beta) / cos_i + sin^2(beta) cos_i) / r)``.
* At an eye (given its apertures) that beam is averaged over the limiting aperture or the
  aid's objective: locally the incident Gaussian seen through the reflection's ray map
  ``(I + D V)^-1`` (an astigmatic Gaussian), its disk mean by converged quadrature, raised
  by the exact field's largest excess over it on the disk's rim
  (:func:`_curved_aperture_w_m2`).
* The specular NOHD of a sphere or cylinder is solved on that same function along the
  worst reflected ray (:func:`specular_nohd`), so the observers and the NOHD agree.
* **Curved meshes** (mesh files whose facets approximate a curved surface): a smooth
  surface with interpolated vertex normals, traced by dense rays and averaged over the
  limiting aperture, through any focus or caustic (:mod:`hazard.physics.mesh_mirror`); their flat
  facets, if any, as above. The specular NOHD of such a spot is the larger of its
  samples' and the rays' (through the focus).
* Attenuation once per leg: ``exp(-mu (R1 + D))``, R1 from the aperture to the mirror.
"""

from __future__ import annotations

import math
import threading
import time
from dataclasses import dataclass

import numpy as np

from hazard.physics.mesh_mirror import aperture_irradiance, curved_face_mask, is_curved_mesh, mirror_rays, tube_nohd
from hazard.physics.rays import own_object

__all__ = ["specular_irradiance", "specular_nohd", "SpecularNohd", "mirror_directions", "reflected_power_w",
           "mesh_mirror_irradiance", "APERTURE_STATS", "aperture_stats_since", "describe_apertures"]

_ITERATIONS = 40  # fixed-point steps before the bisection (_bisect_specular)
_BISECTIONS = 64
_CONVERGED = 1e-9  # 1 - cos of the angle between the reflected ray and the observer


class _ApertureStats:
    """Counts of the mirror beams averaged over observers' apertures in this process, per
    mirror kind ("flat", "sphere", "cylinder", "curved mesh") and way ("averaged": the
    disk mean; "straddle": the sampled bound of an eye with no specular point of its own;
    "skipped": such eyes the prefilter proved dark), with the seconds spent (summed over
    threads); read as differences around a stage (:func:`aperture_stats_since`)."""

    def __init__(self):
        self._lock = threading.Lock()
        self._counts = {}

    def add(self, kind, way, n, seconds=0.0):
        with self._lock:
            c = self._counts.setdefault(f"{kind}/{way}", [0, 0.0])
            c[0] += int(n)
            c[1] += float(seconds)

    def snapshot(self) -> dict:
        with self._lock:
            return {k: tuple(v) for k, v in self._counts.items()}


APERTURE_STATS = _ApertureStats()


def aperture_stats_since(before: dict) -> dict:
    """``{"kind/way": (observers, seconds)}`` added since ``before`` (an
    :meth:`_ApertureStats.snapshot`); ways with no observer left out."""
    now = APERTURE_STATS.snapshot()
    out = {k: (n - before.get(k, (0, 0.0))[0], s - before.get(k, (0, 0.0))[1]) for k, (n, s) in now.items()}
    return {k: v for k, v in out.items() if v[0] > 0}


def describe_apertures(counts: dict) -> str:
    """One line for a stage's detail: the observers whose mirror beams were averaged over
    the limiting aperture, per mirror kind, and the cost."""
    if not counts:
        return "aperture: no mirror beam averaged over an observer's aperture"
    parts = []
    for kind in ("flat", "sphere", "cylinder", "curved mesh"):
        ways = {k.split("/")[1]: v for k, v in counts.items() if k.split("/")[0] == kind}
        if not ways:
            continue
        text = ", ".join(f"{n} {way}" + (f" ({s:.3g} s)" if s > 0 else "") for way, (n, s) in sorted(ways.items()))
        parts.append(f"{kind}: {text}")
    return ("aperture (observer rows per mirror; flat: observer-facet pairs; straddle: an eye at a curved beam's edge "
            "bounded by samples of its disk, skipped: such eyes proven dark): " + "; ".join(parts))


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


def lit_planes(spot):
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
        flat = np.isin(faces, _target_faces(spot))  # lit facets
        if spot.outline_s is None and getattr(t.spec, "shape", None) in ("box", "mesh"):
            # and those only the tail beyond the sampled square reaches (issue 29); not the
            # terrain's many facets (a grazing beam's tail spans hundreds: 45x the time)
            flat |= _tail_facets(spot, faces, normals, d) & ~flat
        flat &= ~curved_face_mask(t)  # a curved mesh's facets are traced by hazard.physics.mesh_mirror
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


def _tail_facets(spot, faces, normals, d) -> np.ndarray:
    """Facets (global ids ``faces``, unit ``normals`` as the mesh orients them) that no cell
    lit but the Gaussian's tail beyond the sampled square may reach: facing the beam
    (``normals . d < 0``), their projection in s not wholly inside the square (inside it
    the cells say they are not hit) and within ``sqrt(_TAIL_EXPONENT)`` of the axis (deeper
    the engine's value is 0). A box's side face next to a front face whose edge lies beyond
    4 w got 0 before (issue 29). Facets whose outline is unknown: all facing ones."""
    half = spot.beam.half_width
    cand = np.flatnonzero((normals @ d) < 0)
    out = np.zeros(len(faces), bool)
    if not len(cand):
        return out
    tri = _facet_triangles_s(spot, faces[cand])
    if tri is None:
        out[cand] = True
        return out
    bad = ~np.all(np.isfinite(tri), axis=(1, 2))
    t = np.nan_to_num(tri)
    inside = np.all(np.abs(t) < half, axis=(1, 2))
    e = np.roll(t, -1, axis=1) - t
    area2 = e[:, 0, 0] * e[:, 1, 1] - e[:, 0, 1] * e[:, 1, 0]
    cross = e[..., 0] * (-t[..., 1]) - e[..., 1] * (-t[..., 0])  # the origin against each edge
    length = np.sqrt((e * e).sum(-1))
    near = np.all(np.sign(area2)[:, None] * cross >= -math.sqrt(_TAIL_EXPONENT) * length, axis=1)
    out[cand] = bad | (near & ~inside & (np.abs(area2) > 0))
    return out


def _lit(spot, s, faces=None, reach_s=None):
    """Observers whose incident ray (transverse coordinates s) lands on the spot's target
    (on one of ``faces``): any of the five rays of the cell holding s (conservative).
    ``reach_s`` (per row, units of w): an aperture of that radius about s - lit when its
    disk overlaps the outline (expanded by it), or when s or one of 8 points on its rim
    is lit (cells)."""
    if reach_s is not None:
        if spot.outline_s is not None:
            from hazard.physics.beam import inside_convex

            return _inside_expanded(s, spot.outline_s, reach_s, inside_convex)
        ang = 2 * np.pi * np.arange(8) / 8
        ring = s[:, None, :] + reach_s[:, None, None] * np.stack([np.cos(ang), np.sin(ang)], axis=1)[None]
        return _lit(spot, s, faces) | _lit(spot, ring.reshape(-1, 2), faces).reshape(-1, 8).any(axis=1)
    if spot.outline_s is not None:  # a flat target nothing shadows: its exact outline
        from hazard.physics.beam import inside_convex

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


def _inside_expanded(s, outline, reach_s, inside_convex):
    """Points s (N, 2) within ``reach_s`` (N,) of a convex outline (its edges moved out
    by reach_s: a superset of the disks that overlap it), grouped by equal reach."""
    out = np.zeros(len(s), bool)
    for r in np.unique(reach_s):
        rows = np.flatnonzero(reach_s == r)
        out[rows] = inside_convex(s[rows], outline, margin=-float(r))
    return out


def _facet_triangles_s(spot, faces):
    """The triangles (F, 3, 2) of a flat facet (global ids ``faces``) in beam coordinates
    s, or None where they cannot be matched to the target's mesh. The central projection
    from the beam's virtual source keeps s constant along each ray, so a planar triangle
    projects to a triangle (NaN vertices: behind the virtual source)."""
    if spot.ray_faces is None or spot.target.mesh is None:
        return None
    ids, _, first = spot.ray_faces
    local = np.searchsorted(ids, faces)
    mesh = spot.target.mesh
    if np.any(local >= len(ids)) or len(ids) != len(mesh.faces) or np.any(ids[np.minimum(local, len(ids) - 1)] != faces):
        return None
    tri = np.asarray(mesh.vertices, float)[np.asarray(mesh.faces)[local]]
    if not np.allclose(tri[:, 0], first[local], rtol=0.0, atol=1e-9 * max(1.0, float(np.abs(first).max()))):
        return None  # the tracer's triangles are not the mesh's: unknown outline
    s, _ = spot.beam.to_s(tri.reshape(-1, 3))
    return s.reshape(-1, 3, 2)


def _near_triangles(p, tri, r) -> np.ndarray:
    """Points p (N, 2) within r (N,) of any triangle (T, 3, 2): inside one with its edges
    moved out by r (a superset of the disks that overlap it). A triangle with a
    non-finite vertex counts as everywhere (conservative); degenerate ones (edge-on to
    the rays, they reflect nothing) as nowhere."""
    out = np.zeros(len(p), bool)
    if not len(tri) or not len(p):
        return out
    if not np.all(np.isfinite(tri)):
        out[:] = True
        return out
    e = np.roll(tri, -1, axis=1) - tri  # (T, 3, 2)
    area2 = e[:, 0, 0] * e[:, 1, 1] - e[:, 0, 1] * e[:, 1, 0]
    keep = np.abs(area2) > 1e-12 * (1.0 + (tri * tri).sum(axis=(1, 2)))
    tri, e, orient = tri[keep], e[keep], np.sign(area2[keep])
    length = np.sqrt((e * e).sum(-1))  # (T, 3)
    step = max(1, 2_000_000 // (3 * max(len(tri), 1)))
    for a in range(0, len(p), step):
        rel = p[a:a + step, None, None, :] - tri[None]  # (n, T, 3, 2)
        cross = e[None, ..., 0] * rel[..., 1] - e[None, ..., 1] * rel[..., 0]
        inside = orient[None, :, None] * cross >= -r[a:a + step, None, None] * length[None] - 1e-12
        out[a:a + step] = np.any(np.all(inside, axis=2), axis=1)
    return out


def _tail_lit(spot, s, faces, reach_s=None) -> np.ndarray:
    """Images (transverse s (N, 2), units of w; NaN: none) of eyes lit through a flat
    facet by the Gaussian's tail beyond the sampled square (``|s_i| >= beam.half_width``),
    where no cell says what the rays hit (issue 29): there the tail (below exp(-L^2) of the
    peak, sized to 1 % of the limit; it was exp(-16) at the old fixed L = 4) is taken to
    reach the facet unshadowed (conservative, as :func:`_lit_or_tail` for curved sides),
    within the facet's own outline (its triangles projected into s). With ``reach_s``
    (an aperture of that radius about s): lit when the disk reaches beyond the square and
    comes within reach_s of the facet (a superset of the disks overlapping its part
    there). Without the facet's triangles the facet's plane counts as unbounded. Disks
    deeper than ``exp(-_TAIL_EXPONENT)`` (where the engine's value underflows to 0 anyway)
    are not tested."""
    r = np.zeros(len(s)) if reach_s is None else np.asarray(reach_s, float)
    finite = np.all(np.isfinite(s), axis=1)
    s0 = np.nan_to_num(s)
    gap = np.maximum(np.sqrt((s0 * s0).sum(axis=1)) - r, 0.0)  # the disk's nearest approach to the axis
    # deeper than exp(-_TAIL_EXPONENT) the engine's own value is 0: nothing to light
    beyond = np.flatnonzero(finite & (np.abs(s0).max(axis=1) + r >= spot.beam.half_width) & (gap * gap <= _TAIL_EXPONENT))
    out = np.zeros(len(s), bool)
    if not len(beyond):
        return out
    tri = _facet_triangles_s(spot, faces)
    if tri is None:
        out[beyond] = True
        return out
    if np.all(np.isfinite(tri)):  # the facet's bounding box in s first (cheap)
        lo, hi = tri.min(axis=(0, 1)), tri.max(axis=(0, 1))
        sb, rb = s[beyond], r[beyond]
        beyond = beyond[np.all((sb >= lo - rb[:, None]) & (sb <= hi + rb[:, None]), axis=1)]
    out[beyond] = _near_triangles(s[beyond], tri, r[beyond])
    return out


def _flat_geometry(spot, plane, obs, reach_m=None):
    """Per observer through one flat facet: (mask, E_geo, point X, unit incoming d,
    the image's s and axial z). ``reach_m`` (per observer, [m]): the radius of the
    aperture about the eye; an eye is lit when its aperture's image overlaps the lit
    part of the facet (:func:`_lit`)."""
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
    reach_s = None
    if reach_m is not None:
        reach_s = np.asarray(reach_m, float) / (beam.diameter_at(np.where(ok, z, 1.0)) / 2)
    lit = _lit(spot, np.nan_to_num(s, nan=1e9), faces, reach_s)
    if spot.outline_s is None:  # cells end at the sampled square: the tail beyond it (issue 29)
        lit |= _tail_lit(spot, s, faces, reach_s)
    ok &= lit
    e = np.where(ok, beam.irradiance_w_m2(np.nan_to_num(s), np.where(ok, z, 1.0)), 0.0)
    return ok, e, x, _unit(d), s, z


def _specular_point(spot, obs):
    """Specular points on a convex sphere or cylinder side: (P, n, d, settled, on_surface,
    near): the reflection law holds at P (to 1e-9 in cosine); P lies within the
    cylinder's length (always for a sphere); P lies within two radii of it (where an
    unsettled iteration must be taken as lit).

    Fixed-point iteration of the reflection law (the normal bisects the directions to
    the source and to the observer) from the virtual source of the ray through P; only
    rows not yet settled are iterated. Plain steps converge fast far away (contraction
    about r / distance); after 20 steps they are halved. Rows still unsettled after
    ``_ITERATIONS`` steps (close to a large mirror, where r / distance > 3 and the
    iteration diverges) are solved by bisection in the plane of the reflection
    (:func:`_bisect_specular`).
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
            step = k * (target - along[active])
            along[active] += step
        n_new = _unit((1 - k) * na + k * _unit(u))
        moved = np.max(np.abs(n_new - na), axis=1)
        if ax is not None:  # a row settles when its point along the axis does too
            moved = np.maximum(moved, np.abs(step) / r)
        n[active] = n_new
        active = active[moved > 1e-14]
    if len(active):
        n[active], along[active] = _bisect_specular(spot, obs[active])
    p = c + r * n if ax is None else c + along[:, None] * ax + r * n
    s, _z = beam.to_s(p)
    d = _unit(beam.rays(np.nan_to_num(s))[1])
    refl = d - 2 * (d * n).sum(1)[:, None] * n
    settled = (refl * _unit(obs - p)).sum(1) > 1 - _CONVERGED
    on_surface = np.ones(len(obs), bool) if ax is None else np.abs(along) <= an[4]
    near = np.ones(len(obs), bool) if ax is None else np.abs(along) <= an[4] + 2 * r
    return p, n, d, settled, on_surface, near


def _bisect_specular(spot, obs):
    """The specular point of a convex sphere or cylinder for observers (M, 3) by bisection:
    (unit normals n (M, 3), positions along a cylinder's axis (M,), 0 for a sphere).

    The normal at P, the virtual source S (or, collimated, the beam's direction) and the
    observer O lie in one plane through the centre c (for a cylinder: everything projected
    along its axis, where the section is a circle). In it, with x towards O and y towards
    S, P = c + r (cos t, sin t) for t in [0, beta] (beta the angle of S); the reflection
    law is g(t) = n x u_O + n x u_S = 0 (u the unit directions from P), with g(0) > 0 >
    g(beta): ``_BISECTIONS`` halvings. A cylinder's ray keeps its ratio of axial to
    in-plane travel on reflection, so P's axial position divides S -> O in the ratio of
    the in-plane lengths (collimated: ``z_O - L_2 d_z / |d_in-plane|``). Rows with O on
    the ray from c through S get the back-reflection point; the caller checks the law."""
    beam = spot.beam
    c, r, ax, flat = _section(spot)
    o = flat(obs - c)
    if beam.divergence_rad > 0:
        src = beam.position_m - beam.axis * (beam.diameter_m / beam.divergence_rad)
        sv = np.broadcast_to(flat(src - c), o.shape)
    else:
        src, sv = None, np.broadcast_to(flat(-np.asarray(beam.axis, float)), o.shape) * 1e12 * max(r, 1.0)
    x = _unit(o)
    toward = _unit(sv)
    y = toward - (toward * x).sum(1)[:, None] * x
    y = _unit(np.where(np.linalg.norm(y, axis=1)[:, None] > 1e-12, y, np.cross(x, [0.0, 0.0, 1.0] if ax is None else ax)))
    beta = np.arctan2((toward * y).sum(1), (toward * x).sum(1))
    lo, hi = np.zeros(len(o)), beta

    def cross(a, b):
        return (a * x).sum(1) * (b * y).sum(1) - (a * y).sum(1) * (b * x).sum(1)

    for _ in range(_BISECTIONS):
        th = 0.5 * (lo + hi)
        nv = np.cos(th)[:, None] * x + np.sin(th)[:, None] * y
        g = cross(nv, _unit(o - r * nv)) + cross(nv, _unit(sv - r * nv))
        lo, hi = np.where(g > 0, th, lo), np.where(g > 0, hi, th)
    th = 0.5 * (lo + hi)
    nv = np.cos(th)[:, None] * x + np.sin(th)[:, None] * y
    if ax is None:
        return nv, np.zeros(len(o))
    z_o = (obs - c) @ ax
    l1, l2, z_s, slope = _in_plane_legs(spot, o, nv, r, ax)
    if z_s is None:
        return nv, z_o - l2 * slope
    return nv, z_s + (z_o - z_s) * l1 / (l1 + l2)


def _in_plane_legs(spot, o, nv, r, ax):
    """A cylinder's reflection in its cross-section (o: the observers relative to the axis,
    in-plane; nv: the in-plane unit normals at the specular points): the in-plane lengths
    source -> P (inf when collimated) and P -> observer [m], the source's axial position
    relative to the centre (None when collimated) and the collimated beam's axial travel per
    in-plane length."""
    beam = spot.beam
    c = spot.target.mesh.analytic[1]
    l2 = np.linalg.norm(o - r * nv, axis=1)
    if beam.divergence_rad > 0:
        src = beam.position_m - beam.axis * (beam.diameter_m / beam.divergence_rad)
        rel = src - c
        l1 = np.linalg.norm(rel - (rel @ ax) * ax - r * nv, axis=1)
        return l1, l2, float(rel @ ax), 0.0
    dz = float(np.dot(beam.axis, ax))
    return np.full(len(o), np.inf), l2, None, dz / max(math.sqrt(max(1.0 - dz * dz, 0.0)), 1e-300)


def _vergences(kind, n, d, p_src, ax=None, r=1.0):
    """Reflected wavefront vergences (1/q_t, 1/q_s) [1/m] (Coddington, reflection); for a
    cylinder the two eigenvalues of its vergence matrix (their area factor
    ``(1 + D/q_t)(1 + D/q_s)`` is exact)."""
    cos_i = np.clip(-(n * d).sum(1), 1e-12, 1.0)
    v_in = np.where(np.isfinite(p_src), 1.0 / np.where(np.isfinite(p_src), p_src, 1.0), 0.0)
    if kind == "flat":
        return v_in, v_in
    if kind == "sphere":
        return v_in + 2.0 / (r * cos_i), v_in + 2.0 * cos_i / r
    # a cylinder curves along the circumference c only (curvature tensor c c^T / r): the
    # reflected vergence matrix v_in I + 2 M, M = [[k_tt / cos_i, k_ts], [k_ts, k_ss cos_i]]
    # (generalised Coddington), has det M = 0, so det(I + D V) = (1 + D v_in)(1 + D v_in +
    # 2 D tr M) exactly, tr M = (cos^2(beta) / cos_i + sin^2(beta) cos_i) / r = (cos_i +
    # (t_in . c)^2 / cos_i) / r, t_in the incoming ray's part along the surface (|t_in| =
    # sin_i): smooth through normal incidence, where the plane of incidence is undefined
    tin = d - (d * n).sum(1)[:, None] * n
    circ = np.cross(ax, n)
    return v_in + 2.0 * (cos_i + (tin * circ).sum(1) ** 2 / cos_i) / r, v_in


def _curved_source(spot, p, n, d, ok):
    """At specular points P (M, 3) of a convex sphere / cylinder side with unit normals n
    and unit incoming rays d: the incident irradiance [W/m^2] (unattenuated, 0 where not
    ``ok``) and the reflected wavefront's vergences (1/q_t, 1/q_s) [1/m], so that the
    mirror beam at distance D from P is ``E_inc / ((1 + D/q_t)(1 + D/q_s))`` (before
    reflectance, attenuation and gain). One piece for the observers
    (:func:`_curved_geometry`) and the NOHD (:func:`_curved_roots`)."""
    beam = spot.beam
    an = spot.target.mesh.analytic
    s, z = beam.to_s(p)
    s = np.nan_to_num(s)
    e_inc = np.where(ok, beam.irradiance_w_m2(s, np.where(ok, z, 1.0)), 0.0)
    p_src = beam.source_distance_m(z) * np.sqrt(1 + (s ** 2).sum(1) * (beam.divergence_rad / 2) ** 2)
    if an[0] == "sphere":
        vt, vs = _vergences("sphere", n, d, p_src, r=an[2])
    else:
        vt, vs = _vergences("cylinder", n, d, p_src, an[2], an[3])
    return e_inc, vt, vs


def _lit_or_tail(spot, s):
    """Points (beam coordinates s, (N, 2)) of a curved side lit by the beam: a lit cell
    (:func:`_lit`), or beyond the sampled square (``|s_i| >= beam.half_width``, where no
    cell says what the ray hits): there the Gaussian's tail (below ``exp(-L^2)`` of the
    peak; a focusing side may gather it) reaches the surface unless something shadows
    it, which is not known there, so it is taken as lit (conservative). Before, those
    points were dark and an eye beyond the 4 w edge of a cylinder's fan or a sphere's
    cone got 0 (issue 29)."""
    finite = np.all(np.isfinite(s), axis=1)
    tail = finite & np.any(np.abs(np.nan_to_num(s)) >= spot.beam.half_width, axis=1)
    return tail | _lit(spot, np.nan_to_num(s, nan=1e9))


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
    ok = settled & on_surface & front & _lit_or_tail(spot, s) & (z > 0)
    e_inc, vt, vs = _curved_source(spot, p, n, d, ok)
    dist = np.linalg.norm(obs - p, axis=1)
    geo = margin * e_inc / ((1 + dist * vt) * (1 + dist * vs))
    return ok, geo, p, n, d, ~settled & near


def _seen(ray_scene, spot, points, normals, obs, mask):
    """Clear ``mask`` (in place) where the segment from the reflection point (just off
    the surface along its normal) to the observer is blocked; nothing without a ray scene."""
    idx = np.flatnonzero(mask)
    if ray_scene is None or not len(idx):
        return
    nrm = normals if np.ndim(normals) == 1 else normals[idx]
    start = ray_scene.off_surface(points[idx], nrm)
    mask[idx] = ~ray_scene.occluded(start, obs[idx], transparent=own_object(spot.target))


def specular_irradiance(spot, observers_m, gain, attenuation_per_m, states=None, apertures=None, ray_scene=None):
    """Irradiance [W/m^2] of a spot's mirror lobe at observers: (M,) or (M, T) with states.

    Sum over the spot's lit flat facets and, for a sphere or cylinder, its curved
    surface (module notes). Observers near a curved mirror where the specular point
    cannot be found (the iteration does not converge: within a few radii) get the
    mirror's highest possible irradiance, ``rho E_peak`` (conservative).

    ``apertures`` (:class:`hazard.physics.aperture.Apertures`, one row per observer): flat facets
    give the power of the unfolded Gaussian through each eye's limiting aperture or its
    aid's collecting disk (:func:`hazard.physics.aperture.aperture_irradiance_w_m2`, ``gain`` not
    applied there) instead of the point value times ``gain``. A mirror with an exact
    outline (a plate or disk the beam reaches whole) counts only the part of each disk
    whose rays reach it (a 256-gon clipped to the outline: above the exact value by at
    most 1.5e-4 of the disk's area); other flat facets integrate the whole unfolded beam
    over the disk, as if the mirror did not cut it (an upper bound, exact where the
    disk's image lies inside the lit part; an eye is lit when its disk's image overlaps
    that part at all). A sphere's or cylinder's curved side is averaged over the same
    disks through its local astigmatic Gaussian, its error bounded from above
    (:func:`_curved_aperture_w_m2`); an eye with no specular point of its own but part
    of its disk in that beam gets a sampled bound (:func:`_straddle_w_m2`); a curved mesh's rays are binned over the limiting
    aperture (:mod:`hazard.physics.mesh_mirror`).

    ``ray_scene`` (optional, :class:`hazard.physics.rays.RayScene`): each observer's line of
    sight is traced from its own reflection point (just off the surface there; the
    mirror's own triangles never block when it is convex); without it every line is clear.
    """
    obs = np.asarray(observers_m, float)
    m = len(obs)
    gain = np.broadcast_to(np.asarray(gain, float), (m,))
    out = np.zeros((m,) if states is None else (m, len(np.atleast_1d(states))))
    if m == 0 or not spot.material.has_specular:
        return out
    pos, mu, tangent = spot.beam.position_m, attenuation_per_m, spot.target.tangent
    reach = None if apertures is None else np.maximum(apertures.eye_radius_m, np.where(apertures.aided, apertures.collect_radius_m, 0.0))
    for plane in lit_planes(spot):
        ok, e, x, d, s, z = _flat_geometry(spot, plane, obs, reach)
        _seen(ray_scene, spot, x, plane[0], obs, ok)
        if not np.any(ok):
            continue
        path = np.linalg.norm(x[ok] - pos, axis=1) + np.linalg.norm(obs[ok] - x[ok], axis=1)
        rho = _reflectance(spot, _local(plane[0], tangent, -d[ok]), states)
        if apertures is None:
            geo = e[ok] * np.exp(-mu * path) * gain[ok]
        else:
            t0 = time.perf_counter()
            geo = _flat_aperture_w_m2(spot.beam, s[ok], z[ok], path, mu, apertures.take(np.flatnonzero(ok)), spot.outline_s)
            APERTURE_STATS.add("flat", "averaged", int(ok.sum()), time.perf_counter() - t0)
        out[ok] += rho * (geo if states is None else geo[:, None])
    if is_curved_mesh(spot.target):
        t0 = time.perf_counter()
        out += mesh_mirror_irradiance(spot, obs, gain, mu, states).irradiance_w_m2
        APERTURE_STATS.add("curved mesh", "averaged", m, time.perf_counter() - t0)
    if spot.target.mesh.analytic is not None:
        _add_curved_side(spot, obs, gain, mu, states, ray_scene, out, apertures)
    return np.minimum(out, _power_cap(spot, obs, gain, mu, states))


def _add_curved_side(spot, obs, gain, mu, states, ray_scene, out, apertures=None) -> None:
    """Add (in place) a sphere's or cylinder's curved side to ``out``: Coddington spreading
    from each observer's specular point (module notes), averaged over each observer's
    limiting aperture or aid's objective when ``apertures`` are given
    (:func:`_curved_aperture_w_m2`; else the point value times ``gain``), and
    ``rho E_peak`` where that point cannot be found (conservative). With apertures, eyes
    with no lit specular point of their own, and eyes so deep in the Gaussian's tail that
    the point value underflows (the disk mean is then not computable from it), get the
    straddle bound (:func:`_add_straddle`)."""
    pos, tangent = spot.beam.position_m, spot.target.tangent
    ok, geo, p, n, d, near = _curved_geometry(spot, obs)
    _seen(ray_scene, spot, p, n, obs, ok)
    _seen(ray_scene, spot, p, n, obs, near)
    dark = ~ok & ~near
    if np.any(ok):
        path = np.linalg.norm(p[ok] - pos, axis=1) + np.linalg.norm(obs[ok] - p[ok], axis=1)
        rho = _reflectance(spot, _local(n[ok], tangent, -d[ok]), states)
        if apertures is None:
            g = geo[ok] * np.exp(-mu * path) * gain[ok]
        else:
            rows, t0 = np.flatnonzero(ok), time.perf_counter()
            with np.errstate(over="ignore", invalid="ignore"):  # deep-tail rows: replaced below
                g = _curved_aperture_w_m2(spot, obs[rows], p[rows], n[rows], d[rows], geo[rows] * np.exp(-mu * path),
                                          apertures.take(rows))
            deep = ~np.isfinite(g) | ~(geo[rows] > 0)
            g = np.where(deep, 0.0, g)
            if np.any(deep):
                k = rows[deep]
                dark[k[~_tail_negligible(spot, obs[k], p[k], n[k], d[k], _reach(apertures, k))]] = True
            APERTURE_STATS.add(spot.target.mesh.analytic[0], "averaged", len(rows), time.perf_counter() - t0)
        out[ok] += rho * (g if states is None else g[:, None])
    if apertures is not None and np.any(dark):
        _add_straddle(spot, obs, np.flatnonzero(dark), mu, states, ray_scene, apertures, out)
    if np.any(near):
        rho_max = _reflectance(spot, _local(spot.frames[:, 2], tangent, -spot.incoming), states).max(axis=0)
        cap = spot.max_irradiance_w_m2 * gain[near]
        out[near] = np.maximum(out[near], rho_max * cap if states is None else cap[:, None] * rho_max[None, :])


def _reach(apertures, rows) -> np.ndarray:
    """The largest disk radius [m] each observer's power is collected over (eye or aid)."""
    return np.maximum(apertures.eye_radius_m[rows], np.where(apertures.aided[rows], apertures.collect_radius_m[rows], 0.0))


def _add_straddle(spot, obs, rows, mu, states, ray_scene, apertures, out) -> None:
    """Raise ``out[rows]`` (in place) to the straddle bound (:func:`_straddle_w_m2`) of the
    observers the prefilter (:func:`_straddle_needed`) cannot prove dark; counted in
    :data:`APERTURE_STATS`."""
    need, t0, kind = _straddle_needed(spot, obs[rows], _reach(apertures, rows)), time.perf_counter(), spot.target.mesh.analytic[0]
    APERTURE_STATS.add(kind, "skipped", int((~need).sum()))
    rows = rows[need]
    if len(rows):
        out[rows] = np.maximum(out[rows], _straddle_w_m2(spot, obs[rows], mu, states, ray_scene, apertures.take(rows)))
        APERTURE_STATS.add(kind, "straddle", len(rows), time.perf_counter() - t0)


_TAIL_EXPONENT = 800.0  # exp(-800) is below every double: a disk wholly that deep in the tail gets 0


def _tail_negligible(spot, obs, p, n, d, reach_m) -> np.ndarray:
    """Observers whose specular point lies so deep in the Gaussian's tail that no point of
    their disk (radius ``reach_m``) can hold a representable field: in the local Gaussian
    of :func:`_curved_beam_map` a disk point is at least ``|s_P| - a ||J||`` from the beam's
    axis (units of w); taken with twice the disk's reach (for the model's curvature), a
    squared distance above ``_TAIL_EXPONENT`` means a field below exp(-800) of the peak."""
    with np.errstate(over="ignore", invalid="ignore"):  # a non-finite gap is not taken as negligible
        jac, s_p = _curved_beam_map(spot, obs, p, n, d)
        gap = np.linalg.norm(s_p, axis=1) - 2 * np.asarray(reach_m, float) * np.linalg.norm(jac, ord=2, axis=(1, 2))
    return np.isfinite(gap) & (gap > 0) & (gap * gap > _TAIL_EXPONENT)


_STRADDLE_RINGS = ((1.0 / 3.0, 8), (2.0 / 3.0, 16), (1.0, 64))  # (radius / a, points) sampled beside the centre


def _straddle_max(spot, obs, radius_m, mu, states, ray_scene) -> np.ndarray:
    """Per observer (M,) or (M, T): the largest exact curved-side irradiance (reflectance
    and attenuation applied, lines of sight traced) at the disk's centre and
    ``_STRADDLE_RINGS`` rings (radius ``radius_m``, normal to the direction from the
    mirror's centre: for a cylinder from its axis, perpendicular to it); 0 where no
    sample is lit."""
    an = spot.target.mesh.analytic
    c = np.broadcast_to(an[1], obs.shape)
    if an[0] != "sphere":
        c = c + ((obs - c) @ an[2])[:, None] * an[2]
    u = _unit(obs - c)
    e1 = _unit(np.cross(u, np.where(np.abs(u[:, :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])))
    e2 = np.cross(u, e1)
    ring = [np.zeros((1, 2))] + [f * np.stack([np.cos(th), np.sin(th)], 1)
                                 for f, k in _STRADDLE_RINGS for th in [2 * math.pi * np.arange(k) / k]]
    unit_pts = np.concatenate(ring)  # (K, 2)
    a = np.broadcast_to(np.asarray(radius_m, float), (len(obs),))[:, None, None]
    pts = (obs[:, None, :] + a * (unit_pts[None, :, :1] * e1[:, None, :] + unit_pts[None, :, 1:] * e2[:, None, :])).reshape(-1, 3)
    with np.errstate(over="ignore", invalid="ignore"):  # unlit samples far out of the beam: not used
        ok, geo, p, n, d, _ = _curved_geometry(spot, pts)
    _seen(ray_scene, spot, p, n, pts, ok)
    val = np.zeros((len(pts),) if states is None else (len(pts), len(np.atleast_1d(states))))
    if np.any(ok):
        path = np.linalg.norm(p[ok] - spot.beam.position_m, axis=1) + np.linalg.norm(pts[ok] - p[ok], axis=1)
        rho = _reflectance(spot, _local(n[ok], spot.target.tangent, -d[ok]), states)
        g = geo[ok] * np.exp(-mu * path)
        val[ok] = rho * (g if states is None else g[:, None])
    return val.reshape((len(obs), len(unit_pts)) + val.shape[1:]).max(axis=1)


def _straddle_needed(spot, obs, reach_m) -> np.ndarray:
    """The prefilter of :func:`_straddle_w_m2`: False for observers (with no lit specular
    point of their own) whose disk of radius ``reach_m`` provably holds no lit point.

    * **Shadow.** No mirror-reflected ray of a convex sphere or cylinder enters its shadow
      (the cone from the virtual source tangent to the sphere, beyond the plane through the
      centre normal to the cone's axis; a cylinder's wedge in its cross-section, where a
      point's reflection depends on its projection only; a cylinder of radius r when
      collimated): a disk more than its radius inside the shadow is dark.
    * **Beyond a cylinder's end.** The specular point's axial position is
      ``z_P = z_S + (z_X - z_S) f(X')``, ``f = L1 / (L1 + L2)`` the share of the source's
      in-plane leg (collimated: ``z_X - L2 dz/d_in``), X' the point's projection. Over the
      disk ``z_X`` spans ``z_O +- a``; f (or L2) is taken at the centre and 4 in-plane points
      ``a`` away, its range doubled about them; if the interval product for z_P lies wholly
      beyond the cylinder's ends, the disk is dark.

    Everything else (cells shadowed by other objects, unsettled rows) is kept. Tested in
    ``tests/validation/test_curved_fan_ends.py`` against dense samples of the disk."""
    an = spot.target.mesh.analytic
    a = np.asarray(reach_m, float) * (1 + 1e-9) + 1e-12
    need = ~_disk_in_shadow(spot, obs, a)
    if an[0] != "sphere" and np.any(need):
        rows = np.flatnonzero(need)
        need[rows] = ~_disk_beyond_end(spot, obs[rows], a[rows])
    return need


def _section(spot):
    """A sphere's or cylinder's centre c, radius r [m], axis (None for a sphere) and the
    projection onto its section plane (along a cylinder's axis; a sphere's: the identity),
    where its reflection is a circle's."""
    an = spot.target.mesh.analytic
    c, r = an[1], (an[2] if an[0] == "sphere" else an[3])
    ax = None if an[0] == "sphere" else np.asarray(an[2], float)

    def flat(v):
        return v if ax is None else v - (v @ ax)[..., None] * ax

    return c, r, ax, flat


def _disk_in_shadow(spot, obs, a) -> np.ndarray:
    """Observers whose ball of radius a (M,) lies wholly in the mirror's own shadow
    (:func:`_straddle_needed`)."""
    beam = spot.beam
    c, r, ax, flat = _section(spot)
    o = flat(obs - c)
    if beam.divergence_rad > 0:
        sv = flat(beam.position_m - beam.axis * (beam.diameter_m / beam.divergence_rad) - c)
        lc = float(np.linalg.norm(sv))
        if lc <= r:
            return np.zeros(len(obs), bool)
        v = o - sv
        cone = -sv / lc
        lv = np.maximum(np.linalg.norm(v, axis=1), 1e-300)
        gamma = np.arccos(np.clip((v @ cone) / lv, -1.0, 1.0))
        alpha = math.asin(r / lc)
        return (gamma < alpha) & (lv * np.sin(alpha - gamma) > a) & (v @ cone - a > lc)
    u = flat(np.asarray(beam.axis, float))
    if np.linalg.norm(u) < 1e-9:
        return np.zeros(len(obs), bool)
    u = u / np.linalg.norm(u)
    along = o @ u
    return (np.linalg.norm(o - along[:, None] * u, axis=1) < r - a) & (along > a)


def _disk_beyond_end(spot, obs, a) -> np.ndarray:
    """Observers whose disk of radius a (M,) provably reflects from beyond a cylinder's
    ends only (:func:`_straddle_needed`)."""
    an = spot.target.mesh.analytic
    c, ax, r, half = an[1], np.asarray(an[2], float), an[3], an[4]
    e1 = _unit(np.cross(ax, [1.0, 0.0, 0.0] if abs(ax[0]) < 0.9 else [0.0, 1.0, 0.0]))
    e2 = np.cross(ax, e1)
    offs = np.array([[0.0, 0.0], [1.0, 0.0], [-1.0, 0.0], [0.0, 1.0], [0.0, -1.0]])
    pts = obs[:, None, :] + a[:, None, None] * (offs[None, :, :1] * e1 + offs[None, :, 1:] * e2)
    pts = pts.reshape(-1, 3)
    nv, _ = _bisect_specular(spot, pts)
    rel = pts - c
    o = rel - (rel @ ax)[:, None] * ax
    l1, l2, z_s, slope = _in_plane_legs(spot, o, nv, r, ax)
    q = (l2 if z_s is None else l1 / (l1 + l2)).reshape(len(obs), 5)
    lo, hi = q.min(axis=1), q.max(axis=1)
    lo, hi = lo - (hi - lo), hi + (hi - lo)
    z_o = (obs - c) @ ax
    if z_s is None:
        zmin, zmax = z_o - a - np.maximum(hi * slope, lo * slope), z_o + a - np.minimum(hi * slope, lo * slope)
    else:
        lo, hi = np.clip(lo, 0.0, 1.0), np.clip(hi, 0.0, 1.0)
        ends = np.stack([(z_o + sa * a - z_s) * f for sa in (-1, 1) for f in (lo, hi)], axis=1)
        zmin, zmax = z_s + ends.min(axis=1), z_s + ends.max(axis=1)
    return np.all(np.isfinite(q), axis=1) & ((zmin > half) | (zmax < -half))


def _straddle_w_m2(spot, obs, mu, states, ray_scene, apertures) -> np.ndarray:
    """A sphere's or cylinder's mirror beam through the aperture of observers with no
    specular point of their own (just outside the beam's geometric edge: the reflection of
    a cylinder's end or a sphere's silhouette) but part of whose disk is lit, (M,) or (M, T).

    A conservative bound, not the disk mean: the largest exact value found at the disk's
    samples (:func:`_straddle_max`) taken over the whole disk, i.e. as if the disk were
    wholly lit at that value (the true mean is that times the lit fraction at most, up to
    the field's variation between samples). Naked eye: that over its limiting aperture;
    an aid: also ``tau E_max (a_c / 3.5 mm)^2`` over its collecting disk. Not exact: a lit
    cap thinner than ``1 - cos(pi / 64)`` (1.2e-3) of the radius on the rim can fall
    between the samples (that eye then stays at 0)."""
    from hazard.physics.aperture import PUPIL_RADIUS_M

    out = _straddle_max(spot, obs, apertures.eye_radius_m, mu, states, ray_scene)
    k = np.flatnonzero(apertures.aided)
    if len(k):
        emax = _straddle_max(spot, obs[k], apertures.collect_radius_m[k], mu, states, ray_scene)
        f = apertures.transmission[k] * (apertures.collect_radius_m[k] / PUPIL_RADIUS_M) ** 2
        out[k] = np.maximum(out[k], emax * (f if states is None else f[:, None]))
    return out


_DISK_RULES = ((12, 24), (24, 48), (48, 96))  # (radial Gauss-Legendre, angular) nodes of the disk mean
_DISK_RTOL = 1e-6  # two successive rules agreeing to this accept the finer one


def _curved_beam_map(spot, obs, p, n, d):
    """The mirror beam near each observer as the incident Gaussian seen through the ray map:
    (J (M, 2, 2), s_P (M, 2)). A displacement delta (tangential, sagittal:
    the plane of incidence and across it) normal to the reflected ray at the observer
    traces back to the reflected wavefront at P as ``(I + D V)^-1 delta`` (V the
    reflected vergence matrix, generalised Coddington, :func:`_vergences`), and that to the
    incident wavefront unchanged (reflection is an isometry between the two transverse
    planes in these bases); in beam coordinates ``s = s_P + J delta``. The field there is
    ``E(O) exp(|s_P|^2 - |s_P + J delta|^2)`` to first order in delta / R (R the smallest
    of the distance D, the radius r and the incident wavefront radius: the spreading factor
    and the map's curvature vary on that scale; :func:`_curved_aperture_w_m2` bounds the rest)."""
    beam = spot.beam
    an = spot.target.mesh.analytic
    r = an[2] if an[0] == "sphere" else an[3]
    out_dir = obs - p
    dist = np.linalg.norm(out_dir, axis=1)
    cos_i = np.clip(-(n * d).sum(1), 1e-12, 1.0)
    t = d - (d * n).sum(1)[:, None] * n
    tn = np.linalg.norm(t, axis=1)
    flat = tn < 1e-12  # normal incidence: any tangent
    if np.any(flat):
        t[flat] = np.cross(n[flat], np.where(np.abs(n[flat, :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]]))
        tn[flat] = np.linalg.norm(t[flat], axis=1)
    t = t / tn[:, None]
    sg = np.cross(n, t)
    t_in = _unit(t - (t * d).sum(1)[:, None] * d)
    s_pt, z = beam.to_s(p)
    p_src = beam.source_distance_m(z) * np.sqrt(1 + (s_pt ** 2).sum(1) * (beam.divergence_rad / 2) ** 2)
    v_in = np.where(np.isfinite(p_src), 1.0 / np.where(np.isfinite(p_src), p_src, 1.0), 0.0)
    if an[0] == "sphere":
        ct, cs = np.ones(len(p)), np.zeros(len(p))  # curvature 1/r in every direction: diagonal
        vtt, vts, vss = v_in + 2.0 / (r * cos_i), np.zeros(len(p)), v_in + 2.0 * cos_i / r
    else:
        c = _unit(np.cross(np.broadcast_to(an[2], n.shape), n))
        ct, cs = (c * t).sum(1), (c * sg).sum(1)
        vtt, vts, vss = v_in + 2 * ct * ct / (r * cos_i), 2 * ct * cs / r, v_in + 2 * cs * cs * cos_i / r
    m = np.empty((len(p), 2, 2))
    m[:, 0, 0], m[:, 0, 1], m[:, 1, 0], m[:, 1, 1] = 1 + dist * vtt, dist * vts, dist * vts, 1 + dist * vss
    k = np.linalg.inv(m)
    w = beam.diameter_at(z) / 2
    basis = np.stack([np.stack([t_in @ beam.e1, sg @ beam.e1], 1), np.stack([t_in @ beam.e2, sg @ beam.e2], 1)], 1)
    return basis @ k / w[:, None, None], np.nan_to_num(s_pt)


def _disk_mean_ratio(jac, s_p, radius_m) -> np.ndarray:
    """Mean over disks of radius a of ``exp(|s_P|^2 - |s_P + J delta|^2)`` (the mirror beam
    over its value at the centre), by polar Gauss-Legendre x trapezoid rules of rising
    order; a row whose two finest rules differ by more than ``_DISK_RTOL`` (a beam much
    narrower than the disk) takes the integrand's largest value on the disk,
    ``exp(min(|s_P|^2, 2 a |J^T s_P|))`` (an upper bound)."""
    a = np.broadcast_to(np.asarray(radius_m, float), (len(s_p),))
    b = np.einsum("mji,mj->mi", jac, s_p)  # J^T s_P
    q = np.einsum("mki,mkj->mij", jac, jac)  # J^T J
    prev, out = None, None
    for n_r, n_t in _DISK_RULES:
        x, wx = np.polynomial.legendre.leggauss(n_r)
        rho = 0.5 * (x + 1.0)
        th = 2 * math.pi * (np.arange(n_t) + 0.5) / n_t
        u = (rho[:, None, None] * np.stack([np.cos(th), np.sin(th)], -1)[None]).reshape(-1, 2)  # unit disk nodes
        wt = np.repeat(0.5 * wx * rho, n_t) / n_t * 2.0  # int_0^1 rho drho over the disk's area / pi: sum = 1
        qu = np.einsum("ui,mij,uj->mu", u, q, u)
        bu = b @ u.T
        expo = -(a[:, None] ** 2 * qu + 2 * a[:, None] * bu)
        out = np.exp(np.minimum(expo, 700.0)) @ wt
        if prev is not None:
            good = np.abs(out - prev) <= _DISK_RTOL * np.abs(out)
            if np.all(good):
                return out
        prev = out
    bound = np.exp(np.minimum(np.minimum((s_p * s_p).sum(1), 2 * a * np.linalg.norm(b, axis=1)), 700.0))
    return np.where(np.abs(out - prev) <= _DISK_RTOL * np.abs(out), out, bound)


_RIM_POINTS = 16  # where the local Gaussian is checked against the exact field on each disk's rim
_SMALL_CHANGE = 1e-3  # a disk mean within this of the point value: its change is doubled instead


def _curved_aperture_w_m2(spot, obs, p, n, d, point_w_m2, apertures):
    """A sphere's or cylinder's mirror beam through each observer's limiting aperture (or
    its aid's objective, delivered into the 7 mm pupil): the point value times the disk
    mean of the local Gaussian (:func:`_curved_beam_map`, :func:`_disk_mean_ratio`).

    The local Gaussian is first order in the disk's radius over the scale the ray map
    curves on; its error is bounded from above as follows. Where the mean is within
    ``_SMALL_CHANGE`` of the point value, the larger of the two is taken and its change
    from the point value doubled (the model's own error is a small fraction of that change).
    Elsewhere the exact field (:func:`_curved_geometry`: the specular point and Coddington
    spreading of each rim point) is evaluated at ``_RIM_POINTS`` points of the disk's rim,
    and the mean is raised by the largest ratio of the exact to the model value found
    there (the model's error grows from 0 at the centre to its largest on the rim)."""
    from hazard.physics.aperture import aperture_irradiance_w_m2

    jac, s_p = _curved_beam_map(spot, obs, p, n, d)
    ref = _unit(obs - p)
    t_r, s_r = _curved_transverse(p, n, d, ref)

    def fraction(radius_m, rows):
        a = np.broadcast_to(np.asarray(radius_m, float), (len(rows),))
        ratio = _disk_mean_ratio(jac[rows], s_p[rows], a)
        change = np.abs(ratio - 1.0)
        with np.errstate(over="ignore"):  # rows far in the tail: replaced below (big)
            out = np.maximum(ratio, 1.0) * (1.0 + change)
        big = np.flatnonzero(change > _SMALL_CHANGE)
        if len(big):
            k = rows[big]
            out[big] = ratio[big] * _rim_margin(spot, obs[k], point_w_m2[k], jac[k], s_p[k], t_r[k], s_r[k], a[big])
        return out * math.pi * a * a

    return aperture_irradiance_w_m2(point_w_m2, 1.0, 0.0, apertures, fraction)


def _curved_transverse(p, n, d, ref):
    """The reflected ray's transverse basis at each observer: tangential (in the plane of
    incidence) and sagittal, as in :func:`_curved_beam_map`."""
    t = d - (d * n).sum(1)[:, None] * n
    tn = np.linalg.norm(t, axis=1)
    flat = tn < 1e-12
    if np.any(flat):
        t[flat] = np.cross(n[flat], np.where(np.abs(n[flat, :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]]))
        tn[flat] = np.linalg.norm(t[flat], axis=1)
    t = t / tn[:, None]
    return _unit(t - (t * ref).sum(1)[:, None] * ref), np.cross(n, t)


def _rim_margin(spot, obs, point_w_m2, jac, s_p, t_r, s_r, a) -> np.ndarray:
    """Per observer: max(1, the largest ratio of the exact field to the local Gaussian at
    ``_RIM_POINTS`` points on its disk's rim (radius a, normal to the reflected ray))."""
    th = 2 * math.pi * np.arange(_RIM_POINTS) / _RIM_POINTS
    u = np.stack([np.cos(th), np.sin(th)], axis=1)  # (K, 2): tangential, sagittal
    delta = a[:, None, None] * u[None]  # (M, K, 2)
    pts = obs[:, None, :] + delta[..., :1] * t_r[:, None, :] + delta[..., 1:] * s_r[:, None, :]
    _, geo, *_ = _curved_geometry(spot, pts.reshape(-1, 3))
    _, geo0, *_ = _curved_geometry(spot, obs)
    sd = s_p[:, None, :] + np.einsum("mij,mkj->mki", jac, delta)
    model = geo0[:, None] * np.exp(np.minimum((s_p * s_p).sum(1)[:, None] - (sd * sd).sum(2), 700.0))
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = np.where(model > 0, geo.reshape(len(obs), -1) / model, np.where(geo.reshape(len(obs), -1) > 0, np.inf, 1.0))
    worst = np.max(ratio, axis=1)
    # an infinite ratio (lit where the model is 0): the disk's largest possible mean, the
    # incident beam's value at the centre of its image
    cap = np.exp(np.minimum((s_p * s_p).sum(1), 700.0))
    return np.where(np.isfinite(worst), np.maximum(worst, 1.0), cap)


def reflected_power_w(spot, states=None):
    """Power [W] in the spot's mirror lobe, ``sum rho_i P_i`` over its samples (per state):
    all a mirror beam can carry."""
    rho = _reflectance(spot, _local(spot.frames[:, 2], spot.target.tangent, -spot.incoming), states)
    return (rho * (spot.power_w if states is None else spot.power_w[:, None])).sum(axis=0)


def _power_cap(spot, obs, gain, mu, states):
    """The most a mirror beam can deliver averaged over the limiting aperture (M,) or
    (M, T): its whole power ``sum rho_i P_i`` through the aperture's area, attenuated from
    the spot's farthest sample to the observer, times the optical gain (an upper bound
    for aided eyes too: the gain is at least the transmission)."""
    c = spot.centroid
    extent = float(np.sqrt(((spot.points - c) ** 2).sum(1).max()))
    if spot.spread_m2 is not None and len(spot.spread_m2):
        extent += 3.0 * math.sqrt(max(float(np.max(spot.spread_m2)), 0.0))
    leg = np.maximum(np.linalg.norm(obs - c, axis=1) - extent, 0.0)
    cap = np.exp(-mu * leg) * gain / (math.pi * (spot.aperture_m / 2) ** 2)
    p_refl = reflected_power_w(spot, states)
    return cap * p_refl if states is None else cap[:, None] * p_refl[None, :]


CUT_SIDES = 256  # the aperture's disk as a circumscribed polygon when the mirror's outline cuts it


def _flat_aperture_w_m2(beam, s, z, path_m, mu, apertures, outline_s=None):
    """The unfolded Gaussian (image at transverse s, axial z) through the apertures, with
    the ray tilt of the point value and attenuation along the folded path. With the
    mirror's exact outline (``outline_s``, s coordinates: the rays that reach the mirror)
    only the part of each disk's image inside it counts (:func:`_cut_fraction`), else
    the whole Gaussian over the disk (an upper bound)."""
    from hazard.physics.aperture import aperture_irradiance_w_m2, disk_fraction

    w = beam.diameter_at(z) / 2
    s2 = (s * s).sum(axis=1)
    power = beam.power_w * np.exp(-mu * path_m) * np.sqrt(1.0 + s2 * (beam.divergence_rad / 2) ** 2)
    if outline_s is None:
        return aperture_irradiance_w_m2(power, w, np.sqrt(s2) * w, apertures)

    def fraction(radius_m, rows):
        from hazard.physics.beam import inside_convex

        f = disk_fraction(radius_m, np.sqrt(s2[rows]) * w[rows], w[rows])
        r_s = np.asarray(radius_m, float) / w[rows]
        cut = np.flatnonzero(~_inside_by(s[rows], outline_s, r_s, inside_convex) & (f > 0))
        if len(cut):
            f[cut] = np.minimum(f[cut], _cut_fraction(outline_s, s[rows][cut], r_s[cut]))
        return f

    return aperture_irradiance_w_m2(power, w, np.sqrt(s2) * w, apertures, fraction)


def _inside_by(s, outline, r_s, inside_convex):
    """Disks (centres s, radii r_s; units of w) wholly inside a convex outline."""
    out = np.zeros(len(s), bool)
    for r in np.unique(r_s):
        rows = np.flatnonzero(r_s == r)
        out[rows] = inside_convex(s[rows], outline, margin=float(r))
    return out


def _cut_fraction(outline_s, centres_s, radii_s, sides=CUT_SIDES) -> np.ndarray:
    """Gaussian power fraction (density ``exp(-|s|^2) / pi``) in each disk cut by the
    convex outline: the disk's circumscribed ``sides``-gon clipped to the outline
    (Sutherland-Hodgman) and integrated exactly (Owen's T, :func:`hazard.physics.beam.polygon_moments`).
    An upper bound: the polygon exceeds the disk by ``1/cos^2(pi/sides) - 1`` = 1.5e-4
    of its area."""
    from hazard.physics.beam import clip_convex, polygon_moments

    ang = 2 * np.pi * (np.arange(sides) + 0.5) / sides
    ring = np.stack([np.cos(ang), np.sin(ang)], axis=1) / np.cos(np.pi / sides)
    polys = [clip_convex(c + r * ring, outline_s) for c, r in zip(centres_s, radii_s)]
    out = np.zeros(len(polys))
    live = [k for k, q in enumerate(polys) if len(q) >= 3]
    if live:
        out[live] = polygon_moments([polys[k] for k in live]).fraction
    return out


def _cached_rays(spot, mu):
    """The spot's curved-facet rays (:func:`hazard.physics.mesh_mirror.mirror_rays`), built once
    per attenuation coefficient and kept on the spot."""
    cache = spot.__dict__.setdefault("_mesh_rays_cache", {})
    if mu not in cache:
        cache[mu] = mirror_rays(spot, mu, lambda s: _lit(spot, s))
    return cache[mu]


def mesh_mirror_irradiance(spot, observers_m, gain, attenuation_per_m, states=None):
    """A curved mesh's mirror reflection at observers (M, 3), averaged over the limiting
    aperture ``spot.aperture_m``: :class:`hazard.physics.mesh_mirror.ApertureIrradiance` (upper
    value, estimate, stated error, rays through the aperture, binned or ray tubes); its
    rays are built once per spot and attenuation coefficient [1/m]. ``gain`` (M,)."""
    obs, mu = np.asarray(observers_m, float), attenuation_per_m
    gain = np.broadcast_to(np.asarray(gain, float), (len(obs),))
    rays = _cached_rays(spot, mu)
    m = len(obs)
    if rays is None:
        from hazard.physics.mesh_mirror import ApertureIrradiance

        z = np.zeros((m,) if states is None else (m, len(np.atleast_1d(states))))
        return ApertureIrradiance(z, z, z, np.zeros(m, np.int64), np.zeros(m, bool))
    rho = _reflectance(spot, _local(rays.normals, spot.target.tangent, -rays.incoming), states)
    return aperture_irradiance(rays, rho, obs, gain, mu, getattr(spot, "aperture_m", 7e-3))


@dataclass(frozen=True)
class MirrorBeamSteps:
    """The numbers behind a mirror beam's NOHD, for its worked steps (review page): the
    governing part's ``E(D) = K rho E_peak exp(-mu D) / ((1 + D v_t)(1 + D v_s)) = MPE``.

    Attributes
    ----------
    governed_by : str
        "sample" (a flat sample of the spot), "whole-target bound" (a faceted target's
        edge bound), "aperture power cap" (the lobe's whole power over the limiting
        aperture: ``D = ln(K P_r / (A MPE)) / mu``), "curved side" or "curved facets"
        (no closed form: Coddington spreading or ray tubes along the worst ray).
    reflectance : float or None
        rho of the governing part (largest over the history's states).
    incident_peak_w_m2 : float or None
        E_peak [W/m^2]: its highest incident irradiance (after the laser -> mirror path).
    vergence_t_per_m, vergence_s_per_m : float or None
        v_t, v_s [1/m]: the reflected wavefront's vergences (1 / the virtual source's distance).
    aperture_cap_w_m2 : float or None
        K P_r / A [W/m^2]: no mirror beam averages more over the limiting aperture.
    """

    governed_by: str
    reflectance: float | None = None
    incident_peak_w_m2: float | None = None
    vergence_t_per_m: float | None = None
    vergence_s_per_m: float | None = None
    aperture_cap_w_m2: float | None = None

    def to_dict(self) -> dict:
        return {"governed_by": self.governed_by, "reflectance": self.reflectance,
                "incident_peak_w_m2": self.incident_peak_w_m2, "vergence_t_per_m": self.vergence_t_per_m,
                "vergence_s_per_m": self.vergence_s_per_m, "aperture_cap_w_m2": self.aperture_cap_w_m2}


class SpecularNohd:
    """Specular NOHD of a spot: the farthest distance beyond the mirror [m] at which some
    part of the reflected beam still reaches the MPE, its direction (unit, or None) and
    the numbers behind it (:class:`MirrorBeamSteps`, or None)."""

    def __init__(self, nohd_m, direction, steps: MirrorBeamSteps | None = None):
        self.nohd_m = nohd_m
        self.direction = direction
        self.steps = steps


def _level_roots(e0, vt, vs, mu, mpe_w_m2) -> np.ndarray:
    """Per row: the distance D [m] at which ``e0 exp(-mu D) / ((1 + D vt)(1 + D vs))``
    falls to ``mpe_w_m2``; 0 where e0 < MPE, inf where it is still above the MPE at
    1e9 m (collimated and unattenuated). For vt, vs, mu >= 0 (flat and convex mirrors)
    f(D) = ln(e0 / MPE) - mu D - ln(1 + D vt) - ln(1 + D vs) falls and is convex, so
    Newton's steps from D = 0 climb to the root from below without passing it; stopped
    at 1e-13 relative (rows not settled in 100 steps: log bisection, 1e-12)."""
    e0, vt, vs = np.broadcast_arrays(*(np.asarray(x, float) for x in (e0, vt, vs)))
    hot = e0 >= mpe_w_m2
    if not np.any(hot):
        return np.zeros(e0.shape)
    c = np.log(np.where(hot, e0, mpe_w_m2) / mpe_w_m2)

    def f(dist):
        return c - mu * dist - np.log1p(dist * vt) - np.log1p(dist * vs)

    beyond = hot & (f(np.full(e0.shape, 1e9)) >= 0)
    live = hot & ~beyond
    d = np.zeros(e0.shape)
    for _ in range(100):
        slope = -mu - vt / (1 + d * vt) - vs / (1 + d * vs)
        step = np.where(live, -f(d) / np.where(live, slope, -1.0), 0.0)
        d = d + np.maximum(step, 0.0)
        if not np.any(live & (step > 1e-13 * d)):
            break
    else:
        slow = live & (np.abs(f(d)) > 1e-12)
        lo, hi = np.where(slow, np.maximum(d, 1e-9), 1.0), np.full(e0.shape, 1e9)
        for _ in range(200):
            mid = np.sqrt(lo * hi)
            above = f(mid) >= 0
            lo, hi = np.where(above, mid, lo), np.where(above, hi, mid)
            if np.all((hi / lo - 1 < 1e-12) | ~slow):
                break
        d = np.where(slow, lo, d)
    return np.where(beyond, np.inf, np.where(hot, d, 0.0))


def _max_over_states(rho):
    return rho if rho.ndim == 1 else rho.max(axis=1)


def _flat_sample_roots(spot, mpe_w_m2, mu, states, gain):
    """NOHD [m] per spot sample on a flat facet (a plate, disk, box or mesh facet, a
    cylinder's cap; 0 for samples on a curved side): the unfolded beam's peak
    ``rho E_peak,i exp(-mu D) / (1 + D / p)^2`` (``E_peak,i`` the highest incident
    irradiance in the sample's cells after laser -> mirror attenuation, p the incident
    wavefront radius), and ``rho E_peak,i`` per sample."""
    rho = _max_over_states(_edge_reflectance(
        spot, _reflectance(spot, _local(spot.frames[:, 2], spot.target.tangent, -spot.incoming), states), states))
    e0 = rho * spot.peak_irradiance_w_m2 * gain
    n, d, p_src = spot.frames[:, 2], spot.incoming, spot.source_distance_m
    an = spot.target.mesh.analytic
    flat = np.ones(len(e0), bool) if an is None else (
        np.zeros(len(e0), bool) if an[0] == "sphere" else np.abs(n @ an[2]) > 0.5)
    vt, vs = _vergences("flat", n, d, p_src)
    e_flat = np.where(flat, e0, 0.0)
    if spot.edge_peak_w_m2 is not None:  # a sampled faceted target: the whole-target bound as one more sample
        e_flat = np.append(e_flat, _facet_reflectance_max(spot, rho, states) * spot.edge_peak_w_m2 * gain)
        v = 1.0 / spot.edge_source_m
        vt, vs = np.append(vt, v), np.append(vs, v)
    roots = _level_roots(e_flat, vt, vs, mu, mpe_w_m2)
    cap_w_m2 = _aperture_power(spot, states) * gain
    cap = _cap_root(cap_w_m2, mu, mpe_w_m2)
    i = int(np.argmax(roots)) if len(roots) else 0
    if not len(roots) or roots[i] <= 0:
        steps = None
    elif roots[i] > cap:
        steps = MirrorBeamSteps("aperture power cap", aperture_cap_w_m2=cap_w_m2)
    else:
        rho_i = float(rho[i]) if i < len(rho) else _facet_reflectance_max(spot, rho, states)
        steps = MirrorBeamSteps("sample" if i < len(rho) else "whole-target bound", rho_i, float(e_flat[i]) / (rho_i * gain),
                                float(vt[i]), float(vs[i]), cap_w_m2)
    return np.minimum(roots, cap), e0, steps


def _cap_root(cap_w_m2, mu, mpe_w_m2) -> float:
    """The distance [m] at which ``cap exp(-mu D)`` (a mirror lobe's whole power over the
    limiting aperture) falls to the MPE: 0 below it, inf without attenuation."""
    if cap_w_m2 < mpe_w_m2:
        return 0.0
    return math.inf if mu <= 0 else math.log(cap_w_m2 / mpe_w_m2) / mu


def _curved_hit(spot, s):
    """Where the beam's rays at transverse coordinates s (K, 2) first meet the spot's
    sphere / cylinder side from outside: (P, unit outward normal, unit incoming ray,
    hit)."""
    an = spot.target.mesh.analytic
    o, d = spot.beam.rays(s)
    d = _unit(d)
    rel = o - an[1]
    ax = None if an[0] == "sphere" else an[2]
    r = an[2] if ax is None else an[3]
    oc, dd = (rel, d) if ax is None else (rel - (rel @ ax)[:, None] * ax, d - (d @ ax)[:, None] * ax)
    qa, qb, qc = (dd * dd).sum(1), (oc * dd).sum(1), (oc * oc).sum(1) - r * r
    disc = qb * qb - qa * qc
    t = (-qb - np.sqrt(np.maximum(disc, 0.0))) / np.maximum(qa, 1e-300)
    hit = (disc > 0) & (qa > 1e-300) & (qc > 0) & (t > 0)
    p = o + t[:, None] * d
    rad = p - an[1] if ax is None else p - an[1] - ((p - an[1]) @ ax)[:, None] * ax
    if ax is not None:
        hit &= np.abs((p - an[1]) @ ax) <= an[4]
    return p, _unit(rad), d, hit


def _curved_roots(spot, s, mpe_w_m2, mu, states, gain):
    """Per beam coordinate s (K, 2): the point P where its ray meets the curved side, the
    reflected direction u there, and the distance D [m] from P along u at which the
    observers' irradiance (:func:`_curved_source`, reflectance, attenuation, gain) falls
    to the MPE (0: not lit or below the MPE at P)."""
    p, n, d, hit = _curved_hit(spot, s)
    ok = hit & _lit(spot, s)
    e_inc, vt, vs = _curved_source(spot, p, n, d, ok)
    rho = _max_over_states(_reflectance(spot, _local(n, spot.target.tangent, -d), states))
    e0 = np.where(ok, rho * e_inc * np.exp(-mu * np.linalg.norm(p - spot.beam.position_m, axis=1)) * gain, 0.0)
    u = _unit(d - 2 * (d * n).sum(1)[:, None] * n)
    return _level_roots(e0, vt, vs, mu, mpe_w_m2), p, u


CURVED_GRID = 49  # beam coordinates per side of the grid searched over a curved side's lit part
CURVED_STARTS = 3  # best grid points refined by Nelder-Mead


def _curved_nohd(spot, mpe_w_m2, mu, states, gain):
    """The curved side's NOHD [m], from the point P along the direction u (or None):
    the largest root of :func:`_curved_roots` over the lit part, searched on a grid of
    beam coordinates (the samples' bounding box widened by a tenth, the samples and the
    axis) and refined by Nelder-Mead from the best ``CURVED_STARTS``; then solved on the
    observers' own function :func:`specular_irradiance` along u (:func:`_observer_root`)."""
    from scipy.optimize import minimize

    s_pts = spot.beam.to_s(spot.points)[0]
    s_pts = s_pts[np.all(np.isfinite(s_pts), axis=1)]
    if not len(s_pts):
        return 0.0, None, None
    lo, hi = s_pts.min(axis=0), s_pts.max(axis=0)
    pad = 0.1 * (hi - lo) + 0.05
    g = [np.linspace(a - b, c + b, CURVED_GRID) for a, b, c in zip(lo, pad, hi)]
    cand = np.vstack([np.stack(np.meshgrid(*g), axis=-1).reshape(-1, 2), s_pts, [[0.0, 0.0]]])
    roots, _, _ = _curved_roots(spot, cand, mpe_w_m2, mu, states, gain)
    if not np.any(roots > 0):
        return 0.0, None, None
    if np.isinf(roots).any():
        i = int(np.argmax(roots))
        _, p, u = _curved_roots(spot, cand[i:i + 1], mpe_w_m2, mu, states, gain)
        return math.inf, p[0], u[0]
    best_s, best = cand[int(np.argmax(roots))], float(roots.max())
    for i in np.argsort(-roots)[:CURVED_STARTS]:
        res = minimize(lambda x, scale=best: -_curved_roots(spot, x[None, :], mpe_w_m2, mu, states, gain)[0][0] / scale, cand[i],
                       method="Nelder-Mead", options={"xatol": 1e-6, "fatol": 1e-11, "maxiter": 400})
        if -res.fun * best > best:
            best_s, best = res.x, -float(res.fun) * best
    root, p, u = _curved_roots(spot, best_s[None, :], mpe_w_m2, mu, states, gain)
    return _observer_root(spot, p[0], u[0], float(root[0]), mpe_w_m2, mu, states, gain), p[0], u[0]


def _observer_root(spot, p, u, guess_m, mpe_w_m2, mu, states, gain) -> float:
    """The farthest distance D [m] along ``p + D u`` at which :func:`specular_irradiance`
    (the observers' function, largest over ``states``) still reaches the MPE: scanned
    on 65 log-spaced distances over [guess / 2, 2 guess] (widened while the far end is
    still above), then bisected to 1e-12 relative. Never below ``guess_m`` (the closed
    form of the same pieces: a disagreement keeps the longer)."""
    def above(dist):
        e = specular_irradiance(spot, p + np.atleast_1d(dist)[:, None] * u, gain, mu, states)
        return (e if e.ndim == 1 else e.max(axis=1)) >= mpe_w_m2

    lo_m, hi_m = guess_m / 2, guess_m * 2
    while above(hi_m)[0] and hi_m < 1e9:
        hi_m *= 4
    grid = np.geomspace(lo_m, hi_m, 65)
    ok = np.flatnonzero(above(grid))
    if not len(ok) or ok[-1] == len(grid) - 1:
        return guess_m if not len(ok) else max(guess_m, hi_m)
    a, b = grid[ok[-1]], grid[ok[-1] + 1]
    while b / a - 1 > 1e-12:
        mid = math.sqrt(a * b)
        a, b = (mid, b) if above(mid)[0] else (a, mid)
    return max(a, guess_m)


def specular_nohd(spot, mpe_w_m2, attenuation_per_m, states=None, gain=1.0) -> SpecularNohd:
    """The mirror beam's NOHD: the largest distance beyond the mirror [m] at which the
    observers' irradiance still reaches ``mpe_w_m2``, over the flat facets' samples
    (:func:`_flat_sample_roots`: each sample's peak and wavefront radius at its nearest
    range, bounded by the lobe's whole power over the limiting aperture) and a sphere's
    or cylinder's curved side (:func:`_curved_nohd`: the same Coddington spreading and
    power bound as at the observers, solved along the worst reflected ray), and its
    direction (unit). ``rho``: the highest reflectance over ``states``; ``gain`` the eye's
    optical gain; ``inf`` where the beam stays above the MPE past 1e9 m. A curved mesh is
    also followed through its focus or caustic (:func:`_curved_mesh_nohd`), the larger taken."""
    flat = _samples_nohd(spot, mpe_w_m2, attenuation_per_m, states, gain)
    if flat.nohd_m is None or not is_curved_mesh(spot.target):
        return flat
    return _curved_mesh_nohd(spot, mpe_w_m2, attenuation_per_m, states, gain, flat)


def _samples_nohd(spot, mpe_w_m2, attenuation_per_m, states=None, gain=1.0) -> SpecularNohd:
    """The NOHD of the spot's samples and analytic curved side (:func:`specular_nohd`)."""
    if not spot.material.has_specular:
        return SpecularNohd(None, None)
    mu = attenuation_per_m
    roots, e0, steps = _flat_sample_roots(spot, mpe_w_m2, mu, states, gain)
    i = int(np.argmax(roots))
    n_s = len(spot.power_w)  # the whole-target bound, if last, points along the hottest sample's mirror direction
    j = i if (roots[i] > 0 and i < n_s) else int(np.argmax(e0[:n_s]))
    nohd, direction = float(roots[i]), _unit(mirror_directions(spot)[j])
    if spot.target.mesh.analytic is not None:
        curved, _, u = _curved_nohd(spot, mpe_w_m2, mu, states, gain)
        if curved > nohd:
            nohd, direction, steps = curved, u, MirrorBeamSteps("curved side")
    return SpecularNohd(nohd, np.asarray(direction, float).tolist(), steps)


def _edge_reflectance(spot, rho, states):
    """Reflectance of each sample for its NOHD: a sample of a faceted target (box, plate,
    disk, mesh) whose normal is none of its lit facets' straddles an edge (its mean normal
    blends two faces: at grazing incidence a far lower Fresnel reflectance than either
    face's), so it takes the largest over those facets as well (conservative)."""
    if spot.target.mesh.analytic is not None or spot.outline_s is not None:
        return rho
    planes = lit_planes(spot)
    if not planes:
        return rho
    normals = np.array([p[0] for p in planes])
    blended = np.max(spot.frames[:, 2] @ normals.T, axis=1) < 1 - 1e-9
    if not np.any(blended):
        return rho
    d = spot.incoming[blended]
    faces = [_reflectance(spot, _local(n, spot.target.tangent, -d), states) for n in normals]
    out = rho.copy()
    out[blended] = np.maximum(rho[blended], np.max(faces, axis=0))
    return out


def _facet_reflectance_max(spot, rho, states) -> float:
    """The highest reflectance of a faceted spot: over its samples (``rho``) and its lit
    facets at the mean incidence (largest over ``states``)."""
    best = float(np.max(rho)) if len(rho) else 0.0
    for n, _, _ in lit_planes(spot):
        r = _reflectance(spot, _local(n, spot.target.tangent, -spot.mean_incoming[None, :]), states)
        best = max(best, float(np.max(r)))
    return best


def _aperture_power(spot, states=None) -> float:
    """The mirror lobe's whole power (largest over ``states``) over the limiting
    aperture's area [W/m^2]: no mirror beam can average more over the aperture."""
    return float(np.max(reflected_power_w(spot, states))) / (math.pi * (spot.aperture_m / 2) ** 2)


def _curved_mesh_nohd(spot, mpe_w_m2, mu, states, gain, flat: SpecularNohd) -> SpecularNohd:
    """The curved facets' ray-tube NOHD (:func:`hazard.physics.mesh_mirror.tube_nohd`: through a
    focus, bounded by the aperture); where the lit part also has flat facets, the larger
    of it and the samples' NOHD (which takes every sample as flat: conservative)."""
    rays = _cached_rays(spot, mu)
    if rays is None:
        return flat
    rho = _reflectance(spot, _local(rays.normals, spot.target.tangent, -rays.incoming), states)
    rho = rho if states is None else rho.max(axis=1)
    dist, direction = tube_nohd(rays, rho, mpe_w_m2, mu, getattr(spot, "aperture_m", 7e-3), gain)
    if lit_planes(spot) and flat.nohd_m >= dist:  # flat facets lit too
        return flat
    return SpecularNohd(dist, flat.direction if direction is None else _unit(direction).tolist(), MirrorBeamSteps("curved facets"))


def mirror_directions(spot):
    """Reflected directions (N, 3) of a spot's samples: ``d - 2 (d . n) n`` on each
    sample's normal (unit when ``d`` and ``n`` are)."""
    n, d = spot.frames[:, 2], spot.incoming
    return d - 2 * (d * n).sum(1)[:, None] * n
