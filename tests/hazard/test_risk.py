"""hazard risk: inputs, resume, the tilt path against the Rice formula, the other inputs
against closed forms, the map files, and a random-geometry property.

Expected values are written here from the formulas (range-safety.md sections 6 and 8,
the Kruse visibility model, Fresnel reflectance), never from the engine's functions.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st
from scipy.stats import binomtest, ncx2, norm

import scenes
from hazard.drivers.risk import run_risk

BASE = '''name = "risk-test"
[laser]
wavelength_nm = 1064.0
power_w = {power}
beam_diameter_m = 0.005
divergence_rad = 0.001
position_m = [0.0, 0.0, 0.0]
aim_m = [0.0, {aim_y}, 0.0]
[exposure]
duration_s = 10.0
standard = "ansi-z136.1-2014"
'''

MPE_1064_10S = 50.0  # W/m^2, ANSI Z136.1-2014 Table 5b, 1064 nm, 10 s (read back from risk.json and checked)


def _plate(name, center, normal, tangent, size, material):
    def v(x):
        return [float(a) for a in x]

    return (f'[[targets]]\nname = "{name}"\nshape = "plate"\ncenter_m = {v(center)}\nnormal = {v(normal)}\n'
            f'tangent = {v(tangent)}\nsize_m = [{size}, {size}]\nmaterial = {material}\n')


def _observers(points, name="o"):
    return "".join(f'[[observers]]\nname = "{name}{i}"\npoints_m = [{list(map(float, p))}]\n' for i, p in enumerate(points))


def _run(text, tmp_path, sub="out", **kw):
    sc = scenes.loads(text, base_dir=tmp_path)
    return run_risk(sc, tmp_path / sub, serial=True, **kw)


def _within(p_hat, p, n, k=4.0):
    return abs(p_hat - p) <= k * math.sqrt(max(p * (1 - p), 1e-12) / n) + 1e-3


# -- inputs ---------------------------------------------------------------------------
@pytest.mark.parametrize("extra, where", [
    ("[uncertainty]\npointing_sigma_mrad = 1.0\n", "uncertainty.pointing_sigma_mrad"),
    ("[uncertainty]\n[uncertainty.visibility]\ndistribution = \"lognormal\"\nmedian_km = 5.0\n", "sigma: required"),
    ("[uncertainty]\n[[uncertainty.materials]]\ntarget = \"nope\"\nmaterials = [{model = \"lambertian\", reflectance = 0.2}]\n",
     "uncertainty.materials[0].target: 'nope'"),
    ("[uncertainty]\n[uncertainty.map]\nextent_m = [10.0, 0.0, 0.0, 10.0]\nspacing_m = 1.0\n", "extent_m"),
    ("[uncertainty]\nnormal_wander_correlation_time_s = 1.0\n", "normal_wander_correlation_time_s"),
    ("[uncertainty]\n[uncertainty.scintillation]\ncn2_m23 = 1e-14\nturbulence = \"weak\"\n", "exactly one"),
    ("[uncertainty]\n[[uncertainty.materials]]\ntarget = \"t\"\nmaterials = [{model = \"lambertian\", reflectance = 0.2}]\n"
     "weights = [1.0, 2.0]\n", "one per material"),
])
def test_bad_uncertainty_names_the_field(extra, where, tmp_path):
    text = BASE.format(power=1.0, aim_y=10.0) + _plate("t", [0, 10, 0], [0, -1, 0], [1, 0, 0], 1.0, '{ model = "lambertian", reflectance = 0.5 }')
    with pytest.raises(ValueError) as exc:
        scenes.loads(text + extra, base_dir=tmp_path)
    assert where in str(exc.value)


def test_no_uncertainty_is_a_clear_error(tmp_path):
    sc = scenes.loads(BASE.format(power=1.0, aim_y=10.0) + _plate("t", [0, 10, 0], [0, -1, 0], [1, 0, 0], 1.0,
                                                                   '{ model = "lambertian", reflectance = 0.5 }'))
    with pytest.raises(ValueError, match=r"no \[uncertainty\] table"):
        run_risk(sc, tmp_path / "o", serial=True)


def test_wander_is_a_stationary_ou_process(tmp_path):
    """Node-to-node correlation exp(-dt/tau) and the stated sigma at every node."""
    from hazard.drivers.risk.evaluate import Evaluator

    text = (BASE.format(power=1.0, aim_y=10.0) + _plate("t", [0, 10, 0], [0, -1, 0], [1, 0, 0], 1.0, '{ model = "lambertian", reflectance = 0.5 }')
            + "[uncertainty]\nnormal_tilt_sigma_deg = 1.0\nnormal_wander_correlation_time_s = 5.0\nwander_nodes = 8\n")
    ev = Evaluator(scenes.loads(text))
    times = np.asarray(ev.model.wander_times_s)
    assert len(times) == 8 and times[0] == 0 and times[-1] == 10.0
    d = ev.model.draw(np.random.default_rng(1), 40000)
    x = d.tilt_rad[:, 0, :, 0]
    sig = math.radians(1.0)
    assert np.allclose(x.std(axis=0), sig, rtol=0.03)
    rho = np.corrcoef(x[:, 0], x[:, 3])[0, 1]
    assert rho == pytest.approx(math.exp(-(times[3] - times[0]) / 5.0), abs=0.02)


# -- the tilt path and importance sampling against Rice -------------------------------
def _retro_scene(draws, sampling, offsets):
    """A glass plate (n = 1.5) facing the laser 500 m out: the mirror beam returns along
    the axis, a normal tilt delta turns it by 2 delta (normal incidence)."""
    return (BASE.format(power=2000.0, aim_y=500.0)
            + _plate("glass", [0, 500, 0], [0, -1, 0], [1, 0, 0], 2.0, '{ model = "specular", n = 1.5 }')
            + _observers([[d, 0.0, 0.0] for d in offsets])
            + f'[uncertainty]\ndraws = {draws}\nsampling = "{sampling}"\nsensitivity_draws = 0\nnormal_tilt_sigma_deg = 0.02\n')


def _retro_reference(d, mpe):
    """Rice (spec section 8) in tilt space: the returning beam's 1/e half-angle seen from
    the mirror is w(1000 m)/500 m; the hazardous half-angle theta_h = theta_w
    sqrt(ln(E0/MPE)) with E0 = R P / (pi w^2), R = ((n-1)/(n+1))^2 (Fresnel, normal
    incidence); the beam lands at 2 delta, so in delta: radius theta_h/2, offset d/1000."""
    w = (0.005 + 0.001 * 1000.0) / 2
    e0 = 0.04 * 2000.0 / (math.pi * w * w)
    theta_h = (w / 500.0) * math.sqrt(math.log(e0 / mpe))
    sigma = math.radians(0.02)
    return float(ncx2.cdf((theta_h / 2 / sigma) ** 2, 2, (d / 1000.0 / sigma) ** 2))


def test_tilt_against_rice_plain_and_importance(tmp_path):
    offs = [0.5, 1.0]
    for sampling in ("plain", "importance"):
        res = _run(_retro_scene(3000, sampling, offs), tmp_path, sampling)
        mpe = res.doc["mpe_w_m2"]
        assert mpe == MPE_1064_10S
        for r, d in zip(res.observers, offs):
            ref = _retro_reference(d, mpe)
            assert 0.02 < ref < 0.6
            assert _within(r["probability_exceed"], ref, 3000), (sampling, d, r["probability_exceed"], ref)


@pytest.mark.slow  # 10-20 s idle; test_tilt_against_rice_plain_and_importance runs by default
def test_importance_reaches_a_rare_tilt(tmp_path):
    """An observer whose Rice chance is ~1e-7: importance sampling gets it within its CI;
    plain sampling of the same size sees nothing and says only an upper bound."""
    d = 2.2
    res = _run(_retro_scene(6000, "importance", [d]), tmp_path, "is")
    ref = _retro_reference(d, res.doc["mpe_w_m2"])
    assert 1e-9 < ref < 1e-5
    r = res.observers[0]
    assert r["hits"] >= 10 and r["probability_ci_low"] <= ref <= r["probability_ci_high"]
    assert r["probability_exceed"] == pytest.approx(ref, rel=0.35)
    plain = _run(_retro_scene(6000, "plain", [d]), tmp_path, "plain").observers[0]
    assert plain["hits"] == 0 and plain["probability_ci_high"] >= ref


# -- the other inputs against closed forms --------------------------------------------
def _kruse_mu(v_km, wl_nm):
    q = 1.6 if v_km > 50 else (1.3 if v_km > 6 else 0.585 * v_km ** (1 / 3))
    return 3.912 / (v_km * 1e3) * (wl_nm / 550.0) ** (-q)


def test_visibility_discrete(tmp_path):
    """On the axis 2 km out, E = P/(pi w^2) exp(-mu(V) L): only the hazier visibility
    keeps it below the MPE; P = that visibility's share."""
    power = 1000.0
    text = (BASE.format(power=power, aim_y=2000.0) + _plate("side", [300, 0, 0], [-1, 0, 0], [0, 1, 0], 1.0,
                                                            '{ model = "lambertian", reflectance = 0.5 }')
            + _observers([[0.0, 2000.0, 0.0]])
            + '[uncertainty]\ndraws = 2000\nsensitivity_draws = 0\n[uncertainty.visibility]\ndistribution = "discrete"\n'
              'values_km = [1.0, 40.0]\nweights = [1.0, 3.0]\n')
    w = (0.005 + 0.001 * 2000.0) / 2
    e = [power / (math.pi * w * w) * math.exp(-_kruse_mu(v, 1064.0) * 2000.0) for v in (1.0, 40.0)]
    assert e[0] < MPE_1064_10S < e[1]
    r = _run(text, tmp_path).observers[0]
    assert _within(r["probability_exceed"], 0.75, 2000)


def test_material_choices_and_aided(tmp_path):
    """A plate that is one of two Lambertian materials (rho 0.1, 0.9; weights 3:1): only
    rho 0.9 exceeds the MPE at the observer: P = 1/4. Through 7x50 binoculars (gain
    min(M^2, (D/7 mm)^2) tau = 49 x 1.0) both do: aided P = 1."""
    power = 200.0
    text = (BASE.format(power=power, aim_y=20.0)
            + _plate("board", [0, 20, 0], [0, -1, 0], [1, 0, 0], 1.0, '{ model = "lambertian", reflectance = 0.5 }')
            + '[[observers]]\nname = "near"\npoints_m = [[0.3, 19.0, 0.05]]\n'
            + '[[observers]]\nname = "bino"\npoints_m = [[0.3, 19.0, 0.05]]\noptics = { magnification = 7.0, objective_diameter_m = 0.05, transmission = 1.0 }\n'
            + '[uncertainty]\ndraws = 1200\nsensitivity_draws = 0\n[[uncertainty.materials]]\ntarget = "board"\n'
              'materials = [{ model = "lambertian", reflectance = 0.1 }, { model = "lambertian", reflectance = 0.9 }]\nweights = [3.0, 1.0]\n')
    rr = math.hypot(0.3, 1.0, 0.05)
    cos = 1.0 / rr
    e = [rho * power * cos / (math.pi * rr * rr) for rho in (0.1, 0.9)]
    assert e[0] < MPE_1064_10S < e[1] and 49 * e[0] > MPE_1064_10S
    near, bino = _run(text, tmp_path).observers
    assert _within(near["probability_exceed"], 0.25, 1200)
    assert bino["optical_gain"] == pytest.approx(49.0)
    assert bino["probability_exceed"] == 1.0
    assert [a["probability_exceed"] for a in near["aided"]] == [1.0]


# -- resume, seeds and files ----------------------------------------------------------
def _small(tmp_path, seed=0):
    return (BASE.format(power=100.0, aim_y=50.0)
            + _plate("t", [0, 50, 0], [0, -1, 0], [1, 0, 0], 1.0, '{ model = "lambertian", reflectance = 0.5 }')
            + _observers([[2.0, 45.0, 0.0], [-3.0, 40.0, 0.0]])
            + f'[uncertainty]\ndraws = 120\nseed = {seed}\nsensitivity_draws = 32\nbrdf_scale_sigma = 0.5\npointing_sigma_rad = 0.002\n'
              '[uncertainty.map]\nextent_m = [-10.0, 10.0, 30.0, 48.0]\nspacing_m = 4.0\n')


def test_resume_reuses_chunks_and_refuses_another_run(tmp_path):
    first = _run(_small(tmp_path), tmp_path)
    csv1 = (tmp_path / "out" / "risk.csv").read_bytes()
    again = _run(_small(tmp_path), tmp_path)
    assert again.doc["run"]["ran"] == 0 and again.doc["run"]["reused"] == first.doc["run"]["chunks"]
    assert (tmp_path / "out" / "risk.csv").read_bytes() == csv1
    with pytest.raises(ValueError, match="another risk analysis"):
        _run(_small(tmp_path, seed=5), tmp_path)
    other = _run(_small(tmp_path, seed=5), tmp_path, force=True)
    assert other.doc["seed"] == 5 and other.doc["run"]["reused"] == 0


def test_map_files(tmp_path):
    res = _run(_small(tmp_path), tmp_path)
    out = tmp_path / "out"
    rows = (out / "probability_map.csv").read_text().strip().splitlines()
    assert rows[0].startswith("x_m,y_m,z_m,probability_exceed") and len(rows) - 1 == 5 * 5
    assert res.doc["map"]["shape"] == [5, 5]
    rasterio = pytest.importorskip("rasterio")
    with rasterio.open(out / "probability_map_local_frame.tif") as ds:
        assert (ds.count, ds.height, ds.width) == (3, 5, 5) and ds.crs is None
        band = ds.read(2)  # the upper bound, rows north to south
    hi = np.array([float(r.split(",")[5]) for r in rows[1:]]).reshape(5, 5)[::-1]
    assert np.allclose(band, hi, rtol=1e-6)
    gj = json.loads((out / "probability_contours_local_frame.json").read_text())
    assert all(f["properties"]["cells"] == int((hi >= f["properties"]["level"]).sum()) for f in gj["features"])
    for name in ("risk.html", "probability_map.png"):
        assert (out / name).exists()


def test_site_scene_writes_lonlat(tmp_path):
    pytest.importorskip("rasterio")
    text = scenes.example_path("range_geo").read_text()
    text += ('\n[uncertainty]\ndraws = 16\nsensitivity_draws = 0\nbrdf_scale_sigma = 0.3\n'
             '[uncertainty.map]\nextent_m = [-100.0, 100.0, -100.0, 100.0]\nspacing_m = 50.0\n')
    sc = scenes.loads(text, base_dir=scenes.example_path("range_geo").parent)
    res = run_risk(sc, tmp_path / "geo", serial=True)
    import rasterio

    with rasterio.open(tmp_path / "geo" / "probability_map.tif") as ds:
        assert ds.crs is not None and "ortho" in ds.crs.to_proj4()
    gj = json.loads((tmp_path / "geo" / "probability_contours.geojson").read_text())
    lat0, lon0, _ = sc.site.frame.origin_deg_m
    for f in gj["features"]:
        lon, lat = np.array(f["geometry"]["coordinates"][0][0]).reshape(-1, 2)[0] if f["geometry"]["type"] == "MultiPolygon" \
            else np.array(f["geometry"]["coordinates"][0][0])
        assert abs(lat - lat0) < 0.01 and abs(lon - lon0) < 0.01
    assert res.doc["map"]["files"][0] == "probability_map.csv"


# -- a property over random geometry ----------------------------------------------------
@settings(max_examples=6, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(yaw=st.floats(-40, 40), dist=st.floats(3.0, 12.0), side=st.floats(-60, 60), sigma=st.floats(0.2, 1.2),
       seed=st.integers(0, 1000))
def test_lambertian_lognormal_random_geometry(tmp_path_factory, yaw, dist, side, sigma, seed):
    """A large Lambertian plate turned by ``yaw`` and lit whole, a far-field observer at a
    random angle: P(E > MPE) = Phi(ln(E_med/MPE)/sigma) with E_med = rho P cos / (pi R^2);
    the power is chosen to put E_med near the MPE. The observer stays out of the incident
    beam (more than 8 deg between its direction and the beam's, seen from the plate)."""
    assume(abs(yaw - side) > 8)
    tmp = tmp_path_factory.mktemp("prop")
    a = math.radians(yaw)
    n = [math.sin(a), -math.cos(a), 0.0]
    t = [math.cos(a), math.sin(a), 0.0]
    c = np.array([0.0, 30.0, 0.0])
    b = math.radians(side)  # observer direction from the normal, in the horizontal plane
    u = np.array([math.cos(b) * n[0] - math.sin(b) * t[0], math.cos(b) * n[1] - math.sin(b) * t[1], 0.0])
    q = c + dist * u
    cos = math.cos(b)
    e_unit = 0.5 * cos / (math.pi * dist * dist)  # per watt
    z = norm.ppf(np.random.default_rng(seed).uniform(0.15, 0.85))
    power = MPE_1064_10S * math.exp(-sigma * z) / e_unit  # E_med = MPE exp(-sigma z): P = Phi(-z)
    text = (BASE.format(power=power, aim_y=30.0) + _plate("p", c, n, t, 4.0, '{ model = "lambertian", reflectance = 0.5 }')
            + _observers([q]) + f"[uncertainty]\ndraws = 600\nseed = {seed}\nsensitivity_draws = 0\nbrdf_scale_sigma = {sigma}\n")
    r = run_risk(scenes.loads(text), tmp / "o", serial=True).observers[0]
    ref = float(norm.cdf(-z))
    assert _within(r["probability_exceed"], ref, 600, k=4.5), (r["probability_exceed"], ref)
    ci = binomtest(r["hits"], 600).proportion_ci(0.95, method="exact")
    assert r["probability_ci_low"] == pytest.approx(ci.low, abs=1e-12) and r["probability_ci_high"] == pytest.approx(ci.high, abs=1e-12)


def test_failed_chunks_exit_4_and_write_nothing(tmp_path, monkeypatch):
    """A chunk of draws that fails (here an injected error in chunk 1, NaN ratios in chunk 2)
    stops the run with exit 4 and one summary line; no risk file is written, the finished
    chunks are kept, and --keep-going runs the rest before failing the same way."""
    import io

    import hazard.drivers.risk.run as rr
    from hazard.cli import main

    real = rr._main_chunk

    def broken(ev, prop, s, index, n):
        out = real(ev, prop, s, index, n)
        if index == 1:
            raise RuntimeError("injected chunk failure")
        if index == 2:
            out["ratio"][3] = np.nan  # one draw the engine could not evaluate: never counted as safe
        return out

    monkeypatch.setattr(rr, "_main_chunk", broken)
    monkeypatch.setattr(rr, "POINT_VALUES_PER_CHUNK", 1)  # chunks of 16 draws, the smallest
    scene = tmp_path / "s.toml"
    scene.write_text(_small(tmp_path))
    argv = ["risk", str(scene), "-o", str(tmp_path / "out"), "--serial", "--quiet", "--draws", "64", "--sensitivity-draws", "0"]
    out, err = io.StringIO(), io.StringIO()
    assert main(argv, stdout=out, stderr=err) == 4
    assert err.getvalue().count("\n") == 1, err.getvalue()
    assert "1 of 4 chunks of draws failed (16 draws), 2 not run (stopped at the first failure" in err.getvalue()
    assert "RuntimeError: injected chunk failure" in err.getvalue()
    assert not (tmp_path / "out" / "risk.json").exists() and not (tmp_path / "out" / "risk.csv").exists()
    assert sorted(p.name for p in (tmp_path / "out" / ".risk").glob("*.npz")) == ["m000000.npz"]
    err = io.StringIO()
    assert main(argv + ["--keep-going"], stdout=out, stderr=err) == 4
    assert "2 of 4 chunks of draws failed (32 draws);" in err.getvalue()
    assert "FloatingPointError: chunk m2: 1 of 16 draws gave a NaN exposure ratio" in err.getvalue()
    assert sorted(p.name for p in (tmp_path / "out" / ".risk").glob("*.npz")) == ["m000000.npz", "m000003.npz"]
    monkeypatch.setattr(rr, "_main_chunk", real)
    err = io.StringIO()
    assert main(argv, stdout=out, stderr=err) == 0 and err.getvalue() == ""
    doc = json.loads((tmp_path / "out" / "risk.json").read_text())
    assert doc["run"]["ran"] == 2 and doc["run"]["reused"] == 2


def test_draws_are_traced_by_the_analysis_stages(tmp_path):
    """The risk's evaluator takes its limits and ray scene from the analysis's own stages
    (``mpe``, ``rays``, once) and traces each turned beam through the stages ``beam`` and
    ``history``: the MPE is ANSI Table 5b's, the plate (1 m, 50 m down range, no
    atmosphere) takes the whole 100 W of the nominal beam, half of a beam turned so that its
    axis meets the plate's edge (a Gaussian cut through its centre), none of one turned past it."""
    from hazard.pipeline.stages import LimitsResult, RaysResult
    from hazard.drivers.risk.evaluate import DRAW_STAGES, SHARED_STAGES, Evaluator

    ev = Evaluator(scenes.loads(_small(tmp_path), base_dir=tmp_path), backend="numpy")
    assert (SHARED_STAGES, DRAW_STAGES) == (("mpe", "rays"), ("beam", "history"))
    assert isinstance(ev.shared["mpe"], LimitsResult) and isinstance(ev.shared["rays"], RaysResult)
    assert ev.mpe_w_m2 == pytest.approx(MPE_1064_10S, rel=1e-12) and ev.mu0 == 0.0
    assert sum(sp.total_power_w for sp in ev.nominal.spots) == pytest.approx(100.0, rel=1e-6)
    half = ev.traced_for(np.array([0.5 / 50.0, 0.0]))  # the axis meets the plate's edge x = 0.5 m at y = 50 m
    assert sum(sp.total_power_w for sp in half.spots) == pytest.approx(50.0, rel=1e-3)
    assert not np.allclose(half.beam.axis, ev.nominal.beam.axis)
    assert ev.traced_for(np.array([3.0 / 50.0, 0.0])).spots == []  # 2.5 m past the edge: 45 beam radii
