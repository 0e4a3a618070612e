"""The slump's sampling (hazard.physics.slump) and the melt times of series histories."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import brdfmodels as bm
from hazard.pipeline.history import series_melt
from hazard.physics.slump import SpotSlump, _chunks, _disk_offsets, normal_rotations, rotation


def _angle(a, b):
    return math.degrees(math.acos(min(1.0, abs(float(np.dot(a, b))))))


WANDER_ARGS = (st.floats(0.1, 8.0), st.floats(0.25, 2.0), st.integers(0, 2**31 - 1))


@settings(max_examples=10, deadline=None, derandomize=True)  # 40 took 4.1 s CPU; the slow twin below draws 200
@given(*WANDER_ARGS)
def test_wander_disk_samples_leave_no_normal_farther_than_the_step(wander_deg, step_deg, seed):
    """Every normal within the wander bound has a sampled normal within one step (the
    rings are ``step`` apart and points on a ring are at most ``step`` apart)."""
    n = np.array([0.0, 0.0, 1.0])
    sl = SpotSlump(np.zeros(2), np.full(2, math.radians(wander_deg)), np.array([1.0, 0.0, 0.0]), math.radians(step_deg))
    normals = normal_rotations(sl, n, 0, 1, sl.step_rad) @ n
    rng = np.random.default_rng(seed)
    r = math.radians(wander_deg) * np.sqrt(rng.uniform(0, 1, 200))  # uniform over the disk
    az = rng.uniform(0, 2 * math.pi, 200)
    for ri, ai in zip(r, az):
        q = np.array([math.sin(ri) * math.cos(ai), math.sin(ri) * math.sin(ai), math.cos(ri)])
        assert min(_angle(q, m) for m in normals) <= step_deg * (1 + 1e-9)
    assert all(_angle(m, n) <= wander_deg * (1 + 1e-9) for m in normals)  # nothing outside the bound


@pytest.mark.slow
@settings(max_examples=200, deadline=None, derandomize=True)
@given(*WANDER_ARGS)
def test_wander_disk_samples_leave_no_normal_farther_than_the_step_many(wander_deg, step_deg, seed):
    test_wander_disk_samples_leave_no_normal_farther_than_the_step.hypothesis.inner_test(wander_deg, step_deg, seed)


def test_tilt_range_is_sampled_at_both_ends_and_every_step():
    """Over a chunk the mean normal takes every tilt in [lo, hi]: samples at both ends
    and no gap wider than the step, all rotating about the axis towards the direction."""
    n, d = np.array([0.0, -1.0, 0.0]), np.array([0.0, 0.0, 1.0])
    axis = np.cross(n, d)
    tilt = np.radians([0.0, 1.3, 4.1])
    sl = SpotSlump(tilt, np.zeros(3), axis, math.radians(1.0))
    normals = normal_rotations(sl, n, 0, 2, sl.step_rad) @ n
    up = np.sort(np.degrees(np.arcsin(np.clip(normals @ d, -1, 1))))  # each sample's tilt towards d
    assert up[0] == pytest.approx(0.0, abs=1e-12) and up[-1] == pytest.approx(4.1, rel=1e-12)
    assert np.max(np.diff(up)) <= 1.0 + 1e-9


def test_chunks_share_their_ends_and_split_at_melt_onset():
    """Chunks cover every time, consecutive chunks share one time (the path stays
    joined), the pre-melt chunk has no wander, and no chunk's tilt spans more than two
    steps."""
    f = np.r_[np.zeros(6), np.linspace(0, 1, 15)[1:], np.ones(5)]
    tilt, wander = math.radians(6) * f, np.where(f > 0, math.radians(2), 0.0)
    sl = SpotSlump(tilt, wander, np.array([1.0, 0.0, 0.0]), math.radians(1.0))
    ch = _chunks(sl)
    assert ch[0][0] == 0 and ch[-1][1] == len(f) - 1
    assert all(a[1] == b[0] for a, b in zip(ch[:-1], ch[1:]))
    assert wander[ch[0][0]:ch[0][1] + 1].max() == 0.0  # pre-melt: the nominal normal alone
    for a, b in ch:
        assert np.ptp(tilt[a:b + 1]) <= 2 * sl.step_rad + 1e-12


def test_rotation_is_rodrigues():
    """Rotating x by 90 deg about z gives y; rotations are orthonormal."""
    r = rotation([0.0, 0.0, 1.0], math.pi / 2)
    np.testing.assert_allclose(r @ [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], atol=1e-15)
    r = rotation(np.array([1.0, 2.0, 2.0]) / 3.0, 0.7)
    np.testing.assert_allclose(r @ r.T, np.eye(3), atol=1e-15)


def test_disk_of_zero_wander_is_its_centre():
    assert _disk_offsets(0.0, 0.01) == [(0.0, 0.0)]


def test_series_melt_times():
    """A melt-fraction series 0, 0, 0.5, 1: melting starts at the last zero (linear
    between points) and is complete where the series reaches 1."""
    h = bm.History([0.0, 2.0, 4.0, 5.0, 8.0], [[0.3, 0.0], [0.5, 0.0], [0.7, 0.5], [0.8, 1.0], [0.9, 1.0]],
                   ["extinction", "melt_fraction"])
    m = series_melt(h, np.linspace(0, 8, 9))
    assert m.onset_s == 2.0 and m.full_s == 5.0
    np.testing.assert_allclose(m.fraction, np.interp(np.linspace(0, 8, 9), [0, 2, 4, 5, 8], [0, 0, 0.5, 1, 1]))
    assert series_melt(bm.History([0.0, 1.0], [0.3, 0.5], "extinction"), np.array([0.0])) is None
    one = series_melt(bm.History([0.0, 1.0, 3.0], [0.0, 0.4, 0.8], "melt_fraction"), np.array([0.0, 3.0]))
    assert one.onset_s == 0.0 and one.full_s is None


def test_slumping_target_reports_melt_times_sampling_and_what_is_left_out():
    """stainless_melt: the target row says when it melts, how the slump was sampled
    (with the half-step check, never below it) and what the slump leaves out."""
    import hazard
    import scenes

    res = hazard.analyze(scenes.load(scenes.examples()["stainless_melt"]))
    row = res.targets[0].to_dict()
    assert 0 < row["melt"]["onset_s"] < row["melt"]["full_melt_s"] < 10.0
    sl = row["slump"]
    assert sl["tilt_deg"] == pytest.approx(6.0) and sl["wander_deg"] == pytest.approx(2.0)
    assert sl["normals_sampled"] > 1 and sl["normals_sampled_half_step"] > sl["normals_sampled"]
    assert row["nohd_dynamic_m"] >= sl["max_nohd_half_step_m"]
    assert "wander at the observers" in sl["left_out"] and "behind the plate" in sl["left_out"]
    from hazard.outputs.report import summary_text

    assert "slump left out: the wander at the observers" in summary_text(res)
