"""Model-specific checks against analytic cases and published numbers."""

import json

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import brdfmodels as bm

from .conftest import TS5_PUBLISHED, glossy_log_coefficients, make_dynamic


# --- Lambertian ---------------------------------------------------------------------------
def test_lambertian_value_and_albedo():
    m = bm.Lambertian(0.5)
    assert m.evaluate([0.2, 0.1, 0.9], [-0.3, 0.5, 0.4]) == pytest.approx(0.5 / np.pi)
    r = bm.hemispherical_reflectance(m, bm.spherical_to_vector(np.radians(60), 0.0), rtol=1e-8)
    assert r.converged and r.value == pytest.approx(0.5, abs=max(r.error_estimate, 1e-9) * 3)


# --- Specular and Fresnel ---------------------------------------------------------------
def test_specular_has_no_finite_part_and_traces_as_beam():
    m = bm.Specular(0.9)
    wi = bm.spherical_to_vector(0.4, 0.2)
    assert m.evaluate(wi, bm.mirror_direction(wi)) == 0.0
    assert m.has_specular and m.specular_reflectance(wi) == 0.9
    np.testing.assert_allclose(bm.mirror_direction(wi), wi * [-1, -1, 1])
    assert bm.hemispherical_reflectance(m, wi).value == pytest.approx(0.9)


@pytest.mark.parametrize("material, expected", [("cu", 0.991), ("al", 0.954)])
def test_normal_incidence_reflectance_of_metals(material, expected):
    # shared/data README: Cu 0.991 (n=0.123, k=7.245), Al 0.954 (n=1.029, k=9.252) at 1.064 um
    m = bm.Specular.for_material(material, 1064.0)
    assert float(m.specular_reflectance([0, 0, 1])) == pytest.approx(expected, abs=5e-4)


def test_fresnel_dielectric_and_grazing():
    assert float(bm.fresnel_reflectance(1.0, 1.5)) == pytest.approx(0.04)
    # Brewster angle: p-polarised reflectance vanishes, unpolarised = R_s / 2
    tb = np.arctan(1.5)
    ci, ct = np.cos(tb), np.cos(np.arcsin(np.sin(tb) / 1.5))
    rs = ((ci - 1.5 * ct) / (ci + 1.5 * ct)) ** 2
    assert float(bm.fresnel_reflectance(ci, 1.5)) == pytest.approx(rs / 2, rel=1e-12)
    assert float(bm.fresnel_reflectance(0.0, 0.123, 7.245)) == pytest.approx(1.0)


def test_specular_argument_errors():
    with pytest.raises(ValueError, match="exactly one"):
        bm.Specular()
    with pytest.raises(ValueError, match="exactly one"):
        bm.Specular(0.5, n=1.5)
    with pytest.raises(ValueError, match="wavelength_nm=5000.0 is outside the cu table"):
        bm.Specular.for_material("cu", 5000.0)
    with pytest.raises(ValueError, match=r"material='gold': expected one of \['al', 'cu'\]"):
        bm.optical_constants("gold", 1064)


# --- Five-parameter Torrance-Sparrow -----------------------------------------------------
def test_ts5_white_paint_dhr_matches_paper():
    # Zhang et al. 2010: model directional-hemispherical reflectance of white paint 73.4 %
    m = bm.TorranceSparrow5(**TS5_PUBLISHED["white_paint"])
    r = bm.hemispherical_reflectance(m, [0, 0, 1], rtol=1e-6)
    assert r.converged
    assert round(r.value, 3) == 0.734
    assert r.value == pytest.approx(0.7341, abs=2e-4)


def test_ts5_peak_value_at_normal_mirror():
    # D(0) = 1, R0(gamma = 0) = 1, G = 1: f_r = kb + kd at normal incidence, normal view
    p = TS5_PUBLISHED["forged_steel"]
    m = bm.TorranceSparrow5(**p)
    assert m.evaluate([0, 0, 1], [0, 0, 1]) == pytest.approx(p["kb"] + p["kd"])


@pytest.mark.parametrize("name", sorted(TS5_PUBLISHED))
def test_ts5_published_sets_finite_everywhere(name):
    m = bm.TorranceSparrow5(**TS5_PUBLISHED[name])
    t = np.radians(np.concatenate([np.linspace(0, 89, 30), [89.9, 89.9999]]))
    p = np.radians(np.linspace(-180, 180, 25))
    tt, pp = np.meshgrid(t, p, indexing="ij")
    wo = bm.spherical_to_vector(tt, pp).reshape(-1, 3)
    for ti in t:
        f = m.evaluate(bm.spherical_to_vector(ti, 0.0), wo)
        assert np.all(np.isfinite(f)) and np.all(f >= 0)


@given(
    kb=st.floats(0, 10), kr=st.floats(0.05, 20), a=st.floats(0.05, 20), b=st.floats(-100, 5), kd=st.floats(0, 3),
    ti=st.floats(0, np.pi / 2), to=st.floats(0, np.pi / 2), po=st.floats(-np.pi, np.pi),
)
@settings(max_examples=300, deadline=None)
def test_ts5_property_finite_non_negative(kb, kr, a, b, kd, ti, to, po):
    m = bm.TorranceSparrow5(kb=kb, kr=kr, a=a, b=b, kd=kd)
    f = m.evaluate(bm.spherical_to_vector(ti, 0.0), bm.spherical_to_vector(to, po))
    assert np.isfinite(f) and f >= 0


def test_ts5_rejects_overflowing_b():
    with pytest.raises(ValueError, match="b=800.0: expected a number <= 700"):
        bm.TorranceSparrow5(kb=1, kr=1, a=1, b=800, kd=0)


# --- spherical-harmonic models -------------------------------------------------------------
def test_sh_matches_closed_form_two_term_expansion():
    # ln f~ = c0 y_0^0 + c1 y_1^0(theta~_h) with theta~_h = pi (theta_h / (pi/2))^0.6 (Eq. 34)
    basis = bm.SHBasis(1, 0, 0, 0)
    c0, c1 = 1.3, 2.1
    m = bm.SphericalHarmonicBRDF(basis, [c0, c1], fanout=0.6, log=True)
    rng = np.random.default_rng(3)
    wi = bm.spherical_to_vector(rng.uniform(0, 1.5, 200), rng.uniform(-3, 3, 200))
    wo = bm.spherical_to_vector(rng.uniform(0, 1.5, 200), rng.uniform(-3, 3, 200))
    th = bm.half_diff(wi, wo)[0]
    tt = np.pi * (th / (np.pi / 2)) ** 0.6
    f_tilde = np.exp(c0 / np.sqrt(4 * np.pi) + c1 * np.sqrt(3 / (4 * np.pi)) * np.cos(tt))
    np.testing.assert_allclose(m.evaluate(wi, wo), f_tilde / (wi[:, 2] * wo[:, 2]), rtol=1e-12)
    np.testing.assert_allclose(m.evaluate_cos(wi, wo), f_tilde / wi[:, 2], rtol=1e-12)
    lin = bm.SphericalHarmonicBRDF(basis, [c0, -c1], log=False)
    expect = np.maximum(c0 / np.sqrt(4 * np.pi) - c1 * np.sqrt(3 / (4 * np.pi)) * np.cos(tt), 0)
    np.testing.assert_allclose(lin.evaluate(wi, wo), expect / (wi[:, 2] * wo[:, 2]), rtol=1e-12)
    # f_r cos(theta_r) at a grazing observer is f~ / cos(theta_i): finite, no 0/0
    g = bm.spherical_to_vector(np.radians(89.9999999), 0.0)
    assert np.isfinite(m.evaluate_cos([0, 0, 1], g)) and float(m.evaluate_cos([0, 0, 1], g)) < 20


def test_dynamic_interpolates_coefficients_linearly():
    # Bailey et al. 2008 Sec. IV H: 840 C from the 800 C and 900 C tables = 0.6 c800 + 0.4 c900
    basis = bm.SHBasis(4, 0, 2, 0)
    c800 = glossy_log_coefficients(basis, peak_sr=20)
    c900 = glossy_log_coefficients(basis, peak_sr=5)
    dyn = bm.DynamicBRDF(basis, [1073.15, 1173.15], [c800, c900], "temperature_k")
    np.testing.assert_allclose(dyn.coefficients_at(1113.15), 0.6 * c800 + 0.4 * c900, rtol=1e-12)
    wi, wo = bm.spherical_to_vector(0.3, 0), bm.spherical_to_vector(0.35, 3.0)
    assert dyn.evaluate(wi, wo, state=1113.15) == pytest.approx(float(dyn.at_state(1113.15).evaluate(wi, wo)))


def test_dynamic_state_policy():
    dyn = make_dynamic()
    wi = [0, 0, 1]
    with pytest.raises(ValueError, match=r"temperature_k=1000.0 is outside the tabulated range \[300.0, 900.0\]"):
        dyn.evaluate(wi, wi, state=1000.0)
    with pytest.raises(ValueError, match="depends on temperature_k; pass state="):
        dyn.evaluate(wi, wi)
    clamped = bm.DynamicBRDF(dyn.basis, dyn.states, dyn.coefficients, "temperature_k", extrapolation="clamp")
    assert clamped.evaluate(wi, wi, state=5000.0) == dyn.evaluate(wi, wi, state=900.0)
    with pytest.raises(ValueError, match="extrapolation='linear': expected one of"):
        bm.DynamicBRDF(dyn.basis, dyn.states, dyn.coefficients, "temperature_k", extrapolation="linear")


@pytest.mark.parametrize("projected", [False, True])
def test_evaluate_many_equals_per_state(projected):
    dyn = make_dynamic()
    rng = np.random.default_rng(2)
    wi, wo = rng.normal(size=(500, 3)), rng.normal(size=(500, 3))
    states = np.array([300.0, 333.3, 600.0, 750.0, 900.0])
    many = dyn.evaluate_many(wi, wo, states, projected=projected, chunk_rows=128)
    fn = dyn.evaluate_cos if projected else dyn.evaluate
    for j, s in enumerate(states):
        np.testing.assert_allclose(many[:, j], fn(wi, wo, state=s), rtol=1e-11, atol=0)
    # per-row states broadcast against the directions
    per_row = dyn.evaluate(wi, wo, state=np.full(500, 600.0))
    np.testing.assert_allclose(per_row, many[:, 2] if not projected else dyn.evaluate(wi, wo, state=600.0), rtol=1e-11)


@pytest.mark.parametrize("log", [True, False])
@pytest.mark.parametrize("projected", [False, True])
def test_evaluate_many_max_over_states_equals_max_of_the_full_array(log, projected):
    # the reduced path takes the max before exp / clipping / division by the cosines
    dyn = make_dynamic()
    if not log:
        dyn = bm.DynamicBRDF(dyn.basis, dyn.states, np.abs(dyn.coefficients), "temperature_k", log=False)
    rng = np.random.default_rng(3)
    wi, wo = rng.normal(size=(700, 3)), rng.normal(size=(700, 3))  # half below the horizon
    states = np.linspace(300.0, 900.0, 9)
    scale = rng.uniform(0.0, 3.0, 700)
    scale[:20] = 0.0
    full = dyn.evaluate_many(wi, wo, states, projected=projected, row_scale=scale, chunk_rows=97)
    top = dyn.evaluate_many(wi, wo, states, projected=projected, row_scale=scale, chunk_rows=97, reduce="max")
    assert top.shape == (700,)
    np.testing.assert_allclose(top, full.max(axis=1), rtol=1e-14, atol=0)
    assert np.all(top[:20] == 0) and np.any(top > 0)
    with pytest.raises(ValueError, match="reduce='min': expected None, 'max' or 'path-max'"):
        dyn.evaluate_many(wi, wo, states, reduce="min")


@settings(max_examples=200, deadline=None)
@given(st.lists(st.floats(-1e3, 1e3), min_size=2, max_size=8, unique=True),
       st.lists(st.floats(-1e3, 1e3), min_size=1, max_size=40),
       st.integers(0, 2**32 - 1))
def test_segment_extremes_keep_the_max_of_any_piecewise_linear_function(nodes, query, seed):
    from brdfmodels.states import interpolation_weights, segment_extremes

    nodes = np.sort(np.array(nodes))
    q = np.clip(np.array(query), nodes[0], nodes[-1])
    values = np.random.default_rng(seed).normal(size=(3, nodes.size))  # three functions
    kept = segment_extremes(nodes, q)
    assert set(kept) <= set(q) and kept.size <= 2 * (nodes.size + 1)
    full = (values @ interpolation_weights(nodes, q)).max(axis=1)
    np.testing.assert_allclose((values @ interpolation_weights(nodes, kept)).max(axis=1), full, rtol=0, atol=1e-9)


def test_dynamic_shape_errors():
    basis = bm.SHBasis(4, 0, 2, 0)
    with pytest.raises(ValueError, match=r"coefficients: expected shape \(2, 7\)"):
        bm.DynamicBRDF(basis, [0.0, 1.0], np.zeros((2, 5)), "time_s")
    with pytest.raises(ValueError, match="strictly increasing"):
        bm.DynamicBRDF(basis, [1.0, 0.0], np.zeros((2, 7)), "time_s")


# --- envelopes --------------------------------------------------------------------------
def _pairs(n=3000, seed=4):
    rng = np.random.default_rng(seed)
    wi = bm.spherical_to_vector(np.arccos(rng.uniform(0.02, 1, n)), rng.uniform(-np.pi, np.pi, n))
    wo = bm.spherical_to_vector(np.arccos(rng.uniform(0.02, 1, n)), rng.uniform(-np.pi, np.pi, n))
    return wi, wo


def test_exact_envelope_bounds_every_state():
    dyn = make_dynamic()
    env = bm.Envelope(dyn)
    wi, wo = _pairs()
    rep = bm.envelope_report(env, dyn, wi, wo)
    assert rep.fraction_bounded == 1.0
    assert rep.min_ratio == pytest.approx(1.0)  # exact: reached at a node
    # the max over a dense state sweep equals the envelope (no state beats the nodes)
    sweep = np.max([dyn.evaluate(wi, wo, state=s) for s in np.linspace(300, 900, 61)], axis=0)
    np.testing.assert_allclose(env.evaluate(wi, wo), sweep, rtol=1e-12)


def test_paper_adjusted_envelope_is_conservative_and_reports_overprediction():
    dyn = make_dynamic()
    env = bm.Envelope(dyn, base=0.01, multiplier=1.5, fanout_h=0.45)
    rep = bm.envelope_report(env, dyn, *_pairs())
    assert rep.fraction_bounded == 1.0
    assert rep.median_ratio > 1.5 and np.isfinite(rep.max_ratio)
    assert "bounded 100.0000 %" in str(rep)


@given(st.floats(300, 900))
@settings(max_examples=50, deadline=None)
def test_envelope_property_any_state(state):
    dyn = make_dynamic()
    wi, wo = _pairs(200, seed=7)
    assert np.all(bm.Envelope(dyn).evaluate(wi, wo) >= dyn.evaluate(wi, wo, state=state) * (1 - 1e-12))


def test_envelope_of_scaled_dynamic_is_conservative():
    # factor 1 -> 0.2 between nodes times an SH lobe: per-segment max of a product
    dyn = make_dynamic()
    model = bm.Scaled(dyn, bm.StateTable([300.0, 500.0, 900.0], [1.0, 0.2, 0.6], "temperature_k"))
    rep = bm.envelope_report(bm.Envelope(model), model, *_pairs(800))
    assert rep.fraction_bounded == 1.0


@pytest.mark.parametrize("kw, match", [(dict(multiplier=0.9), "multiplier=0.9"), (dict(base=-1.0), "base=-1.0")])
def test_envelope_rejects_non_conservative_adjustments(kw, match):
    with pytest.raises(ValueError, match=match):
        bm.Envelope(make_dynamic(), **kw)


# --- combinations ------------------------------------------------------------------------
def test_sum_and_scaled():
    lam, spec = bm.Lambertian(0.3), bm.Specular(0.5)
    s = lam + spec + bm.Lambertian(0.1)
    assert isinstance(s, bm.Sum) and len(s.models) == 3
    assert s.evaluate([0, 0, 1], [0, 1, 1]) == pytest.approx(0.4 / np.pi)
    assert s.specular_reflectance([0, 0, 1]) == 0.5
    sc = bm.Scaled(s, bm.StateTable([0.0, 10.0], [1.0, 0.5], "time_s"))
    assert sc.is_dynamic and sc.state_name == "time_s"
    assert sc.evaluate([0, 0, 1], [0, 1, 1], state=5.0) == pytest.approx(0.75 * 0.4 / np.pi)
    assert sc.specular_reflectance([0, 0, 1], state=10.0) == pytest.approx(0.25)
    r = bm.hemispherical_reflectance(sc, [0, 0, 1], state=10.0, rtol=1e-7)
    assert r.value == pytest.approx(0.5 * 0.9, abs=1e-5)


def test_sum_rejects_mixed_states():
    a = make_dynamic()
    b = bm.Scaled(bm.Lambertian(0.5), bm.StateTable([0.0, 1.0], [1.0, 0.5], "time_s"))
    with pytest.raises(ValueError, match="different states"):
        bm.Sum([a, b])


# --- registry and persistence ---------------------------------------------------------------
def test_create_by_name_case_insensitive():
    assert bm.create("Lambertian", reflectance=0.2) == bm.Lambertian(0.2)
    assert "torrance-sparrow-5" in bm.available_models()


def test_unknown_model_and_parameter_errors():
    with pytest.raises(ValueError, match=r"model='lambert' is unknown: expected one of \[.*'lambertian'"):
        bm.create("lambert", reflectance=0.2)
    with pytest.raises(ValueError, match=r"lambertian: unknown parameters \['reflectivity'\]"):
        bm.create("lambertian", reflectivity=0.2)


@pytest.mark.parametrize("bad", [-0.1, float("nan"), 1.5, "0.5"])
def test_bad_reflectance(bad):
    with pytest.raises(ValueError, match="reflectance="):
        bm.Lambertian(bad)


def test_loads_rejects_unknown_version_and_keys():
    doc = json.loads(bm.dumps(bm.Lambertian(0.5)))
    with pytest.raises(ValueError, match="version: this library reads version 1"):
        bm.loads(json.dumps({**doc, "version": 2}))
    with pytest.raises(ValueError, match="missing 'model'"):  # was a KeyError (issue 30)
        bm.loads(json.dumps({"format": doc["format"], "version": 1}))
    with pytest.raises(ValueError, match=r"^format: expected 'brdfmodels.model' \(not a brdfmodels model file\)$"):
        bm.loads(json.dumps({"format": "SECRET-abc", "token": "SECRET-def"}))  # nothing of the file is quoted
    with pytest.raises(ValueError, match=r"^1 unknown key\(s\) in model file; expected only format, version, model$"):
        bm.loads(json.dumps({**doc, "extra": 1}))  # the key is not quoted: a model file is data (issue 30)
    doc["model"]["params"]["colour"] = "red"
    with pytest.raises(ValueError, match="unknown parameters"):
        bm.loads(json.dumps(doc))


def test_entry_point_plugins_are_registered(monkeypatch):
    from brdfmodels import registry

    class Plugin(bm.Lambertian):
        pass

    class EP:
        name = "test-plugin-model"

        def load(self):
            return Plugin

    monkeypatch.setattr(registry, "_PLUGINS_LOADED", False)
    monkeypatch.setattr(registry, "entry_points", lambda group: [EP()] if group == "brdfmodels.models" else [])
    try:
        assert "test-plugin-model" in bm.available_models()
        assert isinstance(bm.create("test-plugin-model", reflectance=0.1), Plugin)
    finally:
        registry._REGISTRY.pop("test-plugin-model", None)


def test_save_is_atomic_on_failure(tmp_path, monkeypatch):
    target = tmp_path / "m.json"
    target.write_text("old")
    class Unserialisable(bm.Lambertian):
        def to_dict(self):
            return {"type": "lambertian", "params": {"reflectance": float("nan")}}  # json refuses nan

    with pytest.raises(ValueError):
        bm.save(Unserialisable(0.5), target)
    assert target.read_text() == "old"

    def failing_write(*a, **k):
        raise RuntimeError("disk full")

    from brdfmodels import fileio

    monkeypatch.setattr(fileio.os, "replace", failing_write)
    with pytest.raises(RuntimeError):
        bm.save(bm.Lambertian(0.5), target)
    assert target.read_text() == "old" and list(tmp_path.iterdir()) == [target]


def test_load_names_the_file(tmp_path):
    p = tmp_path / "bad.json"
    p.write_text("{not json")
    with pytest.raises(ValueError, match="bad.json: not a brdfmodels JSON document"):
        bm.load(p)


@pytest.mark.parametrize("scale", [1e2, 1e4])
def test_extreme_sh_coefficients_stay_finite(scale):
    basis = bm.SHBasis(8, 4, 2, 0)
    rng = np.random.default_rng(11)
    coef = rng.normal(scale=scale, size=(2, basis.size))
    dyn = bm.DynamicBRDF(basis, [0.0, 1.0], coef, "time_s")
    wi, wo = rng.normal(size=(300, 3)), rng.normal(size=(300, 3))
    many = dyn.evaluate_many(wi, wo, [0.0, 0.5, 1.0])
    assert np.all(np.isfinite(many)) and np.all(many >= 0) and many.max() <= bm.FR_MAX
    single = dyn.evaluate(wi, wo, state=0.5)
    assert np.all(np.isfinite(single))
