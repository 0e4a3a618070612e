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
    from hazard.outputs.label_place import place_labels

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
    from hazard.outputs.label_place import place_labels

    fig, ax = subplots(figsize=(1.2, 0.6))
    ax.set_xlim(0, 1)
    ax.set_ylim(0, 1)
    ax.text(0.0, 0.3, "a long label over the whole small panel", fontsize=8)
    ax.text(0.0, 0.35, "a second long label over the whole panel", fontsize=8)
    fig.canvas.draw()
    place_labels(ax)
    assert len(ax.texts) == 2 and all(t.get_visible() for t in ax.texts)  # nothing dropped


def _views(name):
    from hazard.pictures.elevation_view import ElevationViewDisplay
    from hazard.pictures.plan_view import PlanViewDisplay

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


def _line_px(ax, a, b, step_px=1.0) -> np.ndarray:
    """Points [px] every ``step_px`` along the data segment a-b (sampled here, not by the placer)."""
    pa, pb = ax.transData.transform(np.array([a, b], float))
    n = int(np.ceil(np.hypot(*(pb - pa)) / step_px)) + 1
    return pa + np.linspace(0.0, 1.0, n)[:, None] * (pb - pa)


def _covering(ax, t, pts, own_xy, own_px=14.0) -> int:
    """How many of ``pts`` [px] the box of text ``t`` covers, those within ``own_px`` of its own point aside."""
    from matplotlib.text import Text

    b = Text.get_window_extent(t, ax.figure.canvas.get_renderer())
    far = pts[np.hypot(*(pts - ax.transData.transform(own_xy)).T) > own_px]
    return int(np.sum((far[:, 0] >= b.x0) & (far[:, 0] <= b.x1) & (far[:, 1] >= b.y0) & (far[:, 1] <= b.y1)))


def test_a_label_over_a_drawn_finding_moves_off_it_and_one_over_unmarked_data_stays():
    """A label drawn across a finding's line and points (noted with figure_index.mark) is
    moved off them (issue 34 leftover: range_clearance's terrain label over the danger
    zone's end); a label over a line that is no finding stays where it was."""
    from hazard.canvas import subplots
    from hazard.outputs.figure_index import mark
    from hazard.outputs.label_place import place_labels

    fig, ax = subplots(figsize=(5, 4))
    ax.set_xlim(0, 100)
    ax.set_ylim(0, 100)
    ax.plot([50, 50], [0, 100], c="r")
    mark(ax, ["sdz"], "zone", [[50, 0], [50, 100]], "line")
    crosses = np.array([[30.0, 62.0], [70.0, 62.0]])
    ax.plot(*crosses.T, "rx")
    mark(ax, ["observers[0]", "observers[1]"], "hazardous observers", crosses, "points")
    ax.plot([0, 100], [20, 20], c="k")  # no finding: the placer may cover it
    over = ax.annotate("a label across the beam", (40.0, 60.0), xytext=(0, 0), textcoords="offset points", fontsize=8)
    stays = ax.annotate("a label over a plain line", (3.0, 20.0), xytext=(0, 0), textcoords="offset points", fontsize=8)
    fig.canvas.draw()
    beam = _line_px(ax, (50, 0), (50, 100))
    pts = np.vstack([beam, ax.transData.transform(crosses)])
    assert _covering(ax, over, pts, (40.0, 60.0)) > 0  # before: across the beam
    before = stays.get_window_extent().frozen()
    assert place_labels(ax) == 1
    fig.canvas.draw()
    assert _covering(ax, over, pts, (40.0, 60.0)) == 0
    assert np.allclose(stays.get_window_extent().get_points(), before.get_points())


def test_labels_still_clear_each_other_before_they_clear_the_data():
    """Three labels on one point between two finding lines closer than a label's width:
    no place clears the data, so each clears the labels (none dropped, none on another)."""
    from hazard.canvas import subplots
    from hazard.outputs.figure_index import mark
    from hazard.outputs.label_place import place_labels

    fig, ax = subplots(figsize=(3, 3))
    ax.set_xlim(0, 100)
    ax.set_ylim(0, 100)
    for x in np.arange(5.0, 100.0, 10.0):
        mark(ax, [f"tracks[{int(x)}]"], "track", [[x, 0], [x, 100]], "line")
    for k in range(3):
        ax.annotate(f"label {k} of the point", (48.0, 50.0), xytext=(0, 0), textcoords="offset points", fontsize=8)
    fig.canvas.draw()
    place_labels(ax)
    fig.canvas.draw()
    assert len(ax.texts) == 3 and not overlaps(ax) and not outside(ax)


@pytest.mark.parametrize("name", ["range_clearance", pytest.param("mirror_window", marks=pytest.mark.slow)])
def test_no_label_of_the_plan_view_covers_a_hazardous_observer_it_does_not_name(name):
    """In the plan view's panels no label covers the marker of a hazardous observer
    (report.json's observers at or above the MPE, positions from report.json) other than
    near its own point."""
    from hazard.pictures.plan_view import PlanViewDisplay
    from hazard.outputs.report import report_dict
    from matplotlib.text import Annotation

    doc = report_dict(bundled(name))
    xy = np.array([o["position_m"][:2] for o in doc["observers"] if o.get("hazardous")], float)
    assert len(xy)
    fig, axes = PlanViewDisplay.from_result(bundled(name)).plot()
    fig.canvas.draw()
    for ax in axes:
        pts = ax.transData.transform(xy)
        f = ax.get_window_extent()
        pts = pts[(pts[:, 0] >= f.x0) & (pts[:, 0] <= f.x1) & (pts[:, 1] >= f.y0) & (pts[:, 1] <= f.y1)]
        for t in ax.texts:
            if isinstance(t, Annotation) and t.xycoords == "data" and t.get_visible() and t._check_xy(fig.canvas.get_renderer()):
                assert _covering(ax, t, pts, t.xy) == 0, (ax.get_title(), t.get_text())


@pytest.mark.parametrize("name", ["mirror_window", pytest.param("airspace", marks=pytest.mark.slow)])
def test_no_two_tick_labels_of_a_panel_touch(name):
    """The panels are narrower now that the pictures print at 6 pt (issue 34 leftover a):
    airspace's elevation x labels ran together ("1000012500"); no two visible tick
    labels of an axis overlap."""
    for ax in _views(name):
        r = ax.figure.canvas.get_renderer()
        for axis, lo, hi in ((ax.xaxis, 0, 2), (ax.yaxis, 1, 3)):  # along the axis: a gap of 2 px at least
            boxes = sorted((t.get_window_extent(r).extents for t in axis.get_ticklabels() if t.get_visible() and t.get_text()),
                           key=lambda b: b[lo])
            for a, b in itertools.pairwise(boxes):
                assert b[lo] - a[hi] >= 2.0, (ax.get_title(), a, b)
