"""Threads for the hot loops: blocks of rows side by side, one BLAS thread each.

NumPy ufuncs, BLAS and Embree release the GIL, so blocks of a large evaluation run in
parallel on threads. Two rules keep that from backfiring: while blocks run, BLAS is held
to one thread (spec `engineering-notes.md`: "running BLAS threads and Python threads
together doubled the time"), and work started inside a block runs serially (no threads
within threads).

``thread_limit(n)`` caps the threads of everything called inside it on this thread (a
study on a cluster runs each scenario with ``thread_limit(1)``: the workers are the
parallelism).
"""

from __future__ import annotations

import operator
import os
import threading
from contextlib import contextmanager

__all__ = ["default_threads", "thread_limit", "map_blocks", "block_rows", "BLOCK_VALUES"]

BLOCK_VALUES = 4_000_000  # values per block (32 MB in float64; a few such arrays live per thread)

_local = threading.local()
_controller = None


def _cpu_count() -> int:
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # not on Linux
        return max(1, os.cpu_count() or 1)


def default_threads() -> int:
    """Threads a hot loop may use here: the CPUs this process may run on, or the cap of
    the innermost :func:`thread_limit` on this thread (1 inside a block)."""
    cap = getattr(_local, "cap", None)
    return _cpu_count() if cap is None else cap


@contextmanager
def thread_limit(threads: int):
    """Cap the threads of hot loops called inside the ``with`` block (on this thread)."""
    try:
        n = None if isinstance(threads, bool) else operator.index(threads)
    except TypeError:
        n = None
    if n is None or n < 1:
        raise ValueError(f"threads={threads!r}: expected an integer >= 1")
    threads = n
    old = getattr(_local, "cap", None)
    _local.cap = threads if old is None else min(old, threads)
    try:
        yield
    finally:
        _local.cap = old


def _in_block():
    _local.cap = 1


def blas_one_thread():
    """A context manager limiting the BLAS libraries to one thread (threadpoolctl), for
    work already running on one thread per block."""
    global _controller
    if _controller is None:  # inspecting the loaded libraries costs ~0.5 ms: once
        from threadpoolctl import ThreadpoolController

        _controller = ThreadpoolController()
    return _controller.limit(limits=1, user_api="blas")


def block_rows(values_per_row: int, max_rows: int) -> int:
    """Rows per block: at most ``max_rows``, and at most :data:`BLOCK_VALUES` values in
    all (never below 256 rows), so long rows (many states or times) keep memory bounded."""
    return min(max_rows, max(256, BLOCK_VALUES // max(1, values_per_row)))


def map_blocks(fn, n: int, block: int, threads=None) -> list:
    """``[fn(a, b) for each block [a, b) of range(n)]``, on threads when it pays.

    Parameters
    ----------
    fn : callable (a, b) -> result
        Works on rows ``a:b``; blocks must write disjoint outputs.
    n, block : int
        Rows and rows per block.
    threads : int, optional
        Default :func:`default_threads`. One block, or one thread, runs inline.

    Returns
    -------
    list
        The results in block order.
    """
    starts = range(0, n, block)
    workers = min(default_threads() if threads is None else int(threads), len(starts))
    if workers <= 1:
        return [fn(a, min(a + block, n)) for a in starts]
    from concurrent.futures import ThreadPoolExecutor

    with blas_one_thread(), ThreadPoolExecutor(workers, initializer=_in_block) as pool:
        return list(pool.map(lambda a: fn(a, min(a + block, n)), starts))
