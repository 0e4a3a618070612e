"""hazard.drivers.runner: the one resumable task runner of ``hazard study`` and ``hazard risk``.

Serial and Dask runs of the same tasks record the same results; the first failure (a task
that raised, or a result that records its failure) stops the rest unless ``keep_going``;
the teardown runs after the tasks, failures included; a folder claimed by another run's
digest is refused unless ``force``. The study's and the risk's own resume and kill tests
are in test_study.py and test_risk.py.
"""

from __future__ import annotations

import json

import pytest

from hazard.drivers.runner import claim_folder, error_line, failure_kinds, run_tasks

TORN_DOWN: list = []  # teardown calls (module level: a Dask worker in this process appends here)


def square(shared, task):
    """A task: ``shared`` scales the square; task 3 raises, a negative task records its failure."""
    if task == 3:
        raise RuntimeError(f"task  {task}\n failed")
    return {"task": task, "value": shared * task * task, "error": "negative" if task < 0 else None}


def tear_down():
    TORN_DOWN.append("done")


def _run(pending, **kw):
    got = []
    failed = run_tasks(square, 2, pending, lambda t, r: got.append((t, r["value"])), failure_of=lambda r: r["error"],
                       teardown=tear_down, **kw)
    return got, failed


def test_serial_runs_in_order_and_stops_at_the_first_failure():
    TORN_DOWN.clear()
    got, failed = _run([1, 2, 3, 4], serial=True)
    assert got == [(1, 2), (2, 8)] and failed == [(3, "RuntimeError: task 3 failed")]  # 4 not run
    got, failed = _run([1, -2, 4], serial=True)  # a result that records its failure is recorded, and stops the run
    assert got == [(1, 2), (-2, 8)] and failed == [(-2, "negative")]
    got, failed = _run([1, 3, -2, 4], serial=True, keep_going=True)
    assert got == [(1, 2), (-2, 8), (4, 32)] and [t for t, _ in failed] == [3, -2]
    with pytest.raises(RuntimeError, match="task  3"):
        _run([1, 3, 4], serial=True, raise_errors=True)
    assert TORN_DOWN == ["done"] * 4  # after every run, the raising one included


def test_dask_records_the_serial_results_and_tears_down_on_the_worker():
    from distributed import LocalCluster

    TORN_DOWN.clear()
    with LocalCluster(n_workers=1, threads_per_worker=1, processes=False, dashboard_address=None) as cluster:
        got, failed = _run([1, 2, 5, 6], scheduler=cluster.scheduler_address)
        assert sorted(got) == [(1, 2), (2, 8), (5, 50), (6, 72)] and failed == []
        got, failed = _run([1, 3, 2, -4], scheduler=cluster.scheduler_address, keep_going=True)
        assert sorted(got) == [(-4, 32), (1, 2), (2, 8)] and sorted(failed) == [(-4, "negative"), (3, "RuntimeError: task 3 failed")]
        got, failed = _run([3] + list(range(10, 60)), scheduler=cluster.scheduler_address)
        assert failed == [(3, "RuntimeError: task 3 failed")] and len(got) < 50  # the rest cancelled (one worker: in order)
    assert TORN_DOWN == ["done"] * 3


def test_claim_folder_keeps_a_run_and_refuses_another(tmp_path):
    meta, done = tmp_path / "meta.json", tmp_path / "t1.npz"
    claim_folder(meta, "abc", json.dumps({"digest": "abc"}), force=False, finished=[], held="x")
    done.write_bytes(b"1")
    claim_folder(meta, "abc", json.dumps({"digest": "abc", "more": 1}), force=False, finished=[done], held="x")
    assert done.exists() and json.loads(meta.read_text())["more"] == 1
    with pytest.raises(ValueError, match=r"^OUT holds chunks of another run \(digest abc\); pass --force to start over$"):
        claim_folder(meta, "def", "{}", force=False, finished=[done], held="OUT holds chunks of another run")
    assert done.exists()
    claim_folder(meta, "def", json.dumps({"digest": "def"}), force=True, finished=[done], held="x")
    assert not done.exists() and json.loads(meta.read_text()) == {"digest": "def"}


def test_error_lines_and_kinds():
    assert error_line(ValueError("a\n  b")) == "ValueError: a b"
    assert failure_kinds(["A: 1", "B: 2", "A: 3"]) == {"A": "A: 1", "B": "B: 2"}
