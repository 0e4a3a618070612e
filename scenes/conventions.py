"""Beam conventions: the laser's diameter and divergence as a datasheet states them,
converted once at load to the standards' form (1/e-irradiance diameter, full angle).

ANSI Z136.1 and IEC 60825-1 give beam diameters and divergences at the 1/e points of the
irradiance, divergence as a full angle; datasheets often give 1/e^2 (13.5 %), D86 or FWHM,
and half angles. ``[laser] diameter_definition`` (``"1/e"``, ``"1/e2"``, ``"d86"``,
``"fwhm"``) and ``divergence_definition`` (``"<angle>_<level>"``: angle ``full`` or
``half``, level one of the four, e.g. ``"half_1/e2"``) say which; for a Gaussian beam
(I = I0 exp(-2 r^2 / w^2), w the 1/e^2 radius)::

    d_1/e = d_1/e2 / sqrt(2)        (I falls to 1/e at r = w / sqrt(2))
    d_1/e = d86 / sqrt(2)           (86.5 % of the power lies within r = w: d86 = d_1/e2)
    d_1/e = d_fwhm / sqrt(ln 2)     (I falls to 1/2 at r = w sqrt(ln 2 / 2))
    full angle = 2 x half angle

A beam that is not Gaussian has no exact conversion; these are the Gaussian-equivalent
values (said in the note). The defaults are the standards' form; a scene that leaves
them out gets a one-line note naming it (:func:`beam_notes`).

:func:`convert_beam` rewrites the raw ``[laser]`` table before validation (after
:func:`scenes.quantities.convert_units`), so every reader of ``beam_diameter_m`` and
``divergence_rad`` gets the 1/e full-angle value, and the definitions become the
standards' (converting again changes nothing).
"""

from __future__ import annotations

import math

__all__ = ["DIAMETER_DEFINITIONS", "DIVERGENCE_DEFINITIONS", "TO_ONE_OVER_E", "ConventionError", "convert_beam", "beam_notes",
           "conversion_lines"]

# level -> factor from a diameter (or full angle) at that level to the 1/e one (Gaussian)
TO_ONE_OVER_E = {"1/e": 1.0, "1/e2": 1.0 / math.sqrt(2.0), "d86": 1.0 / math.sqrt(2.0), "fwhm": 1.0 / math.sqrt(math.log(2.0))}
_FORMULA = {"1/e": "d_1/e", "1/e2": "d_1/e2 / sqrt(2)", "d86": "d86 / sqrt(2)", "fwhm": "d_fwhm / sqrt(ln 2)"}
DIAMETER_DEFINITIONS = tuple(TO_ONE_OVER_E)
DIVERGENCE_DEFINITIONS = tuple(f"{a}_{lv}" for a in ("full", "half") for lv in TO_ONE_OVER_E)
STANDARD = ("1/e", "full_1/e")


class ConventionError(ValueError):
    """An unknown beam definition; the message names the key."""


def _number(v) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)


def _check(laser: dict, key: str, choices) -> str | None:
    v = laser.get(key)
    if v is not None and v not in choices:
        raise ConventionError(f"laser.{key} = {v!r}: expected one of {', '.join(repr(c) for c in choices)}")
    return v


def convert_beam(data: dict) -> tuple[dict, dict | None]:
    """The raw scene mapping with ``[laser]`` diameter and divergence converted to 1/e
    full angle (a copy when changed), and the record of the conversion (None without a
    ``[laser]`` table): ``{"diameter_definition", "divergence_definition" (as given, None
    when left out), "beam_diameter_as_given_m", "beam_diameter_m" (1/e), "divergence_as_given_rad",
    "divergence_rad" (1/e full angle), "diameter_factor", "divergence_factor",
    "steps" (the formulas with numbers)}``.

    Raises
    ------
    ConventionError
        A definition that is not one of :data:`DIAMETER_DEFINITIONS` /
        :data:`DIVERGENCE_DEFINITIONS`.
    """
    laser = data.get("laser") if isinstance(data, dict) else None
    if not isinstance(laser, dict):
        return data, None
    dd = _check(laser, "diameter_definition", DIAMETER_DEFINITIONS)
    vd = _check(laser, "divergence_definition", DIVERGENCE_DEFINITIONS)
    angle, level = (vd or STANDARD[1]).split("_", 1)
    f_d = TO_ONE_OVER_E[dd or STANDARD[0]]
    f_v = TO_ONE_OVER_E[level] * (2.0 if angle == "half" else 1.0)
    d, v = laser.get("beam_diameter_m"), laser.get("divergence_rad")
    rec = {"diameter_definition": dd, "divergence_definition": vd, "beam_diameter_as_given_m": d, "divergence_as_given_rad": v,
           "diameter_factor": f_d, "divergence_factor": f_v, "beam_diameter_m": d, "divergence_rad": v, "steps": []}
    if dd is None and vd is None:
        return data, rec
    laser = dict(laser)
    if _number(d):
        rec["beam_diameter_m"] = laser["beam_diameter_m"] = d * f_d
    if _number(v):
        rec["divergence_rad"] = laser["divergence_rad"] = v * f_v
    laser.update({"diameter_definition": STANDARD[0], "divergence_definition": STANDARD[1]})
    rec["steps"] = conversion_lines(rec)
    return {**data, "laser": laser}, rec


def conversion_lines(rec: dict) -> list:
    """The conversions as steps with their formulas and numbers (none for the standards' form)."""
    out = []
    dd, vd = rec["diameter_definition"], rec["divergence_definition"]
    if dd not in (None, "1/e") and _number(rec["beam_diameter_as_given_m"]):
        out.append(f"beam diameter: {dd} {1e3 * rec['beam_diameter_as_given_m']:.6g} mm -> d_1/e = {_FORMULA[dd]} = "
                   f"{1e3 * rec['beam_diameter_m']:.6g} mm (Gaussian beam)")
    if vd not in (None, "full_1/e") and _number(rec["divergence_as_given_rad"]):
        angle, level = vd.split("_", 1)
        form = _FORMULA[level].replace("d_", "theta_").replace("d86", "theta86")
        if angle == "half":
            form = f"2 x {form}"
        out.append(f"divergence: {angle} angle at {level} {1e3 * rec['divergence_as_given_rad']:.6g} mrad -> full angle at 1/e "
                   f"= {form} = {1e3 * rec['divergence_rad']:.6g} mrad (Gaussian beam)")
    if "fwhm" in (dd, vd):
        out.append(FWHM_CAVEAT)
    return out


# a top hat of diameter D has FWHM = D = its 1/e diameter, so the Gaussian conversion makes it 1/sqrt(ln 2) = 1.20 D
FWHM_CAVEAT = ("FWHM read for a Gaussian beam: for a flatter beam (top hat, multimode) the 1/e diameter and angle are "
               "smaller, down to the FWHM itself (a top hat): the irradiance may then be up to 1/ln 2 = 1.44 x the one used "
               "and a NOHD up to 1.20 x longer; give the 1/e2 or d86 values of such a beam (conservative for it)")


def beam_headline(rec: dict | None) -> str:
    """One line for the top of every answer: the beam convention the NOHDs were computed in,
    and whether the scene gave it or the default was taken."""
    if rec is None:
        return ""
    given = [k for k in ("diameter_definition", "divergence_definition") if rec.get(k) is not None]
    how = ("both definitions given in the scene" if len(given) == 2 else
           "default, not given in the scene" if not given else f"{given[0]} given, the other the default")
    conv = "" if not rec.get("steps") else "; the scene's values converted to it: see the notes"
    return f"beam: 1/e-irradiance diameter and 1/e full-angle divergence, the standards' form ({how}{conv})"


def beam_notes(rec: dict | None) -> list:
    """The notes an answer carries about the beam's convention: the conversions made, or
    (neither definition given) one line naming the convention the values were read in."""
    if rec is None:
        return []
    if rec["diameter_definition"] is None and rec["divergence_definition"] is None:
        return ["beam convention: laser.beam_diameter_m and laser.divergence_rad read as the 1/e-irradiance diameter and "
                "full angle (the ANSI Z136.1 / IEC 60825-1 form); for datasheet 1/e^2 values set laser.diameter_definition = "
                "\"1/e2\" and laser.divergence_definition = \"full_1/e2\""]
    out = [f"beam convention: {s}" for s in rec["steps"]]
    if rec["diameter_definition"] is None:
        out.append("beam convention: laser.beam_diameter_m read as the 1/e-irradiance diameter (the default: "
                   "diameter_definition not given)")
    if rec["divergence_definition"] is None:
        out.append("beam convention: laser.divergence_rad read as the 1/e full angle (the default: divergence_definition "
                   "not given)")
    return out or [f"beam convention: diameter at {rec['diameter_definition']}, divergence {rec['divergence_definition']} "
                   f"(the standards' form, nothing converted)"]
