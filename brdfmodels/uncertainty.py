"""Parameter uncertainties of a nonlinear least-squares fit from the Jacobian at the
optimum, as lmfit reports them (its ``scale_covar=True`` convention):

    cov = s^2 (J^T J)^-1,   s^2 = sum(r^2) / (n - k),   stderr_j = sqrt(cov_jj)

with r the (weighted) residuals at the optimum, n of them, k parameters, and J = dr/dp
by central differences (step 1e-6 of each parameter, or 1e-9 absolute at 0). The
intervals are first-order (linearised about the optimum): good when the residuals are
small against the curvature of the model, optimistic for strongly nonlinear directions;
the condition number of J^T J is reported beside them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

__all__ = ["Uncertainty", "jacobian_uncertainty"]


@dataclass(frozen=True)
class Uncertainty:
    """Standard errors, covariance and correlation of fitted parameters (by name)."""

    names: tuple
    values: np.ndarray
    stderr: np.ndarray
    covariance: np.ndarray
    condition_number: float
    dof: int

    def correlation(self) -> np.ndarray:
        d = np.sqrt(np.diag(self.covariance))
        with np.errstate(invalid="ignore", divide="ignore"):
            return self.covariance / np.outer(d, d)

    def to_dict(self) -> dict:
        return {"stderr": {n: float(s) for n, s in zip(self.names, self.stderr)},
                "correlation": self.correlation().round(6).tolist(), "condition_number": self.condition_number,
                "degrees_of_freedom": self.dof, "method": "cov = s^2 (J^T J)^-1 at the optimum (lmfit's scale_covar)"}


def jacobian_uncertainty(residuals, values, names) -> Uncertainty:
    """:class:`Uncertainty` of ``values`` (k,) for ``residuals(p) -> (n,)`` (see the
    module notes). Parameters the data do not determine (a singular J^T J) get inf."""
    p = np.asarray(values, float)
    r0 = np.asarray(residuals(p), float)
    n, k = len(r0), len(p)
    jac = np.empty((n, k))
    for j in range(k):
        h = 1e-6 * abs(p[j]) if p[j] != 0 else 1e-9
        up, dn = p.copy(), p.copy()
        up[j] += h
        dn[j] -= h
        jac[:, j] = (np.asarray(residuals(up)) - np.asarray(residuals(dn))) / (2 * h)
    jtj = jac.T @ jac
    dof = max(n - k, 1)
    s2 = float(r0 @ r0) / dof
    cond = float(np.linalg.cond(jtj)) if np.all(np.isfinite(jtj)) else math.inf
    if not math.isfinite(cond) or cond > 1e15:
        cov = np.full((k, k), np.inf)
    else:
        cov = s2 * np.linalg.inv(jtj)
    return Uncertainty(tuple(names), p, np.sqrt(np.maximum(np.diag(cov), 0.0)), cov, cond, dof)
