"""Plausibility warnings of an analysis: the scene's (unit slips, :mod:`scenes.scene`)
and those only the results show. Each can change a verdict, so the answer prints them
above it, report.json holds them under ``warnings`` and the review page shows them in its
verdict box. They are warnings, never errors: the values may be meant.

Found from the results:

- the direct beam's NOHD is under ``NOHD_TARGET_FRACTION`` of the distance from the laser
  to the nearest lit spot (or to the aim point): on a high-energy range the beam is
  hazardous where it lands, so a beam harmless 100 times closer than its target is most
  likely a unit slip (a divergence in degrees or mrad typed as rad, kW typed as W);
- a target the beam reaches (spot power > 0) that reflects nothing (its lit side or its
  material): its reflections are 0 in the answer;
- a scene whose targets the beam reaches none of (unless something moves: the static aim
  of a slewing beam may miss them, and the motion results hold the reflections).
"""

from __future__ import annotations

import numpy as np

__all__ = ["answer_warnings", "result_warnings", "NOHD_TARGET_FRACTION"]

NOHD_TARGET_FRACTION = 0.01  # direct-beam NOHD under this fraction of the distance to the target: warned (two orders of magnitude)


def _target_distance_m(result):
    """Distance [m] from the aperture to the nearest lit spot's centroid, with its target's
    name; to the aim point (name None) when no spot is lit; (None, None) without either."""
    scene = result.scene
    laser = np.asarray(scene.laser_position_m, float)
    lit = [sp for sp in result.spots if sp.total_power_w > 0]
    if lit:
        d = [float(np.linalg.norm(np.asarray(sp.centroid, float) - laser)) for sp in lit]
        k = int(np.argmin(d))
        return d[k], lit[k].target.name
    aim = scene.spec.laser.aim_m
    if aim is None:
        return None, None
    return float(np.linalg.norm(np.asarray(aim, float) - np.asarray(scene.spec.laser.position_m, float))), None


def _short_nohd(result) -> list:
    """The direct beam's NOHD under NOHD_TARGET_FRACTION of the distance to the target."""
    z = getattr(result, "sdz", None)
    nohd = None if z is None else z.nohd_m
    dist, name = _target_distance_m(result)
    if nohd is None or dist is None or not nohd < NOHD_TARGET_FRACTION * dist:
        return []
    where = f"the nearest lit spot (on {name!r})" if name else "the aim point"
    beam = ("the direct beam is below the MPE from its aperture on (NOHD 0 m)" if nohd <= 0 else
            f"the direct beam's NOHD ({nohd:.4g} m) is under 1/{1 / NOHD_TARGET_FRACTION:g} of the distance to {where}")
    la = result.scene.spec.laser
    return [f"{beam} ({dist:.6g} m away): on a high-energy laser range the beam is normally hazardous where it lands; "
            f"check the units of laser.power_w ({la.average_power_w:g} W: kW typed as W?), beam_diameter_m "
            f"({la.beam_diameter_m:g} m) and divergence_rad ({la.divergence_rad:g} rad: mrad or degrees typed as rad?)"]


REFLECTS_NOTHING = 1e-12  # a lit material's directional-hemispherical reflectance at the spot's incidence under this: nothing
_RHO_ATTR = "_lit_reflectance"  # where a spot keeps its reflectance once integrated (its material and incidence never change)


def _spot_reflectance(sp):
    """The directional-hemispherical reflectance [-] of a spot's lit material at its mean
    incidence (delta lobes included; :func:`brdfmodels.analysis.hemispherical_reflectance`
    to 1 %), None where it cannot be said (a dynamic material, grazing incidence). Kept on
    the spot once integrated (a measured table's integral is seconds, and a run's
    report.json, answer and exit code each ask for the verdict); nothing is kept beyond
    the spot's own life."""
    from brdfmodels.analysis import hemispherical_reflectance

    if _RHO_ATTR in vars(sp):
        return vars(sp)[_RHO_ATTR]
    wi = np.asarray(sp.mean_frame, float) @ -np.asarray(sp.mean_incoming, float)
    rho = None
    if not getattr(sp.material, "is_dynamic", False) and wi[2] > 1e-9:
        wi = wi / np.linalg.norm(wi)
        rho = hemispherical_reflectance(sp.material, wi, rtol=1e-2, atol=0.0, max_evaluations=200_000).value
    setattr(sp, _RHO_ATTR, rho)
    return rho


def _dark_targets(result) -> set:
    """Names of the targets whose every lit spot's material reflects nothing there."""
    dark, lit = set(), set()
    for sp in result.spots:
        if sp.total_power_w > 0:
            rho = _spot_reflectance(sp)
            (dark if rho is not None and rho < REFLECTS_NOTHING else lit).add(sp.target.name)
    return dark - lit


def _reflects_nothing(result) -> list:
    """Targets the beam reaches that reflect nothing, and a beam that reaches no target."""
    out = []
    dark = _dark_targets(result)
    for i, t in enumerate(result.targets):
        if t.spot_power_w > 0 and (t.static_lobe is None or t.name in dark):
            why = t.lit_side if t.static_lobe is None else "its material's reflectance there is 0"
            label = f"targets[{i}] ({t.name})" if i < len(result.scene.targets) else f"the {t.name}"  # the terrain: after the scene's
            out.append(f"{label}: the beam reaches it ({t.spot_power_w:.4g} W) but it reflects nothing "
                       f"({why}): its reflections are 0 in this answer; check its material (a reflectance of 0?) "
                       "and which side faces the laser")
    if result.targets and not any(t.spot_power_w > 0 for t in result.targets) and getattr(result, "motion", None) is None:
        # (with a moving beam or target the static aim may miss them: the motion results hold the reflections)
        out.append(f"the beam reaches none of the {len(result.targets)} target(s): no reflection is analysed; check "
                   "laser.aim_m or direction and the targets' positions")
    return out


def result_warnings(result) -> list:
    """The warnings only the results show (see the module notes)."""
    return _short_nohd(result) + _reflects_nothing(result)


def answer_warnings(result) -> list:
    """Every plausibility warning of an analysis: the scene's, then the results'."""
    return list(getattr(result.scene, "warnings", None) or []) + result_warnings(result)
