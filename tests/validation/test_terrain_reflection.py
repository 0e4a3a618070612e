"""The beam that lands on the ground reflects from it (issue 13 item 2), against the
formulas (range-safety.md section 1; laser-safety.md 3.1), not the engine:

- the plate in the beam takes F = erf(h / w)^2 of it (a centred square of half-side h
  facing the laser, w = (a + R phi) / 2 the 1/e radius at its range R);
- the rest, P_g = P (1 - F) exp(-mu L_g), lands on flat ground around the axis point;
  on its way it peaks at the square's edge: 4 P / (pi D^2) exp(-h^2 / w^2) at the plate;
- a Lambertian ground of reflectance rho sends an observer at distance d, at angle
  theta_r from the ground's normal, E = rho P_g cos(theta_r) / (pi d^2) (a spot ~0.1 m
  across seen from >= 10 m: the point-source form is good to (0.1 / 10)^2 = 1e-4).
The engine's spot power is conservative by at most its beam_rtol (1e-3 of the beam): the
value must lie in [E, E (1 + 3e-3)].
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from scipy.special import erf

import hazard
import scenes

from . import _refs as ref

P, A, PHI = 2000.0, 0.05, 1e-3
O = np.array([0.0, -40.0, 30.0])  # the laser; the axis comes down to the ground at the origin
G = np.zeros(3)
C = 0.5 * (O + G)  # the plate halfway, facing the laser
HALF = 0.01  # plate half-side [m]


def _ground_power(mu=0.0):
    w = (A + np.linalg.norm(C - O) * PHI) / 2
    f = erf(HALF / w) ** 2
    return P * (1 - f) * math.exp(-mu * np.linalg.norm(G - O))


def _scene(points, rho=None, mu=0.0):
    d = (G - O) / np.linalg.norm(G - O)
    plate = dict(name="plate", shape="plate", center=C, normal=-d, tangent=np.array([1.0, 0.0, 0.0]), size=(2 * HALF, 2 * HALF),
                 material=ref.lambertian(0.5))
    obs = [(f"o{i}", p, None) for i, p in enumerate(points)]
    text = ref.scene_text(power=P, a=A, phi=PHI, position=O, aim=C, targets=[plate], observers=obs, mu=mu)
    terrain = '[terrain]\nkind = "flat"\nextent_m = 200.0\nresolution_m = 10.0\n'
    if rho is not None:
        terrain += f"material = {ref.lambertian(rho)}\n"
    return scenes.loads(text.replace("[analysis]", terrain + "[analysis]"))


def _lambert(p, rho, power, at=G, normal=(0.0, 0.0, 1.0)):
    """rho P cos(theta_r) / (pi d^2) of a small Lambertian spot at ``at`` (0 behind it)."""
    rel = np.asarray(p, float) - at
    d = np.linalg.norm(rel)
    return max(rho * power * (rel @ np.asarray(normal)) / d / (math.pi * d * d), 0.0)


def _plate_part(p, mu):
    """The plate's own diffuse reflection (Lambertian 0.5, facing the laser) where p sees
    its lit face: 0.5 F P exp(-mu R_c) cos / (pi d^2) exp(-mu d)."""
    w = (A + np.linalg.norm(C - O) * PHI) / 2
    power = P * erf(HALF / w) ** 2 * math.exp(-mu * np.linalg.norm(C - O))
    n = (O - G) / np.linalg.norm(O - G)
    return _lambert(p, 0.5, power, C, n) * math.exp(-mu * np.linalg.norm(p - C))


@pytest.mark.parametrize("rho", [None, 0.2])
def test_the_ground_reflects_the_spill_with_its_material_or_reflectance_1(rho):
    """Observers beyond the plate (they see its unlit back) get only the ground's
    reflection; without [terrain] material the ground is Lambertian with reflectance 1,
    and the report says so."""
    pts = [np.array([0.0, 30.0, 1.7]), np.array([20.0, 10.0, 5.0]), np.array([-15.0, 25.0, 10.0])]
    res = hazard.analyze(_scene(pts, rho))
    want = [_lambert(p, 1.0 if rho is None else rho, _ground_power()) for p in pts]
    got = res.observers.reflected_irradiance_w_m2
    assert np.all(got >= np.array(want) * (1 - 1e-9)) and np.all(got <= np.array(want) * (1 + 3e-3)), (got, want)
    (stop,) = res.spill.stopped
    assert stop.object == "terrain" and stop.power_w == pytest.approx(_ground_power(), rel=3e-3)
    assert ("Lambertian of reflectance 1" in stop.reflected) == (rho is None)
    # on its way from the plate to the ground the spill is the beam outside the square:
    # its highest point is on the square's edge, E = 4 P / (pi D^2) exp(-h^2 / w^2) at the plate's range
    r_c = float(np.linalg.norm(C - O))
    d = A + r_c * PHI
    peak = 4 * P / (math.pi * d * d) * math.exp(-(HALF / (d / 2)) ** 2)
    assert peak <= stop.peak_irradiance_w_m2 <= peak * (1 + 1e-4) and stop.hazard_ratio == pytest.approx(peak / res.mpe_w_m2, rel=1e-4)
    assert "terrain" in [t.name for t in res.targets]


GROUND_DRAW = dict(az=st.floats(-1.2, 1.2), el=st.floats(0.05, 1.4), dist=st.floats(10.0, 150.0), mu=st.sampled_from([0.0, 1e-3]))


@ref.FAST_TWIN
@given(**GROUND_DRAW)
def test_a_lambertian_ground_seen_from_anywhere_beyond_the_plate(az, el, dist, mu):
    """The default run of :func:`_lambertian_ground_case` (10 draws; the slow twin 120)."""
    _lambertian_ground_case(az, el, dist, mu)


@pytest.mark.slow
@ref.SLOW
@given(**GROUND_DRAW)
def test_a_lambertian_ground_sweep(az, el, dist, mu):
    _lambertian_ground_case(az, el, dist, mu)


def _lambertian_ground_case(az, el, dist, mu):
    """An observer at (azimuth from +y, elevation, distance) from the ground spot, on the
    side away from the laser: rho P_g cos(theta_r) / (pi d^2), attenuated on both legs,
    plus the plate's own reflection where the observer (high up) sees its lit face."""
    p = G + dist * np.array([math.sin(az) * math.cos(el), math.cos(az) * math.cos(el), math.sin(el)])
    res = hazard.analyze(_scene([p], 0.6, mu))
    want = _lambert(p, 0.6, _ground_power(mu)) * math.exp(-mu * dist) + _plate_part(p, mu)
    got = float(res.observers.reflected_irradiance_w_m2[0])
    assert want * (1 - 1e-9) <= got <= want * (1 + 3e-3)
