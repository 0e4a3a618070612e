"""The plan and elevation views agree with the text (issue 34 item 2): beams drawn to
where the analysis stops them and never past, aim lines not through the ground, a
readable vertical exaggeration said on the axis, the hazardous ground as cells at their
true size, the site panel showing what stands around the hazard, and range rings that
say what they are centred on. Expected values come from the scene's geometry, not from
the pictures' code."""

from __future__ import annotations

import math

import numpy as np
import pytest

import hazard
import scenes
from tests._bundled import bundled

pytest.importorskip("matplotlib")

WALL_X_M = 163.205  # the near face of a wall across the window's mirror beam (box centre x 173.205, 20 m deep)


@pytest.fixture(scope="module")
def mirror_wall(tmp_path_factory):
    """mirror_window with a wall across its mirror beam (bearing 120 deg, level) ~190 m out."""
    text = scenes.example_path("mirror_window").read_text().replace('name = "mirror_window"', 'name = "mirror_wall"')
    text += ('[[occluders]]\nname = "wall"\nshape = "box"\ncenter_m = [173.205, -100.0, 0.0]\nsize_m = [20.0, 20.0, 40.0]\n')
    path = tmp_path_factory.mktemp("wall") / "mirror_wall.toml"
    path.write_text(text)
    return hazard.analyze(scenes.load(path))


def test_a_mirror_beam_stopped_by_a_wall_is_drawn_to_the_wall_and_says_so(mirror_wall):
    from hazard.pictures.elevation_view import ElevationViewDisplay
    from hazard.pictures.plan_view import PlanViewDisplay
    from hazard.outputs.finding_geometry import mirror_segments

    row = next(t for t in mirror_wall.targets if t.name == "window")
    ((name, a, b),) = mirror_segments(mirror_wall)
    u = (b - a) / np.linalg.norm(b - a)
    assert u[:2] == pytest.approx([math.cos(math.radians(-30)), math.sin(math.radians(-30))], abs=1e-3)  # d - 2 (d.n) n, d = +y
    to_wall = (WALL_X_M - a[0]) / u[0]  # along the beam from the window to the wall's face
    assert np.linalg.norm(b - a) == pytest.approx(to_wall, abs=0.5)  # the spot's rays fan out by centimetres
    assert row.specular_nohd_dynamic_m > 5 * to_wall  # the NOHD runs far beyond: the wall stops it
    plan = PlanViewDisplay.from_result(mirror_wall)
    assert plan.mirrors[0][2][0] <= WALL_X_M + 0.5  # the plan's beam ends at the wall
    assert any("mirror beam of window ends at 188 m (stopped by a backstop)" == text for _, text in plan.ends)
    elev = ElevationViewDisplay.from_result(mirror_wall)
    (_, sa, sb), = elev.mirrors
    assert np.hypot(*(sb - sa)) <= to_wall + 0.5  # the projection is no longer than the beam


def test_without_a_backstop_the_mirror_beam_is_drawn_to_its_nohd():
    from hazard.outputs.finding_geometry import mirror_segments

    res = bundled("mirror_window")
    ((_, a, b),) = mirror_segments(res)
    row = next(t for t in res.targets if t.name == "window")
    assert np.linalg.norm(b - a) == pytest.approx(row.specular_nohd_dynamic_m, rel=1e-9)


def test_the_elevation_aim_line_stops_where_its_centre_meets_a_hill(tmp_path):
    from hazard.pictures.elevation_view import ElevationViewDisplay

    text = scenes.example_path("range_terrain").read_text()  # a hill 40 m high 850 m down range, behind the target
    text = text.replace("center_m = [200.0, 100.0, 0.0]", "center_m = [0.0, 450.0, 0.0]").replace("height_m = 25.0", "height_m = 40.0")
    text = text.replace("extent_m = 600.0", "extent_m = 1400.0")
    (tmp_path / "hill.toml").write_text(text)
    res = hazard.analyze(scenes.load(tmp_path / "hill.toml"))
    d = ElevationViewDisplay.from_result(res)
    (s0, z0), (s1, z1) = d.aim_sz
    off = res.scene.offset_m

    def ground(s):  # world height of the ground under the aim (due north from the laser at world (0, -400))
        s = np.atleast_1d(s)
        return res.scene.terrain.height_at(np.zeros_like(s) - off[0], -400.0 + s - off[1]) + off[2]

    assert z1 == pytest.approx(ground(s1)[0], abs=0.05)  # it ends on the ground, not inside the hill
    s = np.linspace(s0, s1, 400)[1:-1]  # and is above the ground all the way there
    z = z0 + (s - s0) * (z1 - z0) / (s1 - s0)
    assert np.all(z > ground(s) - 1e-6)
    assert s1 < float(res.sdz.max_range_m) + 1e-6 and 600.0 < s1  # past the target at 600 m, short of the zone's end
    if d.aim_past is not None:  # what goes on is drawn dotted, never past the zone's range
        assert d.aim_past[1][0] <= float(res.sdz.max_range_m) + 1e-6


def _exaggeration(ax) -> float:
    x0, x1 = ax.get_xlim()
    y0, y1 = ax.get_ylim()
    box = ax.get_window_extent()
    return (box.height / (y1 - y0)) / (box.width / (x1 - x0))


def test_the_elevation_range_panel_exaggerates_at_most_ten_times_and_says_so():
    from hazard.pictures.elevation_view import ElevationViewDisplay

    fig, axes = ElevationViewDisplay.from_result(bundled("mirror_window")).plot()  # a level scene: x4300 before
    fig.canvas.draw()
    e = _exaggeration(axes[0])
    assert e == pytest.approx(10.0, rel=1e-3) and "vertical scale x10)" in axes[0].get_ylabel()
    assert _exaggeration(axes[1]) == pytest.approx(1.0, rel=1e-3) and "equal scale" in axes[1].get_ylabel()


def test_hazardous_ground_is_drawn_as_cells_of_their_true_size_and_the_site_frames_what_stands_around():
    from matplotlib.collections import PolyCollection

    from hazard.pictures.plan_view import PlanViewDisplay

    res = bundled("range_terrain")
    fig, axes = PlanViewDisplay.from_result(res).plot()
    cells = [c for c in axes[1].collections if isinstance(c, PolyCollection) and c.get_label().startswith("hazardous ground")]
    assert len(cells) == 1
    squares = [p.vertices for p in cells[0].get_paths()]
    want = int((res.footprint_dynamic.mask | res.footprint_static.mask).sum())
    assert len(squares) == want == 2
    for v in squares:
        assert np.ptp(v[:, 0]) == pytest.approx(res.scene.terrain.dx) and np.ptp(v[:, 1]) == pytest.approx(res.scene.terrain.dx)
    x0, x1 = axes[1].get_xlim()
    y0, y1 = axes[1].get_ylim()
    bunker = np.array(res.scene.spec.occluders[0].center_m)[:2]  # the scene file's (world) coordinates
    assert x0 < bunker[0] < x1 and y0 < bunker[1] < y1  # the bunker beside the target (20 m east, 30 m short)
    road = np.asarray(res.observers.position_m)[[i for i, n in enumerate(res.observers.labels) if n.startswith("near-road")], :2]
    assert len(road) == 17 and np.all((road[:, 0] >= x0) & (road[:, 0] <= x1) & (road[:, 1] >= y0) & (road[:, 1] <= y1))


def test_the_first_range_ring_says_what_the_rings_are_centred_on():
    from hazard.pictures.plan_view import PlanViewDisplay

    fig, axes = PlanViewDisplay.from_result(bundled("range_terrain")).plot()
    rng = [t.get_text() for t in axes[0].texts if t.get_text().endswith(" from the laser")]
    site = [t.get_text() for t in axes[1].texts if t.get_text().endswith(" from target-plate")]
    assert len(rng) == 1 and len(site) == 1


def test_the_scale_bar_takes_a_corner_that_covers_nothing_and_safe_observers_stay_over_the_crosses():
    from hazard.canvas import subplots
    from hazard.pictures.plan_view import PlanViewDisplay, quiet_corner

    _, ax = subplots(figsize=(4, 4))
    ax.set_xlim(0, 100)
    ax.set_ylim(0, 100)
    assert quiet_corner(ax, np.array([[50.0, 50.0]])) == "lower left"  # nothing in any corner: the usual place
    assert quiet_corner(ax, np.array([[5.0, 5.0]])) == "lower right"  # the laser in the lower left corner
    assert quiet_corner(ax, np.array([[5.0, 5.0], [95.0, 5.0]])) == "upper right"
    d = PlanViewDisplay("t", np.array([50.0, 5.0]), np.array([[50.0, 5.0], [50.0, 95.0]]), None, "zone",
                        observers_xy=np.array([[50.0, 50.0], [50.5, 50.0]]), hazardous=np.array([True, False]),
                        aided=np.zeros(2, bool))
    fig, axes = d.plot()
    safe = [c for c in axes[1].collections if c.get_label().startswith("observers below")]
    crosses = [c for c in axes[1].collections if c.get_label().startswith("observers at or above")]
    assert len(safe) == len(crosses) == 1 and safe[0].get_zorder() > crosses[0].get_zorder()


def test_a_site_kilometres_long_is_not_drawn_flat():
    from hazard.pictures.elevation_view import ElevationViewDisplay

    d = ElevationViewDisplay("t", np.array([0.0, 0.0]), np.array([[0.0, 0.0], [6000.0, 60.0]]),
                             targets=[("a", np.array([100.0, 10.0])), ("b", np.array([5000.0, 60.0]))])
    fig, axes = d.plot()
    fig.canvas.draw()
    y0, y1 = axes[1].get_ylim()
    assert y0 <= 10.0 - 5.0 and y1 >= 60.0 + 5.0  # both targets and a margin
    assert _exaggeration(axes[1]) == pytest.approx(10.0, rel=1e-3)  # at equal scale 50 m in 5 km would be a line
    assert axes[1].get_ylabel() == "height [m] (vertical scale x10)"


def test_the_plan_aim_line_ends_where_the_zone_does_along_the_aim():
    from hazard.pictures.plan_view import clip_to_zone

    deg = np.radians
    ring = [[0.0, 0.0]] + [[1000 * np.sin(deg(a)), 1000 * np.cos(deg(a))] for a in (-10, -1)]  # a wall stops the aim's
    ring += [[300 * np.sin(deg(a)), 300 * np.cos(deg(a))] for a in (-1, 1)]  # +-1 deg at 300 m; the rest runs 1 km
    ring += [[1000 * np.sin(deg(a)), 1000 * np.cos(deg(a))] for a in (1, 10)]
    aim = np.array([[0.0, 0.0], [0.0, 1000.0]])  # drawn to the zone's farthest reach
    np.testing.assert_allclose(clip_to_zone(aim, np.array(ring)), [[0.0, 0.0], [0.0, 300.0 * np.cos(deg(1))]], atol=1e-6)
    np.testing.assert_allclose(clip_to_zone(aim, None), aim)
