"""The bundled range_clearance example says what its README walk-through says it says."""

from __future__ import annotations

import math

import numpy as np
import pytest

from tests._bundled import bundled


@pytest.fixture(scope="module")
def result():
    return bundled("range_clearance")


def test_the_danger_zone_is_contained_by_the_hill_and_stays_on_the_range(result):
    z = result.sdz
    assert z.directions.kind == "cone" and z.directions.buffer_rad == pytest.approx(3 * 5e-5)
    assert z.contained and z.leaves_boundary is False and not z.above_horizon
    assert z.max_range_m < 1700 < z.nohd_m  # the hill, not the NOHD, ends it
    assert all(a.contained and a.nohd_m > z.nohd_m for a in z.aided)


def test_the_spill_is_hazardous_on_its_way_and_found_on_the_grid(result):
    (stop,) = result.spill.stopped
    assert stop.object == "terrain" and stop.hazard_ratio > 1
    labels = result.observers.labels
    hot = [labels[i] for i in np.flatnonzero(result.hazardous)]
    assert hot and all(n.startswith("approach:crossing") for n in hot)
    k = labels.index("approach:crossing[1]")
    assert result.observers.position_m[k][1] > 0  # behind the board, in the spill ring


def test_the_spotters_are_outside_the_aided_diffuse_nohd(result):
    board = next(t for t in result.targets if t.name == "target-board")
    aided = board.aided[0]["nohd_dynamic_m"]
    labels = result.observers.labels
    for i in (labels.index("spotters[0]"), labels.index("spotters[1]")):
        p = result.observers.position_m[i]
        assert math.dist(p[:2], (0.0, 0.0)) > aided and not result.hazardous[i]
    assert any(t.name == "terrain" for t in result.targets)  # the spill's landing place reflects
