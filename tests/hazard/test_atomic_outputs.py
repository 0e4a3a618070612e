"""Outputs replaced as one unit (brdfmodels.output_sets): fault injection at every step.

Each test writes an old complete set, then a new one that is interrupted before, between
and after each rename (an exception in-process, ``os._exit`` and a real SIGKILL in a
subprocess), and checks that the folder then holds the old complete set or the new one
(after :func:`recover`, which every command runs first), with no temporaries left behind
and files hazard did not write untouched.
"""

from __future__ import annotations

import io
import json
import os
import signal
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest
from hypothesis import given, settings, strategies as st

import hazard
import scenes
from brdfmodels import output_sets
from brdfmodels.output_sets import MANIFEST, OutputFolderError, output_unit, recover
from hazard import cli

ROOT = Path(__file__).resolve().parents[2]
STEPS = ("staged", "moved", "switched")


class Crash(BaseException):
    """An interruption (not an Exception: nothing may swallow it)."""


def snapshot(out: Path) -> dict:
    """name -> bytes of every file under ``out`` except the manifest (None: no folder)."""
    if not out.is_dir():
        return None
    return {str(p.relative_to(out)): p.read_bytes() for p in sorted(out.rglob("*")) if p.is_file() and p.name != MANIFEST}


def leftovers(out: Path) -> list:
    return sorted(p.name for p in out.parent.iterdir() if p.name.startswith(f".{out.name}."))


def write_set(out, files: dict, **kw):
    with output_unit(out, command=kw.pop("command", "run"), **kw) as unit:
        for n, data in files.items():
            (unit.stage / n).write_bytes(data)
    return unit


OLD = {"report.json": b'{"set": "old"}', "observers.csv": b"old\r\n", "plan.png": b"old png"}
NEW = {"report.json": b'{"set": "new"}', "observers.csv": b"new\r\n"}


def crash_at_step(monkeypatch, step):
    def hook(name):
        if name == step:
            raise Crash(name)

    monkeypatch.setattr(output_sets, "_step", hook)


def crash_at_rename(monkeypatch, k):
    calls, real = [0], os.rename

    def rename(a, b):
        calls[0] += 1
        if calls[0] == k:
            raise Crash(f"rename {k}")
        return real(a, b)

    monkeypatch.setattr(os, "rename", rename)


@pytest.mark.parametrize("how", [("step", s) for s in STEPS] + [("rename", k) for k in (1, 2)])
def test_interrupted_switch_leaves_old_or_new_set(tmp_path, monkeypatch, how):
    out = tmp_path / "o"
    write_set(out, OLD)
    assert snapshot(out) == OLD and leftovers(out) == []
    with monkeypatch.context() as m:
        (crash_at_step if how[0] == "step" else crash_at_rename)(m, how[1])
        with pytest.raises(Crash):
            write_set(out, NEW, overwrite=True)
    # before recovery: either OUT is whole, or it is missing beside the old set in one .old folder
    if not out.exists():
        (old,) = [p for p in out.parent.iterdir() if p.name.endswith(".old")]
        assert snapshot(old) == OLD
    recover(out)
    assert snapshot(out) == (NEW if how == ("step", "switched") else OLD)
    assert leftovers(out) == []
    write_set(out, NEW, overwrite=True)  # the next run completes normally
    assert snapshot(out) == NEW and leftovers(out) == []
    assert json.loads((out / MANIFEST).read_text())["files"] == {n: "run" for n in NEW}


_CHILD = textwrap.dedent("""
    import os, sys, time
    from pathlib import Path
    from brdfmodels import output_sets
    out, step, kill = Path(sys.argv[1]), sys.argv[2], sys.argv[3]
    def hook(name):
        if name == step:
            if kill == "wait":
                print("ready", flush=True)
                time.sleep(60)
            os._exit(9)
    output_sets._step = hook
    with output_sets.output_unit(out, command="run", overwrite=True) as unit:
        for n in ("report.json", "observers.csv"):
            (unit.stage / n).write_bytes(b"new " + n.encode())
""")


def _env():
    return {**os.environ, "PYTHONPATH": str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", "")}


@pytest.mark.parametrize("step", STEPS)
def test_process_killed_at_each_step(tmp_path, step):
    """``os._exit`` at each step: no cleanup code runs (as for kill -9)."""
    out = tmp_path / "o"
    write_set(out, OLD)
    r = subprocess.run([sys.executable, "-c", _CHILD, str(out), step, "exit"], env=_env(), capture_output=True, timeout=60)
    assert r.returncode == 9, r.stderr.decode()
    assert leftovers(out)  # the crash left its staging (and, from "moved", the old set)
    recover(out)
    new = {"report.json": b"new report.json", "observers.csv": b"new observers.csv"}
    assert snapshot(out) == (new if step == "switched" else OLD) and leftovers(out) == []


def test_real_sigkill_between_the_renames(tmp_path):
    out = tmp_path / "o"
    write_set(out, OLD)
    p = subprocess.Popen([sys.executable, "-c", _CHILD, str(out), "moved", "wait"], env=_env(), stdout=subprocess.PIPE)
    try:
        assert p.stdout.readline() == b"ready\n"
        os.kill(p.pid, signal.SIGKILL)
    finally:
        p.wait(timeout=60)
    assert p.returncode == -signal.SIGKILL and not out.exists()  # the worst moment: OUT renamed away
    write_set(out, {"x.csv": b"x"}, command="render")  # any next unit recovers first
    assert snapshot(out) == {**OLD, "x.csv": b"x"} and leftovers(out) == []


def test_foreign_files_refused_then_kept_with_force(tmp_path):
    out = tmp_path / "o"
    out.mkdir()
    (out / "notes.txt").write_text("mine")
    (out / "sub").mkdir()
    (out / "sub" / "a.dat").write_bytes(b"a")
    ino = (out / "notes.txt").stat().st_ino
    with pytest.raises(OutputFolderError, match=r"holds files hazard did not write \(notes.txt, sub\).*--force"):
        write_set(out, NEW)
    assert leftovers(out) == []
    write_set(out, NEW, force=True)
    assert snapshot(out) == {**NEW, "notes.txt": b"mine", "sub/a.dat": b"a"}
    assert (out / "notes.txt").stat().st_ino == ino  # the same file, not a copy
    assert set(json.loads((out / MANIFEST).read_text())["files"]) == set(NEW)  # never claimed
    write_set(out, {"report.json": b"3"}, overwrite=True, force=True)  # the run's old table goes, notes stay
    assert snapshot(out) == {"report.json": b"3", "notes.txt": b"mine", "sub/a.dat": b"a"}


def test_own_outputs_need_overwrite_and_other_commands_files_are_kept(tmp_path):
    out = tmp_path / "o"
    write_set(out, OLD)
    with pytest.raises(OutputFolderError, match=r"o/observers.csv exists: pass --force"):
        write_set(out, NEW)
    write_set(out, {"keepout.png": b"k"}, command="render")  # into the run's folder: the run's files stay
    assert snapshot(out) == {**OLD, "keepout.png": b"k"}
    write_set(out, NEW, overwrite=True)  # run again: its plan.png is gone, render's picture stays
    assert snapshot(out) == {**NEW, "keepout.png": b"k"}
    assert json.loads((out / MANIFEST).read_text())["files"] == {"keepout.png": "render", **{n: "run" for n in NEW}}


def test_working_folder_is_kept_across_units_and_crashes(tmp_path, monkeypatch):
    """A checkpoint folder written straight into OUT (``.risk``) survives every switch."""
    out = tmp_path / "o"
    (out / ".risk").mkdir(parents=True)
    (out / ".risk" / "c0.npz").write_bytes(b"chunk")
    write_set(out, OLD, command="risk", working=(".risk",))
    with monkeypatch.context() as m:
        crash_at_step(m, "moved")
        with pytest.raises(Crash):
            write_set(out, NEW, command="risk", overwrite=True, working=(".risk",))
    recover(out)
    assert snapshot(out) == {**OLD, ".risk/c0.npz": b"chunk"}
    (out / ".risk" / "c1.npz").write_bytes(b"more")
    write_set(out, NEW, command="risk", overwrite=True, working=(".risk",))
    assert snapshot(out) == {**NEW, ".risk/c0.npz": b"chunk", ".risk/c1.npz": b"more"} and leftovers(out) == []


def test_stale_temporaries_only_of_dead_processes_and_only_ours(tmp_path):
    out = tmp_path / "o"
    write_set(out, OLD)
    dead = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True, text=True).stdout.strip()
    stale = tmp_path / f".o.{dead}.0123456789abcdef.tmp"
    live = tmp_path / f".o.{os.getppid()}.0123456789abcdef.tmp"  # another process still writing
    mine = [tmp_path / ".o.notes.tmp", tmp_path / ".o.1.xyz.old", tmp_path / ".other.1.0123456789abcdef.tmp"]
    for p in [stale, live, *mine]:
        p.mkdir()
        (p / "f").write_text("x")
    said = recover(out)
    assert not stale.exists() and live.exists() and all(p.exists() for p in mine)
    assert said == [f"{out}: removed the stale {stale.name}"] and snapshot(out) == OLD


def test_symlinked_output_folder_switches_its_target(tmp_path):
    real = tmp_path / "real"
    write_set(real, OLD)
    link = tmp_path / "link"
    link.symlink_to(real)
    write_set(link, NEW, overwrite=True)
    assert link.is_symlink() and snapshot(link) == NEW and snapshot(real) == NEW


_SETS = st.lists(st.dictionaries(st.sampled_from(["report.json", "observers.csv", "plan.png", "zones.json"]),
                                 st.binary(min_size=0, max_size=8), min_size=1), min_size=1, max_size=4)
_CRASHES = st.lists(st.sampled_from(STEPS + ("rename1", "rename2", None)), min_size=4, max_size=4)


def _check_sequence(out: Path, sets, crashes):
    """Random sets written in turn, each maybe interrupted anywhere: the folder always holds
    the last complete set (or the one before, when the last was interrupted before its
    switch), and nothing is left beside it."""
    done = None
    for files, crash in zip(sets, crashes):
        mp = pytest.MonkeyPatch()
        try:
            if crash in STEPS:
                crash_at_step(mp, crash)
            elif crash:
                crash_at_rename(mp, int(crash[-1]))
            try:
                write_set(out, files, overwrite=True)
                done = files
            except Crash:
                if crash == "switched":
                    done = files  # interrupted after its switch
        finally:
            mp.undo()
        recover(out)
        assert snapshot(out) == done and leftovers(out) == []


@settings(derandomize=True, deadline=None, max_examples=15)
@given(sets=_SETS, crashes=_CRASHES)
def test_property_any_sequence_of_interrupted_runs(tmp_path_factory, sets, crashes):
    _check_sequence(tmp_path_factory.mktemp("p") / "o", sets, crashes)


@pytest.mark.slow
@settings(derandomize=True, deadline=None, max_examples=300)
@given(sets=_SETS, crashes=_CRASHES)
def test_property_any_sequence_of_interrupted_runs_many(tmp_path_factory, sets, crashes):
    _check_sequence(tmp_path_factory.mktemp("p") / "o", sets, crashes)


# -- the commands -------------------------------------------------------------------------

@pytest.fixture(scope="module")
def results():
    return {n: hazard.analyze(scenes.load(scenes.example_path(n))) for n in ("plate", "binoculars")}


def run(*argv):
    out, err = io.StringIO(), io.StringIO()
    return cli.main([str(a) for a in argv], stdout=out, stderr=err), out.getvalue(), err.getvalue()


@pytest.mark.parametrize("how", [("step", s) for s in STEPS] + [("rename", k) for k in (1, 2)])
def test_hazard_run_interrupted_keeps_one_whole_report(tmp_path, monkeypatch, results, how):
    monkeypatch.setattr(cli, "_analyse", lambda args, err: results[os.path.basename(args.scene)])
    ref = {}
    for name in results:
        assert run("run", name, "-o", tmp_path / name, "--quiet")[0] == 0
        ref[name] = snapshot(tmp_path / name)
    assert ref["plate"]["report.json"] != ref["binoculars"]["report.json"]
    out = tmp_path / "o"
    assert run("run", "plate", "-o", out, "--quiet")[0] == 0
    (out / "notes.txt").write_text("not ours")
    assert run("run", "binoculars", "-o", out, "--quiet", "--force")[0] == 0  # with --force, kept
    with monkeypatch.context() as m:
        (crash_at_step if how[0] == "step" else crash_at_rename)(m, how[1])
        with pytest.raises(Crash):
            run("run", "plate", "-o", out, "--quiet", "--force")
    assert run("run", "binoculars", "-o", tmp_path / "other", "--quiet")[0] == 0  # unrelated: no recovery of o
    recover(out)
    expect = "plate" if how == ("step", "switched") else "binoculars"
    assert snapshot(out) == {**ref[expect], "notes.txt": b"not ours"} and leftovers(out) == []


def test_hazard_run_review_page_sees_render_pictures(tmp_path, monkeypatch, results):
    monkeypatch.setattr(cli, "_analyse", lambda args, err: results["plate"])
    out = tmp_path / "o"
    assert run("run", "plate", "-o", out, "--quiet")[0] == 0
    code, stdout, _ = run("run", "plate", "-o", out, "--quiet", "--force", "--report")
    assert code == 0 and f"wrote {out / 'report.html'}" in stdout and ".tmp" not in stdout
    assert (out / "report.html").exists() and leftovers(out) == []
    code, stdout, err = run("report", out, "--quiet")
    assert code == 0 and stdout == f"wrote {out / 'map.html'}\nwrote {out / 'report.html'}\n", err
    files = json.loads((out / MANIFEST).read_text())["files"]
    assert files["report.html"] == files["map.html"] == "report" and files["report.json"] == "run"


def _risk_view(out: Path):
    """The final set of a risk run: its file names, risk.csv, and risk.json's seed."""
    names = sorted(p.name for p in out.iterdir() if not p.name.startswith("."))
    return names, (out / "risk.csv").read_bytes(), json.loads((out / "risk.json").read_text())["seed"]


@pytest.mark.slow  # about 15 s each (three risk runs)
@pytest.mark.parametrize("how", [("step", "moved"), ("step", "switched"), ("rename", 2)])
def test_hazard_risk_interrupted_keeps_one_whole_set(tmp_path, monkeypatch, how):
    from tests.hazard.test_risk import _run, _small

    _run(_small(tmp_path, seed=5), tmp_path, "ref")
    out = tmp_path / "out"
    _run(_small(tmp_path), tmp_path)
    old, new = _risk_view(out), _risk_view(tmp_path / "ref")
    assert old[1] != new[1] and "risk.html" in old[0]
    with monkeypatch.context() as m:
        (crash_at_step if how[0] == "step" else crash_at_rename)(m, how[1])
        with pytest.raises(Crash):
            _run(_small(tmp_path, seed=5), tmp_path, force=True)
    recover(out)
    assert _risk_view(out) == (new if how == ("step", "switched") else old) and leftovers(out) == []
    assert (out / ".risk" / "meta.json").exists()  # the chunks (working files) are kept for a resume
    again = _run(_small(tmp_path, seed=5), tmp_path)  # resumes: the interrupted run's chunks are reused
    assert _risk_view(out) == new and again.doc["run"]["ran"] == 0


def test_folder_of_an_older_version_drops_its_stale_pictures(tmp_path, monkeypatch, results):
    """A run folder without a manifest (older laser-hazard): with --force its named outputs
    are replaced or dropped (no old plan.png beside a new report), other files kept."""
    from hazard.pictures.figures import FIXED_NAMES

    monkeypatch.setattr(cli, "_analyse", lambda args, err: results["plate"])
    out = tmp_path / "o"
    out.mkdir()
    for n in ("report.json", "observers.csv", FIXED_NAMES[0], "notes.txt"):
        (out / n).write_bytes(b"older " + n.encode())
    code, _, err = run("run", "plate", "-o", out, "--quiet")
    assert code == 2 and "exists: pass --force" in err
    assert run("run", "plate", "-o", out, "--quiet", "--force")[0] == 0
    names = set(os.listdir(out))
    assert FIXED_NAMES[0] not in names and "notes.txt" in names and (out / "report.json").read_bytes()[:1] == b"{"
    assert "notes.txt" not in json.loads((out / MANIFEST).read_text())["files"]


def test_leftovers_of_the_older_version_are_recovered(tmp_path):
    """Before this helper, write_outputs left ``.o.<8 chars>.tmp`` (files) and
    ``.o.<8 chars>.old/d`` (the old folder): put back when OUT is missing, then removed."""
    out = tmp_path / "o"
    (tmp_path / ".o.ab_cd123.old" / "d").mkdir(parents=True)
    (tmp_path / ".o.ab_cd123.old" / "d" / "report.json").write_bytes(b"old")
    (tmp_path / ".o.zz9_0000.tmp").mkdir()
    (tmp_path / ".o.zz9_0000.tmp" / "report.json").write_bytes(b"new, unfinished")
    (tmp_path / ".o.keepme00.tmp" / "sub").mkdir(parents=True)  # not what the old version left: untouched
    recover(out)
    assert snapshot(out) == {"report.json": b"old"} and leftovers(out) == [".o.keepme00.tmp"]


@pytest.mark.parametrize("step", STEPS)
def test_hazard_report_interrupted_keeps_the_run_whole(tmp_path, monkeypatch, results, step):
    monkeypatch.setattr(cli, "_analyse", lambda args, err: results["plate"])
    out = tmp_path / "o"
    assert run("run", "plate", "-o", out, "--quiet")[0] == 0
    old = snapshot(out)
    with monkeypatch.context() as m:
        crash_at_step(m, step)
        with pytest.raises(Crash):
            run("report", out, "--quiet")
    recover(out)
    now = snapshot(out)
    pages = {n: now.get(n) for n in ("map.html", "report.html")}  # both pages or neither
    assert leftovers(out) == [] and now == (old if step != "switched" else {**old, **pages})
    assert ("report.html" in now) == ("map.html" in now) == (step == "switched")


def plate_study(powers):
    """A grid study of the bundled plate over ``powers`` [W]."""
    from hazard.drivers.study import Parameter, Study

    return Study(name="t", scene="plate", kind="grid", parameters=(Parameter("laser.power_w", values=powers),))


def study_view(out):
    """A study folder's visible file names and its results.csv bytes."""
    return sorted(p.name for p in out.iterdir() if not p.name.startswith(".")), (out / "results.csv").read_bytes()


@pytest.mark.parametrize("step", ["moved", pytest.param("switched", marks=pytest.mark.slow)])
def test_hazard_study_interrupted_keeps_one_whole_summary(tmp_path, monkeypatch, step):
    from hazard.drivers.study import run_study

    study, view = plate_study, study_view
    out = tmp_path / "o"
    run_study(study((10.0,)), out, serial=True)
    old = view(out)
    with monkeypatch.context() as m:
        crash_at_step(m, step)
        with pytest.raises(Crash):
            run_study(study((10.0, 1000.0)), out, serial=True, force=True)
    recover(out)
    assert leftovers(out) == [] and len(list((out / "scenarios").glob("*.json"))) == 2  # the scenarios stay for a resume
    if step == "moved":
        assert view(out) == old
    run_study(study((10.0, 1000.0)), out, serial=True)  # resumes: nothing to run again
    assert view(out)[1].count(b"\n") == old[1].count(b"\n") + 1


def test_without_hard_links_kept_files_are_copied(tmp_path, monkeypatch):
    out = tmp_path / "o"
    write_set(out, OLD)
    write_set(out, {"keepout.png": b"k"}, command="render")

    def no_link(a, b, **kw):
        raise OSError(1, "Operation not permitted")

    monkeypatch.setattr(os, "link", no_link)
    write_set(out, NEW, overwrite=True)
    assert snapshot(out) == {**NEW, "keepout.png": b"k"} and leftovers(out) == []


def test_current_folder_is_refused_with_a_clear_error(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    for bad in (".", "..", str(tmp_path)):
        with pytest.raises(OutputFolderError, match="current folder .* cannot be replaced as one unit"):
            write_set(bad, NEW)
    write_set("o", NEW)  # relative names work
    assert snapshot(tmp_path / "o") == NEW and leftovers(tmp_path / "o") == []
    with output_unit("o", command="run", overwrite=True) as unit:
        (unit.stage / "a.csv").write_bytes(b"a")
    assert unit.final(unit.stage / "a.csv") == Path("o") / "a.csv"  # printed as the user gave it


def test_hazard_run_says_what_it_recovered(tmp_path, monkeypatch, results):
    monkeypatch.setattr(cli, "_analyse", lambda args, err: results["plate"])
    out = tmp_path / "o"
    assert run("run", "plate", "-o", out, "--quiet")[0] == 0
    old = snapshot(out)
    with monkeypatch.context() as m:
        crash_at_step(m, "moved")
        with pytest.raises(Crash):
            run("run", "binoculars", "-o", out, "--quiet", "--force")
    assert not out.exists()
    code, _, err = run("run", "plate", "-o", out, "--quiet")  # recovered first, then refused: its outputs are back
    assert code == 2 and "restored the previous outputs after an interrupted switch" in err and snapshot(out) == old


def test_force_into_another_scenes_folder_replaces_the_runs_set(tmp_path, monkeypatch, results):
    """Issue 31 item 6: ``--force`` into a folder of another scene. The earlier run wrote
    hazard_local_frame.tif (a scene with a ground grid); the new scene writes none: the
    stale grid goes (the new report says it was not written, and it is not there), while
    files hazard did not write and another command's pictures stay, each said on stdout."""
    from hazard.outputs import map_outputs

    monkeypatch.setattr(cli, "_analyse", lambda args, err: results["plate"])
    real = map_outputs.map_files
    out = tmp_path / "o"
    with monkeypatch.context() as m:  # the other scene's set: its map outputs include the grid
        m.setattr(map_outputs, "map_files", lambda result: ({**real(result)[0], "hazard_local_frame.tif": b"II*\0other scene"},
                                                             real(result)[1]))
        assert run("run", "plate", "-o", out, "--quiet")[0] == 0
    assert (out / "hazard_local_frame.tif").exists()
    write_set(out, {"keepout.png": b"k"}, command="render")
    (out / "notes.txt").write_text("not ours")
    (out / "zones.kml").write_bytes(b"<kml/> placed by another program")  # an output's name, not in the manifest
    code, stdout, _ = run("run", "plate", "-o", out, "--quiet", "--force")
    assert code == 0
    doc = json.loads((out / "report.json").read_text())
    assert "hazard_local_frame.tif" in doc["map_outputs"]["not_written"]
    assert not (out / "hazard_local_frame.tif").exists()  # its own stale file removed
    files = json.loads((out / MANIFEST).read_text())["files"]
    assert "hazard_local_frame.tif" not in files and files["keepout.png"] == "render"
    assert "notes.txt" not in files and "zones.kml" not in files
    assert (out / "notes.txt").read_text() == "not ours" and (out / "zones.kml").read_bytes().startswith(b"<kml/> placed")
    assert f"kept {out / 'notes.txt'} (not written by hazard: left as it was)" in stdout
    assert f"kept {out / 'zones.kml'} (not written by hazard: left as it was)" in stdout
    assert f"kept {out / 'keepout.png'} (written by hazard render before this run" in stdout
    assert "hazard_local_frame.tif" not in stdout


def test_force_says_which_foreign_file_a_new_output_replaced(tmp_path):
    out = tmp_path / "o"
    out.mkdir()
    (out / "report.json").write_text("someone else's")
    (out / "keep.txt").write_text("k")
    unit = write_set(out, NEW, force=True)
    assert unit.replaced_foreign == ["report.json"] and unit.kept == {"keep.txt": ""}
    assert snapshot(out) == {**NEW, "keep.txt": b"k"}
    unit = write_set(out, {"report.json": b"3"}, overwrite=True, force=True)  # the run's own table goes: not "kept"
    assert unit.replaced_foreign == [] and unit.kept == {"keep.txt": ""}


_NAMES = st.sampled_from(["report.json", "observers.csv", "plan.png", "hazard.tif", "keepout.png", "notes.txt", "a.csv"])
_STEPS_OWN = st.lists(st.tuples(st.sampled_from(["run", "render", "foreign"]), st.sets(_NAMES, min_size=1, max_size=4)),
                      min_size=1, max_size=6)


def _check_ownership(out: Path, steps) -> None:
    """Random writes by two commands and by another program, each command with --force:
    after each, the command's new set is there, its own stale files are gone, every other
    file stays byte for byte, and ``kept`` / ``replaced_foreign`` name exactly the
    survivors it did not write and the foreign files it overwrote (the reference is a dict
    of owners kept in the test, not the manifest)."""
    owner: dict = {}  # name -> "run" / "render" / "" (another program)
    content: dict = {}
    for k, (who, names) in enumerate(steps):
        if who == "foreign":
            out.mkdir(parents=True, exist_ok=True)
            for n in names:
                if n not in owner:  # another program writes only new names
                    (out / n).write_bytes(f"foreign {k} {n}".encode())
                    owner[n], content[n] = "", f"foreign {k} {n}".encode()
            continue
        files = {n: f"{who} {k} {n}".encode() for n in names}
        unit = write_set(out, files, command=who, overwrite=True, force=True)
        replaced = sorted(n for n in names if owner.get(n) == "")
        for n in [n for n, o in owner.items() if o == who and n not in names]:
            del owner[n], content[n]  # the command's own stale file: removed
        kept = {n: o for n, o in sorted(owner.items()) if n not in names}
        owner.update({n: who for n in names})
        content.update(files)
        assert unit.replaced_foreign == replaced
        assert unit.kept == kept
        assert snapshot(out) == content and leftovers(out) == []
        listed = json.loads((out / MANIFEST).read_text())["files"]
        assert listed == {n: o for n, o in owner.items() if o}


@settings(derandomize=True, deadline=None, max_examples=15)
@given(steps=_STEPS_OWN)
def test_property_force_replaces_only_its_own_set(tmp_path_factory, steps):
    _check_ownership(tmp_path_factory.mktemp("own") / "o", steps)


@pytest.mark.slow
@settings(derandomize=True, deadline=None, max_examples=300)
@given(steps=_STEPS_OWN)
def test_property_force_replaces_only_its_own_set_many(tmp_path_factory, steps):
    _check_ownership(tmp_path_factory.mktemp("own") / "o", steps)


def test_other_commands_files_from_another_source_never_mix(tmp_path):
    """A render of scene A beside a run of scene B: refused without --force, dropped (and
    listed) with it; of the same scene, kept. Units without a source check nothing."""
    out = tmp_path / "o"
    write_set(out, OLD, source="sha256:A")
    write_set(out, {"keepout.png": b"k"}, command="render", source="sha256:A")
    unit = write_set(out, NEW, overwrite=True, source="sha256:A")  # the same scene again: the render stays
    assert unit.dropped_stale == [] and unit.kept == {"keepout.png": "render"}
    assert json.loads((out / MANIFEST).read_text())["sources"] == {"render": "sha256:A", "run": "sha256:A"}
    with pytest.raises(OutputFolderError, match=r"files of hazard render \(keepout.png\) made from another input: pass --force"):
        write_set(out, NEW, overwrite=True, source="sha256:B")
    assert snapshot(out) == {**NEW, "keepout.png": b"k"} and leftovers(out) == []
    (out / "notes.txt").write_text("not ours")
    unit = write_set(out, {"report.json": b"B"}, overwrite=True, force=True, source="sha256:B")
    assert unit.dropped_stale == ["keepout.png"] and unit.kept == {"notes.txt": ""}
    assert snapshot(out) == {"report.json": b"B", "notes.txt": b"not ours"}
    doc = json.loads((out / MANIFEST).read_text())
    assert doc["files"] == {"report.json": "run"} and doc["sources"] == {"run": "sha256:B"}
    unit = write_set(out, {"lobe.gif": b"g"}, command="render", force=True)  # no source given: nothing is checked or dropped
    assert unit.dropped_stale == [] and snapshot(out)["report.json"] == b"B"


def test_hazard_run_of_another_scene_drops_its_render_and_page(tmp_path, monkeypatch, results):
    """The review board never gets scene A's 3-D render or page beside scene B's report."""
    monkeypatch.setattr(cli, "_analyse", lambda args, err: results[os.path.basename(args.scene)])
    out = tmp_path / "o"
    assert run("run", "plate", "-o", out, "--quiet")[0] == 0
    write_set(out, {"keepout.png": b"plate render"}, command="render", source=cli._scene_source("plate"))
    code, stdout, _ = run("report", out, "--quiet")
    assert code == 0 and json.loads((out / MANIFEST).read_text())["files"]["report.html"] == "report"
    code, _, err = run("run", "binoculars", "-o", out, "--quiet")
    assert code == 2 and "--force" in err  # refused (its own report.json is there)
    code, _, err = run("render", "binoculars", "-o", out, "--quiet")  # another command, another scene: refused before any work
    assert code == 2 and "files of hazard report (map.html, report.html) and hazard run (observers.csv, report.json" in err
    assert "made from another input: pass --force" in err
    code, stdout, _ = run("run", "binoculars", "-o", out, "--quiet", "--force")
    assert code == 0
    assert f"removed {out / 'keepout.png'} (written by hazard render from another scene)" in stdout
    assert f"removed {out / 'report.html'} (written by hazard report from another scene)" in stdout
    assert f"removed {out / 'map.html'} (written by hazard report from another scene)" in stdout
    assert not (out / "keepout.png").exists() and not (out / "report.html").exists()
    doc = json.loads((out / MANIFEST).read_text())
    assert doc["sources"] == {"run": cli._scene_source("binoculars")} != {"run": cli._scene_source("plate")}
    # the same scene again keeps a render of it
    write_set(out, {"keepout.png": b"binoculars render"}, command="render", source=cli._scene_source("binoculars"))
    code, stdout, _ = run("run", "binoculars", "-o", out, "--quiet", "--force")
    assert code == 0 and (out / "keepout.png").read_bytes() == b"binoculars render" and "removed" not in stdout
