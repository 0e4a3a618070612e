"""DHR quadrature against independent references; error estimates must be honest."""

from functools import lru_cache

import numpy as np
import pytest

import brdfmodels as bm
from brdfmodels import accuracy


@lru_cache(maxsize=None)
def _lobe(width_deg, peak_sr, lh_max=32):
    model = accuracy.sharp_sh_lobe(width_deg=width_deg, peak_sr=peak_sr, lh_max=lh_max)
    return model, _one_d_reference(model)


def _one_d_reference(model):
    """DHR at normal incidence of an isotropic-in-h model: a 1-D integral in theta_o."""
    # vectorised fixed-order Gauss-Legendre on many panels, checked against doubling
    def integral(panels):
        x, w = np.polynomial.legendre.leggauss(20)
        a, b = panels[:-1, None], panels[1:, None]
        t = (a + (b - a) * 0.5 * (x + 1)).ravel()
        f = model.evaluate([0, 0, 1], np.stack([np.sin(t), 0 * t, np.cos(t)], -1)) * np.cos(t) * np.sin(t) * 2 * np.pi
        return float(((b - a) * 0.5 * w * f.reshape(a.size, -1)).sum())

    panels = np.concatenate([[0.0], np.geomspace(1e-7, np.pi / 2, 4000)])
    coarse, fine = integral(panels[::2]), integral(panels)
    assert abs(coarse - fine) < 1e-13
    return fine


@pytest.mark.parametrize("rtol", [1e-3, 1e-5, 1e-7, 1e-9])
def test_sharp_lobe_dhr_error_within_estimate(rtol):
    model, ref = _lobe(2.0, 50.0)
    r = bm.hemispherical_reflectance(model, [0, 0, 1], rtol=rtol)
    assert r.converged
    assert abs(r.value - ref) <= r.error_estimate
    assert r.error_estimate <= rtol * ref * 1.0001


def test_very_sharp_lobe_is_found():
    # a 0.05-degree lobe: missed entirely by a uniform grid of 1-degree cells
    model, ref = _lobe(0.05, 5e4, 64)
    r = bm.hemispherical_reflectance(model, [0, 0, 1], rtol=1e-6)
    assert r.value == pytest.approx(ref, rel=1e-5)


@pytest.mark.parametrize("theta_deg", [0.0, 30.0, 70.0, 89.0, 89.9999])
def test_lambertian_dhr_exact_at_all_incidences(theta_deg):
    wi = bm.spherical_to_vector(np.radians(theta_deg), 0.7)
    r = bm.hemispherical_reflectance(bm.Lambertian(0.37), wi, rtol=1e-10)
    assert r.value == pytest.approx(0.37, abs=max(r.error_estimate, 1e-14))


def test_dhr_bad_input():
    with pytest.raises(ValueError, match="above the surface"):
        bm.hemispherical_reflectance(bm.Lambertian(0.5), [0, 0, -1])
    with pytest.raises(ValueError, match=r"one direction of shape \(3,\)"):
        bm.hemispherical_reflectance(bm.Lambertian(0.5), [[0, 0, 1]])


def test_budget_exhaustion_is_reported():
    r = bm.hemispherical_reflectance(accuracy.sharp_sh_lobe(), [0, 0, 1], rtol=1e-12, max_evaluations=50_000)
    assert not r.converged and r.evaluations <= 50_000 and r.error_estimate > 0


def test_error_tables_print():
    rows = accuracy.dhr_error_table(rtols=(1e-2, 1e-4))
    assert [r["rtol"] for r in rows] == [1e-2, 1e-4]
    assert rows[1]["error"] <= rows[1]["error_estimate"]
    heat = accuracy.heating_tolerance_table(rtols=(1e-4, 1e-7))
    assert heat[1]["max_error_temperature_k"] < heat[0]["max_error_temperature_k"]
    text = accuracy.format_table(heat, "heating")
    assert "max_error_temperature_k" in text.splitlines()[1]


def test_zonal_projection_reproduces_a_smooth_profile():
    coef = bm.sh.zonal_coefficients(lambda th: 1.0 + np.cos(th) ** 2, 12, fanout=1.0)
    m = bm.SphericalHarmonicBRDF(bm.SHBasis(12, 0, 0, 0), coef, fanout=1.0, log=False)
    t = np.linspace(0.0, 1.4, 9)
    wo = bm.spherical_to_vector(2 * t[t < 0.7], 0.0)
    th = bm.half_diff([0, 0, 1], wo)[0]
    np.testing.assert_allclose(m.evaluate_cos([0, 0, 1], wo), 1.0 + np.cos(th) ** 2, rtol=1e-6)
