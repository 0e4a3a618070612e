"""Labels that do not cover each other (issue 34: the airspace range panel's labels of the
track, the danger zone's end and the FAA distances were drawn over one another).

:func:`place_labels` takes a panel whose texts are placed (and kept inside the panel,
:func:`hazard.plan_view.keep_texts_inside`) and moves each label that overlaps one placed
before it, or the scale bar, to the nearest free place in the panel - a few box heights
up or down, or a box width aside -, drawing a thin leader line from its point to it, so
that no label hides another and each stays tied to its point. A label with no free place
stays where it was (never dropped). Display coordinates [px] throughout; matplotlib is
already imported by the caller."""

from __future__ import annotations

import numpy as np

__all__ = ["place_labels", "text_boxes"]

PAD_PX = 2.0  # the gap kept between two labels
STEPS = 10  # candidate places: up to this many box heights up or down, with and without a box width aside


def _visible(t, renderer) -> bool:
    if not t.get_visible() or not t.get_text().strip():
        return False
    check = getattr(t, "_check_xy", None)  # an annotation is drawn only when its point is in the panel
    return bool(check(renderer)) if check is not None else True


def _movable(ax, t) -> bool:
    """A label placed at a data point (not a panel-fraction text such as the north arrow's N)."""
    from matplotlib.text import Annotation

    if isinstance(t, Annotation):
        return t.xycoords == "data" and t.anncoords in ("offset points", "data")
    return t.get_transform() == ax.transData


def text_boxes(ax) -> list:
    """(text, [x0, y0, x1, y1] [px]) of every visible text of ``ax`` (labels, ring and
    contour labels, annotations: their text, without an annotation's arrow)."""
    from matplotlib.text import Text

    r = ax.figure.canvas.get_renderer()
    out = []
    for t in ax.texts:
        if _visible(t, r):
            b = Text.get_window_extent(t, r)  # the text's own box (an annotation's arrow is not the label)
            out.append((t, np.array([b.x0, b.y0, b.x1, b.y1])))
    return out


def _hits(box, others) -> bool:
    if not len(others):
        return False
    o = np.asarray(others)
    return bool(np.any((box[0] < o[:, 2] + PAD_PX) & (o[:, 0] < box[2] + PAD_PX) & (box[1] < o[:, 3] + PAD_PX)
                       & (o[:, 1] < box[3] + PAD_PX)))


def _candidates(box) -> np.ndarray:
    """Shifts [px] to try, nearest first."""
    h, w = box[3] - box[1] + PAD_PX, box[2] - box[0] + PAD_PX
    dy = np.arange(-STEPS, STEPS + 1) * h
    dx = np.array([0.0, -0.5 * w, 0.5 * w, -w, w])
    grid = np.stack(np.meshgrid(dx, dy), -1).reshape(-1, 2)
    grid = grid[np.any(grid != 0, axis=1)]
    return grid[np.argsort(np.hypot(grid[:, 0], 1.5 * grid[:, 1]), kind="stable")]


def _shift(ax, t, shift_px) -> None:
    from matplotlib.text import Annotation

    if isinstance(t, Annotation) and t.anncoords == "offset points":
        t.xyann = tuple(np.asarray(t.xyann, float) + shift_px * 72.0 / ax.figure.dpi)
    elif isinstance(t, Annotation):
        t.xyann = tuple(ax.transData.inverted().transform(ax.transData.transform(t.xyann) + shift_px))
    else:
        t.set_position(tuple(ax.transData.inverted().transform(ax.transData.transform(t.get_position()) + shift_px)))


def _leader(ax, t, p, old, box) -> None:
    """A thin line from the label's point ``p`` [px] to the nearest point of its new box
    when that is farther from the point than its ``old`` box was."""
    from matplotlib.text import Annotation

    if isinstance(t, Annotation) and t.arrowprops:
        return  # its arrow already joins it to its point
    q = np.clip(p, box[:2], box[2:])
    if np.hypot(*(q - p)) > np.hypot(*(np.clip(p, old[:2], old[2:]) - p)) + 3.0:
        ax.plot(*ax.transData.inverted().transform(np.array([p, q])).T, c="#777777", lw=0.5, zorder=8)


def place_labels(ax) -> int:
    """Move the labels of ``ax`` that overlap a label placed before them (or the scale
    bar) to the nearest free place inside the panel, with a leader line; call once the
    limits are final. Returns how many were moved."""
    from matplotlib.offsetbox import AnchoredOffsetbox
    from matplotlib.text import Annotation

    r = ax.figure.canvas.get_renderer()
    limits = ax.get_xlim(), ax.get_ylim()  # a leader line never widens the panel
    f = ax.get_window_extent(r)
    frame = np.array([f.x0 + PAD_PX, f.y0 + PAD_PX, f.x1 - PAD_PX, f.y1 - PAD_PX])
    placed = [np.array([b.x0, b.y0, b.x1, b.y1]) for b in (a.get_window_extent(r) for a in ax.artists
                                                           if isinstance(a, AnchoredOffsetbox))]
    boxes = text_boxes(ax)
    fixed = [b for t, b in boxes if not _movable(ax, t)]
    placed += fixed
    moved = 0
    for t, box in boxes:
        if not _movable(ax, t):
            continue
        if not _hits(box, placed):
            placed.append(box)
            continue
        point = ax.transData.transform(t.xy if isinstance(t, Annotation) else t.get_position())
        for s in _candidates(box):
            nb = box + np.array([s[0], s[1], s[0], s[1]])
            if nb[0] >= frame[0] and nb[1] >= frame[1] and nb[2] <= frame[2] and nb[3] <= frame[3] and not _hits(nb, placed):
                _shift(ax, t, s)
                _leader(ax, t, point, box, nb)
                box, moved = nb, moved + 1
                break
        placed.append(box)
    ax.set_xlim(*limits[0])
    ax.set_ylim(*limits[1])
    return moved
