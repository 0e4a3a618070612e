"""Benchmarks as pytest items, excluded from the default run (marker ``bench``)."""

import pytest

pytestmark = pytest.mark.bench


def test_bench_evaluate_many():
    from .bench_brdf import run

    res = run()
    print(res)


def test_bench_hazard_map():
    from .bench_engine import run

    print(run())


def test_bench_workflows():
    from .bench_workflows import run

    print(run())


def test_bench_keepout_refinement():
    from .bench_keepout import run

    tables = run()
    default = next(r for r in tables["refine_levels"] if r["refine_levels"] == 3)
    # the default's accuracy, as in the README table (errors are deterministic, times are not)
    assert default["nohd_error"] < 1e-9 and default["volume_error"] < 1e-4 and default["sharp kr=0.003 volume_error"] < 1e-4


def test_bench_whole_run():
    from .bench_whole_run import run

    print(run())


def test_bench_ray_cache():
    from .bench_ray_cache import run

    print(run())


def test_bench_motion():
    from .bench_motion import run

    print(run())


def test_bench_risk():
    from .bench_risk import run

    print(run())
