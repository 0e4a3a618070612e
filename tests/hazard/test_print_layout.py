"""report.pdf keeps every picture, and so its legend, inside the page (issue 34 leftover
4). report.pdf is report.html printed by headless Chromium on A4 with the page's
``@page`` margins (14 mm x 12 mm); the test lays the page out in the same Chromium for
print (print media, the A4 content box as the viewport) and checks that every picture
lies inside the page's width and fits a page's height (``break-inside: avoid`` then keeps
it whole), so nothing of a picture, its legend beside or below the plot included, is cut.
The pictures' own legends are inside the PNGs (tests/hazard/test_picture_pixels.py)."""

from __future__ import annotations

import pytest

from tests.hazard.test_review_report import BROWSER_ARGS, copy_out, os_chromium, plate  # noqa: F401 (fixtures)

MM_PX = 96 / 25.4  # CSS pixels per mm
PAGE_W_PX = (210 - 2 * 12) * MM_PX  # A4 less the @page margins of hazard/templates/_style.css.j2
PAGE_H_PX = (297 - 2 * 14) * MM_PX


def test_every_picture_of_the_printed_report_is_inside_the_page(plate, tmp_path, os_chromium):  # noqa: F811
    sync_api = pytest.importorskip("playwright.sync_api", reason="needs playwright: pip install 'laser-hazard[test]'")
    pytest.importorskip("matplotlib", reason="the pictures need matplotlib (pip install 'laser-hazard[render]')")
    out = copy_out(plate["out"], tmp_path / "out")
    with sync_api.sync_playwright() as p:
        browser = p.chromium.launch_persistent_context(str(tmp_path / "profile"), executable_path=os_chromium, args=BROWSER_ARGS,
                                                       headless=True, viewport={"width": round(PAGE_W_PX), "height": round(PAGE_H_PX)})
        try:
            page = browser.new_page()
            page.emulate_media(media="print")
            page.goto((out / "report.html").resolve().as_uri(), wait_until="load")
            boxes = page.eval_on_selector_all("figure img", """imgs => imgs.map(i => {
                const r = i.getBoundingClientRect();
                return {name: i.title, left: r.left, right: r.right, width: r.width, height: r.height, natural: i.naturalWidth};
            })""")
            page_w = page.evaluate("document.documentElement.clientWidth")
        finally:
            browser.close()
    assert abs(page_w - PAGE_W_PX) <= 1.0  # laid out at the printed width
    assert {b["name"] for b in boxes} >= {"plan.png", "elevation.png"}
    for b in boxes:
        assert b["natural"] > 0 and b["width"] > 0, b
        assert b["left"] >= -0.5 and b["right"] <= PAGE_W_PX + 0.5, b  # inside the page's width, the legend too
        assert b["height"] <= PAGE_H_PX, b  # fits one page: printed whole
