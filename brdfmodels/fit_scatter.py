"""Fit an ABg scatter lobe to measured BRDF samples (nlopt), with parameter uncertainties.

The objective is the weighted RMS of the log ratio ``ln f_model - ln f_data`` (scatter
data span decades: a log fit weighs the wings like the peak). The search runs in
``(ln A, ln B, g)`` inside ``ABG_BOUNDS``: a global nlopt stage (CRS2 by default), then a
BOBYQA polish. Uncertainties of (A, B, g) come from the Jacobian of the log residuals at
the optimum (:mod:`brdfmodels.uncertainty`).
"""

from __future__ import annotations

import math
import time

import numpy as np

from .fitting import TS5_METHODS, TS5_POLISH_MAXEVAL, FitResult, check_nlopt_data, nlopt_stage
from .scatter import ABg, direction_cosine_offset
from .uncertainty import jacobian_uncertainty

__all__ = ["fit_abg", "ABG_BOUNDS"]

ABG_BOUNDS = {"a": (1e-10, 1e6), "b": (1e-12, 1e4), "g": (0.0, 6.0)}  # search box (A and B searched in log)


def fit_abg(wi, wo, brdf_per_sr, *, method="crs2", seed=0, maxeval=4000, weights=None, xtol_rel=1e-12) -> FitResult:
    """Fit ``A / (B + |beta - beta0|^g)`` (:class:`brdfmodels.ABg`) to samples.

    Parameters
    ----------
    wi, wo : array_like (N, 3)
        Directions to the source and to the observer (surface frame).
    brdf_per_sr : array_like (N,)
        Measured BRDF [1/sr], > 0.
    method : str
        Global nlopt stage, one of ``TS5_METHODS`` (crs2, esch, isres, direct-l, mlsl).
    seed, maxeval : int
        nlopt's seed and the global stage's budget.
    weights : array_like (N,), optional
        Sample weights (default 1).

    Returns
    -------
    FitResult
        ``details``: the parameters (``p_a``, ``p_b``, ``p_g``), their standard errors
        (``stderr_a`` ...) and ``uncertainty`` (:meth:`Uncertainty.to_dict`).
    """
    import nlopt

    start = time.perf_counter()
    wi, wo, f, w = check_nlopt_data(wi, wo, brdf_per_sr, weights, 3, method, "have no logarithm")
    xd = direction_cosine_offset(wi, wo)
    lf, sw = np.log(f), np.sqrt(w / w.sum())
    count = [0]

    def residuals(p):  # natural parameters (A, B, g)
        a, b, g = p
        return sw * (math.log(max(a, 1e-300)) - np.log(b + (np.ones_like(xd) if g == 0 else xd ** g)) - lf)

    def fun(x, grad):
        count[0] += 1
        r = residuals((math.exp(x[0]), math.exp(x[1]), x[2]))
        return float(r @ r)

    lo = np.array([math.log(ABG_BOUNDS["a"][0]), math.log(ABG_BOUNDS["b"][0]), ABG_BOUNDS["g"][0]])
    hi = np.array([math.log(ABG_BOUNDS["a"][1]), math.log(ABG_BOUNDS["b"][1]), ABG_BOUNDS["g"][1]])
    nlopt.srand(int(seed))
    x = nlopt_stage(TS5_METHODS[method], lo, hi, fun, 0.5 * (lo + hi), maxeval)
    x = nlopt_stage("LN_BOBYQA", lo, hi, fun, x, TS5_POLISH_MAXEVAL, xtol_rel)
    p = np.array([math.exp(x[0]), math.exp(x[1]), x[2]])
    model = ABg(*p)
    unc = jacobian_uncertainty(residuals, p, ("a", "b", "g"))
    rms = float(np.sqrt(np.sum(residuals(p) ** 2)))
    rel = float(np.sqrt(np.mean(((model.evaluate(wi, wo) - f) / f) ** 2)))
    details = {**{f"p_{k}": float(v) for k, v in zip(("a", "b", "g"), p)},
               **{f"stderr_{k}": float(s) for k, s in zip(("a", "b", "g"), unc.stderr)},
               "uncertainty": unc.to_dict(), "at_bound": [k for k, v, l, h in zip("abg", x, lo, hi) if v <= l + 1e-9 or v >= h - 1e-9]}
    return FitResult(model, rms, rel, unc.condition_number, 0, len(f), 3, count[0], time.perf_counter() - start,
                     f"nlopt {method} + bobyqa (log residuals)", details)
