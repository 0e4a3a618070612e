"""Visual interference of visible lasers with aviation: the FAA flight-zone levels and
their distances for the direct beam and each reflection (report.json
``visual_interference``).

Levels (range-safety.md section 5; the US flight zones of FAA Order JO 7400.2, Part 6,
Ch. 29 and AC 70-1, as summarised there), as effective irradiance VCF x E:

========  ======================  ==========================
distance  limit                   beyond it
========  ======================  ==========================
SZED      100 uW/cm^2 = 1 W/m^2   no flash blindness
CZED      5 uW/cm^2 = 0.05 W/m^2  no glare
LFED      50 nW/cm^2 = 5e-4 W/m^2 no distraction
NOHD      the MPE, no VCF          no eye injury
========  ======================  ==========================

The visual correction factor VCF is the CIE 1924 photopic luminous efficiency V(lambda)
(1 at 555 nm; ``hazard/data/cie1924_photopic_v.csv``, 1 nm steps from CVRL, read
exactly at whole nanometres and linearly between them); ``[airspace] visual_correction =
"none"`` takes VCF = 1 (the most conservative; whether the FAA applies V(lambda) exactly
or a scotopic/mesopic variant for some zones is not confirmed in the spec). The levels
apply to visible lasers (400-700 nm); other wavelengths get ``applies = false`` and the
NOHD only. The NOHD never takes the VCF.

Distances. The direct beam: E(R) = 4 VCF P exp(-mu R) / (pi (a + R phi)^2) = E_lim, i.e.
R = (sqrt(4 P VCF / (pi E_lim)) - a) / phi without attenuation (range-safety.md section 5,
derived from section 1), :func:`hazard.physics.nohd.nohd_direct` with P VCF and E_lim. A
reflection: the largest range of the target's hazard lobe (diffuse and glossy part,
:func:`hazard.physics.keepout.hazard_lobe`, over the target's whole state history) and of its
mirror beam (:func:`hazard.physics.specular.specular_nohd`) at E_lim / VCF; for a moving beam or
target, the largest over the static spot and the ``SPOTS_PER_TARGET`` most powerful
spots of its beam states (``beam_states`` counts them). Attenuation is not
credited unless ``[airspace] credit_attenuation = true`` (FAA practice per the spec,
not confirmed: an explicit flag).
"""

from __future__ import annotations

import functools
from collections.abc import Mapping
from dataclasses import dataclass
from importlib import resources
from typing import ClassVar

import numpy as np

__all__ = ["LEVELS_W_M2", "VISIBLE_NM", "photopic_v", "visual_correction_factor", "level_limit_w_m2",
           "visual_interference", "zone_distances_m", "LevelDistances", "TargetLevelDistances", "VisualInterference"]

LEVELS_W_M2 = {"szed": 1.0, "czed": 5e-2, "lfed": 5e-4}  # range-safety.md section 5 (FAA flight-zone levels, CW)
VISIBLE_NM = (400.0, 700.0)
LEVEL_TEXT = {"szed": "sensitive-zone exposure distance (100 uW/cm^2: no flash blindness beyond)",
              "czed": "critical-zone exposure distance (5 uW/cm^2: no glare beyond)",
              "lfed": "laser-free-zone exposure distance (50 nW/cm^2: no distraction beyond)",
              "nohd": "nominal ocular hazard distance (the MPE, no visual correction)"}


@dataclass(frozen=True)
class LevelDistances:
    """The direct beam's distances to the FAA levels and to the MPE
    (:func:`zone_distances_m`; report.json ``visual_interference.direct``).

    Attributes
    ----------
    lfed_m, czed_m, szed_m : float or None
        Along the beam from the laser to where the effective irradiance VCF x E falls to
        the laser-free, critical and sensitive zone level [m] (0: the level is not
        reached); None: not a visible laser, the levels do not apply.
    nohd_m : float
        To where the irradiance falls to the MPE, without the VCF [m].
    """

    lfed_m: float | None
    czed_m: float | None
    szed_m: float | None
    nohd_m: float

    def distance_m(self, level: str) -> float | None:
        """The distance [m] of ``level`` (``"lfed"``, ``"czed"``, ``"szed"`` or ``"nohd"``)."""
        if level not in ("lfed", "czed", "szed", "nohd"):
            raise ValueError(f"level={level!r}: expected 'lfed', 'czed', 'szed' or 'nohd'")
        return getattr(self, f"{level}_m")

    def to_dict(self) -> dict:
        return {"lfed_m": self.lfed_m, "czed_m": self.czed_m, "szed_m": self.szed_m, "nohd_m": self.nohd_m}


@dataclass(frozen=True)
class TargetLevelDistances(LevelDistances):
    """A lit target's distances (report.json ``visual_interference.targets.<name>``), from
    the target: its lobe's and mirror beam's largest reach over the spots computed.

    Attributes
    ----------
    lfed_m, czed_m, szed_m : float or None
        Reach at each FAA level, the effective irradiance VCF x E [m]; None: not a visible laser.
    nohd_m : float
        Reach at the MPE [m]: the keepout stage's NOHD (the scene's attenuation), and a
        moving beam's spots' at the MPE.
    beam_states : int
        The spots whose distances were computed (the static one and, for a moving beam,
        up to ``SPOTS_PER_TARGET`` of its states).
    """

    beam_states: int

    def to_dict(self) -> dict:
        return {**super().to_dict(), "beam_states": self.beam_states}


@dataclass(frozen=True)
class VisualInterference:
    """The FAA visual-interference levels and their distances (:func:`visual_interference`;
    report.json ``visual_interference``, written by :meth:`to_dict` in this field order).

    Attributes
    ----------
    applies : bool
        A visible laser (400-700 nm): the visual levels apply.
    wavelength_nm : float
        The laser's wavelength [nm].
    vcf : float
        The visual correction factor (unitless; 0 when the levels do not apply).
    weighting : str
        How the VCF is weighted, in words.
    attenuation_credited : bool
        Atmospheric attenuation is credited for the levels (``[airspace] credit_attenuation``).
    attenuation_per_m : float
        The attenuation coefficient the levels use [1/m] (0 when not credited).
    levels_w_m2 : Mapping of str to float
        Each level's effective irradiance [W/m^2] (``"szed"``, ``"czed"``, ``"lfed"``; read only).
    levels : Mapping of str to str
        Each distance's meaning, in words (the levels and ``"nohd"``; read only).
    mpe_w_m2 : float
        The MPE the NOHD is taken at [W/m^2].
    source : str
        Where the levels and the formula come from.
    reason : str or None
        Why the levels do not apply (not a visible laser); None: the key is absent.
    direct : LevelDistances
        The direct beam's distances, from the laser.
    targets : Mapping of str to TargetLevelDistances
        Per lit target (by name, read only), its distances from the target.
    nohd_attenuation : str
        Which attenuation the NOHD values use, in words.
    """

    applies: bool
    wavelength_nm: float
    vcf: float
    weighting: str
    attenuation_credited: bool
    attenuation_per_m: float
    levels_w_m2: Mapping[str, float]
    levels: Mapping[str, str]
    mpe_w_m2: float
    source: str
    reason: str | None
    direct: LevelDistances
    targets: Mapping[str, TargetLevelDistances]
    nohd_attenuation: str

    ABSENT_WHEN_NONE: ClassVar[tuple[str, ...]] = ("reason",)

    def to_dict(self) -> dict:
        out = {"applies": self.applies, "wavelength_nm": self.wavelength_nm, "vcf": self.vcf, "weighting": self.weighting,
               "attenuation_credited": self.attenuation_credited, "attenuation_per_m": self.attenuation_per_m,
               "levels_w_m2": dict(self.levels_w_m2), "levels": dict(self.levels), "mpe_w_m2": self.mpe_w_m2, "source": self.source}
        if self.reason is not None:
            out["reason"] = self.reason
        out.update(direct=self.direct.to_dict(), targets={name: t.to_dict() for name, t in self.targets.items()},
                   nohd_attenuation=self.nohd_attenuation)
        return out


@functools.cache
def _v_table() -> tuple[np.ndarray, np.ndarray]:
    text = resources.files("hazard").joinpath("data/cie1924_photopic_v.csv").read_text()
    rows = [ln.split(",") for ln in text.splitlines() if ln and not ln.startswith("#") and not ln.startswith("wavelength")]
    a = np.asarray(rows, float)
    return a[:, 0], a[:, 1]


def photopic_v(wavelength_nm: float) -> float:
    """CIE 1924 photopic V(lambda) at ``wavelength_nm`` (0 outside 380-780 nm)."""
    wl, v = _v_table()
    x = float(wavelength_nm)
    if x < wl[0] or x > wl[-1]:
        return 0.0
    return float(np.interp(x, wl, v))


def visual_correction_factor(wavelength_nm: float, weighting: str = "photopic") -> float:
    """The VCF: V(lambda) (``"photopic"``) or 1 (``"none"``)."""
    if weighting == "none":
        return 1.0
    if weighting != "photopic":
        raise ValueError(f"visual_correction={weighting!r}: expected 'photopic' or 'none'")
    return photopic_v(wavelength_nm)


def applies(wavelength_nm: float) -> bool:
    return VISIBLE_NM[0] <= float(wavelength_nm) <= VISIBLE_NM[1]


def level_limit_w_m2(limit: str, mpe_w_m2: float, vcf: float) -> float:
    """The irradiance E [W/m^2] (before the VCF) at which a level is reached: E_lim / VCF,
    or the MPE for ``"nohd"`` (inf when the VCF is 0: the level cannot be reached)."""
    if limit == "nohd":
        return float(mpe_w_m2)
    return float(LEVELS_W_M2[limit] / vcf) if vcf > 0 else float("inf")


def zone_distances_m(power_w, beam_diameter_m, divergence_rad, mpe_w_m2, vcf, attenuation_per_m=0.0) -> dict:
    """The direct beam's ``lfed_m``, ``czed_m``, ``szed_m`` and ``nohd_m`` (see the module notes)."""
    from hazard.physics.nohd import nohd_direct

    out = {}
    for key in ("lfed", "czed", "szed", "nohd"):
        e = level_limit_w_m2(key, mpe_w_m2, vcf)
        out[f"{key}_m"] = 0.0 if not np.isfinite(e) else nohd_direct(
            power_w, e, beam_diameter_m, divergence_rad, attenuation_per_m=attenuation_per_m).nohd_m
    return out


def _row_nohd_m(row) -> float:
    """A target row's NOHD [m]: the longest of its lobes and mirror beams (the keepout stage's)."""
    vals = [0.0] + [x for x in (row.specular_nohd_static_m, row.specular_nohd_dynamic_m) if x is not None]
    vals += [lobe.max_range_m for lobe in (row.static_lobe, row.dynamic_lobe) if lobe is not None]
    return float(max(vals))


def _spot_reach_m(sp, e_w_m2, mu, states, analysis) -> float:
    """How far [m] a spot's reflection stays at or above ``e_w_m2``: its lobe (over the
    history's states) and its mirror beam. The lobe's point form first: where its largest
    range reaches :func:`hazard.physics.near_field_lobe.near_field_reach_m`, that is the lobe's
    (the near-field envelope stays within it); else the lobe with the near field."""
    from hazard.physics.keepout import hazard_lobe
    from hazard.physics.near_field_lobe import near_field_reach_m
    from hazard.physics.specular import specular_nohd

    if not np.isfinite(e_w_m2):
        return 0.0
    st = states.get(sp.target.index)
    kw = dict(states=st, grid_deg=analysis.direction_grid_deg, refine_levels=analysis.refine_levels)
    r = float(hazard_lobe(sp, e_w_m2, mu, near_field=False, **kw).max_range_m)
    if r < near_field_reach_m(sp):
        r = float(hazard_lobe(sp, e_w_m2, mu, **kw).max_range_m)
    if sp.material.has_specular:
        r = max(r, float(specular_nohd(sp, e_w_m2, mu, st).nohd_m))
    return r


def _target_distances(sp, states, mpe_w_m2, vcf, mu, analysis) -> dict:
    """A lit target's visual distances: its lobe and mirror beam at each level."""
    return {f"{key}_m": _spot_reach_m(sp, level_limit_w_m2(key, mpe_w_m2, vcf), mu, states, analysis)
            for key in ("lfed", "czed", "szed")}


SPOTS_PER_TARGET = 3  # a moving beam's spots per target whose distances are computed (the most powerful ones)


def _lit_spots(result) -> dict:
    """Target name -> the spots whose distances are computed: the static analysis's, and
    for a moving beam or target the ``SPOTS_PER_TARGET`` most powerful of its beam states
    (a target the sweep lights but the nominal aim misses is not left out)."""
    out: dict[str, list] = {}
    for sp in result.spots:
        out.setdefault(sp.target.name, []).append(sp)
    run = None if result.motion is None else result.motion.run
    if run is not None and run.motion.beam_moves:
        moving: dict[str, list] = {}
        for bs in run.states_list:
            for sp in bs.spots:
                moving.setdefault(sp.target.name, []).append(sp)
        for name, sps in moving.items():
            out.setdefault(name, []).extend(sorted(sps, key=lambda x: -x.total_power_w)[:SPOTS_PER_TARGET])
    return out


def visual_interference(result) -> VisualInterference:
    """report.json ``visual_interference``: the levels, the VCF and the distances per path
    (``direct``, and per lit target)."""
    spec = result.scene.spec
    la = spec.laser
    air = spec.airspace
    weighting = "photopic" if air is None else air.visual_correction
    credit = bool(air is not None and air.credit_attenuation)
    mu = float(result.attenuation_per_m) if credit else 0.0
    vis = applies(la.wavelength_nm)
    vcf = visual_correction_factor(la.wavelength_nm, weighting) if vis else 0.0
    direct = zone_distances_m(la.average_power_w, la.beam_diameter_m, la.divergence_rad, result.mpe_w_m2, vcf, mu)
    if not vis:
        direct.update(lfed_m=None, czed_m=None, szed_m=None)
    rows = {t.name: t for t in result.targets}
    static_ids = {id(x) for x in result.spots}
    targets: dict[str, TargetLevelDistances] = {}
    for name, spots in _lit_spots(result).items():  # the NOHD is the keepout stage's (the scene's attenuation); levels: visible only
        levels: dict[str, float | None] = {"lfed_m": None, "czed_m": None, "szed_m": None}
        if vis:
            each = [_target_distances(sp, result.states, result.mpe_w_m2, vcf, mu, spec.analysis) for sp in spots]
            levels = {k: max(d[k] for d in each) for k in levels}
        row = rows.get(name)
        static = [_row_nohd_m(row)] if row is not None and row.spot_power_w else []
        moving = [_spot_reach_m(sp, result.mpe_w_m2, result.attenuation_per_m, result.states, spec.analysis)
                  for sp in spots if id(sp) not in static_ids]
        targets[name] = TargetLevelDistances(**levels, nohd_m=max(static + moving), beam_states=len(spots))
    return VisualInterference(
        applies=vis, wavelength_nm=la.wavelength_nm, vcf=vcf,
        weighting="CIE 1924 photopic V(lambda)" if weighting == "photopic" else "none (VCF = 1)",
        attenuation_credited=credit, attenuation_per_m=mu, levels_w_m2=dict(LEVELS_W_M2), levels=dict(LEVEL_TEXT),
        mpe_w_m2=float(result.mpe_w_m2),
        source="range-safety.md section 5 (FAA Order JO 7400.2 Part 6 Ch. 29 / AC 70-1 levels); D = (sqrt(4 P VCF / "
               "(pi E_lim)) - a) / phi for the direct beam",
        reason=None if vis else f"{la.wavelength_nm:g} nm is outside the visible band 400-700 nm: the FAA visual levels do not apply",
        direct=LevelDistances(**direct), targets=targets,
        nohd_attenuation="targets: the scene's attenuation (the keepout stage's NOHD); direct: as the levels")
