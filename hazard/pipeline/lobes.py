"""Stage ``keepout``: per lit target the hazard lobes (NOHD per direction, static and
dynamic) and the specular NOHD, gathered into the report's target rows."""

from __future__ import annotations

import math

import numpy as np

from hazard.physics.engine import FAR_FIELD_SPOT_SIZES, frame_groups, path_states
from hazard.physics.keepout import nohd_range_fn, hazard_lobe
from hazard.physics.nohd import optical_gain
from hazard.pipeline.results import TargetResult
from hazard.physics.specular import specular_nohd

__all__ = ["target_results", "near_field_lobe_notes", "curved_spot_notes"]


def _dynamic_states(target, states):
    """States a dynamic target passes through (:func:`hazard.physics.engine.path_states`: for
    one state its history plus the material's nodes inside that range, so no peak
    between nodes is missed; for two states the path in time order); None for a static
    target."""
    if target.index not in states:
        return None
    return path_states(target.material, states[target.index])


def _state_range(states):
    """[lo, hi] of a one-state history, [[lo, hi], [lo, hi]] of a two-state one."""
    s = np.asarray(states, float)
    if s.ndim == 1:
        return [float(s.min()), float(s.max())]
    return [[float(s[:, d].min()), float(s[:, d].max())] for d in range(s.shape[1])]


SLUMP_LEFT_OUT = ("the wander at the observers (their irradiance follows the mean tilted normal; clear by the dynamic "
                  "lobe's NOHD), and directions behind the plate within tilt + wander of its plane (outside the lobe's "
                  "hemisphere)")


def slump_summary(sp, states, mpe_w_m2, mu, lobe, gain=1.0) -> dict | None:
    """The slump a dynamic lobe covers, and the estimate of its sampling error: the
    union sampled at half the step, at the lobe's farthest direction (the largest of
    the two is the reported NOHD: never the smaller)."""
    sl = sp.slump
    t = sp.target
    if sl is None or not sl.moves or lobe is None or t.index not in states:
        return None
    half = nohd_range_fn(sp, mpe_w_m2, mu, gain, states[t.index], sl.step_rad / 2)
    r_half = float(half(lobe.max_direction_local[None, :])[0])
    err = max(r_half - lobe.max_range_m, 0.0)
    if r_half > lobe.max_range_m:  # the NOHD is now the half-step union's: no single intensity gives it
        lobe.peak_intensity_w_sr = None
    lobe.max_range_m = max(lobe.max_range_m, r_half)
    return {"tilt_deg": float(np.degrees(t.slump.tilt_rad)), "wander_deg": float(np.degrees(t.slump.wander_rad)),
            "tilt_direction": t.slump.direction.tolist(), "step_deg": float(np.degrees(sl.step_rad)),
            "normals_sampled": lobe.normals, "normals_sampled_half_step": int(half.samples), "max_nohd_half_step_m": r_half,
            "sampling_error_estimate_m": err,
            "method": "irradiance map: the mean tilted normal at each time; keep-out lobe: union over the tilts and the "
                      "wander disk of each part of the history, paired with that part's states",
            "left_out": SLUMP_LEFT_OUT}


def _specular(sp, mpe_w_m2, mu, initial, dyn_states, gain):
    """Specular NOHD static and dynamic [m], the direction of the longer and the static
    one's numbers (:class:`hazard.physics.specular.MirrorBeamSteps`), or Nones."""
    if not sp.material.has_specular:
        return None, None, None, None
    ns = specular_nohd(sp, mpe_w_m2, mu, initial, gain=gain)
    nd = specular_nohd(sp, mpe_w_m2, mu, dyn_states, gain=gain) if dyn_states is not None else ns
    return ns.nohd_m, nd.nohd_m, (nd.direction if nd.nohd_m >= ns.nohd_m else ns.direction), ns.steps


def _hazards(sp, states, mpe_w_m2, mu, analysis, gain=1.0):
    """Static and dynamic lobes at ``analysis.direction_grid_deg`` with
    ``analysis.refine_levels`` levels, the specular NOHDs (static, dynamic, direction,
    the static one's numbers) and the slump, for an eye with optical gain ``gain``."""
    t = sp.target
    initial = states[t.index][:1] if t.index in states else None
    dyn_states = _dynamic_states(t, states)
    grid = dict(gain=gain, grid_deg=analysis.direction_grid_deg, refine_levels=analysis.refine_levels)
    static_lobe = hazard_lobe(sp, mpe_w_m2, mu, states=initial, **grid)
    # the lobe takes the history in time order (a slump pairs each part of it with its normals)
    dynamic_lobe = static_lobe if dyn_states is None else hazard_lobe(sp, mpe_w_m2, mu, states=states[t.index], **grid)
    slump = slump_summary(sp, states, mpe_w_m2, mu, dynamic_lobe, gain)  # raises the lobe's max to the half-step value
    return (static_lobe, dynamic_lobe) + _specular(sp, mpe_w_m2, mu, initial, dyn_states, gain) + (slump,)


def profile_fraction(sp, mu) -> float:
    """How far into the beam's profile the target reaches: its hottest incident
    irradiance over the beam's on-axis irradiance at that point's axial range, both
    attenuated along the same path (1: the target holds the axis; 1e-6: its nearest
    point is 3.7 1/e radii off it). The attenuation in logarithms: no underflow in
    thick air."""
    beam = sp.beam
    if sp.peak_irradiance_w_m2 is None or beam is None or not len(sp.peak_irradiance_w_m2):
        return 1.0
    k = int(np.argmax(sp.peak_irradiance_w_m2))
    e = float(sp.peak_irradiance_w_m2[k])
    if not e > 0:
        return 0.0
    z = max(float((np.asarray(sp.points[k], float) - beam.position_m) @ beam.axis), 0.0)
    on_axis = float(beam.irradiance_w_m2(np.zeros((1, 2)), np.array([z]))[0])  # P >= 1 nW (the schema): no underflow
    log_axis = math.log(on_axis) - mu * float(sp.range_from_laser_m[k])
    return float(min(math.exp(min(math.log(e) - log_axis, 0.0)), 1.0))


def target_result(sp, states, mpe_w_m2, mu, analysis) -> TargetResult:
    """One lit target's row: spot, naked-eye lobes and specular NOHDs, state range."""
    t = sp.target
    *hz, steps, slump = _hazards(sp, states, mpe_w_m2, mu, analysis)
    row = TargetResult(
        t.name, sp.total_power_w, sp.size_m, *hz,
        _name_list(t.material.state_name) if t.material.is_dynamic else None,
        _state_range(states[t.index]) if t.index in states else None,
        sp.power_error_w, sp.exact, sp.max_irradiance_w_m2, sp.mean_irradiance_w_m2, sp.side,
    )
    row.beam_profile_fraction = profile_fraction(sp, mu)
    row.specular_steps = steps
    row.slump = slump
    return row


def _name_list(name):
    return name if isinstance(name, str) else list(name)


def scene_aids(scene) -> list:
    """The distinct optical aids of the scene: the observer groups' optics, then
    ``[exposure] optics`` (each an OpticsSpec)."""
    seen, out = set(), []
    groups = scene.observers.optics if scene.observers is not None else ()
    for o in list(groups) + list(scene.spec.exposure.optics):
        key = None if o is None else (o.magnification, o.objective_diameter_m, o.transmission)
        if key is not None and key not in seen:
            seen.add(key)
            out.append(o)
    return out


def aided_nohds(sp, states, mpe_w_m2, mu, analysis, aid) -> dict:
    """NOHDs [m] of one lit target seen through an optical aid: the lobes and the specular
    NOHD with the aid's gain ``K = min(tau M^2, tau (D_o / 7 mm)^2)`` (each term >= 1;
    diffuse light fills the objective; for the mirror beam the beam-size limit is not
    taken, an upper bound)."""
    k = optical_gain(aid.magnification, aid.objective_diameter_m, aid.transmission)
    static_lobe, dynamic_lobe, spec_static, spec_dyn, _, _, _ = _hazards(sp, states, mpe_w_m2, mu, analysis, gain=k)
    return {"magnification": aid.magnification, "objective_diameter_m": aid.objective_diameter_m,
            "transmission": aid.transmission, "gain": k, "nohd_static_m": static_lobe.max_range_m,
            "nohd_dynamic_m": dynamic_lobe.max_range_m, "specular_nohd_static_m": spec_static, "specular_nohd_dynamic_m": spec_dyn}


def target_results(spots, states, mpe_w_m2, mu, analysis, aids=()) -> list:
    """Rows of the lit targets, in the order of their spots, with their NOHDs through each
    optical aid in ``aids``."""
    rows = []
    for sp in spots:
        row = target_result(sp, states, mpe_w_m2, mu, analysis)
        row.aided = [aided_nohds(sp, states, mpe_w_m2, mu, analysis, aid) for aid in aids]
        rows.append(row)
    return rows


def near_field_lobe_notes(spots, rows) -> list[str]:
    """Notes on the lit targets whose keep-out lobe ends within ``FAR_FIELD_SPOT_SIZES``
    spot sizes (the map's far-field rule), one note per kind, every such target named with its
    reach: where the lobe there is the farthest root of the near-field integral over the spot
    (:mod:`hazard.physics.near_field_lobe`), how it was found and its tolerance; where it could not be
    (a slumping spot, a spot without its triangles), that the lobe is the point-source form
    from the spot's centroid, which is short along a spot stretched by grazing incidence (a
    plate at 89.9 deg: 0.52 m where the integral reaches 6.30 m)."""
    by_name = {sp.target.name: sp for sp in spots}
    integrated, point_form = [], []
    for row in rows:
        sp, lobe = by_name.get(row.name), row.dynamic_lobe
        if sp is None or lobe is None or not lobe.max_range_m > 0:
            continue
        if not lobe.max_range_m < FAR_FIELD_SPOT_SIZES * sp.size_m:
            continue  # the keep-out distance lies in the far field (report.json's lobe "near_field" says what was integrated)
        nf = lobe.near_field  # a slumping spot's dynamic lobe (the union of tilted normals) has none
        if nf and nf["directions_integrated"]:
            integrated.append((row.name, lobe.max_range_m, sp.size_m, nf))
        else:
            point_form.append((row.name, lobe.max_range_m, sp.size_m,
                               "a slumping spot" if sp.slump is not None else "no near-field triangles"))
    out = []
    if integrated:
        grids = {(tuple(nf["grid_theta_deg"]), nf["grid_phi_deg"]) for *_, nf in integrated}
        grid = "; ".join(f"polar rows {', '.join(f'{t:g}' for t in th)} deg, azimuth step {ph:g} deg" for th, ph in sorted(grids))
        each = "; ".join(f"{name} {reach:.4g} m (spot size {size:.4g} m, {nf['directions_integrated']} direction(s), "
                         f"scan step up to {nf['scan_step_max_m']:.3g} m)" for name, reach, size, nf in integrated)
        out.append(f"keep-out lobe(s) within {FAR_FIELD_SPOT_SIZES:g} spot sizes of their spot, each the farthest root "
                   f"of the near-field integral over the spot (the observers' own, 1 % of P / d^2 per sample) from the "
                   f"spot's centroid on a grid of directions ({grid}), scanned inward (the step added to the distance), "
                   f"between the nodes the largest node of the cell plus a curvature margin, never below the point form: "
                   f"{each}")
    if point_form:
        each = "; ".join(f"{name} {reach:.4g} m (spot size {size:.4g} m, 2 RMS radii; {why})" for name, reach, size, why in point_form)
        out.append(f"keep-out lobe(s) ending within {FAR_FIELD_SPOT_SIZES:g} spot sizes of their spot and not integrated "
                   f"there: the point-source form, which is short along a spot stretched by grazing incidence (a plate at "
                   f"89.9 deg: 0.52 m where the exact integral reaches 6.30 m), so not a keep-out distance there; the "
                   f"observers and the hazardous-ground footprint use the exact integral over the spot: place observers "
                   f"along the spot to map the zone: {each}")
    return out


def curved_spot_notes(spots) -> list[str]:
    """One note naming the lit spots of several surface frames (:func:`hazard.physics.engine.frame_groups`:
    a sphere's or cylinder's facets, a terrain's) and what their results rest on: the far
    field and the lobe's point form are the larger of the mean frame's ``f_r cos`` and the
    sum over the spot's own frames, which rests on its few samples; the keep-out zone's
    volume and outline cover only the hemisphere above each mean plane."""
    curved = [(sp.target.name, len(g[0])) for sp in spots if (g := frame_groups(sp)) is not None]
    if not curved:
        return []
    each = ", ".join(f"{name} ({n} frames)" for name, n in curved)
    return [f"curved spot(s): {each}: their far field and keep-out lobe take the larger of the mean frame's f_r cos and "
            f"the sum over the spot's own surface frames (the mean frame alone sends nothing beside or behind a curved "
            f"body); that sum rests on the spot's few samples and can be short beside a sphere or cylinder (up to 15 % "
            f"in range in the tests) and in the crescent behind it, and the keep-out zone's volume and outline cover only "
            f"the hemisphere above each spot's mean plane: place observers around curved targets (README: 'A curved "
            f"spot's light beside and behind it')"]
