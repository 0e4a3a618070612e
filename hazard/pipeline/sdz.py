"""Stage ``sdz``: the laser surface danger zone (LSDZ) of the direct beam on the ground.

Range practice (range-safety.md section 3; NAVFAC MIL-HDBK-1027/3B section 8, citing
MCO P3570.1A; MIL-HDBK-828B): the beam may point anywhere within its aiming error
around the aim (``[laser] pointing_error_rad``, a bound or ``pointing_error_sigmas``
standard deviations: the buffer angle theta_b) or within a ``[laser] sector`` widened
by theta_b. Along each direction the hazard reaches L = min(NOHD, the first backstop):
the direct-beam NOHD (with attenuation; :func:`hazard.physics.nohd.nohd_direct`), cut where the
ray meets the terrain or an occluder. The LSDZ is the ground projection of those
segments, widened by the beam's own hazardous half-width.

How it is computed, and what is conservative:

- directions: a pointing cone in rings every theta_b / 32; a sector widened by theta_b
  on the sphere (every direction within the angle theta_b of the sector, the buffer
  about every edge) in rows of elevation every theta_b / 4, each row from its exact
  first to its last bearing every theta_b / 4 in bearing (the spec's "azimuth steps of
  at most theta_b / 4"; :func:`scenes.geometry.widened_azimuths_rad`: beside a meridian
  arc at elevation E the row reaches asin(sin theta_b / cos E) beyond it, about
  theta_b / cos E, not theta_b), plus the rows where the caps about the corners are
  widest; at most ``MAX_RAYS`` (a coarser step is said);
- each direction is ray-cast (Embree) against the terrain and the occluders. Targets
  are not backstops: within its pointing error the beam can miss them;
- the zone is star-shaped about the laser's foot: around it, in bins of the largest
  angular gap between the sampled directions' bearings, each bin reaches the longest
  sampled reach of itself and its two neighbours, drawn as an outer polygon (its chords
  lie outside that arc); then widened by the beam's largest hazardous half-width,
  max over R of w(R) sqrt(ln(E(R) / MPE)) (:func:`hazard_half_width_m`);
- a sector's zone without the buffer is given too (``nominal``), so the buffer zone is
  the difference;
- each direction is stopped only where its whole hazardous cross-section is: the centre
  ray and 8 rays on the octagon around the hazardous disk |s| <= sqrt(ln(E_0 K / MPE))
  are cast (:func:`beam_stop_m`): a beam that clips a wall's top or a ridge goes on;
- an aim outside the declared sector is added to it (with its cone), and the scene warns;
- ``contained``: every direction ends on a backstop before its NOHD; a direction above
  the horizon that does not, and a zone leaving ``[range] boundary_m``, are said.
Not modelled: the Earth's curvature and refraction; nothing stops the beam beyond the
terrain's extent.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

from scenes.geometry import direction_in_sector, widened_azimuths_rad

from hazard.physics.beam import perp_basis
from hazard.pipeline.backstops import first_backstop_rays
from hazard.pipeline.pointing import aim_track_directions
from hazard.pipeline.spill import AidedNohd, direct_nohds

__all__ = ["DangerZone", "GroundZone", "AidedZone", "NominalZone", "SdzDirections", "MirrorReach", "MirrorBeam", "Directions", "pointing_directions", "bearing_vectors", "danger_zone", "zone_polygon", "MAX_RAYS"]

MAX_RAYS = 1_000_000  # directions cast per zone (a sector finer than this gets a coarser step, said)
CONE_STEP = 1.0 / 32  # cone: ring and arc step in buffer angles (area overestimate 0.5-2.2 %, 4 ms: README table)
SECTOR_STEP = 1.0 / 4  # sector: lattice step in buffer angles (range-safety.md 3: at most theta_b / 4)
SECTOR_STEP_NO_BUFFER_RAD = 1e-3  # sector without a pointing error: 1 mrad steps
UNBOUNDED_DRAW_M = 1e5  # an infinite NOHD's zone is drawn this far (its area and range are reported as inf)
BUFFER_QUAD_SEGS = 16  # segments per quarter circle of the widened zone's round corners


@dataclass(frozen=True, kw_only=True)
class MirrorReach:
    """How far a mirror beam reaches and whether it is contained (report.json
    ``sdz.mirror_beams[].aided``, and the naked-eye keys of ``sdz.mirror_beams[]``).

    Attributes
    ----------
    nohd_m : float
        The target's largest specular NOHD used for every sample ray [m].
    max_reach_m : float
        The farthest reach min(first backstop, NOHD) of its rays [m].
    contained : bool
        Every ray is stopped by a backstop before the NOHD (or the NOHD is 0).
    above_horizon : bool
        A ray not stopped rises above the horizon.
    leaves_boundary : bool or None
        A ray's ground track leaves the ``[range]`` boundary; None (absent): no ``[range]`` or NOHD 0.
    """

    nohd_m: float
    max_reach_m: float
    contained: bool
    above_horizon: bool
    leaves_boundary: bool | None = None

    ABSENT_WHEN_NONE: ClassVar[tuple[str, ...]] = ("leaves_boundary",)

    def to_dict(self) -> dict:
        out = {"nohd_m": self.nohd_m, "max_reach_m": self.max_reach_m, "contained": self.contained,
               "above_horizon": self.above_horizon}
        if self.leaves_boundary is not None:
            out["leaves_boundary"] = self.leaves_boundary
        return out


@dataclass(frozen=True, kw_only=True)
class MirrorBeam(MirrorReach):
    """One lit mirror's beam (:func:`hazard.pipeline.mirror_reach.mirror_beams`; report.json
    ``sdz.mirror_beams[]``), naked eye, and through the aid that reaches furthest.

    Attributes
    ----------
    target : str
        The mirror target's name.
    rays : int
        How many sample rays were cast.
    aided : MirrorReach or None
        The beam out to the largest aided specular NOHD; None (absent): no aid reaches further.
    """

    target: str
    rays: int
    aided: MirrorReach | None = None

    ABSENT_WHEN_NONE: ClassVar[tuple[str, ...]] = ("leaves_boundary", "aided")

    def to_dict(self) -> dict:
        out = {"target": self.target, "nohd_m": self.nohd_m, "max_reach_m": self.max_reach_m, "rays": self.rays,
               "contained": self.contained, "above_horizon": self.above_horizon}
        if self.leaves_boundary is not None:
            out["leaves_boundary"] = self.leaves_boundary
        if self.aided is not None:
            out["aided"] = self.aided.to_dict()
        return out


@dataclass(frozen=True)
class SdzDirections:
    """The directions the danger zone was cast over (report.json ``sdz.directions``).

    Attributes
    ----------
    kind : str
        What they cover: ``"aim"``, ``"cone"`` or ``"sector"``.
    aim_track : bool
        A slewing beam's track is among them.
    count : int
        How many directions were cast.
    step_rad : float
        The sampling step [rad].
    buffer_rad : float
        The buffer angle theta_b [rad].
    pointing_error_rad : float
        The scene's pointing error [rad].
    pointing_error_kind : str
        Whether it is a bound or standard deviations.
    pointing_error_sigmas : float or None
        How many standard deviations the buffer is (None: a bound).
    pointing_error_source : str
        Where the pointing error comes from, in words.
    """

    kind: str
    aim_track: bool
    count: int
    step_rad: float
    buffer_rad: float
    pointing_error_rad: float
    pointing_error_kind: str
    pointing_error_sigmas: float | None
    pointing_error_source: str

    def to_dict(self) -> dict:
        return {"kind": self.kind, "aim_track": self.aim_track, "count": self.count, "step_rad": self.step_rad,
                "buffer_rad": self.buffer_rad, "pointing_error_rad": self.pointing_error_rad,
                "pointing_error_kind": self.pointing_error_kind, "pointing_error_sigmas": self.pointing_error_sigmas,
                "pointing_error_source": self.pointing_error_source}


@dataclass(frozen=True, kw_only=True)
class GroundZone:
    """One danger zone on the ground in world coordinates (:func:`_zone_dict`; the zone keys of
    report.json ``sdz`` and of each ``sdz.aided[]``).

    Attributes
    ----------
    nohd_m : float
        The NOHD along every direction [m] (inf: unbounded).
    polygon_m : tuple of tuple of float
        The zone's outline, world x, y [m] (rounded to 1 mm).
    area_m2 : float
        Its area [m^2] (inf: unbounded; 0 for a NOHD of 0).
    unbounded : bool
        Some direction reaches an infinite NOHD without a backstop.
    max_range_m : float
        The farthest reach min(NOHD, first backstop) over the directions [m].
    hazard_half_width_m : float
        The beam's largest hazardous half-width the zone is widened by [m].
    contained : bool
        Every direction ends on a backstop before its NOHD.
    escaping_directions : int
        How many directions reach their NOHD without a backstop.
    above_horizon : bool
        One of those rises above the horizon.
    escaping_bearing_deg, escaping_elevation_deg : tuple of float or None
        ``[first, last]`` compass bearing [deg] and ``[low, high]`` elevation [deg] the escaping
        directions span (:func:`escaping_span_deg`); None (the keys absent): none escapes.
    leaves_boundary : bool or None
        The zone leaves the ``[range]`` boundary; None (absent): no ``[range]``.
    outside_boundary_m2 : float or None
        Its area outside the boundary [m^2]; None (absent): no ``[range]``.
    """

    nohd_m: float
    polygon_m: tuple[tuple[float, ...], ...]
    area_m2: float
    unbounded: bool
    max_range_m: float
    hazard_half_width_m: float
    contained: bool
    escaping_directions: int
    above_horizon: bool
    escaping_bearing_deg: tuple[float, ...] | None = None
    escaping_elevation_deg: tuple[float, ...] | None = None
    leaves_boundary: bool | None = None
    outside_boundary_m2: float | None = None

    ABSENT_WHEN_NONE: ClassVar[tuple[str, ...]] = ("escaping_bearing_deg", "escaping_elevation_deg", "leaves_boundary",
                                                   "outside_boundary_m2")

    def zone_dict(self) -> dict:
        """The zone's keys as report.json writes them (the optional ones only when set)."""
        out = {"nohd_m": self.nohd_m, "polygon_m": [list(p) for p in self.polygon_m], "area_m2": self.area_m2,
               "unbounded": self.unbounded, "max_range_m": self.max_range_m, "hazard_half_width_m": self.hazard_half_width_m,
               "contained": self.contained, "escaping_directions": self.escaping_directions, "above_horizon": self.above_horizon}
        if self.escaping_bearing_deg is not None:
            out["escaping_bearing_deg"] = list(self.escaping_bearing_deg)
        if self.escaping_elevation_deg is not None:
            out["escaping_elevation_deg"] = list(self.escaping_elevation_deg)
        if self.leaves_boundary is not None:
            out["leaves_boundary"] = self.leaves_boundary
        if self.outside_boundary_m2 is not None:
            out["outside_boundary_m2"] = self.outside_boundary_m2
        return out


@dataclass(frozen=True, kw_only=True)
class AidedZone(GroundZone):
    """The danger zone through one optical aid (report.json ``sdz.aided[]``: the aid's keys,
    then the zone's).

    Attributes
    ----------
    aid : AidedNohd
        The aid and its direct-beam NOHD [m] (:class:`hazard.pipeline.spill.AidedNohd`; its
        ``nohd_m`` is the zone's).
    """

    aid: AidedNohd

    def to_dict(self) -> dict:
        return {**self.aid.to_dict(), **self.zone_dict()}


@dataclass(frozen=True)
class NominalZone:
    """A sector's zone without the pointing buffer (report.json ``sdz.nominal``).

    Attributes
    ----------
    polygon_m : tuple of tuple of float
        Its outline, world x, y [m].
    area_m2 : float
        Its area [m^2] (inf: unbounded).
    """

    polygon_m: tuple[tuple[float, ...], ...]
    area_m2: float

    def to_dict(self) -> dict:
        return {"polygon_m": [list(p) for p in self.polygon_m], "area_m2": self.area_m2}


@dataclass(frozen=True, kw_only=True)
class DangerZone(GroundZone):
    """The laser surface danger zone of the direct beam (:func:`danger_zone`; report.json ``sdz``:
    ``directions``, the naked-eye zone's keys (:class:`GroundZone`), ``nominal``, ``aided``,
    ``mirror_beams``).

    Attributes
    ----------
    directions : SdzDirections
        The directions cast.
    nominal : NominalZone or None
        A sector with a buffer: the sector itself; None (absent) otherwise.
    aided : tuple of AidedZone
        One per optical aid reaching further than the naked eye (may be empty).
    mirror_beams : tuple of MirrorBeam or None
        Each lit mirror's beam (:func:`hazard.pipeline.mirror_reach.mirror_beams`, merged in from
        the ``mirror_beams`` stage by :func:`dataclasses.replace`); None (absent): that stage was skipped.
    """

    directions: SdzDirections
    nominal: NominalZone | None = None
    aided: tuple[AidedZone, ...] = ()
    mirror_beams: tuple[MirrorBeam, ...] | None = None

    ABSENT_WHEN_NONE: ClassVar[tuple[str, ...]] = GroundZone.ABSENT_WHEN_NONE + ("nominal", "mirror_beams")

    def to_dict(self) -> dict:
        out = {"directions": self.directions.to_dict(), **self.zone_dict()}
        if self.nominal is not None:
            out["nominal"] = self.nominal.to_dict()
        out["aided"] = [a.to_dict() for a in self.aided]
        if self.mirror_beams is not None:
            out["mirror_beams"] = [m.to_dict() for m in self.mirror_beams]
        return out


@dataclass(frozen=True)
class Directions:
    """Unit beam directions (N, 3) the laser may point in, the sampling step [rad], what
    they cover (``aim``, ``cone`` or ``sector``) and the buffer angle theta_b [rad]."""

    unit: np.ndarray
    step_rad: float
    kind: str
    buffer_rad: float
    aim_track: bool = False  # a slewing beam's track is among the directions


def bearing_vectors(azimuth_rad, elevation_rad) -> np.ndarray:
    """Unit vectors (N, 3) from compass bearings (clockwise from +y, north) and elevations
    (broadcast against each other)."""
    az, el = np.broadcast_arrays(np.asarray(azimuth_rad, float), np.asarray(elevation_rad, float))
    return np.stack([np.sin(az) * np.cos(el), np.cos(az) * np.cos(el), np.sin(el)], axis=-1).reshape(-1, 3)


def _cone_basis(axis):
    """Two unit vectors across ``axis``: e1 horizontal, e2 rising (so the rings' samples
    at psi = 0, pi/2, pi, 3 pi/2 are the cone's extreme bearings and elevations)."""
    e1 = np.cross(axis, [0.0, 0.0, 1.0])
    if np.linalg.norm(e1) < 1e-9:  # a vertical beam: any pair will do
        return perp_basis(axis)
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(e1, axis)
    return e1, (e2 if e2[2] >= 0 else -e2) / np.linalg.norm(e2)


def cone_directions(axis, half_angle, step) -> np.ndarray:
    """Unit directions (N, 3) filling a cone of ``half_angle`` [rad] about ``axis``: rings
    every ``step`` [rad], each with a multiple of 4 samples starting at the horizontal offset."""
    e1, e2 = _cone_basis(axis)
    out = [axis[None]]
    n_r = max(1, math.ceil(half_angle / step))
    for k in range(1, n_r + 1):
        rho = half_angle * k / n_r
        psi = np.linspace(0.0, 2 * np.pi, 4 * max(2, math.ceil(2 * np.pi * math.sin(rho) / step / 4)), endpoint=False)
        out.append(math.cos(rho) * axis + math.sin(rho) * (np.cos(psi)[:, None] * e1 + np.sin(psi)[:, None] * e2))
    return np.vstack(out)


def _sector_elevations(sector, b, step) -> np.ndarray:
    """Rows of elevation [rad] of the sector widened by b: every ``step`` over [E0 - b,
    E1 + b] (within +-90 deg), plus the rows where its corners' caps are widest in
    bearing, asin(sin E / cos b) (:func:`scenes.geometry.widened_azimuths_rad`)."""
    e0, e1 = (math.radians(x) for x in sector.elevation_deg)
    lo, hi = max(e0 - b, -np.pi / 2), min(e1 + b, np.pi / 2)
    rows = np.linspace(lo, hi, max(2, math.ceil((hi - lo) / step) + 1)) if hi > lo else np.array([lo])
    tips = [math.asin(max(-1.0, min(1.0, math.sin(e) / math.cos(b)))) for e in (e0, e1)] if b > 0 else []
    return np.unique(np.concatenate([rows, [t for t in tips if lo <= t <= hi]]))


def _sector(sector, buffer_rad) -> tuple[np.ndarray, float]:
    """The directions within ``buffer_rad`` of the sector on the sphere, and the step: rows
    of elevation (:func:`_sector_elevations`), each from its exact first to its last
    bearing (:func:`scenes.geometry.widened_azimuths_rad`) every ``step`` in bearing. A
    lattice over more than ``MAX_RAYS`` directions gets a coarser step."""
    b = buffer_rad
    step = SECTOR_STEP * b if b > 0 else SECTOR_STEP_NO_BUFFER_RAD
    for _ in range(3):
        el = _sector_elevations(sector, b, step)
        lo, hi = widened_azimuths_rad(sector, b, el)
        keep = hi >= lo
        el, lo, span = el[keep], lo[keep], np.minimum(hi[keep] - lo[keep], 2 * np.pi)
        whole = span >= 2 * np.pi
        count = np.where(whole, np.maximum(4, np.ceil(span / step)), np.maximum(1, np.ceil(span / step)) + 1).astype(int)
        if count.sum() <= MAX_RAYS:
            break
        step *= math.sqrt(count.sum() / MAX_RAYS) * 1.01
    row = np.repeat(np.arange(len(el)), count)
    k = np.arange(len(row)) - np.repeat(np.cumsum(count) - count, count)
    frac = k / np.where(whole, count, np.maximum(count - 1, 1))[row]
    return bearing_vectors(lo[row] + span[row] * frac, el[row]), step


def pointing_directions(scene) -> Directions:
    """The directions the beam may point in (see the module notes)."""
    laser = scene.spec.laser
    b = laser.pointing_buffer_rad
    axis = np.asarray(scene.laser_direction, float)
    if laser.sector is not None:
        unit, step = _sector(laser.sector, b)
        if not direction_in_sector(axis, laser.sector, b):  # the aim must be in the zone whatever the sector says
            unit = np.vstack([unit, cone_directions(axis, b, CONE_STEP * b) if b > 0 else axis[None]])
        return _with_aim_track(scene, Directions(unit, step, "sector", b))
    if b <= 0:
        return _with_aim_track(scene, Directions(axis[None], 0.0, "aim", 0.0))
    return _with_aim_track(scene, Directions(cone_directions(axis, b, CONE_STEP * b), CONE_STEP * b, "cone", b))


def _with_aim_track(scene, d: Directions) -> Directions:
    """``d`` and a slewing beam's track (:func:`hazard.pipeline.pointing.aim_track_directions`),
    each track direction widened across the track by the buffer (the band the cones of
    the track's directions sweep), the track's ends by their cones."""
    b = d.buffer_rad
    track, gap = aim_track_directions(scene, max(CONE_STEP * b, 1e-5) if b > 0 else None)
    if not len(track):
        return d
    parts = [d.unit, track]
    if b > 0 and len(track) > 1:
        along = np.gradient(track, axis=0)
        across = np.cross(along, track)
        across /= np.maximum(np.linalg.norm(across, axis=1, keepdims=True), 1e-300)
        for f in np.linspace(-1.0, 1.0, 2 * max(2, math.ceil(1 / CONE_STEP / 4)) + 1):
            v = np.cos(f * b) * track + np.sin(f * b) * across
            parts.append(v / np.linalg.norm(v, axis=1, keepdims=True))
        parts += [cone_directions(track[0], b, CONE_STEP * b), cone_directions(track[-1], b, CONE_STEP * b)]
    unit = np.vstack(parts)
    return Directions(unit, max(d.step_rad, gap), d.kind, b, aim_track=True)


def _envelope(phi, reach) -> tuple[np.ndarray, bool]:
    """Outer polygon vertices (K, 2) about the origin of a star-shaped zone given by
    sampled bearings ``phi`` [rad] and reaches [m] (see the module notes), and whether it
    goes all the way round (else the origin closes it).

    Bins of width w (the largest gap between neighbouring bearings inside the zone) each
    reach the longest reach of itself and its neighbours, ``near``; the vertex on the
    edge between two bins sits at the larger of their ``near`` over cos(w / 2), so the
    chord between two edges stays outside the arc of the bin's ``near``."""
    order = np.argsort(phi)
    phi, reach = phi[order], reach[order]
    gaps = np.diff(np.concatenate([phi, [phi[0] + 2 * np.pi]]))
    g = int(np.argmax(gaps))
    round_ = bool(gaps[g] <= np.pi / 8)
    if round_:
        start, width = phi[0], float(gaps[g])
        n_bins = math.ceil(2 * np.pi / width)
    else:
        start = phi[(g + 1) % len(phi)]
        width = float(np.delete(gaps, g).max())
        n_bins = math.floor((2 * np.pi - gaps[g]) / max(width, 1e-12)) + 1 if width > 0 else 1
    width = max(width, 1e-9)
    k = np.minimum(((phi - start) % (2 * np.pi)) // width, n_bins - 1).astype(int)
    r = np.zeros(n_bins)
    np.maximum.at(r, k, reach)
    if round_:
        near = np.maximum(r, np.maximum(np.roll(r, 1), np.roll(r, -1)))
        radius = np.maximum(near, np.roll(near, 1))  # edge j lies between bins j - 1 and j
        edges = start + width * np.arange(n_bins)
    else:
        pad = np.concatenate([[0.0], r, [0.0]])
        near = np.maximum(pad[1:-1], np.maximum(pad[:-2], pad[2:]))
        padn = np.concatenate([[0.0], near, [0.0]])
        radius = np.maximum(padn[:-1], padn[1:])  # n_bins + 1 edges
        edges = start + width * np.arange(n_bins + 1)
    radius = radius / math.cos(width / 2)  # width < pi: the largest gap, outside the zone, is larger
    return np.stack([radius * np.sin(edges), radius * np.cos(edges)], axis=1), round_


def zone_polygon(foot_xy, ends_xy, pad_m):
    """The ground zone (shapely polygon) swept by segments from ``foot_xy`` to each of
    ``ends_xy`` (N, 2), as an outer envelope, widened by ``pad_m``."""
    from shapely.geometry import LineString, Point, Polygon

    pad_m = pad_m / math.cos(math.pi / (4 * BUFFER_QUAD_SEGS))  # shapely's round caps are inscribed polygons: circumscribe them

    rel = np.asarray(ends_xy, float) - foot_xy
    reach = np.hypot(rel[:, 0], rel[:, 1])
    far = reach > 1e-9 * max(float(reach.max()), 1.0)
    if not far.any():
        return Point(foot_xy).buffer(pad_m, quad_segs=BUFFER_QUAD_SEGS)
    phi = np.arctan2(rel[far, 0], rel[far, 1])
    if np.ptp(phi) == 0:
        return LineString([foot_xy, foot_xy + rel[far][np.argmax(reach[far])]]).buffer(pad_m, quad_segs=BUFFER_QUAD_SEGS)
    pts, round_ = _envelope(phi, reach[far])
    ring = pts + foot_xy if round_ else np.vstack([[0.0, 0.0], pts]) + foot_xy
    poly = Polygon(ring)
    if not poly.is_valid:
        poly = poly.buffer(0)
    return poly.buffer(pad_m, quad_segs=BUFFER_QUAD_SEGS)


def hazard_half_width_m(laser, power_w, mpe_w_m2, length_m, mu=0.0) -> float:
    """The beam's largest hazardous half-width [m] out to ``length_m``: the largest r
    with E(R) exp(-r^2 / w(R)^2) >= MPE, i.e. max over R of w(R) sqrt(ln(E(R) / MPE)),
    E(R) = 4 P exp(-mu R) / (pi (a + R phi)^2), w = (a + R phi) / 2 (range-safety.md 1;
    without attenuation the maximum is sqrt(P / (pi e MPE)) where D(R)^2 = 4 P / (pi e
    MPE)). The maximum over the range is where it peaks (:func:`_widest_diameter_m`,
    exact) clipped to [0, ``length_m``], or an end; raised by 1e-6 of itself."""
    a, phi = laser.beam_diameter_m, laser.divergence_rad

    def half(r):
        d = a + r * phi
        ln = math.log(4 * power_w / (math.pi * d * d * mpe_w_m2)) - mu * r
        return d / 2 * math.sqrt(ln) if ln > 0 else 0.0

    best = max(half(0.0), half(length_m))
    if length_m > 0 and phi > 0:
        r_peak = (_widest_diameter_m(a, phi, power_w, mpe_w_m2, mu) - a) / phi
        best = max(best, half(min(max(r_peak, 0.0), length_m)))
    return best * (1 + 1e-6)


def _widest_diameter_m(a, phi, power_w, mpe_w_m2, mu) -> float:
    """The beam diameter d = a + R phi [m] where w sqrt(ln(E / MPE)) peaks: with
    C = ln(4 P / (pi MPE)) + mu a / phi and k = mu / phi, d^2 (C - 2 ln d - k d) has its
    one stationary point (a maximum: the bracket falls with d) at 4 ln d + 3 k d = 2 C - 2;
    d = exp((C - 1) / 2) without attenuation, else Newton's method on u = ln d from the
    attenuation-free root (the left side is increasing and convex in u, so the iterates
    fall monotonically to the root; no scipy.optimize import, 0.3 s)."""
    k = mu / phi
    rhs = 2 * (math.log(4 * power_w / (math.pi * mpe_w_m2)) + k * a) - 2
    u = rhs / 4
    if k > 0:
        for _ in range(200):
            step = (4 * u + 3 * k * math.exp(u) - rhs) / (4 + 3 * k * math.exp(u))
            u -= step
            if abs(step) <= 4e-16 * max(abs(u), 1.0):
                break
    return math.exp(u)


EDGE_RAYS = 8  # rays around each direction's hazardous cross-section (a circumscribed octagon)


def beam_stop_m(laser, origin, dirs, ray_scene, n_targets, s_max) -> np.ndarray:
    """Distance [m] along each direction to where its whole hazardous cross-section is
    stopped (inf: some of it never is). The beam pointed along d is the Gaussian of the
    laser's a and phi; its hazardous part lies within |s| <= ``s_max`` = sqrt(ln(E_0 K /
    MPE)) (E_0 the aperture's peak; it shrinks with range, so this bounds it). Rays at the
    vertices of the octagon circumscribing that disk (|s| = s_max / cos(pi / 8)) and the
    centre ray are cast: a backstop that stops all of them stops the disk where its edge
    is straight across the beam (a wall's top, a ridge's crest); the direction's distance
    is the farthest of theirs. A backstop the beam only clips lets it go on."""
    dirs = np.asarray(dirs, float)
    n = len(dirs)
    stop = _first_backstop(origin, dirs, ray_scene, n_targets)
    if ray_scene is None or s_max <= 0:
        return stop
    ref = np.where(np.abs(dirs[:, :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
    e1 = np.cross(dirs, ref)
    e1 /= np.linalg.norm(e1, axis=1, keepdims=True)
    e2 = np.cross(dirs, e1)
    psi = 2 * np.pi * np.arange(EDGE_RAYS) / EDGE_RAYS
    r = s_max / math.cos(np.pi / EDGE_RAYS)
    s1, s2 = r * np.cos(psi), r * np.sin(psi)  # (E,)
    tr = s1[None, :, None] * e1[:, None, :] + s2[None, :, None] * e2[:, None, :]  # (N, E, 3)
    o = origin + tr * (laser.beam_diameter_m / 2)
    d = dirs[:, None, :] + tr * (laser.divergence_rad / 2)
    edge = first_backstop_rays(o.reshape(-1, 3), d.reshape(-1, 3), ray_scene, n_targets).reshape(n, EDGE_RAYS)
    return np.maximum(stop, edge.max(axis=1))


def _first_backstop(origin, dirs, ray_scene, n_targets, max_passes=64) -> np.ndarray:
    """Distance [m] to the first terrain or occluder hit along each direction (inf: none),
    through the targets (rays that meet a target go on from just past it)."""
    return first_backstop_rays(np.broadcast_to(origin, np.shape(dirs)), dirs, ray_scene, n_targets, max_passes)


@dataclass
class Zone:
    """One LSDZ: its polygon (local, shapely), NOHD [m], and per direction the reach [m]
    and whether a backstop stops it."""

    polygon: Any  # shapely Polygon
    nohd_m: float
    reach_m: np.ndarray
    stopped: np.ndarray
    half_width_m: float


def _zone(scene, dirs, backstop_m, nohd_m, power_w, mpe_w_m2, mu) -> Zone:
    """The zone out to min(backstop, NOHD) along each direction, however far. An infinite
    NOHD (a collimated beam in clear air) is drawn to ``UNBOUNDED_DRAW_M`` (or the farthest
    finite reach) and its area and range stay infinite."""
    laser, origin = scene.spec.laser, np.asarray(scene.laser_position_m, float)
    reach = np.minimum(backstop_m, nohd_m)
    # a finite reach is drawn whole (a 237 km aided zone was cut at 100 km, its area with it);
    # an infinite one at UNBOUNDED_DRAW_M or the farthest finite reach, whichever is farther
    finite = reach[np.isfinite(reach)]
    draw_inf = max(UNBOUNDED_DRAW_M, float(finite.max()) if len(finite) else 0.0)
    drawn = np.where(np.isfinite(reach), reach, draw_inf)
    ends = origin + dirs * drawn[:, None]
    half = hazard_half_width_m(laser, power_w, mpe_w_m2, float(drawn.max()), mu)
    # an infinite NOHD is never reached by a backstop at inf; a zero NOHD (the beam below the
    # MPE from the aperture on) has nothing hazardous to stop
    stopped = (nohd_m <= 0) | (np.isfinite(backstop_m) & (backstop_m <= nohd_m))
    return Zone(zone_polygon(origin[:2], ends[:, :2], half + 1e-9), nohd_m, reach, stopped, half)


def _zone_fields(scene, z: Zone, dirs, boundary) -> dict:
    """A zone's :class:`GroundZone` fields (world coordinates)."""
    poly = z.polygon
    ring = np.asarray(poly.exterior.coords) + scene.offset_m[:2]
    escape = ~z.stopped
    unbounded = bool(np.isinf(z.reach_m).any())
    area = math.inf if unbounded else (float(poly.area) if z.nohd_m > 0 else 0.0)  # NOHD 0: only the 1e-9 m pad is drawn
    out = {"nohd_m": z.nohd_m, "polygon_m": tuple(tuple(p) for p in ring.round(3).tolist()), "area_m2": area,
           "unbounded": unbounded,
           "max_range_m": float(z.reach_m.max()), "hazard_half_width_m": z.half_width_m, "contained": bool(z.stopped.all()),
           "escaping_directions": int(escape.sum()), "above_horizon": bool(np.any(escape & (dirs[:, 2] > 0)))}
    if escape.any():  # which way the zone escapes: said with every "NOT contained"
        bearing, elevation = escaping_span_deg(dirs[escape])
        out["escaping_bearing_deg"], out["escaping_elevation_deg"] = tuple(bearing), tuple(elevation)
    if boundary is not None:
        outside = poly.difference(boundary)
        out["leaves_boundary"] = bool(outside.area > 0)
        out["outside_boundary_m2"] = math.inf if unbounded and outside.area > 0 else float(outside.area)
    return out


def escaping_span_deg(dirs) -> tuple[list, list]:
    """The compass bearings [deg, clockwise from north] and elevations [deg] a set of unit
    directions (N, 3) spans: ``[first, last]`` bearing going clockwise around the largest
    gap between them (so a span across north reads e.g. [350, 10]), ``[low, high]``
    elevation."""
    bearing = np.sort(np.degrees(np.arctan2(dirs[:, 0], dirs[:, 1])) % 360.0)
    gaps = np.diff(np.concatenate([bearing, bearing[:1] + 360.0]))
    k = int(np.argmax(gaps))  # the span starts after the largest gap
    first, last = bearing[(k + 1) % len(bearing)], bearing[k]
    elevation = np.degrees(np.arcsin(np.clip(dirs[:, 2], -1.0, 1.0)))
    return [round(float(first), 3), round(float(last), 3)], [round(float(elevation.min()), 3), round(float(elevation.max()), 3)]


def boundary_polygon(scene):
    """The range boundary (shapely polygon, local coordinates), or None without a [range]."""
    from shapely.geometry import Polygon

    r = scene.spec.range
    if r is None:
        return None
    b = Polygon(np.asarray(r.boundary_m, float) - scene.offset_m[:2])
    return b if b.is_valid else b.buffer(0)


def danger_zone(scene, mpe_w_m2, mu, aids, ray_scene=None) -> DangerZone:
    """The LSDZ of the direct beam, naked and through each optical aid (report.json
    ``sdz``; see the module notes). ``ray_scene``: the analysis' ray scene (targets,
    occluders, terrain), None when the scene has no terrain and no occluders."""
    laser = scene.spec.laser
    d = pointing_directions(scene)
    power = laser.average_power_w
    naked, aided = direct_nohds(laser, power, mpe_w_m2, mu, aids)
    gain = max([1.0] + [a.gain for a in aided])  # the widest hazardous beam: one cast serves every zone
    s_max = math.sqrt(max(math.log(4 * power * gain / (math.pi * laser.beam_diameter_m ** 2 * mpe_w_m2)), 0.0))
    origin = np.asarray(scene.laser_position_m, float)
    backstop_m = beam_stop_m(laser, origin, d.unit, ray_scene, len(scene.targets), s_max)
    boundary = boundary_polygon(scene)
    dirs = SdzDirections(kind=d.kind, aim_track=d.aim_track, count=int(len(d.unit)), step_rad=d.step_rad, buffer_rad=d.buffer_rad,
                         pointing_error_rad=laser.pointing_error_rad, pointing_error_kind=laser.pointing_error_kind,
                         pointing_error_sigmas=laser.pointing_error_sigmas, pointing_error_source=laser.pointing_error_source)
    naked_zone = _zone_fields(scene, _zone(scene, d.unit, backstop_m, naked, power, mpe_w_m2, mu), d.unit, boundary)
    nominal = None
    if d.kind == "sector" and d.buffer_rad > 0:  # the sector itself, without the buffer (drawn in the plan view)
        unit, _ = _sector(laser.sector, 0.0)
        stop = beam_stop_m(laser, origin, unit, ray_scene, len(scene.targets), s_max)
        z0 = _zone(scene, unit, stop, naked, power, mpe_w_m2, mu)
        nominal = NominalZone(polygon_m=tuple(tuple(p) for p in (np.asarray(z0.polygon.exterior.coords) + scene.offset_m[:2]).round(3).tolist()),
                              area_m2=math.inf if np.isinf(z0.reach_m).any() else float(z0.polygon.area))
    aided_zones = tuple(AidedZone(aid=a, **_zone_fields(scene, _zone(scene, d.unit, backstop_m, a.nohd_m, power * a.gain, mpe_w_m2, mu),
                                                         d.unit, boundary)) for a in aided)
    return DangerZone(directions=dirs, nominal=nominal, aided=aided_zones, **naked_zone)
