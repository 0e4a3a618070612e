"""Scene keys of things that move (scenes.spec / scenes.motion): what cannot be meant is an
error naming the key; the schedules give what their definitions say, checked against
formulas written here (bearing/elevation rates, linear interpolation, closed windows)
and, for a geodetic track, pyproj's geodesic computed independently."""

from __future__ import annotations

import math

import numpy as np
import pytest

import scenes
from scenes.motion import Windows, motion_of
from tests._scene_text import PLATE_AT_50M

TRACK = """
[[observers]]
name = "aircraft"
kind = "track"
"""


def load(extra: str):
    return scenes.loads(PLATE_AT_50M + extra)


@pytest.mark.parametrize("extra, words", [
    (TRACK + "times_s = [0.0, 1.0]\n", "a track needs times_s and positions_m"),
    (TRACK + "times_s = [0.0, 1.0]\npositions_m = [[0.0, 0.0, 0.0]]\n", "one row per time"),
    (TRACK + "times_s = [1.0, 0.0]\npositions_m = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]]\n", "strictly increasing"),
    (TRACK + "start_m = [0.0, 0.0, 0.0]\nvelocity_m_s = [1.0, 0.0, 0.0]\n", "duration_s"),
    (TRACK + "points_m = [[0.0, 0.0, 0.0]]\ntimes_s = [0.0]\npositions_m = [[0.0, 0.0, 0.0]]\n", "points_m: not used by a track"),
    (TRACK + "times_s = [0.0]\npositions_m = [[0.0, 0.0, 0.0]]\neye_height_m = 1.7\n", "eye_height_m: not used by a track"),
    ("[[observers]]\nname = \"o\"\npoints_m = [[0.0, 0.0, 0.0]]\ntimes_s = [0.0]\n", "times_s: only for a moving observer"),
    ("[laser.aim_track]\ntimes_s = [0.0, 1.0, 2.0]\nazimuth_rate_deg_s = 1.0\n", "with rates, expected the span"),
    ("[laser.aim_track]\ntimes_s = [0.0, 1.0]\n", "exactly one"),
    ("[laser.aim_track]\ntimes_s = [0.0, 1.0]\naim_m = [[0.0, 0.0, 1.0]]\n", "one row per time"),
    ("[motion]\ntime_start_s = 5.0\ntime_end_s = 1.0\n", "expected after time_start_s"),
    ("[airspace]\n[[airspace.zones]]\nname = \"z\"\nlimit = \"lfed\"\nboundary_m = [[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]]\n"
     "floor_agl_m = 100.0\nceiling_agl_m = 50.0\n", "ceiling_agl_m=50.0: expected above floor_agl_m"),
    ("[airspace]\n[[airspace.zones]]\nname = \"z\"\nlimit = \"glare\"\nboundary_m = [[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]]\n"
     "ceiling_agl_m = 50.0\n", "limit"),
])
def test_keys_that_cannot_be_meant_are_errors_naming_them(extra, words):
    with pytest.raises(ValueError, match=words.replace("(", r"\(").replace(")", r"\)").replace("[", r"\[")):
        load(extra)


def test_windows_that_end_before_they_begin_are_an_error():
    text = PLATE_AT_50M.replace("aim_m = [0.0, 0.0, 1.0]", "aim_m = [0.0, 0.0, 1.0]\nwindows = [[5.0, 5.0]]")
    with pytest.raises(ValueError, match=r"laser.windows: window 0 = \[5.0, 5.0\]: expected \[t0_s, t1_s\] with t1_s > t0_s"):
        scenes.loads(text)


def test_a_motion_table_without_anything_moving_is_a_warning():
    sc = load("[motion]\ntime_step_s = 0.5\n")
    assert any("motion: the scene has nothing that moves" in w for w in sc.warnings)
    assert motion_of(sc) is None


def test_a_track_has_no_static_points_and_a_straight_flight_line_its_two_ends():
    sc = load(TRACK + "start_m = [-100.0, 10.0, 50.0]\nvelocity_m_s = [20.0, 0.0, 1.0]\nduration_s = 10.0\nstart_time_s = 5.0\n"
              "[[observers]]\nname = \"post\"\npoints_m = [[3.0, -10.0, 1.0]]\n")
    assert len(sc.observers) == 1 and sc.observers.labels() == ["post"]
    m = motion_of(sc)
    tr = m.tracks[0]
    assert tr.span_s == (5.0, 15.0) and (m.t_start_s, m.t_end_s) == (5.0, 15.0)
    off = sc.offset_m
    np.testing.assert_allclose(tr.at([5.0, 10.0, 15.0]) + off, [[-100, 10, 50], [0, 10, 55], [100, 10, 60]], atol=1e-9)
    assert list(tr.present([4.9, 5.0, 15.0, 15.1])) == [False, True, True, False]


def test_rates_turn_the_aim_by_bearing_and_elevation_from_the_laser_aim():
    sc = load("[laser.aim_track]\ntimes_s = [2.0, 12.0]\nazimuth_rate_deg_s = 3.0\nelevation_rate_deg_s = 0.5\n")
    aim = motion_of(sc).aim
    for t, dt in ((0.0, 0.0), (2.0, 0.0), (7.0, 5.0), (12.0, 10.0), (20.0, 10.0)):  # held before and after
        az, el = math.radians(3.0 * dt), math.radians(0.5 * dt)  # the aim at t0 points +y: bearing 0, elevation 0
        np.testing.assert_allclose(aim.direction(t)[0], [math.sin(az) * math.cos(el), math.cos(az) * math.cos(el), math.sin(el)],
                                   atol=1e-12)


def test_aim_points_are_linear_in_time_and_the_direction_is_their_unit_vector():
    sc = load("[laser.aim_track]\ntimes_s = [0.0, 10.0]\naim_m = [[-10.0, 0.0, 1.0], [10.0, 0.0, 1.0]]\n")
    u = motion_of(sc).aim.direction([2.5])[0]
    p = np.array([-5.0, 0.0, 1.0]) - np.array([0.0, -50.0, 1.0])
    np.testing.assert_allclose(u, p / np.linalg.norm(p), atol=1e-12)


def test_windows_are_closed_intervals_merged():
    w = Windows.of([[10.0, 20.0], [0.0, 5.0], [18.0, 25.0]])
    np.testing.assert_array_equal(w.intervals, [[0.0, 5.0], [10.0, 25.0]])
    assert list(w.lased([-1.0, 0.0, 5.0, 5.0001, 9.999, 10.0, 25.0, 25.1])) == [False, True, True, False, False, True, True, False]
    assert Windows.of(None).lased(np.array([1e9])).all()


@pytest.mark.parametrize("name", ["airspace"])
def test_the_bundled_example_loads_with_its_motion(name):
    sc = scenes.load(scenes.example_path(name))
    m = motion_of(sc)
    assert m.aim is not None and len(m.tracks) == 1 and m.windows.intervals.tolist() == [[0.0, 20.0], [40.0, 60.0]]
    assert (m.t_start_s, m.t_end_s) == (0.0, 60.0)


def test_a_geodetic_track_follows_the_geodesic_with_its_height_linear_in_time():
    pyproj = pytest.importorskip("pyproj")
    p = scenes.example_path("range_geo")
    a, b = (32.55, -106.40, 3000.0), (32.70, -106.20, 3600.0)
    text = p.read_text() + f"""
[[observers]]
name = "jet"
kind = "track"
times_s = [0.0, 60.0]
positions_geo = [[{a[0]}, {a[1]}, {a[2]}], [{b[0]}, {b[1]}, {b[2]}]]
"""
    sc = scenes.loads(text, base_dir=p.parent)
    tr = motion_of(sc).tracks[0]
    frame = sc.site.frame
    g = pyproj.Geod(ellps="WGS84")
    az, _, dist = g.inv(a[1], a[0], b[1], b[0])
    for f in (0.0, 0.25, 0.5, 1.0):
        lon, lat, _ = g.fwd(a[1], a[0], az, f * dist)
        world = tr.at([60.0 * f])[0] + sc.offset_m
        world[2] -= frame.refraction_rise_m(world[:1], world[1:2])[0]  # the apparent frame's rise off again
        glat, glon, gh = frame.geodetic(world[None])
        assert abs(glat[0] - lat) < 1e-9 and abs(glon[0] - lon) < 1e-9
        assert abs(gh[0] - (a[2] + f * (b[2] - a[2]))) < 1e-3
    # the chord between the rows would cut below the geodesic: the midpoint differs by metres
    mid_chord = 0.5 * (tr.at([0.0])[0] + tr.at([60.0])[0])
    assert np.linalg.norm(tr.at([30.0])[0] - mid_chord) > 0.5


def test_a_moving_position_without_its_height_is_an_error():
    pytest.importorskip("pyproj")
    p = scenes.example_path("range_geo")
    text = p.read_text() + '\n[[observers]]\nname = "jet"\nkind = "track"\ntimes_s = [0.0]\npositions_geo = [[32.55, -106.40]]\n'
    with pytest.raises(ValueError, match=r"observers\[\d+\].positions_geo: a moving position needs its height"):
        scenes.loads(text, base_dir=p.parent)
