"""Probabilistic risk (``hazard risk``, :func:`hazard.drivers.risk.run_risk`) against references
written here from the formulas of /work/shared/spec/range-safety.md (sections 1, 2, 6, 8)
with numpy/scipy, never from the engine's functions.

The engine draws operations (Monte Carlo); at each draw an observer's peak irradiance E
(direct beam + reflections) is compared with the point-source MPE (read from risk.json
``mpe_w_m2``; the MPE itself is validated elsewhere). Each test builds a scene whose
exceedance probability has a closed form:

1. Lambertian plate under a log-normal BRDF scale exp(sigma Z): P = Phi(ln(E_med/MPE)/sigma),
   E_med = rho P cos(theta_r) / (pi R^2) (far field; laser-safety.md 3.1 diffuse form).
2. Direct beam under a 2-D Gaussian pointing error (sigma per axis, bias b): the Rice law
   P = ncx2.cdf((theta_h/sigma)^2, 2, (|theta_o - b|/sigma)^2),
   theta_h = theta_w sqrt(ln(E0/MPE)), theta_w = w(R)/R (range-safety.md 8, 1).
3. The same with importance sampling (unbiased).
4. A rare event (P ~ 1e-6): importance sampling finds it, plain sampling reports 0 hits
   with a Clopper-Pearson upper bound above it (conservative, never "safe").
5. Scintillation: log-normal with mean 1, sigma^2 = ln(1 + A sigma_I^2), sigma_I^2 the
   saturated plane-wave index of the Rytov variance, A the 7 mm aperture averaging
   (range-safety.md 6, 8): P = Q((ln(MPE/E0) + sigma^2/2)/sigma), median E0 exp(-sigma^2/2).
6. Operations per year: 1 - (1 - p)^N and 1 - exp(-N p) (range-safety.md 8).
7. Serial and dask-cluster runs give identical results for a seed.
8. First-order Sobol driver: pointing for a direct-beam observer, material for a diffuse one.
9. The command line: a run, and a bad key refused in one line without a traceback.

Statistical checks use a 4-sigma binomial band |p_hat - P| <= 4 sqrt(P (1 - P) / n) + 1e-3
(a factor 2 error in any sigma moves P by many bands in the scenes chosen), and sample
quantiles against the exact quantiles within 4 standard errors of a sample quantile,
sqrt(p (1 - p) / n) / f(x_p).
"""

from __future__ import annotations

import csv
import importlib.util
import json
import math
import subprocess
import sys

import numpy as np
import pytest
from scipy.stats import binomtest, ncx2, norm

import scenes

# =========================================================================== references


def beam_w(a, phi, z):
    """1/e irradiance radius w(z) = (a + z phi)/2 of the Gaussian beam, a the 1/e diameter at
    the aperture, phi the full 1/e divergence (range-safety.md section 1)."""
    return 0.5 * (a + z * phi)


def beam_peak(power, a, phi, z, mu=0.0):
    """On-axis irradiance E0 = P / (pi w^2) exp(-mu z) = 4 P / (pi D^2) exp(-mu z)
    (range-safety.md sections 1 and 2)."""
    w = beam_w(a, phi, z)
    return power / (math.pi * w * w) * math.exp(-mu * z)


def hazard_angle(power, a, phi, R, mpe, mu=0.0):
    """Angular hazard radius about an observer at range R: theta_h = theta_w sqrt(ln(E0/MPE)),
    theta_w = w(R)/R the beam's 1/e half-angle seen from the aperture (range-safety.md 8);
    0 when even the axis is below the MPE."""
    e0 = beam_peak(power, a, phi, R, mu)
    if e0 <= mpe:
        return 0.0
    return beam_w(a, phi, R) / R * math.sqrt(math.log(e0 / mpe))


def rice_exceedance(theta_h, theta_o, sigma):
    """P(|e - theta_o| < theta_h) for a 2-D isotropic Gaussian pointing error of sigma per
    axis: ncx2.cdf((theta_h/sigma)^2, 2, (theta_o/sigma)^2) = 1 - Q1(theta_o/sigma,
    theta_h/sigma) (range-safety.md section 8)."""
    return float(ncx2.cdf((theta_h / sigma) ** 2, 2, (theta_o / sigma) ** 2))


def rice_irradiance_quantile(e0, theta_w, theta_o, sigma, q):
    """Quantile q of E = E0 exp(-delta^2/theta_w^2), delta = |theta_o - e| (the beam's
    Gaussian profile in angle, range-safety.md 1 and 8): delta^2/sigma^2 ~ ncx2(2,
    (theta_o/sigma)^2) and E falls with delta, so E_q = E0 exp(-(sigma/theta_w)^2 X_{1-q})."""
    x = ncx2.ppf(1.0 - q, 2, (theta_o / sigma) ** 2)
    return e0 * math.exp(-((sigma / theta_w) ** 2) * x)


def rice_irradiance_quantile_rel_se(theta_w, theta_o, sigma, q, n):
    """Relative standard error of the sample quantile of E above: sqrt(q(1-q)/n)/f_X(x)
    in X = delta^2/sigma^2, times (sigma/theta_w)^2 (d ln E / dX)."""
    lam = (theta_o / sigma) ** 2
    x = ncx2.ppf(1.0 - q, 2, lam)
    return math.sqrt(q * (1 - q) / n) / ncx2.pdf(x, 2, lam) * (sigma / theta_w) ** 2


def lambertian_far_field(rho, spot_power, cos_r, R, mu_path=0.0):
    """Far-field irradiance of a Lambertian spot: E = rho P cos(theta_r) / (pi R^2), times
    exp(-mu (R_laser + R)) with attenuation (laser-safety.md 3.1; range-safety.md 8 for the
    log-normal scale applied to it)."""
    return rho * spot_power * cos_r / (math.pi * R * R) * math.exp(-mu_path)


def lognormal_scale_exceedance(e_med, mpe, sigma):
    """E = E_med exp(sigma Z): P(E > MPE) = Phi(ln(E_med/MPE)/sigma) (range-safety.md 8, the
    log-normal with median E_med)."""
    return float(norm.cdf(math.log(e_med / mpe) / sigma))


def lognormal_quantile_rel_se(sigma, q, n):
    """Relative standard error of the sample q-quantile of a log-normal with log-sd sigma:
    sqrt(q(1-q)/n) / phi(z_q) * sigma (delta method on ln E)."""
    return math.sqrt(q * (1 - q) / n) / norm.pdf(norm.ppf(q)) * sigma


def rytov_variance(cn2, wavelength_m, L, wave="plane"):
    """sigma_R^2 = 1.23 Cn^2 k^(7/6) L^(11/6), k = 2 pi / lambda; spherical: 0.407 of it
    (beta0^2 = 0.5 Cn^2 k^(7/6) L^(11/6)) (range-safety.md section 6)."""
    k = 2.0 * math.pi / wavelength_m
    s = 1.23 * cn2 * k ** (7.0 / 6.0) * L ** (11.0 / 6.0)
    return s if wave == "plane" else 0.5 / 1.23 * s


def saturated_scintillation_index(s):
    """Plane-wave sigma_I^2 from the Rytov variance s = sigma_R^2 (Andrews et al. 1999):
    exp[0.49 s/(1 + 1.11 s^(6/5))^(7/6) + 0.51 s/(1 + 0.69 s^(6/5))^(5/6)] - 1
    (sigma_R^(12/5) = s^(6/5)); -> s as s -> 0, -> 1 in the strong limit (range-safety.md 6)."""
    return math.expm1(0.49 * s / (1 + 1.11 * s**1.2) ** (7.0 / 6.0) + 0.51 * s / (1 + 0.69 * s**1.2) ** (5.0 / 6.0))


def aperture_averaging(wavelength_m, L, D=0.007):
    """Churnside's factor A = 1 / (1 + 1.07 (k D^2 / (4 L))^(7/6)), D = 7 mm (the eye's
    pupil; range-safety.md section 6)."""
    k = 2.0 * math.pi / wavelength_m
    return 1.0 / (1.0 + 1.07 * (k * D * D / (4.0 * L)) ** (7.0 / 6.0))


def scintillation_log_variance(cn2, wavelength_m, L, D=0.007, wave="plane"):
    """sigma^2 = ln(1 + A sigma_I^2) of the irradiance factor chi (ln chi ~ N(-sigma^2/2,
    sigma^2), mean 1) on a path of length L (range-safety.md 6 and 8)."""
    si2 = saturated_scintillation_index(rytov_variance(cn2, wavelength_m, L, wave)) * aperture_averaging(wavelength_m, L, D)
    return math.log1p(si2)


def lognormal_mean1_exceedance(e_mean, mpe, sigma2):
    """P(E > MPE) for E = <E> chi, chi log-normal with mean 1: Q((ln(MPE/<E>) + sigma^2/2)/sigma)
    (range-safety.md 6 'Log-normal exceedance', 8)."""
    s = math.sqrt(sigma2)
    return float(norm.sf((math.log(mpe / e_mean) + sigma2 / 2.0) / s))


def clopper_pearson(k, n):
    """Exact (Clopper-Pearson) 95 % interval (range-safety.md 8)."""
    ci = binomtest(int(k), int(n)).proportion_ci(0.95, method="exact")
    return float(ci.low), float(ci.high)


def at_least_one(p, N):
    """P(>= 1 exceedance in N operations) = 1 - (1 - p)^N (range-safety.md 8)."""
    return -math.expm1(N * math.log1p(-p)) if p < 1 else 1.0


def at_least_one_poisson(p, N):
    """Poisson form 1 - exp(-N p) (range-safety.md 8)."""
    return -math.expm1(-N * p)


def binomial_band(P, n):
    """The 4-sigma binomial band of a Monte Carlo estimate with n draws, plus 1e-3."""
    return 4.0 * math.sqrt(P * (1.0 - P) / n) + 1e-3


# =========================================================================== scene text


def _toml(v):
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        return repr(v)
    if isinstance(v, str):
        return json.dumps(v)
    if isinstance(v, dict):
        return "{ " + ", ".join(f"{k} = {_toml(x)}" for k, x in v.items()) + " }"
    return "[" + ", ".join(_toml(x if not isinstance(x, (np.floating, np.integer)) else float(x)) for x in v) + "]"


def scene_text(*, power, a, phi, position, aim, targets, observers, uncertainty, wavelength_nm=1064.0, name="risk"):
    """A scene as TOML. targets: dicts of [[targets]] keys; observers: (name, [points]);
    uncertainty: dict of the [uncertainty] table (sub-tables as dicts: inline tables)."""
    out = [
        f"name = {_toml(name)}",
        "[laser]",
        f"wavelength_nm = {_toml(float(wavelength_nm))}",
        f"power_w = {_toml(float(power))}",
        f"beam_diameter_m = {_toml(float(a))}",
        f"divergence_rad = {_toml(float(phi))}",
        f"position_m = {_toml([float(x) for x in position])}",
        f"aim_m = {_toml([float(x) for x in aim])}",
        "[exposure]",
        "duration_s = 10.0",
        'standard = "ansi-z136.1-2014"',
    ]
    for t in targets:
        out.append("[[targets]]")
        out += [f"{k} = {_toml(v)}" for k, v in t.items()]
    for oname, pts in observers:
        out += ["[[observers]]", f"name = {_toml(oname)}",
                "points_m = [" + ", ".join(_toml([float(x) for x in p]) for p in pts) + "]"]
    out.append("[uncertainty]")
    out += [f"{k} = {_toml(v)}" for k, v in uncertainty.items()]
    return "\n".join(out) + "\n"


def side_plate():
    """A small plate 200 m to the side of a beam along +y from the origin: nothing reaches
    it (0.38 rad off the axis), so only the direct beam matters."""
    return dict(name="side", shape="plate", center_m=[200.0, 500.0, 0.0], normal=[-1.0, 0.0, 0.0],
                tangent=[0.0, 1.0, 0.0], size_m=[0.5, 0.5], material={"model": "lambertian", "reflectance": 0.5})


def observer_names(group, n):
    """A group of one point is named by the group; of several, 'group[i]'."""
    return [group] if n == 1 else [f"{group}[{i}]" for i in range(n)]


def run(text, tmp_path, sub="out", **kw):
    """Load the scene, run the risk analysis serially; returns (risk.json, {name: csv row})."""
    from hazard.drivers.risk import run_risk

    scene = scenes.loads(text, base_dir=tmp_path)
    out = tmp_path / sub
    kw.setdefault("serial", True)
    run_risk(scene, out, **kw)
    return read_outputs(out)


def read_outputs(out):
    data = json.loads((out / "risk.json").read_text())
    with open(out / "risk.csv", newline="") as fh:
        rows = {r["name"]: r for r in csv.DictReader(fh)}
    return data, rows


def by_name(data):
    return {o["name"]: o for o in data["observers"]}


def check_ci_plain(o, n):
    """A plain run: p = hits/n and the CI is Clopper-Pearson of (hits, n)."""
    assert o["ci_method"] == "clopper-pearson"
    assert o["probability_exceed"] == pytest.approx(o["hits"] / n, rel=1e-12, abs=1e-15)
    lo, hi = clopper_pearson(o["hits"], n)
    assert o["probability_ci_low"] == pytest.approx(lo, abs=1e-9)
    assert o["probability_ci_high"] == pytest.approx(hi, abs=1e-9)


def check_csv_row(o, row, n):
    assert float(row["probability_exceed"]) == pytest.approx(o["probability_exceed"], rel=1e-6, abs=1e-12)
    assert float(row["probability_ci_low"]) == pytest.approx(o["probability_ci_low"], rel=1e-6, abs=1e-12)
    assert float(row["probability_ci_high"]) == pytest.approx(o["probability_ci_high"], rel=1e-6, abs=1e-12)
    assert int(row["draws"]) == n and int(row["hits"]) == o["hits"]
    for q in ("p50", "p95", "p99"):
        assert float(row[f"irradiance_{q}_w_m2"]) == pytest.approx(o["irradiance_quantiles_w_m2"][q], rel=1e-6)
        assert float(row[f"hazard_ratio_{q}"]) == pytest.approx(o["hazard_ratio_quantiles"][q], rel=1e-6)
    assert np.allclose([float(row["x_m"]), float(row["y_m"]), float(row["z_m"])], o["position_m"], rtol=1e-6, atol=1e-6)


# =========================================================================== reference self-checks


def test_reference_formulas_against_the_spec():
    """The helpers reproduce the worked values of range-safety.md sections 6 and 8 (no engine)."""
    assert rice_exceedance(0.4e-3, 1e-3, 0.5e-3) == pytest.approx(0.049518, abs=1e-6)
    # Rytov variance, 1064 nm over 2 km (section 6 table)
    assert rytov_variance(1e-15, 1064e-9, 2000.0) == pytest.approx(0.1100, abs=5e-5)
    assert rytov_variance(1e-14, 1064e-9, 2000.0) == pytest.approx(1.1005, abs=5e-5)
    assert rytov_variance(1e-13, 1064e-9, 2000.0) == pytest.approx(11.00, abs=5e-3)
    assert rytov_variance(1e-14, 1064e-9, 2000.0, "spherical") == pytest.approx(0.447, abs=5e-4)
    # saturated index: sigma_I^2 -> sigma_R^2 as sigma_R^2 -> 0 (ratio 1 + O(s)), -> 1 when strong
    for s in (1e-6, 1e-4, 1e-3):
        assert saturated_scintillation_index(s) / s == pytest.approx(1.0, abs=2 * s)
    assert saturated_scintillation_index(1e6) == pytest.approx(1.0, abs=0.05)
    # log-normal exceedance table P(I > k <I>) (section 6)
    for si2, k, want in ((0.1, 2.0, 8.21e-3), (0.3, 2.0, 0.0538), (1.0, 2.0, 0.1059), (1.0, 7.09, 2.81e-3)):
        assert lognormal_mean1_exceedance(1.0, k, math.log1p(si2)) == pytest.approx(want, rel=3e-3)
    # eye aperture: A ~ 1 at km ranges
    assert 0.97 < aperture_averaging(1064e-9, 2000.0) < 1.0
    # Clopper-Pearson (section 8, scipy docs) and zero hits in 300
    assert clopper_pearson(7, 50) == pytest.approx((0.0581917, 0.2673960), abs=1e-7)
    assert clopper_pearson(0, 300)[1] == pytest.approx(1 - 0.025 ** (1 / 300), abs=1e-9)
    assert clopper_pearson(0, 300)[1] == pytest.approx(0.012221, abs=1e-6)
    # Poisson over N operations (section 8)
    assert at_least_one(1e-4, 5000) == pytest.approx(0.39348, abs=1e-5)
    assert at_least_one_poisson(1e-4, 5000) == pytest.approx(0.39347, abs=1e-5)


def test_rice_reference_against_a_brute_force_beam():
    """The Rice law's small-angle hazard disk against a direct simulation of the Gaussian
    beam (no engine): rotate the axis by a 2-D Gaussian error about the aperture, evaluate
    E = P/(pi w(z)^2) exp(-r^2/w(z)^2) at the observer exactly, count E > MPE."""
    rng = np.random.default_rng(12345)
    P, a, phi, mpe, sigma = 2000.0, 0.01, 0.5e-3, 50.0, 0.5e-3
    n = 400_000
    for R, th_x, th_z, bias_up in ((1000.0, 1.25e-3, 0.0, 0.0), (400.0, 0.7e-3, 0.7e-3, 0.0), (1000.0, 0.0, 0.8e-3, 0.8e-3)):
        p = np.array([R * math.tan(th_x), R, R * math.tan(th_z)])
        e = rng.standard_normal((n, 2)) * sigma + np.array([0.0, bias_up])
        u = np.stack([np.tan(e[:, 0]), np.ones(n), np.tan(e[:, 1])], 1)
        u /= np.linalg.norm(u, axis=1)[:, None]
        z = u @ p
        r2 = p @ p - z * z
        w = beam_w(a, phi, z)
        E = P / (np.pi * w * w) * np.exp(-r2 / (w * w))
        got = float(np.mean(E > mpe))
        L = float(np.linalg.norm(p))
        theta_o = math.hypot(math.atan2(p[0], p[1]), math.atan2(p[2], p[1]) - bias_up)
        want = rice_exceedance(hazard_angle(P, a, phi, L, mpe), theta_o, sigma)
        assert abs(got - want) <= 4 * math.sqrt(want * (1 - want) / n) + 1e-4, (R, got, want)


# =========================================================================== 1. Lambertian, log-normal BRDF scale

LAM_P, LAM_A, LAM_PHI, LAM_RHO = 1e5, 0.005, 1e-3, 0.5
LAM_LASER = (0.0, -50.0, 0.0)
MPE_DESIGN = 50.0  # 1064 nm, 10 s, ANSI Z136.1-2014: used only to place the observers


def lambertian_plate():
    return dict(name="plate", shape="plate", center_m=[0.0, 0.0, 0.0], normal=[0.0, -1.0, 0.0],
                tangent=[1.0, 0.0, 0.0], size_m=[1.0, 1.0], material={"model": "lambertian", "reflectance": LAM_RHO})


def lambertian_observers(sigma, zs, angles_deg=(20.0, 35.0, 50.0, 30.0, 25.0), azimuths_deg=(0.0, 90.0, 180.0, 270.0, 45.0)):
    """Observers in front of the plate (normal -y) at angle theta_r from its normal, each at
    the distance that puts E_med / MPE = exp(sigma z) (so P ~ Phi(z) with the design MPE).
    Returns the points and their (cos theta_r, R)."""
    pts, geo = [], []
    for z, th, ps in zip(zs, angles_deg, azimuths_deg):
        th, ps = math.radians(th), math.radians(ps)
        e_med = MPE_DESIGN * math.exp(sigma * z)
        R = math.sqrt(LAM_RHO * LAM_P * math.cos(th) / (math.pi * e_med))
        pts.append([R * math.sin(th) * math.cos(ps), -R * math.cos(th), R * math.sin(th) * math.sin(ps)])
        geo.append((math.cos(th), R))
    return pts, geo


def lambertian_scene(sigma, pts, draws, seed, extra=None):
    unc = dict(draws=draws, seed=seed, sampling="plain", sensitivity_draws=0, brdf_scale_sigma=float(sigma))
    unc.update(extra or {})
    return scene_text(power=LAM_P, a=LAM_A, phi=LAM_PHI, position=LAM_LASER, aim=(0.0, 0.0, 0.0),
                      targets=[lambertian_plate()], observers=[("lam", pts)], uncertainty=unc)


@pytest.mark.parametrize("sigma", [0.5, 1.0])
def test_lambertian_lognormal_brdf_scale(tmp_path, sigma):
    """P(E > MPE) = Phi(ln(E_med/MPE)/sigma) with E_med = rho P cos(theta_r)/(pi R^2); the
    reported interval is Clopper-Pearson of (hits, draws); the irradiance quantiles are
    E_med exp(sigma z_q)."""
    n = 4000
    zs = (-1.6, -0.5, 0.4, 1.25)
    pts, geo = lambertian_observers(sigma, zs)
    data, rows = run(lambertian_scene(sigma, pts, n, 11), tmp_path)
    mpe = data["mpe_w_m2"]
    assert data["draws"] == n and data["seed"] == 11 and data["sampling"] == "plain"
    obs = by_name(data)
    names = observer_names("lam", len(pts))
    assert sorted(obs) == sorted(names) and sorted(rows) == sorted(names)
    misses = 0
    for name, p, (cos_r, R) in zip(names, pts, geo):
        o = obs[name]
        e_med = lambertian_far_field(LAM_RHO, LAM_P, cos_r, R)
        want = lognormal_scale_exceedance(e_med, mpe, sigma)
        got = o["probability_exceed"]
        assert abs(got - want) <= binomial_band(want, n), f"{name}: p_hat {got:.4f}, reference {want:.4f}"
        check_ci_plain(o, n)
        misses += not (o["probability_ci_low"] <= want <= o["probability_ci_high"])
        np.testing.assert_allclose(o["position_m"], p, atol=1e-9)
        for q, zq in (("p50", 0.0), ("p95", norm.ppf(0.95)), ("p99", norm.ppf(0.99))):
            e_q = e_med * math.exp(sigma * zq)
            tol = 4 * lognormal_quantile_rel_se(sigma, {"p50": 0.5, "p95": 0.95, "p99": 0.99}[q], n) + 5e-3
            assert o["irradiance_quantiles_w_m2"][q] == pytest.approx(e_q, rel=tol), f"{name} {q}"
            assert o["hazard_ratio_quantiles"][q] == pytest.approx(o["irradiance_quantiles_w_m2"][q] / mpe, rel=1e-9)
        check_csv_row(o, rows[name], n)
        assert "P(E > MPE)" in o["statement"]
    assert misses <= 1, f"{misses} of {len(pts)} reported 95 % intervals exclude the reference"


# =========================================================================== 2-4. pointing error (Rice)

RICE_P, RICE_A, RICE_PHI, RICE_SIGMA = 2000.0, 0.01, 0.5e-3, 0.5e-3
RICE_LASER = np.zeros(3)
RICE_AIM = (0.0, 3000.0, 0.0)  # the beam runs along +y; right = +x, up = +z


def at_angles(R, th_right, th_up):
    """A point at axial range R (along +y) seen at angles (right, up) from the aperture."""
    return [R * math.tan(th_right), R, R * math.tan(th_up)]


# axis at 1 km (P ~ 0.5), 1.25 mrad to the right (~0.05), 0.8 mrad up (~0.2), 400 m diagonal (~0.18)
RICE_OBS = [at_angles(1000.0, 0.0, 0.0), at_angles(1000.0, 1.25e-3, 0.0), at_angles(1000.0, 0.0, 0.8e-3),
            at_angles(400.0, 0.7e-3, 0.7e-3)]


def rice_scene(pts, *, draws, seed, sampling, bias=(0.0, 0.0), group="ptg", extra=None):
    unc = dict(draws=draws, seed=seed, sampling=sampling, sensitivity_draws=0, pointing_sigma_rad=RICE_SIGMA,
               pointing_bias_rad=[float(b) for b in bias])
    unc.update(extra or {})
    return scene_text(power=RICE_P, a=RICE_A, phi=RICE_PHI, position=RICE_LASER, aim=RICE_AIM, targets=[side_plate()],
                      observers=[(group, pts)], uncertainty=unc)


def rice_reference(p, mpe, bias=(0.0, 0.0)):
    """(P, theta_o, theta_w, E0) for an observer at p: angles (right, up) from the aperture,
    offset by the bias, range L = |p - laser|."""
    p = np.asarray(p, float) - RICE_LASER
    L = float(np.linalg.norm(p))
    right, up = math.atan2(p[0], p[1]), math.atan2(p[2], p[1])
    theta_o = math.hypot(right - bias[0], up - bias[1])
    th_h = hazard_angle(RICE_P, RICE_A, RICE_PHI, L, mpe)
    return rice_exceedance(th_h, theta_o, RICE_SIGMA), theta_o, beam_w(RICE_A, RICE_PHI, L) / L, beam_peak(RICE_P, RICE_A, RICE_PHI, L)


@pytest.mark.parametrize("bias", [(0.0, 0.0), (0.0, 0.8e-3)], ids=["no-bias", "bias-up"])
def test_rice_pointing_plain(tmp_path, bias):
    """Direct beam under a 2-D Gaussian pointing error (sigma 0.5 mrad; with a boresight bias
    of 0.8 mrad up, which centres the beam on the 'up' observer): P from the Rice law, the
    irradiance quantiles from the non-central chi-square of delta^2/sigma^2."""
    n = 4000
    data, rows = run(rice_scene(RICE_OBS, draws=n, seed=5, sampling="plain", bias=bias), tmp_path)
    mpe = data["mpe_w_m2"]
    obs = by_name(data)
    assert data["sampling"] == "plain"
    for name, p in zip(observer_names("ptg", len(RICE_OBS)), RICE_OBS):
        o = obs[name]
        want, theta_o, theta_w, e0 = rice_reference(p, mpe, bias)
        got = o["probability_exceed"]
        assert abs(got - want) <= binomial_band(want, n), f"{name}: p_hat {got:.4f}, Rice {want:.4f}"
        check_ci_plain(o, n)
        check_csv_row(o, rows[name], n)
        for q, qq in (("p50", 0.5), ("p95", 0.95), ("p99", 0.99)):
            e_q = rice_irradiance_quantile(e0, theta_w, theta_o, RICE_SIGMA, qq)
            tol = 4 * rice_irradiance_quantile_rel_se(theta_w, theta_o, RICE_SIGMA, qq, n) + 5e-3
            assert o["irradiance_quantiles_w_m2"][q] == pytest.approx(e_q, rel=tol), f"{name} {q}"


def test_rice_pointing_importance_sampling_is_unbiased(tmp_path):
    """The same scene with importance sampling: the weighted estimate agrees with the Rice law
    within the plain binomial band, and its interval (Clopper-Pearson on the effective
    sample size) contains it."""
    n = 4000
    data, rows = run(rice_scene(RICE_OBS, draws=n, seed=6, sampling="importance"), tmp_path)
    mpe = data["mpe_w_m2"]
    assert data["sampling"] == "importance"
    obs = by_name(data)
    misses = 0
    for name, p in zip(observer_names("ptg", len(RICE_OBS)), RICE_OBS):
        o = obs[name]
        want = rice_reference(p, mpe)[0]
        got = o["probability_exceed"]
        assert o["ci_method"] == "clopper-pearson-effective"
        assert abs(got - want) <= binomial_band(want, n), f"{name}: IS estimate {got:.4f}, Rice {want:.4f}"
        assert o["probability_ci_low"] <= got <= o["probability_ci_high"]
        misses += not (o["probability_ci_low"] <= want <= o["probability_ci_high"])
        assert float(rows[name]["probability_exceed"]) == pytest.approx(got, rel=1e-6, abs=1e-12)
    assert misses <= 1, f"{misses} of {len(RICE_OBS)} reported 95 % intervals exclude the Rice value"


RARE_THETA = 2.873e-3  # 5.75 sigma to the right at 1 km: Rice P ~ 1e-6


@pytest.mark.slow  # 15-25 s idle (2 x 20000 draws); test_rice_pointing_importance_sampling_is_unbiased runs by default
def test_rare_event_importance_vs_plain(tmp_path):
    """P ~ 1e-6: importance sampling with 20000 draws finds it within a factor 1.5 and its
    interval contains it; plain sampling with the same draws sees no hit and says so with a
    Clopper-Pearson upper bound above the true P (conservative, never 'safe')."""
    n = 20_000
    pts = [at_angles(1000.0, RARE_THETA, 0.0)]
    text = rice_scene(pts, draws=n, seed=7, sampling="importance", group="rare")
    data, _ = run(text, tmp_path, sub="is")
    want = rice_reference(pts[0], data["mpe_w_m2"])[0]
    assert 3e-7 < want < 3e-6  # the design (with the design MPE)
    o = by_name(data)["rare"]
    got = o["probability_exceed"]
    assert want / 1.5 <= got <= want * 1.5, f"IS estimate {got:.3e}, Rice {want:.3e}"
    assert o["probability_ci_low"] <= want <= o["probability_ci_high"]

    data, _ = run(text, tmp_path, sub="plain", sampling="plain")
    assert data["sampling"] == "plain"
    o = by_name(data)["rare"]
    assert o["hits"] == 0 and o["probability_exceed"] == 0.0
    check_ci_plain(o, n)
    assert o["probability_ci_high"] >= want
    assert o["probability_ci_high"] == pytest.approx(1 - 0.025 ** (1 / n), rel=1e-9)


# =========================================================================== 5. scintillation

SC_A, SC_PHI, SC_L, SC_LAMBDA = 0.01, 0.5e-3, 2000.0, 1064e-9


@pytest.mark.parametrize("cn2", [1e-15, 1e-14])
def test_scintillation_lognormal(tmp_path, cn2):
    """Direct beam at 2 km, no pointing error, plane-wave scintillation: P(E > MPE) =
    Q((ln(MPE/E) + sigma^2/2)/sigma), the median E exp(-sigma^2/2), sigma^2 =
    ln(1 + A sigma_I^2(sigma_R^2)). Observers on the axis (P ~ 0.8) and off it (P ~ 0.5, ~0.1)."""
    n = 4000
    sig2 = scintillation_log_variance(cn2, SC_LAMBDA, SC_L)
    sig = math.sqrt(sig2)
    w = beam_w(SC_A, SC_PHI, SC_L)
    ratio = {t: MPE_DESIGN * math.exp(-(norm.isf(t) * sig - sig2 / 2)) for t in (0.8, 0.5, 0.1)}  # E for P = t
    power = ratio[0.8] * math.pi * w * w
    offsets = [0.0] + [w * math.sqrt(math.log(ratio[0.8] / ratio[t])) for t in (0.5, 0.1)]
    pts = [[r, SC_L, 0.0] for r in offsets]
    unc = dict(draws=n, seed=9, sampling="plain", sensitivity_draws=0,
               scintillation={"cn2_m23": cn2, "wave": "plane", "aperture_m": 0.007})
    text = scene_text(power=power, a=SC_A, phi=SC_PHI, position=(0.0, 0.0, 0.0), aim=(0.0, 3000.0, 0.0),
                      targets=[side_plate()], observers=[("sc", pts)], uncertainty=unc)
    data, rows = run(text, tmp_path)
    mpe = data["mpe_w_m2"]
    obs = by_name(data)
    for name, p in zip(observer_names("sc", len(pts)), pts):
        o = obs[name]
        L = math.hypot(p[0], p[1])
        s2 = scintillation_log_variance(cn2, SC_LAMBDA, L)
        e_mean = beam_peak(power, SC_A, SC_PHI, SC_L) * math.exp(-(p[0] / w) ** 2)
        want = lognormal_mean1_exceedance(e_mean, mpe, s2)
        got = o["probability_exceed"]
        assert abs(got - want) <= binomial_band(want, n), f"{name}: p_hat {got:.4f}, log-normal {want:.4f}"
        check_ci_plain(o, n)
        check_csv_row(o, rows[name], n)
        s = math.sqrt(s2)
        for q, qq in (("p50", 0.5), ("p95", 0.95), ("p99", 0.99)):
            e_q = e_mean * math.exp(-s2 / 2 + s * norm.ppf(qq))
            tol = 4 * lognormal_quantile_rel_se(s, qq, n) + 5e-3
            assert o["irradiance_quantiles_w_m2"][q] == pytest.approx(e_q, rel=tol), f"{name} {q}"
    # the design itself discriminates: a factor 2 in sigma (either way) moves some observer's P
    # by more than twice its band
    for f in (4.0, 0.25):
        shifts = []
        for r in offsets:
            e = beam_peak(power, SC_A, SC_PHI, SC_L) * math.exp(-(r / w) ** 2)
            p_true = lognormal_mean1_exceedance(e, MPE_DESIGN, sig2)
            shifts.append(abs(lognormal_mean1_exceedance(e, MPE_DESIGN, f * sig2) - p_true) / binomial_band(p_true, n))
        assert max(shifts) > 2.0, (f, shifts)


# =========================================================================== 6. operations per year


def test_operations_per_year(tmp_path):
    """With operations = N per year: probability_at_least_one = 1 - (1 - p)^N and the Poisson
    form 1 - exp(-N p) of the reported p, their interval the same map of the p interval, and
    risk.csv's probability_per_year the same; no sensitivity asked: none reported."""
    n, N = 4000, 5000.0
    pts, _ = lambertian_observers(0.5, (-3.0, -2.3, -0.5))  # P ~ 1.3e-3, 0.011, 0.31
    data, rows = run(lambertian_scene(0.5, pts, n, 21, extra={"operations": N}), tmp_path)
    obs = by_name(data)
    for name in observer_names("lam", len(pts)):
        o = obs[name]
        p = o["probability_exceed"]
        ops = o["operations"]
        assert ops is not None and ops["n"] == pytest.approx(N)
        assert ops["probability_at_least_one"] == pytest.approx(at_least_one(p, N), abs=1e-9)
        assert ops["probability_at_least_one_poisson"] == pytest.approx(at_least_one_poisson(p, N), abs=1e-9)
        lo, hi = o["probability_ci_low"], o["probability_ci_high"]
        assert ops["ci_low"] <= ops["probability_at_least_one"] <= ops["ci_high"]
        assert any(ops["ci_low"] == pytest.approx(f(lo, N), abs=1e-9) and ops["ci_high"] == pytest.approx(f(hi, N), abs=1e-9)
                   for f in (at_least_one, at_least_one_poisson)), ops
        assert float(rows[name]["probability_per_year"]) == pytest.approx(ops["probability_at_least_one"], rel=1e-6, abs=1e-12)
        assert o["sensitivity"] is None and rows[name]["driver"] == ""
    # the rarest observer has hits (~5 expected), so the per-year values are not all 0 or 1
    p_rare = obs[observer_names("lam", len(pts))[0]]["probability_exceed"]
    assert 0 < p_rare < 0.01 and 0.5 < at_least_one(p_rare, N) < 1.0


# =========================================================================== 7-8. cluster and sensitivity

SENS_P, SENS_A, SENS_PHI, SENS_SIGMA = 1e4, 0.01, 0.5e-3, 0.5e-3
SENS_LASER = (0.0, -100.0, 0.0)  # aims at a 1 m Lambertian plate at the origin (normal -y)


def sensitivity_scene(draws, seed, sampling, sensitivity_draws):
    """Observer 'beam' 50 m down the beam, off the axis so that only a pointing error brings the
    beam to it (Rice P ~ 0.3); observer 'diffuse' 6 m from the plate at 30 deg, lit only by
    the Lambertian reflection under the BRDF scale (P ~ 0.3). The plate catches the whole beam
    whatever the pointing error (4 sigma at 100 m is 0.2 m)."""
    th_h = hazard_angle(SENS_P, SENS_A, SENS_PHI, 50.0, MPE_DESIGN)
    from scipy.optimize import brentq

    th_o = brentq(lambda t: rice_exceedance(th_h, t, SENS_SIGMA) - 0.3, 0.0, 10 * SENS_SIGMA)
    e_med = MPE_DESIGN * math.exp(0.5 * norm.ppf(0.3))
    th = math.radians(30.0)
    R = math.sqrt(LAM_RHO * SENS_P * math.cos(th) / (math.pi * e_med))
    beam_obs = [50.0 * math.tan(th_o), -50.0, 0.0]
    diffuse_obs = [R * math.sin(th), -R * math.cos(th), 0.0]
    unc = dict(draws=draws, seed=seed, sampling=sampling, sensitivity_draws=sensitivity_draws,
               pointing_sigma_rad=SENS_SIGMA, brdf_scale_sigma=0.5)
    return scene_text(power=SENS_P, a=SENS_A, phi=SENS_PHI, position=SENS_LASER, aim=(0.0, 0.0, 0.0),
                      targets=[lambertian_plate()], observers=[("beam", [beam_obs]), ("diffuse", [diffuse_obs])],
                      uncertainty=unc)


@pytest.mark.slow  # ~24 s CPU with its 2-worker cluster; the default run: tests/hazard/test_runner.py (the one runner study and risk share: Dask records the serial results) and test_study.py::test_serial_equals_dask_embedded_and_existing_scheduler
def test_serial_and_cluster_identical(tmp_path):
    """A fixed seed gives the same results serially and on a 2-worker dask LocalCluster:
    risk.csv byte for byte, risk.json's observers equal."""
    pytest.importorskip("distributed")
    from hazard.drivers.risk import run_risk

    # 1000 draws: two main chunks of 500 (2 observers) and one sensitivity chunk, so the two
    # workers share the chunks and their results are combined in chunk order; the identity
    # checked does not depend on the number of draws (2000 took 2 x 8.5 s more CPU)
    scene = scenes.loads(sensitivity_scene(1000, 17, "auto", 128), base_dir=tmp_path)
    run_risk(scene, tmp_path / "serial", serial=True)
    run_risk(scene, tmp_path / "cluster", serial=False, workers=2)
    a = (tmp_path / "serial" / "risk.csv").read_bytes()
    b = (tmp_path / "cluster" / "risk.csv").read_bytes()
    assert a == b
    ja, _ = read_outputs(tmp_path / "serial")
    jb, _ = read_outputs(tmp_path / "cluster")
    assert ja["observers"] == jb["observers"]
    for key in ("mpe_w_m2", "draws", "seed", "sampling"):
        assert ja[key] == jb[key]


@pytest.mark.slow  # 15-25 s idle (2000 draws x 512 sensitivity draws)
def test_sensitivity_drivers(tmp_path):
    """First-order Sobol indices name the input that drives each observer: 'pointing' for the
    observer only the direct beam can reach, 'material' for the one only the plate lights."""
    data, rows = run(sensitivity_scene(2000, 23, "plain", 512), tmp_path)
    obs = by_name(data)
    inputs = {"pointing", "material", "tilt", "visibility", "scintillation", "observer_position"}
    for name, driver in (("beam", "pointing"), ("diffuse", "material")):
        o = obs[name]
        assert 0.1 < o["probability_exceed"] < 0.5, (name, o["probability_exceed"])  # the design P ~ 0.3
        sens = o["sensitivity"]
        assert sens is not None and sens["of"] in ("exceedance", "log_ratio")
        assert set(sens["first_order"]) <= inputs and {"pointing", "material"} <= set(sens["first_order"])
        assert sens["driver"] == driver, sens
        assert max(sens["first_order"], key=sens["first_order"].get) == driver
        assert rows[name]["driver"] == driver


# =========================================================================== 9. command line


def _cli():
    """``python -m hazard`` (the package's __main__), else the CLI module itself."""
    mod = "hazard" if importlib.util.find_spec("hazard.__main__") is not None else "hazard.cli"
    return [sys.executable, "-m", mod]


def test_cli_risk(tmp_path):
    """`hazard risk SCENE -o OUT --draws 500 --seed 3 --serial --quiet` writes risk.json and
    risk.csv; a misspelled [uncertainty] key is refused with exit != 0, one message naming
    the key, no traceback."""
    pts, _ = lambertian_observers(0.5, (0.0,))
    scene = tmp_path / "scene.toml"
    scene.write_text(lambertian_scene(0.5, pts, 4000, 0))
    out = tmp_path / "out"
    res = subprocess.run([*_cli(), "risk", str(scene), "-o", str(out), "--draws", "500", "--seed", "3", "--serial", "--quiet"],
                         capture_output=True, text=True, timeout=300)
    assert res.returncode == 0, res.stderr
    data, rows = read_outputs(out)
    assert data["draws"] == 500 and data["seed"] == 3
    assert list(rows) == ["lam"] and int(rows["lam"]["draws"]) == 500

    bad = tmp_path / "bad.toml"
    bad.write_text(scene.read_text().replace("[uncertainty]\n", "[uncertainty]\npointing_sigma_mrad = 0.5\n"))
    res = subprocess.run([*_cli(), "risk", str(bad), "-o", str(tmp_path / "out-bad"), "--serial", "--quiet"],
                         capture_output=True, text=True, timeout=300)
    assert res.returncode != 0
    assert "pointing_sigma_mrad" in res.stderr
    assert "Traceback" not in res.stderr and "Traceback" not in res.stdout
    assert not (tmp_path / "out-bad" / "risk.json").exists()
