"""The dynamic-BRDF paper's validation protocol, on a synthetic truth, and the evidence
behind the fitting defaults.

Truth: :class:`SyntheticGroovedMetal`, an analytic anisotropic lobe (elongated along the
grooves) whose peak drops and broadens as the metal oxidises - the trend of Bailey et
al. 2008, Table I - not a spherical-harmonic model, so fits cannot be exact by
construction. Measurements: the witness-screen forward simulator
(:func:`brdfmodels.screen.simulate_test`) with noise, reduced by
:func:`brdfmodels.screen.reduce_test`.

Protocol (paper Sec. V, spec `dynamic-sh-brdf.md` section 13): fit with incidence -20,
0.3, 5, 20, 40 deg (grooves horizontal) and 20 deg (grooves vertical); predict the
held-out 10 and 30 deg (horizontal) and 40 deg (vertical) tests; fit two states and
predict the state between them.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np

from .models import BRDFModel
from .parallel import blas_one_thread
from .screen import Samples, reduce_test, simulate_test
from .sh import SHBasis

__all__ = [
    "SyntheticGroovedMetal",
    "FIT_TESTS",
    "HELD_OUT_TESTS",
    "protocol_samples",
    "prediction_error",
    "run_protocol",
    "select_fit_defaults",
    "choose_sh_basis",
    "cheapest_within",
    "order_error_table",
    "DEFAULT_LH_MAXES",
    "DEFAULT_MH_MAXES",
    "DEFAULT_FANOUTS",
    "DEFAULT_BASIS_TOLERANCE",
]

FIT_TESTS = ((-20.0, 0.0), (0.3, 0.0), (5.0, 0.0), (20.0, 0.0), (40.0, 0.0), (20.0, 90.0))  # (incidence, groove angle) deg
HELD_OUT_TESTS = ((10.0, 0.0), (30.0, 0.0), (40.0, 90.0))


class SyntheticGroovedMetal(BRDFModel):
    """Analytic anisotropic, state-dependent BRDF (a test truth, not registered).

    ``f_r = kd(s) + ks(s) exp(-(hx^2/ax(s)^2 + hy^2/ay(s)^2) / hz^2) / (4 pi ax ay hz^4 cos_i cos_r)^(1/2)``
    style lobe in half-vector slopes (Ward-like, reciprocal), x along the grooves. The
    state s is oxide extinction in [0.311, 1.5]: ks falls as exp(-(s - 0.311)), the lobe
    widths grow by 60 % per unit s, the diffuse part grows slightly.
    """

    def __init__(self, ks=0.5, kd=0.03, ax=0.06, ay=0.15):
        self.ks, self.kd, self.ax, self.ay = float(ks), float(kd), float(ax), float(ay)
        self._freeze()

    @property
    def is_dynamic(self):
        return True

    @property
    def state_name(self):
        return "extinction"

    @property
    def state_range(self):
        return (0.311, 1.5)

    def _fr(self, wi, wo, state):
        s = np.asarray(state, float)
        grow = 1.0 + 0.6 * (s - 0.311)
        ks = self.ks * np.exp(-(s - 0.311))
        ax, ay = self.ax * grow, self.ay * grow
        h = wi + wo
        h = h / np.linalg.norm(h, axis=1, keepdims=True)
        hz = np.maximum(h[:, 2], 1e-12)
        e = (h[:, 0] ** 2 / ax**2 + h[:, 1] ** 2 / ay**2) / hz**2
        ward = np.exp(-e) / (4 * math.pi * ax * ay * np.sqrt(np.maximum(wi[:, 2] * wo[:, 2], 1e-300)))
        return self.kd * (1 + 0.3 * (s - 0.311)) / math.pi + ks * ward

    def _params(self):
        return {"ks": self.ks, "kd": self.kd, "ax": self.ax, "ay": self.ay}


def protocol_samples(truth=None, *, tests=FIT_TESTS, times_s=(0.0, 5.0, 10.0), noise=0.02, pixels=(72, 72), seed=0) -> Samples:
    """Simulated, reduced witness-screen samples of ``tests`` (incidence, groove) at
    ``times_s``; the state rises linearly from 0.311 at t = 0 to 1.5 at t = 10 s."""
    truth = truth or SyntheticGroovedMetal()
    parts = []
    for k, (inc, groove) in enumerate(tests):
        t = simulate_test(truth, test_id=f"{inc:g}deg-g{groove:g}", incidence_deg=inc, groove_angle_deg=groove, times_s=times_s,
                          state_of_time=lambda tt: 0.311 + (1.5 - 0.311) * tt / 10.0, temperature_of_time=lambda tt: 300.0 + 100.0 * tt,
                          pixels=pixels, noise=noise, seed=seed + k, gain_counts=400.0)
        parts.append(reduce_test(t))
    return Samples.concatenate(parts)


def prediction_error(model, samples: Samples, state=None) -> dict:
    """Held-out error of a model against samples: RMS of ln(f_model / f_data) and the
    relative RMS sqrt(mean(((f_model - f_data)/f_data)^2))."""
    f = model.evaluate(samples.wi, samples.wo, state=state)
    d = samples.brdf_per_sr
    ok = f > 0
    log_rms = float(np.sqrt(np.mean(np.log(f[ok] / d[ok]) ** 2))) if np.any(ok) else math.inf
    return {"log_rms": log_rms, "relative_rms": float(np.sqrt(np.mean(((f - d) / d) ** 2)))}


@dataclass
class ProtocolResult:
    per_test: list  # rows: test, time_s, log_rms, relative_rms
    interpolation: dict
    fit_summary: dict

    def table(self):
        return self.per_test


def run_protocol(basis=None, *, fanout=0.6, noise=0.02, seed=0, **fit_kwargs) -> ProtocolResult:
    """Fit the protocol's fit tests at t = 0, 5, 10 s as a dynamic SH model (state = time),
    report the error on each held-out test and time, and the error of interpolating the
    t = 0 and t = 10 fits to t = 5 s."""
    from .fitting import fit_dynamic_sh

    basis = basis or SHBasis(8, 4, 2, 0)
    truth = SyntheticGroovedMetal()
    fit_s = protocol_samples(truth, noise=noise, seed=seed)
    held = protocol_samples(truth, tests=HELD_OUT_TESTS, noise=noise, seed=seed + 100)
    dyn = fit_dynamic_sh(fit_s, basis, [0.0, 5.0, 10.0], state="time_s", fanout=fanout, **fit_kwargs)
    rows = []
    for tid in np.unique(held.test_id):
        for t in (0.0, 5.0, 10.0):
            sel = held.select((held.test_id == tid) & (held.time_s == t))
            rows.append({"test": str(tid), "time_s": t, **prediction_error(dyn.model, sel, state=t)})
    ends = fit_dynamic_sh(fit_s.select(fit_s.time_s != 5.0), basis, [0.0, 10.0], state="time_s", fanout=fanout, **fit_kwargs)
    mid = held.select(held.time_s == 5.0)
    interp = {"interpolated_0_10_to_5": prediction_error(ends.model, mid, state=5.0),
              "fitted_at_5": prediction_error(dyn.model, mid, state=5.0)}
    return ProtocolResult(rows, interp, {"samples": len(fit_s), "coefficients": basis.size})


def select_fit_defaults(*, rconds=(1e-1, 1e-2, 1e-3, 1e-4, 1e-6), horizon_weights=(0.0, 0.01, 0.1, 1.0), basis=None, seed=0) -> list:
    """Held-out prediction error of single-state fits for each (rcond, horizon weight):
    the evidence the defaults of :func:`brdfmodels.fitting.fit_sh` were chosen from.

    Trains on the protocol's fit tests at t = 0 and scores on the held-out tests at t = 0,
    reporting the training residual beside it (small training residuals with large
    held-out errors are the spurious lobes of unregularised fits)."""
    from .fitting import fit_sh

    basis = basis or SHBasis(8, 4, 2, 0)
    truth = SyntheticGroovedMetal()
    fit_s = protocol_samples(truth, times_s=(0.0,), seed=seed)
    held = protocol_samples(truth, tests=HELD_OUT_TESTS, times_s=(0.0,), seed=seed + 100)
    # also score a coarse full-hemisphere grid of the truth: where nothing was measured
    rng = np.random.default_rng(seed)
    n = 4000
    wi = _hemisphere(rng, n, 0.05)
    wo = _hemisphere(rng, n, 0.05)
    f_true = truth.evaluate(wi, wo, state=0.311)
    rows = []
    for rc in rconds:
        for hw in horizon_weights:
            r = fit_sh(fit_s.wi, fit_s.wo, fit_s.brdf_per_sr, basis, rcond=rc, horizon=hw > 0, horizon_weight=hw)
            lf = np.log(np.maximum(r.model.evaluate(wi, wo), 1e-300) / f_true)
            rows.append({
                "rcond": rc,
                "horizon_weight": hw,
                "train_log_rms": r.residual_rms,
                "held_out_log_rms": prediction_error(r.model, held)["log_rms"],
                "hemisphere_log_rms": float(np.sqrt(np.mean(lf**2))),
                "hemisphere_median_abs_log": float(np.median(np.abs(lf))),
                "pruned_modes": r.pruned_modes,
            })
    return rows


def _hemisphere(rng, n, min_cos):
    c = rng.uniform(min_cos, 1.0, n)
    p = rng.uniform(-math.pi, math.pi, n)
    s = np.sqrt(1 - c * c)
    return np.stack([s * np.cos(p), s * np.sin(p), c], 1)


# Default grid and tolerance of choose_sh_basis (docs/fit-defaults.md, "Choosing the
# basis"; README "basis is chosen by what it predicts"). On six grooved-metal truths the
# leave-one-test-out error was lowest at lh_max 8-12 and kept falling up to mh_max 8;
# lh_max 18-20 changed no choice, and fan-outs 0.5 and 0.7 made the choice worse on five
# of them. The score is the worst fold, not the mean (issue 32 item 5): on the unsaturated
# moving-lobe truth of tests/validation/test_sh_basis_peak.py the mean's choice, (10, 8,
# 0.4), predicted the 40 deg vertical-groove held-out test to 0.54 log-RMS; the worst
# fold's at tolerance 0.1, (8, 8, 0.4), to 0.25 (every held-out set and state <= 0.25),
# and on the grooved metal it keeps the earlier choice (10, 6, 0.6), 0.18. Tolerance 0.2-0.3
# picks (8, 6, 0.4) there: 0.29, too close to the 0.30 goal.
DEFAULT_LH_MAXES = (4, 6, 8, 10, 12, 14, 16)
DEFAULT_MH_MAXES = (0, 2, 4, 6, 8)
DEFAULT_FANOUTS = (0.4, 0.6, 0.8)
# Tikhonov smoothing (issue 32 item 5, later round): every fit is regularised by
# alpha N sum (l(l+1))^2 c^2 with alpha from this decade grid, chosen by the same folds, and
# the setting with the lowest worst fold wins (tolerance 0). On every truth of
# docs/fit-defaults.md (peak table and the camera-sampled grooved metal) its choice predicts
# every held-out set to <= 0.25; alpha = 0 in the grid let the camera grooved metal pick an
# unregularised (12, 6, 0.6), 0.58, and tolerances 0.05-0.1 picked 0.31-0.32 on one lobe.
DEFAULT_BASIS_TOLERANCE = 0.0
DEFAULT_SMOOTHINGS = (1e-7, 1e-6, 1e-5, 1e-4, 1e-3)
_FAST_FIT_OPTIONS = ("rcond", "horizon", "horizon_weight", "log", "method", "smoothing_power")
_EVAL_PAIRS = 100_000


def choose_sh_basis(samples: Samples, *, lh_maxes=DEFAULT_LH_MAXES, mh_maxes=DEFAULT_MH_MAXES, fanouts=DEFAULT_FANOUTS,
                    ld_max=2, md_max=0, tolerance=DEFAULT_BASIS_TOLERANCE, state=None, states=None, progress=None,
                    smoothings=DEFAULT_SMOOTHINGS, **fit_kwargs):
    """Basis orders, fan-out and smoothing strength by leave-one-test-out
    cross-validation, scored by the worst held-out test.

    Each test (one incidence and groove orientation) is held out in turn and predicted by
    a :func:`brdfmodels.fitting.fit_sh` fit of the others (per state group when ``state``
    is given). A setting's score is its worst fold: the out-of-plane (other groove
    orientation) and extrapolating tests count as much as the in-plane ones, which
    outnumber them in the paper's protocol (5 of 6) and dominate a mean.

    Parameters
    ----------
    samples : Samples
        Reduced measurements of at least two tests (``test_id``).
    lh_maxes, mh_maxes : sequence of int
        Halfway degrees and orders to try (pairs with ``mh_max > lh_max`` are skipped).
    fanouts : sequence of float
        Fan-out exponents to try.
    ld_max, md_max : int
        Difference-angle orders (fixed).
    tolerance : float
        The chosen setting is the cheapest (fewest coefficients) whose worst-fold error is
        at most ``(1 + tolerance)`` times the lowest (default 0: the lowest; the
        smoothing, not the basis size, limits what the fit does beyond the data).
    state : str, optional
        A state column (``"time_s"``, ``"temperature_k"``, a named state): the folds are
        made within each state group, and the worst is over every group's folds (one
        basis for the whole dynamic model, as :func:`brdfmodels.fitting.fit_dynamic_sh`
        fits). Without it all samples are one state.
    states : array_like, optional
        The state nodes samples are grouped to (default: the column's distinct values).
    progress : callable, optional
        Called with (settings done, settings) before each setting and at the end.
    smoothings : sequence of float
        Tikhonov strengths alpha >= 0 to try per basis (``fit_sh``'s ``smoothing``;
        default ``DEFAULT_SMOOTHINGS``, 1e-7 to 1e-3; ``(0.0,)`` with ``tolerance=0.1``
        is the earlier truncated-SVD selection).
    **fit_kwargs
        Passed on to ``fit_sh``: ``rcond``, ``horizon``, ``horizon_weight``, ``log``,
        ``method``, ``smoothing_power``.

    Returns
    -------
    best : dict
        The chosen row of ``table``.
    table : list of dict
        Every setting fitted: ``lh_max, mh_max, fanout, smoothing, coefficients``,
        ``worst_fold_log_rms`` (the score), ``held_out_log_rms`` (mean over the folds),
        ``fold_log_rms`` (fold name -> error; ``"<test>@<state>"`` with ``state``),
        ``fit_time_s`` (one ``fit_sh`` of all samples (of the first state group) with that
        basis) and ``eval_s_per_1e6`` (evaluating it at 1e6 direction pairs); BLAS runs on
        one thread throughout (the evaluation's blocks still run on threads).

    Notes
    -----
    With ``method="tsvd"`` (the default) the folds are solved without refitting. Every
    basis of the grid is a subset of the columns of the largest (lh, mh), so per fan-out
    each test's weighted design rows of that basis are reduced once to a QR factor; a
    fold stacks the other tests' factors and the horizon rows' and factors them again
    (B = Q R). A basis's fold matrix is then Q R[:, cols], and the truncated SVD of the
    small R[:, cols] (with the smoothing rows stacked under it) gives the same
    coefficients as ``fit_sh`` on the fold, up to rounding
    (``tests/brdfmodels/test_basis_selection.py``). A log fold's error is computed from
    the held-out test's own design rows.
    """
    groups = _state_groups(samples, state, states)
    splits = {g: _loto_split(s) for g, s in groups.items()}
    lh_maxes, mh_maxes, fanouts, tolerance = _check_grid(lh_maxes, mh_maxes, fanouts, tolerance)
    opts = _fit_options(fit_kwargs)
    smoothings = _check_smoothings(smoothings)
    settings = [(fan, mh, lh) for fan in fanouts for mh in mh_maxes for lh in lh_maxes if mh <= lh]
    master = SHBasis(max(lh_maxes), max(mh for _, mh, _ in settings), ld_max, md_max)
    rng = np.random.default_rng(0)
    pairs = (_hemisphere(rng, _EVAL_PAIRS, 0.05), _hemisphere(rng, _EVAL_PAIRS, 0.05))
    data = {g: _fold_data(s, opts) for g, s in groups.items()} if opts["method"] == "tsvd" else None
    costs, table, solvers = {}, [], {}
    with blas_one_thread():  # small factorizations: BLAS threads gain nothing and contend (3.7 s vs 3.8-12 s)
        for done, (fan, mh, lh) in enumerate(settings):
            if progress is not None:
                progress(done, len(settings))
            basis = SHBasis(lh, mh, ld_max, md_max)
            if any(int(np.sum(~m)) < basis.size for tests, _ in splits.values() for m in tests):
                continue  # a fold with fewer samples than coefficients: fit_sh refuses it
            if data is not None and (not solvers or next(iter(solvers.values())).fanout != fan):
                solvers = {g: _FoldSolver(data[g], splits[g][0], fan, master, opts) for g in groups}
            if (lh, mh) not in costs:  # fit and evaluation cost depend on the basis, not the fan-out
                costs[(lh, mh)] = _basis_costs(next(iter(groups.values())), basis, fan, fit_kwargs, pairs)
            for sm in smoothings:
                folds = _group_fold_errors(groups, splits, solvers, basis, fan, {**fit_kwargs, "smoothing": sm}, state is not None)
                table.append({"lh_max": lh, "mh_max": mh, "fanout": fan, "smoothing": sm, "coefficients": basis.size,
                              "worst_fold_log_rms": max(folds.values()), "held_out_log_rms": float(np.mean(list(folds.values()))),
                              "fold_log_rms": folds, "fit_time_s": costs[(lh, mh)][0], "eval_s_per_1e6": costs[(lh, mh)][1]})
    if progress is not None:
        progress(len(settings), len(settings))
    if not table:
        raise ValueError(f"choose_sh_basis: {len(samples)} samples; every basis in the grid has more coefficients than a "
                         "leave-one-test-out fold has samples: give more samples or smaller lh_maxes/mh_maxes")
    fan_rank = {f: i for i, f in enumerate(fanouts)}
    table.sort(key=lambda r: (r["lh_max"], r["mh_max"], fan_rank[r["fanout"]], r["smoothing"]))
    return cheapest_within(table, tolerance), table


def _state_groups(samples, state, states):
    """state value (None: one group) -> Samples, for per-state leave-one-test-out."""
    if state is None:
        if states is not None:
            raise ValueError(f"states={states!r}: given without state; expected a state column name too")
        return {None: samples}
    from .screen import group_by_state, state_column

    nodes = np.unique(state_column(samples, state)) if states is None else states
    if np.size(nodes) > 50:
        raise ValueError(f"state={state!r}: {np.size(nodes)} distinct values; expected at most 50 state nodes (give states=)")
    return group_by_state(samples, state, nodes)


def _group_fold_errors(groups, splits, solvers, basis, fan, fit_kwargs, named):
    """Fold name -> held-out log-RMS of every test of every state group."""
    out = {}
    for g, s in groups.items():
        tests, held = splits[g]
        if solvers.get(g) is None:
            errs = _fold_errors_fit_sh(s, tests, held, basis, fan, fit_kwargs)
        else:
            errs = solvers[g].fold_errors(basis, fit_kwargs.get("smoothing", 0.0), held)
        for test, e in zip(held, errs):
            out[f"{test.test_id[0]}@{g:g}" if named else str(test.test_id[0])] = float(e)
    return out


def cheapest_within(table, tolerance, key="worst_fold_log_rms"):
    """The selection rule of :func:`choose_sh_basis`.

    Parameters
    ----------
    table : list of dict
        Rows with ``coefficients`` and ``key``.
    tolerance : float
        Relative slack on the lowest error.
    key : str
        The error column the rule reads (default: the worst fold's log-RMS).

    Returns
    -------
    dict
        The row with the fewest coefficients whose ``key`` is at most
        ``(1 + tolerance)`` times the lowest (ties: the lower error).
    """
    best_err = min(r[key] for r in table)
    good = [r for r in table if r[key] <= best_err * (1 + tolerance)]
    return min(good, key=lambda r: (r["coefficients"], r[key]))


def _loto_split(samples):
    """Masks of each test and the held-out samples of each, for leave-one-test-out."""
    ids = np.unique(samples.test_id)
    if len(ids) < 2:
        raise ValueError(f"choose_sh_basis: {len(ids)} test(s); leave-one-test-out needs at least 2")
    masks = [samples.test_id == t for t in ids]
    return masks, [samples.select(m) for m in masks]


def _check_grid(lh_maxes, mh_maxes, fanouts, tolerance):
    """Validated grid: tuples of orders and fan-outs, and the tolerance."""
    from ._checks import finite_scalar

    orders = []
    for name, seq in (("lh_maxes", lh_maxes), ("mh_maxes", mh_maxes)):
        vals = tuple(seq) if isinstance(seq, (tuple, list, range, np.ndarray)) else ()
        if not vals or not all(isinstance(v, (int, np.integer)) and not isinstance(v, bool) and v >= 0 for v in vals):
            raise ValueError(f"{name}={seq!r}: expected a non-empty sequence of integers >= 0")
        orders.append(tuple(int(v) for v in vals))
    if not isinstance(fanouts, (tuple, list, np.ndarray)) or len(fanouts) == 0:
        raise ValueError(f"fanouts={fanouts!r}: expected a non-empty sequence of numbers > 0")
    fans = tuple(finite_scalar("fanouts", f, minimum=0.0, strict_min=True) for f in fanouts)
    if not any(mh <= lh for lh in orders[0] for mh in orders[1]):
        raise ValueError(f"mh_maxes={mh_maxes!r}: every order exceeds every lh_max in {lh_maxes!r}; no basis to try")
    return orders[0], orders[1], fans, finite_scalar("tolerance", tolerance, minimum=0.0)


def _check_smoothings(smoothings):
    """Validated tuple of Tikhonov strengths (>= 0) to try."""
    from ._checks import finite_scalar

    if not isinstance(smoothings, (tuple, list, np.ndarray)) or len(smoothings) == 0:
        raise ValueError(f"smoothings={smoothings!r}: expected a non-empty sequence of numbers >= 0")
    return tuple(finite_scalar("smoothings", v, minimum=0.0) for v in smoothings)


def _fit_options(fit_kwargs):
    """fit_sh's options as the fold solver uses them (its defaults, its checks)."""
    from ._checks import finite_scalar
    from .fitting import DEFAULT_HORIZON_WEIGHT

    unknown = sorted(set(fit_kwargs) - set(_FAST_FIT_OPTIONS))
    if unknown:
        raise ValueError(f"choose_sh_basis: unknown fit_sh options {unknown}; expected some of {list(_FAST_FIT_OPTIONS)}")
    rc, hw = fit_kwargs.get("rcond"), fit_kwargs.get("horizon_weight")
    method = fit_kwargs.get("method", "tsvd")
    if method not in ("tsvd", "constrained"):
        raise ValueError(f"method={method!r}: expected 'tsvd' or 'constrained'")
    return {"rcond": None if rc is None else finite_scalar("rcond", rc, minimum=0.0, maximum=1.0),  # None: fit_sh's default
            "horizon_weight": DEFAULT_HORIZON_WEIGHT if hw is None else finite_scalar("horizon_weight", hw, minimum=0.0),
            "horizon": bool(fit_kwargs.get("horizon", True)), "log": bool(fit_kwargs.get("log", True)), "method": method,
            "smoothing_power": finite_scalar("smoothing_power", fit_kwargs.get("smoothing_power", 2.0), minimum=0.0)}


def _fold_errors_fit_sh(samples, tests, held, basis, fanout, fit_kwargs):
    """Held-out log-RMS of each fold by fitting it with fit_sh (methods other than tsvd)."""
    from .fitting import fit_sh

    errs = []
    for m, test in zip(tests, held):
        train = samples.select(~m)
        r = fit_sh(train.wi, train.wo, train.brdf_per_sr, basis, fanout=fanout, weights=train.weight, **fit_kwargs)
        errs.append(prediction_error(r.model, test)["log_rms"])
    return errs


def _basis_costs(samples, basis, fanout, fit_kwargs, pairs):
    """Seconds of one fit_sh of all samples, and of evaluating the fit per 1e6 pairs."""
    from .fitting import fit_sh

    t0 = time.perf_counter()
    r = fit_sh(samples.wi, samples.wo, samples.brdf_per_sr, basis, fanout=fanout, weights=samples.weight, **fit_kwargs)
    fit_s = time.perf_counter() - t0
    t0 = time.perf_counter()
    r.model.evaluate(*pairs)
    return fit_s, (time.perf_counter() - t0) * 1e6 / len(pairs[0])


def _fold_data(samples, opts):
    """Checked directions, f_r, weights and the fitted quantity (ln f~ or f~), as fit_sh has them."""
    from .fitting import check_fit_data

    wi, wo, f, w = check_fit_data(samples.wi, samples.wo, samples.brdf_per_sr, samples.weight)
    if opts["log"] and np.any(f <= 0):
        raise ValueError(f"brdf_per_sr: {int((f <= 0).sum())} values <= 0 cannot enter a log fit; mask them first")
    ft = wi[:, 2] * wo[:, 2] * f
    return wi, wo, f, w, (np.log(ft) if opts["log"] else ft)


class _FoldSolver:
    """Truncated-SVD fits of every leave-one-test-out fold, for one fan-out and any basis
    whose columns are among ``master``'s, from QR factors (see :func:`choose_sh_basis`)."""

    def __init__(self, data, tests, fanout, master, opts):
        wi, wo, f, w, y = data
        self.fanout, self.opts, self.master = fanout, opts, master
        self.index = {c: i for i, c in enumerate(master.columns)}
        designs = [self.master.evaluate_directions(wi[m], wo[m], fanout=fanout) for m in tests]
        # each test's own design rows and ln(cos_i cos_r), for its held-out error (log fits)
        self.held = [(a, np.log(wi[m][:, 2] * wo[m][:, 2])) for a, m in zip(designs, tests)] if opts["log"] else None
        per_test = [self._factor(a, y[m], np.sqrt(w[m])) for a, m in zip(designs, tests)]
        horizon = self._horizon_factor() if opts["horizon"] and opts["horizon_weight"] > 0 else None
        self.folds = [self._merge(per_test, k, ~m, f, w, horizon) for k, m in enumerate(tests)]
        self.n_train = [int(np.sum(~m)) for m in tests]

    def _factor(self, a, y, sw):
        """R and Q^T z of one test's weighted design rows."""
        q, r = np.linalg.qr(a * sw[:, None])
        return r, q.T @ (y * sw)

    def _horizon_factor(self):
        """R of the horizon rows and Q^T of their ln(cos_i cos_r) and of ones."""
        from .fitting import horizon_directions

        hwi, hwo = horizon_directions()
        q, r = np.linalg.qr(self.master.evaluate_directions(hwi, hwo, fanout=self.fanout))
        return r, q.T @ np.log(hwi[:, 2] * hwo[:, 2]), q.T @ np.ones(len(hwi)), len(hwi)

    def _merge(self, per_test, k, train, f, w, horizon):
        """One fold's R and Q^T z: the other tests' factors (weights normalised to the
        fold's mean, as fit_sh does) and the horizon rows with the fold's floor."""
        scale = 1.0 / math.sqrt(float(w[train].mean()))
        rs = [r * scale for j, (r, _) in enumerate(per_test) if j != k]
        cs = [c * scale for j, (_, c) in enumerate(per_test) if j != k]
        if horizon is not None:
            r_h, c_log, c_one, n_h = horizon
            sw_h = math.sqrt(self.opts["horizon_weight"] * int(train.sum()) / n_h)
            rs.append(r_h * sw_h)
            cs.append(sw_h * (c_log + math.log(float(f[train].min())) * c_one) if self.opts["log"] else np.zeros(len(r_h)))
        q, r = np.linalg.qr(np.vstack(rs))
        return r, q.T @ np.concatenate(cs)

    def fold_errors(self, basis, smoothing, held):
        """Held-out log-RMS of each fold's fit: for log fits from the held-out test's own
        design rows (ln f_model = min(A c - ln(cos_i cos_r), ln FR_MAX), as the model
        evaluates it), otherwise by evaluating the models."""
        from .models import FR_MAX

        models = self.models(basis, smoothing)
        if self.held is None:
            return [prediction_error(model, test)["log_rms"] for model, test in zip(models, held)]
        cols = [self.index[c] for c in basis.columns]
        out = []
        for model, (a, log_cos), test in zip(models, self.held, held):
            ln_f = np.minimum(a[:, cols] @ model.coefficients - log_cos, math.log(FR_MAX))
            out.append(float(np.sqrt(np.mean((ln_f - np.log(test.brdf_per_sr)) ** 2))))
        return out

    def models(self, basis, smoothing=0.0):
        """The fit of each fold with ``basis``: the fold's rows times ``basis``'s columns
        are Q R[:, cols], so their SVD is Q times that of R[:, cols] (with ``smoothing``,
        the penalty rows of :func:`brdfmodels.fitting.smoothing_rows` stacked under it)."""
        from .fitting import default_rcond, smoothing_rows

        from .models import SphericalHarmonicBRDF

        missing = [c for c in basis.columns if c not in self.index]
        if missing:
            raise ValueError(f"basis={basis!r}: columns {missing[:3]} are not in the fold solver's {self.master!r}")
        cols = [self.index[c] for c in basis.columns]
        out = []
        for (r, d), n in zip(self.folds, self.n_train):
            r = r[:, cols]
            if smoothing > 0:
                r = np.vstack([r, smoothing_rows(basis, smoothing, self.opts["smoothing_power"], n)])
                d = np.concatenate([d, np.zeros(len(cols))])
            u, s, vt = np.linalg.svd(r, full_matrices=False)
            rcond = default_rcond(smoothing) if self.opts["rcond"] is None else self.opts["rcond"]
            keep = s > rcond * s[0]
            coef = vt[keep].T @ ((u[:, keep].T @ d) / s[keep])
            out.append(SphericalHarmonicBRDF(basis, coef, fanout=self.fanout, log=self.opts["log"]))
        return out


def order_error_table(*, lh_maxes=(4, 6, 8, 10, 12, 16), mh_maxes=(0, 2, 4, 6), seed=0, eval_points=200_000) -> list:
    """Held-out error, fit time and evaluation time per 1e6 directions over harmonic orders
    (single state, the protocol's fit and held-out tests)."""
    from .fitting import fit_sh

    truth = SyntheticGroovedMetal()
    fit_s = protocol_samples(truth, times_s=(0.0,), seed=seed)
    held = protocol_samples(truth, tests=HELD_OUT_TESTS, times_s=(0.0,), seed=seed + 100)
    rng = np.random.default_rng(seed)
    wi, wo = _hemisphere(rng, eval_points, 0.05), _hemisphere(rng, eval_points, 0.05)
    rows = []
    for lh in lh_maxes:
        for mh in mh_maxes:
            if mh > lh:
                continue
            basis = SHBasis(lh, mh, 2, 0)
            r = fit_sh(fit_s.wi, fit_s.wo, fit_s.brdf_per_sr, basis)
            t0 = time.perf_counter()
            r.model.evaluate(wi, wo)
            t_eval = (time.perf_counter() - t0) * 1e6 / eval_points
            rows.append({"lh_max": lh, "mh_max": mh, "coefficients": basis.size, "held_out_log_rms": prediction_error(r.model, held)["log_rms"],
                         "fit_time_s": r.fit_time_s, "eval_s_per_1e6": t_eval})
    return rows
