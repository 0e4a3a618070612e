"""Threaded blocks: order, caps, no threads within threads, BLAS held to one thread, and
results that do not depend on the thread count."""

import threading

import numpy as np
import pytest

import brdfmodels as bm
from brdfmodels.parallel import default_threads, map_blocks, thread_limit


def test_blocks_in_order_cover_every_row():
    out = map_blocks(lambda a, b: (a, b), 10, 3, threads=2)
    assert out == [(0, 3), (3, 6), (6, 9), (9, 10)]
    assert map_blocks(lambda a, b: (a, b), 0, 3, threads=2) == []


def test_blocks_run_on_worker_threads_with_one_blas_thread_and_no_nesting():
    from threadpoolctl import threadpool_info, threadpool_limits

    main = threading.get_ident()

    def blas_threads():
        return [lib["num_threads"] for lib in threadpool_info() if lib["user_api"] == "blas"]

    def block(a, b):
        blas = blas_threads()
        inner = map_blocks(lambda c, d: threading.get_ident(), 4, 1)  # would nest: runs inline
        return threading.get_ident(), default_threads(), blas, set(inner)

    # two BLAS threads outside (an xdist worker holds one: tests/conftest.py), one inside the blocks
    with threadpool_limits(limits=2, user_api="blas"):
        before = blas_threads()
        assert before and all(n == 2 for n in before)
        res = map_blocks(block, 8, 2, threads=2)
        for ident, cap, blas, inner in res:
            assert ident != main and cap == 1 and inner == {ident}
            assert all(n == 1 for n in blas)
        assert blas_threads() == before  # restored after the blocks


def test_thread_limit_caps_and_nests():
    assert map_blocks(lambda a, b: threading.get_ident(), 4, 1, threads=None)  # default runs
    with thread_limit(1):
        assert default_threads() == 1
        assert set(map_blocks(lambda a, b: threading.get_ident(), 4, 1)) == {threading.get_ident()}
        with thread_limit(3):  # an inner limit never raises the outer cap
            assert default_threads() == 1
    with thread_limit(2):
        assert default_threads() == 2
    for bad in (0, -1, 1.5, "2", None, True):
        with pytest.raises(ValueError, match="threads="):
            with thread_limit(bad):
                pass


def test_evaluate_many_and_sh_eval_do_not_depend_on_threads():
    rng = np.random.default_rng(5)
    basis = bm.SHBasis(8, 4, 2, 0)
    coef = rng.normal(scale=0.2, size=(5, basis.size))
    dyn = bm.DynamicBRDF(basis, np.linspace(0.0, 1.0, 5), coef, "s")
    n = 5000
    wo = bm.spherical_to_vector(rng.uniform(0, 1.5, n), rng.uniform(-np.pi, np.pi, n))
    wi = bm.spherical_to_vector(0.4, 0.2)
    states = np.linspace(0.0, 1.0, 7)
    scale = rng.uniform(0, 2, n)
    one = dyn.evaluate_many(wi, wo, states, row_scale=scale, chunk_rows=300, threads=1)
    two = dyn.evaluate_many(wi, wo, states, row_scale=scale, chunk_rows=300, threads=2)
    np.testing.assert_array_equal(one, two)
    static = bm.SphericalHarmonicBRDF(basis, coef[0])
    wo = np.tile(wo, (15, 1))  # more rows than one block of the static evaluation
    with thread_limit(1):
        a = static.evaluate(wi, wo)
    with thread_limit(2):
        b = static.evaluate(wi, wo)
    np.testing.assert_array_equal(a, b)
