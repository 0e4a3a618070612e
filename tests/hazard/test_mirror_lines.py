"""The drawn mirror beam lies on its own hazard zone's axis, and a beam only an optical aid
makes hazardous is drawn too (issue 34 leftover c).

References from the formulas alone (as tests/hazard/test_mirror_zone.py): a flat mirror
folds the laser's Gaussian, so the reflected beam starts where the laser's axis meets the
plate and runs along d - 2 (d . n) n; at a range z past the mirror (R1 from the laser to
it) its 1/e radius is w = (a + phi (R1 + z)) / 2 and its peak irradiance
E0 = rho P / (pi w^2) (clear air), so through an aid of gain G (7x50: min(M^2, (D / 7 mm)^2)
= 49) its NOHD is where G E0 = MPE: w = sqrt(rho P G / (pi MPE))."""

from __future__ import annotations

import math

import numpy as np
import pytest

import hazard
import scenes
from tests._bundled import bundled
from tests.validation import _refs as ref

P_W, A_M, PHI_RAD, R1_M, RHO, TILT_DEG = 0.05, 0.01, 5e-4, 100.0, 0.8, 30.0


def _aid_only():
    """A 50 mW beam on a tilted flat mirror: below the MPE for the naked eye everywhere,
    above it through 7x50 binoculars (an observer group carries them)."""
    t = math.radians(TILT_DEG)
    n = np.array([math.sin(t), -math.cos(t), 0.0])
    mirror = dict(name="mirror", shape="plate", center=(0.0, 0.0, 0.0), normal=n, tangent=(math.cos(t), math.sin(t), 0.0),
                  size=(20.0, 20.0), material=ref.specular(RHO))
    text = ref.scene_text(power=P_W, a=A_M, phi=PHI_RAD, position=(0.0, -R1_M, 0.0), aim=(0.0, 0.0, 0.0), targets=[mirror],
                          observers=[("post", (50.0, -50.0, 0.0), {"magnification": 7.0, "objective_diameter_m": 0.05})], analysis="")
    return hazard.analyze(scenes.loads(text)), n


def test_a_beam_only_binoculars_make_hazardous_is_drawn_on_its_axis_to_the_aided_nohd():
    from hazard.pictures.plan_view import PlanViewDisplay, beam_ends
    from hazard.outputs.finding_geometry import mirror_lines

    res, n = _aid_only()
    mpe = float(res.mpe_w_m2)
    assert RHO * P_W / (math.pi * ((A_M + PHI_RAD * R1_M) / 2) ** 2) < mpe  # the naked eye is safe at the mirror already
    d = np.array([0.0, 1.0, 0.0])
    u = d - 2 * (d @ n) * n
    w = math.sqrt(RHO * P_W * 49.0 / (math.pi * mpe))
    nohd = (2 * w - A_M) / PHI_RAD - R1_M
    ((name, a, b, eye),) = mirror_lines(res)
    assert name == "mirror" and eye == "7x50 optics"
    np.testing.assert_allclose(a, [0.0, 0.0, 0.0], atol=1e-9)  # where the laser axis meets the plate
    np.testing.assert_allclose((b - a) / np.linalg.norm(b - a), u, atol=1e-9)
    assert np.linalg.norm(b - a) == pytest.approx(nohd, rel=1e-3)
    plan = PlanViewDisplay.from_result(res)
    assert len(plan.mirrors) == 1 and np.allclose(plan.mirrors[0][2], b[:2])
    (text,) = [t for _, t in beam_ends(res, np.zeros(2), np.zeros(3)) if t.startswith("mirror beam")]
    assert "through 7x50 optics" in text


@pytest.mark.parametrize("name", [pytest.param("steel_vs_copper", marks=pytest.mark.slow), "mirror_window"])
def test_the_drawn_mirror_line_lies_inside_its_own_zone(name):
    """Every point of each drawn mirror line (plan) lies inside the zone drawn for the same
    beam and eye (it started at the spot's centroid along the hottest sample: up to ~1 m
    off its zone at 20 km in steel_vs_copper)."""
    from shapely.geometry import LineString, Polygon

    from hazard.physics.mirror_zone import mirror_zones
    from hazard.outputs.finding_geometry import mirror_lines

    res = bundled(name)
    zones = {(m.target, m.eye): Polygon(m.ring).buffer(0) for m in mirror_zones(res)}
    lines = mirror_lines(res)
    assert lines
    for target, a, b, eye in lines:
        zone = zones[(target, eye)]
        length = float(np.linalg.norm(b - a))
        assert zone.buffer(1e-6 * length + 1e-6).contains(LineString([a[:2], b[:2]])), (target, eye, zone.distance(LineString([a[:2], b[:2]])))


@pytest.mark.parametrize("nz", [0.0, 0.15])
def test_the_elevation_view_draws_the_mirror_zone_holding_its_hazardous_points(nz):
    """A 100 W beam on a flat plate (tilted 30 deg in plan, its normal given the vertical
    component ``nz``): the elevation view draws the reflected beam's zone, and every
    point of the Gaussian's hazardous set (radius w sqrt(ln(E0 / MPE)) about the reflected
    axis, formulas above) at ranges along it, above and below the axis, lies inside the
    drawn outline; a level beam's outline is no taller than the widest half-width plus the
    eye's aperture radius (and 2 % for the sampling's hold between ranges)."""
    from shapely.geometry import MultiPoint, Polygon

    from hazard.pictures.elevation_view import ElevationViewDisplay

    power, a, phi, r1, rho = 100.0, 0.01, 5e-4, 100.0, 0.8
    t = math.radians(TILT_DEG)
    n = np.array([math.sin(t), -math.cos(t), nz])
    n /= np.linalg.norm(n)
    mirror = dict(name="mirror", shape="plate", center=(0.0, 0.0, 0.0), normal=n, tangent=(math.cos(t), math.sin(t), 0.0),
                  size=(20.0, 20.0), material=ref.specular(rho))
    res = hazard.analyze(scenes.loads(ref.scene_text(power=power, a=a, phi=phi, position=(0.0, -r1, 0.0), aim=(0.0, 0.0, 0.0),
                                                     targets=[mirror], analysis="")))
    mpe = float(res.mpe_w_m2)
    d = np.array([0.0, 1.0, 0.0])
    u = d - 2 * (d @ n) * n
    up = np.cross(np.array([-u[1], u[0], 0.0]) / np.hypot(u[0], u[1]), u)  # perpendicular to the axis, in its vertical plane
    view = ElevationViewDisplay.from_result(res)
    ((target, eye, ring),) = view.mirror_zones
    assert target == "mirror" and eye == "naked eye"
    zone = Polygon(ring).buffer(1e-9)
    w0 = lambda z: (a + phi * (r1 + z)) / 2  # noqa: E731
    e0 = lambda z: rho * power / (math.pi * w0(z) ** 2)  # noqa: E731
    nohd = (2 * math.sqrt(rho * power / (math.pi * mpe)) - a) / phi - r1  # where the peak falls to the MPE
    z = np.linspace(0.01, 0.98, 40) * nohd
    hw = np.array([w0(x) * math.sqrt(math.log(e0(x) / mpe)) for x in z])
    f = np.array([-0.999, -0.5, 0.0, 0.5, 0.999])
    pts = (z[:, None, None] * u + (f[None, :, None] * hw[:, None, None]) * up).reshape(-1, 3)
    sz = np.stack([pts[:, 1] + r1, pts[:, 2]], axis=1)  # distance along the aim's azimuth (+y) from the laser, height
    assert zone.contains(MultiPoint(sz.tolist()))
    if nz == 0.0:
        zz = np.linspace(0.0, nohd, 20001)[1:-1]
        widest = float(np.max(w0(zz) * np.sqrt(np.log(np.maximum(e0(zz), mpe) / mpe))))
        pupil = 3.5e-3  # the 7 mm limiting aperture's radius at 1064 nm, 10 s
        assert widest + pupil <= ring[:, 1].max() <= 1.02 * (widest + pupil)
