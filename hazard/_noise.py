"""Dependency noise on the terminal, caught by the command line (never at import).

The ``hazard`` command's stderr carries only its own lines (see :data:`OWN_LINE`): progress
and stage lines, warnings and errors, each starting ``hazard``. What dependencies print
there that a user cannot act on is handled for the duration of one command
(:func:`quiet_dependencies`, entered by :func:`hazard.cli.main` when it runs as the
command, ``main()`` without arguments: the console script and ``python -m hazard``; a call
``main(argv)`` from Python leaves warnings and loggers to the caller; the library changes
no global state at import):

* Python warnings raised outside this project's packages (numpy, pyproj, rasterio, ...)
  become one plain line each, ``hazard: warning: <package> <Category>: <message>`` (the
  first of each kind; never dropped: a numerical warning may matter);
* Dask's cluster chatter (``distributed`` loggers below ERROR: a nanny "killing" a worker
  that did not stop within its grace time at the end of a run, closed comms) is not shown;
  the workers of the embedded cluster start with the same level
  (:func:`hazard.drivers.runner.local_cluster`);
* VTK's own log on stderr (``bad X server connection`` with raw terminal escape codes,
  from an off-screen render without a display) is turned off during ``hazard render``;
  a render that really fails still raises, and says so in the one error line.
"""

from __future__ import annotations

import contextlib
import logging
import os
import re
import warnings

__all__ = ["quiet_dependencies", "OWN_LINE"]

# a line the hazard command writes on stderr: "hazard: ...", "hazard <verb>: ...", or a
# progress bar's redraw (only on a terminal)
OWN_LINE = re.compile(r"^hazard( [a-z]+)?: ")
_OWN_PACKAGES = ("hazard", "scenes", "brdfmodels")
_DASK_LOGGERS = ("distributed",)


def _package_of(filename: str) -> str:
    """The top-level package a warning's file belongs to ('' if it is not a package's)."""
    parts = os.path.normpath(str(filename)).split(os.sep)
    for marker in ("site-packages", "dist-packages"):
        if marker in parts:
            i = parts.index(marker)
            return parts[i + 1].split(".")[0] if i + 1 < len(parts) else ""
    for own in _OWN_PACKAGES:
        if own in parts[:-1]:
            return own
    return parts[-1].rsplit(".", 1)[0] if parts else ""


@contextlib.contextmanager
def _warnings_as_lines(err):
    seen = set()

    def show(message, category, filename, lineno, file=None, line=None):
        text = " ".join(str(message).split())
        pkg = _package_of(filename)
        key = (pkg, category.__name__, text[:120])
        if key in seen:
            return
        seen.add(key)
        who = "" if pkg in _OWN_PACKAGES else f"{pkg} "
        err.write(f"hazard: warning: {who}{category.__name__}: {text[:300]}\n")

    with warnings.catch_warnings():
        warnings.showwarning = show
        yield


@contextlib.contextmanager
def _dask_quiet(active: bool):
    if not active:
        yield
        return
    try:
        import distributed  # noqa: F401 - its import sets its loggers' levels; ours must come after
    except ImportError:
        yield
        return
    loggers = [logging.getLogger(n) for n in _DASK_LOGGERS]
    levels = [lg.level for lg in loggers]
    for lg in loggers:
        lg.setLevel(logging.ERROR)
    try:
        yield
    finally:
        for lg, lv in zip(loggers, levels):
            lg.setLevel(lv)


@contextlib.contextmanager
def _vtk_quiet(active: bool):
    if not active:
        yield
        return
    try:
        from vtkmodules.vtkCommonCore import vtkLogger, vtkObject
    except ImportError:
        yield
        return
    # VTK has no getter of the stderr level: the current cutoff (stderr's unless a log file
    # asks for more) is what is put back
    before = vtkLogger.GetCurrentVerbosityCutoff(), vtkObject.GetGlobalWarningDisplay()
    vtkLogger.SetStderrVerbosity(vtkLogger.VERBOSITY_OFF)
    vtkObject.GlobalWarningDisplayOff()
    try:
        yield
    finally:
        vtkLogger.SetStderrVerbosity(vtkLogger.ConvertToVerbosity(int(before[0])))
        vtkObject.SetGlobalWarningDisplay(before[1])


@contextlib.contextmanager
def quiet_dependencies(err, verb: str, serial: bool = False):
    """For one ``hazard`` command: dependency warnings as one plain line each on ``err``,
    Dask's cluster chatter (study, risk on Dask) and VTK's log (render) off (module notes)."""
    with _warnings_as_lines(err), _dask_quiet(verb in ("study", "risk") and not serial), _vtk_quiet(verb == "render"):
        yield
