"""The plan view (hazard run --plot, hazard render): what it draws, checked in its pixels."""

from __future__ import annotations

import io

import numpy as np
import pytest

from hazard.cli import main
from hazard.pictures import palette as C
from hazard.pictures.palette import rgb
from hazard.pictures.plan_view import PlanViewDisplay, nice_length_m

pytest.importorskip("matplotlib")
imageio = pytest.importorskip("imageio.v3")


def _near(img, rgb, tol=12):
    return np.all(np.abs(img[..., :3].astype(int) - rgb) <= tol, axis=-1)


@pytest.fixture(scope="module")
def run_with_plot(tmp_path_factory):
    out = tmp_path_factory.mktemp("plan")
    text = io.StringIO()
    code = main(["run", "steel_vs_copper", "-o", str(out / "o"), "--plot"], stdout=text, stderr=io.StringIO())
    assert code == 0
    return out / "o", text.getvalue()


def test_run_plot_writes_the_plan_with_the_other_outputs(run_with_plot):
    out, text = run_with_plot
    want = ["elevation.png", "exposure_arc-10m_crossing.png", "exposure_shell-20m_crossing_0.png", "exposure_shell-20m_crossing_1.png",
            "figures.json", "nohd_time_copper.png", "nohd_time_stainless.png", "observers.csv", "plan.png", "report.json",
            "zones_local_frame.json"]
    assert sorted(p.name for p in out.iterdir() if p.name != ".laser-hazard.json") == want  # + the outputs' manifest
    assert all("wrote " + str(out / n) in text for n in want)


def test_figures_json_says_every_hazardous_finding_is_drawn_and_is_in_the_manifest(run_with_plot):
    import json

    from brdfmodels.output_sets import read_manifest
    from tests.hazard.test_figure_index import check_coverage, hazardous_paths

    out, _ = run_with_plot
    doc = json.loads((out / "report.json").read_text())
    figs = json.loads((out / "figures.json").read_text())
    assert read_manifest(out)["figures.json"] == "run"  # claimed like the other outputs
    pngs = sorted(p.name for p in out.glob("*.png"))
    assert sorted(figs["figures"]) == pngs  # an entry for every picture written, and no other
    paths = hazardous_paths(doc)
    assert "sdz.mirror_beams[0]" in paths and sum(p.startswith("observers[") for p in paths) == 39
    assert not check_coverage(doc, figs)
    for name, entry in figs["figures"].items():  # the time plots say which finding they draw
        if name.startswith("exposure_"):
            assert any(f["paths"] and f["paths"][0].startswith("observers[") for f in entry["findings"]), name


def test_every_png_of_the_run_is_whole_and_nothing_runs_off_its_edge(run_with_plot):
    from tests.hazard.test_picture_pixels import png_problems

    out, _ = run_with_plot
    pngs = sorted(out.glob("*.png"))
    assert len(pngs) == 7
    problems = {p.name: png_problems(p.read_bytes()) for p in pngs}
    assert not {n: v for n, v in problems.items() if v}, problems


def test_the_plan_shows_the_zone_the_mirror_beam_and_both_verdicts(run_with_plot):
    img = imageio.imread(run_with_plot[0] / "plan.png")
    zone_fill = _near(img, (249, 197, 198))  # #e41a1c at alpha 0.25 over white
    mirror = _near(img, rgb(C.MIRROR), 30)  # the copper mirror beam
    green = _near(img, rgb(C.SAFE), 30)  # observers below the MPE
    red = _near(img, (228, 26, 28), 30)  # hazardous observers' crosses, the aim line and the zone's edge
    assert zone_fill.sum() > 5000 and mirror.sum() > 300 and green.sum() > 300 and red.sum() > 300


def test_a_plot_without_matplotlib_is_a_clear_error(monkeypatch, tmp_path):
    import importlib.util

    real = importlib.util.find_spec
    monkeypatch.setattr(importlib.util, "find_spec", lambda name, *a: None if name == "matplotlib" else real(name, *a))
    err = io.StringIO()
    code = main(["run", "plate", "-o", str(tmp_path / "o"), "--plot"], stdout=io.StringIO(), stderr=err)
    assert code != 0 and "laser-hazard[render]" in err.getvalue() and not (tmp_path / "o").exists()


def test_site_limits_hold_the_hazard_circles_and_the_hazardous_observers():
    d = PlanViewDisplay("t", np.zeros(2), np.zeros((2, 2)), None, "z", targets=[("a", np.array([100.0, 0.0]), 30.0, 45.0, True), ("far", np.array([5e3, 0.0]), 1.0, 1.0, False)],
                        observers_xy=np.array([[-50.0, 20.0], [0.0, 500.0]]), hazardous=np.array([True, False]))
    x0, x1, y0, y1 = d.site_limits()
    assert x0 <= -50 and x1 >= 145 and y0 <= -45 and y1 >= 45 and y1 < 500  # the safe far observer is not framed


@pytest.mark.parametrize("span, want", [(1000.0, 200.0), (73.0, 10.0), (5e4, 1e4), (9.0, 1.0), (0.3, 0.05)])
def test_the_scale_bar_is_a_round_fifth_of_the_width(span, want):
    assert nice_length_m(span) == pytest.approx(want)


def test_the_legend_stays_inside_the_picture_and_an_edge_on_wall_is_drawn(tmp_path):
    """A wall seen edge-on (a vertical plate occluder) has no plan area: it is drawn as a
    thick line; the legend beside the site panel is not cut at the picture's edge (it
    was: bbox_inches='tight' now)."""
    ring = np.array([[-5.0, 100.0], [5.0, 100.0]])
    d = PlanViewDisplay("t", np.zeros(2), np.array([[0.0, 0.0], [0.0, 200.0]]), None, "zone",
                        targets=[("a", np.array([0.0, 50.0]), 3.0, 9.0, True)], occluders=[ring],
                        observers_xy=np.array([[1.0, 20.0], [4.0, 60.0]]), hazardous=np.array([True, False]))
    img = imageio.imread(io.BytesIO(d.png_bytes()))
    wall = _near(img, (85, 85, 85), 10)  # #555555
    assert wall.sum() > 20
    legend_text = np.flatnonzero(np.any(img[..., :3].min(axis=-1) < 128, axis=0))
    assert legend_text.max() < img.shape[1] - 2  # dark pixels end before the right edge: nothing cut off
    red = _near(img, (228, 26, 28), 30)  # the hazardous observer's marker, drawn large on top
    assert red.sum() > 40
