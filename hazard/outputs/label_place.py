"""Labels that do not cover each other nor the findings drawn (issue 34: the airspace range
panel's labels of the track, the danger zone's end and the FAA distances were drawn over
one another; range_clearance's terrain label over the danger zone's end).

:func:`place_labels` takes a panel whose texts are placed (and kept inside the panel,
:func:`hazard.pictures.plan_view.keep_texts_inside`) and moves each label that overlaps one placed
before it, the scale bar, or a finding drawn in the panel (the points, lines and
outlines noted by :func:`hazard.outputs.figure_index.mark`: hazardous observers, zones, beams,
lobes, tracks; sampled every ``STEP_PX``) to the nearest free place in the panel - a few
box heights up or down, or a box width aside -, drawing a thin leader line from its point
to it, so that no label hides another or a finding and each stays tied to its point.
Near its own point (``OWN_PX``) a label may touch the data it names; a label is moved
off data by at most ``DATA_STEPS`` box heights (farther it would seem to name another
place). Where no place near is free of both, a label overlapping another goes to the
nearest place free of labels (it may cover data there), and a label covering only data
stays; none is dropped. Display
coordinates [px] throughout; matplotlib is already imported by the caller."""

from __future__ import annotations

import numpy as np

__all__ = ["place_labels", "text_boxes", "data_points"]

PAD_PX = 2.0  # the gap kept between two labels
DATA_PAD_PX = 3.0  # the gap kept between a label and a finding's drawn point or line
STEP_PX = 3.0  # spacing of the points sampled along a finding's drawn lines and outlines
OWN_PX = 14.0  # within this of its own point a label may cover data (its marker, the line it names)
DATA_STEPS = 3  # a label covering only data moves at most this many box heights (farther it would name the wrong place)
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


def _in_frame(p, d, frame) -> tuple:
    """(t0, t1): the part of each segment p + t d (t in [0, 1]) inside ``frame`` (x0, y0,
    x1, y1) (t0 > t1 when it misses it)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        a = (frame[:2] - p) / d
        b = (frame[2:] - p) / d
    lo = np.where(d == 0, np.where((p >= frame[:2]) & (p <= frame[2:]), -np.inf, np.inf), np.minimum(a, b))
    hi = np.where(d == 0, np.where((p >= frame[:2]) & (p <= frame[2:]), np.inf, -np.inf), np.maximum(a, b))
    return np.maximum(lo.max(axis=1), 0.0), np.minimum(hi.min(axis=1), 1.0)


def _sampled(p, frame) -> np.ndarray:
    """Points every ``STEP_PX`` along the polyline ``p`` (K, 2) [px], inside ``frame``."""
    d = np.diff(p, axis=0)
    t0, t1 = _in_frame(p[:-1], d, frame)
    ok = t1 >= t0
    p0, d, t0, t1 = p[:-1][ok], d[ok], t0[ok], t1[ok]
    n = np.ceil(np.hypot(*d.T) * (t1 - t0) / STEP_PX).astype(int) + 1
    seg = np.repeat(np.arange(len(n)), n)
    k = np.arange(n.sum()) - np.repeat(np.cumsum(n) - n, n)
    t = t0[seg] + (t1 - t0)[seg] * k / np.maximum(n[seg] - 1, 1)
    return p0[seg] + d[seg] * t[:, None]


def data_points(ax) -> np.ndarray:
    """(N, 2) [px]: the findings drawn in ``ax`` (:func:`hazard.outputs.figure_index.drawn_findings`)
    inside the panel, as their points and as points every ``STEP_PX`` along their lines
    and outlines."""
    from hazard.outputs.figure_index import drawn_findings

    f = ax.get_window_extent(ax.figure.canvas.get_renderer())
    frame = np.array([f.x0, f.y0, f.x1, f.y1])
    out = [np.zeros((0, 2))]
    for kind, xy in drawn_findings(ax):
        p = ax.transData.transform(xy[np.all(np.isfinite(xy), axis=1)])
        if kind == "polygon" and len(p) >= 3:
            p = np.vstack([p, p[:1]])
        out.append(_sampled(p, frame) if kind in ("line", "polygon") and len(p) >= 2 else p)
    p = np.vstack(out)
    return p[np.all((p >= frame[:2]) & (p <= frame[2:]), axis=1)]


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


def _covered(boxes, pts) -> np.ndarray:
    """How many of the points ``pts`` (N, 2) each of ``boxes`` (C, 4) [px] covers (with ``DATA_PAD_PX``)."""
    if not len(pts):
        return np.zeros(len(boxes), int)
    x, y = pts[:, 0][None, :], pts[:, 1][None, :]
    b = boxes[:, :, None]
    return np.sum((x > b[:, 0] - DATA_PAD_PX) & (x < b[:, 2] + DATA_PAD_PX) & (y > b[:, 1] - DATA_PAD_PX) & (y < b[:, 3] + DATA_PAD_PX), axis=1)


def _free_shift(box, placed, data, frame):
    """The shift [px] for ``box``: the nearest putting it inside ``frame`` clear of the
    ``placed`` boxes and of the ``data`` points within ``DATA_STEPS`` box heights; else,
    when it overlaps a placed box, the nearest clear of the boxes (farther from its point
    only to clear a label); None: stay."""
    shifts = _candidates(box)
    boxes = box[None, :] + np.hstack([shifts, shifts])
    ok = np.all(boxes[:, :2] >= frame[:2], axis=1) & np.all(boxes[:, 2:] <= frame[2:], axis=1)
    ok &= np.array([not _hits(b, placed) for b in boxes])
    count = _covered(boxes, data)
    clear = np.flatnonzero(ok & (count == 0) & (np.abs(shifts[:, 1]) <= DATA_STEPS * (box[3] - box[1] + PAD_PX) + 0.5))
    if len(clear):
        return shifts[clear[0]]
    if _hits(box, placed) and ok.any():
        return shifts[np.flatnonzero(ok)[0]]
    return None


def place_labels(ax) -> int:
    """Move the labels of ``ax`` that overlap a label placed before them, the scale bar
    or a finding drawn in the panel (:func:`data_points`) to the nearest free place
    inside the panel, with a leader line; call once the limits are final. Returns how
    many were moved."""
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
    pts = data_points(ax)
    moved = 0
    for t, box in boxes:
        if not _movable(ax, t):
            continue
        point = ax.transData.transform(t.xy if isinstance(t, Annotation) else t.get_position())
        data = pts[np.hypot(*(pts - point).T) > OWN_PX]  # its own marker and line may be touched
        if not _hits(box, placed) and not _covered(box[None, :], data)[0]:
            placed.append(box)
            continue
        s = _free_shift(box, placed, data, frame)
        if s is not None:
            nb = box + np.array([s[0], s[1], s[0], s[1]])
            _shift(ax, t, s)
            _leader(ax, t, point, box, nb)
            box, moved = nb, moved + 1
        placed.append(box)
    ax.set_xlim(*limits[0])
    ax.set_ylim(*limits[1])
    return moved
