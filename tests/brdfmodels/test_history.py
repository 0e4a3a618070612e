"""Oxidation and heating histories against high-precision and analytic references."""


import mpmath
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import brdfmodels as bm

mpmath.mp.dps = 50


def _reference_integral(ta, tb, ya, yb, t0):
    """Integral of exp(-T0 / T(t)) over one linear piece, at 50 digits, two ways.

    Route 1: Gauss-Legendre quadrature on 32 sub-pieces (the integrand can fall by e^20
    across a piece). Route 2: the closed form through the exponential integral,
    F(T) = T e^{-T0/T} - T0 E1(T0/T). The reference is accepted only if they agree.
    """
    f = lambda t: mpmath.exp(-mpmath.mpf(t0) / (ya + (yb - ya) * (t - ta) / (tb - ta)))
    quad = mpmath.quad(f, mpmath.linspace(ta, tb, 33), method="gauss-legendre")
    if t0 == 0:
        return quad
    if ya == yb:
        closed = (tb - ta) * mpmath.exp(-mpmath.mpf(t0) / ya)
    else:
        big_f = lambda T: T * mpmath.exp(-mpmath.mpf(t0) / T) - t0 * mpmath.e1(mpmath.mpf(t0) / T)
        closed = (big_f(mpmath.mpf(yb)) - big_f(mpmath.mpf(ya))) * (tb - ta) / (mpmath.mpf(yb) - ya)
    assert abs(quad - closed) <= 1e-12 * abs(closed), (quad, closed)
    return closed


def _reference_xi(times, temps, t0, d0, xi0):
    """xi from the 50-digit reference integrals (independent of the code under test)."""
    total = mpmath.mpf(0)
    out = [xi0]
    for (ta, tb), (ya, yb) in zip(zip(times[:-1], times[1:]), zip(temps[:-1], temps[1:])):
        if tb > ta:
            total += _reference_integral(mpmath.mpf(ta), mpmath.mpf(tb), mpmath.mpf(ya), mpmath.mpf(yb), float(t0))
        out.append(float(mpmath.sqrt(mpmath.mpf(xi0) ** 2 + d0 * total)))
    return np.array(out)


@pytest.mark.parametrize("t0", [0.0, 9060.0, 2.0e4, 5.0e4])
def test_oxidation_matches_high_precision_quadrature(t0):
    rng = np.random.default_rng(int(t0))
    times = np.cumsum(np.concatenate([[0.0], rng.uniform(0.01, 3.0, 12)]))
    temps = rng.uniform(290.0, 1800.0, times.size)
    # a temperature jump: repeated time with a new temperature
    times = np.insert(times, 6, times[5])
    temps = np.insert(temps, 6, 1700.0)
    model = bm.OxidationModel(t0, 1.0, 0.0)
    xi = model.extinction(times, temps)
    ref = _reference_xi(times, temps, t0, 1.0, 0.0)
    np.testing.assert_allclose(xi, ref, rtol=1e-8, atol=0)


@given(
    st.lists(st.tuples(st.floats(1e-6, 100.0), st.floats(250.0, 3000.0)), min_size=1, max_size=6),
    st.floats(100.0, 5e4),
)
@settings(max_examples=40, deadline=None)
def test_oxidation_property_against_reference(pieces, t0):
    times = np.concatenate([[0.0], np.cumsum([p[0] for p in pieces])])
    temps = np.concatenate([[300.0], [p[1] for p in pieces]])
    xi = bm.OxidationModel(t0, 1.0, 0.0).extinction(times, temps)
    ref = _reference_xi(times, temps, t0, 1.0, 0.0)
    np.testing.assert_allclose(xi, ref, rtol=1e-8, atol=1e-300)


def test_oxidation_constant_temperature_closed_form():
    # xi^2 = xi0^2 + d0 exp(-T0/T) t (spec: parabolic law at constant T)
    m = bm.OxidationModel.stainless_steel()
    t = np.array([0.0, 0.5, 2.0])
    xi = m.extinction(t, np.full(3, 1400.0))
    np.testing.assert_allclose(xi, np.sqrt(0.311**2 + 935.0 * np.exp(-9060.0 / 1400.0) * t), rtol=1e-14)
    np.testing.assert_allclose(m.reflectance_factor(t, np.full(3, 1400.0)), np.exp(-(xi - 0.311)))


def test_oxidation_bad_input():
    m = bm.OxidationModel.stainless_steel()
    with pytest.raises(ValueError, match="non-decreasing"):
        m.extinction([0, 2, 1], [300, 300, 300])
    with pytest.raises(ValueError, match="temperatures_k contains -5.0: expected absolute"):
        m.extinction([0, 1], [300, -5])
    with pytest.raises(ValueError, match="activation_temperature_k=-1.0"):
        bm.OxidationModel(-1.0, 1.0, 0.1)


def _plate(**kw):
    base = dict(thickness_m=1e-3, density_kg_m3=8000.0, specific_heat_j_kg_k=500.0, initial_reflectance=0.6,
                emissivity=0.0, melt_temperature_k=1700.0, latent_heat_j_kg=2.7e5, convection_w_m2_k=0.0,
                ambient_temperature_k=300.0, oxidation=None)
    base.update(kw)
    return bm.ThinPlateHeating(**base)


def test_adiabatic_heating_and_melting_plateau_analytic():
    # no losses, constant absorptance: T rises at (1-R) E / (rho c h), holds at T_melt for
    # rho L h / ((1-R) E), then rises again at the same rate
    p = _plate()
    e = 1e7
    rate = 0.4 * e / (8000 * 500 * 1e-3)  # K/s
    t_melt = (1700 - 300) / rate
    plateau = 8000 * 2.7e5 * 1e-3 / (0.4 * e)
    t = np.array([0.0, 0.5 * t_melt, t_melt + 0.5 * plateau, t_melt + plateau + 0.1])
    res = p.solve(t, e, rtol=1e-10)
    np.testing.assert_allclose(res.temperature_k, [300, 300 + 0.5 * (1400), 1700, 1700 + 0.1 * rate], rtol=1e-6)
    np.testing.assert_allclose(res.melt_fraction, [0, 0, 0.5, 1.0], atol=1e-6)


def test_zero_power_stays_at_ambient():
    res = bm.ThinPlateHeating.stainless_steel().solve(np.linspace(0, 100, 11), 0.0)
    np.testing.assert_allclose(res.temperature_k, 293.15, rtol=1e-9)
    assert np.all(res.extinction >= 0.311)  # oxidation at room temperature is negligible, not negative


def test_long_times_reach_radiative_convective_steady_state():
    p = _plate(emissivity=0.5, convection_w_m2_k=20.0, faces=2)
    e = 2e4
    res = p.solve(np.array([0.0, 1e4, 1e5]), e)
    t_end = res.temperature_k[-1]
    balance = 0.4 * e - 2 * (0.5 * bm.history.STEFAN_BOLTZMANN_W_M2_K4 * (t_end**4 - 300**4) + 20 * (t_end - 300))
    assert abs(balance) < 1e-5 * 0.4 * e
    assert res.temperature_k[-1] == pytest.approx(res.temperature_k[-2], rel=1e-6)


@pytest.mark.parametrize("irr, thick", [(1e10, 1e-5), (1e9, 1e-4), (1e6, 1e-2)])
def test_extreme_heating_is_finite(irr, thick):
    p = bm.ThinPlateHeating.stainless_steel(thickness_m=thick, oxidation=bm.OxidationModel(5e4, 1e9, 0.3))
    res = p.solve(np.linspace(0, 1.0, 50), irr, rtol=1e-6)
    for arr in (res.temperature_k, res.extinction, res.reflectance):
        assert np.all(np.isfinite(arr))
    assert np.all(np.diff(res.extinction) >= -1e-12)
    assert np.all((res.reflectance >= 0) & (res.reflectance <= 0.6 + 1e-12))


def test_oxidation_darkens_and_feeds_back():
    # with oxidation the plate absorbs more, so it is hotter than without
    times = np.linspace(0, 5, 1001)
    hot = bm.ThinPlateHeating.stainless_steel().solve(times, 5e6)
    cold = bm.ThinPlateHeating.stainless_steel(oxidation=None).solve(times, 5e6)
    assert hot.reflectance[-1] < 0.6 and np.all(hot.temperature_k >= cold.temperature_k - 1e-6)
    # its extinction equals the parabolic law applied to its own temperature history
    # (sampled finely: piecewise-linear T(t) between samples is the only difference)
    xi = bm.OxidationModel.stainless_steel().extinction(times, hot.temperature_k)
    np.testing.assert_allclose(hot.extinction, xi, rtol=1e-4)


def test_pulse_table_irradiance():
    p = _plate()
    res = p.solve(np.array([0.0, 1.0, 2.0, 3.0]), (np.array([0.0, 1.0, 1.0 + 1e-9, 3.0]), np.array([1e6, 1e6, 0.0, 0.0])))
    rate = 0.4 * 1e6 / 4000.0
    np.testing.assert_allclose(res.temperature_k, [300, 300 + rate, 300 + rate, 300 + rate], rtol=1e-6)


def test_history_maps_time_to_state():
    h = bm.History([0.0, 1.0, 3.0], [0.3, 0.5, 0.9], "extinction")
    np.testing.assert_allclose(h.state_at([0.5, 2.0]), [0.4, 0.7])
    with pytest.raises(ValueError, match=r"time_s=4.0 is outside the tabulated range \[0.0, 3.0\]"):
        h.state_at(4.0)
    res = _plate().solve(np.linspace(0, 1, 5), 1e6)
    assert res.history("temperature_k").state_name == "temperature_k"
    h2 = bm.History.from_temperature_series([0, 1], [300, 1500], bm.OxidationModel.stainless_steel(), "extinction")
    assert h2.states[0] == pytest.approx(0.311)
