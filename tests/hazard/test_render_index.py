"""figures.json for the 3-D pictures (issue 34 item 1): keepout.png, overview.png and
lobe.gif list the report.json findings they draw, their frame, whether the camera shows
each finding and whether its label is in the picture. The camera's answer is checked
against the rendered pixels of a scene built here; the coverage against report.json's
hazardous findings, enumerated from report.json alone (tests/hazard/test_figure_index.py)."""

from __future__ import annotations

import io
import json

import numpy as np
import pytest

import scenes
from hazard.cli import main
from tests._bundled import bundled
from tests.hazard.test_figure_index import hazardous_paths

pv = pytest.importorskip("pyvista")

SMALL = (640, 560)  # window [px]: the legend (up to ~24 entries) fits beside it; quick to render
NOT_IN_3D = ("visual_interference", "sdz.aided")  # only the plan and elevation views draw these


def _report(result) -> dict:
    from hazard.outputs.report import report_dict

    return json.loads(json.dumps(report_dict(result), allow_nan=False))


def _pixel(clip_matrix, point, size) -> tuple:
    """(row, column) [px] of a point in a picture ``size`` (w, h) by the camera matrix."""
    c = clip_matrix @ np.append(point, 1.0)
    x, y = c[:2] / c[3]
    return int(round((1 - y) / 2 * size[1])), int(round((x + 1) / 2 * size[0]))


def test_the_camera_answer_is_where_the_picture_draws_the_point_and_a_line_through_the_view_is_in_it():
    from hazard.outputs.figure_index import view_entry
    from hazard.pictures.render import _world_to_clip

    size = (400, 300)
    p = pv.Plotter(off_screen=True, window_size=list(size))
    p.set_background("white")
    red = np.array([3.0, -2.0, 1.0])
    p.add_mesh(pv.PolyData(red[None]), color="red", point_size=14, render_points_as_spheres=True, lighting=False)
    p.add_mesh(pv.Box((-5, 5, -5, 5, -1, 1)), color="#bbbbbb", opacity=0.3)
    p.camera_position = [(20.0, 15.0, 12.0), (0.0, 0.0, 0.0), (0.0, 0.0, 1.0)]
    img = p.screenshot(None, return_img=True)[..., :3].astype(int)
    m = _world_to_clip(p, size)
    cam = np.asarray(p.camera.position, float)
    p.close()
    row, col = _pixel(m, red, size)
    near = img[max(row - 2, 0):row + 3, max(col - 2, 0):col + 3].reshape(-1, 3)
    assert any(r > 200 and g < 80 and b < 80 for r, g, b in near), (row, col)  # the red point is drawn there
    behind = cam + (cam / np.linalg.norm(cam)) * 10.0  # behind the camera
    aside = np.array([0.0, 0.0, 5000.0])  # straight up, far out of the view
    u = np.cross(cam, [0.0, 0.0, 1.0]) / np.linalg.norm(np.cross(cam, [0.0, 0.0, 1.0]))  # across the line of sight
    across = np.stack([1e4 * u, -1e4 * u])  # both ends far out of the view, crossing it at the focal point
    assert not any(view_entry("3d", {"title": "t"}, [(["sdz"], "", e, "points", e)], m, set())["findings"][0]["inside"][0]
                   for e in across)
    notes = [(["observers[0]"], "red", red, "points", red),
             (["observers[1]", "observers[2]"], "two", np.stack([red, aside]), "points", np.stack([red, aside])),
             (["observers[3]"], "behind", behind, "points", behind), (["sdz"], "aim", across, "line", across),
             (["sdz.mirror_beams[0]"], "up", np.stack([aside, aside + [10.0, 0, 0]]), "line", np.stack([aside, aside]))]
    f = view_entry("3d", {"title": "t", "extent": [-5, 5, -5, 5]}, notes, m, {"red", "aim"})["findings"]
    assert [x["inside"] for x in f] == [[True], [True, False], [False], [True], [False]]
    assert [x["label_shown"] for x in f] == [True, False, False, True, False]
    assert f[1]["bbox"] == [0.0, 3.0, -2.0, 0.0]


def _render(name, tmp_path):
    from hazard.pictures import render

    res = bundled(name)
    paths = render.keepout(res, tmp_path, window_size=SMALL, vtk=False)
    return res, paths["figures"]


def check_3d_coverage(doc, entry) -> list:
    """The hazardous findings of report.json the overview (everything hazardous) must draw
    - every one but those only the 2-D views draw (FAA distances, the aided zones) - that
    it does not draw in view with its label shown; [] when it draws them all."""
    drawn = {}
    for f in entry["findings"]:
        for path, inside in zip(f["paths"], f["inside"]):
            drawn.setdefault(path, []).append(inside and f["label_shown"])
    return [p for p in hazardous_paths(doc) if not p.startswith(NOT_IN_3D) and not any(drawn.get(p, []))]


def dark_edges(png) -> list:
    """The edges of a picture with dark pixels (any channel at most 90 of 255: the black
    and dark grey of text and labels) in their outer 3 pixels: text cut by the edge."""
    import matplotlib.image as mpimg

    img = (mpimg.imread(png)[..., :3] * 255).round().astype(int)
    edges = {"left": img[:, :3], "right": img[:, -3:], "top": img[:3], "bottom": img[-3:]}
    return [side for side, px in edges.items() if (px.max(axis=-1) <= 90).any()]


def _check(name, tmp_path):
    res, figs = _render(name, tmp_path)
    doc = _report(res)
    over = figs["overview.png"]
    assert not check_3d_coverage(doc, over), check_3d_coverage(doc, over)
    for f in over["findings"]:  # report.json's own positions of the observers are where the picture says it drew them
        for path in f["paths"]:
            if path.startswith("observers[") and len(f["paths"]) == 1:
                x, y = np.asarray(doc["observers"][int(path[10:-1])]["position_m"], float)[:2]
                assert f["bbox"] == pytest.approx([x, x, y, y])
    for fname in ("keepout.png", "overview.png"):
        assert not dark_edges(tmp_path / fname), (fname, dark_edges(tmp_path / fname))  # issue 34: text cut at the left edge
        (panel,) = figs[fname]["panels"]
        x0, x1, y0, y1 = panel["extent"]
        assert x0 < x1 and y0 < y1 and panel["title"].startswith(doc["scene"]["name"]) and "3-D" in panel["projection"]
        assert all(f["panel"] == panel["title"] for f in figs[fname]["findings"])
    return res, doc, figs


def test_mirror_window_overview_draws_every_hazardous_finding_and_the_close_view_says_what_it_leaves_out(tmp_path):
    res, doc, figs = _check("mirror_window", tmp_path)
    close = {p: f for f in figs["keepout.png"]["findings"] for p in f["paths"]}
    i = next(i for i, o in enumerate(doc["observers"]) if o["name"] == "in-beam-50m")
    assert doc["observers"][i]["hazardous"]
    x, y = doc["observers"][i]["position_m"][:2]
    x0, x1, y0, y1 = figs["keepout.png"]["panels"][0]["extent"]
    assert np.hypot(x, y) > 10 * max(x1 - x0, y1 - y0)  # 50 m out along the mirror beam: far off the 2.6 m close view ...
    assert close[f"observers[{i}]"]["inside"] == [False]  # ... and the close view says it does not show it
    assert close["sdz.mirror_beams[0]"]["inside"] == [True] and close["sdz"]["inside"] == [True]  # lines crossing the view


@pytest.mark.slow
@pytest.mark.parametrize("name", sorted(set(scenes.examples()) - {"mirror_window"}))
def test_every_bundled_overview_draws_every_hazardous_finding(name, tmp_path):
    _check(name, tmp_path)


def test_lobe_animation_lists_its_lobes_with_their_caption(tmp_path):
    from hazard.pictures import render

    res = bundled("steel_vs_copper")
    anim = render.animate_lobe(res, tmp_path, max_frames=2, window_size=(320, 240))
    entry = anim["figures"]["lobe.gif"]
    doc = _report(res)
    lobes = [p for p in hazardous_paths(doc) if ".keepout_" in p]
    drawn = {p for f in entry["findings"] if f["label_shown"] for p, ok in zip(f["paths"], f["inside"]) if ok}
    assert lobes and set(lobes) <= drawn
    assert entry["view"] == "animation" and all(t["name"] in entry["findings"][0]["label"] for t in doc["targets"])


@pytest.mark.slow
def test_hazard_render_lists_every_picture_it_writes_in_figures_json(tmp_path):
    out = tmp_path / "r"
    code = main(["render", "steel_vs_copper", "-o", str(out), "--quiet"], stdout=io.StringIO(), stderr=io.StringIO())
    assert code == 0
    figs = json.loads((out / "figures.json").read_text())["figures"]
    written = {p.name for p in out.iterdir() if p.suffix in (".png", ".gif")}
    assert {"keepout.png", "overview.png", "lobe.gif", "plan.png"} <= written and written == set(figs)
    doc = json.loads((out / "report.json").read_text()) if (out / "report.json").exists() else _report(bundled("steel_vs_copper"))
    assert not check_3d_coverage(doc, figs["overview.png"])


@pytest.mark.slow
def test_a_run_after_a_render_still_lists_the_3d_pictures_it_keeps(tmp_path):
    out = tmp_path / "r"
    args = ["mirror_window", "-o", str(out), "--quiet"]
    assert main(["render", *args, "--no-animation"], stdout=io.StringIO(), stderr=io.StringIO()) == 0
    before = json.loads((out / "figures.json").read_text())["figures"]
    said = io.StringIO()
    assert main(["run", *args, "--plot", "--force"], stdout=said, stderr=io.StringIO()) == 0
    figs = json.loads((out / "figures.json").read_text())["figures"]
    assert "kept" in said.getvalue() and (out / "keepout.png").exists()
    assert figs["keepout.png"] == before["keepout.png"] and figs["overview.png"] == before["overview.png"]
    written = {p.name for p in out.iterdir() if p.suffix in (".png", ".gif")}
    assert written == set(figs)


@pytest.mark.slow
def test_the_3d_overview_draws_the_tracks_and_flight_zones_and_says_what_it_leaves_to_the_2d_views(tmp_path):
    """airspace (issue 34 leftover d): the overview draws the helicopter's track (its
    ``tracks[k]`` and its observer row) and every flight zone in view with their plan-view
    texts in its legend, the exceeded zone in the danger zone's red at its place in the
    picture; its FAA distances are not drawn in 3-D, said in the title and listed under
    ``not_drawn``."""
    import matplotlib.image as mpimg

    res, figs = _render("airspace", tmp_path)
    doc = _report(res)
    over = figs["overview.png"]
    drawn = {p: f for f in over["findings"] for p in f["paths"]}
    tracks = [f"tracks[{k}]" for k in range(len(doc["tracks"]))]
    zones = [f"airspace.zones[{k}]" for k in range(len(doc["airspace"]["zones"]))]
    assert tracks and zones
    for p in tracks + zones:
        assert all(drawn[p]["inside"]) and drawn[p]["label_shown"], (p, drawn.get(p))
    rows = [f"observers[{i}]" for i, o in enumerate(doc["observers"]) if o["name"] in {t["name"] for t in doc["tracks"]}]
    assert rows and all(all(drawn[r]["inside"]) for r in rows)
    left = [p for p in hazardous_paths(doc) if p.startswith(NOT_IN_3D)]
    assert left
    for fname in ("keepout.png", "overview.png"):
        nd = figs[fname]["not_drawn"]
        assert set(left) <= set(nd["paths"]) and nd["see"] == ["plan.png", "elevation.png"]
        assert not any(p.startswith(("tracks", "airspace.zones")) for p in nd["paths"])
        assert "FAA distance" in nd["label"] and "track" not in nd["label"] and "flight zone" not in nd["label"]
    from hazard.pictures import render

    framing = render.Framing(np.zeros((3, 2)), np.zeros(3))
    assert over["not_drawn"]["label"] in render._title_lines(res, framing, "t")  # said in the title strip
    exceeded = [k for k, z in enumerate(doc["airspace"]["zones"]) if not z["holds"]]
    assert exceeded  # the EXCEEDED airfield zone is drawn red: the zone's colour is in the picture
    img = (mpimg.imread(tmp_path / "overview.png")[..., :3] * 255).round().astype(int)
    red = (img[..., 0] > 200) & (img[..., 1] < 120) & (img[..., 2] < 120)
    assert red.sum() > 50