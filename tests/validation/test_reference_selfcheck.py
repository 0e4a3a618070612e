"""Self-checks of the validation references (``_refs.py``): they keep the referee honest.

No engine code is called here. Each reference formula is checked against an independent
computation: brute-force 2-D quadrature, Monte Carlo ray traces written in numpy, direct
evaluation, and the worked examples of /work/shared/spec/range-safety.md and
/work/shared/spec/laser-safety.md.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from scipy.integrate import dblquad, quad

from . import _refs as ref

# ---------------------------------------------------------------- worked examples of the spec


def test_spec_power_fraction_examples():
    """range-safety.md 1 'Power fractions': 7 mm beam through a 7 mm aperture 0.63212;
    10 mm beam through a centred 10 x 4 mm slot 0.36101; 10 mm beam, disk rho = 3.5 mm
    offset 3 mm: 0.29279."""
    assert ref.disk_fraction(3.5e-3, 0.0, 3.5e-3) == pytest.approx(0.63212, abs=1e-5)
    assert ref.rect_fraction(-5e-3, 5e-3, -2e-3, 2e-3, 5e-3) == pytest.approx(0.36101, abs=1e-5)
    assert ref.disk_fraction(3.5e-3, 3e-3, 5e-3) == pytest.approx(0.29279, abs=1e-5)


def test_spec_peak_irradiance_example():
    """range-safety.md 1 worked example: P = 1 W, a = 2 mm gives E0 = 3.1831e5 W/m^2."""
    b = ref.Beam(1.0, 2e-3, 1e-3, [0, 0, 0], [0, 1, 0])
    assert b.peak(0.0) == pytest.approx(3.1831e5, rel=1e-4)


def test_spec_nohd_examples():
    """laser-safety.md 3.2: direct NOHD 157.58 m (1 W, a = 2 mm, phi = 1 mrad, MPE 50);
    flat mirror rho = 0.9, 10 W, a = 3 mm, phi = 1 mrad: 475.7 m (direct 501.6 m);
    range-safety.md 2: R0 = 10 km, mu = 2e-4 /m gives R = 5671.4 m (a = 0, Lambert W)."""
    assert ref.folded_specular_range(1.0, 1.0, 2e-3, 1e-3, 50.0) == pytest.approx(157.58, abs=0.01)
    assert ref.folded_specular_range(10.0, 0.9, 3e-3, 1e-3, 50.0) == pytest.approx(475.7, abs=0.1)
    assert ref.folded_specular_range(10.0, 1.0, 3e-3, 1e-3, 50.0) == pytest.approx(501.6, abs=0.1)
    assert ref.lambert_w_range(10_000.0, 2e-4) == pytest.approx(5671.4, abs=0.1)


def test_spec_curved_reflector_examples():
    """range-safety.md 4: sphere rho = 0.9, E = 1e4, r = 0.05 m: I = 5.625 W/sr,
    E(10 m) = 0.05625 W/m^2, R_h = 0.75 m at MPE 10; cylinder, psi = 0, D = 10 m: 22.5 W/m^2."""
    i = ref.sphere_intensity(0.9, 0.05, 1e4, math.inf, 0.0)
    assert i == pytest.approx(5.625, rel=1e-12)
    assert i / 10.0**2 == pytest.approx(0.05625, rel=1e-12)
    assert math.sqrt(i / 10.0) == pytest.approx(0.75, rel=1e-12)
    assert ref.cylinder_fan_irradiance(0.9, 1e4, 0.05, 0.0, 10.0) == pytest.approx(22.5, rel=1e-12)


def test_spec_binocular_gain_example():
    """laser-safety.md 3.1 ENOHD: 7x50, tau = 1: K = min(tau M^2, tau (D0/7 mm)^2) = 49 (vs 51)."""
    assert ref.optical_gain(7.0, 0.05, 1.0) == pytest.approx(49.0)
    assert ref.optical_gain(10.0, 0.05, 1.0) == pytest.approx((50 / 7) ** 2)
    assert ref.optical_gain(7.0, 0.05, 1.0, beam_diameter_m=0.014) == pytest.approx(4.0)


# ---------------------------------------------------------------- power fractions vs quadrature


def _gauss2(x, y, w):
    return math.exp(-(x * x + y * y) / (w * w)) / (math.pi * w * w)


@ref.FAST
@given(st.floats(-3, 3), st.floats(0.01, 4), st.floats(-3, 3), st.floats(0.01, 4))
def test_rect_erf_formula_equals_2d_quadrature(x1, dx, y1, dy):
    """F = 1/4 [erf(x2/w)-erf(x1/w)][erf(y2/w)-erf(y1/w)] (range-safety.md 1) against a
    brute-force dblquad of exp(-r^2/w^2)/(pi w^2) over the rectangle."""
    w = 1.0
    x2, y2 = x1 + dx, y1 + dy
    brute = dblquad(lambda y, x: _gauss2(x, y, w), x1, x2, y1, y2, epsabs=1e-13, epsrel=1e-11)[0]
    assert ref.rect_fraction(x1, x2, y1, y2, w) == pytest.approx(brute, rel=1e-8, abs=1e-13)


@ref.FAST
@given(st.floats(0.02, 4), st.floats(0, 4))
def test_disk_marcum_formula_equals_polar_quadrature(rho, d):
    """F = ncx2.cdf((rho/sigma)^2, 2, (d/sigma)^2), sigma = w/sqrt(2) (range-safety.md 1)
    against a polar quadrature of the Gaussian over the offset disk."""
    w = 1.0

    def ring(t):  # angle-integrated Gaussian on the circle of radius t around the disk centre
        return quad(lambda a: _gauss2(d + t * math.cos(a), t * math.sin(a), w), 0, 2 * math.pi, epsabs=1e-14)[0] * t

    brute = quad(ring, 0, rho, epsabs=1e-13, epsrel=1e-10, limit=200)[0]
    assert ref.disk_fraction(rho, d, w) == pytest.approx(brute, rel=1e-7, abs=1e-12)


@ref.FAST
@given(st.floats(-3, 3), st.floats(0.01, 6), st.floats(-3, 3), st.floats(0.01, 6), st.floats(0, 2 * math.pi))
def test_polygon_integrator_equals_erf_for_rotated_rectangles(x1, dx, y1, dy, angle):
    """The polygon integrator (used for tilted plates) gives the erf formula for any
    rectangle rotated about the beam axis (the Gaussian is circular)."""
    c, s = math.cos(angle), math.sin(angle)
    rect = np.array([[x1, y1], [x1 + dx, y1], [x1 + dx, y1 + dy], [x1, y1 + dy]])
    rot = rect @ np.array([[c, s], [-s, c]])
    expected = ref.rect_fraction(x1, x1 + dx, y1, y1 + dy, 1.0)
    assert ref.gaussian_polygon_fraction(rot, 1.0) == pytest.approx(expected, rel=1e-9, abs=1e-14)
    # the weighted branch with weight 1 is the same integral
    one = lambda x, z: np.ones_like(x)
    assert ref.gaussian_polygon_fraction(rot, 1.0, weight=one) == pytest.approx(expected, rel=1e-9, abs=1e-14)


def test_polygon_integrator_on_a_trapezoid_and_with_a_weight():
    """A general quadrilateral and a weighted integrand against dblquad."""
    poly = np.array([[-0.7, -1.2], [1.4, -0.3], [0.9, 1.1], [-1.1, 0.6]])
    lo = lambda x: ref._polygon_z_range(poly, np.array([x]))[0][0]
    hi = lambda x: ref._polygon_z_range(poly, np.array([x]))[1][0]
    weight = lambda x, z: np.exp(-0.3 * x + 0.2 * z)
    for wfun, f in ((None, lambda z, x: _gauss2(x, z, 0.8)),
                    (weight, lambda z, x: _gauss2(x, z, 0.8) * math.exp(-0.3 * x + 0.2 * z))):
        brute = 0.0
        xs = np.sort(poly[:, 0])
        for a, b in zip(xs[:-1], xs[1:]):
            brute += dblquad(f, a, b, lo, hi, epsabs=1e-13, epsrel=1e-11)[0]
        assert ref.gaussian_polygon_fraction(poly, 0.8, weight=wfun) == pytest.approx(brute, rel=1e-8)


# ---------------------------------------------------------------- tilted plates vs a Monte Carlo ray trace


def _mc_plate_power(beam, center, normal, tangent, size, n, rng):
    """Monte Carlo: rays from the virtual source through Gaussian points of the transverse
    plane at the plate's range; count the ones whose hit on the plate's plane lies inside
    the rectangle, each weighted by exp(-mu * path)."""
    R = float(np.dot(np.asarray(center) - beam.pos, beam.u))
    sigma = beam.w(R) / math.sqrt(2)
    q = rng.normal(0.0, sigma, size=(n, 2))
    hits = beam.unproject(q, R, center, normal)
    x, y, _ = ref.plate_frame(normal, tangent)
    d = hits - np.asarray(center)
    inside = (np.abs(d @ x) <= size[0] / 2) & (np.abs(d @ y) <= size[1] / 2)
    wts = np.exp(-beam.mu * np.linalg.norm(hits - beam.pos, axis=1)) * inside
    return beam.P * wts.mean(), beam.P * wts.std() / math.sqrt(n)


@pytest.mark.parametrize("tilt_deg, offset, size, mu", [
    (0.0, (0.0, 0.0), (0.4, 0.3), 0.0),
    (55.0, (0.3, -0.2), (0.8, 0.5), 0.0),
    (60.0, (0.0, 0.0), (2.0, 0.2), 2e-3),
    (40.0, (-0.9, 0.4), (1.5, 1.5), 2e-3),
])
def test_tilted_plate_central_projection_equals_monte_carlo(tilt_deg, offset, size, mu):
    """The central projection of a tilted plate (rays from the virtual source a/phi behind
    the aperture, range-safety.md 1), with per-ray Beer-Lambert attenuation, against a
    Monte Carlo ray trace (4e6 rays, 5 sigma). The beam is wide and close (D = 0.5 m at
    20 m with phi = 20 mrad) so the projection is far from orthographic."""
    rng = np.random.default_rng(1)
    beam = ref.Beam(1.0, 0.1, 0.02, [0, -20.0, 0], [0, 0, 0], mu=mu)
    D = beam.diameter(20.0)
    m = ref.rotation_matrix([1.0, 0.3, 0.2], math.radians(tilt_deg))
    normal, tangent = m @ np.array([0, -1.0, 0]), m @ np.array([1.0, 0, 0])
    center = np.array([offset[0] * D, 0.0, offset[1] * D])
    sz = (size[0] * D, size[1] * D)
    exact = ref.plate_spot_power(beam, center, normal, tangent, sz)
    mc, err = _mc_plate_power(beam, center, normal, tangent, sz, 4_000_000, rng)
    assert abs(exact - mc) < 5 * err + 1e-12
    if tilt_deg == 0.0 and mu == 0.0:
        w = beam.w(20.0)
        assert exact == pytest.approx(ref.rect_fraction(-sz[0] / 2, sz[0] / 2, -sz[1] / 2, sz[1] / 2, w), rel=1e-10)


# ---------------------------------------------------------------- NOHD root


@ref.FAST
@given(st.floats(0.1, 1e5), st.floats(0.05, 1.0), st.floats(1e-3, 0.05), st.floats(1e-4, 3e-3),
       st.sampled_from([0.0, 1e-4, 2e-3]), st.floats(1.0, 500.0))
def test_specular_nohd_root_by_direct_evaluation(power, rho, a, phi, mu, mpe):
    """The bisection root R of rho 4P exp(-mu R)/(pi (a + R phi)^2) = MPE (laser-safety.md
    3.1, range-safety.md 2) evaluated back: the irradiance there is the MPE; and with
    a = 0 it equals the Lambert-W closed form R = (2/mu) W(mu R0/2)."""
    R = ref.folded_specular_range(power, rho, a, phi, mpe, mu)
    e = lambda r: rho * 4 * power * math.exp(-mu * r) / (math.pi * (a + r * phi) ** 2)
    if R > 0:
        assert e(R) == pytest.approx(mpe, rel=1e-9)
        assert e(R * 0.999) > mpe > e(R * 1.001)
    else:
        assert e(0.0) <= mpe
    R0 = math.sqrt(4 * rho * power / (math.pi * mpe)) / phi
    assert ref.folded_specular_range(power, rho, 0.0, phi, mpe, mu) == pytest.approx(ref.lambert_w_range(R0, mu), rel=1e-9)


# ---------------------------------------------------------------- flat mirror image model vs energy balance


def test_mirror_image_model_conserves_the_intercepted_power():
    """Flat mirror (range-safety.md 4, unfolded path): the reflected irradiance at a point
    O is rho times the beam at O's mirror image O', where the unfolded ray S->O' passes
    through the mirror. Integrated over a screen normal to the reflected axis (midpoint
    rule, 1000 x 1000) it must give rho times the power the mirror intercepts."""
    beam = ref.Beam(10.0, 0.02, 1e-3, [0, -300.0, 0], [0, 0, 0])
    ti = math.radians(35)
    n = np.array([-math.sin(ti), -math.cos(ti), 0.0])
    size = (0.12, 0.2)
    tangent = np.array([0, 0, 1.0])
    rdir = ref.reflect(beam.u, n)
    rho = 0.8
    p_spot = ref.plate_spot_power(beam, [0, 0, 0], n, tangent, size)
    R2 = 150.0
    e1, e2 = ref.transverse_basis(rdir)
    half, m = 0.4, 1000
    g = (np.arange(m) + 0.5) / m * 2 * half - half
    gx, gy = np.meshgrid(g, g)
    obs = R2 * rdir + gx.reshape(-1, 1) * e1 + gy.reshape(-1, 1) * e2
    img = obs - 2 * (obs @ n)[:, None] * n  # mirror plane through the origin
    e = image_irradiance(beam, img, n, tangent, size, rho)
    integral = e.sum() * (2 * half / m) ** 2
    assert integral == pytest.approx(rho * p_spot, rel=5e-3)
    # the lit patch lies well inside the screen, so the integral is not truncated
    border = np.maximum(np.abs(gx), np.abs(gy)).reshape(-1) > 0.9 * half
    assert e[border].max() == 0.0


def image_irradiance(beam, img, n, tangent, size, rho, center=(0.0, 0.0, 0.0)):
    """rho x the (unattenuated) beam at the image points, where the ray from the virtual
    source to the image crosses the mirror's plane inside the mirror; else 0."""
    img = np.atleast_2d(img)
    c = np.asarray(center, float)
    S = beam.source
    d = img - S
    s = ((c - S) @ n) / (d @ n)
    cross = S + s[:, None] * d - c
    x, y, _ = ref.plate_frame(n, tangent)
    inside = (np.abs(cross @ x) <= size[0] / 2) & (np.abs(cross @ y) <= size[1] / 2)
    rel = img - beam.pos
    R = rel @ beam.u
    r2 = (rel**2).sum(1) - R * R
    D = beam.diameter(R)
    return np.where(inside, rho * 4 * beam.P / (math.pi * D * D) * np.exp(-4 * r2 / (D * D)), 0.0)


# ---------------------------------------------------------------- sphere and cylinder vs Monte Carlo


def test_sphere_intensity_equals_monte_carlo_ray_trace():
    """Convex sphere, Gaussian beam centred (range-safety.md 4): I(psi) = rho (r^2/4) E0
    exp(-r^2 sin^2(psi/2)/w^2). A Monte Carlo trace (parallel rays, Gaussian positions,
    exact sphere intersection, mirror reflection, histogram of psi over solid angle) must
    agree per 10-degree bin within 3 %; the total is rho P F_disk(r)."""
    rng = np.random.default_rng(3)
    P, rho, r, w = 1.0, 0.9, 1.0, 0.8
    n = 4_000_000
    q = rng.normal(0.0, w / math.sqrt(2), size=(n, 2))
    h2 = (q**2).sum(1)
    q = q[h2 < r * r]
    # beam along +y; hit on the sphere centred at the origin
    y = -np.sqrt(r * r - (q**2).sum(1))
    normal = np.stack([q[:, 0], y, q[:, 1]], 1) / r
    d_in = np.array([0.0, 1.0, 0.0])
    d_out = d_in - 2 * (normal @ d_in)[:, None] * normal
    psi = np.arccos(np.clip(d_out @ np.array([0.0, -1.0, 0.0]), -1, 1))
    edges = np.radians(np.arange(0, 171, 10))
    counts, _ = np.histogram(psi, edges)
    E0 = P / (math.pi * w * w)
    for lo, hi, c in zip(edges[:-1], edges[1:], counts):
        omega = 2 * math.pi * (math.cos(lo) - math.cos(hi))
        mc = rho * P * c / n / omega
        exact = quad(lambda t: ref.sphere_intensity(rho, r, E0, w, t) * 2 * math.pi * math.sin(t), lo, hi)[0] / omega
        assert mc == pytest.approx(exact, rel=0.03)
    total = quad(lambda t: ref.sphere_intensity(rho, r, E0, w, t) * 2 * math.pi * math.sin(t), 0, math.pi)[0]
    assert total == pytest.approx(rho * P * ref.disk_fraction(r, 0.0, w), rel=1e-9)


def test_cylinder_fan_equals_monte_carlo_ray_trace():
    """Cylinder, axis normal to the beam (range-safety.md 4): E(D) = rho E r cos(psi/2)/(2D)
    with E the incident irradiance at the impact parameter h = r sin(psi/2), times the
    out-of-plane spreading R_s/(R_s + D) of a diverging beam (R_s: distance from the
    virtual source; thin-fan limit). A 3-D Monte Carlo trace (rays from the virtual
    source, exact cylinder intersection, reflection, counts in (psi, z) cells on a screen
    cylinder of radius D) agrees within 4 % at z = 0."""
    rng = np.random.default_rng(5)
    P, rho, r = 1.0, 0.9, 0.2
    Rs = 40.0  # virtual source to the cylinder axis
    w = 0.15  # 1/e radius at the axis
    D = 20.0
    dz, dpsi = 0.05, math.radians(2.0)
    psis = np.radians([10.0, 40.0, 80.0, 120.0])
    counts = np.zeros(len(psis))
    n, chunks = 1_000_000, 10
    S = np.array([0.0, -Rs, 0.0])
    for _ in range(chunks):
        q = rng.normal(0.0, w / math.sqrt(2), size=(n, 2))  # (x, z) at the plane y = 0
        q = q[np.abs(q[:, 0]) < r]
        d = np.stack([q[:, 0], np.full(len(q), Rs), q[:, 1]], 1)
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        # intersect with x^2 + y^2 = r^2 (axis z)
        a2 = d[:, 0] ** 2 + d[:, 1] ** 2
        b = 2 * (S[1] * d[:, 1])
        c = S[1] ** 2 - r * r
        t = (-b - np.sqrt(b * b - 4 * a2 * c)) / (2 * a2)
        hit = S + t[:, None] * d
        nrm = np.stack([hit[:, 0], hit[:, 1], np.zeros(len(hit))], 1) / r
        out = d - 2 * (d * nrm).sum(1, keepdims=True) * nrm
        # propagate to the screen cylinder of radius D about the axis
        a2 = out[:, 0] ** 2 + out[:, 1] ** 2
        b = 2 * (hit[:, 0] * out[:, 0] + hit[:, 1] * out[:, 1])
        c = hit[:, 0] ** 2 + hit[:, 1] ** 2 - D * D
        s = (-b + np.sqrt(b * b - 4 * a2 * c)) / (2 * a2)
        scr = hit + s[:, None] * out
        ang = np.arctan2(scr[:, 0], -scr[:, 1])  # psi measured from -y toward +x
        near = np.abs(scr[:, 2]) < dz / 2
        for i, psi in enumerate(psis):
            counts[i] += np.count_nonzero(near & (np.abs(ang - psi) < dpsi / 2))
    E0 = P / (math.pi * w * w)
    for psi, cnt in zip(psis, counts):
        mc = rho * P * cnt / (n * chunks) / (D * dpsi * dz)
        h = r * math.sin(psi / 2)
        far = ref.cylinder_fan_irradiance(rho, E0 * math.exp(-h * h / (w * w)), r, psi, D) * Rs / (Rs + D)
        assert mc == pytest.approx(far, rel=0.04)
        exact = ref.cylinder_fan_exact(rho, r, Rs, w, E0, (D * math.sin(psi), -D * math.cos(psi)))[0]
        assert mc == pytest.approx(exact, rel=0.03)


@pytest.mark.parametrize("psi_deg", [-100.0, -30.0, 5.0, 60.0, 120.0])
def test_exact_cylinder_fan_tends_to_the_far_field_formula(psi_deg):
    """The traced fan (``cylinder_fan_exact``) tends to rho E(h) r cos(psi/2)/(2D)
    (range-safety.md 4) for a collimated beam as D/r grows (error ~ r/D)."""
    rho, r, w, E0 = 0.7, 0.1, 0.08, 3.0
    psi = math.radians(psi_deg)
    h = r * math.sin(abs(psi) / 2)
    for D, tol in ((1e3, 2e-3), (1e5, 2e-5)):
        far = ref.cylinder_fan_irradiance(rho, E0 * math.exp(-h * h / (w * w)), r, abs(psi), D)
        exact = ref.cylinder_fan_exact(rho, r, 1e12, w, E0, (D * math.sin(psi), -D * math.cos(psi)))[0]
        assert exact == pytest.approx(far, rel=tol)


@pytest.mark.parametrize("tilt_deg, offset, size, spin", [
    (0.0, (0.0, 0.0), (0.3, 0.3), 0.0),
    (10.7, (-0.98, 0.24), (1.35, 1.27), 1.46),
    (55.0, (0.6, -0.4), (0.5, 2.0), 0.3),
    (30.0, (1.8, 1.5), (0.4, 0.4), 2.0),
])
def test_peak_irradiance_on_a_plate_equals_brute_force(tilt_deg, offset, size, spin):
    """``plate_peak_irradiance`` (max over the centrally projected outline) against a brute
    force: the beam irradiance (normal to the axis, at each point's own range) times
    exp(-mu |p - laser|) on a 601 x 601 grid of world points on the plate."""
    beam = ref.Beam(1000.0, 0.05, 2e-3, [0, -150.0, 0], [0, 0, 0], mu=2e-3)
    D = beam.diameter(150.0)
    m = ref.rotation_matrix([math.cos(1.1), 0.0, math.sin(1.1)], math.radians(tilt_deg)) @ ref.rotation_matrix([0, 1.0, 0], spin)
    normal, tangent = m @ np.array([0, -1.0, 0]), m @ np.array([1.0, 0, 0])
    center = np.array([offset[0] * D, 0.0, offset[1] * D])
    sz = (size[0] * D, size[1] * D)
    x, y, _ = ref.plate_frame(normal, tangent)
    g = np.linspace(-0.5, 0.5, 601)
    S, T = np.meshgrid(g * sz[0], g * sz[1])
    pts = center + S.reshape(-1, 1) * x + T.reshape(-1, 1) * y
    rel = pts - beam.pos
    R = rel @ beam.u
    r2 = (rel**2).sum(1) - R * R
    Dp = beam.diameter(R)
    e = 4 * beam.P / (math.pi * Dp**2) * np.exp(-4 * r2 / Dp**2) * np.exp(-beam.mu * np.linalg.norm(rel, axis=1))
    assert ref.plate_peak_irradiance(beam, center, normal, tangent, sz) == pytest.approx(e.max(), rel=2e-3)
