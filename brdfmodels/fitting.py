"""Fitting BRDF models and histories to measurements.

* :func:`fit_sh` - spherical-harmonic fit of ln f~ (or f~) by truncated SVD, with the
  paper's horizon tacking (Bailey et al. 2008, Sec. IV F; spec `dynamic-sh-brdf.md` 8).
* :func:`fit_dynamic_sh` - one fit per state group -> :class:`DynamicBRDF`.
* :func:`envelope_paper`, :func:`envelope_sh` - conservative envelopes that bound every
  measured sample (the paper's base/multiplier/fan-out recipe with its parameters chosen
  automatically; and a compact one-coefficient-set SH envelope from a linear program).
* :func:`fit_ts5` - five-parameter model by a global nlopt stage and a local polish.
* :func:`fit_oxidation` - Wagner/Arrhenius oxidation law from a reflectance series.

Fits return result dataclasses (model, residuals, conditioning, evaluations, time); they
never mutate a model.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np

from ._checks import directions, finite_array, finite_scalar
from .geometry import spherical_to_vector
from .history import OxidationModel
from .models import DynamicBRDF, Envelope, SphericalHarmonicBRDF, TorranceSparrow5
from .sh import SHBasis

__all__ = [
    "FitResult",
    "fit_sh",
    "fit_dynamic_sh",
    "DynamicFitResult",
    "envelope_paper",
    "envelope_sh",
    "EnvelopeFit",
    "fit_ts5",
    "TS5_METHODS",
    "compare_ts5_methods",
    "fit_oxidation",
    "OxidationFit",
    "DEFAULT_RCOND",
    "DEFAULT_HORIZON_WEIGHT",
]

# Defaults chosen by held-out prediction error on the paper's validation protocol
# (brdfmodels.validation.select_fit_defaults; table in docs/fit-defaults.md), not by
# training residual.
DEFAULT_RCOND = 1e-2
DEFAULT_HORIZON_WEIGHT = 0.01
# The horizon "zero" of a log fit: f~ = cos(theta_i) cos(theta_r) f_r vanishes at the
# horizon through cos(theta_r) itself, so the rows at theta_r = 89.5 deg take
# f~ = cos_i cos_r * (smallest measured f_r). A fixed fraction of the smallest f~ instead
# (tried: 1e-3) dragged the unmeasured hemisphere 1000x below a diffuse truth.


@dataclass(frozen=True)
class FitResult:
    """Outcome of a fit.

    Attributes
    ----------
    model : BRDFModel
    residual_rms : float
        RMS residual in the fitted space (ln f~ for log fits), data rows only.
    relative_rms : float
        sqrt(mean(((f_model - f_data) / f_data)^2)) over the data (the paper's error E).
    condition_number : float
        Of the (weighted) design matrix, before pruning (SH fits).
    pruned_modes : int
        Singular modes dropped by the truncated SVD.
    samples, coefficients : int
    evaluations : int
        Objective evaluations (iterative fits).
    fit_time_s : float
    method : str
    details : dict
    """

    model: object
    residual_rms: float
    relative_rms: float
    condition_number: float
    pruned_modes: int
    samples: int
    coefficients: int
    evaluations: int
    fit_time_s: float
    method: str
    details: dict = field(default_factory=dict)

    def summary(self) -> dict:
        return {
            "model": self.model.name,
            "method": self.method,
            "samples": self.samples,
            "coefficients": self.coefficients,
            "residual_rms": self.residual_rms,
            "relative_rms": self.relative_rms,
            "condition_number": self.condition_number,
            "pruned_modes": self.pruned_modes,
            "evaluations": self.evaluations,
            "fit_time_s": self.fit_time_s,
            **{k: v for k, v in self.details.items() if isinstance(v, (int, float, str))},
        }


def check_fit_data(wi, wo, brdf, weights):
    """Checked fit samples: (wi (N, 3), wo (N, 3), f_r [1/sr] (N,), weights (N,)); ValueError
    naming the field on non-finite values, mismatched lengths, negative weights or directions
    at or below the horizon. ``weights`` None: all 1."""
    wi = directions("wi", wi).reshape(-1, 3)
    wo = directions("wo", wo).reshape(-1, 3)
    f = finite_array("brdf_per_sr", brdf).ravel()
    if not (len(wi) == len(wo) == len(f)):
        raise ValueError(f"wi, wo and brdf_per_sr: expected the same number of samples, got {len(wi)}, {len(wo)}, {len(f)}")
    if weights is None:
        w = np.ones(len(f))
    else:
        w = finite_array("weights", weights, minimum=0.0).ravel()
        if w.shape != f.shape:
            raise ValueError(f"weights: expected {len(f)} values, got {w.size}")
    above = (wi[:, 2] > 0) & (wo[:, 2] > 0)
    if not np.all(above):
        raise ValueError(f"wi/wo: {int((~above).sum())} samples at or below the horizon; expected directions above the surface")
    return wi, wo, f, w


def check_nlopt_data(wi, wo, brdf, weights, n_params: int, method: str, nonpositive: str):
    """:func:`check_fit_data` for a parametric nlopt fit (TS5, ABg): positive values (what a
    value <= 0 cannot do: ``nonpositive``), at least ``n_params`` samples, a known global
    ``method``."""
    wi, wo, f, w = check_fit_data(wi, wo, brdf, weights)
    if np.any(f <= 0):
        raise ValueError(f"brdf_per_sr: values <= 0 {nonpositive}; mask them first")
    if len(f) < n_params:
        raise ValueError(f"underdetermined fit: {len(f)} samples for {n_params} parameters")
    if method not in TS5_METHODS:
        raise ValueError(f"method={method!r}: expected one of {sorted(TS5_METHODS)}")
    return wi, wo, f, w


def horizon_directions(n_incidence=6, n_azimuth=24, theta_deg=89.5):
    """Direction pairs on the observer's horizon used to tack a fit down (spec section 8)."""
    ti = np.radians(np.linspace(0, 80, n_incidence))
    pi = np.linspace(-np.pi, np.pi, 8, endpoint=False)
    po = np.linspace(-np.pi, np.pi, n_azimuth, endpoint=False)
    tt, pp, oo = np.meshgrid(ti, pi, po, indexing="ij")
    wi = spherical_to_vector(tt.ravel(), pp.ravel())
    wo = spherical_to_vector(np.full(oo.size, math.radians(theta_deg)), oo.ravel())
    return wi, wo


def _design(basis, wi, wo, fanout):
    return basis.evaluate_directions(wi, wo, fanout=fanout)


def _hemisphere_grid(n_theta=12, n_phi=24):
    """Direction pairs spread over the hemisphere (for constraints where nothing was measured)."""
    t = np.radians(np.linspace(2.0, 86.0, n_theta))
    p = np.linspace(-np.pi, np.pi, n_phi, endpoint=False)
    tt, pp = np.meshgrid(t, p, indexing="ij")
    dirs = spherical_to_vector(tt.ravel(), pp.ravel())
    wi = np.repeat(dirs[:: max(1, len(dirs) // 24)], len(dirs), axis=0)
    wo = np.tile(dirs, (len(dirs[:: max(1, len(dirs) // 24)]), 1))
    return wi, wo


def default_rcond(smoothing) -> float:
    """rcond of a fit when none is given: ``DEFAULT_RCOND`` without smoothing, 0 with it."""
    return DEFAULT_RCOND if smoothing == 0 else 0.0


def smoothing_rows(basis: SHBasis, smoothing, power, n_data):
    """Tikhonov rows of a smoothness (Laplace-Beltrami) penalty on SH coefficients.

    Parameters
    ----------
    basis : SHBasis
    smoothing : float
        Strength alpha >= 0, relative to the data: the penalty is
        ``alpha * n_data * sum_k (l_k (l_k + 1))^power c_k^2``.
    power : float
        1: the gradient energy of the fitted function on the (fanned-out) sphere; 2: the
        squared Laplacian. Product columns take l_h (l_h + 1) + l_d (l_d + 1).
    n_data : float
        Sum of the data rows' (normalised) weights.

    Returns
    -------
    ndarray, shape (K, K)
        Diagonal rows ``sqrt(alpha n_data (l(l+1))^power)`` to stack under the weighted
        design matrix (right-hand side 0).
    """
    eig = np.array([c[1] * (c[1] + 1) if c[0] != "hd" else c[1] * (c[1] + 1) + c[3] * (c[3] + 1) for c in basis.columns], float)
    return np.diag(np.sqrt(smoothing * n_data * eig ** power))


def fit_sh(wi, wo, brdf_per_sr, basis: SHBasis, *, fanout=0.6, log=True, weights=None, horizon=True,
           horizon_weight=None, rcond=None, method="tsvd", smoothing=0.0, smoothing_power=2.0) -> FitResult:
    """Least-squares spherical-harmonic fit (truncated SVD) of measured f_r.

    Parameters
    ----------
    wi, wo : array_like, shape (N, 3)
        Sample directions in the surface frame.
    brdf_per_sr : array_like, shape (N,)
        Measured f_r [1/sr] (> 0 for a log fit: mask empty pixels before fitting).
    basis : SHBasis
    fanout : float
        Fan-out exponent s_e (Eq. 34).
    log : bool
        Fit ln f~ (separable logarithmic form) rather than f~.
    weights : array_like, optional
        Per-sample weights (relative; normalised to mean 1).
    horizon : bool
        Tack the BRDF to "zero" at the horizon: extra rows at theta_r = 89.5 deg with
        f~ = cos_i cos_r min(f_r) (log; f~ vanishes there through cos_r) or 0 (linear).
    horizon_weight : float
        Total weight of the horizon rows as a fraction of the data's
        (default ``DEFAULT_HORIZON_WEIGHT``).
    rcond : float
        Singular values below ``rcond * s_max`` are pruned (default ``DEFAULT_RCOND``
        without smoothing, 0 with it: the penalty regularises, and pruning relative to
        the penalty rows' largest singular value would drop data modes).
    smoothing : float
        Tikhonov strength alpha (0: none) of a smoothness penalty on the coefficients,
        ``alpha N sum_k (l_k (l_k + 1))^p c_k^2`` (N data rows; :func:`smoothing_rows`):
        where nothing was measured the fit continues as smoothly as the data allow.
    smoothing_power : float
        p of the penalty (2: squared Laplace-Beltrami operator, 1: gradient energy).
    method : {"tsvd", "constrained"}
        Truncated SVD, or constrained least squares: the same weighted problem subject to
        the fitted ln f~ staying at or below the largest measured value over a grid of
        the whole hemisphere (no lobe taller than anything measured where nothing was
        measured); solved with SLSQP from the SVD solution.

    Raises
    ------
    ValueError
        Underdetermined data (fewer samples than coefficients), non-positive values in a
        log fit, directions below the horizon.
    """
    start = time.perf_counter()
    wi, wo, f, w = check_fit_data(wi, wo, brdf_per_sr, weights)
    k = basis.size
    if len(f) < k:
        raise ValueError(f"underdetermined fit: {len(f)} samples for {k} coefficients; give at least {k} samples or a smaller basis")
    smoothing = finite_scalar("smoothing", smoothing, minimum=0.0)
    smoothing_power = finite_scalar("smoothing_power", smoothing_power, minimum=0.0)
    rcond = default_rcond(smoothing) if rcond is None else finite_scalar("rcond", rcond, minimum=0.0, maximum=1.0)
    hw = DEFAULT_HORIZON_WEIGHT if horizon_weight is None else finite_scalar("horizon_weight", horizon_weight, minimum=0.0)
    ft = wi[:, 2] * wo[:, 2] * f  # f~ (Eq. 17)
    if log:
        if np.any(f <= 0):
            raise ValueError(f"brdf_per_sr: {int((f <= 0).sum())} values <= 0 cannot enter a log fit; mask them first")
        y = np.log(ft)
    else:
        y = ft
    a = _design(basis, wi, wo, fanout)
    w = w / w.mean()
    rows_a, rows_y, rows_w = [a], [y], [w]
    floor = None
    if horizon and hw > 0:
        hwi, hwo = horizon_directions()
        floor = float(f.min())
        rows_a.append(_design(basis, hwi, hwo, fanout))
        rows_y.append(np.log(hwi[:, 2] * hwo[:, 2] * floor) if log else np.zeros(len(hwi)))
        rows_w.append(np.full(len(hwi), hw * len(f) / len(hwi)))
    big_a = np.vstack(rows_a)
    big_y = np.concatenate(rows_y)
    sw = np.sqrt(np.concatenate(rows_w))
    b_mat, z = big_a * sw[:, None], big_y * sw
    if smoothing > 0:
        b_mat = np.vstack([b_mat, smoothing_rows(basis, smoothing, smoothing_power, len(f))])
        z = np.concatenate([z, np.zeros(k)])
    u, s, vt = np.linalg.svd(b_mat, full_matrices=False)
    keep = s > rcond * s[0]
    coef = vt[keep].T @ ((u[:, keep].T @ z) / s[keep])
    if method not in ("tsvd", "constrained"):
        raise ValueError(f"method={method!r}: expected 'tsvd' or 'constrained'")
    n_active = 0
    if method == "constrained":
        from scipy.optimize import minimize

        gwi, gwo = _hemisphere_grid()
        g = _design(basis, gwi, gwo, fanout)
        cap = float(y.max()) if log else float(ft.max())
        # the cap applies to ln f~ (or f~); grid pairs carry their own cos factors already
        scale = float(np.sum(z * z)) or 1.0
        res = minimize(lambda c: 0.5 * float(np.sum((b_mat @ c - z) ** 2)) / scale, coef,
                       jac=lambda c: (b_mat.T @ (b_mat @ c - z)) / scale, method="SLSQP",
                       constraints=[{"type": "ineq", "fun": lambda c: cap - g @ c, "jac": lambda c: -g}],
                       options={"maxiter": 500, "ftol": 1e-12})
        if not res.success:
            raise ValueError(f"constrained fit did not converge ({res.message}); use method='tsvd'")
        coef = res.x
        n_active = int(np.sum(g @ coef > cap - 1e-6))
    model = SphericalHarmonicBRDF(basis, coef, fanout=fanout, log=log)
    pred = a @ coef
    res = pred - y
    f_model = np.exp(pred) / (wi[:, 2] * wo[:, 2]) if log else np.maximum(pred, 0) / (wi[:, 2] * wo[:, 2])
    return FitResult(
        model=model,
        residual_rms=float(np.sqrt(np.mean(res**2))),
        relative_rms=float(np.sqrt(np.mean(((f_model - f) / f) ** 2))),
        condition_number=float(s[0] / s[-1]) if s[-1] > 0 else math.inf,
        pruned_modes=int((~keep).sum()),
        samples=len(f),
        coefficients=k,
        evaluations=1,
        fit_time_s=time.perf_counter() - start,
        method="truncated SVD" if method == "tsvd" else "constrained least squares (SLSQP)",
        details={"active_constraints": n_active, "rcond": rcond, "horizon_weight": hw if horizon else 0.0, "horizon_floor_per_sr": floor or 0.0, "log": log, "fanout": fanout,
                 "smoothing": smoothing, "smoothing_power": smoothing_power},
    )


@dataclass(frozen=True)
class DynamicFitResult:
    """Outcome of :func:`fit_dynamic_sh`.

    Attributes
    ----------
    model : DynamicBRDF
    fits : dict
        State node -> :class:`FitResult` of its group (for two states the key is the
        pair ``(s1, s2)``).
    fit_time_s : float
    """

    model: DynamicBRDF
    fits: dict  # state (or state pair) -> FitResult
    fit_time_s: float


def fit_dynamic_sh(samples, basis: SHBasis, states, *, state="temperature_k", fanout=0.6, log=True, extrapolation="error",
                   progress=None, **kwargs) -> DynamicFitResult:
    """One SH fit per state group -> a :class:`DynamicBRDF` (paper Sec. IV H: one
    coefficient set per tabulated state, interpolated linearly per coefficient).

    Parameters
    ----------
    samples : brdfmodels.screen.Samples
        The measured table; each state group needs enough samples for the basis.
    basis : SHBasis
    states : array_like (T,), or [nodes_1 (n1,), nodes_2 (n2,)]
        The state nodes (in the state's unit); each sample joins its nearest node (per
        axis for two states, :func:`brdfmodels.screen.group_by_states`).
    state : str or [str, str]
        The state column: ``"temperature_k"``, ``"time_s"`` or a named column of
        ``samples.states``; two names (e.g. ``["extinction", "melt_fraction"]``) fit a
        two-state model with coefficients (n1, n2, K), bilinear between the nodes.
    fanout, log, extrapolation
        As :class:`DynamicBRDF`.
    progress : callable, optional
        Called with (states fitted, states) after each fit.
    **kwargs
        Passed to :func:`fit_sh`.

    Raises
    ------
    ValueError
        A node (or grid node) without samples, listing them; a group that cannot be fitted.
    """
    if not isinstance(state, str):
        return _fit_dynamic_sh_2(samples, basis, states, state, fanout=fanout, log=log, extrapolation=extrapolation,
                                 progress=progress, **kwargs)
    from .screen import group_by_state

    start = time.perf_counter()
    groups = group_by_state(samples, state, states)
    missing = [float(s) for s in np.asarray(states, float) if float(s) not in groups]
    if missing:
        raise ValueError(f"states {missing}: no samples near them; expected samples for every state")
    fits = _fit_groups(groups, basis, state, fanout, log, progress, kwargs)
    nodes = np.array(sorted(fits))
    coef = np.array([fits[s].model.coefficients for s in nodes])
    model = DynamicBRDF(basis, nodes, coef, state, fanout=fanout, log=log, extrapolation=extrapolation)
    return DynamicFitResult(model, fits, time.perf_counter() - start)


def _fit_groups(groups: dict, basis, state, fanout, log, progress, kwargs) -> dict:
    """:func:`fit_sh` of every group (node -> Samples), in sorted node order."""
    fits = {}
    for s_val, g in sorted(groups.items()):
        try:
            fits[s_val] = fit_sh(g.wi, g.wo, g.brdf_per_sr, basis, fanout=fanout, log=log, weights=g.weight, **kwargs)
        except ValueError as exc:
            where = f"{state}={s_val:g}" if isinstance(state, str) else ", ".join(f"{n}={v:g}" for n, v in zip(state, s_val))
            raise ValueError(f"state {where}: {exc}") from None
        if progress is not None:
            progress(len(fits), len(groups))
    return fits


def _fit_dynamic_sh_2(samples, basis, states, names, *, fanout, log, extrapolation, progress, **kwargs) -> DynamicFitResult:
    """The two-state branch of :func:`fit_dynamic_sh`: one fit per grid node (s1, s2)."""
    from .screen import group_by_states
    from .states import state_axes, state_names

    start = time.perf_counter()
    names = list(state_names(names, "state"))
    axes = state_axes(states, tuple(names))
    groups = group_by_states(samples, names, axes)
    missing = [(float(a), float(b)) for a in axes[0] for b in axes[1] if (float(a), float(b)) not in groups]
    if missing:
        raise ValueError(f"state nodes ({names[0]}, {names[1]}) {missing}: no samples near them; "
                         f"expected samples for every node of the {axes[0].size} x {axes[1].size} grid")
    fits = _fit_groups(groups, basis, names, fanout, log, progress, kwargs)
    coef = np.array([[fits[(float(a), float(b))].model.coefficients for b in axes[1]] for a in axes[0]])
    model = DynamicBRDF(basis, [axes[0], axes[1]], coef, names, fanout=fanout, log=log, extrapolation=extrapolation)
    return DynamicFitResult(model, fits, time.perf_counter() - start)


@dataclass(frozen=True)
class EnvelopeFit:
    """A conservative envelope with its check against the measured samples."""

    model: object
    fraction_bounded: float
    median_overprediction: float
    max_overprediction: float
    method: str
    details: dict = field(default_factory=dict)

    def summary(self) -> dict:
        return {"method": self.method, "fraction_bounded": self.fraction_bounded,
                "median_overprediction": self.median_overprediction, "max_overprediction": self.max_overprediction, **self.details}


def _bound_report(env_values, data):
    ratio = env_values / data
    return float(np.mean(env_values >= data * (1 - 1e-12))), float(np.median(ratio)), float(ratio.max())


def envelope_paper(model, samples, *, fanout_h_candidates=None) -> EnvelopeFit:
    """The paper's envelope recipe with its parameters chosen automatically.

    For each candidate halfway fan-out (the fit's and smaller ones), the multiplier is the
    smallest that makes ``Envelope(model, multiplier=m, fanout_h=s)`` bound every measured
    sample (all states); the candidate with the smallest median over-prediction wins.
    The base stays 0 (a log-SH envelope is never 0, so the multiplier alone suffices).
    """
    fan = getattr(model, "fanout", 0.6)
    cands = fanout_h_candidates if fanout_h_candidates is not None else [None, 0.9 * fan, 0.75 * fan, 0.6 * fan]
    best = None
    for fh in cands:
        env0 = Envelope(model, fanout_h=fh)
        e = env0.evaluate(samples.wi, samples.wo)
        mult = max(1.0, float(np.max(samples.brdf_per_sr / e)) * (1 + 1e-9))
        env = Envelope(model, multiplier=mult, fanout_h=fh)
        frac, med, mx = _bound_report(env.evaluate(samples.wi, samples.wo), samples.brdf_per_sr)
        if best is None or med < best[0]:
            best = (med, EnvelopeFit(env, frac, med, mx, "paper recipe (multiplier, halfway fan-out)",
                                     {"multiplier": mult, "fanout_h": fh if fh is not None else fan, "base": 0.0}))
    return best[1]


def envelope_sh(samples, basis: SHBasis, *, fanout=0.6, horizon=True) -> EnvelopeFit:
    """Compact conservative SH envelope: one log-coefficient set c with
    ``ln f~_env >= ln f~_data`` at every sample (all states), minimising the summed log
    over-prediction - a linear program (SciPy HiGHS). Horizon rows are capped at the data
    maximum so the unconstrained parts cannot grow without bound.
    """
    from scipy.optimize import linprog

    wi, wo, f, _ = check_fit_data(samples.wi, samples.wo, samples.brdf_per_sr, None)
    if np.any(f <= 0):
        raise ValueError("brdf_per_sr: values <= 0 cannot bound a log envelope; mask them first")
    y = np.log(wi[:, 2] * wo[:, 2] * f)
    a = _design(basis, wi, wo, fanout)
    a_ub, b_ub = [-a], [-y]
    if horizon:
        hwi, hwo = horizon_directions()
        a_ub.append(_design(basis, hwi, hwo, fanout))
        b_ub.append(np.full(len(hwi), y.max()))
    # Bound the coefficients relative to a least-squares fit: directions the samples do not
    # constrain otherwise let the LP return huge, nearly cancelling coefficients whose
    # evaluation is not reproducible to the margin below.
    ls = fit_sh(wi, wo, f, basis, fanout=fanout).model.coefficients
    cap = 10.0 * float(np.max(np.abs(ls))) + 10.0
    res = linprog(a.sum(axis=0), A_ub=np.vstack(a_ub), b_ub=np.concatenate(b_ub), bounds=[(-cap, cap)] * basis.size, method="highs")
    if not res.success:
        raise ValueError(f"envelope_sh: the linear program failed ({res.message}); use a larger basis or envelope_paper")
    coef = res.x.copy()
    # the solver meets constraints to its tolerance (~1e-7 in ln f~): lift the constant
    # term by the largest violation plus a margin for rounding at the coefficients' scale,
    # so every sample is bounded whatever order the sum is evaluated in
    margin = 1e-12 * (1.0 + float(np.abs(coef).sum()) * 4.0)
    violation = max(float(np.max(y - a @ coef)), 0.0)
    coef[0] += (violation + margin) * math.sqrt(4.0 * math.pi)  # column 0 is y_0^0 = 1/sqrt(4 pi)
    model = SphericalHarmonicBRDF(basis, coef, fanout=fanout, log=True)
    frac, med, mx = _bound_report(model.evaluate(wi, wo), f)
    return EnvelopeFit(model, frac, med, mx, "compact SH envelope (linear program)", {"coefficients": basis.size})


# -- five-parameter model ---------------------------------------------------------------------
TS5_BOUNDS = {  # search box of the global stage (transformed: log for positive parameters)
    "kb": (1e-4, 100.0),
    "kr": (0.05, 50.0),
    "a": (0.05, 30.0),
    "b": (-100.0, 10.0),
    "kd": (1e-4, 10.0),
}
TS5_METHODS = {
    "esch": "GN_ESCH",
    "crs2": "GN_CRS2_LM",
    "isres": "GN_ISRES",
    "direct-l": "GN_DIRECT_L",
    "mlsl": "G_MLSL_LDS",
}


def _ts5_params(x):
    return dict(kb=math.exp(x[0]), kr=math.exp(x[1]), a=math.exp(x[2]), b=x[3], kd=math.exp(x[4]))


def _ts5_objective(wi, wo, f, w):
    def obj(x):
        m = TorranceSparrow5(**_ts5_params(x))
        rel = (m.evaluate(wi, wo) - f) / f
        return float(np.sqrt(np.sum(w * rel * rel) / np.sum(w)))

    return obj


TS5_POLISH_MAXEVAL = 20000  # budget of the local polish after the global stage
PROGRESS_EVERY = 100  # objective evaluations between two progress calls of fit_ts5


def nlopt_stage(algorithm: str, lo, hi, fun, x0, maxeval, xtol_rel=None) -> np.ndarray:
    """One bounded nlopt minimisation of ``fun(x, grad)`` from ``x0``: ``algorithm`` an
    nlopt name (``G_MLSL_LDS`` gets a BOBYQA local optimiser at xtol 1e-6), at most
    ``maxeval`` evaluations, and ``xtol_rel`` when given. Returns x (``x0`` when nlopt
    stops on round-off before it moves)."""
    import nlopt

    n = len(lo)
    opt = nlopt.opt(getattr(nlopt, algorithm), n)
    if algorithm == "G_MLSL_LDS":
        loc = nlopt.opt(nlopt.LN_BOBYQA, n)
        loc.set_xtol_rel(1e-6)
        opt.set_local_optimizer(loc)
    opt.set_lower_bounds(lo)
    opt.set_upper_bounds(hi)
    opt.set_min_objective(fun)
    opt.set_maxeval(int(maxeval))
    if xtol_rel is not None:
        opt.set_xtol_rel(xtol_rel)
    try:
        return np.array(opt.optimize(x0))
    except nlopt.RoundoffLimited:
        return np.array(x0, float)


def fit_ts5(wi, wo, brdf_per_sr, *, method="crs2", seed=0, maxeval=20000, local="bobyqa", weights=None, xtol_rel=1e-10,
            progress=None) -> FitResult:
    """Fit the five-parameter model: a global nlopt stage, then a local polish.

    The objective is the paper's relative RMS error E (Zhang et al. 2010 report E per
    fit; its definition is not in the text - this one is stated in the spec). Parameters
    are searched in transformed space (log kb, log kr, log a, b, log kd) inside
    ``TS5_BOUNDS``.

    Parameters
    ----------
    method : str
        Global algorithm: one of ``TS5_METHODS`` ("esch" is the evolutionary method
        nearest to the paper's GA). The default comes from :func:`compare_ts5_methods`.
    seed : int
        nlopt's random seed (results are reproducible).
    maxeval : int
        Budget of the global stage.
    local : {"bobyqa", "neldermead"}
        Local polish (nlopt LN_BOBYQA / LN_NELDERMEAD).
    progress : callable, optional
        Called with (evaluations, budget) every ``PROGRESS_EVERY`` objective evaluations
        and at the end; budget = ``maxeval`` + ``TS5_POLISH_MAXEVAL`` (the polish usually
        stops well short of its share).
    """
    import nlopt

    start = time.perf_counter()
    wi, wo, f, w = check_nlopt_data(wi, wo, brdf_per_sr, weights, 5, method, "cannot enter the relative error")
    if local not in ("bobyqa", "neldermead"):
        raise ValueError(f"local={local!r}: expected 'bobyqa' or 'neldermead'")
    obj = _ts5_objective(wi, wo, f, w)
    count = [0]
    budget = int(maxeval) + TS5_POLISH_MAXEVAL

    def fun(x, grad):
        count[0] += 1
        if progress is not None and count[0] % PROGRESS_EVERY == 0:
            progress(min(count[0], budget), budget)
        return obj(x)

    lo = np.array([math.log(TS5_BOUNDS["kb"][0]), math.log(TS5_BOUNDS["kr"][0]), math.log(TS5_BOUNDS["a"][0]), TS5_BOUNDS["b"][0], math.log(TS5_BOUNDS["kd"][0])])
    hi = np.array([math.log(TS5_BOUNDS["kb"][1]), math.log(TS5_BOUNDS["kr"][1]), math.log(TS5_BOUNDS["a"][1]), TS5_BOUNDS["b"][1], math.log(TS5_BOUNDS["kd"][1])])
    nlopt.srand(int(seed))
    x_global = nlopt_stage(TS5_METHODS[method], lo, hi, fun, 0.5 * (lo + hi), maxeval)
    e_global, ev_global = obj(x_global), count[0]
    x = nlopt_stage("LN_BOBYQA" if local == "bobyqa" else "LN_NELDERMEAD", lo, hi, fun, x_global, TS5_POLISH_MAXEVAL, xtol_rel)
    e = obj(x)
    if progress is not None:
        progress(budget, budget)
    model = TorranceSparrow5(**_ts5_params(x))
    unc = _ts5_uncertainty(wi, wo, f, w, _ts5_params(x))
    return FitResult(model, e, e, math.nan, 0, len(f), 5, count[0], time.perf_counter() - start, f"nlopt {method} + {local}",
                     {"global_error": e_global, "global_evaluations": ev_global, **{f"p_{k}": v for k, v in _ts5_params(x).items()},
                      **{f"stderr_{k}": float(v) for k, v in zip(unc.names, unc.stderr)}, "uncertainty": unc.to_dict()})


def _ts5_uncertainty(wi, wo, f, w, params):
    """Standard errors of (kb, kr, a, b, kd) from the Jacobian of the relative residuals
    (the objective's) at the optimum (:mod:`brdfmodels.uncertainty`)."""
    from .uncertainty import jacobian_uncertainty

    names = ("kb", "kr", "a", "b", "kd")
    sw = np.sqrt(w / w.sum())

    def residuals(p):
        q = dict(zip(names, p))
        q = {k: (max(v, 1e-300) if k != "b" else v) for k, v in q.items()}
        return sw * (TorranceSparrow5(**q).evaluate(wi, wo) - f) / f

    return jacobian_uncertainty(residuals, [params[k] for k in names], names)


def compare_ts5_methods(wi, wo, brdf_per_sr, *, budgets=(2000, 8000), seeds=(0, 1, 2), methods=None, progress=None) -> list:
    """Error reached vs evaluations vs seconds for each global algorithm (+ polish).

    ``progress``, if given, is called with (fits done, fits) after each fit.
    """
    rows = []
    methods = list(methods or sorted(TS5_METHODS))
    total, done = len(methods) * len(budgets) * len(seeds), 0
    for method in methods:
        for budget in budgets:
            errs, evals, secs = [], [], []
            for seed in seeds:
                r = fit_ts5(wi, wo, brdf_per_sr, method=method, seed=seed, maxeval=budget)
                errs.append(r.relative_rms)
                evals.append(r.evaluations)
                secs.append(r.fit_time_s)
                done += 1
                if progress is not None:
                    progress(done, total)
            rows.append({"method": method, "budget": budget, "median_error": float(np.median(errs)), "worst_error": float(np.max(errs)),
                         "evaluations": float(np.mean(evals)), "time_s": float(np.mean(secs))})
    return rows


# -- oxidation ---------------------------------------------------------------------------
@dataclass(frozen=True)
class OxidationFit:
    """Fitted oxidation law with its uncertainty.

    ``model`` holds T_0, d_0, xi_0; ``reflectance0`` is the bare reflectance R_0 in
    ``R = R_0 exp(-xi)``. ``reference_temperature_k`` and ``rate_at_reference_per_s``
    (k_ref = d_0 exp(-T_0 / T_ref)) are the well-conditioned parameters actually fitted;
    ``correlation`` is their correlation matrix (T_0, ln k_ref, xi_0, ln R_0) and
    ``correlation_t0_log_d0`` the correlation of T_0 with ln d_0 (near +-1: why the
    reparametrisation is needed). ``ci95`` maps names to (low, high).
    """

    model: OxidationModel
    reflectance0: float
    reference_temperature_k: float
    rate_at_reference_per_s: float
    correlation: np.ndarray
    correlation_t0_log_d0: float
    condition_number: float
    ci95: dict
    residual_rms: float
    fit_time_s: float


def fit_oxidation(times_s, temperatures_k, reflectance, *, reference_temperature_k=None, initial=(8000.0, 0.3)) -> OxidationFit:
    """Fit T_0, d_0, xi_0 (and R_0) of ``R = R_0 exp(-xi(t))`` to a reflectance series.

    Uses the reparametrisation of the spec: ``d_0 exp(-T_0/T) = k_ref exp(-T_0 (1/T -
    1/T_ref))`` with ``ln k_ref`` fitted (T_ref default: the 90th percentile of the
    temperatures, where most oxidation happens), by nonlinear least squares on ln R.
    """
    from scipy.optimize import least_squares

    start = time.perf_counter()
    t = finite_array("times_s", times_s, ndim=1)
    temp = finite_array("temperatures_k", temperatures_k, ndim=1)
    r = finite_array("reflectance", reflectance, ndim=1)
    if not (t.shape == temp.shape == r.shape):
        raise ValueError(f"times_s, temperatures_k, reflectance: expected equal lengths, got {t.size}, {temp.size}, {r.size}")
    if t.size < 6:
        raise ValueError(f"underdetermined fit: {t.size} points for 4 parameters; give at least 6")
    if np.any(r <= 0):
        raise ValueError("reflectance: expected values > 0")
    t_ref = float(np.percentile(temp, 90)) if reference_temperature_k is None else finite_scalar("reference_temperature_k", reference_temperature_k, minimum=0.0, strict_min=True)
    y = np.log(r)

    def xi_of(p):
        t0, lk, xi0 = p[0], p[1], p[2]
        d0 = math.exp(lk + t0 / t_ref)
        return OxidationModel(max(t0, 0.0), d0, max(xi0, 0.0)).extinction(t, temp)

    def resid(p):
        return p[3] - xi_of(p) - y

    t0_init, xi0_init = initial
    # initial ln k_ref from the total darkening: xi_end^2 - xi0^2 ~ k_ref * (effective time)
    darkening = max(y[0] - y[-1], 1e-3)
    eff = OxidationModel(t0_init, 1.0, 0.0).extinction(t, temp)[-1] ** 2 * math.exp(t0_init / t_ref)
    lk_init = math.log(max(((xi0_init + darkening) ** 2 - xi0_init**2) / max(eff, 1e-300), 1e-300))
    p0 = np.array([t0_init, lk_init, xi0_init, y[0] + xi0_init])
    sol = least_squares(resid, p0, x_scale=np.array([1000.0, 1.0, 0.1, 0.1]), bounds=([0.0, -200.0, 0.0, -10.0], [1e5, 200.0, 10.0, 5.0]),
                        xtol=1e-14, ftol=1e-14, gtol=1e-14, max_nfev=5000)
    p = sol.x
    jac = sol.jac
    dof = max(t.size - 4, 1)
    s2 = float(np.sum(sol.fun**2) / dof)
    jtj = jac.T @ jac
    cov = s2 * np.linalg.pinv(jtj)
    sd = np.sqrt(np.maximum(np.diag(cov), 0.0))
    corr = cov / np.outer(np.maximum(sd, 1e-300), np.maximum(sd, 1e-300))
    # covariance of (T0, ln d0) where ln d0 = ln k_ref + T0 / T_ref
    jac_orig = np.array([[1.0, 0.0], [1.0 / t_ref, 1.0]])  # d(T0, ln d0)/d(T0, ln k_ref)
    c2 = jac_orig @ cov[:2, :2] @ jac_orig.T
    corr_t0_d0 = float(c2[0, 1] / math.sqrt(max(c2[0, 0] * c2[1, 1], 1e-300)))
    d0 = math.exp(p[1] + p[0] / t_ref)
    sd_ld0 = math.sqrt(max(c2[1, 1], 0.0))
    ci = {
        "activation_temperature_k": (p[0] - 1.96 * sd[0], p[0] + 1.96 * sd[0]),
        "rate_per_s": (d0 * math.exp(-1.96 * sd_ld0), d0 * math.exp(1.96 * sd_ld0)),
        "initial_extinction": (p[2] - 1.96 * sd[2], p[2] + 1.96 * sd[2]),
        "rate_at_reference_per_s": (math.exp(p[1] - 1.96 * sd[1]), math.exp(p[1] + 1.96 * sd[1])),
    }
    ev = np.linalg.eigvalsh(jtj)
    return OxidationFit(
        model=OxidationModel(p[0], d0, p[2]),
        reflectance0=math.exp(p[3]),
        reference_temperature_k=t_ref,
        rate_at_reference_per_s=math.exp(p[1]),
        correlation=corr,
        correlation_t0_log_d0=corr_t0_d0,
        condition_number=float(math.sqrt(ev.max() / max(ev.min(), 1e-300))),
        ci95=ci,
        residual_rms=float(np.sqrt(np.mean(sol.fun**2))),
        fit_time_s=time.perf_counter() - start,
    )
