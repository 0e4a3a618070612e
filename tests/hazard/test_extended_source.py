"""Extended sources (C_E per observer) against hand calculations from the standard's formulas.

References written out here, not taken from the code (spec `laser-safety.md` 2.1, 2.4):
- 1064 nm, 1.3e-5 s <= t < 10 s: H = 90 C_C C_E t^0.75 J/m^2 (IEC 90 C7 C6 t^0.75), C_C = 1;
- C_E = 1 (alpha < 1.5 mrad), alpha / 1.5 mrad up to alpha_max, then alpha_max / 1.5 mrad
  (2014) or alpha^2 / (1.5 mrad * 100 mrad) (2007);
- alpha_max (2014) = 5 mrad (t < 625 us), 200 t^0.5 mrad (to 0.25 s), 100 mrad;
- the spot of a Gaussian beam (1/e diameter a, divergence phi) at range R_L is a disc of 1/e
  diameter D = a + R_L phi; seen from distance R at angle theta from the plate normal it
  subtends alpha = 2 atan(D cos(theta) / (2 R)).
"""

import csv
import json
import math
from types import SimpleNamespace

import numpy as np
import pytest

import hazard
import scenes
from hazard.pipeline.extended_source import apply_extended_source, extended_source_mpe, observer_subtense_rad
from hazard.outputs.report import report_dict, write_outputs
from hazard.outputs.report_schema import validate_report

A, PHI, R_L = 0.1, 1e-4, 10.0
D = A + R_L * PHI  # 1/e spot diameter on the plate [m]
ALPHA_MIN = 1.5e-3

SCENE = """
name = "es"
[laser]
wavelength_nm = 1064.0
{laser}
beam_diameter_m = {a}
divergence_rad = {phi}
position_m = [0.0, -{rl}, 0.0]
aim_m = [0.0, 0.0, 0.0]
[exposure]
duration_s = {t}
standard = "{std}"
{ext}
[[targets]]
name = "plate"
shape = "plate"
center_m = [0.0, 0.0, 0.0]
normal = {normal}
tangent = [0.0, 0.0, 1.0]
size_m = [{size}, {size}]
material = {material}
{observers}
[analysis]
beam_samples = {samples}
"""
LAMBERT = '{ model = "lambertian", reflectance = 0.5 }'
GLOSSY = ('{ model = "sum", models = [{ type = "lambertian", params = { reflectance = 0.5 } }, '
          '{ type = "specular", params = { reflectance = 0.1 } }] }')


def scene(points, *, extended=None, t=1.0, std="ansi-z136.1-2014", power=5e5, material=LAMBERT, laser=None,
          normal=(0.0, -1.0, 0.0), samples=256, size=2.0):
    obs = "".join(f'[[observers]]\nname = "o{i}"\npoints_m = [{[float(v) for v in p]}]\n' for i, p in enumerate(points))
    ext = "" if extended is None else f"extended_source = {'true' if extended else 'false'}"
    return scenes.loads(SCENE.format(laser=laser or f"power_w = {power}", a=A, phi=PHI, rl=R_L, t=t, std=std, ext=ext,
                                     material=material, observers=obs, normal=[float(v) for v in normal], samples=samples,
                                     size=float(size)))


def on_normal(r):
    return (0.0, -r, 0.0)


def at_angle(r, deg):
    th = math.radians(deg)
    return (r * math.sin(th), -r * math.cos(th), 0.0)


def alpha_hand(r, deg=0.0):
    return 2 * math.atan(D * math.cos(math.radians(deg)) / (2 * r))


def mpe_1064_hand(t, c_e):
    """W/m^2: H = 90 C_C C_E t^0.75 J/m^2, C_C = 1 at 1064 nm, over t."""
    return 90.0 * c_e * t**0.75 / t


@pytest.mark.parametrize("samples", [16, 256, 4096])
def test_subtense_is_the_hand_disc_whatever_the_beam_sampling(samples):
    # the beam samples may overstate the spot's moments (a sample's power sits at its cell's
    # centre); the subtense never exceeds that of the untruncated beam footprint
    res = hazard.analyze(scene([on_normal(20.0), at_angle(20.0, 60.0)], samples=samples))
    np.testing.assert_allclose(res.observers.angular_subtense_rad, [alpha_hand(20.0), alpha_hand(20.0, 60.0)], rtol=1e-9)


@pytest.mark.parametrize("samples", [16, 256, 4096])
def test_truncated_spot_subtense(samples):
    # a 5 cm plate in the 10.1 cm (1/e) beam: the lit square holds a truncated Gaussian of
    # per-axis variance sigma^2 (1 - 2 b phi(b) / (2 Phi(b) - 1)), sigma^2 = w^2 / 2, b = (s/2) / sigma
    side, r = 0.05, 20.0
    sigma = (D / 2) / math.sqrt(2.0)
    b = side / 2 / sigma
    phi = math.exp(-b * b / 2) / math.sqrt(2 * math.pi)
    var = sigma**2 * (1 - 2 * b * phi / math.erf(b / math.sqrt(2)))
    truth = 2 * math.atan(math.sqrt(2 * var) / r)  # 1/e-equivalent diameter 2 sqrt(2 var)
    res = hazard.analyze(scene([on_normal(r)], size=side, samples=samples))
    alpha = res.observers.angular_subtense_rad[0]
    # the scatter of the engine's samples leaves out the spread within each sample (low at
    # coarse sampling), but its edge samples sit at the centroid of their whole beam cell,
    # part of it off the plate (high by up to 0.7 % in alpha at 16384 samples: Spot.size_m
    # is 0.9 % high here at every sampling). Known limitation, see hazard.pipeline.extended_source.
    assert alpha <= truth * 1.01
    assert alpha >= 0.75 * truth


def test_oblique_incidence_uses_the_minor_axis():
    # plate tilted 60 deg about z: the footprint is D across and D / cos(60) = 2 D along the
    # plane of incidence; an eye on the plate's normal sees the minor axis D
    n = (math.sin(math.radians(60.0)), -math.cos(math.radians(60.0)), 0.0)
    eye = tuple(20.0 * np.asarray(n))
    res = hazard.analyze(scene([eye], normal=n, extended=True))
    assert res.observers.angular_subtense_rad[0] == pytest.approx(alpha_hand(20.0), rel=1e-4)
    assert res.observers.c_e[0] == pytest.approx(alpha_hand(20.0) / ALPHA_MIN, rel=1e-4)


def test_default_is_point_source_and_ratio_unchanged():
    pts = [on_normal(20.0), at_angle(20.0, 60.0), on_normal(2.0)]
    for res in (hazard.analyze(scene(pts)), hazard.analyze(scene(pts, extended=False))):
        mpe = mpe_1064_hand(1.0, 1.0)  # 90 W/m^2
        assert res.mpe_w_m2 == pytest.approx(mpe, rel=1e-12)
        np.testing.assert_array_equal(res.observers.c_e, 1.0)
        np.testing.assert_allclose(res.observers.mpe_w_m2, mpe, rtol=1e-12)
        np.testing.assert_allclose(res.hazard_ratio, res.observers.peak_irradiance_w_m2 / mpe, rtol=1e-12)
        st = res.stage("extended_source")
        assert not st.ran and "point-source" in st.detail and "extended_source = true" in st.detail
        # the subtense is still reported (by hand)
        np.testing.assert_allclose(res.observers.angular_subtense_rad, [alpha_hand(20.0), alpha_hand(20.0, 60.0), alpha_hand(2.0)],
                                   rtol=1e-9)
        assert res.extended_source.to_dict() == {"applied": False}


def test_extended_source_divides_the_ratio_by_c_e():
    # (on the normal closer than the laser's 10 m an eye would stand in the beam itself)
    pts = [on_normal(20.0), at_angle(20.0, 60.0), on_normal(200.0), at_angle(2.0, 20.0)]
    off = hazard.analyze(scene(pts))
    on = hazard.analyze(scene(pts, extended=True))
    alpha = np.array([alpha_hand(20.0), alpha_hand(20.0, 60.0), alpha_hand(200.0), alpha_hand(2.0, 20.0)])
    # 5.05, 2.52, 0.505 (< alpha_min), 47.4 mrad: alpha_max = 100 mrad at 1 s
    c_e = np.where(alpha < ALPHA_MIN, 1.0, alpha / ALPHA_MIN)
    np.testing.assert_allclose(on.observers.angular_subtense_rad, alpha, rtol=1e-9)
    np.testing.assert_allclose(on.observers.c_e, c_e, rtol=1e-9)
    np.testing.assert_allclose(on.observers.mpe_w_m2, mpe_1064_hand(1.0, c_e), rtol=1e-9)
    np.testing.assert_array_equal(on.observers.peak_irradiance_w_m2, off.observers.peak_irradiance_w_m2)
    np.testing.assert_allclose(on.hazard_ratio, off.hazard_ratio / c_e, rtol=1e-9)
    # the verdict follows: the observer at 20 m on the normal is hazardous as a point source, not with C_E
    assert off.hazardous[0] and not on.hazardous[0]
    assert on.hazardous_static[0] == on.hazardous[0]
    assert np.isnan(on.observers.first_exceedance_s[0]) and off.observers.first_exceedance_s[0] == 0.0
    st = on.stage("extended_source")
    assert st.ran and "C_E from the spot subtense" in st.detail and "3 of 4 observers above alpha_min" in st.detail
    assert on.mpe_w_m2 == off.mpe_w_m2  # the scalar (point-source) MPE is kept for lobes and NOHDs


def test_beyond_alpha_max_2014_short_exposure():
    t = 1e-3  # alpha_max = 200 t^0.5 mrad = 6.32 mrad
    a_max = 0.2 * math.sqrt(t)
    # 7.3 mrad (> alpha_max), 2.5 mrad; the first beside the laser, behind its aperture plane
    # (on the normal at 10 m it would stand on the aperture itself: in the beam, C_E = 1)
    pts = [at_angle(12.0, 30.0), on_normal(40.0)]
    res = hazard.analyze(scene(pts, extended=True, t=t))
    alpha = np.array([alpha_hand(12.0, 30.0), alpha_hand(40.0)])
    assert alpha[0] > a_max > alpha[1] > ALPHA_MIN
    c_e = np.array([a_max / ALPHA_MIN, alpha[1] / ALPHA_MIN])
    np.testing.assert_allclose(res.observers.c_e, c_e, rtol=1e-9)
    np.testing.assert_allclose(res.observers.mpe_w_m2, mpe_1064_hand(t, c_e), rtol=1e-9)


def test_beyond_alpha_max_2007_grows_as_alpha_squared():
    pts = [at_angle(0.6, 35.0)]  # 138 mrad > alpha_max = 100 mrad (2007: at every duration); well off the beam
    res = hazard.analyze(scene(pts, extended=True, std="iec-60825-1-2007"))
    alpha = alpha_hand(0.6, 35.0)
    assert alpha > 0.1
    c_e = alpha**2 / (ALPHA_MIN * 0.1)
    assert res.observers.c_e[0] == pytest.approx(c_e, rel=1e-9)
    assert res.observers.mpe_w_m2[0] == pytest.approx(mpe_1064_hand(1.0, c_e), rel=1e-9)
    # the 2014 edition caps C_E at alpha_max / alpha_min = 66.7 for the same observer
    res14 = hazard.analyze(scene(pts, extended=True))
    assert res14.observers.c_e[0] == pytest.approx(0.1 / ALPHA_MIN, rel=1e-12)


def test_observer_in_the_direct_beam_adds_the_exposures_as_fractions_of_their_mpes():
    """2 m in front of the plate on its normal an eye stands in the laser's own beam (a
    point source: the point-source MPE) and sees the diffuse spot behind it (C_E): the
    hazard ratio is E_direct / MPE + E_reflected / (C_E MPE). Beside the beam (0.68 m off
    its axis, where the Gaussian is ~1e-70 of its peak) the spot's C_E alone."""
    res = hazard.analyze(scene([on_normal(2.0), at_angle(2.0, 20.0)], extended=True))
    obs = res.observers
    mpe = mpe_1064_hand(1.0, 1.0)
    c_e0 = alpha_hand(2.0) / ALPHA_MIN
    assert obs.direct_irradiance_w_m2[0] > 1e3 * obs.reflected_irradiance_w_m2[0] > 0
    want = obs.direct_irradiance_w_m2[0] / mpe + obs.reflected_irradiance_w_m2[0] / mpe_1064_hand(1.0, c_e0)
    assert res.hazard_ratio[0] == pytest.approx(want, rel=1e-9)
    assert 1.0 < obs.c_e[0] < c_e0
    assert obs.c_e[1] == pytest.approx(alpha_hand(2.0, 20.0) / ALPHA_MIN, rel=1e-6)


def test_specular_observer_keeps_c_e_1():
    # a glossy plate: the mirror beam goes back towards the laser (normal incidence)
    pts = [on_normal(20.0), at_angle(20.0, 60.0)]
    res = hazard.analyze(scene(pts, extended=True, material=GLOSSY, power=10.0))
    spec_e = res.observers.specular_irradiance_w_m2
    assert res.observers.c_e[0] == 1.0  # on the mirror axis
    assert res.observers.mpe_w_m2[0] == pytest.approx(mpe_1064_hand(1.0, 1.0), rel=1e-12)
    assert spec_e[0] > 0 and spec_e[1] == 0
    assert res.observers.c_e[1] == pytest.approx(alpha_hand(20.0, 60.0) / ALPHA_MIN, rel=1e-9)


def test_specular_known_per_observer():
    """With the per-observer specular part known, only observers receiving it keep C_E = 1."""
    res = hazard.analyze(scene([on_normal(20.0), at_angle(20.0, 60.0)], extended=True, material=GLOSSY, power=10.0))
    res.observers.specular_irradiance_w_m2 = np.array([3.0, 0.0])
    res.stages = [s for s in res.stages if s.name != "extended_source"]
    apply_extended_source(res)
    c_e1 = alpha_hand(20.0, 60.0) / ALPHA_MIN
    np.testing.assert_allclose(res.observers.c_e, [1.0, c_e1], rtol=1e-9)
    np.testing.assert_allclose(res.observers.mpe_w_m2, [90.0, 90.0 * c_e1], rtol=1e-9)


def test_pulsed_applies_c_e_per_pulse_duration():
    """Per-pulse MPE x PRF with C_E at the pulse duration (alpha_max = 5 mrad below 625 us)."""
    laser = "pulse_energy_j = 1.0\npulse_duration_s = 1e-8\nprf_hz = 10.0"
    pts = [on_normal(20.0), on_normal(200.0)]
    off = hazard.analyze(scene(pts, laser=laser))
    on = hazard.analyze(scene(pts, extended=True, laser=laser))
    n = 10.0  # pulses in 1 s
    # rule 3 governs: H_1 N^-0.25 with H_1 = 2e-2 C_C C_E J/m^2 (1050-1400 nm, 1e-11 - 1.3e-5 s)
    point = 2e-2 * n**-0.25 * 10.0
    assert off.mpe_w_m2 == pytest.approx(point, rel=1e-12)
    c_e_pulse = 5e-3 / ALPHA_MIN  # 5.05 mrad > alpha_max = 5 mrad at 10 ns
    np.testing.assert_allclose(on.observers.mpe_w_m2, [point * c_e_pulse, point], rtol=1e-9)
    np.testing.assert_allclose(on.hazard_ratio, off.hazard_ratio * [1 / c_e_pulse, 1.0], rtol=1e-9)
    for res in (off, on):  # report.json's pulse block, and extended_source's MPE entries with their pulse (issue 35)
        doc = json.loads(json.dumps(report_dict(res)))
        validate_report(doc)
    assert doc["pulse"]["governing_rule"] and doc["extended_source"]["mpe_smallest_alpha"]["pulse"]["rules"]


def test_several_spots_smallest_subtense_and_elongated_spot():
    def fake_spot(center, dx, dy, normal=(0.0, -1.0, 0.0)):
        c = np.asarray(center, float)
        pts = c + np.array([[dx, 0, 0], [-dx, 0, 0], [0, 0, dy], [0, 0, -dy]], float)
        n = np.asarray(normal, float)
        return SimpleNamespace(points=pts, power_w=np.ones(4), centroid=c, mean_frame=np.stack([[1.0, 0, 0], [0, 0, 1.0], n]))

    # points at +-d on an axis, equal weights: second moment d^2/2, 1/e diameter 2 sqrt(2 d^2/2) = 2 d
    big, small = fake_spot((0, 0, 0), 0.05, 0.05), fake_spot((1.0, 0, 0), 0.01, 0.03)
    eye = np.array([[0.0, -10.0, 0.0]])
    a_big = observer_subtense_rad([big], eye)[0]
    assert a_big == pytest.approx(2 * math.atan(0.1 / 20.0), rel=1e-12)
    # the elongated spot: minor axis 0.02 m, seen from sqrt(101) m at cos = 10 / sqrt(101) along x
    r = math.sqrt(101.0)
    a_small = observer_subtense_rad([small], eye)[0]
    assert a_small == pytest.approx(2 * math.atan(0.02 * 10 / r / (2 * r)), rel=1e-9)
    assert observer_subtense_rad([big, small], eye)[0] == pytest.approx(a_small, rel=1e-12)
    # an eye behind a spot's surface ignores it; behind every spot: a point source
    behind = np.array([[0.0, 10.0, 0.0]])
    assert observer_subtense_rad([big], behind)[0] == 0.0
    back = fake_spot((0, 0, 0), 0.05, 0.05, normal=(0.0, 1.0, 0.0))
    assert observer_subtense_rad([big, back], behind)[0] == pytest.approx(2 * math.atan(0.1 / 20.0), rel=1e-12)


@pytest.mark.parametrize("wl,t,std", [(1064.0, 1.0, "ansi-z136.1-2014"), (532.0, 100.0, "ansi-z136.1-2014"),
                                      (905.0, 30.0, "iec-60825-1-2014"), (1064.0, 1e-3, "iec-60825-1-2007"),
                                      (633.0, 1000.0, "ansi-z136.1-2007")])
def test_mpe_monotone_in_alpha_and_bins_round_down(wl, t, std):
    alpha = np.geomspace(1e-4, 0.3, 3000)
    exact = extended_source_mpe(alpha, wl, t, standard=std)
    assert exact.exact
    assert np.all(np.diff(exact.mpe_w_m2) >= -1e-12 * exact.mpe_w_m2[1:])  # rounding down alpha never raises the MPE
    assert np.all(exact.c_e >= 1.0)
    binned = extended_source_mpe(alpha, wl, t, standard=std, max_exact=10)
    assert not binned.exact
    assert np.all(binned.alpha_eval_rad <= alpha)
    assert np.all(binned.mpe_w_m2 <= exact.mpe_w_m2 * (1 + 1e-12))
    # 0.1 % bins in alpha: the MPE is at most 0.1 % low where it grows as alpha, 0.2 % where as
    # alpha^2 (2007, above 100 mrad; the photochemical limit, 400-600 nm and t >= 10 s, above its
    # field of view gamma_ph = 11 mrad up to 100 s, 1.1 t^0.5 mrad to 1e4 s, spec 2.4); the first
    # bin above alpha_min rounds to a point source (a 1.2 % step for t >= 10 s)
    first_bin = alpha <= ALPHA_MIN * 1.001
    gamma_ph = 11e-3 if t <= 100 else (1.1e-3 * t**0.5 if t <= 1e4 else 0.11)
    photo_sq = (400 <= wl < 600 and t >= 10) & (alpha > gamma_ph)
    lin = (alpha <= 0.1) & ~photo_sq
    assert np.all(binned.mpe_w_m2[~first_bin & lin] >= exact.mpe_w_m2[~first_bin & lin] / 1.0011)
    assert np.all(binned.mpe_w_m2[~lin] >= exact.mpe_w_m2[~lin] / 1.0021)
    assert np.all(binned.mpe_w_m2[first_bin] >= exact.mpe_w_m2[first_bin] / 1.013)
    small = alpha <= ALPHA_MIN
    np.testing.assert_allclose(exact.mpe_w_m2[small], hazard.ocular_mpe(wl, t, standard=std).irradiance_w_m2, rtol=1e-12)


def test_report_columns(tmp_path):
    pts = [on_normal(20.0), on_normal(200.0)]
    res = hazard.analyze(scene(pts, extended=True))
    write_outputs(res, tmp_path)
    rows = list(csv.DictReader((tmp_path / "observers.csv").open()))
    c_e = [alpha_hand(20.0) / ALPHA_MIN, 1.0]
    for row, a, ce in zip(rows, [alpha_hand(20.0), alpha_hand(200.0)], c_e):
        assert float(row["angular_subtense_rad"]) == pytest.approx(a, rel=1e-9)
        assert float(row["c_e"]) == pytest.approx(ce, rel=1e-9)
        assert float(row["mpe_w_m2"]) == pytest.approx(90.0 * ce, rel=1e-9)
        assert float(row["hazard_ratio"]) == pytest.approx(float(row["peak_irradiance_w_m2"]) / (90.0 * ce), rel=1e-9)
    doc = json.loads((tmp_path / "report.json").read_text())
    assert doc["extended_source"]["applied"] is True
    assert doc["extended_source"]["observers_above_alpha_min"] == 1
    assert doc["extended_source"]["mpe_smallest_alpha"]["c_e"] == pytest.approx(c_e[0], rel=1e-9)
    obs = doc["observers"][0]
    assert obs["c_e"] == pytest.approx(c_e[0], rel=1e-9) and obs["mpe_w_m2"] == pytest.approx(90.0 * c_e[0], rel=1e-9)
    assert obs["mpe_radiant_exposure_j_m2"] == pytest.approx(90.0 * c_e[0] * 1.0, rel=1e-9)
    assert any(s["name"] == "extended_source" and s["ran"] for s in doc["stages"])
    off = report_dict(hazard.analyze(scene(pts)))
    assert off["extended_source"] == {"applied": False}
    validate_report(doc)  # the applied block against its schema (issue 35)
    assert [o["c_e"] for o in off["observers"]] == [1.0, 1.0]


def test_projected_minor_axis_matches_an_eigen_decomposition():
    """The closed form (trace and cofactor of the projected second moments) against
    numpy's eigenvalues of P C P, for a tilted elongated spot and random eyes."""
    from hazard.pipeline.extended_source import _second_moments, spot_subtense_rad

    rng = np.random.default_rng(1)
    rot = np.linalg.qr(rng.normal(size=(3, 3)))[0]
    pts = (rng.normal(size=(300, 3)) * [0.03, 0.0, 0.08]) @ rot.T
    w = rng.uniform(0.5, 1.0, 300)
    c = (pts * w[:, None]).sum(0) / w.sum()
    sp = SimpleNamespace(points=pts, power_w=w, centroid=c, mean_frame=np.stack([rot[:, 0], rot[:, 2], rot[:, 1]]))
    eyes = rng.normal(0.0, 5.0, (500, 3))
    alpha, front = spot_subtense_rad(sp, eyes)
    cov = _second_moments(sp)
    for e, a, f in zip(eyes, alpha, front):
        v = e - c
        r = np.linalg.norm(v)
        u = v / r
        p = np.eye(3) - np.outer(u, u)
        lam = np.sort(np.linalg.eigvalsh(p @ cov @ p))[1]  # [0] is the line of sight
        assert f == (u @ rot[:, 1] > 0)
        assert a == (pytest.approx(2 * math.atan(math.sqrt(2 * max(lam, 0.0)) / r), rel=1e-6) if f else 0.0)
