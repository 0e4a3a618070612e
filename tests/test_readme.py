"""The README works as written (issue 31 item 5): every relative link resolves to a file
that ships in the repository (and its #anchor to a heading there), every ``hazard``
command in its bash blocks parses, no command reuses an output folder it owns without
``--force``, and every block runs, in the default suite.

Skipped: the set-up install commands (``pip install ...`` parts of a line), the CI's own
test command (the block after ``<!-- test-command -->``, run by ``.ci/run``) and blocks
marked ``<!-- no-run -->`` (placeholders: your own scene, a scheduler's address).

The README's examples are quick by design (a few hundred risk draws, a three-run study,
one convergence knob, a static render; the text says how to scale each up). Each block
is one piece (``test_readme_block_runs``, one test per block, so ``pytest -n auto``
spreads them over the cores): its commands in order, in a fresh folder, in one Python
process through the ``hazard`` script's own entry (the set-up line through bash and a
``hazard`` on PATH, as typed). No block reads what an earlier block wrote
(``test_no_readme_block_reads_an_earlier_blocks_output``), so the pieces are independent.
Measured on the shared 2-core machine (load 5-9), ``-n 2``: every block, 110 s CPU in
all (pytest and its two workers included), 3.5 min wall; the longest piece is the
airspace block (its run and its render), 89 s wall. With a process per command it was
138 s CPU. Before (the 20,000- and 50,000-draw risk runs, a four-run study of
steel_vs_copper, every convergence knob, an animated render) the default suite ran only
the quick blocks (about 6 s CPU) and the whole README only under ``-m slow``: the old
blocks less the two risk runs took 245 s CPU, the first risk run 14 min wall. ``-m slow``
still runs the whole README in order in one folder, each command through bash.
"""

from __future__ import annotations

import json
import os
import re
import shlex
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
SKIP_MARKERS = ("<!-- no-run -->", "<!-- test-command -->")
QUICK_VERBS = {"mpe", "nohd", "validate", "models", "schema"}
WRITING_VERBS = {"run", "render", "risk"}  # a second write of its own folder needs --force (study resumes, report rebuilds)


def bash_blocks(text: str) -> list[dict]:
    """The README's ```bash blocks: ``line`` (1-based, of the fence), ``body``, ``marker`` (the
    HTML comment on the last non-blank line before the fence, or "")."""
    lines, blocks, i = text.splitlines(), [], 0
    while i < len(lines):
        if lines[i].strip() == "```bash":
            before = next((x.strip() for x in reversed(lines[:i]) if x.strip()), "")
            j = next(k for k in range(i + 1, len(lines)) if lines[k].strip() == "```")
            blocks.append({"line": i + 1, "body": "\n".join(lines[i + 1:j]),
                           "marker": before if before.startswith("<!--") else ""})
            i = j
        i += 1
    return blocks


def commands(body: str) -> list[str]:
    """The commands of a block: continuation lines joined, comment lines dropped, the
    ``pip install`` parts of an ``A && B`` line dropped (set-up, not the tool)."""
    out = []
    for line in body.replace("\\\n", " ").splitlines():
        line = line.strip()
        if not line or line.startswith("#"):
            continue
        parts = [p.strip() for p in line.split("&&")]
        parts = [p for p in parts if not re.match(r"^(python -m )?pip install\b", p)]
        if parts:
            out.append(" && ".join(parts))
    return out


def runnable() -> list[tuple[int, list[str]]]:
    """(fence line, commands) of every block the README runner executes, in order."""
    return [(b["line"], commands(b["body"])) for b in bash_blocks(README.read_text(encoding="utf-8"))
            if b["marker"] not in SKIP_MARKERS and commands(b["body"])]


def _argv(cmd: str) -> list[str]:
    return shlex.split(cmd, comments=True)


def test_readme_blocks_are_found_and_skips_are_marked():
    blocks = bash_blocks(README.read_text(encoding="utf-8"))
    assert len(blocks) >= 10
    run = runnable()
    assert len(run) >= 8 and all(cmds for _, cmds in run)
    # every runnable command is the tool (a placeholder scene or scheduler would be marked no-run)
    for line, cmds in run:
        for c in cmds:
            argv = _argv(c)
            assert argv[0] == "hazard", f"README line {line}: {c!r} is not a hazard command (mark the block <!-- no-run -->?)"
            assert "my_scene.toml" not in argv and not any(a.startswith("tcp://") for a in argv), f"README line {line}: {c!r}"
    # the set-up line keeps its hazard part
    assert "hazard run steel_vs_copper -o hazard-out --force" in run[0][1]


def test_every_readme_command_parses():
    """Unknown flags or verbs fail here in milliseconds instead of in the slow run."""
    from hazard.cli import build_parser

    parser = build_parser()
    for line, cmds in runnable():
        for c in cmds:
            try:
                parser.parse_args(_argv(c)[1:])
            except (Exception, SystemExit) as exc:  # _UsageError, or argparse's exit
                pytest.fail(f"README line {line}: {c!r} does not parse: {exc}")


def test_no_readme_command_rewrites_its_own_folder_without_force():
    """``hazard run X -o out`` after another ``hazard run ... -o out`` needs --force (the
    issue's failing blocks); the check follows the README's order."""
    from hazard.cli import build_parser

    parser, written, bad = build_parser(), {}, []
    for line, cmds in runnable():
        for c in cmds:
            args = parser.parse_args(_argv(c)[1:])
            folder = getattr(args, "output", None)
            if args.verb not in WRITING_VERBS or not folder:
                continue
            if (args.verb, folder) in written and not args.force:
                bad.append(f"README line {line}: {c!r} writes {folder} again (first at line {written[args.verb, folder]}) "
                           "without --force")
            written.setdefault((args.verb, folder), line)
    assert bad == [], "\n".join(bad)


def _slug(heading: str) -> str:
    """GitHub's anchor of a Markdown heading."""
    text = re.sub(r"[^\w\- ]", "", heading.strip().lower())
    return text.replace(" ", "-")


def _anchors(md: Path) -> set:
    return {_slug(m.group(1)) for m in re.finditer(r"^#{1,6}\s+(.+?)\s*$", md.read_text(encoding="utf-8"), re.M)}


def _links(md: Path) -> list[str]:
    text = md.read_text(encoding="utf-8")
    text = re.sub(r"```.*?```", "", text, flags=re.S)  # not inside code blocks
    return re.findall(r"\]\(([^)\s]+)\)", text)


@pytest.mark.parametrize("doc", ["README.md", *sorted(str(p.relative_to(ROOT)) for p in (ROOT / "docs").glob("*.md"))])
def test_every_relative_link_resolves(doc):
    """The README cites only documents that ship in the repository (no spec files left
    outside it), and an anchor names a heading of its target."""
    md = ROOT / doc
    links = _links(md)
    bad = []
    for link in links:
        if re.match(r"^[a-z]+:", link):  # http:, https:, mailto:
            continue
        path, _, anchor = link.partition("#")
        target = (md.parent / path).resolve() if path else md
        if not target.is_file() or ROOT not in target.parents:
            bad.append(f"{link}: no file {target}")
        elif anchor and target.suffix == ".md" and anchor not in _anchors(target):
            bad.append(f"{link}: no heading #{anchor} in {target.name}")
    assert bad == [], f"{doc}: broken links: {bad}"
    if doc == "README.md":
        cited = {link.partition("#")[0] for link in links}
        assert {"docs/laser-safety.md", "docs/range-safety.md", "docs/scene-reference.md"} <= cited


def test_readme_names_no_spec_file_outside_the_repository():
    """The method notes the README relies on are the shipped docs/*.md: "range-safety.md"
    or "laser-safety.md" (the project's private spec) may appear only in a link into docs/."""
    text = README.read_text(encoding="utf-8")
    rest = re.sub(r"\[[^\]]*\]\(docs/[^)]*\)", "", text)  # drop the links into docs/ (label and target)
    for name in ("range-safety.md", "laser-safety.md", "engineering-notes.md", "dynamic-sh-brdf.md"):
        assert name not in rest, f"README names {name} outside a link to docs/{name}"


def _shim(tmp_path: Path) -> dict:
    """A ``hazard`` on PATH that runs this checkout (not whatever is installed)."""
    bin_dir = tmp_path / "bin"
    bin_dir.mkdir()
    shim = bin_dir / "hazard"
    shim.write_text(f'#!/bin/sh\nexec "{sys.executable}" -m hazard "$@"\n')
    shim.chmod(0o755)
    env = dict(os.environ, PATH=f"{bin_dir}{os.pathsep}{os.environ.get('PATH', '')}", PYTHONPATH=str(ROOT),
               MPLBACKEND="Agg")
    return env


def _work(tmp_path: Path) -> Path:
    """The fresh folder the commands run in."""
    work = tmp_path / "work"
    work.mkdir()
    (work / "examples").symlink_to(ROOT / "examples")  # commands name examples/*.py
    (work / "hazard").symlink_to(ROOT / "hazard")  # and hazard/studies/*.toml (the same package as on PYTHONPATH)
    return work


def _run_blocks(blocks, tmp_path: Path) -> None:
    """Each command through bash and the ``hazard`` shim, as a reader types it."""
    env = _shim(tmp_path)
    work = _work(tmp_path)
    for line, cmds in blocks:
        for c in cmds:
            done = subprocess.run(["bash", "-c", c], cwd=work, env=env, capture_output=True, text=True, timeout=3600)
            ok = done.returncode == 0 or (done.returncode == 3 and "--fail-on-hazard" in c)
            assert ok, f"README line {line}: {c!r} exited {done.returncode}:\n{done.stderr[-2000:]}"


def _written_folders(cmd: str, parser) -> set:
    """The folders a command writes (``-o``) or paths it writes (``--plot FILE``)."""
    args = parser.parse_args(_argv(cmd)[1:])
    return {str(v) for k in ("output", "plot") if isinstance(v := getattr(args, k, None), str)}


def test_no_readme_block_reads_an_earlier_blocks_output():
    """Each block runs alone in a fresh folder (in parallel under xdist): a command naming
    a folder that only an earlier block wrote (``hazard report out`` with ``out`` from the
    block before) would fail there, so the two would have to be one piece."""
    from hazard.cli import build_parser

    parser, earlier, bad = build_parser(), {}, []
    for line, cmds in runnable():
        own = set()
        for c in cmds:
            writes = _written_folders(c, parser)
            for token in _argv(c)[1:]:
                if token in earlier and token not in own and token not in writes:
                    bad.append(f"README line {line}: {c!r} reads {token}, written by the block at line {earlier[token]}")
            own |= writes
        for folder in own:
            earlier.setdefault(folder, line)
    assert bad == [], "\n".join(bad)


# One Python process per block runs its commands in order through the console script's own
# entry (sys.argv set, hazard.cli.main() as the ``hazard`` script calls it): the block is one
# shell session without paying Python's and the packages' start-up per command (about 1 s
# of CPU each). Nothing is shared between blocks or with the test process.
_BLOCK_DRIVER = """
import json, shlex, sys
from hazard.cli import main
cmds, result, codes = json.loads(sys.argv[1]), sys.argv[2], []
for c in cmds:
    sys.argv = shlex.split(c, comments=True)
    try:
        code = main()
    except SystemExit as exc:
        code = exc.code if isinstance(exc.code, int) else 1
    codes.append(code)
    sys.stdout.flush()
    sys.stderr.flush()
    if not (code == 0 or (code == 3 and "--fail-on-hazard" in c)):
        break
with open(result, "w") as f:
    json.dump(codes, f)
"""
SHELL_SYNTAX = re.compile(r"[|;&<>`$()]")


@pytest.mark.parametrize("line, cmds", runnable(), ids=[f"line{line}" for line, _ in runnable()])
def test_readme_block_runs(line, cmds, tmp_path):
    """One README block, its commands in order, in a fresh folder (see the module notes);
    the commands as collected (a README edited during the run changes nothing)."""
    assert cmds
    first = line == runnable()[0][0]  # the set-up line goes through bash and the hazard script, as typed
    if first or any(SHELL_SYNTAX.search(re.sub(r"\s#.*$", "", c)) for c in cmds):  # as does a pipe or redirection
        _run_blocks([(line, cmds)], tmp_path)
        return
    env, work = _shim(tmp_path), _work(tmp_path)
    result = tmp_path / "codes.json"
    done = subprocess.run([sys.executable, "-c", _BLOCK_DRIVER, json.dumps(cmds), str(result)], cwd=work, env=env,
                          capture_output=True, text=True, timeout=1800)
    codes = json.loads(result.read_text()) if result.exists() else []
    assert done.returncode == 0 and len(codes) == len(cmds), \
        f"README line {line}: stopped after {len(codes)} of {len(cmds)} commands (exit codes {codes}):\n{done.stderr[-3000:]}"


def test_every_runnable_block_is_a_piece():
    """The parametrised pieces are every runnable block once, in the README's order, and
    the quick verbs are among them (a README rewrite cannot drop them silently)."""
    lines = [line for line, _ in runnable()]
    assert lines == sorted(set(lines)) and len(lines) >= 8
    verbs = {_argv(c)[1] for _, cmds in runnable() for c in cmds}
    assert QUICK_VERBS | WRITING_VERBS | {"study", "convergence", "report", "compare"} <= verbs, verbs


@pytest.mark.slow  # the whole README in order in one folder, as a reader would run it (the pieces above run it by block)
def test_every_readme_block_runs_in_order(tmp_path):
    _run_blocks(runnable(), tmp_path)


def test_the_source_distribution_carries_the_cited_documents():
    """MANIFEST.in puts every document the README links to into the sdist (the wheel holds
    the packages only)."""
    rules = [line.split() for line in (ROOT / "MANIFEST.in").read_text().splitlines() if line and not line.startswith("#")]
    included = []
    for rule in rules:
        if rule[0] == "include":
            included += [lambda p, names=rule[1:]: p in names]
        elif rule[0] == "recursive-include":
            included += [lambda p, top=rule[1], pats=rule[2:]: p.startswith(top + "/") and any(Path(p).match(x) for x in pats)]
    cited = {link.partition("#")[0] for link in _links(README) if not re.match(r"^[a-z]+:", link)}
    missing = [p for p in sorted(cited) if not any(rule(p) for rule in included)]
    assert cited and missing == [], f"README cites files MANIFEST.in leaves out of the sdist: {missing}"
