"""Keep-out lobes of an extended diffuse spot (issue 29 item 2): the NOHD per direction
near a grazing spot against the farthest root of the section-10 integral, written here
from the formula (range-safety.md section 10), never from the engine:

    E(o) = int int P / (pi w^2) exp(-(X^2 + Z^2) / w^2) rho / pi (o - p).n / |o - p|^3 dX dZ

over the beam's cross-section (X across, Z along the plane of incidence; the ray lands
at p = X t + Z / cos(i) b on a plate at incidence i), by tensor Gauss-Legendre (24 nodes
across 10 w, 8 nodes on each of 40-2000 panels along it, each at most 5 cm long on the plate). The reference root along a ray
from the spot's power centroid (the lobe's origin) is the farthest radius where E
reaches the MPE: scanned at 0.4 % steps of the scan range, bisected to 1e-7.

The lobe (hazard.physics.near_field_lobe) reports on its direction grid the farthest root of the
engine's near-field integral plus the scan's step, never below the point form; between
grid nodes the largest of the cell's nodes plus a curvature margin. Checks:

- never short, on and off the grid: the lobe >= the reference root (to 1e-6 and the
  engine's 1 % near-field tolerance, i.e. 0.5 % in range);
- at grid nodes and, by default, along random directions (the node computation
  there, fast, with the integral's work budget unspent): no longer than the larger of the point form and the reference root plus
  the stated step and bisection tolerance (and the integral's 1 % tolerance);
- a grazing spot's lobe is elongated: along the spot, low down, it reaches the
  integral's root far beyond the centroid's point form.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import hazard
import scenes
from hazard.physics import near_field_lobe
from hazard.physics.keepout import nohd_range_fn
from hazard.physics.mpe import ocular_mpe
from hazard.pipeline.spots import ray_scene, trace_beam

from . import _refs as ref
from .test_near_field_spot import _diverging_reference

A, PHI, R1 = 0.05, 1e-9, 2000.0  # collimated (w = a / 2 on the plate), from beyond the spot's far end
W = (A + R1 * PHI) / 2
RHO = 0.8
PANEL_M = 0.05  # the reference's Gauss-Legendre panels along the spot: at most this long on the plate (40 to 2000)
RANGE_TOL = 0.005  # the integral's 1 % tolerance (hazard.physics.near_field.NEAR_FIELD_RTOL) in range: half of it
FEW = settings(ref.FAST, max_examples=2)
MANY = settings(ref.SLOW, max_examples=20)


def _frame(inc_deg):
    """Plate normal, along-the-spot and across unit vectors for a beam along +y."""
    i = math.radians(inc_deg)
    return (np.array([0.0, -math.cos(i), math.sin(i)]), np.array([0.0, math.sin(i), math.cos(i)]),
            np.array([1.0, 0.0, 0.0]))


def _nodes(inc_deg, power_w, half_len_m, half_wid_m):
    """Reference quadrature: surface points (K, 3) and their powers (K,) [W]."""
    n, b, t = _frame(inc_deg)
    c = math.cos(math.radians(inc_deg))
    xg, xw = np.polynomial.legendre.leggauss(24)
    zg, zw = np.polynomial.legendre.leggauss(8)
    panels = int(np.clip(math.ceil(10 * W / c / PANEL_M), 40, 2000))
    edges = np.linspace(-5.0, 5.0, panels + 1)
    zc = (((edges[:-1] + edges[1:]) / 2)[:, None] + (np.diff(edges) / 2)[:, None] * zg[None, :]).ravel()
    zwt = (np.diff(edges)[:, None] / 2 * zw[None, :]).ravel()
    X, Z = np.meshgrid(5.0 * xg, zc, indexing="ij")
    wts = np.outer(5.0 * xw, zwt) * W * W
    p = (X * W)[..., None] * t + (Z * W / c)[..., None] * b
    on = (np.abs(X * W) <= half_wid_m) & (np.abs(Z * W / c) <= half_len_m)  # the plate's outline clips
    power = power_w / (math.pi * W * W) * np.exp(-(X * X + Z * Z)) * wts * on
    keep = power > 0
    return p[keep], power[keep], n


def _ref_irradiance(nodes, o):
    """The section-10 integral [W/m^2] at observers ``o`` (M, 3)."""
    p, power, n = nodes
    o = np.asarray(o, float)
    out = np.empty(len(o))
    step = max(1, (1 << 21) // len(p))
    for a in range(0, len(o), step):
        y = o[a:a + step, None, :] - p[None]
        r2 = np.einsum("mij,mij->mi", y, y)
        out[a:a + step] = (power * RHO / math.pi * np.clip(y @ n, 0, None) / r2 ** 1.5).sum(axis=1)
    return out


def _ref_root(nodes, c, w, mpe, r_max):
    """Farthest radius along ``c + r w`` where the reference reaches ``mpe``: a scan of
    250 radii to ``r_max``, then bisection (:func:`_refs.farthest_root`)."""
    return ref.farthest_root(lambda p: _ref_irradiance(nodes, p), c, w, mpe, np.linspace(r_max / 250, r_max, 250))


def _plate_spot(inc_deg, power_w, half_len_m, half_wid_m):
    """The analysis's spot on a Lambertian plate, its MPE and the world offset."""
    n, b, t = _frame(inc_deg)
    plate = dict(name="plate", shape="plate", center=np.zeros(3), normal=n, tangent=t,
                 size=(2 * half_wid_m, 2 * half_len_m), material=ref.lambertian(RHO))
    text = ref.scene_text(power=power_w, a=A, phi=PHI, position=np.array([0.0, -R1, 0.0]), aim=np.zeros(3), targets=[plate],
                          observers=[("o", np.array([0.0, 0.0, 50.0]), None)],
                          analysis="direction_grid_deg = 10.0\nrefine_levels = 0\n")
    enabled, near_field_lobe.ENABLED = near_field_lobe.ENABLED, False  # the test makes its own lobe function
    try:
        res = hazard.analyze(scenes.loads(text))
    finally:
        near_field_lobe.ENABLED = enabled
    return res.spots[0], res.mpe_w_m2, np.asarray(res.scene.offset_m, float)


def _world_dir(n, b, t, el_deg, az_deg):
    """Unit vector at elevation ``el_deg`` above the plate, azimuth from the spot's
    length ``b`` towards ``t``."""
    e, a = math.radians(el_deg), math.radians(az_deg)
    return math.cos(e) * (math.cos(a) * b + math.sin(a) * t) + math.sin(e) * n


def _grid_dir(theta_deg, phi_deg):
    """A node of the lobe's direction grid, in the spot's mean frame."""
    th, ph = math.radians(theta_deg), math.radians(phi_deg)
    return np.array([math.sin(th) * math.cos(ph), math.sin(th) * math.sin(ph), math.cos(th)])


def _check(inc_deg, power_w, world_dirs, grid_dirs=(), half_len_m=None, half_wid_m=0.5, roots_only=False):
    """The lobe against the reference root along world directions (never short) and
    along grid nodes (never short, and within the stated tolerance). ``roots_only``: the
    world directions too get the node computation (the integral's root along them, no
    grid: fast)."""
    half_len_m = 4 * W / math.cos(math.radians(inc_deg)) if half_len_m is None else half_len_m
    spot, mpe, off = _plate_spot(inc_deg, power_w, half_len_m, half_wid_m)
    fn = nohd_range_fn(spot, mpe, 0.0, 1.0, None)
    assert isinstance(fn, near_field_lobe.NearLobeFn)
    frame = spot.mean_frame
    if roots_only:
        on_grid = np.concatenate([np.array([_grid_dir(*g) for g in grid_dirs]).reshape(-1, 3),
                                  np.asarray(world_dirs, float).reshape(-1, 3) @ frame.T])
        world_dirs = np.zeros((0, 3))
    else:
        on_grid = np.array([_grid_dir(*g) for g in grid_dirs]).reshape(-1, 3)
    w = np.concatenate([np.asarray(world_dirs, float).reshape(-1, 3), on_grid @ frame])
    point = fn.base(w @ frame.T)
    reported = point.copy() if roots_only else fn(w @ frame.T)  # the lobe (grid envelope off the nodes)
    g = slice(len(w) - len(on_grid), None)
    fresh = near_field_lobe.NearLobeFn(spot, fn.base, mpe, 0.0, 1.0, None)  # the integral's budget unspent
    probe = np.array([_grid_dir(t, p) for t in near_field_lobe.THETA_ROWS_DEG for p in range(-180, 181, 30)])
    fresh.prepare(probe, fn.base(probe))
    node_root, step = fresh.roots(on_grid, point[g])  # a node's own value: the integral's root + the scan step
    assert fresh.bound_points == 0
    reported[g] = np.maximum(point[g], node_root)
    nodes = _nodes(inc_deg, power_w, half_len_m, half_wid_m)
    c = spot.centroid + off
    r_max = 1.5 * float(reported.max()) + 1.0
    roots = np.array([_ref_root(nodes, c, w[k], mpe, r_max) for k in range(len(w))])
    assert np.all(reported >= roots * (1 - RANGE_TOL) - 1e-9), f"short: {reported} < {roots}"
    if len(on_grid):
        allowed = np.maximum(point[g], roots[g] * (1 + RANGE_TOL) + step * (1 + 1 / 8) + near_field_lobe.ROOT_RTOL * r_max)
        assert np.all(reported[g] <= allowed + 1e-9), f"too long on the grid: {reported[g]} > {allowed}"
    return reported, point, roots, fn


GRID = [(0.0, 0.0), (45.0, 0.0), (70.0, 90.0), (85.0, 180.0), (89.5, 0.0), (89.5, 90.0)]


def test_plate_at_85_deg():
    """85 deg, 200 W: the spot is 0.29 m long (1/e); at grid nodes the lobe is the
    integral's root within its stated step; off them, never short."""
    n, b, t = _frame(85.0)
    _check(85.0, 200.0, [_world_dir(n, b, t, 3.0, 0.0), _world_dir(n, b, t, 20.0, 180.0)], [GRID[1], GRID[4]], roots_only=True)


@pytest.mark.slow
@pytest.mark.xfail(strict=True, reason="known looseness, safe side: since the per-beam sampled square (issue 29's tail, "
                   "2026-11-26) the node at (89.5, 90) deg reads 0.84225 m against its allowed 0.84122 m (the integral's "
                   "root + the scan step): 0.12 % long, never short; strict, so fixing it fails here and says so")
def test_plate_at_85_deg_more_directions():
    """85 deg, 1 kW: more directions on and off the grid (the whole lobe: never short)."""
    n, b, t = _frame(85.0)
    dirs = [_world_dir(n, b, t, el, az) for el, az in [(90.0, 0.0), (20.0, 180.0), (3.0, 0.0), (3.0, 90.0)]]
    _check(85.0, 1000.0, dirs, GRID)


@pytest.mark.slow
def test_plate_at_89_9_deg_is_elongated():
    """89.9 deg: the spot is 14 m long (1/e); along it, 3 deg above the plate, the
    integral's root (6.3 m) is 12x the centroid's point form (0.52 m); the lobe reaches it."""
    n, b, t = _frame(89.9)
    dirs = [_world_dir(n, b, t, el, az) for el, az in [(3.0, 0.0), (3.0, 180.0), (10.0, 0.0), (45.0, 90.0)]]
    reported, point, roots, _ = _check(89.9, 1000.0, dirs, GRID[:3])
    assert roots[0] > 5 * point[0]  # the defect: the point form is short along the spot
    assert reported[0] >= roots[0] * (1 - RANGE_TOL)


@FEW
@given(inc=st.floats(60.0, 89.9), power=ref.log_uniform(300.0, 3000.0), el=st.floats(3.0, 90.0), az=st.floats(-180.0, 180.0))
def test_random_incidence_power_and_direction(inc, power, el, az):
    """The node computation (the integral's farthest root plus the scan step) along a
    random direction: never short, no longer than the stated tolerance."""
    n, b, t = _frame(inc)
    _check(inc, power, [_world_dir(n, b, t, el, az)], roots_only=True)


@pytest.mark.slow
@settings(ref.SLOW, max_examples=6)
@given(inc=st.floats(60.0, 89.9), power=ref.log_uniform(300.0, 3000.0), el=st.floats(3.0, 90.0), az=st.floats(-180.0, 180.0))
def test_random_incidence_power_and_direction_whole_lobe(inc, power, el, az):
    """The whole lobe (grid envelope) along a random direction: never short."""
    n, b, t = _frame(inc)
    _check(inc, power, [_world_dir(n, b, t, el, az)])


@pytest.mark.slow
@MANY
@given(inc=st.floats(60.0, 89.9), power=ref.log_uniform(100.0, 10000.0), el=st.floats(1.0, 90.0),
       az=st.floats(-180.0, 180.0), clip=st.floats(0.5, 4.0),
       node=st.tuples(st.sampled_from(near_field_lobe.THETA_ROWS_DEG), st.sampled_from([0.0, 30.0, 90.0, 180.0, -120.0])))
def test_random_incidence_direction_clip_and_node_many(inc, power, el, az, clip, node):
    n, b, t = _frame(inc)
    _check(inc, power, [_world_dir(n, b, t, el, az)], [node], half_len_m=clip * W / math.cos(math.radians(inc)), roots_only=True)


def test_an_aid_never_sees_less_than_the_naked_eye():
    """Through an aid of gain K >= 1 the irradiance is K times the naked eye's, so its lobe
    holds the naked lobe in every direction. Found on range_clearance's grazing ground spot:
    between grid nodes the lobe is the cell's largest node plus a curvature margin, which is
    larger for the naked lobe's sharper ridge (18.01 m) than for the aided one's (16.93 m),
    and 16.93 m was reported for 7x50 binoculars. Here a plate at 88 deg: the aided lobe
    >= the naked one on a dense fan of directions and in its largest range, and along the
    spot it reaches the reference root of the integral at MPE / K (never short)."""
    inc, power, k = 88.0, 1000.0, 44.1
    half_len = 4 * W / math.cos(math.radians(inc))
    spot, mpe, off = _plate_spot(inc, power, half_len, 0.5)
    naked, aided = nohd_range_fn(spot, mpe, 0.0, 1.0, None), nohd_range_fn(spot, mpe, 0.0, k, None)
    th, ph = np.meshgrid(np.radians(np.linspace(0.0, 89.9, 40)), np.radians(np.linspace(-180.0, 180.0, 73)), indexing="ij")
    fan = np.stack([np.sin(th) * np.cos(ph), np.sin(th) * np.sin(ph), np.cos(th)], -1).reshape(-1, 3)
    r1, rk = naked(fan), aided(fan)
    assert np.all(rk >= r1), f"aided below naked at {int((rk < r1).sum())} of {len(fan)} directions"
    assert rk.max() >= r1.max()
    n, b, t = _frame(inc)
    w = np.array([_world_dir(n, b, t, el, 0.0) for el in (2.0, 10.0)])
    reported = aided(w @ spot.mean_frame.T)
    nodes = _nodes(inc, power, half_len, 0.5)
    roots = np.array([_ref_root(nodes, spot.centroid + off, wk, mpe / k, 1.5 * float(reported.max()) + 1.0) for wk in w])
    assert np.all(roots > 0) and np.all(reported >= roots * (1 - RANGE_TOL) - 1e-9), (reported, roots)


# ------------------------------------------------------------------ grazing terrain (the 100 kW ground spot)
@pytest.mark.slow
def test_grazing_terrain():
    """The ground spot of test_near_field_spot (100 kW at 89.91 deg, l = 16.7 m): the lobe
    never short of the integral's farthest root (coded there, Gauss-Legendre over the
    ground) along and across the spot, and the eye-height points along the spot that the
    integral finds hazardous (before: missed by the keep-out 33 m along it) lie inside it."""
    from .test_near_field_spot import EYE, GY, _ground_reference, _ground_scene

    res = hazard.analyze(_ground_scene(8.0, 40.0, [np.array([0.0, GY, 2.0])]))
    spot = next(s for s in res.spots if s.target.name == "terrain")
    mpe, off = res.mpe_w_m2, np.asarray(res.scene.offset_m, float)
    fn = nohd_range_fn(spot, mpe, 0.0, 1.0, None)
    assert isinstance(fn, near_field_lobe.NearLobeFn)
    c = spot.centroid + off
    frame = spot.mean_frame
    dirs = [(60.0, 90.0), (20.0, 90.0), (5.0, 90.0), (5.0, -90.0), (10.0, 0.0)]  # azimuth from +x: 90 deg is along the spot
    w = np.array([[math.cos(math.radians(e)) * math.cos(math.radians(a)), math.cos(math.radians(e)) * math.sin(math.radians(a)),
                   math.sin(math.radians(e))] for e, a in dirs])
    reported = fn(w @ frame.T)
    for k in range(len(w)):
        rs = np.linspace(0.05, 1.5 * reported[k] + 1, 400)
        hot = np.flatnonzero(_ground_reference(c + rs[:, None] * w[k]) >= mpe)
        assert not len(hot) or hot[-1] < len(rs) - 1
        root = rs[hot[-1] + 1] if len(hot) else 0.0  # the scan's far end: >= the root
        assert reported[k] >= root - (rs[1] - rs[0]), f"short along {dirs[k]}: {reported[k]} < {root}"
    along = np.array([[0.0, GY + d, EYE] for d in (-33.0, -20.0, 20.0, 33.0)])
    want = _ground_reference(along) / mpe
    v = along - c
    dist = np.linalg.norm(v, axis=1)
    inside = dist <= fn((v / dist[:, None]) @ frame.T)
    assert np.all(inside[want >= 1.0]), (want, dist, inside)


def test_a_pure_mirror_has_no_near_field_lobe():
    """A pure (Fresnel) mirror reflects nothing outside its mirror beam: f_r cos P = 0 in every
    lobe direction, so the near-field integral is 0 too. The scan once ended on the spot
    itself (1e-12 m), where the bound's remainders made a 9e-13 m "lobe" that the verdict
    then listed as a hazard zone without a range boundary (mirror_window's window)."""
    from tests._bundled import bundled

    result = bundled("mirror_window")
    window = next(t for t in result.targets if t.name == "window")
    assert window.static_lobe.max_range_m == 0.0 and window.dynamic_lobe.max_range_m == 0.0
    painted = next(t for t in result.targets if t.name == "painted-target")
    assert painted.static_lobe.max_range_m > 0.9  # the diffuse target beside it keeps its lobe


# ------------------------------------------------------------------ a history: the states' shortcut decides as all states
def _history_lobe(n_states):
    """The witness screen's spot (a state-looping dynamic material) and its near-field lobe
    function over ``n_states`` states across the material's range, bounds prepared."""
    from tests._bundled import bundled

    res = bundled("witness_screen")
    spot = res.spots[0]
    lo, hi = spot.material.state_range
    states = np.linspace(lo, hi, n_states)
    fn = nohd_range_fn(spot, res.mpe_w_m2, 0.0, 1.0, states)
    assert isinstance(fn, near_field_lobe.NearLobeFn)
    probe = np.array([_grid_dir(t, p) for t in near_field_lobe.THETA_ROWS_DEG for p in range(-180, 181, 30)])
    r0 = fn.base(probe)
    fn.prepare(probe, r0)
    return spot, fn, res.mpe_w_m2, float(r0.max())


@settings(ref.FAST, max_examples=3)
@given(seed=st.integers(0, 2**31 - 1), n_states=st.integers(2, 24))
def test_history_state_shortcut_decides_as_every_state(seed, n_states):
    """With a history the lobe integrates each point first at its state of the largest bound,
    then only at the states whose own bound reaches the MPE (hazard.physics.near_field_lobe
    NearLobeFn.hazardous): at random points near the spot (inside the point form's reach)
    the decision equals the integral at every state reaching the MPE (the bound below the
    MPE at a state: the integral there is too). Radii log-uniform from 1e-3 of the point
    form's reach: near the spot every state's bound is infinite."""
    from hazard.physics.engine import near_field_w_m2

    spot, fn, mpe, reach = _history_lobe(n_states)
    rng = np.random.default_rng(seed)
    w = rng.normal(size=(40, 3)) * np.repeat([1.0, 0.05], 20)[:, None] + np.repeat([0.0, 1.0], 20)[:, None] * fn.peaks[0]
    w[:, 2] = np.abs(w[:, 2])  # half anywhere above the spot, half about the point form's farthest direction
    w /= np.linalg.norm(w, axis=1, keepdims=True)
    pts = spot.centroid + (np.exp(rng.uniform(math.log(1e-3), math.log(1.2), 40)) * reach)[:, None] * (w @ spot.mean_frame)
    every = near_field_w_m2(spot, pts, np.ones(len(pts)), 0.0, fn.states).max(axis=1) >= mpe
    got = fn.hazardous(pts)
    assert fn.bound_points == 0
    np.testing.assert_array_equal(got, every)
    assert every.any() and not every.all()  # both verdicts drawn


# ------------------------------------------------------------------ the flat spot's bound (a spot much larger than its lobe)
def _flat_bound_case(inc, power, h, along, across):
    spot, mpe, off = _plate_spot(inc, power, 4 * W / math.cos(math.radians(inc)), 0.5)
    fn = nohd_range_fn(spot, mpe, 0.0, 1.0, None)
    probe = np.array([_grid_dir(t, p) for t in near_field_lobe.THETA_ROWS_DEG for p in range(-180, 181, 30)])
    fn.prepare(probe, fn.base(probe))
    n, b, t = _frame(inc)
    pts = spot.centroid + np.array([h * n + along * W / math.cos(math.radians(inc)) * b + across * W * t])
    bound = fn._flat_bound(pts)
    ref_e = _ref_irradiance(_nodes(inc, power, 4 * W / math.cos(math.radians(inc)), 0.5), pts + off)
    assert np.all(np.isfinite(bound))
    assert np.all(bound >= ref_e / mpe), (bound, ref_e / mpe)


@settings(ref.FAST, max_examples=8)
@given(inc=st.floats(0.0, 89.9), power=ref.log_uniform(1.0, 3000.0), h=ref.log_uniform(0.02, 2.0),
       along=st.floats(-3.0, 3.0), across=st.floats(-3.0, 3.0))
def test_flat_spot_bound_is_above_the_integral(inc, power, h, along, across):
    """The lobe's bound for a flat spot (hazard.physics.near_field_lobe NearLobeFn._flat_bound:
    the largest incident irradiance x the point form's largest intensity / P x pi ln(1 +
    rho^2 / h^2)) is finite and never below the section-10 integral (coded here) at random
    points above a Lambertian plate, down to 2 cm above it."""
    _flat_bound_case(inc, power, h, along, across)


# ------------------------------------------------------------------ extreme grazing: never short, and within a stated factor
GRAZING_FACTOR = 4.5  # the whole lobe along the spot, 3 deg above the plate, at most this x the integral's root (module notes)


def _grazing(inc, power, el, az):
    """The whole lobe (grid envelope, the integral's default work budget) along a world
    direction against the reference root; returns (lobe, reference root, point form)."""
    n, b, t = _frame(inc)
    reported, point, roots, fn = _check(inc, power, [_world_dir(n, b, t, el, az)])
    return float(reported[0]), float(roots[0]), float(point[0]), fn


@pytest.mark.slow
def test_plate_at_89_9_deg_within_a_factor_of_the_integral():
    """89.9 deg, 1 kW, 3 deg above the plate along the spot: the section-10 integral's
    farthest root is 6.30 m (12x the centroid's point form, 0.52 m). The lobe is never
    short of it and at most GRAZING_FACTOR x it (before: 69.5 m, 11x, once the integral's
    work budget was spent and the old flat-spot bound, 1000x above the integral near the
    spot, decided)."""
    lobe, root, point, fn = _grazing(89.9, 1000.0, 3.0, 0.0)
    assert 6.2 < root < 6.4 and root > 10 * point  # the reference's own figure (the case the issue measured)
    assert root * (1 - RANGE_TOL) <= lobe <= GRAZING_FACTOR * root, (lobe, root, fn.info)


@pytest.mark.slow
@settings(ref.SLOW, max_examples=4)
@given(inc=st.floats(80.0, 89.99), el=st.floats(1.0, 10.0), az=st.floats(-30.0, 30.0))
def test_random_grazing_angles_whole_lobe(inc, el, az):
    """Random grazing incidence 80-89.99 deg, low along the spot: the whole lobe is never
    short of the integral's root, and at most GRAZING_FACTOR x the larger of it and the
    point form plus two of the lobe's stated scan steps (its resolution, added to each
    node's root: at 89.99 deg the step is 28.6 m, from the spot's smallest extent, where
    the root 3 deg above the plate is 0.57 m and the lobe 12.2 m; see the README)."""
    lobe, root, point, fn = _grazing(inc, 1000.0, el, az)
    allowed = GRAZING_FACTOR * max(root, point) + 2 * fn.info["scan_step_max_m"]
    assert root * (1 - RANGE_TOL) <= lobe <= allowed, (inc, el, az, lobe, root, point, fn.info)


@settings(ref.FAST, max_examples=2)
@given(inc=st.floats(80.0, 89.99), el=st.floats(2.0, 10.0))
def test_random_grazing_angles_node_root(inc, el):
    """Random grazing incidence 80-89.99 deg along the spot: the node computation (the
    integral's farthest root plus the scan step, budget unspent) never short, within the
    stated step (asserted in _check)."""
    n, b, t = _frame(inc)
    _check(inc, 1000.0, [_world_dir(n, b, t, el, 0.0)], roots_only=True)


# ------------------------------------------------------------------ the flat spot's bound, piece by piece
def _triangle_quadrature(tri, foot, h):
    """int_tri dA / (h^2 + |p - foot|^2) over a planar triangle (3, 2): the triangle cut
    into 4^5 similar ones, each by the Duffy map p = A + u (B - A) + u v (C - B) with
    8 x 8 Gauss-Legendre nodes (Jacobian 2 area u)."""
    g, gw = np.polynomial.legendre.leggauss(8)
    g, gw = (g + 1) / 2, gw / 2
    tris = [np.asarray(tri, float)]
    for _ in range(5):
        nxt = []
        for a, b, c in tris:
            ab, bc, ca = (a + b) / 2, (b + c) / 2, (c + a) / 2
            nxt += [np.array([a, ab, ca]), np.array([ab, b, bc]), np.array([ca, bc, c]), np.array([ab, bc, ca])]
        tris = nxt
    t = np.array(tris)  # (K, 3, 2)
    u, v = np.meshgrid(g, g, indexing="ij")
    wts = np.outer(gw, gw) * u
    p = t[:, None, None, 0] + u[None, ..., None] * (t[:, None, None, 1] - t[:, None, None, 0]) \
        + (u * v)[None, ..., None] * (t[:, None, None, 2] - t[:, None, None, 1])
    e1, e2 = t[:, 1] - t[:, 0], t[:, 2] - t[:, 0]
    area2 = np.abs(e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0])
    f = 1.0 / (h * h + ((p - foot) ** 2).sum(-1))
    return float((area2[:, None, None] * wts[None] * f).sum())


@settings(ref.FAST, max_examples=25)
@given(tri=st.lists(st.tuples(st.floats(-1.0, 1.0), st.floats(-1.0, 1.0)), min_size=3, max_size=3),
       stretch=ref.log_uniform(1.0, 50.0), foot=st.tuples(st.floats(-3.0, 3.0), st.floats(-3.0, 3.0)), h=ref.log_uniform(0.1, 3.0))
def test_inverse_square_bound_is_above_the_quadrature(tri, stretch, foot, h):
    """hazard.physics.near_field_lobe._inverse_square_bound (strip, transposed strip and annulus
    forms) is never below int_tri dA / R^2 (Gauss-Legendre coded here) on random
    triangles, stretched up to 50:1 as a grazing spot's are."""
    t = np.array(tri) * np.array([stretch, 1.0])
    e1, e2 = t[1] - t[0], t[2] - t[0]
    area = 0.5 * abs(e1[0] * e2[1] - e1[1] * e2[0])
    if area < 1e-3 * stretch:
        return  # a degenerate draw: nothing to integrate
    f = np.array(foot) * np.array([stretch, 1.0])
    want = _triangle_quadrature(t, f, h)
    got = near_field_lobe._inverse_square_bound(f[None], np.array([h * h]), near_field_lobe._triangle_boxes(t[None]))[0, 0]
    assert got >= want * (1 - 1e-6), (got, want)


def test_projected_brdf_max_is_the_models_largest_value():
    """The proven largest f_r cos (hazard.physics.near_field_lobe.projected_brdf_max) of a
    Lambertian (rho / pi, reached at the normal), a constant scale of it and a sum; None
    for a model whose largest value has no closed form here (a glossy lobe)."""
    import brdfmodels

    lam = brdfmodels.Lambertian(0.6)
    both = brdfmodels.Sum([brdfmodels.Scaled(lam, 0.5), brdfmodels.Lambertian(0.2)])
    rng = np.random.default_rng(7)
    wi, wo = rng.normal(size=(2, 4000, 3))
    wi[:, 2], wo[:, 2] = np.abs(wi[:, 2]), np.abs(wo[:, 2])
    wo[0] = [0.0, 0.0, 1.0]
    for model, top in [(lam, 0.6 / math.pi), (both, (0.3 + 0.2) / math.pi)]:
        f = model.evaluate_cos(wi / np.linalg.norm(wi, axis=1, keepdims=True), wo / np.linalg.norm(wo, axis=1, keepdims=True))
        assert near_field_lobe.projected_brdf_max(model) == pytest.approx(top, rel=1e-12)
        assert f.max() <= top * (1 + 1e-12) and f.max() == pytest.approx(top, rel=1e-9)
    glossy = brdfmodels.TorranceSparrow5(kb=1.0, kr=0.5, a=0.1, b=0.2, kd=0.1)
    assert near_field_lobe.projected_brdf_max(glossy) is None
    assert near_field_lobe.projected_brdf_max(brdfmodels.Sum([lam, glossy])) is None


def _diverging_flat_bound_case(inc, phi, rng_m, h, along):
    """The flat spot's bound (as ``_flat_bound_case``) for a diverging beam: the plate ``rng_m`` from a 1 kW, 5 cm
    laser of divergence ``phi`` at incidence ``inc``; the reference traces the rays from the virtual source
    (``test_near_field_spot._diverging_reference``)."""
    n, b, t = _frame(inc)
    ell = (0.05 + rng_m * phi) / 2 / math.cos(math.radians(inc))
    half_len = min(3 * ell, 0.75 * rng_m)
    plate = dict(name="plate", shape="plate", center=np.zeros(3), normal=n, tangent=t, size=(1.0, 2 * half_len),
                 material=ref.lambertian(RHO))
    laser = np.array([0.0, -rng_m, 0.0])
    scene = scenes.loads(ref.scene_text(power=1000.0, a=0.05, phi=phi, position=laser, aim=np.zeros(3), targets=[plate]))
    spot = trace_beam(scene, ray_scene(scene, "embree", 1), 0.0).built.spots[0]
    mpe = ocular_mpe(1064.0, 10.0).irradiance_w_m2  # scene_text's 1064 nm, 10 s: an input, not under test
    fn = nohd_range_fn(spot, mpe, 0.0, 1.0, None)
    probe = np.array([_grid_dir(th, p) for th in near_field_lobe.THETA_ROWS_DEG for p in range(-180, 181, 30)])
    fn.prepare(probe, fn.base(probe))
    o = h * n + along * min(ell, 0.5 * rng_m) * b
    off = np.asarray(scene.offset_m, float)
    bound = fn._flat_bound((o - off)[None, :])
    want = _diverging_reference(1000.0, 0.05, phi, laser, np.zeros(3), np.zeros(3), n, b, t, half_len, 0.5, o, rho=RHO)
    assert np.all(np.isfinite(bound)) and bound[0] >= want / mpe, (bound, want / mpe)


@settings(ref.FAST, max_examples=4)
@given(inc=st.floats(80.0, 89.99), phi=ref.log_uniform(1e-5, 2e-3), rng_m=ref.log_uniform(50.0, 3000.0),
       h=ref.log_uniform(0.05, 3.0), along=st.floats(-1.5, 1.5))
def test_flat_spot_bound_is_above_the_integral_of_a_diverging_beam(inc, phi, rng_m, h, along):
    """A diverging beam at grazing incidence lays its power unevenly over each triangle of the spot (the perspective
    map, hazard.physics.near_field): the bound takes each triangle's largest stretch and stays above the integral of the rays
    traced from the virtual source at random points above the plate."""
    _diverging_flat_bound_case(inc, phi, rng_m, h, along)


@settings(ref.FAST, max_examples=2)
@given(seed=st.integers(0, 2**31 - 1), n_states=st.integers(2, 24))
def test_state_evaluations_count_each_kernel_evaluation_at_its_states(seed, n_states):
    """The lobe's ``kernel_state_evaluations`` (the work the near-field floor of
    tests/bench/bench_whole_run.py repeats) is the sum over its integrals of the kernel
    evaluations each made times the states it was evaluated at, counted here around every
    call of the integral; with the states' shortcut it lies between one state per
    evaluation and every state."""
    from hazard.physics import near_field

    spot, fn, mpe, reach = _history_lobe(n_states)
    calls, real = [], near_field_lobe.near_field_w_m2

    def counted(sp, pts, weight, mu, states, **kw):
        before = near_field.STATS.snapshot()["evaluations"]
        out = real(sp, pts, weight, mu, states, **kw)
        calls.append((near_field.STATS.snapshot()["evaluations"] - before, 1 if states is None else len(states)))
        return out

    rng = np.random.default_rng(seed)
    w = rng.normal(size=(40, 3))
    w[:, 2] = np.abs(w[:, 2])
    w /= np.linalg.norm(w, axis=1, keepdims=True)
    pts = spot.centroid + (np.exp(rng.uniform(math.log(1e-3), math.log(1.2), 40)) * reach)[:, None] * (w @ spot.mean_frame)
    before = fn.evaluations, fn.state_evaluations  # the lobe function is shared (memoised per spot and states)
    near_field_lobe.near_field_w_m2 = counted
    try:
        fn.hazardous(pts)
    finally:
        near_field_lobe.near_field_w_m2 = real
    n, n_states_done = sum(c for c, _ in calls), sum(c * q for c, q in calls)
    made = fn.evaluations - before[0], fn.state_evaluations - before[1]
    assert n > 0 and made == (n, n_states_done)
    assert n <= made[1] <= n * n_states


@settings(ref.FAST, max_examples=2)
@given(n_states=st.integers(1, 12), mpe_scale=st.floats(0.3, 3.0))
def test_build_counters_are_every_brdf_row_it_evaluates(n_states, mpe_scale):
    """:func:`_check_build_counters` on a few draws."""
    _check_build_counters(n_states, mpe_scale)


@pytest.mark.slow
@settings(ref.SLOW, max_examples=24)
@given(n_states=st.integers(1, 40), mpe_scale=st.floats(0.05, 20.0))
def test_build_counters_are_every_brdf_row_it_evaluates_many(n_states, mpe_scale):
    """:func:`_check_build_counters` over more states and MPEs (slow: ~0.3 s a draw)."""
    _check_build_counters(n_states, mpe_scale)


def _check_build_counters(n_states, mpe_scale):
    """The lobe's counters of BRDF work (the near-field floor of tests/bench/bench_whole_run.py
    repeats each) are exactly the rows of ``f_r cos`` its build asks for, counted here by
    wrapping the three callers of ``projected_brdf``: the point form ``base``
    (``point_form_evaluations``: the grid, the peaks, the scan start's cone), the samples'
    bound (``bound_evaluations``: (point, sample) pairs) and the integral's kernel
    (``kernel_evaluations``); each ``*_state_evaluations`` the rows times the states each
    call was made at. A fresh lobe function (not the memoised one), MPE scaled so that
    the scans differ."""
    from hazard.physics import engine, keepout
    from hazard.physics.engine import path_states

    res = bundled_witness()
    spot = res.spots[0]
    lo, hi = spot.material.state_range
    states = path_states(spot.material, np.linspace(lo, hi, n_states))
    mpe = res.mpe_w_m2 * mpe_scale
    base = nohd_range_fn(spot, mpe, 0.0, 1.0, np.linspace(lo, hi, n_states), near_field=False)
    rows = {"base": [0, 0], "bound": [0, 0], "kernel": [0, 0]}
    real = {m: m.projected_brdf for m in (keepout, near_field_lobe, engine)}

    def counting(module, key):
        def f(model, wi, wo, st_=None, row_scale=None, reduce=None):
            rows[key][0] += len(wo)
            rows[key][1] += len(wo) * (1 if st_ is None else len(st_))
            return real[module](model, wi, wo, st_, row_scale, reduce)
        return f

    fn = near_field_lobe.NearLobeFn(spot, base, mpe, 0.0, 1.0, states)
    for module, key in ((keepout, "base"), (near_field_lobe, "bound"), (engine, "kernel")):
        module.projected_brdf = counting(module, key)
    try:
        fn.envelope(np.array([[0.0, 0.0, 1.0]]))  # builds the grid; the envelope itself evaluates no BRDF
    finally:
        for module, f in real.items():
            module.projected_brdf = f
    info = fn.info
    assert rows["base"][0] > 0  # the grid at least
    assert [info["point_form_evaluations"], info["point_form_state_evaluations"]] == rows["base"]
    assert [info["bound_evaluations"], info["bound_state_evaluations"]] == rows["bound"]
    assert [info["kernel_evaluations"], info["kernel_state_evaluations"]] == rows["kernel"]
    assert rows["base"][1] == rows["base"][0] * len(states) and rows["bound"][1] == rows["bound"][0] * len(states)


def bundled_witness():
    """The witness screen's analysis (a state-looping dynamic material; read only)."""
    from tests._bundled import bundled

    return bundled("witness_screen")
