"""Labels do not cover each other (issue 34 leftover 3): in the rendered figure, the
window extents of the texts of each panel (matplotlib's ``Text.get_window_extent``: the
text's own box, an annotation's arrow aside) do not overlap, and every label stays
inside its panel."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from tests._bundled import bundled

pytest.importorskip("matplotlib")


def _boxes(ax) -> list:
    from matplotlib.text import Text

    r = ax.figure.canvas.get_renderer()
    out = []
    for t in ax.texts:
        check = getattr(t, "_check_xy", None)
        if t.get_visible() and t.get_text().strip() and (check is None or check(r)):
            b = Text.get_window_extent(t, r)
            out.append((t.get_text(), b))
    return out


def overlaps(ax) -> list:
    """Pairs of texts of ``ax`` whose boxes overlap (by more than half a pixel)."""
    out = []
    for (ta, a), (tb, b) in itertools.combinations(_boxes(ax), 2):
        if min(a.x1, b.x1) - max(a.x0, b.x0) > 0.5 and min(a.y1, b.y1) - max(a.y0, b.y0) > 0.5:
            out.append((ta, tb))
    return out


def outside(ax) -> list:
    f = ax.get_window_extent(ax.figure.canvas.get_renderer())
    return [t for t, b in _boxes(ax) if b.x0 < f.x0 - 0.5 or b.x1 > f.x1 + 0.5 or b.y0 < f.y0 - 0.5 or b.y1 > f.y1 + 0.5]


def test_labels_at_one_point_are_spread_apart_inside_the_panel_each_tied_to_its_point():
    from hazard.canvas import subplots
    from hazard.label_place import place_labels

    fig, ax = subplots(figsize=(5, 4))
    ax.set_xlim(0, 100)
    ax.set_ylim(0, 100)
    for k in range(6):  # six labels on one point, and two texts on the data at the same place
        ax.annotate(f"label number {k} of the point", (50.0, 50.0), xytext=(4, 4), textcoords="offset points", fontsize=8)
    ax.text(50.0, 50.0, "a plain text", fontsize=8)
    ax.text(50.5, 50.5, "another plain text", fontsize=8)
    fig.canvas.draw()
    assert len(overlaps(ax)) >= 20  # before: all on top of each other
    r = fig.canvas.get_renderer()
    points = [(50.0, 50.0)] * 7 + [(50.5, 50.5)]
    from matplotlib.text import Text

    def gap(t, xy):  # [px] from a label's point to its box
        p = ax.transData.transform(xy)
        b = Text.get_window_extent(t, r)
        return p, np.clip(p, [b.x0, b.y0], [b.x1, b.y1])

    before = [float(np.hypot(*np.subtract(*gap(t, xy)))) for t, xy in zip(ax.texts, points)]
    lines = len(ax.lines)
    moved = place_labels(ax)
    fig.canvas.draw()
    assert moved == 7 and not overlaps(ax) and not outside(ax)
    assert lines == 0 and len(ax.lines) >= 4
    ends = [ax.transData.transform(np.asarray(ln.get_xydata(), float)) for ln in ax.lines]
    for t, xy, was in zip(ax.texts, points, before):  # each label as near its point as it was, or a leader line joins them
        p, q = gap(t, xy)
        assert np.hypot(*(q - p)) <= was + 3.0 or any(np.allclose(e[0], p, atol=0.5) and np.allclose(e[1], q, atol=1.0)
                                                       for e in ends), t.get_text()


def test_a_label_with_no_free_place_stays():
    from hazard.canvas import subplots
    from hazard.label_place import place_labels

    fig, ax = subplots(figsize=(1.2, 0.6))
    ax.set_xlim(0, 1)
    ax.set_ylim(0, 1)
    ax.text(0.0, 0.3, "a long label over the whole small panel", fontsize=8)
    ax.text(0.0, 0.35, "a second long label over the whole panel", fontsize=8)
    fig.canvas.draw()
    place_labels(ax)
    assert len(ax.texts) == 2 and all(t.get_visible() for t in ax.texts)  # nothing dropped


def _views(name):
    from hazard.elevation_view import ElevationViewDisplay
    from hazard.plan_view import PlanViewDisplay

    res = bundled(name)
    out = []
    for display in (PlanViewDisplay, ElevationViewDisplay):
        fig, axes = display.from_result(res).plot()
        fig.canvas.draw()
        out += list(np.ravel(axes))
    return out


@pytest.mark.parametrize("name", ["mirror_window", pytest.param("airspace", marks=pytest.mark.slow),
                                  pytest.param("range_terrain", marks=pytest.mark.slow)])
def test_no_two_labels_of_a_panel_overlap(name):
    for ax in _views(name):
        assert not overlaps(ax), (ax.get_title(), overlaps(ax))
