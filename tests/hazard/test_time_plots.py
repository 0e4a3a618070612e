"""hazard.pictures.plots.time_figures: NOHD vs time per lit target and exposure vs time for the
worst observers, as PNG bytes (checked in their pixels), with or without a kept history."""

from __future__ import annotations

import copy
import dataclasses
import io
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

import hazard
import scenes
from hazard.pictures import plots
from tests._bundled import bundled

pytest.importorskip("matplotlib")

BLUE = (31, 119, 180)  # tab:blue: the NOHD curve, the accumulated exposure
RED = (214, 39, 40)  # tab:red: the NOHD maximum, the first exceedance


def _analyze(name, keep_history):
    return bundled(name, keep_history=keep_history)


@pytest.fixture(scope="module")
def full():
    return _analyze("steel_vs_copper", True)


@pytest.fixture(scope="module")
def lean():
    return _analyze("steel_vs_copper", False)


@pytest.fixture(scope="module")
def figures(full):
    return plots.time_figures(full)


def _pixels(png):
    from matplotlib.image import imread

    img = imread(io.BytesIO(png), format="png")
    assert img.ndim == 3 and img.shape[0] > 200 and img.shape[1] > 300
    return np.round(img[..., :3] * 255).astype(int)


def _count(img, rgb, tol=12):
    return int(np.all(np.abs(img - np.array(rgb)) <= tol, axis=-1).sum())


def _worst(result, k=3):
    ratio = result.hazard_ratio
    return np.argsort(-ratio, kind="stable")[:k]


def test_one_nohd_figure_per_lit_target(figures, full):
    names = [sp.target.name for sp in full.spots]
    assert names == ["stainless", "copper"]
    for n in names:
        img = _pixels(figures[f"nohd_time_{n}.png"])
        assert _count(img, BLUE) > 200  # the curve
        assert _count(img, RED) > 20  # the maximum's marker
        assert (img.sum(axis=-1) < 3 * 250).mean() > 0.02  # not a blank page


def test_worst_observers_by_hazard_ratio(figures, full):
    rows = _worst(full)
    assert np.all(full.hazard_ratio[rows][:-1] >= full.hazard_ratio[rows][1:])
    assert full.hazard_ratio[rows].min() >= np.sort(full.hazard_ratio)[-3]
    expected = {f"exposure_{plots.file_part(full.observers.labels[i])}.png" for i in rows}
    assert expected == {"exposure_shell-20m_crossing_0.png", "exposure_arc-10m_crossing.png", "exposure_shell-20m_crossing_1.png"}
    assert set(figures) == {"nohd_time_stainless.png", "nohd_time_copper.png"} | expected
    for name in expected:
        img = _pixels(figures[name])
        assert _count(img, BLUE) > 200  # H(t)
        assert _count(img, RED, tol=30) > 200  # these observers exceed the MPE: the first exceedance's line
    assert len(plots.time_figures(full, worst=1)) == 3
    assert len(plots.time_figures(full, worst=0)) == 2


def test_displays_carry_what_the_figures_mark(full):
    d = plots.ExposureDisplay.from_result(full, int(_worst(full, 1)[0]))
    assert d.first_exceedance_s == pytest.approx(0.1) and d.mpe_w_m2 == pytest.approx(50.0)
    assert d.hazard_ratio == pytest.approx(full.hazard_ratio.max())
    n = plots.NOHDTimeDisplay.from_result(full, 1)
    assert n.dynamic and n.mpe_w_m2 == pytest.approx(50.0) and n.target == "copper"


def test_without_history_the_worst_observers_are_recomputed_exactly(full, lean, figures):
    assert lean.observers.irradiance_w_m2 is None
    rows = _worst(lean)
    np.testing.assert_array_equal(rows, _worst(full))
    hist, why = plots._observer_histories(lean, rows)
    assert why is None
    np.testing.assert_allclose(hist, full.observers.irradiance_w_m2[rows], rtol=1e-12, atol=0.0)
    assert plots.time_figures(lean) == figures  # the same pictures, byte for byte


def test_without_history_an_irreproducible_recomputation_is_said(lean):
    obs = dataclasses.replace(lean.observers, peak_irradiance_w_m2=lean.observers.peak_irradiance_w_m2 * 1.01)
    bad = copy.copy(lean)
    bad.observers = obs
    out = plots.time_figures(bad)
    assert not any(k.startswith("exposure_") and k.endswith(".png") for k in out)
    text = out["exposure_omitted.txt"].decode()
    assert text.count("\n") == 1 and "keep_history=True" in text
    for i in _worst(bad):
        assert bad.observers.labels[i] in text


def test_static_scene_draws_flat_lines_over_the_window():
    r = _analyze("plate", None)
    assert len(r.times_s) == 1
    out = plots.time_figures(r)
    assert set(out) == {"nohd_time_plate.png", "exposure_east.png", "exposure_west-behind-box.png"}
    n = plots.NOHDTimeDisplay.from_result(r, 0)
    assert not n.dynamic and n.times_s[-1] == pytest.approx(10.0) and np.ptp(n.nohd_dynamic_m) == 0
    assert _count(_pixels(out["nohd_time_plate.png"]), BLUE) > 200
    east = _pixels(out["exposure_east.png"])  # below the MPE: H(t) drawn, no exceedance line
    assert _count(east, BLUE) > 200 and _count(east, RED, tol=30) < 20


def test_file_names_are_safe():
    assert plots.file_part("shell-20m:crossing[0]") == "shell-20m_crossing_0"
    assert plots.file_part("a b/c") == "a_b_c"
    assert plots.file_part("../") == "unnamed"
    assert plots._unique("x.png", {"x.png": b""}) == "x_2.png"


def _hot_plate(tmp_path, power_w):
    text = Path(scenes.example_path("plate")).read_text()
    assert "power_w = 100.0" in text
    path = tmp_path / "plate_hot.toml"
    path.write_text(text.replace("power_w = 100.0", f"power_w = {power_w!r}"))
    return hazard.analyze(scenes.load(path))


def test_exposure_plot_marks_the_exceedance_by_the_verdicts_rule_and_names_its_mpe(tmp_path):
    """Issue 34: a static observer over the 10 s MPE had "first exceedance t = 0 s" drawn
    while H(t) was below the elapsed-time MPE curve. The plot now names the MPE the verdict
    uses (the exposure duration's) and marks the exceedance by that rule (E >= that MPE)."""
    from hazard.physics import mpe as _mpe

    r = _hot_plate(tmp_path, 100.0 * 1.5 / 0.0007053)  # hazard ratio ~1.5 at "east"
    i = r.observers.labels.index("east")
    d = plots.ExposureDisplay.from_result(r, i)
    spec = r.scene.spec
    assert d.duration_s == spec.exposure.duration_s == 10.0
    limit = _mpe.ocular_mpe(spec.laser.wavelength_nm, 10.0, standard=spec.exposure.standard).irradiance_w_m2
    assert d.mpe_w_m2 == pytest.approx(limit, rel=1e-12)
    e = float(d.irradiance_w_m2[0])
    assert 1.0 < e / limit < 3.0 and d.hazard_ratio == pytest.approx(e / limit, rel=1e-9)
    # the case of the issue: early on H(t) = E t is under the elapsed-time curve, yet the verdict holds from t = 0
    assert np.any(d.exposure_j_m2[1:] < d.mpe_exposure_j_m2[1:])
    assert d.verdict_exceedance_s() == 0.0
    _, ax = d.plot()
    labels = [t.get_text() for t in ax.get_legend().get_texts()]
    assert any("verdict's rule" in s and "MPE for 10 s" in s and "t = 0 s" in s for s in labels), labels
    assert any("not the verdict's rule" in s for s in labels), labels
    h = f"{limit * 10.0:.4g} J/m^2"
    assert any(h in s and "MPE for 10 s as exposure" in s for s in labels), labels


def test_exposure_plot_below_the_verdicts_mpe_marks_nothing(tmp_path):
    r = _hot_plate(tmp_path, 100.0 * 0.5 / 0.0007053)
    d = plots.ExposureDisplay.from_result(r, r.observers.labels.index("east"))
    assert d.hazard_ratio < 1 and np.isnan(d.verdict_exceedance_s())
    _, ax = d.plot()
    labels = [t.get_text() for t in ax.get_legend().get_texts()]
    assert any(s.startswith("no exceedance in the window") for s in labels), labels


def _uv_plate(windows=None):
    text = Path(scenes.example_path("plate")).read_text()
    text = text.replace("wavelength_nm = 1064.0", "wavelength_nm = 355.0").replace("power_w = 100.0", "power_w = 10000.0")
    if windows:
        text = text.replace("aim_m = [0.0, 0.0, 0.0]", f"aim_m = [0.0, 0.0, 0.0]\nwindows = {windows}")
    return hazard.analyze(scenes.loads(text, base_dir=Path(scenes.example_path("plate")).parent))


@pytest.mark.slow
def test_exposure_plot_draws_the_uv_days_limit_where_it_governs():
    # 355 nm, ANSI, five 600 s firing windows a day: 3000 s exposed; Table 5a 315-400 nm,
    # 10 - 3e4 s: 1.0 J/cm^2 = 1e4 J/m^2 for the day's summed dose (3.33 W/m^2 while exposed),
    # below one 10 s exposure's 0.56 * 10^0.25 J/cm^2 / 10 s = 995.8 W/m^2: the day's rule governs
    win = "[[0.0, 600.0], [3600.0, 4200.0], [7200.0, 7800.0], [10800.0, 11400.0], [14400.0, 15000.0]]"
    r = _uv_plate(win)
    d = plots.ExposureDisplay.from_result(r, r.observers.labels.index("east"))
    assert d.uv_day_j_m2 == pytest.approx(1e4, rel=1e-9) and d.mpe_w_m2 == pytest.approx(1e4 / 3000.0, rel=1e-9)
    _, ax = d.plot()
    labels = [t.get_text() for t in ax.get_legend().get_texts()]
    assert any(s.startswith("UV day's limit") and "3000 s exposed in 24 h" in s and "1e+04 J/m^2" in s for s in labels), labels
    flat = [ln for ln in ax.get_lines() if np.allclose(ln.get_ydata(), 1e4, rtol=1e-9)]
    assert len(flat) == 1 and flat[0].get_color() == "tab:purple"
    # no windows: the one 10 s exposure is the day; its MPE is the single-exposure one, no day line
    one = _uv_plate()
    d1 = plots.ExposureDisplay.from_result(one, one.observers.labels.index("east"))
    assert d1.uv_day_j_m2 is None
    _, ax1 = d1.plot()
    assert not any(t.get_text().startswith("UV day's limit") for t in ax1.get_legend().get_texts())


def test_exposure_plot_of_a_path_draws_the_uv_days_limit_where_it_governs():
    from hazard.pipeline.motion_stage import path_summary

    # 355 nm, ANSI: lit at 20 W/m^2 for 100 s every 1000 s, five times, sampled every 5 s: the day's dose
    # (5 x 2100 J/m^2, trapezoids with 5 s ramps) over 1.0 J/cm^2 = 1e4 J/m^2 for 500 s exposed (Table 5a
    # 315-400 nm, 10 - 3e4 s); every 10 s window (200 J/m^2) far below its MPE
    t = np.arange(0.0, 4200.0, 5.0)
    e = np.zeros_like(t)
    for a in (10.0, 1010.0, 2010.0, 3010.0, 4010.0):
        e[(t >= a) & (t <= a + 100.0)] = 20.0
    for wl, day in ((355.0, 1e4), (532.0, None)):  # 532 nm: no day rule
        from hazard.pipeline.motion import SummarisedPath

        p = _path(t, e)
        p = SummarisedPath.of(p, path_summary(p, 10.0, wl, "ansi-z136.1-2014"))
        result = SimpleNamespace(mpe_w_m2=1.0, scene=SimpleNamespace(spec=SimpleNamespace(
            laser=SimpleNamespace(wavelength_nm=wl), exposure=SimpleNamespace(standard="ansi-z136.1-2014", duration_s=10.0))))
        d = plots.ExposureDisplay.from_path(result, p)
        _, ax = d.plot()
        labels = [x.get_text() for x in ax.get_legend().get_texts()]
        if day is None:
            assert d.uv_day_j_m2 is None and not any(x.startswith("UV day's limit") for x in labels)
            continue
        assert d.uv_day_j_m2 == pytest.approx(day, rel=1e-9) and p.summary.uv_24h.ratio > 1.0
        assert any(x.startswith("UV day's limit for 500 s exposed in 24 h: 1e+04 J/m^2") for x in labels), labels


def _path(t, e):
    from hazard.pipeline.motion import PathResult

    return PathResult("p", 0, "track", t, np.zeros((len(t), 3)), e > 0, np.zeros_like(e), e, 1.0, False)


def _fake_static(uv, mpe_w_m2, single_w_m2):
    obs = SimpleNamespace(irradiance_w_m2=np.array([[3.5]]), labels=["east"], first_exceedance_s=np.array([np.nan]))
    obs.__len__ = lambda: 1
    spec = SimpleNamespace(laser=SimpleNamespace(wavelength_nm=355.0),
                           exposure=SimpleNamespace(standard="ansi-z136.1-2014", duration_s=10.0))
    return SimpleNamespace(observers=[0], times_s=np.array([0.0]), scene=SimpleNamespace(spec=spec), uv_24h=uv,
                           mpe=SimpleNamespace(irradiance_w_m2=single_w_m2), mpe_w_m2=mpe_w_m2,
                           observer_mpe_w_m2=mpe_w_m2, hazard_ratio=np.array([3.5 / mpe_w_m2]))


@pytest.mark.parametrize("avg, mpe, single, drawn", [
    # the fast twin of the scene test above: the day's average 1e4 J/m^2 / 3000 s set the MPE, below
    # one 10 s exposure's 995.8 W/m^2 (ANSI Table 5a 315-400 nm): drawn
    (1e4 / 3000.0, 1e4 / 3000.0, 995.8, True),
    # the day is the one exposure (average == the single exposure's MPE): not a separate limit
    (995.8, 995.8, 995.8, False),
    # a lower limit (e.g. a pulse rule) set the MPE below the day's average: the day's rule does not govern
    (1e4 / 3000.0, 1.0, 995.8, False),
])
def test_uv_day_line_only_where_the_day_rule_governs(avg, mpe, single, drawn):
    uv = SimpleNamespace(average_irradiance_w_m2=avg, radiant_exposure_j_m2=avg * 3000.0, total_on_time_s=3000.0)  # a UV24hResult's fields
    r = _fake_static(uv, mpe, single)
    r.observers = SimpleNamespace(irradiance_w_m2=np.array([[3.5]]), labels=["east"], first_exceedance_s=np.array([np.nan]))
    d = plots.ExposureDisplay.from_result(_Len1(r), 0)
    assert (d.uv_day_j_m2 is not None) == drawn
    if drawn:
        assert d.uv_day_j_m2 == pytest.approx(1e4, rel=1e-12) and "3000 s exposed in 24 h" in d.uv_day_text


class _Len1(SimpleNamespace):
    """A fake result whose observers have one row."""

    def __init__(self, r):
        super().__init__(**vars(r))
        self.observers = _Obs(**vars(r.observers))


class _Obs(SimpleNamespace):
    def __len__(self):
        return 1
