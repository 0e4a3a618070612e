"""Run the mutated-scene analysis corpus of ``test_fuzz_scenes`` outside pytest, resumably.

``test_every_mutation`` runs its 14 406 cases in one pytest call and only reports at the end;
at a few seconds of CPU per accepted mutant that is many hours on 2 shared cores. This runs
the same cases through the same harness (``run_case``, same time box of 120 s CPU, validate
on every fourth case) one at a time, and appends one JSON line per case to a log: its index,
base scene, path, mutation, outcome, CPU seconds and the first line of any failure. A case
is written as ``start`` before it runs, so a hang or a crash of the process shows which case
it was. Started again with the same log, it skips the cases already done.

    nice -n 19 python -m tests.fuzz.run_corpus LOG.jsonl [--order interleave|cheap] [--only BASE,...]
    python -m tests.fuzz.run_corpus LOG.jsonl --summary

Cases run interleaved over the bundled scenes by default (so a partial run covers every
scene), or by base scene, cheapest first (``--order cheap``).
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
import traceback
from collections import Counter
from itertools import zip_longest
from pathlib import Path

from tests.fuzz import test_fuzz_scenes as fz


def _key(case) -> str:
    name, path, kind = case
    return f"{name}:{'.'.join(map(str, path))}:{kind}"


def _order(cases, how: str, only: set | None):
    indexed = [(i, c) for i, c in enumerate(cases) if not only or c[0] in only]
    by_base: dict = {}
    for i, c in indexed:
        by_base.setdefault(c[0], []).append((i, c))
    if how == "cheap":
        return [ic for base in sorted(by_base, key=lambda b: len(by_base[b])) for ic in by_base[base]]
    return [ic for group in zip_longest(*by_base.values()) for ic in group if ic is not None]


def _done(log: Path) -> set:
    if not log.exists():
        return set()
    done = set()
    for line in log.read_text().splitlines():
        rec = json.loads(line)
        if rec.get("outcome") != "start":
            done.add(rec["key"])
    return done


def summary(log: Path) -> dict:
    """Counts of outcomes, CPU time and the failing cases of a log (a started case with no
    end line is a hang or a crash of the runner)."""
    recs = [json.loads(ln) for ln in log.read_text().splitlines()]
    ended = {r["key"]: r for r in recs if r["outcome"] != "start"}
    started = [r for r in recs if r["outcome"] == "start" and r["key"] not in ended]
    out = Counter(r["outcome"] for r in ended.values())
    cpu = sorted(((r["cpu_s"], r["key"]) for r in ended.values()), reverse=True)
    return {"cases": len(ended), "of": len(fz.ALL_CASES), "outcomes": dict(out),
            "cpu_s_total": round(sum(c for c, _ in cpu), 1), "slowest": cpu[:10],
            "never_ended": [r["key"] for r in started],
            "failures": [(r["key"], r["detail"]) for r in ended.values() if r["outcome"] in ("failure", "traceback")]}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("log", type=Path)
    ap.add_argument("--order", choices=("interleave", "cheap"), default="interleave")
    ap.add_argument("--only", default="", help="comma-separated base scenes")
    ap.add_argument("--summary", action="store_true")
    args = ap.parse_args(argv)
    if args.summary:
        json.dump(summary(args.log), sys.stdout, indent=1)
        print()
        return 0
    done = _done(args.log)
    only = set(filter(None, args.only.split(",")))
    with tempfile.TemporaryDirectory() as tmp, args.log.open("a") as log:
        for i, case in _order(fz.ALL_CASES, args.order, only):
            key = _key(case)
            if key in done:
                continue
            log.write(json.dumps({"i": i, "key": key, "outcome": "start"}) + "\n")
            log.flush()
            c0, detail = time.process_time(), ""
            try:
                outcome = fz.run_case(*case, cli=i % 4 == 0, tmp=tmp)
            except AssertionError as exc:
                outcome, detail = "failure", str(exc).splitlines()[0][:500]
            except Exception as exc:  # noqa: BLE001 - a traceback out of the harness is a finding
                outcome = "traceback"
                detail = f"{type(exc).__name__}: {exc}"[:300] + " | " + traceback.format_exc().splitlines()[-3][:200]
            log.write(json.dumps({"i": i, "key": key, "outcome": outcome, "cpu_s": round(time.process_time() - c0, 3),
                                  "detail": detail}) + "\n")
            log.flush()
    return 0


if __name__ == "__main__":
    sys.exit(main())
