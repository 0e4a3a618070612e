"""hazard risk in bounded memory (issue 37 item 2): the chunks are read back one at a
time into a column store, and the observers' statistics are computed one block of
observers at a time.

The expected statistics are written here from their definitions (counts, weighted
sums, the inverse of the weighted empirical CDF by a sort per column), never from the
engine's functions; the streamed values must equal them, and must not depend on the
block size (bit for bit: numpy sums the rows of a block in the same order as of the
whole array). The memory test runs in a child process and reads its own VmHWM.
"""

from __future__ import annotations

import itertools
import json
import subprocess
import sys
import textwrap
from types import SimpleNamespace

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import scenes
from hazard.drivers.risk.columns import ColumnStore, block_bounds
from hazard.drivers.risk.results import observer_stats
from tests._scene_text import PLATE_AT_50M

QS = (0.50, 0.95, 0.99)
FAST = settings(derandomize=True, deadline=None, max_examples=25)


@FAST
@given(rows=st.integers(1, 5000), cols=st.integers(1, 3000), budget=st.integers(1, 50_000))
def test_blocks_cover_the_columns_never_one_wide(rows, cols, budget):
    b = block_bounds(rows, cols, budget)
    assert b[0][0] == 0 and b[-1][1] == cols
    assert all(x[1] == y[0] for x, y in itertools.pairwise(b))
    widths = [j1 - j0 for j0, j1 in b]
    assert min(widths) >= (1 if cols == 1 else 2)  # a one-column block would be summed pairwise
    assert max(widths) <= max(3, budget // rows)  # about the budget (two or three columns when it is smaller)


@FAST
@given(seed=st.integers(0, 2**32 - 1), rows=st.integers(1, 60), cols=st.integers(1, 40), budget=st.integers(1, 400))
def test_store_gives_back_the_columns(tmp_path_factory, seed, rows, cols, budget):
    rng = np.random.default_rng(seed)
    a = rng.standard_normal((rows, cols))
    cuts = np.sort(rng.integers(0, rows + 1, 3))
    with ColumnStore(tmp_path_factory.mktemp("cs"), {"x": rows}, cols, budget) as store:
        for lo, hi in zip([0, *cuts], [*cuts, rows]):
            store.append("x", a[lo:hi])
        got = np.hstack([blk for _, _, blk in store.blocks("x")])
    np.testing.assert_array_equal(got, a)


def _oracle(r, w, gains, importance):
    """Per observer, from the definitions: hits, P estimate, quantiles (smallest value with
    at least the fraction q of the weight at or below it), lit fraction and lit quantiles."""
    n, m = r.shape
    out = {"hits": [], "p": [], "q": [], "lit": [], "q_lit": []}
    for j in range(m):
        own = r[:, j] * gains[j]
        over = own >= 1.0
        out["hits"].append(int(over.sum()))
        out["p"].append(float(np.sum(w[over])) / n if importance else over.sum() / n)
        ww = w if importance else np.ones(n)
        out["q"].append(_quantiles(own, ww))
        lit = own > 0
        out["lit"].append(float(ww[lit].sum() / ww.sum()))
        out["q_lit"].append(_quantiles(own[lit], ww[lit]) if lit.any() else [np.nan] * 3)
    return {k: np.array(v, float) for k, v in out.items()}


def _quantiles(v, w):
    order = np.argsort(v, kind="stable")
    cum, total, res = 0.0, float(np.sum(w)), []
    pairs = list(zip(v[order].tolist(), w[order].tolist()))
    for q in QS:
        cum = 0.0
        for x, wi in pairs:
            cum += wi
            if cum / total >= q - 1e-12:
                res.append(x)
                break
    return res


def _stats(tmp, r, log_w, gains, importance, budget):
    n, m = r.shape
    scene = scenes.loads(PLATE_AT_50M + '[[observers]]\nname = "o"\npoints_m = [[5.0, -20.0, 1.0]]\n')
    ev = SimpleNamespace(own_gain=lambda: gains, scene=scene)
    s = SimpleNamespace(sampling="importance" if importance else "plain", draws=n, n_observers=m)
    with ColumnStore(tmp, {"ratio": n}, m, budget) as store:
        for lo in range(0, n, 37):
            store.append("ratio", r[lo:lo + 37])
        got = SimpleNamespace(log_weight=log_w, store=store)
        return observer_stats(ev, s, got)


@FAST
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(20, 300), m=st.integers(1, 30), importance=st.booleans())
def test_streamed_statistics_equal_the_definitions_and_the_whole_array(tmp_path_factory, seed, n, m, importance):
    rng = np.random.default_rng(seed)
    r = np.where(rng.random((n, m)) < 0.4, 0.0, np.exp(rng.normal(0, 1.2, (n, m))))  # unlit draws, and ratios about 1
    log_w = np.log(rng.choice([0.5, 1.0, 2.0], n))  # dyadic weights: every sum exact
    gains = rng.choice([1.0, 2.0, 4.0], m)
    small = _stats(tmp_path_factory.mktemp("a"), r, log_w, gains, importance, 2 * n)  # two-column blocks
    whole = _stats(tmp_path_factory.mktemp("b"), r, log_w, gains, importance, 10**9)  # one block
    for k in ("p", "lo", "hi", "hits", "n_eff", "q", "q_lit", "lit_frac"):
        np.testing.assert_array_equal(getattr(small, k), getattr(whole, k), err_msg=k)
    want = _oracle(r, np.exp(log_w), gains, importance)
    np.testing.assert_array_equal(small.hits, want["hits"])
    np.testing.assert_allclose(small.p, want["p"], rtol=1e-12, atol=0)
    np.testing.assert_array_equal(small.q.T, want["q"])
    np.testing.assert_array_equal(small.q_lit.T, want["q_lit"])
    np.testing.assert_allclose(small.lit_frac, want["lit"], rtol=1e-12)


CHILD = textwrap.dedent('''
    import json, sys, tempfile
    from pathlib import Path
    from types import SimpleNamespace
    import numpy as np
    import scenes
    from hazard.drivers.risk.results import observer_stats
    from hazard.drivers.risk.run import Chunks, gather

    def hwm_mb():
        with open("/proc/self/status") as f:
            return next(int(l.split()[1]) for l in f if l.startswith("VmHWM:")) / 1024

    draws, m, chunk, text = int(sys.argv[1]), int(sys.argv[2]), int(sys.argv[3]), sys.argv[4]
    d = Path(tempfile.mkdtemp(dir=sys.argv[5]))
    files = []
    for c in range(0, draws, chunk):  # the chunks a run leaves in .risk/, one at a time
        rng = np.random.default_rng(c)
        ratio = np.where(rng.random((chunk, m)) < 0.5, 0.0, rng.exponential(0.5, (chunk, m)))
        f = d / f"m{c:06d}.npz"
        np.savez(f, ratio=ratio, log_weight=np.zeros(chunk), component=np.zeros(chunk, int), map_hits=np.zeros(0),
                 map_sum_w=np.zeros(0), map_sum_w2=np.zeros(0))
        files.append(f)
        del ratio
    before = hwm_mb()
    s = SimpleNamespace(sampling="plain", draws=draws, n_observers=m, sensitivity_draws=0)
    got = gather(Chunks(files, [], 0, len(files)), s, [], d)
    scene = scenes.loads(text)
    st = observer_stats(SimpleNamespace(own_gain=lambda: np.ones(m), scene=scene), s, got)
    got.store.close()
    print(json.dumps({"writing_mb": before, "peak_mb": hwm_mb(), "hits": float(st.hits.sum())}))
''')


@pytest.mark.slow
def test_risk_statistics_memory_is_bounded_by_the_block_not_the_data(tmp_path):
    """1e4 draws x 1e4 observers of ratios (800 MB as float64; the whole-array statistics
    took 6.6 GB at this size) are reduced within a few hundred MB (measured: see README)."""
    pytest.importorskip("scipy")
    if not sys.platform.startswith("linux"):
        pytest.skip("VmHWM is Linux's")
    draws, m, chunk = 10_000, 10_000, 200
    text = PLATE_AT_50M + '[[observers]]\nname = "o"\npoints_m = [[5.0, -20.0, 1.0]]\n'
    out = subprocess.run([sys.executable, "-c", CHILD, str(draws), str(m), str(chunk), text, str(tmp_path)],
                         capture_output=True, text=True, timeout=600, check=True)
    got = json.loads(out.stdout.strip().splitlines()[-1])
    data_mb = draws * m * 8 / 2**20
    assert got["hits"] > 0  # the statistics ran over the data
    assert got["peak_mb"] < 0.6 * data_mb, got  # never the whole (draws, M) array, let alone its sort's temporaries
