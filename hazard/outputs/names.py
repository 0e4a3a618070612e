"""Names of output files."""

from __future__ import annotations

import re


def file_part(name) -> str:
    """``name`` as part of a file name: runs of other characters than letters, digits,
    ``.``, ``-`` and ``_`` become one ``_`` (``shell-20m:crossing[0]`` ->
    ``shell-20m_crossing_0``)."""
    return re.sub(r"[^A-Za-z0-9.-]+", "_", str(name)).strip("_.") or "unnamed"
