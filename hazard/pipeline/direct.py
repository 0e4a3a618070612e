"""Stage ``direct``: the laser's own beam at the observers (spec `range-safety.md` sections 2 and 10).

An observer in the beam receives the Gaussian profile at its range (rays from the
virtual point source, :class:`hazard.physics.beam.BeamGeometry`):
``E = P / (pi w(z)^2) exp(-|s|^2) sqrt(1 + |s|^2 phi^2 / 4) exp(-mu L)`` with ``s`` its
transverse position in units of the 1/e radius ``w(z) = (a + z phi) / 2`` and ``L`` the
path from the aperture (Beer-Lambert once): the point value. The verdict compares the
MPE with the power through the limiting aperture (7 mm at 400-1400 nm; ANSI Z136.1-2014
sec. 8.3 / Table 8, IEC 60825-1:2014 Table A.5) centred on the eye, or through an optical
aid's collecting disk ``min(D_o, 7 mm M)`` delivered into the 7 mm pupil
(:func:`hazard.physics.aperture.aperture_irradiance_w_m2`: exact Marcum-Q fraction of the
Gaussian at offset ``|s| w`` from the axis, times the same tilt and attenuation). Beside
a beam narrower than the aperture that exceeds the point value by orders of magnitude;
on the axis of such a beam it is below it (the standard's quantity). Nothing reaches
the eye when any object (target, occluder, terrain) lies on the ray between the
aperture and the eye.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hazard.physics.aperture import Apertures, aperture_irradiance_w_m2

__all__ = ["BeamAt", "DirectBeam", "beam_at", "direct_beam", "gaussian_aperture_w_m2", "rim_clear", "with_pointing"]

APERTURE_PLANE_TOL_M = 1e-9  # a point this close to the aperture plane is on it [m]


@dataclass
class DirectBeam:
    """Per observer the direct-beam irradiance [W/m^2] the verdict uses (through the
    limiting aperture or the aid's collecting disk, attenuation and line of sight
    applied), the point value at the eye (``point_w_m2``, no aid), the aperture's
    diameter [m], and how many observers the beam reaches and how many it would reach
    but something blocks. With a pointing error or sector, ``irradiance_w_m2`` is the
    largest over the directions the beam may point in (:mod:`hazard.pipeline.pointing`)
    and ``at_aim_w_m2`` the nominal aim's; ``raised``: observers the pointing raised."""

    irradiance_w_m2: np.ndarray
    reached: int
    blocked: int
    at_aim_w_m2: np.ndarray | None = None
    raised: int = 0
    point_w_m2: np.ndarray | None = None
    aperture_m: np.ndarray | None = None

    @property
    def detail(self) -> str:
        top = float(self.irradiance_w_m2.max()) if len(self.irradiance_w_m2) else 0.0
        text = (f"{self.reached} observer(s) with a clear line into the beam (E > 0, at most {top:.4g} W/m^2 through the "
                f"limiting aperture), {self.blocked} more behind something that blocks it (Gaussian profile at each range, "
                f"attenuation; power through the limiting aperture or the aid's collecting disk, ANSI Z136.1-2014 sec. 8.3)")
        if self.point_w_m2 is not None and self.aperture_m is not None and len(self.aperture_m):
            up = int(np.count_nonzero(self.irradiance_w_m2 > self.point_w_m2))
            text += (f"; aperture {float(self.aperture_m.min()) * 1e3:.4g}-{float(self.aperture_m.max()) * 1e3:.4g} mm, "
                     f"{up} observer(s) above their point value")
        if self.at_aim_w_m2 is not None:
            text += (f"; over the pointing error / sector (the worst direction at each observer; terrain and occluders "
                     f"block it, targets do not): {self.raised} observer(s) get more than at the aim; "
                     f"reflections are for the nominal aim only")
        return text


def with_pointing(d: DirectBeam, scene, beam, observers, mu, ray_scene, apertures: Apertures) -> DirectBeam:
    """``d`` with each observer's direct beam raised to its worst over the directions the
    beam may point in (:func:`hazard.pipeline.pointing.pointing_worst_w_m2`)."""
    from hazard.pipeline.pointing import pointing_worst_w_m2

    def through(rows, point_w_m2, axial_m, offset_m, path_m):
        return gaussian_aperture_w_m2(beam, axial_m, offset_m, path_m, mu, apertures.take(rows))

    worst, point = pointing_worst_w_m2(scene, beam, observers, mu, ray_scene, through)
    total = np.maximum(d.irradiance_w_m2, worst)
    at_point = np.maximum(d.point_w_m2, point) if d.point_w_m2 is not None else point
    return DirectBeam(total, int(np.count_nonzero(total)), d.blocked, d.irradiance_w_m2, int((worst > d.irradiance_w_m2).sum()),
                      at_point, d.aperture_m)


def gaussian_aperture_w_m2(beam, axial_m, offset_m, path_m, mu, apertures: Apertures) -> np.ndarray:
    """The beam's irradiance through each observer's aperture [W/m^2]
    (:func:`hazard.physics.aperture.aperture_irradiance_w_m2`) at axial distance ``axial_m``,
    ``offset_m`` from the axis, ``path_m`` from the aperture (attenuation), with the
    ray tilt ``sqrt(1 + |s|^2 phi^2 / 4)`` of the point value at the eye."""
    w = beam.diameter_at(np.asarray(axial_m, float)) / 2
    s2 = (np.asarray(offset_m, float) / w) ** 2
    power = beam.power_w * np.exp(-mu * np.asarray(path_m, float)) * np.sqrt(1.0 + s2 * (beam.divergence_rad / 2) ** 2)
    return aperture_irradiance_w_m2(power, w, offset_m, apertures)


@dataclass
class BeamAt:
    """The unobstructed beam at points: ``rows`` of the points it reaches (on or in front
    of the aperture plane, irradiance above floating-point zero, or within ``reach_m`` of
    such a point), their irradiance [W/m^2] with attenuation along the ray, the ray's
    aperture point [m], its path to the point [m], the axial distance [m] and the distance
    from the axis [m]."""

    rows: np.ndarray
    irradiance_w_m2: np.ndarray
    origin_m: np.ndarray
    path_m: np.ndarray
    axial_m: np.ndarray
    offset_m: np.ndarray | None = None


_UNDERFLOW_S = 27.3  # exp(-27.3^2) < 1e-323: a point farther out (units of w) gets exactly 0
_EXP_ZERO = 746.0  # exp(-x) is exactly 0.0 in float64 for x >= this (the smallest subnormal is exp(-744.44))


def beam_at(beam, points_m, mu, reach_m=0.0) -> BeamAt:
    """The Gaussian beam at points (N, 3), nothing in the way (see the module notes);
    ``reach_m``: also the points whose point value underflows but which lie within that
    distance of where it does not (an aperture there still collects power)."""
    p = np.asarray(points_m, float).reshape(-1, 3)
    s, z = beam.to_s(p)
    # z >= 0: a point on the aperture plane is in the beam as it leaves (z = 0, irradiance
    # P / (pi w0^2) exp(-|s|^2)); behind it (z < 0) the laser emits nothing. "On the plane"
    # within APERTURE_PLANE_TOL_M: rounding puts a point given on it 1e-17 m either side.
    z = np.where(np.abs(z) <= APERTURE_PLANE_TOL_M, 0.0, z)
    s2 = s[:, 0] * s[:, 0] + s[:, 1] * s[:, 1]  # (s ** 2).sum(axis=1), bit for bit
    inside = np.isfinite(z) & (z >= 0) & np.isfinite(s[:, 0]) & np.isfinite(s[:, 1])
    # the point value is exactly 0 where exp(-|s|^2) underflows (|s|^2 >= _EXP_ZERO): only the
    # other rows, and those within reach of the beam, are evaluated (the same values)
    near = inside & (s2 < _EXP_ZERO)
    if reach_m > 0:
        far = np.flatnonzero(inside & ~near)  # (behind the laser the beam's width is not defined)
        with np.errstate(divide="ignore"):  # a zero width (a focus): within reach, kept
            near[far] = np.sqrt(s2[far]) - reach_m / (beam.diameter_at(z[far]) / 2) < _UNDERFLOW_S
    idx = np.flatnonzero(near)
    if len(idx) < len(p):  # gathers only where some point drops out (the values are the same)
        s, z, p, s2 = s[idx], z[idx], p[idx], s2[idx]
    e = beam.irradiance_w_m2(s, z)
    w = beam.diameter_at(z) / 2
    r = np.sqrt(s2)  # |s|, from the squares above (not summed again)
    live = e > 0  # exp(-|s|^2) underflows to 0 only far outside the beam
    if reach_m > 0:
        live |= r - reach_m / w < _UNDERFLOW_S
    if not live.all():
        idx, e, w, r, s, z, p = idx[live], e[live], w[live], r[live], s[live], z[live], p[live]
    o, _ = beam.rays(s)
    dist = np.linalg.norm(p - o, axis=1)
    return BeamAt(idx, e * np.exp(-mu * dist), o, dist, z, r * w)


def clear_of_objects(at: BeamAt, points_m, tracer) -> np.ndarray:
    """Per row of ``at``: no object stands between the ray's origin and the point."""
    p = np.asarray(points_m, float).reshape(-1, 3)[at.rows]
    clear = np.ones(len(p), bool)  # a point on the aperture itself (no path) has nothing in between
    far = np.flatnonzero(at.path_m > APERTURE_PLANE_TOL_M)
    if len(far):
        hits = tracer.first_hit(at.origin_m[far], p[far] - at.origin_m[far])
        clear[far] = ~(hits.hit & (hits.t < at.path_m[far] * (1 - 1e-9)))
    return clear


RIM_POINTS = 8  # points on the aperture's rim tried when the line to its centre is blocked


def rim_clear(origin_m, points_m, radius_m, tracer, n=RIM_POINTS) -> np.ndarray:
    """Per eye whose own line is blocked: is the line from the beam's origin to any of
    ``n`` points on its aperture's rim (radius ``radius_m``, normal to the line) clear?
    Then part of the aperture is lit and the eye is taken as unshadowed (the full
    aperture value: an upper bound; an obstacle whose gaps fall between the rim points
    is taken as closed)."""
    line = points_m - origin_m
    u = line / np.linalg.norm(line, axis=1, keepdims=True)
    helper = np.where(np.abs(u[:, :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
    e1 = np.cross(u, helper)
    e1 /= np.linalg.norm(e1, axis=1, keepdims=True)
    e2 = np.cross(u, e1)
    ang = 2 * np.pi * np.arange(n) / n
    rim = points_m[:, None, :] + radius_m[:, None, None] * (np.cos(ang)[None, :, None] * e1[:, None, :]
                                                           + np.sin(ang)[None, :, None] * e2[:, None, :])
    o = np.repeat(origin_m, n, axis=0)
    d = rim.reshape(-1, 3) - o
    hits = tracer.first_hit(o, d)
    ok = ~(hits.hit & (hits.t < np.linalg.norm(d, axis=1) * (1 - 1e-9)))
    return ok.reshape(-1, n).any(axis=1)


def direct_beam(beam, observers, tracer, mu, apertures: Apertures) -> DirectBeam:
    """The direct beam at every observer (see the module notes), in blocks of observers
    on threads; ``tracer`` answers ``first_hit(origins, directions)`` against every
    object in the scene; ``apertures`` (:func:`hazard.physics.aperture.observer_apertures`) the
    observers' limiting apertures and aids."""
    out, point = np.zeros(len(observers)), np.zeros(len(observers))

    def block(a0, a1, p):
        at = beam_at(beam, p, mu, apertures.reach_m)
        clear = clear_of_objects(at, p, tracer)
        rows = a0 + at.rows
        ap = apertures.take(rows)
        through = gaussian_aperture_w_m2(beam, at.axial_m, at.offset_m, at.path_m, mu, ap)
        point[rows] = np.where(clear, at.irradiance_w_m2, 0.0)
        edge = np.flatnonzero(~clear & (through > 0))
        if len(edge):  # a shadow's edge across the aperture: partly lit counts as lit (an upper bound)
            radius = np.maximum(ap.eye_radius_m, np.where(ap.aided, ap.collect_radius_m, 0.0))[edge]
            clear[edge] = rim_clear(at.origin_m[edge], np.asarray(p, float).reshape(-1, 3)[at.rows[edge]], radius, tracer)
        out[rows] = np.where(clear, through, 0.0)
        return int((~clear & (through > 0)).sum())

    blocked = sum(observers.map_blocks(block))
    return DirectBeam(out, int(np.count_nonzero(out)), blocked, point_w_m2=point, aperture_m=apertures.diameter_m)
