"""Stage ``mpe``: the exposure limit of the scene's laser, and the atmosphere's attenuation."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING

from scenes.motion import Windows

from hazard.physics import mpe as _mpe
from hazard.physics.nohd import attenuation_from_visibility

if TYPE_CHECKING:  # annotations only
    from scenes.spec import SceneSpec

__all__ = ["ExposureLimits", "exposure_limits", "uv_24h_limit", "attenuation_per_m"]


@dataclass
class ExposureLimits:
    """The MPE of an exposure: ``mpe`` (the ocular MPE result with its steps), ``pulse``
    (repetitive-pulse result or None), the irradiance limit [W/m^2] (the smaller of the
    average-power MPE and per-pulse MPE x PRF) and the radiant-exposure limit [J/m^2]."""

    mpe: _mpe.MPEResult
    pulse: _mpe.RepetitivePulseResult | None
    irradiance_w_m2: float
    radiant_exposure_j_m2: float
    detail: str
    uv_24h: _mpe.UV24hResult | None = None  # (180-400 nm): the day's summed dose limit
    notes: list[str] = field(default_factory=list)


def exposure_limits(spec: SceneSpec) -> ExposureLimits:
    """Ocular MPE for the laser and exposure of a scene spec (ANSI Z136.1 / IEC 60825-1
    tables via :mod:`hazard.physics.mpe`); pulsed lasers take the smaller of the average-power
    MPE and the per-pulse MPE times the PRF (the repetitive-pulse rules). In the UV the
    limit is also held to the day's summed dose (:func:`uv_24h_limit`), the lowest governing."""
    laser = spec.laser
    wl, t_exp, std = laser.wavelength_nm, spec.exposure.duration_s, spec.exposure.standard
    res = _mpe.ocular_mpe(wl, t_exp, standard=std)
    pulse = None
    mpe_w_m2 = res.irradiance_w_m2
    if laser.power_w is None:
        prf_hz = laser.prf_hz
        if prf_hz is None:  # the spec's validator requires it of a pulsed laser: a spec built around it
            raise ValueError("laser.prf_hz = None: a pulsed laser (no power_w) needs prf_hz [Hz] > 0")
        pulse = _mpe.repetitive_pulse_mpe(wl, laser.pulse_duration_s, prf_hz, t_exp, standard=std)
        mpe_w_m2 = min(mpe_w_m2, pulse.per_pulse_radiant_exposure_j_m2 * prf_hz)
        detail = f"pulsed: per-pulse MPE x PRF = {pulse.per_pulse_radiant_exposure_j_m2 * prf_hz:.6g} W/m^2 average"
    else:
        detail = f"{res.irradiance_w_m2:.6g} W/m^2 for {t_exp:g} s"
    uv, notes = None, []
    if wl < 400:
        uv, note = uv_24h_limit(spec)
        notes.append(note)
        if uv.average_irradiance_w_m2 < mpe_w_m2:
            mpe_w_m2 = uv.average_irradiance_w_m2
            detail += f"; UV 24 h accumulation governs: {mpe_w_m2:.6g} W/m^2 ({uv.total_on_time_s:g} s of exposure in 24 h)"
    return ExposureLimits(res, pulse, mpe_w_m2, mpe_w_m2 * t_exp, detail, uv, notes)


def uv_24h_limit(spec: SceneSpec) -> tuple[_mpe.UV24hResult, str]:
    """The UV (180-400 nm) day's limit of a scene (:func:`hazard.physics.mpe.uv_24h_mpe`) and a note.

    An observer held in place is exposed whenever the laser fires: the exposure time in 24 h
    is the largest lased time of the firing windows (``[laser] windows``) within any 24 h
    (:func:`hazard.physics.mpe.on_time_in_24h_s` of the windows merged once, by
    :meth:`scenes.motion.Windows.of`, as the motion stage lases them), or ``exposure.duration_s`` if longer or when no
    windows are given (then the exposure duration is taken as the day's whole exposure).
    """
    laser, t_exp = spec.laser, spec.exposure.duration_s
    on = _mpe.on_time_in_24h_s(Windows.of(laser.windows).intervals) if laser.windows else 0.0
    total = min(max(t_exp, on), _mpe.UV_ACCUMULATION_S)
    uv = _mpe.uv_24h_mpe(laser.wavelength_nm, total, standard=spec.exposure.standard)
    if laser.windows:
        src = (f"the firing windows lase up to {on:.6g} s within 24 h" + ("" if on >= t_exp else
               f", less than exposure.duration_s = {t_exp:g} s, which is used"))
    else:
        src = (f"no firing windows: exposure.duration_s = {t_exp:g} s is taken as the whole exposure in 24 h "
               f"(give [laser] windows for repeated firing)")
    note = (f"UV: exposures within 24 h add up (ANSI Z136.1-2014 8.2 / IEC 60825-1:2014 A.3, [M]); {src}: the summed dose "
            f"limit is {uv.radiant_exposure_j_m2:.6g} J/m^2 over {uv.total_on_time_s:.6g} s, an average of "
            f"{uv.average_irradiance_w_m2:.6g} W/m^2 while exposed ({uv.mpe.governing_limit}, {uv.mpe.table_row})")
    return uv, note


def attenuation_per_m(spec: SceneSpec) -> float:
    """Beer-Lambert coefficient mu [1/m]: given, or from the visibility (Kruse model,
    :func:`hazard.physics.nohd.attenuation_from_visibility`), else 0."""
    atm = spec.atmosphere
    if atm.attenuation_per_m is not None:
        return atm.attenuation_per_m
    if atm.visibility_km is not None:
        return attenuation_from_visibility(atm.visibility_km, spec.laser.wavelength_nm)
    return 0.0
