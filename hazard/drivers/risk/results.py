"""From the chunks to the answer: per observer and per map cell the exceedance
probability, its interval, quantiles, the risk over operations and the sensitivity
(formulas: :mod:`hazard.drivers.risk.stats`)."""

from __future__ import annotations

import numpy as np

from hazard.physics.nohd import optical_gain
from hazard.drivers.risk import stats
from hazard.drivers.risk.evaluate import map_shape
from hazard.drivers.risk.importance import ALPHA0

__all__ = ["observer_rows", "observer_stats", "map_result", "statement", "sensitivity", "lit_quantiles"]

SOBOL_MIN_HITS = 10  # fewer exceedances in the sensitivity sample: apportion the variance of ln(E) instead


def statement(p: float, lo: float, hi: float, n: int, what: str = "E > MPE") -> str:
    """The exact statistical statement, e.g. "P(E > MPE) = 3.2e-3, 95 % CI [2.1e-3, 4.6e-3], 20,000 draws"."""
    def f(x):
        return "0" if x == 0 else ("1" if x == 1 else f"{x:.2g}" if x >= 1e-2 else f"{x:.2e}".replace("e-0", "e-"))

    return f"P({what}) = {f(p)}, {int(round(100 * stats.LEVEL))} % CI [{f(lo)}, {f(hi)}], {n:,} draws"


def _estimate(over: np.ndarray, w: np.ndarray, importance: bool, n: int) -> stats.Estimate:
    return stats.estimate(*stats.weighted_counts(over, w), n, importance, ALPHA0)


def sensitivity(store, gains: np.ndarray, active: list) -> list | None:
    """Per observer: first-order Sobol indices of the exceedance (or of ln ratio when the
    sample has fewer than 10 exceedances) and the driver; None without a sensitivity sample.
    ``store``: the gathered arrays (:class:`hazard.drivers.risk.columns.ColumnStore` with "A" and
    "C_<group>"), read one block of observers at a time."""
    if store is None or "A" not in store.rows:
        return None
    out = []
    for j0, j1 in store.bounds["A"]:
        g = gains[j0:j1]
        a = store.block("A", j0, j1) * g
        cs = {k: store.block(f"C_{k}", j0, j1) * g for k in active}
        out += _sensitivity_block(a, cs, active)
    return out


def _sensitivity_block(a: np.ndarray, cs: dict, active: list) -> list:
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
    from hazard.pipeline.lobes import scene_aids

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


class _Columns:
    """Per observer (M,) arrays filled block by block (:func:`observer_stats`)."""

    def __init__(self, m: int, n_aids: int):
        self.p, self.lo, self.hi, self.hits, self.n_eff = (np.empty(m) for _ in range(5))
        self.q, self.q_lit = np.empty((len(stats.QUANTILES), m)), np.empty((len(stats.QUANTILES), m))
        self.lit_frac = np.empty(m)
        self.aided = [(np.empty(m), np.empty(m), np.empty(m)) for _ in range(n_aids)]
        self.method = None


def observer_stats(ev, s, gathered) -> _Columns:
    """The per-observer statistics from the gathered ratios (:func:`hazard.drivers.risk.run.gather`),
    one block of observers at a time: the same values as from the whole (draws, M) array."""
    imp = s.sampling == "importance"
    w = np.exp(gathered.log_weight)
    gains = ev.own_gain()[: s.n_observers]
    aids = _aids(ev.scene)
    out = _Columns(s.n_observers, len(aids))
    for j0, j1, r in gathered.store.blocks("ratio"):
        own = r * gains[j0:j1]
        est = _estimate(own >= 1.0, w, imp, s.draws)
        out.p[j0:j1], out.lo[j0:j1], out.hi[j0:j1], out.hits[j0:j1], out.n_eff[j0:j1] = est.p, est.lo, est.hi, est.hits, est.n_eff
        out.method = est.method
        out.q[:, j0:j1] = stats.weighted_quantiles(own, w if imp else None)
        out.lit_frac[j0:j1], out.q_lit[:, j0:j1] = lit_quantiles(own, w if imp else None)
        del own
        for (_, g), cols in zip(aids, out.aided):
            e = _estimate(r * g >= 1.0, w, imp, s.draws)
            cols[0][j0:j1], cols[1][j0:j1], cols[2][j0:j1] = e.p, e.lo, e.hi
    return out


def observer_rows(ev, s, gathered, sens) -> list:
    """One dict per observer point (see risk.json ``observers``)."""
    m = s.n_observers
    if m == 0:
        return []
    c = observer_stats(ev, s, gathered)
    aided = [(a, g, cols) for (a, g), cols in zip(_aids(ev.scene), c.aided)]
    gains = ev.own_gain()[:m]
    ops = _operations(stats.Estimate(c.p, c.lo, c.hi, c.hits, c.n_eff, c.method), ev.scene.spec.uncertainty.operations)
    labels = ev.labels
    pos = ev.points_m[:m] + ev.scene.offset_m
    rows = []
    for j in range(m):
        rows.append({
            "name": labels[j], "position_m": [float(x) for x in pos[j]], "optical_gain": float(gains[j]),
            "probability_exceed": float(c.p[j]), "probability_ci_low": float(c.lo[j]), "probability_ci_high": float(c.hi[j]),
            "ci_method": c.method, "hits": int(c.hits[j]), "effective_draws": float(c.n_eff[j]),
            "hazard_ratio_quantiles": {f"p{int(round(100 * x))}": float(c.q[i, j]) for i, x in enumerate(stats.QUANTILES)},
            "irradiance_quantiles_w_m2": {f"p{int(round(100 * x))}": float(c.q[i, j] * ev.mpe_w_m2) for i, x in enumerate(stats.QUANTILES)},
            "lit_fraction": float(c.lit_frac[j]), "hazard_ratio_quantiles_lit": _quantile_dict(c.q_lit, j),
            "aided": [{"magnification": a.magnification, "objective_diameter_m": a.objective_diameter_m, "gain": float(g),
                       "probability_exceed": float(e[0][j]), "probability_ci_low": float(e[1][j]), "probability_ci_high": float(e[2][j])}
                      for a, g, e in aided],
            "operations": ops[j], "sensitivity": None if sens is None else sens[j],
            "statement": statement(float(c.p[j]), float(c.lo[j]), float(c.hi[j]), s.draws),
        })
    return rows


def map_result(ev, s, gathered) -> dict | None:
    """The probability map: cell centres (world) and per cell the probability and its interval."""
    n_map = s.n_points - s.n_observers
    if n_map == 0:
        return None
    est = stats.estimate(gathered.map_hits, gathered.map_sum_w, gathered.map_sum_w2, s.draws, s.sampling == "importance", ALPHA0)
    spec = ev.scene.spec.uncertainty.map
    pts = ev.points_m[s.n_observers:] + ev.scene.offset_m
    return {"points_m": pts, "shape": map_shape(spec), "probability": est.p, "ci_low": est.lo, "ci_high": est.hi,
            "hits": est.hits, "spacing_m": spec.spacing_m, "extent_m": list(spec.extent_m), "eye_height_m": spec.eye_height_m,
            "method": est.method}
