"""A curved spot's far field in every direction: a Lambertian sphere in a beam much wider than
it, seen from far away (beyond the engine's 20 spot sizes) at phase angle g from the
backscatter direction, against the Lambert sphere's radiant intensity (written here from
the formula, not from the engine):

    I(g) = 2 rho P / (3 pi^2) [sin g + (pi - g) cos g],   P = P_beam (1 - exp(-r^2 / w^2))

(the power the sphere intercepts from the Gaussian of 1/e radius w; the integral of
``rho / pi cos(i) cos(e) dA`` over the lit and seen part of the sphere in a uniform beam).
E = I / R^2 at range R from the sphere.

Before 2026-11-27 the engine took a spot's far field from its mean frame alone (``rho / pi
cos`` from the mean normal, which points back at the laser): 0.63 of I at g = 80 deg and
**0** at 90 deg and beyond, where the sphere's limb and far side still send light (I(90) =
0.32 I(0)); observers there were reported safe. Now the larger of the mean frame's form and
the sum over the spot's own frames (``engine.point_form``): never below the old value, and
at or above I here at 80-120 deg. Still short (strict xfails with the figures): the sum
rests on the spot's few samples (15 on a 5 cm sphere in a 2 m beam), so it depends on how
their frames fall (0.857 of I at 92.7 deg in a turned scene) and leaves the crescent
(g >= 150 deg) short.
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

RHO = 0.8


def _sphere_far_field(power_w, a_m, r_m, range_m, g_deg, spin_deg, rot):
    """Engine and reference irradiance [W/m^2] at an observer ``range_m`` from a sphere of
    radius ``r_m`` on the axis of a collimated beam (1/e diameter ``a_m``) 100 m from the
    laser, at phase angle ``g_deg`` (turned ``spin_deg`` about the beam), the scene
    rotated by ``rot``."""
    Q = ref.euler_rotation(*rot)
    u = np.array([0.0, 1.0, 0.0])
    g, s = math.radians(g_deg), math.radians(spin_deg)
    side = np.array([math.cos(s), 0.0, math.sin(s)])
    obs = range_m * (math.cos(g) * -u + math.sin(g) * side)
    t = dict(name="ball", shape="sphere", center=np.zeros(3), normal=Q @ [0.0, 0.0, 1.0], tangent=Q @ [1.0, 0.0, 0.0],
             size=(2 * r_m,), material=ref.lambertian(RHO))
    text = ref.scene_text(power=power_w, a=a_m, phi=0.0, position=Q @ (-100.0 * u), aim=np.zeros(3), targets=[t],
                          observers=[("eye", Q @ obs, None)])
    res = hazard.analyze(scenes.loads(text))
    w = a_m / 2
    p_int = power_w * (1 - math.exp(-r_m * r_m / (w * w)))
    intensity = 2 * RHO * p_int / (3 * math.pi ** 2) * (math.sin(g) + (math.pi - g) * math.cos(g))
    return float(res.observers.peak_irradiance_w_m2[0]), intensity / range_m ** 2


@pytest.mark.slow
@pytest.mark.xfail(strict=True, reason="open (2026-11-27): the sum over a curved spot's few sample frames depends on how "
                   "they fall: g = 92.71 deg, spin 126.3 deg, r = 4.76 cm, scene rotated by (-1.2012, -2.0516, -3.1007): "
                   "engine 3.888e-5 W/m^2, the Lambert sphere's 4.538e-5 (0.857); the mean frame alone gave 0")
@ref.settings(ref.FAST, max_examples=3)
@given(g=st.floats(20.0, 120.0), spin=st.floats(-180.0, 180.0), r=ref.log_uniform(0.01, 0.05),
       rot=st.tuples(st.floats(-math.pi, math.pi), st.floats(-math.pi, math.pi), st.floats(-math.pi, math.pi)))
def test_sphere_far_field_never_below_the_lambert_sphere(g, spin, r, rot):
    """Phase angles 20-120 deg, any side, spheres 2-10 cm across in a 2 m beam, the scene
    turned: the engine's far-field irradiance is never below the Lambert sphere's (less
    the reference's own 0.3 %: the beam's Gaussian over the sphere, (r / w)^2, and the
    spot centroid's offset from the centre over the range)."""
    got, want = _sphere_far_field(1000.0, 2.0, r, 50.0, g, spin, rot)
    assert got >= want * (1 - 3e-3), f"g = {g:.4g} deg: engine {got:.6g} W/m^2 below the Lambert sphere's {want:.6g}"


@pytest.mark.parametrize("g", [pytest.param(80.0, marks=pytest.mark.slow), 90.0, pytest.param(100.0, marks=pytest.mark.slow), 120.0])
def test_sphere_far_field_beside_and_behind(g):
    """Beside the sphere and behind its mean plane (0 before), never below the formula."""
    got, want = _sphere_far_field(1000.0, 2.0, 0.025, 50.0, g, 40.0, (0.0, 0.0, 0.0))
    assert got >= want * (1 - 3e-3), f"g = {g:g} deg: engine {got:.6g} W/m^2 below the Lambert sphere's {want:.6g}"


@pytest.mark.slow
@pytest.mark.xfail(strict=True, reason="open (2026-11-27): the crescent phases of a curved spot with few samples - a 5 cm "
                   "sphere in a 2 m beam has 15 samples: at g = 150 deg the engine gives 0.67 of the Lambert sphere's "
                   "irradiance, at 170 deg ~0 (its samples' frames all face away); I(150) = 0.015 I(0), I(170) = 5.6e-4 I(0)")
@pytest.mark.parametrize("g", [150.0, 170.0])
def test_sphere_far_field_crescent(g):
    got, want = _sphere_far_field(1000.0, 2.0, 0.025, 50.0, g, 40.0, (0.0, 0.0, 0.0))
    assert got >= want * (1 - 3e-3), f"g = {g:g} deg: engine {got:.6g} W/m^2 below the Lambert sphere's {want:.6g}"


def test_a_report_names_its_curved_spots():
    """A run with a sphere in the beam says what its curved spot's results rest on (the
    frames' sum, the zone's hemisphere); a plate's spot is not named (traced only)."""
    from hazard.pipeline import lobes
    from hazard.pipeline.spots import ray_scene, trace_beam

    t = dict(name="ball", shape="sphere", center=np.zeros(3), normal=[0.0, 0.0, 1.0], tangent=[1.0, 0.0, 0.0],
             size=(0.05,), material=ref.lambertian(RHO))
    text = ref.scene_text(power=1.0, a=0.1, phi=0.0, position=[0.0, -50.0, 0.0], aim=np.zeros(3), targets=[t])
    notes = [n for n in hazard.analyze(scenes.loads(text)).notes if n.startswith("curved spot(s): ball (")]
    assert len(notes) == 1 and "hemisphere above each spot's mean plane" in notes[0]
    plate = dict(t, name="plate", shape="plate", size=(0.5, 0.5), normal=[0.0, -1.0, 0.0])
    scene = scenes.loads(ref.scene_text(power=1.0, a=0.1, phi=0.0, position=[0.0, -50.0, 0.0], aim=np.zeros(3), targets=[plate]))
    assert lobes.curved_spot_notes(trace_beam(scene, ray_scene(scene, "embree", 1), 0.0).built.spots) == []
