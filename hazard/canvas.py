"""Figures that need no global matplotlib backend: a :class:`matplotlib.figure.Figure`
with its own Agg canvas, outside pyplot's figure manager. The library draws only on
these, so drawing never switches a user's backend (``matplotlib.use``), never opens a
window, and leaves nothing in ``pyplot``'s list of open figures (nothing to close).
matplotlib is imported when a figure is made, never by ``import hazard``."""

from __future__ import annotations

__all__ = ["new_figure", "subplots"]


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
