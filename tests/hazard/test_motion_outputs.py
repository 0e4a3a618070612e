"""The motion and airspace stages end to end: what report.json, observers.csv, the track
tables, the map outputs and the VTK output carry, and consistency checks against the
static analysis (expected values from the formulas of range-safety.md sections 1-2 where
a number is checked). The physics of crossings, slews, windows and FAA distances is
validated independently in tests/validation/test_motion_refs.py."""

from __future__ import annotations

import csv
import io
import json
import math
from pathlib import Path

import numpy as np
import pytest

import hazard
import scenes
from hazard.cli import main
from hazard.outputs.report import report_dict
from hazard.outputs.report_schema import validate_report
from tests._scene_text import PLATE_AT_50M
from tests._bundled import bundled


@pytest.fixture(scope="module")
def airspace_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("air") / "out"
    err = io.StringIO()
    code = main(["run", "airspace", "-o", out, "--quiet", "--fail-on-hazard"], stdout=io.StringIO(), stderr=err)
    return code, out, err.getvalue()


def test_the_airspace_example_reports_tracks_zones_and_distances(airspace_run):
    code, out, err = airspace_run
    assert code == 3, err  # the laser-free zone is entered: a hazard
    doc = json.loads((out / "report.json").read_text())
    (track,) = doc["tracks"]
    assert track["name"] == "helicopter" and track["csv"] == "track_helicopter.csv" and not track["hazardous"]
    assert track["visual_levels_reached"] == ["szed", "czed", "lfed"] and track["min_step_s"] < 1e-3
    zones = {z["name"]: z for z in doc["airspace"]["zones"]}
    lfz = zones["airfield LFZ"]
    assert not lfz["holds"] and 0.0 <= lfz["worst_time_s"] <= 20.0 and lfz["worst_path"] == "direct"
    x, y, z = lfz["worst_point_m"]
    assert -1000 <= x <= 1000 and 8000 <= y <= 10000 and 0 <= z <= 609.6
    vi = doc["visual_interference"]
    assert vi["applies"] and vi["vcf"] == pytest.approx(0.8849624)
    # the direct beam's SZED by the closed form (range-safety.md section 5), a = 5 mm
    assert vi["direct"]["szed_m"] == pytest.approx((math.sqrt(4 * 5.0 * 0.8849624 / (math.pi * 1.0)) - 0.005) / 0.0005, rel=1e-9)
    assert doc["motion"]["windows_s"] == [[0.0, 20.0], [40.0, 60.0]] and doc["motion"]["beam_states"] >= 2
    assert {s["name"]: s["ran"] for s in doc["stages"]}["motion"]


def test_observers_csv_has_the_track_row_and_the_fixed_observers_motion_columns(airspace_run):
    _, out, _ = airspace_run
    rows = {r["name"]: r for r in csv.DictReader(io.StringIO((out / "observers.csv").read_text()))}
    doc = json.loads((out / "report.json").read_text())
    heli, post = rows["helicopter"], rows["post"]
    t = doc["tracks"][0]
    assert float(heli["radiant_exposure_j_m2"]) == t["radiant_exposure_j_m2"]
    assert float(heli["peak_irradiance_w_m2"]) == t["peak_irradiance_w_m2"]
    assert [float(v) for v in (heli["x_m"], heli["y_m"], heli["z_m"])] == t["worst_point_m"]
    fixed = doc["motion"]["fixed_observers"][0]
    assert float(post["motion_radiant_exposure_j_m2"]) == fixed["radiant_exposure_j_m2"]
    listed = {r["name"] for r in doc["observers"]}
    assert listed == {"helicopter", "post"}


def test_the_track_table_integrates_to_the_reported_exposure(airspace_run):
    _, out, _ = airspace_run
    doc = json.loads((out / "report.json").read_text())
    rows = list(csv.DictReader(io.StringIO((out / "track_helicopter.csv").read_text())))
    assert list(rows[0]) == ["time_s", "x_m", "y_m", "z_m", "lased", "direct_irradiance_w_m2", "reflected_irradiance_w_m2",
                             "irradiance_w_m2", "cumulative_exposure_j_m2"]
    t = np.array([float(r["time_s"]) for r in rows])
    e = np.array([float(r["irradiance_w_m2"]) for r in rows])
    d = np.array([float(r["direct_irradiance_w_m2"]) + float(r["reflected_irradiance_w_m2"]) for r in rows])
    np.testing.assert_allclose(e, d, rtol=1e-12)
    trap = float(np.sum(0.5 * (e[1:] + e[:-1]) * np.diff(t)))
    assert trap == pytest.approx(doc["tracks"][0]["path_exposure_j_m2"], rel=1e-9)
    lased = np.array([r["lased"] == "True" for r in rows])
    assert not np.any(e[~lased] > 0)  # nothing outside the windows (20 s to 40 s here)
    assert np.all(np.diff(t) > 0) and t[0] == 0.0 and t[-1] == 30.0


def slew_scene(extra=""):
    """A 10 W beam slewing 1 deg/s in bearing from north over [0, 20] s; a point 5 deg east
    at 1 km (off the nominal aim) and the target far north."""
    return scenes.loads(f"""
name = "slew"
[laser]
wavelength_nm = 1064.0
power_w = 10.0
beam_diameter_m = 0.01
divergence_rad = 4.8e-4
position_m = [0.0, 0.0, 0.0]
aim_m = [0.0, 1000.0, 0.0]
[laser.aim_track]
times_s = [0.0, 20.0]
azimuth_rate_deg_s = 1.0
[exposure]
duration_s = 10.0
[[targets]]
name = "plate"
shape = "plate"
center_m = [0.0, 3000.0, 0.0]
normal = [0.0, -1.0, 0.0]
size_m = [5.0, 5.0]
material = {{ model = "lambertian", reflectance = 0.1 }}
[[observers]]
name = "mast"
points_m = [[{1000 * math.sin(math.radians(5))}, {1000 * math.cos(math.radians(5))}, 0.0]]
{extra}""")


def test_the_static_analysis_holds_the_beam_anywhere_on_its_slew():
    res = hazard.analyze(slew_scene())
    d = 0.01 + 1000 * 4.8e-4  # the beam's 1/e diameter at 1 km (range-safety.md section 1)
    on_axis = 4 * 10.0 / (math.pi * d * d)
    assert res.observers.direct_irradiance_w_m2[0] == pytest.approx(on_axis, rel=2e-3)
    assert res.observers.direct_at_aim_irradiance_w_m2[0] == 0.0  # 5 deg off the nominal aim
    assert res.sdz.directions.aim_track and res.hazardous[0]
    doc = json.loads(json.dumps(report_dict(res)))
    validate_report(doc)  # the motion block with an aim track's rates, and a fixed observer over time (issue 35)
    assert doc["motion"]["aim_track"]["azimuth_rate_deg_s"] == 1.0 and doc["motion"]["fixed_observers"]


def test_a_fixed_observer_list_too_long_for_time_steps_is_said(monkeypatch):
    from hazard.pipeline import motion_stage

    monkeypatch.setattr(motion_stage, "FIXED_OBSERVERS_MAX", 0)
    res = hazard.analyze(slew_scene())
    assert res.motion.fixed() == [] and any("not evaluated over time" in n for n in res.motion.notes)
    assert "not evaluated over time" in res.stage("motion").detail


def test_a_mirror_sliding_in_its_own_plane_reflects_the_same_beam():
    """A flat mirror translated in its plane with the spot on it: the mirror beam does not
    move, so a drone crossing it receives what it receives from the mirror at rest."""
    base = """
name = "m"
[laser]
wavelength_nm = 532.0
power_w = 100.0
beam_diameter_m = 0.02
divergence_rad = 1e-4
position_m = [0.0, -100.0, 0.0]
aim_m = [0.0, 0.0, 0.0]
[exposure]
duration_s = 1.0
[[targets]]
name = "mirror"
shape = "plate"
center_m = [0.0, 0.0, 0.0]
normal = [0.0, -0.7071067811865476, 0.7071067811865476]
size_m = [2.0, 2.0]
material = { model = "specular", reflectance = 0.9 }
%s
[[observers]]
name = "drone"
kind = "track"
start_m = [-20.0, 0.0, 100.0]
velocity_m_s = [4.0, 0.0, 0.0]
duration_s = 10.0
"""
    moving = '[targets.track]\ntimes_s = [0.0, 10.0]\ncenter_m = [[-0.5, 0.0, 0.0], [0.5, 0.0, 0.0]]'
    a = hazard.analyze(scenes.loads(base % "")).motion.tracks()[0].summary
    b = hazard.analyze(scenes.loads(base % moving)).motion.tracks()[0].summary
    assert b.radiant_exposure_j_m2 == pytest.approx(a.radiant_exposure_j_m2, rel=1e-2)
    assert a.hazardous and b.hazardous


def test_a_standing_track_sees_the_dynamic_history_the_fixed_observer_sees():
    """A track standing at a fixed observer's point over the history's window takes, per
    sample, the larger of the two bracketing history states: its peak is the fixed
    observer's peak."""
    p = scenes.example_path("stainless_melt")
    sc0 = scenes.load(p)
    t_end = sc0.spec.analysis.time_end_s or sc0.spec.exposure.duration_s
    res0 = bundled("stainless_melt")  # the default analysis of sc0
    i = int(np.argmax(res0.observers.peak_irradiance_w_m2))
    x, y, z = (float(v) for v in res0.observers.position_m[i])
    text = p.read_text() + f"""
[[observers]]
name = "standing"
kind = "track"
times_s = [0.0, {t_end}]
positions_m = [[{x!r}, {y!r}, {z!r}], [{x!r}, {y!r}, {z!r}]]
"""
    res = hazard.analyze(scenes.loads(text, base_dir=p.parent))
    s = res.motion.tracks()[0].summary
    assert s.peak_irradiance_w_m2 == pytest.approx(float(res0.observers.peak_irradiance_w_m2[i]), rel=1e-9)


def test_map_outputs_carry_the_tracks_zones_and_visual_outlines(airspace_run):
    _, out, _ = airspace_run
    doc = json.loads((out / "zones_local_frame.json").read_text())
    kinds = [f["properties"]["kind"] for f in doc["features"]]
    assert kinds.count("track") == 1 and kinds.count("airspace_zone") == 2 and kinds.count("visual_zone") == 3
    lfz = next(f for f in doc["features"] if f["properties"].get("name") == "airfield LFZ")
    assert lfz["properties"]["holds"] is False and lfz["properties"]["ceiling_agl_m"] == 609.6


def test_a_geodetic_track_is_a_line_at_its_given_positions_on_the_map(tmp_path):
    pytest.importorskip("pyproj")
    p = scenes.example_path("range_geo")
    text = p.read_text() + """
[[observers]]
name = "jet"
kind = "track"
times_s = [0.0, 60.0]
positions_geo = [[32.55, -106.40, 3000.0], [32.70, -106.20, 3000.0]]
"""
    (tmp_path / "s.toml").write_text(text)
    (tmp_path / "range_geo_dem.tif").write_bytes(p.with_name("range_geo_dem.tif").read_bytes())
    code = main(["run", tmp_path / "s.toml", "-o", tmp_path / "o", "--quiet"], stdout=io.StringIO(), stderr=io.StringIO())
    assert code in (0, 3)
    doc = json.loads((tmp_path / "o" / "zones.geojson").read_text())
    (jet,) = [f for f in doc["features"] if f["properties"]["kind"] == "track"]
    c = jet["geometry"]["coordinates"]
    assert abs(c[0][0] + 106.40) < 1e-7 and abs(c[0][1] - 32.55) < 1e-7
    assert abs(c[-1][0] + 106.20) < 1e-7 and abs(c[-1][1] - 32.70) < 1e-7
    rows = list(csv.DictReader(io.StringIO((tmp_path / "o" / "track_jet.csv").read_text())))
    assert abs(float(rows[0]["lat_deg"]) - 32.55) < 1e-9 and abs(float(rows[0]["height_m"]) - 3000.0) < 1e-3


def test_the_vtk_output_holds_the_zones_as_volumes():
    pytest.importorskip("pyvista")
    from hazard.pictures import render

    res = bundled("airspace")
    blocks = render._scene_blocks(res, 6.0)
    names = set(blocks.keys())
    assert {"track_helicopter", "airspace_airfield LFZ", "visual_szed", "visual_czed", "visual_lfed"} <= names
    prism = blocks["airspace_airfield LFZ"]
    # 4 walls, floor and ceiling, in the scene's local coordinates (world - offset, as every block)
    assert prism.n_cells == 6 and prism.bounds[5] + res.scene.offset_m[2] == pytest.approx(609.6)
    assert np.all(np.isfinite(blocks["visual_szed"].points))


def test_each_track_gets_its_exposure_plot():
    pytest.importorskip("matplotlib")
    from hazard.pictures.plots import time_figures

    res = bundled("airspace")
    figs = time_figures(res, worst=0)
    assert "exposure_track_helicopter.png" in figs and figs["exposure_track_helicopter.png"][:4] == b"\x89PNG"


def test_an_infrared_laser_has_no_visual_levels_and_its_zones_say_why():
    sc = scenes.loads(PLATE_AT_50M + """
[airspace]
[[airspace.zones]]
name = "z"
limit = "lfed"
boundary_m = [[-10.0, -60.0], [10.0, -60.0], [10.0, 60.0], [-10.0, 60.0]]
ceiling_agl_m = 100.0
""")
    res = hazard.analyze(sc)
    vi = res.visual_interference
    assert not vi.applies and vi.direct.lfed_m is None and vi.direct.nohd_m > 0 and "visible band" in vi.reason
    assert res.airspace.zones[0].holds and "not visible" in res.airspace.note
    validate_report(json.loads(json.dumps(report_dict(res))))  # visual_interference's reason, airspace's note (issue 35)


def test_a_track_within_the_pointing_error_of_the_beam_is_crossed_through_its_axis():
    """An aircraft at 100 m/s passes 3 m beside a beam of 1/e radius w = 0.25 m at 5 km:
    at the nominal aim it receives exp(-(3/w)^2) H ~ 0; with a 1 mrad pointing bound (5 m
    there) the beam may sit on it: H = P exp(-mu R) / (sqrt(pi) w v) (range-safety.md 2)."""
    path = Path(__file__).resolve().parents[2] / "examples" / "accuracy" / "aircraft_crossing.toml"
    text = path.read_text().replace("start_m = [-1000.0, 5000.0, 0.0]", "start_m = [-1000.0, 5000.0, 3.0]")  # 3 m above the axis
    h = 10.0 * math.exp(-1e-4 * 5000) / (math.sqrt(math.pi) * 0.25 * 100.0)
    nominal = hazard.analyze(scenes.loads(text)).motion.tracks()[0].summary
    biased = hazard.analyze(scenes.loads(text.replace("aim_m = [0.0, 20000.0, 0.0]", "aim_m = [0.0, 20000.0, 0.0]\npointing_error_rad = 0.001")))
    s = biased.motion.tracks()[0].summary
    assert nominal.radiant_exposure_j_m2 < 1e-6 * h
    assert s.radiant_exposure_j_m2 == pytest.approx(h, rel=1e-3)
    assert math.hypot(*s.pointing_bias_rad) == pytest.approx(3.0 / 5000.0, rel=1e-3)
    assert "worst constant pointing bias" in biased.stage("motion").detail
    doc = json.loads(json.dumps(report_dict(biased)))
    assert doc["tracks"][0]["pointing_bias_rad"] == list(s.pointing_bias_rad) and doc["tracks"][0]["pointing_buffer_rad"] == 0.001
    validate_report(doc)  # a track's pointing_bias_rad against its schema (issue 35)


def test_the_dwell_time_counts_only_the_time_the_surface_was_under_the_spot():
    """A spot (radius 0.5 m) at x = 0 for 2 s, away at x = 5 m for 3 s, back at x = 0:
    the surface at x = 0 has been lit 2 s when the spot returns, not 5 s; the one at
    x = 5 m 0 s when the spot arrives there (windows: none, key times 0, 2, 5)."""
    from types import SimpleNamespace as NS

    from hazard.pipeline.motion import MotionRun, _dwell_s
    from scenes.motion import Windows

    target = NS(index=0)

    def state(t, x):
        return NS(time_s=t, spots=[NS(centroid=np.array([x, 0.0, 0.0]), size_m=1.0, target=target)])

    motion = NS(windows=Windows(None), t_start_s=0.0, target_tracks=[], beam_moves=True)
    run = MotionRun(None, motion, 0.0, 1.0, None, {0: np.zeros((3, 1))}, np.array([0.0, 1.0, 2.0]),
                    [state(0.0, 0.0), state(2.0, 5.0), state(5.0, 0.0)], np.array([0.0, 2.0, 5.0]), "embree", 1)
    np.testing.assert_allclose(_dwell_s(run, np.array([0.0, 1.0, 2.0, 4.0, 5.0, 6.0])), [0.0, 1.0, 0.0, 2.0, 2.0, 3.0])


def test_the_elevation_view_puts_observers_where_they_are():
    """The observers were drawn with the scene's offset added twice (a scene whose first
    target is not at the origin: the post of `airspace`, 20 m up, was drawn 120 m up)."""
    pytest.importorskip("matplotlib")
    from hazard.pictures.elevation_view import ElevationViewDisplay

    res = bundled("airspace")
    d = ElevationViewDisplay.from_result(res)
    laser = np.array([0.0, 0.0, 2.0])
    u = np.array([-30.0, 2000.0, 98.0]) / np.linalg.norm([-30.0, 2000.0, 98.0])
    h = u[:2] / np.linalg.norm(u[:2])  # the view's horizontal axis: along the aim's bearing
    s_post = float((np.array([60.0, 1900.0]) - laser[:2]) @ h)
    np.testing.assert_allclose(d.observers_sz[0], [s_post, 20.0], rtol=0, atol=1e-6)


def test_a_track_outside_the_analysed_span_is_said_not_dropped_silently():
    text = PLATE_AT_50M + """
[[observers]]
name = "early"
kind = "track"
times_s = [0.0, 10.0]
positions_m = [[-100.0, -20.0, 5.0], [100.0, -20.0, 5.0]]
[[observers]]
name = "late"
kind = "track"
times_s = [50.0, 60.0]
positions_m = [[-100.0, -20.0, 5.0], [100.0, -20.0, 5.0]]
[motion]
time_start_s = 0.0
time_end_s = 5.0
"""
    res = hazard.analyze(scenes.loads(text))
    assert [p.name for p in res.motion.tracks()] == ["early"]
    notes = " ".join(res.motion.notes)
    assert "track late ([50, 60] s) lies outside the analysed span [0, 5] s: NOT evaluated" in notes
    assert "track early: only [0, 5] s of its [0, 10] s" in notes
    from hazard.outputs.report import answer_text

    assert "track late" in answer_text(res)


def test_a_track_under_the_terrain_is_said():
    p = scenes.example_path("range_terrain")
    text = p.read_text() + """
[[observers]]
name = "mole"
kind = "track"
times_s = [0.0, 5.0]
positions_m = [[0.0, 0.0, -500.0], [10.0, 0.0, -500.0]]
"""
    res = hazard.analyze(scenes.loads(text, base_dir=p.parent))
    assert any("track mole:" in n and "under the terrain" in n for n in res.motion.notes)


def test_the_track_text_of_the_pictures_says_the_faa_levels_the_report_lists():
    """The pictures' text of a track (plan and elevation views, figures.json) names the FAA
    levels report.json's ``tracks[k].visual_levels_reached`` lists: the helicopter of the
    airspace example reaches all three (it read none before the path summaries were typed:
    the text looked for a key only the report's copy had)."""
    from hazard.outputs.figure_index import track_lines

    res = bundled("airspace")
    doc = report_dict(res)
    ((_, name, xyz, text),) = track_lines(res, {"observers": {}})
    levels = doc["tracks"][0]["visual_levels_reached"]
    assert name == "helicopter" and levels == ["szed", "czed", "lfed"] and xyz.shape[1] == 3
    assert text.endswith(f"FAA levels reached: {', '.join(x.upper() for x in levels)})"), text
