"""Progress bars (issue 12, item 3): drawn on stderr only when it is a terminal, never in
pipes, files or tests; --quiet turns them off; each long loop reports its steps."""

import io
import sys

import numpy as np
import pytest

import brdfmodels as bm
import hazard
import scenes
from brdfmodels import fitting, validation
from hazard.cli import main
from hazard.progress import progress_callback, progress_to, terminal_bar
from hazard.drivers.study import Parameter, Study, progress_bar, run_study


class Terminal(io.StringIO):
    """A stream that says it is a terminal."""

    def isatty(self):
        return True


@pytest.fixture
def no_tqdm(monkeypatch):
    monkeypatch.setitem(sys.modules, "tqdm", None)  # import tqdm raises ImportError: the plain bar


def test_no_bar_when_stderr_is_not_a_terminal(tmp_path, capsys):
    bar = terminal_bar(3, "steps")  # default stream: sys.stderr, captured here (not a terminal)
    for _ in range(3):
        bar.update()
    bar.close()
    assert bar.n == 3 and capsys.readouterr().err == ""
    err = io.StringIO()
    code = main(["run", "plate", "-o", str(tmp_path / "o")], stdout=io.StringIO(), stderr=err)
    # the stage lines only: no bar, no carriage return
    assert code == 0 and "\r" not in err.getvalue() and "keep-out lobe" not in err.getvalue()
    assert all(line.startswith("hazard: ") for line in err.getvalue().splitlines())


def test_plain_bar_on_a_terminal(no_tqdm, monkeypatch):
    term = Terminal()
    with terminal_bar(4, "frames", stream=term, leave=True) as bar:
        bar.update(3)
    text = term.getvalue()
    assert "\rframes [" in text and "3/4" in text and text.endswith("\n")
    monkeypatch.setattr(sys, "stderr", Terminal())  # the default stream is a terminal now
    with terminal_bar(2, "drawn") as bar:
        bar.update()
    with progress_to(None), terminal_bar(2, "off") as bar:  # turned off (--quiet)
        bar.update()
    assert "drawn [" in sys.stderr.getvalue() and "off" not in sys.stderr.getvalue()


def test_tqdm_bar_on_a_terminal():
    pytest.importorskip("tqdm")
    term = Terminal()
    show = progress_callback("scenarios", unit="scenario", stream=term)
    for done in (0, 1, 3):
        show(done, 3)
    assert "scenarios" in term.getvalue() and "3/3" in term.getvalue()


def test_run_draws_keepout_bars_on_a_terminal_and_quiet_silences(tmp_path, no_tqdm):
    term = Terminal()
    code = main(["run", "plate", "-o", str(tmp_path / "a")], stdout=io.StringIO(), stderr=term)
    assert code == 0 and "\rkeep-out lobe plate [" in term.getvalue() and "hazard: keepout..." in term.getvalue()
    term = Terminal()
    code = main(["run", "plate", "-o", str(tmp_path / "b"), "--quiet"], stdout=io.StringIO(), stderr=term)
    assert code == 0 and term.getvalue() == ""


def test_keepout_bar_counts_refinement_levels(no_tqdm):
    scene = scenes.load(scenes.example_path("plate"))
    term = Terminal()
    with progress_to(term):
        res = hazard.analyze(scene)
    levels = scene.spec.analysis.refine_levels
    draws = [d for d in term.getvalue().split("\r") if d.startswith("keep-out lobe plate")]
    counts = [int(d.split("] ")[1].split("/")[0]) for d in draws]
    assert counts[0] == 0 and 1 <= counts[-1] <= levels + 1 and counts == sorted(counts)
    assert res.targets[0].static_lobe.max_range_m > 0


def test_study_bar_only_on_a_terminal(tmp_path, no_tqdm):
    study = Study(name="t", scene="plate", kind="grid", parameters=(Parameter("laser.power_w", values=(10.0, 100.0)),))
    piped = io.StringIO()
    run_study(study, tmp_path / "a", serial=True, progress=progress_bar(piped))
    assert piped.getvalue() == ""
    term = Terminal()
    run_study(study, tmp_path / "b", serial=True, progress=progress_bar(term))
    text = term.getvalue()
    assert "2/2" in text and "keep-out lobe" not in text  # one bar for the study, none per scenario


def test_fit_loops_report_progress(monkeypatch):
    rng = np.random.default_rng(0)
    truth = bm.create("torrance-sparrow-5", kb=5.708, kr=2.240, a=0.452, b=-58.722, kd=0.220)
    wi = bm.spherical_to_vector(rng.uniform(0, 1.2, 100), rng.uniform(-np.pi, np.pi, 100))
    wo = bm.spherical_to_vector(rng.uniform(0, 1.2, 100), rng.uniform(-np.pi, np.pi, 100))
    calls = []
    fitting.fit_ts5(wi, wo, truth.evaluate(wi, wo), maxeval=300, xtol_rel=1e-4, progress=lambda d, t: calls.append((d, t)))
    budget = 300 + fitting.TS5_POLISH_MAXEVAL
    assert calls[0] == (fitting.PROGRESS_EVERY, budget) and calls[-1] == (budget, budget)
    assert [d for d, _ in calls] == sorted(d for d, _ in calls)
    samples = validation.protocol_samples(pixels=(16, 16))
    calls.clear()
    fitting.fit_dynamic_sh(samples, bm.SHBasis(4, 2, 2, 0), [0.0, 5.0, 10.0], state="time_s", progress=lambda d, t: calls.append((d, t)))
    assert calls == [(1, 3), (2, 3), (3, 3)]
    calls.clear()
    validation.choose_sh_basis(samples, lh_maxes=(2, 4), mh_maxes=(0, 4), fanouts=(0.6,), progress=lambda d, t: calls.append((d, t)))
    assert calls == [(0, 3), (1, 3), (2, 3), (3, 3)]  # lh 2 with mh 4 is skipped (mh > lh): 3 settings
    calls.clear()
    stub = type("Fit", (), {"relative_rms": 0.1, "evaluations": 10, "fit_time_s": 0.01})
    monkeypatch.setattr(fitting, "fit_ts5", lambda *a, **k: stub)  # the comparison's loop, not its fits
    fitting.compare_ts5_methods(wi, wo, truth.evaluate(wi, wo), budgets=(100, 200), seeds=(0,), methods=["crs2", "esch"],
                                progress=lambda d, t: calls.append((d, t)))
    assert calls == [(1, 4), (2, 4), (3, 4), (4, 4)]
