"""Specular spheres and cylinders, against references written from range-safety.md
section 4 (not from the engine).

References (``_refs.py``; checked by Monte Carlo ray traces in test_reference_selfcheck.py):
- convex sphere, radius r, reflectance rho, Gaussian beam centred on it: intensity
  I(psi) = rho (r^2/4) E0 exp(-r^2 sin^2(psi/2)/w^2) [W/sr], psi from the back-reflection
  direction, E0 = 4P/(pi D^2), w = D/2 at the sphere; a far observer (D_obs >> r) gets
  I exp(-mu L1) exp(-mu L2)/D_obs^2. This far-field form is exact to O(r/D_obs), and a
  narrow beam on a large sphere amplifies that error through exp(-r^2 sin^2/w^2), so the
  random draws use the same reflection traced without the far-field step
  (``_refs.sphere_mirror_exact``: the exact in-plane ray, its spacing at the observer and
  the ring spreading about the axis; it tends to the formula as r/D_obs, checked below).
  1 %, and the engine must never be lower than the reference by more than that;
- cylinder, radius r, axis normal to the beam: a fan in the plane normal to the axis,
  E(D) = rho E r cos(psi/2)/(2 D) with E the incident irradiance at the impact parameter
  h = r sin(psi/2), valid while the fan is thin (beam << cylinder length). With a narrow
  Gaussian beam the O(r/D) error of that far-field step is amplified by the steep
  exp(-h^2/w^2), so the reference is the same fan traced without it
  (``_refs.cylinder_fan_exact``: exact ray through the observer, ray spacing there, and
  the out-of-plane spreading l0/(l0 + D) of a diverging beam); the self-check shows it
  equals the formula as D/r grows and matches a Monte Carlo trace. The verdict's value
  is the mean over the 7 mm limiting aperture: across its thickness the fan keeps the
  incident Gaussian (``_refs.fan_pupil_factor``, 1-D quadrature, checked below against
  the Bessel closed form), a few % below the point value where the fan is a centimetre
  thick. 1 %, one-sided (engine not lower than the reference by more than 1 %).

The random draws include mirrors much larger than the beam (sphere and cylinder radius
up to 10 beam radii: the whole beam on the mirror) as well as beams much wider.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import assume, given
from hypothesis import strategies as st

import hazard
import scenes

from . import _refs as ref
from ._refs import HEAVY_TWIN




def _scene(beam, target, observers):
    obs = [(f"o{i}", p, None) for i, p in enumerate(observers)]
    return scenes.loads(ref.scene_text(power=beam.P, a=beam.a, phi=beam.phi, position=beam.pos, aim=np.zeros(3),
                                       targets=[target], observers=obs, mu=beam.mu))


# ------------------------------------------------------------------ sphere


def _sphere_case(r, L, w_over_r, q, mu, rho, obs_dirs, rot):
    """Sphere of radius r at the origin, laser L away (whole scene rotated by ``rot``);
    the beam's 1/e radius at the sphere is w_over_r x r, a fraction q of its diameter
    from divergence. ``obs_dirs``: (psi, azimuth, distance/r). Returns the scene, the
    references and the observer points."""
    Q = ref.euler_rotation(*rot)
    D = 2 * w_over_r * r
    phi = q * D / L
    a = (1 - q) * D
    beam = ref.Beam(100.0, a, phi, Q @ np.array([0.0, -L, 0.0]), np.zeros(3), mu=mu)
    back = -beam.u
    e1, e2 = beam.e1, beam.e2
    E0 = beam.peak(L)
    Rs = L + a / phi  # virtual source -> sphere centre
    pts, want = [], []
    for psi, az, m in obs_dirs:
        side = math.cos(az) * e1 + math.sin(az) * e2
        d = math.cos(psi) * back + math.sin(psi) * side
        O = m * r * d
        e, hit2 = ref.sphere_mirror_exact(rho, r, Rs, D / 2, E0, (float(O @ side), float(O @ beam.u)))
        hit = hit2[0] * side + hit2[1] * beam.u
        att = math.exp(-mu * (np.linalg.norm(hit - beam.pos) + np.linalg.norm(O - hit)))
        pts.append(O)
        want.append(e * att if _in_beam_square(hit2, Rs, D) else math.nan)
    target = dict(name="ball", shape="sphere", center=np.zeros(3), normal=Q @ np.array([0.0, 0.0, 1.0]),
                  tangent=Q @ np.array([1.0, 0.0, 0.0]), size=(2 * r,), material=ref.specular(rho))
    return beam, _scene(beam, target, pts), np.array(want), pts


def _in_beam_square(hit2, Rs, D):
    """Whether the reflecting ray's incident ray (through x0 in the plane of the centre)
    lies within 3.8 beam radii of the axis. The engine samples the beam over 4 radii
    (what lies beyond carries 3.1e-8 of its power, at most exp(-16) of its peak): an
    observer lit only from beyond is checked for a finite value, not against the tail."""
    x0 = float(hit2[0]) * Rs / (float(hit2[1]) + Rs)
    return abs(x0) <= 3.8 * D / 2


def _check_tail(g, e):
    if math.isnan(e):
        assert math.isfinite(g) and g >= 0
        return True
    return False


def _check_sphere(got, want):
    for g, e in zip(got, want):
        if _check_tail(g, e):
            continue
        assert g >= e * (1 - 0.01), f"engine {g:.6g} below the exact reference {e:.6g} by more than 1 %"
        assert g == pytest.approx(e, rel=0.01)


@pytest.mark.parametrize("psi_deg", [5.0, 8.0, 12.0, 15.0, 19.0])
def test_sphere_observers_5_to_19_degrees_off_back_reflection(psi_deg):
    """Sphere r = 5 cm, beam w = 5 cm centred on it, 200 m away; observers 100 m away
    (2000 r), 5-19 deg off the back-reflection direction: I(psi)/D^2 with
    I = rho (r^2/4) E0 exp(-r^2 sin^2(psi/2)/w^2) (range-safety.md 4). They must not get
    zero. 1 % of the exact trace (which is within 5e-5 of the far-field formula here),
    and never lower than it by more than 1 %."""
    psi = math.radians(psi_deg)
    beam, scene, want, _ = _sphere_case(0.05, 200.0, 1.0, 0.5, 0.0, 0.9, [(psi, 0.3, 2000.0)], (0.0, 0.0, 0.0))
    res = hazard.analyze(scene)
    got = res.observers.reflected_irradiance_w_m2  # the reflection alone (the direct beam's Gaussian wings may add to the total)
    assert got[0] > 0
    _check_sphere(got, want)


def test_sphere_spec_example_uniform_beam():
    """range-safety.md 4 test: rho = 0.9, r = 0.05 m, E = 1e4 W/m^2 (beam much wider than
    the sphere): I = 5.625 W/sr isotropic; at D = 100 m (2000 r) E = I/D^2 = 5.625e-4 W/m^2
    in every lit direction (psi 10-120 deg here). 1 %."""
    r, w = 0.05, 5.0  # w >> r: exp(-r^2 sin^2/w^2) > 0.9999
    D = 2 * w
    P = 1e4 * math.pi * D * D / 4
    L = 100.0
    beam = ref.Beam(P, D - L * 1e-3, 1e-3, [0.0, -L, 0.0], [0, 0, 0])
    assert beam.peak(L) == pytest.approx(1e4)
    dirs = [(math.radians(p), az, 2000.0) for p, az in ((10, 0.0), (45, 1.0), (90, 2.0), (120, 4.0))]
    target = dict(name="ball", shape="sphere", center=np.zeros(3), normal=[0, 0, 1.0], tangent=[1.0, 0, 0],
                  size=(2 * r,), material=ref.specular(0.9))
    pts = []
    for psi, az, m in dirs:
        d = math.cos(psi) * -beam.u + math.sin(psi) * (math.cos(az) * beam.e1 + math.sin(az) * beam.e2)
        pts.append(m * r * d)
    # observers 100 m from a 10 m wide beam: keep them out of it
    pts = [p for p in pts if ref.off_incident_beam(beam, p)]
    assert len(pts) >= 3
    res = hazard.analyze(_scene(beam, target, pts))
    _check_sphere(res.observers.peak_irradiance_w_m2, [5.625 / 100.0**2] * len(pts))


SPHERE_ARGS = dict(
    r=ref.log_uniform(0.02, 0.3), L=ref.log_uniform(20.0, 2000.0), w_over_r=ref.log_uniform(0.1, 5.0), q=st.floats(0.1, 0.9),
    mu=st.sampled_from([0.0, 1e-4, 2e-3]), rho=st.floats(0.3, 1.0),
    obs=st.lists(st.tuples(st.floats(math.radians(2), math.radians(120)), st.floats(0, 2 * math.pi),
                           ref.log_uniform(30.0, 5000.0)), min_size=1, max_size=6),
    rot=st.tuples(st.floats(-math.pi, math.pi), st.floats(-math.pi, math.pi), st.floats(-math.pi, math.pi)),
)


def _observed_off_beam(case, check, *args):
    """Build a case (its last two arguments: observers ``obs`` and scene rotation),
    keep only the observers off the incident beam, analyse and check against the
    reference."""
    *head, obs, rot = args
    beam, scene, want, pts = case(*head, obs, rot)
    keep = [i for i, p in enumerate(pts) if ref.off_incident_beam(beam, p)]
    assume(keep)
    if len(keep) < len(pts):
        beam, scene, want, pts = case(*head, [obs[i] for i in keep], rot)
    check(hazard.analyze(scene).observers.peak_irradiance_w_m2, want)


def _sphere_property(r, L, w_over_r, q, mu, rho, obs, rot):
    _observed_off_beam(_sphere_case, _check_sphere, r, L, w_over_r, q, mu, rho, obs, rot)


@HEAVY_TWIN
@given(**SPHERE_ARGS)
def test_sphere_far_field_property(**kw):
    """Random spheres (r 2-30 cm, beam w 0.1-5 r: spheres ten times the beam down to a
    fifth of it; 20 m - 2 km away, mu in {0, 1e-4, 2e-3}), observers 30-5000 r away, psi
    2-120 deg from back-reflection, any azimuth: the exact trace of I(psi) exp(-mu L1)
    exp(-mu L2)/D^2 (range-safety.md 4). 1 %, one-sided too."""
    _sphere_property(**kw)


@pytest.mark.slow
@ref.SLOW
@given(**SPHERE_ARGS)
def test_sphere_far_field_sweep(**kw):
    """Larger sweep of ``test_sphere_far_field_property``."""
    _sphere_property(**kw)


def test_sphere_exact_trace_tends_to_the_far_field_formula():
    """The exact sphere trace used above equals I(psi)/D^2 to O(r/D): relative difference
    below 1.2 r/D for D = 1e3-1e5 r, psi 5-120 deg (range-safety.md 4)."""
    rho, r, w, E0 = 0.9, 0.05, 0.05, 1e4
    for psi_deg in (5.0, 20.0, 60.0, 120.0):
        psi = math.radians(psi_deg)
        for m in (2e4, 2e5, 2e6):
            D = m * r
            e, _ = ref.sphere_mirror_exact(rho, r, 1e12, w, E0, (D * math.sin(psi), -D * math.cos(psi)))
            far = ref.sphere_intensity(rho, r, E0, w, psi) / D ** 2
            assert abs(e / far - 1) <= 1.2 / m


def test_fan_pupil_factor_bessel_closed_form():
    """The disk mean of exp(-y^2/W^2) over radius a is exp(-b) (I0(b) + I1(b)),
    b = a^2 / (2 W^2) (integrate over the disk's chords); the quadrature of
    ``_refs.fan_pupil_factor`` matches it to 1e-8."""
    from scipy.special import i0e, i1e

    for W in (1e-3, 3.5e-3, 1e-2, 1.0):
        b = 3.5e-3 ** 2 / (2 * W * W)
        assert ref.fan_pupil_factor(0.05, 1e12, W, (1e-9, -1.0), (0.0, -0.05)) == pytest.approx(i0e(b) + i1e(b), rel=1e-8)


# ------------------------------------------------------------------ cylinder


def _cylinder_case(r, R1, w_over_r, q, mu, rho, obs, rot):
    """Cylinder of radius r, axis normal to the beam, at the origin; laser R1 away. Its
    length is 40 beam diameters (the fan is thin). ``obs``: (psi signed, D/r) in the
    plane normal to the axis, psi from the back-reflection direction."""
    Q = ref.euler_rotation(*rot)
    D = 2 * w_over_r * r
    phi = q * D / R1
    a = (1 - q) * D
    beam = ref.Beam(100.0, a, phi, Q @ np.array([0.0, -R1, 0.0]), np.zeros(3), mu=mu)
    axis = Q @ np.array([0.0, 0.0, 1.0])
    side = Q @ np.array([1.0, 0.0, 0.0])
    back = -beam.u
    Rs = R1 + a / phi  # virtual source -> cylinder axis
    E0 = beam.peak(R1)
    pts, want = [], []
    for psi, m in obs:
        d = math.cos(psi) * back + math.sin(psi) * side
        Dobs = m * r
        O = Dobs * d
        o_xy = (float(O @ side), float(O @ beam.u))
        e, hit2 = ref.cylinder_fan_exact(rho, r, Rs, D / 2, E0, o_xy)
        e *= ref.fan_pupil_factor(r, Rs, D / 2, o_xy, hit2)  # the 7 mm mean across the fan's thickness
        hit = hit2[0] * side + hit2[1] * beam.u
        att = math.exp(-mu * (np.linalg.norm(hit - beam.pos) + np.linalg.norm(O - hit)))
        want.append(e * att if _in_beam_square(hit2, Rs, D) else math.nan)
        pts.append(O)
    target = dict(name="pipe", shape="cylinder", center=np.zeros(3), normal=axis, tangent=side,
                  size=(2 * r, 40 * D), material=ref.specular(rho))
    return beam, _scene(beam, target, pts), np.array(want), pts


def _check_cylinder(got, want):
    for g, e in zip(got, want):
        if _check_tail(g, e):
            continue
        assert g >= e * (1 - 0.01), f"engine {g:.6g} below the thin-fan reference {e:.6g} by more than 1 %"
        assert g == pytest.approx(e, rel=0.01)


def test_cylinder_fan_spec_example_scaled():
    """range-safety.md 4 cylinder test: rho = 0.9, E = 1e4 W/m^2, r = 0.05 m, psi = 0 gives
    22.5 W/m^2 at D = 10 m. Here the same cylinder in a nearly collimated beam (w = 10 cm,
    phi = 10 urad, R1 = 50 m) with observers at psi = 10, 30, 60, -90 deg and D = 10 m:
    E = rho E(h) r cos(psi/2)/(2D) (also checked against the exact fan trace, 1 %).
    1 %, one-sided."""
    r, R1 = 0.05, 50.0
    w = 0.1
    D = 2 * w
    phi = 1e-5
    a = D - R1 * phi
    P = 1e4 * math.pi * D * D / 4
    beam = ref.Beam(P, a, phi, [0.0, -R1, 0.0], [0, 0, 0])
    assert beam.peak(R1) == pytest.approx(1e4)
    assert ref.cylinder_fan_irradiance(0.9, 1e4, r, 0.0, 10.0) == pytest.approx(22.5)
    Rs = R1 + a / phi
    pts, want = [], []
    for psi_deg in (10.0, 30.0, 60.0, -90.0):
        psi = math.radians(psi_deg)
        d = np.array([math.sin(psi), -math.cos(psi), 0.0])
        pts.append(10.0 * d)
        h = r * math.sin(abs(psi) / 2)
        far = ref.cylinder_fan_irradiance(0.9, 1e4 * math.exp(-h * h / w**2), r, abs(psi), 10.0) * Rs / (Rs + 10.0)
        exact = ref.cylinder_fan_exact(0.9, r, Rs, w, 1e4, (pts[-1][0], pts[-1][1]))[0]
        assert exact == pytest.approx(far, rel=0.01)
        want.append(far)
    assert all(ref.off_incident_beam(beam, p) for p in pts)
    target = dict(name="pipe", shape="cylinder", center=np.zeros(3), normal=[0, 0, 1.0], tangent=[1.0, 0, 0],
                  size=(2 * r, 40 * D), material=ref.specular(0.9))
    res = hazard.analyze(_scene(beam, target, pts))
    _check_cylinder(res.observers.peak_irradiance_w_m2, want)


CYL_ARGS = dict(
    r=ref.log_uniform(0.05, 0.5), R1=ref.log_uniform(20.0, 2000.0), w_over_r=ref.log_uniform(0.1, 2.0), q=st.floats(0.1, 0.9),
    mu=st.sampled_from([0.0, 1e-4, 2e-3]), rho=st.floats(0.3, 1.0),
    obs=st.lists(st.tuples(st.floats(math.radians(5), math.radians(120)).flatmap(
        lambda p: st.sampled_from([p, -p])), ref.log_uniform(50.0, 400.0)), min_size=1, max_size=5),
    rot=st.tuples(st.floats(-math.pi, math.pi), st.floats(-math.pi, math.pi), st.floats(-math.pi, math.pi)),
)


def _cylinder_property(r, R1, w_over_r, q, mu, rho, obs, rot):
    assume(R1 > 40 * r)
    _observed_off_beam(_cylinder_case, _check_cylinder, r, R1, w_over_r, q, mu, rho, obs, rot)


@HEAVY_TWIN
@given(**CYL_ARGS)
def test_cylinder_fan_property(**kw):
    """Random cylinders (r 5-50 cm, beam w 0.1-2 r: radius up to ten beam radii; length 40
    beam diameters, 20 m - 2 km,
    mu in {0, 1e-4, 2e-3}), observers in the fan plane at psi 5-120 deg either side and
    50-400 r away: rho E(h) r cos(psi/2)/(2D) traced without the far-field step, x
    attenuation per leg (range-safety.md 4). 1 %, one-sided."""
    _cylinder_property(**kw)


@pytest.mark.slow
@ref.SLOW
@given(**CYL_ARGS)
def test_cylinder_fan_sweep(**kw):
    """Larger sweep of ``test_cylinder_fan_property``."""
    _cylinder_property(**kw)
