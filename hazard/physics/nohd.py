"""Nominal ocular hazard distances: direct beam, diffuse, specular, BRDF lobes.

Formulas from the project's spec (`laser-safety.md` section 3.1):

* Direct beam (ANSI Z136.1 eq. B, [C] Laser-Studio ``computeNOHD``):
  ``E(R) = 4 K P e^{-mu R} / (pi (a + R phi)^2)``; without attenuation
  ``NOHD = (sqrt(4 K P / (pi MPE)) - a) / phi``. ``a`` is the 1/e beam diameter, ``phi``
  the 1/e full-angle divergence: ``4P / (pi a^2)`` is then the peak irradiance of a
  Gaussian beam.
* With Beer-Lambert attenuation the equation is solved exactly: with ``s = a + R phi``,
  ``(mu s / 2 phi) e^{mu s / 2 phi} = (mu D0 / 2 phi) e^{mu a / 2 phi}``, ``D0 =
  sqrt(4 K P / (pi MPE))``, so ``s = (2 phi / mu) W(.)`` with the Lambert W function
  ([D]; for a = 0 it is the spec's ``R = (2/mu) W(mu R0 / 2)``). W is evaluated from the
  logarithm of its argument, so mu -> 0 and mu R ~ 700 stay finite and exact.
* Diffuse (Lambertian) reflection: ``NHZ = sqrt(rho P cos(theta_v) / (pi MPE))`` (ANSI
  form, [C]); a BRDF lobe of radiant intensity I [W/sr]: ``I e^{-mu R} / R^2 = MPE``.
* Specular reflection from a flat mirror of reflectance rho_s: the direct-beam formula
  with ``rho_s P``, along the folded path ([D], standard practice).
* Optically aided viewing: gain ``K = min(tau M^2, tau (D_o / 7 mm)^2, tau (D_b / 7 mm)^2)``,
  each term clipped to >= 1 ([C] Laser-Studio).
* Kruse visibility model: ``mu = (3.91 / V) (550 nm / lambda)^q`` with q = 1.6 (V > 50 km),
  1.3 (6-50 km), 0.585 V^(1/3) (V < 6 km) ([M] full Kruse model; [C] Laser-Studio uses
  the last form only).
"""

from __future__ import annotations

import math
import sys

import numpy as np
from dataclasses import dataclass, field


def lambertw(z, k=0, tol=1e-8):
    """scipy.special.lambertw, imported on first use (``import hazard`` stays light)."""
    from scipy.special import lambertw as _w

    return _w(z, k, tol)

__all__ = [
    "NOHDResult",
    "nohd_direct",
    "nohd_diffuse",
    "nohd_specular",
    "nohd_from_intensity",
    "hazard_distance",
    "optical_gain",
    "group_gains",
    "attenuation_from_visibility",
    "range_from_intensity",
    "PUPIL_DIAMETER_M",
]

PUPIL_DIAMETER_M = 7e-3


def _num(name, value, *, minimum=None, strict=False, maximum=None):
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise ValueError(f"{name}={value!r}: expected a finite number")
    v = float(value)
    if minimum is not None and (v <= minimum if strict else v < minimum):
        raise ValueError(f"{name}={v!r}: expected a number {'>' if strict else '>='} {minimum}")
    if maximum is not None and v > maximum:
        raise ValueError(f"{name}={v!r}: expected a number <= {maximum}")
    return v


def log_lambertw_exp(log_z: float) -> float:
    """ln W(e^L) on the principal branch for any real L: no overflow for large L, no
    underflow for very negative L (there W(z) = z (1 - z + 3 z^2 / 2 - ...))."""
    if log_z < -20.0:
        z = math.exp(log_z)
        return log_z + math.log1p(-z + 1.5 * z * z)
    if log_z < 700.0:
        return math.log(float(lambertw(math.exp(log_z)).real))
    w = log_z - math.log(log_z)
    for _ in range(50):  # Newton on w + ln w = L
        step = (w + math.log(w) - log_z) / (1.0 + 1.0 / w)
        w -= step
        if abs(step) <= 1e-15 * w:
            break
    return math.log(w)


def _lambertw0(z: np.ndarray) -> np.ndarray:
    """Principal branch W0(z) for real z >= 0 (array), vectorised.

    Winitzki's start ``l (1 - ln(1 + l) / (2 + l))``, ``l = ln(1 + z)`` (within a few per
    cent everywhere), then three Halley steps on ``w - z e^-w = 0`` (scaled by e^-w, so
    nothing overflows): within 4e-16 relative of ``scipy.special.lambertw`` for
    1e-8 <= z <= 1e300 (tested), about 3x faster (keep-out grids evaluate millions).
    """
    l = np.log1p(z)
    w = l * (1.0 - np.log1p(l) / (2.0 + l))
    for _ in range(3):
        t = w - z * np.exp(-w)
        w = w - t / ((w + 1.0) - (w + 2.0) * t / (2.0 * w + 2.0))
    return w


def _scaled_lambertw(log_scale: float, log_z: float) -> float:
    """scale * W(e^L) from the logarithms of both (finite for mu -> 0 and mu R -> 700)."""
    return math.exp(log_scale + log_lambertw_exp(log_z))


@dataclass(frozen=True)
class NOHDResult:
    """A hazard distance with the steps that produced it.

    ``nohd_m`` is 0.0 when the irradiance is below the MPE already at the aperture (or
    the source emits nothing), and ``math.inf`` when it never falls below it (no
    divergence and no attenuation).
    """

    nohd_m: float
    kind: str
    method: str
    formula: str
    inputs: dict
    steps: tuple = field(default=())
    beyond_reflector_m: float | None = None

    def to_dict(self) -> dict:
        d = {
            "nohd_m": self.nohd_m,
            "kind": self.kind,
            "method": self.method,
            "formula": self.formula,
            "inputs": dict(self.inputs),
            "steps": list(self.steps),
        }
        if self.beyond_reflector_m is not None:
            d["beyond_reflector_m"] = self.beyond_reflector_m
        return d

    def __str__(self):
        return "\n".join(self.steps)


def _beam_distance(d0, a, phi, mu):
    """Range where 4KP e^{-mu R}/(pi (a + R phi)^2) falls to the MPE, given D0."""
    if d0 <= a:
        return 0.0, "aperture irradiance already at or below the MPE"
    if phi == 0.0:
        if mu == 0.0:
            return math.inf, "no divergence and no attenuation: the beam never falls below the MPE"
        return 2.0 * math.log(d0 / a) / mu, "collimated beam: R = 2 ln(D0 / a) / mu"
    if mu == 0.0:
        return (d0 - a) / phi, "closed form"
    log_z = math.log(mu) + math.log(d0) - math.log(2.0 * phi) + mu * a / (2.0 * phi)
    s = _scaled_lambertw(math.log(2.0 * phi) - math.log(mu), log_z)
    return max(s - a, 0.0) / phi, "Lambert W"


def nohd_direct(power_w, mpe_w_m2, beam_diameter_m, divergence_rad, *, attenuation_per_m=0.0, optical_gain=1.0, beam_growth="linear") -> NOHDResult:
    """NOHD of the direct beam.

    Parameters
    ----------
    power_w : float
        Beam power P [W] (for a pulse: the pulse energy [J] with an MPE in J/m^2).
    mpe_w_m2 : float
        MPE [W/m^2] (or J/m^2 for pulses), > 0.
    beam_diameter_m : float
        Beam diameter a at the aperture, at the 1/e points [m].
    divergence_rad : float
        Full-angle divergence phi at the 1/e points [rad] (0: collimated).
    attenuation_per_m : float
        Atmospheric attenuation coefficient mu [1/m].
    optical_gain : float
        Collecting gain K of viewing optics (>= 1; see :func:`optical_gain`).
    beam_growth : {"linear", "quadrature"}
        ``a + R phi`` (ANSI eq. B) or ``sqrt(a^2 + R^2 phi^2)`` ([C] calculator.academy);
        they differ only where ``R phi ~ a``. The quadrature form with attenuation has no
        closed form and is solved by a bracketed root.
    """
    p = _num("power_w", power_w, minimum=0.0)
    mpe = _num("mpe_w_m2", mpe_w_m2, minimum=0.0, strict=True)
    a = _num("beam_diameter_m", beam_diameter_m, minimum=0.0)
    phi = _num("divergence_rad", divergence_rad, minimum=0.0)
    mu = _num("attenuation_per_m", attenuation_per_m, minimum=0.0)
    k = _num("optical_gain", optical_gain, minimum=1.0)
    if beam_growth not in ("linear", "quadrature"):
        raise ValueError(f"beam_growth={beam_growth!r}: expected 'linear' or 'quadrature'")
    d0 = math.sqrt(4.0 * k * p / (math.pi * mpe))
    inputs = dict(power_w=p, mpe_w_m2=mpe, beam_diameter_m=a, divergence_rad=phi, attenuation_per_m=mu,
                  optical_gain=k, beam_growth=beam_growth)
    steps = [
        "Direct-beam NOHD (ANSI Z136.1 eq. B): E(R) = 4 K P exp(-mu R) / (pi (a + R phi)^2) = MPE",
        f"  P = {p:.6g} W, MPE = {mpe:.6g} W/m^2, a = {a:.6g} m (1/e), phi = {phi:.6g} rad (1/e), mu = {mu:.6g} 1/m, K = {k:.6g}",
        f"  D0 = sqrt(4 K P / (pi MPE)) = sqrt(4 * {k:.6g} * {p:.6g} / (pi * {mpe:.6g})) = {d0:.6g} m",
    ]
    if beam_growth == "linear":
        r, method = _beam_distance(d0, a, phi, mu)
        formula = "NOHD = (D0 - a) / phi" if mu == 0 else "NOHD = ((2 phi / mu) W((mu D0 / 2 phi) exp(mu a / 2 phi)) - a) / phi"
    else:
        formula = "NOHD = sqrt(D0^2 - a^2) / phi" if mu == 0 else "root of 4 K P exp(-mu R) / (pi (a^2 + R^2 phi^2)) = MPE"
        if d0 <= a:
            r, method = 0.0, "aperture irradiance already at or below the MPE"
        elif phi == 0 and mu == 0:
            r, method = math.inf, "no divergence and no attenuation: the beam never falls below the MPE"
        elif mu == 0:
            r, method = math.sqrt(d0 * d0 - a * a) / phi, "closed form"
        else:
            res = hazard_distance(lambda rr: 4 * k * p * math.exp(-mu * rr) / (math.pi * (a * a + (rr * phi) ** 2)), mpe)
            r, method = res, "bracketed root (Brent)"
    steps.append(f"  {formula}")
    steps.append(f"  NOHD = {r:.6g} m ({method})")
    return NOHDResult(r, "direct", method, formula, inputs, tuple(steps))


def nohd_from_intensity(intensity_w_sr, mpe_w_m2, *, attenuation_per_m=0.0) -> NOHDResult:
    """Hazard distance of a point-like source of radiant intensity I [W/sr]:
    ``I exp(-mu R) / R^2 = MPE``, ``R = (2 / mu) W(mu R0 / 2)`` with ``R0 = sqrt(I / MPE)``.

    Valid when R is much larger than the source (spec 3.1, BRDF-based reflection); for a
    BRDF lobe ``I = f_r cos(theta_r) P_incident`` (times atmospheric transmission to the
    target and any optical gain).
    """
    i = _num("intensity_w_sr", intensity_w_sr, minimum=0.0)
    mpe = _num("mpe_w_m2", mpe_w_m2, minimum=0.0, strict=True)
    mu = _num("attenuation_per_m", attenuation_per_m, minimum=0.0)
    r0 = math.sqrt(i / mpe)
    if r0 == 0.0:
        r, method = 0.0, "no emission"
    elif mu == 0.0:
        r, method = r0, "closed form"
    else:
        r, method = _scaled_lambertw(math.log(2.0) - math.log(mu), math.log(mu) + math.log(r0) - math.log(2.0)), "Lambert W"
    formula = "R = sqrt(I / MPE)" if mu == 0 else "R = (2 / mu) W(mu sqrt(I / MPE) / 2)"
    steps = (
        "Point-source hazard distance: I exp(-mu R) / R^2 = MPE",
        f"  I = {i:.6g} W/sr, MPE = {mpe:.6g} W/m^2, mu = {mu:.6g} 1/m",
        f"  R0 = sqrt(I / MPE) = {r0:.6g} m",
        f"  {formula} = {r:.6g} m ({method})",
    )
    return NOHDResult(r, "intensity", method, formula, dict(intensity_w_sr=i, mpe_w_m2=mpe, attenuation_per_m=mu), steps)


def range_from_intensity(intensity_w_sr, mpe_w_m2, attenuation_per_m=0.0) -> np.ndarray:
    """Vectorised :func:`nohd_from_intensity`: hazard range [m] for an array of radiant
    intensities [W/sr] (no checks, no steps; for keep-out grids)."""
    i = np.maximum(np.asarray(intensity_w_sr, dtype=float), 0.0)
    r0 = np.sqrt(i / mpe_w_m2)
    if attenuation_per_m == 0.0:
        return r0
    mu = attenuation_per_m
    z = mu * r0 / 2.0
    out = np.zeros_like(r0)
    small = z < 1e-8  # z = 0 too: mu r0 / 2 underflows for a subnormal mu while r0 > 0 (it gave R = 0)
    out[small] = r0[small] * (1.0 - z[small])  # W(z) = z - z^2 + ...
    big = z >= 1e-8
    zb = z[big]
    inf = np.isinf(zb)  # W(inf) = inf; the iteration would give nan
    out[big] = np.where(inf, np.inf, 2.0 / mu * _lambertw0(np.where(inf, 1.0, zb)))
    return out


def nohd_diffuse(power_w, mpe_w_m2, reflectance, *, viewing_angle_rad=0.0, attenuation_per_m=0.0, optical_gain=1.0) -> NOHDResult:
    """Nominal hazard zone of a Lambertian reflection (ANSI form [C]):
    ``NHZ = sqrt(K rho P cos(theta_v) / (pi MPE))``, with attenuation solved exactly.

    Assumes a point-like spot: if the spot subtends more than 1.5 mrad at the eye, C_E > 1
    and the MPE is higher (this bound is then conservative).
    """
    p = _num("power_w", power_w, minimum=0.0)
    rho = _num("reflectance", reflectance, minimum=0.0, maximum=1.0)
    th = _num("viewing_angle_rad", viewing_angle_rad)
    if abs(th) > math.pi / 2:
        raise ValueError(f"viewing_angle_rad={th!r}: expected an angle from the normal in [-pi/2, pi/2]")
    k = _num("optical_gain", optical_gain, minimum=1.0)
    intensity = k * rho * p * math.cos(th) / math.pi
    base = nohd_from_intensity(intensity, mpe_w_m2, attenuation_per_m=attenuation_per_m)
    steps = (
        "Diffuse-reflection NHZ (Lambertian): K rho P cos(theta_v) exp(-mu R) / (pi R^2) = MPE",
        f"  P = {p:.6g} W, rho = {rho:.6g}, theta_v = {math.degrees(th):.6g} deg, K = {k:.6g}",
        f"  I = K rho P cos(theta_v) / pi = {intensity:.6g} W/sr",
        *base.steps[1:],
    )
    inputs = dict(power_w=p, reflectance=rho, viewing_angle_rad=th, optical_gain=k, **base.inputs)
    return NOHDResult(base.nohd_m, "diffuse", base.method, base.formula, inputs, steps)


def nohd_specular(power_w, mpe_w_m2, beam_diameter_m, divergence_rad, reflectance, *, attenuation_per_m=0.0,
                  optical_gain=1.0, range_to_reflector_m=0.0) -> NOHDResult:
    """NOHD of a beam reflected by a flat mirror of reflectance rho_s, along the folded
    path from the laser: the direct-beam formula with ``rho_s P``.

    ``beyond_reflector_m`` is the part of it past the mirror (``NOHD - range_to_reflector_m``,
    not below 0). A curved or finite reflector adds divergence and lowers the hazard.
    """
    rho = _num("reflectance", reflectance, minimum=0.0, maximum=1.0)
    r1 = _num("range_to_reflector_m", range_to_reflector_m, minimum=0.0)
    p = _num("power_w", power_w, minimum=0.0)
    base = nohd_direct(rho * p, mpe_w_m2, beam_diameter_m, divergence_rad, attenuation_per_m=attenuation_per_m, optical_gain=optical_gain)
    beyond = max(base.nohd_m - r1, 0.0)
    steps = (
        "Specular-reflection NOHD (flat mirror, folded path): the direct beam with rho_s P",
        f"  rho_s = {rho:.6g}: rho_s P = {rho * p:.6g} W",
        *base.steps[1:],
        f"  beyond the reflector at {r1:.6g} m: {beyond:.6g} m",
    )
    inputs = dict(base.inputs, power_w=p, reflectance=rho, range_to_reflector_m=r1)
    return NOHDResult(base.nohd_m, "specular", base.method, base.formula, inputs, steps, beyond_reflector_m=beyond)


def hazard_distance(irradiance_at, mpe_w_m2, *, r_start_m=1.0, r_max_m=1e9) -> float:
    """Largest range [m] where a decreasing irradiance profile ``irradiance_at(R)``
    [W/m^2] equals the MPE, found by bracketing (doubling) and Brent's method.

    Returns 0.0 if ``irradiance_at(0)`` is already at or below the MPE and ``math.inf``
    if it is still above the MPE at ``r_max_m``.
    """
    mpe = _num("mpe_w_m2", mpe_w_m2, minimum=0.0, strict=True)
    g = lambda r: irradiance_at(r) - mpe
    if g(0.0) <= 0:
        return 0.0
    lo, hi = 0.0, float(r_start_m)
    while g(hi) > 0:
        lo, hi = hi, hi * 2.0
        if hi > r_max_m:
            return math.inf
    from scipy.optimize import brentq  # here: scipy.optimize costs 0.3 s at import

    return brentq(g, lo, hi, xtol=1e-12 * hi, rtol=4 * sys.float_info.epsilon, maxiter=500)


def optical_gain(magnification, objective_diameter_m, transmission=1.0, beam_diameter_m=None) -> float:
    """Collecting gain of viewing optics ([C] Laser-Studio):
    ``K = min(tau M^2, tau (D_o / 7 mm)^2, tau (D_b / 7 mm)^2)``, each term clipped to >= 1.

    Parameters
    ----------
    magnification : float
        M (>= 1).
    objective_diameter_m : float
        Objective (entrance) diameter D_o [m].
    transmission : float
        Optical transmission tau in (0, 1].
    beam_diameter_m : float, optional
        Beam diameter at the observer D_b [m]; limits the gain when the beam is smaller
        than the objective.
    """
    m = _num("magnification", magnification, minimum=1.0)
    d_o = _num("objective_diameter_m", objective_diameter_m, minimum=0.0, strict=True)
    tau = _num("transmission", transmission, minimum=0.0, strict=True, maximum=1.0)
    terms = [tau * m * m, tau * (d_o / PUPIL_DIAMETER_M) ** 2]
    if beam_diameter_m is not None:
        terms.append(tau * (_num("beam_diameter_m", beam_diameter_m, minimum=0.0) / PUPIL_DIAMETER_M) ** 2)
    return min(max(t, 1.0) for t in terms)


def group_gains(optics, group) -> np.ndarray:
    """Per observer the fixed gain (:func:`optical_gain` without the beam term) of its
    group's optics; ``optics[g]`` is an OpticsSpec, or None for the naked eye (gain 1)."""
    per = np.array([1.0 if o is None else optical_gain(o.magnification, o.objective_diameter_m, o.transmission) for o in optics] or [1.0])
    return per[np.asarray(group, np.int64)]


UV_ATTENUATION_FLOOR_NM = 400.0
"""Below this wavelength [nm] the Kruse attenuation is held at its 400 nm value (protective)."""


def attenuation_from_visibility(visibility_km, wavelength_nm) -> float:
    """Atmospheric attenuation coefficient mu [1/m] from the meteorological visibility
    (Kruse model, [M]; spec section 3.1).

    The Kruse fit is made for the visible and near infrared. Below 400 nm it is not
    extrapolated: its ``(550/lambda)^q`` growth would give the ultraviolet more attenuation,
    hence a shorter NOHD, than any validated model supports, so the 400 nm value is used
    (the lower attenuation: protective, [D]).
    """
    v = _num("visibility_km", visibility_km, minimum=0.0, strict=True)
    wl = max(_num("wavelength_nm", wavelength_nm, minimum=0.0, strict=True), UV_ATTENUATION_FLOOR_NM)
    q = 1.6 if v > 50 else (1.3 if v > 6 else 0.585 * v ** (1.0 / 3.0))
    return 3.91 / v * (550.0 / wl) ** q / 1000.0
