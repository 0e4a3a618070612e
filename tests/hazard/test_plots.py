"""Display objects store data once and draw it; the figures are real PNGs."""

import numpy as np
import pytest

import brdfmodels as bm
from hazard.pictures import plots
from tests._bundled import bundled

pytest.importorskip("matplotlib")


@pytest.fixture(scope="module")
def dyn_result():
    return bundled("steel_vs_copper", keep_history=True)


def test_brdf_plane_display_with_samples(tmp_path):
    from brdfmodels import screen

    m = bm.TorranceSparrow5(kb=0.072, kr=16.125, b=-29.917, a=0.959, kd=0.081)
    s = screen.reduce_test(screen.simulate_test(m, incidence_deg=20.0, noise=0.0))
    d = plots.BRDFPlaneDisplay.from_model(m, 20.0, samples=s)
    assert len(d.samples_deg) > 10
    # the measured in-plane samples lie on the model curve (noise-free)
    np.testing.assert_allclose(d.samples_fr, np.interp(d.samples_deg, d.angles_deg, d.curves["model"]), rtol=0.05)
    assert d.save(tmp_path / "b.png").stat().st_size > 10_000


def test_nohd_time_display(dyn_result, tmp_path):
    d = plots.NOHDTimeDisplay.from_result(dyn_result, target=1)  # copper: cleaning, then oxidation
    assert d.nohd_dynamic_m.max() > d.nohd_static_m > d.nohd_dynamic_m.min()
    assert d.save(tmp_path / "n.png").stat().st_size > 10_000


def test_exposure_display(dyn_result, tmp_path):
    d = plots.ExposureDisplay.from_result(dyn_result, observer=0)
    assert np.all(np.diff(d.exposure_j_m2) >= 0) and d.mpe_exposure_j_m2[-1] == pytest.approx(500.0)
    assert d.save(tmp_path / "e.png").stat().st_size > 10_000
    lean = bundled("steel_vs_copper", keep_history=False)
    with pytest.raises(ValueError, match="keep_history=True"):
        plots.ExposureDisplay.from_result(lean)


def test_error_table_display(tmp_path):
    rows = [{"knob": "a", "t": 0.1, "e": 1e-2}, {"knob": "a", "t": 0.2, "e": 1e-3}, {"knob": "b", "t": 0.3, "e": 1e-4}]
    d = plots.ErrorTableDisplay.from_rows(rows, "t", "e", group="knob")
    assert set(d.series) == {"a", "b"}
    assert d.save(tmp_path / "t.png").stat().st_size > 5_000
