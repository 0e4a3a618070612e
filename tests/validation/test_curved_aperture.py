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
    in front (down to 0.017 r) at up to 3 reflected radii off the axis: never below the
    exact disk mean, at most 1 % above it. (Before the specular point's bisection
    fallback, an eye closer than about r / 3 got the mirror's cap: up to 1e4 x.)"""
    text, _, want = _case(r, L, w, q, 0.9, dist, edge)
    _check(text, want)


@pytest.mark.slow
@ref.settings(ref.FAST, max_examples=40)
@given(r=ref.log_uniform(0.2, 3.0), L=ref.log_uniform(20.0, 1000.0), w=ref.log_uniform(1.5e-3, 2e-2), q=st.floats(0.1, 0.9),
       dist=ref.log_uniform(0.01, 3.0), edge=st.floats(0.3, 3.0))
def test_sphere_mirror_aperture_sweep(r, L, w, q, dist, edge):
    """Larger sweep of ``test_sphere_mirror_aperture_property``, eyes from 1 cm."""
    test_sphere_mirror_aperture_property.hypothesis.inner_test(r, L, w, q, dist, edge)


@pytest.mark.parametrize("edge", [1.4634293528560813, 3.0])
def test_sphere_mirror_aperture_close_to_a_large_sphere(edge):
    """An eye 0.143 m from a 1.35 m sphere (found by the property test's random draw), 1.46
    and 3 reflected radii off the axis: the specular-point iteration diverged there
    (r / distance = 9.4) and the eye got the mirror's cap, 12 x and 9200 x the exact
    7 mm disk mean; now within 1 % above it."""
    text, _, want = _case(math.exp(0.3), 150.2956476850026, 0.009234660514758594, 0.7, 0.9, 0.14298934837275115, edge)
    _check(text, want)


# ------------------------------------------------------------ the end of a cylinder's fan


def _fan_back_exact(rho, r, Rs, w, E0, o_xy):
    """The in-plane exact fan of ``_refs.cylinder_fan_exact`` (same formulas: exact circle
    intersection, mirror reflection, ray spacing, out-of-plane spreading l0 / Lp) for an
    observer near the back-reflection direction, where that helper's bracket (up to
    grazing) holds no sign change: the reflecting ray's x0 is sought within +-r/2 (rays
    turned back by up to 60 degrees). Returns (irradiance, x0, hit point)."""
    from scipy.optimize import brentq

    S, O = np.array([0.0, -Rs]), np.asarray(o_xy, float)

    def ray(x0):
        d = np.array([x0, Rs]) / math.hypot(x0, Rs)
        c = Rs * d[0] * np.array([d[1], -d[0]])
        p = c - math.sqrt(max(r * r - float(c @ c), 0.0)) * d
        n = p / r
        return p, d - 2 * float(d @ n) * n

    def dist(x0):
        p, out = ray(x0)
        v = O - p
        return out[0] * v[1] - out[1] * v[0]

    x0 = brentq(dist, -0.5 * r, 0.5 * r, xtol=1e-15 * r, rtol=1e-14)
    p, out = ray(x0)
    assert float((O - p) @ out) > 0, "observer behind the reflecting point"
    delta = 1e-4 * min(w, r)
    spacing = abs(dist(x0 + delta) - dist(x0 - delta)) / (2 * delta)
    l0 = math.hypot(x0, Rs)
    zfac = l0 / (np.linalg.norm(p - S) + np.linalg.norm(O - p))
    return rho * E0 * math.exp(-x0 * x0 / (w * w)) / spacing * zfac, x0, p


def _fan_end_case(gap, optics=None, dist=0.3, e0=1e-3, x_off=2e-3):
    """A mirror cylinder (r = 0.5 m, axis z, 0.2 m long, ends at z = +-0.1 m) 100 m from the
    laser, beam w = 4 mm at it aimed 1 mm below its top end (a quarter of the beam passes
    over it); an observer 0.3 m in front, 2 mm across the fan, ``gap`` above the fan's top
    edge (the reflection of the end's rim): no specular point of its own.

    Reference, from the formulas alone: a ray from the virtual source S (in-plane as in
    ``_refs.cylinder_fan_exact``) keeps its axial slope on reflection, so the one reaching
    the in-plane point O_t at height zeta above the beam axis crossed Y = 0 at
    z0 = zeta l0 / Lp (l0 = |S -> x0|, Lp = |p - S| + |O_t - p|) and hit at zeta |p - S| / Lp:
    lit up to zeta_e = e0 Lp / |p - S| (e0 = 1 mm, the end above the axis); the field is the
    in-plane one times exp(-z0^2 / w^2). Disk mean (the disk normal to the in-plane ray,
    spanning the in-plane normal t and z): Gauss-Legendre in t = a sin(theta) over the lit chord x the
    z integral in closed form (erf), converged (two orders agree to 1e-7).
    Returns (scene text, disk mean, the field's largest value on the lit t chord)."""
    from scipy.special import erf

    r, length, L, w, q, rho = 0.5, 0.2, 100.0, 4e-3, 0.5, 0.9
    zc = length / 2 - e0
    D = 2 * w
    phi = q * D / L
    a_beam = (1 - q) * D
    beam = ref.Beam(100.0, a_beam, phi, [0.0, -L, zc], [0.0, 0.0, zc])
    Rs = L + a_beam / phi
    E0 = beam.peak(L)
    S = np.array([0.0, -Rs])
    o_xy = np.array([x_off, -(r + dist)])

    def in_plane(pt):
        e2d, x0, p = _fan_back_exact(rho, r, Rs, w, E0, pt)
        ls = float(np.linalg.norm(p - S))
        lp = ls + float(np.linalg.norm(pt - p))
        return e2d, math.hypot(x0, Rs) / lp, e0 * lp / ls, p

    _, _, edge0, p0 = in_plane(o_xy)
    ray = ref.unit(o_xy - p0)
    tv = np.array([ray[1], -ray[0]])
    zeta_o = edge0 + gap

    def mean(radius, n):
        th_m = math.acos(min(gap / radius, 1.0))  # t = a sin(theta): smooth where the chord meets the rim
        x, wx = np.polynomial.legendre.leggauss(n)
        total, peak = 0.0, 0.0
        for th, wth in zip(th_m * x, th_m * wx):
            t, wt = radius * math.sin(th), wth * radius * math.cos(th)
            e2d, k, edge, _ = in_plane(o_xy + t * tv)
            z1, z2 = zeta_o - math.sqrt(radius * radius - t * t), edge
            if z2 > z1:
                total += wt * e2d * w / k * math.sqrt(math.pi) / 2 * (erf(k * z2 / w) - erf(k * z1 / w))
                peak = max(peak, e2d)
        return total / (math.pi * radius * radius), peak

    def converged(radius):
        lo, _ = mean(radius, 24)
        hi, peak = mean(radius, 48)
        assert abs(hi - lo) <= 1e-7 * abs(hi), "reference quadrature not converged"
        return hi, peak

    want, peak = converged(PUPIL_R)
    if optics:
        coll = min(optics["objective_diameter_m"], 2 * PUPIL_R * optics["magnification"]) / 2
        m_aid, p_aid = converged(coll)
        f = optics.get("transmission", 1.0) * (coll / PUPIL_R) ** 2
        want, peak = max(want, f * m_aid), max(peak, f * p_aid)
    target = dict(name="pipe", shape="cylinder", center=np.zeros(3), normal=[0.0, 0.0, 1.0], tangent=[1.0, 0.0, 0.0],
                  size=(2 * r, length), material=ref.specular(rho))
    obs = np.array([o_xy[0], o_xy[1], zc + zeta_o])
    text = ref.scene_text(power=beam.P, a=a_beam, phi=phi, position=beam.pos, aim=[0.0, 0.0, zc], targets=[target],
                          observers=[("o", obs, optics)])
    return text, want, peak


@pytest.mark.parametrize("gap", [0.5e-3, 2e-3, 3e-3])
def test_cylinder_fan_end_straddled_by_the_pupil(gap):
    """Issue 29: an eye 0.5-3 mm above the top edge of a cylinder's fan (no specular point
    of its own: before, 0, a wrong "safe") has part of its 7 mm pupil in the beam. The
    engine's bound (the largest exact value sampled on the disk, over the whole disk) is
    > 0, never below the exact disk mean, and never above the field's largest value there."""
    text, want, peak = _fan_end_case(gap)
    assert want > 0
    got = float(hazard.analyze(scenes.loads(text)).observers.specular_irradiance_w_m2[0])
    assert got > 0
    assert got >= want * (1 - 1e-9), f"engine {got:.6g} below the exact disk mean {want:.6g}"
    assert got <= peak * 1.01, f"engine {got:.6g} above the field's largest value on the disk {peak:.6g}"


def test_cylinder_fan_end_binoculars():
    """The same fan end 10 mm above its edge (outside the 7 mm pupil: the naked eye gets
    nothing) through 7x50 binoculars (transmission 0.9, collecting over 24.5 mm): tau x the
    objective's power into the pupil, bounded as above."""
    optics = {"magnification": 7.0, "objective_diameter_m": 0.05, "transmission": 0.9}
    text, want, peak = _fan_end_case(10e-3, optics)
    assert want > 0
    got = float(hazard.analyze(scenes.loads(text)).observers.specular_irradiance_w_m2[0])
    assert got >= want * (1 - 1e-9), f"engine {got:.6g} below the exact disk mean {want:.6g}"
    assert got <= peak * 1.01, f"engine {got:.6g} above the field's largest value on the disk {peak:.6g}"


@ref.settings(ref.FAST, max_examples=6)
@given(gap=st.floats(0.1e-3, 3.3e-3), dist=ref.log_uniform(0.05, 3.0), e0=st.floats(-2e-3, 4e-3), x_off=st.floats(-6e-3, 6e-3))
def test_cylinder_fan_end_property(gap, dist, e0, x_off):
    """Random eyes 0.1-3.3 mm beyond the fan's end, 5 cm - 3 m before the cylinder, up to
    6 mm across the fan, the end 2 mm below to 4 mm above the beam's axis: the engine is
    never below the exact 7 mm mean nor above the field's largest value on the disk."""
    text, want, peak = _fan_end_case(gap, dist=dist, e0=e0, x_off=x_off)
    got = float(hazard.analyze(scenes.loads(text)).observers.specular_irradiance_w_m2[0])
    assert want > 0 and got > 0
    assert got >= want * (1 - 1e-9), f"engine {got:.6g} below the exact disk mean {want:.6g}"
    assert got <= peak * 1.01, f"engine {got:.6g} above the field's largest value on the disk {peak:.6g}"


@pytest.mark.slow
@ref.settings(ref.FAST, max_examples=40)
@given(gap=st.floats(0.1e-3, 3.4e-3), dist=ref.log_uniform(0.05, 3.0), e0=st.floats(-4e-3, 6e-3), x_off=st.floats(-8e-3, 8e-3))
def test_cylinder_fan_end_sweep(gap, dist, e0, x_off):
    """Larger sweep of ``test_cylinder_fan_end_property``."""
    test_cylinder_fan_end_property.hypothesis.inner_test(gap, dist, e0, x_off)
