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
    "order_error_table",
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


def choose_sh_basis(samples: Samples, *, lh_maxes=(4, 6, 8, 10), mh_maxes=(0, 2, 4), fanouts=(0.4, 0.6, 0.8), ld_max=2, md_max=0,
                    tolerance=0.05, progress=None, **fit_kwargs):
    """Basis orders and fan-out by leave-one-test-out cross-validation.

    Each test (one incidence and groove orientation) is held out in turn; the mean
    held-out log-RMS error is the score. Returns ``(best, table)``: the cheapest setting
    (fewest coefficients) within ``tolerance`` of the lowest error, and the table of every
    setting (error, coefficients, fit time) it was chosen from. ``progress``, if given,
    is called with (settings done, settings) before each (orders, fan-out) setting and at
    the end.
    """
    from .fitting import fit_sh

    tests = np.unique(samples.test_id)
    if len(tests) < 2:
        raise ValueError(f"choose_sh_basis: {len(tests)} test(s); leave-one-test-out needs at least 2")
    table = []
    total = sum(mh <= lh for lh in lh_maxes for mh in mh_maxes) * len(fanouts)
    done = 0
    for lh in lh_maxes:
        for mh in mh_maxes:
            if mh > lh:
                continue
            basis = SHBasis(lh, mh, ld_max, md_max)
            eval_s = None
            for fan in fanouts:
                if progress is not None:
                    progress(done, total)
                done += 1
                errs, t_fit = [], 0.0
                ok = True
                for tid in tests:
                    train = samples.select(samples.test_id != tid)
                    test = samples.select(samples.test_id == tid)
                    if len(train) < basis.size:
                        ok = False
                        break
                    t0 = time.perf_counter()
                    r = fit_sh(train.wi, train.wo, train.brdf_per_sr, basis, fanout=fan, weights=train.weight, **fit_kwargs)
                    t_fit += time.perf_counter() - t0
                    errs.append(prediction_error(r.model, test)["log_rms"])
                if ok:
                    if eval_s is None:  # evaluation cost depends on the basis, not the fan-out
                        rng = np.random.default_rng(0)
                        d1, d2 = _hemisphere(rng, 100_000, 0.05), _hemisphere(rng, 100_000, 0.05)
                        t0 = time.perf_counter()
                        r.model.evaluate(d1, d2)
                        eval_s = (time.perf_counter() - t0) * 10.0
                    table.append({"lh_max": lh, "mh_max": mh, "fanout": fan, "coefficients": basis.size,
                                  "held_out_log_rms": float(np.mean(errs)), "fit_time_s": t_fit / len(tests),
                                  "eval_s_per_1e6": eval_s})
    if progress is not None:
        progress(total, total)
    best_err = min(r["held_out_log_rms"] for r in table)
    good = [r for r in table if r["held_out_log_rms"] <= best_err * (1 + tolerance)]
    best = min(good, key=lambda r: (r["coefficients"], r["held_out_log_rms"]))
    return best, table


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
