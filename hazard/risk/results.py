"""From the chunks to the answer: per observer and per map cell the exceedance
probability, its interval, quantiles, the risk over operations and the sensitivity
(formulas: :mod:`hazard.risk.stats`)."""

from __future__ import annotations

import numpy as np

from ..nohd import optical_gain
from . import stats
from .evaluate import map_shape
from .importance import ALPHA0

__all__ = ["observer_rows", "map_result", "statement", "sensitivity", "lit_quantiles"]

SOBOL_MIN_HITS = 10  # fewer exceedances in the sensitivity sample: apportion the variance of ln(E) instead


def statement(p: float, lo: float, hi: float, n: int, what: str = "E > MPE") -> str:
    """The exact statistical statement, e.g. "P(E > MPE) = 3.2e-3, 95 % CI [2.1e-3, 4.6e-3], 20,000 draws"."""
    def f(x):
        return "0" if x == 0 else ("1" if x == 1 else f"{x:.2g}" if x >= 1e-2 else f"{x:.2e}".replace("e-0", "e-"))

    return f"P({what}) = {f(p)}, {int(round(100 * stats.LEVEL))} % CI [{f(lo)}, {f(hi)}], {n:,} draws"


def _estimate(over: np.ndarray, w: np.ndarray, importance: bool, n: int) -> stats.Estimate:
    return stats.estimate(*stats.weighted_counts(over, w), n, importance, ALPHA0)


def sensitivity(chunks, gains: np.ndarray, active: list) -> list | None:
    """Per observer: first-order Sobol indices of the exceedance (or of ln ratio when the
    sample has fewer than 10 exceedances) and the driver; None without a sensitivity sample."""
    if not chunks:
        return None
    a = np.concatenate([c["A"] for c in chunks]) * gains
    cs = {g: np.concatenate([c[f"C_{g}"] for c in chunks]) * gains for g in active}
    over = a >= 1.0
    hits = over.sum(axis=0) + sum((c >= 1.0).sum(axis=0) for c in cs.values())
    ind = stats.sobol_first_order(over.astype(float), {g: (c >= 1.0).astype(float) for g, c in cs.items()})
    tiny = 1e-300
    logs = stats.sobol_first_order(np.log(np.maximum(a, tiny)), {g: np.log(np.maximum(c, tiny)) for g, c in cs.items()})
    out = []
    for j in range(a.shape[1]):
        use_ind = hits[j] >= SOBOL_MIN_HITS
        src = ind if use_ind else logs
        first = {g: (None if not np.isfinite(src[g][j]) else float(src[g][j])) for g in active}
        known = {g: v for g, v in first.items() if v is not None}
        of = ("exceedance" if use_ind else "log_ratio") if known else (
            f"none: the irradiance does not vary over the {a.shape[0]} sensitivity draws (raise sensitivity_draws)")
        out.append({"of": of, "draws": int(a.shape[0]), "first_order": first, "driver": max(known, key=known.get) if known else None})
    return out


def _operations(est: stats.Estimate, n_ops) -> list:
    if n_ops is None:
        return [None] * len(est.p)
    p1, pp = stats.at_least_one(est.p, n_ops)
    lo, _ = stats.at_least_one(est.lo, n_ops)
    hi, _ = stats.at_least_one(est.hi, n_ops)
    return [{"n": n_ops, "probability_at_least_one": float(p1[j]), "probability_at_least_one_poisson": float(pp[j]),
             "ci_low": float(lo[j]), "ci_high": float(hi[j])} for j in range(len(est.p))]


def _aids(scene) -> list:
    from ..pipeline.lobes import scene_aids

    return [(a, optical_gain(a.magnification, a.objective_diameter_m, a.transmission)) for a in scene_aids(scene)]


def lit_quantiles(own: np.ndarray, w: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
    """Per column of the hazard ratios ``own`` (n, M): the (weighted) fraction of the draws
    that put any light on the point (ratio > 0) and the quantiles of the ratio among those
    draws (len(QUANTILES), M; NaN where no draw lit the point).

    A point lit in under 1 % of the draws has all three unconditional quantiles 0; these
    say how strong the exposure is when it comes.
    """
    n, m = own.shape
    lit = own > 0
    ww = np.ones(n) if w is None else np.asarray(w, float)
    lw = ww[:, None] * lit  # (n, M): the weights of the lit draws, 0 elsewhere
    total = lw.sum(axis=0)
    frac = total / ww.sum() if ww.sum() > 0 else np.zeros(m)
    order = np.argsort(np.where(lit, own, np.inf), axis=0, kind="stable")  # the unlit last, with no weight
    vs = np.take_along_axis(own, order, axis=0)
    cdf = np.cumsum(np.take_along_axis(lw, order, axis=0), axis=0)
    with np.errstate(invalid="ignore", divide="ignore"):
        cdf = cdf / total
    q = np.full((len(stats.QUANTILES), m), np.nan)
    some = total > 0
    for i, x in enumerate(stats.QUANTILES):  # the smallest value with at least the fraction x at or below it
        k = np.minimum((cdf < x - 1e-12).sum(axis=0), n - 1)
        q[i, some] = np.take_along_axis(vs, k[None, :], axis=0)[0, some]
    return frac, q


def _quantile_dict(q: np.ndarray, j: int, scale: float = 1.0) -> dict:
    return {f"p{int(round(100 * x))}": (None if not np.isfinite(q[i, j]) else float(q[i, j] * scale))
            for i, x in enumerate(stats.QUANTILES)}


def observer_rows(ev, s, chunks, sens) -> list:
    """One dict per observer point (see risk.json ``observers``)."""
    m = s.n_observers
    if m == 0:
        return []
    r = np.concatenate([c["ratio"] for c in chunks.main]) if chunks.main else np.zeros((0, m))
    w = np.exp(np.concatenate([c["log_weight"] for c in chunks.main])) if chunks.main else np.zeros(0)
    imp = s.sampling == "importance"
    gains = ev.own_gain()[:m]
    own = r * gains
    est = _estimate(own >= 1.0, w, imp, s.draws)
    q = stats.weighted_quantiles(own, w if imp else None)
    lit_frac, q_lit = lit_quantiles(own, w if imp else None)
    aided = [(a, g, _estimate(r * g >= 1.0, w, imp, s.draws)) for a, g in _aids(ev.scene)]
    ops = _operations(est, ev.scene.spec.uncertainty.operations)
    labels = ev.labels
    pos = ev.points_m[:m] + ev.scene.offset_m
    rows = []
    for j in range(m):
        rows.append({
            "name": labels[j], "position_m": [float(x) for x in pos[j]], "optical_gain": float(gains[j]),
            "probability_exceed": float(est.p[j]), "probability_ci_low": float(est.lo[j]), "probability_ci_high": float(est.hi[j]),
            "ci_method": est.method, "hits": int(est.hits[j]), "effective_draws": float(est.n_eff[j]),
            "hazard_ratio_quantiles": {f"p{int(round(100 * x))}": float(q[i, j]) for i, x in enumerate(stats.QUANTILES)},
            "irradiance_quantiles_w_m2": {f"p{int(round(100 * x))}": float(q[i, j] * ev.mpe_w_m2) for i, x in enumerate(stats.QUANTILES)},
            "lit_fraction": float(lit_frac[j]), "hazard_ratio_quantiles_lit": _quantile_dict(q_lit, j),
            "aided": [{"magnification": a.magnification, "objective_diameter_m": a.objective_diameter_m, "gain": float(g),
                       "probability_exceed": float(e.p[j]), "probability_ci_low": float(e.lo[j]), "probability_ci_high": float(e.hi[j])}
                      for a, g, e in aided],
            "operations": ops[j], "sensitivity": None if sens is None else sens[j],
            "statement": statement(float(est.p[j]), float(est.lo[j]), float(est.hi[j]), s.draws),
        })
    return rows


def map_result(ev, s, chunks) -> dict | None:
    """The probability map: cell centres (world) and per cell the probability and its interval."""
    n_map = s.n_points - s.n_observers
    if n_map == 0:
        return None
    hits = sum(c["map_hits"] for c in chunks.main)
    sw = sum(c["map_sum_w"] for c in chunks.main)
    sw2 = sum(c["map_sum_w2"] for c in chunks.main)
    est = stats.estimate(hits, sw, sw2, s.draws, s.sampling == "importance", ALPHA0)
    spec = ev.scene.spec.uncertainty.map
    pts = ev.points_m[s.n_observers:] + ev.scene.offset_m
    return {"points_m": pts, "shape": map_shape(spec), "probability": est.p, "ci_low": est.lo, "ci_high": est.hi,
            "hits": est.hits, "spacing_m": spec.spacing_m, "extent_m": list(spec.extent_m), "eye_height_m": spec.eye_height_m,
            "method": est.method}
