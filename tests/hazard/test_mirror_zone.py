"""A flat mirror's reflected-beam hazard zone has its width (issue 29 item 4 / issue 34).

References from the formulas alone: a flat mirror folds the laser's Gaussian, so at a
range z past the mirror (R1 from the laser to it) the beam has 1/e radius
w = (a + phi (R1 + z)) / 2 and peak E0 = rho P exp(-mu (R1 + z)) / (pi w^2); its hazardous
set's half-width is w sqrt(ln(E0 / MPE)). The reflected axis is the laser's axis mirrored
on the plate's normal, d - 2 (d . n) n, from where the laser axis meets the plate."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

import hazard
import scenes
from tests.validation import _refs as ref
from tests.validation._refs import FAST_TWIN, SLOW

def _scene(*, power, a, phi, r1, mu, rho, normal, tangent, center=(0.0, 0.0, 0.0), size=(20.0, 20.0)):
    """A specular plate ``mirror`` at ``center`` lit along +y by a 1064 nm laser ``r1`` m south
    (the validation suite's scene builder; default analysis knobs)."""
    mirror = dict(name="mirror", shape="plate", center=center, normal=normal, tangent=tangent, size=size, material=ref.specular(rho))
    return scenes.loads(ref.scene_text(power=power, a=a, phi=phi, position=(0.0, -r1, 0.0), aim=(0.0, 0.0, 0.0), targets=[mirror],
                                       mu=mu, analysis=""))


def _case(power=100.0, a=0.01, phi=5e-4, r1=100.0, mu=0.0, tilt_deg=30.0, rho=0.8, nz=0.0):
    """The scene's result and the unit reflected axis (the plate's normal tilted
    ``tilt_deg`` in plan and given the vertical component ``nz`` before normalising)."""
    t = math.radians(tilt_deg)
    n = np.array([math.sin(t), -math.cos(t), nz])  # faces the laser (beam along +y)
    n /= np.linalg.norm(n)
    res = hazard.analyze(_scene(power=power, a=a, phi=phi, r1=r1, mu=mu, rho=rho, normal=n, tangent=(math.cos(t), math.sin(t), 0.0)))
    assert np.allclose(res.spots[0].target.normal, n, atol=1e-9)  # the scene holds the plate as meant
    d = np.array([0.0, 1.0, 0.0])
    u = d - 2 * (d @ n) * n
    return res, u


def _half_width_m(z, power, a, phi, r1, mu, rho, mpe):
    """w sqrt(ln(E0 / MPE)) of the unfolded Gaussian at z past the mirror [m] (0 below the MPE)."""
    path = r1 + np.asarray(z, float)
    w = (a + phi * path) / 2
    e0 = rho * power * np.exp(-mu * path) / (math.pi * w * w)
    return np.where(e0 > mpe, w * np.sqrt(np.log(np.maximum(e0, mpe) / mpe)), 0.0)


def test_the_half_width_is_the_gaussian_formula_at_several_ranges():
    from hazard.physics.mirror_zone import edges_m

    power, a, phi, r1, mu, rho = 100.0, 0.01, 5e-4, 100.0, 2e-4, 0.8
    res, u = _case(power, a, phi, r1, mu, 30.0, rho)
    mpe = float(res.mpe_w_m2)
    (sp,) = [s for s in res.spots if s.target.name == "mirror"]
    across = np.array([-u[1], u[0], 0.0])
    z = np.array([1.0, 50.0, 300.0, 800.0, 1500.0])
    ref = _half_width_m(z, power, a, phi, r1, mu, rho, mpe)
    assert np.all(ref > 0.05)  # every range hazardous, widths well above the solver's scan floor
    lo, hi, found = edges_m(sp, z[:, None] * u, across, (a + phi * (r1 + z)) / 2, mpe, mu)
    assert found.all()
    np.testing.assert_allclose(hi, ref, rtol=1e-6)
    np.testing.assert_allclose(-lo, ref, rtol=1e-6)


def test_the_zone_polygon_is_as_wide_as_the_formula_and_ends_at_the_nohd():
    from shapely.geometry import Point, Polygon

    from hazard.physics.mirror_zone import PUPIL_RADIUS_M, mirror_zones

    power, a, phi, r1, mu, rho = 100.0, 0.01, 5e-4, 100.0, 0.0, 0.8
    res, u = _case(power, a, phi, r1, mu, 30.0, rho)
    (zone,) = mirror_zones(res)
    mpe = float(res.mpe_w_m2)
    z = np.linspace(0.0, zone.reach_m * 1.2, 4001)
    ref = _half_width_m(z, power, a, phi, r1, mu, rho, mpe)
    nohd_ref = float(z[ref > 0].max())
    assert zone.nohd_m == pytest.approx(nohd_ref, abs=zone.reach_m * 1.2 / 4000)
    assert zone.max_half_width_m == pytest.approx(ref.max() + PUPIL_RADIUS_M, rel=0.02)
    assert zone.max_half_width_m >= ref.max() + PUPIL_RADIUS_M  # never narrower than the formula's widest
    poly = Polygon(zone.ring)
    n = np.array([-u[1], u[0]])
    k = int(np.argmax(ref))
    for side in (1.0, -1.0):  # the widest section's edges inside, a hand's width past them outside
        assert poly.contains(Point(*(u[:2] * z[k] + side * ref[k] * n)))
        assert not poly.contains(Point(*(u[:2] * z[k] + side * (ref[k] + PUPIL_RADIUS_M + 0.01) * n)))
    beyond = u[:2] * zone.reach_m * 1.02
    assert not poly.contains(Point(*beyond))  # past the NOHD: outside


def _check_contains(power, a, phi, r1, mu, tilt_deg, rho, nz, frac_z, frac_r, frac_v):
    from shapely.geometry import Point, Polygon

    from hazard.physics.mirror_zone import PUPIL_RADIUS_M, SAMPLES, mirror_zones

    res, u = _case(power, a, phi, r1, mu, tilt_deg, rho, nz)
    zones = mirror_zones(res)
    mpe = float(res.mpe_w_m2)
    if not zones:  # no mirror beam reaches the MPE: the formula agrees at the mirror
        assert _half_width_m(1e-3, power, a, phi, r1, mu, rho, mpe) < 1e-3
        return
    (zone,) = zones
    poly = Polygon(zone.ring).buffer(1e-9 * zone.reach_m)
    side = np.array([-u[1], u[0], 0.0]) / np.hypot(u[0], u[1])  # across the axis, level
    up = np.cross(side, u)
    z = np.asarray(frac_z) * zone.reach_m
    h = _half_width_m(z, power, a, phi, r1, mu, rho, mpe)
    r = np.asarray(frac_r) * 1.5 * np.maximum(h, 1e-3)
    v = np.asarray(frac_v) * np.sqrt(np.maximum(h * h - r * r, 0.0))  # a height inside the section where r is
    pts = (z[:, None] * u + r[:, None] * side + v[:, None] * up)[:, :2]  # the reflected axis starts where the laser's meets the plate: the origin
    inside = np.abs(r) <= h  # hazardous by the formula (point irradiance at or above the MPE: r^2 + v^2 <= h^2)
    dz = zone.reach_m / (SAMPLES - 1)
    widest_near = np.maximum.reduce([_half_width_m(np.clip(z + k * dz, 0, None), power, a, phi, r1, mu, rho, mpe)
                                     for k in (-1, 0, 1)])
    clearly_out = np.abs(r) > 1.01 * (widest_near + PUPIL_RADIUS_M) + 1e-6
    for p, yes, no in zip(pts, inside, clearly_out):
        if yes:
            assert poly.contains(Point(*p)), (p, zone.max_half_width_m)
        if no:
            assert not poly.contains(Point(*p)), p


CASE = dict(power=st.floats(10.0, 5000.0), a=st.floats(0.003, 0.1), phi=st.floats(1e-4, 2e-3), r1=st.floats(20.0, 500.0),
            mu=st.floats(0.0, 1e-3), tilt_deg=st.floats(5.0, 70.0), rho=st.floats(0.05, 1.0), nz=st.floats(-0.3, 0.3),
            frac_z=st.lists(st.floats(0.0, 1.0), min_size=20, max_size=20),
            frac_r=st.lists(st.floats(-1.0, 1.0), min_size=20, max_size=20),
            frac_v=st.lists(st.floats(-1.0, 1.0), min_size=20, max_size=20))


@FAST_TWIN
@given(**CASE)
def test_the_zone_holds_every_hazardous_point_and_not_the_clearly_safe(**kw):
    _check_contains(**kw)


@pytest.mark.slow
@SLOW
@given(**CASE)
def test_the_zone_holds_every_hazardous_point_and_not_the_clearly_safe_many(**kw):
    _check_contains(**kw)


def _mirror_band_pt(fig, ax, mid, n) -> float:
    """How wide [pt] the band of mirror-coloured pixels is across the beam at ``mid``
    (data x, y) along the unit normal ``n``, in the rendered ``fig``."""
    from matplotlib.colors import to_rgb

    from hazard.pictures import palette as C

    fig.canvas.draw()
    img = np.asarray(fig.canvas.buffer_rgba())[..., :3].astype(float) / 255
    p0 = ax.transData.transform(mid)
    step = ax.transData.transform(mid + n) - p0
    step /= np.hypot(*step)
    target = np.array(to_rgb(C.MIRROR)) - 1.0
    target /= np.linalg.norm(target)
    hits = []
    for t in np.arange(-20.0, 20.5, 0.5):  # pixels along the normal
        x, y = p0 + t * step
        c = img[int(round(img.shape[0] - y)), int(round(x))] - 1.0
        size = np.linalg.norm(c)
        if size > 0.1 and np.abs(c / size - target).sum() < 0.35:
            hits.append(t)
    return 0.0 if not hits else (max(hits) - min(hits)) * 72.0 / fig.dpi


def test_the_drawn_zone_is_visible_in_the_plan_view():
    """Pixels: across the middle of the mirror beam in the range panel (a zone 0.3 m wide
    on a km frame) the mirror colour spans at least ``MIN_ZONE_PT`` (the zone drawn
    exaggerated, and said): the axis line alone (1.6 pt) does not."""
    matplotlib = pytest.importorskip("matplotlib")
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from hazard.pictures.plan_view import MIN_ZONE_PT, PlanViewDisplay

    res, u = _case()
    d = PlanViewDisplay.from_result(res)
    assert d.mirror_zones and d.mirror_zones[0][1] == "naked eye"
    ring = d.mirror_zones[0][2]
    mid = u[:2] * 0.5 * float(np.max(ring @ u[:2]))
    n = np.array([-u[1], u[0]])
    fig, axes = d.plot()
    try:
        assert _mirror_band_pt(fig, axes[0], mid, n) >= 0.9 * MIN_ZONE_PT
        labels = [t.get_text() for t in axes[0].texts]
        assert any("mirror-beam zone of mirror" in t and "drawn exaggerated" in t for t in labels), labels
    finally:
        plt.close(fig)
    d.mirror_zones = []  # the same picture without the zone: the line alone is thinner (the check can fail)
    fig, axes = d.plot()
    try:
        assert _mirror_band_pt(fig, axes[0], mid, n) < 0.9 * MIN_ZONE_PT
    finally:
        plt.close(fig)


def test_a_beam_cut_above_its_axis_is_drawn_where_its_hot_part_is():
    """A plate holding only the part of the beam above its axis (its lower edge 0.05 m
    above the axis, the beam's 1/e radius 0.1 m there): every point the observers' own
    function calls hazardous, at any height, lies in the plan zone (the section's
    horizontal extent taken over its heights; through the axis's line alone it fails)."""
    from shapely.geometry import Point, Polygon

    from hazard.physics.mirror_zone import mirror_zones
    from hazard.physics.specular import specular_irradiance

    res = hazard.analyze(_scene(power=2000.0, a=0.2, phi=2e-4, r1=100.0, mu=0.0, rho=0.9, normal=(0.5, -math.sqrt(0.75), 0.0),
                                tangent=(math.sqrt(0.75), 0.5, 0.0), center=(0.0, 0.0, 0.35), size=(0.6, 0.6)))
    (zone,) = mirror_zones(res)
    (sp,) = res.spots
    poly = Polygon(zone.ring).buffer(1e-9 * zone.reach_m)
    d = np.array([0.0, 1.0, 0.0])
    n = np.array([0.5, -math.sqrt(0.75), 0.0])
    u = d - 2 * (d @ n) * n
    side = np.array([-u[1], u[0], 0.0])
    rng = np.random.default_rng(7)
    m = 4000
    z = rng.uniform(0.0, zone.reach_m, m)
    w = (0.2 + 2e-4 * (100.0 + z)) / 2
    pts = z[:, None] * u + (rng.uniform(-2, 2, m) * w)[:, None] * side + (rng.uniform(-0.5, 2.5, m) * w)[:, None] * [0, 0, 1.0]
    hot = specular_irradiance(sp, pts, 1.0, 0.0) >= res.mpe_w_m2
    assert hot.sum() > 100
    assert all(poly.contains(Point(*p[:2])) for p in pts[hot])
