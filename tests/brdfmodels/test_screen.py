"""Witness-screen reduction against its own forward model and the paper's equations."""

import warnings

import numpy as np
import pytest

import brdfmodels as bm
from brdfmodels import screen

from .conftest import TS5_PUBLISHED, make_dynamic

STEEL = bm.TorranceSparrow5(**TS5_PUBLISHED["forged_steel"])


def test_noise_free_reduction_recovers_the_brdf_exactly():
    t = screen.simulate_test(STEEL, noise=0.0, incidence_deg=30.0, groove_angle_deg=90.0)
    s = screen.reduce_test(t)
    assert len(s) > 5000
    np.testing.assert_allclose(s.brdf_per_sr, STEEL.evaluate(s.wi, s.wo), rtol=1e-12)


def test_dynamic_frames_recover_each_state():
    dyn = make_dynamic()
    t = screen.simulate_test(dyn, noise=0.0, times_s=(0.0, 1.0, 2.0), state_of_time=lambda tt: 300.0 + 300.0 * tt,
                             temperature_of_time=lambda tt: 500.0 + tt, gain_counts=50.0)
    s = screen.reduce_test(t)
    for f, state in enumerate((300.0, 600.0, 900.0)):
        sel = s.frame_id == f
        np.testing.assert_allclose(s.brdf_per_sr[sel], dyn.evaluate(s.wi[sel], s.wo[sel], state=state), rtol=1e-12)
    np.testing.assert_allclose(np.unique(s.temperature_k), [500.0, 501.0, 502.0])
    groups = screen.group_by_state(s, "time_s", [0.0, 2.0])
    assert set(groups) == {0.0, 2.0} and np.all(groups[2.0].time_s >= 1.0)


def test_noise_propagates_as_expected():
    # pixel noise enters twice (frame and point-source image): scatter 2 % x sqrt(2); the
    # single calibration pixel U_C^P scales the whole test by its own noise, a systematic
    # of the method of the same size
    t = screen.simulate_test(STEEL, noise=0.02, seed=3)
    s = screen.reduce_test(t)
    rel = s.brdf_per_sr / STEEL.evaluate(s.wi, s.wo) - 1
    assert abs(np.mean(rel)) < 3 * 0.02 and np.std(rel) == pytest.approx(0.02 * np.sqrt(2), rel=0.1)


def test_eq16_expanded_equals_step_by_step():
    rng = np.random.default_rng(0)
    up = rng.uniform(10, 100, (8, 8))
    u = rng.uniform(1, 50, (8, 8))
    r = rng.uniform(0.5, 1.0, (8, 8))
    cal = screen.Calibration(5.0, (3, 4), 1234.0)
    ci, cr = rng.uniform(0.3, 1, (8, 8)), rng.uniform(0.3, 1, (8, 8))
    resp = screen.responsivity(up, r, cal, r[3, 4])
    a = screen.frame_brdf(u, resp, r, ci, cr, 230.0)
    b = screen.frame_brdf_expanded(u, up, cal, r, r[3, 4], ci, cr, 230.0)
    np.testing.assert_allclose(a, b, rtol=1e-13)


def test_eq6_maps_edges_to_corners():
    g = screen.ScreenGeometry(np.array([0.0, 1.0, 1.0]), np.array([2.0, 1.0, 1.0]), np.array([0.0, 1.0, -1.0]), 10, 90, 5, 105)
    np.testing.assert_allclose(screen.screen_points(g, 10, 5), g.upper_left_m)
    np.testing.assert_allclose(screen.screen_points(g, 10, 105), g.upper_right_m)
    np.testing.assert_allclose(screen.screen_points(g, 90, 5), g.lower_left_m)
    np.testing.assert_allclose(screen.screen_points(g, 50, 55), [1.0, 1.0, 0.0])
    np.testing.assert_allclose(g.normal, [0, -1, 0])


def test_masks_saturated_background_and_offscreen_pixels():
    t = screen.simulate_test(STEEL, noise=0.0, gain_counts=200.0, saturation=10000.0)
    frame = t.frames[0]
    s = screen.reduce_test(t)
    g = t.geometry
    on_screen = frame[int(g.top_row):int(g.bottom_row) + 1, int(g.left_col):int(g.right_col) + 1]
    n_sat = int((on_screen >= 10000.0).sum())
    assert n_sat > 0
    assert len(s) <= on_screen.size - n_sat
    np.testing.assert_allclose(s.brdf_per_sr, STEEL.evaluate(s.wi, s.wo), rtol=1e-12)  # none of them leaked in


def test_spot_size_warning():
    t = screen.simulate_test(STEEL, distance_m=0.05, screen_size_m=0.05, spot_size_m=0.005, gain_counts=1.0)
    with pytest.warns(screen.SpotSizeWarning, match="under 20 spot sizes"):
        screen.reduce_test(t)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        screen.reduce_test(screen.simulate_test(STEEL))


def _bad(**changes):
    t = screen.simulate_test(STEEL, times_s=(0.0, 1.0), temperature_of_time=lambda tt: 300.0 + tt)
    for k, v in changes.items():
        setattr(t, k, v(t) if callable(v) else v)
    return t


@pytest.mark.parametrize(
    "changes, match",
    [
        (dict(frames=lambda t: t.frames[:, :-1]), r"frames: expected shape \(F, 96, 96\)"),
        (dict(frames=lambda t: np.where(np.arange(96)[None, :, None] == 3, np.nan, t.frames)), "frame 0 contains nan"),
        (dict(times_s=np.array([0.0])), "one time per frame"),
        (dict(pyrometer_times_s=np.array([0.5, 0.8]), pyrometer_temperatures_k=np.array([300.0, 301.0])), r"covers \[0.5, 0.8\] s but the frames span \[0, 1\] s"),
        (dict(frames=lambda t: np.zeros_like(t.frames)), "every pixel is masked"),
        (dict(calibration=screen.Calibration(5.0, (500, 3), 10.0)), r"calibration.pixel=\[500, 3\] is outside"),
    ],
)
def test_bad_input(changes, match):
    with pytest.raises(ValueError, match=match):
        screen.reduce_test(_bad(**changes))


def test_screen_edges_outside_image():
    t = screen.simulate_test(STEEL)
    g = t.geometry
    t.geometry = screen.ScreenGeometry(g.upper_left_m, g.upper_right_m, g.lower_left_m, g.top_row, 200.0, g.left_col, g.right_col)
    with pytest.raises(ValueError, match="lie outside the 96 x 96 image"):
        screen.reduce_test(t)


def test_files_round_trip_and_missing_calibration(tmp_path):
    t = screen.simulate_test(STEEL, times_s=(0.0, 1.0), temperature_of_time=lambda tt: 300.0 + tt)
    t.test_id = "a"
    text = screen.save_test(t, tmp_path).read_text()
    s = screen.reduce_test(screen.load_test(tmp_path / "a.toml"))
    direct = screen.reduce_test(t)
    np.testing.assert_allclose(s.brdf_per_sr, direct.brdf_per_sr)
    s.to_csv(tmp_path / "s.csv")
    back = screen.Samples.from_csv(tmp_path / "s.csv")
    np.testing.assert_array_equal(back.brdf_per_sr, s.brdf_per_sr)
    np.testing.assert_array_equal(back.wo, s.wo)
    pytest.importorskip("pyarrow")
    s.write(tmp_path / "s.parquet")
    pq = screen.Samples.read(tmp_path / "s.parquet")
    np.testing.assert_array_equal(pq.brdf_per_sr, s.brdf_per_sr)
    np.testing.assert_array_equal(pq.test_id.astype(str), s.test_id.astype(str))
    (tmp_path / "b.toml").write_text(text.replace("counts = ", "count = "))
    with pytest.raises(ValueError, match="calibration.counts: missing"):
        screen.load_test(tmp_path / "b.toml")
