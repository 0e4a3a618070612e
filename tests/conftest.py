"""Test-suite configuration: deterministic property tests on CI; one BLAS thread per
xdist worker.

``pytest -n auto`` runs one worker per core. Each worker's OpenBLAS would start a pool of
one thread per core as well, so two workers on two cores ran four BLAS threads, and
OpenBLAS's threads spin while they wait: a 1452 x 37 SVD (a fit with its horizon rows)
took 0.235 s of CPU on two threads against 0.0016 s on one on this 2-core machine at load
20 (`test_fold_solver_equals_fit_sh_per_fold` 5.3-6.6 s -> 0.2 s). A worker therefore holds
BLAS to one thread (threadpoolctl, and the environment for the processes it starts). The
engine's own thread blocks (``brdfmodels.parallel``) already run BLAS on one thread; the
results do not depend on the BLAS thread count (``tests/brdfmodels/test_parallel.py``
raises it to two where it checks the blocks' limit).

``-n`` without ``--dist`` hands each worker whole test files (``--dist loadfile``) instead
of single tests: a module's shared set-up (a module-scoped run of a bundled example, a
risk run, a plotted run) then runs once, not once in each worker. With xdist's default
(``load``) the first quarter of the suite is dealt out one test at a time in turn, and
later tests in chunks, so most modules' fixtures ran in both workers (three plotting
modules under ``-n 2``: 105 s CPU with ``load``, their 15 s / 10 s / 10 s fixtures twice).
An explicit ``--dist`` is left as given; serial runs are unaffected.
"""

import os

import pytest
from hypothesis import settings

settings.register_profile("ci", derandomize=True, deadline=None, print_blob=True)
settings.register_profile("dev", deadline=None)
settings.load_profile("ci" if os.environ.get("CI") else "dev")

_BLAS_VARS = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")
_blas_limit = []  # the worker's threadpoolctl limit, held for the session


@pytest.hookimpl(tryfirst=True)  # before xdist's own, which makes "no" into "load" under -n
def pytest_cmdline_main(config):
    """``-n`` without ``--dist``: whole files per worker (see the module's docstring)."""
    if config.getoption("numprocesses", None) and config.getoption("dist", "no") == "no":
        config.option.dist = "loadfile"


def pytest_configure(config):
    """In an xdist worker: BLAS on one thread (see the module's docstring)."""
    if not os.environ.get("PYTEST_XDIST_WORKER"):
        return
    for var in _BLAS_VARS:
        os.environ.setdefault(var, "1")
    try:
        from threadpoolctl import threadpool_limits
    except ImportError:  # numpy not loaded yet: the environment above is enough
        return
    _blas_limit.append(threadpool_limits(limits=1, user_api="blas"))
