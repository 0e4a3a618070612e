"""Per-draw arrays of a risk run read back by blocks of observer columns, in bounded memory.

A chunk of draws gives (draws, M) arrays (the observers' exposure ratios; the
sensitivity sample's A and C_i sets). The statistics of an observer need every draw of
its column (exact quantiles), not every observer at once: :class:`ColumnStore` copies the
chunks, in chunk order, into one scratch file per array laid out block by block (block b
holds columns ``j0:j1`` of every draw as a C-ordered (draws, j1 - j0) array), and
:meth:`ColumnStore.blocks` reads one block at a time. The memory held is one chunk while
copying and one block while reading (``BLOCK_VALUES`` values, at least two columns),
whatever the number of observers.

Bit-identical to the whole-array statistics: numpy reduces axis 0 of a C-ordered array
of two or more columns row by row (the same sums in the same order in any column block);
a single column would be summed pairwise, so a block never has one column unless the
array has only one.
"""

from __future__ import annotations

import itertools
import math
import os
from pathlib import Path

import numpy as np

__all__ = ["BLOCK_VALUES", "ColumnStore", "block_bounds"]

BLOCK_VALUES = 2_000_000  # draws x columns read at once (16 MB of float64; ~12 such temporaries in the statistics)


def block_bounds(n_rows: int, n_cols: int, block_values: int = BLOCK_VALUES) -> list:
    """(j0, j1) column ranges covering ``n_cols`` columns, each about ``block_values /
    n_rows`` wide and never a single column unless ``n_cols`` is 1 (see the module notes)."""
    if n_cols <= 0:
        return []
    want = max(1, math.ceil(n_cols / max(1, block_values // max(n_rows, 1))))
    n_blocks = max(1, min(want, n_cols // 2))
    edges = np.linspace(0, n_cols, n_blocks + 1).round().astype(int)
    return [(int(a), int(b)) for a, b in itertools.pairwise(edges.tolist())]


class ColumnStore:
    """Named (rows, M) float64 arrays in scratch files under ``folder``, written by row
    chunks and read by column blocks (:func:`block_bounds`)."""

    def __init__(self, folder, rows: dict, n_cols: int, block_values: int = BLOCK_VALUES):
        self.folder, self.rows, self.n_cols = Path(folder), dict(rows), int(n_cols)
        self.bounds = {k: block_bounds(n, self.n_cols, block_values) for k, n in self.rows.items()}
        self.filled = {k: 0 for k in self.rows}
        self._files = {}
        for k in self.rows:
            path = self.folder / f"columns-{k}.f64"
            self._files[k] = open(path, "w+b")
            self._files[k].truncate(8 * self.rows[k] * self.n_cols)

    def append(self, key: str, values: np.ndarray) -> None:
        """The next rows of array ``key`` ((c, M), in draw order)."""
        v = np.asarray(values, float)
        if v.ndim != 2 or v.shape[1] != self.n_cols:
            raise ValueError(f"{key}: expected ({self.n_cols} columns), got shape {v.shape}")
        a, n, fd = self.filled[key], self.rows[key], self._files[key].fileno()
        if a + len(v) > n:
            raise ValueError(f"{key}: {a + len(v)} rows written, {n} expected")
        for j0, j1 in self.bounds[key]:
            os.pwrite(fd, np.ascontiguousarray(v[:, j0:j1]).tobytes(), 8 * (n * j0 + a * (j1 - j0)))
        self.filled[key] = a + len(v)

    def blocks(self, key: str):
        """(j0, j1, (rows, j1 - j0) array) of every column block of ``key``, in order."""
        n, f = self.rows[key], self._files[key]
        if self.filled[key] != n:
            raise ValueError(f"{key}: {self.filled[key]} of {n} rows written")
        for j0, j1 in self.bounds[key]:
            f.seek(8 * n * j0)
            yield j0, j1, np.fromfile(f, dtype=np.float64, count=n * (j1 - j0)).reshape(n, j1 - j0)

    def block(self, key: str, j0: int, j1: int) -> np.ndarray:
        """Block ``(j0, j1)`` of ``key`` (one of its :func:`block_bounds`)."""
        n, f = self.rows[key], self._files[key]
        f.seek(8 * n * j0)
        return np.fromfile(f, dtype=np.float64, count=n * (j1 - j0)).reshape(n, j1 - j0)

    def close(self) -> None:
        """Close and delete the scratch files."""
        for k, f in self._files.items():
            f.close()
            (self.folder / f"columns-{k}.f64").unlink(missing_ok=True)
        self._files = {}

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
