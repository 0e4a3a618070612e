"""Stage ``direct``: the laser's own beam at the observers (spec `range-safety.md` section 2).

An observer in the beam receives the Gaussian profile at its range (rays from the
virtual point source, :class:`hazard.beam.BeamGeometry`):
``E = P / (pi w(z)^2) exp(-|s|^2) sqrt(1 + |s|^2 phi^2 / 4) exp(-mu L)`` with ``s`` its
transverse position in units of the 1/e radius ``w(z) = (a + z phi) / 2`` and ``L`` the
path from the aperture (Beer-Lambert once), times the optical gain of its group with the
beam diameter at the observer limiting it (``K = min(tau M^2, tau (D_o/7 mm)^2,
tau (D_b/7 mm)^2)``, :func:`hazard.nohd.optical_gain`). Nothing reaches it when any
object (target, occluder, terrain) lies on the ray between the aperture and the eye.
The peak irradiance is used, not the 7 mm aperture average: conservative for beams
narrower than the pupil.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..nohd import PUPIL_DIAMETER_M, optical_gain

__all__ = ["BeamAt", "DirectBeam", "beam_at", "direct_beam", "with_pointing"]

APERTURE_PLANE_TOL_M = 1e-9  # a point this close to the aperture plane is on it [m]


@dataclass
class DirectBeam:
    """Per observer the direct-beam irradiance [W/m^2] (gain, attenuation and line of
    sight applied), and how many observers the beam reaches and how many it would reach
    but something blocks. With a pointing error or sector, ``irradiance_w_m2`` is the
    largest over the directions the beam may point in (:mod:`hazard.pipeline.pointing`)
    and ``at_aim_w_m2`` the nominal aim's; ``raised``: observers the pointing raised."""

    irradiance_w_m2: np.ndarray
    reached: int
    blocked: int
    at_aim_w_m2: np.ndarray | None = None
    raised: int = 0

    @property
    def detail(self) -> str:
        top = float(self.irradiance_w_m2.max()) if len(self.irradiance_w_m2) else 0.0
        text = (f"{self.reached} observer(s) with a clear line into the beam (E > 0, at most {top:.4g} W/m^2), "
                f"{self.blocked} more behind something that blocks it (Gaussian profile at each range, attenuation, "
                f"optical gain)")
        if self.at_aim_w_m2 is not None:
            text += (f"; over the pointing error / sector (the worst direction at each observer; terrain and occluders "
                     f"block it, targets do not): {self.raised} observer(s) get more than at the aim; "
                     f"reflections are for the nominal aim only")
        return text


def with_pointing(d: DirectBeam, scene, beam, observers, mu, ray_scene) -> DirectBeam:
    """``d`` with each observer's direct beam raised to its worst over the directions the
    beam may point in (:func:`hazard.pipeline.pointing.pointing_worst_w_m2`)."""
    from .pointing import pointing_worst_w_m2

    def gain(rows, diameter_m):
        return _beam_gain(observers.optics, observers.group[rows], diameter_m)

    worst = pointing_worst_w_m2(scene, beam, observers, mu, ray_scene, gain)
    total = np.maximum(d.irradiance_w_m2, worst)
    return DirectBeam(total, int(np.count_nonzero(total)), d.blocked, d.irradiance_w_m2, int((worst > d.irradiance_w_m2).sum()))


def _beam_gain(optics, group, beam_diameter_m):
    """Optical gain per observer: 1 for the naked eye; for a group's optics the smallest
    of ``tau M^2``, ``tau (D_o / 7 mm)^2`` and ``tau (D_b / 7 mm)^2``, each clipped to
    >= 1 (:func:`hazard.nohd.optical_gain`, vectorised over the beam diameter D_b)."""
    gain = np.ones(len(group))
    for g, o in enumerate(optics):
        rows = np.flatnonzero(group == g)
        if o is None or not len(rows):
            continue
        fixed = optical_gain(o.magnification, o.objective_diameter_m, o.transmission)  # the first two terms
        gain[rows] = np.minimum(fixed, np.maximum(o.transmission * (beam_diameter_m[rows] / PUPIL_DIAMETER_M) ** 2, 1.0))
    return gain


@dataclass
class BeamAt:
    """The unobstructed beam at points: ``rows`` of the points it reaches (on or in front
    of the aperture plane, irradiance above floating-point zero), their irradiance [W/m^2] with
    attenuation along the ray, the ray's aperture point [m], its path to the point [m]
    and the axial distance [m]."""

    rows: np.ndarray
    irradiance_w_m2: np.ndarray
    origin_m: np.ndarray
    path_m: np.ndarray
    axial_m: np.ndarray


def beam_at(beam, points_m, mu) -> BeamAt:
    """The Gaussian beam at points (N, 3), nothing in the way (see the module notes)."""
    p = np.asarray(points_m, float).reshape(-1, 3)
    s, z = beam.to_s(p)
    # z >= 0: a point on the aperture plane is in the beam as it leaves (z = 0, irradiance
    # P / (pi w0^2) exp(-|s|^2)); behind it (z < 0) the laser emits nothing. "On the plane"
    # within APERTURE_PLANE_TOL_M: rounding puts a point given on it 1e-17 m either side.
    z = np.where(np.abs(z) <= APERTURE_PLANE_TOL_M, 0.0, z)
    idx = np.flatnonzero(np.isfinite(z) & (z >= 0) & np.all(np.isfinite(s), axis=1))
    e = beam.irradiance_w_m2(s[idx], z[idx])
    live = e > 0  # exp(-|s|^2) underflows to 0 only far outside the beam
    idx, e = idx[live], e[live]
    o, _ = beam.rays(s[idx])
    dist = np.linalg.norm(p[idx] - o, axis=1)
    return BeamAt(idx, e * np.exp(-mu * dist), o, dist, z[idx])


def clear_of_objects(at: BeamAt, points_m, tracer) -> np.ndarray:
    """Per row of ``at``: no object stands between the ray's origin and the point."""
    p = np.asarray(points_m, float).reshape(-1, 3)[at.rows]
    clear = np.ones(len(p), bool)  # a point on the aperture itself (no path) has nothing in between
    far = np.flatnonzero(at.path_m > APERTURE_PLANE_TOL_M)
    if len(far):
        hits = tracer.first_hit(at.origin_m[far], p[far] - at.origin_m[far])
        clear[far] = ~(hits.hit & (hits.t < at.path_m[far] * (1 - 1e-9)))
    return clear


def direct_beam(beam, observers, tracer, mu) -> DirectBeam:
    """The direct beam at every observer (see the module notes), in blocks of observers
    on threads; ``tracer`` answers ``first_hit(origins, directions)`` against every
    object in the scene."""
    out = np.zeros(len(observers))

    def block(a0, a1, p):
        at = beam_at(beam, p, mu)
        clear = clear_of_objects(at, p, tracer)
        gain = _beam_gain(observers.optics, observers.group[a0 + at.rows], beam.diameter_at(at.axial_m))
        out[a0 + at.rows] = np.where(clear, at.irradiance_w_m2 * gain, 0.0)
        return int((~clear).sum())

    blocked = sum(observers.map_blocks(block))
    return DirectBeam(out, int(np.count_nonzero(out)), blocked)
