"""Sphere and cylinder mirror beams averaged over the limiting aperture (issue 29 item 1
for curved mirrors), against a reference written here from the formulas alone.

The standards compare the MPE with the power through the limiting aperture (7 mm at
400-1400 nm; an optical aid collects over min(D_o, 7 mm M) and delivers it, times its
transmission, into the 7 mm pupil: range-safety.md section 10). Reference: the exact
geometric-optics field of a mirror sphere centred on the beam
(``_refs.sphere_mirror_exact``: the exact reflecting ray, its spacing at the point and
the ring spreading about the axis, range-safety.md 4) integrated over the disk normal to
the reflected ray by a polar Gauss-Legendre x trapezoid rule coded here, converged (two
orders agree to 1e-7). The engine must never be below it and at most 1 % above.
Observers stand near a large sphere lit by a narrow beam, at the edge of the reflected
beam, where the point value and the average differ (by x1.1 to x3 here).
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

PUPIL_R = 3.5e-3


def _disk_mean(fn, centre_xy, ray_xy, radius, n_r=24, n_t=48):
    """Mean of fn(X, Y) (arrays: X the distance from the beam axis, Y along it) over the
    disk of ``radius`` centred at the in-plane point ``centre_xy``, normal to the in-plane
    unit ray ``ray_xy`` (the disk spans the in-plane normal and the out-of-plane axis):
    polar Gauss-Legendre in the radius x trapezoid in the angle."""
    x, wx = np.polynomial.legendre.leggauss(n_r)
    rho = 0.5 * (x + 1.0)
    th = 2 * math.pi * (np.arange(n_t) + 0.5) / n_t
    t = np.array([ray_xy[1], -ray_xy[0]])
    rr, tt = np.meshgrid(rho, th, indexing="ij")
    dt, dz = radius * rr * np.cos(tt), radius * rr * np.sin(tt)
    px, py = centre_xy[0] + dt * t[0], centre_xy[1] + dt * t[1]
    vals = fn(np.hypot(px, dz).ravel(), py.ravel()).reshape(rr.shape)
    return float(((wx * rho)[:, None] * vals).sum() / n_t)


def _converged_mean(fn, centre_xy, ray_xy, radius):
    lo = _disk_mean(fn, centre_xy, ray_xy, radius, 16, 32)
    hi = _disk_mean(fn, centre_xy, ray_xy, radius, 24, 48)
    assert abs(hi - lo) <= 1e-7 * abs(hi) + 1e-300, "reference quadrature not converged"
    return hi


def _case(r, L, w, q, rho, dist, edge, optics=None):
    """A mirror sphere of radius r at the origin, a beam of 1/e radius w at it (fraction q
    of its diameter from divergence) from L away along +y; an observer ``dist`` in front
    of the sphere, ``edge`` x the reflected beam's local 1/e radius off the axis."""
    D = 2 * w
    phi = q * D / L
    a = (1 - q) * D
    beam = ref.Beam(100.0, a, phi, [0.0, -L, 0.0], [0.0, 0.0, 0.0])
    Rs = L + a / phi
    E0 = beam.peak(L)
    y_obs = -(r + dist)
    w_refl = w * (1 + 2 * dist / r + dist / Rs)  # the reflected beam's 1/e radius near the axis (paraxial)
    x_obs = edge * w_refl
    fn = lambda X, Y: ref.sphere_mirror_exact(rho, r, Rs, w, E0, (X, Y))[0]  # arrays in, arrays out
    point, p = ref.sphere_mirror_exact(rho, r, Rs, w, E0, (x_obs, y_obs))
    ray = ref.unit(np.array([x_obs, y_obs]) - p)
    want = _converged_mean(fn, (x_obs, y_obs), ray, PUPIL_R)
    if optics:
        coll = min(optics["objective_diameter_m"], 2 * PUPIL_R * optics["magnification"]) / 2
        aid = optics.get("transmission", 1.0) * _converged_mean(fn, (x_obs, y_obs), ray, coll) * (coll / PUPIL_R) ** 2
        want = max(want, aid)
    target = dict(name="ball", shape="sphere", center=np.zeros(3), normal=[0.0, 0.0, 1.0], tangent=[1.0, 0.0, 0.0],
                  size=(2 * r,), material=ref.specular(rho))
    text = ref.scene_text(power=beam.P, a=a, phi=phi, position=beam.pos, aim=np.zeros(3), targets=[target],
                          observers=[("o", np.array([x_obs, y_obs, 0.0]), optics)])
    return text, point, want


def _check(text, want, over=0.01):
    res = hazard.analyze(scenes.loads(text))
    got = float(res.observers.specular_irradiance_w_m2[0])
    assert got >= want * (1 - 1e-9), f"engine {got:.6g} below the aperture average {want:.6g}"
    assert got <= want * (1 + over), f"engine {got:.6g} above the aperture average {want:.6g} by more than {over:.1%}"
    return got


@pytest.mark.parametrize("edge", [0.5, 1.5, 2.5])
def test_sphere_mirror_beam_through_the_pupil(edge):
    """A 1 m mirror sphere 100 m from the laser, beam w = 4 mm at it; naked eye 0.3 m in
    front of it, at 0.5, 1.5 and 2.5 of the reflected beam's 1/e radii off its axis: the
    7 mm disk mean of the exact field (before: the point value, x0.4 at 2.5 radii)."""
    text, point, want = _case(1.0, 100.0, 4e-3, 0.5, 0.9, 0.3, edge)
    if edge >= 2.5:
        assert want > 1.5 * point  # the point value would be a wrong "safe"
    _check(text, want)


def test_sphere_mirror_beam_binoculars():
    """The same sphere seen through 7x50 binoculars (transmission 0.9) at 2 radii off the
    reflected beam's axis: tau x the power over the 24.5 mm objective into the 7 mm pupil
    (x170 the point value). The objective is 8 % of the distance wide: the local Gaussian
    is 1.06 % low on its rim, and the engine raises the whole mean by that (1.05 % high
    here); 1.5 % allowed above."""
    optics = {"magnification": 7.0, "objective_diameter_m": 0.05, "transmission": 0.9}
    text, point, want = _case(1.0, 100.0, 4e-3, 0.5, 0.9, 0.3, 2.0, optics)
    assert want > 100 * point
    _check(text, want, over=0.015)


@ref.settings(ref.FAST, max_examples=8)
@given(r=ref.log_uniform(0.2, 3.0), L=ref.log_uniform(20.0, 1000.0), w=ref.log_uniform(1.5e-3, 2e-2), q=st.floats(0.1, 0.9),
       dist=ref.log_uniform(0.05, 3.0), edge=st.floats(0.3, 3.0))
def test_sphere_mirror_aperture_property(r, L, w, q, dist, edge):
    """Random large spheres (r 0.2-3 m), narrow beams (w 1.5-20 mm), naked eyes 5 cm - 3 m
    in front at up to 3 reflected radii off the axis: never below the exact disk mean,
    at most 1 % above it."""
    text, _, want = _case(r, L, w, q, 0.9, dist, edge)
    _check(text, want)
