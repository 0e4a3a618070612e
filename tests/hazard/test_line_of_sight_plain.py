"""Lines of sight from a convex target's spot: segments that cannot cross the target's own
triangles (the whole target behind the plane through their start, by more than float32
rounding, and their end in front of it) are asked of the engine once, without the trace
back from their end (``RayScene.behind_plane``). The answer must be the same as with the
trace back, and the same as a segment-triangle test in float64 written here (Moller-
Trumbore over every triangle but the target's own)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import scenes
from hazard.physics import engine
from hazard.pipeline.analysis import plan
from hazard.pipeline.log import StageLog
from hazard.pipeline.stages import REGISTRY, derive_plan, run_stages
from hazard.physics.rays import RayScene
from hazard.pipeline.spots import ray_meshes

SCENE = """
name = "los"
[laser]
wavelength_nm = 1064.0
power_w = 10.0
beam_diameter_m = {beam}
divergence_rad = 0.0005
position_m = [{lx}, {ly}, {lz}]
aim_m = [{cx}, {cy}, {cz}]
[exposure]
duration_s = 1.0
[[targets]]
name = "t"
shape = "{shape}"
center_m = [{cx}, {cy}, {cz}]
normal = [{nx}, {ny}, {nz}]
tangent = [1.0, 0.0, 0.0]
size_m = {size}
material = {{ model = "lambertian", reflectance = 0.5 }}
{occluders}
[[observers]]
name = "one"
points_m = [[{cx}, {oy}, {cz}]]
"""

SIZES = {"plate": "[2.0, 2.0]", "box": "[2.0, 0.3, 2.0]", "sphere": "[1.5]"}


def _segment_blocked(start, ends, tri, clear_m):
    """True where the segment start -> end (its last ``clear_m`` left out) crosses one of
    the triangles ``tri`` (T, 3, 3): Moller-Trumbore in float64, t in (0, |end - start| - clear]."""
    vec = ends - start
    length = np.linalg.norm(vec, axis=1)
    d = vec / length[:, None]
    e1, e2 = tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]
    p = np.cross(d[:, None, :], e2[None])  # (N, T, 3)
    det = np.einsum("ntk,tk->nt", p, e1)
    ok = np.abs(det) > 1e-14
    inv = np.where(ok, 1.0 / np.where(ok, det, 1.0), 0.0)
    s = start - tri[:, 0]  # (T, 3)
    u = np.einsum("ntk,tk->nt", p, s) * inv
    q = np.cross(s, e1)  # (T, 3)
    v = np.einsum("nk,tk->nt", d, q) * inv
    t = np.einsum("tk,tk->t", e2, q)[None] * inv
    hit = ok & (u >= 0) & (v >= 0) & (u + v <= 1) & (t > 0) & (t <= (length - clear_m)[:, None])
    return hit.any(axis=1)


def _scene(shape, offset, tilt, boxes, beam_m=0.01):
    cx, cy, cz = offset, offset, 5.0 + offset
    nrm = np.array([math.sin(tilt[0]), -math.cos(tilt[0]) * math.cos(tilt[1]), math.cos(tilt[0]) * math.sin(tilt[1])])
    occ = "".join(f'[[occluders]]\nshape = "box"\ncenter_m = [{cx + b[0]}, {cy + b[1]}, {cz + b[2]}]\n'
                  f"size_m = [{b[3]}, {b[3]}, {b[3]}]\n" for b in boxes)
    text = SCENE.format(lx=cx + 3.0, ly=cy - 40.0, lz=cz + 2.0, cx=cx, cy=cy, cz=cz, nx=nrm[0], ny=nrm[1], nz=nrm[2],
                        shape=shape, size=SIZES[shape], occluders=occ, oy=cy - 10.0, beam=beam_m)
    return scenes.loads(text)


def _spots(scene):
    """The scene's spots, as the analysis builds them (its stages up to ``beam`` only)."""
    reg = {k: REGISTRY[k] for k in ("mpe", "rays", "beam")}
    inputs = {"scene": scene, "plan": plan(scene), "backend": "embree", "threads": 1, "keep_history": None}
    return run_stages(reg, derive_plan(reg, inputs), inputs, StageLog())["beam"].traced.built.spots


def _check(shape, offset, tilt, boxes, seed, beam_m=0.01):
    scene = _scene(shape, offset, tilt, boxes, beam_m)
    (spot,) = _spots(scene)
    rays = RayScene(ray_meshes(scene))
    c = spot.centroid  # the scene's local frame (re-centred on its first target: scenes.scene)
    rng = np.random.default_rng(seed)
    pts = c + rng.uniform([-15.0, -30.0, -8.0], [15.0, 4.0, 8.0], size=(400, 3))
    got = engine.spot_line_of_sight(rays, spot, pts)[0]
    # the same rows with every segment traced back from its end (the plain query switched off)
    rays_back = RayScene(ray_meshes(scene))
    rays_back.behind_plane = lambda *a: False
    np.testing.assert_array_equal(got, engine.spot_line_of_sight(rays_back, spot, pts)[0])
    # the other ray backend (float64 numpy) takes the same split and gives the same answers
    np.testing.assert_array_equal(got, engine.spot_line_of_sight(RayScene(ray_meshes(scene), backend="numpy"), spot, pts)[0])
    # an independent reference on the rows in front of the spot's plane
    nrm = spot.mean_frame[2]
    start = rays.off_surface(spot.sight_point_m, nrm)
    front = (pts - start) @ nrm > 0
    own = rays.face_object == spot.target.index
    tri = rays.vertices[rays.faces[~own]]
    blocked = _segment_blocked(start, pts[front], tri, 1e-6 * rays.scale_m)
    np.testing.assert_array_equal(got[front], ~blocked)
    return got[front], rays.behind_plane(spot.target.index, start, nrm)


BOX = st.tuples(st.floats(-10.0, -2.5),  # beside the beam (x >= 0 from the laser to the target)
                st.floats(-25.0, -2.0), st.floats(-4.0, 4.0), st.floats(0.5, 3.0))


@settings(derandomize=True, deadline=None, max_examples=4)
@given(shape=st.sampled_from(sorted(SIZES)), offset=st.sampled_from([0.0, 1e3, 1e6]),
       tilt=st.tuples(st.floats(-0.6, 0.6), st.floats(-0.6, 0.6)), boxes=st.lists(BOX, min_size=1, max_size=3),
       seed=st.integers(0, 2**31 - 1), beam_m=st.sampled_from([0.01, 0.5]))
def test_plain_lines_of_sight_match_the_trace_back_and_float64(shape, offset, tilt, boxes, seed, beam_m):
    """Random convex targets (plate, box, sphere), tilts, 1-3 boxes in front, observers all
    around (boxes beside the beam), the scene 0, 1 km or 1000 km from the origin, a 1 cm
    or a 0.5 m beam (its near field, 20 spot sizes, reaches behind the target): the lines of sight are
    the trace back's and the numpy backend's, and in front of the spot those of the float64
    segment test."""
    _check(shape, offset, tilt, boxes, seed, beam_m)


@pytest.mark.slow
@settings(derandomize=True, deadline=None, max_examples=40)
@given(shape=st.sampled_from(sorted(SIZES)), offset=st.sampled_from([0.0, 1e3, 1e6]),
       tilt=st.tuples(st.floats(-0.6, 0.6), st.floats(-0.6, 0.6)), boxes=st.lists(BOX, min_size=1, max_size=3),
       seed=st.integers(0, 2**31 - 1), beam_m=st.sampled_from([0.01, 0.5]))
def test_plain_lines_of_sight_match_the_trace_back_and_float64_many(shape, offset, tilt, boxes, seed, beam_m):
    """The property above on more draws."""
    _check(shape, offset, tilt, boxes, seed, beam_m)


def test_the_plain_query_is_taken_for_a_plate():
    """A plate: its start 1e-6 of the scene's size (13 m) off its face, more than float32
    rounding there (4 x 2**-23 x 13 m + 8 x 2**-23 x 2 m = 8e-6 m against 1.3e-5 m): the
    plain query is taken, and both answers occur. The same 1000 km from the origin: the
    scene is re-centred on its first target (scenes.scene), so the same holds."""
    for offset in (0.0, 1e6):
        visible, plain = _check("plate", offset, (0.2, -0.1), [(-4.0, -12.0, 0.0, 2.0)], 1)
        assert plain and visible.any() and not visible.all()
    # a 0.5 m beam: its near field (20 spot sizes) reaches observers behind the plate, whose
    # segments cross its plane: those keep the trace back (the plain query would be blocked by the plate)
    _check("plate", 0.0, (0.2, -0.1), [(-4.0, -12.0, 0.0, 2.0)], 1, beam_m=0.5)


def test_behind_plane_geometry():
    """A unit cube at the origin: the plane z = 0.5 + g with normal +z has the cube behind
    it by g. g = 1e-3 m: behind (the rounding bound there is 4 x 2**-23 x 0.501 + 8 x 2**-23
    x 1.001 = 1.2e-6 m); g = 1e-6 m: not proven (below that bound); g = 0 or a plane cutting
    the cube: not behind; the normal -z through z = -0.5 - g: behind."""
    from scenes.geometry import shape_mesh
    from scenes.spec import OccluderSpec

    cube = shape_mesh(OccluderSpec(shape="box", center_m=[0.0, 0.0, 0.0], size_m=[1.0, 1.0, 1.0]))
    far = shape_mesh(OccluderSpec(shape="box", center_m=[50.0, 0.0, 0.0], size_m=[1.0, 1.0, 1.0]))
    rays = RayScene([(cube.vertices, cube.faces, 0), (far.vertices, far.faces, 1)])
    up, down = np.array([0.0, 0.0, 1.0]), np.array([0.0, 0.0, -1.0])
    assert rays.behind_plane(0, [0.2, 0.1, 0.5 + 1e-3], up)
    assert not rays.behind_plane(0, [0.2, 0.1, 0.5 + 1e-6], up)
    assert not rays.behind_plane(0, [0.2, 0.1, 0.5], up)
    assert not rays.behind_plane(0, [0.2, 0.1, 0.2], up)
    assert rays.behind_plane(0, [0.0, 0.0, -0.5 - 1e-3], down)
    # 50 m out the coordinates' rounding counts: 4 x 2**-23 x 50.5 + 8 x 2**-23 x 1.0 = 2.5e-5 m
    assert rays.behind_plane(1, [50.0, 0.0, 0.5 + 1e-3], up)
    assert not rays.behind_plane(1, [50.0, 0.0, 0.5 + 1e-5], up)
