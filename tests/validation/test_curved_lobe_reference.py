"""Keep-out lobes of a CURVED diffuse spot (a Lambertian sphere or capped cylinder in a
collimated Gaussian beam): the engine's lobe against the section-10 integral
(range-safety.md section 10) written here from the formula and the geometry alone,
never from the engine's physics:

    E(o) = int over the body's surface of E_inc(p) rho / pi cos(theta_o) / |o - p|^2 dA,
    cos(theta_o) = (o - p).n / |o - p|  (0 where n.(o - p) <= 0: the point faces away),
    E_inc(p) = P / (pi w^2) exp(-r_perp(p)^2 / w^2) max(0, n.(-u))

(the beam's convention as tests/validation/test_near_field_lobes.py and _refs.Beam: the
scene's ``beam_diameter_m`` a is the 1/e diameter, w = (a + R phi) / 2 the 1/e radius;
u the beam's direction, r_perp the distance from its axis). A convex body in a collimated
beam: a point is lit iff n.(-u) > 0 and seen from o iff n.(o - p) > 0 (no other occlusion).

Quadrature (tensor Gauss-Legendre, 8 nodes a panel in each surface parameter, each
parameter's range restricted to where the Gaussian exceeds exp(-42) of its peak,
T = 6.5 w from the beam's axis):

- sphere (centre C, radius r): polar angle theta from -u (lit: theta < 90 deg, where
  E_inc -> 0 smoothly) and azimuth phi; dA = r^2 sin(theta) dtheta dphi;
- cylinder (axis a, radius r, half length h): the lit half of the mantle, alpha in
  [-90, 90] deg about the direction of -u across the axis, s along the axis; dA = r dalpha ds;
  each end disk lit when (+-a).(-u) > 0 (polar rho, beta; dA = rho drho dbeta).

Panels are at most w / k of arc in each parameter (k = the refinement: 1, 2, 4, ...).
The reference root along ``c + t w`` (c: the spot's power centroid, the lobe's origin) is
the farthest t where E >= MPE: a geometric scan from 1e-4 m to the point-form bound
sqrt(rho P / (pi MPE)) plus the body's size (nothing beyond it can reach the MPE:
E <= rho / pi P / dist^2), then bisection to 1e-7; refined (k doubled) until the root
moves < 0.1 % (REF_RTOL), the finer root kept.

The engine's lobe (hazard.physics.keepout.nohd_range_fn -> near_field_lobe.NearLobeFn)
along world directions ``fn(w @ spot.mean_frame.T)``, MPE the engine's own
(ocular_mpe at the scene's 1064 nm, 10 s: an input, not under test). Checks:

- never short (the safety assertion): lobe >= root (1 - RANGE_TOL), RANGE_TOL = 0.5 %
  in range (the integral's 1 % tolerance, as the flat test);
- points just off the body (a gap of w and 4 w) where the reference reaches the MPE
  and that lie outside the incident beam are inside the lobe (whatever its origin);
- the lobe/root ratio and the point form are printed (``-s``); no tightness bound is
  asserted: the lobe is up to 10x the root on small spheres (the point form and the
  scan's step decide there) and the cases it would bound are SHORT already.

Found (2026-11-27, main 39495b9, the same with x43's curved bound /work/notes/x43_curved_bound.patch):
the lobe was SHORT where a curved spot sends light at or below its mean plane or low
over it (the integral, the engine's own hazard.physics.engine.near_field_w_m2 included,
reaches the MPE there: at 4 points checked it is within -5.5 % to +4.3 % of this reference):
0 m beside a 0.5 m sphere where the root is 3.8 m. The spot's point form took the mean
frame alone (0 at and below its plane); now the larger of it and the sum over the spot's
own frames, and the lobe's grid goes on below the mean plane. Still SHORT (strict xfails):
a direction between grid nodes by 0.65 % (the lobe's 0.5 % floor), and an edge-on
cylinder whose power centroid (the lobe's origin) lies 47 m from the body; see SHORT.
"""

from __future__ import annotations

import math
import time

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import scenes
from hazard.physics import near_field_lobe
from hazard.physics.keepout import nohd_range_fn
from hazard.physics.mpe import ocular_mpe
from hazard.pipeline.spots import ray_scene, trace_beam

from . import _refs as ref

A, PHI = 0.05, 1e-9  # a collimated beam: 1/e diameter 5 cm
RHO = 0.8
MPE = ocular_mpe(1064.0, 10.0).irradiance_w_m2  # scene_text's 1064 nm, 10 s: an input, not under test
RANGE_TOL = 0.005  # never short by more than this (the integral's 1 % tolerance in range)
REF_RTOL = 1e-3  # the reference's own convergence: the root moves less than this on refinement
T_GAUSS = 6.5  # the Gaussian's support kept [w]: exp(-42) of the peak beyond
U = np.array([0.0, 1.0, 0.0])  # the beam along +y, from (0, -R1, 0) to the origin
_G, _GW = np.polynomial.legendre.leggauss(8)


def _gl(lo, hi, panels):
    """Composite 8-node Gauss-Legendre nodes and weights on [lo, hi]."""
    e = np.linspace(lo, hi, int(panels) + 1)
    mid, half = (e[:-1] + e[1:]) / 2, np.diff(e) / 2
    return (mid[:, None] + half[:, None] * _G).ravel(), (half[:, None] * _GW).ravel()


def _beam_irr(p, power, w):
    """The collimated Gaussian's irradiance across the beam [W/m^2] at points p (..., 3)."""
    r2 = p[..., 0] ** 2 + p[..., 2] ** 2
    return power / (math.pi * w * w) * np.exp(-r2 / (w * w))


# ------------------------------------------------------------------ the reference's surface quadrature
def sphere_nodes(power, w, centre, r, k=1):
    """Surface nodes (K, 3), normals (K, 3) and E_inc dA (K,) [W] of the lit sphere."""
    e1, e2 = np.array([1.0, 0.0, 0.0]), np.array([0.0, 0.0, 1.0])
    b0 = np.array([-centre[0], -centre[2]])  # the beam's axis across the beam, about the centre
    rho0, T = float(np.hypot(*b0)), T_GAUSS * w
    lo, hi = max(0.0, rho0 - T), min(r, rho0 + T)
    if lo >= r:
        return np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0)
    th_lo, th_hi = math.asin(lo / r), math.asin(hi / r)
    if rho0 > T:
        half = math.asin(T / rho0)
        ph0 = math.atan2(b0[1], b0[0])
        ph_lo, ph_hi = ph0 - half, ph0 + half
    else:
        ph_lo, ph_hi = -math.pi, math.pi
    nt = k * max(2, math.ceil(r * (th_hi - th_lo) / w))
    npp = k * max(4, math.ceil(hi * (ph_hi - ph_lo) / w))
    th, tw = _gl(th_lo, th_hi, nt)
    ph, pw = _gl(ph_lo, ph_hi, npp)
    TH, PH = np.meshgrid(th, ph, indexing="ij")
    n = (np.sin(TH) * np.cos(PH))[..., None] * e1 + (np.sin(TH) * np.sin(PH))[..., None] * e2 - np.cos(TH)[..., None] * U
    p = centre + r * n
    dP = _beam_irr(p, power, w) * np.cos(TH) * r * r * np.sin(TH) * np.outer(tw, pw)
    return p.reshape(-1, 3), n.reshape(-1, 3), dP.ravel()


def cylinder_nodes(power, w, centre, axis, r, half_len, k=1):
    """Surface nodes, normals and E_inc dA [W] of the lit part of a capped cylinder."""
    a = ref.unit(axis)
    b = -U - (-U @ a) * a
    sb = float(np.linalg.norm(b))  # |(-u) across the axis|: the mantle's largest cos(incidence)
    T = T_GAUSS * w
    ps, ns, dps = [], [], []
    if sb > 1e-12:
        b = b / sb
        c = np.cross(a, b)
        # s where the axis point is within T + r of the beam's axis (across the beam: x, z)
        cx, ax = np.array([centre[0], centre[2]]), np.array([a[0], a[2]])
        qa, qb, qc = ax @ ax, 2 * cx @ ax, cx @ cx - (T + r) ** 2
        if qa < 1e-15:
            s_lo, s_hi = (-half_len, half_len) if qc <= 0 else (0.0, 0.0)
        else:
            disc = qb * qb - 4 * qa * qc
            s_lo, s_hi = ((-qb - math.sqrt(disc)) / (2 * qa), (-qb + math.sqrt(disc)) / (2 * qa)) if disc > 0 else (0.0, 0.0)
            s_lo, s_hi = max(s_lo, -half_len), min(s_hi, half_len)
        if s_hi > s_lo:
            al, aw = _gl(-math.pi / 2, math.pi / 2, k * max(4, math.ceil(math.pi * r / w)))
            s, sw = _gl(s_lo, s_hi, k * max(2, math.ceil((s_hi - s_lo) / w)))
            AL, S = np.meshgrid(al, s, indexing="ij")
            n = np.cos(AL)[..., None] * b + np.sin(AL)[..., None] * c
            p = centre + S[..., None] * a + r * n
            dP = _beam_irr(p, power, w) * np.cos(AL) * sb * r * np.outer(aw, sw)
            ps.append(p.reshape(-1, 3)), ns.append(n.reshape(-1, 3)), dps.append(dP.ravel())
    cos_cap = abs(float(a @ U))
    if cos_cap > 1e-12:  # the end disk facing the laser
        nc = -a if a @ U > 0 else a
        e1 = ref.unit(np.cross(nc, [0.3, 0.5, 0.7]))
        e2 = np.cross(nc, e1)
        rr, rw = _gl(0.0, r, k * max(2, math.ceil(r / w)))
        be, bw = _gl(-math.pi, math.pi, k * max(8, math.ceil(2 * math.pi * r / w)))
        RR, BE = np.meshgrid(rr, be, indexing="ij")
        p = centre + half_len * nc + (RR * np.cos(BE))[..., None] * e1 + (RR * np.sin(BE))[..., None] * e2
        dP = _beam_irr(p, power, w) * cos_cap * RR * np.outer(rw, bw)
        ps.append(p.reshape(-1, 3)), ns.append(np.broadcast_to(nc, p.shape).reshape(-1, 3)), dps.append(dP.ravel())
    if not ps:
        return np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0)
    return np.concatenate(ps), np.concatenate(ns), np.concatenate(dps)


def ref_irradiance(nodes, o):
    """The section-10 integral [W/m^2] at observers ``o`` (M, 3)."""
    p, n, dP = nodes
    keep = dP > 0
    p, n, dP = p[keep], n[keep], dP[keep]
    o = np.atleast_2d(np.asarray(o, float))
    out = np.empty(len(o))
    step = max(1, (1 << 21) // max(len(p), 1))
    for s in range(0, len(o), step):
        y = o[s:s + step, None, :] - p[None]
        r2 = np.einsum("mij,mij->mi", y, y)
        cos_n = np.clip(np.einsum("mij,ij->mi", y, n), 0.0, None)
        out[s:s + step] = (dP * RHO / math.pi * cos_n / r2 ** 1.5).sum(axis=1)
    return out


def ref_root_once(nodes, c, w, r_max):
    """Farthest t along c + t w where the integral reaches MPE (0: nowhere): a geometric
    scan of 500 radii from 1e-4 m, then bisection (:func:`_refs.farthest_root`)."""
    return ref.farthest_root(lambda p: ref_irradiance(nodes, p), c, w, MPE, np.geomspace(1e-4, r_max, 500))


def ref_root(make_nodes, c, w, r_max, k0=1, k_max=16):
    """The converged reference root: k doubled until the root moves < REF_RTOL (at most to
    ``k_max``); returns (root, k, relative change of the last refinement)."""
    k, prev = k0, ref_root_once(make_nodes(k0), c, w, r_max)
    while True:
        k *= 2
        cur = ref_root_once(make_nodes(k), c, w, r_max)
        change = abs(cur - prev) / max(cur, 1e-12) if (cur > 0 or prev > 0) else 0.0
        if change < REF_RTOL or k >= k_max:  # not converged at k_max (an observer within a panel of the surface):
            return max(cur, prev), k, change  # the larger, its last change widens the check's tolerance
        prev = cur


# ------------------------------------------------------------------ the engine's spot and lobe
class Case:
    """A body ``R1`` m down range in the beam: ``kind`` sphere or cylinder, diameter ``f`` beam
    diameters, centre offset (ox, oz) beam diameters across the beam, a cylinder's axis
    ``axis`` and length ``fl`` beam diameters; ``power`` [W]."""

    def __init__(self, kind, power, R1, f, ox=0.0, oz=0.0, axis=(1.0, 0.0, 0.0), fl=4.0, a=A, rot=None):
        self.kind, self.power, self.R1, self.a = kind, float(power), float(R1), float(a)
        self.Q = np.eye(3) if rot is None else ref.euler_rotation(*rot)  # the whole scene turned (the reference stays in the beam's frame)
        self.D = self.a + R1 * PHI
        self.w = self.D / 2
        self.r = f * self.D / 2
        self.centre = np.array([ox * self.D, 0.0, oz * self.D])
        self.axis = ref.unit(np.asarray(axis, float))
        self.half = fl * self.D / 2
        self.label = (f"{kind} d={2 * self.r:.4g} m ({f:.3g} D)" + (f" L={2 * self.half:.3g} m axis={np.round(self.axis, 3).tolist()}"
                      if kind == "cylinder" else "") + f" off=({ox:.3g},{oz:.3g}) D at {R1:g} m, a={self.a:g} m, P={power:.4g} W"
                      + ("" if rot is None else f", scene rotated by {tuple(rot)}"))

    def nodes(self, k):
        if self.kind == "sphere":
            return sphere_nodes(self.power, self.w, self.centre, self.r, k)
        return cylinder_nodes(self.power, self.w, self.centre, self.axis, self.r, self.half, k)

    def scene_text(self):
        Q = self.Q
        if self.kind == "sphere":
            t = dict(name="t", shape="sphere", center=Q @ self.centre, normal=Q @ np.array([0.0, 0.0, 1.0]),
                     tangent=Q @ np.array([1.0, 0.0, 0.0]), size=(2 * self.r,), material=ref.lambertian(RHO))
        else:
            t = dict(name="t", shape="cylinder", center=Q @ self.centre, normal=Q @ self.axis,
                     tangent=Q @ ref.unit(np.cross(self.axis, [0.3, 0.5, 0.7])), size=(2 * self.r, 2 * self.half),
                     material=ref.lambertian(RHO))
        return ref.scene_text(power=self.power, a=self.a, phi=PHI, position=Q @ np.array([0.0, -self.R1, 0.0]), aim=np.zeros(3),
                              targets=[t])

    def engine(self):
        """The spot (traced, no analysis), its lobe function and the world offset."""
        scene = scenes.loads(self.scene_text())
        spot = next(s for s in trace_beam(scene, ray_scene(scene, "embree", 1), 0.0).built.spots if s.target.name == "t")
        fn = nohd_range_fn(spot, MPE, 0.0, 1.0, None)
        return spot, fn, np.asarray(scene.offset_m, float)

    def extent(self):
        return 2 * (self.r + (self.half if self.kind == "cylinder" else 0.0))


def directions(spot, Q=None):
    """Named directions in the beam's frame (beam along +y): back toward the laser, along
    the beam, sideways, up, and low above the spot's mean plane (3 and 10 deg) and 20 deg
    below it. ``Q``: the scene's rotation (world = Q beam frame; None: none)."""
    f = np.asarray(spot.mean_frame, float) @ (np.eye(3) if Q is None else Q)  # the mean frame's axes in the beam's frame
    out = {"back to laser": -U, "along beam": U, "side +x": np.array([1.0, 0.0, 0.0]), "side -x": np.array([-1.0, 0.0, 0.0]),
           "up +z": np.array([0.0, 0.0, 1.0])}
    for el, az in [(3.0, 0.0), (3.0, 90.0), (10.0, 45.0), (45.0, 180.0), (-20.0, 0.0)]:
        e, z = math.radians(el), math.radians(az)
        out[f"mean el {el:g} az {az:g}"] = math.cos(e) * (math.cos(z) * f[0] + math.sin(z) * f[1]) + math.sin(e) * f[2]
    return {k: ref.unit(v) for k, v in out.items()}


def check(case, dirs=None, verbose=True, with_probes=True):
    """The lobe never short of the reference root along ``dirs`` (name -> unit vector in
    the beam's frame; default :func:`directions`). Returns rows (name, root, lobe, ratio, k, change, point form)."""
    t0 = time.perf_counter()
    spot, fn, off = case.engine()
    dirs = directions(spot, case.Q) if dirs is None else dirs
    names = list(dirs)
    w = np.array([dirs[n] for n in names])  # the beam's frame
    local = (w @ case.Q.T) @ np.asarray(spot.mean_frame, float).T  # the lobe function's (mean-frame) directions
    lobe = np.asarray(fn(local), float)
    point = np.asarray(fn.base(local), float) if hasattr(fn, "base") else np.full(len(w), np.nan)
    t_engine = time.perf_counter() - t0
    c = case.Q.T @ (np.asarray(spot.centroid, float) + off)  # the lobe's origin in the beam's frame
    r_max = math.sqrt(RHO * case.power / (math.pi * MPE)) + 2 * case.extent() + float(np.linalg.norm(c - case.centre)) + 0.1
    rows = []
    for j, name in enumerate(names):
        root, k, change = ref_root(case.nodes, c, w[j], r_max)
        rows.append((name, root, float(lobe[j]), float(lobe[j]) / root if root > 0 else math.inf, k, change, float(point[j])))
    t_ref = time.perf_counter() - t0 - t_engine
    if verbose:
        print(f"\n{case.label}: engine {t_engine:.2f} s, reference {t_ref:.2f} s, lobe type {type(fn).__name__},"
              f" scan_step_max_m={getattr(fn, 'info', {}).get('scan_step_max_m') if isinstance(fn, near_field_lobe.NearLobeFn) else None}")
        for name, root, lb, ratio, k, change, pf in rows:
            print(f"  {name:22s} root_ref={root:10.5g} m  lobe={lb:10.5g} m  ratio={ratio:9.4g}  point form={pf:10.5g} m"
                  f"  (k={k}, last change {change:.1e})")
    probes = probe_points(case, spot, fn, c, off) if with_probes else []
    check.last = (rows, fn, t_engine, t_ref, probes)  # for a report's table
    if verbose:
        for name, dist, lb, e, in_beam in probes:
            print(f"  probe {name:28s} |o-c|={dist:10.5g} m  lobe={lb:10.5g} m  E_ref/MPE={e / MPE:8.4g}"
                  f"{'  (in the incident beam)' if in_beam else ''}{'  OUTSIDE THE LOBE' if dist > lb * (1 + RANGE_TOL) else ''}")
    short = [(n, root, lb) for n, root, lb, _, _, change, _ in rows if lb < root * (1 - RANGE_TOL - change) - 1e-9]
    short += [(n, dist, lb) for n, dist, lb, e, in_beam in probes if not in_beam and dist > lb * (1 + RANGE_TOL) + 1e-9]
    assert not short, f"SHORT lobe for {case.label}: {short}"
    return rows, fn


def probe_points(case, spot, fn, c, off):
    """Points just off the body (a gap of w and 4 w from its surface, in the six axis
    directions of the beam's frame and four diagonals) where the reference reaches the
    MPE (1 % margin): each must lie inside the lobe, |o - c| <= lobe((o - c) / |o - c|),
    whatever the lobe's origin c (the rays from c may never pass the body). Returns
    (name, |o - c|, lobe, E_ref, inside the incident beam) of the hazardous ones."""
    dirs = [np.array(v, float) for v in ([1, 0, 0], [-1, 0, 0], [0, 0, 1], [0, 0, -1], [0, -1, 0], [0, 1, 0],
                                          [1, -1, 1], [-1, -1, -1], [1, -1, -1], [-1, -1, 1])]
    reach = case.r + (case.half if case.kind == "cylinder" else 0.0)  # a bounding sphere's radius
    pts, names = [], []
    for v in dirs:
        v = ref.unit(v)
        for g in (1.0, 4.0):
            pts.append(case.centre + (reach + g * case.w) * v), names.append(f"{np.round(v, 2).tolist()} gap {g:g} w")
    pts = np.array(pts)
    e = np.maximum(ref_irradiance(case.nodes(2), pts), ref_irradiance(case.nodes(4), pts))
    hot = np.flatnonzero(e >= MPE * 1.01)
    if not len(hot):
        return []
    v = pts[hot] - c
    dist = np.linalg.norm(v, axis=1)
    lobe = np.asarray(fn(((v / dist[:, None]) @ case.Q.T) @ np.asarray(spot.mean_frame, float).T), float)
    in_beam = np.hypot(pts[hot, 0], pts[hot, 2]) < 2 * case.D  # the direct beam's hazard holds these anyway
    return [(names[h], float(dist[j]), float(lobe[j]), float(e[h]), bool(in_beam[j])) for j, h in enumerate(hot)]


# ------------------------------------------------------------------ the reference's own checks (fast)
def test_reference_intercepts_the_gaussian_power():
    """The quadrature's E_inc dA sums to the beam's power the body takes: a centred sphere
    P (1 - exp(-r^2 / w^2)); a long cylinder across the beam P erf(r / w) (its mantle),
    the same when tilted 40 deg into the beam (the mantle's projection is unchanged)
    and a short tilted one (mantle and lit end disk) P erf(r / w) within its ends' clip."""
    c = Case("sphere", 100.0, 100.0, 2.0)
    assert c.nodes(1)[2].sum() == pytest.approx(100.0 * (1 - math.exp(-c.r ** 2 / c.w ** 2)), rel=1e-9)
    c = Case("cylinder", 100.0, 100.0, 2.0, axis=(1.0, 0.0, 0.0), fl=20.0)
    assert c.nodes(1)[2].sum() == pytest.approx(100.0 * math.erf(c.r / c.w), rel=1e-9)
    t = math.radians(40.0)
    c = Case("cylinder", 100.0, 100.0, 2.0, axis=(math.cos(t), math.sin(t), 0.0), fl=40.0)
    assert c.nodes(1)[2].sum() == pytest.approx(100.0 * math.erf(c.r / c.w), rel=1e-9)


def test_reference_far_field_is_the_point_form():
    """Far away (1000 body sizes) along -u the integral is the point form: a Lambertian
    sphere in a uniform beam returns I = rho E0 r^2 (2 / 3) W/sr straight back
    (int cos^2 theta sin theta dtheta dphi over the lit hemisphere x rho / pi = 2 rho / 3)."""
    c = Case("sphere", 100.0, 100.0, 0.02)  # r = w / 100: uniform to 1e-4
    e0 = 100.0 / (math.pi * c.w ** 2)
    d = 1000.0 * c.D
    got = ref_irradiance(c.nodes(1), np.array([c.centre - (d + c.r) * U]))[0]
    assert got == pytest.approx(RHO * e0 * c.r ** 2 * 2 / 3 / d ** 2, rel=2e-4)


# ------------------------------------------------------------------ the engine's lobe against it
FAST_ONE = settings(ref.FAST, max_examples=1)


# the sweep's finding (a constant: hypothesis derives its draws from the test's source, decorators included)
RANDOM_SHORT = ("SHORT (found here, shrunk by hypothesis): a sphere of 6.5 D, 0.64 D off the axis 20 m down range, power "
                "for a point-form root of 0.0657 m: along the mean plane (el 0, az -62) the reference root is 0.0400 m, "
                "the lobe 0.0341 m (-14.8 %: the lumpy sum over the spot's few sample frames). Before the curved point "
                "form: a 5 cm sphere on the axis, 1451 W, el 0: root 0.9499 m, lobe 0.7497 m (-21 %), now 0.9615 m; "
                "~6 min with the shrinking")


@pytest.mark.slow  # ~2 s (the default run's budget is spent)
@FAST_ONE
@given(kind=st.sampled_from(["sphere", "cylinder"]), f=ref.log_uniform(0.5, 3.0), ox=st.floats(-0.4, 0.4),
       tilt=st.floats(0.0, 60.0), spin=st.floats(-180.0, 180.0), root=ref.log_uniform(0.05, 2.0),
       el=st.floats(-20.0, 90.0), az=st.floats(-180.0, 180.0))
def test_random_body_never_short(kind, f, ox, tilt, spin, root, el, az):
    """A random sphere or cylinder (0.5-3 beam diameters, off the beam's axis by up to 0.4 D,
    the cylinder's axis across the beam turned ``spin`` about it and tilted ``tilt`` into
    it) 100 m down range, power for a point-form range ``root`` [m]; along a random
    direction of the spot's mean frame (elevation ``el``, down to 20 deg below its plane)
    the lobe is never short of the reference root (one draw by default: ~1.5 s)."""
    _random_case(kind, f, ox, tilt, spin, root, el, az, 100.0)


def _random_case(kind, f, ox, tilt, spin, root, el, az, R1):
    s, t = math.radians(spin), math.radians(tilt)
    axis = (math.cos(t) * math.cos(s), math.sin(t), math.cos(t) * math.sin(s))
    power = math.pi * root * root * MPE / RHO
    case = Case(kind, power, R1, f, ox=ox, oz=0.5 * ox, axis=axis, fl=3.0)
    spot, fn, off = case.engine()
    fr = np.asarray(spot.mean_frame, float) @ case.Q
    e, z = math.radians(el), math.radians(az)
    w = math.cos(e) * (math.cos(z) * fr[0] + math.sin(z) * fr[1]) + math.sin(e) * fr[2]
    check(case, {f"el {el:.3g} az {az:.3g}": ref.unit(w)}, with_probes=False)


@pytest.mark.slow
@pytest.mark.xfail(strict=True, reason=RANDOM_SHORT)
@settings(ref.SLOW, max_examples=10)
@given(kind=st.sampled_from(["sphere", "cylinder"]), f=ref.log_uniform(0.5, 10.0), ox=st.floats(-1.0, 1.0),
       tilt=st.floats(0.0, 60.0), spin=st.floats(-180.0, 180.0), root=ref.log_uniform(0.05, 50.0),
       el=st.floats(-20.0, 90.0), az=st.floats(-180.0, 180.0), R1=st.floats(20.0, 200.0))
def test_random_body_never_short_many(kind, f, ox, tilt, spin, root, el, az, R1):
    """As :func:`test_random_body_never_short` over the whole range: 0.5-10 beam diameters,
    roots 0.05-50 m, 20-200 m down range."""
    if abs(ox) * A > f * A / 2 + 3 * A:
        return
    _random_case(kind, f, ox, tilt, spin, root, el, az, R1)


# the cases of the report (slow): (id, Case arguments)
CASES = [
    ("sphere-0.5D-20m", dict(kind="sphere", power=2.0, R1=20.0, f=0.5)),
    ("sphere-1D-off-50m", dict(kind="sphere", power=30.0, R1=50.0, f=1.0, ox=0.4, oz=-0.2)),
    ("sphere-2D-100m", dict(kind="sphere", power=1000.0, R1=100.0, f=2.0)),
    ("sphere-10D-200m", dict(kind="sphere", power=1e5, R1=200.0, f=10.0)),
    ("sphere-10D-off-150m", dict(kind="sphere", power=3e5, R1=150.0, f=10.0, ox=3.0, oz=1.5)),
    ("cyl-0.5D-across-20m", dict(kind="cylinder", power=5.0, R1=20.0, f=0.5, axis=(1.0, 0.0, 0.0), fl=4.0)),
    ("cyl-2D-across-100m", dict(kind="cylinder", power=3000.0, R1=100.0, f=2.0, axis=(0.0, 0.0, 1.0), fl=6.0)),
    ("cyl-10D-tilt45-200m", dict(kind="cylinder", power=1e5, R1=200.0, f=10.0, axis=(1.0, 1.0, 0.0), fl=20.0)),
    ("cyl-2D-tilt-cap-lit-60m", dict(kind="cylinder", power=300.0, R1=60.0, f=2.0, axis=(0.5, 0.7, 0.5), fl=1.0, ox=0.3)),
    ("cyl-edge-on-reproducer-100m", dict(kind="cylinder", power=100.0, R1=100.0, f=0.25, axis=(0.0, 0.0, 1.0), fl=0.5,
                                         ox=0.03125, oz=0.0625, a=0.01, rot=(0.6586652289504804, 1.3672976968937096,
                                                                            -1.8623530121926877))),
]


# SHORT on the engine of 2026-11-27 (main 39495b9: also sphere-10D-200m, sphere-10D-off-150m, cyl-2D-across-100m and
# cyl-10D-tilt45-200m, which the curved point form and the grid's rows below the mean plane mended), the same with x43's
# curved bound: each figure is the reference root against the lobe along the named direction (``-s`` prints all of them)
SHORT = {
    "sphere-2D-100m": "mean el 10 az 45 (between grid nodes): root 1.0681 m, lobe 1.0612 m (-0.65 %: the lobe keeps the point "
                      "form where the integral's root at the nodes lies within its 0.5 % floor; -2.9 % before the curved "
                      "point form)",
    "cyl-edge-on-reproducer-100m": "mean el 10 az 45: root 0.1362 m, lobe 0.1264 m (-7.1 %), mean el 3 az 0 -2.9 %, side -x "
                                   "-1.8 %: the lobe is the point form there, whose sum over the 2.5 mm cylinder's few sample "
                                   "frames is lumpy. Before the rays started at the triangles (d7b260c) the spot's power "
                                   "centroid lay 47 m up beam (float32 hits on facets edge-on to the beam: spot size 2616 m)",
}


@pytest.mark.slow
@pytest.mark.parametrize("name,kw", [pytest.param(n, kw, marks=pytest.mark.xfail(strict=True, reason="SHORT: " + SHORT[n]))
                                     if n in SHORT else (n, kw) for n, kw in CASES], ids=[c[0] for c in CASES])
def test_case_never_short(name, kw):
    """Each case: the lobe along the named directions (:func:`directions`) never short of
    the reference root."""
    check(Case(**kw))
