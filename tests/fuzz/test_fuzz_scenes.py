"""Fuzz the input boundary: mutated scene files must give one clear error line or a
sane result, never a traceback, a hang, a non-finite number or a vanished target.

Every bundled example scene is made cheap (few observers, beam rays and keep-out cells)
and then mutated at every field path of its data: the field deleted, set to NaN, +-inf,
1e308, -1, 0, true, "x", [], a deeply nested list, a list one longer or shorter, or an
unknown key added beside it. Each mutant is written as TOML and goes through
``scenes.loads`` (and ``hazard validate`` for a share of them); accepted mutants are
analysed in-process under a time limit.

The default slice draws a fixed (derandomized) sample of the mutants; ``-m slow`` runs all
of them (several thousand) plus random pairs of mutations.
"""

from __future__ import annotations

import copy
import io
import json
import math
import random
import signal
import threading
import time
import tomllib
from collections import Counter
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import hazard
import scenes
from hazard.cli import main
from hazard.outputs.report import report_dict

# every declared target must be in the report, hit by the beam or not (False: only count)
REQUIRE_ALL_TARGETS = True
# time box of one analysis: the issue's hang limit (tests/fuzz/_file_corpus.py's too). Most cheap
# bases run in under 1 s; airspace (its zone lattice over the track's times) and range_geo took
# 14 and 23 s alone, 67 and 165 s (footprint 154 s; 15 s with the coarser terrain above) on 2
# shared cores at load 9: a 20 s box failed their unmutated bases. Counted in CPU seconds of
# this process (with a wall-clock backstop, WALL_FACTOR): at load 19 an ASTM case of 8 s CPU
# took 158 s wall and was reported as a hang
CASE_SECONDS = 120
DEEP = 200  # nesting depth of the "deep list" mutation (the limit is 32)
MAX_PATH_DEPTH = 8  # a second mutation's field path at most this deep (the bundled scenes' deepest: 6)

_MISSING = object()
MUTATIONS = ("delete", "nan", "inf", "-inf", "1e308", "-1", "0", "true", "str", "empty", "deep", "longer", "shorter", "unknown")


# -- TOML writing (inline tables only: every structure round-trips) ----------------------
def _toml_value(v) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        if math.isnan(v):
            return "nan"
        if math.isinf(v):
            return "inf" if v > 0 else "-inf"
        return repr(v)
    if isinstance(v, str):
        return json.dumps(v)
    if isinstance(v, list):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    if isinstance(v, dict):
        return "{ " + ", ".join(f"{json.dumps(k)} = {_toml_value(x)}" for k, x in v.items()) + " }"
    raise TypeError(type(v))


def to_toml(data: dict) -> str:
    return "".join(f"{json.dumps(k)} = {_toml_value(v)}\n" for k, v in data.items())


# -- cheap bases and their field paths ---------------------------------------------------
def _cheap(data: dict) -> dict:
    a = data.setdefault("analysis", {})
    a.update(beam_samples=16, direction_grid_deg=10.0, refine_levels=1)
    for o in data.get("observers", []):
        if "count" in o:
            o["count"] = min(o["count"], 4)
        if "counts" in o:
            o["counts"] = [3, 3]
    if any("history" in t for t in data["targets"]):
        a["time_step_s"] = (a.get("time_end_s") or data["exposure"]["duration_s"]) / 8
    terrain = data.get("terrain", {})
    if "resolution_m" in terrain and "extent_m" in terrain:  # at most 30 cells across: range_geo's footprint took 154 s
        terrain["resolution_m"] = max(terrain["resolution_m"], terrain["extent_m"] / 30)
    return data


BASES = {name: (_cheap(tomllib.loads(p.read_text())), p.parent) for name, p in scenes.examples().items()}


def _paths(node, prefix=()):
    if isinstance(node, dict):
        for k, v in node.items():
            yield prefix + (k,)
            yield from _paths(v, prefix + (k,))
    elif isinstance(node, list):
        for i, v in enumerate(node):
            yield prefix + (i,)
            yield from _paths(v, prefix + (i,))


def _mutate(data, path, kind):
    d = copy.deepcopy(data)
    node = d
    for key in path[:-1]:
        node = node[key]
    last = path[-1]
    old = node[last]
    if kind == "delete":
        if isinstance(node, list):
            del node[last]
        else:
            del node[last]
        return d
    if kind == "unknown":
        target = old if isinstance(old, dict) else node
        if isinstance(target, dict):
            target["no_such_key"] = 1.0
        else:
            target.append(1.0)
        return d
    if kind in ("longer", "shorter"):
        if not isinstance(old, list):
            return None
        node[last] = old + [old[-1] if old else 1.0] if kind == "longer" else old[:-1]
        return d
    values = {"nan": math.nan, "inf": math.inf, "-inf": -math.inf, "1e308": 1e308, "-1": -1, "0": 0, "true": True,
              "str": "x", "empty": []}
    if kind == "deep":
        v = 1.0
        for _ in range(DEEP):
            v = [v]
        node[last] = v
    else:
        node[last] = values[kind]
    return d


ALL_CASES = [(name, path, kind) for name, (data, _) in BASES.items() for path in _paths(data) for kind in MUTATIONS]


# -- checks ------------------------------------------------------------------------------
WALL_FACTOR = 5  # the wall-clock backstop of a time box, in units of its CPU limit (a wait uses no CPU)


class _Timeout(BaseException):  # past the CLI's error boundary (it catches Exception: a hang was "exit 1")
    pass


def _time_box(seconds):
    """Raise _Timeout in the main thread after ``seconds`` of this process' CPU time (the
    issue's "120 s on 2 cores": a shared machine at load 19 stretched an 8 s CPU case to
    158 s wall), or after ``WALL_FACTOR`` times as long on the wall clock (a wait)."""
    if threading.current_thread() is not threading.main_thread() or not hasattr(signal, "setitimer"):
        return None

    def fire(signum, frame):
        raise _Timeout()

    old = (signal.signal(signal.SIGPROF, fire), signal.signal(signal.SIGALRM, fire))
    signal.setitimer(signal.ITIMER_PROF, seconds)
    signal.setitimer(signal.ITIMER_REAL, seconds * WALL_FACTOR)
    return old


def _end_box(old):
    if old is not None:
        signal.setitimer(signal.ITIMER_PROF, 0)
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGPROF, old[0])
        signal.signal(signal.SIGALRM, old[1])


def _non_finite(obj, where=""):
    """Paths of NaN anywhere, and of infinities outside distances (an infinite NOHD of an
    undiverging beam is a real answer; the report writes it as the string "inf")."""
    out = []
    stack = [(obj, where)]
    while stack:
        node, w = stack.pop()
        if isinstance(node, dict):
            stack.extend((v, f"{w}.{k}") for k, v in node.items())
        elif isinstance(node, (list, tuple)):
            stack.extend((v, f"{w}[{i}]") for i, v in enumerate(node))
        elif node == "nan" or (isinstance(node, float) and math.isnan(node)):
            out.append(w)
        elif node in ("inf", "-inf") or (isinstance(node, float) and math.isinf(node)):
            leaf = w.rsplit(".", 1)[-1]
            if not any(s in leaf for s in ("nohd", "_m", "range", "ratio", "volume", "distance")):
                out.append(w)
    return out


def run_case(name, path, kind, *, cli=False, tmp=None, analyse=True) -> str:
    """Run one mutant; returns its outcome ("rejected", "accepted", "skipped"; "loaded" for
    an accepted one when not ``analyse``) or raises AssertionError describing the failure."""
    data, base_dir = BASES[name]
    mutant = _mutate(data, path, kind)
    if mutant is None:
        return "skipped"
    text = to_toml(mutant)
    label = f"{name}: {'.'.join(map(str, path))} <- {kind}"
    try:
        scene = scenes.loads(text, source="<fuzz>", base_dir=base_dir)
    except ValueError as exc:  # SceneError is a ValueError
        msg = str(exc)
        assert msg and "\n" not in msg and len(msg) < 2000, f"{label}: unclear error {msg!r}"
        accepted = False
    else:
        accepted = True
    if cli and tmp is not None:
        for extra in base_dir.iterdir():  # the files the scene names (materials, heightmaps)
            if extra.suffix != ".toml" and not (Path(tmp) / extra.name).exists():
                (Path(tmp) / extra.name).write_bytes(extra.read_bytes())
        f = Path(tmp) / "mutant.toml"
        f.write_text(text)
        out, err = io.StringIO(), io.StringIO()
        code = main(["validate", str(f), "--json"], stdout=out, stderr=err)
        lines = [ln for ln in err.getvalue().splitlines() if not ln.startswith("hazard: warning:")]
        assert "Traceback" not in err.getvalue(), f"{label}: traceback"
        assert code == (0 if accepted else 2), f"{label}: validate exit {code} but loads {'accepted' if accepted else 'refused'}: {err.getvalue()}"
        assert len(lines) == (0 if accepted else 1), f"{label}: stderr {err.getvalue()!r}"
    if not accepted:
        return "rejected"
    if not analyse:
        return "loaded"
    old = _time_box(CASE_SECONDS)
    cpu_start = time.process_time()
    try:
        result = hazard.analyze(scene, progress=None, threads=1)
        doc = report_dict(result)
    except _Timeout:
        raise AssertionError(f"{label}: analysis ran over {CASE_SECONDS} s") from None
    except ValueError as exc:  # an accepted scene the analysis refuses: validate and run disagree
        raise AssertionError(f"{label}: accepted by loads but the analysis refused it: {exc}") from None
    finally:
        _end_box(old)
    assert time.process_time() - cpu_start < CASE_SECONDS
    declared = {t["name"] for t in mutant["targets"] if isinstance(t, dict) and "name" in t} or {t.name for t in scene.targets}
    reported = {t["name"] for t in doc["targets"]}
    bad = _non_finite(doc)
    assert not bad, f"{label}: non-finite numbers at {bad[:5]}"
    if not declared <= reported:
        assert not REQUIRE_ALL_TARGETS, f"{label}: targets {sorted(declared - reported)} vanished from the report"
        return "accepted, a target missing from the report"
    return "accepted"


# -- the tests ---------------------------------------------------------------------------
STATS: Counter = Counter()


# 30 drawn cases in the default run (each an analysis of a mutated bundled scene); every
# case of every scene runs in the slow test_every_mutation below, pairs in test_pairs_of_mutations
@settings(max_examples=30, derandomize=True, deadline=None, database=None,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])
@given(case=st.sampled_from(ALL_CASES), use_cli=st.integers(0, 3))
def test_mutated_scenes(case, use_cli, tmp_path):
    STATS[run_case(*case, cli=use_cli == 0, tmp=tmp_path)] += 1


BOUNDARY_SAMPLE = 150  # mutants through loads (validate on a quarter) in the default run: 2.0 s CPU (240: 3.4 s)


def test_the_input_boundary_of_a_sample(tmp_path):
    """A seeded sample of the mutants through the input boundary only (no analysis: the cases
    above and the slow corpus do that): one clear line or acceptance, validate == loads."""
    counts = Counter(run_case(*c, cli=i % 4 == 0, tmp=tmp_path, analyse=False)
                     for i, c in enumerate(random.Random(7).sample(ALL_CASES, BOUNDARY_SAMPLE)))
    assert counts["rejected"] > 0 and counts["loaded"] > 0, counts  # both sides of the boundary are met


def test_named_examples_of_the_issue(tmp_path):
    """The issue's examples: each is one clear error line, at validation."""
    base = copy.deepcopy(BASES["plate"][0])
    cases = {
        "missing parameter": (("targets", 0, "material"), {"model": "lambertian"}, "missing parameter reflectance"),
        "infinite beam": (("laser", "beam_diameter_m"), math.inf, "finite"),
        "bool power": (("laser", "power_w"), True, "valid number"),
        "tiny grid": (("analysis", "direction_grid_deg"), 1e-308, "HAZARD_MAX_KEEPOUT_CELLS"),
        "device file": (("targets", 0, "material"), {"file": "/dev/zero"}, "not a regular file"),
        "five-parameter kd = 22": (("targets", 0, "material"), {"model": "torrance-sparrow-5", "kb": 0.072, "kr": 16.125,
                                                                 "b": -29.917, "a": 0.959, "kd": 22.0}, "hemispherical reflectance"),
    }
    for _what, (path, value, expect) in cases.items():
        d = copy.deepcopy(base)
        node = d
        for k in path[:-1]:
            node = node[k]
        node[path[-1]] = value
        with pytest.raises(scenes.SceneError, match=expect):
            scenes.loads(to_toml(d))
    d = copy.deepcopy(base)
    d["observers"] = [{"name": "g", "origin_m": [0.0, -20.0, -5.0], "u_m": [10.0, 0.0, 0.0], "v_m": [0.0, 0.0, 10.0],
                       "counts": [31623, 31623]}]
    with pytest.raises(scenes.SceneError, match="HAZARD_MAX_OBSERVERS"):
        scenes.loads(to_toml(d))
    text = to_toml(base).replace('"position_m" = [0.0, -50.0, 0.0]', '"position_m" = ' + "[" * 10000 + "]" * 10000)
    assert "[" * 10000 in text
    with pytest.raises(scenes.SceneError, match="nesting depth"):
        scenes.loads(text)
    d = copy.deepcopy(base)
    d["laser"]["divergence_rad"] = 1.0
    d["laser"]["beam_diameter_m"] = 5.0
    sc = scenes.loads(to_toml(d))
    assert any("mrad" in w for w in sc.warnings) and any("mm meant" in w for w in sc.warnings)
    for power, hint in ((5e7, "over 10 MW"), (1e-4, "under 1 mW")):
        d = copy.deepcopy(base)
        d["laser"]["power_w"] = power
        assert any(hint in w and "laser.power_w" in w for w in scenes.loads(to_toml(d)).warnings)
    assert not scenes.loads(to_toml(base)).warnings


@pytest.mark.slow
def test_every_mutation(tmp_path):
    """Every mutant of every bundled scene (several thousand), validate on a quarter."""
    counts = Counter()
    failures = []
    start = time.perf_counter()
    for i, case in enumerate(ALL_CASES):
        try:
            counts[run_case(*case, cli=i % 4 == 0, tmp=tmp_path)] += 1
        except AssertionError as exc:
            failures.append(str(exc).splitlines()[0])
    print(f"\nfuzz: {len(ALL_CASES)} cases, {dict(counts)}, {len(failures)} failures, {time.perf_counter() - start:.1f} s")
    assert not failures, "\n".join(failures[:20])


def second_path(a, k):
    """The mutant of the enumerated case ``a`` and the path of its ``k``-th field (modulo
    their count) that a second mutation hits; (None, None) when there is no such field."""
    name, path, first = a
    once = _mutate(BASES[name][0], path, first)
    if once is None:
        return None, None
    # not inside a "deep" list (its 200 levels are one case; a second "deep" in it made 400,
    # past the recursion limit of this file's TOML writer: 2 "tracebacks" of the harness)
    paths = [p for p in _paths(once) if len(p) <= MAX_PATH_DEPTH]
    return (once, paths[k % len(paths)]) if paths else (None, None)


def run_pair(a, kind, k, *, cli=False, tmp=None) -> str:
    """Two mutations at once: the enumerated case ``a``, then ``kind`` at the ``k``-th field
    of its mutant; the outcome of :func:`run_case` ("skipped" when there is no second field)."""
    once, path = second_path(a, k)
    if path is None:
        return "skipped"
    name = f"{a[0]}+"
    BASES[name] = (once, BASES[a[0]][1])
    try:
        return run_case(name, path, kind, cli=cli, tmp=tmp)
    finally:
        del BASES[name]


def pair_cases(n, seed=30, firsts=None):
    """``n`` seeded pairs (first case, second mutation, field index) for the resumable runner
    (tests/fuzz/run_corpus.py --pairs); the first drawn from ``firsts`` (default: every case)."""
    rng = random.Random(seed)
    firsts = list(firsts) if firsts is not None else ALL_CASES
    return [(rng.choice(firsts), rng.choice(MUTATIONS), rng.randrange(10_001)) for _ in range(n)]


@pytest.mark.slow
@settings(max_examples=2000, derandomize=True, deadline=None, database=None,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])
@given(a=st.sampled_from(ALL_CASES), kind=st.sampled_from(MUTATIONS), k=st.integers(0, 10_000))
def test_pairs_of_mutations(a, kind, k, tmp_path):
    """Two mutations at once: one enumerated, one more at another path of the mutant."""
    run_pair(a, kind, k)


def test_a_nesting_depth_error_names_the_line():
    """The depth limit named the file only ("<fuzz>: nesting depth = 203 exceeds ..."): 108 of
    1216 refused mutants in a seeded sample named no key or line. Now the line where the
    depth is reached, and its key when it is a bare key (a quoted key is not echoed)."""
    from tests._scene_text import PLATE_AT_50M

    text = PLATE_AT_50M.replace("position_m = [0.0, -50.0, 1.0]", "position_m = " + "[" * 40 + "1.0" + "]" * 40)
    line = next(i for i, ln in enumerate(text.split("\n"), 1) if ln.startswith("position_m = [[["))
    with pytest.raises(scenes.SceneError, match=rf"^<scene>: line {line} \(key position_m\): nesting depth = 40 exceeds"):
        scenes.loads(text)
    text = PLATE_AT_50M + '"zq9 SECRET" = ' + "[" * 40 + "]" * 40 + "\n"
    with pytest.raises(scenes.SceneError) as err:
        scenes.loads(text)
    assert f"<scene>: line {text.count(chr(10))}: nesting depth = 40" in str(err.value) and "SECRET" not in str(err.value)
    data, base_dir = BASES["plate"]
    mutant = to_toml(_mutate(data, ("laser", "power_w"), "deep"))
    line = next(i for i, ln in enumerate(mutant.split("\n"), 1) if "[[[" in ln)
    with pytest.raises(scenes.SceneError, match=rf"<fuzz>: line {line}: nesting depth = {DEEP + 1} exceeds the limit 32"):
        scenes.loads(mutant, source="<fuzz>", base_dir=base_dir)


def test_pairs_resume_by_key(tmp_path):
    """The resumable pairs runner (tests/fuzz/run_corpus.py --pairs): a seeded sample is the
    same sample each time, its keys name both mutations, a case in the log is not run again,
    and a pair leaves the bases as they were."""
    from tests.fuzz import run_corpus

    a, b = run_corpus._pairs(40, 5, None), run_corpus._pairs(40, 5, None)
    assert [k for _, k, _ in a] == [k for _, k, _ in b] and len({k for _, k, _ in a}) == len(a)
    assert all(k.count(":") == 3 and "+" in k for _, k, _ in a)
    log = tmp_path / "pairs.jsonl"
    assert run_corpus.main([str(log), "--pairs", "6", "--seed", "5"]) == 0
    first = log.read_text()
    assert run_corpus.main([str(log), "--pairs", "6", "--seed", "5"]) == 0 and log.read_text() == first  # nothing re-run
    assert run_corpus.summary(log, 6)["cases"] == len(run_corpus._pairs(6, 5, None))
    assert set(BASES) == set(scenes.examples())
    assert run_pair((("plate", ("laser", "power_w"), "0")), "delete", 0) == "rejected"
