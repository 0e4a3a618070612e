"""Sample-to-sample variability of a measured BRDF: envelopes at a stated coverage.

Bailey et al., J. Laser Appl. 20(1), 2008, Sec. V B 1: between stainless-steel samples
"total reflectance could also vary by almost a factor of two, and peak values could vary
by almost an order of magnitude" (copper: peaks and powers by nearly a factor of two);
Sec. VI A: single-sample fits of the melting regime were "quite poor, badly predicting
the BRDF", and "large data sets with sufficient tests to characterize the range of
possible response may be required". This module measures that range from several
physical samples of one condition and turns it into conservative models.

A *sample* is one ``test_id`` of a :class:`~brdfmodels.screen.Samples` table; a
*condition* is one incidence (and, optionally, one state node). Per condition, with K
samples and coverage c:

1. Each sample is fitted alone with the same basis (:func:`brdfmodels.fitting.fit_sh`,
   the samples' weights, the given fit options).
2. The K fits are evaluated at common direction pairs j: the condition's measured pairs
   and ``n_directions`` outgoing directions over the hemisphere at the condition's
   incidence (a Fibonacci lattice, equal solid angle per point: Gonzalez, Math. Geosci.
   42, 49-64, 2010), giving V[k, j] [1/sr].
3. Coverage quantile per direction: the order statistic ``q_j = V_(r),j`` with
   ``r = ceil(c K)`` (Hyndman & Fan, Am. Stat. 50, 361-365, 1996, definition 1: the
   inverse of the empirical CDF, numpy's ``method="inverted_cdf"``). It is the smallest
   value with at least a fraction c of the samples at or below it, so at every direction
   at most ``K - r <= (1 - c) K`` samples lie above it. Interpolating definitions
   (numpy's default ``"linear"``) can fall below the r-th order statistic and leave more
   than (1 - c) K samples above, so they are not conservative; ``"higher"`` keeps the
   guarantee but can be one order statistic higher than needed.
4. Envelopes: a log-SH model >= q_j at every evaluated pair (coverage envelope) and one
   >= max_k V[k, j] there and >= every measured value of the condition (max envelope),
   each a linear program (:func:`brdfmodels.fitting.envelope_sh`), then checked and, if
   rounding left a pair above, lifted by the largest shortfall.
5. Spread: per sample the directional-hemispherical reflectance of its fit at the
   incidence (:func:`brdfmodels.analysis.hemispherical_reflectance`) and its part over
   the solid angle the measurements cover (the fit beyond it is an extrapolation), its
   measured and fitted peak f_r; their max/min ratios; quantiles over directions of the per-direction
   ratio max_k V / min_k V; which samples lie above the coverage envelope, and where.

The guarantee of step 3 is about the measured samples. Whether q_j bounds the
c-quantile xi_c of the material's population is chance: for continuous values
``P(V_(r) >= xi_c) = P(Binomial(K, c) <= r - 1)`` (David & Nagaraja, Order Statistics,
3rd ed., 2003, Sec. 7.1), reported as ``population_confidence`` (K = 10, c = 0.95:
r = 10, 0.40).

Fits of scaled data are scaled fits (ln f~ shifts by a constant, the constant harmonic
absorbs it) when the truncated SVD prunes no mode: with pruned modes the constant shift
can be partly discarded. Each fit's pruned modes are in the summary.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np

from ._checks import finite_scalar
from .analysis import hemispherical_reflectance
from .fitting import EnvelopeFit, envelope_sh, fit_sh
from .geometry import vector_to_spherical
from .models import SphericalHarmonicBRDF
from .screen import Samples, group_by_state
from .sh import SHBasis

__all__ = ["sample_variability", "VariabilityResult", "ConditionVariability", "coverage_rank", "population_confidence",
           "hemisphere_lattice", "QUANTILE_METHOD"]

QUANTILE_METHOD = "inverted_cdf"  # Hyndman & Fan (1996) definition 1; see the module docstring
_LP_ROUNDS = 6  # constraint-generation rounds of the max envelope before it takes every measured row
_RATIO_QUANTILES = (0.5, 0.95, 1.0)


def coverage_rank(n_samples: int, coverage: float) -> int:
    """Rank r = ceil(c K) of the order statistic that is the coverage quantile.

    Hyndman & Fan (1996), definition 1: the smallest r with r / K >= c. ``c K`` is
    rounded to 1e-9 first so that, e.g., 0.35 x 20 = 7.000000000000001 gives 7.

    Parameters
    ----------
    n_samples : int
        K >= 1.
    coverage : float
        c in (0, 1] (dimensionless).
    """
    return max(1, math.ceil(round(coverage * n_samples, 9)))


def population_confidence(n_samples: int, rank: int, coverage: float) -> float:
    """P(V_(r) >= xi_c) = P(Binomial(K, c) <= r - 1) for continuous values.

    The probability that the r-th smallest of K independent samples is at or above the
    population's c-quantile (David & Nagaraja, Order Statistics, 3rd ed., 2003, Sec. 7.1),
    evaluated as the regularised incomplete beta ``I_{1-c}(K - r + 1, r)`` (DLMF 8.17.4-8.17.5).
    """
    from scipy.special import betainc

    if rank > n_samples:
        return 1.0
    return float(betainc(n_samples - rank + 1, rank, 1.0 - coverage))


def hemisphere_lattice(n: int, seed: int = 0) -> np.ndarray:
    """``n`` outgoing directions over the hemisphere, equal solid angle per point, (n, 3).

    Fibonacci lattice (Gonzalez 2010): ``z_i = 1 - (i + 1/2) / n`` (uniform in z is uniform
    in solid angle, d omega = dz dphi), ``phi_i = i pi (3 - sqrt 5) + phi_0`` with a
    seeded random rotation ``phi_0``.
    """
    if n == 0:
        return np.empty((0, 3))
    i = np.arange(n)
    z = 1.0 - (i + 0.5) / n
    phi = i * math.pi * (3.0 - math.sqrt(5.0)) + np.random.default_rng(seed).uniform(0.0, 2.0 * math.pi)
    s = np.sqrt(1.0 - z * z)
    return np.stack([s * np.cos(phi), s * np.sin(phi), z], axis=1)


# -- conditions ---------------------------------------------------------------------------
@dataclass(frozen=True)
class _Condition:
    label: str
    wi: np.ndarray
    test_ids: tuple
    rows: Samples
    state_value: float | None


def _angles_deg(w):
    th, ph = vector_to_spherical(w)
    return float(np.degrees(th)), float(np.degrees(ph))


def _test_incidences(samples: Samples, resolution_deg: float) -> dict:
    """test_id -> mean unit incidence of its rows; ValueError when a test's rows differ."""
    out = {}
    for tid in dict.fromkeys(samples.test_id.tolist()):
        w = samples.wi[samples.test_id == tid]
        w = w / np.linalg.norm(w, axis=1, keepdims=True)
        m = w.mean(axis=0)
        m /= np.linalg.norm(m)
        spread = float(np.degrees(np.arccos(np.clip(w @ m, -1.0, 1.0))).max())
        if spread > resolution_deg:
            raise ValueError(f"samples: test {tid!r} has rows up to {spread:.3g} deg from its mean incidence; expected one "
                             f"incidence per test (test_id), within incidence_resolution_deg={resolution_deg!r}")
        out[tid] = m
    return out


def _incidence_key(w, resolution_deg):
    th, ph = _angles_deg(w)
    kt = round(th / resolution_deg)
    return (kt, 0 if kt == 0 else round(ph / resolution_deg) % round(360.0 / resolution_deg))


def _auto_groups(incidence: dict, resolution_deg: float) -> dict:
    """Tests grouped by incidence (theta_i, phi_i) rounded to ``resolution_deg``."""
    groups = {}
    for tid, w in incidence.items():
        groups.setdefault(_incidence_key(w, resolution_deg), []).append(tid)
    digits = max(1, -math.floor(math.log10(resolution_deg)))
    return {f"theta_i={kt * resolution_deg:.{digits}f}deg phi_i={kp * resolution_deg:.{digits}f}deg": tids
            for (kt, kp), tids in groups.items()}


def _check_groups(groups, incidence: dict, resolution_deg: float) -> dict:
    """Validate user groups: known test ids, one incidence per group."""
    try:
        items = list(dict(groups).items())
    except (TypeError, ValueError):
        raise ValueError(f"groups={groups!r}: expected a mapping of condition label to a list of test_id values") from None
    by_str = {str(t): t for t in incidence}
    out = {}
    for label, tids in items:
        if isinstance(tids, str):
            tids = [tids]
        resolved = []
        for t in tids:
            if str(t) not in by_str:
                raise ValueError(f"groups[{label!r}]: test_id {t!r} is not in samples; expected one of {sorted(by_str)}")
            resolved.append(by_str[str(t)])
        resolved = list(dict.fromkeys(resolved))
        for a in resolved[1:]:
            gap = float(np.degrees(np.arccos(np.clip(incidence[a] @ incidence[resolved[0]], -1.0, 1.0))))
            if gap > resolution_deg:
                th0, ph0 = _angles_deg(incidence[resolved[0]])
                th1, ph1 = _angles_deg(incidence[a])
                raise ValueError(f"groups[{label!r}]: test {resolved[0]!r} (theta_i={th0:.2f} deg, phi_i={ph0:.2f} deg) and "
                                 f"test {a!r} (theta_i={th1:.2f} deg, phi_i={ph1:.2f} deg) differ in incidence by {gap:.3g} deg; "
                                 f"expected one incidence per condition (within incidence_resolution_deg={resolution_deg!r})")
        out[str(label)] = resolved
    return out


def _conditions(samples, groups, state, states, resolution_deg) -> list:
    """Split the table into conditions (incidence group x state node) of >= 2 samples."""
    incidence = _test_incidences(samples, resolution_deg)
    named = groups is not None
    table = _check_groups(groups, incidence, resolution_deg) if named else _auto_groups(incidence, resolution_deg)
    out = []
    for label, tids in table.items():
        rows = samples.select(np.isin(samples.test_id, np.array(tids, dtype=samples.test_id.dtype)))
        wi = np.mean([incidence[t] for t in tids], axis=0)
        wi /= np.linalg.norm(wi)
        where = f"groups[{label!r}]" if named else "samples"
        if state is None:
            parts = {None: rows}
        else:
            by_node = group_by_state(rows, state, states)
            parts = {float(s): by_node.get(float(s)) for s in np.atleast_1d(np.asarray(states, float))}
        for s_val, part in parts.items():
            lab = label if s_val is None else f"{label} {state}={s_val:g}"
            present = () if part is None else tuple(dict.fromkeys(part.test_id.tolist()))
            if len(present) < 2:
                raise ValueError(f"{where}: condition {lab!r} has {len(present)} sample(s) {[str(t) for t in present]}; "
                                 "expected at least 2 samples (test_id values) per condition to measure sample-to-sample variability")
            out.append(_Condition(lab, wi, present, part, s_val))
    return out


# -- per-condition analysis --------------------------------------------------------------------
def _evaluation_pairs(rows: Samples, wi_c, n_directions, max_measured_pairs, seed):
    """The measured pairs (distinct, at most ``max_measured_pairs``, a seeded subset beyond
    that) and ``n_directions`` lattice directions at the condition's incidence."""
    pairs = np.hstack([rows.wi, rows.wo])
    _, idx = np.unique(np.round(pairs, 12), axis=0, return_index=True)
    idx = np.sort(idx)
    if idx.size > max_measured_pairs:
        idx = np.sort(np.random.default_rng(seed).choice(idx, max_measured_pairs, replace=False))
    hemi = hemisphere_lattice(n_directions, seed)
    wi = np.vstack([rows.wi[idx], np.tile(wi_c, (len(hemi), 1))])
    wo = np.vstack([rows.wo[idx], hemi])
    measured = np.concatenate([np.ones(idx.size, bool), np.zeros(len(hemi), bool)])
    return wi, wo, measured


def _as_samples(wi, wo, f) -> Samples:
    n = len(f)
    return Samples(wi, wo, f, np.zeros(n), np.full(n, np.nan), np.full(n, "envelope", dtype=object), np.zeros(n, int),
                   np.ones(n))


def _lift(model: SphericalHarmonicBRDF, wi, wo, target):
    """Raise the constant harmonic until the model is >= target at every pair (y_0^0 =
    1 / sqrt(4 pi), so adding d sqrt(4 pi) to it multiplies f_r by e^d)."""
    for _ in range(4):
        short = float(np.max(target / model.evaluate(wi, wo)))
        if short <= 1.0:
            return model
        coef = model.coefficients.copy()
        coef[0] += (math.log(short) + 1e-12 * (1.0 + float(np.abs(coef).sum()))) * math.sqrt(4.0 * math.pi)
        model = SphericalHarmonicBRDF(model.basis, coef, fanout=model.fanout, log=True)
    raise RuntimeError("envelope: could not lift the model above its targets (non-finite values?)")


def _sh_envelope(wi, wo, target, basis, fanout, data: Samples | None = None, what="") -> EnvelopeFit:
    """Log-SH model >= ``target`` at every pair (and >= every row of ``data``), checked.

    The linear program (:func:`brdfmodels.fitting.envelope_sh`) first takes the targets;
    measured rows still above it are added and the program solved again (constraint
    generation), at most ``_LP_ROUNDS`` times, then with every row.
    """
    pos = target > 0  # a log envelope is > 0 everywhere: zero targets bound themselves
    cw, co, ct = wi[pos], wo[pos], target[pos]
    rounds = 0
    while True:
        rounds += 1
        lp = envelope_sh(_as_samples(cw, co, ct), basis, fanout=fanout)
        if data is None:
            break
        over = data.brdf_per_sr > lp.model.evaluate(data.wi, data.wo)
        if not np.any(over):
            break
        take = over if rounds < _LP_ROUNDS else np.ones(len(data), bool)
        cw, co, ct = np.vstack([cw, data.wi[take]]), np.vstack([co, data.wo[take]]), np.concatenate([ct, data.brdf_per_sr[take]])
    model = _lift(lp.model, cw, co, ct)
    env = model.evaluate(wi, wo)
    ratio = env[pos] / target[pos]
    details = {"pairs": int(len(target)), "lp_rounds": rounds, "min_ratio": float(ratio.min()), "coefficients": basis.size}
    if data is not None:
        details["measured_rows_bounded"] = float(np.mean(data.brdf_per_sr <= model.evaluate(data.wi, data.wo)))
    return EnvelopeFit(model, float(np.mean(env >= target)), float(np.median(ratio)), float(ratio.max()),
                       f"SH envelope of the {what} (linear program)", details)


def _fit_samples(cond: _Condition, basis, fanout, fit_kwargs) -> tuple:
    fits = []
    for tid in cond.test_ids:
        part = cond.rows.select(cond.rows.test_id == tid)
        try:
            fits.append(fit_sh(part.wi, part.wo, part.brdf_per_sr, basis, fanout=fanout, weights=part.weight, **fit_kwargs))
        except ValueError as exc:
            raise ValueError(f"samples: test {tid!r} (condition {cond.label!r}): {exc}") from None
    return tuple(fits)


def _ratio_quantiles(r):
    r = r[np.isfinite(r)]
    return {f"q{round(100 * p)}": (float(np.quantile(r, p)) if r.size else math.nan) for p in _RATIO_QUANTILES}


def _measured_cone(cond: _Condition, wo_lattice) -> np.ndarray:
    """Lattice directions in the solid angle the measurements cover: within r of a
    measured outgoing direction, r the median nearest-neighbour spacing of the measured
    directions (chord length; it over-states the cone by about r at its edges)."""
    from scipy.spatial import cKDTree

    if len(wo_lattice) == 0:
        return np.zeros(0, bool)
    wo = np.unique(np.round(cond.rows.wo, 12), axis=0)
    tree = cKDTree(wo)
    r = float(np.median(tree.query(wo, k=2)[0][:, 1])) if len(wo) > 1 else 0.0
    dist, _ = tree.query(wo_lattice, distance_upper_bound=r * (1 + 1e-9))
    return np.isfinite(dist)


def _reflectances(cond: _Condition, fits, values, wo_eval, measured, reflectance_rtol) -> dict:
    """Each fit's directional-hemispherical reflectance (adaptive quadrature,
    :func:`brdfmodels.analysis.hemispherical_reflectance`) and its part over the measured
    cone: ``(2 pi / n) sum_j f_r(wi, wo_j) cos(theta_j)`` over the lattice points in it
    (equal solid angle 2 pi / n each, Gonzalez 2010)."""
    dhr = [hemispherical_reflectance(f.model, cond.wi, rtol=reflectance_rtol, max_evaluations=400_000) for f in fits]
    lattice = ~measured
    cone = _measured_cone(cond, wo_eval[lattice])
    w = 2.0 * math.pi / max(int(lattice.sum()), 1)
    part = np.full(len(fits), math.nan)
    if cone.any():
        part = w * (values[:, lattice][:, cone] * wo_eval[lattice][cone, 2]).sum(axis=1)
    return {"reflectance": np.array([d.value for d in dhr]), "reflectance_converged": [d.converged for d in dhr],
            "reflectance_measured_cone": part, "measured_cone_sr": w * int(cone.sum())}


def _max_min(v) -> float:
    v = np.asarray(v, float)
    return float(v.max() / v.min()) if np.all(np.isfinite(v)) and v.min() > 0 else math.inf


def _spread(cond: _Condition, fits, values, wo_eval, measured, quantile, reflectance_rtol) -> dict:
    """Per-sample reflectances and peaks, their max/min ratios, per-direction ratio quantiles."""
    out = _reflectances(cond, fits, values, wo_eval, measured, reflectance_rtol)
    out["peak_measured_per_sr"] = np.array([cond.rows.brdf_per_sr[cond.rows.test_id == t].max() for t in cond.test_ids])
    out["peak_fitted_per_sr"] = values[:, measured].max(axis=1) if measured.any() else values.max(axis=1)
    for key in ("reflectance", "reflectance_measured_cone", "peak_measured_per_sr", "peak_fitted_per_sr"):
        out[key.removesuffix("_per_sr") + "_ratio"] = _max_min(out[key])
    with np.errstate(divide="ignore", invalid="ignore"):
        per_dir = values.max(axis=0) / values.min(axis=0)
        median = np.median(values, axis=0)
        log_rel = np.log(values[:, measured] / median[measured])
        out["coverage_over_median"] = _ratio_quantiles(quantile / median)
    # geometric-mean ratio of each sample's fit to the per-direction median (measured pairs)
    out["relative_scale"] = np.exp(np.mean(log_rel, axis=1)) if measured.any() else np.full(len(fits), math.nan)
    out["direction_ratio_measured"] = _ratio_quantiles(per_dir[measured])
    out["direction_ratio_hemisphere"] = _ratio_quantiles(per_dir[~measured])
    return out


def _exceedances(cond: _Condition, values, env_values, env_rows, wo_eval, measured) -> list:
    """Per sample: where its fit (evaluated pairs) and its data (measured rows) lie above
    the coverage envelope, and the worst ratio with its outgoing direction."""
    th, ph = vector_to_spherical(wo_eval)
    out = []
    for k, tid in enumerate(cond.test_ids):
        r = values[k] / env_values
        j = int(np.argmax(r))
        sel = cond.rows.test_id == tid
        d = cond.rows.brdf_per_sr[sel] / env_rows[sel]
        i = int(np.argmax(d))
        dth, dph = vector_to_spherical(cond.rows.wo[sel][i])
        out.append({
            "test_id": str(tid), "directions_above": int(np.sum(r > 1.0)), "fraction_above": float(np.mean(r > 1.0)),
            "worst_ratio": float(r[j]), "worst_theta_o_deg": float(np.degrees(th[j])), "worst_phi_o_deg": float(np.degrees(ph[j])),
            "worst_is_measured_pair": bool(measured[j]), "measured_points_above": int(np.sum(d > 1.0)),
            "measured_fraction_above": float(np.mean(d > 1.0)), "measured_worst_ratio": float(d[i]),
            "measured_worst_theta_o_deg": float(np.degrees(dth)), "measured_worst_phi_o_deg": float(np.degrees(dph)),
        })
    return out


@dataclass(frozen=True)
class ConditionVariability:
    """Variability of one condition (one incidence, optionally one state node).

    Attributes
    ----------
    label : str
    theta_i_deg, phi_i_deg : float
        Incidence [deg] in the surface frame (phi from the grooves, x).
    state_name : str or None
    state_value : float or None
        State node of the condition (in the state's unit: s, K, ...).
    test_ids : tuple
        The K samples.
    coverage : float
        c (dimensionless).
    rank : int
        r = ceil(c K): the coverage quantile is the r-th smallest of K.
    population_confidence : float
        P(V_(r) >= population c-quantile) = P(Binomial(K, c) <= r - 1).
    wi : ndarray, shape (3,)
        The condition's incidence (unit vector, surface frame).
    wi_eval, wo_eval : ndarray, shape (J, 3)
        Evaluated direction pairs (measured pairs first, then the hemisphere lattice).
    measured : ndarray of bool, shape (J,)
    values_per_sr : ndarray, shape (K, J)
        Each sample's fit at the evaluated pairs [1/sr].
    quantile_per_sr, max_per_sr : ndarray, shape (J,)
        Per-direction coverage quantile and maximum across samples [1/sr].
    coverage_envelope, max_envelope : EnvelopeFit
        SH models >= ``quantile_per_sr`` / ``max_per_sr`` at every evaluated pair (the max
        one also >= every measured value); ratios are over-prediction of the target.
    fits : tuple of FitResult
    spread : dict
        ``reflectance`` (K,): each fit's directional-hemispherical reflectance at ``wi``
        (dimensionless; beyond the measured cone it is the fit's extrapolation);
        ``reflectance_measured_cone`` (K,): its part over the measured cone
        (``measured_cone_sr`` [sr]); ``peak_measured_per_sr``, ``peak_fitted_per_sr``
        (K,): largest measured value and largest fitted value at the measured pairs;
        ``*_ratio``: max/min of each over the samples; ``relative_scale`` (K,):
        geometric mean over the measured pairs of a fit / the per-direction median;
        ``direction_ratio_measured`` / ``_hemisphere``: quantiles (q50, q95, q100) over
        directions of max_k V / min_k V; ``coverage_over_median``: the same of q_j / median_j.
    exceedances : list of dict
        Per sample: evaluated pairs and measured rows above the coverage envelope.
    fraction_above : float
        Fraction of (sample, evaluated pair) points above the coverage envelope
        (<= 1 - c by construction).
    measured_fraction_above : float
        Fraction of the measured rows above the coverage envelope (not guaranteed: the
        fits' residuals).
    rows : Samples
        The condition's measured rows.
    run_time_s : float
    """

    label: str
    theta_i_deg: float
    phi_i_deg: float
    state_name: str | None
    state_value: float | None
    test_ids: tuple
    coverage: float
    rank: int
    population_confidence: float
    wi: np.ndarray
    wi_eval: np.ndarray
    wo_eval: np.ndarray
    measured: np.ndarray
    values_per_sr: np.ndarray
    quantile_per_sr: np.ndarray
    max_per_sr: np.ndarray
    coverage_envelope: EnvelopeFit
    max_envelope: EnvelopeFit
    fits: tuple
    spread: dict
    exceedances: list
    fraction_above: float
    measured_fraction_above: float
    rows: Samples
    run_time_s: float

    @property
    def n_samples(self) -> int:
        return len(self.test_ids)

    def envelope(self, kind: str = "coverage") -> EnvelopeFit:
        """The ``"coverage"`` or ``"max"`` envelope."""
        if kind not in ("coverage", "max"):
            raise ValueError(f"kind={kind!r}: expected 'coverage' or 'max'")
        return self.coverage_envelope if kind == "coverage" else self.max_envelope

    def summary(self) -> dict:
        """JSON-ready numbers of the condition (arrays left out, per-sample lists kept)."""
        s = self.spread
        keys = ("reflectance", "reflectance_measured_cone", "peak_measured_per_sr", "peak_fitted_per_sr", "relative_scale")
        per_sample = [{"test_id": t, **{key: float(s[key][k]) for key in keys},
                       "reflectance_converged": bool(s["reflectance_converged"][k]),
                       "fit_relative_rms": float(self.fits[k].relative_rms), "fit_pruned_modes": int(self.fits[k].pruned_modes)}
                      for k, t in enumerate(self.test_ids)]
        ratios = ("reflectance_ratio", "reflectance_measured_cone_ratio", "peak_measured_ratio", "peak_fitted_ratio",
                  "direction_ratio_measured", "direction_ratio_hemisphere", "coverage_over_median")
        return {
            "label": self.label, "theta_i_deg": self.theta_i_deg, "phi_i_deg": self.phi_i_deg, "state_name": self.state_name,
            "state_value": self.state_value, "n_samples": self.n_samples, "coverage": self.coverage,
            "quantile_method": QUANTILE_METHOD, "rank": self.rank, "population_confidence": self.population_confidence,
            "pairs": int(self.measured.size), "measured_pairs": int(self.measured.sum()),
            "measured_cone_sr": float(s["measured_cone_sr"]), "samples": per_sample, **{k: s[k] for k in ratios},
            "fraction_above_coverage_envelope": self.fraction_above, "allowed_fraction_above": 1.0 - self.coverage,
            "measured_fraction_above_coverage_envelope": self.measured_fraction_above,
            "coverage_envelope": self.coverage_envelope.summary(), "max_envelope": self.max_envelope.summary(),
            "exceedances": self.exceedances, "run_time_s": self.run_time_s,
        }


def _analyse(cond: _Condition, basis, coverage, fanout, n_directions, seed, max_measured_pairs, reflectance_rtol, state,
             fit_kwargs) -> ConditionVariability:
    start = time.perf_counter()
    fits = _fit_samples(cond, basis, fanout, fit_kwargs)
    wi_e, wo_e, measured = _evaluation_pairs(cond.rows, cond.wi, n_directions, max_measured_pairs, seed)
    values = np.stack([f.model.evaluate(wi_e, wo_e) for f in fits])
    k = len(fits)
    rank = coverage_rank(k, coverage)
    ordered = np.sort(values, axis=0)
    quantile, vmax = ordered[rank - 1], ordered[-1]  # order statistics r and K (Hyndman & Fan definition 1)
    cov_env = _sh_envelope(wi_e, wo_e, quantile, basis, fanout, what=f"{coverage:g} quantile across {k} samples")
    max_env = _sh_envelope(wi_e, wo_e, vmax, basis, fanout, data=cond.rows, what=f"maximum across {k} samples and their data")
    env_values = cov_env.model.evaluate(wi_e, wo_e)
    env_rows = cov_env.model.evaluate(cond.rows.wi, cond.rows.wo)
    th, ph = _angles_deg(cond.wi)
    return ConditionVariability(
        label=cond.label, theta_i_deg=th, phi_i_deg=ph, state_name=state, state_value=cond.state_value,
        test_ids=tuple(str(t) for t in cond.test_ids), coverage=coverage, rank=rank,
        population_confidence=population_confidence(k, rank, coverage), wi=cond.wi, wi_eval=wi_e, wo_eval=wo_e,
        measured=measured, values_per_sr=values, quantile_per_sr=quantile, max_per_sr=vmax, coverage_envelope=cov_env,
        max_envelope=max_env, fits=fits, spread=_spread(cond, fits, values, wo_e, measured, quantile, reflectance_rtol),
        exceedances=_exceedances(cond, values, env_values, env_rows, wo_e, measured),
        fraction_above=float(np.mean(values > env_values)),
        measured_fraction_above=float(np.mean(cond.rows.brdf_per_sr > env_rows)), rows=cond.rows,
        run_time_s=time.perf_counter() - start)


# -- result -----------------------------------------------------------------------------------
@dataclass(frozen=True)
class VariabilityResult:
    """Sample-to-sample variability of every condition, with envelope models.

    Attributes
    ----------
    conditions : tuple of ConditionVariability
    coverage : float
    basis : SHBasis
    fanout : float
    state_name : str or None
    run_time_s : float
    """

    conditions: tuple
    coverage: float
    basis: SHBasis
    fanout: float
    state_name: str | None
    run_time_s: float

    @property
    def labels(self) -> list:
        return [c.label for c in self.conditions]

    def condition(self, label: str | None = None) -> ConditionVariability:
        """The condition called ``label`` (None: the only one)."""
        if label is None:
            if len(self.conditions) != 1:
                raise ValueError(f"condition=None: the result has {len(self.conditions)} conditions {self.labels}; name one")
            return self.conditions[0]
        for c in self.conditions:
            if c.label == label:
                return c
        raise ValueError(f"condition={label!r}: expected one of {self.labels}")

    def combined_envelope(self, kind: str = "coverage") -> EnvelopeFit:
        """One SH model >= every condition's ``kind`` target (coverage quantile or max) at
        its evaluated pairs (the max one also >= every measured value): all incidences
        and states of the result in one static bound."""
        if kind not in ("coverage", "max"):
            raise ValueError(f"kind={kind!r}: expected 'coverage' or 'max'")
        tgt = [c.quantile_per_sr if kind == "coverage" else c.max_per_sr for c in self.conditions]
        wi = np.vstack([c.wi_eval for c in self.conditions])
        wo = np.vstack([c.wo_eval for c in self.conditions])
        data = Samples.concatenate([c.rows for c in self.conditions]) if kind == "max" else None
        what = f"{self.coverage:g} quantile" if kind == "coverage" else "maximum"
        return _sh_envelope(wi, wo, np.concatenate(tgt), self.basis, self.fanout, data=data,
                            what=f"{what} of {len(self.conditions)} conditions")

    def summary(self) -> dict:
        """JSON-ready summary: settings and each condition's :meth:`ConditionVariability.summary`."""
        return {"coverage": self.coverage, "quantile_method": QUANTILE_METHOD, "basis": self.basis.to_dict(), "fanout": self.fanout,
                "state_name": self.state_name, "conditions": [c.summary() for c in self.conditions], "run_time_s": self.run_time_s}

    def save(self, path, *, kind: str = "coverage", condition: str | None = None, combined: bool = False):
        """Write an envelope model with :func:`brdfmodels.save` (versioned JSON, atomic).

        ``kind`` ``"coverage"`` or ``"max"``; ``condition`` a label (None: the only
        condition); ``combined=True`` the :meth:`combined_envelope` of all conditions.
        Returns the path.
        """
        from .registry import save

        model = self.combined_envelope(kind).model if combined else self.condition(condition).envelope(kind).model
        return save(model, path)


def sample_variability(samples: Samples, basis: SHBasis, *, coverage=0.95, fanout=0.6, groups=None, state=None, states=None,
                       n_directions=1024, seed=0, incidence_resolution_deg=0.1, max_measured_pairs=20000,
                       reflectance_rtol=1e-4, **fit_kwargs) -> VariabilityResult:
    """Envelopes of several samples of one condition at a stated coverage, and their spread.

    Parameters
    ----------
    samples : brdfmodels.screen.Samples
        Measured f_r [1/sr]; each ``test_id`` is one physical sample.
    basis : SHBasis
        The basis every sample is fitted with and the envelopes are built in.
    coverage : float
        c in (0, 1]: the envelope is the per-direction r-th smallest of K samples,
        r = ceil(c K) (module docstring, step 3).
    fanout : float
        Fan-out exponent s_e of the fits and envelopes (paper Eq. 34).
    groups : mapping of str to list of test_id, optional
        Explicit conditions (tests in no group are left out); default: tests grouped by
        incidence (theta_i, phi_i) rounded to ``incidence_resolution_deg``.
    state : str, optional
        A state column as :func:`brdfmodels.screen.group_by_state` takes it (``"time_s"``,
        ``"temperature_k"``, ...). With ``states`` (its nodes, in its unit) each condition
        is split by the nearest node. Without it a test's rows (all its frames) form one
        sample.
    n_directions : int
        Hemisphere lattice directions evaluated at each condition's incidence (0: only
        the measured pairs).
    seed : int
        Rotation of the lattice and the subset of measured pairs beyond
        ``max_measured_pairs``.
    incidence_resolution_deg : float
        Incidences closer than this [deg] are one; a test's rows must agree to it.
    max_measured_pairs : int
        Distinct measured pairs evaluated per condition (a seeded subset beyond it).
    reflectance_rtol : float
        Relative tolerance of each fit's directional-hemispherical reflectance.
    **fit_kwargs
        Passed to :func:`brdfmodels.fitting.fit_sh` (``horizon``, ``rcond``, ...).

    Returns
    -------
    VariabilityResult
        Per condition: fits, per-direction quantile and max, the two envelopes and their
        checks, the spread (reflectance and peak max/min ratios, direction ratio
        quantiles) and the samples above the coverage envelope.

    Raises
    ------
    ValueError
        A condition with fewer than 2 samples, tests of one condition (or rows of one
        test) at different incidence, bad arguments, or a fit's own error (naming the test).
    """
    start = time.perf_counter()
    if not isinstance(samples, Samples):
        raise ValueError(f"samples={type(samples).__name__}: expected a brdfmodels.screen.Samples table")
    if not isinstance(basis, SHBasis):
        raise ValueError(f"basis={basis!r}: expected an SHBasis")
    coverage = finite_scalar("coverage", coverage, minimum=0.0, maximum=1.0, strict_min=True)
    res = finite_scalar("incidence_resolution_deg", incidence_resolution_deg, minimum=0.0, strict_min=True, maximum=10.0)
    for name, v, lo in (("n_directions", n_directions, 0), ("max_measured_pairs", max_measured_pairs, 1)):
        if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < lo:
            raise ValueError(f"{name}={v!r}: expected an integer >= {lo}")
    if "weights" in fit_kwargs:
        raise ValueError("weights: each sample is fitted with the table's own weight column; set samples.weight instead")
    if (state is None) != (states is None):
        raise ValueError(f"state={state!r}, states={states!r}: give both (a state column and its nodes) or neither")
    conds = _conditions(samples, groups, state, states, res)
    out = tuple(_analyse(c, basis, coverage, fanout, int(n_directions), seed, int(max_measured_pairs), reflectance_rtol, state,
                         fit_kwargs) for c in conds)
    return VariabilityResult(out, coverage, basis, fanout, state, time.perf_counter() - start)
