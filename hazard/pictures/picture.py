"""One picture from a 3-D render: the view with a title strip above it and its legend
beside it, composed as pixel arrays so that nothing is ever cut at an edge (the legend
panel is as wide as matplotlib measures the legend to be) and a test knows exactly where
the scene and the legend are. matplotlib is imported when a picture is composed."""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np

__all__ = ["compose", "write_png"]

DPI = 100
MARGIN_PX = 12


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


def legend_panel(entries, height_px) -> np.ndarray:
    """The legend of ``entries`` (label, colour, "patch" | "line" | "marker") on a white
    panel ``height_px`` high, as wide as the legend measures (plus margins)."""
    from hazard.canvas import new_figure

    handles = [_handle(*e) for e in entries]
    fig = new_figure((4.0, height_px / DPI), DPI)
    leg = fig.legend(handles=handles, loc="upper left", bbox_to_anchor=(0.0, 1.0), frameon=True, fontsize=10,
                     borderaxespad=0.5, title="legend", title_fontsize=10)
    fig.canvas.draw()
    box = leg.get_window_extent()
    width_px = int(np.ceil(box.width)) + 2 * MARGIN_PX
    if box.height > height_px - MARGIN_PX:
        raise ValueError(f"legend of {len(entries)} entries is {box.height:.0f} px high; the picture is {height_px} px")
    fig.set_size_inches(width_px / DPI, height_px / DPI)
    leg.set_bbox_to_anchor((MARGIN_PX / width_px, 1.0 - MARGIN_PX / height_px))
    return _figure_pixels(fig)


def title_strip(lines, width_px) -> np.ndarray:
    """``lines`` of text, the first bold, on a white strip ``width_px`` wide."""
    from hazard.canvas import new_figure

    line_px = 22
    fig = new_figure((width_px / DPI, (len(lines) * line_px + MARGIN_PX) / DPI), DPI)
    for i, text in enumerate(lines):
        fig.text(MARGIN_PX / width_px, 1.0 - (MARGIN_PX / 2 + (i + 0.5) * line_px) / (len(lines) * line_px + MARGIN_PX), text,
                 fontsize=13 if i == 0 else 10, fontweight="bold" if i == 0 else "normal", va="center", wrap=True)
    return _figure_pixels(fig)


def compose(scene_rgb, legend_entries, title_lines) -> tuple:
    """(picture (H, W, 3) uint8, layout): the title strip on top, the scene below on the
    left and the legend panel on its right. ``layout`` gives ``scene`` and ``legend`` as
    (row0, row1, col0, col1) [px] in the picture."""
    scene = np.asarray(scene_rgb)[..., :3].astype(np.uint8)
    h, w = scene.shape[:2]
    legend = legend_panel(legend_entries, h) if legend_entries else np.full((h, 1, 3), 255, np.uint8)
    body = np.hstack([scene, legend])
    strip = title_strip(title_lines, body.shape[1])
    picture = np.vstack([strip, body])
    top = strip.shape[0]
    return picture, {"scene": (top, top + h, 0, w), "legend": (top, top + h, w, w + legend.shape[1])}


def write_png(picture, path) -> Path:
    """Write the picture through a temporary beside ``path``, then rename."""
    import matplotlib.image as mpimg

    from brdfmodels.fileio import atomic_write

    return atomic_write(Path(path), lambda tmp: mpimg.imsave(tmp, picture, format="png"), keep_suffix=True)
