"""Half/diff coordinates: round trips, singular points, reciprocity (spec section 2)."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import brdfmodels as bm

unit_upper = st.tuples(
    st.floats(0.0, np.pi / 2 * 0.999), st.floats(-np.pi, np.pi)
).map(lambda a: bm.spherical_to_vector(*a))


@given(unit_upper, unit_upper)
@settings(max_examples=200, deadline=None)
def test_round_trip_half_diff(wi, wo):
    th, ph, td, pd = bm.half_diff(wi, wo)
    wi2, wo2 = bm.half_diff_to_directions(th, ph, td, pd)
    np.testing.assert_allclose(wi2, wi, atol=1e-9)
    np.testing.assert_allclose(wo2, wo, atol=1e-9)
    assert 0 <= th <= np.pi / 2 + 1e-12 and 0 <= td <= np.pi / 2 + 1e-12


@given(unit_upper, unit_upper)
@settings(max_examples=200, deadline=None)
def test_reciprocity_maps_phi_d_by_pi(wi, wo):
    th, ph, td, pd = bm.half_diff(wi, wo)
    th2, ph2, td2, pd2 = bm.half_diff(wo, wi)
    assert th2 == pytest.approx(th, abs=1e-12)
    assert td2 == pytest.approx(td, abs=1e-12)
    if 1e-6 < td and th > 1e-6:
        dphi = np.angle(np.exp(1j * (pd2 - pd - np.pi)))
        assert abs(dphi) < 1e-7


def test_mirror_and_retro_are_finite_and_fixed():
    wi = bm.spherical_to_vector(0.7, 0.4)
    th, ph, td, pd = bm.half_diff(wi, bm.mirror_direction(wi))
    assert th == pytest.approx(0.0, abs=1e-15) and ph == 0.0
    assert td == pytest.approx(0.7, abs=1e-12)
    th, ph, td, pd = bm.half_diff(wi, wi)  # retro
    assert td == pytest.approx(0.0, abs=1e-7) and pd == 0.0 and th == pytest.approx(0.7)
    # both on the horizon, opposite: h falls back to the normal, still finite
    out = bm.half_diff([1, 0, 0], [-1, 0, 0])
    assert np.all(np.isfinite(out))


def test_known_values():
    # wi at 30 deg in the xz plane, wo at normal: h at 15 deg, d at 15 deg from h
    wi = bm.spherical_to_vector(np.radians(30), 0.0)
    th, ph, td, pd = bm.half_diff(wi, [0, 0, 1])
    assert np.degrees(th) == pytest.approx(15.0)
    assert np.degrees(td) == pytest.approx(15.0)
    assert ph == pytest.approx(0.0) and pd == pytest.approx(0.0)


def test_broadcasting_equals_per_element():
    rng = np.random.default_rng(1)
    wi = rng.normal(size=(4, 1, 3))
    wo = rng.normal(size=(1, 5, 3))
    out = bm.half_diff(wi, wo)
    assert out[0].shape == (4, 5)
    for i in range(4):
        for j in range(5):
            single = bm.half_diff(wi[i, 0], wo[0, j])
            np.testing.assert_allclose([o[i, j] for o in out], single, atol=1e-14)


def test_material_frame_rotation():
    v = np.array([1.0, 0.0, 0.0])
    # grooves at 90 deg: the surface x axis is the material's -y axis
    np.testing.assert_allclose(bm.to_material_frame(v, np.pi / 2), [0, -1, 0], atol=1e-15)
    frame = bm.local_frame([0, -1, 0], [1, 0, 0])
    np.testing.assert_allclose(bm.world_to_local([0, -1, 0], frame), [0, 0, 1], atol=1e-15)
    np.testing.assert_allclose(bm.local_to_world(bm.world_to_local([0.3, 0.2, 0.1], frame), frame), [0.3, 0.2, 0.1])


@pytest.mark.parametrize(
    "bad, match",
    [([0, 0, 0], "zero-length"), ([np.nan, 0, 1], "non-finite"), ([1, 0], r"shape \(\.\.\., 3\)"), ("x", "3-vectors")],
)
def test_bad_directions(bad, match):
    with pytest.raises(ValueError, match=match) as exc:
        bm.half_diff(bad, [0, 0, 1])
    assert "wi" in str(exc.value)


def test_tangent_parallel_to_normal():
    with pytest.raises(ValueError, match="parallel"):
        bm.local_frame([0, 0, 1], [0, 0, 2])
