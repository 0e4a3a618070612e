"""map.html (issue 34 item 5): the run's plan view as an interactive page that works offline.

The expectations come from report.json and the zones GeoJSON the run wrote (which finding
must be drawn, each observer's numbers), from geometry (a plane facing the light is lit
fully, flat ground at the sine of the light's altitude) and from a real headless Chromium
(Debian's, driven by playwright: skipped with the reason when it cannot be had): the page
loads with no console error and no request outside the file, every finding's layer is on
the map, a click on an observer shows report.json's hazard ratio, a layer toggles off, and
the screenshot shows the hazard colours (pixels counted).
"""

from __future__ import annotations

import io
import json
import math
import re
import shutil
from pathlib import Path

import markupsafe
import numpy as np
import pytest

from hazard.cli import main
from hazard.outputs.map_page import LAYERS, MAP_NAME, hillshade, png_gray_alpha, write_map_page
from hazard.outputs.review import fmt_number
from tests.hazard.test_review_report import NASTY, BROWSER_ARGS, _console_errors, os_chromium  # noqa: F401
from tests.hazard.test_review_report import SCENE as PLATE_FAN

HAZARDOUS_NAME = "on the aim <b>&amp;"  # escaped by the page, shown as typed
# added to the map-outputs scene (every kind of zone but the nominal sector: footprint, danger zone
# with buffer and through optics, keep-out lobe, mirror beam, range boundary; flat terrain
# on a site): an observer on the aim line at 150 m (hazardous: ratio about 3e3)
ON_THE_AIM = f"""
[[observers]]
name = {json.dumps(HAZARDOUS_NAME)}
points_m = [[0.0, 150.0, 0.0]]
eye_height_m = 1.7
"""
RED_RGB = ((0xD7, 0x19, 0x1C), (0xE4, 0x1A, 0x1C))  # the danger zone's and a hazardous observer's colours


def run(*argv):
    out, err = io.StringIO(), io.StringIO()
    code = main([str(a) for a in argv], stdout=out, stderr=err)
    return code, out.getvalue(), err.getvalue()


def page_data(page: str) -> dict:
    """The data the page draws (its ``<script type="application/json" id="map-data">``)."""
    m = re.search(r'<script type="application/json" id="map-data">(.*?)</script>', page, re.S)
    assert m, "no map data in the page"
    return json.loads(m.group(1))


def features(data: dict, layer_id: str) -> list:
    return next(lay for lay in data["layers"] if lay["id"] == layer_id)["features"]


def _run_report(root: Path, scene: str) -> dict:
    """``hazard run SCENE -o OUT --report`` and what it wrote."""
    (root / "scene.toml").write_text(scene)
    out = root / "out"
    code, stdout, err = run("run", root / "scene.toml", "-o", out, "--quiet", "--report")
    assert code == 0, err
    page = (out / MAP_NAME).read_text(encoding="utf-8")
    zones = out / ("zones.geojson" if (out / "zones.geojson").exists() else "zones_local_frame.json")
    return {"out": out, "stdout": stdout, "page": page, "data": page_data(page), "scene": scene,
            "doc": json.loads((out / "report.json").read_text()), "geojson": json.loads(zones.read_text())}


@pytest.fixture(scope="module")
def site(tmp_path_factory):
    """The site scene with an observer on the aim (about 4 s; lon/lat needs the geo extra)."""
    pytest.importorskip("pyproj", reason="a [site] scene needs pyproj: pip install 'laser-hazard[geo]'")
    pytest.importorskip("rasterio", reason="the map outputs of a site need rasterio: pip install 'laser-hazard[geo]'")
    from tests.hazard.test_map_outputs import SCENE as GEO_ZONES

    return _run_report(tmp_path_factory.mktemp("site"), GEO_ZONES + ON_THE_AIM)


@pytest.fixture(scope="module")
def local(tmp_path_factory):
    """The review page's plate with a fan of 60 observers, two hazardous, and a name with
    markup, in the scene's local frame (no site: L.CRS.Simple in metres; about 2 s)."""
    return _run_report(tmp_path_factory.mktemp("local"), PLATE_FAN)


# -- without a browser -------------------------------------------------------------------
def test_hillshade_lights_a_plane_by_the_cosine_of_its_angle_to_the_sun():
    alt, az = 45.0, 315.0
    flat = hillshade(np.zeros((4, 5)), 10.0, az, alt)
    assert np.allclose(flat, math.sin(math.radians(alt)))
    x, y = np.meshgrid(np.arange(5) * 10.0, np.arange(4) * 10.0)
    facing = hillshade(-1.0 * (-x + y) / math.sqrt(2), 10.0, az, alt)  # rises to the south-east: faces the north-west sun at 45 deg
    assert np.allclose(facing, 1.0)
    away = hillshade(2.0 * (-x + y) / math.sqrt(2), 10.0, az, alt)  # 63 deg slope facing away: in its own shadow
    assert np.allclose(away, 0.0)
    east = hillshade(0.5 * x, 10.0, 90.0, 0.0)  # sun on the horizon in the east, slope rising east: unlit
    assert np.allclose(east, 0.0)


def test_the_hillshade_png_reads_back():
    image = pytest.importorskip("PIL.Image", reason="reads the PNG back (Pillow comes with the render extra)")
    rng = np.random.default_rng(3)
    g, a = rng.integers(0, 256, (7, 11), dtype=np.uint8), rng.integers(0, 256, (7, 11), dtype=np.uint8)
    im = image.open(io.BytesIO(png_gray_alpha(g, a)))
    assert im.mode == "LA" and im.size == (11, 7)
    back = np.asarray(im)
    assert np.array_equal(back[..., 0], g) and np.array_equal(back[..., 1], a)


def test_run_report_writes_map_html_listed_in_the_manifest(site):
    out = site["out"]
    assert f"wrote {out / MAP_NAME}" in site["stdout"]
    manifest = json.loads((out / ".laser-hazard.json").read_text())
    assert manifest["files"][MAP_NAME] == "run" and manifest["files"]["report.html"] == "run"
    code, stdout, err = run("report", out)  # hazard report writes it again, as its own
    assert code == 0, err
    assert stdout.splitlines() == [f"wrote {out / MAP_NAME}", f"wrote {out / 'report.html'}"]
    assert json.loads((out / ".laser-hazard.json").read_text())["files"][MAP_NAME] == "report"
    assert "<li>map.html: present: the plan view as an interactive map" in (out / "report.html").read_text(encoding="utf-8")


def test_the_page_is_one_file_that_fetches_nothing(site):
    page = site["page"]
    assert "<link" not in page.lower() and "@import" not in page
    assert not re.search(r"<script[^>]*\bsrc=", page, re.I)
    assert not re.search(r"url\((?!data:|#default#VML)", page)  # the CSS's images are data URIs
    assert "Leaflet" in page and "BSD-2-Clause" in page and "PROVENANCE.md" in page
    licence = (Path(__file__).parents[2] / "hazard/templates/vendor/leaflet/LICENSE").read_text()
    assert licence in page  # BSD-2 clause 2: the notice and conditions travel with the minified copy


def test_every_finding_of_report_json_is_in_a_layer(site):
    doc, data, gj = site["doc"], site["data"], site["geojson"]
    names = {lid: [f["properties"]["name"] for f in features(data, lid)] for lid in LAYERS}
    hazardous = [o["name"] for o in doc["observers"] if o["hazardous"]]
    assert hazardous == [HAZARDOUS_NAME] and names["observers_hazardous"] == hazardous
    assert sorted(names["observers_safe"]) == sorted(o["name"] for o in doc["observers"] if not o["hazardous"])
    assert len(names["sdz"]) == (doc["sdz"]["polygon_m"] is not None) == 1
    assert len(names["sdz_aided"]) == sum(bool(a.get("polygon_m")) for a in doc["sdz"]["aided"]) == 1
    for t in doc["targets"]:
        assert (t["name"] in names["keepout_lobe"]) == (max(t["nohd_static_m"], t["nohd_dynamic_m"]) > 0), t["name"]
        assert (t["name"] in names["mirror_beam"]) == bool(t["specular_nohd_dynamic_m"]), t["name"]
    variants = sorted(f["properties"]["variant"] for f in features(data, "footprint"))
    assert variants == sorted(k for k, v in doc["footprint"].items() if v["cells"] > 0) == ["dynamic", "static"]
    assert len(names["range_boundary"]) == 1
    assert sorted(lay["legend_rank"] for lay in data["layers"]) == list(range(len(LAYERS)))  # each layer listed once
    # every GeoJSON feature is drawn by exactly one layer, its geometry unchanged
    assert sum(lay["count"] for lay in data["layers"]) == len(gj["features"]) and data["stray"] == []
    drawn = [f["geometry"] for lay in data["layers"] for f in lay["features"]]
    assert sorted(map(json.dumps, drawn)) == sorted(json.dumps(f["geometry"]) for f in gj["features"])


def test_each_observer_pop_up_holds_report_json_numbers(site):
    rows = {o["name"]: o for o in site["doc"]["observers"]}
    popups = [f["properties"]["popup"] for lid in ("observers_hazardous", "observers_safe") for f in features(site["data"], lid)]
    assert len(popups) == len(rows)
    for p in popups:
        name = p["title"].removeprefix("observer ")
        lines = {key: (shown, exact) for key, shown, exact in p["lines"]}
        for key in ("peak_irradiance_w_m2", "mpe_w_m2", "hazard_ratio"):
            assert float(lines[key][1]) == rows[name][key], (name, key)
        assert p["source"] == "report.json observers"
    assert lines["mpe_w_m2"][0] == "50\u00a0W/m\u00b2"
    assert site["data"]["labels"]["hazard_ratio"] == "hazard ratio"


def test_absent_kinds_and_the_terrain_are_said(site):
    page, data = site["page"], site["data"]
    absent = site["geojson"]["laser_hazard"]["absent"]
    assert set(absent) >= {"track", "airspace_zone", "visual_zone", "sdz_nominal"}
    for why in absent.values():
        assert str(markupsafe.escape(why)) in page
    hs = data["hillshade"]
    assert hs["uri"].startswith("data:image/png;base64,") and "hillshade of the analysed terrain (flat;" in hs["what"]
    err_m = float(re.search(r"within ([0-9.e-]+) m of its exact place", hs["what"]).group(1))
    # the terrain grid (x -400..400 m, y -200..600 m) is an ENU rectangle, not a lon/lat one: meridian
    # convergence x y tan(lat) / R and the parallel's bend x^2 tan(lat) / (2 R) at the far corner (Mercator is
    # linear to a few mm over 800 m); a few cm, far below a cell (4 m)
    t, r = math.tan(math.radians(47.0)), 6.38e6
    expected_m = (400 * 600 + 400**2 / 2) * t / r
    assert 0.7 * expected_m < err_m < 1.3 * expected_m
    (s, w), (n, e) = hs["bounds"]
    assert 46.99 < s < 47.0 < n < 47.01 and 7.99 < w < 8.0 < e < 8.01


def test_where_a_beam_or_zone_is_drawn_to_and_whether_the_hazard_goes_farther(site):
    doc, data = site["doc"], site["data"]
    sdz = features(data, "sdz")[0]["properties"]["end"]  # drawn to its reach (NOHD: no backstop on flat ground)
    assert not sdz["short"] and math.isclose(sdz["drawn_m"], doc["sdz"]["max_range_m"], rel_tol=1e-3)
    mirror = next(t for t in doc["targets"] if t["specular_nohd_dynamic_m"])
    end = features(data, "mirror_beam")[0]["properties"]["end"]  # from the mirror, along the slant of the beam
    assert not end["short"] and math.isclose(end["drawn_m"], mirror["specular_nohd_dynamic_m"], rel_tol=1e-3)
    # the aided zone (7x binoculars) reaches 237 km, and its polygon is drawn that far (it was cut at 100 km)
    reach = doc["sdz"]["aided"][0]["max_range_m"]
    aided = features(data, "sdz_aided")[0]["properties"]["end"]
    assert reach > 2e5 and not aided["short"] and math.isclose(aided["drawn_m"], reach, rel_tol=1e-3)


def test_a_zone_drawn_short_of_its_reach_is_said(site, tmp_path):
    """A copy of the run whose report.json gives the aided zone twice the reach its polygon
    is drawn to: the page says how far it reaches, beyond the drawing, in the layer list too."""
    out = shutil.copytree(site["out"], tmp_path / "out")
    doc = json.loads((out / "report.json").read_text())
    reach = 2.0 * float(doc["sdz"]["aided"][0]["max_range_m"])
    doc["sdz"]["aided"][0]["max_range_m"] = reach
    (out / "report.json").write_text(json.dumps(doc))
    page = write_map_page(out).read_text(encoding="utf-8")
    aided = features(page_data(page), "sdz_aided")[0]["properties"]["end"]
    assert aided["short"] and aided["text"].endswith(f"it reaches {fmt_number(reach, 'm', sig=4)} (report.json), beyond this drawing")
    assert str(markupsafe.escape(aided["text"])) in page  # in the layer list too


def test_an_unbounded_danger_zone_is_said_unbounded(local, tmp_path):
    """A collimated beam in clear air: report.json's reach "inf" (JSON has no infinity), its
    polygon drawn to 100 km; the copy of the local run is given that reach."""
    out = shutil.copytree(local["out"], tmp_path / "out")
    gj = json.loads((out / "zones_local_frame.json").read_text())
    sdz = next(f for f in gj["features"] if f["properties"]["kind"] == "sdz")
    sdz["properties"]["max_range_m"] = "inf"
    (out / "zones_local_frame.json").write_text(json.dumps(gj))
    end = features(page_data(write_map_page(out).read_text(encoding="utf-8")), "sdz")[0]["properties"]["end"]
    assert end["short"] and end["reported_m"] == "inf"
    assert end["text"].endswith("; it is unbounded (report.json: an infinite reach), beyond this drawing")


def test_an_observer_report_json_calls_hazardous_is_drawn_hazardous(local, tmp_path):
    """Where the GeoJSON and report.json disagree, the page takes the hazardous side."""
    out = shutil.copytree(local["out"], tmp_path / "out")
    gj = json.loads((out / "zones_local_frame.json").read_text())
    name = next(o["name"] for o in local["doc"]["observers"] if o["hazardous"])
    next(f for f in gj["features"] if f["properties"].get("name") == name)["properties"]["hazard"] = "none"
    (out / "zones_local_frame.json").write_text(json.dumps(gj))
    data = page_data(write_map_page(out).read_text(encoding="utf-8"))
    assert name in [f["properties"]["name"] for f in features(data, "observers_hazardous")]


def test_distances_without_pyproj_are_on_a_sphere_and_said(site, tmp_path, monkeypatch):
    """Where the page is made without pyproj, the spherical distance is within 0.6 % of the
    geodesic one (here 0.25 % at 47 deg N, north-south) and the page says which it used."""
    ends = [(f["properties"]["end"]["drawn_m"]) for lid in ("sdz", "sdz_aided") for f in features(site["data"], lid)]
    monkeypatch.setitem(__import__("sys").modules, "pyproj", None)  # import pyproj raises ImportError
    out = shutil.copytree(site["out"], tmp_path / "out")
    data = page_data(write_map_page(out).read_text(encoding="utf-8"))
    sphere = [f["properties"]["end"]["drawn_m"] for lid in ("sdz", "sdz_aided") for f in features(data, lid)]
    assert all(0 < abs(a / b - 1) < 6e-3 for a, b in zip(sphere, ends)) and "on a sphere (pyproj is not installed" in data["distance_note"]
    assert site["data"]["distance_note"] == ""


def test_a_changed_scene_file_or_a_missing_geojson_is_said(site, tmp_path):
    out = shutil.copytree(site["out"], tmp_path / "out")
    scene = tmp_path / "scene.toml"
    scene.write_text(site["scene"] + "\n# edited after the run\n")
    doc = json.loads((out / "report.json").read_text())
    doc["scene"]["source"] = str(scene)
    (out / "report.json").write_text(json.dumps(doc))
    data = page_data(write_map_page(out).read_text(encoding="utf-8"))
    assert data["hillshade"] is None and "has changed since the run" in data["hillshade_absent"]
    (out / "zones.geojson").unlink()
    page = write_map_page(out).read_text(encoding="utf-8")
    assert "No map: zones.geojson cannot be read" in page and page_data(page)["layers"] == []
    doc.pop("map_outputs")  # a run from before the map outputs
    (out / "report.json").write_text(json.dumps(doc))
    page = write_map_page(out).read_text(encoding="utf-8")
    assert "No map: report.json lists no zones GeoJSON (map_outputs.files): run hazard run again" in page


# -- in a real browser ---------------------------------------------------------------------
@pytest.fixture(scope="module")
def browser(tmp_path_factory, os_chromium):  # noqa: F811 (the fixture imported above)
    sync_api = pytest.importorskip("playwright.sync_api", reason="needs playwright: pip install 'laser-hazard[test]' "
                                                                 "(it drives the OS's Chromium; never `playwright install`)")
    with sync_api.sync_playwright() as p:
        context = p.chromium.launch_persistent_context(str(tmp_path_factory.mktemp("profile")), executable_path=os_chromium,
                                                       args=BROWSER_ARGS, headless=True, viewport={"width": 1280, "height": 860})
        try:
            yield context
        finally:
            context.close()


def open_map(browser, out: Path):
    """The page loaded: (page, console errors, URLs requested)."""
    page = browser.new_page()
    errors, requests = _console_errors(page), []
    page.on("request", lambda r: requests.append(r.url))
    page.goto((out / MAP_NAME).resolve().as_uri(), wait_until="load")
    page.wait_for_function("window.hazardMap !== undefined")
    return page, errors, requests


def layers_on_map(page) -> dict:
    """layer id -> (on the map, Leaflet features drawn, their names)."""
    return page.evaluate("""() => { const h = window.hazardMap, out = {};
        for (const [id, g] of Object.entries(h.geo)) {
            const ls = g.getLayers();
            out[id] = [h.map.hasLayer(h.layers[id]), ls.length, ls.map(l => l.feature.properties.name)]; }
        return out; }""")


def click_observer(page, name: str) -> dict:
    """Zoom to the observer ``name``, click it (a real mouse click) and read the pop-up's rows."""
    xy = page.evaluate("""(name) => { const h = window.hazardMap;
        const hits = Object.values(h.geo).flatMap(g => g.getLayers()).filter(l =>
            l.feature.properties.kind === 'observer' && l.feature.properties.name === name);
        h.map.setView(hits[0].getLatLng(), h.data.site ? 20 : 8, {animate: false});
        const p = h.map.latLngToContainerPoint(hits[0].getLatLng()), r = h.map.getContainer().getBoundingClientRect();
        return [r.left + p.x, r.top + p.y]; }""", name)
    page.mouse.click(*xy)
    page.wait_for_selector(".leaflet-popup-content .popup")
    return page.evaluate("""() => { const c = document.querySelector('.leaflet-popup-content');
        const rows = {}; c.querySelectorAll('tr').forEach(tr => rows[tr.dataset.key] =
            [tr.querySelector('.value').textContent, tr.querySelector('.value').dataset.exact || null]);
        return {title: c.querySelector('h3').textContent, rows: rows}; }""")


def red_pixels(png: bytes, box) -> tuple[int, float]:
    """Pixels of the hazard reds (within 40 per channel) in ``box`` (x0, y0, x1, y1) and the
    standard deviation of its grey levels (0: one flat colour)."""
    image = pytest.importorskip("PIL.Image", reason="counts the screenshot's pixels (Pillow comes with the render extra)")
    rgb = np.asarray(image.open(io.BytesIO(png)).convert("RGB"), int)[box[1]:box[3], box[0]:box[2]]
    red = np.zeros(rgb.shape[:2], bool)
    for c in RED_RGB:
        red |= np.all(np.abs(rgb - np.array(c)) <= 40, axis=-1)
    return int(red.sum()), float(rgb.mean(axis=-1).std())


def check_loaded_map(browser, out: Path, doc: dict, shot: Path) -> object:
    """The checks every map page passes; returns the open page."""
    page, errors, requests = open_map(browser, out)
    data = page.evaluate("window.hazardMap.data")
    on_map = layers_on_map(page)
    for lay in data["layers"]:
        shown, count, names = on_map[lay["id"]]
        assert count == lay["count"] and shown == (count > 0), lay["id"]
    assert sorted(on_map["observers_hazardous"][2]) == sorted(o["name"] for o in doc["observers"] if o["hazardous"])
    for t in doc.get("tracks") or []:
        assert t["name"] in on_map["track"][2]
    for z in (doc.get("airspace") or {}).get("zones") or []:
        assert z["name"] in on_map["airspace_zone"][2]
    box = page.evaluate("(() => { const r = document.getElementById('map').getBoundingClientRect(); "
                        "return [r.left, r.top, r.right, r.bottom].map(Math.round); })()")
    png = page.screenshot(path=str(shot))
    reds, spread = red_pixels(png, box)
    assert spread > 5.0, "the map is one flat colour"
    assert reds > 30 or not data["headline"].startswith("HAZARD"), "no hazard red on the map of a HAZARD verdict"
    assert errors == [], errors
    assert all(u.startswith(("file:", "data:")) for u in requests), requests
    return page


def test_the_map_in_a_real_headless_chromium(site, browser, tmp_path):
    """The site run's map.html (about 3 s): loads clean, every layer, the observer's numbers, a toggle."""
    doc = site["doc"]
    page = check_loaded_map(browser, site["out"], doc, tmp_path / "map.png")
    try:
        assert page.evaluate("window.hazardMap.map.options.crs === L.CRS.EPSG3857")  # lon/lat on Web Mercator
        popup = click_observer(page, HAZARDOUS_NAME)
        row = next(o for o in doc["observers"] if o["name"] == HAZARDOUS_NAME)
        assert popup["title"] == f"observer {HAZARDOUS_NAME}"  # the name as typed, never as markup
        tips = page.evaluate("Array.from(document.querySelectorAll('.leaflet-tooltip')).map(t => [t.textContent, "
                             "t.querySelectorAll('b').length])")  # the hover label under the mouse, and the targets'
        assert [HAZARDOUS_NAME, 0] in tips and all(n == 0 for _, n in tips), tips
        text, exact = popup["rows"]["hazard_ratio"]
        assert float(exact) == row["hazard_ratio"]
        assert math.isclose(float(text.replace("\u00a0", "").replace(",", "")), row["hazard_ratio"], rel_tol=5e-4)
        assert popup["rows"]["mpe_w_m2"][0] == "50\u00a0W/m\u00b2" and popup["rows"]["verdict"][0] == "hazardous"
        assert page.locator(".grat-label").count() >= 2  # the longitude and latitude lines are labelled
        assert page.locator("#legend .legend-row").first.get_attribute("data-layer") == "observers_hazardous"
        assert page.locator(".end-label.short").all_inner_texts() == []  # every zone and beam drawn to its reach
        label = page.locator(".leaflet-control-layers-overlays label", has_text="Mirror beams")
        label.locator("input").uncheck()
        assert not page.evaluate("window.hazardMap.map.hasLayer(window.hazardMap.layers.mirror_beam)")
    finally:
        page.close()


@pytest.mark.slow
@pytest.mark.parametrize("example", ["range_geo", "airspace", "range_terrain", "steel_vs_copper"])
def test_bundled_examples_maps_in_chromium(example, browser, tmp_path):
    """Each bundled example's map (the cached analyses of tests._bundled; up to 25 s each)."""
    from hazard.outputs.map_outputs import map_files
    from hazard.outputs.report import write_outputs
    from tests._bundled import bundled

    result = bundled(example)
    maps, section = map_files(result)
    out = tmp_path / "out"
    write_outputs(result, out, extra=maps, sections={"map_outputs": section})
    write_map_page(out)
    doc = json.loads((out / "report.json").read_text())
    page = check_loaded_map(browser, out, doc, tmp_path / f"{example}.png")
    try:
        data = page.evaluate("window.hazardMap.data")
        if (doc["scene"]["echo"].get("terrain") or {}).get("kind") not in (None, "flat"):
            assert data["hillshade"] is not None and page.evaluate("window.hazardMap.map.hasLayer(window.hazardMap.layers.hillshade)")
        hazardous = [o["name"] for o in doc["observers"] if o["hazardous"]]
        if hazardous:
            row = next(o for o in doc["observers"] if o["name"] == hazardous[0])
            assert float(click_observer(page, row["name"])["rows"]["hazard_ratio"][1]) == row["hazard_ratio"]
    finally:
        page.close()


def test_the_local_frame_map_in_a_real_headless_chromium(local, browser, tmp_path):
    """No site: metres on L.CRS.Simple, the cursor in x, y; both hazardous observers' numbers."""
    doc = local["doc"]
    hazardous = [o for o in doc["observers"] if o["hazardous"]]
    assert len(hazardous) == 2 and local["data"]["site"] is False
    page = check_loaded_map(browser, local["out"], doc, tmp_path / "local.png")
    try:
        assert page.evaluate("window.hazardMap.map.options.crs === L.CRS.Simple")
        for row in hazardous:  # 6 cm apart in the fan: each found by its own click at high zoom
            popup = click_observer(page, row["name"])
            assert popup["title"] == f"observer {row['name']}" and float(popup["rows"]["hazard_ratio"][1]) == row["hazard_ratio"]
        page.mouse.move(300, 400)
        assert re.fullmatch(r"x -?[0-9.]+ m, y -?[0-9.]+ m", page.locator("#cursor").inner_text())
        assert page.locator("#hazardous-list li a").all_inner_texts() == [o["name"] for o in hazardous]
        nasty = click_observer(page, NASTY)
        assert nasty["title"] == f"observer {NASTY}"
    finally:
        page.close()


def test_a_mirror_beam_stopped_by_a_backstop_is_not_said_short():
    """A mirror beam the analysis stops at a wall 188 m out (its NOHD 1121 m) is drawn to the
    wall; the page takes that stop as its reach, not the NOHD (no false "reaches farther")."""
    from hazard.outputs.map_page import _reported_reach_m

    assert _reported_reach_m({"kind": "mirror_beam", "nohd_m": 1121.0, "reach_m": 188.0}, {}) == 188.0
    assert _reported_reach_m({"kind": "mirror_beam", "nohd_m": 1121.0}, {}) == 1121.0  # an older GeoJSON
