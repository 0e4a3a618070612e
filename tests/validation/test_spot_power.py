"""Power intercepted by flat targets, laser->target attenuation and the peak incident
irradiance, against references written from range-safety.md section 1 (not from the
engine).

References (``_refs.py``):
- rectangle normal to the beam: F = 1/4 [erf(x2/w)-erf(x1/w)][erf(y2/w)-erf(y1/w)],
  w = D/2, D = a + R phi (range-safety.md 1, 'Power fractions');
- disk of radius rho offset d: F = ncx2.cdf((rho/sigma)^2, 2, (d/sigma)^2), sigma = w/sqrt(2)
  (range-safety.md 1);
- tilted plate: the same Gaussian integrated over the plate's outline projected centrally
  from the virtual source a/phi behind the aperture (range-safety.md 1, beam model);
- attenuation: exp(-mu * path), path = laser -> hit point (laser-safety.md 3.1 Beer-Lambert).
Tolerance: 1 % relative, or 1e-6 P absolute for tiny fractions; the engine's stated
``spot_power_error_w`` must cover its difference from the reference.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

import hazard
import scenes

from . import _refs as ref

P = 1000.0
MU = st.sampled_from([0.0, 1e-4, 2e-3])



def _plate_case(R1, a, phi, fw, fh, ox, oz, tilt_deg, tilt_az, spin, mu, rot, shape="plate"):
    """Scene and reference for one flat target. The beam runs along +y from (0,-R1,0) to
    the origin; the target centre is offset (ox, oz) x D in the transverse plane; the
    target is tilted by tilt_deg about a transverse axis at azimuth tilt_az and spun by
    ``spin`` about the beam; the whole scene is then rotated by ``rot`` (3 angles)."""
    Q = ref.euler_rotation(*rot)
    pos0, aim0 = np.array([0.0, -R1, 0.0]), np.zeros(3)
    u0 = np.array([0.0, 1.0, 0.0])
    D = a + R1 * phi
    center0 = np.array([ox * D, 0.0, oz * D])
    axis = np.array([math.cos(tilt_az), 0.0, math.sin(tilt_az)])
    M = ref.rotation_matrix(axis, math.radians(tilt_deg)) @ ref.rotation_matrix(u0, spin)
    normal0, tangent0 = M @ -u0, M @ np.array([1.0, 0.0, 0.0])
    pos, aim, center, normal, tangent = (Q @ v for v in (pos0, aim0, center0, normal0, tangent0))
    beam = ref.Beam(P, a, phi, pos, aim, mu=mu)
    if shape == "plate":
        size = (fw * D, fh * D)
        expected = ref.plate_spot_power(beam, center, normal, tangent, size)
        axial = ref.plate_spot_power(beam, center, normal, tangent, size, path="axial") if mu > 0 else expected
    else:  # disk normal to the beam: path r^2/(2 R1) longer off the axis
        size = (fw * D,)
        expected = P * ref.disk_fraction(fw * D / 2, math.hypot(ox, oz) * D, D / 2) * math.exp(-mu * R1)
        rmax = min(math.hypot(ox, oz) * D + fw * D / 2, math.hypot(ox, oz) * D + 4 * D)
        axial = expected * math.exp(-mu * rmax**2 / (2 * R1))
    target = dict(name="t", shape=shape, center=center, normal=normal, tangent=tangent, size=size,
                  material=ref.lambertian(0.5))
    text = ref.scene_text(power=P, a=a, phi=phi, position=pos, aim=aim, targets=[target], mu=mu)
    _plate_case.last_target = target  # for debugging a failing draw
    return text, (expected, abs(expected - axial)), beam, D


def _check_power(res_target, expected, mu, R1):
    expected = expected[0] if isinstance(expected, tuple) else expected
    got = res_target.spot_power_w
    tol = max(0.01 * expected, 1e-6 * P * math.exp(-mu * R1))
    assert abs(got - expected) <= tol, f"spot power {got!r} vs reference {expected!r} (tol {tol:.3g})"


def _check_error_bound(res_target, expected):
    """|engine - reference| <= stated bound + slack. The slack is the reference's own
    accuracy (1e-7 relative, 1e-9 P) plus, with attenuation, the one genuine convention
    ambiguity: path length along each ray vs the hit's axial range (r^2/(2R) per ray).
    Quadrature, projection or single-attenuation-length-per-spot errors are not excused:
    if the engine makes them, its bound must say so."""
    expected, ambiguity = expected
    got, bound = res_target.spot_power_w, res_target.spot_power_error_w
    assert bound >= 0
    slack = 1e-7 * max(expected, 1e-300) + 1e-9 * P + ambiguity
    assert abs(got - expected) <= bound + slack, (
        f"|engine - reference| = {abs(got - expected):.4g} W ({got / expected - 1:+.3g} relative) "
        f"exceeds the stated bound {bound:.4g} W")


# ------------------------------------------------------------------ named cases

CASES = {
    # name: (R1, a, phi, fw, fh, ox, oz, tilt, tilt_az, spin)
    "spec-slot-10x4mm": (0.0, 0.01, 1e-3, 1.0, 0.4, 0.0, 0.0, 0.0, 0.0, 0.0),
    "centred-small-plate-in-a-wide-beam": (800.0, 0.02, 1e-3, 0.05, 0.05, 0.0, 0.0, 0.0, 0.0, 0.0),
    "tiny-plate-on-the-axis": (1500.0, 0.05, 2e-3, 0.02, 0.03, 0.0, 0.0, 0.0, 0.0, 0.0),
    "plate-larger-than-beam": (50.0, 0.005, 1e-3, 20.0, 20.0, 0.0, 0.0, 0.0, 0.0, 0.0),
    "edge-through-the-axis": (100.0, 0.01, 1e-3, 10.0, 10.0, 5.0, 0.0, 0.0, 0.0, 0.0),
    "corner-cut": (100.0, 0.01, 1e-3, 2.0, 2.0, 0.7, -0.8, 0.0, 0.0, 0.0),
    "off-beam-small-fraction": (300.0, 0.01, 1e-3, 0.5, 0.5, 1.5, 1.2, 0.0, 0.0, 0.0),
    "tilted-60-centred-small": (200.0, 0.01, 1e-3, 0.2, 0.1, 0.0, 0.0, 60.0, 0.3, 0.4),
    "tilted-45-cut": (200.0, 0.01, 1e-3, 3.0, 1.0, 0.6, 0.2, 45.0, 1.2, 0.0),
    # found by the slow sweep (a = e^-3 m, phi = e^-7 rad, R1 = e^2 m):
    "thin-strip-spun": (math.exp(2.0), math.exp(-3.0), math.exp(-7.0), 1.0, math.exp(-2.5), 0.0, 0.0, 0.0, 0.0, 0.5),
    "long-thin-strip-tilted-13": (math.exp(2.0), math.exp(-3.0), math.exp(-7.0), math.exp(2.75), math.exp(-2.5),
                                  0.0, 0.0, 13.0, 1.0, 0.0),
    "square-tilted-1-rotated-scene": (math.exp(2.0), math.exp(-3.0), math.exp(-7.0), 1.0, 1.0, 0.0, 0.0, 1.0, 0.0, 0.0,
                                      (0.0, 0.0, 1.0)),
}


def _named(name):
    case = CASES[name]
    R1, a, phi, fw, fh, ox, oz, tilt, taz, spin = case[:10]
    rot = case[10] if len(case) > 10 else (0.0, 0.0, 0.0)
    R1 = R1 or 10.0  # the laser must stand off the target
    if name == "spec-slot-10x4mm":  # the spec example: 10 mm beam at the target, 10 x 4 mm slot
        a, phi = 0.01 - R1 * 1e-4, 1e-4
    return R1, _plate_case(R1, a, phi, fw, fh, ox, oz, tilt, taz, spin, 0.0, rot)


@pytest.mark.parametrize("name", sorted(CASES))
def test_plate_spot_power_named_cases(name):
    """Spot power on plates: the spec's centred 10 x 4 mm slot in a 10 mm beam (F = 0.36101,
    range-safety.md 1), small plates centred in a wide beam (the 'hole on the axis' an
    undersampled beam misses), a plate larger than the beam, an edge through the axis
    (F = 1/2), a corner cut, an off-beam tail, tilted plates, and thin strips found by the
    slow sweep. Reference: erf rectangle /
    central projection of the outline (range-safety.md 1). 1 % or 1e-6 P."""
    R1, (text, expected, _, _) = _named(name)
    if name == "spec-slot-10x4mm":
        assert expected[0] == pytest.approx(0.36101 * P, rel=1e-5)
    if name == "edge-through-the-axis":
        assert expected[0] == pytest.approx(0.5 * P, rel=1e-6)
    res = hazard.analyze(scenes.loads(text))
    _check_power(res.targets[0], expected, 0.0, R1)


@pytest.mark.parametrize("name", sorted(CASES))
def test_plate_spot_power_error_bound_named_cases(name):
    """The engine's ``spot_power_error_w`` bounds |engine - reference| for the named cases
    (reference: erf rectangle / central projection, range-safety.md 1)."""
    R1, (text, expected, _, _) = _named(name)
    res = hazard.analyze(scenes.loads(text))
    _check_error_bound(res.targets[0], expected)


@pytest.mark.parametrize("rho_over_w, d_over_w", [(0.1, 0.0), (1.0, 0.0), (5.0, 0.0), (0.6, 0.6), (1.0, 1.5), (0.3, 2.0)])
def test_disk_spot_power_marcum(rho_over_w, d_over_w):
    """Disk normal to the beam, radius rho, centre offset d: F = ncx2.cdf((rho/sigma)^2, 2,
    (d/sigma)^2), sigma = w/sqrt(2); centred F = 1 - exp(-rho^2/w^2) (range-safety.md 1).
    1 % (or 1e-6 P), and the stated error bound covers the difference."""
    R1, a, phi = 120.0, 0.01, 1e-3
    D = a + R1 * phi
    fw = 2 * rho_over_w * (D / 2) / D
    off = d_over_w * (D / 2) / D
    text, expected, _, _ = _plate_case(R1, a, phi, fw, fw, off, 0.0, 0.0, 0.0, 0.0, 0.0, (0.3, 0.2, 0.1), shape="disk")
    res = hazard.analyze(scenes.loads(text))
    _check_power(res.targets[0], expected, 0.0, R1)
    _check_error_bound(res.targets[0], expected)



@pytest.mark.parametrize("f, ox", [(1.0, 0.0), (0.5, 0.3), (2.0, 0.1)])
def test_disk_just_in_front_of_a_wall_is_exact(f, ox):
    """A disk (diameter f D, centre ox D off the axis) 1 mm in front of a 1 m wall, a
    collimated 2 cm beam 50 m away. Found on 2026-11-27: the outline check's rays through
    the disk's circumscribed pieces (the polygon about the circle) reach past its rim
    there, met the wall behind and refused the exact integral; the rays' total then gave
    774 W (bound 503 W) for the exact 632 W, 240 W for 161 W and 992 W for 979 W. A hit
    beyond the disk's plane is no evidence of anything in front of it (the sampler's rule,
    ``beam.before_plane``). Reference: the Marcum-Q disk fraction (range-safety.md 1) for
    the disk, and the wall's exact 1 m square less the disk for the wall: never below, the
    stated bound (the disk polygon's, under 1e-5 P) covers the difference."""
    a = 0.02
    disk = dict(name="t", shape="disk", center=[ox * a, 0.0, 0.0], normal=[0, -1.0, 0], tangent=[1.0, 0, 0], size=[f * a],
                material=ref.lambertian(0.5))
    wall = dict(name="wall", shape="plate", center=[0.0, 1e-3, 0.0], normal=[0, -1.0, 0], tangent=[1.0, 0, 0], size=[1.0, 1.0],
                material=ref.lambertian(0.5))
    text = ref.scene_text(power=P, a=a, phi=0.0, position=[0, -50.0, 0], aim=[0, 0, 0], targets=[disk, wall])
    got = hazard.analyze(scenes.loads(text)).targets
    w = a / 2
    want_disk = P * ref.disk_fraction(f * a / 2, ox * a, w)
    want_wall = P * ref.rect_fraction(-0.5, 0.5, -0.5, 0.5, w) - want_disk
    for t, want in zip(got, (want_disk, want_wall)):
        assert t.spot_power_w >= want - 1e-9 * P, f"{t.name}: {t.spot_power_w!r} W below the exact {want!r} W"
        assert t.spot_power_w - want <= t.spot_power_error_w + 1e-9 * P, f"{t.name}: {t.spot_power_w!r} W vs exact {want!r} W"
        assert t.spot_power_error_w <= 1e-5 * P  # the outline's polygon bound (the rays' was 58-503 W)


# ------------------------------------------------------------------ properties

PLATE_ARGS = dict(
    R1=ref.log_uniform(5.0, 2000.0), a=ref.log_uniform(2e-3, 0.05), phi=ref.log_uniform(1e-4, 2e-3),
    fw=ref.log_uniform(0.05, 20.0), fh=ref.log_uniform(0.05, 20.0), ox=st.floats(-2.0, 2.0), oz=st.floats(-2.0, 2.0),
    tilt_deg=st.floats(0.0, 60.0), tilt_az=st.floats(0.0, 2 * math.pi), spin=st.floats(0.0, 2 * math.pi), mu=MU,
    rot=st.tuples(st.floats(-math.pi, math.pi), st.floats(-math.pi, math.pi), st.floats(-math.pi, math.pi)),
)


def _plate_property(R1, a, phi, fw, fh, ox, oz, tilt_deg, tilt_az, spin, mu, rot, bound=False):
    text, expected, _, _ = _plate_case(R1, a, phi, fw, fh, ox, oz, tilt_deg, tilt_az, spin, mu, rot)
    res = hazard.analyze(scenes.loads(text))
    if bound:
        _check_error_bound(res.targets[0], expected)
    else:
        _check_power(res.targets[0], expected, mu, R1)


@ref.FAST_TWIN
@given(**PLATE_ARGS)
def test_plate_spot_power_property(**kw):
    """Random plates (0.05-20 D per side, offsets up to 2 D, tilts up to 60 deg, any spin,
    mu in {0, 1e-4, 2e-3}, R1 5 m - 2 km, whole scene rotated): spot power = P x the
    Gaussian integrated over the centrally projected outline, each ray attenuated by
    exp(-mu path) (range-safety.md 1; laser-safety.md 3.1). 1 % or 1e-6 P."""
    _plate_property(**kw)


@ref.FAST_TWIN
@given(**PLATE_ARGS)
def test_plate_spot_power_error_bound_property(**kw):
    """Same draws: the stated ``spot_power_error_w`` covers |engine - reference|."""
    _plate_property(**kw, bound=True)


@pytest.mark.slow
@ref.SLOW
@given(**PLATE_ARGS)
def test_plate_spot_power_property_sweep(**kw):
    """Larger sweep of ``test_plate_spot_power_property`` (same reference and tolerance)."""
    _plate_property(**kw)


@pytest.mark.slow
@ref.SLOW
@given(**PLATE_ARGS)
def test_plate_spot_power_error_bound_sweep(**kw):
    """Larger sweep of ``test_plate_spot_power_error_bound_property``."""
    _plate_property(**kw, bound=True)


DISK_ARGS = dict(
    R1=ref.log_uniform(5.0, 2000.0), a=ref.log_uniform(2e-3, 0.05), phi=ref.log_uniform(1e-4, 2e-3),
    f=ref.log_uniform(0.05, 20.0), off=st.floats(0.0, 2.0), az=st.floats(0.0, 2 * math.pi), mu=MU,
    rot=st.tuples(st.floats(-math.pi, math.pi), st.floats(-math.pi, math.pi), st.floats(-math.pi, math.pi)),
)


def _disk_property(R1, a, phi, f, off, az, mu, rot):
    text, expected, _, _ = _plate_case(R1, a, phi, f, f, off * math.cos(az), off * math.sin(az), 0.0, 0.0, 0.0, mu, rot,
                                       shape="disk")
    res = hazard.analyze(scenes.loads(text))
    _check_power(res.targets[0], expected, mu, R1)


@ref.FAST_TWIN
@given(**DISK_ARGS)
def test_disk_spot_power_property(**kw):
    """Random disks normal to the beam (diameter 0.05-20 D, offset up to 2 D): Marcum-Q
    fraction x exp(-mu R1) (range-safety.md 1). 1 % or 1e-6 P."""
    _disk_property(**kw)


@pytest.mark.slow
@ref.SLOW
@given(**DISK_ARGS)
def test_disk_spot_power_sweep(**kw):
    """Larger sweep of ``test_disk_spot_power_property``."""
    _disk_property(**kw)


# ------------------------------------------------------------------ attenuation laser -> target


@pytest.mark.parametrize("mu", [1e-4, 2e-3])
@pytest.mark.parametrize("R1", [5.0, 400.0, 2000.0])
def test_attenuation_laser_to_target(mu, R1):
    """Spot power with [atmosphere] attenuation_per_m = mu equals the unattenuated
    reference times exp(-mu R1) (Beer-Lambert, laser-safety.md 3.1; once on the leg
    laser->target). Plate normal to the beam, 3 D x 3 D, centred."""
    a, phi = 0.01, 1e-3
    text, expected, _, D = _plate_case(R1, a, phi, 3.0, 3.0, 0.0, 0.0, 0.0, 0.0, 0.0, mu, (0.0, 0.0, 0.0))
    w = D / 2
    by_hand = P * ref.rect_fraction(-1.5 * D, 1.5 * D, -1.5 * D, 1.5 * D, w) * math.exp(-mu * R1)
    assert expected[0] == pytest.approx(by_hand, rel=1e-6)
    res = hazard.analyze(scenes.loads(text))
    _check_power(res.targets[0], by_hand, mu, R1)


@pytest.mark.parametrize("R1, tilt", [(1000.0, 60.0), (200.0, 60.0), (200.0, 30.0)])
def test_tilted_plate_attenuation_per_ray_error_bound(R1, tilt):
    """A tilted plate in an attenuating atmosphere: each ray's power is attenuated by
    exp(-mu L) along its own path (Beer-Lambert, laser-safety.md 3.1), so the spot power
    is the Gaussian x exp(-mu L(x, z)) integrated over the projected outline. Within 1 %,
    and the stated error bound covers the difference (a single attenuation length for the
    whole spot is an approximation, not a convention)."""
    text, expected, _, _ = _plate_case(R1, 0.05, 2e-3, 0.5, 0.5, 0.0, 0.0, tilt, 0.0, 0.0, 2e-3, (0.0, 0.0, 0.0))
    res = hazard.analyze(scenes.loads(text))
    _check_power(res.targets[0], expected, 2e-3, R1)
    _check_error_bound(res.targets[0], expected)


# ------------------------------------------------------------------ peak incident irradiance


@pytest.mark.parametrize("fw, fh, ox, oz, mu", [
    (0.05, 0.05, 0.0, 0.0, 0.0),     # tiny plate on the axis: E0
    (20.0, 20.0, 0.0, 0.0, 2e-3),    # larger than the beam: E0 exp(-mu R1)
    (1.0, 1.0, 1.0, 0.0, 1e-4),      # edge at x = 0.5 D: E0 exp(-(0.5 D)^2/w^2)
    (0.5, 0.5, 1.5, -1.0, 0.0),      # off the beam: nearest corner
])
def test_target_peak_irradiance_normal_plates(fw, fh, ox, oz, mu):
    """Highest incident irradiance on the lit part of a plate normal to the beam:
    4P/(pi D^2) exp(-r_min^2/w^2) exp(-mu R1), r_min = the plate point nearest the axis
    (range-safety.md 1 profile; Beer-Lambert). 1 %."""
    R1, a, phi = 150.0, 0.01, 1e-3
    text, _, beam, D = _plate_case(R1, a, phi, fw, fh, ox, oz, 0.0, 0.0, 0.0, mu, (0.0, 0.0, 0.0))
    x1, x2 = (ox - fw / 2) * D, (ox + fw / 2) * D
    z1, z2 = (oz - fh / 2) * D, (oz + fh / 2) * D
    expected = ref.rect_peak_irradiance(beam, R1, x1, x2, z1, z2)
    res = hazard.analyze(scenes.loads(text))
    assert res.targets[0].peak_irradiance_w_m2 == pytest.approx(expected, rel=0.01)


@pytest.mark.parametrize("f, off", [(0.1, 0.0), (2.0, 0.5), (0.4, 1.2)])
def test_target_peak_irradiance_disks(f, off):
    """Disk normal to the beam, diameter f D, centre offset off D: peak = E0 exp(-r_min^2/w^2),
    r_min = max(0, d - rho) (range-safety.md 1). 1 %."""
    R1, a, phi = 150.0, 0.01, 1e-3
    text, _, beam, D = _plate_case(R1, a, phi, f, f, off, 0.0, 0.0, 0.0, 0.0, 0.0, (0.0, 0.0, 0.0), shape="disk")
    rmin = max(0.0, off * D - f * D / 2)
    w = D / 2
    expected = beam.peak(R1) * math.exp(-rmin**2 / w**2)
    res = hazard.analyze(scenes.loads(text))
    assert res.targets[0].peak_irradiance_w_m2 == pytest.approx(expected, rel=0.01)


def _peak_property(R1, a, phi, fw, fh, ox, oz, tilt_deg, tilt_az, spin, mu, rot):
    text, _, beam, _ = _plate_case(R1, a, phi, fw, fh, ox, oz, tilt_deg, tilt_az, spin, mu, rot)
    tg = _plate_case.last_target
    expected = ref.plate_peak_irradiance(beam, tg["center"], tg["normal"], tg["tangent"], tg["size"])
    if tilt_deg == 0.0 and rot == (0.0, 0.0, 0.0):  # the closed form for a plate normal to the beam
        D = a + R1 * phi
        x1, x2, z1, z2 = (ox - fw / 2) * D, (ox + fw / 2) * D, (oz - fh / 2) * D, (oz + fh / 2) * D
        assert expected == pytest.approx(ref.rect_peak_irradiance(beam, R1, x1, x2, z1, z2), rel=1e-6)
    res = hazard.analyze(scenes.loads(text))
    assert res.targets[0].peak_irradiance_w_m2 == pytest.approx(expected, rel=0.01)


@ref.FAST_TWIN
@given(**PLATE_ARGS)
def test_target_peak_irradiance_property(**kw):
    """Random plates (as in the spot-power property): the highest incident irradiance on the
    lit part, normal to the beam and attenuated, = max over the projected outline of
    E0(R) (D(R)/D(s))^2 exp(-|q|^2/w^2) exp(-mu L) (range-safety.md 1 profile, rays from
    the virtual source; Beer-Lambert). 1 %."""
    _peak_property(**kw)


@pytest.mark.slow
@ref.SLOW
@given(**PLATE_ARGS)
def test_target_peak_irradiance_sweep(**kw):
    """Larger sweep of ``test_target_peak_irradiance_property``."""
    _peak_property(**kw)


# ------------------------------------------------------------------ a plate partly hidden by another


def _shadowed_pair(R_front, R_back, a, phi, front, back, mu=0.0):
    """Two plates normal to a beam along +y from (0, -R_back, 0)... front plate at range
    R_front, back plate at R_back; rectangles (x1, x2, z1, z2) in metres in their planes."""
    pos = np.array([0.0, -R_back, 0.0])
    targets = []
    for name, R, (x1, x2, z1, z2) in (("front", R_front, front), ("back", R_back, back)):
        targets.append(dict(name=name, shape="plate", center=np.array([(x1 + x2) / 2, R - R_back, (z1 + z2) / 2]),
                            normal=np.array([0.0, -1.0, 0.0]), tangent=np.array([1.0, 0.0, 0.0]),
                            size=(x2 - x1, z2 - z1), material=ref.lambertian(0.5)))
    return ref.scene_text(power=P, a=a, phi=phi, position=pos, aim=pos + [0.0, 1.0, 0.0], targets=targets, mu=mu)


def _shadowed_reference(R_front, R_back, a, phi, front, back, mu=0.0):
    """Back plate's power: the Gaussian over its rectangle minus over its rectangle's
    intersection with the front plate's shadow. Rays leave a virtual point source, so the
    front rectangle projects onto the back plane scaled by w_back / w_front (w = (a + R
    phi)/2, range-safety.md 1); each rectangle's fraction is an erf product."""
    w_f, w_b = (a + R_front * phi) / 2, (a + R_back * phi) / 2
    k = w_b / w_f
    sx1, sx2, sz1, sz2 = (v * k for v in front)
    bx1, bx2, bz1, bz2 = back
    whole = ref.rect_fraction(bx1, bx2, bz1, bz2, w_b)
    ix1, ix2, iz1, iz2 = max(bx1, sx1), min(bx2, sx2), max(bz1, sz1), min(bz2, sz2)
    hidden = ref.rect_fraction(ix1, ix2, iz1, iz2, w_b) if ix1 < ix2 and iz1 < iz2 else 0.0
    front_p = P * ref.rect_fraction(*front, w_f) * math.exp(-mu * R_front)
    return front_p, P * (whole - hidden) * math.exp(-mu * R_back)


@pytest.mark.parametrize("front, back", [
    ((-0.05, 0.05, -0.05, 0.05), (-1.0, 1.0, -1.0, 1.0)),     # a small window centred in front of a wide plate
    ((0.0, 0.3, -0.3, 0.3), (-0.2, 0.2, -0.2, 0.2)),          # half of the back plate hidden
    ((-0.3, -0.02, -0.01, 0.04), (-0.1, 0.25, -0.15, 0.05)),  # off-centre overlap
])
def test_plate_partly_hidden_by_a_plate_in_front(front, back):
    """A plate behind another receives the beam less the front plate's shadow: exact by
    erf rectangles (range-safety.md 1); 1e-6 relative (both are exact), with the
    stated error bound covering the difference."""
    R_f, R_b, a, phi = 40.0, 55.0, 0.05, 2e-3
    text = _shadowed_pair(R_f, R_b, a, phi, front, back)
    want_front, want_back = _shadowed_reference(R_f, R_b, a, phi, front, back)
    res = hazard.analyze(scenes.loads(text))
    got = {t.name: t for t in res.targets}
    assert got["front"].spot_power_w == pytest.approx(want_front, rel=1e-6)
    assert got["back"].spot_power_w == pytest.approx(want_back, rel=1e-6, abs=1e-9 * P)
    assert abs(got["back"].spot_power_w - want_back) <= got["back"].spot_power_error_w + 1e-6 * want_back + 1e-9 * P


HIDDEN_ARGS = dict(
    R_f=st.floats(5.0, 200.0), gap=st.floats(0.5, 100.0), a=ref.log_uniform(2e-3, 0.05), phi=ref.log_uniform(1e-4, 2e-3),
    f=st.tuples(st.floats(-2.0, 2.0), st.floats(0.02, 2.0), st.floats(-2.0, 2.0), st.floats(0.02, 2.0)),
    b=st.tuples(st.floats(-2.0, 2.0), st.floats(0.02, 3.0), st.floats(-2.0, 2.0), st.floats(0.02, 3.0)),
    mu=st.sampled_from([0.0, 2e-3]))


@ref.FAST_TWIN  # 25 examples took 7.8 s CPU; the slow twin below sweeps 120
@given(**HIDDEN_ARGS)
def test_plate_partly_hidden_property(R_f, gap, a, phi, f, b, mu):
    """Random front/back plate pairs normal to the beam (offsets to 2 D, sizes 0.02-3 D,
    attenuation): the back plate's spot power is the erf rectangle less its shadowed part
    (range-safety.md 1; Beer-Lambert along the axis), 1 % or 1e-6 P."""
    R_b = R_f + gap
    D_f, D_b = a + R_f * phi, a + R_b * phi
    front = (f[0] * D_f, f[0] * D_f + f[1] * D_f, f[2] * D_f, f[2] * D_f + f[3] * D_f)
    back = (b[0] * D_b, b[0] * D_b + b[1] * D_b, b[2] * D_b, b[2] * D_b + b[3] * D_b)
    res = hazard.analyze(scenes.loads(_shadowed_pair(R_f, R_b, a, phi, front, back, mu)))
    want_front, want_back = _shadowed_reference(R_f, R_b, a, phi, front, back, mu)
    got = {t.name: t.spot_power_w for t in res.targets}
    # off-axis rays travel r^2/(2R) further than the axis: the reference uses the axial range
    for name, want, R in (("front", want_front, R_f), ("back", want_back, R_b)):
        tol = max(0.01 * want, 1e-6 * P) + want * (1 - math.exp(-mu * 8 * max(D_f, D_b) ** 2 / R))
        assert abs(got[name] - want) <= tol, f"{name}: engine {got[name]:.6g} W vs reference {want:.6g} W"


def test_shadow_edges_on_the_beam_axis():
    """The slow property's shrunk example: front plate [0, D_f]^2 at 5 m, back strip
    x in [-1.5 D_b, 0.5 D_b], z in [0, 0.125 D_b] at 6 m (D = a + R phi, a = e^-3 m,
    phi = e^-7 rad): both lower edges on the beam's axis, the strip's edges on the
    sampling cells' boundaries, so no cell's ray lay inside its outline to see the front
    plate's shadow there. The back strip's power is the erf rectangle less the front's
    shadow (the reference above): 69.08 W of 1000 W (it was 260 W, with a bound of 4e-7 W),
    and the same with the front moved 1 um (it was 482 W), on either ray backend. The
    sampler's ray through each piece of the strip's outline (``beam._piece_hits``) sees it."""
    R_f, R_b, a, phi = 5.0, 6.0, math.exp(-3.0), math.exp(-7.0)
    D_f, D_b = a + R_f * phi, a + R_b * phi
    front, back = (0.0, D_f, 0.0, D_f), (-1.5 * D_b, 0.5 * D_b, 0.0, 0.125 * D_b)
    res = hazard.analyze(scenes.loads(_shadowed_pair(R_f, R_b, a, phi, front, back)))
    want_front, want_back = _shadowed_reference(R_f, R_b, a, phi, front, back)
    got = {t.name: t.spot_power_w for t in res.targets}
    assert got["front"] == pytest.approx(want_front, rel=1e-6)
    assert got["back"] == pytest.approx(want_back, rel=0.01), f"back: engine {got['back']:.6g} W vs reference {want_back:.6g} W"
    front = (1e-6, D_f, 1e-6, D_f)
    res = hazard.analyze(scenes.loads(_shadowed_pair(R_f, R_b, a, phi, front, back)))
    got = {t.name: t.spot_power_w for t in res.targets}
    assert got["back"] == pytest.approx(_shadowed_reference(R_f, R_b, a, phi, front, back)[1], rel=0.01)
    # the other ray backend (float64 numpy, no float32 grazes) finds the same shadow
    res = hazard.analyze(scenes.loads(_shadowed_pair(R_f, R_b, a, phi, front, back)), backend="numpy")
    assert {t.name: t.spot_power_w for t in res.targets} == pytest.approx(got, rel=1e-6)


def _strip_behind_box(x1, x2, z1, z2, edge):
    """A collimated 2 cm beam along +y; a plate strip x in [x1, x2], z in [z1, z2] (1/e
    radii w = 1 cm) at y = 0 facing it; a 1 m box 5 m in front hiding x < edge. Returns
    the strip's (spot power, stated bound) and the erf rectangle of its lit part
    [max(x1, edge), x2] x [z1, z2] (range-safety.md 1; a collimated beam's shadow is the
    box's own edge)."""
    got = hazard.analyze(scenes.loads(_strip_behind_box_text(x1, x2, z1, z2, edge))).targets[0]
    want = P * ref.rect_fraction(max(x1, edge), x2, z1, z2, 1.0) if edge < x2 else 0.0
    return got.spot_power_w, got.spot_power_error_w, want


def _strip_behind_box_text(x1, x2, z1, z2, edge, w=0.01):
    """The scene of :func:`_strip_behind_box` (``w``: the beam's 1/e radius [m])."""
    strip = dict(name="t", shape="plate", center=[(x1 + x2) / 2 * w, 0.0, (z1 + z2) / 2 * w], normal=[0, -1.0, 0],
                 tangent=[1.0, 0, 0], size=[(x2 - x1) * w, (z2 - z1) * w], material=ref.lambertian(0.5))
    text = ref.scene_text(power=P, a=2 * w, phi=0.0, position=[0, -20.0, 0], aim=[0, 0, 0], targets=[strip])
    return text + f'[[occluders]]\nshape = "box"\ncenter_m = [{edge * w - 0.5!r}, -5.0, 0.0]\nsize_m = [1.0, 0.1, 1.0]\n'


def _check_strip(x1, x2, z1, z2, edge):
    got, bound, want = _strip_behind_box(x1, x2, z1, z2, edge)
    slack = 1e-6 * want + 1e-9 * P
    assert got >= want - slack, f"engine {got:.6g} W below the exact {want:.6g} W (bound {bound:.3g} W)"
    assert got - want <= bound + slack, f"engine - exact = {got - want:.4g} W over the stated bound {bound:.4g} W"


@pytest.mark.parametrize("x1, x2, z1, z2, edge", [
    (-2.6875, 1.25, -0.234375, -0.203125, 0.0625),  # was 0.61 W of 7.16
    pytest.param(-1.8125, 1.9375, -0.65625, -0.625, 0.0, marks=pytest.mark.slow),  # was 1.26 W (bound 0.86) of 5.81
])
def test_thin_strip_behind_a_box_edge(x1, x2, z1, z2, edge):
    """Found on 2026-11-26 (a sweep with edges on the cells' boundaries): a strip thinner
    than the coarse cells lying between their rays, half hidden by a box. A box has no
    exact outline, so the strip's power is the rays'; its vertices (the refinement's
    only seeds) were all at its ends, so the rays met only its ends: 0.61 W of 7.16 W,
    with a bound of 0.05 W. Now the cells its projected hull meets are split to half its
    width (``beam._seed_cells``). exact <= engine <= exact + stated bound."""
    _check_strip(x1, x2, z1, z2, edge)


STRIP_ARGS = dict(x1=st.integers(-48, -1), x2=st.integers(1, 48), z1=st.integers(-96, 96), h=st.sampled_from([1, 2, 4, 8]),
                  edge=st.integers(-8, 8))


@pytest.mark.slow
@ref.settings(ref.SLOW, max_examples=40)  # 1.5-4 s each: a strip's edges are resolved by rays (the box allows no outline)
@given(**STRIP_ARGS)
def test_thin_strip_behind_a_box_property_slow(x1, x2, z1, h, edge):
    """Strips on the cells' grid (x in 1/16 w, z in 1/64 w, 1/64-1/8 w thin) behind a box
    edge on it: exact <= engine <= exact + stated bound."""
    _check_strip(x1 / 16, x2 / 16, z1 / 64, (z1 + h) / 64, edge / 16)


@pytest.mark.slow
@ref.SLOW
@given(**HIDDEN_ARGS)
def test_plate_partly_hidden_property_slow(R_f, gap, a, phi, f, b, mu):
    test_plate_partly_hidden_property.hypothesis.inner_test(R_f, gap, a, phi, f, b, mu)


def test_peak_irradiance_beside_a_shadow():
    """A 0.1 m square centred in front of a wide plate hides the axis: the back plate's
    highest incident irradiance is at the shadow's edge midpoints, r = 0.05 w_b / w_f
    from the axis: E0(R_b) exp(-r^2 / w_b^2) (range-safety.md 1 profile). Within 1 %, and
    never below (the tool must not under-state a heating drive)."""
    R_f, R_b, a, phi = 40.0, 55.0, 0.05, 2e-3
    front, back = (-0.05, 0.05, -0.05, 0.05), (-1.0, 1.0, -1.0, 1.0)
    w_f, w_b = (a + R_f * phi) / 2, (a + R_b * phi) / 2
    r = 0.05 * w_b / w_f
    want = P / (math.pi * w_b**2) * math.exp(-(r / w_b) ** 2)
    res = hazard.analyze(scenes.loads(_shadowed_pair(R_f, R_b, a, phi, front, back)))
    got = {t.name: t for t in res.targets}["back"].peak_irradiance_w_m2
    assert want * (1 - 1e-9) <= got <= want * 1.01
