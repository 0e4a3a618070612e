"""Convergence report and the keep-out volume against its analytic value."""

import io
import json
import math

import pytest

import hazard
import scenes
from hazard.drivers import convergence as conv
from hazard.physics import near_field_lobe
from hazard.cli import main


@pytest.fixture
def point_form_lobes(monkeypatch):
    """The `plate` lobe (0.56 m, 10 spot sizes) lies within its spot's near field, where the
    lobe is the near-field integral's root on a direction grid (tests/validation/
    test_near_field_lobes.py); these tests check the point-form lobe and the convergence
    machinery against closed forms."""
    monkeypatch.setattr(near_field_lobe, "ENABLED", False)


def test_lambertian_keepout_volume_is_analytic(point_form_lobes):
    # R(theta) = R0 sqrt(cos theta)  =>  V = int R^3 / 3 d omega = (4 pi / 15) R0^3
    res = hazard.analyze(scenes.load(scenes.example_path("plate")))  # not the shared bundled() result: the lobes are patched
    lobe = res.targets[0].static_lobe
    r0 = hazard.nohd_diffuse(100.0, 50.0, 0.5).nohd_m
    exact = 4 * math.pi / 15 * r0**3
    assert lobe.volume_m3 == pytest.approx(exact, rel=1e-6)
    # the estimate (2x2 Gauss vs midpoint) must bound the true error, and stay useful
    assert abs(lobe.volume_m3 - exact) <= lobe.volume_error_m3 < 1e-3 * exact


def test_convergence_report_and_recommendation(tmp_path, point_form_lobes):
    rep = conv.convergence("plate", knobs=["direction_grid_deg", "beam_samples"],
                           levels={"direction_grid_deg": (8.0, 4.0, 2.0), "beam_samples": (16, 64)}, tolerance=1e-3)
    assert [r["knob"] for r in rep.rows] == ["direction_grid_deg"] * 3 + ["beam_samples"] * 2
    assert rep.rows[2]["rel_error_max_nohd"] == 0.0 and all(r["time_s"] > 0 for r in rep.rows)
    assert rep.recommended == {"direction_grid_deg": 8.0, "beam_samples": 16}
    assert conv.plot(rep, tmp_path / "c.png").stat().st_size > 5000


def test_convergence_knobs_follow_the_scene():
    assert conv.knobs_used({"targets": [{}]}) == ["direction_grid_deg", "refine_levels", "beam_samples", "beam_rtol"]
    heat = {"targets": [{"history": {"kind": "heating"}}]}
    assert conv.knobs_used(heat)[-2:] == ["time_step_fraction", "heating_rtol"]
    with pytest.raises(ValueError, match="knob 'heating_rtol': the scene does not use it"):
        conv.convergence("plate", knobs=["heating_rtol"])


def test_convergence_cli():
    out, err = io.StringIO(), io.StringIO()
    code = main(["convergence", "plate", "--knob", "refine_levels", "--json", "--quiet"], stdout=out, stderr=err)
    doc = json.loads(out.getvalue())
    assert code == 0 and set(doc["recommended"]) == {"refine_levels"} and len(doc["rows"]) == 5
