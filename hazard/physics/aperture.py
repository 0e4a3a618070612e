"""Exposure through the limiting aperture: what the MPE is compared with.

Spec `range-safety.md` sections 1 and 10. The standards compare the MPE with the
irradiance *averaged over the limiting aperture* (a disk of diameter D_f centred on the
eye's position), not with the irradiance at one point (ANSI Z136.1-2014 sec. 8.3 and
Table 8; IEC 60825-1:2014 Table A.5). Ocular D_f, values as in the spec:

* 400-1400 nm: 7 mm;
* 180-400 nm and 1400 nm-0.1 mm: 1 mm for t < 0.3 s, 1.5 t^0.375 mm for 0.3-10 s,
  3.5 mm for t > 10 s;
* 0.1-1 mm: 11 mm (skin: 3.5 mm, 11 mm at 0.1-1 mm).

**Gaussian beam through a disk** [D]. For ``E = E0 exp(-r^2 / w^2)`` (w the 1/e radius,
``P = E0 pi w^2``) and a disk of radius a centred at distance d from the axis, the power
fraction is ``F = 1 - Q_1(sqrt(2) d / w, sqrt(2) a / w)`` (Marcum Q), i.e. the CDF at
``2 a^2 / w^2`` of a non-central chi-square with 2 degrees of freedom and non-centrality
``2 d^2 / w^2`` (:func:`scipy.stats.ncx2`, here its kernel :func:`scipy.special.chndtr`);
the aperture-averaged irradiance is ``P F / (pi a^2)``. Numerics: F = 0 where the
whole disk lies more than 38 w beyond the axis (``exp(-38^2)`` underflows), F = 1 where
it holds the beam to ``exp(-(a - d)^2 / w^2) < 1e-627``; where a / w or d / w exceed 300
(beams thinner than 1/300 of the aperture, where scipy's Boost kernel can overflow) the
1-D integral ``F = int_{-a}^{a} exp(-(x - d)^2 / w^2) erf(sqrt(a^2 - x^2) / w) dx /
(sqrt(pi) w)`` with ``x = a sin(theta)`` (smooth at the rim), 80 panels in theta over
the part of [-a, a] within 40 w of d, 12 Gauss-Legendre nodes each. Measured: the two
agree to 1e-13 where F > 1e-10 and 1e-11 where F > 1e-100 (20 000 random cases); the
quadrature matches a 40-digit mpmath integral at F = 1.7e-142 to 1e-9, where the CDF
is 0.4 % off (immaterial there). Never NaN.

**Optical aids.** An aid of objective diameter D_o, magnification M and transmission
tau collects the power through a disk of diameter ``min(D_o, 7 mm M)`` about the eye's
line and delivers it into the 7 mm pupil: ``E = tau P_collected / (pi (3.5 mm)^2)``
(spec section 10); on the axis of a wide beam ``tau min(M^2, (D_o / 7 mm)^2) E0``, the
usual gain (:func:`hazard.physics.nohd.optical_gain`). The observer may also look without the
aid, so an aided observer gets the larger of the two (the old gains' clip at 1).

**Fields that vary slowly.** The mean of a smooth field f over a disk of radius a is
``f(centre) + a^2 / 8 Laplacian(f) + O(a^4)``; a diffuse spot's field falls as
``cos / R^2`` (Laplacian of order ``f / R^2``), so the point value equals the aperture
average to a relative ``~ (a / R)^2``: 1.2e-5 at R = 1 m for a = 3.5 mm. Diffuse
reflections therefore keep their point values (tested in
``tests/validation/test_limiting_aperture.py``); only Gaussian beams (the direct beam
and flat mirrors' beams) are averaged.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

__all__ = ["Apertures", "LimitingAperture", "limiting_aperture", "limiting_aperture_m", "disk_fraction", "aperture_irradiance_w_m2", "observer_apertures",
           "PUPIL_RADIUS_M"]

PUPIL_RADIUS_M = 3.5e-3  # the dark-adapted pupil an optical aid delivers into (7 mm)
_FAR = 38.0  # exp(-38^2) = 1e-627: below every double
_NCX2_MAX = 300.0  # a / w, d / w above which the 1-D quadrature replaces scipy's ncx2
_PANELS, _NODES = 80, 12


def limiting_aperture_m(wavelength_nm, duration_s, *, skin=False) -> float:
    """Limiting aperture diameter D_f [m] (ANSI Z136.1-2014 sec. 8.3 / Table 8, IEC
    60825-1:2014 Table A.5; values as in spec range-safety.md section 10).

    Parameters
    ----------
    wavelength_nm : float
        Wavelength [nm], 180 nm to 1 mm (1e6 nm).
    duration_s : float
        Exposure duration t [s] (> 0): sets D_f in the UV and far infrared.
    skin : bool
        The skin's aperture instead of the eye's.
    """
    wl, t = float(wavelength_nm), float(duration_s)
    if not (math.isfinite(wl) and 180.0 <= wl <= 1e6):
        raise ValueError(f"wavelength_nm = {wavelength_nm!r}: expected 180 to 1e6 nm (the limiting-aperture table)")
    if not (math.isfinite(t) and t > 0):
        raise ValueError(f"duration_s = {duration_s!r}: expected a finite duration > 0 s")
    if wl >= 1e5:
        return 11e-3
    if skin:
        return 3.5e-3
    if 400.0 <= wl < 1400.0:
        return 7e-3
    if t < 0.3:
        return 1e-3
    if t <= 10.0:
        return 1.5e-3 * t ** 0.375
    return 3.5e-3


@dataclass(frozen=True)
class LimitingAperture:
    """What the MPE is compared with (report.json ``limiting_aperture``; :func:`limiting_aperture`).

    Attributes
    ----------
    diameter_m : float
        The limiting aperture's diameter D_f [m] (:func:`limiting_aperture_m`).
    source : str
        The standards' tables it comes from, with their editions.
    optical_aids : str
        How an optical aid collects and delivers the beam, in words.
    applies_to : str
        Which beams are averaged over it and which keep the point value, in words.
    """

    diameter_m: float
    source: str
    optical_aids: str
    applies_to: str

    def to_dict(self) -> dict:
        return {"diameter_m": self.diameter_m, "source": self.source, "optical_aids": self.optical_aids, "applies_to": self.applies_to}


def limiting_aperture(wavelength_nm, duration_s) -> LimitingAperture:
    """The eye's limiting aperture at ``wavelength_nm`` [nm] and exposure ``duration_s`` [s], and how the analysis uses it."""
    return LimitingAperture(
        diameter_m=limiting_aperture_m(wavelength_nm, duration_s),
        source="ANSI Z136.1-2014 sec. 8.3 / Table 8; IEC 60825-1:2014 Table A.5",
        optical_aids="collect over min(D_o, 7 mm M), delivered into the 7 mm pupil (tau P / (pi (3.5 mm)^2)); "
                     "the naked eye's value if larger",
        applies_to="the direct beam and flat mirrors' beams (exact Gaussian power through the disk); diffuse "
                   "reflections and curved mirrors keep the point value (times the aid's fixed gain)")


def disk_fraction(radius_m, offset_m, beam_radius_m) -> np.ndarray:
    """Fraction of a Gaussian beam's power inside a disk (see the module notes).

    Parameters
    ----------
    radius_m : array_like
        Disk radius a [m] (> 0).
    offset_m : array_like
        Distance d [m] of the disk's centre from the beam axis, in the cross-section.
    beam_radius_m : array_like
        The beam's 1/e irradiance radius w [m] (> 0).

    Returns
    -------
    numpy.ndarray
        F in [0, 1], broadcast shape; never NaN.
    """
    a, d, w = np.broadcast_arrays(*(np.asarray(v, float) for v in (radius_m, offset_m, beam_radius_m)))
    for name, v in (("radius_m", a), ("beam_radius_m", w)):
        if v.size and not np.all(np.isfinite(v) & (v > 0)):
            raise ValueError(f"{name}: expected finite values > 0 m, got {v[~(np.isfinite(v) & (v > 0))].ravel()[0]!r}")
    d = np.abs(d)
    if d.size and not np.all(np.isfinite(d)):
        raise ValueError(f"offset_m: expected finite values, got {d[~np.isfinite(d)].ravel()[0]!r}")
    with np.errstate(over="ignore"):
        ra, rd = a / w, d / w  # inf for w far below a: settled by the cases below
    out = np.where(ra - rd > _FAR, 1.0, 0.0)
    mid = np.abs(ra - rd) <= _FAR
    quad = mid & ((ra > _NCX2_MAX) | (rd > _NCX2_MAX))
    easy = mid & ~quad
    if np.any(easy):
        out[easy] = _ncx2_fraction(ra[easy], rd[easy])
    if np.any(quad):
        out[quad] = _quadrature_fraction(ra[quad], rd[quad])
    return np.clip(out, 0.0, 1.0)


def _ncx2_fraction(ra, rd) -> np.ndarray:
    """F from the non-central chi-square CDF (a / w, d / w moderate):
    :func:`scipy.special.chndtr`, the kernel of :func:`scipy.stats.ncx2` (importing
    scipy.stats costs a second); any non-finite value goes to the quadrature."""
    from scipy.special import chndtr

    with np.errstate(all="ignore"):
        f = chndtr(2 * ra * ra, 2, 2 * rd * rd)
    bad = ~np.isfinite(f)
    if np.any(bad):
        f[bad] = _quadrature_fraction(ra[bad], rd[bad])
    return f


def _quadrature_fraction(ra, rd) -> np.ndarray:
    """F by the 1-D integral of the module notes (units of w): x over
    ``[max(-a, d - 40), min(a, d + 40)]`` in panels, ``x = a sin(theta)`` in each."""
    from scipy.special import erf

    x0 = np.maximum(-ra, rd - 40.0)
    x1 = np.minimum(ra, rd + 40.0)
    out = np.zeros(len(ra))
    live = x1 > x0
    if not np.any(live):
        return out
    a, d = ra[live], rd[live]
    t0 = np.arcsin(np.clip(x0[live] / a, -1, 1))
    t1 = np.arcsin(np.clip(x1[live] / a, -1, 1))
    u, wts = np.polynomial.legendre.leggauss(_NODES)
    edges = t0[:, None] + (t1 - t0)[:, None] * np.linspace(0.0, 1.0, _PANELS + 1)[None, :]
    half = 0.5 * (edges[:, 1:] - edges[:, :-1])
    theta = (0.5 * (edges[:, 1:] + edges[:, :-1]))[:, :, None] + half[:, :, None] * u[None, None, :]
    x, c = a[:, None, None] * np.sin(theta), a[:, None, None] * np.cos(theta)
    g = c * np.exp(-(x - d[:, None, None]) ** 2) * erf(np.maximum(c, 0.0))
    out[live] = (g * wts[None, None, :] * half[:, :, None]).sum(axis=(1, 2)) / math.sqrt(math.pi)
    return out


@dataclass
class Apertures:
    """Per observer: the eye's limiting-aperture radius [m], the radius of the disk its
    optical aid collects over [m] (the eye's own for the naked eye) and the aid's
    transmission (1 for the naked eye); ``aided`` marks the rows with an aid."""

    eye_radius_m: np.ndarray
    collect_radius_m: np.ndarray
    transmission: np.ndarray
    aided: np.ndarray

    def take(self, rows) -> "Apertures":
        return Apertures(self.eye_radius_m[rows], self.collect_radius_m[rows], self.transmission[rows], self.aided[rows])

    @property
    def diameter_m(self) -> np.ndarray:
        """The aperture the verdict's power is collected over [m]: the aid's collecting
        disk for aided observers, D_f otherwise."""
        return 2 * np.where(self.aided, self.collect_radius_m, self.eye_radius_m)

    @property
    def reach_m(self) -> float:
        """The largest collecting radius [m] (how far beside a beam power can be picked up)."""
        return float(max(self.eye_radius_m.max(initial=0.0), self.collect_radius_m.max(initial=0.0)))


def observer_apertures(optics, group, wavelength_nm, duration_s) -> Apertures:
    """Per observer the apertures of its group (``optics[g]``: an OpticsSpec with
    ``magnification``, ``objective_diameter_m``, ``transmission``, or None for the naked
    eye): D_f from :func:`limiting_aperture_m`; an aid collects over
    ``min(D_o, 7 mm M)``."""
    eye = limiting_aperture_m(wavelength_nm, duration_s) / 2
    group = np.asarray(group, np.intp)
    optics = list(optics) or [None]
    coll = np.array([eye if o is None else min(o.objective_diameter_m, 2 * PUPIL_RADIUS_M * o.magnification) / 2 for o in optics])
    tau = np.array([1.0 if o is None else float(o.transmission) for o in optics])
    aided = np.array([o is not None for o in optics], bool)
    return Apertures(np.full(len(group), eye), coll[group], tau[group], aided[group])


def aperture_irradiance_w_m2(power_w, beam_radius_m, offset_m, apertures: Apertures, fraction=None) -> np.ndarray:
    """The irradiance the MPE is compared with [W/m^2] for a Gaussian beam at observers.

    Naked eye: ``P F(a_f, d, w) / (pi a_f^2)``; with an aid the larger of that and
    ``tau P F(a_c, d, w) / (pi (3.5 mm)^2)``, ``a_c = min(D_o, 7 mm M) / 2`` (module notes).

    Parameters
    ----------
    power_w : array_like
        Beam power at the observer's range [W] (after attenuation).
    beam_radius_m : array_like
        The beam's 1/e radius there [m].
    offset_m : array_like
        The eye's distance from the beam axis [m].
    apertures : Apertures
        The observers' apertures (same length).
    fraction : callable, optional
        ``fraction(radius_m, rows)``: the power fraction through disks of those radii
        about observers ``rows`` when part of the beam is cut off (a mirror smaller than
        the beam); default :func:`disk_fraction` of the whole Gaussian.
    """
    p = np.asarray(power_w, float)
    if fraction is None:
        def fraction(radius_m, rows):
            return disk_fraction(radius_m, np.broadcast_to(np.asarray(offset_m, float), p.shape)[rows],
                                 np.broadcast_to(np.asarray(beam_radius_m, float), p.shape)[rows])
    every = np.arange(len(apertures.eye_radius_m))
    eye = p * fraction(apertures.eye_radius_m, every) / (math.pi * apertures.eye_radius_m ** 2)
    if not np.any(apertures.aided):
        return eye
    out = eye.copy()
    k = np.flatnonzero(apertures.aided)
    pk = np.broadcast_to(p, eye.shape)[k]
    aid = apertures.transmission[k] * pk * fraction(apertures.collect_radius_m[k], k) / (math.pi * PUPIL_RADIUS_M ** 2)
    out[k] = np.maximum(eye[k], aid)
    return out
