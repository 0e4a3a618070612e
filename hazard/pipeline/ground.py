"""Stage ``footprint``: the hazardous ground at eye height over a terrain."""

from __future__ import annotations

from dataclasses import dataclass

from ..keepout import Footprint, ground_footprint

__all__ = ["Footprints", "footprints"]


@dataclass
class Footprints:
    """Hazardous ground with the initial states held (static) and over the history."""

    static: Footprint
    dynamic: Footprint
    detail: str


def footprints(spots, beam, terrain, ray_scene, mpe_w_m2, mu, eye_height_m, states, target_rows) -> Footprints:
    """Ground cells at ``eye_height_m`` where the irradiance summed over every spot
    reaches the MPE, out to the longest NOHD of any target (diffuse or specular)."""
    lit = [tr for tr in target_rows if tr.dynamic_lobe is not None]  # unlit targets' rows carry no lobe
    rmax = max([tr.dynamic_lobe.max_range_m for tr in lit] + [tr.specular_nohd_dynamic_m or 0.0 for tr in lit] + [0.0])
    initial = {k: v[:1] for k, v in states.items()}
    fp_static = ground_footprint(spots, beam, terrain, ray_scene, mpe_w_m2, mu, eye_height_m, states_by_target=initial,
                                 max_range_m=rmax)
    fp_dyn = fp_static
    if states:
        fp_dyn = ground_footprint(spots, beam, terrain, ray_scene, mpe_w_m2, mu, eye_height_m, states_by_target=states,
                                  max_range_m=rmax)
    detail = (f"hazardous ground at {eye_height_m:g} m eye height: static {fp_static.area_m2:.4g} m^2, "
              f"dynamic {fp_dyn.area_m2:.4g} m^2")
    return Footprints(fp_static, fp_dyn, detail)
