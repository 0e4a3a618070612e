"""The laser's own beam at observers, against the Gaussian beam written from the formulas
(range-safety.md section 2; laser-safety.md 3.1), not from the engine:

- on the axis at range R: E = 4 P exp(-mu R) / (pi (a + R phi)^2);
- off the axis by r (perpendicular to the axis at axial range R): times exp(-r^2 / w^2),
  w = (a + R phi) / 2 the 1/e radius (the ray tilt adds a factor 1 + O(phi^2 r^2 / w^2),
  below 1e-9 here);
- the point value at the eye (``direct_point_irradiance_w_m2``) is that Gaussian; the
  verdict's value (``direct_irradiance_w_m2``) is the power through the 7 mm limiting
  aperture, and through optics the power an aid collects over min(D_o, 7 mm M) into the
  7 mm pupil (range-safety.md section 10; ``_refs.aperture_irradiance``, ncx2);
- nothing where a target or occluder stands between the aperture and the eye; the part
  of the beam that misses a small target (the spill) goes on.
The total irradiance is the direct plus the reflected part. Tolerance 1e-6 (the
references are exact).
"""

from __future__ import annotations

import io
import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

import hazard
import scenes
from hazard.cli import main

from . import _refs as ref

P, A, PHI = 5000.0, 0.02, 1e-3  # W, m, rad
R_T = 800.0  # laser -> target [m]; the beam runs along +y from (0, -R_T, 0)


def _e_axis(R, mu=0.0):
    D = A + R * PHI
    return 4 * P * math.exp(-mu * R) / (math.pi * D * D)


def _gain(M, D0, tau, R):
    Db = A + R * PHI
    return min(max(tau * M * M, 1.0), max(tau * (D0 / 7e-3) ** 2, 1.0), max(tau * (Db / 7e-3) ** 2, 1.0))


def _scene(observers, *, mu=0.0, plate=0.5, occluder=None):
    target = dict(name="plate", shape="plate", center=np.zeros(3), normal=np.array([0.0, -1.0, 0.0]),
                  tangent=np.array([1.0, 0.0, 0.0]), size=(plate, plate), material=ref.lambertian(0.5))
    text = ref.scene_text(power=P, a=A, phi=PHI, position=np.array([0.0, -R_T, 0.0]), aim=np.zeros(3), targets=[target],
                          observers=observers, mu=mu)
    if occluder is not None:
        c, size = occluder
        text += f"[[occluders]]\nshape = \"box\"\ncenter_m = {ref.vec(c)}\nsize_m = {ref.vec(size)}\n"
    return scenes.loads(text)


def _at(R, x=0.0, z=0.0):
    """A point at axial range R from the laser, offset (x, z) across the beam."""
    return np.array([x, R - R_T, z])


def test_on_axis_off_axis_and_through_binoculars():
    """Observers standing in the beam 300 m from the laser (on the axis, 1 w and 2 w off it,
    one with 7x50 binoculars): the direct beam, and it is what makes them hazardous."""
    R, w = 300.0, (A + 300.0 * PHI) / 2
    optics = dict(magnification=7.0, objective_diameter_m=0.05, transmission=0.9)
    obs = [("axis", _at(R), None), ("one-w", _at(R, x=w), None), ("two-w", _at(R, x=w * 0.6, z=-w * 0.8 * 2), None),
           ("bino", _at(R, x=w), optics)]
    res = hazard.analyze(_scene(obs))
    r2 = [0.0, w * w, (0.6 * w) ** 2 + (1.6 * w) ** 2, w * w]
    want = [_e_axis(R) * math.exp(-q / w**2) for q in r2]
    np.testing.assert_allclose(res.observers.direct_point_irradiance_w_m2, want, rtol=1e-6)
    got = res.observers.direct_irradiance_w_m2
    through = [ref.aperture_irradiance(P, w, math.sqrt(q), o) for q, o in zip(r2, [None] * 3 + [optics])]
    np.testing.assert_allclose(got, through, rtol=1e-6)
    # a beam much wider than the aid's disk: the usual gain (to (24.5 mm / w)^2 = 2.3e-2)
    assert got[3] == pytest.approx(want[3] * _gain(7.0, 0.05, 0.9, R), rel=0.03)
    np.testing.assert_allclose(res.observers.aperture_diameter_m, [7e-3] * 3 + [0.049], rtol=1e-12)
    # the total is direct + reflected, and the verdict uses it
    np.testing.assert_allclose(res.observers.peak_irradiance_w_m2, got + res.observers.reflected_irradiance_w_m2, rtol=1e-12)
    assert res.hazardous[0] and res.stage("direct").ran


@pytest.mark.parametrize("mu", [1e-4, 2e-3])
def test_attenuation_once_along_the_path(mu):
    R = 500.0
    res = hazard.analyze(_scene([("axis", _at(R), None)], mu=mu))
    assert res.observers.direct_point_irradiance_w_m2[0] == pytest.approx(_e_axis(R, mu), rel=1e-6)


def test_target_shadow_spill_and_occluder():
    """Beyond the target: in its shadow nothing, beside it (the spill of a 0.5 m plate in a
    1.7 m beam) the beam at that range; behind a box on the way: nothing."""
    R = R_T + 200.0
    w = (A + R * PHI) / 2
    box = (np.array([3.0, -500.0, 0.0]), (1.0, 1.0, 1.0))  # at 300 m from the laser, 3 m off the axis
    obs = [("shadow", _at(R), None), ("spill", _at(R, x=0.8 * w), None), ("behind-box", _at(600.0, x=3.0 * 600 / 300), None)]
    res = hazard.analyze(_scene(obs, occluder=box))
    got = res.observers.direct_point_irradiance_w_m2
    assert got[0] == 0.0 and got[2] == 0.0
    assert got[1] == pytest.approx(_e_axis(R) * math.exp(-0.64), rel=1e-6)


def test_observer_in_the_beam_is_a_hazard_on_the_command_line(tmp_path):
    """An observer 500 m in front of the target, in the beam: `--fail-on-hazard` exits 3
    (it exited 0: the direct beam was left out)."""
    path = tmp_path / "in_beam.toml"
    text = ref.scene_text(power=P, a=A, phi=PHI, position=np.array([0.0, -R_T, 0.0]), aim=np.zeros(3),
                          targets=[dict(name="plate", shape="plate", center=np.zeros(3), normal=np.array([0.0, -1.0, 0.0]),
                                        tangent=np.array([1.0, 0.0, 0.0]), size=(0.5, 0.5), material=ref.lambertian(0.5))],
                          observers=[("in-beam", _at(300.0), None)])
    path.write_text(text)
    out = io.StringIO()
    code = main(["run", str(path), "-o", str(tmp_path / "o"), "--fail-on-hazard", "--quiet"], stdout=out, stderr=io.StringIO())
    assert code == 3 and "in-beam" in out.getvalue()


DIRECT_ARGS = dict(R=st.floats(5.0, 3000.0), x=st.floats(-3.0, 3.0), z=st.floats(-3.0, 3.0), mu=st.sampled_from([0.0, 1e-4, 2e-3]))


@ref.FAST_TWIN  # 25 examples took 5.5 s CPU of the default run (10: 2 s); the slow twin below sweeps 120
@given(**DIRECT_ARGS)
def test_direct_beam_property(R, x, z, mu):
    """Random observers in front of and beyond the target, on and off the beam: the
    Gaussian at their range where the plate does not shadow them, else 0."""
    w = (A + R * PHI) / 2
    p = _at(R, x=x * w, z=z * w)
    res = hazard.analyze(_scene([("o", p, None)], mu=mu))
    # rays leave a virtual point source a / phi behind the aperture: the plate's shadow
    # at range R is the plate scaled by (R + a/phi) / (R_T + a/phi)
    k = (R_T + A / PHI) / (R + A / PHI)
    behind_plate = R > R_T and abs(x * w) * k < 0.25 and abs(z * w) * k < 0.25
    want = 0.0 if behind_plate else _e_axis(R, mu) * math.exp(-(x * x + z * z))
    got = res.observers.direct_point_irradiance_w_m2[0]
    # the one convention between the engine and this reference: the path along the ray
    # is longer than the axial range by about r^2 / (2R)
    path_excess = mu * ((x * x + z * z) * w * w) / (2 * R)
    assert got == pytest.approx(want, rel=1e-6 + path_excess, abs=1e-9 * _e_axis(R, mu))


@pytest.mark.slow
@ref.SLOW
@given(**DIRECT_ARGS)
def test_direct_beam_property_sweep(R, x, z, mu):
    test_direct_beam_property.hypothesis.inner_test(R, x, z, mu)


@pytest.mark.parametrize("half", [0.2, 0.5, 0.9])
def test_spill_nohd_from_the_nearest_unshadowed_point(half):
    """A square plate of half-width h centred in the beam at R_T = 800 m (w = 0.41 m):
    the spill passes beside its edges, where the beam profile is at most exp(-h^2 / w^2)
    (the edge midpoints); the direct beam along the spill then reaches the MPE at
    4 P exp(-h^2/w^2) / (pi (a + R phi)^2) = MPE, R = (sqrt(4 P q / (pi MPE)) - a) / phi
    (no attenuation; range-safety.md 2). The spill's power leaving the scene is P
    minus the erf rectangle. Never below the reference, and within 1 % (the profile's
    point search is a lattice on the cell edges, lowered by its spacing: an upper
    bound)."""
    res = hazard.analyze(_scene([("o", _at(100.0, x=50.0), None)], plate=2 * half))
    sp = res.spill
    w_t = (A + R_T * PHI) / 2
    q = math.exp(-(half / w_t) ** 2)
    assert q <= sp.peak_profile <= q * 1.01
    mpe = res.mpe_w_m2
    want = (math.sqrt(4 * P * q / (math.pi * mpe)) - A) / PHI
    assert want * (1 - 1e-9) <= sp.nohd_m <= want * 1.01
    assert sp.leaves_scene_w == pytest.approx(P * (1 - ref.rect_fraction(-half, half, -half, half, w_t)), rel=1e-9)
    assert res.stage("spill").ran and sp.stopped == ()


def test_spill_stopped_by_an_occluder_is_reported_with_its_range():
    """A 2 m box 300 m down range, 0.3 m off the axis, takes part of the spill: report.json
    names it, with the power it stops (an erf integral of the unshadowed part it covers;
    here checked as a bound: between 0 and the whole spill) and its range (~299 m)."""
    box = (np.array([1.3, 300.0 - R_T, 0.0]), (2.0, 2.0, 2.0))
    res = hazard.analyze(_scene([("o", _at(100.0, x=50.0), None)], plate=0.5, occluder=box))
    (stop,) = res.spill.stopped
    assert stop.object == "occluders[0]" and 0 < stop.power_w < P
    assert stop.range_m == pytest.approx(299.0, abs=0.5)


def _road(start, end, count):
    return (f'[[observers]]\nname = "road"\nstart_m = {ref.vec(np.asarray(start, float))}\n'
            f'end_m = {ref.vec(np.asarray(end, float))}\ncount = {count}\n')


@pytest.mark.parametrize("offset", [0.0, 3.7, -6.2])
def test_a_road_sampled_every_10_m_finds_the_beam_between_its_points(offset):
    """A 2.7 cm beam crosses a road 300 m from the laser, perpendicular, between two of its
    points 10 m apart (the nearest is `offset` + 5 m away): the crossing is added as a
    point of its own with the on-axis irradiance 4 P / (pi (a + R phi)^2) (1e-6) and it
    is hazardous; the road's own points see nothing (range-safety.md 2; issue 13 item 7)."""
    R = 300.0
    x0 = -500.0 + 5.0 + offset  # the road's points sit at x0 + 10 k: the axis (x = 0) falls between two
    text = ref.scene_text(power=P, a=A, phi=PHI, position=np.array([0.0, -R_T, 0.0]), aim=np.zeros(3),
                          targets=[dict(name="plate", shape="plate", center=np.zeros(3), normal=np.array([0.0, -1.0, 0.0]),
                                        tangent=np.array([1.0, 0.0, 0.0]), size=(0.5, 0.5), material=ref.lambertian(0.5))])
    text = text.replace("[analysis]", _road([x0, R - R_T, 0.0], [x0 + 1000.0, R - R_T, 0.0], 101) + "[analysis]")
    res = hazard.analyze(scenes.loads(text))
    obs = res.observers
    labels = obs.labels
    k = labels.index("road:crossing")
    assert obs.position_m[k][0] == pytest.approx(0.0, abs=1e-6)
    assert obs.direct_point_irradiance_w_m2[k] == pytest.approx(_e_axis(R), rel=1e-6)
    assert res.hazardous[k] and "direct beam" in res.stage("crossings").detail
    road = [i for i, n in enumerate(labels) if n.startswith("road[")]
    assert len(road) == 101 and np.all(obs.direct_irradiance_w_m2[road] < 1e-6 * _e_axis(R))


def test_a_mirror_beam_crossing_a_road_is_found():
    """A flat mirror at 45 deg sends the beam along -x; a road along y at x = -100 m with
    points every 10 m misses it. The crossing point: the image beam at folded range
    R_T + 100 m, on its axis: rho 4 P / (pi (a + R phi)^2) (image source; 1e-3)."""
    rho = 0.9
    n = np.array([-1.0, -1.0, 0.0]) / math.sqrt(2)
    target = dict(name="mirror", shape="plate", center=np.zeros(3), normal=n, tangent=np.array([1.0, -1.0, 0.0]) / math.sqrt(2),
                  size=(0.5, 0.5), material=ref.specular(rho))
    text = ref.scene_text(power=P, a=A, phi=PHI, position=np.array([0.0, -R_T, 0.0]), aim=np.zeros(3), targets=[target])
    text = text.replace("[analysis]", _road([-100.0, -503.0, 0.0], [-100.0, 497.0, 0.0], 101) + "[analysis]")
    res = hazard.analyze(scenes.loads(text))
    k = res.observers.labels.index("road:crossing")
    D = A + (R_T + 100.0) * PHI
    assert res.observers.position_m[k][1] == pytest.approx(0.0, abs=1e-3)
    assert res.observers.peak_irradiance_w_m2[k] == pytest.approx(rho * 4 * P / (math.pi * D * D), rel=1e-3)
    assert "the mirror beam of mirror crosses" in res.stage("crossings").detail


_BEAM_AT = dict(seed=st.integers(0, 2 ** 31 - 1), reach=st.sampled_from([0.0, 1e-3, 0.05, 2.0]), mu=st.sampled_from([0.0, 2e-3]))


@pytest.mark.slow
@ref.SLOW
@given(**_BEAM_AT)
def test_beam_at_rows_and_values_from_the_formula_many(seed, reach, mu):
    """The same over more random point sets."""
    test_beam_at_rows_and_values_from_the_formula.hypothesis.inner_test(seed, reach, mu)


@ref.FAST
@given(**_BEAM_AT)
def test_beam_at_rows_and_values_from_the_formula(seed, reach, mu):
    """``beam_at`` on random points out to 60 beam radii across (the far ones' point value
    underflows to exactly 0, and only rows within ``reach`` of where it does not are
    kept), behind the aperture and on its plane: the rows kept are those with a non-zero
    Gaussian or within reach, their values the Gaussian written here,
    ``P / (pi w^2) exp(-|s|^2) sqrt(1 + |s|^2 phi^2 / 4) exp(-mu path)``."""
    from hazard.physics.beam import BeamGeometry
    from hazard.pipeline.direct import beam_at

    rng = np.random.default_rng(seed)
    beam = BeamGeometry.create(np.array([0.0, -R_T, 0.0]), np.array([0.0, 1.0, 0.0]), P, A, PHI)
    n = 2000
    zr = np.concatenate([rng.uniform(-5.0, 3000.0, n - 10), np.zeros(10)])  # some on the aperture plane
    w = (A + np.maximum(zr, 0.0) * PHI) / 2
    ang, rad = rng.uniform(0, 2 * math.pi, n), w * rng.uniform(0.0, 60.0, n) ** rng.uniform(0.5, 1.0, n)
    pts = np.stack([rad * np.cos(ang), zr - R_T, rad * np.sin(ang)], axis=1)
    at = beam_at(beam, pts, mu, reach)
    s = rad / w
    e = P / (math.pi * w * w) * np.exp(-s * s) * np.sqrt(1.0 + s * s * (PHI / 2) ** 2)
    want = np.flatnonzero((zr >= 0) & ((e > 0) | ((s - reach / w < 27.3) if reach > 0 else False)))
    assert np.array_equal(at.rows, want)
    origin = beam.position_m + (pts[want] - beam.position_m - np.outer(zr[want], beam.axis)) * (A / 2) / w[want, None]
    path = np.linalg.norm(pts[want] - origin, axis=1)
    np.testing.assert_allclose(at.irradiance_w_m2, e[want] * np.exp(-mu * path), rtol=1e-9, atol=0)
