"""Progress bars for steps that can take a while: drawn on stderr only when it is a
terminal (tqdm; a plain bar if tqdm is missing), turned off with :func:`progress_to`."""

from __future__ import annotations

import contextvars
import sys
from contextlib import contextmanager

__all__ = ["progress_to", "progress_stream", "terminal_bar", "progress_callback"]


_OFF = object()
_PROGRESS_STREAM = contextvars.ContextVar("hazard_progress_stream", default=None)


@contextmanager
def progress_to(stream):
    """Draw the progress bars of the work done inside on ``stream`` (None: no bars).

    Without it bars go to ``sys.stderr``. Either way a bar is drawn only when its stream
    is a terminal; the command line uses this for ``--quiet`` and for its own stderr.
    """
    token = _PROGRESS_STREAM.set(_OFF if stream is None else stream)
    try:
        yield
    finally:
        _PROGRESS_STREAM.reset(token)


def _is_terminal(stream) -> bool:
    try:
        return bool(stream.isatty())
    except (AttributeError, ValueError, OSError):  # no isatty, or a closed stream
        return False


def progress_stream():
    """The stream progress bars go to now, or None when bars are off (not a terminal, or
    turned off by :func:`progress_to`)."""
    stream = _PROGRESS_STREAM.get()
    if stream is _OFF:
        return None
    stream = sys.stderr if stream is None else stream
    return stream if _is_terminal(stream) else None


class _NoBar:
    """The bar when bars are off: counts, draws nothing."""

    def __init__(self, total, initial=0):
        self.total, self.n = total, initial

    def update(self, n=1):
        self.n += n

    def set_description(self, desc):
        pass

    def set_postfix_str(self, text):
        pass

    def close(self):
        pass

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


class _TextBar(_NoBar):
    """``desc [#####.....] 12/40`` redrawn in place, when tqdm is not installed."""

    WIDTH = 30

    def __init__(self, stream, total, desc, leave, initial=0):
        super().__init__(total, initial)
        self.stream, self.desc, self.leave, self.closed = stream, desc, leave, False
        self._draw()

    def _draw(self):
        k = int(self.WIDTH * min(self.n, self.total) / max(self.total, 1))
        self.stream.write(f"\r{self.desc} [{'#' * k}{'.' * (self.WIDTH - k)}] {self.n}/{self.total}\x1b[K")
        self.stream.flush()

    def update(self, n=1):
        super().update(n)
        self._draw()

    def set_description(self, desc):
        self.desc = desc
        self._draw()

    def close(self):
        if not self.closed:
            self.closed = True
            self.stream.write("\n" if self.leave else "\r\x1b[K")
            self.stream.flush()


def terminal_bar(total, desc, *, unit="step", leave=False, initial=0, stream=None):
    """A progress bar for a step that can take more than a few seconds.

    Parameters
    ----------
    total : int
        Steps in all.
    desc : str
        What is counted, shown before the bar.
    unit : str
        Name of one step (tqdm's rate display).
    leave : bool
        Keep the finished bar on screen (else it is erased).
    initial : int
        Steps already done.
    stream : file, optional
        Draw here (when it is a terminal); default: the stream of :func:`progress_to`,
        else ``sys.stderr``.

    Returns
    -------
    object
        With ``update(n=1)``, ``set_description(text)``, ``close()``, ``n`` and ``total``;
        a context manager. A tqdm bar when tqdm is installed, a plain text bar otherwise,
        and a bar that draws nothing unless the stream is a terminal.
    """
    stream = progress_stream() if stream is None else (stream if _is_terminal(stream) else None)
    if stream is None:
        return _NoBar(total, initial)
    try:
        from tqdm import tqdm
    except ImportError:
        return _TextBar(stream, total, desc, leave, initial)
    return tqdm(total=total, desc=desc, unit=unit, leave=leave, initial=initial, file=stream, dynamic_ncols=True)


def progress_callback(desc, *, unit="step", leave=True, stream=None):
    """A ``progress(done, total)`` callback that draws a :func:`terminal_bar`, closed when
    ``done`` reaches ``total`` (for loops that report through a callback)."""
    bar = None

    def show(done, total):
        nonlocal bar
        if bar is None:
            bar = terminal_bar(total, desc, unit=unit, leave=leave, initial=done, stream=stream)
        else:
            bar.update(done - bar.n)
        if done >= total:
            bar.close()

    return show
