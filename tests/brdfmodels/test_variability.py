"""Sample-to-sample variability: coverage envelopes against order statistics written here.

Samples are generated exactly (noise-free) on a direction grid, or through the
witness-screen simulator, from a truth scaled by known factors a_k. Expected values come
from the formulas: the coverage quantile of the a_k by a sort (smallest a with at least a
fraction c of the a_k at or below it), max/min ratios of the a_k.
"""

import json
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import brdfmodels as bm
from brdfmodels import screen, validation
from brdfmodels.variability import coverage_rank, population_confidence

from .conftest import glossy_log_coefficients

BASIS = bm.SHBasis(4, 0, 2, 0)
TRUTH = bm.SphericalHarmonicBRDF(BASIS, glossy_log_coefficients(BASIS, peak_sr=1.0, width_rad=0.2, diffuse_sr=0.05))


def order_quantile(x, c):
    """Smallest value v of x with (number of x <= v) / n >= c: the sorted list's element
    of rank ceil(c n), found by walking the sorted list (not the engine's code)."""
    xs = sorted(x)
    n = len(xs)
    for i, v in enumerate(xs, start=1):
        if i / n >= c - 1e-12:
            return v
    return xs[-1]


def grid_pairs(incidence_deg=20.0, phi_i_deg=0.0, step_deg=6.0):
    th = np.radians(np.arange(1.0, 80.0, step_deg))
    ph = np.radians(np.arange(0.0, 360.0, 2 * step_deg))
    tt, pp = np.meshgrid(th, ph, indexing="ij")
    wo = bm.spherical_to_vector(tt.ravel(), pp.ravel())
    wi = np.tile(bm.spherical_to_vector(math.radians(incidence_deg), math.radians(phi_i_deg)), (len(wo), 1))
    return wi, wo


def make_samples(models, *, incidence_deg=20.0, phi_i_deg=0.0, prefix="s", time_s=0.0, step_deg=6.0):
    """One test per model, exact f_r on the grid (weights 1)."""
    wi, wo = grid_pairs(incidence_deg, phi_i_deg, step_deg)
    n = len(wo)
    parts = [screen.Samples(wi, wo, m.evaluate(wi, wo), np.full(n, time_s), np.full(n, np.nan),
                            np.full(n, f"{prefix}{k}", dtype=object), np.zeros(n, int), np.ones(n)) for k, m in enumerate(models)]
    return screen.Samples.concatenate(parts)


def scaled(scales, truth=TRUTH, **kw):
    return make_samples([bm.Scaled(truth, float(a)) for a in scales], **kw)


def test_order_quantile_helper_and_rank():
    assert order_quantile([3, 1, 2, 5, 4], 0.8) == 4  # 4 of 5 at or below 4
    assert order_quantile([3, 1, 2, 5, 4], 0.81) == 5
    assert order_quantile(list(range(1, 21)), 0.35) == 7  # 0.35 * 20 = 7.000000000000001 in floats
    for n in range(1, 30):
        for c in (0.05, 0.35, 0.5, 0.8, 0.9, 0.95, 1.0):
            assert coverage_rank(n, c) == order_quantile(list(range(1, n + 1)), c)
    # P(Binomial(K, c) <= r - 1); K = 10, c = 0.95, r = 10: 1 - 0.95^10
    assert population_confidence(10, 10, 0.95) == pytest.approx(1 - 0.95**10, rel=1e-12)
    p = sum(math.comb(20, i) * 0.9**i * 0.1 ** (20 - i) for i in range(18))
    assert population_confidence(20, 18, 0.9) == pytest.approx(p, rel=1e-12)


def test_pure_scale_factors_give_the_quantile_of_the_factors():
    a = np.random.default_rng(7).lognormal(0.0, 0.4, 7)
    c = 0.8
    res = bm.sample_variability(scaled(a), BASIS, coverage=c, n_directions=400)
    cond = res.condition()
    qa = order_quantile(a, c)
    assert cond.rank == 6 and cond.n_samples == 7
    # fits of scaled data are the scaled fit (no pruned mode): quantile = qa x the a=1 fit
    base = cond.values_per_sr[0] / a[0]
    np.testing.assert_allclose(cond.values_per_sr, a[:, None] * base[None, :], rtol=1e-9)
    np.testing.assert_allclose(cond.quantile_per_sr, qa * base, rtol=1e-9)
    np.testing.assert_allclose(cond.max_per_sr, a.max() * base, rtol=1e-9)
    # ... and within the fit's accuracy of qa x truth (fit relative RMS ~ 8 %: horizon tacking)
    truth = TRUTH.evaluate(cond.wi_eval, cond.wo_eval)
    fit_err = cond.fits[0].relative_rms
    assert fit_err < 0.1
    m = cond.measured
    rel = cond.quantile_per_sr[m] / (qa * truth[m]) - 1
    assert np.sqrt(np.mean(rel**2)) == pytest.approx(fit_err, rel=1e-6)  # the same error as the a = 1 fit
    env = cond.coverage_envelope.model.evaluate(cond.wi_eval, cond.wo_eval)
    assert np.all(env >= cond.quantile_per_sr)
    assert np.median(env[m] / (qa * truth[m])) == pytest.approx(1.0, abs=3 * fit_err)
    assert cond.coverage_envelope.median_overprediction < 1 + 1e-6  # the target lies in the basis


def test_spread_ratios_equal_the_scale_ratio():
    a = np.array([0.55, 1.0, 1.7, 0.8, 1.25])
    res = bm.sample_variability(scaled(a), BASIS, coverage=0.6, n_directions=600)
    cond = res.condition()
    s = cond.summary()
    ratio = a.max() / a.min()
    for key in ("reflectance_ratio", "reflectance_measured_cone_ratio", "peak_measured_ratio", "peak_fitted_ratio"):
        assert s[key] == pytest.approx(ratio, rel=1e-9), key
    for key in ("direction_ratio_measured", "direction_ratio_hemisphere"):
        assert all(v == pytest.approx(ratio, rel=1e-9) for v in s[key].values()), key
    # per-direction median = median(a) x base (odd K): relative scale a_k / median(a)
    np.testing.assert_allclose([p["relative_scale"] for p in s["samples"]], a / np.median(a), rtol=1e-9)
    assert all(v == pytest.approx(order_quantile(a, 0.6) / np.median(a), rel=1e-9) for v in s["coverage_over_median"].values())
    # peak of the measured data: a_k x the truth's largest grid value
    wi, wo = grid_pairs()
    np.testing.assert_allclose([p["peak_measured_per_sr"] for p in s["samples"]], a * TRUTH.evaluate(wi, wo).max(), rtol=1e-12)
    # each fit's reflectance: a_k x (the a = 1 fit's), and near the truth's (fit accuracy)
    refl = np.array([p["reflectance"] for p in s["samples"]])
    np.testing.assert_allclose(refl / a, refl[1], rtol=1e-9)
    assert refl[1] == pytest.approx(bm.hemispherical_reflectance(TRUTH, wi[0]).value, rel=0.05)
    # the measured cone: theta_o <= 79 deg, widened by the grid's spacing (6 deg), of the
    # hemisphere's 2 pi sr (a lattice estimate: a few % either way)
    cone = lambda deg: 2 * math.pi * (1 - math.cos(math.radians(deg)))
    assert 0.97 * cone(79.0) <= s["measured_cone_sr"] <= 1.03 * cone(85.0)


def _shape_varied(k, seed=3):
    """Samples that differ in shape, not only scale: each coefficient perturbed."""
    rng = np.random.default_rng(seed)
    c0 = TRUTH.coefficients
    return [bm.SphericalHarmonicBRDF(BASIS, c0 + rng.normal(0.0, 0.25, c0.size)) for _ in range(k)]


@pytest.mark.parametrize("coverage", [0.5, 0.75, 0.95])
def test_quantile_property_at_every_direction(coverage):
    k = 9
    res = bm.sample_variability(make_samples(_shape_varied(k)), BASIS, coverage=coverage, n_directions=300)
    cond = res.condition()
    v = cond.values_per_sr
    # the per-direction quantile is the order statistic of rank ceil(c K), column by column
    expect = np.array([order_quantile(v[:, j], coverage) for j in range(v.shape[1])])
    np.testing.assert_array_equal(cond.quantile_per_sr, expect)
    np.testing.assert_array_equal(cond.quantile_per_sr, np.quantile(v, coverage, axis=0, method="inverted_cdf"))
    env = cond.coverage_envelope.model.evaluate(cond.wi_eval, cond.wo_eval)
    above = (v > env[None, :]).sum(axis=0)
    assert np.all(above <= (1 - coverage) * k + 1e-9)  # at every direction
    assert cond.fraction_above == pytest.approx(above.sum() / v.size)
    assert cond.fraction_above <= 1 - coverage + 1e-12
    assert cond.coverage_envelope.fraction_bounded == 1.0 and cond.coverage_envelope.details["min_ratio"] >= 1.0
    # the report of who exceeds where matches a count made here
    for k_, row in enumerate(cond.exceedances):
        assert row["directions_above"] == int(np.sum(v[k_] > env))
    if coverage < 1:
        assert sum(r["directions_above"] for r in cond.exceedances) == above.sum()
    # the max envelope bounds every sample's fit and every measured value
    menv = cond.max_envelope.model
    assert np.all(menv.evaluate(cond.wi_eval, cond.wo_eval)[None, :] >= v)
    assert np.all(menv.evaluate(cond.rows.wi, cond.rows.wo) >= cond.rows.brdf_per_sr)
    assert cond.max_envelope.details["measured_rows_bounded"] == 1.0


def test_conditions_by_incidence_and_state(tmp_path):
    a = [0.5, 1.0, 2.0]
    parts = [scaled(a, incidence_deg=20.0, prefix="i20-"), scaled(a, incidence_deg=40.0, prefix="i40-"),
             scaled([0.7, 1.4], incidence_deg=20.0, phi_i_deg=90.0, prefix="v20-")]
    late = scaled([x * 0.5 for x in a], incidence_deg=20.0, prefix="i20-", time_s=5.0)
    res = bm.sample_variability(screen.Samples.concatenate(parts), BASIS, coverage=0.9, n_directions=200)
    assert res.labels == ["theta_i=20.0deg phi_i=0.0deg", "theta_i=40.0deg phi_i=0.0deg", "theta_i=20.0deg phi_i=90.0deg"]
    assert [c.n_samples for c in res.conditions] == [3, 3, 2]
    assert [c.theta_i_deg for c in res.conditions] == pytest.approx([20.0, 40.0, 20.0])
    # state nodes split a condition; the second node is half as bright
    both = screen.Samples.concatenate([parts[0], late])
    res2 = bm.sample_variability(both, BASIS, coverage=0.9, n_directions=200, state="time_s", states=[0.0, 5.0])
    c0, c5 = res2.conditions
    assert (c0.state_value, c5.state_value) == (0.0, 5.0) and c5.label.endswith("time_s=5")
    np.testing.assert_allclose(c5.max_per_sr, 0.5 * c0.max_per_sr, rtol=1e-9)
    # one model over all conditions: >= each condition's quantile, JSON summary, save/load
    comb = res.combined_envelope("coverage")
    for c in res.conditions:
        assert np.all(comb.model.evaluate(c.wi_eval, c.wo_eval) >= c.quantile_per_sr)
    json.dumps(res.summary())
    path = res.save(tmp_path / "env.json", kind="max", condition="theta_i=40.0deg phi_i=0.0deg")
    assert bm.load(path) == res.conditions[1].max_envelope.model
    assert bm.load(res.save(tmp_path / "all.json", combined=True)) == comb.model


def test_explicit_groups_from_a_csv_table(tmp_path):
    s = screen.Samples.concatenate([scaled([0.5, 1.0], prefix="a"), scaled([2.0], prefix="b")])
    s = screen.Samples.read(s.to_csv(tmp_path / "samples.csv"))  # test_id read back as str
    res = bm.sample_variability(s, BASIS, groups={"steel": ["a0", "a1", "b0"]}, n_directions=100, coverage=1.0)
    cond = res.condition("steel")
    assert cond.test_ids == ("a0", "a1", "b0") and cond.rank == 3
    assert cond.spread["peak_measured_ratio"] == pytest.approx(4.0, rel=1e-12)


def test_errors():
    one = scaled([1.0])
    msg = r"samples: condition 'theta_i=20.0deg phi_i=0.0deg' has 1 sample\(s\) \['s0'\]; expected at least 2"
    with pytest.raises(ValueError, match=msg):
        bm.sample_variability(one, BASIS)
    mixed = screen.Samples.concatenate([scaled([1.0], prefix="a"), scaled([1.0], incidence_deg=30.0, prefix="b")])
    msg = r"groups\['g'\]: test 'a0' \(theta_i=20.00 deg.*test 'b0' \(theta_i=30.00 deg.*differ in incidence by 10 deg"
    with pytest.raises(ValueError, match=msg):
        bm.sample_variability(mixed, BASIS, groups={"g": ["a0", "b0"]})
    with pytest.raises(ValueError, match="has 1 sample"):  # automatic grouping: two conditions of one sample
        bm.sample_variability(mixed, BASIS)
    one_test_two_angles = screen.Samples.concatenate([scaled([1.0]), scaled([1.0], incidence_deg=25.0)])
    with pytest.raises(ValueError, match=r"samples: test 's0' has rows up to .* deg from its mean incidence"):
        bm.sample_variability(one_test_two_angles, BASIS)
    two = scaled([1.0, 2.0])
    with pytest.raises(ValueError, match=r"groups\['g'\]: test_id 'x' is not in samples"):
        bm.sample_variability(two, BASIS, groups={"g": ["s0", "x"]})
    for bad in (0.0, 1.5, math.nan):
        with pytest.raises(ValueError, match="coverage="):
            bm.sample_variability(two, BASIS, coverage=bad)
    with pytest.raises(ValueError, match="state='time_s', states=None: give both"):
        bm.sample_variability(two, BASIS, state="time_s")
    with pytest.raises(ValueError, match="n_directions=-1: expected an integer >= 0"):
        bm.sample_variability(two, BASIS, n_directions=-1)
    with pytest.raises(ValueError, match=r"condition 'theta_i=20.0deg phi_i=0.0deg time_s=9' has 0 sample"):
        bm.sample_variability(two, BASIS, state="time_s", states=[0.0, 9.0])
    with pytest.raises(ValueError, match="weights: each sample is fitted with the table's own weight column"):
        bm.sample_variability(two, BASIS, weights=np.ones(len(two)))
    dark = scaled([1.0, 2.0])
    dark.brdf_per_sr[3] = 0.0
    with pytest.raises(ValueError, match=r"samples: test 's0' \(condition 'theta_i=20.0deg phi_i=0.0deg'\): brdf_per_sr: 1 values <= 0"):
        bm.sample_variability(dark, BASIS)
    res = bm.sample_variability(two, BASIS, n_directions=50)
    with pytest.raises(ValueError, match="kind='mean': expected 'coverage' or 'max'"):
        res.condition().envelope("mean")
    with pytest.raises(ValueError, match="condition='x': expected one of"):
        res.condition("x")


def test_screen_simulation_end_to_end():
    """Scaled truths through the witness-screen simulator and the reduction (no noise, no
    saturation): the per-direction quantile is the factors' quantile times one fit."""
    truth = validation.SyntheticGroovedMetal()
    a = [0.5, 0.8, 1.0, 1.6]
    parts = []
    for k, ak in enumerate(a):
        t = screen.simulate_test(bm.Scaled(truth, ak), test_id=f"t{k}", incidence_deg=30.0, pixels=(40, 40), noise=0.0,
                                 saturation=1e12, state_of_time=lambda tt: 0.5)
        parts.append(screen.reduce_test(t))
    res = bm.sample_variability(screen.Samples.concatenate(parts), bm.SHBasis(6, 2, 2, 0), coverage=0.7, n_directions=300)
    cond = res.condition()
    base = cond.values_per_sr[2]
    np.testing.assert_allclose(cond.quantile_per_sr, order_quantile(a, 0.7) * base, rtol=1e-6)
    assert cond.spread["peak_measured_ratio"] == pytest.approx(max(a) / min(a), rel=1e-9)
    assert cond.spread["reflectance_ratio"] == pytest.approx(max(a) / min(a), rel=1e-6)
    assert cond.fraction_above <= 0.3 and cond.coverage_envelope.details["min_ratio"] >= 1.0
    assert cond.max_envelope.details["measured_rows_bounded"] == 1.0


@settings(max_examples=12, deadline=None)
@given(st.lists(st.floats(0.2, 5.0), min_size=2, max_size=6), st.sampled_from([0.5, 0.7, 0.9, 0.95, 1.0]))
def test_random_scale_sets(scales, coverage):
    a = np.array(scales)
    res = bm.sample_variability(scaled(a, step_deg=10.0), BASIS, coverage=coverage, n_directions=120, reflectance_rtol=1e-3)
    cond = res.condition()
    base = cond.values_per_sr[0] / a[0]
    np.testing.assert_allclose(cond.quantile_per_sr, order_quantile(a, coverage) * base, rtol=1e-8)
    env = cond.coverage_envelope.model.evaluate(cond.wi_eval, cond.wo_eval)
    assert np.all(env >= cond.quantile_per_sr)
    assert np.all((cond.values_per_sr > env).sum(axis=0) <= (1 - coverage) * len(a) + 1e-9)
    assert np.all(cond.max_envelope.model.evaluate(cond.wi_eval, cond.wo_eval) >= cond.max_per_sr)
    assert cond.spread["reflectance_ratio"] == pytest.approx(a.max() / a.min(), rel=1e-8)
