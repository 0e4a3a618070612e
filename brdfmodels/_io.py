"""Deprecated alias of :mod:`brdfmodels.fileio` (the public file-I/O layer), kept for one
release so that code written against it still runs; import :mod:`brdfmodels.fileio`."""

from .fileio import *  # noqa: F401,F403
from .fileio import __all__  # noqa: F401
