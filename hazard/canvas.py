"""Figures that need no global matplotlib backend: a :class:`matplotlib.figure.Figure`
with its own Agg canvas, outside pyplot's figure manager. The library draws only on
these, so drawing never switches a user's backend (``matplotlib.use``), never opens a
window, and leaves nothing in ``pyplot``'s list of open figures (nothing to close).
matplotlib is imported when a figure is made, never by ``import hazard``."""

from __future__ import annotations

__all__ = ["new_figure", "subplots", "smallest_text_px", "PRINT_MIN_PT", "PRINTED_WIDTH_IN"]

PRINT_MIN_PT = 6.0  # the smallest text of a picture in the printed report [pt] (issue 34: legends printed at 3.4 pt)
# the width [in] a picture of the report is printed at: the content box of an A4 page of
# hazard/templates/_style.css.j2 ("page": portrait, 12 mm margins; "wide": landscape, 14 mm margins)
PRINTED_WIDTH_IN = {"page": (210.0 - 2 * 12.0) / 25.4, "wide": (297.0 - 2 * 14.0) / 25.4}


def new_figure(figsize, dpi=None, **kw):
    """A figure ``figsize`` (width, height) [in] at ``dpi`` [pixels/in] (matplotlib's
    default when None) on an Agg canvas; ``kw`` go to :class:`matplotlib.figure.Figure`.

    ``fig.savefig`` writes files and ``fig.canvas.draw()`` renders (text extents) with no
    backend selected; pyplot's state is not touched."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=figsize, dpi=dpi, **kw)
    FigureCanvasAgg(fig)
    return fig


def subplots(nrows=1, ncols=1, *, figsize, **kw) -> tuple:
    """(figure, axes) as ``pyplot.subplots`` returns them, on :func:`new_figure`; ``kw``
    go to :meth:`matplotlib.figure.Figure.subplots` (``squeeze``, ``sharex``, ...)."""
    fig = new_figure(figsize)
    return fig, fig.subplots(nrows, ncols, **kw)


def smallest_text_px(fig, dpi) -> float:
    """The height [px] of the smallest visible text of ``fig`` (titles, labels, tick and
    legend texts, annotations) in its picture saved at ``dpi``: its font size [pt] x
    dpi / 72. The printed size [pt] is this x the printed width / the picture's width [px]
    x 72; nan when the figure shows no text."""
    from matplotlib.text import Text

    fig.canvas.draw()  # the tick labels exist once drawn
    sizes = [t.get_fontsize() for t in fig.findobj(Text) if t.get_visible() and t.get_text().strip()
             and (t.axes is None or t.axes.get_visible())]
    return float(min(sizes) * dpi / 72.0) if sizes else float("nan")
