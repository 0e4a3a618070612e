"""The pictures of issue 18, checked in their pixels and their data: the 3-D close view
and overview (legend whole, colours as the legend says, the mirror beam to its NOHD in
the overview), the plan view's lobe outlines, rings and named observers, the elevation
view's projections, and the log-distance framing."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from hazard.pictures import palette as C
from hazard.pictures.palette import rgb
from tests._bundled import bundled

pytest.importorskip("matplotlib")


@pytest.fixture(scope="module")
def svc():
    return bundled("steel_vs_copper")


def _near(img, colour, tol):
    return np.all(np.abs(img[..., :3].astype(int) - np.array(rgb(colour))) <= tol, axis=-1)


def _region(img, box):
    r0, r1, c0, c1 = box
    return img[r0:r1, c0:c1]


@pytest.fixture(scope="module")
def renders(svc, tmp_path_factory):
    pytest.importorskip("pyvista")
    import matplotlib.image as mpimg

    from hazard.pictures import render

    out = tmp_path_factory.mktemp("renders")
    paths = render.keepout(svc, out, vtk=False)
    imgs = {k: (mpimg.imread(paths[k])[..., :3] * 255).round().astype(int) for k in ("keepout", "overview")}
    return paths, imgs


@pytest.mark.parametrize("name", ["keepout", "overview"])
def test_the_legend_is_whole_and_beside_the_scene(renders, name):
    paths, imgs = renders
    img, layout = imgs[name], paths["layout"][name]
    h, w = img.shape[:2]
    assert layout["scene"][1] - layout["scene"][0] == 900 and layout["scene"][3] == 1280  # the 3-D view at its size
    assert layout["legend"][2] == 1280 and layout["legend"][3] == w  # the legend panel ends at the picture's edge
    legend = _region(img, layout["legend"])
    dark = np.flatnonzero(np.any(legend.min(axis=-1) < 128, axis=0))
    assert len(dark) and dark.max() < legend.shape[1] - 4  # its text ends inside the panel: nothing cut
    rows = np.flatnonzero(np.any(legend.min(axis=-1) < 128, axis=1))
    assert rows.max() < legend.shape[0] - 4
    assert np.all(img[:, -2:] >= 250) and np.all(img[-2:, :] >= 250)  # white margins: nothing runs off the picture


@pytest.mark.parametrize("colour", [C.STATIC, C.DYNAMIC, C.MIRROR, C.HAZARDOUS, C.SAFE])
def test_each_legend_colour_is_in_the_legend_and_in_the_close_view(renders, colour):
    paths, imgs = renders
    img, layout = imgs["keepout"], paths["layout"]["keepout"]
    assert _near(_region(img, layout["legend"]), colour, 6).sum() > 30  # the legend's patch or line
    scene = _region(img, layout["scene"])
    if colour == C.MIRROR:  # the mirror beam leaves the close view at once: its colour is drawn unlit
        assert _near(scene, colour, 10).sum() > 300
    elif colour in (C.STATIC, C.DYNAMIC):  # lit surfaces: the hue of the legend's colour, shaded
        r, g, b = (scene[..., i] for i in range(3))
        hue = (b > r + 60) & (b > g + 15) if colour == C.STATIC else (r > 150) & (g > 0.5 * r) & (g < 0.85 * r) & (b < 0.25 * r)
        assert hue.sum() > 800
    else:
        assert _near(scene, colour, 12).sum() > 100


def test_the_overview_holds_the_mirror_beam_to_its_nohd(svc, renders):
    from hazard.pictures import render

    paths, imgs = renders
    scene = _region(imgs["overview"], paths["layout"]["overview"]["scene"])
    mirror = _near(scene, C.MIRROR, 10)
    cols = np.flatnonzero(mirror.any(axis=0))
    assert mirror.sum() > 600 and np.ptp(cols) > 250  # the copper mirror beam, ~5 km, drawn across the picture
    blocks = render._scene_blocks(svc, 6.0)
    frames = render.framings(svc, blocks)
    over = frames["overview"]
    copper = next(t for t in svc.targets if t.name == "copper")
    sp = next(s for s in svc.spots if s.target.name == "copper")
    end = sp.centroid + np.asarray(copper.specular_direction) * copper.specular_nohd_dynamic_m
    drawn = over.draw(end[None])[0]
    assert np.all(drawn >= over.bounds[:, 0]) and np.all(drawn <= over.bounds[:, 1])
    assert over.compressed and over.extent_m >= copper.specular_nohd_dynamic_m * 0.99


def test_log_distance_is_continuous_monotone_and_true_inside():
    from hazard.pictures.render import Framing

    f = Framing(np.zeros((3, 2)), np.array([1.0, 2.0, 3.0]), 10.0)
    r = np.array([0.0, 5.0, 10.0 - 1e-9, 10.0, 10.0 + 1e-9, 20.0, 1e3, 1e5])
    pts = f.centre_m + r[:, None] * np.array([0.6, 0.8, 0.0])
    d = np.linalg.norm(f.draw(pts) - f.centre_m, axis=1)
    want = np.where(r <= 10.0, r, 10.0 * (1 + np.log(np.maximum(r, 10.0) / 10.0)))
    np.testing.assert_allclose(d, want, rtol=1e-12, atol=1e-9)
    assert np.all(np.diff(d) > 0)
    dirs = (f.draw(pts[1:]) - f.centre_m) / d[1:, None]
    np.testing.assert_allclose(dirs, np.broadcast_to([0.6, 0.8, 0.0], dirs.shape), atol=1e-12)  # radial


def test_ring_radii_are_round_and_reach_the_extent():
    from hazard.pictures.render import ring_radii

    assert ring_radii(63.0, False) == [10.0, 20.0, 30.0, 40.0, 50.0, 60.0]
    log_rings = ring_radii(7968.0, True)
    assert log_rings == [100.0, 200.0, 500.0, 1000.0, 2000.0, 5000.0]


def test_a_two_state_dynamic_lobe_is_drawn_from_its_history_in_time_order():
    """It crashed (np.unique flattened the (T, 2) states), and a sorted history would
    have dropped the slump: the drawn lobe reaches the reported dynamic NOHD."""
    pytest.importorskip("pyvista")
    from hazard.pictures import render

    res = bundled("stainless_melt")
    blocks = render._scene_blocks(res, 6.0)
    drawn = float(np.max(blocks["lobe_dynamic_stainless"]["nohd_m"]))
    reported = res.targets[0].dynamic_lobe.max_range_m
    assert 0.9 * reported <= drawn <= reported * (1 + 1e-9)


# ----- the plan view


@pytest.fixture(scope="module")
def plan(svc):
    from hazard.pictures.plan_view import PlanViewDisplay

    return PlanViewDisplay.from_result(svc)


def test_the_plan_names_the_worst_hazardous_observers_and_counts_the_rest(svc, plan):
    ratio = np.asarray(svc.hazard_ratio)
    bad = np.flatnonzero(ratio >= 1.0)
    worst = bad[np.argsort(-ratio[bad], kind="stable")][:8]
    assert [t.split(" (")[0] for _, t in plan.labels] == [svc.observers.labels[i] for i in worst]
    assert plan.unlabelled == len(bad) - 8


def test_the_plan_draws_both_lobes_of_each_target(plan):
    kinds = sorted((t, k) for t, k, cut, rings, holes in plan.lobes)
    assert kinds == [("copper", "dynamic"), ("copper", "static"), ("stainless", "dynamic"), ("stainless", "static")]
    assert all(cut == "projection" for _, _, cut, _, _ in plan.lobes)  # no ground in this scene


def test_the_plan_picture_shows_outlines_rings_and_labels(plan):
    import io

    import matplotlib.image as mpimg

    img = (mpimg.imread(io.BytesIO(plan.png_bytes()))[..., :3] * 255).round().astype(int)
    assert _near(img, C.DYNAMIC, 12).sum() > 200  # the dynamic outlines (dashed)
    assert _near(img, C.STATIC, 12).sum() > 100  # the static outlines' edges
    assert _near(img, C.RINGS, 6).sum() > 1000  # the range rings
    assert _near(img, C.MIRROR, 12).sum() > 300


# ----- the elevation view


def test_the_elevation_projects_across_the_aim(svc):
    from hazard.pictures.elevation_view import ElevationViewDisplay

    d = ElevationViewDisplay.from_result(svc)
    scene = svc.scene
    u = np.array([scene.laser_direction[0], scene.laser_direction[1], 0.0])
    u /= np.linalg.norm(u)
    from hazard.outputs.finding_geometry import mirror_lines

    ends = {name: end for name, _, end, _ in mirror_lines(svc)}  # scene-local 3-D, on the zone's axis (tests/hazard/test_mirror_lines.py)
    assert set(ends) == {name for name, _, _ in d.mirrors}
    for name, _a, b in d.mirrors:  # each end: distance along the aim's azimuth from the laser, world height
        end = ends[name]
        want = [float((end - scene.laser_position_m)[:2] @ u[:2]), float(end[2] + scene.offset_m[2])]
        np.testing.assert_allclose(b, want, rtol=1e-6, atol=1e-6)
    assert {(t, k) for t, k, _ in d.lobes} == {("copper", "static"), ("copper", "dynamic"), ("stainless", "static"), ("stainless", "dynamic")}


def test_the_elevation_of_a_scene_with_ground_draws_the_terrain_under_the_aim():
    from hazard.pictures.elevation_view import ElevationViewDisplay

    res = bundled("range_terrain")
    d = ElevationViewDisplay.from_result(res)
    s, ground, eye = d.profile
    t = res.scene.terrain
    u = np.asarray(res.scene.laser_direction[:2], float)
    u /= np.linalg.norm(u)
    xy = res.scene.laser_position_m[:2] + s[:, None] * u
    np.testing.assert_allclose(ground, t.height_at(xy[:, 0], xy[:, 1]) + res.scene.offset_m[2])
    assert eye == res.scene.spec.analysis.footprint_eye_height_m
    lo, hi = t.x0, t.x0 + t.dx * (t.heights.shape[1] - 1)
    assert np.all((xy[:, 0] >= lo - 1e-9) & (xy[:, 0] <= hi + 1e-9))  # not drawn past the terrain's edge


def _box_mesh(center, size):
    """An axis-aligned box: 8 corners, 12 triangles (written here, not the scene's)."""
    from types import SimpleNamespace

    corners = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], float) * np.asarray(size) / 2
    quads = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
    faces = np.array([t for a, b, c, d in quads for t in ((a, b, c), (a, c, d))])
    return SimpleNamespace(vertices=corners + np.asarray(center, float), faces=faces)


def test_the_elevation_cuts_an_occluder_on_the_aim_plane_and_outlines_one_beside_it():
    """A berm across the aim (x = 0 plane) is cut: its section is the rectangle y in [8, 12],
    z in [-1, 5]; a box 30 m to the side is not cut and is outlined by its projection."""
    from shapely.geometry import Polygon

    from hazard.outputs.lobe_outline import elevation_frame
    from hazard.pictures.elevation_view import occluder_outlines

    view = elevation_frame(np.zeros(3), np.array([0.0, 1.0, 0.0]))  # aim north: s = y, plane x = 0

    def sz(points):
        return view.to_2d(points)

    cut, beside = occluder_outlines([_box_mesh([0.5, 10.0, 2.0], [3.0, 4.0, 6.0]), _box_mesh([30.0, 50.0, 1.0], [2, 2, 2])], view, sz)
    assert len(cut) == 1 and len(beside) == 1
    section = Polygon(cut[0])
    assert section.area == pytest.approx(4.0 * 6.0, rel=1e-12)
    np.testing.assert_allclose(section.bounds, [8.0, -1.0, 12.0, 5.0], atol=1e-12)
    np.testing.assert_allclose(Polygon(beside[0]).bounds, [49.0, 0.0, 51.0, 2.0], atol=1e-12)


@given(st.floats(-80, 80), st.floats(-0.9, 0.9), st.floats(0.5, 5.0))
@settings(max_examples=25, derandomize=True, deadline=None)
def test_a_section_lies_on_the_plane_and_in_the_box(azimuth_deg, offset_rel, half_m):
    """For any vertical plane through a cube's inside, every section point is on the plane and
    in the cube, and the section closes into one polygon whose area is the cube's height times
    the chord length across the square at that offset (the chord written from the geometry)."""
    from shapely.geometry import Polygon

    from hazard.outputs.lobe_outline import elevation_frame
    from hazard.pictures.elevation_view import occluder_outlines, plane_section

    a = np.radians(azimuth_deg)
    aim = np.array([np.sin(a), np.cos(a), 0.0])
    normal = np.array([aim[1], -aim[0], 0.0])
    laser = -offset_rel * half_m * normal - 100.0 * aim
    box = _box_mesh([0.0, 0.0, 0.0], [2 * half_m] * 3)
    view = elevation_frame(laser, aim)
    seg = plane_section(box.vertices, box.faces, view.origin_m, view.n)
    assert len(seg)
    pts = seg.reshape(-1, 3)
    np.testing.assert_allclose((pts - view.origin_m) @ view.n, 0.0, atol=1e-9 * half_m)
    assert np.all(np.abs(pts) <= half_m * (1 + 1e-12))
    cut, beside = occluder_outlines([box], view, view.to_2d)
    assert len(cut) == 1 and not beside
    t = np.linspace(-3 * half_m, 3 * half_m, 600001)  # the chord across the square |x|, |y| <= h, sampled densely
    p = (-offset_rel * half_m * normal)[None, :2] + t[:, None] * aim[None, :2]
    inside = np.all(np.abs(p) <= half_m, axis=1)
    chord = t[inside].max() - t[inside].min()
    assert Polygon(cut[0]).area == pytest.approx(chord * 2 * half_m, rel=5e-5)
