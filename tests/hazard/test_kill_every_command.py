"""Fault injection for the commands the other files did not cover (issue 30, item 6):
``hazard render`` (an output folder, :func:`brdfmodels.output_sets.output_unit`) and
``hazard fit`` (files at separate paths, :class:`brdfmodels.output_sets.FileSet`), each
interrupted before, between and after every rename; ``hazard report`` and ``hazard study``
at the renames themselves; a fast twin of the slow ``hazard risk`` test.

run, risk (slow), study and report at the steps: tests/hazard/test_atomic_outputs.py; the
FileSet alone: tests/brdfmodels/test_file_set_kill.py.

A render here draws nothing: ``render.keepout`` and the figure writers are replaced by stubs
that write a tagged file each (the switch is the command's, not the renderer's; the real
render takes 40 s). ``hazard fit`` is killed for real (``os._exit`` in a child process: no
``except`` or ``finally`` runs) and the next ``hazard fit`` naming the same files, refused
for its input, must leave them all old or all new, with no temporary, backup or journal.
"""

from __future__ import annotations

import io
import os
import random
import subprocess
import sys
import textwrap
import types
from pathlib import Path

import pytest

from brdfmodels.output_sets import recover
from hazard import cli
from tests.hazard.test_atomic_outputs import STEPS, Crash, crash_at_rename, crash_at_step, leftovers, snapshot

ROOT = Path(__file__).resolve().parents[2]
HOWS = [("step", s) for s in STEPS] + [("rename", k) for k in (1, 2)]


def run(*argv):
    out, err = io.StringIO(), io.StringIO()
    return cli.main([str(a) for a in argv], stdout=out, stderr=err), out.getvalue(), err.getvalue()


# -- hazard render -------------------------------------------------------------------------
@pytest.fixture
def stub_render(monkeypatch):
    """``hazard render`` without drawing: each call writes keepout.png, keepout.vtm and
    overview.png holding the tag set in the returned dict (one file per kind of output)."""
    from hazard.pictures import figures, render

    tag = {"now": "old"}
    monkeypatch.setattr(cli, "_analyse", lambda args, err: types.SimpleNamespace(states=(), scene=types.SimpleNamespace(name="plate")))

    def keepout(result, stage, lobe_resolution_deg=None, force=False):
        paths = {"png": Path(stage) / "keepout.png", "vtm": Path(stage) / "keepout.vtm", "figures": {}}
        for k in ("png", "vtm"):
            paths[k].write_text(f"{tag['now']} {k}")
        return paths

    def write_figures(figs, stage):
        (Path(stage) / "overview.png").write_text(f"{tag['now']} overview")
        return [Path(stage) / "overview.png"]

    monkeypatch.setattr(render, "keepout", keepout)
    monkeypatch.setattr(figures, "run_figures", lambda result, progress=None, rendered=None: [])
    monkeypatch.setattr(figures, "write_figures", write_figures)
    return tag


def _render_set(tag):
    return {"keepout.png": f"{tag} png".encode(), "keepout.vtm": f"{tag} vtm".encode(), "overview.png": f"{tag} overview".encode()}


@pytest.mark.parametrize("how", HOWS)
def test_hazard_render_interrupted_keeps_one_whole_set(tmp_path, monkeypatch, stub_render, how):
    out = tmp_path / "o"
    assert run("render", "plate", "-o", out, "--quiet", "--no-animation")[0] == 0
    (out / "notes.txt").write_text("not ours")
    old = snapshot(out)
    assert old == {**_render_set("old"), "notes.txt": b"not ours"}
    stub_render["now"] = "new"
    with monkeypatch.context() as m:
        (crash_at_step if how[0] == "step" else crash_at_rename)(m, how[1])
        with pytest.raises(Crash):
            run("render", "plate", "-o", out, "--quiet", "--no-animation", "--force")
    recover(out)
    assert snapshot(out) == ({**_render_set("new"), "notes.txt": b"not ours"} if how == ("step", "switched") else old)
    assert leftovers(out) == []
    stub_render["now"] = "third"  # the next render completes and removes nothing of the crash's
    assert run("render", "plate", "-o", out, "--quiet", "--no-animation", "--force")[0] == 0
    assert snapshot(out) == {**_render_set("third"), "notes.txt": b"not ours"} and leftovers(out) == []


def test_hazard_render_recovers_a_crash_by_itself(tmp_path, monkeypatch, stub_render):
    """Between the two renames the folder is gone; the next ``hazard render`` puts the old
    set back before anything else (no explicit recover()), then writes its own."""
    out = tmp_path / "o"
    assert run("render", "plate", "-o", out, "--quiet", "--no-animation")[0] == 0
    stub_render["now"] = "new"
    with monkeypatch.context() as m:
        crash_at_step(m, "moved")
        with pytest.raises(Crash):
            run("render", "plate", "-o", out, "--quiet", "--no-animation", "--force")
    assert not out.exists() and [p.name.endswith(".old") for p in tmp_path.iterdir()].count(True) == 1
    code, _, err = run("render", "plate", "-o", out, "--quiet", "--no-animation")  # no --force: the restored set is its own
    assert code == 2 and "exists" in err and snapshot(out) == _render_set("old") and leftovers(out) == []


# -- hazard report and hazard study at the renames -------------------------------------------
def crash_at_switch_rename(monkeypatch, out: Path, k: int):
    """Crash at the ``k``-th rename of the switch of ``out`` (1: OUT -> .OUT.*.old, 2: the
    staging folder -> OUT); renames of anything else (a page's own atomic write) pass."""
    calls, real = [0], os.rename

    def rename(a, b):
        if any(Path(x).parent == out.parent and (Path(x).name == out.name or Path(x).name.startswith(f".{out.name}."))
               for x in (a, b)):
            calls[0] += 1
            if calls[0] == k:
                raise Crash(f"switch rename {k}")
        return real(a, b)

    monkeypatch.setattr(os, "rename", rename)


@pytest.fixture(scope="module")
def plate_result():
    import hazard
    import scenes

    return hazard.analyze(scenes.load(scenes.example_path("plate")), progress=None)


@pytest.mark.parametrize("k", (1, 2))
def test_hazard_report_interrupted_at_a_rename_keeps_the_run_whole(tmp_path, monkeypatch, plate_result, k):
    monkeypatch.setattr(cli, "_analyse", lambda args, err: plate_result)
    out = tmp_path / "o"
    assert run("run", "plate", "-o", out, "--quiet")[0] == 0
    old = snapshot(out)
    with monkeypatch.context() as m:
        crash_at_switch_rename(m, out, k)
        with pytest.raises(Crash):
            run("report", out, "--quiet")
    recover(out)
    assert snapshot(out) == old and leftovers(out) == []
    assert run("report", out, "--quiet")[0] == 0 and {"map.html", "report.html"} <= set(snapshot(out))


@pytest.mark.parametrize("k", (pytest.param(1, marks=pytest.mark.slow), 2))  # two studies each: 3-4 s at load 10
def test_hazard_study_interrupted_at_a_rename_keeps_one_whole_summary(tmp_path, monkeypatch, k):
    from hazard.drivers.study import run_study
    from tests.hazard.test_atomic_outputs import plate_study as study, study_view as view

    out = tmp_path / "o"
    run_study(study((10.0,)), out, serial=True)
    old = view(out)
    with monkeypatch.context() as m:
        crash_at_switch_rename(m, out, k)
        with pytest.raises(Crash):
            run_study(study((10.0, 1000.0)), out, serial=True, force=True)
    recover(out)
    assert view(out) == old and leftovers(out) == []


# -- hazard risk: the fast twin of test_atomic_outputs' slow risk test -----------------------
def _tiny_risk(seed):
    from tests.hazard.test_risk import _small

    text = _small(None, seed=seed).replace("draws = 120", "draws = 16").replace("sensitivity_draws = 32", "sensitivity_draws = 4")
    return text[:text.index("[uncertainty.map]")]


@pytest.mark.parametrize("how", [("rename", 2), pytest.param(("step", "switched"), marks=pytest.mark.slow)])
def test_hazard_risk_interrupted_keeps_one_whole_set_fast(tmp_path, monkeypatch, how):
    """16 draws, no map: the same assertions as the slow test on a run of 2 s."""
    from tests.hazard.test_atomic_outputs import _risk_view
    from tests.hazard.test_risk import _run

    _run(_tiny_risk(5), tmp_path, "ref")
    out = tmp_path / "out"
    _run(_tiny_risk(0), tmp_path)
    old, new = _risk_view(out), _risk_view(tmp_path / "ref")
    assert old[2] != new[2]
    with monkeypatch.context() as m:
        (crash_at_step if how[0] == "step" else crash_at_rename)(m, how[1])
        with pytest.raises(Crash):
            _run(_tiny_risk(5), tmp_path, force=True)
    recover(out)
    assert _risk_view(out) == (new if how == ("step", "switched") else old) and leftovers(out) == []


# -- hazard fit, killed for real ---------------------------------------------------------------
_FIT_CHILD = textwrap.dedent("""
    import os, sys
    import brdfmodels.output_sets as unit
    from hazard.cli import main
    kill_at, argv = sys.argv[1], sys.argv[2:]
    if kill_at == "writing":  # mid-write: the model's temporary written, the envelope's not yet
        import brdfmodels
        real_save, saved = brdfmodels.save, []
        def save(*a, **k):
            saved.append(1)
            if len(saved) == 2:
                os._exit(9)
            return real_save(*a, **k)
        brdfmodels.save = save
    def step(name):
        if name == kill_at:
            os._exit(9)  # a kill: no except, no finally, no cleanup
    unit._step = step
    sys.exit(main(argv))
""")


def _samples_csv(path):
    rng = random.Random(3)
    rows = ["theta_i_deg,phi_i_deg,theta_r_deg,phi_r_deg,brdf_per_sr"]
    for _ in range(60):
        rows.append(",".join(f"{x:.4f}" for x in (rng.uniform(0, 70), rng.uniform(-170, 170), rng.uniform(0, 80),
                                                   rng.uniform(-170, 170), 0.5 / 3.141592653589793)))
    path.write_text("\n".join(rows) + "\n")


def _files(folder):
    return {p.name: p.read_bytes() for p in sorted(folder.iterdir()) if p.is_file()}


@pytest.mark.parametrize("kill_at", ["files: rename 1", pytest.param("writing", marks=pytest.mark.slow),
                                     pytest.param("files: rename 0", marks=pytest.mark.slow),
                                     pytest.param("files: renamed", marks=pytest.mark.slow)])
def test_hazard_fit_killed_leaves_old_or_new_files(tmp_path, kill_at):
    """``hazard fit sh`` writing a model and an envelope (two paths) over an old pair, killed
    while fitting (temporaries written), before, between and after its renames. The next
    ``hazard fit`` naming the files (refused for its input, exit 2) finishes the switch:
    both old (rolled back) or both new (completed), nothing else left beside them."""
    out = tmp_path / "out"
    out.mkdir()
    _samples_csv(tmp_path / "t.csv")
    model, env = out / "m.json", out / "env.json"
    model.write_text("old model")
    env.write_text("old envelope")
    argv = ["fit", "sh", tmp_path / "t.csv", "-o", model, "--basis", "2,2,0,0", "--envelope", "sh", "--envelope-output", env,
            "--force", "--quiet"]
    child = subprocess.run([sys.executable, "-c", _FIT_CHILD, kill_at, *map(str, argv)], capture_output=True, text=True, timeout=240,
                           env={**os.environ, "PYTHONPATH": str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", "")})
    assert child.returncode == 9, child.stderr
    assert set(_files(out)) - {"m.json", "env.json"}  # the kill left temporaries, backups or journals
    (tmp_path / "bad.csv").write_text("theta_i_deg\n")
    code, stdout, err = run("fit", "sh", tmp_path / "bad.csv", "-o", model, "--envelope", "sh", "--envelope-output", env, "--force")
    assert code == 2 and stdout == "", err
    assert "hazard: note:" in err  # what the recovery did is said
    now = _files(out)
    assert set(now) == {"m.json", "env.json"}  # no temporary, backup or journal left
    if kill_at == "files: renamed":
        assert now["m.json"] != b"old model" and now["env.json"] != b"old envelope"  # completed: the new pair
        assert "completed" in err
    else:
        assert now == {"m.json": b"old model", "env.json": b"old envelope"}  # rolled back: the old pair
