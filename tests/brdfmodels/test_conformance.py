"""One conformance suite over every registered model (style: scikit-learn's checks)."""

import numpy as np
import pytest

import brdfmodels as bm

from .conftest import EXAMPLES

GRAZING = np.radians(89.9999)


def _random_pairs(n=400, seed=0, below=True):
    rng = np.random.default_rng(seed)
    wi = rng.normal(size=(n, 3))
    wo = rng.normal(size=(n, 3))
    if not below:
        wi[:, 2] = np.abs(wi[:, 2]) + 1e-3
        wo[:, 2] = np.abs(wo[:, 2]) + 1e-3
    return wi, wo


def test_every_registered_model_has_an_example():
    covered = {type(m).name for _, m, _, _ in EXAMPLES}
    assert set(bm.available_models()) <= covered


def test_non_negative_finite_and_zero_below_horizon(example):
    _, model, state, _ = example
    wi, wo = _random_pairs()
    f = model.evaluate(wi, wo, state=state)
    assert np.all(np.isfinite(f)) and np.all(f >= 0)
    below = (wi[:, 2] <= 0) | (wo[:, 2] <= 0)
    assert np.all(f[below] == 0)
    fc = model.evaluate_cos(wi, wo, state=state)
    assert np.all(np.isfinite(fc)) and np.all(fc >= 0) and np.all(fc[below] == 0)


def test_projected_equals_fr_times_cos(example):
    _, model, state, _ = example
    wi, wo = _random_pairs(below=False)
    np.testing.assert_allclose(model.evaluate_cos(wi, wo, state=state), model.evaluate(wi, wo, state=state) * wo[:, 2] / np.linalg.norm(wo, axis=1), rtol=1e-10)


def test_reciprocal_where_claimed(example):
    _, model, state, _ = example
    if not model.reciprocal:
        pytest.skip("model does not claim reciprocity")
    wi, wo = _random_pairs(below=False, seed=3)
    np.testing.assert_allclose(model.evaluate(wi, wo, state=state), model.evaluate(wo, wi, state=state), rtol=1e-9)


PHYSICAL = [e for e in EXAMPLES if e[3]]


@pytest.mark.parametrize("example", PHYSICAL, ids=[e[0] for e in PHYSICAL])
@pytest.mark.parametrize("theta_i_deg", [0.0, 40.0, 75.0])
def test_dhr_at_most_one_for_physical_parameters(example, theta_i_deg):
    _, model, state, _ = example
    wi = bm.spherical_to_vector(np.radians(theta_i_deg), 0.3)
    r = bm.hemispherical_reflectance(model, wi, state=state, rtol=1e-4)
    assert r.value <= 1.0 + r.error_estimate


@pytest.mark.parametrize(
    "pair",
    ["grazing_i", "grazing_o", "grazing_both_mirror", "grazing_both_retro", "mirror", "retro", "normal_both"],
)
def test_finite_at_singular_geometry(example, pair):
    _, model, state, _ = example
    g = bm.spherical_to_vector(GRAZING, 0.2)
    w = bm.spherical_to_vector(0.5, 1.0)
    cases = {
        "grazing_i": (g, w),
        "grazing_o": (w, g),
        "grazing_both_mirror": (g, bm.mirror_direction(g)),
        "grazing_both_retro": (g, g),
        "mirror": (w, bm.mirror_direction(w)),
        "retro": (w, w),
        "normal_both": ([0, 0, 1], [0, 0, 1]),
    }
    wi, wo = cases[pair]
    f = model.evaluate(wi, wo, state=state)
    assert np.isfinite(f) and f >= 0
    assert np.isfinite(model.evaluate_cos(wi, wo, state=state))


def test_continuous_near_mirror_and_retro(example):
    # Continuity, not smoothness: a fan-out exponent s < 1 (Eq. 34) makes the lobe
    # Hoelder-continuous at theta_h = 0, so the gap must shrink with the perturbation.
    _, model, state, _ = example
    w = bm.spherical_to_vector(0.5, 1.0)
    for target in (bm.mirror_direction(w), w):
        th, ph = bm.vector_to_spherical(target)
        at = float(model.evaluate(w, target, state=state))
        gaps = []
        for eps in (1e-4, 1e-7, 1e-10):
            near = [bm.spherical_to_vector(th + eps * np.cos(a), ph + eps * np.sin(a)) for a in np.linspace(0, 2 * np.pi, 7)]
            gaps.append(max(abs(float(model.evaluate(w, v, state=state)) - at) for v in near))
        assert gaps[2] <= 1e-3 * max(at, 1e-12) + 1e-12
        assert gaps[2] <= gaps[0] + 1e-12


def test_broadcasting_equals_per_element(example):
    _, model, state, _ = example
    rng = np.random.default_rng(5)
    wi = np.abs(rng.normal(size=(3, 1, 3))) + [0, 0, 0.1]
    wo = rng.normal(size=(1, 4, 3))
    f = model.evaluate(wi, wo, state=state)
    assert f.shape == (3, 4)
    for i in range(3):
        for j in range(4):
            assert f[i, j] == pytest.approx(float(model.evaluate(wi[i, 0], wo[0, j], state=state)), rel=1e-12, abs=0)


def test_json_round_trip_exact(example, tmp_path):
    _, model, state, _ = example
    again = bm.loads(bm.dumps(model))
    assert again == model and type(again) is type(model)
    wi, wo = _random_pairs(seed=9)
    np.testing.assert_array_equal(again.evaluate(wi, wo, state=state), model.evaluate(wi, wo, state=state))
    path = bm.save(model, tmp_path / "m.json")
    assert bm.load(path) == model


def test_immutable(example):
    _, model, _, _ = example
    with pytest.raises(AttributeError, match="immutable"):
        model.anything = 1
    arrays = [v for v in vars(model).values() if isinstance(v, np.ndarray)]
    for arr in arrays:
        with pytest.raises(ValueError):
            arr[...] = 0
