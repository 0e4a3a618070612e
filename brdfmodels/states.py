"""Piecewise-linear tables over a scalar state, with an explicit policy outside the table.

Used for the coefficient tables of :class:`~brdfmodels.DynamicBRDF` (paper Sec. IV H:
"each of the harmonic coefficients would be separately linearly interpolated"), for
state-dependent scale factors, and for histories (time -> state).
"""

from __future__ import annotations

import numpy as np

from ._checks import finite_array

__all__ = ["StateTable", "interpolation_weights", "EXTRAPOLATION_POLICIES"]

EXTRAPOLATION_POLICIES = ("error", "clamp")


def check_nodes(name: str, nodes) -> np.ndarray:
    """1-d, finite, strictly increasing node array (at least one node)."""
    x = finite_array(name, nodes, ndim=1)
    if x.size == 0:
        raise ValueError(f"{name}: expected at least one value, got an empty array")
    if x.size > 1 and not np.all(np.diff(x) > 0):
        i = int(np.argmin(np.diff(x)))
        raise ValueError(f"{name}: expected strictly increasing values, got {x[i]!r} then {x[i + 1]!r}")
    x = x.copy()
    x.setflags(write=False)
    return x


def check_policy(value: str) -> str:
    if value not in EXTRAPOLATION_POLICIES:
        raise ValueError(f"extrapolation={value!r}: expected one of {list(EXTRAPOLATION_POLICIES)}")
    return value


def check_in_range(query: np.ndarray, nodes: np.ndarray, state_name: str, policy: str) -> np.ndarray:
    """Apply the extrapolation policy: raise naming the range, or clamp into it."""
    q = np.asarray(query, dtype=float)
    if not np.all(np.isfinite(q)):
        raise ValueError(f"{state_name}: state values must be finite, got {q[~np.isfinite(q)].ravel()[0]!r}")
    lo, hi = float(nodes[0]), float(nodes[-1])
    if policy == "error":
        outside = (q < lo) | (q > hi)
        if np.any(outside):
            bad = float(q[outside].ravel()[0])
            raise ValueError(
                f"{state_name}={bad!r} is outside the tabulated range [{lo!r}, {hi!r}]; "
                f"pass extrapolation='clamp' to hold the end states"
            )
        return q
    return np.clip(q, lo, hi)


def cell_fraction(nodes: np.ndarray, x) -> tuple:
    """``(j, frac)``: the lower node of each value's cell (the last cell for values at or
    past the last node) and the value's fraction across it; both 0 for a one-node table."""
    x = np.asarray(x, dtype=float)
    if nodes.size == 1:
        return np.zeros(x.shape, np.intp), np.zeros(x.shape)
    j = np.clip(np.searchsorted(nodes, x, side="right") - 1, 0, nodes.size - 2)
    return j, (x - nodes[j]) / (nodes[j + 1] - nodes[j])


def grid_points(axes) -> np.ndarray:
    """Every node pair (n1 n2, 2) of a two-state grid, the second state varying fastest."""
    g1, g2 = np.meshgrid(*axes, indexing="ij")
    return np.stack([g1.ravel(), g2.ravel()], axis=1)


def interpolation_weights(nodes: np.ndarray, query: np.ndarray) -> np.ndarray:
    """Weights W (T, Q) with ``table.T @ W`` = linear interpolation at ``query`` (in range)."""
    q = np.asarray(query, dtype=float).ravel()
    t = nodes.size
    w = np.zeros((t, q.size))
    if t == 1:
        w[0] = 1.0
        return w
    j, frac = cell_fraction(nodes, q)
    cols = np.arange(q.size)
    w[j, cols] = 1.0 - frac
    w[j + 1, cols] += frac
    return w


def segment_extremes(nodes: np.ndarray, query: np.ndarray) -> np.ndarray:
    """The query states that can hold the maximum, over ``query``, of a function that is
    linear (or monotone of linear) between consecutive ``nodes``: the smallest and the
    largest query state in each node interval, sorted and unique.

    On a closed interval a linear function peaks at an end, so the other states of that
    interval can never be larger: the max over the result equals the max over ``query``.
    """
    q = np.unique(np.asarray(query, dtype=float).ravel())  # sorted
    if q.size <= 2:
        return q
    seg = np.searchsorted(nodes, q, side="right")  # non-decreasing along sorted q
    first = np.r_[True, seg[1:] != seg[:-1]]
    last = np.r_[seg[1:] != seg[:-1], True]
    return q[first | last]


def interpolate_rows(nodes: np.ndarray, table: np.ndarray, query: np.ndarray) -> np.ndarray:
    """Row-wise linear interpolation of ``table`` (T, K) at in-range ``query`` -> (Q, K)."""
    q = np.asarray(query, dtype=float).ravel()
    if nodes.size == 1:
        return np.repeat(table[:1], q.size, axis=0)
    j, frac = cell_fraction(nodes, q)
    frac = frac[:, None]
    return table[j] * (1.0 - frac) + table[j + 1] * frac


class StateTable:
    """A scalar function of a state, tabulated and interpolated linearly.

    Parameters
    ----------
    states : array_like, shape (T,)
        Strictly increasing state values (unit given by ``state_name``).
    values : array_like, shape (T,)
        Function values at the states.
    state_name : str
        What the state is, with its unit: ``"time_s"``, ``"temperature_k"``,
        ``"extinction"``.
    extrapolation : {"error", "clamp"}
        Outside the table: raise ValueError naming the range (default) or hold the end
        values.
    """

    def __init__(self, states, values, state_name: str, extrapolation: str = "error"):
        self.states = check_nodes("states", states)
        v = finite_array("values", values, ndim=1)
        if v.shape != self.states.shape:
            raise ValueError(f"values: expected shape {self.states.shape} (one per state), got {v.shape}")
        v = v.copy()
        v.setflags(write=False)
        self.values = v
        if not isinstance(state_name, str) or not state_name:
            raise ValueError(f"state_name={state_name!r}: expected a non-empty string such as 'time_s'")
        self.state_name = state_name
        self.extrapolation = check_policy(extrapolation)

    def __call__(self, state) -> np.ndarray:
        q = check_in_range(state, self.states, self.state_name, self.extrapolation)
        return np.interp(q, self.states, self.values) if self.states.size > 1 else np.full(np.shape(q), self.values[0])

    @property
    def state_range(self) -> tuple:
        return (float(self.states[0]), float(self.states[-1]))

    def to_dict(self) -> dict:
        return {
            "states": self.states.tolist(),
            "values": self.values.tolist(),
            "state_name": self.state_name,
            "extrapolation": self.extrapolation,
        }

    @classmethod
    def from_dict(cls, data: dict) -> "StateTable":
        known = {"states", "values", "state_name", "extrapolation"}
        unknown = set(data) - known
        if unknown:
            raise ValueError(f"state table: unknown keys {sorted(unknown)}; expected {sorted(known)}")
        return cls(**data)

    def __eq__(self, other):
        return isinstance(other, StateTable) and self.to_dict() == other.to_dict()

    __hash__ = None

    def __repr__(self):
        lo, hi = self.state_range
        return f"StateTable({self.state_name}: {self.states.size} nodes in [{lo:g}, {hi:g}])"


# -- two states (bilinear tables) ------------------------------------------------------------
def state_names(value, field: str = "state_name") -> tuple:
    """One state name, or two different ones, as a tuple; ValueError naming ``field``."""
    if isinstance(value, str) and value:
        return (value,)
    names = tuple(value) if isinstance(value, (list, tuple)) else ()
    if len(names) != 2 or not all(isinstance(n, str) and n for n in names) or names[0] == names[1]:
        raise ValueError(f"{field}={value!r}: expected a non-empty string such as 'extinction', or two different ones "
                         f"such as ['extinction', 'melt_fraction']")
    return names


def state_axes(states, names: tuple) -> tuple:
    """The checked node array of each state in ``names`` (:func:`state_names`): ``states``
    itself for one state, ``[nodes_1, nodes_2]`` for two."""
    if len(names) == 1:
        return (check_nodes("states", states),)
    if not isinstance(states, (list, tuple)) or len(states) != 2:
        raise ValueError(f"states: expected two node arrays [nodes of {names[0]}, nodes of {names[1]}] for two states")
    return tuple(check_nodes(f"states[{d}] ({names[d]})", states[d]) for d in range(2))


def check_in_range_2d(query, axes, names, policy: str) -> np.ndarray:
    """The policy of :func:`check_in_range` per axis of (..., 2) states."""
    q = np.asarray(query, dtype=float)
    if q.shape[-1:] != (2,):
        raise ValueError(f"state: expected pairs ({names[0]}, {names[1]}) in the last axis, got shape {q.shape}")
    cols = [check_in_range(q[..., d], axes[d], names[d], policy) for d in range(2)]
    return np.stack(cols, axis=-1)


def bilinear_weights(axes, query: np.ndarray) -> np.ndarray:
    """Weights W (n1 n2, Q) with ``table.reshape(n1 n2, K).T @ W`` = the bilinear
    interpolation at in-range ``query`` (Q, 2): linear per axis (Bailey et al. 2008,
    Sec. IV H: "each of the harmonic coefficients would be separately linearly
    interpolated"), the product of the two axes' weights, so every weight is >= 0 and
    they sum to 1 (a convex blend of the four corners of the query's cell)."""
    q = np.asarray(query, dtype=float).reshape(-1, 2)
    w1 = interpolation_weights(axes[0], q[:, 0])
    w2 = interpolation_weights(axes[1], q[:, 1])
    return (w1[:, None, :] * w2[None, :, :]).reshape(axes[0].size * axes[1].size, q.shape[0])


def _split_segment(axes, a: np.ndarray, b: np.ndarray) -> list:
    """Parameters in [0, 1] where the segment a -> b crosses a grid line, with 0 and 1."""
    cuts = [0.0, 1.0]
    for d in range(2):
        lo, hi = sorted((a[d], b[d]))
        inner = axes[d][(axes[d] > lo) & (axes[d] < hi)]
        if inner.size:
            cuts.extend(((inner - a[d]) / (b[d] - a[d])).tolist())
    return sorted(set(cuts))


def path_pieces(axes, path) -> tuple:
    """Split a polyline of states (P, 2) into straight pieces that each lie in one cell of
    the grid ``axes``: returns ``(starts, ends)``, each (M, 2).

    Along such a piece every bilinearly interpolated quantity is a quadratic in the
    piece's parameter (exactly: the two axis weights are linear in it), so its maximum
    over the piece is at an end or at the vertex. Consecutive pieces on one grid-parallel
    line inside one cell are merged (a quantity is linear there: the two outermost
    states bound it). A one-point path gives one piece of length 0.
    """
    p = np.asarray(path, dtype=float).reshape(-1, 2)
    starts, ends = [], []
    for a, b in zip(p[:-1], p[1:]):
        if np.array_equal(a, b):
            continue
        cuts = _split_segment(axes, a, b)
        for t0, t1 in zip(cuts[:-1], cuts[1:]):
            starts.append(a + (b - a) * t0)
            ends.append(a + (b - a) * t1)
    if not starts:
        return p[:1].copy(), p[:1].copy()
    return _merge_straight(axes, np.array(starts), np.array(ends))


def _merge_straight(axes, starts: np.ndarray, ends: np.ndarray) -> tuple:
    """Merge runs of consecutive pieces that share one grid-parallel line and one cell."""
    mids = 0.5 * (starts + ends)
    cell = np.stack([cell_fraction(axes[d], mids[:, d])[0] for d in range(2)], axis=1)
    flat = starts == ends  # (M, 2): the coordinate that does not change
    out_s, out_e = [starts[0].copy()], [ends[0].copy()]
    for i in range(1, len(starts)):
        prev = i - 1
        same_line = any(flat[i, d] and flat[prev, d] and starts[i, d] == starts[prev, d] for d in range(2))
        if same_line and np.array_equal(cell[i], cell[prev]):
            lo = np.minimum(np.minimum(out_s[-1], out_e[-1]), np.minimum(starts[i], ends[i]))
            hi = np.maximum(np.maximum(out_s[-1], out_e[-1]), np.maximum(starts[i], ends[i]))
            out_s[-1], out_e[-1] = lo, hi
        else:
            out_s.append(starts[i].copy())
            out_e.append(ends[i].copy())
    return np.array(out_s), np.array(out_e)


def quadratic_max(e0: np.ndarray, em: np.ndarray, e1: np.ndarray) -> np.ndarray:
    """Maximum over t in [0, 1] of the quadratic through (0, e0), (1/2, em), (1, e1).

    ``q(t) = e0 + beta t + gamma t^2`` with ``gamma = 2 (e0 + e1 - 2 em)`` and
    ``beta = e1 - e0 - gamma``; a concave q (gamma < 0) with its vertex
    ``t* = -beta / (2 gamma)`` inside (0, 1) peaks at ``e0 - beta^2 / (4 gamma)``.
    """
    gamma = 2.0 * (e0 + e1 - 2.0 * em)
    beta = e1 - e0 - gamma
    out = np.maximum(e0, e1)
    concave = gamma < 0.0
    if np.any(concave):
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            t = -beta / (2.0 * gamma)
            top = e0 - beta * beta / (4.0 * gamma)
        inside = concave & (t > 0.0) & (t < 1.0) & np.isfinite(top)
        out = np.where(inside, np.maximum(out, top), out)
    return out


def bilinear_rows(axes, table: np.ndarray, query: np.ndarray) -> np.ndarray:
    """Bilinear interpolation of ``table`` (n1, n2, K) at in-range ``query`` (Q, 2) ->
    (Q, K), from the four corners of each query's cell (no dense weight matrix)."""
    q = np.asarray(query, dtype=float).reshape(-1, 2)
    (i, x), (j, y) = (cell_fraction(axes[d], q[:, d]) for d in range(2))
    i1 = np.minimum(i + 1, axes[0].size - 1)
    j1 = np.minimum(j + 1, axes[1].size - 1)
    x, y = x[:, None], y[:, None]
    return (table[i, j] * ((1 - x) * (1 - y)) + table[i1, j] * (x * (1 - y))
            + table[i, j1] * ((1 - x) * y) + table[i1, j1] * (x * y))
