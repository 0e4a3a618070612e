"""Importing or calling the library changes no process-wide state (issue #35 item 4).

A user's session picks its own matplotlib backend and draws its own figure; then every
public module of brdfmodels, scenes and hazard is imported and the drawing entry points
run on a bundled example (plan and elevation views, time plots, the 3-D render when
pyvista is installed). The backend, the user's open figures, ``pyvista.OFF_SCREEN``,
numpy's error state and print options, the warnings filters, ``os.environ``, the root
logger, threadpoolctl's limits, the recursion limit, the locale and matplotlib's rcParams
must be what they were. It runs in a subprocess: pytest's own process has its state set
by pytest and by other tests. The CLI is the one place that makes its process headless
(:mod:`hazard._cli_env`); ``test_render_cli_and_static_scene`` and the ``--plot`` tests
show that it still renders.
"""

from __future__ import annotations

import ast
import json
import os
import pathlib
import subprocess
import sys

import pytest

pytest.importorskip("matplotlib")

ROOT = pathlib.Path(__file__).resolve().parents[1]
PACKAGES = ("brdfmodels", "scenes", "hazard")

_SCRIPT = r'''
import importlib, json, locale, logging, os, pathlib, pkgutil, sys, tempfile, warnings

import matplotlib
matplotlib.use("pdf")  # the user's backend: not Agg, available headless
import matplotlib.pyplot as plt
import numpy as np

plt.plot([0, 1], [1, 0])  # the user's own figure, drawn before the library is used
try:
    import pyvista
except ImportError:
    pyvista = None
try:
    import threadpoolctl
except ImportError:
    threadpoolctl = None


def state():
    root = logging.getLogger()
    return {
        "backend": matplotlib.get_backend().lower(),
        "figures": plt.get_fignums(),
        "pyvista.OFF_SCREEN": None if pyvista is None else bool(pyvista.OFF_SCREEN),
        "np.geterr": np.geterr(),
        "np.printoptions": repr(sorted(np.get_printoptions().items())),
        "warnings.filters": repr(warnings.filters),
        "os.environ": dict(os.environ),
        "root logger": [repr(root.handlers), root.level],
        "logger names": sorted(n for n, lg in logging.root.manager.loggerDict.items()
                               if isinstance(lg, logging.Logger) and (lg.handlers or lg.level)),
        "threadpools": None if threadpoolctl is None else sorted(
            (i["user_api"], i["internal_api"], i["filepath"], i["num_threads"]) for i in threadpoolctl.threadpool_info()),
        "recursionlimit": sys.getrecursionlimit(),
        "locale": locale.setlocale(locale.LC_ALL, None),
        "rcParams": repr(sorted((k, v) for k, v in matplotlib.rcParams.items() if k != "backend")),
    }


def walk():
    """Import every module of the packages; (imported, skipped: name -> why)."""
    imported, skipped = [], {}
    for top in sys.argv[1].split(","):
        pkg = importlib.import_module(top)
        imported.append(top)
        for info in pkgutil.walk_packages(pkg.__path__, top + "."):
            if info.name.rsplit(".", 1)[-1] == "__main__":  # runs the CLI
                continue
            try:
                importlib.import_module(info.name)
            except ImportError as exc:  # an optional extra not installed: named in the report
                skipped[info.name] = str(exc)
                continue
            imported.append(info.name)
    return imported, skipped


def draw(mode):
    """Draw by every path (``cheap``: small data) or a bundled example's every picture and
    render; (pictures, rendered)."""
    pictures, rendered = [], []
    if mode == "cheap":  # every way the library makes a figure, on small data
        from hazard import convergence, picture, plan_view, plots
        pictures.append(len(plots.ErrorTableDisplay.from_rows([{"t": 1, "e": 0.1}, {"t": 2, "e": 0.01}], "t", "e").png_bytes()))
        fig, axes = plan_view.two_panels(None, (4, 2))
        pictures.append(len(picture.compose(np.full((60, 80, 3), 200, np.uint8), [("a", "#ff0000", "patch")], ["title"])[0]))
        from hazard import study
        from types import SimpleNamespace
        rows = [dict({c: 0.1 / k for c in convergence.REL_ERROR_COLUMNS.values()}, knob="beam_samples", value=k, time_s=k)
                for k in (1, 2, 4)]
        runs = [{"error": None, "in:x": x, "nohd_static_m": x, "nohd_dynamic_m": 2 * x} for x in (1.0, 2.0)]
        with tempfile.TemporaryDirectory() as tmp:
            pictures.append(os.path.basename(str(convergence.plot(convergence.ConvergenceReport(rows, {}, 0.01), tmp + "/c.png"))))
            pictures.append(os.path.basename(str(study._plot(SimpleNamespace(name="s"), runs, pathlib.Path(tmp)))))
    else:  # the bundled example's every picture, and the 3-D render
        import hazard, scenes
        from hazard.pictures.figures import run_figures

        result = hazard.analyze(scenes.load(scenes.example_path(mode)), keep_history=True)
        pictures = sorted(run_figures(result))
        if pyvista is not None:
            from hazard import render
            with tempfile.TemporaryDirectory() as tmp:
                rendered = sorted(k for k, v in render.keepout(result, tmp).items() if os.path.exists(str(v)))
    return pictures, rendered


ours = tuple(sys.argv[1].split(","))
if sys.argv[3] == "-":  # the third-party modules the packages and the drawing import, in import order
    seen = set(sys.modules)
    walk()
    draw(sys.argv[2])
    print(json.dumps([m for m in sys.modules if m not in seen and m.split(".")[0] not in ours
                      and m.split(".")[0] not in sys.stdlib_module_names]))
    sys.exit(0)
# the dependencies' own import-time effects (scipy.special's and scipy.sparse's warnings
# filters, loggers of charset_normalizer and pyvista.plotting, scipy's OpenBLAS) are the
# user's baseline, not the library's doing
for name in json.loads(pathlib.Path(sys.argv[3]).read_text()):
    try:
        importlib.import_module(name)
    except Exception:  # a private submodule not importable on its own: its package brought it
        pass
before = state()
imported, skipped = walk()
after_import = state()
pictures, rendered = draw(sys.argv[2])
after_calls = state()
print(json.dumps({"before": before, "after_import": after_import, "after_calls": after_calls, "imported": imported,
                  "skipped": skipped, "pictures": pictures, "rendered": rendered}))
'''


def _run(mode, tmp_path):
    env = {k: v for k, v in os.environ.items() if k not in ("MPLBACKEND", "PYVISTA_OFF_SCREEN")}
    env["PYTHONPATH"] = str(ROOT)
    deps = tmp_path / "dependencies.json"
    for args in ([mode, "-"], [mode, str(deps)]):
        out = subprocess.run([sys.executable, "-c", _SCRIPT, ",".join(PACKAGES), *args], capture_output=True, text=True,
                             cwd=ROOT, env=env, timeout=600)
        assert out.returncode == 0, out.stderr[-4000:]
        if args[1] == "-":
            deps.write_text(out.stdout.strip().splitlines()[-1])
    return json.loads(out.stdout.strip().splitlines()[-1])


def _differences(a, b) -> dict:
    return {k: (a[k], b[k]) for k in a if a[k] != b[k]}


def _check_imports(run):
    assert run["before"]["backend"] == "pdf" and run["before"]["figures"] == [1]
    assert len(run["imported"]) > 100, run["imported"]  # the walk found the packages' modules
    assert not any(m.startswith("hazard.") and m.count(".") == 1 for m in run["skipped"]), run["skipped"]
    assert _differences(run["before"], run["after_import"]) == {}


_LIGHT = r'''
import json, os, sys
import matplotlib
matplotlib.use("pdf")
import matplotlib.pyplot as plt
import numpy as np
plt.plot([0, 1], [1, 0])
state = lambda: [matplotlib.get_backend().lower(), plt.get_fignums(), np.geterr(), dict(os.environ), "pyvista" in sys.modules]
before = state()
from hazard import plots
png = plots.ErrorTableDisplay.from_rows([{"t": 1, "e": 0.1}, {"t": 2, "e": 0.01}], "t", "e").png_bytes()
print(json.dumps([before, state(), png[:8] == b"\x89PNG\r\n\x1a\n"]))
'''


def test_a_display_keeps_the_users_backend_and_figures():
    """The fast check (the full one is slow): a user's ``pdf`` backend and open figure are
    kept when a Display draws a PNG (it once switched the backend to Agg)."""
    env = {k: v for k, v in os.environ.items() if k not in ("MPLBACKEND", "PYVISTA_OFF_SCREEN")}
    env["PYTHONPATH"] = str(ROOT)
    out = subprocess.run([sys.executable, "-c", _LIGHT], capture_output=True, text=True, cwd=ROOT, env=env, timeout=300)
    assert out.returncode == 0, out.stderr[-4000:]
    before, after, is_png = json.loads(out.stdout.strip().splitlines()[-1])
    assert before[:2] == ["pdf", [1]] and is_png
    assert after == before


@pytest.mark.slow
def test_importing_every_module_and_drawing_changes_no_global_state(tmp_path):
    """Every public module imported; a figure made by every drawing path (Display, two
    panels, composed picture, convergence and study plots) on small data."""
    run = _run("cheap", tmp_path)
    _check_imports(run)
    assert len(run["pictures"]) == 4 and run["pictures"][2:] == ["c.png", "summary.png"], run["pictures"]
    assert _differences(run["before"], run["after_calls"]) == {}


@pytest.mark.slow
def test_every_picture_and_the_render_of_an_example_change_no_global_state(tmp_path):
    """A bundled example's plan and elevation views, time plots and (pyvista installed)
    3-D render: the user's backend, figure and ``pyvista.OFF_SCREEN`` kept throughout."""
    run = _run("plate", tmp_path)
    _check_imports(run)
    assert {"plan.png", "elevation.png"} <= set(run["pictures"]), run["pictures"]
    assert any(p.startswith("nohd_time_") for p in run["pictures"]) and any(p.startswith("exposure_") for p in run["pictures"])
    if run["before"]["pyvista.OFF_SCREEN"] is not None:
        assert run["before"]["pyvista.OFF_SCREEN"] is False  # the user's setting, kept through the render
        assert {"keepout", "overview"} <= set(run["rendered"]), run["rendered"]
    assert _differences(run["before"], run["after_calls"]) == {}


def _scoped_lines(tree) -> set:
    """Lines inside ``with warnings.catch_warnings():`` blocks: a filter set there is
    undone when the block ends (scoped, not global)."""
    lines = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.With) and any(ast.unparse(i.context_expr) == "warnings.catch_warnings()" for i in node.items):
            lines.update(range(node.body[0].lineno, node.end_lineno + 1))
    return lines


def _calls(path: pathlib.Path):
    """(line, dotted name) of every call and assignment target in ``path``'s source, but
    the warnings filters of a ``catch_warnings`` block (restored at its end)."""
    tree = ast.parse(path.read_text(), str(path))
    scoped = _scoped_lines(tree)
    for node in ast.walk(tree):
        if isinstance(node, ast.Call) and node.lineno in scoped and ast.unparse(node.func).startswith("warnings."):
            continue
        if isinstance(node, ast.Call):
            yield node.lineno, ast.unparse(node.func)
        elif isinstance(node, (ast.Assign, ast.AugAssign)):
            for t in node.targets if isinstance(node, ast.Assign) else [node.target]:
                yield node.lineno, "=" + ast.unparse(t)
        elif isinstance(node, (ast.Import, ast.ImportFrom)):
            mod = node.module if isinstance(node, ast.ImportFrom) else None
            for a in node.names:
                yield node.lineno, "import " + (f"{mod}.{a.name}" if mod else a.name)


# calls and assignments that change process-wide state; the CLI's own module is exempt
_GLOBAL = ("matplotlib.use", "import matplotlib.pyplot", "=pv.OFF_SCREEN", "=pyvista.OFF_SCREEN", "np.seterr",
           "numpy.seterr", "warnings.filterwarnings", "warnings.simplefilter", "logging.basicConfig",
           "sys.setrecursionlimit", "locale.setlocale", "np.set_printoptions", "threadpool_limits", "os.putenv",
           "os.environ.update", "os.environ.setdefault", "=os.environ[", "logging.captureWarnings")


def test_no_library_source_changes_global_state():
    found = []
    for top in PACKAGES:
        for path in sorted((ROOT / top).rglob("*.py")):
            if path.name == "_cli_env.py":
                continue
            found += [f"{path.relative_to(ROOT)}:{line}: {name}" for line, name in _calls(path)
                      if any(name == g or name.startswith(g) for g in _GLOBAL)]
    assert found == []


def test_the_cli_environment_is_restored():
    """``hazard.cli.main`` called in a Python session: the headless settings hold for the
    command only (pyvista's switch too, when pyvista is imported)."""
    from hazard._cli_env import headless

    pv = sys.modules.get("pyvista")
    before = {k: os.environ.get(k) for k in ("MPLBACKEND", "PYVISTA_OFF_SCREEN")}
    off = None if pv is None else pv.OFF_SCREEN
    with headless():
        assert os.environ["MPLBACKEND"] == "Agg" and os.environ["PYVISTA_OFF_SCREEN"] == "true"
        assert pv is None or pv.OFF_SCREEN is True
    assert {k: os.environ.get(k) for k in before} == before
    assert pv is None or pv.OFF_SCREEN == off


def test_the_umask_is_read_without_setting_it(monkeypatch):
    """Outputs get the usual permissions (0666 minus the umask) from a mask read, not set
    and put back (a moment in which another thread's new file would get the mask 0)."""
    from brdfmodels.fileio import current_umask

    old = os.umask(0o027)
    try:
        assert current_umask() == 0o027
        os.umask(0o002)
        assert current_umask() == 0o002
    finally:
        os.umask(old)
    status = pathlib.Path("/proc/self/status")
    if not (status.exists() and "Umask:" in status.read_text()):
        pytest.skip("no Umask line in /proc/self/status (Linux < 4.7 or not Linux): the mask is set and put back")

    def refuse(mask):
        raise AssertionError(f"os.umask({mask:o}) called: the mask was set to read it")

    monkeypatch.setattr(os, "umask", refuse)
    assert current_umask() == old
