"""Rays from far away decide hit or miss to within a micrometre of a triangle's edge: the
ray engine works in float32, and a start 1 km away is rounded by ~6e-5 m (its ulp), so a
ray is started at the box of the triangles (``RayScene._ahead``) and only the box's own
rounding is left. Expected values from the geometry alone: a ray aimed a distance
``delta`` inside a square's edge hits it at the range of its aim point; one aimed
``delta`` outside misses (both ray engines)."""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from hazard.physics.rays import RayScene

SIDE = 0.5  # the square's side [m]


def _square(centre, normal, along):
    """A square of side ``SIDE`` (two triangles) centred at ``centre``, one edge's
    direction ``along``; returns the mesh tuple, the inward unit vector of its edge at
    ``centre + (SIDE / 2) * out`` and that edge's direction."""
    n = np.asarray(normal, float) / np.linalg.norm(normal)
    u = np.asarray(along, float) - (np.asarray(along, float) @ n) * n
    u /= np.linalg.norm(u)
    v = np.cross(n, u)
    c = np.asarray(centre, float)
    h = SIDE / 2
    verts = np.array([c - h * u - h * v, c + h * u - h * v, c + h * u + h * v, c - h * u + h * v])
    faces = np.array([[0, 1, 2], [0, 2, 3]])
    return (verts, faces, 0), v, u  # the edge at c + h v runs along u; -v points inside


@settings(max_examples=6, deadline=None, derandomize=True)
@given(rng_seed=st.integers(0, 2**31 - 1), range_m=st.floats(300.0, 3000.0),
       tilt_deg=st.floats(0.0, 70.0))
def test_hit_or_miss_a_micrometre_from_an_edge_from_far_away(rng_seed, range_m, tilt_deg):
    """A square 0.5 m wide, tilted ``tilt_deg`` to rays that start ``range_m`` away along
    an oblique line (every coordinate of the start large, so float32 rounds all three);
    aim points 1-10 um inside or outside one of its edges, anywhere along that edge's middle
    half: inside hits at the aim point's distance, outside misses (Embree)."""
    pytest.importorskip("embreex")
    _edge_rays("embree", rng_seed, range_m, tilt_deg)


def test_hit_or_miss_from_far_away_numpy_engine():
    """The same on trimesh's float64 engine (one draw: it is the slower engine)."""
    pytest.importorskip("rtree")
    _edge_rays("numpy", 12345, 2000.0, 35.0)


def _edge_rays(backend, rng_seed, range_m, tilt_deg):
    rng = np.random.default_rng(rng_seed)
    t = math.radians(tilt_deg)
    normal = np.array([0.0, -math.cos(t), math.sin(t)])
    mesh, out, along = _square([0.1, 0.2, 0.3], normal, [1.0, 0.0, 0.0])
    scene = RayScene([mesh], backend=backend)
    n = 200
    delta = rng.uniform(1e-6, 1e-5, n) * rng.choice([-1.0, 1.0], n)  # > 0: outside the edge
    aim = np.array([0.1, 0.2, 0.3]) + (SIDE / 2 + delta)[:, None] * out + rng.uniform(-SIDE / 4, SIDE / 4, n)[:, None] * along
    come = np.array([0.37, 0.8, 0.47]) - 0.3 * rng.random(3) * np.array([1.0, 0.0, 1.0])
    come = come if come @ normal < 0 else -come  # travelling into the square's face
    come /= np.linalg.norm(come)
    start = aim - range_m * come
    hits = scene.first_hit(start, np.broadcast_to(come, start.shape))
    inside = delta < 0
    np.testing.assert_array_equal(hits.hit, inside)
    np.testing.assert_allclose(hits.t[inside], range_m, rtol=0, atol=1e-6 * range_m)


def test_rays_that_miss_the_box_or_start_inside_it_are_not_moved():
    """The start is moved only along a ray that meets the box, from outside it: a start
    inside it, a ray pointing away from it and one passing beside it keep theirs."""
    mesh, _, _ = _square([0.0, 0.0, 0.0], [0.0, -1.0, 0.0], [1.0, 0.0, 0.0])
    scene = RayScene([mesh], backend="numpy")
    o = np.array([[0.0, -1000.0, 0.0], [0.0, -0.0001, 0.0], [0.0, -1000.0, 0.0], [5.0, -1000.0, 0.0]])
    d = np.array([[0.0, 1.0, 0.0], [0.0, 1.0, 0.0], [0.0, -1.0, 0.0], [0.0, 1.0, 0.0]])
    start, ahead = scene._ahead(o, d)
    np.testing.assert_array_equal(start, o + ahead[:, None] * d)
    pad = 1e-3 * SIDE
    np.testing.assert_allclose(ahead, [1000.0 - pad, 0.0, 0.0, 0.0], rtol=0, atol=1e-9)
    hits = scene.first_hit(o, d)
    np.testing.assert_array_equal(hits.hit, [True, True, False, False])
    np.testing.assert_allclose(hits.t[:2], [1000.0, 0.0001], rtol=1e-12)
