"""The hazard zone of each mirror beam in plan (issue 29 item 4 / issue 34): its width.

A mirror (a target with a specular lobe) sends a reflected beam; the set of points where
that beam reaches the MPE is a long thin "cigar" about the beam's axis out to the
specular NOHD. For a Gaussian beam of 1/e radius w(z) and on-axis irradiance E0(z)
(E = E0 exp(-r^2 / w^2)) its half-width at range z is ``w(z) sqrt(ln(E0(z) / MPE))``.

Here the half-width is not taken from a formula but solved on the observers' own function
(:func:`hazard.physics.specular.specular_irradiance`, point irradiance times the eye's gain, the
largest over the target's states along its history, the same pieces the specular NOHD
uses): scanned across the beam and its edges bisected (:func:`edges_m`) at ``SAMPLES`` ranges along the reflected beam's axis (a spot on one flat plane:
the laser's axis reflected there, :func:`beam_axis`; else the axis of the drawn mirror
line, :func:`hazard.pictures.plan_view.mirror_segments`: from the spot's centroid along the
reported direction), to the NOHD or where the analysis stops the beam
(``sdz.mirror_beams[].max_reach_m``): the cross-section's horizontal extent over all its
heights (:func:`section_extent_m`). Then, to be conservative:

- the limiting aperture's radius (the eye's 7 mm / 2, through an aid its collecting
  radius) is added: an average over a disk never exceeds the point irradiance at the
  disk's point nearest the axis where the profile falls off the axis, so an eye whose
  aperture reaches the MPE lies within the point half-width plus the radius;
- each sample's half-width is raised to hold the profile between samples: the larger of
  an interval's ends and, where the profile is concave, the crossing of its neighbouring
  chords extended into it (:func:`_bulge`).

The plan outline is the cross-sections' horizontal extent joined along the axis (the
section's vertical extent projects onto the axis's own plan direction: the two end
sections pushed out by their half-width times the axis's vertical component); a beam within
1e-3 rad of the vertical is drawn as a disk of its largest half-width. A range short of
the reach where the scan finds no hazardous point (a sliver narrower than the scan's
step) is counted (``ranges_not_found``), never silently dropped.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from hazard.physics.aperture import PUPIL_RADIUS_M, limiting_aperture_m  # 7 mm: beam_zone's default; mirror_zones uses the scene's aperture
from hazard.physics.engine import mirror_axis, path_states
from hazard.physics.nohd import optical_gain
from hazard.physics.specular import is_curved_mesh, lit_planes, specular_irradiance

__all__ = ["MirrorZone", "mirror_zones", "mirror_stops_m", "edges_m", "section_extent_m", "beam_axis", "beam_zone", "eye_rows", "side_view_ring", "SAMPLES"]

SAMPLES = 97  # ranges along the beam at which the half-width is solved


@dataclass
class MirrorZone:
    """One mirror beam's plan zone, scene-local x, y [m] (add the scene offset for world)."""

    target: str
    eye: str  # "naked eye" or the aid, "7x50 optics"
    ring: np.ndarray  # (K, 2) the outline
    nohd_m: float | None  # the specular NOHD for this eye
    reach_m: float  # how far it is drawn from the mirror (the NOHD, or where the analysis stops the beam)
    max_half_width_m: float  # the widest half-width, aperture radius included
    aperture_radius_m: float  # the radius added for the aperture average
    ranges_not_found: int  # ranges short of the reach where no hazardous point was found (module notes)
    exact_axis: bool = True  # the laser's axis reflected on the flat mirror (False: the drawn line's axis, see the module notes)
    # the cross-sections in 3-D, scene-local: centre_m (K, 3) on the axis, the unit vectors across (horizontal) and up
    # (perpendicular to the axis), and the half-extents left/right along across, above/below along up [m] (aperture included)
    sections: dict | None = None


def side_view_ring(zone: MirrorZone, to_2d) -> np.ndarray | None:
    """(K, 2) outline of the zone seen from the side: every cross-section taken as the
    rectangle of its extents across and up (which holds it), the eight corners of each two
    neighbouring sections projected by ``to_2d`` ((N, 3) scene-local points -> (N, 2)) and
    the union of their convex hulls taken (so the outline holds the projected zone);
    None without sections."""
    from shapely.geometry import MultiPoint, Polygon
    from shapely.ops import unary_union

    s = zone.sections
    if not s:
        return None
    a = np.stack([s["left_m"], -s["right_m"], -s["right_m"], s["left_m"]], axis=1)  # (K, 4) along across
    b = np.stack([s["above_m"], s["above_m"], -s["below_m"], -s["below_m"]], axis=1)  # (K, 4) along up
    corners = s["centre_m"][:, None, :] + a[..., None] * s["across"] + b[..., None] * s["up"]  # (K, 4, 3)
    flat = np.asarray(to_2d(corners.reshape(-1, 3)), float).reshape(len(corners), 4, 2)
    hulls = [MultiPoint(np.vstack([flat[i], flat[i + 1]]).tolist()).convex_hull for i in range(len(flat) - 1)]
    shape = unary_union([h for h in hulls if isinstance(h, Polygon)])
    if shape.is_empty:
        return None
    shape = shape if shape.geom_type == "Polygon" else shape.convex_hull
    return np.asarray(shape.exterior.coords, float)



def mirror_stops_m(result) -> dict:
    """Per target, where the analysis stops its mirror beam's farthest ray [m] (report.json
    ``sdz.mirror_beams[].max_reach_m``; None or inf where nothing stops it)."""
    return {m.target: m.max_reach_m for m in _mirror_beams(result)}


def _mirror_beams(result) -> tuple:
    """The result's mirror beams (:class:`hazard.pipeline.sdz.MirrorBeam`; none without a danger zone or that stage)."""
    z = getattr(result, "sdz", None)
    return () if z is None else z.mirror_beams or ()

def _irradiance(spot, pts, gain, mu, states) -> np.ndarray:

    e = specular_irradiance(spot, pts, gain, mu, states)
    return e if e.ndim == 1 else e.max(axis=1)


TOL = 1e-7  # the edges' relative tolerance (the hazardous side kept)
SCAN = 201  # offsets across the beam scanned at each range before the edges are bisected


def _hot(spot, pts, mpe_w_m2, gain, mu, states) -> np.ndarray:
    return _irradiance(spot, pts, gain, mu, states) >= mpe_w_m2


def _bisect_edge(spot, centre, across, inside, outside, mpe_w_m2, gain, mu, states) -> np.ndarray:
    """Offsets (K,) between ``inside`` (at or above the MPE) and ``outside`` (below),
    bisected to ``TOL`` of the offset: the one at or above the MPE returned."""
    a, b = inside.copy(), outside.copy()
    k = np.flatnonzero(np.abs(b - a) > TOL * np.maximum(np.abs(a), np.abs(b)))
    while len(k):
        mid = 0.5 * (a[k] + b[k])
        up = _hot(spot, centre[k] + mid[:, None] * across, mpe_w_m2, gain, mu, states)
        a[k] = np.where(up, mid, a[k])
        b[k] = np.where(up, b[k], mid)
        k = k[np.abs(b[k] - a[k]) > TOL * np.maximum(np.abs(a[k]), np.abs(b[k]))]
    return a


def _scan(spot, centre, across, scale_m, mpe_w_m2, mu, states, gain):
    """Brackets of the outermost hazardous points on the lines ``centre`` (K, 3) +
    t ``across``: (lo inside, lo outside, hi inside, hi outside, found) [m]; see
    :func:`edges_m`."""
    k = len(centre)
    h = 4.0 * np.maximum(np.asarray(scale_m, float), 1e-6) * np.ones(k)
    t = np.linspace(-1.0, 1.0, SCAN)
    for _ in range(60):
        off = h[:, None] * t[None, :]
        pts = centre[:, None, :] + off[..., None] * across
        hot = _hot(spot, pts.reshape(-1, 3), mpe_w_m2, gain, mu, states).reshape(k, SCAN)
        wide = hot[:, 0] | hot[:, -1]
        if not wide.any():
            break
        h = np.where(wide, 2 * h, h)
    found = hot.any(axis=1)
    i_lo = np.where(found, np.argmax(hot, axis=1), 1)
    i_hi = np.where(found, SCAN - 1 - np.argmax(hot[:, ::-1], axis=1), SCAN - 2)
    r = np.arange(k)
    return off[r, i_lo], off[r, np.maximum(i_lo - 1, 0)], off[r, i_hi], off[r, np.minimum(i_hi + 1, SCAN - 1)], found


def edges_m(spot, centre_m, across, scale_m, mpe_w_m2, mu, states=None, gain=1.0):
    """Signed offsets (lo, hi) [m] along the unit ``across`` from the points ``centre_m``
    (K, 3) of the outermost points on those lines where the observers' irradiance
    (:func:`hazard.physics.specular.specular_irradiance` times ``gain``, the largest over
    ``states``) reaches ``mpe_w_m2``, and a mask of the lines where any did: ``SCAN``
    offsets over +-H scanned (H from 4 ``scale_m``, doubled while the scan's ends are
    still hazardous), then the outer edges bisected to ``TOL`` relative. A hazardous sliver
    narrower than H / 100 between two scanned offsets is missed (said in the report)."""
    centre = np.asarray(centre_m, float)
    k = len(centre)
    in_lo, out_lo, in_hi, out_hi, found = _scan(spot, centre, np.asarray(across, float), scale_m, mpe_w_m2, mu, states, gain)
    both = _bisect_edge(spot, np.vstack([centre, centre]), across, np.concatenate([in_lo, in_hi]),
                        np.concatenate([out_lo, out_hi]), mpe_w_m2, gain, mu, states)  # both edges in one pass
    return np.where(found, both[:k], 0.0), np.where(found, both[k:], 0.0), found


LEVELS = 7  # heights across the section (over its vertical extent) at which its horizontal extent is solved


def section_extent_m(spot, centre_m, across, up, scale_m, mpe_w_m2, mu, states=None, gain=1.0):
    """(lo, hi, found): the horizontal extent [m] along ``across`` of the hazardous
    cross-section at each of ``centre_m`` (K, 3), over all heights: scanned through the
    centre; then along ``up`` through that extent's middle (the section's vertical
    extent, at the scan's resolution); then at ``LEVELS`` heights spread over it (a beam
    whose hot part sits above or below the axis, or is cut by the mirror's outline, is
    widest off the axis's own line); every level's edges bisected (:func:`edges_m`) in
    one pass and the union taken."""
    centre = np.asarray(centre_m, float)
    across, up = np.asarray(across, float), np.asarray(up, float)
    k = len(centre)
    first = _scan(spot, centre, across, scale_m, mpe_w_m2, mu, states, gain)
    mid = np.where(first[4], 0.5 * (first[0] + first[2]), 0.0)
    vlo, _, vhi, _, vfound = _scan(spot, centre + mid[:, None] * across, up, scale_m, mpe_w_m2, mu, states, gain)
    lines, scans = [centre], [first]
    for f in np.linspace(0.0, 1.0, LEVELS):
        c = centre + np.where(vfound, vlo + f * (vhi - vlo), 0.0)[:, None] * up
        lines.append(c)
        scans.append(_scan(spot, c, across, scale_m, mpe_w_m2, mu, states, gain))
    c_all = np.vstack(lines + lines)
    inside = np.concatenate([s_[0] for s_ in scans] + [s_[2] for s_ in scans])
    outside = np.concatenate([s_[1] for s_ in scans] + [s_[3] for s_ in scans])
    edge = _bisect_edge(spot, c_all, across, inside, outside, mpe_w_m2, gain, mu, states)
    n = len(scans)
    ok = np.array([s_[4] for s_ in scans])  # (n, K)
    lo = np.where(ok, edge[:n * k].reshape(n, k), np.inf).min(axis=0)
    hi = np.where(ok, edge[n * k:].reshape(n, k), -np.inf).max(axis=0)
    found = ok.any(axis=0)
    return np.where(found, lo, 0.0), np.where(found, hi, 0.0), found


def _outline(origin_m, axis, z, left, right) -> np.ndarray:
    """(K, 2) plan ring of the cross-sections' horizontal extents (``left``, ``right``
    half-widths at ranges ``z``), or a disk for a near-vertical beam."""
    u = np.asarray(axis, float)
    horiz = float(np.hypot(u[0], u[1]))
    c = np.asarray(origin_m, float)[:2]
    if horiz < 1e-3:
        r = float(max(left.max(initial=0.0), right.max(initial=0.0)) + horiz * z[-1])
        t = np.linspace(0, 2 * math.pi, 73)[:-1]
        return c + max(r, 1e-9) * np.stack([np.cos(t), np.sin(t)], axis=1)
    n = np.array([-u[1], u[0]]) / horiz
    along = c + z[:, None] * u[:2]
    tilt = abs(float(u[2]))  # a section of radius h spans h |u_z| along the axis in plan: the ends pushed out by it
    along[0] -= u[:2] / horiz * tilt * max(left[0], right[0])
    along[-1] += u[:2] / horiz * tilt * max(left[-1], right[-1])
    return np.vstack([along + left[:, None] * n, (along - right[:, None] * n)[::-1]])


def _bulge(z, h) -> np.ndarray:
    """Half-widths (K,) at the samples ``z`` such that the polygon joining them holds the
    profile between samples: on each interval the larger of its ends and, where the
    profile is concave, the bound of the neighbouring chords extended into it (a concave
    function lies below a chord's extension outside the chord), at their crossing; each
    sample takes the larger bound of its two intervals (module notes)."""
    z, h = np.asarray(z, float), np.asarray(h, float)
    k = len(h)
    ends = np.maximum(h[:-1], h[1:])
    if k < 4:
        bound = ends
    else:
        slope = np.diff(h) / np.maximum(np.diff(z), 1e-300)
        s1 = np.concatenate([[np.inf], slope[:-1]])  # the chord before interval i, extended right
        s2 = np.concatenate([slope[1:], [-np.inf]])  # the chord after it, extended left
        x0, x1 = z[:-1], z[1:]
        with np.errstate(invalid="ignore", divide="ignore"):
            cross = (h[1:] - h[:-1] + s1 * x0 - s2 * x1) / (s1 - s2)  # where h0 + s1 (x - x0) = h1 + s2 (x - x1)
        cross = np.clip(np.where(np.isfinite(cross), cross, x0), x0, x1)
        line1 = np.where(np.isfinite(s1), h[:-1] + np.where(np.isfinite(s1), s1, 0.0) * (cross - x0), np.inf)
        line2 = np.where(np.isfinite(s2), h[1:] + np.where(np.isfinite(s2), s2, 0.0) * (cross - x1), np.inf)
        peak = np.minimum(line1, line2)
        bound = np.maximum(ends, np.where(np.isfinite(peak), peak, ends))
    out = h.copy()
    out[:-1] = np.maximum(out[:-1], bound)
    out[1:] = np.maximum(out[1:], bound)
    return out


def _scale_m(spot, origin_m, z) -> np.ndarray:
    """The incident beam's 1/e radius [m] after the unfolded path (laser to ``origin_m``,
    then ``z``): the scan's scale."""
    beam = spot.beam
    if beam is None:
        return np.full(len(z), 1.0)
    path = float(np.linalg.norm(np.asarray(origin_m, float) - beam.position_m)) + z
    return 0.5 * np.asarray(beam.diameter_at(path), float) * np.ones(len(z))


def beam_zone(spot, origin_m, axis, reach_m, mpe_w_m2, mu, states=None, gain=1.0, aperture_radius_m=PUPIL_RADIUS_M):
    """(ring (K, 2), largest half-width [m], ranges short of the reach with no hazardous
    point found) of one mirror beam from ``origin_m`` along ``axis`` to ``reach_m``
    (module notes)."""
    u = np.asarray(axis, float) / np.linalg.norm(axis)
    horiz = float(np.hypot(u[0], u[1]))
    side = np.cross(u, [1.0, 0.0, 0.0])
    n3 = np.array([-u[1], u[0], 0.0]) / horiz if horiz >= 1e-3 else side / np.linalg.norm(side)
    z = np.linspace(0.0, float(reach_m), SAMPLES)
    z[0] = min(1e-6 * max(float(reach_m), 1e-3), 1e-3)  # just off the mirror's surface
    up = np.cross(n3, u)
    centre = np.asarray(origin_m, float) + z[:, None] * u
    scale = _scale_m(spot, origin_m, z)
    lo, hi, found = section_extent_m(spot, centre, n3, up, scale, mpe_w_m2, mu, states, gain)
    short = int(np.sum(~found & (z < 0.999 * reach_m)))
    left = _bulge(z, np.maximum(hi, 0.0)) + aperture_radius_m
    right = _bulge(z, np.maximum(-lo, 0.0)) + aperture_radius_m
    vlo, vhi, _ = section_extent_m(spot, centre, up, n3, scale, mpe_w_m2, mu, states, gain)  # along up, over all offsets across
    z[0] = 0.0
    sections = {"centre_m": np.asarray(origin_m, float) + z[:, None] * u, "across": n3, "up": up, "left_m": left, "right_m": right,
                "above_m": _bulge(z, np.maximum(vhi, 0.0)) + aperture_radius_m, "below_m": _bulge(z, np.maximum(-vlo, 0.0)) + aperture_radius_m}
    return _outline(origin_m, u, z, left, right), float(max(left.max(), right.max())), short, sections


def beam_axis(spot, origin_m, axis) -> tuple[np.ndarray, np.ndarray, bool]:
    """(origin (3,), unit direction (3,), exact) of the reflected beam's axis: for a spot
    on one flat plane (no curved side) the laser's axis reflected there (the unfolded
    Gaussian's own axis: where the laser axis meets the plane, along ``d - 2 (d . n) n``);
    else ``origin_m`` along ``axis`` as given (the drawn mirror line), ``exact`` False."""

    u = np.asarray(axis, float) / np.linalg.norm(axis)
    t = spot.target
    planes = lit_planes(spot) if spot.beam is not None else []
    if len(planes) != 1 or t.mesh.analytic is not None or is_curved_mesh(t):
        return np.asarray(origin_m, float), u, False
    n, q, _ = planes[0]
    p, d = np.asarray(spot.beam.position_m, float), np.asarray(spot.beam.axis, float)
    dn = float(d @ n)
    if abs(dn) < 1e-12:
        return np.asarray(origin_m, float), u, False
    hit = p + d * float((np.asarray(q, float) - p) @ n) / dn
    r = d - 2 * dn * n
    return hit, r / np.linalg.norm(r), True


def eye_rows(result, row) -> list:
    """(label, gain, aperture radius [m], NOHD [m], stop [m] or None) per eye of target row
    ``row``'s mirror beam: the naked eye, then each aid."""
    spec = result.scene.spec
    pupil_m = 0.5 * limiting_aperture_m(spec.laser.wavelength_nm, spec.exposure.duration_s)  # the standard's aperture (7 mm at 400-1400 nm)
    stops = mirror_stops_m(result)
    entry = {m.target: m for m in _mirror_beams(result)}.get(row.name)
    out = [("naked eye", 1.0, pupil_m, row.specular_nohd_dynamic_m, stops.get(row.name))]
    for a in row.aided or []:
        nohd = a.get("specular_nohd_dynamic_m")
        if not nohd:
            continue
        m, d = float(a["magnification"]), float(a["objective_diameter_m"])
        stop = entry.aided.max_reach_m if entry is not None and entry.aided is not None else stops.get(row.name)
        out.append((f"{m:g}x{1e3 * d:g} optics", optical_gain(m, d, a.get("transmission", 1.0)),
                    0.5 * min(d, 2 * PUPIL_RADIUS_M * m), nohd, stop))  # an aid delivers into the 7 mm pupil (hazard.physics.aperture)
    return out


def mirror_zones(result) -> list:
    """:class:`MirrorZone` of every lit mirror, naked eye and through each aid with a
    specular NOHD (one only an aid reaches included), from the spot's centroid along the
    reported direction (:func:`hazard.pictures.plan_view.mirror_segments`' axis) or, on one flat
    plane, the laser's reflected axis (:func:`beam_axis`); module notes."""

    cached = result.__dict__.get("_mirror_zones") if hasattr(result, "__dict__") else None
    if cached is not None:  # the plan view and the zones file ask for the same run's zones
        return cached
    rows = {t.name: t for t in result.targets}
    mpe = float(result.mpe_w_m2)  # the exposure MPE the specular NOHDs use
    out = []
    for sp in result.spots:
        row = rows.get(sp.target.name)
        if row is None or not sp.material.has_specular:
            continue
        t = sp.target
        states = path_states(t.material, result.states[t.index]) if t.index in result.states else None
        axis = np.asarray(row.specular_direction, float) if row.specular_direction is not None else mirror_axis(sp)
        start, axis, exact = beam_axis(sp, sp.centroid, axis)
        for eye, gain, radius, nohd, stop in eye_rows(result, row):
            if not nohd:
                continue
            reach = float(nohd) if math.isfinite(nohd) else 1e5
            if stop is not None and math.isfinite(stop) and 0.0 <= stop < reach:
                reach = float(stop)
            ring, widest, short, sections = beam_zone(sp, start, axis, reach, mpe, result.attenuation_per_m, states, gain, radius)
            out.append(MirrorZone(t.name, eye, ring, nohd, reach, widest, radius, short, exact, sections))
    if hasattr(result, "__dict__"):
        result.__dict__["_mirror_zones"] = out
    return out
