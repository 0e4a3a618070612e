"""Benchmarks as pytest items (marker ``bench``, excluded from the default run): each
asserts its goal as a ratio of its time to its floor measured in the same run (median of
5 each), never a time on its own.

    python -m pytest tests/bench -m bench -s                  # the issues' sizes and goals
    BENCH_QUICK=1 python -m pytest tests/bench -m bench -s    # .ci/run: small sizes, quick goals

Full goals: from the issues (map and whole run 1.3, issue 37; ``evaluate_many`` 1.5,
issue 2) or, where no issue set one, the README's figures with room for the +-30 % of a
shared machine (marked "bound"). Quick goals: set from the ratios measured at the quick
sizes on this 2-core machine under a load of 11-14 (other engineers' jobs), with room
above the largest; they catch a path that becomes several times slower, not 10 %. A goal
the code does not meet today is an ``xfail`` that names the measured ratio (visible in
the summary, never hidden); a pass there shows as XPASS.
"""

import pytest

from ._floor import QUICK, check_goal

pytestmark = pytest.mark.bench

# goals without an issue behind them (see the module's docstring)
MOTION_FULL = 25.0  # bound: README 9 ms against a 0.4 ms floor (22)
MOTION_QUICK = 300.0  # measured 85-160 at load 11-14 (the floor is 0.7 ms: the ratio is noisy)
LOBE_QUICK = 4.0  # the lobe at 1 deg: measured 1.85 at load 11


def goal(full, quick):
    return quick if QUICK else full


def not_met(reason):
    """The full goal is not met today: expected to fail (not strict), with the measured ratio."""
    return pytest.mark.xfail(not QUICK, reason=reason, strict=False)


def test_bench_evaluate_many():
    from .bench_brdf import run

    res = run(n=300_000 if QUICK else 1_000_000)  # quick: at 1e5 the fixed costs per call dominate (2.1-3.7 on one code)
    check_goal("evaluate_many", res["ratio"], goal(1.5, 3.0))


def test_bench_hazard_map():  # issue 37: 1.16-1.23 in CPU time, quiet (2026-11-26, load 0.9-1.3; 1.34-1.35 before the plain lines of sight)
    from .bench_engine import run

    res = run(rows=50 if QUICK else 1000)
    check_goal("hazard map stages", res["ratio"], goal(1.3, 5.0))  # quick: 1.4-3.5 in CPU time at load 5-25 (0.05-0.08 s floor)


def test_bench_whole_run():  # issue 37: 1.23-1.25 in CPU time against the complete floor, quiet (2026-11-26, load 0.9-1.2)
    from .bench_whole_run import run

    res = run(rows=50 if QUICK else 1000)
    check_goal("whole run", res["ratio"], goal(1.3, 4.0))


def test_bench_outputs():  # issue 37: 0.83-1.04x the analysis in wall time, median 0.94 of six (met), quiet (2026-11-27, load 1.4-1.9)
    from .bench_outputs import run

    res = run(rows=100 if QUICK else 1000, repeat=3)
    check_goal("outputs / analysis", res["ratio"], goal(1.0, 3.0))  # quick: 0.18 measured at load 2.6 (1.06 at load 6 before)


@not_met("motion stage: ratio 104 at load 12 (73 ms vs 0.7 ms); met (XPASS) on 2026-11-26 at load ~2")
def test_bench_motion():
    from .bench_motion import run

    res = run()
    check_goal("motion stage", res["ratio"], goal(MOTION_FULL, MOTION_QUICK))


def test_bench_risk():
    from .bench_risk import run

    res = run(n=20 if QUICK else 200)
    check_goal("risk per draw", res["ratio"], goal(1.3, 2.0))


def test_bench_ray_cache():
    from .bench_ray_cache import run

    res = run(resolution_m=5.0 if QUICK else 1.7)
    # a hit (hash + lookup) against the Embree build it saves: README 0.02-0.04 s against 1.2-1.5 s
    check_goal("ray cache hit / build", res["hit_s"] / res["build_s"], goal(0.1, 0.3))


def test_bench_workflows():
    """Full: the study on a 2-worker LocalCluster, the keep-out lobe at 0.25 deg and the
    render. Quick: the lobe at 1 deg only (a quick study measures the cluster's start:
    20 scenarios took 18.6 s against a 1.1 s floor at load 11)."""
    if not QUICK:
        pytest.importorskip("distributed", reason="the study runs on a Dask LocalCluster: pip install 'laser-hazard[cluster]'")
        pytest.importorskip("pyvista", reason="the render needs pyvista: pip install 'laser-hazard[render]'")
    from .bench_workflows import run

    rows = run(study_scenarios=0 if QUICK else 200, lobe_grid_deg=1.0 if QUICK else 0.25, render=not QUICK)
    # bounds (no issue set goals): README study 1.9-2.3, lobe 2.0-2.2, render 2.6-3.8
    goals = [(LOBE_QUICK,)] if QUICK else [(3.0,), (3.0,), (5.0,)]
    assert len(rows) == len(goals)
    failed = []
    for row, (g,) in zip(rows, goals):  # every row checked (and printed at the end) before any fails
        try:
            check_goal(row["name"], row["ratio"], g)
        except AssertionError as e:
            failed.append(str(e))
    assert not failed, "; ".join(failed)


@pytest.mark.skipif(QUICK, reason="accuracy tables over every bundled scene at 9 settings x 3 runs: minutes, not a quick check")
def test_bench_keepout_refinement():
    from .bench_keepout import run

    tables = run()
    default = next(r for r in tables["refine_levels"] if r["refine_levels"] == 3)
    # the default's accuracy, as in the README table (errors are deterministic, times are not)
    assert default["nohd_error"] < 1e-9 and default["volume_error"] < 1e-4 and default["sharp kr=0.003 volume_error"] < 1e-4
