"""Which rows of a large observer table the outputs list, in bounded memory.

``np.argsort(-score, kind="stable")[:k]`` sorts every row and makes two more copies of
the column (at 1e7 observers: 240 MB beside the result); the same rows come from one
partition (:func:`top_rows`), of the few rows that can be among them when a sample of the
column says which (:func:`_candidates`).
"""

from __future__ import annotations

import numpy as np

__all__ = ["top_rows"]

SAMPLE_ROWS = 32_768  # rows of the column a threshold is read from (a strided view: no pass over the column)


def top_rows(score: np.ndarray, k: int) -> np.ndarray:
    """The rows of the ``k`` largest values of ``score`` (no NaN), ties taken by the
    lowest row, in row order: ``np.sort(np.argsort(-score, kind="stable")[:k])``.

    Parameters
    ----------
    score : (M,) float array without NaN (the caller maps NaN to +inf: unknown is worst).
    k : how many rows (all of them when ``k >= M``).
    """
    score = np.asarray(score)
    m = len(score)
    if k >= m:
        return np.arange(m)
    if k <= 0:
        return np.zeros(0, np.int64)
    rows = _candidates(score, k)
    sub = score if rows is None else score[rows]
    kth = np.partition(sub, len(sub) - k)[len(sub) - k]  # the k-th largest value
    above = np.flatnonzero(sub > kth)  # fewer than k
    tie = np.flatnonzero(sub == kth)[: k - len(above)]  # the lowest rows first (the candidates are ascending)
    picked = np.sort(np.concatenate([above, tie]))
    return picked if rows is None else rows[picked]


def _candidates(score: np.ndarray, k: int) -> np.ndarray | None:
    """The rows (ascending) whose value is at least a threshold read from a strided sample
    of ``score``, set to let about twice ``k`` rows through; None (every row a candidate)
    when ``k`` is over a sixteenth of the rows or fewer than ``k`` pass (a sample that
    missed the column's top). At least ``k`` rows at or above it: the ``k``-th largest
    value is too, so every row of the ``k`` largest, ties included, is a candidate."""
    m = len(score)
    if 16 * k > m or m < 4 * SAMPLE_ROWS:
        return None
    sample = score[:: m // SAMPLE_ROWS]
    rank = min(len(sample), 2 * k * len(sample) // m + 16)  # from the top: ~2k rows of the column expected above
    threshold = np.partition(sample, len(sample) - rank)[len(sample) - rank]
    rows = np.flatnonzero(score >= threshold)
    return rows if len(rows) >= k else None
