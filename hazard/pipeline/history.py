"""Stage ``history``: the analysis times and each dynamic target's state over them."""

from __future__ import annotations

from dataclasses import dataclass, field

import math

import numpy as np

import brdfmodels

__all__ = ["StateHistories", "analysis_times", "spot_states", "state_histories"]


@dataclass
class StateHistories:
    """``states``: target index -> material state at each analysis time ((T,), or (T, 2)
    for two states); ``detail``: what drove each (measured series, or heating at the
    spot's peak irradiance); ``melt``: target index -> :class:`Melt`, where known (a
    heating history, or a series with a ``melt_fraction`` state)."""

    states: dict[int, np.ndarray]
    detail: str
    melt: dict[int, Melt] = field(default_factory=dict)


@dataclass(frozen=True)
class Melt:
    """A target's melt fraction at the analysis times and when melting starts and ends
    [s] (None: not within the run)."""

    fraction: np.ndarray
    onset_s: float | None
    full_s: float | None

    def summary(self) -> dict:
        """The report's entry (``targets[i].melt``): onset and full-melt times [s]."""
        return {"onset_s": self.onset_s, "full_melt_s": self.full_s, "max_fraction": float(np.max(self.fraction))}


def analysis_times(spec, dynamic: bool, node_times_s=()) -> np.ndarray:
    """Times [s] of the map: 0 .. ``time_end_s`` (default: the exposure duration) every
    ``time_step_s`` (default: 1/100 of it) for dynamic materials, else just 0; with the
    nodes of measured series (``node_times_s``) inside that span added: a series is linear
    between its nodes, so its extremes fall on a node or a step and the peak over the
    times is the peak over the whole run (a brightest node between steps was missed:
    0.886 of its irradiance at 0.5 s and 0.25 s steps, 0.970 at 0.05 s)."""
    if not dynamic:
        return np.array([0.0])
    t_end = spec.analysis.time_end_s or spec.exposure.duration_s
    dt = spec.analysis.time_step_s or t_end / 100.0
    times = np.arange(0.0, t_end + 0.5 * dt, dt)
    times[-1] = min(times[-1], t_end) if len(times) > 1 else times[-1]
    nodes = np.concatenate([np.ravel(np.asarray(t, float)) for t in node_times_s]) if len(node_times_s) else np.zeros(0)
    nodes = nodes[(nodes > 0.0) & (nodes < times[-1])]
    if len(nodes):
        times = np.unique(np.concatenate([times, nodes]))
        times = times[np.concatenate([[True], np.diff(times) > 1e-12 * max(t_end, 1e-300)])]
    return times


def series_nodes(targets) -> list[np.ndarray]:
    """The node times [s] of every target's measured series (for :func:`analysis_times`)."""
    return [np.asarray(t.history.times_s, float) for t in targets if getattr(t, "history", None) is not None]


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
              f"T_max {res.temperature_k.max():.0f} K" + _melt_text(res.melt_onset_s, res.full_melt_s))
    melt = Melt(np.interp(times, res.times_s, res.melt_fraction), res.melt_onset_s, res.full_melt_s)
    return res.history(hs.state, extrapolation="clamp"), detail, melt


def _melt_text(onset_s, full_s) -> str:
    if onset_s is None:
        return ", no melting"
    return f", melting from {onset_s:.4g} s" + (f", all molten at {full_s:.4g} s" if full_s is not None else ", not all molten")


def series_melt(hist, times) -> Melt | None:
    """The melt fraction of a series history that carries one (None otherwise): onset is
    the last time the series is 0 before it rises (it is linear between its points),
    full melt the first time it reaches 1 (interpolated)."""
    names = list(hist.state_names)
    if "melt_fraction" not in names:
        return None
    k = names.index("melt_fraction")
    t_s = hist.times_s
    f_s = hist.states if hist.state_dim == 1 else hist.states[:, k]
    frac = np.asarray(hist.state_at(times), float)
    frac = frac if frac.ndim == 1 else frac[:, k]
    up = np.flatnonzero(f_s > 0)
    onset = None if not len(up) else float(t_s[up[0] - 1] if up[0] > 0 else t_s[0])
    full_i = np.flatnonzero(f_s >= 1)
    full = None
    if len(full_i):
        j = full_i[0]
        full = float(t_s[0]) if j == 0 else float(np.interp(1.0, [f_s[j - 1], f_s[j]], [t_s[j - 1], t_s[j]]))
    return Melt(frac, onset, full)


def state_histories(dynamic_spots, times, t_end) -> StateHistories:
    """States over ``times`` of each dynamic spot's material (measured series or heating)."""
    states, parts, melts = {}, [], {}
    for sp in dynamic_spots:
        t = sp.target
        if t.spec.history.kind == "heating":
            hist, detail, melt = _heated_history(sp, times, t_end)
        else:
            hist, melt = t.history, series_melt(t.history, times)
            detail = f"{t.name}: measured series" + ("" if melt is None else _melt_text(melt.onset_s, melt.full_s))
        parts.append(detail)
        states[t.index] = hist.state_at(times)
        if melt is not None:
            melts[t.index] = melt
    return StateHistories(states, "; ".join(parts), melts)


def spot_states(spec, spots, times):
    """The spots' dynamic targets over ``times``: ``(spots, hist, notes)`` with the spots
    given their slumps (:func:`with_slumps`), the :class:`StateHistories` and the slump
    notes; ``(spots, None, [])`` when no spot is dynamic."""
    dynamic = [sp for sp in spots if sp.material.is_dynamic]
    if not dynamic:
        return spots, None, []
    hist = state_histories(dynamic, times, spec.analysis.time_end_s or spec.exposure.duration_s)
    spots, notes = with_slumps(spots, hist.melt, spec.analysis.slump_step_deg)
    return spots, hist, notes


def with_slumps(spots, melts: dict, step_deg: float = 2.0):
    """The spots, each whose target's material declares a slump given its
    :class:`~hazard.physics.slump.SpotSlump` over the analysis times (the lobe's union
    sampled every ``step_deg``); and a note per slumping target for the stage record."""
    from dataclasses import replace

    from hazard.physics.slump import spot_slump

    out, notes = [], []
    for sp in spots:
        melt = melts.get(sp.target.index)
        sl = spot_slump(sp.target, melt.fraction, sp.mean_frame[2], math.radians(step_deg)) if melt is not None else None
        if sl is not None and sl.moves:
            s = sp.target.slump
            notes.append(f"{sp.target.name}: slump tilts the normal up to {np.degrees(s.tilt_rad):.3g} deg (with the melt "
                         f"fraction), wander within {np.degrees(s.wander_rad):.3g} deg once molten")
            sp = replace(sp, slump=sl)
        out.append(sp)
    return out, notes
