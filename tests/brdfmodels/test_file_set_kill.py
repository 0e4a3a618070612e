"""hazard fit's separate output files (``brdfmodels.output_sets.FileSet``) after a KILL between
their renames (issue 30: "no output set is ever mixed"): the process dies in the middle (no
exception handler runs: ``os._exit``), leaving some new files beside old ones; the next
FileSet naming any of them finishes the switch first: back to the previous files when some
temporaries were not renamed in yet, forward when all were (only backups left)."""

from __future__ import annotations

import subprocess
import sys
import textwrap

import pytest

from brdfmodels.output_sets import FileSet

CHILD = textwrap.dedent("""
    import os, sys
    import brdfmodels.output_sets as unit
    kill_at = sys.argv[1]
    finals = sys.argv[2:]

    def step(name):
        if name == kill_at:
            os._exit(9)  # a kill: no except, no finally
    unit._step = step
    fs = unit.FileSet(finals)
    for p in finals:
        fs.stage(p).write_text("new " + os.path.basename(p))
    fs.commit()
""")


def _kill_during_commit(tmp_path, kill_at, finals):
    r = subprocess.run([sys.executable, "-c", CHILD, kill_at, *map(str, finals)], capture_output=True, text=True)
    assert r.returncode == 9, r.stderr


def _files(tmp_path):
    return sorted(p.name for p in tmp_path.rglob("*") if p.is_file())


@pytest.mark.parametrize("kill_at", ["files: rename 0", "files: rename 1", "files: rename 2"])
def test_a_kill_between_renames_is_rolled_back_by_the_next_set(tmp_path, kill_at):
    a, b, c = tmp_path / "model.json", tmp_path / "sub" / "env.json", tmp_path / "s.csv"
    b.parent.mkdir()
    a.write_text("old model.json")
    b.write_text("old env.json")  # s.csv did not exist before
    _kill_during_commit(tmp_path, kill_at, [a, b, c])
    if kill_at != "files: rename 0":
        assert a.read_text() == "new model.json"  # the mix the kill left: model switched ...
    assert any(p.name.endswith(".journal") for p in tmp_path.rglob("*"))  # ... and the journal says what was under way
    done = FileSet([c])  # the next run naming any one of the set's files
    assert done.recovered == ["an interrupted write of model.json, env.json, s.csv was rolled back to the previous files"]
    assert a.read_text() == "old model.json" and b.read_text() == "old env.json" and not c.exists()
    assert _files(tmp_path) == ["env.json", "model.json"]  # no temporary, backup or journal left


def test_a_kill_after_every_rename_is_completed_by_the_next_set(tmp_path):
    a, c = tmp_path / "model.json", tmp_path / "s.csv"
    a.write_text("old model.json")
    _kill_during_commit(tmp_path, "files: renamed", [a, c])
    assert FileSet([a]).recovered == ["an interrupted write of model.json, s.csv was completed"]
    assert a.read_text() == "new model.json" and c.read_text() == "new s.csv"
    assert _files(tmp_path) == ["model.json", "s.csv"]


def test_a_normal_commit_leaves_no_journal(tmp_path):
    a = tmp_path / "model.json"
    fs = FileSet([a])
    fs.stage(a).write_text("x")
    fs.commit()
    assert _files(tmp_path) == ["model.json"]
