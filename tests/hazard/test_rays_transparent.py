"""``RayScene.occluded(..., transparent=)``: the convex object a segment leaves does not
block it; anything else on the segment still does (both ray engines)."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import scenes
from hazard.physics.rays import CONVEX_SHAPES, RayScene, own_object
from scenes.geometry import shape_mesh
from scenes.spec import OccluderSpec


def _objects():
    """A sphere of radius 1 at the origin (object 0) and a 1 m cube centred 5 m along +x
    (object 1)."""
    ball = shape_mesh(OccluderSpec(shape="sphere", center_m=[0.0, 0.0, 0.0], size_m=[2.0]))
    cube = shape_mesh(OccluderSpec(shape="box", center_m=[5.0, 0.0, 0.0], size_m=[1.0, 1.0, 1.0]))
    return [(ball.vertices, ball.faces, 0), (cube.vertices, cube.faces, 1)]


@pytest.mark.parametrize("backend", ["embree", "numpy"])
def test_own_object_transparent_others_not(backend):
    """Segments from 0.9 m inside the sphere (its tessellation crosses each of them):
    blocked without ``transparent``; with the sphere transparent, clear towards +y, -x and
    up to 0.5 m before the cube, still blocked through the cube (+x, 10 m out)."""
    pytest.importorskip("rtree") if backend == "numpy" else pytest.importorskip("embreex")
    scene = RayScene(_objects(), backend=backend)
    start = np.array([[0.0, 0.9, 0.0], [0.9, 0.0, 0.0], [-0.9, 0.0, 0.0], [0.9, 0.0, 0.0]])
    end = np.array([[0.0, 10.0, 0.0], [10.0, 0.0, 0.0], [-10.0, 0.0, 0.0], [4.0, 0.0, 0.0]])
    np.testing.assert_array_equal(scene.occluded(start, end), [True, True, True, True])
    np.testing.assert_array_equal(scene.occluded(start, end, transparent=0), [False, True, False, False])


def test_own_object_only_for_convex_targets():
    """Targets of the convex shapes are transparent to their own lines of sight; the
    terrain (no shape) and meshes are not: their own relief can shadow their reflection."""
    assert set(CONVEX_SHAPES) == {"plate", "disk", "box", "sphere", "cylinder"}
    text = """
name = "t"
[laser]
wavelength_nm = 1064.0
power_w = 1.0
beam_diameter_m = 0.01
divergence_rad = 0.001
position_m = [0.0, -10.0, 5.0]
aim_m = [0.0, 0.0, 5.0]
[exposure]
duration_s = 1.0
[[targets]]
name = "ball"
shape = "sphere"
center_m = [0.0, 0.0, 5.0]
size_m = [1.0]
material = { model = "specular", reflectance = 0.9 }
[terrain]
kind = "flat"
extent_m = 100.0
resolution_m = 10.0
"""
    sc = scenes.loads(text)
    assert own_object(sc.targets[0]) == sc.targets[0].index == 0
    assert own_object(sc.terrain_target) is None


def _traced_back_by_first_hit(scene, start, end, own):
    """The trace-back written with the public first hit (its refined t and objects): a
    segment is blocked when the first hit seen from its end (moved the scene's clearance
    towards the start) is another object's and lies within the segment."""
    clear = 1e-6 * scene.scale_m
    vec = end - start
    length = np.linalg.norm(vec, axis=1)
    back = -vec / length[:, None]
    hits = scene.first_hit(end + back * np.minimum(clear, 0.5 * length)[:, None], back)
    blocked_all = scene.occluded(start, end)
    return blocked_all & hits.hit & (hits.t < length - clear) & (hits.obj != own)


@pytest.mark.parametrize("backend", ["embree", pytest.param("numpy", marks=pytest.mark.slow)])  # numpy: 56 s
@settings(derandomize=True, deadline=None, max_examples=5)
@given(seed=st.integers(0, 2**31 - 1))
def test_transparent_equals_the_first_hit_trace_back(backend, seed):
    """``occluded(..., transparent=)`` (faces only from the engine, t on the other
    objects' hits) gives exactly the booleans of the trace-back written with
    ``first_hit``, on random segments from inside and around the sphere to random
    points around both objects; and the per-scene normals are the per-call ones."""
    pytest.importorskip("rtree") if backend == "numpy" else pytest.importorskip("embreex")
    scene = RayScene(_objects(), backend=backend)
    rng = np.random.default_rng(seed)
    n = 400
    start = rng.normal(size=(n, 3))
    start *= (rng.uniform(0.0, 1.5, n) / np.linalg.norm(start, axis=1))[:, None]
    end = rng.uniform([-8.0, -6.0, -6.0], [12.0, 6.0, 6.0], size=(n, 3))
    got = scene.occluded(start, end, transparent=0)
    np.testing.assert_array_equal(got, _traced_back_by_first_hit(scene, start, end, 0))
    assert got.any() and not got.all()  # both outcomes occur
    faces = rng.integers(0, scene.n_triangles, 50)
    v = scene.vertices[scene.faces[faces]]
    nrm = np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0])
    np.testing.assert_array_equal(scene.face_normals(faces), nrm / np.linalg.norm(nrm, axis=1, keepdims=True))
