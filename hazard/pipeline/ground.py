"""Stage ``footprint``: the hazardous ground at eye height over a terrain."""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from hazard.physics import near_field as _near
from hazard.physics.keepout import Footprint, ground_footprint
from hazard.pipeline.direct import beam_at, clear_of_objects
from hazard.physics.slump import held_slump

__all__ = ["Footprints", "footprints"]


@dataclass
class Footprints:
    """Hazardous ground with the initial states held (static) and over the history."""

    static: Footprint
    dynamic: Footprint
    detail: str


def footprints(spots, beam, terrain, ray_scene, mpe_w_m2, mu, eye_height_m, states, target_rows, aperture_m=None) -> Footprints:
    """Ground cells at ``eye_height_m`` where the irradiance summed over every spot
    reaches the MPE, out to the longest NOHD of any target (diffuse or specular);
    ``aperture_m``: the limiting aperture the direct beam's ratio is taken through."""
    before, bounded = _near.STATS.snapshot(), _near.BOUNDED.snapshot()
    lit = [tr for tr in target_rows if tr.dynamic_lobe is not None]  # unlit targets' rows carry no lobe
    rmax = max([tr.dynamic_lobe.max_range_m for tr in lit] + [tr.specular_nohd_dynamic_m or 0.0 for tr in lit] + [0.0])
    initial = {k: v[:1] for k, v in states.items()}
    held = [sp if sp.slump is None else held_slump(sp) for sp in spots]  # the initial state holds its initial tilt
    fp_static = ground_footprint(held, beam, terrain, ray_scene, mpe_w_m2, mu, eye_height_m, states_by_target=initial,
                                 max_range_m=rmax)
    fp_dyn = fp_static
    if states:
        fp_dyn = ground_footprint(spots, beam, terrain, ray_scene, mpe_w_m2, mu, eye_height_m, states_by_target=states,
                                  max_range_m=rmax)
    direct = direct_ratio(beam, terrain, ray_scene, mu, eye_height_m, mpe_w_m2, aperture_m)
    fp_static, fp_dyn = replace(fp_static, direct_ratio=direct), replace(fp_dyn, direct_ratio=direct)
    detail = (f"hazardous ground at {eye_height_m:g} m eye height: static {fp_static.area_m2:.4g} m^2, "
              f"dynamic {fp_dyn.area_m2:.4g} m^2; {_near.describe(_near.stats_since(before))}")
    b = {k: v - bounded[k] for k, v in _near.BOUNDED.snapshot().items()}
    if b["observers"] or b["pairs"]:
        detail += (f"; near a Lambertian spot {b['observers']} node(s) and {b['pairs']} node-sample/triangle pair(s) bounded "
                   "first (nodes whose bound stays below the MPE are not integrated: their ratio is that bound)")
    return Footprints(fp_static, fp_dyn, detail)


def direct_ratio(beam, terrain, ray_scene, mu, eye_height_m, mpe_w_m2, aperture_m=None) -> np.ndarray:
    """The laser's own beam at each terrain node's eye-height point, as a hazard ratio
    (nominal aim, naked eye, :func:`hazard.pipeline.direct.beam_at`; through the limiting
    aperture of diameter ``aperture_m`` when given, :mod:`hazard.physics.aperture`; zero where an
    object stands between the aperture and the eye's centre)."""
    from hazard.physics.aperture import Apertures
    from hazard.pipeline.direct import gaussian_aperture_w_m2

    ny, nx = terrain.heights.shape
    gx, gy = np.meshgrid(terrain.x0 + terrain.dx * np.arange(nx), terrain.y0 + terrain.dx * np.arange(ny))
    pts = np.stack([gx.ravel(), gy.ravel(), terrain.heights.ravel() + eye_height_m], 1)
    at = beam_at(beam, pts, mu, 0.0 if aperture_m is None else aperture_m / 2)
    out = np.zeros(len(pts), np.float32)
    if len(at.rows):
        clear = clear_of_objects(at, pts, ray_scene) if ray_scene is not None else np.ones(len(at.rows), bool)
        e = at.irradiance_w_m2
        if aperture_m is not None:
            n = len(at.rows)
            eye = Apertures(np.full(n, aperture_m / 2), np.full(n, aperture_m / 2), np.ones(n), np.zeros(n, bool))
            e = gaussian_aperture_w_m2(beam, at.axial_m, at.offset_m, at.path_m, mu, eye)
        out[at.rows] = np.where(clear, e / mpe_w_m2, 0.0)
    return out.reshape(ny, nx)
