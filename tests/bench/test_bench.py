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
