"""Stage ``history``: the analysis times and each dynamic target's state over them."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

import brdfmodels

__all__ = ["StateHistories", "analysis_times", "state_histories"]


@dataclass
class StateHistories:
    """``states``: target index -> material state at each analysis time; ``detail``: what
    drove each (measured series, or heating at the spot's peak irradiance)."""

    states: dict
    detail: str


def analysis_times(spec, dynamic: bool) -> np.ndarray:
    """Times [s] of the map: 0 .. ``time_end_s`` (default: the exposure duration) every
    ``time_step_s`` (default: 1/100 of it) for dynamic materials, else just 0."""
    if not dynamic:
        return np.array([0.0])
    t_end = spec.analysis.time_end_s or spec.exposure.duration_s
    dt = spec.analysis.time_step_s or t_end / 100.0
    times = np.arange(0.0, t_end + 0.5 * dt, dt)
    times[-1] = min(times[-1], t_end) if len(times) > 1 else times[-1]
    return times


def _heated_history(sp, times, t_end):
    """A thin-plate heating history driven by the spot's hottest point (local peak
    irradiance after attenuation), with oxidation if given; returns (history, detail)."""
    t, hs = sp.target, sp.target.spec.history
    kw = {}
    if hs.thickness_m is not None:
        kw["thickness_m"] = hs.thickness_m
    if hs.initial_reflectance is not None:
        kw["initial_reflectance"] = hs.initial_reflectance
    if hs.oxidation is not None:
        kw["oxidation"] = brdfmodels.OxidationModel(**hs.oxidation.model_dump())
    plate = getattr(brdfmodels.ThinPlateHeating, hs.plate)(**kw)
    irr = sp.max_irradiance_w_m2
    res = plate.solve(times if len(times) > 1 else np.array([0.0, t_end]), irr, rtol=hs.rtol)
    detail = (f"{t.name}: heating at the spot's peak {irr:.4g} W/m^2 (spot mean {sp.mean_irradiance_w_m2:.4g} W/m^2), "
              f"T_max {res.temperature_k.max():.0f} K")
    return res.history(hs.state, extrapolation="clamp"), detail


def state_histories(dynamic_spots, times, t_end) -> StateHistories:
    """States over ``times`` of each dynamic spot's material (measured series or heating)."""
    states, parts = {}, []
    for sp in dynamic_spots:
        t = sp.target
        if t.spec.history.kind == "heating":
            hist, detail = _heated_history(sp, times, t_end)
        else:
            hist, detail = t.history, f"{t.name}: measured series"
        parts.append(detail)
        states[t.index] = hist.state_at(times)
    return StateHistories(states, "; ".join(parts))
