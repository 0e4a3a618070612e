"""Scattered tables are conservative between samples: a lobe whose peak falls between the
measured directions comes out at its peak value, not the 0.3-0.9 of it that a linear
interpolation gives (issue 32). Truths typed in here: Gaussian lobes in direction cosines
(X = beta_i + beta_o, Harvey's beta - beta0, taken along and across D = beta_o - beta_i:
reciprocal), of several widths, elliptic, and a pair off the mirror direction; measured
on a goniometer grid (incidences every 10 deg; theta_r, phi_r every 5 deg from 2.5 deg, so
the mirror direction itself is never a sample).

Stated here and checked: at the true peak (incidences 15-60 deg, away from normal
incidence where the direction-cosine coordinates are singular) the model is at least
``1 - PEAK_TOL`` of the truth when the lobe's width is at least the spacing in X (5 deg:
0.087; the random lobes from 0.12); everywhere it lies between the barycentric value and
PEAK_CAP times it (measured: the cap is reached at a few random pairs, 4x above both the
truth and the barycentric value). The barycentric value alone fails the first check
(shown)."""

from __future__ import annotations


import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import brdfmodels as bm
from brdfmodels.scattered import PEAK_CAP

PEAK_TOL = 0.05  # the model at a true peak is at least 0.95 of it (measured: 0.964 at worst; width 0.1: 0.976)
FLOOR, HEIGHT = 0.05, 5.0  # [1/sr]


def _sph(theta_deg, phi_deg):
    t, p = np.radians(theta_deg), np.radians(phi_deg)
    return np.stack([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)], axis=-1)


def _along_across(wi, wo):
    """X = beta_i + beta_o along and across D = beta_o - beta_i (x for D = 0)."""
    x, d = wi[..., :2] + wo[..., :2], wo[..., :2] - wi[..., :2]
    n = np.hypot(d[..., 0], d[..., 1])
    e = np.where(n[..., None] > 1e-12, d / np.where(n > 1e-12, n, 1.0)[..., None], [1.0, 0.0])
    return np.sum(x * e, axis=-1), x[..., 0] * e[..., 1] - x[..., 1] * e[..., 0]


def lobe(s_along, s_across, x0):
    """FLOOR + HEIGHT exp(-((a - x0) / s_along)^2 - (b / s_across)^2) + the same at -x0 (a
    pair when x0 != 0: swapping wi and wo turns (a, b) into (-a, -b); x0 = 0: one lobe of
    twice the height) [1/sr]."""
    def f(wi, wo):
        a, b = _along_across(*np.broadcast_arrays(np.asarray(wi, float), np.asarray(wo, float)))
        g = lambda c: np.exp(-((a - c) / s_along) ** 2 - (b / s_across) ** 2)  # noqa: E731
        return FLOOR + HEIGHT * (g(x0) + g(-x0))
    return f


def _peak_directions(wi, x0):
    """wo at a lobe's centre: beta_o = -beta_i + x0 along -beta_i (then D is along -beta_i too)."""
    n = np.hypot(wi[:, 0], wi[:, 1])
    e = -wi[:, :2] / n[:, None]
    t = -wi[:, :2] + x0 * e
    return np.column_stack([t, np.sqrt(np.clip(1.0 - np.sum(t * t, axis=1), 0.0, None))])  # 0: beyond the horizon


TI, TR, PR = np.arange(0.0, 71.0, 10.0), np.arange(2.5, 88.0, 5.0), np.arange(2.5, 360.0, 5.0)


def _grid(truth, between="peak"):
    ti, tr, pr = (g.ravel() for g in np.meshgrid(TI, TR, PR, indexing="ij"))
    wi, wo = _sph(ti, 0.0 * ti), _sph(tr, pr)
    return bm.ScatteredBRDF.from_samples(wi, wo, truth(wi, wo), between=between)


def _check(s_along, s_across, x0, seed, n=200):
    """The three stated checks; returns the lowest ratio at the peaks of the linear model."""
    truth = lobe(s_along, s_across, x0)
    m, lin = _grid(truth), _grid(truth, "linear")
    rng = np.random.default_rng(seed)
    wi = _sph(rng.uniform(15.0, 60.0, n), rng.uniform(0.0, 360.0, n))
    wo = _peak_directions(wi, x0)
    keep = wo[:, 2] > 0.2
    at_peak = m.evaluate(wi[keep], wo[keep]) / truth(wi[keep], wo[keep])
    assert at_peak.min() >= 1.0 - PEAK_TOL, (s_along, s_across, x0, at_peak.min())
    a, b = _sph(rng.uniform(0, 75, 4000), rng.uniform(0, 360, 4000)), _sph(rng.uniform(0, 85, 4000), rng.uniform(0, 360, 4000))
    v, v_lin = m.evaluate(a, b), lin.evaluate(a, b)
    assert np.all(v >= v_lin * (1 - 1e-12)) and np.all(v <= PEAK_CAP * v_lin * (1 + 1e-12))
    return float(np.min(lin.evaluate(wi[keep], wo[keep]) / truth(wi[keep], wo[keep])))


@pytest.mark.parametrize("s_along, s_across, x0", [(0.1, 0.1, 0.0), (0.25, 0.1, 0.0)])
def test_a_lobe_peaking_between_samples_comes_out_at_its_peak(s_along, s_across, x0):
    """Mirror-direction lobes (round and elliptic) whose peak is never sampled: the linear
    interpolation is low at the peak (down to 0.65 for the narrowest); the default is not."""
    lowest_linear = _check(s_along, s_across, x0, seed=1)
    assert lowest_linear < 1.0 - PEAK_TOL  # the check would fail the barycentric value: it can fail


def test_an_off_mirror_pair_of_lobes_comes_out_at_its_peaks():
    _check(0.15, 0.1, 0.3, seed=2)


@pytest.mark.slow
@pytest.mark.parametrize("s_along, s_across, x0", [(0.2, 0.2, 0.0), (0.1, 0.3, 0.0)])
def test_more_lobes_peaking_between_samples(s_along, s_across, x0):
    assert _check(s_along, s_across, x0, seed=1) < 1.0 - PEAK_TOL


def test_each_sample_is_still_exact_and_the_model_reciprocal():
    truth = lobe(0.12, 0.2, 0.1)
    ti, tr, pr = (g.ravel() for g in np.meshgrid(TI, TR, PR, indexing="ij"))
    wi, wo = _sph(ti, 0.0 * ti), _sph(tr, pr)
    m = _grid(truth)
    np.testing.assert_allclose(m.evaluate(wi, wo), truth(wi, wo), rtol=1e-6)  # the joggle: 4.6e-7 here, linear alike
    a, b = _sph(np.full(300, 35.0), np.linspace(0, 360, 300)), _sph(np.full(300, 40.0), np.linspace(180, 200, 300))
    np.testing.assert_allclose(m.evaluate(b, a), m.evaluate(a, b), rtol=1e-12)


PROPS = dict(derandomize=True, deadline=None, database=None)


@settings(max_examples=2, **PROPS)
@given(st.floats(0.12, 0.3), st.floats(0.12, 0.3), st.floats(0.0, 0.4), st.integers(0, 1000))
def test_random_lobe_centres_and_widths(s_along, s_across, x0, seed):
    _check(s_along, s_across, x0, seed, n=60)


@pytest.mark.slow
@settings(max_examples=25, **PROPS)
@given(st.floats(0.12, 0.3), st.floats(0.12, 0.3), st.floats(0.0, 0.4), st.integers(0, 1000))
def test_random_lobe_centres_and_widths_many(s_along, s_across, x0, seed):
    _check(s_along, s_across, x0, seed)
