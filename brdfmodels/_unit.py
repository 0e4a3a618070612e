"""Deprecated alias of :mod:`brdfmodels.output_sets` (output folders and file sets
replaced as one unit), kept for one release so that code written against it still runs;
import :mod:`brdfmodels.output_sets`."""

from .output_sets import *  # noqa: F401,F403
from .output_sets import __all__  # noqa: F401
