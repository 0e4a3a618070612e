"""report.pdf keeps every picture, and so its legend, inside the page (issue 34 leftover
4). report.pdf is report.html printed by headless Chromium on A4 with the page's
``@page`` margins (14 mm x 12 mm); the test lays the page out in the same Chromium for
print (print media, the A4 content box as the viewport) and checks that every picture
lies inside the page's width and fits a page's height (``break-inside: avoid`` then keeps
it whole), so nothing of a picture, its legend beside or below the plot included, is cut.
The pictures' own legends are inside the PNGs (tests/hazard/test_picture_pixels.py).

Every picture's smallest text prints at least 6 pt high (issue 34 leftover: the plan
view's legend printed at 3.4 pt): figures.json gives each picture's smallest text height
in its own pixels (``text_px_min``, the font size x dpi / 72); the printed height is that
x the width Chromium lays the picture out at / its width in pixels. The plan and
elevation views print on landscape pages (``figure.wide``, ``@page wide``): they are laid
out at the landscape content width, and the PDF Chromium prints has landscape pages."""

from __future__ import annotations

import json
import re

import pytest

from tests.hazard.test_review_report import BROWSER_ARGS, copy_out, os_chromium, plate  # noqa: F401 (fixtures)

MM_PX = 96 / 25.4  # CSS pixels per mm
PAGE_W_PX = (210 - 2 * 12) * MM_PX  # A4 less the @page margins of hazard/templates/_style.css.j2
PAGE_H_PX = (297 - 2 * 14) * MM_PX
WIDE_W_PX, WIDE_H_PX = (297 - 2 * 14) * MM_PX, (210 - 2 * 12) * MM_PX  # landscape A4 less @page wide's margins
PT_PER_PX = 72 / 96  # CSS
MIN_PT = 6.0  # the smallest printed text the issue asks for


def _laid_out(sync_api, chromium, out, profile, width_px, height_px, pdf=False) -> tuple:
    """(boxes of the report's pictures, the laid-out width [CSS px], PDF bytes or None) in
    print media with the viewport ``width_px`` x ``height_px``."""
    with sync_api.sync_playwright() as p:
        browser = p.chromium.launch_persistent_context(str(profile), executable_path=chromium, args=BROWSER_ARGS,
                                                       headless=True, viewport={"width": round(width_px), "height": round(height_px)})
        try:
            page = browser.new_page()
            page.emulate_media(media="print")
            page.goto((out / "report.html").resolve().as_uri(), wait_until="load")
            boxes = page.eval_on_selector_all("figure img", """imgs => imgs.map(i => {
                const r = i.getBoundingClientRect();
                return {name: i.title, left: r.left, right: r.right, width: r.width, height: r.height, natural: i.naturalWidth,
                        wide: i.closest('figure').classList.contains('wide')};
            })""")
            page_w = page.evaluate("document.documentElement.clientWidth")
            printed = page.pdf(prefer_css_page_size=True) if pdf else None
        finally:
            browser.close()
    return boxes, page_w, printed


def test_every_picture_of_the_printed_report_is_inside_the_page(plate, tmp_path, os_chromium):  # noqa: F811
    sync_api = pytest.importorskip("playwright.sync_api", reason="needs playwright: pip install 'laser-hazard[test]'")
    pytest.importorskip("matplotlib", reason="the pictures need matplotlib (pip install 'laser-hazard[render]')")
    out = copy_out(plate["out"], tmp_path / "out")
    figures = json.loads((out / "figures.json").read_text())["figures"]
    portrait, page_w, printed = _laid_out(sync_api, os_chromium, out, tmp_path / "p1", PAGE_W_PX, PAGE_H_PX, pdf=True)
    landscape, wide_w, _ = _laid_out(sync_api, os_chromium, out, tmp_path / "p2", WIDE_W_PX, WIDE_H_PX)
    assert abs(page_w - PAGE_W_PX) <= 1.0 and abs(wide_w - WIDE_W_PX) <= 1.0  # laid out at the printed widths
    assert {b["name"] for b in portrait} >= {"plan.png", "elevation.png"}
    wide = {b["name"] for b in portrait if b["wide"]}
    assert wide >= {"plan.png", "elevation.png"}
    # the PDF has portrait A4 pages and landscape ones (595 x 842 pt); Chromium writes each page's MediaBox
    sizes = {tuple(round(float(v)) for v in m) for m in re.findall(rb"/MediaBox\s*\[\s*0\s+0\s+([\d.]+)\s+([\d.]+)\s*\]", printed)}
    assert sizes == {(595, 842), (842, 595)}, sizes
    checked = []
    for b in [b for b in portrait if not b["wide"]] + [b for b in landscape if b["name"] in wide]:
        w_px, h_px = (WIDE_W_PX, WIDE_H_PX) if b["wide"] else (PAGE_W_PX, PAGE_H_PX)
        assert b["natural"] > 0 and b["width"] > 0, b
        assert b["left"] >= -0.5 and b["right"] <= w_px + 0.5, b  # inside the page's width, the legend too
        assert b["height"] <= h_px, b  # fits one page: printed whole
        if "text_px_min" in figures.get(b["name"], {}):
            pt = figures[b["name"]]["text_px_min"] * b["width"] / b["natural"] * PT_PER_PX
            assert pt >= MIN_PT, (b["name"], pt)
            checked.append(b["name"])
    assert {"plan.png", "elevation.png"} <= set(checked) and any(n.startswith(("exposure", "nohd_time")) for n in checked), checked
