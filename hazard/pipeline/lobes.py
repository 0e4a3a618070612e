"""Stage ``keepout``: per lit target the hazard lobes (NOHD per direction, static and
dynamic) and the specular NOHD, gathered into the report's target rows."""

from __future__ import annotations

import numpy as np

from ..keepout import hazard_lobe
from ..results import TargetResult
from ..specular import specular_nohd

__all__ = ["target_results"]


def _dynamic_states(target, states):
    """States a dynamic target passes through: its history plus the material's nodes
    inside that range (so no peak between nodes is missed); None for a static target."""
    if target.index not in states:
        return None
    s_hist = states[target.index]
    nodes = target.material.state_nodes()
    lo, hi = s_hist.min(), s_hist.max()
    return np.unique(np.concatenate([s_hist, nodes[(nodes >= lo) & (nodes <= hi)]]))


def _specular(sp, mpe_w_m2, mu, initial, dyn_states):
    """Specular NOHD static and dynamic [m] and the direction of the longer (or Nones)."""
    if not sp.material.has_specular:
        return None, None, None
    ns = specular_nohd(sp, mpe_w_m2, mu, initial)
    nd = specular_nohd(sp, mpe_w_m2, mu, dyn_states) if dyn_states is not None else ns
    return ns.nohd_m, nd.nohd_m, (nd.direction if nd.nohd_m >= ns.nohd_m else ns.direction)


def target_result(sp, states, mpe_w_m2, mu, analysis) -> TargetResult:
    """One lit target's row: spot, lobes at ``analysis.direction_grid_deg`` with
    ``analysis.refine_levels`` levels, specular NOHDs, state range."""
    t = sp.target
    initial = states[t.index][:1] if t.index in states else None
    dyn_states = _dynamic_states(t, states)
    grid = dict(grid_deg=analysis.direction_grid_deg, refine_levels=analysis.refine_levels)
    static_lobe = hazard_lobe(sp, mpe_w_m2, mu, states=initial, **grid)
    dynamic_lobe = static_lobe if dyn_states is None else hazard_lobe(sp, mpe_w_m2, mu, states=dyn_states, **grid)
    spec_static, spec_dyn, spec_dir = _specular(sp, mpe_w_m2, mu, initial, dyn_states)
    return TargetResult(
        t.name, sp.total_power_w, sp.size_m, static_lobe, dynamic_lobe, spec_static, spec_dyn, spec_dir,
        t.material.state_name if t.material.is_dynamic else None,
        [float(states[t.index].min()), float(states[t.index].max())] if t.index in states else None,
        sp.power_error_w, sp.exact, sp.max_irradiance_w_m2, sp.mean_irradiance_w_m2, sp.side,
    )


def target_results(spots, states, mpe_w_m2, mu, analysis) -> list:
    """Rows of the lit targets, in the order of their spots."""
    return [target_result(sp, states, mpe_w_m2, mu, analysis) for sp in spots]
