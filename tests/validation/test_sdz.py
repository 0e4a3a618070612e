"""The laser surface danger zone (issue 13 item 3) against geometry written from the
formulas (range-safety.md sections 1-3), not the engine:

- the direct-beam NOHD without attenuation: 4 P / (pi (a + L phi)^2) = MPE, so
  L = (sqrt(4 P / (pi MPE)) - a) / phi; the MPE is ANSI Z136.1-2014 Table 5b,
  1050-1400 nm, t >= T2 = 10 s: 5.0 C_C mW/cm^2 = 50 W/m^2 (C_C = 1);
- the beam's hazardous half-width: max over R of w sqrt(ln(E(R) / MPE)), w = D / 2; with
  u = D^2 the maximum of u ln(c / u) / 4 (c = 4 P / (pi MPE)) is at u = c / e, giving
  sqrt(P / (pi e MPE)) when that D lies on the path, else the end value;
- a cone of half-angle theta about a horizontal aim, nothing in the way: a circular
  sector of radius L and half-angle theta about the laser's foot; widened by h its area
  is (Steiner) theta L^2 + (2 L + 2 theta L) h + pi h^2;
- a cone about a downward aim that meets flat ground everywhere: the convex hull of the
  laser's foot and the cone's ground ellipse (each boundary ray o + t d meets z = 0 at
  t = z_o / -d_z), widened by h; its longest ray: z_o / sin(beta - theta);
- a wall across the whole cone stops every ray at its distance: contained.
The zone is an outer envelope of sampled directions: never smaller than the reference
(1e-6), at most 5 % larger (the cone is sampled every theta_b / 32: 0.5-2.2 % over in 12 random draws,
4 % where the cone grazes the ground at 3 deg).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from scipy.optimize import brentq
from shapely.geometry import MultiPoint

import hazard
import scenes

from . import _refs as ref

P, A, PHI, MPE = 1000.0, 0.05, 1e-3, 50.0
C = 4 * P / (math.pi * MPE)
L = (math.sqrt(C) - A) / PHI  # 4996 m


def _half_width(r_max):
    """max over R in [0, r_max] of w(R) sqrt(ln(E(R) / MPE)) (no attenuation)."""
    d_star = math.sqrt(C / math.e)
    d_end = A + r_max * PHI
    if A <= d_star <= d_end:
        return math.sqrt(P / (math.pi * math.e * MPE))
    d = d_end if d_end < d_star else A
    return d / 2 * math.sqrt(math.log(C / (d * d)))


def _scene(position, aim, *, pointing=None, extra="", sector=None, plate_at=(300.0, 300.0, 50.0)):
    plate = dict(name="plate", shape="plate", center=np.array(plate_at, float), normal=np.array([0.0, -1.0, 0.0]),
                 tangent=np.array([1.0, 0.0, 0.0]), size=(1.0, 1.0), material=ref.lambertian(0.5))
    text = ref.scene_text(power=P, a=A, phi=PHI, position=np.asarray(position, float), aim=np.asarray(aim, float), targets=[plate])
    laser_extra = ""
    if pointing is not None:
        laser_extra += f"pointing_error_rad = {ref.fmt(pointing)}\n"
    if sector is not None:
        laser_extra += f"sector = {{ azimuth_deg = [{ref.fmt(sector[0])}, {ref.fmt(sector[1])}], elevation_deg = [0.0, 0.0] }}\n"
    text = text.replace("[exposure]", laser_extra + "[exposure]")
    return scenes.loads(text.replace("[analysis]", extra + "[analysis]"))


FLAT = '[terrain]\nkind = "flat"\nextent_m = 20000.0\nresolution_m = 1000.0\n'


@pytest.mark.parametrize("theta", [5e-4, pytest.param(2e-3, marks=pytest.mark.slow), 2e-2])
def test_a_horizontal_pointing_cone_sweeps_a_circular_sector(theta):
    """A laser 30 m up aiming level (its lowest ray meets the ground beyond L): the zone is
    the sector of radius L, half-angle theta, widened by the hazardous half-width."""
    res = hazard.analyze(_scene([0.0, 0.0, 30.0], [0.0, 1000.0, 30.0], pointing=theta, extra=FLAT if theta < 5e-3 else ""))
    assert res.mpe_w_m2 == MPE
    z = res.sdz
    h = _half_width(L)
    area = theta * L * L + (2 * L + 2 * theta * L) * h + math.pi * h * h
    assert z.nohd_m == pytest.approx(L, rel=1e-9) and z.max_range_m == pytest.approx(L, rel=1e-9)
    assert z.hazard_half_width_m == pytest.approx(h, rel=1e-5) and z.hazard_half_width_m >= h
    assert area * (1 - 1e-6) <= z.area_m2 <= area * 1.02
    assert not z.contained and z.escaping_directions == z.directions.count and z.above_horizon
    assert z.directions.kind == "cone" and z.directions.buffer_rad == theta


CONE_DRAW = dict(beta_deg=st.floats(8.0, 60.0), theta_deg=st.floats(0.5, 5.0), height=st.floats(5.0, 100.0), bearing=st.floats(-3.1, 3.1))


@ref.FAST_TWIN
@given(**CONE_DRAW)
def test_a_downward_cone_over_flat_ground_covers_the_hull_of_its_ground_ellipse(beta_deg, theta_deg, height, bearing):
    """The default run of :func:`_downward_cone_case` (10 draws; the slow twin sweeps 120)."""
    _downward_cone_case(beta_deg, theta_deg, height, bearing)


@pytest.mark.slow
@ref.SLOW
@given(**CONE_DRAW)
def test_a_downward_cone_over_flat_ground_sweep(beta_deg, theta_deg, height, bearing):
    _downward_cone_case(beta_deg, theta_deg, height, bearing)


def _downward_cone_case(beta_deg, theta_deg, height, bearing):
    """Every ray meets the ground before L: the zone covers the hull of the foot and the
    ellipse, contained. Its far end is where the hazardous edge of the topmost beam (at
    elevation -(beta - theta)) comes down: the upper edge of {r <= w(R) sqrt(ln(E(R) /
    MPE))} meets z = 0 at R* (bisection on the formula); the zone's reach along that
    direction lies between R* and the hit of the ray the engine casts at the octagon
    vertex around |s| <= s_0 = sqrt(ln(E_0 / MPE)) (origin s_0 / cos(pi/8) a/2 up, tilt
    s_0 / cos(pi/8) phi/2): conservative, and not more than that outer ray."""
    beta, theta = math.radians(beta_deg), math.radians(theta_deg)
    o = np.array([10.0, -20.0, height])
    d0 = np.array([math.sin(bearing) * math.cos(beta), math.cos(bearing) * math.cos(beta), -math.sin(beta)])
    res = hazard.analyze(_scene(o, o + 10.0 * d0, pointing=theta, extra='[terrain]\nkind = "flat"\nextent_m = 5000.0\nresolution_m = 250.0\n'))
    z = res.sdz
    # the cone's boundary rays from the formula: cos(theta) d0 + sin(theta) (cos psi e1 + sin psi e2)
    e1 = np.cross(d0, [0.0, 0.0, 1.0])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(d0, e1)
    psi = np.linspace(0.0, 2 * np.pi, 7200, endpoint=False)
    dirs = math.cos(theta) * d0 + math.sin(theta) * (np.cos(psi)[:, None] * e1 + np.sin(psi)[:, None] * e2)
    ground = o + dirs * (height / -dirs[:, 2])[:, None]
    eps = beta - theta  # the topmost direction's depression

    def edge_z(R):  # height of the hazardous region's upper edge at axial range R
        w = (A + R * PHI) / 2
        rh = w * math.sqrt(max(math.log(C / (A + R * PHI) ** 2), 0.0))
        return height - R * math.sin(eps) + rh * math.cos(eps)

    r_star = brentq(edge_z, 0.0, 10 * height / math.sin(eps))
    s_o = math.sqrt(math.log(C / A**2)) / math.cos(math.pi / 8)
    z0 = height + s_o * A / 2 * math.cos(eps)  # the outer ray: origin raised, direction tilted up
    t_out = z0 / (math.sin(eps) - s_o * PHI / 2 * math.cos(eps))
    h = _half_width(t_out)
    hull = MultiPoint(np.vstack([ground[:, :2], o[:2]]).tolist()).convex_hull.buffer(h, quad_segs=256)
    assert z.contained and z.escaping_directions == 0 and not z.above_horizon
    assert r_star * (1 - 1e-6) <= z.max_range_m <= t_out * (1 + 1e-5)  # measured along the outer ray itself
    assert hull.area * (1 - 1e-4) <= z.area_m2 <= hull.area * (t_out * math.sin(eps) / height) ** 2 * 1.05


def test_a_wall_across_the_cone_contains_it():
    """A 40 m wall 500 m down range across a 2 mrad cone stops every ray at ~500 m; the
    1 m target plate at 250 m in the beam is not a backstop (the beam can miss it)."""
    wall = '[[occluders]]\nshape = "box"\ncenter_m = [0.0, 501.0, 30.0]\nsize_m = [40.0, 2.0, 40.0]\n'
    res = hazard.analyze(_scene([0.0, 0.0, 30.0], [0.0, 1000.0, 30.0], pointing=2e-3, extra=wall, plate_at=(0.0, 250.0, 30.0)))
    assert res.targets[0].spot_power_w > 0
    z = res.sdz
    assert z.contained and 500.0 / math.cos(2e-3) * (1 - 1e-9) <= z.max_range_m <= 500.0 / math.cos(2e-3) * (1 + 2e-5)
    assert z.area_m2 <= 2e-3 * 500.0**2 * 1.02 + (2 * 500.0 * 1.002 + 2e-3 * 1000) * _half_width(500.0 / math.cos(2e-3)) * 1.02 + 1.0


def test_a_sector_and_a_range_boundary():
    """A level sector of bearings [-10, 10] deg widened by a 1 mrad pointing bound: the
    sector of radius L and half-angle 10 deg + 1 mrad; a square boundary of 3 km x 3 km
    about the laser cuts it: the part outside is said (its area from the formula: the
    reference sector (a fine polygon of its arc) minus the square)."""
    half = math.radians(10.0) + 1e-3
    res = hazard.analyze(_scene([0.0, 0.0, 30.0], [0.0, 1000.0, 30.0], pointing=1e-3, sector=(-10.0, 10.0),
                                extra="[range]\nboundary_m = [[-1500.0, -1500.0], [1500.0, -1500.0], [1500.0, 1500.0], [-1500.0, 1500.0]]\n"))
    z = res.sdz
    h = _half_width(L)
    area = half * L * L + (2 * L + 2 * half * L) * h + math.pi * h * h
    assert z.directions.kind == "sector" and z.directions.step_rad <= 1e-3 / 4 * (1 + 1e-9)
    assert area * (1 - 1e-6) <= z.area_m2 <= area * 1.02
    assert z.leaves_boundary
    # the sector without its buffer: half-angle 10 deg exactly
    half0 = math.radians(10.0)
    area0 = half0 * L * L + (2 * L + 2 * half0 * L) * h + math.pi * h * h
    assert area0 * (1 - 1e-6) <= z.nominal.area_m2 <= area0 * 1.02 and z.nominal.area_m2 < z.area_m2
    psi = np.linspace(-half, half, 4001)
    sector = MultiPoint([[0.0, 0.0]] + (L * np.stack([np.sin(psi), np.cos(psi)], 1)).tolist()).convex_hull
    from shapely.geometry import box
    outside = sector.difference(box(-1500.0, -1500.0, 1500.0, 1500.0)).area
    assert z.outside_boundary_m2 >= outside * (1 - 1e-6)
    # report.json's sdz block with its optional keys (nominal, leaves_boundary, escaping_*) against its schema (issue 35)
    import json

    from hazard.outputs.report import report_dict
    from hazard.outputs.report_schema import validate_report

    validate_report(json.loads(json.dumps(report_dict(res))))


def test_a_sigma_pointing_error_needs_its_multiple_and_uses_it():
    """A 1-sigma pointing error without its multiple is an error (no default is assumed);
    with 3 sigma the buffer is 3 x 0.1 mrad and the source is recorded."""
    base = ref.scene_text(power=P, a=A, phi=PHI, position=np.array([0.0, 0.0, 30.0]), aim=np.array([0.0, 1000.0, 30.0]),
                          targets=[dict(name="plate", shape="plate", center=np.array([0.0, 1000.0, 30.0]), normal=np.array([0.0, -1.0, 0.0]),
                                        tangent=np.array([1.0, 0.0, 0.0]), size=(1.0, 1.0), material=ref.lambertian(0.5))])
    with pytest.raises(scenes.SceneError, match="pointing_error_sigmas"):
        scenes.loads(base.replace("[exposure]", 'pointing_error_rad = 1e-4\npointing_error_kind = "sigma"\n[exposure]'))
    sc = scenes.loads(base.replace("[exposure]", 'pointing_error_rad = 1e-4\npointing_error_kind = "sigma"\npointing_error_sigmas = 3.0\n'
                                                 'pointing_error_source = "range SOP table 2"\n[exposure]'))
    z = hazard.analyze(sc).sdz
    assert z.directions.buffer_rad == pytest.approx(3e-4) and z.directions.pointing_error_source == "range SOP table 2"


def test_a_collimated_beam_in_clear_air_is_never_contained():
    """divergence 0, no attenuation: the NOHD is infinite and nothing stops the upper half
    of a level cone (found by a new-user trial: inf <= inf had counted as 'stopped')."""
    text = ref.scene_text(power=P, a=A, phi=0.0, position=np.array([0.0, 0.0, 30.0]), aim=np.array([0.0, 1000.0, 30.0]),
                          targets=[dict(name="plate", shape="plate", center=np.array([300.0, 300.0, 50.0]), normal=np.array([0.0, -1.0, 0.0]),
                                        tangent=np.array([1.0, 0.0, 0.0]), size=(1.0, 1.0), material=ref.lambertian(0.5))])
    text = text.replace("[exposure]", "pointing_error_rad = 1e-3\n[exposure]").replace("[analysis]", FLAT + "[analysis]")
    z = hazard.analyze(scenes.loads(text)).sdz
    assert z.unbounded and not z.contained and z.above_horizon and z.escaping_directions > 0


@pytest.mark.parametrize("clearance, contained", [(-0.5, False), (1.5, True)])
def test_a_wall_the_beam_only_clips_does_not_contain_it(clearance, contained):
    """A wall 500 m down range whose top lies `clearance` x s_0 w(R) above the beam's axis
    (s_0 = sqrt(ln(E_0 / MPE)), the hazardous cross-section's largest reach in units of
    w): below the axis plus the hazardous half-width, the beam's upper part goes over and
    the zone is not contained; well above it, it is. No pointing error: the aim alone."""
    R = 500.0
    w = (A + R * PHI) / 2
    s0 = math.sqrt(math.log(C / A**2))
    rh = w * math.sqrt(math.log(C / (A + R * PHI) ** 2))  # the true hazardous half-width at the wall
    top = 30.0 + (rh * 0.5 if clearance < 0 else clearance * s0 * w)
    wall = f'[[occluders]]\nshape = "box"\ncenter_m = [0.0, 501.0, {ref.fmt(top - 20.0)}]\nsize_m = [40.0, 2.0, 40.0]\n'
    z = hazard.analyze(_scene([0.0, 0.0, 30.0], [0.0, 1000.0, 30.0], extra=wall)).sdz
    assert z.contained == contained
    if not contained:
        assert z.max_range_m == pytest.approx(L, rel=1e-9)  # the part over the wall goes on to the NOHD


def test_an_aim_outside_the_sector_is_in_the_zone():
    """A sector of bearings 80-100 deg (east) while the aim is due north: the zone covers
    the aim line too (a new-user trial found it covered the east only), and the scene warns."""
    sc = _scene([0.0, 0.0, 30.0], [0.0, 1000.0, 30.0], pointing=1e-3, sector=(80.0, 100.0))
    assert any("sector" in w and "aim" in w for w in sc.warnings)
    z = hazard.analyze(sc).sdz
    from shapely.geometry import Point, Polygon

    zone = Polygon(z.polygon_m)
    assert zone.contains(Point(0.0, 0.9 * L)) and zone.contains(Point(0.9 * L, 0.0))


def _half_width_ref(a, phi, power_w, mpe_w_m2, length_m, mu):
    """max over R in [0, length_m] of w(R) sqrt(ln(E(R) / MPE)) with attenuation, coded
    here: a grid of 4001 ranges over the part of the path where E >= MPE (its end found
    by brentq on ln(E / MPE), which falls with R), then the bounded Brent search on the
    two cells about the grid's best point (the function is unimodal there and nonzero)."""
    from scipy.optimize import minimize_scalar

    def ln(r):
        d = a + r * phi
        return math.log(4 * power_w / (math.pi * d * d * mpe_w_m2)) - mu * r

    def half(r):
        v = ln(r)
        return (a + r * phi) / 2 * math.sqrt(v) if v > 0 else 0.0

    if ln(0.0) <= 0:
        return 0.0
    end = length_m if ln(length_m) > 0 else brentq(ln, 0.0, length_m, xtol=1e-15 * length_m)
    r = np.linspace(0.0, end, 4001)
    i = int(np.argmax([half(x) for x in r]))
    lo, hi = r[max(i - 1, 0)], r[min(i + 1, len(r) - 1)]
    best = max(half(r[i]), half(end))
    if hi > lo:
        res = minimize_scalar(lambda x: -half(x), bounds=(lo, hi), method="bounded", options={"xatol": 1e-12 * max(end, 1.0)})
        best = max(best, -float(res.fun))
    return best


def test_the_hazardous_half_width_where_the_beam_is_hazardous_only_near_the_laser():
    """No attenuation, 183 W, a = 66.1 mm, phi = 1.54 mrad, MPE 550 W/m^2 over a 12 km
    path: E >= MPE only in the first ~370 m, the widest point (D^2 = c / e) at 213 m, so
    the half-width is sqrt(P / (pi e MPE)) = 0.1974 m (a bounded search over the whole
    12 km, flat zero on most of it, returned the aperture's 0.0706 m: 2.8 x too narrow)."""
    from types import SimpleNamespace

    from hazard.pipeline.sdz import hazard_half_width_m

    laser = SimpleNamespace(beam_diameter_m=0.0661, divergence_rad=0.00154)
    want = math.sqrt(183.0 / (math.pi * math.e * 550.0))
    got = hazard_half_width_m(laser, 183.0, 550.0, 1.2e4)
    assert got == pytest.approx(want * (1 + 1e-6), rel=1e-12) and got >= want


def _check_half_width(a, phi, power_w, mpe_w_m2, length_m, mu):
    from types import SimpleNamespace

    from hazard.pipeline.sdz import hazard_half_width_m

    want = _half_width_ref(a, phi, power_w, mpe_w_m2, length_m, mu)
    got = hazard_half_width_m(SimpleNamespace(beam_diameter_m=a, divergence_rad=phi), power_w, mpe_w_m2, length_m, mu)
    # the engine's value is the exact maximum raised by 1e-6: never below the reference, and above it by
    # that 1e-6 only (the reference's bounded search is converged to 1e-12 of the path)
    assert got >= want * (1 + 1e-6) * (1 - 1e-12)
    assert got == pytest.approx(want * (1 + 1e-6), rel=1e-9, abs=1e-300)


_HALF_ARGS = dict(a=st.floats(1e-3, 1.0), phi=st.floats(1e-5, 1e-2), power_w=st.floats(0.1, 1e5),
                  mpe_w_m2=st.floats(0.1, 1e3), length_m=st.floats(1.0, 1e5),
                  mu=st.one_of(st.just(0.0), st.floats(1e-6, 1e-2)))


@ref.FAST
@given(**_HALF_ARGS)
def test_the_hazardous_half_width_is_the_maximum_over_the_path(a, phi, power_w, mpe_w_m2, length_m, mu):
    """Random beams, powers, MPEs, path lengths and attenuations: the half-width is the
    maximum over the path of w sqrt(ln(E / MPE)) (reference above), never below it."""
    _check_half_width(a, phi, power_w, mpe_w_m2, length_m, mu)


@pytest.mark.slow
@ref.SLOW
@given(**_HALF_ARGS)
def test_the_hazardous_half_width_is_the_maximum_over_the_path_many(a, phi, power_w, mpe_w_m2, length_m, mu):
    _check_half_width(a, phi, power_w, mpe_w_m2, length_m, mu)


def test_a_zone_beyond_100_km_is_drawn_to_its_nohd():
    """A 0.04 mrad beam: L = (sqrt(4 P / (pi MPE)) - a) / phi = 124.9 km, nothing in the way.
    The zone's polygon reaches L along the aim (it was cut at 100 km, the unbounded draw
    distance, and its area with it)."""
    phi = 4e-5
    l_far = (math.sqrt(C) - A) / phi
    plate = dict(name="plate", shape="plate", center=np.array([300.0, 300.0, 50.0]), normal=np.array([0.0, -1.0, 0.0]),
                 tangent=np.array([1.0, 0.0, 0.0]), size=(1.0, 1.0), material=ref.lambertian(0.5))
    text = ref.scene_text(power=P, a=A, phi=phi, position=np.array([0.0, 0.0, 30.0]), aim=np.array([0.0, 1000.0, 30.0]), targets=[plate])
    z = hazard.analyze(scenes.loads(text)).sdz
    assert l_far > 1.2e5 and z.max_range_m == pytest.approx(l_far, rel=1e-9)
    ring = np.asarray(z.polygon_m)
    far = float(ring[:, 1].max())  # along the aim (+y) from the laser at y = 0
    assert l_far * (1 - 1e-6) <= far <= l_far + z.hazard_half_width_m + 1.0
    assert z.area_m2 >= 2 * z.hazard_half_width_m * l_far * (1 - 1e-6)
