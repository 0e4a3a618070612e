"""Every PNG of a run (issue 34 item 6): not blank, nothing cut at an edge, every text
and legend inside the picture, the texts a panel places on its data inside that panel,
and drawn in bounded time. Checked in the PNG's pixels and in the figure's rendered
text extents (matplotlib's window extents against the saved area)."""

from __future__ import annotations

import io
import time

import numpy as np
import pytest

import scenes
from tests._bundled import bundled

pytest.importorskip("matplotlib")

FAST = ["mirror_window"]
SLOW = sorted(set(scenes.examples()) - set(FAST))
DPI = 110  # the pictures' resolution (hazard.pictures.plots.DisplayBase)
RENDER_S = 120.0  # every picture of one example (run_figures), on a 2-core machine shared by five runs (mirror_window: 4 to 19 s)


def _pixels(data: bytes) -> np.ndarray:
    import matplotlib.image as mpimg

    return (mpimg.imread(io.BytesIO(data))[..., :3] * 255).round().astype(int)


def png_problems(data: bytes) -> list:
    """Why a PNG is not a whole picture: blank, or something touching its edge (cut)."""
    img = _pixels(data)
    out = []
    ink = img.min(axis=-1) < 200
    packed = (img[::3, ::3, 0] << 16) | (img[::3, ::3, 1] << 8) | img[::3, ::3, 2]  # colours as one integer each
    if ink.mean() < 0.005 or len(np.unique(packed)) < 6:
        out.append(f"blank: {100 * ink.mean():.2g} % ink")
    border = np.concatenate([img[:2].reshape(-1, 3), img[-2:].reshape(-1, 3), img[:, :2].reshape(-1, 3), img[:, -2:].reshape(-1, 3)])
    if border.min() < 235:
        out.append("something runs off the picture's edge (a non-white border pixel)")
    return out


def _inside(box, frame, tol_px=1.5) -> bool:
    return (box.x0 >= frame.x0 - tol_px and box.x1 <= frame.x1 + tol_px and box.y0 >= frame.y0 - tol_px
            and box.y1 <= frame.y1 + tol_px)


def _drawn(t, renderer) -> bool:
    """Whether matplotlib draws text ``t``: visible, not empty, and an annotation only
    when its point is in its panel (or it is not clipped)."""
    if not t.get_visible() or not t.get_text().strip():
        return False
    check = getattr(t, "_check_xy", None)  # matplotlib.text.Annotation: its clipping rule
    return bool(check(renderer)) if check is not None else True


def figure_problems(fig) -> list:
    """Texts and legends of ``fig`` outside the area savefig(bbox_inches="tight") keeps,
    and texts placed on a panel's data that leave the panel."""
    from matplotlib.text import Text
    from matplotlib.transforms import Bbox

    fig.canvas.draw()
    r = fig.canvas.get_renderer()
    saved = fig.get_tightbbox(r).padded(0.1)  # inches, as savefig pads it
    saved = Bbox(saved.get_points() * fig.dpi)
    texts = list(fig.texts)  # every text but tick labels (matplotlib draws those in view only; the PNG's border check sees them)
    for ax in fig.axes:
        texts += list(ax.texts) + [ax.title, ax._left_title, ax._right_title, ax.xaxis.label, ax.yaxis.label]
        texts += [] if ax.get_legend() is None else list(ax.get_legend().get_texts())
    texts += [t for leg in fig.legends for t in leg.get_texts()]
    texts = [t for t in texts if _drawn(t, r)]
    out = []
    for t in texts:
        if isinstance(t, Text):
            if not _inside(t.get_window_extent(r), saved):
                out.append(f"text {t.get_text()!r} outside the picture")
    legends = list(fig.legends) + [ax.get_legend() for ax in fig.axes if ax.get_legend() is not None]
    out += [f"legend outside the picture: {leg.get_window_extent(r)}" for leg in legends if not _inside(leg.get_window_extent(r), saved)]
    for ax in fig.axes:
        frame = ax.get_window_extent(r)
        for t in ax.texts:
            anchored = t.get_transform() == ax.transData or getattr(t, "xycoords", None) == "data" and not getattr(t, "arrow_patch", None)
            if anchored and _drawn(t, r) and not _inside(t.get_window_extent(r), frame):
                out.append(f"text {t.get_text()!r} of panel {ax.get_title()!r} runs out of the panel")
    return out


def _checked(result, monkeypatch):
    """run_figures of ``result`` with each figure kept for inspection (in drawing order)."""
    from hazard.outputs import figure_index
    from hazard.pictures.figures import run_figures

    figs = []
    entry = figure_index.figure_entry
    monkeypatch.setattr(figure_index, "figure_entry", lambda fig, view, **kw: (figs.append(fig), entry(fig, view, **kw))[1])
    t = time.perf_counter()
    out = run_figures(result)
    return out, figs, time.perf_counter() - t


@pytest.mark.slow  # 3 to 20 s on a loaded machine; the default suite checks the PNGs of tests/hazard/test_plan_view.py's run
def test_the_plan_and_elevation_views_are_whole_and_keep_their_text_inside():
    from hazard.pictures.elevation_view import ElevationViewDisplay
    from hazard.pictures.plan_view import PlanViewDisplay

    res = bundled("mirror_window")
    for display in (PlanViewDisplay, ElevationViewDisplay):
        fig, _ = display.from_result(res).plot()
        buf = io.BytesIO()
        fig.savefig(buf, format="png", dpi=DPI, bbox_inches="tight")
        assert not png_problems(buf.getvalue()) + figure_problems(fig)


@pytest.mark.slow  # every picture of every example, the time plots' histories recomputed (mirror_window: 20 s on a loaded machine)
@pytest.mark.parametrize("name", FAST + SLOW)
def test_every_picture_is_whole_and_keeps_its_text_inside(name, monkeypatch):
    out, figs, seconds = _checked(bundled(name), monkeypatch)
    pngs = [n for n in out if n.endswith(".png")]
    assert len(pngs) == len(figs) >= 2 and {"plan.png", "elevation.png"} <= set(pngs)
    problems = {n: png_problems(out[n]) + figure_problems(f) for n, f in zip(pngs, figs)}
    assert not {n: p for n, p in problems.items() if p}, problems
    assert seconds < RENDER_S, f"{seconds:.1f} s to draw the pictures of {name}"


def test_the_checks_see_a_blank_picture_a_cut_text_and_a_label_off_its_panel():
    from hazard.canvas import subplots

    from hazard.canvas import new_figure

    buf = io.BytesIO()
    new_figure((3, 2)).savefig(buf, format="png", dpi=DPI)
    assert any(p.startswith("blank") for p in png_problems(buf.getvalue()))
    fig, ax = subplots(figsize=(3, 2))
    ax.plot([0, 1], [0, 1])
    ax.set_title("panel")
    fig.text(-0.2, 0.5, "cut at the left edge", fontsize=12)  # savefig without bbox_inches="tight" cuts it
    ax.text(0.95, 0.5, "runs out of the panel", fontsize=12)
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=DPI)
    assert "something runs off the picture's edge (a non-white border pixel)" in png_problems(buf.getvalue())
    assert "text 'runs out of the panel' of panel 'panel' runs out of the panel" in figure_problems(fig)
