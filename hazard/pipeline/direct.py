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

from ..nohd import PUPIL_DIAMETER_M

__all__ = ["DirectBeam", "direct_beam"]


@dataclass
class DirectBeam:
    """Per observer the direct-beam irradiance [W/m^2] (gain, attenuation and line of
    sight applied), and how many observers the beam reaches and how many it would reach
    but something blocks."""

    irradiance_w_m2: np.ndarray
    reached: int
    blocked: int

    @property
    def detail(self) -> str:
        top = float(self.irradiance_w_m2.max()) if len(self.irradiance_w_m2) else 0.0
        return (f"{self.reached} observer(s) with a clear line into the beam (E > 0, at most {top:.4g} W/m^2), "
                f"{self.blocked} more behind something that blocks it (Gaussian profile at each range, attenuation, "
                f"optical gain)")


def _beam_gain(optics, group, beam_diameter_m):
    """Optical gain per observer: 1 for the naked eye; for a group's optics the smallest
    of ``tau M^2``, ``tau (D_o / 7 mm)^2`` and ``tau (D_b / 7 mm)^2``, each clipped to
    >= 1 (:func:`hazard.nohd.optical_gain`, vectorised over the beam diameter D_b)."""
    gain = np.ones(len(group))
    for g, o in enumerate(optics):
        rows = np.flatnonzero(group == g)
        if o is None or not len(rows):
            continue
        tau = o.transmission
        fixed = min(max(tau * o.magnification**2, 1.0), max(tau * (o.objective_diameter_m / PUPIL_DIAMETER_M) ** 2, 1.0))
        gain[rows] = np.minimum(fixed, np.maximum(tau * (beam_diameter_m[rows] / PUPIL_DIAMETER_M) ** 2, 1.0))
    return gain


def direct_beam(beam, observers, tracer, mu) -> DirectBeam:
    """The direct beam at every observer (see the module notes); ``tracer`` answers
    ``first_hit(origins, directions)`` against every object in the scene."""
    p = observers.positions_m
    m = len(p)
    out = np.zeros(m)
    if not m:
        return DirectBeam(out, 0, 0)
    s, z = beam.to_s(p)
    ok = np.isfinite(z) & (z > 0) & np.all(np.isfinite(s), axis=1)
    idx = np.flatnonzero(ok)
    e = beam.irradiance_w_m2(s[idx], z[idx])
    live = e > 0  # exp(-|s|^2) underflows to 0 only far outside the beam
    idx, e = idx[live], e[live]
    o, _ = beam.rays(s[idx])
    seg = p[idx] - o
    dist = np.linalg.norm(seg, axis=1)
    hits = tracer.first_hit(o, seg)
    clear = ~(hits.hit & (hits.t < dist * (1 - 1e-9)))
    gain = _beam_gain(observers.optics, observers.group[idx], beam.diameter_at(z[idx]))
    out[idx] = np.where(clear, e * np.exp(-mu * dist) * gain, 0.0)
    return DirectBeam(out, int(np.count_nonzero(out)), int((~clear).sum()))
