"""One picture from a 3-D render: the view with a title strip above it and its legend
beside it, composed as pixel arrays so that nothing is ever cut at an edge (the legend
panel is as wide as matplotlib measures the legend to be) and a test knows exactly where
the scene and the legend are. matplotlib is imported when a picture is composed."""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np

__all__ = ["compose", "write_png", "text_px_min", "LEGEND_PT", "TITLE_PT", "TAG_PX", "WRAP_CHARS"]

DPI = 100
MARGIN_PX = 12
# text sizes [pt at DPI]: a 3-D picture (a 1280 px view and its legend, ~1850 px) prints on a
# landscape A4 page 10.6 in wide (hazard.canvas.PRINTED_WIDTH_IN["wide"]), scaled ~0.57: 12 pt
# prints at 6.8 pt (the 10 pt legend and title lines printed at 5.7 pt, under the 6 pt asked)
LEGEND_PT = 12.0
TITLE_PT = (15.0, 12.0)  # the first title line, the others
TAG_PX = 18  # font size [px] of the tags in a 3-D view (range rings, observer numbers, target names): 7.3 pt printed (they were 11-12 px: 4.7-5.1 pt)
WRAP_CHARS = 60  # a legend line longer than this wraps (a long one widened the picture, and shrank all its print)


def _figure_pixels(fig) -> np.ndarray:
    """The figure as (H, W, 3) uint8, exactly its size in pixels."""
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=DPI)
    import matplotlib.image as mpimg

    buf.seek(0)
    return (mpimg.imread(buf)[..., :3] * 255).round().astype(np.uint8)


def _handle(label, colour, kind):
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch

    if kind == "text":  # a line of the legend without a symbol
        return Line2D([], [], ls="", marker="", label=label)
    if kind == "patch":
        return Patch(facecolor=colour, edgecolor=colour, label=label)
    if kind == "marker":
        return Line2D([], [], ls="", marker="o", ms=8, mfc=colour, mec="k" if colour != "#000000" else colour, label=label)
    return Line2D([], [], color=colour, lw=3, label=label)


def _wrapped(label) -> str:
    import textwrap

    return "\n".join(textwrap.wrap(str(label), WRAP_CHARS, subsequent_indent="  ")) or str(label)


def legend_panel(entries, height_px) -> np.ndarray:
    """The legend of ``entries`` (label, colour, "patch" | "line" | "marker") on a white
    panel at least ``height_px`` high (taller when the legend is: the caller pads the
    view), as wide as the legend measures (plus margins); labels wrapped at
    ``WRAP_CHARS``."""
    from hazard.canvas import new_figure

    handles = [_handle(_wrapped(label), *rest) for label, *rest in entries]
    fig = new_figure((4.0, height_px / DPI), DPI)
    leg = fig.legend(handles=handles, loc="upper left", bbox_to_anchor=(0.0, 1.0), frameon=True, fontsize=LEGEND_PT,
                     borderaxespad=0.5, title="legend", title_fontsize=LEGEND_PT)
    fig.canvas.draw()
    box = leg.get_window_extent()
    width_px = int(np.ceil(box.width)) + 2 * MARGIN_PX
    height_px = max(int(height_px), int(np.ceil(box.height)) + 2 * MARGIN_PX)  # never cut: a taller legend makes a taller panel
    fig.set_size_inches(width_px / DPI, height_px / DPI)
    leg.set_bbox_to_anchor((MARGIN_PX / width_px, 1.0 - MARGIN_PX / height_px))
    return _figure_pixels(fig)


def title_strip(lines, width_px) -> np.ndarray:
    """``lines`` of text, the first bold, on a white strip ``width_px`` wide."""
    from hazard.canvas import new_figure

    line_px = int(np.ceil(1.75 * TITLE_PT[0] * DPI / 72))  # 22 px at the old 13 pt
    fig = new_figure((width_px / DPI, (len(lines) * line_px + MARGIN_PX) / DPI), DPI)
    for i, text in enumerate(lines):
        fig.text(MARGIN_PX / width_px, 1.0 - (MARGIN_PX / 2 + (i + 0.5) * line_px) / (len(lines) * line_px + MARGIN_PX), text,
                 fontsize=TITLE_PT[0] if i == 0 else TITLE_PT[1], fontweight="bold" if i == 0 else "normal", va="center", wrap=True)
    return _figure_pixels(fig)


def compose(scene_rgb, legend_entries, title_lines) -> tuple:
    """(picture (H, W, 3) uint8, layout): the title strip on top, the scene below on the
    left and the legend panel on its right. ``layout`` gives ``scene`` and ``legend`` as
    (row0, row1, col0, col1) [px] in the picture."""
    scene = np.asarray(scene_rgb)[..., :3].astype(np.uint8)
    h, w = scene.shape[:2]
    legend = legend_panel(legend_entries, h) if legend_entries else np.full((h, 1, 3), 255, np.uint8)
    view = np.vstack([scene, np.full((legend.shape[0] - h, w, 3), 255, np.uint8)])  # white below a view shorter than its legend
    body = np.hstack([view, legend])
    strip = title_strip(title_lines, body.shape[1])
    picture = np.vstack([strip, body])
    top = strip.shape[0]
    return picture, {"scene": (top, top + h, 0, w), "legend": (top, top + legend.shape[0], w, w + legend.shape[1])}


def text_px_min(legend_entries, title_lines, tag_px=None) -> float:
    """The height [px] of the smallest text of a picture :func:`compose` makes: the legend
    (``LEGEND_PT``), the title lines (``TITLE_PT``) and the 3-D view's tags (``tag_px``, the
    view's own font size [px]; None: no tags), as figures.json's ``text_px_min``."""
    sizes = ([LEGEND_PT * DPI / 72] if legend_entries else []) + [TITLE_PT[0 if i == 0 else 1] * DPI / 72 for i in range(len(title_lines))]
    return float(min(sizes + ([float(tag_px)] if tag_px is not None else [])))


def write_png(picture, path) -> Path:
    """Write the picture through a temporary beside ``path``, then rename."""
    import matplotlib.image as mpimg

    from brdfmodels.fileio import atomic_write

    return atomic_write(Path(path), lambda tmp: mpimg.imsave(tmp, picture, format="png"), keep_suffix=True)
