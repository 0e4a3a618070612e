"""Statistics of the simulated operations (spec `range-safety.md` section 8).

- **Plain sampling**: k exceedances in n draws; the estimate k/n and the exact
  Clopper-Pearson interval (Clopper & Pearson, Biometrika 26:404, 1934; coverage >= the
  nominal level), ``beta.ppf(a/2, k, n-k+1)`` to ``beta.ppf(1-a/2, k+1, n-k)``.
- **Importance sampling**: the estimate ``mean(w 1{E > MPE})`` is unbiased; its interval
  is Clopper-Pearson at the effective sample size ``n_eff = p(1-p)/se^2`` (Kish's design
  effect; k_eff = p n_eff, real-valued beta quantiles) when at least 10 draws hit. With
  fewer, the weighted variance is itself unreliable, and the interval is [0, U / alpha_0]
  with U the Clopper-Pearson upper bound of the hits among all n draws: every draw comes
  from a mixture holding the stated distribution with weight alpha_0, so the chance of a
  hit per draw is at least alpha_0 P (a rigorous bound, wide by 1/alpha_0).
- Quantiles: the inverse of the (weighted) empirical CDF (Hyndman & Fan definition 1):
  the smallest value with at least the fraction q at or below it.
- Operations: P(at least one exceedance in N) = 1 - (1 - p)^N, and the Poisson form
  1 - exp(-N p); the interval maps through the same monotone function.
- First-order Sobol indices by pick-freeze (Janon, Klein, Lagnoux, Nodet & Prieur,
  ESAIM: P&S 18:342, 2014): with Y = f(A) and Y_i = f(C_i), C_i taking input group i from
  A and every other from an independent B,
  ``S_i = [<Y Y_i> - <(Y + Y_i)/2>^2] / [<(Y^2 + Y_i^2)/2> - <(Y + Y_i)/2>^2]``.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["clopper_pearson", "wilson", "weighted_counts", "estimate", "Estimate", "weighted_quantiles", "at_least_one", "sobol_first_order", "QUANTILES"]

QUANTILES = (0.50, 0.95, 0.99)
MIN_IMPORTANCE_HITS = 10  # fewer hits: the rigorous mixture bound instead of the effective-size interval
LEVEL = 0.95


def clopper_pearson(k, n, level: float = LEVEL):
    """Exact two-sided interval of a binomial proportion (k may be real: effective counts)."""
    from scipy.stats import beta

    k, n = np.asarray(k, float), np.asarray(n, float)
    a = 1 - level
    with np.errstate(invalid="ignore", divide="ignore"):
        lo = np.where(k > 0, beta.ppf(a / 2, np.maximum(k, 1e-300), np.maximum(n - k + 1, 1e-300)), 0.0)
        hi = np.where(k < n, beta.ppf(1 - a / 2, k + 1, np.maximum(n - k, 1e-300)), 1.0)
    return np.nan_to_num(lo, nan=0.0), np.nan_to_num(hi, nan=1.0)


def wilson(k, n, level: float = LEVEL):
    """Wilson score interval (Wilson, JASA 22:209, 1927)."""
    from scipy.stats import norm

    z = norm.isf((1 - level) / 2)
    k, n = np.asarray(k, float), np.asarray(n, float)
    p = k / n
    centre = (p + z * z / (2 * n)) / (1 + z * z / n)
    half = z / (1 + z * z / n) * np.sqrt(p * (1 - p) / n + z * z / (4 * n * n))
    return np.maximum(centre - half, 0.0), np.minimum(centre + half, 1.0)


class Estimate:
    """Per point: the probability, its interval, the hits and the effective draws."""

    def __init__(self, p, lo, hi, hits, n_eff, method):
        self.p, self.lo, self.hi, self.hits, self.n_eff, self.method = p, lo, hi, hits, n_eff, method


def weighted_counts(over: np.ndarray, w: np.ndarray) -> tuple:
    """Per column of ``over`` (n, M) booleans: the hits and the sums of the weights ``w``
    (n,) and of their squares over the hits."""
    return over.sum(axis=0), (w[:, None] * over).sum(axis=0), ((w * w)[:, None] * over).sum(axis=0)


def estimate(hits, sum_w, sum_w2, n: int, importance: bool, alpha0: float) -> Estimate:
    """The exceedance probability per point from the counts of n draws: ``hits`` (draws
    over the limit), ``sum_w``/``sum_w2`` the sums of the weights (and squares) over them
    (equal to ``hits`` for plain sampling)."""
    hits = np.asarray(hits, float)
    if not importance:
        lo, hi = clopper_pearson(hits, n)
        return Estimate(hits / n, lo, hi, hits, np.full(hits.shape, float(n)), "clopper-pearson")
    p = np.asarray(sum_w, float) / n
    var = np.maximum(np.asarray(sum_w2, float) / n - p * p, 0.0) / n  # of the mean
    with np.errstate(divide="ignore", invalid="ignore"):
        n_eff = np.where(var > 0, p * (1 - p) / var, float(n))
    n_eff = np.clip(np.nan_to_num(n_eff, nan=float(n)), 1.0, None)
    lo, hi = clopper_pearson(np.clip(p * n_eff, 0, n_eff), n_eff)
    _, hi_mix = clopper_pearson(hits, n)
    few = hits < MIN_IMPORTANCE_HITS
    hi = np.where(few, np.minimum(1.0, hi_mix / alpha0), hi)
    return Estimate(p, np.where(few, 0.0, lo), hi, hits, n_eff, "clopper-pearson-effective")


def weighted_quantiles(values: np.ndarray, weights: np.ndarray | None, qs=QUANTILES) -> np.ndarray:
    """Quantiles (inverted CDF) of each column of ``values`` (n, M); (len(qs), M)."""
    v = np.asarray(values, float)
    order = np.argsort(v, axis=0, kind="stable")
    vs = np.take_along_axis(v, order, axis=0)
    n = v.shape[0]
    if weights is None:
        idx = [min(n - 1, max(0, math.ceil(q * n) - 1)) for q in qs]
        return vs[idx]
    w = np.asarray(weights, float)[order]
    cdf = np.cumsum(w, axis=0)
    cdf /= cdf[-1:]
    out = np.empty((len(qs), v.shape[1]))
    for i, q in enumerate(qs):
        k = np.minimum((cdf < q - 1e-12).sum(axis=0), n - 1)
        out[i] = np.take_along_axis(vs, k[None, :], axis=0)[0]
    return out


def at_least_one(p, n_operations: float) -> tuple[np.ndarray, np.ndarray]:
    """P(at least one exceedance in N operations): exact binomial 1 - (1-p)^N and Poisson
    1 - exp(-N p)."""
    p = np.clip(np.asarray(p, float), 0.0, 1.0)
    return -np.expm1(n_operations * np.log1p(-np.minimum(p, 1 - 1e-16))) * (p < 1) + (p >= 1), -np.expm1(-n_operations * p)


def sobol_first_order(y_a: np.ndarray, y_c: dict) -> dict:
    """Janon's first-order indices per input group (see the module notes): ``y_a`` (n, M),
    ``y_c`` group -> (n, M); NaN where Y does not vary."""
    out = {}
    for name, yc in y_c.items():
        mean = ((y_a + yc) / 2).mean(axis=0)
        num = (y_a * yc).mean(axis=0) - mean**2
        den = ((y_a**2 + yc**2) / 2).mean(axis=0) - mean**2
        scale = ((y_a**2 + yc**2) / 2).mean(axis=0)
        with np.errstate(divide="ignore", invalid="ignore"):  # Y (nearly) constant: nothing to apportion
            out[name] = np.where(den > 1e-12 * scale + 1e-300, num / den, np.nan)
    return out
