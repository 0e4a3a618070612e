"""Project-level checks: light imports, runnable examples, the CI script follows the README."""

import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
HEAVY = ("pyvista", "vtk", "matplotlib", "dask", "distributed", "trimesh", "embreex", "nlopt")


@pytest.mark.parametrize("package", ["brdfmodels", "hazard", "scenes"])
def test_import_stays_light(package):
    code = f"import sys, {package}; print(','.join(m for m in {HEAVY!r} if m in sys.modules))"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, cwd=ROOT)
    assert out.stdout.strip() == "", f"import {package} pulled in {out.stdout.strip()}"


def test_brdf_tour_example_runs(tmp_path):
    out = subprocess.run(
        [sys.executable, str(ROOT / "examples" / "brdf_tour.py"), "--out", str(tmp_path)],
        capture_output=True, text=True, check=True, cwd=ROOT,
    )
    assert "TS5 white paint" in out.stdout and "bounded 100.0000 %" in out.stdout
    assert (tmp_path / "brdf_tour.png").stat().st_size > 10_000


def test_ci_runs_the_readme_test_command():
    readme = (ROOT / "README.md").read_text()
    ci = (ROOT / ".ci" / "run").read_text()
    assert "<!-- test-command -->" in readme and "<!-- test-command -->" in ci
    block = readme.split("<!-- test-command -->", 1)[1].split("```bash", 1)[1].split("```", 1)[0].strip()
    assert block == 'python -m pip install -e ".[all]" && python -m pytest'


@pytest.mark.parametrize("script, args, expect", [
    ("accuracy_tables.py", [], "Thin-plate heating"),
    ("sh_order_table.py", ["--quick"], "held_out_log_rms"),
    ("static_vs_dynamic.py", [], "observers whose verdict changes"),
    ("power_sweep.py", ["--quick"], "power    10000 W"),
    ("monte_carlo.py", ["--samples", "4", "--serial"], "nohd_dynamic_m"),
    ("render_keepout.py", ["mirror_window", "--frames", "2"], "overview"),
])
def test_examples_run(script, args, expect, tmp_path):
    # CI runs a small version of each example a new user would run
    extra = [] if script == "accuracy_tables.py" else ["--out", str(tmp_path)]
    out = subprocess.run([sys.executable, str(ROOT / "examples" / script), *args, *extra], capture_output=True, text=True, check=True, cwd=ROOT)
    assert expect in out.stdout


def test_every_package_is_in_the_wheel():
    """A sub-package missing from pyproject's list installs nowhere but in editable mode."""
    import tomllib

    listed = set(tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]["packages"])
    found = {".".join(p.parent.relative_to(ROOT).parts) for top in ("brdfmodels", "scenes", "hazard")
             for p in (ROOT / top).rglob("__init__.py")}
    assert found <= listed, f"not in [tool.setuptools] packages: {sorted(found - listed)}"
