"""Observer grids generated where they are used (scenes.observers): the same points as
the formula written here, rows in any order, the load-time checks (inside a solid,
off the terrain, below it) still exact, and an analysis that never holds the whole grid."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import hazard
import scenes
from scenes import SceneError

from tests._scene_text import PLATE_AT_50M

BASE = PLATE_AT_50M

TERRAIN = """
[terrain]
kind = "hill"
center_m = [10.0, -20.0, -2.0]
height_m = 6.0
radius_m = 15.0
extent_m = 200.0
resolution_m = 2.0
"""


def _vec(v):
    return "[" + ", ".join(repr(float(x)) for x in v) + "]"


def _grid(o, u, v, counts, eye=None):
    text = (f'[[observers]]\nname = "g"\norigin_m = {_vec(o)}\nu_m = {_vec(u)}\nv_m = {_vec(v)}\n'
            f"counts = [{counts[0]}, {counts[1]}]\n")
    return text + (f"eye_height_m = {eye!r}\n" if eye is not None else "")


def _formula(o, u, v, counts):
    """The grid by its definition: row-major, iu fastest (world coordinates)."""
    nu, nv = counts
    pts = [np.asarray(o) + iv / max(nv - 1, 1) * np.asarray(v) + iu / max(nu - 1, 1) * np.asarray(u)
           for iv in range(nv) for iu in range(nu)]
    return np.array(pts, float)


def test_a_grid_is_not_stored_and_generates_the_formulas_points():
    o, u, v, c = [-30.0, 5.0, 0.5], [60.0, 3.0, 0.0], [-2.0, 40.0, 1.0], (31, 17)
    s = scenes.loads(BASE + _grid(o, u, v, c))
    obs = s.observers
    assert obs.lazy and len(obs) == 31 * 17
    want = _formula(o, u, v, c)
    np.testing.assert_allclose(s.to_world(obs.block(0, len(obs))), want, rtol=0, atol=1e-12)
    rows = np.random.default_rng(1).permutation(len(obs))[:50]
    np.testing.assert_allclose(s.to_world(obs.take(rows)), want[rows], rtol=0, atol=1e-12)
    np.testing.assert_allclose(s.to_world(obs.block(100, 137)), want[100:137], rtol=0, atol=1e-12)
    assert obs.lazy  # still not stored
    np.testing.assert_allclose(s.to_world(obs.positions_m), want, rtol=0, atol=1e-12)
    assert not obs.lazy  # asked for the whole table: kept


def test_a_grid_at_eye_height_stands_on_the_terrain():
    o, u, v, c = [-40.0, -60.0, 0.0], [80.0, 0.0, 0.0], [0.0, 80.0, 0.0], (41, 41)
    s = scenes.loads(BASE + TERRAIN + _grid(o, u, v, c, eye=1.7))
    p = s.to_world(s.observers.positions_m)
    want = _formula(o, u, v, c)
    np.testing.assert_allclose(p[:, :2], want[:, :2], atol=1e-12)
    local = p - s.offset_m
    np.testing.assert_allclose(local[:, 2], s.terrain.height_at(local[:, 0], local[:, 1]) + 1.7, atol=1e-12)


def test_a_grid_leaving_the_terrain_is_an_error():
    with pytest.raises(SceneError, match=r"observers\[0\] \(g\): some points lie outside the terrain's extent"):
        scenes.loads(BASE + TERRAIN + _grid([150.0, 100.0, 0.0], [80.0, 0.0, 0.0], [0.0, 80.0, 0.0], (5, 5), eye=1.7))  # x to 230 m, past 210


def test_a_grid_below_the_terrain_is_an_error():
    with pytest.raises(SceneError, match="is below the terrain; use eye_height_m"):
        scenes.loads(BASE + TERRAIN + _grid([-20.0, -40.0, 0.0], [40.0, 0.0, 0.0], [0.0, 40.0, 0.0], (9, 9)))


def _box(centre, size):
    return f'[[occluders]]\nshape = "box"\ncenter_m = {_vec(centre)}\nsize_m = {_vec(size)}\n'


def _inside_box(p, centre, size):
    return np.all(np.abs(p - np.asarray(centre)) < np.asarray(size) / 2 * (1 - 1e-9), axis=1)


@settings(max_examples=40, deadline=None)
@given(yaw=st.floats(0, 6.28), tilt=st.floats(-0.6, 0.6), nu=st.integers(2, 40), nv=st.integers(2, 40),
       fu=st.floats(0, 1), fv=st.floats(0, 1), size=st.floats(0.2, 6.0), eye=st.booleans())
def test_a_point_inside_a_solid_is_found_without_generating_the_grid(yaw, tilt, nu, nv, fu, fv, size, eye):
    """A box anywhere over a random (tilted, turned) grid: the load refuses the scene
    exactly when some grid point lies inside the box (brute force over the formula's
    points here; the loader generates only the rows near the box)."""
    o = np.array([-20.0, 20.0, 3.0])
    u = 40.0 * np.array([np.cos(yaw), np.sin(yaw), 0.0])
    v = 30.0 * np.array([-np.sin(yaw) * np.cos(tilt), np.cos(yaw) * np.cos(tilt), np.sin(tilt)])
    centre = o + fu * u + fv * v
    text = BASE + (TERRAIN if eye else "") + _grid(o, u, v, (nu, nv), eye=1.7 if eye else None) + _box(centre, [size] * 3)
    if eye:  # the points stand at eye height over the hill: the box sits at that height
        terrain = scenes.loads(BASE + TERRAIN).terrain
        off = np.array([0.0, 0.0, 1.0])
        h = terrain.height_at(np.array([centre[0] - off[0]]), np.array([centre[1] - off[1]]))[0] + off[2] + 1.7
        centre = np.array([centre[0], centre[1], h])
        text = BASE + TERRAIN + _grid(o, u, v, (nu, nv), eye=1.7) + _box(centre, [size] * 3)
    pts = _formula(o, u, v, (nu, nv))
    if eye:
        local = pts - off
        pts[:, 2] = terrain.height_at(local[:, 0], local[:, 1]) + off[2] + 1.7
    inside = _inside_box(pts, centre, [size] * 3).any()
    if inside:
        with pytest.raises(SceneError, match="is inside occluders"):
            scenes.loads(text)
    else:
        scenes.loads(text)


def test_the_analysis_never_holds_a_large_grid(monkeypatch):
    monkeypatch.setattr(scenes.observers, "KEEP_ROWS", 200 * 150 - 1)  # the table is one row too many to keep
    s = scenes.loads(BASE + _grid([-20.0, -30.0, 0.0], [40.0, 0.0, 0.0], [0.0, 25.0, 2.0], (200, 150)))
    res = hazard.analyze(s)
    assert res.observers.observers.lazy  # map, direct beam, crossings and subtense generated their blocks
    assert len(res.observers) >= 200 * 150 and res.observers.peak_irradiance_w_m2.max() > 0
    p = res.observers.position_m  # the report's table asks for it
    assert p.shape == (len(res.observers), 3)


def test_a_small_grid_is_generated_once_and_kept(monkeypatch):
    """At most KEEP_ROWS rows: the points are generated once (by blocks on threads) and
    the direct beam, the map and the subtense read them; they are the grid's formula."""
    monkeypatch.setattr(scenes.observers, "KEEP_ROWS", 200 * 150 + 100)  # the grid and the beam's crossings
    s = scenes.loads(BASE + _grid([-20.0, -30.0, 0.0], [40.0, 0.0, 0.0], [0.0, 25.0, 2.0], (200, 150)))
    lazy = s.observers.block(0, len(s.observers)).copy()  # generated, not kept
    assert s.observers.lazy
    res = hazard.analyze(s)
    assert len(res.observers) <= 200 * 150 + 100 and not res.observers.observers.lazy
    assert np.array_equal(res.observers.observers.positions_m[:len(lazy)], lazy)


def _aperture_warning(pts, laser, d, labels):
    """The near-aperture warning's counts and first names by brute force over ``pts``."""
    rel = pts - laser
    near = np.flatnonzero((rel * rel).sum(1) < 1.0)
    ahead = rel[near] @ d >= -1e-9
    return int(ahead.sum()), int((~ahead).sum()), [labels[i] for i in near[:3]]


_NEAR_APERTURE = dict(yaw=st.floats(0, 6.28), tilt=st.floats(-1.5, 1.5), nu=st.integers(2, 60), nv=st.integers(2, 60),
                      fu=st.floats(-0.1, 1.1), fv=st.floats(-0.1, 1.1), dz=st.floats(-1.5, 1.5), span=st.floats(1.0, 30.0))


@pytest.mark.slow
@settings(max_examples=200, deadline=None, derandomize=True)
@given(**_NEAR_APERTURE)
def test_points_near_the_aperture_are_found_without_generating_the_grid_many(yaw, tilt, nu, nv, fu, fv, dz, span):
    """The same over more random grids."""
    test_points_near_the_aperture_are_found_without_generating_the_grid.hypothesis.inner_test(yaw, tilt, nu, nv, fu, fv, dz, span)


@settings(max_examples=25, deadline=None, derandomize=True)
@given(**_NEAR_APERTURE)
def test_points_near_the_aperture_are_found_without_generating_the_grid(yaw, tilt, nu, nv, fu, fv, dz, span):
    """A random (turned, tilted up to near vertical) grid about the laser: the load's
    warning counts the points within 1 m of the aperture, in front of and behind it, and
    names the first three, as brute force over the formula's points (the loader looks
    only at the index window about the aperture)."""
    laser, d = np.array([0.0, -50.0, 1.0]), np.array([0.0, 1.0, 0.0])
    u = span * np.array([np.cos(yaw), np.sin(yaw), 0.0])
    v = span * np.array([-np.sin(yaw) * np.cos(tilt), np.cos(yaw) * np.cos(tilt), np.sin(tilt)])
    o = laser + np.array([0.0, 0.0, dz]) - fu * u - fv * v
    s = scenes.loads(BASE + _grid(o, u, v, (nu, nv)))
    front, behind, names = _aperture_warning(_formula(o, u, v, (nu, nv)), laser, d, [f"g[{i}]" for i in range(nu * nv)])
    said = [w for w in s.warnings if "laser aperture" in w]
    if not front + behind:
        assert not said
        return
    assert len(said) == 1
    assert said[0].startswith(f"observers: {front + behind} point(s) within 1 m of the laser aperture ({', '.join(names)}")
    assert f": {front} on or in front" in said[0] and f"{behind} behind it" in said[0]
