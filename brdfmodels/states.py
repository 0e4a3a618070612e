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


def interpolation_weights(nodes: np.ndarray, query: np.ndarray) -> np.ndarray:
    """Weights W (T, Q) with ``table.T @ W`` = linear interpolation at ``query`` (in range)."""
    q = np.asarray(query, dtype=float).ravel()
    t = nodes.size
    w = np.zeros((t, q.size))
    if t == 1:
        w[0] = 1.0
        return w
    j = np.clip(np.searchsorted(nodes, q, side="right") - 1, 0, t - 2)
    frac = (q - nodes[j]) / (nodes[j + 1] - nodes[j])
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
    j = np.clip(np.searchsorted(nodes, q, side="right") - 1, 0, nodes.size - 2)
    frac = ((q - nodes[j]) / (nodes[j + 1] - nodes[j]))[:, None]
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
