"""The crossings stage's pieces: observer surfaces and the search along a beam's axis."""

from __future__ import annotations

import math

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from hazard.pipeline import crossings
from hazard.pipeline.surfaces import Draped, Hemisphere, Plane
from scenes.geometry import Heightfield

finite = st.floats(-50.0, 50.0)


@settings(max_examples=40, deadline=None, derandomize=True)
@given(a=st.floats(0.0, 1.0), b=st.floats(0.0, 1.0), ux=finite, uy=finite, vz=st.floats(1.0, 30.0), off=st.floats(-20, 20))
def test_points_of_a_plane_grid_map_to_themselves_and_others_to_their_foot(a, b, ux, uy, vz, off):
    u = np.array([ux, uy, 0.0]) + [1.0, 0.0, 0.0]
    v = np.array([0.0, 0.5, vz])
    plane = Plane(np.array([3.0, -2.0, 1.0]), u, v)
    p = plane.origin_m + a * u + b * v
    np.testing.assert_allclose(plane.project(p[None])[0], p, atol=1e-9)
    n = np.cross(u, v) / np.linalg.norm(np.cross(u, v))
    np.testing.assert_allclose(plane.project((p + off * n)[None])[0], p, atol=1e-9)


def test_points_outside_a_grid_are_clamped_to_its_edge():
    plane = Plane(np.zeros(3), np.array([10.0, 0, 0]), np.array([0, 10.0, 0]))
    np.testing.assert_allclose(plane.project(np.array([[15.0, 5.0, 3.0], [-1.0, -1.0, 0.0]])), [[10.0, 5.0, 0.0], [0.0, 0.0, 0.0]])


def test_a_shell_projects_radially_and_onto_its_equator_below_it():
    shell = Hemisphere(np.array([1.0, 2.0, 3.0]), 5.0)
    out = shell.project(np.array([[1.0, 2.0, 13.0], [4.0, 2.0, -10.0], [1.0, 2.0, 3.0]]))
    np.testing.assert_allclose(out, [[1.0, 2.0, 8.0], [6.0, 2.0, 3.0], [1.0, 2.0, 8.0]])


def test_a_draped_grid_follows_the_terrain_at_eye_height():
    hf = Heightfield(-10.0, -10.0, 1.0, np.add.outer(np.arange(21.0), np.zeros(21)))  # z = y + 10
    dr = Draped(Plane(np.array([-5.0, -5.0, 0.0]), np.array([10.0, 0, 0]), np.array([0, 10.0, 0])), hf, 1.5)
    np.testing.assert_allclose(dr.project(np.array([[0.0, 2.0, 100.0]])), [[0.0, 2.0, 13.5]])


def test_every_local_maximum_is_refined_not_only_the_highest():
    """A beam crossing eye height twice (over a hill) gives two maxima along its axis: the
    weaker one is kept too (the stronger may be behind the hill for the map)."""
    def fn_t(t):
        return 3.0 * np.exp(-((t - 10.3) / 0.2) ** 2) + 1.0 * np.exp(-((t - 42.71) / 0.2) ** 2)
    found = sorted(crossings._maxima(fn_t, np.linspace(0.0, 50.0, 2001), 1e-3), key=lambda x: x[1])
    assert len(found) == 2
    assert math.isclose(found[0][1], 10.3, abs_tol=1e-6) and math.isclose(found[1][1], 42.71, abs_tol=1e-6)
    assert math.isclose(found[0][0], 3.0, rel_tol=1e-9) and math.isclose(found[1][0], 1.0, rel_tol=1e-9)
