"""Check that a refactoring left the outputs identical: run every bundled example (and a few
variants of the moving-observer scenes, so that every optional key of ``motion`` and
``tracks`` is written) with two checkouts, then compare the files byte for byte, with only
the run times masked.

Run (from a checkout; ``BEFORE_SRC`` e.g. ``git archive <commit> | tar -x -C /tmp/before``)::

    python examples/identical_outputs.py run  BEFORE_SRC /tmp/out_before
    python examples/identical_outputs.py run  .          /tmp/out_after
    python examples/identical_outputs.py compare /tmp/out_before /tmp/out_after

``run`` calls ``python -m hazard run NAME -o OUT/NAME --force`` with ``PYTHONPATH=SRC`` for
every ``scenes/examples/*.toml`` of SRC and every variant below (written to ``OUT/_scenes``).
``compare`` reads every file of both folders but pictures (``.png``, ``.tif``): ``report.json``
with each ``"seconds"`` value (the stages' and the motion stage's run times) replaced by 0 and
``scene.source`` (the scene file's path, in each checkout) by the file's name, the run times
in the stages' ``detail`` texts (:data:`RUN_TIME_TEXT`) by ``<run time>``,
every other file as bytes. It prints one line per file (``=`` identical, ``*`` differs, with
the first differing JSON path or line) and exits 1 when any differs or is missing.
"""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
from pathlib import Path

#: Variants of scenes with things that move: (name, source scene relative to SRC, [(old, new) text replacements]).
VARIANTS = [
    ("v_crossing", "examples/accuracy/aircraft_crossing.toml", []),
    # the worst pointing bias of a track (pointing_bias_rad, pointing_buffer_rad)
    ("v_crossing_bias", "examples/accuracy/aircraft_crossing.toml",
     [("start_m = [-1000.0, 5000.0, 0.0]", "start_m = [-1000.0, 5000.0, 3.0]"),
      ("aim_m = [0.0, 20000.0, 0.0]", "aim_m = [0.0, 20000.0, 0.0]\npointing_error_rad = 0.001")]),
    # the UV day's dose of a track (tracks[].uv_24h)
    ("v_crossing_uv", "examples/accuracy/aircraft_crossing.toml", [("wavelength_nm = 532.0", "wavelength_nm = 355.0")]),
    # an aim track given by rates (motion.aim_track's rates), lasing windows, a moving target
    ("v_airspace_rates", "scenes/examples/airspace.toml",
     [('aim_m = [[-30.0, 2000.0, 100.0], [30.0, 2000.0, 100.0]]', "azimuth_rate_deg_s = 0.05\nelevation_rate_deg_s = 0.01"),
      ('material = { model = "lambertian", reflectance = 0.3 }',
       'material = { model = "lambertian", reflectance = 0.3 }\n[targets.track]\ntimes_s = [0.0, 10.0]\n'
       'center_m = [[0.0, 2000.0, 100.0], [2.0, 2000.0, 100.0]]')]),
]

#: The run times a stage's ``detail`` text gives: "(0.000424 s)" (specular), "0.0546 s summed over threads".
RUN_TIME_TEXT = r"(?<=\()[0-9.e+-]+ s(?=\))|[0-9.e+-]+ s(?= summed over threads)"

PICTURES = {".png", ".tif", ".tiff", ".jpg", ".svg", ".pdf"}


def _scenes(src: Path, out: Path) -> list[tuple[str, Path]]:
    """(name, scene file) of every bundled example and every variant."""
    found = [(p.stem, p) for p in sorted((src / "scenes" / "examples").glob("*.toml"))]
    (out / "_scenes").mkdir(parents=True, exist_ok=True)
    for name, rel, edits in VARIANTS:
        text = (src / rel).read_text()
        for old, new in edits:
            if old not in text:
                raise SystemExit(f"variant {name}: {old!r} not in {rel}")
            text = text.replace(old, new)
        path = out / "_scenes" / f"{name}.toml"
        path.write_text(text)
        found.append((name, path))
    return found


def run(src: Path, out: Path) -> int:
    env = {**os.environ, "PYTHONPATH": str(src.resolve()), "MPLBACKEND": "Agg"}
    failed = 0
    for name, scene in _scenes(src, out):
        cmd = [sys.executable, "-m", "hazard", "run", str(scene.resolve()), "-o", str((out / name).resolve()), "--force"]
        r = subprocess.run(cmd, env=env, capture_output=True, text=True, cwd=src)
        print(f"{name}: exit {r.returncode}")
        if r.returncode not in (0, 1):  # 1: hazard found (with --fail-on-hazard only); anything else is a failure
            failed += 1
            print(r.stderr[-2000:])
    return 1 if failed else 0


def _masked(obj):
    """``obj`` with every ``"seconds"`` value 0 (run times) and ``scene.source``, the scene
    file's path (a different checkout), cut to the file's name."""
    if isinstance(obj, dict):
        out = {k: (0 if k == "seconds" else _masked(v)) for k, v in obj.items()}
        if isinstance(out.get("scene"), dict) and isinstance(out["scene"].get("source"), str):
            out["scene"]["source"] = Path(out["scene"]["source"]).name
        if isinstance(out.get("detail"), str):  # a stage record: the run times its text gives
            out["detail"] = re.sub(RUN_TIME_TEXT, "<run time> s", out["detail"])
        return out
    if isinstance(obj, list):
        return [_masked(v) for v in obj]
    return obj


def _first_difference(a, b, path="") -> str:
    if type(a) is not type(b):
        return f"{path or '/'}: {type(a).__name__} -> {type(b).__name__}"
    if isinstance(a, dict):
        if list(a) != list(b):
            return f"{path or '/'}: keys {list(a)} -> {list(b)}"
        return next((d for k in a if (d := _first_difference(a[k], b[k], f"{path}.{k}"))), "")
    if isinstance(a, list):
        if len(a) != len(b):
            return f"{path}: {len(a)} -> {len(b)} entries"
        return next((d for i, (x, y) in enumerate(zip(a, b)) if (d := _first_difference(x, y, f"{path}[{i}]"))), "")
    return "" if a == b else f"{path}: {a!r} -> {b!r}"


def _compare_file(a: Path, b: Path) -> str:
    """'' when identical (report.json: its run times masked), else the first difference."""
    if a.name == "report.json":
        ja, jb = (_masked(json.loads(p.read_text())) for p in (a, b))
        return _first_difference(ja, jb) or ("" if json.dumps(ja) == json.dumps(jb) else "key order")
    ta, tb = a.read_bytes(), b.read_bytes()
    if ta == tb:
        return ""
    la, lb = ta.splitlines(), tb.splitlines()
    k = next((i for i, (x, y) in enumerate(zip(la, lb)) if x != y), min(len(la), len(lb)))
    return f"line {k + 1}: {la[k][:120]!r} -> {lb[k][:120]!r}" if k < min(len(la), len(lb)) else f"{len(la)} -> {len(lb)} lines"


def compare(before: Path, after: Path) -> int:
    bad = 0
    names = sorted({p.relative_to(before) for p in before.rglob("*") if p.is_file()} |
                   {p.relative_to(after) for p in after.rglob("*") if p.is_file()})
    for rel in names:
        if rel.suffix.lower() in PICTURES or rel.parts[0] == "_scenes":
            continue
        a, b = before / rel, after / rel
        if not (a.is_file() and b.is_file()):
            print(f"* {rel}: missing {'before' if not a.is_file() else 'after'}")
            bad += 1
            continue
        diff = _compare_file(a, b)
        print(f"{'*' if diff else '='} {rel}" + (f": {diff}" if diff else ""))
        bad += bool(diff)
    print(f"{bad} file(s) differ" if bad else "all identical (run times masked)")
    return 1 if bad else 0


def main(argv=None) -> int:
    args = list(sys.argv[1:] if argv is None else argv)
    if len(args) == 3 and args[0] == "run":
        return run(Path(args[1]), Path(args[2]))
    if len(args) == 3 and args[0] == "compare":
        return compare(Path(args[1]), Path(args[2]))
    print(__doc__, file=sys.stderr)
    return 2


if __name__ == "__main__":
    sys.exit(main())
