"""The one resumable task runner of ``hazard study`` and ``hazard risk``: on Dask or serially.

A driver cuts its work into independent tasks, each a pure function of (shared inputs,
task), so a serial run, an embedded ``LocalCluster`` and an existing scheduler give the
same results. The driver's folder holds one file per finished task and a digest of what
the tasks depend on (:func:`claim_folder`: a restarted run with the same digest keeps the
finished files and runs only the rest; another analysis in the same folder is an error
unless ``force``). :func:`run_tasks` runs the pending tasks and hands each result to the
driver's ``record`` as it arrives (the driver writes it atomically, so a killed run loses
at most the tasks in flight); the first failed task stops the rest unless ``keep_going``.

On Dask the shared inputs are scattered once to every worker; each task runs in a
single-threaded worker process (:func:`local_cluster`): the workers are the parallelism.
What a worker builds once and reuses over its tasks (the risk's ray scene and nominal
trace, a study's stage memo) is the driver's own per-process cache.
"""

from __future__ import annotations

import json
import os
from collections.abc import Callable, Iterable
from pathlib import Path

from brdfmodels.fileio import atomic_write_text

__all__ = ["local_cluster", "failure_kinds", "error_line", "claim_folder", "run_tasks"]


def local_cluster(n_workers=2):
    """The embedded ``LocalCluster`` of ``hazard study`` and ``hazard risk``:
    ``n_workers`` single-threaded worker processes on loopback. The scheduler's HTTP
    server always starts; it takes a free port (``:0``), so a second cluster on this
    machine does not clash on 8787.

    Dask's nanny starts workers with ``MALLOC_TRIM_THRESHOLD_=65536``, which hands every
    freed NumPy temporary back to the OS and page-faults it in again: measured 0.12 s per
    `plate` scenario instead of 0.068 s. Scenarios are allocation-heavy, so the workers get
    glibc's default (a value set in the user's environment still wins).
    """
    import dask
    from distributed import LocalCluster

    # the workers log Dask's own chatter at ERROR only, as hazard._noise does in this process
    # (a value set in the user's environment still wins)
    env = {"distributed.nanny.pre-spawn-environ.MALLOC_TRIM_THRESHOLD_": None}
    if "DASK_LOGGING__DISTRIBUTED" not in os.environ:
        env["distributed.nanny.pre-spawn-environ.DASK_LOGGING__DISTRIBUTED"] = "error"
    with dask.config.set(env):
        return LocalCluster(n_workers=n_workers, threads_per_worker=1, processes=True, host="127.0.0.1", dashboard_address=":0")


def failure_kinds(errors) -> dict:
    """The first error of each kind (the exception's name before ``:``) among ``errors``
    (strings ``"Kind: message"``), in the order met."""
    kinds: dict = {}
    for e in errors:
        kinds.setdefault(str(e).split(":", 1)[0], str(e))
    return kinds


def error_line(exc: BaseException) -> str:
    """``"Kind: message"`` of an exception on one line (whitespace runs collapsed)."""
    return f"{type(exc).__name__}: {' '.join(str(exc).split())}"


def claim_folder(meta: Path, digest: str, text: str, *, force: bool, finished: Iterable[Path], held: str) -> None:
    """Make ``meta`` (a JSON file with a ``digest`` key) say this run's ``digest``.

    The finished task files of a run with the same digest are kept (resume). When
    ``meta`` names another digest: :class:`ValueError` (``"<held> (digest <old>); pass
    --force to start over"``, ``held`` naming the folder and what it holds), or with
    ``force`` the ``finished`` files are deleted first. ``text``: the new content of
    ``meta`` (written atomically).
    """
    meta = Path(meta)
    if meta.exists():
        old = json.loads(meta.read_text()).get("digest")
        if old != digest:
            if not force:
                raise ValueError(f"{held} (digest {old}); pass --force to start over")
            for p in finished:
                p.unlink()
    atomic_write_text(meta, text)


def run_tasks(fn: Callable, shared, pending: list, record: Callable, *, serial: bool = False, workers: int = 2,
              scheduler: str | None = None, keep_going: bool = False, failure_of: Callable | None = None,
              raise_errors: bool = False, teardown: Callable | None = None) -> list:
    """Run ``fn(shared, task)`` for every task of ``pending``; the failed ones as (task, error line) pairs.

    Parameters
    ----------
    fn : callable
        A module-level function (Dask pickles it by name) of (``shared``, task).
    shared
        The inputs every task shares, scattered once to every worker on Dask.
    pending : list
        The tasks to run.
    record : callable
        ``record(task, result)``, called in this process as each task finishes (in
        completion order on Dask), for every result, failed ones included (see
        ``failure_of``); a task that raised is not recorded.
    serial : bool
        Run in this process, in ``pending``'s order.
    workers, scheduler
        An embedded :func:`local_cluster` of ``workers`` processes, or the address of an
        existing Dask scheduler (``tcp://host:port``).
    keep_going : bool
        Run every task even after one fails; by default the first failure stops the rest
        (on Dask the tasks not yet finished are cancelled).
    failure_of : callable, optional
        ``failure_of(result)`` -> an error line when a result that came back records a
        failure (a study's row with its error), else None.
    raise_errors : bool
        A task that raised raises here (after the cluster is closed) instead of being
        counted as failed.
    teardown : callable, optional
        Called without arguments after the tasks (also after a failure) in every worker
        process (``Client.run``), or in this process for a serial run: it drops what the
        tasks kept per process for this run only (a study's stage memo).
    """
    if serial:
        try:
            return _run_serial(fn, shared, pending, record, keep_going, failure_of, raise_errors)
        finally:
            if teardown is not None:
                teardown()
    from distributed import Client, as_completed

    failed: list = []
    cluster = local_cluster(workers) if scheduler is None else None
    client = Client(cluster) if cluster is not None else Client(scheduler, timeout="20s")
    try:
        [shared_f] = client.scatter([shared], broadcast=True)  # one object, whatever its type
        futures = {client.submit(fn, shared_f, t, pure=False): t for t in pending}
        for fut in as_completed(futures):
            task, exc = futures[fut], fut.exception()
            if exc is not None and raise_errors:
                raise exc
            if _finished(task, None if exc is not None else fut.result(), exc, record, failure_of, failed) and not keep_going:
                client.cancel([f for f in futures if not f.done()])
                break
    finally:
        if teardown is not None:
            try:
                client.run(teardown)
            except Exception:  # noqa: BLE001 - a worker lost meanwhile: its process (and its cache) is gone with it
                pass
        client.close()
        if cluster is not None:
            cluster.close()
    return failed


def _run_serial(fn, shared, pending, record, keep_going, failure_of, raise_errors) -> list:
    """:func:`run_tasks` in this process."""
    failed: list = []
    for t in pending:
        try:
            result, exc = fn(shared, t), None
        except Exception as e:  # noqa: BLE001 - counted and said; the run exits non-zero
            if raise_errors:
                raise
            result, exc = None, e
        if _finished(t, result, exc, record, failure_of, failed) and not keep_going:
            break
    return failed


def _finished(task, result, exc, record, failure_of, failed: list) -> bool:
    """Record a finished task (``exc``: what it raised); True when it failed."""
    if exc is not None:
        failed.append((task, error_line(exc)))
        return True
    record(task, result)
    err = None if failure_of is None else failure_of(result)
    if err is not None:
        failed.append((task, err))
    return err is not None
