"""Reflected-beam physics on geometry the bundled scenes do not have (issue: never "safe"
by approximation). References from the formulas (spec range-safety.md sections 1, 4)."""

from __future__ import annotations

import math

import numpy as np
import pytest

import hazard
import scenes

PLATE = """
name = "p"
[laser]
wavelength_nm = 1064.0
power_w = {power}
beam_diameter_m = {a}
divergence_rad = {phi}
position_m = [0.0, -{r1}, 0.0]
aim_m = [0.0, 0.0, 0.0]
[exposure]
duration_s = {t}
[atmosphere]
attenuation_per_m = {mu}
[[targets]]
name = "plate"
shape = "plate"
center_m = [{x}, 0.0, 0.0]
normal = [0.0, {ny}, 0.0]
tangent = [1.0, 0.0, 0.0]
size_m = [{w}, 1.0]
material = {material}
{extra}
{obs}
"""


def _scene(power=1000.0, a=0.02, phi=0.001, r1=100.0, t=10.0, mu=0.0, x=0.0, ny=-1.0, w=1.0,
           material='{ model = "lambertian", reflectance = 0.5 }', extra="", obs=()):
    o = "".join(f'[[observers]]\nname = "o{i}"\npoints_m = [{[float(v) for v in p]}]\n' for i, p in enumerate(obs))
    return scenes.loads(PLATE.format(power=power, a=a, phi=phi, r1=r1, t=t, mu=mu, x=x, ny=ny, w=w, material=material, extra=extra, obs=o))


def test_cut_beam_heats_at_the_local_peak():
    """A plate edge through the beam axis: half the power, but the hottest point still sees
    the full beam's peak 4 P exp(-mu R) / (pi D^2) (the old drive 4 P_spot / (pi D^2) was
    half of it, and a corner cut 2.7x low)."""
    power, a, phi, r1, mu = 1000.0, 0.02, 0.001, 100.0, 1e-3
    res = hazard.analyze(_scene(power, a, phi, r1, mu=mu, x=0.5, w=1.0))  # plate spans x in [0, 1]
    d = a + r1 * phi
    tr = res.targets[0]
    assert tr.spot_power_w == pytest.approx(0.5 * power * math.exp(-mu * r1), rel=1e-6)  # off-axis rays run slightly longer
    assert tr.peak_irradiance_w_m2 == pytest.approx(4 * power * math.exp(-mu * r1) / (math.pi * d * d), rel=1e-6)
    assert tr.mean_irradiance_w_m2 < tr.peak_irradiance_w_m2


def test_back_face_without_material_reflects_nothing_and_says_so():
    res = hazard.analyze(_scene(ny=1.0, obs=[(5.0, 10.0, 0.0), (5.0, -10.0, 0.0)]))
    assert np.all(res.observers.peak_irradiance_w_m2 == 0)
    assert any("back" in n for n in res.notes) and "back" in res.stage("beam").detail
    (tr,) = res.targets  # the target keeps its row in the report
    assert tr.name == "plate" and "back" in tr.lit_side and tr.spot_power_w == pytest.approx(1000.0, rel=1e-9)


def test_back_face_material_reflects_from_the_lit_side():
    """Lambertian back (rho 0.3): E = rho/pi cos(theta_r) P / R^2 on the laser's side."""
    r = 20.0
    th = math.radians(30)
    obs = [(r * math.sin(th), -r * math.cos(th), 0.0)]
    res = hazard.analyze(_scene(ny=1.0, extra='back = { model = "lambertian", reflectance = 0.3 }', obs=obs))
    assert res.targets[0].lit_side == "back"
    assert res.observers.peak_irradiance_w_m2[0] == pytest.approx(0.3 / math.pi * math.cos(th) * 1000.0 / r**2, rel=1e-6)


def test_mirror_attenuated_once_per_leg():
    """On the mirror axis at R2: rho 4P exp(-mu (R1 + R2)) / (pi D(R1 + R2)^2), averaged over the aperture
    (the old engine took exp(-mu R1) twice: -33 % at mu 2e-3 over 200 m)."""
    power, a, phi, r1, r2, mu = 100.0, 0.01, 0.0005, 200.0, 50.0, 2e-3
    # plate tilted 45 deg about z: the mirror axis leaves along +x
    text = PLATE.format(power=power, a=a, phi=phi, r1=r1, t=0.25, mu=mu, x=0.0, ny=-1.0, w=1.0,
                        material='{ model = "specular", reflectance = 0.8 }', extra="",
                        obs=f'[[observers]]\nname = "axis"\npoints_m = [[{r2}, 0.0, 0.0]]\n')
    text = text.replace("normal = [0.0, -1.0, 0.0]", "normal = [0.7071067811865476, -0.7071067811865476, 0.0]")
    text = text.replace("tangent = [1.0, 0.0, 0.0]", "tangent = [0.7071067811865476, 0.7071067811865476, 0.0]")
    res = hazard.analyze(scenes.loads(text))
    d = a + (r1 + r2) * phi
    # through the 7 mm limiting aperture on the axis (range-safety.md 10): the power in the
    # centred disk, P (1 - exp(-r^2 / w^2)), over its area (1.3e-3 below the peak here)
    w, r = d / 2, 3.5e-3
    ref = 0.8 * power * -math.expm1(-(r / w) ** 2) * math.exp(-mu * (r1 + r2)) / (math.pi * r * r)
    assert res.observers.peak_irradiance_w_m2[0] == pytest.approx(ref, rel=1e-6)


@pytest.mark.parametrize("psi_deg", [0.0, 1e-6, 45.0, 179.0, 179.999])
def test_sphere_finite_at_retro_and_forward_directions(psi_deg):
    """Retro (psi 0) and grazing (psi -> 180) directions: finite, non-negative, and the
    far-field value rho E r^2 / 4 / D^2 where it is lit."""
    text = PLATE.replace('shape = "plate"', 'shape = "sphere"').replace("size_m = [{w}, 1.0]", "size_m = [0.2]")
    D = 50.0
    psi = math.radians(psi_deg)
    obs = f'[[observers]]\nname = "o"\npoints_m = [[{D * math.sin(psi)}, {-D * math.cos(psi)}, 0.0]]\n'
    res = hazard.analyze(scenes.loads(text.format(power=1000.0, a=1.0, phi=0.0, r1=30.0, t=1.0, mu=0.0, x=0.0, ny=-1.0, w=1.0,
                                                  material='{ model = "specular", reflectance = 0.9 }', extra="", obs=obs)))
    e = res.observers.reflected_irradiance_w_m2[0]  # grazing forward, the eye also stands in the beam's spill
    assert np.isfinite(e) and e >= 0
    w = 0.5
    e0 = 1000.0 / (math.pi * w * w)
    ref = 0.9 * 0.01 / 4 * e0 * math.exp(-0.01 * math.sin(psi / 2) ** 2 / w**2) / D**2
    if psi_deg < 179.0:
        assert e == pytest.approx(ref, rel=5e-3)
    else:
        assert e <= 1.01 * ref  # forward grazing: the sphere's limb, at most the far-field value
