"""A long thin danger zone is seen in the plan view's range panel (issue 34 leftover 2): a
37 km x 1.9 m zone is a hairline at range scale, so its outline is also drawn widened
across the aim to a visible width, with a label giving its true width. Checked in the
rendered pixels across the zone; the true width is computed here from report.json's
zone outline and the scene file's aim."""

from __future__ import annotations

import numpy as np
import pytest

import scenes
from tests._bundled import bundled

pytest.importorskip("matplotlib")

MIN_PX = 4.0 * 100 / 72 - 1.5  # the drawn minimum (4 pt at the figure's 100 dpi), less a pixel of anti-aliasing


def _figure(name):
    from hazard.pictures.plan_view import PlanViewDisplay

    fig, axes = PlanViewDisplay.from_result(bundled(name)).plot()
    fig.canvas.draw()
    img = np.asarray(fig.canvas.buffer_rgba())[..., :3].astype(int)
    return fig, axes, img


def _true_width(name, aided=None):
    """The zone's width across the aim [m] (the naked-eye zone, or ``sdz.aided[aided]``),
    from report.json's outline and the scene file."""
    from hazard.outputs.report import report_dict

    res = bundled(name)
    z = report_dict(res)["sdz"]
    ring = np.asarray(z["polygon_m"] if aided is None else z["aided"][aided]["polygon_m"], float)
    scene = scenes.load(scenes.example_path(name))
    d = np.asarray(scene.laser_direction, float)[:2]
    u = d / np.hypot(*d)
    n = np.array([-u[1], u[0]])
    laser = (np.asarray(scene.laser_position_m, float) + np.asarray(scene.offset_m, float))[:2]
    return float(np.ptp((ring - laser) @ n)), laser, u, n, float(np.max((ring - laser) @ u))


def _red_span_px(ax, img, centre, n, half_px=25, colour="red") -> float:
    """Pixels between the first and the last red pixel on a line across ``n`` through
    ``centre`` (data coordinates) in the rendered picture ``img``."""
    c = ax.transData.transform(centre)
    dn = ax.transData.transform(centre + n) - c
    dn = dn / np.hypot(*dn)
    s = np.arange(-half_px, half_px + 1)
    pts = c + s[:, None] * dn
    rows, cols = np.round(img.shape[0] - pts[:, 1]).astype(int), np.round(pts[:, 0]).astype(int)
    px = img[rows, cols]
    if colour == "red":
        red = (px[:, 0] - px[:, 1] > 40) & (px[:, 0] > 150)
    else:  # purple (#984ea3, the zones through optics)
        red = (px[:, 2] - px[:, 1] > 40) & (px[:, 0] - px[:, 1] > 30)
    return float(np.ptp(s[red])) if red.any() else 0.0


@pytest.mark.parametrize("name", ["mirror_window"])
def test_a_hairline_danger_zone_is_drawn_wide_enough_to_see_and_says_its_true_width(name):
    width_m, laser, u, n, length_m = _true_width(name)
    fig, (rng, site), img = _figure(name)
    ends = rng.transData.transform(np.array([laser, laser + n * width_m]))
    assert np.hypot(*(ends[1] - ends[0])) < 1.0  # at true width it is under a pixel at range scale ...
    for f in (0.3, 0.5, 0.7):  # ... drawn at least the minimum across, along the zone
        assert _red_span_px(rng, img, laser + u * f * length_m, n) >= MIN_PX
    texts = [t.get_text() for t in rng.texts]
    said = [t for t in texts if "drawn exaggerated" in t and t.startswith("danger zone")]  # (a mirror beam's zone has its own)
    assert len(said) == 1 and f"{width_m:.3g} m wide" in said[0]
    assert not any("drawn exaggerated" in t.get_text() and t.get_text().startswith("danger zone")
                   for t in site.texts)  # the site panel shows it at true width


def test_widening_keeps_along_offsets_and_multiplies_across_offsets():
    from hazard.pictures.plan_view import widen_across

    ring = np.array([[1.0, 0.0], [10.0, 1.0], [10.0, -2.0]])
    origin, u = np.array([1.0, 0.0]), np.array([1.0, 0.0])
    assert widen_across(ring, origin, u, 5.0) == pytest.approx(np.array([[1.0, 0.0], [10.0, 5.0], [10.0, -10.0]]))
    r = np.array([[0.0, 0.0], [3.0, 4.0]])  # along a diagonal: a point on the line stays, one off it moves away
    u = np.array([0.6, 0.8])
    out = widen_across(np.vstack([r, [[4.0, 3.0]]]), np.zeros(2), u, 2.0)
    assert out[:2] == pytest.approx(r)
    along, across = np.array([4.0, 3.0]) @ u, np.array([4.0, 3.0]) @ np.array([-0.8, 0.6])
    assert out[2] == pytest.approx(along * u + 2.0 * across * np.array([-0.8, 0.6]))


@pytest.mark.parametrize("name", ["mirror_window", pytest.param("range_clearance", marks=pytest.mark.slow),
                                  pytest.param("range_geo", marks=pytest.mark.slow), pytest.param("binoculars", marks=pytest.mark.slow)])
def test_every_widened_zone_label_is_drawn_in_its_panel(name):
    """A panel drawing the widened outline shows its label: the label's point is inside
    the panel (matplotlib hides an annotation whose point is outside), whether or not the
    laser is in the frame (range_clearance's site panel: the laser 1.5 km south of it)."""
    fig, axes, _ = _figure(name)
    r = fig.canvas.get_renderer()
    for ax in axes:
        said = [t for t in ax.texts if "drawn exaggerated" in t.get_text()]
        widened = [p for p in ax.patches if p.get_hatch() in ("////", "\\\\", "xx") and p.get_facecolor()[3] == 0]  # xx: a mirror beam's zone
        assert len(said) == len(widened), ax.get_title()
        for t in said:
            x0, x1 = sorted(ax.get_xlim())
            y0, y1 = sorted(ax.get_ylim())
            assert x0 <= t.xy[0] <= x1 and y0 <= t.xy[1] <= y1 and t._check_xy(r), ax.get_title()


@pytest.mark.slow
def test_a_hairline_danger_zone_through_optics_is_widened_and_says_its_width_too():
    """binoculars: the zone through 7x50 optics reaches 65 km, twice the naked-eye zone;
    past the naked-eye zone's end only its own (purple) widened outline is there."""
    width_m, laser, u, n, length_m = _true_width("binoculars", 0)
    naked = _true_width("binoculars")[4]
    fig, (rng, site), img = _figure("binoculars")
    assert length_m > 1.5 * naked
    for f in (0.6, 0.8):  # beyond the naked-eye zone
        assert f * length_m > naked and _red_span_px(rng, img, laser + u * f * length_m, n, colour="purple") >= MIN_PX
    said = [t.get_text() for t in rng.texts if "through 7x50 optics" in t.get_text() and "drawn exaggerated" in t.get_text()]
    assert len(said) == 1 and f"{width_m:.3g} m wide" in said[0]
