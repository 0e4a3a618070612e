"""The ground footprint's upper bound of the near-field integral (issue 30 item 3 / issue 37):
near a Lambertian spot the footprint first bounds the integral over the spot's triangles
and integrates only the nodes whose bounded sum reaches the MPE.

References written here, never from the engine:

- the distance from a point to a triangle: the minimum over a fine barycentric grid of the
  triangle (within the grid's spacing);
- the section-10 integral over a grazing ground spot (``_ground_reference`` of
  ``test_near_field_spot``: tensor Gauss-Legendre over the beam's cross-section): the bound
  never falls below it (beyond the integral's own 1 % tolerance);
- the footprint with the bound switched off: the same mask, the same ratio wherever a node
  is hazardous, and elsewhere a ratio at least the exact one and below 1.
"""

from __future__ import annotations


import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import hazard

from . import _refs as ref
from .test_near_field_spot import EYE, GY, G_EXTENT, _ground_reference, _ground_scene

FEW = settings(ref.FAST, max_examples=8)
MANY = settings(ref.SLOW, max_examples=80)


def _grid_distance(p, tri, n=240):
    """min |p - x| over x on a barycentric grid of the triangle (n steps per edge), and the
    grid's spacing bound (the longest edge / n)."""
    i, j = np.meshgrid(np.arange(n + 1), np.arange(n + 1), indexing="ij")
    keep = i + j <= n
    u, v = i[keep] / n, j[keep] / n
    x = tri[0] + u[:, None] * (tri[1] - tri[0]) + v[:, None] * (tri[2] - tri[0])
    edge = max(np.linalg.norm(tri[1] - tri[0]), np.linalg.norm(tri[2] - tri[1]), np.linalg.norm(tri[0] - tri[2]))
    return float(np.min(np.linalg.norm(x - p, axis=1))), edge / n


_COORD = st.floats(-10.0, 10.0, allow_nan=False)
_POINT = st.tuples(_COORD, _COORD, _COORD)


def _check_distance(p, a, b, c):
    from hazard.physics.near_field import point_triangle_distance

    tri = np.array([a, b, c], float)
    p = np.asarray(p, float)
    d = float(point_triangle_distance(p[None, :], tri[None])[0])
    want, h = _grid_distance(p, tri)
    assert d <= want + 1e-9  # a lower bound of every point of the triangle: what the footprint's bound needs
    assert d >= want - h - 1e-9


@FEW
@given(_POINT, _POINT, _POINT, _POINT)
def test_point_triangle_distance(p, a, b, c):
    _check_distance(p, a, b, c)


@pytest.mark.slow
@MANY
@given(_POINT, _POINT, _POINT, _POINT)
def test_point_triangle_distance_many(p, a, b, c):
    _check_distance(p, a, b, c)


def test_point_triangle_distance_closed_forms():
    from hazard.physics.near_field import point_triangle_distance

    tri = np.array([[[0.0, 0.0, 0.0], [4.0, 0.0, 0.0], [0.0, 3.0, 0.0]]] * 4)
    p = np.array([[1.0, 1.0, 2.5], [5.0, 0.0, 0.0], [-3.0, -4.0, 0.0], [4.0, 3.0, 0.0]])
    # above the inside: the height; beyond a vertex: to it; beyond the hypotenuse 3x + 4y = 12 (its foot
    # (2.56, 1.08) inside the edge): (3 * 4 + 4 * 3 - 12) / 5
    want = [2.5, 1.0, 5.0, 12.0 / 5.0]
    np.testing.assert_allclose(point_triangle_distance(p, tri), want, rtol=1e-12)


@pytest.fixture(scope="module")
def ground():
    """The grazing 100 kW beam on Lambertian ground (``test_near_field_spot``) on a 5 m grid."""
    return hazard.analyze(_ground_scene(5.0, G_EXTENT, [np.array([0.0, GY, 2.0])]))


@pytest.fixture(scope="module")
def both(ground):
    """Its footprint with the bound and without (no occluder: no lines of sight)."""
    from hazard.physics import near_field
    from hazard.physics.keepout import ground_footprint

    args = (ground.spots, ground.beam, ground.scene.terrain, None, ground.mpe_w_m2, 0.0, EYE)
    before = near_field.BOUNDED.snapshot()
    fast = ground_footprint(*args, bound_below_mpe=True)
    used = near_field.BOUNDED.snapshot()
    return fast, ground_footprint(*args, bound_below_mpe=False), used["pairs"] + used["observers"] - sum(before.values())


def test_bounded_footprint_is_the_exact_one(both):
    """Same mask; equal ratios where hazardous; elsewhere at least the exact ratio, below 1; and
    the bound was used (counted in ``near_field.BOUNDED``)."""
    fast, exact, bounded = both
    assert bounded > 0
    assert fast.mask.sum() > 0
    np.testing.assert_array_equal(fast.mask, exact.mask)
    np.testing.assert_array_equal(np.isnan(fast.ratio), np.isnan(exact.ratio))
    np.testing.assert_array_equal(fast.ratio[fast.mask], exact.ratio[exact.mask])
    rest = ~fast.mask & ~np.isnan(fast.ratio)
    assert (fast.ratio[rest] >= exact.ratio[rest] * (1 - 1e-6)).all()
    assert (fast.ratio[rest] < 1.0).all()
    assert (fast.ratio[rest] > exact.ratio[rest] * 1.01).any()  # the bound really replaced some integrals


def test_bound_is_above_the_section_10_integral(ground, both):
    """Every ground node's bounded ratio against the integral over the ground spot written in
    the test (1 %: that integral's own tolerance against the engine's exact one)."""
    fast = both[0]
    t, off = ground.scene.terrain, np.asarray(ground.scene.offset_m, float)
    ny, nx = fast.mask.shape
    gx, gy = np.meshgrid(t.x0 + off[0] + t.dx * np.arange(nx), t.y0 + off[1] + t.dx * np.arange(ny))
    box = (np.abs(gx) <= 38.0) & (np.abs(gy - GY) <= 38.0)
    want = _ground_reference(np.stack([gx[box], gy[box], np.full(int(box.sum()), EYE)], axis=1)) / ground.mpe_w_m2
    got = np.nan_to_num(fast.ratio[box].astype(float), nan=0.0)
    assert (got >= want * (1 - 0.01)).all()


def _check_spot_bound(ground, xs, ys, hs):
    from hazard.physics.engine import spot_irradiance

    spot = next(s for s in ground.spots if s.target.name == "terrain")
    pts = np.stack([np.asarray(xs), GY + np.asarray(ys), np.asarray(hs)], axis=1)
    g = np.ones(len(pts))
    exact, _ = spot_irradiance(spot, pts, g, 0.0)
    bound, _ = spot_irradiance(spot, pts, g, 0.0, bound=True)
    assert (bound >= exact * (1 - 1e-9)).all()


_OBS = dict(xs=st.lists(st.floats(-60.0, 60.0), min_size=6, max_size=6),
            ys=st.lists(st.floats(-40.0, 600.0), min_size=6, max_size=6),
            hs=st.lists(st.floats(0.05, 30.0), min_size=6, max_size=6))


@FEW
@given(**_OBS)
def test_spot_bound_at_random_observers(ground, xs, ys, hs):
    _check_spot_bound(ground, xs, ys, hs)


@pytest.mark.slow
@MANY
@given(**_OBS)
def test_spot_bound_at_random_observers_many(ground, xs, ys, hs):
    _check_spot_bound(ground, xs, ys, hs)
