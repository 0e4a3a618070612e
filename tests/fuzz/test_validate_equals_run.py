"""validate == run over the fuzz corpus: every mutant of :mod:`tests.fuzz.test_fuzz_scenes`
goes through ``hazard validate`` and through ``hazard run`` (and ``hazard risk`` for a
base with ``[uncertainty]``) up to the point where the run's work starts; the three must
agree: all accept, or all refuse with exit 2 and the same one-line message.

"Where the work starts" is the first call of the analysis (``hazard.pipeline.analysis.analyze``)
or of the risk's shared evaluator (``hazard.drivers.risk.run.shared``): both are replaced by a
stub that records the acceptance and stops, so the check costs a load per verb. Whether
the analysis itself then refuses an accepted mutant is the other fuzz test's question
(``run_case``: "accepted by loads but the analysis refused it").

Default: a seeded sample of the corpus; ``-m slow``: all of it.
"""

from __future__ import annotations

import io
import random
import shutil

import pytest

from hazard.cli import main
from tests.fuzz.test_fuzz_scenes import ALL_CASES, BASES, _mutate, to_toml

SAMPLE = 40  # mutants in the default run (seeded)


class _Accepted(BaseException):  # past the CLI error boundary (it catches Exception)
    """Raised by the stubs: the verb accepted its input and would start work now."""


def _stop(*args, **kwargs):
    raise _Accepted()


def _outcome(verb, path, tmp) -> tuple[str, str]:
    """("accepted", "") or ("refused", message without the verb's prefix)."""
    extra = {"validate": [], "run": ["-o", str(tmp / "out"), "--quiet"],
             "risk": ["-o", str(tmp / "risk"), "--serial", "--quiet"]}[verb]
    out, err = io.StringIO(), io.StringIO()
    try:
        code = main([verb, str(path), *extra], stdout=out, stderr=err)
    except _Accepted:
        return "accepted", ""
    lines = [ln for ln in err.getvalue().splitlines() if not ln.startswith("hazard: warning:")]
    if code == 0 and verb == "validate":
        return "accepted", ""
    assert code == 2 and len(lines) == 1 and "Traceback" not in err.getvalue(), f"{verb}: exit {code}: {err.getvalue()!r}"
    return "refused", lines[0].removeprefix(f"hazard {verb}: error: ")


def check_agreement(case, tmp, monkeypatch) -> str:
    name, path, kind = case
    data, base_dir = BASES[name]
    mutant = _mutate(data, path, kind)
    if mutant is None:
        return "skipped"
    for f in base_dir.iterdir():  # the files the scene names (materials, heightmaps)
        if f.suffix != ".toml" and not (tmp / f.name).exists():
            shutil.copy(f, tmp / f.name)
    scene = tmp / "mutant.toml"
    scene.write_text(to_toml(mutant))
    monkeypatch.setattr("hazard.pipeline.analysis.analyze", _stop)
    monkeypatch.setattr("hazard.drivers.risk.run.shared", _stop)
    label = f"{name}: {'.'.join(map(str, path))} <- {kind}"
    verbs = ["validate", "run"] + (["risk"] if "uncertainty" in data else [])
    got = {v: _outcome(v, scene, tmp) for v in verbs}
    if "risk" in got and got["validate"][0] == "accepted" and "uncertainty" not in mutant:
        # the mutation deleted [uncertainty]: risk alone needs it (its own message)
        assert got["risk"] == ("refused", f"{scene}: no [uncertainty] table: nothing is random (give pointing_sigma_rad, "
                                          f"brdf_scale_sigma, ...)"), f"{label}: {got}"
        del got["risk"]
    assert len(set(got.values())) == 1, f"{label}: verbs disagree: {got}"
    return got["validate"][0]


def _sample():
    rng = random.Random(30)
    return rng.sample(ALL_CASES, SAMPLE)


@pytest.mark.parametrize("case", _sample(), ids=lambda c: f"{c[0]}:{'.'.join(map(str, c[1]))}<-{c[2]}")
def test_validate_equals_run_sample(case, tmp_path, monkeypatch):
    check_agreement(case, tmp_path, monkeypatch)


def test_risk_mutants_agree(tmp_path, monkeypatch):
    """Mutants of the risk example, where all three verbs apply: a seeded sample of them."""
    rng = random.Random(5)
    cases = [c for c in ALL_CASES if c[0] == "risk" and c[1][0] == "uncertainty"]
    outcomes = {check_agreement(c, tmp_path, monkeypatch) for c in rng.sample(cases, 12)}
    assert outcomes <= {"accepted", "refused", "skipped"}


@pytest.mark.slow
def test_validate_equals_run_every_mutant(tmp_path, monkeypatch):
    failures = []
    for case in ALL_CASES:
        try:
            check_agreement(case, tmp_path, monkeypatch)
        except AssertionError as exc:
            failures.append(str(exc).splitlines()[0])
    assert not failures, f"{len(failures)} of {len(ALL_CASES)}:\n" + "\n".join(failures[:20])
