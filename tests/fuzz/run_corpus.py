"""Run the mutated-scene analysis corpus of ``test_fuzz_scenes`` outside pytest, resumably.

``test_every_mutation`` runs its 14 406 cases in one pytest call and only reports at the end;
at a few seconds of CPU per accepted mutant that is many hours on 2 shared cores. This runs
the same cases through the same harness (``run_case``, same time box of 120 s CPU, validate
on every fourth case) one at a time, and appends one JSON line per case to a log: its index,
base scene, path, mutation, outcome, CPU seconds and the first line of any failure. A case
is written as ``start`` before it runs, so a hang or a crash of the process shows which case
it was. Started again with the same log, it skips the cases already done.

    nice -n 19 python -m tests.fuzz.run_corpus LOG.jsonl [--order interleave|cheap] [--only BASE,...]
    nice -n 19 python -m tests.fuzz.run_corpus PAIRS.jsonl --pairs N [--seed S] [--first-accepted-in LOG.jsonl]
    python -m tests.fuzz.run_corpus LOG.jsonl --summary [--pairs N ...]

Cases run interleaved over the bundled scenes by default (so a partial run covers every
scene), or by base scene, cheapest first (``--order cheap``).

``--pairs N`` runs a seeded sample of N cases of ``test_pairs_of_mutations`` instead (one
enumerated mutation, then a second one at another field of the mutant; same log format,
key ``FIRST+PATH:KIND``). Drawn like the test, most first mutations are refused before any
analysis; ``--first-accepted-in`` draws the first mutation from the cases a single-mutation
log shows accepted, so that the second one meets the analysis.
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


def _pairs(n: int, seed: int, first_log: Path | None) -> list:
    """(i, key, runner) of the seeded pairs sample, in drawing order."""
    firsts = None
    if first_log is not None:
        lines = first_log.read_text().splitlines()
        lines = lines if first_log.read_text().endswith("\n") else lines[:-1]  # a log being written
        ok = {r["key"] for r in map(json.loads, lines) if r["outcome"] == "accepted"}
        firsts = [c for c in fz.ALL_CASES if _key(c) in ok]
    out, seen = [], set()
    for i, (a, kind, k) in enumerate(fz.pair_cases(n, seed, firsts)):
        _, path = fz.second_path(a, k)
        key = f"{_key(a)}+{'.'.join(map(str, path)) if path is not None else '-'}:{kind}"
        if key in seen:  # drawn twice
            continue
        seen.add(key)
        out.append((i, key, lambda cli, tmp, a=a, kind=kind, k=k: fz.run_pair(a, kind, k, cli=cli, tmp=tmp)))
    return out


def _singles(how: str, only: set) -> list:
    return [(i, _key(c), lambda cli, tmp, c=c: fz.run_case(*c, cli=cli, tmp=tmp)) for i, c in _order(fz.ALL_CASES, how, only)]


def summary(log: Path, of: int | None = None, keys: set | None = None) -> dict:
    """Counts of outcomes, CPU time and the failing cases of a log (a started case with no
    end line is a hang or a crash of the runner); with ``keys``, of those cases only (the
    others are counted as ``stale``: cases of a sample drawn by an older harness)."""
    recs = [json.loads(ln) for ln in log.read_text().splitlines()]
    stale = {r["key"] for r in recs if keys is not None and r["key"] not in keys}
    recs = [r for r in recs if r["key"] not in stale]
    ended = {r["key"]: r for r in recs if r["outcome"] != "start"}
    started = [r for r in recs if r["outcome"] == "start" and r["key"] not in ended]
    out = Counter(r["outcome"] for r in ended.values())
    cpu = sorted(((r["cpu_s"], r["key"]) for r in ended.values()), reverse=True)
    return {"cases": len(ended), "of": of or len(fz.ALL_CASES), "stale": len(stale), "outcomes": dict(out),
            "cpu_s_total": round(sum(c for c, _ in cpu), 1), "slowest": cpu[:10],
            "never_ended": [r["key"] for r in started],
            "failures": [(r["key"], r["detail"]) for r in ended.values() if r["outcome"] in ("failure", "traceback")]}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("log", type=Path)
    ap.add_argument("--order", choices=("interleave", "cheap"), default="interleave")
    ap.add_argument("--only", default="", help="comma-separated base scenes")
    ap.add_argument("--summary", action="store_true")
    ap.add_argument("--pairs", type=int, default=0, help="run a seeded sample of N pairs of mutations")
    ap.add_argument("--seed", type=int, default=30, help="the seed of the pairs sample")
    ap.add_argument("--first-accepted-in", type=Path, default=None,
                    help="a single-mutation log: draw first mutations from its accepted cases")
    args = ap.parse_args(argv)
    if args.summary:
        keys = {k for _, k, _ in _pairs(args.pairs, args.seed, args.first_accepted_in)} if args.pairs else None
        json.dump(summary(args.log, len(keys) if keys else None, keys), sys.stdout, indent=1)
        print()
        return 0
    done = _done(args.log)
    only = set(filter(None, args.only.split(",")))
    cases = _pairs(args.pairs, args.seed, args.first_accepted_in) if args.pairs else _singles(args.order, only)
    with tempfile.TemporaryDirectory() as tmp, args.log.open("a") as log:
        for i, key, run in cases:
            if key in done:
                continue
            log.write(json.dumps({"i": i, "key": key, "outcome": "start"}) + "\n")
            log.flush()
            c0, detail = time.process_time(), ""
            try:
                outcome = run(i % 4 == 0, tmp)
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
