"""Reflected irradiance at observers: spots from the beam's cells, BRDF and specular reflection.

Physics (spec `dynamic-sh-brdf.md` section 3, `laser-safety.md` section 3.1,
`range-safety.md` sections 1 and 4):

* The beam's cross-section is sampled by :mod:`hazard.physics.beam`: cells with exact Gaussian
  powers, refined where objects' edges cross them; flat targets get the exact integral
  over their projected outline. A spot is the set of cells that land on one target,
  grouped into samples (cells of the coarsest level), each with its power after the
  laser -> target attenuation ``exp(-mu R1)`` (once), hit point, normal and the highest
  incident irradiance it holds.
* A sample of power P on a surface reflects to an observer at distance R as
  ``E = f_r(wi, wo, state) cos(theta_r) P exp(-mu R) K / R^2``, computed through
  ``f_r cos(theta_r)`` so grazing observers give no 0/0. Observers at least 20 spot sizes
  away see the spot as one point source (power-weighted centroid, mean direction and
  normal); nearer ones get the integral over the spot's irradiance
  (:mod:`hazard.physics.near_field`: each sample a point source only where that is proven to
  1 %, its triangles integrated elsewhere).
* An ideal-mirror (delta) lobe is traced by geometric optics from what really hits the
  mirror (:mod:`hazard.physics.specular`): the unfolded beam through the lit part of a flat
  mirror, the Coddington spread of a convex sphere or cylinder.
* A target lit on its back face reflects with its ``back`` material, or not at all (the
  analysis says so).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from brdfmodels import DynamicBRDF, Lambertian, Scaled, StateTable, Sum

from hazard.physics.beam import HALF_WIDTH, OutlineCells, outline_cells
from hazard.physics.near_field import leaf_corners_s, near_field_irradiance, patches_from_leaves, patches_from_pieces, perspective_weights
from hazard.physics.rays import own_object

__all__ = ["Spot", "build_spots", "projected_brdf", "spot_irradiance", "specular_irradiance", "FAR_FIELD_SPOT_SIZES",
           "spot_line_of_sight"]

FAR_FIELD_SPOT_SIZES = 20.0  # witness-screen rule: >= 20 spot sizes for ~1 % point-source error


@dataclass
class Spot:
    """The beam's samples on one target, with per-sample material frames (rows x, y, z).

    ``power_w`` is after the laser -> target attenuation; ``peak_irradiance_w_m2`` per
    sample is the highest incident irradiance (normal to the beam, attenuated) in its
    cells; ``source_distance_m`` the incident wavefront radius (inf when collimated) at
    the sample's nearest range to the laser, where ``peak_irradiance_w_m2`` bounds the
    beam (the two make one bound: a mirror beam from the sample never exceeds the whole
    beam's irradiance at the unfolded range, however long a grazing sample is);
    ``aperture_m`` the limiting aperture over which a mirror beam's power is averaged
    (:func:`hazard.physics.specular.specular_irradiance`; default the smallest of any band).
    """

    target: object
    points: np.ndarray
    power_w: np.ndarray
    incoming: np.ndarray  # propagation direction (towards the surface), unit
    frames: np.ndarray  # (n, 3, 3) material frames (z: the normal of the lit side)
    range_from_laser_m: np.ndarray
    peak_irradiance_w_m2: np.ndarray | None = None
    source_distance_m: np.ndarray | None = None
    material: object = None  # the lit side's material (default: the target's)
    side: str = "front"
    power_error_w: float = 0.0  # bound on the error of total_power_w (already added: conservative)
    exact: bool = False  # total power from the exact outline integral
    lit_area_m2: float = 0.0  # lit area normal to the beam
    cells: object = None  # hazard.physics.beam.CellSampling (shared by the spots of one beam)
    beam: object = None  # hazard.physics.beam.BeamGeometry
    ray_faces: tuple | None = None  # the target's triangles in the tracer: (ids, normals, a vertex each)
    outline_s: np.ndarray | None = None  # exact lit outline in beam coordinates (flat targets hit whole)
    spread_m2: np.ndarray | None = None  # per sample: power-weighted variance of the beam within it [m^2]
    slump: object = None  # hazard.physics.slump.SpotSlump: the molten surface's tilt per analysis time, if any
    aperture_m: float = 7e-3  # limiting aperture diameter [m] of the mirror beams (set by the beam stage: pipeline.spots.mirror_aperture_m)
    edge_peak_w_m2: float | None = None  # sampled faceted targets: incident bound over the whole target (see _edge_bound)
    edge_source_m: float = math.inf  # the wavefront radius where edge_peak_w_m2 holds [m]
    patches: object = None  # hazard.physics.near_field.SpotPatches: the spot's triangles for the near-field integral

    def __post_init__(self):
        if self.material is None:
            self.material = self.target.material

    @property
    def max_irradiance_w_m2(self) -> float:
        """The hottest point's incident irradiance [W/m^2] (what drives heating)."""
        return float(np.max(self.peak_irradiance_w_m2)) if self.peak_irradiance_w_m2 is not None else 0.0

    @property
    def mean_irradiance_w_m2(self) -> float:
        """Spot power over its lit area normal to the beam [W/m^2]."""
        return self.total_power_w / self.lit_area_m2 if self.lit_area_m2 > 0 else 0.0

    @property
    def total_power_w(self) -> float:
        return float(self.power_w.sum())

    @property
    def _weights(self) -> np.ndarray:
        """Per sample weights for the spot's means: its power scaled to a largest of 1
        (a spot of 1e-300 W has means too), equal weights when every power is 0."""
        top = float(np.max(self.power_w)) if len(self.power_w) else 0.0
        return self.power_w / top if top > 0 else np.ones(len(self.power_w))

    @property
    def centroid(self) -> np.ndarray:
        w = self._weights
        return (self.points * w[:, None]).sum(0) / w.sum()

    @property
    def mean_incoming(self) -> np.ndarray:
        d = (self.incoming * self._weights[:, None]).sum(0)
        return d / np.linalg.norm(d)

    @property
    def mean_frame(self) -> np.ndarray:
        f = (self.frames * self._weights[:, None, None]).sum(0)
        z = f[2] / np.linalg.norm(f[2])
        x = f[0] - np.dot(f[0], z) * z
        x /= np.linalg.norm(x)
        return np.stack([x, np.cross(z, x), z])

    @property
    def sight_point_m(self) -> np.ndarray:
        """Where lines of sight from the spot start: the centroid lifted along the mean normal
        above every sample point and, on a solid or mesh target, above the target's vertices
        within the spot's size of it. On a flat spot it is the centroid; a convex spot's
        centroid lies behind its own surface, which would hide every observer from it."""
        cached = self.__dict__.get("_sight_point")
        if cached is not None:
            return cached
        n, c = self.mean_frame[2], self.centroid
        lift = float(np.max((self.points - c) @ n))
        if getattr(getattr(self.target, "spec", None), "shape", None) in ("box", "sphere", "cylinder", "mesh"):
            rel = self.target.mesh.vertices - c
            along = rel @ n
            near = np.linalg.norm(rel - along[:, None] * n, axis=1) <= max(self.size_m, 1e-9)
            if np.any(near):
                lift = max(lift, float(along[near].max()))
        out = c + max(0.0, lift) * n
        self.__dict__["_sight_point"] = out
        return out

    @property
    def size_m(self) -> float:
        """Spot size: twice the power-weighted RMS radius (the 1/e diameter for a Gaussian)."""
        r2 = ((self.points - self.centroid) ** 2).sum(1)
        if self.spread_m2 is not None:
            r2 = r2 + self.spread_m2
        return float(2 * math.sqrt(max((r2 * self.power_w).sum() / self.total_power_w, 0.0)))

    @property
    def extent_m(self) -> float:
        """Largest distance [m] from the centroid to any part of the spot: its triangles'
        vertices, or (built without them) its samples plus 3 RMS radii of their spread."""
        c = self.centroid
        if self.patches is not None and len(self.patches.tri_x):
            return float(np.sqrt(((self.patches.tri_x - c) ** 2).sum(-1)).max())
        sd = np.sqrt(self.spread_m2) if self.spread_m2 is not None else 0.0
        return float((np.linalg.norm(self.points - c, axis=1) + 3 * sd).max())

    @property
    def mean_range_m(self) -> float:
        return float((self.range_from_laser_m * self.power_w).sum() / self.total_power_w)


def _hit_normals(target, points, faces, ray_scene):
    mesh = target.mesh
    n = ray_scene.face_normals(faces)
    if mesh.analytic is not None:
        kind = mesh.analytic[0]
        if kind == "sphere":
            c, r = mesh.analytic[1], mesh.analytic[2]
            n = points - c
        elif kind == "cylinder":
            c, ax, r, half_h = mesh.analytic[1:]
            rel = points - c
            along = rel @ ax
            side = np.abs(along) < half_h * (1 - 1e-9)
            radial = rel - along[:, None] * ax
            n = np.where(side[:, None], radial, n)
        n = n / np.linalg.norm(n, axis=1, keepdims=True)
    return n


def _frames(target, normals):
    t = target.tangent
    x = t - (normals @ t)[:, None] * normals
    bad = np.linalg.norm(x, axis=1) < 1e-9
    if np.any(bad):  # tangent along the normal at this point: any perpendicular will do
        alt = np.cross(normals[bad], [0.0, 0.0, 1.0])
        alt[np.linalg.norm(alt, axis=1) < 1e-9] = np.cross(normals[bad][np.linalg.norm(alt, axis=1) < 1e-9], [1.0, 0.0, 0.0])
        x[bad] = alt
    x /= np.linalg.norm(x, axis=1, keepdims=True)
    y = np.cross(normals, x)
    g = target.groove_angle_rad
    xm = math.cos(g) * x + math.sin(g) * y
    ym = -math.sin(g) * x + math.cos(g) * y
    return np.stack([xm, ym, normals], axis=1)


# -- spots from the beam's cells ----------------------------------------------------------
@dataclass
class SpotBuild:
    """Spots of one beam and what else the beam did (powers after no attenuation)."""

    spots: list[Spot]
    spill_w: float
    blocked_w: float
    unreflected: list[tuple[str, str, float]]  # (target name, side, power [W]) lit but not reflected (back face without material)
    exact: list[str]  # target names whose power is the exact outline integral
    error_w: float  # bound on the power misassigned between objects (unresolved cells + truncation)
    negligible: list[tuple[str, int, float, float]] = field(default_factory=list)  # (target name, leaves, power [W], floor [W/m^2]) left out (:func:`_negligible_tail`)


def flat_outlines(beam, targets) -> dict:
    """Projected outlines of the flat targets wholly in front of the aperture:
    index -> (upper-bound polygon, lower-bound polygon) in beam coordinates."""
    from hazard.physics.beam import flat_outline_s

    out = {}
    for t in targets:
        if t.spec.shape in ("plate", "disk"):
            o = flat_outline_s(beam, t)
            if o is not None:
                out[t.index] = o
    return out


def _exact_power(beam, outline, upper_fraction):
    """Outline integral of the beam [W] (``upper_fraction``: the outer outline's power
    fraction) and its bound (disk: circumscribed - inscribed)."""
    from hazard.physics.beam import polygon_fraction

    upper = beam.power_w * upper_fraction
    if outline[1] is outline[0]:  # a plate: its outline is exact
        return upper, 0.0
    return upper, upper - beam.power_w * polygon_fraction(outline[1])


def _subtract_holes(oc, holes_oc, hole_polys):
    """Moments of each piece minus those of the holes' pieces in the same cell (power,
    area, first and second moments add over disjoint regions); the nearest point to the
    axis is searched outside the holes."""
    from hazard.physics.beam import PolygonMoments, r2_min_outside

    m = oc.moments
    frac, area = m.fraction.copy(), m.area.copy()
    first = m.mean * frac[:, None]
    second = (m.cov + m.mean[:, :, None] * m.mean[:, None, :]) * frac[:, None, None]
    where = {int(k): r for r, k in enumerate(oc.keys)}
    holes = [[] for _ in oc.pieces]
    for i, hoc in enumerate(holes_oc):
        hm = hoc.moments
        for r, k in enumerate(hoc.keys):
            q = where.get(int(k))
            if q is None:
                continue
            frac[q] -= hm.fraction[r]
            area[q] -= hm.area[r]
            first[q] -= hm.mean[r] * hm.fraction[r]
            second[q] -= (hm.cov[r] + np.outer(hm.mean[r], hm.mean[r])) * hm.fraction[r]
            holes[q].append((hoc.pieces[r], hole_polys[i]))
    frac = np.maximum(frac, 0.0)
    safe = np.where(frac > 1e-300, frac, 1.0)
    mean = np.where((frac > 1e-300)[:, None], first / safe[:, None], m.mean)
    cov = second / safe[:, None, None] - mean[:, :, None] * mean[:, None, :]
    cov = np.where((frac > 1e-300)[:, None, None], cov, m.cov)
    cov[:, 0, 0] = np.maximum(cov[:, 0, 0], 0.0)
    cov[:, 1, 1] = np.maximum(cov[:, 1, 1], 0.0)
    r2 = np.array([m.r2_min[q] if not holes[q] else r2_min_outside(oc.pieces[q], holes[q]) for q in range(len(frac))])
    return PolygonMoments(frac, mean, cov, r2, np.maximum(area, 0.0))


def _plane_hits(beam, target, s):
    """Where the rays through s (N, 2) meet a flat target's plane: points, unit directions,
    path lengths [m] and axial distances [m] (exact)."""
    o, d = beam.rays(np.asarray(s, float).reshape(-1, 2))
    n = target.normal
    t = ((target.center_m - o) @ n) / (d @ n)
    pts = o + t[:, None] * d
    norm = np.linalg.norm(d, axis=1)
    return pts, d / norm[:, None], t * norm, (pts - beam.position_m) @ beam.axis


@dataclass
class ExactSamples:
    """Samples of a flat target from its outline pieces (see :func:`_exact_samples`)."""

    points: np.ndarray  # hits of the rays through the pieces' centroids [m]
    directions: np.ndarray  # their unit directions
    path_m: np.ndarray  # laser -> hit path lengths [m]
    axial_m: np.ndarray  # axial distances of the hits [m]
    power_w: np.ndarray  # attenuated (shortest path in the piece: an upper bound)
    peak_irradiance_w_m2: np.ndarray  # upper bound of the incident irradiance over each piece
    cov_s: np.ndarray  # (n, 2, 2) covariance of s within each piece
    area_s: np.ndarray  # piece areas in s (units of w^2)
    error_w: float  # disk polygon bound + attenuation spread + nothing else
    total_w: float  # the unattenuated outline integral
    near_axial_m: np.ndarray | None = None  # smallest axial distance over each piece [m] (where its peak bound holds)
    pieces: np.ndarray | None = None  # (n,) object: each sample's outline piece in s (None: holes cut from it)
    fraction: np.ndarray | None = None  # the pieces' exact beam power fractions


def _hole_cells(outline, fronts, n0, half_width):
    """The parts of a flat target's outline hidden by exact targets in front of it, cut by
    the coarsest cells, and the power fraction by which the smallest hole (inscribed
    polygons) may fall short of the largest (circumscribed) one."""
    from hazard.physics.beam import clip_convex, polygon_fraction

    holes, polys, slack = [], [], 0.0
    for front in fronts:
        small = clip_convex(outline[1], front[1])
        if len(small):
            holes.append(outline_cells(small, n0, half_width))
            polys.append(small)
        if outline[0] is not outline[1] or front[0] is not front[1]:  # disks: the largest hole may be larger
            big = clip_convex(outline[0], front[0])
            slack += (polygon_fraction(big) if len(big) else 0.0) - (polygon_fraction(small) if len(small) else 0.0)
    return holes, polys, slack


def _exact_samples(beam, n0, target, outline, tracer, mu, fronts=()):
    """Samples of a flat target from its outline cut by the coarsest cells (exact powers,
    centroids, covariances and nearest-to-axis points), less the parts hidden by the flat
    targets ``fronts`` (index -> outline) in front of it; None when a ray through a
    piece's centroid meets anything else before the target's plane (the outline is then
    not what is lit; a hit beyond the plane is a float32 graze past the outline's edge, or
    a disk's circumscribed polygon reaching past the disk, and nothing is in front there:
    the rule of the sampler's piece rays, ``beam.before_plane``).
    Attenuation per piece uses its shortest path (an upper bound); the spread to the
    longest goes into the error bound. The power outside the beam square (<= 3.1e-8 P)
    is spread over the pieces."""
    from hazard.physics.beam import before_plane, hit_depths_m, polygon_moments

    oc = outline_cells(outline[0], n0, beam.half_width)
    if not oc.pieces:
        return None
    holes, hole_polys, slack = _hole_cells(outline, list(fronts.values()) if fronts else [], n0, beam.half_width)
    m = _subtract_holes(oc, holes, hole_polys) if holes else oc.moments
    lit = np.flatnonzero((m.fraction > 0) & np.isfinite(m.r2_min))
    if not len(lit):
        return None if not holes else ExactSamples(*(np.zeros((0,) + sh) for sh in ((3,), (3,), (), (), (), (), (2, 2), ())),
                                                   0.0, 0.0)
    oc = OutlineCells(oc.keys[lit], [oc.pieces[q] for q in lit], None)
    m = m.take(lit)
    o, dirs = beam.rays(m.mean)
    hits = tracer.first_hit(o, dirs)
    allowed = [target.index, -1] + list(fronts or {})
    before = before_plane(beam, target, m.mean, hit_depths_m(beam, tracer, hits))  # beyond the plane: a graze past its edge
    if np.any(~np.isin(hits.obj, allowed) & before):
        return None
    pts, unit, path, z = _plane_hits(beam, target, m.mean)
    verts = np.concatenate(oc.pieces)
    counts = [len(p) for p in oc.pieces]
    owner = np.repeat(np.arange(len(oc.pieces)), counts)
    _, _, vpath, vz = _plane_hits(beam, target, verts)
    lmin, lmax, zmin, smax2 = np.minimum(path, np.inf), path.copy(), z.copy(), np.zeros(len(pts))
    np.minimum.at(lmin, owner, vpath)
    np.maximum.at(lmax, owner, vpath)
    np.minimum.at(zmin, owner, vz)
    np.maximum.at(smax2, owner, (verts * verts).sum(1))
    whole = polygon_moments([outline[0]])
    total, disk_err = _exact_power(beam, outline, float(whole.fraction[0]))
    total -= beam.power_w * sum(float(h.moments.fraction.sum()) for h in holes)
    power = beam.power_w * m.fraction
    power *= total / max(power.sum(), 1e-300)
    up, down = np.exp(-mu * lmin), np.exp(-mu * lmax)
    w = beam.diameter_at(zmin) / 2
    r2 = m.r2_min.copy()
    whole_r2 = float(whole.r2_min[0]) if not holes else math.inf
    if whole_r2 < r2.min() * (1 - 1e-9) - 1e-12:  # the outline's nearest point lies outside the beam square
        near = int(np.argmin(r2))
        _, _, opath, oz = _plane_hits(beam, target, outline[0])
        r2[near] = whole_r2
        zmin[near], lmin[near] = min(zmin[near], float(oz.min())), min(lmin[near], float(opath.min()))
        smax2[near] = max(smax2[near], float((outline[0] ** 2).sum(1).max()))
        up[near] = math.exp(-mu * lmin[near])
        w = beam.diameter_at(zmin) / 2
    peak = beam.power_w / (math.pi * w * w) * np.exp(-r2) * np.sqrt(1 + smax2 * (beam.divergence_rad / 2) ** 2) * up
    err = disk_err + beam.power_w * slack + float((power * (up - down)).sum())
    pieces = None
    if not holes:  # the pieces are what is lit (with holes only their moments are)
        pieces = np.empty(len(oc.pieces), object)
        pieces[:] = [np.asarray(p, float) for p in oc.pieces]
    return ExactSamples(pts, unit, path, z, power * up, peak, m.cov, m.area, err, total, zmin, pieces, m.fraction)


def _aggregate(keys, weights, values):
    """Weighted means of ``values`` (n, ...) over groups ``keys`` (n,)."""
    uniq, inv = np.unique(keys, return_inverse=True)
    wsum = np.bincount(inv, weights, len(uniq))
    flat = values.reshape(len(values), -1)
    out = np.stack([np.bincount(inv, weights * flat[:, k], len(uniq)) for k in range(flat.shape[1])], axis=1)
    return inv, wsum, (out / np.maximum(wsum, 1e-300)[:, None]).reshape((len(uniq),) + values.shape[1:])


def _surface_jacobian(beam, w, dirs, normals):
    """d(hit point)/ds on the surface for rays (dirs, N x 3) at 1/e radii w [m]:
    ``w (e_k - d (e_k . n) / (d . n))`` for k = 1, 2 (two N x 3 arrays)."""
    den = np.einsum("ij,ij->i", dirs, normals)
    den = np.where(np.abs(den) > 1e-9, den, -1e-9)
    return [w[:, None] * (e[None, :] - dirs * ((normals @ e) / den)[:, None]) for e in (beam.e1, beam.e2)]


def _leaf_geometry(beam, cells, rows, pts, dirs, normals):
    """Per leaf: the Gaussian-weighted centroid of the cell's footprint on the surface and
    its within-cell variance [m^2] (the cell's s-moments mapped by the Jacobian of the hit
    point with respect to s)."""
    s_c, z = beam.to_s(pts)
    w = beam.diameter_at(z) / 2
    mean, var = cells.moments(rows)
    s0, s1, t0, t1 = cells.bounds(rows)
    centre = np.stack([(s0 + s1) / 2, (t0 + t1) / 2], axis=1)
    jac = _surface_jacobian(beam, w, dirs, normals)
    shifted = pts + jac[0] * (mean[:, 0] - centre[:, 0])[:, None] + jac[1] * (mean[:, 1] - centre[:, 1])[:, None]
    spread = (jac[0] ** 2).sum(1) * var[:, 0] + (jac[1] ** 2).sum(1) * var[:, 1]
    return shifted, spread, s_c, z, w, jac


def _leaf_near_axial(beam, cells, rows, z, w, dirs, normals):
    """Smallest axial distance [m] of each leaf's footprint on the surface: its centre's
    less the axial spread of the cell's half-widths through the hit Jacobian (a linear
    bound; a grazing cell's footprint stretches far along the beam), never below 0."""
    s0, s1, t0, t1 = cells.bounds(rows)
    jac = _surface_jacobian(beam, w, dirs, normals)
    spread = 0.5 * (np.abs(jac[0] @ beam.axis) * (s1 - s0) + np.abs(jac[1] @ beam.axis) * (t1 - t0))
    return np.maximum(z - np.nan_to_num(spread, nan=np.inf, posinf=np.inf), 0.0)


def _edge_bound(beam, cells, target, rows, mu):
    """A bound on the incident irradiance [W/m^2] anywhere on a sampled faceted target, and
    the wavefront radius [m] where it holds: the Gaussian's largest value over every leaf
    touching it (mixed ones too: a sliver lit at grazing incidence may hold no leaf centre
    near its nearest end) at the target's nearest range. (None, inf) for the terrain and
    curved targets (their samples' own bounds hold)."""
    if getattr(target.spec, "shape", None) is None or target.mesh.analytic is not None or not len(rows):
        return None, math.inf
    z = max(_nearest_axial(beam, target), 0.0)
    w = float(beam.diameter_at(z)) / 2
    peak = beam.power_w / (math.pi * w * w) * float(cells.max_profile(rows).max()) * math.exp(-mu * z)
    return peak, float(beam.source_distance_m(z))


def _leaf_corners(beam, s_lo, s_hi, centre_x, normals, jac):
    """Where a diverging beam's rays through each leaf's corners meet the leaf's tangent
    plane (through its centre ray's hit ``centre_x`` (L, 3), normal ``normals``) and their
    perspective weights (``hazard.physics.near_field``): (L, 4, 3) [m] and (L, 4); (None, None)
    for a collimated beam (the affine map through ``jac`` is exact there). A leaf whose
    corner ray runs parallel to or away from that plane keeps the affine corners."""
    if not beam.divergence_rad > 0 or not len(centre_x):
        return None, None
    cs = leaf_corners_s(s_lo, s_hi)
    o, d = beam.rays(cs.reshape(-1, 2))
    n = np.repeat(normals, 4, axis=0)
    dn = np.einsum("ij,ij->i", d, n)
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.einsum("ij,ij->i", np.repeat(centre_x, 4, axis=0) - o, n) / dn
    x = o + t[:, None] * d
    ok = (np.isfinite(t) & (t > 0)).reshape(-1, 4).all(axis=1)
    ds = cs - 0.5 * (s_lo + s_hi)[:, None, :]
    affine = centre_x[:, None, :] + ds[:, :, :1] * jac[0][:, None, :] + ds[:, :, 1:] * jac[1][:, None, :]
    x = np.where(ok[:, None, None], x.reshape(-1, 4, 3), affine)
    g = perspective_weights(beam.source_distance_m((x.reshape(-1, 3) - beam.position_m) @ beam.axis).reshape(-1, 4))
    g[~ok] = 1.0
    return x, g


def _nearest_axial(beam, target) -> float:
    """The target's smallest axial distance from the laser [m] (over its vertices)."""
    v = np.asarray(target.mesh.vertices, float)
    return float(((v - beam.position_m) @ beam.axis).min()) if len(v) else 0.0


def _target_ray_faces(tracer, target):
    if not hasattr(tracer, "face_object"):
        return None
    ids = np.flatnonzero(tracer.face_object == target.index)
    return ids, tracer.face_normals(ids), tracer.vertices[tracer.faces[ids, 0]]


def _spot_from_rows(beam, cells, target, rows, side, material, tracer, mu, scale, error_w, exact):
    """One spot from the leaves ``rows`` that hit ``target`` on one side."""
    pts, dirs, t = cells.point[rows], cells.direction[rows], cells.t[rows]
    normals = _hit_normals(target, pts, cells.faces[rows, 0], tracer)
    if side == "back":
        normals = -normals
    atten = np.exp(-mu * t)
    power = cells.power_w[rows] * scale * atten
    centre_x = pts
    pts, spread, s_c, z, w, jac = _leaf_geometry(beam, cells, rows, pts, dirs, normals)
    near = np.maximum(_leaf_near_axial(beam, cells, rows, z, w, dirs, normals), _nearest_axial(beam, target))
    peak = beam.power_w / (math.pi * w * w) * cells.max_profile(rows) * atten * np.sqrt(1 + (s_c * s_c).sum(1) * (beam.divergence_rad / 2) ** 2)
    area = float(np.sum(cells.size(cells.level[rows]) ** 2 * w * w))
    lv = cells.level[rows]
    key = (cells.i[rows] >> lv).astype(np.int64) * cells.n0 + (cells.j[rows] >> lv)  # the coarsest cell holding each leaf
    wts = np.maximum(power, 1e-300)
    inv, psum, means = _aggregate(key, wts, np.concatenate([pts, dirs, normals, t[:, None], z[:, None]], axis=1))
    n_g = len(psum)
    z_near = np.full(n_g, np.inf)
    np.minimum.at(z_near, inv, near)
    # each leaf's bound carried to its sample's nearest range: the beam there is narrower by (p_leaf / p_near)
    p_leaf, p_near = beam.source_distance_m(z), beam.source_distance_m(z_near)
    ratio = np.where(np.isfinite(p_leaf), p_leaf / np.where(np.isfinite(p_near[inv]), p_near[inv], 1.0), 1.0)
    pk = np.zeros(n_g)
    np.maximum.at(pk, inv, peak * ratio**2)
    # second moment about each sample's centroid: within-leaf spread + leaves' scatter
    scatter = np.bincount(inv, wts * (spread + ((pts - means[inv, 0:3]) ** 2).sum(1)), n_g) / np.maximum(psum, 1e-300)
    nrm = means[:, 6:9] / np.linalg.norm(means[:, 6:9], axis=1, keepdims=True)
    inc = means[:, 3:6] / np.linalg.norm(means[:, 3:6], axis=1, keepdims=True)
    s0, s1, t0, t1 = cells.bounds(rows)
    sample_power = np.bincount(inv, power, n_g)
    corners_x, corners_g = _leaf_corners(beam, np.stack([s0, t0], 1), np.stack([s1, t1], 1), centre_x, normals, jac)
    patches = patches_from_leaves(centre_x, jac, np.stack([s0, t0], 1), np.stack([s1, t1], 1), power, inv, means[:, 0:3],
                                  sample_power, corners_x, corners_g)
    points, scatter = _centroids(patches, means[:, 0:3], scatter)
    return Spot(target, points, sample_power, inc, _frames(target, nrm), means[:, 9], pk,
                p_near, material, side, float(error_w), exact, area, cells, beam,
                _target_ray_faces(tracer, target), spread_m2=scatter, patches=patches)


def _centroids(patches, points, spread_m2):
    """The samples' power centroids and variances [m^2] on the surface: for a diverging
    beam's patches those of the rays' perspective map (:attr:`SpotPatches.moments`; the
    hit of the ray through a sample's beam-coordinate centroid is off its power centroid
    at grazing incidence, a first-order error of every point form about it), else as given."""
    if patches is None or patches.tri_g is None:
        return points, spread_m2
    c, v, _, has = patches.moments
    return np.where(has[:, None], c, points), np.where(has, v, spread_m2)


def _spot_from_outline(beam, cells, target, ex, side, material, tracer, outline_s):
    """One spot from a flat target's exact outline pieces (:class:`ExactSamples`)."""
    normal = target.normal if side == "front" else -target.normal
    normals = np.broadcast_to(normal, ex.points.shape).copy()
    w = beam.diameter_at(ex.axial_m) / 2
    jac = _surface_jacobian(beam, w, ex.directions, normals)
    spread = np.zeros(len(w))
    for r in range(2):
        for c in range(2):
            spread += ex.cov_s[:, r, c] * np.einsum("ij,ij->i", jac[r], jac[c])
    patches = None
    if ex.pieces is not None and len(ex.pieces):
        patches = patches_from_pieces(list(ex.pieces), ex.fraction, ex.power_w, lambda s: _plane_hits(beam, target, s)[0],
                                      ex.points, lambda x: beam.source_distance_m((x - beam.position_m) @ beam.axis))
    points, spread = _centroids(patches, ex.points, spread)
    return Spot(target, points, ex.power_w, ex.directions, _frames(target, normals), ex.path_m, ex.peak_irradiance_w_m2,
                beam.source_distance_m(ex.axial_m if ex.near_axial_m is None else ex.near_axial_m), material, side, float(ex.error_w), True, float(np.sum(ex.area_s * w * w)),
                cells, beam, _target_ray_faces(tracer, target), outline_s, spread, patches=patches)


def _pick_side(target, power_w, back):
    """The side most power reaches, its material (None: not reflected) and the other side's power."""
    side_back = power_w[back].sum() > power_w[~back].sum()
    material = target.back_material if side_back else target.material
    return ("back" if side_back else "front"), material, float(power_w[~back if side_back else back].sum())


def _exact_spot(beam, cells, target, ex, tracer, outline_s, out):
    back = ex.directions @ target.normal > 0
    side, material, other = _pick_side(target, ex.power_w, back)
    if other > 0:
        out.unreflected.append((target.name, "back" if side == "front" else "front", other))
    if material is None:
        out.unreflected.append((target.name, side, float(ex.power_w.sum())))
        return
    use = back if side == "back" else ~back
    ex = ExactSamples(*(getattr(ex, f)[use] if isinstance(getattr(ex, f), np.ndarray) else getattr(ex, f)
                        for f in ExactSamples.__dataclass_fields__))
    out.spots.append(_spot_from_outline(beam, cells, target, ex, side, material, tracer, outline_s))


def _negligible_tail(beam, cells, target, rows, tracer, floor_w_m2) -> np.ndarray:
    """Leaves (``rows``) outside the +-``HALF_WIDTH`` core of the beam square whose incident
    irradiance is below ``floor_w_m2`` everywhere on their footprint: the bound
    ``P / (pi w^2) exp(-min |s|^2) sqrt(1 + |s|max^2 phi^2 / 4)`` with w at the footprint's
    nearest axial distance (:func:`_leaf_near_axial`; unattenuated). A flat facet or a
    diffuse surface reflects at most that (reflectance <= 1) to any eye."""
    s0, s1, t0, t1 = cells.bounds(rows)
    core = (s0 >= -HALF_WIDTH) & (s1 <= HALF_WIDTH) & (t0 >= -HALF_WIDTH) & (t1 <= HALF_WIDTH)
    if np.all(core):
        return np.zeros(len(rows), bool)
    pts, dirs = cells.point[rows], cells.direction[rows]
    normals = _hit_normals(target, pts, cells.faces[rows, 0], tracer)
    _, z = beam.to_s(pts)
    near = _leaf_near_axial(beam, cells, rows, z, beam.diameter_at(z) / 2, dirs, normals)
    w = beam.diameter_at(near) / 2
    s_max2 = np.maximum(s0 * s0, s1 * s1) + np.maximum(t0 * t0, t1 * t1)
    bound = beam.power_w / (math.pi * w * w) * cells.max_profile(rows) * np.sqrt(1 + s_max2 * (beam.divergence_rad / 2) ** 2)
    return ~core & (bound < floor_w_m2)


def _sampled_spot(beam, cells, target, tracer, mu, out, floor_w_m2=None):
    """A target's spot from the leaves whose centre ray hits it; its total raised by the
    power of the mixed leaves touching it and the truncated tail (conservative). With
    ``floor_w_m2`` (the terrain), the leaves beyond the +-4 w core whose incident
    irradiance stays below it (:func:`_negligible_tail`) are left out of the spot's samples
    (their power stays in its total; ``out.negligible`` says how many): a grazing beam's
    tail stretches a terrain spot far along the ground for nothing."""
    k = target.index
    rows = np.flatnonzero(cells.labels[:, 0] == k)
    touch = np.flatnonzero(cells.mixed & np.any(cells.labels == k, axis=1))
    if not len(rows):
        if len(touch):
            out.unreflected.append((target.name, "unresolved", float(cells.power_w[touch].sum())))
        return 0.0
    normals = _hit_normals(target, cells.point[rows], cells.faces[rows, 0], tracer)
    back = np.einsum("ij,ij->i", cells.direction[rows], normals) > 0
    # the true power lies between the leaves wholly on the target and those plus every
    # mixed leaf touching it (and the truncated tail): take the upper end; a sphere or
    # cylinder takes its exact outline's power where nothing else shows inside it, else
    # the rays' total plus what its facets may lose (_curved_total)
    raw = float(cells.power_w[rows].sum())
    err = float(cells.power_w[touch].sum()) + cells.truncated_w + cells.unseen_w.get(k, 0.0)  # + where it may lie between rays
    whole = raw - float(cells.power_w[rows][cells.mixed[rows]].sum())
    curved = _curved_total(beam, cells, target, tracer)
    if curved is not None and curved[0] is not None:
        whole, err = curved[0] - curved[1], curved[1]
    elif curved is not None:
        err += curved[1]
    if curved is not None:  # wholly ahead of the aperture, a convex shape is lit outside only (a
        back[:] = False  # faceted limb's hit may face away from its exact normal at grazing)
    scale = (whole + err) / raw
    side, material, other = _pick_side(target, cells.power_w[rows] * scale, back)
    if other > 0:
        out.unreflected.append((target.name, "back" if side == "front" else "front", other))
    use = rows[back] if side == "back" else rows[~back]
    lit = use
    if floor_w_m2 is not None and material is not None and len(use):
        drop = _negligible_tail(beam, cells, target, use, tracer, floor_w_m2)
        if np.any(drop) and not np.all(drop):
            dropped = float(cells.power_w[use[drop]].sum())
            out.negligible.append((target.name, int(drop.sum()), dropped * scale, float(floor_w_m2)))
            scale *= float(cells.power_w[use].sum()) / float(cells.power_w[use[~drop]].sum())  # the spot keeps its total
            use = use[~drop]
    if material is None:
        out.unreflected.append((target.name, side, float(cells.power_w[use].sum() * scale)))
    else:
        sp = _spot_from_rows(beam, cells, target, use, side, material, tracer, mu, scale, err, False)
        sp.edge_peak_w_m2, sp.edge_source_m = _edge_bound(beam, cells, target, np.concatenate([lit, touch]), mu)
        out.spots.append(sp)
    return whole + err


def _curved_total(beam, cells, target, tracer):
    """A sphere's or cylinder's intercepted power from its exact surface, or what its
    triangle mesh may lose (the rays see a polyhedron inscribed in it).

    Returns None for other targets (or a shape not wholly ahead of the aperture); else
    ``(total_w, error_w)`` when nothing else is hit in front of the exact surface by any
    ray inside its outline (rays beside the facets that meet something behind it, a wall
    or the ground, are retraced and their hits compared with the exact surface's
    entry): the Gaussian power over the outline's circumscribed polygon (Owen's T, exact
    for it) and the power between it and the inscribed one; or ``(None, facet_w)``
    otherwise, facet_w the power between the outline and the mesh's own (the hull of its
    projected vertices, :func:`hazard.physics.beam.curved_outline_s`), a bound on the power lost
    to faceting.
    """
    from hazard.physics.beam import CELL_OFFSETS, curved_outline_s, inside_convex_many, polygon_moments

    outl = curved_outline_s(beam, target.mesh)
    if outl is None:
        return None
    frac = polygon_moments(list(outl)).fraction
    outer_w, inner_w, mesh_w = beam.power_w * frac
    s0, s1, t0, t1 = cells.bounds()
    lo, hi = outl[0].min(axis=0), outl[0].max(axis=0)
    near = np.flatnonzero((s1 >= lo[0]) & (s0 <= hi[0]) & (t1 >= lo[1]) & (t0 <= hi[1]))
    d = (s1 - s0)[near]
    s = (np.stack([s0[near], t0[near]], axis=1)[:, None, :] + CELL_OFFSETS[None, :, :] * d[:, None, None]).reshape(-1, 2)
    inside = inside_convex_many(s, outl[0])
    lab = cells.labels[near].ravel()
    other = np.flatnonzero(inside & (lab != target.index) & (lab != -1))
    if not len(other) or not np.any(_in_front_of_surface(beam, tracer, target.mesh.analytic, s[other])):
        return outer_w, max(outer_w - inner_w, 0.0)
    return None, max(outer_w - mesh_w, 0.0)


def _in_front_of_surface(beam, tracer, analytic, s) -> np.ndarray:
    """For rays at s (N, 2): whether their first hit lies in front of the exact sphere or
    capped cylinder ``analytic`` where they meet it (False where they miss it)."""
    o, dirs = beam.rays(s)
    unit = dirs / np.linalg.norm(dirs, axis=1, keepdims=True)
    hits = tracer.first_hit(o, dirs)
    t_hit = np.where(hits.hit, np.linalg.norm(hits.point - o, axis=1), np.inf)
    entry = _entry_distance(analytic, o, unit)
    return np.isfinite(entry) & (t_hit < entry * (1 - 1e-9))


def _entry_distance(analytic, o, u) -> np.ndarray:
    """Distance [m] along unit rays (o, u) to where they enter a sphere ``("sphere", c, r)``
    or capped cylinder ``("cylinder", c, axis, r, half_length)``; inf where they miss.
    Solved from each line's point nearest the centre (no cancellation of long ranges)."""
    c = np.asarray(analytic[1], float)
    shift = ((c - o) * u).sum(1)
    q = o + shift[:, None] * u - c
    if analytic[0] == "sphere":
        half = np.sqrt(np.maximum(analytic[2] ** 2 - (q * q).sum(1), 0.0))
        meet = ((q * q).sum(1) <= analytic[2] ** 2) & (shift + half > 0)
        return np.where(meet, np.maximum(shift - half, 0.0), np.inf)
    ax, r, h = np.asarray(analytic[2], float), analytic[3], analytic[4]
    qa, ua = q @ ax, u @ ax
    qp, up = q - qa[:, None] * ax, u - ua[:, None] * ax
    a2, b2, c2 = (up * up).sum(1), 2 * (qp * up).sum(1), (qp * qp).sum(1) - r * r
    disc = b2 * b2 - 4 * a2 * c2
    par = a2 < 1e-15
    root = np.sqrt(np.maximum(disc, 0.0))
    with np.errstate(divide="ignore", invalid="ignore"):
        lo1 = np.where(par, np.where(c2 <= 0, -np.inf, np.inf), (-b2 - root) / (2 * a2))
        hi1 = np.where(par, np.where(c2 <= 0, np.inf, -np.inf), (-b2 + root) / (2 * a2))
        ta, tb = (-h - qa) / ua, (h - qa) / ua
    slab = np.abs(ua) < 1e-15
    lo2 = np.where(slab, np.where(np.abs(qa) <= h, -np.inf, np.inf), np.minimum(ta, tb))
    hi2 = np.where(slab, np.where(np.abs(qa) <= h, np.inf, -np.inf), np.maximum(ta, tb))
    lo, hi = np.maximum(lo1, lo2), np.minimum(hi1, hi2)
    meet = (par | (disc >= 0)) & (lo <= hi) & (hi + shift > 0)
    return np.where(meet, np.maximum(lo + shift, 0.0), np.inf)


def build_spots(beam, cells, targets, tracer, mu, outlines=None, ground=None, ground_floor_w_m2=None) -> SpotBuild:
    """Spots from the beam's leaf cells: one per lit target (the side that most power
    reaches; a back face reflects with the target's ``back`` material or not at all),
    and one on ``ground`` (the terrain as a target, :attr:`scenes.Scene.terrain_target`)
    where the beam lands on it: its power stays counted as blocked.

    A flat target whose edges meet only empty beam gets samples from its exact outline
    (:func:`_exact_samples`); any other target's total is the cells' sum raised by the
    power in mixed cells that touch it and the truncated tail (conservative: never less
    than the true intercepted power, within the stated error).
    """
    outlines = outlines or {}
    out = SpotBuild([], 0.0, 0.0, [], [], cells.unresolved_w + cells.truncated_w)
    totals = 0.0
    for target in targets:
        k = target.index
        ex = None
        fronts = {j: outlines[j] for j in cells.occluders.get(k, ())}
        if k in cells.exact_targets and k in outlines and all(j in outlines for j in cells.occluders.get(k, ())):
            ex = _exact_samples(beam, cells.n0, target, outlines[k], tracer, mu, fronts)
        if ex is None:
            totals += _sampled_spot(beam, cells, target, tracer, mu, out)
            continue
        out.exact.append(target.name)
        totals += ex.total_w
        if not ex.power_w.sum() > 0:  # wholly hidden by the targets in front of it
            continue
        _exact_spot(beam, cells, target, ex, tracer, None if fronts else outlines[k][0], out)
    if ground is not None:
        _sampled_spot(beam, cells, ground, tracer, mu, out, ground_floor_w_m2)
    out.blocked_w = float(cells.power_w[cells.labels[:, 0] >= len(targets)].sum())
    out.spill_w = max(beam.power_w - totals - out.blocked_w, 0.0)  # the rest (exact where the targets' totals are)
    return out


# -- BRDF evaluation over states ------------------------------------------------------------
def projected_brdf(model, wi, wo, states=None, row_scale=None, reduce=None) -> np.ndarray:
    """``f_r cos(theta_r)`` [1/sr] at pairs (N, 3), for no state (N,) or states (T,) -> (N, T),
    optionally multiplied by a per-row factor ``row_scale`` (N,).

    Dynamic SH models are evaluated as one basis evaluation and one matrix product over
    all states, with ``row_scale`` folded into the exponent; a state-table factor
    multiplies; other models loop over the states. ``reduce="max"`` returns the maximum
    over the states (N,) without forming (N, T) where the model allows: inside the
    dynamic SH evaluation, and as ``f x max(factor)`` for a static model scaled by a
    (non-negative) state-table factor. ``reduce="path-max"``: the maximum over the path
    joining the states in time order (a dynamic SH model finds it exactly, see
    :meth:`brdfmodels.DynamicBRDF.evaluate_many`; for one state the caller adds the
    table's nodes inside the path's range, so the max over the states is the path's);
    a two-state sum takes the sum of its parts' maxima (conservative).
    """
    if states is None:
        f = model.evaluate_cos(wi, wo)
        return f if row_scale is None else f * row_scale
    states = np.asarray(states, float)
    if isinstance(model, DynamicBRDF):
        return model.evaluate_many(wi, wo, states, projected=True, row_scale=row_scale, reduce=reduce)
    if isinstance(model, Scaled):
        table = isinstance(model.factor, StateTable)
        if reduce and not (table and model.model.is_dynamic):
            # the max of a product with a non-negative factor that does not vary with the
            # inner model's states (or an inner model that does not vary) factorises
            inner = projected_brdf(model.model, wi, wo, states if model.model.is_dynamic else None, row_scale, reduce)
            return inner * (float(np.max(model.factor(states))) if table else model.factor)
        inner = projected_brdf(model.model, wi, wo, states if model.model.is_dynamic else None, row_scale)
        if inner.ndim == 1:
            inner = inner[:, None]
        f = inner * (model.factor(states)[None, :] if table else model.factor)
        return f.max(axis=1) if reduce else f
    if not model.is_dynamic:
        f = model.evaluate_cos(wi, wo)
        if row_scale is not None:
            f = f * row_scale
        return f if reduce else np.repeat(f[:, None], len(states), axis=1)
    if reduce and isinstance(model, Sum) and model.state_dim == 2:
        # the max of a sum <= the sum of the parts' maxima (exact when one part varies)
        return sum(projected_brdf(m, wi, wo, states if m.is_dynamic else None, row_scale, reduce) for m in model.models)
    f = _per_state(model, wi, wo, states) if states.ndim == 1 and model.state_dim == 1 else \
        np.stack([model.evaluate_cos(wi, wo, state=s) for s in states], axis=-1)
    f = f if row_scale is None else f * row_scale[:, None]
    return f.max(axis=1) if reduce else f


_STATE_BLOCK = 1 << 16  # (pair, state) evaluations of a state-looping model per call


def _per_state(model, wi, wo, states):
    """``f_r cos(theta_r)`` (N, T) of a model without a vectorised state path, the pairs
    repeated over the (scalar) states in one call per block: the model's per-call work
    (checks, normalisation) once per block instead of once per state."""
    wi, wo = np.broadcast_arrays(np.asarray(wi, float), np.asarray(wo, float))
    wi, wo = wi.reshape(-1, 3), wo.reshape(-1, 3)
    n, t = len(wi), len(states)
    out = np.empty((n, t))
    step = max(1, _STATE_BLOCK // t)
    for a in range(0, n, step):
        k = min(n, a + step) - a
        rep = (k, t, 3)
        out[a:a + k] = model.evaluate_cos(np.broadcast_to(wi[a:a + k, None], rep), np.broadcast_to(wo[a:a + k, None], rep),
                                          state=np.broadcast_to(states, (k, t)))
    return out


def path_states(model, states) -> np.ndarray:
    """The states that give a model's exact maximum over a history's path: for one state
    the sorted states with the model's nodes inside their range (the path covers that
    range; between nodes a table is linear), for two states the path itself in time
    order (:meth:`brdfmodels.DynamicBRDF.evaluate_many` with ``reduce="path-max"``)."""
    s = np.asarray(states, float)
    if s.ndim == 2:
        return s
    nodes = np.asarray(model.state_nodes(), float)
    lo, hi = s.min(), s.max()
    return np.unique(np.concatenate([s, nodes[(nodes >= lo) & (nodes <= hi)]]))


def to_local(frames, v):
    """World vectors v (..., 3) into frames (3, 3) or per-row frames (N, 3, 3)."""
    if frames.ndim == 2:
        return v @ frames.T
    return np.einsum("nij,nj->ni", frames, v)


def frame_groups(spot: Spot):
    """The spot's samples grouped by their material frame, for its point form: ``(frames
    (G, 3, 3), wi (G, 3), share (G,))`` - each group's frame, its power-weighted incoming
    direction in that frame (towards the source) and its share of the spot's power; None
    where every sample has the same frame (a flat spot: the mean frame's point form is
    exact). A curved spot (a sphere's or cylinder's facets, a terrain's) sends light
    into directions its mean plane would call grazing or behind it: a Lambertian sphere's
    radiant intensity at 90 deg from the beam is 2 rho P / (3 pi^2), where the mean
    frame's ``rho / pi cos`` gives 0."""
    fr = np.asarray(spot.frames, float).reshape(len(spot.frames), 9)
    if not len(fr) or bool(np.all(fr == fr[0])):
        return None
    u, inv = np.unique(fr, axis=0, return_inverse=True)
    inv = inv.ravel()
    w = spot._weights
    inc = np.zeros((len(u), 3))
    np.add.at(inc, inv, spot.incoming * w[:, None])
    inc /= np.maximum(np.linalg.norm(inc, axis=1, keepdims=True), 1e-300)
    frames = u.reshape(-1, 3, 3)
    total = float(spot.power_w.sum())
    share = np.bincount(inv, weights=spot.power_w, minlength=len(u)) / total if total > 0 else np.full(len(u), 1.0 / len(u))
    return frames, to_local(frames, -inc), share


def point_form(spot: Spot, d, scale, states=None, reduce=None, sparse=False, groups=False):
    """The spot's radiant intensity over its power, ``f_r cos``, at unit world directions
    ``d`` (M, 3) from its centroid, times ``scale`` (M,): (M,) or (M, T) with states
    (``reduce`` as :func:`projected_brdf`), and where it is evaluated (M,) bool (in front
    and ``scale > 0``; 0 elsewhere); ``sparse``: (rows evaluated, their values) instead;
    ``groups``: the spot's :func:`frame_groups` when the caller has them (False: made here).
    The mean frame's ``f_r cos``; for a spot of several frames (:func:`frame_groups`) the
    larger of that and the sum of each frame's share: the sum alone rests on a curved
    spot's few samples (15 on a 5 cm sphere in a 2 m beam gave 0.71 of a Lambertian
    sphere's intensity 30 deg off the backscatter, where the mean frame gives 1.48), the
    mean frame alone gives 0 at and behind its plane."""
    fr = spot.mean_frame
    wo = to_local(fr, d)
    live = (wo[:, 2] > 0) & (scale > 0)  # behind the surface or out of sight: nothing, not evaluated
    wi = to_local(fr, -spot.mean_incoming)[None, :]  # one direction: the models broadcast it after checking it once
    groups = frame_groups(spot) if groups is False else groups
    if groups is None and live.all():
        v = projected_brdf(spot.material, wi, wo, states, scale, reduce=reduce)
        return (np.arange(len(d)), v) if sparse else (v, live)
    rows = np.flatnonzero(live)
    v = projected_brdf(spot.material, wi, wo[rows], states, scale[rows], reduce=reduce)
    if groups is None and sparse:
        return rows, v
    e = np.zeros((len(d),) if states is None or reduce is not None else (len(d), len(states)))
    e[rows] = v
    if groups is not None:
        e2, live2 = _frames_sum(spot, d, scale, states, reduce, groups)
        e, live = np.maximum(e, e2), live | live2
    if sparse:
        rows = np.flatnonzero(live)
        return rows, e[rows]
    return e, live


def _frames_sum(spot: Spot, d, scale, states, reduce, groups):
    """:func:`point_form`'s sum over ``groups`` (frames, wi, share): (M,) or (M, T), and
    where some frame faces ``d`` (M,)."""
    frames, wi, share = groups
    m = len(d)
    e = np.zeros((m,) if states is None or reduce is not None else (m, len(states)))
    live = np.zeros(m, bool)
    for g in range(len(frames)):
        wo = to_local(frames[g], d)
        on = (wo[:, 2] > 0) & (scale > 0)
        rows = np.flatnonzero(on)
        if len(rows):
            e[rows] += projected_brdf(spot.material, wi[g][None], wo[rows], states, scale[rows] * share[g], reduce=reduce)
        live |= on
    return e, live


def spot_irradiance(spot: Spot, observers_m, gain, attenuation_per_m, states=None, visible=None, *, sparse=False, bound=False):
    """BRDF-reflected irradiance [W/m^2] at observers (M, 3) from one spot.

    Returns ``(E, far)``: E of shape (M,) or (M, T) with states, and the far-field mask.
    ``visible`` (M,) is the line-of-sight mask (default: all visible); it is folded into
    the per-observer factor, so occluded observers cost no extra pass. With
    ``sparse=True`` it returns ``((rows, E_rows), far)``: when every observer is in the
    far field only the rows that receive light (maps skip everyone behind the surface or
    out of sight), otherwise all rows. ``bound=True``: near the spot an upper bound where
    the integral over its triangles would be needed and the material has one
    (:func:`brdf_bound`; :func:`near_field_w_m2`), the exact value elsewhere.
    """
    if spot.slump is not None and states is not None:
        from hazard.physics.slump import slumped_irradiance

        return slumped_irradiance(spot_irradiance, spot, observers_m, gain, attenuation_per_m, states, visible, sparse)
    obs = np.asarray(observers_m, float)
    m = len(obs)
    c = spot.centroid
    rng = np.linalg.norm(obs - c, axis=1)
    far = rng >= FAR_FIELD_SPOT_SIZES * max(spot.size_m, 1e-9)
    vis = np.ones(m) if visible is None else np.asarray(visible, float)
    if np.all(far):
        scale = spot.total_power_w * gain * vis / rng**2
        if attenuation_per_m:
            scale *= np.exp(-attenuation_per_m * rng)
        # observers behind the surface or out of sight receive nothing: evaluated only in front (point_form)
        if sparse:
            return point_form(spot, (obs - c) / rng[:, None], scale, states, sparse=True), far
        return point_form(spot, (obs - c) / rng[:, None], scale, states)[0], far
    shape = (m,) if states is None else (m, len(states))
    e = np.zeros(shape)
    if np.any(far):
        d = (obs[far] - c) / rng[far, None]
        scale = spot.total_power_w * np.exp(-attenuation_per_m * rng[far]) * gain[far] * vis[far] / rng[far] ** 2
        e[far] = point_form(spot, d, scale, states)[0]
    near = np.flatnonzero(~far & (vis > 0))
    if len(near) and spot.patches is not None:
        e[near] = near_field_w_m2(spot, obs[near], gain[near] * vis[near], attenuation_per_m, states, bound=bound)
    elif len(near):  # a spot built without its patches (by hand): its samples as point sources
        e[near] = _samples_as_points(spot, obs[near], gain[near] * vis[near], attenuation_per_m, states)
    return ((np.arange(m), e), far) if sparse else (e, far)


def _samples_as_points(spot: Spot, obs, weight, attenuation_per_m, states):
    """Irradiance [W/m^2] (M,) or (M, T) at ``obs`` from each spot sample as a point source
    (spots built without their near-field patches), ``weight`` the gain x line of sight."""
    model = spot.material
    e = np.zeros((len(obs),) if states is None else (len(obs), len(states)))
    wi_all = to_local(spot.frames, -spot.incoming)
    for i in range(len(spot.points)):
        v = obs - spot.points[i]
        r = np.maximum(np.linalg.norm(v, axis=1), 1e-300)
        wo = to_local(spot.frames[i], v / r[:, None])
        scale = spot.power_w[i] * np.exp(-attenuation_per_m * r) * weight / r**2
        e += projected_brdf(model, np.broadcast_to(wi_all[i], wo.shape), wo, states, scale)
    return e


def spot_line_of_sight(ray_scene, spot: Spot, p) -> tuple[np.ndarray, int]:
    """Line of sight from ``spot`` to points ``p`` (N, 3): one occlusion query from just
    off the spot's centroid, in which a convex target's own triangles do not block (the
    centroid of a curved spot lies inside the tessellation); far-field points behind the
    spot's surface receive nothing whatever is in between (behind every one of its
    frames' planes, :func:`frame_groups`): no ray needed, False. Returns (mask, segments traced)."""
    c, nrm = spot.centroid, spot.mean_frame[2]
    start = ray_scene.off_surface(spot.sight_point_m, nrm)  # in front of a convex mesh's own bulge too
    rel = p - c
    along = rel @ nrm
    groups = frame_groups(spot)  # in front of any of its frames' surfaces: lit in the far field (point_form)
    front = along > 0 if groups is None else (rel @ groups[0][:, 2].T).max(axis=1) > 0
    far = np.einsum("ij,ij->i", rel, rel) >= (FAR_FIELD_SPOT_SIZES * max(spot.size_m, 1e-9)) ** 2
    need = ~far | front | spot.material.has_specular
    idx = np.flatnonzero(need)
    row = np.zeros(len(p), bool)
    own = own_object(spot.target)
    plain = np.zeros(len(idx), bool)  # segments the target's own triangles cannot cross: no trace back from their end
    if own is not None and len(idx) and ray_scene.behind_plane(own, start, nrm):
        plain = along[idx] > float((start - c) @ nrm)  # the end in front of the plane through the start
    for rows, transparent in ((idx[plain], None), (idx[~plain], own)):
        if len(rows):
            row[rows] = ~ray_scene.occluded(np.broadcast_to(start, (len(rows), 3)), p[rows], transparent=transparent)
    return row, len(idx)


def brdf_bound(model) -> float | None:
    """An upper bound [1/sr] of ``f_r`` over every pair of directions and state, where one
    is proven: ``rho / pi`` for a Lambertian material; None otherwise."""
    return model.reflectance / math.pi if type(model) is Lambertian else None


def near_field_w_m2(spot: Spot, obs, weight, attenuation_per_m, states, bound=False, max_evaluations=None):
    """Irradiance [W/m^2] (M,) or (M, T) at near observers ``obs`` (M, 3) with factors
    ``weight`` (gain x line of sight): the integral over the spot's patches
    (:func:`hazard.physics.near_field.near_field_irradiance`, ``f_r cos(theta_r)`` of each
    sample's material frame and incidence). ``bound=True`` and a material with
    :func:`brdf_bound`: an upper bound where the integral over triangles would
    be needed (the point form's pairs exact). ``max_evaluations``: the integral's
    ceiling in kernel evaluations (NaN at the observers it leaves unfinished:
    :func:`hazard.physics.near_field.near_field_irradiance`)."""
    model = spot.material
    wi_all = to_local(spot.frames, -spot.incoming)
    frames = np.asarray(spot.frames, float)
    one = frames[0] if len(frames) and np.all(frames == frames[0]) else None  # a flat spot: one frame (no per-node gather)

    def kernel(samples, x, o, scale):
        v = o - x
        r = np.maximum(np.sqrt(np.einsum("ij,ij->i", v, v)), 1e-300)
        u = v / r[:, None]
        wo = to_local(frames[samples], u) if one is None else np.einsum("ij,nj->ni", one, u)  # the same sums
        s = scale / (r * r)
        if attenuation_per_m:
            s = s * np.exp(-attenuation_per_m * r)
        return projected_brdf(model, wi_all[samples], wo, states, s)

    shape = (len(obs),) if states is None else (len(obs), len(states))
    fr_bound = brdf_bound(model) if bound else None
    return near_field_irradiance(spot.patches, spot.points, spot.spread_m2, spot.frames[:, 2], spot.power_w, obs, weight, kernel,
                                 shape, fr_bound_per_sr=fr_bound, max_evaluations=max_evaluations)


def specular_power_w(spot: Spot, states=None):
    """Power [W] in the delta (mirror) lobe of a spot, per state."""
    model = spot.material
    wi = to_local(spot.frames, -spot.incoming)
    if states is None:
        return float((model.specular_reflectance(wi) * spot.power_w).sum())
    return np.array([(model.specular_reflectance(wi, state=s) * spot.power_w).sum() for s in states])


def mirror_axis(spot: Spot) -> np.ndarray:
    n = spot.mean_frame[2]
    d = spot.mean_incoming
    r = d - 2 * np.dot(d, n) * n
    return r / np.linalg.norm(r)


def specular_irradiance(spot: Spot, observers_m, gain, attenuation_per_m, beam=None, states=None, apertures=None,
                        ray_scene=None):
    """Irradiance [W/m^2] of the reflected (delta-lobe) beam at observers (M,) or (M, T),
    by geometric optics from the part of the beam that really hits the mirror (see
    :func:`hazard.physics.specular.specular_irradiance`; ``beam`` is not used: the spot carries
    its beam; ``apertures``: flat mirrors' beams through the observers' limiting
    apertures, :mod:`hazard.physics.aperture`). With ``ray_scene`` each observer's line of sight
    is traced from its own reflection point (the spot's line of sight is not applied to
    the result)."""
    from hazard.physics.specular import specular_irradiance as _specular

    return _specular(spot, observers_m, gain, attenuation_per_m, states, apertures, ray_scene=ray_scene)


def spot_directions(spot: Spot):
    """Incidence direction of the spot in its mean material frame."""
    return to_local(spot.mean_frame, -spot.mean_incoming)


__all__ += ["specular_power_w", "mirror_axis", "spot_directions", "SpotBuild", "path_states", "frame_groups", "point_form"]
