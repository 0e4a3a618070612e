"""The command line's own process settings: headless matplotlib and pyvista.

The library never changes global state (its figures have their own Agg canvas,
:mod:`hazard.canvas`; its pyvista plotters are made with ``off_screen=True``). The CLI
still makes its process headless, for anything drawn by a library it calls and for the
Dask worker processes it starts (they inherit the environment):

* matplotlib: ``MPLBACKEND=Agg`` (read at its import; ``python -m hazard`` and the
  ``hazard`` script import no matplotlib before the command runs). A matplotlib imported
  already (``main`` called in a Python session) keeps the session's backend: the library
  needs none;
* pyvista: ``PYVISTA_OFF_SCREEN=true`` (read at its import), and ``pyvista.OFF_SCREEN``
  when it is imported already.

:func:`headless` restores the environment variables and ``pyvista.OFF_SCREEN`` when the
command returns, so that ``hazard.cli.main`` called in a Python session leaves them as
they were; a matplotlib imported during the command keeps the Agg backend it started
with (matplotlib reads ``MPLBACKEND`` once, at import).
"""

from __future__ import annotations

import contextlib
import os
import sys

__all__ = ["headless"]

_ENV = {"MPLBACKEND": "Agg", "PYVISTA_OFF_SCREEN": "true"}


@contextlib.contextmanager
def headless():
    """Within ``with``: matplotlib's backend Agg and pyvista off-screen for this process
    (and the processes it starts); the environment and ``pyvista.OFF_SCREEN`` restored
    after."""
    old_env = {k: os.environ.get(k) for k in _ENV}
    pv = sys.modules.get("pyvista")
    old_off = None if pv is None else pv.OFF_SCREEN
    os.environ.update(_ENV)
    if pv is not None:
        pv.OFF_SCREEN = True
    try:
        yield
    finally:
        for k, v in old_env.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v
        pv = sys.modules.get("pyvista")
        if pv is not None:  # as it was, or as its import would have read the old environment
            pv.OFF_SCREEN = old_off if old_off is not None else (old_env["PYVISTA_OFF_SCREEN"] or "false").lower() == "true"
