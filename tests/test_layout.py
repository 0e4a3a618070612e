"""The code layout the README draws is the one on disk, and its layers import downward only
(issue 35 item 3).

``hazard`` is five sub-packages in layers, each importing only from layers below it (module
and function level, read from the source with ast): ``physics`` (safety limits and optics) <
``pipeline`` (declared stages, results, verdict) < ``outputs`` (report, review page, maps) <
``pictures`` < ``drivers`` (study, convergence, risk) < the command line (``hazard.cli``).
The README's "Code layout" diagram names every module of every layer; a module added,
moved or removed without the diagram fails here, and so does an import up the layers.
"""

from __future__ import annotations

import ast
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
LAYERS = ("physics", "pipeline", "outputs", "pictures", "drivers")
SHARED = {"hazard.progress", "hazard.canvas"}  # progress bars and backend-free figures: utilities every layer may use
TOP = {"hazard", "hazard.__main__", "hazard.cli", "hazard.cli_units", "hazard._cli_env", "hazard._noise"}


def _diagram() -> dict:
    """Layer -> the module names the README's code-layout diagram lists for it: a line
    ``  <layer>/  mod mod sub/ ...`` and its continuation lines (indented further, no
    folder name of their own)."""
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    section = text.split("## Code layout", 1)[1].split("\n## ", 1)[0]
    block = section.split("```text", 1)[1].split("```", 1)[0]
    out, layer = {}, None
    for line in block.splitlines():
        m = re.match(r"^  (\w+)/\s+(.*)$", line)
        if m and m.group(1) in LAYERS:
            layer, names = m.group(1), m.group(2)
        elif layer and re.match(r"^ {6,}\S", line):
            names = line
        else:
            layer = None
            continue
        out.setdefault(layer, set()).update(n.rstrip("/") for n in names.split())
    return out


def _disk() -> dict:
    """Layer -> its modules and sub-packages on disk (``__init__`` left out)."""
    out = {}
    for layer in LAYERS:
        folder = ROOT / "hazard" / layer
        out[layer] = {p.stem for p in folder.glob("*.py") if p.stem != "__init__"} | \
                     {p.name for p in folder.iterdir() if p.is_dir() and (p / "__init__.py").exists()}
    return out


def test_the_readme_diagram_names_every_module_of_every_layer():
    drawn, disk = _diagram(), _disk()
    assert set(drawn) == set(LAYERS) == {p.name for p in (ROOT / "hazard").iterdir()
                                         if p.is_dir() and (p / "__init__.py").exists() and p.name != "studies"}
    for layer in LAYERS:
        assert drawn[layer] == disk[layer], (layer, sorted(drawn[layer] - disk[layer]), sorted(disk[layer] - drawn[layer]))


def _module(path: Path, root: Path = ROOT) -> str:
    parts = list(path.relative_to(root).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _imports(path: Path, root: Path = ROOT) -> set:
    """Project modules ``path`` imports anywhere in its source (absolute names)."""
    mod, out = _module(path, root), set()
    base = mod.split(".") if path.name == "__init__.py" else mod.split(".")[:-1]
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            out |= {a.name for a in node.names}
        elif isinstance(node, ast.ImportFrom):
            head = base[: len(base) - (node.level - 1)] if node.level else []
            name = ".".join(head + ([node.module] if node.module else []))
            out |= {name} | {f"{name}.{a.name}" for a in node.names}
    return {m for m in out if m == "hazard" or m.startswith("hazard.")}


def layer_of(module: str):
    """The layer index of a module (None for the shared utilities and the package root)."""
    parts = module.split(".")
    if len(parts) > 1 and parts[1] in LAYERS:
        return LAYERS.index(parts[1])
    if module in TOP:
        return len(LAYERS)
    return None


def upward_imports(root: Path) -> list:
    """``module -> imported`` for every import of a higher layer (or of the command line)."""
    bad = []
    for path in sorted((root / "hazard").rglob("*.py")):
        me = layer_of(_module(path, root))
        if me is None or me == len(LAYERS):
            continue
        for target in sorted(_imports(path, root)):
            to = layer_of(target)
            if target in SHARED or target == "hazard" or to is None:
                continue
            if to > me:
                bad.append(f"{_module(path, root)} -> {target}")
    return bad


def test_layers_import_downward_only():
    assert upward_imports(ROOT) == []


def test_the_layer_check_catches_an_upward_import(tmp_path, monkeypatch):
    (tmp_path / "hazard" / "physics").mkdir(parents=True)
    (tmp_path / "hazard" / "physics" / "x.py").write_text("def f():\n    from hazard.outputs import report\n")
    assert upward_imports(tmp_path) == ["hazard.physics.x -> hazard.outputs", "hazard.physics.x -> hazard.outputs.report"]


@pytest.mark.parametrize("layer", LAYERS)
def test_every_layer_says_what_it_holds(layer):
    doc = ast.get_docstring(ast.parse((ROOT / "hazard" / layer / "__init__.py").read_text(encoding="utf-8")))
    assert doc and len(doc) > 40
