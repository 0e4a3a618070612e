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
