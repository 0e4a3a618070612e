"""The ``hazard`` command's stderr holds only its own lines.

Its own lines start ``hazard: `` (stage lines, warnings, notes) or ``hazard <verb>: ``
(an error, a summary); nothing else: no Python warning of a dependency with its source
line, no Dask logger line, no VTK log with terminal escape codes. The bundled examples run
as a user runs them, in a subprocess (``python -m hazard``, stderr a pipe, not a terminal).
"""

from __future__ import annotations

import importlib.util
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

import hazard
from tests._scene_text import PLATE_AT_50M

ROOT = Path(hazard.__file__).resolve().parents[1]
OWN = re.compile(r"^hazard( [a-z]+)?: \S")  # the tool's own line


def _hazard(*argv, cwd, timeout=600):
    env = {**os.environ, "PYTHONPATH": str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", "")}
    env.pop("PYTHONWARNINGS", None)
    p = subprocess.run([sys.executable, "-m", "hazard", *map(str, argv)], cwd=cwd, env=env, capture_output=True, text=True,
                       timeout=timeout)
    return p.returncode, p.stdout, p.stderr


def _foreign(stderr: str) -> list:
    return [ln for ln in stderr.splitlines() if ln.strip() and not OWN.match(ln)]


# the shared plate scene on a [site] whose heights are over the EGM96 geoid (its grid is not installed here)
EGM96_SCENE = PLATE_AT_50M + '[site]\norigin = [35.0, -106.0, 1500.0]\nvertical = "egm96"\n'


def test_quick_runs_write_only_their_own_lines(tmp_path):
    for argv, code in ((["validate", "binoculars"], 0), (["run", "plate", "-o", tmp_path / "plate"], 0),
                       (["mpe", "--wavelength-nm", "1064", "--duration-s", "10"], 0), (["validate", "nope.toml"], 2)):
        got, out, err = _hazard(*argv, cwd=tmp_path)
        assert got == code, (argv, err)
        assert not _foreign(err), (argv, _foreign(err))
        assert "\x1b[" not in err


@pytest.mark.skipif(importlib.util.find_spec("pyproj") is None, reason="pyproj (the geo extra) is not installed")
def test_missing_geoid_grid_is_one_line(tmp_path):
    """Without PROJ's EGM96 grid the scene is refused in one line naming the grid; pyproj's
    own "Best transformation is not available" warning is not shown beside it."""
    import pyproj

    if any(pyproj.datadir.get_data_dir() and (Path(d) / "us_nga_egm96_15.tif").exists()
           for d in pyproj.datadir.get_data_dir().split(os.pathsep)):
        pytest.skip("the EGM96 grid is installed here: the scene loads")
    (tmp_path / "egm.toml").write_text(EGM96_SCENE)
    got, _, err = _hazard("validate", "egm.toml", cwd=tmp_path)
    assert got == 2 and len(err.splitlines()) == 1 and "us_nga_egm96_15.tif is not installed" in err, err
    assert not _foreign(err)


def test_a_dependency_warning_is_one_plain_line(tmp_path):
    """Warnings raised inside a dependency during a command become one 'hazard: warning:'
    line each, naming the package, the first of each kind only (a stand-in package under a
    site-packages folder warns twice and overflows numpy twice, through a sitecustomize)."""
    pkg = tmp_path / "site-packages" / "fakedep"
    pkg.mkdir(parents=True)
    (pkg / "__init__.py").write_text(
        "import warnings\nimport numpy as np\n\n\ndef noisy():\n"
        "    warnings.warn('the frobnicator is deprecated', DeprecationWarning)\n"
        "    warnings.warn('the frobnicator is deprecated', DeprecationWarning)\n"
        "    np.exp(np.array([1e4]))\n    np.exp(np.array([2e4]))\n")
    (tmp_path / "sitecustomize.py").write_text(
        "import fakedep\nimport hazard.physics.mpe as m\n_real = m.ocular_mpe\n\n\n"
        "def ocular_mpe(*a, **k):\n    fakedep.noisy()\n    return _real(*a, **k)\n\n\nm.ocular_mpe = ocular_mpe\n")
    env_path = os.pathsep.join([str(tmp_path), str(tmp_path / "site-packages"), str(ROOT)])
    env = {**os.environ, "PYTHONPATH": env_path, "PYTHONWARNINGS": "default"}
    p = subprocess.run([sys.executable, "-m", "hazard", "mpe", "--wavelength-nm", "1064", "--duration-s", "10"], cwd=tmp_path,
                       env=env, capture_output=True, text=True, timeout=300)
    assert p.returncode == 0, p.stderr
    assert p.stderr.splitlines() == ["hazard: warning: fakedep DeprecationWarning: the frobnicator is deprecated",
                                     "hazard: warning: fakedep RuntimeWarning: overflow encountered in exp"], p.stderr
    # called from Python (main(argv)), the warnings are the caller's to handle: raised as usual
    code = ("import io, warnings, fakedep, hazard.cli\nwith warnings.catch_warnings(record=True) as w:\n"
            "    warnings.simplefilter('always')\n    hazard.cli.main(['mpe', '--wavelength-nm', '1064', '--duration-s', '10'], "
            "stdout=io.StringIO(), stderr=io.StringIO())\nprint(sorted({x.category.__name__ for x in w}))\n")
    p = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, env=env, capture_output=True, text=True, timeout=300)
    assert p.stdout.strip() == "['DeprecationWarning', 'RuntimeWarning']", (p.stdout, p.stderr)


@pytest.mark.slow
@pytest.mark.skipif(importlib.util.find_spec("pyvista") is None, reason="pyvista (the render extra) is not installed")
def test_render_without_a_display_is_clean(tmp_path):
    """No 'bad X server connection' with raw escape codes from VTK off-screen."""
    env_display = os.environ.pop("DISPLAY", None)
    try:
        got, _, err = _hazard("render", "plate", "-o", tmp_path / "r", "--no-animation", cwd=tmp_path)
    finally:
        if env_display is not None:
            os.environ["DISPLAY"] = env_display
    assert got == 0, err
    assert not _foreign(err) and "\x1b[" not in err and "X server" not in err, err


@pytest.mark.slow
@pytest.mark.skipif(importlib.util.find_spec("distributed") is None, reason="dask.distributed is not installed")
def test_risk_and_study_on_dask_are_clean(tmp_path):
    """The embedded Dask cluster starts and stops without a logger line on stderr."""
    got, _, err = _hazard("risk", "risk", "-o", tmp_path / "risk", "--draws", "64", "--sensitivity-draws", "0", cwd=tmp_path)
    assert got == 0, err
    assert not _foreign(err) and "distributed" not in err, err
    got, _, err = _hazard("study", "power_sweep", "-o", tmp_path / "study", cwd=tmp_path)
    assert got == 0, err
    assert not _foreign(err) and "distributed" not in err, err
