"""The packages' imports, read from the source (ast), never by importing it.

* no function-level import of a project module that closes a cycle with the module-level
  imports (a cycle hidden by moving one side into a function: issue 35);
* no cycle in the whole import graph (module and function level) but the one documented in
  ``ALLOWED_CYCLES``;
* no import of another module's private name (``from m import _x``, ``m._x``), and a private
  module (``brdfmodels._checks``) imported only inside its own package; the deprecated
  aliases ``brdfmodels._io`` / ``brdfmodels._unit`` not at all (``brdfmodels.fileio`` /
  ``brdfmodels.output_sets``).

Third-party imports inside functions (pyvista, rasterio, matplotlib, dask: heavy or
optional) are not project modules and are never counted. Each checker is also run on a small
package written into ``tmp_path`` that breaks its rule, so none of them can pass vacuously.
"""

from __future__ import annotations

import ast
import functools
from collections import deque
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("brdfmodels", "scenes", "hazard")
# (module, module): a cycle of the whole graph that is allowed, and why
ALLOWED_CYCLES = {
    # hazard.analyze imports the engine on first call so that `import hazard` stays light
    # (MPE and NOHD only); hazard.pipeline.analysis reads hazard.__version__ inside a function
    frozenset({"hazard", "hazard.pipeline.analysis"}),
}
DEPRECATED = {"brdfmodels._io", "brdfmodels._unit"}  # thin re-exports kept one release


def _modules(root: Path, packages) -> dict:
    """Dotted module name -> source path of every module of ``packages`` under ``root``."""
    out = {}
    for pkg in packages:
        for p in sorted((root / pkg).rglob("*.py")):
            parts = list(p.relative_to(root).with_suffix("").parts)
            if "templates" in parts:
                continue
            if parts[-1] == "__init__":
                parts = parts[:-1]
            out[".".join(parts)] = p
    return out


def _source_module(mod: str, path: Path, node: ast.ImportFrom) -> str:
    if node.level == 0:
        return node.module or ""
    base = mod.split(".") if path.name == "__init__.py" else mod.split(".")[:-1]
    base = base[: len(base) - (node.level - 1)]
    return ".".join(base + ([node.module] if node.module else []))


@functools.lru_cache(maxsize=None)
def _tree(path: Path, mtime_ns: int) -> ast.Module:
    """The parsed source of ``path`` (parsed once per version of the file)."""
    return ast.parse(path.read_text(encoding="utf-8"))


def _parse(path: Path) -> ast.Module:
    return _tree(path, path.stat().st_mtime_ns)


def _is_type_checking(node) -> bool:
    return isinstance(node, ast.If) and "TYPE_CHECKING" in ast.unparse(node.test)


def _imports(mods: dict):
    """(module-level edges {module: {module}}, function-level edges [(module, module, line)],
    every import statement [(module, node, source module or None)]) between project modules;
    imports under ``if TYPE_CHECKING`` never run and are left out."""
    top, inner, statements = {m: set() for m in mods}, [], []

    def targets(mod, path, node) -> set:
        if isinstance(node, ast.Import):
            names = [a.name for a in node.names]
        else:
            src = _source_module(mod, path, node)
            names = [f"{src}.{a.name}" if f"{src}.{a.name}" in mods else src for a in node.names]
        return {n for n in names if n in mods and n != mod}

    def visit(mod, path, body, in_function: bool) -> None:
        for node in body:
            if _is_type_checking(node):
                continue
            if isinstance(node, (ast.Import, ast.ImportFrom)):
                src = _source_module(mod, path, node) if isinstance(node, ast.ImportFrom) else None
                statements.append((mod, node, src))
                for t in targets(mod, path, node):
                    if in_function:
                        inner.append((mod, t, node.lineno))
                    else:
                        top[mod].add(t)
            function = isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda))
            for field in ("body", "orelse", "finalbody", "handlers"):
                sub = getattr(node, field, None)
                if isinstance(sub, list):
                    visit(mod, path, [n for n in sub if isinstance(n, ast.AST)], in_function or function)

    for mod, path in mods.items():
        visit(mod, path, _parse(path).body, False)
    return top, inner, statements


def _path(graph: dict, start: str, goal: str) -> list | None:
    """A shortest import chain start -> ... -> goal in ``graph`` (None: none)."""
    prev, queue = {start: None}, deque([start])
    while queue:
        m = queue.popleft()
        if m == goal:
            chain = []
            while m is not None:
                chain.append(m)
                m = prev[m]
            return chain[::-1]
        for n in sorted(graph.get(m, ())):
            if n not in prev:
                prev[n] = m
                queue.append(n)
    return None


def hidden_cycles(root: Path, packages) -> list[str]:
    """Function-level imports A -> B where B already imports A through module-level imports."""
    mods = _modules(root, packages)
    top, inner, _ = _imports(mods)
    out = []
    for a, b, line in sorted(inner):
        back = _path(top, b, a)
        if back:
            out.append(f"{mods[a].relative_to(root)}:{line}: {a} imports {b} inside a function; {' -> '.join(back)} "
                       "at module level: move the shared piece to the lower module")
    return out


def graph_cycles(root: Path, packages, allowed=frozenset()) -> list[str]:
    """Cycles of the whole import graph (module and function level), one line per pair of
    modules that import each other through some chain, except the ``allowed`` pairs."""
    mods = _modules(root, packages)
    top, inner, _ = _imports(mods)
    graph = {m: set(s) for m, s in top.items()}
    for a, b, _ in inner:
        graph[a].add(b)
    out = []
    for a in sorted(graph):
        for b in sorted(graph[a]):
            back = _path(graph, b, a)
            if back and a < b and frozenset({a, b}) not in allowed:
                out.append(f"{a} -> {b} -> ... -> {a}: {' -> '.join([a] + back)}")
    return out


def private_reach_ins(root: Path, packages, deprecated=frozenset()) -> list[str]:
    """Imports of another module's private names and of private modules from outside their
    package, and attribute access ``module._name`` on an imported project module."""
    mods = _modules(root, packages)
    _, _, statements = _imports(mods)

    def private(name: str) -> bool:
        return name.startswith("_") and not name.startswith("__")

    def outside(mod: str, target: str) -> bool:  # target is a private module not in mod's package
        parts = target.split(".")
        k = next((i for i, p in enumerate(parts) if private(p)), None)
        return k is not None and not (mod + ".").startswith(".".join(parts[:k]) + ".")

    out, aliases = [], {m: {} for m in mods}
    for mod, node, src in statements:
        where = f"{mods[mod].relative_to(root)}:{node.lineno}"
        named = [a.name for a in node.names] if src is None else [src] + [f"{src}.{a.name}" for a in node.names]
        for t in dict.fromkeys(n for n in named if n in mods or n == src):
            if t.split(".")[0] in packages and (t in deprecated or outside(mod, t)):
                out.append(f"{where}: imports the private module {t}")
        if src is not None and src.split(".")[0] in packages:
            for a in node.names:
                full = f"{src}.{a.name}"
                if private(a.name) and full not in mods:
                    out.append(f"{where}: imports the private name {a.name} of {src}")
                if full in mods:
                    aliases[mod][a.asname or a.name] = full
        elif src is None:
            for a in node.names:
                if a.asname and a.name in mods:
                    aliases[mod][a.asname] = a.name
    for mod, path in mods.items():
        for node in ast.walk(_parse(path)):
            if (isinstance(node, ast.Attribute) and private(node.attr) and isinstance(node.value, ast.Name)
                    and node.value.id in aliases[mod]):
                out.append(f"{path.relative_to(root)}:{node.lineno}: uses the private name {node.attr} of "
                           f"{aliases[mod][node.value.id]}")
    return out


def test_no_function_level_import_hides_a_cycle():
    assert hidden_cycles(ROOT, PACKAGES) == []


def test_import_graph_has_no_cycle_but_the_documented_one():
    assert graph_cycles(ROOT, PACKAGES, ALLOWED_CYCLES) == []


def test_no_private_reach_ins():
    assert private_reach_ins(ROOT, PACKAGES, DEPRECATED) == []


def test_deprecated_io_aliases_still_export_the_public_modules():
    import brdfmodels._io as old_io
    import brdfmodels._unit as old_unit
    from brdfmodels import fileio, output_sets

    assert {n: getattr(old_io, n) for n in fileio.__all__} == {n: getattr(fileio, n) for n in fileio.__all__}
    assert {n: getattr(old_unit, n) for n in output_sets.__all__} == {n: getattr(output_sets, n) for n in output_sets.__all__}


def _write(root: Path, files: dict) -> None:
    for name, text in files.items():
        p = root / name
        p.parent.mkdir(parents=True, exist_ok=True)
        p.write_text(text, encoding="utf-8")


def test_checkers_find_what_they_forbid(tmp_path):
    """Each rule broken once in a throwaway package: the checkers name each break."""
    _write(tmp_path, {
        "pk/__init__.py": "",
        "pk/low.py": "from .high import thing\n",  # module level: low -> high
        "pk/high.py": "import json\n\ndef thing():\n    from .low import x\n    import pyvista\n    return x\n",  # hidden
        "pk/a.py": "def f():\n    from . import b\n",  # a <-> b, both inside functions
        "pk/b.py": "def g():\n    from .a import f\n",
        "pk/_secret.py": "",
        "pk/old.py": "",
        "pk/ok.py": "from ._secret import *\nfrom . import _secret\n",  # its own package: allowed
        "pk/tc.py": "from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    from .tc2 import T\n",  # never runs
        "pk/tc2.py": "from .tc import X\n",
        "other/__init__.py": "",
        "other/use.py": ("from pk._secret import y\nfrom pk.high import _helper\nfrom pk import high as h\n"
                         "import pk.old as lo\nz = h._cache\nw = lo._table\nv = h.thing\n"),
    })
    hidden = hidden_cycles(tmp_path, ("pk", "other"))
    assert len(hidden) == 1 and "pk.high imports pk.low inside a function" in hidden[0]
    cycles = graph_cycles(tmp_path, ("pk", "other"))
    assert [c.split(":")[0] for c in cycles] == ["pk.a -> pk.b -> ... -> pk.a", "pk.high -> pk.low -> ... -> pk.high"]
    assert graph_cycles(tmp_path, ("pk", "other"), {frozenset({"pk.a", "pk.b"}), frozenset({"pk.high", "pk.low"})}) == []
    found = private_reach_ins(tmp_path, ("pk", "other"), {"pk.old"})
    assert sorted(f.split(": ", 1)[1] for f in found) == sorted([
        "imports the private module pk._secret",
        "imports the private name _helper of pk.high",
        "uses the private name _cache of pk.high",
        "uses the private name _table of pk.old",
        "imports the private module pk.old",  # deprecated: `import pk.old as lo`
    ])
