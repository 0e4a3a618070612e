"""The 3-D pictures of ``hazard render`` (keepout.png, overview.png) print their smallest
text at 6 pt or more on the report's landscape A4 page (issue 34 leftover d: the legend
and title lines printed at 5.7 pt, the tags in the view at 4.7-5.1 pt, the axes' letters
at ~3 pt). A picture is its 1280 px view with a legend beside it
(:func:`hazard.pictures.picture.compose`), printed scaled to the page's content width:
printed pt = text height [px] x (page width [in] x 96 / picture width [px]) x 72 / 96,
the estimate the print-layout test makes (tests/hazard/test_print_layout.py). The page
width is written here from the page (A4 landscape 297 mm less 2 x 14 mm margins of
hazard/templates/_style.css.j2), not read from the code."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("matplotlib")

WIDE_IN = (297.0 - 2 * 14.0) / 25.4  # the landscape page's content width [in]
VIEW = (900, 1280)  # hazard render's default window [px]


def printed_pt(text_px: float, width_px: int, page_in: float = WIDE_IN) -> float:
    """The printed height [pt] of text ``text_px`` high in a picture ``width_px`` wide,
    laid out at most the page's width (CSS max-width 100 %: never enlarged)."""
    css_px = min(page_in * 96.0, width_px)
    return text_px * css_px / width_px * 72.0 / 96.0


LONG = ("observers at or above the MPE (12; 4 more in observers.csv), the worst numbered: a label far longer than any "
        "line of the legend should be, so that it must wrap")


def test_the_widest_legend_still_prints_its_text_at_6_pt():
    from hazard.pictures.picture import TAG_PX, TITLE_PT, compose, text_px_min

    entries = [(LONG, "#e41a1c", "marker"), ("laser beam to the targets", "#e41a1c", "line"),
               ("target-with-a-long-name: NOHD static 1.23e+04 m, dynamic 1.31e+04 m, mirror beam 2.255e+04 m", None, "text")]
    lines = ["scene: keep-out zones (close view)", "MPE 50 W/m^2; local origin at [0.0, 0.0, 0.0] m (world = local + origin)"]
    picture, layout = compose(np.full((*VIEW, 3), 200, np.uint8), entries, lines)
    smallest = text_px_min(entries, lines, TAG_PX)
    assert smallest == pytest.approx(min(12.0 * 100 / 72, TITLE_PT[1] * 100 / 72, TAG_PX))  # the 12 pt legend at 100 dpi: 16.7 px
    assert printed_pt(smallest, picture.shape[1]) >= 6.0, picture.shape
    # the long label wrapped: the legend is narrower than the view's half (unwrapped it was ~1500 px)
    assert layout["legend"][3] - layout["legend"][2] < VIEW[1] / 2


def test_a_legend_taller_than_the_view_makes_the_picture_taller_never_an_error():
    from hazard.pictures.picture import compose

    entries = [(f"observer {k}: 1.2 x MPE", None, "text") for k in range(60)]
    picture, layout = compose(np.full((300, 400, 3), 200, np.uint8), entries, ["title"])
    r0, r1, c0, c1 = layout["legend"]
    assert r1 - r0 > 300 and picture.shape[0] >= r1  # the legend whole, the view padded white below
    assert layout["scene"][1] - layout["scene"][0] == 300
    below = picture[layout["scene"][1]:r1, :400]
    assert (below == 255).all()  # white under the view
