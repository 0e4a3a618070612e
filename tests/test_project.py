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
    assert block == 'python -m pip install -e ".[all]" && python -m ruff check && python -m mypy && python -m pytest -n auto'


@pytest.mark.parametrize("script, args, expect", [
    ("accuracy_tables.py", [], "Thin-plate heating"),
    ("sh_order_table.py", ["--quick"], "held_out_log_rms"),
    ("static_vs_dynamic.py", [], "observers whose verdict changes"),
    pytest.param("power_sweep.py", ["--quick"], "power    10000 W", marks=pytest.mark.slow),  # a study: 10-15 s idle
    ("monte_carlo.py", ["--samples", "4", "--serial"], "nohd_dynamic_m"),
    ("render_keepout.py", ["mirror_window", "--frames", "2"], "overview"),
])
def test_examples_run(script, args, expect, tmp_path):
    # CI runs a small version of each example a new user would run
    extra = [] if script == "accuracy_tables.py" else ["--out", str(tmp_path)]
    out = subprocess.run([sys.executable, str(ROOT / "examples" / script), *args, *extra], capture_output=True, text=True, check=True, cwd=ROOT)
    assert expect in out.stdout


def _setuptools_config() -> dict:
    import tomllib

    return tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]


def test_every_package_is_in_the_wheel():
    """Packages are found, not listed (``[tool.setuptools.packages.find]``): the finder,
    given the include patterns of pyproject.toml, returns exactly the folders with an
    ``__init__.py`` of the three packages (never tests or examples), and no folder is mapped
    from elsewhere (a mapped sub-package cannot be found: hazard/studies is package data)."""
    from setuptools import find_packages

    config = _setuptools_config()
    find = config["packages"]["find"]
    assert "package-dir" not in config and find.get("namespaces") is False
    found = {".".join(p.parent.relative_to(ROOT).parts) for top in ("brdfmodels", "scenes", "hazard")
             for p in (ROOT / top).rglob("__init__.py")}
    assert {"hazard.pipeline", "hazard.drivers.risk"} <= found
    assert set(find_packages(str(ROOT), include=find["include"])) == found


def test_every_package_data_glob_matches_a_file():
    """A glob that matches nothing ships nothing and hides a missing file."""
    config = _setuptools_config()
    for package, globs in config["package-data"].items():
        folder = ROOT / package.replace(".", "/")
        for pattern in globs:
            assert list(folder.glob(pattern)), f"package-data {package}: {pattern!r} matches no file in {folder}"


def test_one_version_source_and_typed_markers():
    import tomllib

    import hazard

    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    assert "version" not in project and "version" in project["dynamic"]
    assert _setuptools_config()["dynamic"]["version"] == {"attr": "hazard.__version__"}
    assert project["license"] == "Apache-2.0"  # SPDX expression (setuptools >= 77)
    out = subprocess.run([sys.executable, "-m", "hazard", "--version"], capture_output=True, text=True, check=True, cwd=ROOT)
    assert out.stdout == f"hazard (laser-hazard) {hazard.__version__}\n"
    for top in ("brdfmodels", "scenes", "hazard"):
        assert (ROOT / top / "py.typed").is_file()
        assert "py.typed" in _setuptools_config()["package-data"][top]
