"""map.html widens a thin zone the way the plan view does (issue 34 leftover c): a danger
zone about 1 m wide and 1.6 km long (range_clearance) is sub-pixel at the scale that shows
it whole, so a hatched band of fixed screen width is drawn along its long axis, and the
page says the zone's true width and that the band is exaggerated. The true width is
computed here from report.json's outline across the scene file's aim."""

from __future__ import annotations

import json

import numpy as np
import pytest

import scenes
from tests._bundled import bundled
from tests.hazard.test_map_page import browser, open_map  # noqa: F401 (the fixture)
from tests.hazard.test_review_report import os_chromium  # noqa: F401 (the browser fixture needs it)

NAME = "range_clearance"


@pytest.fixture(scope="module")
def out(tmp_path_factory):
    from hazard.outputs.map_outputs import map_files
    from hazard.outputs.map_page import write_map_page
    from hazard.outputs.report import write_outputs

    result = bundled(NAME)
    maps, section = map_files(result)
    out = tmp_path_factory.mktemp("thin") / "out"
    write_outputs(result, out, extra=maps, sections={"map_outputs": section.to_dict()})
    write_map_page(out)
    return out


def _aim(doc):
    scene = scenes.load(scenes.example_path(NAME))
    d = np.asarray(scene.laser_direction, float)[:2]
    u = d / np.hypot(*d)
    laser = (np.asarray(scene.laser_position_m, float) + np.asarray(scene.offset_m, float))[:2]
    return laser, u, np.array([-u[1], u[0]])


def test_each_thin_zone_has_a_band_along_its_axis_with_its_true_width_said(out):
    from hazard.outputs.map_page import map_data

    doc = json.loads((out / "report.json").read_text())
    laser, u, n = _aim(doc)
    rings = {"sdz": np.asarray(doc["sdz"]["polygon_m"], float), "sdz_aided": np.asarray(doc["sdz"]["aided"][0]["polygon_m"], float)}
    data = map_data(out)
    for lid, ring in rings.items():
        lay = next(layer for layer in data["layers"] if layer["id"] == lid)
        (f,) = lay["features"]
        band = f["properties"]["thin"]
        width = float(np.ptp((ring - laser) @ n))
        assert band["width_m"] == pytest.approx(width, rel=0.02)  # the rectangle about the zone, rotated to it
        axis = np.asarray(band["axis"], float)[:, ::-1]  # [lat, lng] = [y, x] in the local frame (L.CRS.Simple)
        along, across = (axis - laser) @ u, (axis - laser) @ n
        assert np.all(np.abs(across) <= width)  # on the zone
        assert sorted(along) == pytest.approx([float(((ring - laser) @ u).min()), float(((ring - laser) @ u).max())], abs=0.02 * width + 1e-6)
        (text,) = lay["thin"]
        assert "exaggerated" in text and f"{band['band_px']} px" in text
    for lay in data["layers"]:  # the wide zones (keep-out lobes, ground) get none
        assert lay["id"] in rings or not lay["thin"], lay["id"]


def test_the_band_is_drawn_in_chromium_at_its_screen_width(out, browser):  # noqa: F811
    """The page zoomed to everything: each band is on the map with its width [px], drawn
    along the zone (hundreds of pixels long), and its colour spans at least that width
    across the middle of its axis in the screenshot (the zone alone is a pixel wide there)."""
    import io

    from PIL import Image

    page, errors, _ = open_map(browser, out)
    try:
        page.click("#fit-all")
        page.wait_for_timeout(300)
        bands = page.evaluate("""(() => { const m = window.hazardMap.map, out = [];
            Object.values(window.hazardMap.layers).forEach(g => g.eachLayer && g.eachLayer(l => {
                if (l.options && l.options.className === 'thin-band' && m.hasLayer(l)) {
                    const p = l.getLatLngs().map(ll => m.latLngToContainerPoint(ll)), r = m.getContainer().getBoundingClientRect();
                    out.push({w: l.options.weight, a: [p[0].x + r.left, p[0].y + r.top], b: [p[1].x + r.left, p[1].y + r.top],
                              colour: l.options.color}); } })); return out; })()""")
        png = np.asarray(Image.open(io.BytesIO(page.screenshot())).convert("RGB"), int)
        assert errors == [], errors
    finally:
        page.close()
    assert sorted(b["w"] for b in bands) == [8, 12]
    for b in bands:
        a, e = np.asarray(b["a"], float), np.asarray(b["b"], float)
        assert np.hypot(*(e - a)) > 100  # drawn along the 1.6 km zone, not a dot
    wide = max(bands, key=lambda b: b["w"])  # the naked-eye zone's band, under the aided one: its edges show
    a, e = (np.asarray(wide[k], float) for k in "ab")
    u = (e - a) / np.hypot(*(e - a))
    s = np.arange(-15, 16)
    spans = []
    for t in np.linspace(0.2, 0.4, 21):  # cross-sections along the band (its hatching has gaps of 2 px)
        pts = np.round(a + t * (e - a) + s[:, None] * np.array([-u[1], u[0]])).astype(int)
        px = png[pts[:, 1], pts[:, 0]]
        coloured = (px[:, 0] - px[:, 1] > 60) & (px[:, 0] > 150)  # red or orange (#d7191c, #f39c12), not grey, white or green
        spans.append(int(np.ptp(s[coloured]) + 1) if coloured.any() else 0)
    assert max(spans) >= 8, spans


def test_a_zone_of_no_width_or_no_size_is_not_an_error():
    """A danger zone whose vertices lie on one line (no width: a beam below the MPE from
    its aperture on gives a polygon of coincident or collinear vertices) made `hazard
    report` fail with an internal error; a line gets a band along it, a point none."""
    from hazard.outputs.map_page import _thin_band

    line = {"geometry": {"type": "Polygon", "coordinates": [[[0.0, 0.0], [100.0, 0.0], [50.0, 0.0], [0.0, 0.0]]]}}
    band = _thin_band("sdz", "danger zone", line, site=False)
    assert band["width_m"] == 0.0 and sorted(p[1] for p in band["axis"]) == [0.0, 100.0]
    point = {"geometry": {"type": "Polygon", "coordinates": [[[5.0, 5.0], [5.0, 5.0], [5.0, 5.0], [5.0, 5.0]]]}}
    assert _thin_band("sdz", "danger zone", point, site=False) is None
