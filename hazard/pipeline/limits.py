"""Stage ``mpe``: the exposure limit of the scene's laser, and the atmosphere's attenuation."""

from __future__ import annotations

from dataclasses import dataclass

from .. import mpe as _mpe
from ..nohd import attenuation_from_visibility

__all__ = ["ExposureLimits", "exposure_limits", "attenuation_per_m"]


@dataclass
class ExposureLimits:
    """The MPE of an exposure: ``mpe`` (the ocular MPE result with its steps), ``pulse``
    (repetitive-pulse result or None), the irradiance limit [W/m^2] (the smaller of the
    average-power MPE and per-pulse MPE x PRF) and the radiant-exposure limit [J/m^2]."""

    mpe: object
    pulse: object | None
    irradiance_w_m2: float
    radiant_exposure_j_m2: float
    detail: str


def exposure_limits(spec) -> ExposureLimits:
    """Ocular MPE for the laser and exposure of a scene spec (ANSI Z136.1 / IEC 60825-1
    tables via :mod:`hazard.mpe`); pulsed lasers take the smaller of the average-power
    MPE and the per-pulse MPE times the PRF (the repetitive-pulse rules)."""
    laser = spec.laser
    wl, t_exp, std = laser.wavelength_nm, spec.exposure.duration_s, spec.exposure.standard
    res = _mpe.ocular_mpe(wl, t_exp, standard=std)
    pulse = None
    mpe_w_m2 = res.irradiance_w_m2
    if laser.power_w is None:
        pulse = _mpe.repetitive_pulse_mpe(wl, laser.pulse_duration_s, laser.prf_hz, t_exp, standard=std)
        mpe_w_m2 = min(mpe_w_m2, pulse.per_pulse_radiant_exposure_j_m2 * laser.prf_hz)
        detail = f"pulsed: per-pulse MPE x PRF = {pulse.per_pulse_radiant_exposure_j_m2 * laser.prf_hz:.6g} W/m^2 average"
    else:
        detail = f"{res.irradiance_w_m2:.6g} W/m^2 for {t_exp:g} s"
    return ExposureLimits(res, pulse, mpe_w_m2, mpe_w_m2 * t_exp, detail)


def attenuation_per_m(spec) -> float:
    """Beer-Lambert coefficient mu [1/m]: given, or from the visibility (Kruse model,
    :func:`hazard.nohd.attenuation_from_visibility`), else 0."""
    atm = spec.atmosphere
    if atm.attenuation_per_m is not None:
        return atm.attenuation_per_m
    if atm.visibility_km is not None:
        return attenuation_from_visibility(atm.visibility_km, spec.laser.wavelength_nm)
    return 0.0
