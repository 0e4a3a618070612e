"""Observer points, generated where they are used.

A scene's observers are rows of one table (group by group, in the file's order). The
points of a grid group are not stored: a grid is ``origin + (iv / (nv - 1)) v + (iu /
(nu - 1)) u`` (row-major, iu fastest), lifted to ``terrain + eye_height_m`` when placed
at eye height, so any rows can be generated from their indices (:meth:`Observers.block`,
:meth:`Observers.take`) at the cost of a few multiply-adds and one bilinear height
lookup per point. The hazard map, the direct beam and the extended-source pass generate
their block of rows inside their threads; a 4e6-point grid never exists as a whole array
unless something asks for :attr:`Observers.positions_m` (the report's table does, at
write time). Explicit points, lines and shells are small and stored.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, field, replace
from typing import Callable

import numpy as np

__all__ = ["Observers", "GroupPoints", "stored", "grid_generator"]

BLOCK = 1 << 18  # rows generated at a time when a whole table is needed (bounded memory)
THREAD_BLOCK = 1 << 16  # rows per block of a per-observer pass run on threads (Observers.map_blocks)
KEEP_ROWS = 1 << 21  # Observers.keep_points keeps a table of at most this many rows (2.1e6 rows: 50 MB)


@dataclass(frozen=True)
class GroupPoints:
    """One group's rows [start, start + count): ``at(local_rows)`` gives their points
    (n, 3), local coordinates [m]; ``stored`` when they are an array held in memory."""

    start: int
    count: int
    at: Callable[[np.ndarray], np.ndarray]
    is_stored: bool = True


def stored(points_m) -> Callable:
    """A generator over an array of points (n, 3)."""
    pts = np.asarray(points_m, float).reshape(-1, 3)
    return lambda rows: pts[rows]


def grid_generator(spec, offset_m, terrain, rise=None) -> Callable:
    """Points of a grid group (:func:`scenes.geometry.observer_points`' grid, by index),
    local coordinates; at ``terrain + eye_height_m`` when the group says so, else raised
    by a site's refraction ``rise(x, y)`` (world [m] -> dz [m], :mod:`scenes.geo`)."""
    nu, nv = spec.counts
    o, u, v = (np.asarray(x, float) for x in (spec.origin_m, spec.u_m, spec.v_m))
    off = np.asarray(offset_m, float)
    eye = spec.eye_height_m

    def at(rows):
        iv, iu = np.divmod(np.asarray(rows, np.int64), nu)
        p = o + (iv / max(nv - 1, 1))[:, None] * v + (iu / max(nu - 1, 1))[:, None] * u  # as observer_points
        if eye is None and rise is not None:
            p[:, 2] += rise(p[:, 0], p[:, 1])
        p -= off
        if eye is not None:
            p[:, 2] = terrain.height_at(p[:, 0], p[:, 1]) + eye
        return p
    return at


@dataclass
class Observers:
    """Every observer point (M rows), local coordinates, with its group and index in the
    group and the viewing optics of each group (``optics[g]``: an OpticsSpec or None for
    the naked eye). ``parts`` generate the points (see the module notes)."""

    parts: tuple
    group: np.ndarray
    index_in_group: np.ndarray
    group_names: tuple
    optics: tuple = ()
    _cache: np.ndarray | None = field(default=None, repr=False, compare=False)  # a memo of the points (not the table's value)

    @classmethod
    def from_points(cls, positions_m, group, index_in_group, group_names, optics=()) -> "Observers":
        """A table held as one array (M, 3)."""
        p = np.asarray(positions_m, float).reshape(-1, 3)
        return cls((GroupPoints(0, len(p), stored(p)),), np.asarray(group), np.asarray(index_in_group), tuple(group_names),
                   tuple(optics), p)

    def __len__(self):
        return len(self.group)

    @property
    def lazy(self) -> bool:
        """Some points are generated, not stored."""
        return any(not g.is_stored for g in self.parts) and self._cache is None

    def take(self, rows) -> np.ndarray:
        """Points (n, 3) of the rows ``rows`` (int array, any order)."""
        rows = np.asarray(rows, np.int64).ravel()
        if self._cache is not None:
            return self._cache[rows]
        out = np.empty((len(rows), 3))
        for g in self.parts:
            sel = np.flatnonzero((rows >= g.start) & (rows < g.start + g.count))
            if len(sel):
                out[sel] = g.at(rows[sel] - g.start)
        return out

    def block(self, a0: int, a1: int) -> np.ndarray:
        """Points (a1 - a0, 3) of rows [a0, a1)."""
        if self._cache is not None:
            return self._cache[a0:a1]
        out = np.empty((a1 - a0, 3))
        for g in self.parts:
            lo, hi = max(a0, g.start), min(a1, g.start + g.count)
            if lo < hi:
                out[lo - a0:hi - a0] = g.at(np.arange(lo - g.start, hi - g.start))
        return out

    def map_blocks(self, fn, size: int = THREAD_BLOCK) -> list:
        """``[fn(a0, a1, points) for each block of rows]``, the blocks side by side on
        threads (:func:`brdfmodels.parallel.map_blocks`), each generating its own points;
        ``fn`` writes disjoint rows of its outputs."""
        from brdfmodels.parallel import map_blocks

        return map_blocks(lambda a0, a1: fn(a0, a1, self.block(a0, a1)), len(self), size)

    def blocks(self, size: int = BLOCK):
        """(a0, a1, points) over the whole table, ``size`` rows at a time."""
        for a0 in range(0, len(self), size):
            a1 = min(a0 + size, len(self))
            yield a0, a1, self.block(a0, a1)

    @property
    def positions_m(self) -> np.ndarray:
        """Every point (M, 3) as one array (generated once, then kept)."""
        if self._cache is None:
            out = np.empty((len(self), 3))
            for a0, a1, p in self.blocks():
                out[a0:a1] = p
            self._cache = out
        return self._cache

    def keep_points(self, max_rows: int | None = None) -> bool:
        """Generate every point once, in blocks on threads, and keep them (as
        :attr:`positions_m` does) when the table has at most ``max_rows`` rows, so that
        the passes over the observers (direct beam, map, subtense) read them instead of
        generating them again; a larger table stays lazy (bounded memory). ``max_rows``
        defaults to :data:`KEEP_ROWS`. Returns True when the points are kept."""
        if self._cache is not None:
            return True
        if len(self) > (KEEP_ROWS if max_rows is None else max_rows):
            return False
        from brdfmodels.parallel import map_blocks

        out = np.empty((len(self), 3))

        def fill(a0, a1):
            out[a0:a1] = self.block(a0, a1)

        map_blocks(fill, len(self), THREAD_BLOCK)
        self._cache = out
        return True

    def group_rows(self, g: int) -> np.ndarray:
        """Rows of group ``g`` in their order within the group."""
        rows = np.flatnonzero(self.group == g)
        return rows[np.argsort(self.index_in_group[rows], kind="stable")]

    def with_group(self, name: str, points_m, optics) -> "Observers":
        """This table with a new group of stored points appended (its rows last)."""
        p = np.asarray(points_m, float).reshape(-1, 3)
        m, k = len(self), len(self.group_names)
        cache = None if self._cache is None else np.vstack([self._cache, p])
        return replace(self, parts=self.parts + (GroupPoints(m, len(p), stored(p)),),
                       group=np.concatenate([self.group, np.full(len(p), k)]),
                       index_in_group=np.concatenate([self.index_in_group, np.arange(len(p))]),
                       group_names=self.group_names + (name,), optics=tuple(self.optics) + (optics,), _cache=cache)

    @functools.cached_property
    def group_sizes(self) -> np.ndarray:
        """Points per group (G,)."""
        return np.bincount(self.group, minlength=len(self.group_names))

    def labels(self) -> list:
        """Point names: the group name for a one-point group, ``group[i]`` otherwise."""
        return self.labels_at(np.arange(len(self)))

    def labels_at(self, rows) -> list:
        """The names (:meth:`labels`) of the rows ``rows`` only (int array, any order)."""
        rows = np.asarray(rows, np.int64).ravel()
        sizes, names = self.group_sizes, self.group_names
        return [names[g] if sizes[g] == 1 else f"{names[g]}[{i}]" for g, i in zip(self.group[rows].tolist(), self.index_in_group[rows].tolist())]
