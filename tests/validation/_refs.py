"""Independent reference formulas for the validation suite (numpy/scipy only).

Nothing here imports the engine (``hazard.physics.engine``, ``hazard.pipeline.analysis``, ``hazard.physics.keepout``,
``hazard.physics.nohd``): every number is written out from the formulas of
/work/shared/spec/range-safety.md (sections 1, 2, 4) and /work/shared/spec/laser-safety.md
(sections 3.1: NOHD, diffuse reflection, Beer-Lambert attenuation, ENOHD gain).
The functions are themselves checked in ``test_reference_selfcheck.py`` against brute-force
quadrature, Monte Carlo ray traces and the worked examples of the spec.

Beam conventions (range-safety.md section 1):
  a    = 1/e irradiance diameter at the aperture, phi = full divergence at 1/e,
  D(R) = a + R phi, w_e = D/2 (1/e radius), E(r) = 4P/(pi D^2) exp(-r^2 / w_e^2),
  rays come from a virtual point source a/phi behind the aperture.
Attenuation: exp(-mu * path length), once per leg.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.special import erf, lambertw
from hypothesis import HealthCheck, Phase, settings
from hypothesis import strategies as st
from scipy.stats import ncx2

# hypothesis settings: reproducible (derandomized), no deadline; few examples by default,
# and no shrinking there (a failing engine must not stretch the default run; the example
# printed is the drawn one)
_HC = [HealthCheck.filter_too_much, HealthCheck.too_slow]
FAST = settings(max_examples=25, derandomize=True, deadline=None, database=None, suppress_health_check=_HC,
                phases=[Phase.explicit, Phase.generate])
SLOW = settings(max_examples=120, derandomize=True, deadline=None, database=None, suppress_health_check=_HC)
# the default run of a property whose @pytest.mark.slow twin (same helper) sweeps SLOW: 10
# drawn examples (the twin holds the breadth; 25 cost 2-9 s per property of whole analyses)
FAST_TWIN = settings(FAST, max_examples=10)
# the same for a property whose example costs 1-2 s of CPU (a whole analysis of a curved
# mirror): 4 drawn examples by default (10 took 12-20 s of the default run each), the slow
# twin sweeps SLOW
HEAVY_TWIN = settings(FAST, max_examples=4)

# --------------------------------------------------------------------------- vectors


def unit(v):
    v = np.asarray(v, dtype=float)
    return v / np.linalg.norm(v)


def rotation_matrix(axis, angle):
    """Rodrigues rotation about ``axis`` by ``angle`` [rad]."""
    k = unit(axis)
    kx = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + math.sin(angle) * kx + (1 - math.cos(angle)) * kx @ kx


def euler_rotation(yaw, pitch, roll):
    """A proper rotation from three angles [rad] (z, then y, then x)."""
    return rotation_matrix([0, 0, 1], yaw) @ rotation_matrix([0, 1, 0], pitch) @ rotation_matrix([1, 0, 0], roll)


def plate_frame(normal, tangent):
    """Plate frame as the scene schema defines it: x = tangent made orthogonal to the
    normal, y = z cross x, z = normal (scenes/spec.py, scenes/geometry.py docstring)."""
    z = unit(normal)
    t = np.asarray(tangent, float)
    x = unit(t - np.dot(t, z) * z)
    y = np.cross(z, x)
    return x, y, z


def plate_corners(center, normal, tangent, size):
    x, y, _ = plate_frame(normal, tangent)
    c = np.asarray(center, float)
    w, h = size
    return np.array([c + sx * w / 2 * x + sy * h / 2 * y for sx, sy in ((-1, -1), (1, -1), (1, 1), (-1, 1))])


def reflect(d, n):
    """Mirror reflection of direction d about the plane with unit normal n."""
    d = np.asarray(d, float)
    n = unit(n)
    return d - 2 * np.dot(d, n) * n


def transverse_basis(u):
    """Two unit vectors spanning the plane normal to the beam axis u."""
    u = unit(u)
    helper = np.array([0.0, 0.0, 1.0]) if abs(u[2]) < 0.9 else np.array([1.0, 0.0, 0.0])
    e1 = unit(np.cross(u, helper))
    e2 = np.cross(u, e1)
    return e1, e2


# --------------------------------------------------------------------------- the beam


class Beam:
    """Gaussian beam of range-safety.md section 1 (1/e diameter a, full 1/e divergence phi)."""

    def __init__(self, power, a, phi, position, aim, mu=0.0):
        self.P = float(power)
        self.a = float(a)
        self.phi = float(phi)
        self.pos = np.asarray(position, float)
        self.u = unit(np.asarray(aim, float) - self.pos)
        self.mu = float(mu)
        self.e1, self.e2 = transverse_basis(self.u)

    def diameter(self, R):
        """D(R) = a + R phi (laser-safety.md 3.1, range-safety.md 1)."""
        return self.a + R * self.phi

    def w(self, R):
        return self.diameter(R) / 2.0

    def peak(self, R):
        """E0 = 4P/(pi D^2), unattenuated (range-safety.md 1)."""
        return 4.0 * self.P / (math.pi * self.diameter(R) ** 2)

    @property
    def source(self):
        """Virtual point source a/phi behind the aperture."""
        if self.phi == 0:
            return None
        return self.pos - self.u * (self.a / self.phi)

    def irradiance_at(self, p):
        """Unattenuated beam irradiance (normal to the axis) at point p."""
        d = np.asarray(p, float) - self.pos
        R = float(np.dot(d, self.u))
        r2 = float(np.dot(d, d) - R * R)
        D = self.diameter(R)
        return 4.0 * self.P / (math.pi * D * D) * math.exp(-4.0 * max(r2, 0.0) / (D * D))

    def project(self, pts, R_plane):
        """Central projection (from the virtual source) of points onto the transverse
        plane at axial distance ``R_plane`` from the aperture; returns (N, 2) coordinates
        in (e1, e2). Orthographic when phi = 0."""
        pts = np.atleast_2d(np.asarray(pts, float))
        if self.phi == 0:
            d = pts - self.pos
        else:
            S = self.source
            v = pts - S
            depth = v @ self.u
            if np.any(depth <= 0):
                raise ValueError("point behind the virtual source")
            t = (R_plane + self.a / self.phi) / depth
            d = S + v * t[:, None] - self.pos
        return np.stack([d @ self.e1, d @ self.e2], axis=1)

    def unproject(self, q, R_plane, plane_point, plane_normal):
        """Points where the rays through transverse coordinates q (at R_plane) meet a plane."""
        q = np.atleast_2d(np.asarray(q, float))
        at = self.pos + R_plane * self.u + q[:, :1] * self.e1 + q[:, 1:2] * self.e2
        n = unit(plane_normal)
        if self.phi == 0:
            dirs = np.broadcast_to(self.u, at.shape)
            origin = at
        else:
            origin = np.broadcast_to(self.source, at.shape)
            dirs = at - origin
        s = ((np.asarray(plane_point, float) - origin) @ n) / (dirs @ n)
        return origin + dirs * s[:, None]


# --------------------------------------------------------------------------- power fractions


def rect_fraction(x1, x2, y1, y2, w):
    """F = 1/4 [erf(x2/w) - erf(x1/w)] [erf(y2/w) - erf(y1/w)], w = 1/e radius
    (range-safety.md section 1, 'Power fractions')."""
    return 0.25 * (erf(x2 / w) - erf(x1 / w)) * (erf(y2 / w) - erf(y1 / w))


def disk_fraction(rho, d, w):
    """Disk of radius rho, centre offset d from the axis: F = 1 - Q1(d/sigma, rho/sigma)
    = ncx2.cdf((rho/sigma)^2, 2, (d/sigma)^2), sigma = w/sqrt(2) (range-safety.md 1).
    Centred: F = 1 - exp(-rho^2/w^2)."""
    if d == 0:
        return -math.expm1(-(rho / w) ** 2)
    s = w / math.sqrt(2.0)
    return float(ncx2.cdf((rho / s) ** 2, 2, (d / s) ** 2))


_GL_X, _GL_W = np.polynomial.legendre.leggauss(64)


def _gl(a, b):
    half = 0.5 * (b - a)
    return a + half * (_GL_X + 1.0), half * _GL_W


def _gl_composite(a, b, pieces):
    xs, ws = [], []
    edges = np.linspace(a, b, pieces + 1)
    for lo, hi in zip(edges[:-1], edges[1:]):
        x, wt = _gl(lo, hi)
        xs.append(x)
        ws.append(wt)
    return np.concatenate(xs), np.concatenate(ws)


def _polygon_z_range(poly, x):
    """Lower and upper z of a convex polygon along the vertical lines at x (vectorised)."""
    lo = np.full_like(x, np.inf)
    hi = np.full_like(x, -np.inf)
    n = len(poly)
    for i in range(n):
        (xa, za), (xb, zb) = poly[i], poly[(i + 1) % n]
        if xa == xb:
            continue
        t = (x - xa) / (xb - xa)
        inside = (t >= -1e-12) & (t <= 1 + 1e-12)
        z = za + np.clip(t, 0, 1) * (zb - za)
        lo = np.where(inside, np.minimum(lo, z), lo)
        hi = np.where(inside, np.maximum(hi, z), hi)
    return lo, hi


def gaussian_polygon_fraction(poly, w, weight=None, clip=9.0):
    """Fraction of a centred circular Gaussian (1/e radius w) inside a convex polygon
    (vertices (N, 2) in order): integral of exp(-(x^2+z^2)/w^2)/(pi w^2).

    Outer Gauss-Legendre in x between the vertices' abscissae (the bounds are linear
    there), inner integral in closed form with erf, or Gauss-Legendre when a ``weight``
    function weight(x, z) (e.g. attenuation along each ray) multiplies the Gaussian.
    """
    poly = np.asarray(poly, float)
    L = clip * w
    xs = np.unique(np.clip(poly[:, 0], -L, L))
    total = 0.0
    for xa, xb in zip(xs[:-1], xs[1:]):
        if xb - xa <= 0:
            continue
        pieces = max(1, int(math.ceil((xb - xa) / (2.0 * w))))
        x, wt = _gl_composite(xa, xb, pieces)
        lo, hi = _polygon_z_range(poly, x)
        ok = hi > lo
        lo = np.clip(lo, -L, L)
        hi = np.clip(hi, -L, L)
        gx = np.exp(-(x / w) ** 2) / (math.sqrt(math.pi) * w)
        if weight is None:
            inner = 0.5 * (erf(hi / w) - erf(lo / w))
        else:
            inner = np.zeros_like(x)
            for i in np.nonzero(ok & (hi > lo))[0]:
                pieces_z = max(1, int(math.ceil((hi[i] - lo[i]) / (2.0 * w))))
                z, wz = _gl_composite(lo[i], hi[i], pieces_z)
                gz = np.exp(-(z / w) ** 2) / (math.sqrt(math.pi) * w)
                inner[i] = np.sum(wz * gz * weight(np.full_like(z, x[i]), z))
        total += float(np.sum(wt * gx * np.where(ok, inner, 0.0)))
    return total


def plate_spot_power(beam, center, normal, tangent, size, path="ray"):
    """Power a flat plate intercepts from the beam, attenuated laser->target.

    The plate's outline is projected centrally from the virtual source onto the
    transverse plane through the plate centre, where the profile is the Gaussian with
    w = D/2; the projection of a rectangle is a convex quadrilateral. With mu > 0 each
    ray carries exp(-mu * L): ``path="ray"`` L = |hit - laser| (Beer-Lambert along the
    ray), ``path="axial"`` L = the hit's range along the beam axis. The two differ by
    r^2/(2R) per ray: the spread between them is the convention's own ambiguity."""
    corners = plate_corners(center, normal, tangent, size)
    R = float(np.dot(np.asarray(center, float) - beam.pos, beam.u))
    poly = beam.project(corners, R)
    poly = _ccw(poly)
    w = beam.w(R)
    weight = None
    if beam.mu > 0:
        def weight(x, z):
            hits = beam.unproject(np.stack([x, z], 1), R, center, normal)
            L = np.linalg.norm(hits - beam.pos, axis=1) if path == "ray" else (hits - beam.pos) @ beam.u
            return np.exp(-beam.mu * L)
    return beam.P * gaussian_polygon_fraction(poly, w, weight)


def plate_peak_irradiance(beam, center, normal, tangent, size, n_grid=401):
    """Highest incident irradiance (normal to the beam, attenuated laser->hit) on a flat
    plate's lit part. A ray through the transverse point q (at the plate centre's range R)
    hits the plate at range s(q); there the profile is 4P/(pi D(s)^2) exp(-4 r_s^2/D(s)^2)
    with r_s/D(s) = |q|/D(R) (rays from the virtual source), i.e.
    E0(R) (D(R)/D(s))^2 exp(-|q|^2/w^2) exp(-mu L(q)). Maximised over the projected
    outline: a dense grid, the vertices and the outline point nearest the axis."""
    corners = plate_corners(center, normal, tangent, size)
    R = float(np.dot(np.asarray(center, float) - beam.pos, beam.u))
    poly = _ccw(beam.project(corners, R))
    w = beam.w(R)
    lo = np.maximum(poly.min(0), -4 * w)
    hi = np.minimum(poly.max(0), 4 * w)
    cands = [poly, _nearest_on_polygon(poly)[None, :]]
    if np.all(hi > lo):
        gx, gz = np.meshgrid(np.linspace(lo[0], hi[0], n_grid), np.linspace(lo[1], hi[1], n_grid))
        g = np.stack([gx.ravel(), gz.ravel()], 1)
        zl, zh = _polygon_z_range(poly, g[:, 0])
        cands.append(g[(g[:, 1] >= zl) & (g[:, 1] <= zh)])
    q = np.vstack(cands)
    hits = beam.unproject(q, R, center, normal)
    rel = hits - beam.pos
    s_ax = rel @ beam.u
    L = np.linalg.norm(rel, axis=1)
    e = beam.peak(R) * (beam.diameter(R) / beam.diameter(s_ax)) ** 2 * np.exp(-(q**2).sum(1) / w**2) * np.exp(-beam.mu * L)
    return float(e.max())


def _nearest_on_polygon(poly):
    """Point of a convex polygon nearest the origin (the origin itself if inside)."""
    n = len(poly)

    def cross2(u, v):
        return u[0] * v[1] - u[1] * v[0]

    sides = [cross2(poly[(i + 1) % n] - poly[i], -poly[i]) for i in range(n)]
    inside = all(c >= 0 for c in sides) or all(c <= 0 for c in sides)
    if inside:
        return np.zeros(2)
    best, bd = None, math.inf
    for i in range(n):
        a, b = poly[i], poly[(i + 1) % n]
        t = np.clip(-(a @ (b - a)) / ((b - a) @ (b - a)), 0, 1)
        p = a + t * (b - a)
        if p @ p < bd:
            best, bd = p, p @ p
    return best


def lambertian_spot_irradiance(beam, center, normal, tangent, size, rho, observer, lit_normal):
    """Irradiance at ``observer`` from a Lambertian plate (f_r = rho/pi) lit by the beam,
    summed over the spot without the far-field step: each ray's power dP (attenuated
    laser->hit) reflects to E = rho/pi cos(theta_r) dP exp(-mu |O - p|)/|O - p|^2, theta_r
    from the lit face's normal (laser-safety.md 3.1 diffuse / BRDF forms; Beer-Lambert on
    each leg). Far from the spot this is rho/pi cos(theta_r) P_spot exp(-mu R2)/R2^2."""
    corners = plate_corners(center, normal, tangent, size)
    R = float(np.dot(np.asarray(center, float) - beam.pos, beam.u))
    poly = _ccw(beam.project(corners, R))
    w = beam.w(R)
    O = np.asarray(observer, float)
    nl = unit(lit_normal)

    def weight(x, z):
        hits = beam.unproject(np.stack([x, z], 1), R, center, normal)
        v = O - hits
        L2 = np.einsum("ij,ij->i", v, v)
        L = np.sqrt(L2)
        cos_r = np.clip((v @ nl) / L, 0.0, None)
        att = np.exp(-beam.mu * (np.linalg.norm(hits - beam.pos, axis=1) + L))
        return rho / math.pi * cos_r * att / L2

    return beam.P * gaussian_polygon_fraction(poly, w, weight)


def _ccw(poly):
    c = poly.mean(axis=0)
    ang = np.arctan2(poly[:, 1] - c[1], poly[:, 0] - c[0])
    return poly[np.argsort(ang)]


def rect_peak_irradiance(beam, R, x1, x2, y1, y2):
    """Highest beam irradiance on a rectangle normal to the axis at range R (coordinates
    in the transverse plane): the Gaussian at the rectangle's point nearest the axis,
    attenuated exp(-mu R)."""
    x = min(max(0.0, x1), x2)
    y = min(max(0.0, y1), y2)
    w = beam.w(R)
    return beam.peak(R) * math.exp(-(x * x + y * y) / (w * w)) * math.exp(-beam.mu * R)


# --------------------------------------------------------------------------- NOHDs


def folded_specular_range(power, rho, a, phi, mpe, mu=0.0, r_max=1e7):
    """Folded range R where rho 4P exp(-mu R)/(pi (a + R phi)^2) = MPE (laser-safety.md 3.1,
    specular NOHD with Beer-Lambert; range-safety.md 2: bracket and bisect, the left side
    decreases monotonically). Returns 0 if already below the MPE at R = 0."""
    def f(R):
        D = a + R * phi
        return math.inf if D == 0 else rho * 4 * power * math.exp(-mu * R) / (math.pi * D * D) - mpe

    if f(0.0) <= 0:
        return 0.0
    lo, hi = 0.0, 1.0
    while f(hi) > 0:
        hi *= 2
        if hi > r_max:
            raise ValueError("no root below r_max")
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        if f(mid) > 0:
            lo = mid
        else:
            hi = mid
    return 0.5 * (lo + hi)


def lambert_w_range(R0, mu):
    """a = 0 closed form R = (2/mu) W(mu R0 / 2) (laser-safety.md 3.1, range-safety.md 2)."""
    if mu == 0:
        return R0
    return float((2.0 / mu) * lambertw(mu * R0 / 2.0).real)


def aperture_cap(reflected_power_w, aperture_m=7e-3):
    """The most a reflected beam of power P can deliver averaged over the limiting
    aperture (diameter d; 7 mm for 400-1400 nm, range-safety.md 10): P / (pi d^2 / 4),
    whatever its shape. A mirror at grazing incidence, or much smaller than the aperture,
    is bound by it rather than by rho E_beam."""
    return reflected_power_w / (math.pi * aperture_m**2 / 4.0)


def capped_range(cap_w_m2, mpe, mu):
    """Distance over which a level ``cap`` attenuated as exp(-mu D) stays >= MPE:
    ln(cap / MPE) / mu (inf without attenuation; 0 when cap < MPE)."""
    if cap_w_m2 < mpe:
        return 0.0
    return math.inf if mu == 0 else math.log(cap_w_m2 / mpe) / mu


# --------------------------------------------------------------------------- curved reflectors


def sphere_intensity(rho, r, E0, w, psi):
    """Convex sphere, Gaussian beam centred on it: I(psi) = rho (r^2/4) E0
    exp(-r^2 sin^2(psi/2) / w^2) [W/sr], psi from the back-reflection direction
    (range-safety.md section 4)."""
    return rho * r * r / 4.0 * E0 * np.exp(-(r * np.sin(psi / 2.0)) ** 2 / (w * w))


def cylinder_fan_irradiance(rho, E_inc, r, psi, D):
    """Cylinder with axis normal to the beam, thin fan: E(D) = rho E r cos(psi/2) / (2 D)
    (range-safety.md section 4); E_inc is the incident irradiance at the impact parameter
    h = r sin(psi/2)."""
    return rho * E_inc * r * np.cos(psi / 2.0) / (2.0 * D)


def cylinder_fan_exact(rho, r, Rs, w, E0, observer_xy):
    """Geometric-optics irradiance of the fan of a cylinder (radius r, axis normal to the
    beam) at an observer in the plane normal to the axis, without the far-field step.

    In-plane coordinates: X across the beam, Y along it, the cylinder axis at the origin,
    the virtual source at (0, -Rs). The incident ray crossing Y = 0 at x0 carries
    E0 exp(-x0^2/w^2) per unit x0 and unit height; find the x0 whose reflected ray passes
    through the observer (exact circle intersection, mirror reflection), then
    E = rho E0 exp(-x0^2/w^2) / |dW/dx0| (ray spacing at the observer) times the
    out-of-plane spreading l0/(|p - S| + |O - p|) of the diverging beam (l0 = |S -> (x0, 0)|).
    The same physics as rho E r cos(psi/2)/(2D) (range-safety.md 4) without its O(r/D)
    error. Returns (irradiance, hit point)."""
    from scipy.optimize import brentq

    S = np.array([0.0, -Rs])
    O = np.asarray(observer_xy, float)

    def ray(x0):
        d = np.array([x0, Rs]) / math.hypot(x0, Rs)
        c = Rs * d[0] * np.array([d[1], -d[0]])  # foot of the perpendicular from the axis (stable form)
        p = c - math.sqrt(max(r * r - float(c @ c), 0.0)) * d
        n = p / r
        return p, d - 2 * float(d @ n) * n, d

    def dist(x0):
        p, out, _ = ray(x0)
        v = O - p
        return out[0] * v[1] - out[1] * v[0]

    xmax = r * Rs / math.sqrt(Rs * Rs - r * r) * (1 - 1e-9)
    sgn = 1.0 if O[0] > 0 else -1.0
    x0 = brentq(dist, 0.0, sgn * xmax, xtol=1e-15 * r, rtol=1e-14) if sgn > 0 else -brentq(
        lambda x: dist(-x), 0.0, xmax, xtol=1e-15 * r, rtol=1e-14)
    p, out, _ = ray(x0)
    if float((O - p) @ out) <= 0:
        raise ValueError("observer behind the reflecting point")
    delta = 1e-4 * min(w, r)
    spacing = abs(dist(x0 + delta) - dist(x0 - delta)) / (2 * delta)
    l0 = math.hypot(x0, Rs)
    zfac = l0 / (np.linalg.norm(p - S) + np.linalg.norm(O - p))
    return rho * E0 * math.exp(-x0 * x0 / (w * w)) / spacing * zfac, p


def _circle_reflection(r, Rs, X, Y, n_grid=801):
    """In the plane of the axis and observers O = (X > 0, Y) (arrays; axis along +Y, the
    circle of radius r at the origin, the point source at (0, -Rs)): the x0 where the
    incident ray crosses Y = 0 whose mirror reflection passes through O (the first sign
    change of O's side of the reflected ray from 0 out to the limb, refined by 80
    bisections), the hit points, and the ray spacing |dW/dx0| at O (central difference)."""
    X, Y = np.atleast_1d(np.asarray(X, float)), np.atleast_1d(np.asarray(Y, float))

    def side(x0, rows=slice(None)):
        h = np.hypot(x0, Rs)
        dx, dy = x0 / h, Rs / h
        cx, cy = Rs * dx * dy, -Rs * dx * dx
        root = np.sqrt(np.maximum(r * r - cx * cx - cy * cy, 0.0))
        px, py = cx - root * dx, cy - root * dy
        dn = (dx * px + dy * py) / r
        ox, oy = dx - 2 * dn * px / r, dy - 2 * dn * py / r
        return ox * (Y[rows] - py) - oy * (X[rows] - px), (px, py, ox, oy)

    xmax = r * Rs / math.sqrt(Rs * Rs - r * r) * (1 - 1e-9)
    grid = np.linspace(0.0, xmax, n_grid)
    vals = side(grid[None, :], (slice(None), None))[0]
    change = np.sign(vals[:, 1:]) != np.sign(vals[:, :-1])
    if not np.all(change.any(axis=1)):
        raise ValueError("no reflecting ray reaches an observer")
    k = np.argmax(change, axis=1)
    lo, hi = grid[k], grid[k + 1]
    f_lo = side(lo)[0]
    for _ in range(80):
        mid = 0.5 * (lo + hi)
        f_mid = side(mid)[0]
        same = np.sign(f_mid) == np.sign(f_lo)
        lo, f_lo, hi = np.where(same, mid, lo), np.where(same, f_mid, f_lo), np.where(same, hi, mid)
    x0 = 0.5 * (lo + hi)
    _, (px, py, ox, oy) = side(x0)
    if np.any(ox * (X - px) + oy * (Y - py) <= 0):
        raise ValueError("observer behind the reflecting point")
    a, b = np.maximum(x0 - 1e-6 * r, 0.0), x0 + 1e-6 * r
    return x0, np.stack([px, py], axis=-1), np.abs(side(b)[0] - side(a)[0]) / (b - a)


def fan_pupil_factor(r, Rs, w, observer_xy, hit_xy, aperture_m=7e-3):
    """The mean over the limiting aperture (a disk of diameter ``aperture_m`` facing the
    fan) of a cylinder's thin fan over its value at the disk's centre, for an observer
    in the plane through the beam normal to the axis. Along the axis the reflection keeps
    the incident beam's Gaussian, spreading from the virtual source along the unfolded
    path: 1/e radius ``W = w (|S -> P| + |P -> O|) / l0`` (the inverse of the out-of-plane
    factor of :func:`cylinder_fan_exact`); across it the fan varies on the scale of its
    width, metres away (ignored). Mean of ``exp(-y^2 / W^2)`` over the disk by 64-node
    Gauss-Legendre in y with chord weights ``2 sqrt(a^2 - y^2) / (pi a^2)``."""
    O, p = np.asarray(observer_xy, float), np.asarray(hit_xy, float)
    x0 = float(p[0]) * Rs / (float(p[1]) + Rs)
    W = w * (math.hypot(p[0], p[1] + Rs) + float(np.linalg.norm(O - p))) / math.hypot(x0, Rs)
    a = aperture_m / 2
    t, wt = np.polynomial.legendre.leggauss(64)
    th = 0.5 * math.pi * t  # y = a sin(th): smooth at the rim
    y, c = a * np.sin(th), a * np.cos(th)
    return float((wt * 0.5 * math.pi * c * 2 * c * np.exp(-(y / W) ** 2)).sum() / (math.pi * a * a))


def sphere_mirror_exact(rho, r, Rs, w, E0, observer_xy):
    """Geometric-optics irradiance of a mirror sphere (radius r, centred on the beam axis,
    virtual source Rs before its centre) at observers, without the far-field step.

    By symmetry about the axis the reflecting ray lies in the plane of the axis and the
    observer (``observer_xy`` = (distance from the axis > 0, position along the beam),
    arrays allowed), where the sphere's section is a circle: the in-plane ray crossing
    the centre's plane at x0 and its spacing |dW/dx0| at the observer
    (:func:`_circle_reflection`, as :func:`cylinder_fan_exact`). Out of the plane, rays
    at azimuth dphi about the axis leave the ring x0 dphi and reach the observer's ring
    X_O dphi, so ``E = rho E0 exp(-x0^2/w^2) |x0| / (|dW/dx0| X_O)`` (the annulus' power
    x0 dx0 dphi over the area dW X_O dphi). Its far field is
    ``rho (r^2/4) E0 exp(-r^2 sin^2(psi/2)/w^2) / D^2`` (range-safety.md 4).
    Returns (irradiance, hit point), scalars for one observer."""
    X, Y = observer_xy
    x0, p, spacing = _circle_reflection(r, Rs, X, Y)
    e = rho * E0 * np.exp(-x0 * x0 / (w * w)) * np.abs(x0) / (spacing * np.abs(np.atleast_1d(np.asarray(X, float))))
    return (float(e[0]), p[0]) if np.ndim(X) == 0 else (e, p)


def _mirror_hits(beam, kind, centre, axis, r, half_length, s, base, w):
    """Rays of ``beam`` through transverse coordinates s (N, 2) (units of its 1/e radius w
    at the plane through ``base`` normal to its axis), from its virtual point source, onto
    the outside of a sphere or a finite cylinder (exact quadratic; a cylinder's hit must
    lie within ``half_length`` of the centre along the axis): (hit mask, hit points,
    unit reflected directions)."""
    at = base + w * (s[:, :1] * beam.e1 + s[:, 1:] * beam.e2)
    src = beam.source
    d = at - src
    d /= np.linalg.norm(d, axis=1)[:, None]
    o = src - centre
    if kind == "cylinder":
        dp, op = d - (d @ axis)[:, None] * axis, o - float(o @ axis) * axis
    else:
        dp, op = d, np.broadcast_to(o, d.shape)
    qa, qb, qc = (dp * dp).sum(1), 2 * (dp * op).sum(1), (op * op).sum(-1) - r * r
    disc = qb * qb - 4 * qa * qc
    t = (-qb - np.sqrt(np.maximum(disc, 0.0))) / (2 * np.maximum(qa, 1e-300))
    x = src + t[:, None] * d
    rel = x - centre
    hit = (disc > 0) & (t > 0)
    if kind == "cylinder":
        along = rel @ axis
        hit &= np.abs(along) <= half_length
        rel = rel - along[:, None] * axis
    n = rel / r
    return hit, x, d - 2 * (d * n).sum(1)[:, None] * n


def mirror_disk_bracket(beam, kind, centre, axis, r, half_length, rho, observer, radius, window=7.0, rtol=1e-2,
                        max_levels=6):
    """Brute-force bounds on the mean irradiance [W/m^2] over a disk of ``radius`` centred
    at ``observer`` of the mirror beam of a convex sphere or cylinder (reflectance rho,
    independent of angle) lit by ``beam`` (its virtual point source must be > 0 behind the
    aperture): rays are traced onto the exact surface and reflected (:func:`_mirror_hits`),
    and the power of those crossing the disk is summed. The disk is normal to the
    reflected ray passing nearest its centre (found on a 0.02 w grid of rays).

    The transverse square |s_i| <= ``window`` (in units of the beam's 1/e radius at the
    mirror's centre; the tail beyond carries exp(-window^2)) is cut in cells, each with its
    exact Gaussian power (erf). A cell whose centre and 4 corners all reach the disk's
    plane inside the disk, farther than its image's size from the rim (1.2 x the largest
    corner-to-centre distance: 1 for an affine map), counts whole; one whose rays that
    reach the plane all land outside farther than that counts 0; the others are split
    6 x 6, until the undecided power is below ``rtol`` of the counted one (or
    ``max_levels``). A cell partly on the surface (the cylinder's end, the silhouette) uses
    the image size s_near of the whole cells within 11 radii of the disk (their largest);
    a cell farther out at most 4 s_near (near the silhouette grazing rays stretch a cell's
    image without bound but send it forward, away from eyes placed off the grazing
    directions, as the tests place them). Returns (lower, upper, normal): lower counts the
    undecided cells as 0, upper as wholly in."""
    centre, axis, o_pt = (np.asarray(v, float) for v in (centre, axis, observer))
    axis = unit(axis)
    r_plane = float((centre - beam.pos) @ beam.u)
    base, w = beam.pos + r_plane * beam.u, beam.w(r_plane)
    g = np.arange(-window, window + 1e-9, 0.02)
    grid = np.stack(np.meshgrid(g, g, indexing="ij"), -1).reshape(-1, 2)
    hit, x, out = _mirror_hits(beam, kind, centre, axis, r, half_length, grid, base, w)
    v = o_pt - x
    along_ray = (v * out).sum(1)
    miss = np.linalg.norm(v - along_ray[:, None] * out, axis=1)
    miss = np.where(hit & (along_ray > 0), miss, np.inf)
    if not np.isfinite(miss.min()):
        return 0.0, 0.0, None
    nrm = out[int(np.argmin(miss))]

    def land(s):
        ok, xs, outs = _mirror_hits(beam, kind, centre, axis, r, half_length, s, base, w)
        den = outs @ nrm
        tt = ((o_pt - xs) @ nrm) / np.where(np.abs(den) > 1e-300, den, 1e-300)
        y = xs + tt[:, None] * outs
        ok &= (den > 0) & (tt > 0)
        return ok, np.where(ok[:, None], y, np.nan)

    n0 = int(round(2 * window / 0.1))
    h = 2 * window / n0
    c1 = -window + h * (np.arange(n0) + 0.5)
    cells = np.stack(np.meshgrid(c1, c1, indexing="ij"), -1).reshape(-1, 2)
    corners = np.array([[-0.5, -0.5], [0.5, -0.5], [0.5, 0.5], [-0.5, 0.5]])
    counted, pending = 0.0, 0.0
    for level in range(max_levels):
        pts = np.concatenate([cells[:, None, :], cells[:, None, :] + h * corners[None]], axis=1)  # (K, 5, 2)
        ok, y = land(pts.reshape(-1, 2))
        ok, y = ok.reshape(-1, 5), y.reshape(-1, 5, 3)
        dist = np.linalg.norm(y - o_pt, axis=2)
        spread = np.linalg.norm(y[:, 1:] - y[:, :1], axis=2)  # corner to centre
        size = 1.2 * np.max(np.where(np.isnan(spread), -1.0, spread), axis=1)
        frac = 0.25 * (erf(cells[:, 0] + h / 2) - erf(cells[:, 0] - h / 2)) * (erf(cells[:, 1] + h / 2) - erf(cells[:, 1] - h / 2))
        all_ok = ok.all(axis=1)
        # a cell partly on the surface: its image's size from the whole cells nearby (their
        # largest), or from its own rays if larger
        near = all_ok & (dist[:, 0] < 11 * radius + size)
        ref_size = size[near].max() if np.any(near) else (size[all_ok].max() if np.any(all_ok) else 0.0)
        size = np.where(near, size, np.minimum(np.where(all_ok, size, ref_size), 4 * ref_size))
        closest = np.nanmin(np.where(ok, dist, np.inf), axis=1)
        inside = all_ok & (dist[:, 0] < radius - size)
        outside = closest > radius + size
        counted += float(frac[inside].sum())
        todo = ~inside & ~outside
        pending = float(frac[todo].sum())
        if pending <= rtol * counted or level == max_levels - 1 or not np.any(todo):
            break
        k = 6
        sub = h * ((np.arange(k) + 0.5) / k - 0.5)
        offs = np.stack(np.meshgrid(sub, sub, indexing="ij"), -1).reshape(-1, 2)
        cells = (cells[todo][:, None, :] + offs[None]).reshape(-1, 2)
        h /= k
    scale = rho * beam.P / (math.pi * radius * radius)
    return scale * counted, scale * (counted + pending), nrm


# --------------------------------------------------------------------------- optics


def optical_gain(magnification, objective_diameter_m, transmission=1.0, beam_diameter_m=math.inf, pupil_m=7e-3):
    """Collecting gain of viewing optics (laser-safety.md 3.1, ENOHD): K = min(tau M^2,
    tau D0^2/g^2, tau D_b^2/g^2), g = 7 mm, each term clipped to >= 1. For diffuse light
    the field fills the objective (D_b = infinity)."""
    t = transmission
    terms = [t * magnification**2, t * (objective_diameter_m / pupil_m) ** 2, t * (beam_diameter_m / pupil_m) ** 2]
    return min(max(x, 1.0) for x in terms)


def aperture_irradiance(power, w, d, optics=None, aperture_m=7e-3):
    """What the MPE is compared with (range-safety.md section 10): the power of a Gaussian
    beam (1/e radius w, power ``power`` at the range) through a disk of diameter D_f
    (``aperture_m``) centred d off its axis, over the disk's area; with optics
    {magnification M, objective_diameter_m D_o, transmission tau} the larger of that and
    tau P F(min(D_o, 7 mm M) / 2) / (pi (3.5 mm)^2)."""
    a = aperture_m / 2
    eye = power * disk_fraction(a, d, w) / (math.pi * a * a)
    if not optics:
        return eye
    a_c = min(optics["objective_diameter_m"], 7e-3 * optics["magnification"]) / 2
    return max(eye, optics.get("transmission", 1.0) * power * disk_fraction(a_c, d, w) / (math.pi * 3.5e-3**2))


def disk_polygon_fraction(poly, centre, radius, w, n_theta=2048, n_rho=24):
    """Fraction of a centred circular Gaussian (1/e radius w) inside the intersection of
    the disk (centre, radius) and a convex polygon (vertices (N, 2) in order, either
    orientation): polar coordinates about the disk's centre; along each direction the
    polygon is an interval of the radius (intersection of its edges' half-planes), the
    radial integral by Gauss-Legendre over that interval, the angular one by the
    trapezoid rule (kinks where the interval's ends switch edges: error O(n_theta^-2))."""
    poly = np.asarray(poly, float)
    c = np.asarray(centre, float)
    area2 = np.sum(poly[:, 0] * np.roll(poly[:, 1], -1) - np.roll(poly[:, 0], -1) * poly[:, 1])
    if area2 < 0:
        poly = poly[::-1]
    edge = np.roll(poly, -1, axis=0) - poly
    nrm = np.stack([edge[:, 1], -edge[:, 0]], axis=1)  # outward for counter-clockwise
    b = np.sum(nrm * poly, axis=1) - nrm @ c  # inside: nrm . (c + rho u) <= nrm . vertex
    th = 2 * math.pi * (np.arange(n_theta) + 0.5) / n_theta
    u = np.stack([np.cos(th), np.sin(th)], axis=1)
    k = u @ nrm.T  # (T, E): rho k <= b
    with np.errstate(divide="ignore", invalid="ignore"):
        lim = b[None, :] / k
    hi = np.min(np.where(k > 0, lim, np.inf), axis=1)
    lo = np.max(np.where(k < 0, lim, -np.inf), axis=1)
    blocked = np.any((k == 0) & (b[None, :] < 0), axis=1)
    lo, hi = np.maximum(lo, 0.0), np.minimum(hi, radius)
    ok = (hi > lo) & ~blocked
    x, wt = np.polynomial.legendre.leggauss(n_rho)
    rho = lo[:, None] + (hi - lo)[:, None] * (x[None, :] + 1) / 2
    pts = c[None, None, :] + rho[:, :, None] * u[:, None, :]
    g = np.exp(-np.sum(pts * pts, axis=2) / (w * w)) / (math.pi * w * w) * rho
    inner = np.sum(g * wt[None, :], axis=1) * (hi - lo) / 2
    return float(np.sum(np.where(ok, inner, 0.0)) * 2 * math.pi / n_theta)


def mirror_aperture_irradiance(beam, corners, observer, mirror_point, normal, aperture_m=7e-3):
    """The flat mirror's reflected beam through an eye's aperture (range-safety.md 4 and
    10): unfold at the mirror (the eye's image in the mirror plane), and integrate the
    incident Gaussian over the part of the aperture's disk (normal to the axis at the
    image's range, centred on the image) whose rays from the virtual source reach the
    mirror: the mirror's corners projected centrally onto that plane (``beam.project``),
    cut with the disk (:func:`disk_polygon_fraction`). Returns P F / (pi a^2), before the
    reflectance and attenuation."""
    o = np.asarray(observer, float)
    n = unit(normal)
    image = o - 2 * np.dot(o - np.asarray(mirror_point, float), n) * n
    R = float(np.dot(image - beam.pos, beam.u))
    quad = beam.project(np.asarray(corners, float), R)
    centre = beam.project(image[None], R)[0]
    a = aperture_m / 2
    return beam.P * disk_polygon_fraction(quad, centre, a, beam.w(R)) / (math.pi * a * a)


# --------------------------------------------------------------------------- scene text


def fmt(x):
    return repr(float(x))


def vec(v):
    return "[" + ", ".join(fmt(x) for x in v) + "]"


def scene_text(*, power, a, phi, position, aim, targets, observers=(), mu=0.0, wavelength_nm=1064.0,
               duration_s=10.0, analysis="direction_grid_deg = 10.0\nrefine_levels = 0\n"):
    """A scene file as TOML text. ``targets``: list of dicts with keys name, shape, center,
    normal, tangent, size, material (inline TOML table text), optional back (same).
    ``observers``: list of (name, point, optics-or-None) with optics a dict
    {magnification, objective_diameter_m, transmission}."""
    out = [
        'name = "validation"',
        "[laser]",
        f"wavelength_nm = {fmt(wavelength_nm)}",
        f"power_w = {fmt(power)}",
        f"beam_diameter_m = {fmt(a)}",
        f"divergence_rad = {fmt(phi)}",
        f"position_m = {vec(position)}",
        f"aim_m = {vec(aim)}",
        "[exposure]",
        f"duration_s = {fmt(duration_s)}",
        "[atmosphere]",
        f"attenuation_per_m = {fmt(mu)}",
    ]
    for t in targets:
        out += [
            "[[targets]]",
            f'name = "{t["name"]}"',
            f'shape = "{t["shape"]}"',
            f"center_m = {vec(t['center'])}",
            f"normal = {vec(t['normal'])}",
            f"tangent = {vec(t['tangent'])}",
            f"size_m = {vec(t['size'])}",
            f"material = {t['material']}",
        ]
        if t.get("back"):
            out.append(f"back = {t['back']}")
    for name, p, optics in observers:
        out += ["[[observers]]", f'name = "{name}"', f"points_m = [{vec(p)}]"]
        if optics:
            out.append(
                "optics = { magnification = %s, objective_diameter_m = %s, transmission = %s }"
                % (fmt(optics["magnification"]), fmt(optics["objective_diameter_m"]), fmt(optics.get("transmission", 1.0)))
            )
    if analysis:
        out += ["[analysis]", analysis]
    return "\n".join(out) + "\n"


def lambertian(rho):
    return '{ model = "lambertian", reflectance = %s }' % fmt(rho)


def specular(rho):
    return '{ model = "specular", reflectance = %s }' % fmt(rho)


# --------------------------------------------------------------------------- test helpers


def log_uniform(lo, hi):
    """A hypothesis strategy for floats uniform in log between lo and hi."""
    return st.floats(math.log(lo), math.log(hi)).map(math.exp)


def off_incident_beam(beam, p, factor=2.0):
    """True if p lies outside the incident beam (more than factor x D from its axis, or
    behind the laser). The Gaussian's wings still reach it (exp(-4 factor^2) of the
    peak at factor x D): tests of a reflection compare the reflected part alone."""
    d = np.asarray(p) - beam.pos
    R = float(d @ beam.u)
    r = math.sqrt(max(float(d @ d) - R * R, 0.0))
    return R < 0 or r > factor * beam.diameter(R)


def farthest_root(irradiance, c, w, mpe, rs):
    """Farthest radius along ``c + r w`` where ``irradiance`` (points (N, 3) -> W/m^2)
    reaches ``mpe``: the last hot radius of the increasing scan ``rs``, then bisected to
    1e-7 (relative) toward the next; 0 where none is hot. The scan must end beyond the
    hazard (asserted)."""
    hot = np.flatnonzero(irradiance(c + rs[:, None] * w) >= mpe)
    if not len(hot):
        return 0.0
    assert hot[-1] < len(rs) - 1, "the reference scan did not reach beyond the hazard"
    lo, hi = rs[hot[-1]], rs[hot[-1] + 1]
    while hi - lo > 1e-7 * hi:
        mid = 0.5 * (lo + hi)
        if irradiance((c + mid * w)[None])[0] >= mpe:
            lo = mid
        else:
            hi = mid
    return hi
