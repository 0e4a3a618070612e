"""hazard.outputs._select.top_rows (issue 37: the rows report.json and the map list, found by one
partition instead of a sort of every row) against the stable sort it replaces, and the
map's choice against its lexsort, on random columns with ties, zeros, -0.0 and inf."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from hazard.outputs._select import top_rows

_VALUES = st.lists(st.sampled_from([0.0, -0.0, 0.5, 1.0, 1.0, 2.0, 3.5, np.inf, 1e-300, 7.0]) | st.floats(0, 1e6),
                   min_size=1, max_size=300)


def _stable(score, k):
    return np.sort(np.argsort(-np.asarray(score), kind="stable")[:k])


def _check(values, k):
    score = np.array(values, float)
    np.testing.assert_array_equal(top_rows(score, k), _stable(score, k))


@settings(derandomize=True, deadline=None, max_examples=40)
@given(values=_VALUES, k=st.integers(0, 320))
def test_top_rows_is_the_stable_sorts_first_k(values, k):
    _check(values, k)


@pytest.mark.slow
@settings(derandomize=True, deadline=None, max_examples=1000)
@given(values=_VALUES, k=st.integers(0, 320))
def test_top_rows_is_the_stable_sorts_first_k_many(values, k):
    _check(values, k)


class _Result:
    def __init__(self, ratio, haz):
        self.hazard_ratio, self.hazardous = ratio, haz


@settings(derandomize=True, deadline=None, max_examples=25)
@given(values=_VALUES, nan=st.lists(st.booleans(), min_size=300, max_size=300), extra=st.lists(st.booleans(), min_size=300, max_size=300),
       k=st.integers(1, 40))
def test_map_shows_every_hazardous_then_the_highest(values, nan, extra, k):
    """observers_on_map: the first max(k, hazardous) of the lexsort (hazardous first, then
    by ratio, NaN highest), in row order; hazardous also where the ratio is below 1 (over time)."""
    from hazard.outputs import map_zones

    ratio = np.array(values, float)
    ratio[np.array(nan[:len(ratio)])] = np.nan
    haz = (np.nan_to_num(ratio, nan=np.inf) >= 1.0) | np.array(extra[:len(ratio)])
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(map_zones, "MAP_OBSERVERS_MAX", k)
        rows, which = map_zones.observers_on_map(_Result(ratio.copy(), haz))
    if len(ratio) <= k:
        np.testing.assert_array_equal(rows, np.arange(len(ratio)))
        return
    r = np.nan_to_num(ratio, nan=np.inf)
    want = np.sort(np.lexsort((-r, ~haz))[: max(k, int(haz.sum()))])
    np.testing.assert_array_equal(rows, want)
    assert which.startswith(f"{len(want)} of {len(ratio)}")


@settings(derandomize=True, deadline=None, max_examples=60)
@given(values=_VALUES, k=st.integers(1, 20))
def test_top_rows_from_a_sampled_threshold(values, k):
    """The rows found among the candidates a strided sample lets through (its size made 4,
    so that columns of 16+ rows take that path) are the stable sort's, ties and inf included."""
    from hazard.outputs import _select

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(_select, "SAMPLE_ROWS", 4)
        _check(values, k)


def _columns(rng, m):
    """Large columns on which a strided sample is fair, biased (period of the stride, the
    top away from the sampled rows) or all ties."""
    periodic = np.tile(rng.random(977), m // 977 + 1)[:m]
    off_stride = np.zeros(m)
    off_stride[1::2] = rng.random(m // 2)  # the sample (an even stride) sees only zeros
    sampled_high = np.zeros(m)
    sampled_high[:: m // 32_768] = 1.0 + rng.random(len(sampled_high[:: m // 32_768]))  # the sample sees only its top
    ties = rng.integers(0, 4, m).astype(float)
    return {"random": rng.random(m), "periodic": periodic, "off stride": off_stride, "sampled high": sampled_high,
            "ties": ties, "ascending": np.sort(rng.random(m)), "inf and -inf": np.where(rng.random(m) < 0.3, -np.inf, periodic)}


@pytest.mark.parametrize("k", [1, 977, 8000])
def test_top_rows_of_large_columns(k):
    """131 072 rows (the sampled path: a stride of 4), each kind of column against the stable sort."""
    rng = np.random.default_rng(k)
    for name, score in _columns(rng, 131_072).items():
        np.testing.assert_array_equal(top_rows(score, k), _stable(score, k), err_msg=name)


def test_sampled_threshold_falls_back_when_too_few_rows_pass():
    """A column whose sampled rows hold its top: fewer than k rows reach the sample's
    threshold, every row stays a candidate, and the rows are still the stable sort's."""
    from hazard.outputs._select import _candidates

    score = _columns(np.random.default_rng(5), 131_072)["sampled high"]
    assert _candidates(score, 8000) is None
    assert _candidates(np.random.default_rng(5).random(131_072), 8000) is not None  # a fair sample: the few candidates
    np.testing.assert_array_equal(top_rows(score, 8000), _stable(score, 8000))
