"""Maximum permissible exposure (MPE) per ANSI Z136.1 and IEC 60825-1, with every step.

Values and factors from the 2014 editions (ICNIRP 2013 values; ANSI and IEC agree in SI
units) and, for comparison, the 2007 editions, as collected in the project's spec
(`laser-safety.md` sections 2.1-2.5). Every row carries its provenance label:

* ``[C]`` read in a cited public implementation or guide of the standard;
* ``[D]`` derived (e.g. a unit conversion or an identity between two [C] rows);
* ``[M]`` general knowledge, unverified against the standard's text: such rows are
  flagged in the result (``unverified=True``) and in the printed steps.

Coverage: ocular and skin MPE from 180 nm to 1 mm and 1e-13 s to 3e4 s. The UV rows
(180-400 nm: thermal and photochemical dual limits) are written from general knowledge of
ANSI Z136.1-2014 Table 5a and IEC 60825-1:2014 Table A.1 and labelled [M] (flagged as
unverified in every result), with the lower reading taken where the edges are uncertain.
UV exposures within 24 h add up (:func:`uv_24h_mpe`, [M]). The photochemical limit
(400-600 nm) is averaged over its field of view gamma_ph for sources larger than it
(:func:`photochemical_field_of_view_rad`). The tool computes no laser class (no AEL).

Units: SI throughout (J/m^2, W/m^2); ANSI's tables are in J/cm^2 (1 J/cm^2 = 1e4 J/m^2).
Notation: ANSI C_A, C_B, C_C, C_E = IEC C4, C3, C7, C6.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np

from hazard.physics.aperture import limiting_aperture_m

__all__ = [
    "STANDARDS",
    "DEFAULT_STANDARD",
    "MPEResult",
    "CorrectionFactors",
    "correction_factors",
    "ocular_mpe",
    "skin_mpe",
    "repetitive_pulse_mpe",
    "check_standard",
    "photochemical_field_of_view_rad",
    "uv_24h_mpe",
    "on_time_in_24h_s",
    "UV_ACCUMULATION_S",
]

STANDARDS = {
    "ansi-z136.1-2014": "ANSI Z136.1-2014",
    "iec-60825-1-2014": "IEC 60825-1:2014",
    "ansi-z136.1-2007": "ANSI Z136.1-2007",
    "iec-60825-1-2007": "IEC 60825-1:2007",
}
DEFAULT_STANDARD = "ansi-z136.1-2014"

WAVELENGTH_MIN_NM = 180.0
WAVELENGTH_MAX_NM = 1.0e6
DURATION_MIN_S = 1e-13
DURATION_MAX_S = 3e4
ALPHA_MIN_RAD = 1.5e-3


def check_standard(standard: str) -> str:
    """Canonical standard key; ValueError listing the known ones otherwise."""
    key = str(standard).lower()
    if key not in STANDARDS:
        raise ValueError(f"standard={standard!r} is unknown: expected one of {sorted(STANDARDS)}")
    return key


def _edition(standard: str) -> int:
    return int(standard[-4:])


def _table_name(standard: str, kind: str) -> str:
    """Where the row lives: IEC Annex A tables [C]; ANSI table numbers [M]."""
    if standard.startswith("iec"):
        return f"{STANDARDS[standard]} Table A.{'1' if kind == 'ocular' else '5'}"
    which = "ocular MPE table (Table 5a point / 5b extended" if kind == "ocular" else "skin MPE table (Table 7"
    return f"{STANDARDS[standard]} {which}; table number [M])"


def _check_inputs(wavelength_nm, duration_s, angular_subtense_rad):
    for name, v in (("wavelength_nm", wavelength_nm), ("duration_s", duration_s), ("angular_subtense_rad", angular_subtense_rad)):
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
            raise ValueError(f"{name}={v!r}: expected a finite number")
    wl, t, a = float(wavelength_nm), float(duration_s), float(angular_subtense_rad)
    if not WAVELENGTH_MIN_NM <= wl <= WAVELENGTH_MAX_NM:
        raise ValueError(f"wavelength_nm={wl!r} is outside the standards' tables: expected 180 nm to 1 mm (1e6 nm)")
    if not DURATION_MIN_S <= t <= DURATION_MAX_S:
        raise ValueError(f"duration_s={t!r} is outside the tables: expected 1e-13 s to 3e4 s")
    if a < 0:
        raise ValueError(f"angular_subtense_rad={a!r}: expected >= 0 (0 for a point source)")
    return wl, t, a


# ----------------------------------------------------------------------------------------
@dataclass(frozen=True)
class CorrectionFactors:
    """Correction factors and breakpoints (spec section 2.4) at one wavelength/duration."""

    C_A: float
    C_B: float
    C_C: float
    C_E: float
    T1_s: float
    T2_s: float
    alpha_min_rad: float
    alpha_max_rad: float

    def lines(self) -> list:
        return [
            f"C_A (IEC C4) = {self.C_A:.6g}",
            f"C_B (IEC C3) = {self.C_B:.6g}",
            f"C_C (IEC C7) = {self.C_C:.6g}",
            f"C_E (IEC C6) = {self.C_E:.6g}",
            f"T1 = {self.T1_s:.6g} s, T2 = {self.T2_s:.6g} s",
            f"alpha_min = {1e3 * self.alpha_min_rad:.6g} mrad, alpha_max = {1e3 * self.alpha_max_rad:.6g} mrad",
        ]


def correction_factors(wavelength_nm, duration_s, angular_subtense_rad=0.0, standard=DEFAULT_STANDARD) -> CorrectionFactors:
    """C_A, C_B, C_C, C_E, T1, T2, alpha_min, alpha_max (spec section 2.4, [C]).

    C_A = 1 (< 700 nm), 10^(0.002 (l - 700)) (700-1050), 5 (1050-1400).
    C_B = 1 (400-450), 10^(0.02 (l - 450)) (450-600).
    C_C = 1 (< 1150), 10^(0.018 (l - 1150)) (1150-1200), 8 + 10^(0.04 (l - 1250)) (1200-1400;
    2007 editions: 8).
    T1 = 10 s (< 450 nm), 10 * 10^(0.02 (l - 450)) s (450-500), 100 s (> 500); in the UV,
    302.5-315 nm, T1 = 10^(0.8 (l - 295)) 1e-15 s (the thermal / photochemical switch) [M].
    T2 = 10 * 10^((alpha - 1.5) / 98.5) s for alpha in mrad, clipped to [10, 100] s.
    alpha_max (2014) = 5 mrad (t < 625 us), 200 t^0.5 mrad, 100 mrad (t > 0.25 s); 2007: 100.
    C_E = 1 (alpha < alpha_min, and in the UV), alpha / alpha_min, and above alpha_max: alpha_max/alpha_min
    (2014) or alpha^2 / (alpha_min alpha_max) (2007).
    """
    std = check_standard(standard)
    wl, t, alpha = float(wavelength_nm), float(duration_s), float(angular_subtense_rad)
    # the retinal factors apply to 400-1400 nm only; elsewhere they are reported as 1
    retinal = wl < 1400
    c_a = 1.0 if (wl < 700 or not retinal) else (10 ** (0.002 * (wl - 700)) if wl < 1050 else 5.0)
    c_b = 1.0 if (wl < 450 or wl >= 600) else 10 ** (0.02 * (wl - 450))
    if wl < 1150 or not retinal:
        c_c = 1.0
    elif wl < 1200:
        c_c = 10 ** (0.018 * (wl - 1150))
    else:
        c_c = 8.0 + 10 ** (0.04 * (wl - 1250)) if _edition(std) >= 2014 else 8.0
    if 302.5 <= wl < 315:
        t1 = _uv_t1_s(wl)  # the UV T1 (thermal C1 below, photochemical C2 above)
    else:
        t1 = 10.0 if wl < 450 else (10.0 * 10 ** (0.02 * (wl - 450)) if wl < 500 else 100.0)
    a_mrad = alpha * 1e3
    t2 = 10.0 if a_mrad <= 1.5 else (10.0 * 10 ** ((a_mrad - 1.5) / 98.5) if a_mrad <= 100 else 100.0)
    if _edition(std) >= 2014:
        a_max = 5e-3 if t < 625e-6 else (200e-3 * math.sqrt(t) if t <= 0.25 else 0.1)
    else:
        a_max = 0.1
    if alpha < ALPHA_MIN_RAD or wl < 400:  # C_E is a retinal factor: 1 in the UV
        c_e = 1.0
    elif alpha <= a_max:
        c_e = alpha / ALPHA_MIN_RAD
    else:
        c_e = a_max / ALPHA_MIN_RAD if _edition(std) >= 2014 else alpha**2 / (ALPHA_MIN_RAD * a_max)
    return CorrectionFactors(c_a, c_b, c_c, c_e, t1, t2, ALPHA_MIN_RAD, a_max)


# ----------------------------------------------------------------------------------------
@dataclass(frozen=True)
class _Limit:
    """One candidate limit: radiant exposure H [J/m^2] with its row, formula and label."""

    name: str
    radiant_exposure_j_m2: float
    row: str
    formula: str
    label: str

    @property
    def unverified(self) -> bool:
        return "[M]" in self.label or "UNVERIFIED" in self.label


@dataclass(frozen=True)
class MPEResult:
    """An MPE with everything needed to redo it by hand.

    Attributes
    ----------
    radiant_exposure_j_m2 : float
        MPE as radiant exposure H over the exposure duration [J/m^2].
    irradiance_w_m2 : float
        MPE as average irradiance over the duration, H / t [W/m^2].
    governing_limit : str
        Which limit governs (e.g. "retinal thermal", "photochemical", "corneal").
    table_row, formula : str
        The row of the standard and the formula with numbers.
    limits : tuple
        Every candidate limit of a dual-limit case, as (name, H [J/m^2], label).
    unverified : bool
        True when the governing row is labelled [M] (not verified against the text).
    steps : tuple of str
        The calculation, line by line.
    """

    kind: str
    standard: str
    wavelength_nm: float
    duration_s: float
    angular_subtense_rad: float
    radiant_exposure_j_m2: float
    irradiance_w_m2: float
    governing_limit: str
    table_row: str
    formula: str
    label: str
    unverified: bool
    factors: CorrectionFactors
    limits: tuple
    limiting_aperture_m: float
    steps: tuple = field(default=())

    def to_dict(self) -> dict:
        return {
            "kind": self.kind,
            "standard": self.standard,
            "standard_title": STANDARDS[self.standard],
            "wavelength_nm": self.wavelength_nm,
            "duration_s": self.duration_s,
            "angular_subtense_rad": self.angular_subtense_rad,
            "radiant_exposure_j_m2": self.radiant_exposure_j_m2,
            "irradiance_w_m2": self.irradiance_w_m2,
            "governing_limit": self.governing_limit,
            "table_row": self.table_row,
            "formula": self.formula,
            "label": self.label,
            "unverified": self.unverified,
            "factors": self.factors.__dict__.copy(),
            "limits": [{"name": n, "radiant_exposure_j_m2": h, "label": lab} for n, h, lab in self.limits],
            "limiting_aperture_m": self.limiting_aperture_m,
            "steps": list(self.steps),
        }

    def explain(self) -> str:
        """Which limit governed and why: every candidate limit compared, lowest first."""
        order = sorted(self.limits, key=lambda c: c[1])
        lines = [f"Why: {STANDARDS[self.standard]} applies {len(order)} limit(s) here; the MPE is the lowest:"]
        for name, h, label in order:
            mark = "  <- governs" if name == self.governing_limit else f" ({h / order[0][1]:.4g}x the governing value)"
            lines.append(f"  {name}: H = {h:.6g} J/m^2 {label}{mark}")
        lines.append(f"  governing row: {self.table_row}")
        if self.unverified:
            lines.append("  the governing row is [M]: not verified against the standard's text (see hazard.physics.mpe and the README)")
        return "\n".join(lines)

    def __str__(self):
        return "\n".join(self.steps)


def _limiting_aperture_m(kind: str, wl: float, t: float, governing: str) -> float:
    """Limiting aperture (spec section 2.4): the table of :func:`hazard.physics.aperture.limiting_aperture_m`
    (retina 7 mm; skin 3.5 mm; cornea 1 mm (t < 0.3 s), 1.5 t^0.375 mm (0.3-10 s), 3.5 mm
    (t > 10 s) [C]), the corneal row applied above 1400 nm and to the ANSI corneal limit."""
    if kind != "skin" and wl < 1400 and governing.startswith("corneal"):
        return limiting_aperture_m(1400.0, t)
    return limiting_aperture_m(wl, t, skin=(kind == "skin"))


# -- ocular rows ----------------------------------------------------------------------------
def _retinal_thermal(wl, t, f: CorrectionFactors, std, alpha) -> _Limit:
    ed = _edition(std)
    far = wl >= 1050
    band = "1050-1400 nm" if far else ("700-1050 nm" if wl >= 700 else "400-700 nm")
    ca, cc, ce = f.C_A, f.C_C, f.C_E
    src = "[C] OLBtools Z136 (A), akufcsak table_a1 (I)"
    if t < 1e-11:
        if ed >= 2014:
            if far:
                h = 1e-3 * cc
                return _Limit("retinal thermal", h, f"{band}, 1e-13 - 1e-11 s", f"H = 1e-3 C_C = 1e-3 * {cc:.6g}",
                              "[C] code A only, UNVERIFIED (IEC 2007 had 1.5e-3 C7 C6)")
            return _Limit("retinal thermal", 1e-3, f"{band}, 1e-13 - 1e-11 s", "H = 1.0e-3 J/m^2 (no C_A in either code)", src)
        if far:
            h = 1.5e-3 * cc * ce
            return _Limit("retinal thermal", h, f"{band}, 1e-13 - 1e-11 s", f"H = 1.5e-3 C7 C6 = 1.5e-3 * {cc:.6g} * {ce:.6g}", "[C] IEC 2007 (spec 2.1)")
        raise ValueError(
            f"duration_s={t!r}: {STANDARDS[std]} has no verified row below 1e-11 s for 400-1050 nm in this tool; "
            f"use a 2014 edition"
        )
    if ed >= 2014:
        ns_end = 1.3e-5 if far else 5e-6
        if t < ns_end:
            if far:
                return _Limit("retinal thermal", 2e-2 * cc * ce, f"{band}, 1e-11 - 1.3e-5 s",
                              f"H = 2.0e-2 C_C C_E = 2.0e-2 * {cc:.6g} * {ce:.6g}", src)
            return _Limit("retinal thermal", 2e-3 * ca * ce, f"{band}, 1e-11 - 5e-6 s",
                          f"H = 2.0e-3 C_A C_E = 2.0e-3 * {ca:.6g} * {ce:.6g}", src)
    else:
        if t < 1e-9:
            k = 2.7e5 if far else 2.7e4
            fac = cc if far else ca
            name = "C_C" if far else "C_A"
            return _Limit("retinal thermal", k * t**0.75 * fac * ce, f"{band}, 1e-11 - 1e-9 s",
                          f"H = {k:.1e} t^0.75 {name} C_E = {k:.1e} * {t:.6g}^0.75 * {fac:.6g} * {ce:.6g}",
                          "[C] Laser-Studio EMPdataBinary (2007)")
        ns_end = 5e-5 if far else 1.8e-5
        if t < ns_end:
            if far:
                return _Limit("retinal thermal", 5e-2 * cc * ce, f"{band}, 1e-9 - 5e-5 s",
                              f"H = 5e-2 C_C C_E = 5e-2 * {cc:.6g} * {ce:.6g}", "[C] Laser-Studio (2007)")
            return _Limit("retinal thermal", 5e-3 * ca * ce, f"{band}, 1e-9 - 1.8e-5 s",
                          f"H = 5e-3 C_A C_E = 5e-3 * {ca:.6g} * {ce:.6g}", "[C] Laser-Studio (2007)")
    k, fac, fac_name = (90.0, cc, "C_C") if far else (18.0, ca, "C_A")
    start = ("1.3e-5" if far else "5e-6") if ed >= 2014 else ("5e-5" if far else "1.8e-5")
    if t < 10:
        return _Limit("retinal thermal", k * fac * ce * t**0.75, f"{band}, {start} - 10 s",
                      f"H = {k:g} {fac_name} C_E t^0.75 = {k:g} * {fac:.6g} * {ce:.6g} * {t:.6g}^0.75", src)
    # t >= 10 s
    if alpha <= ALPHA_MIN_RAD:
        e = 10.0 * ca * cc
        formula = f"E = 10 C_A C_C W/m^2 = 10 * {ca:.6g} * {cc:.6g}; H = E t"
        return _Limit("retinal thermal", e * t, f"{band}, 10 - 3e4 s (point source)", formula, src)
    if t < f.T2_s:
        return _Limit("retinal thermal", k * fac * ce * t**0.75,
                      f"{band}, 10 s - T2 (extended source)",
                      f"H = {k:g} {fac_name} C_E t^0.75 = {k:g} * {fac:.6g} * {ce:.6g} * {t:.6g}^0.75",
                      "[M] extended-source rule (IEC 60825-1:2014 Table A.1 structure), unverified")
    e = k * fac * ce * f.T2_s**-0.25
    return _Limit("retinal thermal", e * t, f"{band}, T2 - 3e4 s (extended source)",
                  f"E = {k:g} {fac_name} C_E T2^-0.25 = {k:g} * {fac:.6g} * {ce:.6g} * {f.T2_s:.6g}^-0.25 W/m^2; H = E t",
                  "[M] extended-source rule (IEC 60825-1:2014 Table A.1 structure), unverified")


def photochemical_field_of_view_rad(duration_s) -> float:
    """The photochemical limit's field of view (limiting cone angle) gamma_ph [rad].

    gamma_ph = 11 mrad (t <= 100 s), 1.1 t^0.5 mrad (100 - 1e4 s), 110 mrad (t > 1e4 s):
    ANSI Z136.1-2014 / IEC 60825-1:2014 (ICNIRP 2013 values), spec section 2.4 [C].
    Continuous: 1.1 * 100^0.5 = 11 and 1.1 * 1e4^0.5 = 110.
    """
    t = float(duration_s)
    if not (math.isfinite(t) and t > 0):
        raise ValueError(f"duration_s={duration_s!r}: expected a finite duration > 0 s")
    return 11e-3 if t <= 100.0 else (1.1e-3 * math.sqrt(t) if t <= 1e4 else 110e-3)


def _cone_solid_angle_sr(full_angle_rad):
    """Solid angle [sr] of a cone of full angle ``full_angle_rad``: 2 pi (1 - cos(a / 2)),
    never above the small-angle pi a^2 / 4."""
    return 4.0 * math.pi * math.sin(full_angle_rad / 4.0) ** 2


def _photochemical(wl, t, f: CorrectionFactors, std, alpha=0.0):
    """Photochemical (blue-light) limit, 400-600 nm, t >= 10 s ([C] A), with its field of view.

    Point source (alpha <= gamma_ph): H = 100 C_B J/m^2 (10 - 100 s), E = 1 C_B W/m^2
    (100 - 3e4 s). The limit is on the irradiance averaged over the limiting cone angle
    gamma_ph (:func:`photochemical_field_of_view_rad`), so a uniform source of subtense
    alpha > gamma_ph puts only (gamma_ph / alpha)^2 of its irradiance in that field: the
    limit on the whole irradiance is the point value x (alpha / gamma_ph)^2. The tables'
    radiance form of the same limit (ANSI Z136.1 Table 5b; ICNIRP 2013), L_p t =
    1e6 C_B J m^-2 sr^-1 (10 - 1e4 s) or L_p = 100 C_B W m^-2 sr^-1 (1e4 - 3e4 s), gives
    H = L_p t Omega(alpha), up to 5 % lower (1e6 * Omega(11 mrad) = 95 against 100); the
    lower of the two readings applies, never below the point value.
    """
    if not (400 <= wl < 600 and t >= 10):
        return None
    label = "[C] OLBtools Z136 (A)" if _edition(std) >= 2014 else "[M] same values assumed for 2007"
    if t < 100:
        point = _Limit("photochemical", 100.0 * f.C_B, "400-600 nm, 10 - 100 s", f"H = 100 C_B J/m^2 = 100 * {f.C_B:.6g}", label)
    else:
        point = _Limit("photochemical", f.C_B * t, "400-600 nm, 100 - 3e4 s", f"E = 1 C_B W/m^2 = {f.C_B:.6g}; H = E t", label)
    gamma = photochemical_field_of_view_rad(t)
    if alpha <= gamma:
        return point
    h_fov = point.radiant_exposure_j_m2 * (alpha / gamma) ** 2
    omega = _cone_solid_angle_sr(alpha)
    lt = 1e6 * f.C_B if t < 1e4 else 100.0 * f.C_B * t
    h_rad = lt * omega
    h = max(point.radiant_exposure_j_m2, min(h_fov, h_rad))
    formula = (f"{point.formula}; alpha = {1e3 * alpha:.6g} mrad > gamma_ph = {1e3 * gamma:.6g} mrad: lower of "
               f"H_pt (alpha / gamma_ph)^2 = {point.radiant_exposure_j_m2:.6g} * ({1e3 * alpha:.6g} / {1e3 * gamma:.6g})^2 = {h_fov:.6g} "
               f"and L_p t Omega(alpha) = {lt:.6g} J/(m^2 sr) * {omega:.6g} sr = {h_rad:.6g} J/m^2 (never below H_pt)")
    return _Limit("photochemical", h, f"{point.row}, extended source averaged over gamma_ph (ANSI Table 5b; IEC Table A.1 gamma_ph)",
                  formula, "[C] gamma_ph (spec 2.4), ANSI Z136.1-2007 Table 5b radiance form (Psychtoolbox AnsiZ136MPE); "
                  "[M] the averaging rule for the 2014 editions")


def _corneal_ansi(wl, t, std):
    """ANSI Z136.1-2014 corneal dual limit, 1200-1400 nm [C] OLBtools (A), with the
    t^0.25 term only in its own band (the OLBtools precedence pitfall, spec 2.6)."""
    if not (std == "ansi-z136.1-2014" and 1200 <= wl < 1400 and t >= 1e-11):
        return None
    k = 10 ** (0.01 * (1400 - wl))
    if t < 1e-3:
        h_cm2, formula = 0.3 * k, f"H = 0.3 K = 0.3 * {k:.6g} J/cm^2"
    elif t < 4:
        h_cm2 = 0.3 * k + 0.56 * t**0.25 - 0.1
        formula = f"H = 0.3 K + 0.56 t^0.25 - 0.1 = 0.3 * {k:.6g} + 0.56 * {t:.6g}^0.25 - 0.1 J/cm^2"
    elif t < 10:
        h_cm2, formula = 0.3 * k + 0.7, f"H = 0.3 K + 0.7 = 0.3 * {k:.6g} + 0.7 J/cm^2"
    else:
        h_cm2 = (0.03 * k + 0.07) * t
        formula = f"E = 0.03 K + 0.07 = 0.03 * {k:.6g} + 0.07 W/cm^2; H = E t"
    return _Limit("corneal", h_cm2 * 1e4, "1200-1400 nm corneal dual limit, K = 10^(0.01 (1400 - l))",
                  formula + " (x 1e4 to J/m^2)", "[C] OLBtools Z136 (A)")


def _anterior_dual(wl, t, f: CorrectionFactors, std):
    """IEC 60825-1:2014, 1200-1400 nm: the anterior-segment (cornea/lens) dual limit.

    Table A.1 of IEC 60825-1:2014 gives only the retinal row (C7) here; the edition applies
    an anterior-segment limit in this band only through the Class 3B AEL used as a dual
    limit for Class 1 (clause 4.3 / Table 3 notes, [P] - the text was not read), while
    ICNIRP 2013, whose values the edition adopts, recommends the skin MPE as the dual limit
    and ANSI Z136.1-2014 Table 5a prints the K_lambda corneal row. The text being unclear,
    both readable candidates are applied and the lower governs (more protective):

    * corneal, ANSI Z136.1-2014 Table 5a 1200-1400 nm row (K_lambda = 10^(0.01 (1400 - l))),
      converted to J/m^2 - [M] for IEC;
    * skin MPE, IEC 60825-1:2014 Table A.5 400-1400 nm rows (ICNIRP 2013's dual limit), [M].

    The Class 3B AEL is not used: it is a power through the 7 mm aperture, not an exposure,
    and is above both candidates for beams narrower than about 4 mm (Schulmeister et al.,
    comparison of corneal injury thresholds with laser safety limits, abstract [P]).
    ANSI Z136.1-2014 mode keeps its own corneal row; below 1e-9 s, where that row ends
    and only the unverified sub-1e-11 s retinal row remains (1e-3 C_C: 990 J/m^2 at
    1399.9 nm against 1 J/m^2 at 1400 nm), the skin-MPE candidate (E = 2e11 C_A W/m^2 =
    the 1400-1500 nm sub-ns row) is applied too, [M], as the protective extension.
    Returns the candidates (none outside 1200-1400 nm or for the 2007 editions).
    """
    if not (1200 <= wl < 1400 and std in ("iec-60825-1-2014", "ansi-z136.1-2014")):
        return []
    if std == "ansi-z136.1-2014":
        if t >= 1e-9:
            return []
        skin = _skin_400_1400(wl, t, f, std)
        return [_Limit("corneal: skin MPE", skin.radiant_exposure_j_m2, f"sub-ns corneal dual limit: skin MPE {skin.row}", skin.formula,
                       "[M] ANSI Z136.1-2014 has no verified sub-ns corneal row: the skin/1400 nm sub-ns value applied (protective)")]
    k = _corneal_ansi(wl, t, "ansi-z136.1-2014")
    skin = _skin_400_1400(wl, t, f, std)
    out = []
    if k is not None:
        out.append(_Limit("corneal", k.radiant_exposure_j_m2, f"IEC 2014 anterior-segment dual limit: {k.row} (ANSI Z136.1-2014 Table 5a row)",
                          k.formula, "[M] ANSI/ICNIRP 2013 corneal row applied to IEC 2014 (IEC text unclear: lower of the candidates)"))
    out.append(_Limit("corneal: skin MPE", skin.radiant_exposure_j_m2,
                      f"IEC 2014 anterior-segment dual limit: skin MPE, IEC 60825-1:2014 Table A.5 {skin.row}", skin.formula,
                      "[M] ICNIRP 2013 skin-MPE dual limit applied (IEC text unclear: lower of the candidates)"))
    return out


def _uv_t1_s(wl):
    """T1 = 10^(0.8 (l - 295)) * 1e-15 s, 302.5-315 nm (IEC 60825-1:2014 Table A.3 / Table 9
    factors; ANSI Z136.1-2014 Table 6) [M]: 1e-9 s at 302.5 nm, 10 s at 315 nm, where the
    thermal C1 = 5.6e3 t^0.25 J/m^2 meets the photochemical C2 = 10^(0.2 (l - 295)) J/m^2
    to 0.43 % (5.6e3 * 10^-3.75 = 0.9957)."""
    return 10 ** (0.8 * (wl - 295.0)) * 1e-15


def _ultraviolet(wl, t, std):
    """UV ocular (and skin) MPE, 180-400 nm: the thermal and photochemical dual limits.

    Values from general knowledge of the tables, [M] (not read in the standards' text):

    * IEC 60825-1:2014 (and 2007) Table A.1, rows 180-400 nm (same numbers in Table A.5 for
      the skin): t < 1e-9 s: E = 3e10 W/m^2; 180-302.5 nm: H = 30 J/m^2 (1e-9 - 3e4 s);
      302.5-315 nm: H = C1 = 5.6e3 t^0.25 J/m^2 for t < T1, H = C2 = 10^(0.2 (l - 295))
      J/m^2 for T1 <= t <= 3e4 s; 315-400 nm: C1 (1e-9 - 10 s), 1e4 J/m^2 (10 - 1e3 s),
      E = 10 W/m^2 (1e3 - 3e4 s).
    * ANSI Z136.1-2014 (and 2007) Table 5a, rows 0.180-0.400 um: thermal H = 0.56 t^0.25 J/cm^2
      (1e-9 - 10 s) and photochemical H = 3e-3 J/cm^2 (0.180-0.302 um), 10^(0.2 (l - 295))
      1e-4 J/cm^2 (0.302-0.315 um), 1.0 J/cm^2 (0.315-0.400 um, 10 - 3e4 s), the lower
      governing. Band edge 302 nm as ANSI prints it; from 302 to 302.5 nm the lower of 30
      J/m^2 and C2 (the two readings of the edge). Below 1e-9 s ANSI has no verified UV row:
      the IEC 3e10 W/m^2 is used.
    """
    iec = std.startswith("iec")
    label = "[M] IEC 60825-1 Table A.1 UV row (general knowledge, unverified)" if iec else \
        "[M] ANSI Z136.1 Table 5a UV row (general knowledge, unverified)"
    if t < 1e-9:
        return [_Limit("UV thermal/photochemical", 3e10 * t, "180-400 nm, < 1e-9 s", "E = 3e10 W/m^2; H = E t",
                       label + ("" if iec else "; the IEC sub-ns value, ANSI row not verified"))]
    c1 = 5.6e3 * t**0.25
    thermal = _Limit("UV thermal", c1, "180-400 nm, 1e-9 - 10 s (thermal)", f"H = C1 = 5.6e3 t^0.25 = 5.6e3 * {t:.6g}^0.25 J/m^2"
                     + ("" if iec else " (0.56 t^0.25 J/cm^2)"), label)
    c2 = 10 ** (0.2 * (wl - 295.0))
    if wl < 315.0:
        edge = 302.5 if iec else 302.0
        if wl < edge:
            photo = _Limit("UV photochemical", 30.0, f"180-{edge:g} nm, 1e-9 - 3e4 s (photochemical)", "H = 30 J/m^2 (3e-3 J/cm^2)", label)
        elif wl < 302.5:  # ANSI only: the two readings of the 302 / 302.5 nm band edge
            hp = min(30.0, c2)
            photo = _Limit("UV photochemical", hp, "302-302.5 nm (ANSI band edge 0.302 um), 1e-9 - 3e4 s (photochemical)",
                           f"H = min(30, C2 = 10^(0.2 ({wl:g} - 295))) = min(30, {c2:.6g}) J/m^2 (lower of the two edge readings)", label)
        else:
            photo = _Limit("UV photochemical", c2, "302.5-315 nm, 1e-9 - 3e4 s (photochemical)" if not iec else "302.5-315 nm, T1 - 3e4 s (photochemical)",
                           f"H = C2 = 10^(0.2 (l - 295)) = 10^(0.2 * ({wl:g} - 295)) = {c2:.6g} J/m^2", label)
        if iec and wl >= 302.5:
            # IEC Table A.1 switches at T1 (C1 below, C2 from T1 on), not a running minimum
            t1 = _uv_t1_s(wl)
            return [thermal] if t < t1 else [photo]
        return [photo, thermal] if t < 10.0 else [photo]
    # 315-400 nm
    if t < 10.0:
        return [thermal]
    if not iec:
        return [_Limit("UV photochemical", 1e4, "315-400 nm, 10 - 3e4 s (photochemical)", "H = 1.0 J/cm^2 = 1e4 J/m^2", label)]
    if t < 1e3:
        return [_Limit("UV photochemical", 1e4, "315-400 nm, 10 - 1e3 s (photochemical)", "H = 1e4 J/m^2", label)]
    return [_Limit("UV photochemical", 10.0 * t, "315-400 nm, 1e3 - 3e4 s (photochemical)", "E = 10 W/m^2; H = E t", label)]


def _infrared(wl, t, std):
    """1400 nm - 1 mm (cornea/skin), spec 2.3: IEC [C] Laser-Studio (2007 table); ANSI
    equivalents [M]."""
    label = "[C] Laser-Studio (IEC 2007 table)" if std.startswith("iec") else "[M] ANSI equivalent of the IEC row"
    if 1400 <= wl < 1500 or 1800 <= wl < 2600:
        band, e_sub = ("1400-1500 nm" if wl < 1500 else "1800-2600 nm"), 1e12
    elif 1500 <= wl < 1800:
        band, e_sub = "1500-1800 nm", 1e13
    else:
        band, e_sub = "2600 nm - 1 mm", 1e11
    if t >= 10:
        return _Limit("corneal", 1000.0 * t, "1400 nm - 1 mm, 10 - 3e4 s", "E = 1000 W/m^2; H = E t", label)
    if t < 1e-9:
        return _Limit("corneal", e_sub * t, f"{band}, < 1e-9 s", f"E = {e_sub:.0e} W/m^2; H = E t", label)
    if band == "1500-1800 nm":
        return _Limit("corneal", 1e4, f"{band}, 1e-9 - 10 s", "H = 1e4 J/m^2", label)
    if band == "2600 nm - 1 mm":
        if t < 1e-7:
            return _Limit("corneal", 100.0, f"{band}, 1e-9 - 1e-7 s", "H = 100 J/m^2", label)
        return _Limit("corneal", 5600.0 * t**0.25, f"{band}, 1e-7 - 10 s", f"H = 5600 t^0.25 = 5600 * {t:.6g}^0.25", label)
    if t < 1e-3:
        return _Limit("corneal", 1000.0, f"{band}, 1e-9 - 1e-3 s", "H = 1000 J/m^2", label)
    return _Limit("corneal", 5600.0 * t**0.25, f"{band}, 1e-3 - 10 s", f"H = 5600 t^0.25 = 5600 * {t:.6g}^0.25", label)


def _skin_400_1400(wl, t, f: CorrectionFactors, std):
    """Skin, 400-1400 nm, spec 2.5: [C] akufcsak table_a5 and Laser-Studio."""
    ca = f.C_A
    label = "[C] akufcsak table_a5, Laser-Studio adaptForSkinEMP"
    if t < 1e-9:
        return _Limit("skin", 2e11 * ca * t, "400-1400 nm, < 1e-9 s", f"E = 2e11 C_A W/m^2 = 2e11 * {ca:.6g}; H = E t", label)
    if t < 1e-7:
        return _Limit("skin", 200.0 * ca, "400-1400 nm, 1e-9 - 1e-7 s", f"H = 200 C_A J/m^2 = 200 * {ca:.6g}", label)
    if t < 10:
        return _Limit("skin", 1.1e4 * ca * t**0.25, "400-1400 nm, 1e-7 - 10 s",
                      f"H = 1.1e4 C_A t^0.25 = 1.1e4 * {ca:.6g} * {t:.6g}^0.25", label)
    return _Limit("skin", 2000.0 * ca * t, "400-1400 nm, 10 - 3e4 s", f"E = 2000 C_A W/m^2 = 2000 * {ca:.6g}; H = E t", label)


def _result(kind, std, wl, t, alpha, f, candidates) -> MPEResult:
    candidates = [c for c in candidates if c is not None]
    gov = min(candidates, key=lambda c: c.radiant_exposure_j_m2)
    h = gov.radiant_exposure_j_m2
    aperture = _limiting_aperture_m(kind, wl, t, gov.name)
    table = _table_name(std, kind)
    steps = [
        f"{kind.capitalize()} MPE per {STANDARDS[std]} at {wl:g} nm for {t:g} s"
        + (f", source subtense {1e3 * alpha:g} mrad" if alpha > 0 else " (point source)"),
        *[f"  {line}" for line in f.lines()],
    ]
    for c in candidates:
        mark = "  <- governs (lowest)" if c is gov and len(candidates) > 1 else ""
        steps.append(f"  {c.name} limit, {table}, row {c.row}: {c.formula} -> H = {c.radiant_exposure_j_m2:.6g} J/m^2 {c.label}{mark}")
    steps.append(f"  MPE: H = {h:.6g} J/m^2 ({h * 1e-4:.6g} J/cm^2); E = H / t = {h / t:.6g} W/m^2 ({h / t * 1e-4:.6g} W/cm^2)")
    steps.append(f"  limiting aperture: {1e3 * aperture:.4g} mm")
    if gov.unverified:
        steps.append("  WARNING: the governing row is not verified against the standard's text; check it before relying on it")
    return MPEResult(
        kind=kind,
        standard=std,
        wavelength_nm=wl,
        duration_s=t,
        angular_subtense_rad=alpha,
        radiant_exposure_j_m2=h,
        irradiance_w_m2=h / t,
        governing_limit=gov.name,
        table_row=f"{table}: {gov.row}",
        formula=gov.formula,
        label=gov.label,
        unverified=gov.unverified,
        factors=f,
        limits=tuple((c.name, c.radiant_exposure_j_m2, c.label) for c in candidates),
        limiting_aperture_m=aperture,
        steps=tuple(steps),
    )


def ocular_mpe(wavelength_nm, duration_s, *, standard=DEFAULT_STANDARD, angular_subtense_rad=0.0) -> MPEResult:
    """Ocular MPE for a single exposure of ``duration_s`` at ``wavelength_nm``.

    Parameters
    ----------
    wavelength_nm : float
        180 nm to 1 mm (1e6 nm).
    duration_s : float
        Exposure duration, 1e-13 s to 3e4 s (the pulse duration for a single pulse).
    standard : str
        ``"ansi-z136.1-2014"`` (default), ``"iec-60825-1-2014"``, or the 2007 editions.
    angular_subtense_rad : float
        Apparent source size alpha [rad] (0: point source). Enters C_E and T2.

    Returns
    -------
    MPEResult
        The lowest of the applicable limits (retinal thermal, photochemical 400-600 nm
        for t >= 10 s - averaged over gamma_ph when alpha > gamma_ph - ANSI corneal
        1200-1400 nm; corneal above 1400 nm), with every step.
    """
    std = check_standard(standard)
    wl, t, alpha = _check_inputs(wavelength_nm, duration_s, angular_subtense_rad)
    return _at_breakpoints("ocular", std, wl, t, alpha, _ocular_candidates)


def _ocular_candidates(wl, t, alpha, std):
    """Correction factors and candidate limits of the ocular MPE at (``wl``, ``t``)."""
    f = correction_factors(wl, t, alpha, std)
    if wl < 400:
        return f, _ultraviolet(wl, t, std)
    if wl < 1400:
        return f, [_retinal_thermal(wl, t, f, std, alpha), _photochemical(wl, t, f, std, alpha), _corneal_ansi(wl, t, std),
                   *_anterior_dual(wl, t, f, std)]
    return f, [_infrared(wl, t, std)]


def _skin_candidates(wl, t, alpha, std):
    """Correction factors and candidate limits of the skin MPE at (``wl``, ``t``)."""
    f = correction_factors(wl, t, 0.0, std)
    if wl < 400:
        return f, _ultraviolet(wl, t, std)  # the UV skin rows equal the eye's (IEC Table A.5, ANSI Table 7) [M]
    return f, [_skin_400_1400(wl, t, f, std) if wl < 1400 else _infrared(wl, t, std)]


def _at_breakpoints(kind, std, wl, t, alpha, candidates_of) -> MPEResult:
    """The MPE at (``wl``, ``t``); where a duration or wavelength is exactly a table
    breakpoint (a row ends there and the next begins, or a band edge), the lower of the
    rows that meet there: the tables print both ends ("1e-11 - 1e-9 s", "1e-9 - 1.8e-5
    s") and a round input such as a 1 ns pulse or a 10 s exposure lands on them (IEC
    60825-1:2007, 532 nm, 1 ns: 4.80e-3 J/m^2 from the row ending there, not 5e-3). The
    adjacent rows are read one float step (ulp) away, so only an input exactly on a
    breakpoint can change (10 s less one ulp is not); the steps say so when it governs."""
    f, cands = candidates_of(wl, t, alpha, std)
    h0 = min(c.radiant_exposure_j_m2 for c in cands if c is not None)
    best = (h0, wl, t, f, cands)
    ws, ts = (math.nextafter(wl, 0.0), math.nextafter(wl, math.inf)), (math.nextafter(t, 0.0), math.nextafter(t, math.inf))
    for w, tt in [(wl, x) for x in ts] + [(x, t) for x in ws] + [(x, y) for x in ws for y in ts]:  # fewest moved first
        if not (WAVELENGTH_MIN_NM <= w <= WAVELENGTH_MAX_NM and DURATION_MIN_S <= tt <= DURATION_MAX_S):
            continue
        try:
            fn, cn = candidates_of(w, tt, alpha, std)
        except ValueError:  # no row of this edition there (e.g. below 1e-11 s): nothing to compare
            continue
        h = min(c.radiant_exposure_j_m2 for c in cn if c is not None)
        if h < best[0] * (1 - 1e-12):  # a jump, not the row's own slope over one ulp
            best = (h, w, tt, fn, cn)
    res = _result(kind, std, wl, t, alpha, best[3], best[4])
    if best[0] < h0:
        where = " and ".join(x for x, moved in (("duration", best[2] != t), ("wavelength", best[1] != wl)) if moved)
        res = replace(res, steps=(*res.steps, f"  the {where} is a table breakpoint: the adjacent row gives {best[0]:.6g} J/m^2 "
                                               f"there against {h0:.6g} J/m^2 from the other row meeting there; the lower is used "
                                               "(read one float step inside that row: conservative)"))
    return res


def skin_mpe(wavelength_nm, duration_s, *, standard=DEFAULT_STANDARD) -> MPEResult:
    """Skin MPE (spec section 2.5): 400-1400 nm from the skin table; above 1400 nm the
    skin MPE equals the ocular (corneal) MPE [C Laser-Studio]."""
    std = check_standard(standard)
    wl, t, _ = _check_inputs(wavelength_nm, duration_s, 0.0)
    return _at_breakpoints("skin", std, wl, t, 0.0, _skin_candidates)


# ----------------------------------------------------------------------------------------
UV_ACCUMULATION_S = 86400.0  # 24 h: the UV exposures of a day add up (ANSI Z136.1-2014 8.2; IEC 60825-1:2014 A.3) [M]


@dataclass(frozen=True)
class UV24hResult:
    """The 24 h (accumulated) UV limit: the dose of every exposure within 24 h, summed,
    against the MPE of one exposure lasting their total duration.

    Attributes
    ----------
    total_on_time_s : float
        Sum of the exposure durations within the 24 h [s].
    radiant_exposure_j_m2 : float
        Limit on the summed dose [J/m^2].
    average_irradiance_w_m2 : float
        The same as an irradiance while exposed, H / total_on_time_s [W/m^2].
    mpe : MPEResult
        The single-exposure MPE evaluated at the total (clipped to the tables' 3e4 s).
    """

    wavelength_nm: float
    standard: str
    total_on_time_s: float
    radiant_exposure_j_m2: float
    average_irradiance_w_m2: float
    mpe: MPEResult
    label: str
    steps: tuple
    kind: str = "ocular"

    def to_dict(self) -> dict:
        return {"wavelength_nm": self.wavelength_nm, "standard": self.standard, "kind": self.kind, "accumulation_s": UV_ACCUMULATION_S,
                "total_on_time_s": self.total_on_time_s, "radiant_exposure_j_m2": self.radiant_exposure_j_m2,
                "average_irradiance_w_m2": self.average_irradiance_w_m2, "governing_limit": self.mpe.governing_limit,
                "table_row": self.mpe.table_row, "label": self.label, "unverified": True, "steps": list(self.steps)}

    def __str__(self):
        return "\n".join(self.steps)


def uv_24h_mpe(wavelength_nm, exposure_durations_s, *, standard=DEFAULT_STANDARD, kind="ocular") -> UV24hResult:
    """MPE for the UV exposures (180-400 nm) of the eye or the skin received within 24 h,
    which add up.

    Both standards treat the ultraviolet limits as cumulative over a day: exposures
    repeated within 24 h are summed and the sum compared with the MPE for their total
    duration (ANSI Z136.1-2014 section 8.2, repeated exposures; IEC 60825-1:2014 Annex A,
    A.3; ICNIRP 2013) - [M]: clause wording from general knowledge, not read in the text.
    The rule applied is therefore: dose summed over the exposures <= H(T_sum), the
    single-exposure MPE (:func:`ocular_mpe`, the lowest of its thermal and photochemical
    candidates) at T_sum = the sum of the durations. Each exposure must also meet its own
    MPE (checked elsewhere). The tables end at 3e4 s: for T_sum > 3e4 s the 3e4 s value is
    used, never extrapolated upward (constant-H rows are unchanged; IEC's 315-400 nm
    E = 10 W/m^2 row stops at 3e5 J/m^2, the lower reading).

    Parameters
    ----------
    wavelength_nm : float
        180 nm to 400 nm.
    exposure_durations_s : float or sequence of float
        Durations [s] of the exposures within 24 h (or their total), each > 0, summed <= 24 h.
    standard : str
        One of :data:`STANDARDS`.
    kind : {"ocular", "skin"}
        Whose MPE: :func:`ocular_mpe` or :func:`skin_mpe`. The skin's UV rows (ANSI
        Z136.1-2014 Table 7, IEC 60825-1:2014 Table A.5, 180-400 nm) are the same dual
        photochemical/thermal limits as the eye's [M], and the same 24 h summing is applied
        to them [M] (the UV skin limits are erythema doses, cumulative like the eye's).
    """
    std = check_standard(standard)
    if kind not in ("ocular", "skin"):
        raise ValueError(f"kind={kind!r}: expected 'ocular' or 'skin'")
    wl, _, _ = _check_inputs(wavelength_nm, 1.0, 0.0)
    if not wl < 400.0:
        raise ValueError(f"wavelength_nm={wl!r}: the 24 h accumulation applies to the ultraviolet, expected 180 to < 400 nm")
    durs = [exposure_durations_s] if isinstance(exposure_durations_s, (int, float)) else list(exposure_durations_s)
    for i, d in enumerate(durs):
        if isinstance(d, bool) or not isinstance(d, (int, float)) or not math.isfinite(d) or d <= 0:
            raise ValueError(f"exposure_durations_s[{i}]={d!r}: expected a finite duration > 0 s")
    total = float(sum(durs))
    if not 0 < total <= UV_ACCUMULATION_S * (1 + 1e-12):
        raise ValueError(f"exposure_durations_s sum to {total!r} s: expected > 0 and at most 24 h = {UV_ACCUMULATION_S:g} s")
    t_eval = min(max(total, DURATION_MIN_S), DURATION_MAX_S)
    res = ocular_mpe(wl, t_eval, standard=std) if kind == "ocular" else skin_mpe(wl, t_eval, standard=std)
    h = res.radiant_exposure_j_m2
    label = "[M] UV 24 h accumulation (ANSI Z136.1-2014 8.2, IEC 60825-1:2014 A.3; general knowledge, unverified)"
    whose = "" if kind == "ocular" else " (skin)"
    steps = (
        f"UV exposures{whose} within 24 h per {STANDARDS[std]} at {wl:g} nm: {len(durs)} exposure(s), total {total:.6g} s {label}",
        "  limit on the summed dose = the MPE for one exposure of the total duration"
        + (f" (tables end at 3e4 s: evaluated at {t_eval:g} s, not extrapolated)" if t_eval < total else ""),
        f"  {res.governing_limit}: {res.table_row}: {res.formula} -> H = {h:.6g} J/m^2",
        f"  summed dose <= {h:.6g} J/m^2, i.e. average irradiance while exposed <= {h / total:.6g} W/m^2",
    )
    return UV24hResult(wl, std, total, h, h / total, res, label, steps, kind)


def on_time_in_24h_s(intervals_s) -> float:
    """Largest time [s] the laser is on within any 24 h, for merged firing windows.

    Parameters
    ----------
    intervals_s : array_like, shape (n, 2)
        The closed lasing intervals ``[[t0_s, t1_s], ...]`` [s], sorted and merged (each
        starts after the previous one ends): :attr:`scenes.motion.Windows.intervals` of
        ``scenes.motion.Windows.of(windows)``, the one merge of the firing windows.

    Returns
    -------
    float
        The lased time [s] of the 24 h holding the most (a sliding 24 h window holds the
        most when it starts at a window's start, so those starts are the only ones tried).

    Raises
    ------
    ValueError
        Intervals not of shape (n, 2), an interval ending before it starts, or intervals
        unsorted or overlapping (not merged).
    """
    m = np.asarray(intervals_s, float)
    if m.size == 0:
        return 0.0
    if m.ndim != 2 or m.shape[1] != 2:
        raise ValueError(f"intervals_s: shape {m.shape}: expected (n, 2) [[t0_s, t1_s], ...]")
    bad = np.flatnonzero(~(m[:, 1] >= m[:, 0]))
    if len(bad):
        raise ValueError(f"intervals_s[{bad[0]}] = {m[bad[0]].tolist()}: expected t1_s >= t0_s")
    bad = np.flatnonzero(~(m[1:, 0] > m[:-1, 1]))
    if len(bad):
        raise ValueError(f"intervals_s[{bad[0] + 1}] = {m[bad[0] + 1].tolist()} starts at or before intervals_s[{bad[0]}] = "
                         f"{m[bad[0]].tolist()} ends: expected sorted, merged intervals (scenes.motion.Windows.of(windows).intervals)")
    cum = np.concatenate([[0.0], np.cumsum(m[:, 1] - m[:, 0])])

    def on_before(t):  # lased time in (-inf, t]
        k = np.searchsorted(m[:, 0], t, side="right")  # windows starting at or before t
        part = np.clip(t - m[np.maximum(k - 1, 0), 0], 0.0, m[np.maximum(k - 1, 0), 1] - m[np.maximum(k - 1, 0), 0])
        return cum[np.maximum(k - 1, 0)] + np.where(k > 0, part, 0.0)

    starts = m[:, 0]
    return float(np.max(on_before(starts + UV_ACCUMULATION_S) - on_before(starts)))


# ----------------------------------------------------------------------------------------
PULSE_SUMMING_TIME_S = (  # T_i (IEC 2014 Table 2; ANSI Z136.1-2014 t_min), spec section 2.4 [C]
    (400.0, 1050.0, 5e-6),
    (1050.0, 1400.0, 13e-6),
    (1400.0, 1500.0, 1e-3),
    (1500.0, 1800.0, 10.0),
    (1800.0, 2600.0, 1e-3),
    (2600.0, 1e6 + 1, 1e-7),
)
# the 2007 editions: 18 us (400-1050 nm) and 50 us (1050-1400 nm), the ends of their ns rows
# (spec 2.2 [C]); the infrared values unchanged
PULSE_SUMMING_TIME_2007_S = ((400.0, 1050.0, 18e-6), (1050.0, 1400.0, 50e-6)) + PULSE_SUMMING_TIME_S[2:]


def _pulse_summing_time(wl, standard=DEFAULT_STANDARD):
    """T_i [s] for the edition, or None in the UV (no T_i is tabulated below 400 nm: every
    pulse is counted, the protective reading)."""
    if wl < 400.0:
        return None
    table = PULSE_SUMMING_TIME_S if _edition(standard) >= 2014 else PULSE_SUMMING_TIME_2007_S
    for lo, hi, ti in table:
        if lo <= wl < hi:
            return ti
    return table[-1][2]


@dataclass(frozen=True)
class RepetitivePulseResult:
    """Per-pulse MPE of a pulse train, with the three rules and the governing one.

    ``c_p`` is the thermal rule's factor (ANSI C_P or IEC C5), ``c_p_rule`` the branch of
    the standard that set it, ``pulse_groups`` the number of (effective) pulses counted for
    it, ``counting_time_s`` the time they were counted over and ``pulse_summing_time_s`` T_i.
    """

    per_pulse_radiant_exposure_j_m2: float
    governing_rule: str
    rules: tuple
    pulses: float
    pulse_groups: float
    c_p: float
    steps: tuple
    c_p_rule: str = ""
    counting_time_s: float = 0.0
    pulse_summing_time_s: float | None = None
    unverified: bool = False

    def to_dict(self):
        return {
            "per_pulse_radiant_exposure_j_m2": self.per_pulse_radiant_exposure_j_m2,
            "governing_rule": self.governing_rule,
            "rules": [{"rule": r, "per_pulse_radiant_exposure_j_m2": v} for r, v in self.rules],
            "pulses": self.pulses,
            "pulse_groups": self.pulse_groups,
            "c_p": self.c_p,
            "c_p_rule": self.c_p_rule,
            "counting_time_s": self.counting_time_s,
            "pulse_summing_time_s": self.pulse_summing_time_s,
            "unverified": self.unverified,
            "steps": list(self.steps),
        }

    def explain(self) -> str:
        """Which rule governed and why: every rule's per-pulse value, lowest first."""
        order = sorted(self.rules, key=lambda r: r[1])
        lines = [f"Why: the per-pulse MPE is the lowest of the {len(order)} rules the standard applies to a pulse train:"]
        for name, v in order:
            ratio = f" ({v / order[0][1]:.4g}x the governing value)" if order[0][1] > 0 else ""
            lines.append(f"  {name}: {v:.6g} J/m^2{'  <- governs' if name == self.governing_rule else ratio}")
        lines.append(f"  thermal factor: {self.c_p_rule}")
        return "\n".join(lines)

    def __str__(self):
        return "\n".join(self.steps)


def _c5_iec_2014(tau, n, window_s, alpha, f: CorrectionFactors, ti):
    """C5 of IEC 60825-1:2014 clause 4.3 f) 3) (retinal thermal, 400-1400 nm), as transcribed
    in akufcsak/laser_safety ``get_c5`` [C]; ``n`` counts the (effective) pulses within
    ``window_s`` = min(T2, T). Returns (C5, the branch in words)."""
    if tau > 0.25:
        return 1.0, "C5 = 1: not applicable to pulses longer than 0.25 s (IEC 2014 4.3 f) 3))"
    if tau <= ti:
        if window_s <= 0.25:
            return 1.0, f"C5 = 1: pulses <= T_i and counting time min(T2, T) = {window_s:g} s <= 0.25 s (IEC 2014 4.3 f) 3))"
        if n <= 600:
            return 1.0, f"C5 = 1: pulses <= T_i, N = {n:g} <= 600 (IEC 2014 4.3 f) 3))"
        c5 = max(0.4, 5.0 * n**-0.25)
        return c5, f"C5 = max(0.4, 5 N^-0.25) = max(0.4, 5 * {n:g}^-0.25) = {c5:.6g}: pulses <= T_i, N > 600 (IEC 2014 4.3 f) 3))"
    a_max = f.alpha_max_rad
    if alpha <= 5e-3:
        return 1.0, f"C5 = 1: pulses > T_i, alpha = {1e3 * alpha:g} mrad <= 5 mrad (IEC 2014 4.3 f) 3))"
    if alpha <= a_max:
        c5 = n**-0.25 if n <= 40 else 0.4
        return c5, f"C5 = {'N^-0.25' if n <= 40 else '0.4 (N > 40)'} = {c5:.6g}: pulses > T_i, 5 mrad < alpha <= alpha_max (IEC 2014 4.3 f) 3))"
    c5 = n**-0.25 if n <= 625 else 0.2
    return c5, (f"C5 = {'N^-0.25' if n <= 625 else '0.2 (N > 625)'} = {c5:.6g}: pulses > T_i, alpha > alpha_max = {1e3 * a_max:g} mrad "
                "(IEC 2014 4.3 f) 3); the transcription's C5 = 1 above 100 mrad is not applied: unverified, 0.2 floor kept, protective)")


def _thermal_rule(std, wl, tau, prf, big_t, alpha, rule1):
    """Rule 3 (ANSI C_P) / requirement 3 (IEC C5): per-pulse value, factor, count, steps.

    Pulses closer than T_i are grouped: a group is one pulse of duration T_i carrying all
    its pulses' energy, its MPE H(T_i) shared among them. Counting: the whole train (ANSI
    both editions, IEC 2007: C_P = C5 = N^-0.25 [M]), or min(T2, T) for IEC 2014 in 400-1400
    nm (4.3 f) 3)). Outside 400-1400 nm the N^-0.25 reduction is applied to every standard as
    a protective assumption [M] (the photochemical limits are covered by rule 2 anyway).
    """
    ti = _pulse_summing_time(wl, std)
    grouped = ti is not None and 1.0 / prf < ti
    per_group = max(prf * ti, 1.0) if grouped else 1.0
    h_eff = ocular_mpe(wl, ti, standard=std, angular_subtense_rad=alpha).radiant_exposure_j_m2 if grouped else rule1
    iec14 = std == "iec-60825-1-2014" and 400 <= wl < 1400
    f = correction_factors(wl, tau, alpha, std)
    window = min(f.T2_s, big_t) if iec14 else big_t
    rate = min(prf, 1.0 / ti) if grouped else prf
    n = max(window * rate, 1.0)
    lines = []
    if grouped:
        lines.append(f"  pulses closer than T_i = {ti:g} s are grouped: {per_group:g} pulses per group of duration T_i, "
                     f"H(T_i) = {h_eff:.6g} J/m^2 per group")
    if iec14:
        c_p, why = _c5_iec_2014(ti if grouped else tau, n, window, alpha, f, ti)
        name, label = "rule 3: thermal (C5)", "[C] akufcsak get_c5"
        lines.append(f"  N = {n:g} (effective) pulses within min(T2, T) = min({f.T2_s:g}, {big_t:g}) s")
    else:
        c_p = n**-0.25
        where = "" if 400 <= wl < 1400 else "; outside 400-1400 nm applied as a protective assumption"
        why = f"C_P = N^-0.25 = {n:g}^-0.25 = {c_p:.6g} (N over the whole train{where})"
        name, label = "rule 3: thermal (C_P)", "[M]"
        lines.append(f"  N = {n:g} (effective) pulses in T = {big_t:g} s")
    value = h_eff * c_p / per_group
    src = "H(T_i)" if grouped else "H_1"
    factor = "C5" if iec14 else "C_P"
    lines.append(f"  rule 3 (thermal): {src} {factor} / n_group = {h_eff:.6g} * {c_p:.6g} / {per_group:g} = {value:.6g} J/m^2 {label}")
    lines.append(f"    because {why}")
    return name, value, c_p, why, n, window, ti, lines


def repetitive_pulse_mpe(
    wavelength_nm, pulse_duration_s, prf_hz, exposure_duration_s, *, standard=DEFAULT_STANDARD, angular_subtense_rad=0.0
) -> RepetitivePulseResult:
    """Per-pulse ocular MPE of a repetitively pulsed laser (ANSI rules 1-3 / IEC C5).

    Rule 1: no pulse exceeds the single-pulse MPE. Rule 2: the train's average does not
    exceed the MPE for its duration (per pulse: H(T) / N). Rule 3 (thermal): the single-pulse
    MPE times the standard's factor: ANSI Z136.1 (both editions) C_P = N^-0.25 over the
    train [M]; IEC 60825-1:2007 C5 = N^-0.25; IEC 60825-1:2014 C5 by clause 4.3 f) 3)
    (1 for pulses <= T_i up to N = 600, then 5 N^-0.25 down to 0.4; for longer pulses 1 for
    alpha <= 5 mrad, N^-0.25 down to 0.4 up to alpha_max, down to 0.2 beyond), N counted
    within min(T2, T). Pulses closer than T_i (spec 2.4; 2007: 18 / 50 us) are grouped.

    Parameters
    ----------
    wavelength_nm : float
        180 nm to 1 mm.
    pulse_duration_s, prf_hz, exposure_duration_s : float
        Pulse duration [s], repetition frequency [Hz] and train duration T [s].
    standard : str
        One of :data:`STANDARDS`.
    angular_subtense_rad : float
        Apparent source size alpha [rad] (C_E, T2, and IEC 2014's C5 branch).
    """
    std = check_standard(standard)
    wl, tau, alpha = _check_inputs(wavelength_nm, pulse_duration_s, angular_subtense_rad)
    for name, v in (("prf_hz", prf_hz), ("exposure_duration_s", exposure_duration_s)):
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or v <= 0:
            raise ValueError(f"{name}={v!r}: expected a finite number > 0")
    prf, big_t = float(prf_hz), float(exposure_duration_s)
    if tau * prf >= 1.0:
        raise ValueError(f"pulse_duration_s * prf_hz = {tau * prf:g}: expected < 1 (pulses must not overlap); treat it as CW")
    _check_inputs(wl, big_t, alpha)
    n = max(prf * big_t, 1.0)
    single = ocular_mpe(wl, tau, standard=std, angular_subtense_rad=alpha)
    train = ocular_mpe(wl, big_t, standard=std, angular_subtense_rad=alpha)
    rule1 = single.radiant_exposure_j_m2
    rule2 = train.radiant_exposure_j_m2 / n
    steps = [
        f"Repetitive-pulse MPE per {STANDARDS[std]}: {wl:g} nm, pulse {tau:g} s at {prf:g} Hz for {big_t:g} s (N = {n:g})",
        f"  rule 1 (single pulse): H_1 = {rule1:.6g} J/m^2  [{single.table_row}: {single.formula}]",
        f"  rule 2 (average): H(T) / N = {train.radiant_exposure_j_m2:.6g} / {n:g} = {rule2:.6g} J/m^2  [{train.table_row}: {train.formula}]",
    ]
    name3, rule3, c_p, why, groups, window, ti, lines = _thermal_rule(std, wl, tau, prf, big_t, alpha, rule1)
    steps += lines
    rules = (("rule 1: single pulse", rule1), ("rule 2: average power", rule2), (name3, rule3))
    gov = min(rules, key=lambda r: r[1])
    steps.append(f"  per-pulse MPE = {gov[1]:.6g} J/m^2 ({gov[0]} governs)")
    unverified = single.unverified or train.unverified or not std.startswith("iec-60825-1-2014") or not 400 <= wl < 1400
    if unverified:
        steps.append("  WARNING: a row or rule used here is not verified against the standard's text ([M]); check it before relying on it")
    return RepetitivePulseResult(gov[1], gov[0], rules, n, groups, c_p, tuple(steps), why, window, ti, unverified)
