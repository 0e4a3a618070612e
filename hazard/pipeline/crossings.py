"""Stage ``crossings``: where a narrow beam passes between an observer group's points.

A road sampled every 10 m can let a 0.3 m beam (the laser's own, or a mirror's) pass
between two points unseen, and so can a grid of 10 m cells or a shell. For every line,
grid and shell of observers (:mod:`hazard.pipeline.surfaces`) the irradiance of the
direct beam and of each mirror beam is searched between the points:

- along a line, on the polyline through its points (``SUBSAMPLES`` per segment), and
  on every segment that passes within ``MARGIN_RADII`` beam radii of a beam's axis ray,
  at the segment's point nearest that ray (closest points of two lines) and
  ``CROSS_SAMPLES`` points each side of it every ``STEP_DIAMETERS`` beam diameters: a
  3 cm beam crossing a 4 km segment is found, not only beams wider than the sampling;
- on a grid or a shell, along the curve ``project(o + t d)`` of each beam's axis ray
  projected on the surface (:mod:`hazard.pipeline.surfaces`): it passes through every
  point where the ray meets the surface, so a crossing is on it. The rays: the direct
  beam's axis and the ray through the hottest point of its spill (just off the edge of
  a target that cuts the beam); for a mirror, the reflected rays through its hottest
  point and through its centroid. Each ray is cut to the surface's bounding box (widened
  by 5 beam radii) and sampled every eighth of the beam's 1/e diameter
  (``STEP_DIAMETERS``), at most ``MAX_CANDIDATES`` points.

The direct beam is searched with its shadows (nothing where a target, occluder or the
terrain stands on the ray). Around each of the ``PEAKS`` highest local maxima of the
first pass the search runs again as finely, then a golden-section search to the
maximum. A maximum that beats the group's nearest ``NEIGHBOURS`` points by more than
``GAIN`` and reaches ``FLOOR`` of the MPE is added as an observer point of its own
(group ``<group>:crossing``, the group's optics), so the map, the lines of sight, the
verdicts and the report treat it like any other (a mirror-beam crossing behind a hill
gets no light there in the map; the other maxima are kept for that).
"""

from __future__ import annotations

import dataclasses

import numpy as np

from hazard.physics.aperture import observer_apertures
from hazard.physics.engine import specular_irradiance
from hazard.pipeline.direct import beam_at, clear_of_objects
from hazard.pipeline.surfaces import Polyline, observer_surfaces

__all__ = ["add_crossings", "SUBSAMPLES", "GAIN", "STEP_DIAMETERS"]

SUBSAMPLES = 64  # points per segment of a line in the first pass, and again around each maximum
GAIN = 1.0 + 1e-9  # a crossing is kept when it beats the group's nearest points by more than this factor (a 1 % rule left roads up to 1 % under their peak)
MAX_CANDIDATES = 2_000_000  # first-pass points per group and beam (bounds memory on long lines)
FLOOR = 1e-4  # crossings weaker than this fraction of the MPE are not added
STEP_DIAMETERS = 1.0 / 8  # first-pass step along a beam's axis, in 1/e beam diameters
PEAKS = 4  # local maxima of the first pass refined per group and beam
NEIGHBOURS = 16  # a crossing is compared with this many of the group's nearest points
MARGIN_RADII = 5.0  # a surface's bounding box is widened by this many beam radii (exp(-25) beyond)
CROSS_SAMPLES = 16  # a line's points each side of where a beam's axis passes nearest it (every STEP_DIAMETERS)


@dataclasses.dataclass(frozen=True)
class Ray:
    """A beam's axis ray: origin and unit direction (local m), the axial range of the
    origin from the laser [m] (for the beam's width along it) and the step floor [m]."""

    origin_m: np.ndarray
    direction: np.ndarray
    range0_m: float
    min_step_m: float


def _direct(beam, mu, tracer):
    """The laser's own beam where nothing stands on the ray (a target cutting the beam
    leaves its shadow: the spill around it is what is searched)."""
    def fn(p):
        at = beam_at(beam, p, mu)
        e = np.zeros(len(p))
        if len(at.rows):
            e[at.rows] = np.where(clear_of_objects(at, p, tracer), at.irradiance_w_m2, 0.0)
        return e
    return fn


SPILL_OUTSET = 1e-3  # the spill's hottest ray is moved this fraction outward (off the target's edge it grazes)


def _direct_rays(beam, spill_s) -> list:
    """The beam's axis ray, and the ray through the hottest point of its spill (the edge
    of a target that cuts the beam), moved ``SPILL_OUTSET`` outward."""
    rays = [Ray(beam.position_m, beam.axis, 0.0, beam.diameter_m)]
    if spill_s is not None and np.any(spill_s != 0):
        o, d = beam.rays(np.asarray(spill_s, float)[None] * (1 + SPILL_OUTSET))
        rays.append(Ray(o[0], d[0] / np.linalg.norm(d[0]), 0.0, beam.diameter_m))
    return rays


def _mirror(spot, beam, mu, apertures=None):
    """The mirror beam's value the verdict uses: through the limiting aperture (or the
    group's aid) when ``apertures(n)`` gives the group's apertures for n points (the point
    value peaks on the image of a mirror edge that cuts the beam near its axis, where the
    aperture collects half the beam: the aperture's peak lies inside the lit side); for a
    dynamic material the highest over its state nodes (where the beam lands does not
    depend on the state, how bright it is does)."""
    states = spot.material.state_nodes() if spot.material.is_dynamic else None

    def fn(p):
        ap = None if apertures is None else apertures(len(p))
        e = specular_irradiance(spot, p, np.ones(len(p)), mu, beam, states, ap)
        return e if e.ndim == 1 else e.max(axis=1)
    return fn


def _mirror_rays(spot, beam):
    """Reflected rays through the spot's hottest sample and through its centroid."""
    k = int(np.argmax(spot.peak_irradiance_w_m2)) if spot.peak_irradiance_w_m2 is not None else 0
    rays = []
    for q, d, n, z in ((spot.points[k], spot.incoming[k], spot.frames[k][2], spot.range_from_laser_m[k]),
                       (spot.centroid, spot.mean_incoming, spot.mean_frame[2], spot.mean_range_m)):
        r = d - 2 * np.dot(d, n) * n
        width = min(float(beam.diameter_at(z)), max(spot.size_m, 1e-6))
        rays.append(Ray(np.asarray(q, float), r / np.linalg.norm(r), float(z), width))
    return rays


def _sources(beam, spots, mu, tracer, spill_s, apertures=None):
    """(label, irradiance function, axis rays) of the direct beam and each mirror beam;
    ``apertures(n)``: the searched group's apertures for n points (mirror beams)."""
    out = [("direct beam", _direct(beam, mu, tracer), _direct_rays(beam, spill_s))]
    for sp in spots:
        if sp.material.has_specular:
            out.append((f"mirror beam of {sp.target.name}", _mirror(sp, beam, mu, apertures), _mirror_rays(sp, beam)))
    return out


def _group_apertures(scene, g):
    """n -> the apertures of n points of observer group ``g`` (its optics, the scene's
    wavelength and exposure duration: :func:`hazard.physics.aperture.observer_apertures`)."""
    obs, spec = scene.observers, scene.spec
    optics = [obs.optics[g] if g < len(obs.optics) else None]

    def make(n):
        return observer_apertures(optics, np.zeros(n, np.intp), spec.laser.wavelength_nm, spec.exposure.duration_s)
    return make


def _peaks(e, floor):
    """Indices of the ``PEAKS`` highest local maxima of e at or above ``floor``."""
    left = np.concatenate([[-np.inf], e[:-1]])
    right = np.concatenate([e[1:], [-np.inf]])
    idx = np.flatnonzero((e >= left) & (e >= right) & (e >= floor) & (e > 0))
    return idx[np.argsort(e[idx])[::-1][:PEAKS]]


def _golden(fn_t, a, b, iterations=60):
    """Golden-section search for the maximum of ``fn_t`` on [a, b]: (value, t)."""
    g = (np.sqrt(5.0) - 1) / 2
    x1, x2 = b - g * (b - a), a + g * (b - a)
    f1, f2 = float(fn_t(np.array([x1]))[0]), float(fn_t(np.array([x2]))[0])
    for _ in range(iterations):
        if f1 >= f2:
            b, x2, f2 = x2, x1, f1
            x1 = b - g * (b - a)
            f1 = float(fn_t(np.array([x1]))[0])
        else:
            a, x1, f1 = x1, x2, f2
            x2 = a + g * (b - a)
            f2 = float(fn_t(np.array([x2]))[0])
    return (f1, x1) if f1 >= f2 else (f2, x2)


def _refine(fn_t, t, e, k):
    """The maximum near first-pass sample k: ``SUBSAMPLES`` between its neighbours,
    then a golden-section search; (value, t), never below the sample itself."""
    lo, hi = t[max(k - 1, 0)], t[min(k + 1, len(t) - 1)]
    tf = np.linspace(lo, hi, SUBSAMPLES + 1)
    ef = fn_t(tf)
    q = int(np.argmax(ef))
    best = (float(ef[q]), tf[q]) if ef[q] >= e[k] else (float(e[k]), t[k])
    g = _golden(fn_t, tf[max(q - 1, 0)], tf[min(q + 1, len(tf) - 1)])
    return g if g[0] >= best[0] else best


def _maxima(fn_t, t, floor):
    """(value, t) of each refined local maximum of ``fn_t`` sampled at t."""
    e = fn_t(t)
    return [_refine(fn_t, t, e, k) for k in _peaks(e, floor)]


def _ray_span(ray, corners, beam):
    """[t0, t1] of the ray inside the box around ``corners`` widened by ``MARGIN_RADII``
    beam radii (slab method), or None; and the first-pass step [m]."""
    far = float(np.max(np.linalg.norm(corners - ray.origin_m, axis=1)))
    pad = MARGIN_RADII * float(beam.diameter_at(ray.range0_m + far)) / 2
    lo, hi = corners.min(axis=0) - pad, corners.max(axis=0) + pad
    with np.errstate(divide="ignore", invalid="ignore"):
        ta, tb = (lo - ray.origin_m) / ray.direction, (hi - ray.origin_m) / ray.direction
    inside = (ray.origin_m >= lo) & (ray.origin_m <= hi)
    par = ray.direction == 0
    if np.any(par & ~inside):
        return None
    t0 = max(0.0, float(np.max(np.where(par, -np.inf, np.minimum(ta, tb)))))
    t1 = float(np.min(np.where(par, np.inf, np.maximum(ta, tb))))
    if t1 <= t0:
        return None
    step = STEP_DIAMETERS * min(float(beam.diameter_at(ray.range0_m + t0)), ray.min_step_m)
    return t0, t1, max(step, (t1 - t0) / (MAX_CANDIDATES - 1))


def _on_surface(fn, surface, rays, beam, floor):
    """(value, point) of the maxima of ``fn`` on a grid's or shell's surface along the
    projections of ``rays``."""
    found = []
    for ray in rays:
        span = _ray_span(ray, surface.corners(), beam)
        if span is None:
            continue
        t0, t1, step = span
        def at(t, ray=ray):
            return surface.project(ray.origin_m + np.asarray(t)[:, None] * ray.direction)
        def fn_t(t, at=at):
            return fn(at(t))
        t = np.linspace(t0, t1, int(np.ceil((t1 - t0) / step)) + 1)
        found += [(v, at(np.array([x]))[0]) for v, x in _maxima(fn_t, t, floor)]
    return found


def _closest_approach(line, ray):
    """Per segment of ``line``: the fraction s in [0, 1] of its point nearest the ray
    ``o + t d`` (t >= 0), that distance [m] and the ray's t there (closest points of two
    lines, clamped to the segment and to t >= 0)."""
    p0 = line.points_m[:-1]
    seg = line.points_m[1:] - p0
    d, w0 = ray.direction, p0 - ray.origin_m
    aa = np.einsum("ij,ij->i", seg, seg)
    b, dd, e = seg @ d, np.einsum("ij,ij->i", w0, seg), w0 @ d
    den = aa - b * b  # |d| = 1
    with np.errstate(divide="ignore", invalid="ignore"):
        s = np.where(den > 1e-12 * aa, (b * e - dd) / den, 0.0)
    s = np.clip(np.nan_to_num(s), 0.0, 1.0)
    t = np.maximum(b * s + e, 0.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        s = np.clip(np.where(aa > 0, (t * b - dd) / aa, 0.0), 0.0, 1.0)  # back to the segment for the clamped t
    gap = np.linalg.norm(p0 + s[:, None] * seg - (ray.origin_m + t[:, None] * d), axis=1)
    return s, gap, t


def _line_candidates(line, rays, beam) -> np.ndarray:
    """Polyline parameters where a beam may cross ``line`` between its points, wherever
    the sampling leaves off: on each segment that passes within ``MARGIN_RADII`` beam
    radii of an axis ray, the point nearest the ray and ``CROSS_SAMPLES`` points each
    side of it every ``STEP_DIAMETERS`` beam diameters (the crossing of a beam's axis
    with the line is found analytically, however long the segment and narrow the beam)."""
    out = []
    seg_len = np.linalg.norm(np.diff(line.points_m, axis=0), axis=1)
    k = np.arange(-CROSS_SAMPLES, CROSS_SAMPLES + 1)
    for ray in rays:
        s, gap, t = _closest_approach(line, ray)
        width = np.asarray(beam.diameter_at(ray.range0_m + t), float)
        width = np.maximum(np.minimum(width, ray.min_step_m), 1e-9)
        near = np.flatnonzero((gap <= MARGIN_RADII * width / 2) & (seg_len > 0))
        for i in near:
            ds = STEP_DIAMETERS * width[i] / seg_len[i]
            out.append(i + np.clip(s[i] + k * ds, 0.0, 1.0))
    return np.concatenate(out) if out else np.zeros(0)


def _on_line(fn, line, floor, rays=(), beam=None):
    """(value, point) of the maxima of ``fn`` along a polyline: a uniform first pass and
    the analytic candidates of :func:`_line_candidates` for ``rays``."""
    n_seg = len(line.points_m) - 1
    per = int(max(2, min(SUBSAMPLES, MAX_CANDIDATES // n_seg)))  # long lines: fewer per segment
    t = np.linspace(0.0, n_seg, n_seg * per + 1)
    if beam is not None and rays:
        t = np.unique(np.concatenate([t, _line_candidates(line, rays, beam)]))
    return [(v, line.at(np.array([x]))[0]) for v, x in _maxima(lambda s: fn(line.at(s)), t, floor)]


def _group_near(scene, g):
    """``near(point)``: points of observer group ``g`` among which its ``NEIGHBOURS``
    nearest to ``point`` are. A grid's are generated in the index window around the
    point's grid coordinates (a grid's points are not stored: scenes.observers); other
    groups give all their points."""
    obs, spec = scene.observers, scene.spec.observers[g]
    rows = obs.group_rows(g)
    if spec.layout != "grid" or min(spec.counts) < 2:
        pts = obs.take(rows)
        return lambda point: pts
    nu, nv = spec.counts
    o, u, v = (np.asarray(x, float) for x in (spec.origin_m, spec.u_m, spec.v_m))
    o = o - scene.offset_m
    dims = slice(0, 2) if spec.eye_height_m is not None else slice(0, 3)
    m = np.stack([u[dims], v[dims]], axis=1)
    reach = int(np.ceil(np.sqrt(NEIGHBOURS))) + 1  # a window holding the nearest NEIGHBOURS nodes

    def near(point):
        a, b = np.linalg.lstsq(m, np.asarray(point, float)[dims] - o[dims], rcond=None)[0]
        iu0, iv0 = int(round(a * (nu - 1))), int(round(b * (nv - 1)))
        iu = np.arange(max(iu0 - reach, 0), min(iu0 + reach, nu - 1) + 1)
        iv = np.arange(max(iv0 - reach, 0), min(iv0 + reach, nv - 1) + 1)
        return obs.take(rows[(iv[:, None] * nu + iu[None, :]).ravel()])
    return near


def _new_crossings(fn, found, near):
    """The maxima of ``found`` ((value, point), highest first) that beat the group's
    ``NEIGHBOURS`` nearest points (among ``near(point)``) by more than ``GAIN`` and are
    not a higher one seen again (closer to it than a quarter of the way to the group's
    nearest point)."""
    kept = []
    for value, point in sorted(found, key=lambda x: -x[0]):
        group_points = near(point)
        d2 = np.einsum("ij,ij->i", group_points - point, group_points - point)
        nearest = np.argsort(d2)[:NEIGHBOURS]
        if value <= GAIN * float(fn(group_points[nearest]).max()):
            continue
        if all(np.linalg.norm(point - p) > 0.25 * np.sqrt(d2[nearest[0]]) for p in kept):
            kept.append(point)
    return kept


def add_crossings(scene, beam, spots, mu, mpe_w_m2, tracer, spill_s=None):
    """The scene with an observer point added at each beam crossing that falls between an
    observer group's points (see the module notes), and a one-line account. Crossings
    below ``FLOOR`` of the MPE (naked eye) are left out: even through optics of gain 1000
    they stay under a tenth of it. ``tracer`` answers ``first_hit`` against every
    object (the direct beam's shadows); ``spill_s``: the hottest point of the beam's
    spill in beam coordinates (:func:`hazard.pipeline.spill.hottest_spill_s`)."""
    if scene.observers is None or not len(scene.observers):
        return scene, "no observers"
    floor = FLOOR * mpe_w_m2
    surfaces, left_out = observer_surfaces(scene)
    added, said = [], []
    for g, name, surface in surfaces:
        near = _group_near(scene, g)
        for label, fn, rays in _sources(beam, spots, mu, tracer, spill_s, _group_apertures(scene, g)):
            found = (_on_line(fn, surface, floor, rays, beam) if isinstance(surface, Polyline) else _on_surface(fn, surface, rays, beam, floor))
            for point in _new_crossings(fn, found, near):
                added.append((g, name, point))
                said.append(f"{name}: the {label} crosses between its points at "
                            f"[{point[0]:.6g}, {point[1]:.6g}, {point[2]:.6g}] m (local; its value is the map's)")
    said += [f"not searched: {x}" for x in left_out]
    if not added:
        return scene, "; ".join(["no beam crosses an observer line, grid or shell between its points"] + said)
    return dataclasses.replace(scene, observers=_with_points(scene.observers, added)), "; ".join(said)


def _with_points(obs, added):
    """``obs`` with the points of ``added`` ((line group, line name, point) each), one new
    group per line, named ``<line>:crossing``, with the line's optics."""
    for g in dict.fromkeys(g for g, _, _ in added):  # in order of first appearance
        name = next(n for gg, n, _ in added if gg == g)
        points = [p for gg, _, p in added if gg == g]
        obs = obs.with_group(f"{name}:crossing", np.array(points), obs.optics[g] if g < len(obs.optics) else None)
    return obs
