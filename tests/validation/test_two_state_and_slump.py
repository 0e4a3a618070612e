"""Two-state dynamic BRDFs and the thin-plate melting history (issue 19), against
formulas written in this file.

Independence: no expected value comes from the engine's interpolation, path maximum,
envelope or heating code. The references are

* heating: the loss-free thin plate (emissivity 0, convection 0, no oxidation, constant
  reflectance R) absorbs the constant power (1 - R) E per unit area, so its enthalpy
  rises linearly:  T(t) = T0 + (1 - R) E t / (rho c h)  until
  t1 = rho c h (T_m - T0) / ((1 - R) E),  then the melt fraction rises linearly,
  f(t) = (t - t1) / (t2 - t1),  until  t2 = t1 + rho L h / ((1 - R) E)
  (spec oxidation-and-history.md, "Predicting a history");
* two-state BRDF: the paper's rule (spec dynamic-sh-brdf.md section 9) applied along
  each state axis, i.e. bilinear interpolation of every coefficient. Since ln f~ (log
  fit) or f~ (linear fit) is linear in the coefficients, the model at a state (s1, s2)
  of cell [a1, b1] x [a2, b2] is the blend, with weights (1-x)(1-y), x(1-y), (1-x)y, xy
  (x = (s1-a1)/(b1-a1), y = (s2-a2)/(b2-a2)), of the four corner models, each built
  here as a one-state ``SphericalHarmonicBRDF`` from its own coefficient row. Because
  cos(theta_i) cos(theta_r) is the same for all corners at a fixed geometry, blending
  ln f~ is blending ln f_r, and blending f~ is blending f_r;
* the path maximum: dense sampling of each straight piece of the path inside one grid
  cell (a lower bound on the true maximum, with a rigorous error bound from the piece's
  second derivative, derived in ``_path_reference``) and the convexity of the bilinear
  weights (an upper bound: no state of a cell exceeds the cell's largest corner).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

import brdfmodels as bm

from . import _refs as ref

NAMES = ["extinction", "melt_fraction"]

# --------------------------------------------------------------------------- heating


def _loss_free_plate(h, rho, c, r, t_melt, latent, t0):
    return bm.ThinPlateHeating(h, rho, c, r, 0.0, t_melt, latent, convection_w_m2_k=0.0,
                               ambient_temperature_k=t0, oxidation=None)


@given(thickness=st.floats(1e-4, 1e-2), log10_irr=st.floats(5.0, 9.0), refl=st.floats(0.0, 0.95),
       t_melt=st.floats(400.0, 3000.0))
@ref.FAST
def test_loss_free_plate_melt_times_and_linear_plateau(thickness, log10_irr, refl, t_melt):
    """Loss-free plate (eps = 0, h_c = 0, no oxidation, constant R; written above):
    melt onset t1 = rho c h (T_m - T0) / ((1 - R) E), full melt
    t2 = t1 + rho L h / ((1 - R) E); T(t) = T0 + (1 - R) E t / (rho c h) for t < t1; the
    melt fraction is (t - t1) / (t2 - t1) between them (constant absorbed power), 0
    before, 1 after; the temperature holds at T_m on the plateau.

    Required: 1 % on t1 and t2. Asserted: 1e-4 relative. The onset and full-melt times
    are located by solver events on an ODE whose right-hand side is a constant here, so
    an implicit solver at rtol 1e-8 integrates it essentially exactly (observed ~1e-15);
    1e-4 leaves room for the event location tolerance without hiding a formula error
    (a missing factor (1 - R), rho, c, h or L would be off by far more)."""
    rho, c, latent, t0 = 7900.0, 500.0, 2.7e5, 293.15
    irr = 10.0**log10_irr
    absorbed = (1.0 - refl) * irr
    t1 = rho * c * thickness * (t_melt - t0) / absorbed
    t2 = t1 + rho * latent * thickness / absorbed
    times = np.linspace(0.0, 1.5 * t2, 121)
    res = _loss_free_plate(thickness, rho, c, refl, t_melt, latent, t0).solve(times, irr)

    assert res.melt_onset_s is not None and res.full_melt_s is not None
    assert res.melt_onset_s == pytest.approx(t1, rel=1e-2)  # the requirement
    assert res.full_melt_s == pytest.approx(t2, rel=1e-2)
    assert res.melt_onset_s == pytest.approx(t1, rel=1e-4)  # what the solver actually reaches
    assert res.full_melt_s == pytest.approx(t2, rel=1e-4)

    before = times < t1 * (1 - 1e-9)
    np.testing.assert_allclose(res.temperature_k[before], t0 + absorbed * times[before] / (rho * c * thickness),
                               rtol=1e-6)
    np.testing.assert_allclose(res.melt_fraction[before], 0.0, atol=1e-9)
    during = (times > t1 * (1 + 1e-9)) & (times < t2 * (1 - 1e-9))
    assert during.sum() >= 5  # the plateau is sampled (it is >= 10 % of [0, t2])
    np.testing.assert_allclose(res.melt_fraction[during], (times[during] - t1) / (t2 - t1), rtol=0, atol=1e-6)
    np.testing.assert_allclose(res.temperature_k[during], t_melt, rtol=1e-6)
    after = times > t2 * (1 + 1e-9)
    np.testing.assert_allclose(res.melt_fraction[after], 1.0, atol=1e-9)
    # constant reflectance: nothing oxidises
    np.testing.assert_allclose(res.reflectance, refl, rtol=1e-12, atol=1e-15)


def test_heating_below_melting_reports_no_melt_times():
    """A plate that never reaches T_m (t1 of the formula above is after the last time):
    melt_onset_s and full_melt_s are None, melt fraction 0."""
    rho, c, h, r, e, tm, t0 = 7900.0, 500.0, 1e-3, 0.6, 1e6, 1700.0, 293.15
    t1 = rho * c * h * (tm - t0) / ((1 - r) * e)
    res = _loss_free_plate(h, rho, c, r, tm, 2.7e5, t0).solve(np.linspace(0, 0.5 * t1, 11), e)
    assert res.melt_onset_s is None and res.full_melt_s is None
    np.testing.assert_allclose(res.melt_fraction, 0.0, atol=1e-12)


def test_heating_history_of_melt_fraction_and_of_two_states():
    """HeatingResult.history: a one-state History of the melt fraction and a two-state
    History of (extinction, melt fraction), both piecewise linear in time between the
    result's times (np.interp of the result's own columns, written here): `.states`
    (N,) / (N, 2), `.state_at(t)` shape t.shape / t.shape + (2,), `.state_name` a str /
    a tuple of the two names."""
    rho, c, h, r, e, tm, latent, t0 = 7900.0, 500.0, 1e-3, 0.6, 1e7, 1700.0, 2.7e5, 293.15
    absorbed = (1 - r) * e
    t2 = rho * c * h * (tm - t0) / absorbed + rho * latent * h / absorbed
    times = np.linspace(0.0, 1.3 * t2, 57)
    ox = bm.OxidationModel.stainless_steel()
    res = bm.ThinPlateHeating(h, rho, c, r, 0.3, tm, latent, oxidation=ox).solve(times, e)
    assert res.full_melt_s is not None  # losses are small: it melts fully in the window

    one = res.history("melt_fraction")
    assert one.state_name == "melt_fraction"
    np.testing.assert_array_equal(one.times_s, res.times_s)
    np.testing.assert_array_equal(one.states, res.melt_fraction)
    t = np.random.default_rng(5).uniform(0.0, times[-1], (3, 4))
    assert np.shape(one.state_at(t)) == (3, 4)
    np.testing.assert_allclose(one.state_at(t), np.interp(t, res.times_s, res.melt_fraction), rtol=1e-12, atol=1e-15)

    two = res.history(["extinction", "melt_fraction"])
    assert tuple(two.state_name) == ("extinction", "melt_fraction") and isinstance(two.state_name, tuple)
    assert two.states.shape == (times.size, 2)
    np.testing.assert_array_equal(two.states, np.column_stack([res.extinction, res.melt_fraction]))
    at = two.state_at(t)
    assert at.shape == (3, 4, 2)
    np.testing.assert_allclose(at[..., 0], np.interp(t, res.times_s, res.extinction), rtol=1e-12)
    np.testing.assert_allclose(at[..., 1], np.interp(t, res.times_s, res.melt_fraction), rtol=1e-12, atol=1e-15)
    assert np.asarray(two.state_at(0.5 * t2)).shape == (2,)


# --------------------------------------------------------------------------- two-state SH model


def _directions(rng, n, zmin=0.1):
    """n random unit vectors of the upper hemisphere with z >= zmin (off the horizon)."""
    out = []
    while len(out) < n:
        v = rng.normal(size=3)
        v /= np.linalg.norm(v)
        v[2] = abs(v[2])
        if v[2] >= zmin:
            out.append(v)
    return np.array(out)


def _nodes(rng, n):
    """n strictly increasing, unevenly spaced nodes."""
    return rng.uniform(-1.0, 1.0) + np.concatenate([[0.0], np.cumsum(rng.uniform(0.05, 2.0, n - 1))])


def _table(seed, n1, n2, log, basis=None):
    """Random uneven grid, random coefficients (n1, n2, K). For log=False the constant
    term dominates so that every corner's f~ is positive (no clipping at 0)."""
    rng = np.random.default_rng(seed)
    basis = basis or bm.SHBasis(4, 2, 2, 0)
    k = basis.size
    n1s, n2s = _nodes(rng, n1), _nodes(rng, n2)
    if log:
        coef = rng.normal(0.0, 0.4, (n1, n2, k))
        coef[..., 0] += rng.normal(0.0, 1.0)
    else:
        coef = rng.normal(0.0, 0.04, (n1, n2, k))
        coef[..., 0] = rng.uniform(4.0, 6.0, (n1, n2))
    return rng, basis, n1s, n2s, coef


def _model(basis, n1s, n2s, coef, log, extrapolation="error"):
    return bm.DynamicBRDF(basis, states=[n1s, n2s], coefficients=coef, state_name=NAMES, fanout=0.6, log=log,
                          extrapolation=extrapolation)


def _corner_values(basis, coef, log, wi, wo):
    """(n1, n2, N): each node's one-state model at the direction pairs (f_r), and the
    quantity that is blended (ln f_r for a log fit, f_r for a linear one)."""
    n1, n2 = coef.shape[:2]
    f = np.array([[bm.SphericalHarmonicBRDF(basis, coef[i, j], fanout=0.6, log=log).evaluate(wi, wo)
                   for j in range(n2)] for i in range(n1)])
    assert np.all(f > 0) and np.all(np.isfinite(f))
    return f, (np.log(f) if log else f)


def _cell(nodes, s):
    """Index i of the cell [nodes[i], nodes[i+1]] holding s (the last cell for the end node)."""
    return int(np.clip(np.searchsorted(nodes, s, side="right") - 1, 0, len(nodes) - 2))


def _blend(n1s, n2s, v, s1, s2, log):
    """Reference: bilinear blend of the corner quantity v (n1, n2, N) at (s1, s2), then
    exp for a log fit. Weights written out: (1-x)(1-y), x(1-y), (1-x)y, xy."""
    i, j = _cell(n1s, s1), _cell(n2s, s2)
    x = (s1 - n1s[i]) / (n1s[i + 1] - n1s[i])
    y = (s2 - n2s[j]) / (n2s[j + 1] - n2s[j])
    b = ((1 - x) * (1 - y) * v[i, j] + x * (1 - y) * v[i + 1, j] + (1 - x) * y * v[i, j + 1]
         + x * y * v[i + 1, j + 1])
    return np.exp(b) if log else b


def _interior_and_edge_states(rng, n1s, n2s):
    """Random interior states, states on interior grid lines of each axis, on the outer
    edges, and the midpoint of a cell."""
    u = lambda lo, hi: float(rng.uniform(lo, hi))
    s = [(u(n1s[0], n1s[-1]), u(n2s[0], n2s[-1])) for _ in range(6)]
    s += [(float(rng.choice(n1s)), u(n2s[0], n2s[-1])), (u(n1s[0], n1s[-1]), float(rng.choice(n2s)))]
    s += [(float(n1s[0]), u(n2s[0], n2s[-1])), (float(n1s[-1]), u(n2s[0], n2s[-1])),
          (u(n1s[0], n1s[-1]), float(n2s[-1]))]
    s += [(0.5 * (n1s[0] + n1s[1]), 0.5 * (n2s[-2] + n2s[-1]))]
    return s


@given(seed=st.integers(0, 2**32 - 1), n1=st.integers(2, 5), n2=st.integers(2, 5), log=st.booleans())
@ref.FAST
def test_two_state_model_is_the_bilinear_blend_of_its_corner_models(seed, n1, n2, log):
    """At (s1, s2) in cell [a1,b1]x[a2,b2]: with log=True
    ln f_r = (1-x)(1-y) ln f_00 + x(1-y) ln f_10 + (1-x)y ln f_01 + xy ln f_11
    (equivalently for ln f~ = ln(f_r cos_i cos_r): the cosines are common); with
    log=False the same blend of f_r itself (all corners positive). f_ij = the one-state
    SphericalHarmonicBRDF of coefficient row C[i, j]. Random uneven nodes, coefficients
    and directions; interior states, states on interior grid lines and outer edges."""
    rng, basis, n1s, n2s, coef = _table(seed, n1, n2, log)
    m = _model(basis, n1s, n2s, coef, log)
    assert tuple(m.state_name) == tuple(NAMES)
    wi, wo = _directions(rng, 7), _directions(rng, 7)
    _, v = _corner_values(basis, coef, log, wi, wo)
    for s1, s2 in _interior_and_edge_states(rng, n1s, n2s):
        got = m.evaluate(wi, wo, state=[s1, s2])
        np.testing.assert_allclose(got, _blend(n1s, n2s, v, s1, s2, log), rtol=1e-10, err_msg=f"state ({s1}, {s2})")


@given(seed=st.integers(0, 2**32 - 1), n1=st.integers(2, 4), n2=st.integers(2, 4), log=st.booleans())
@ref.FAST
def test_two_state_model_at_a_node_is_that_node_model(seed, n1, n2, log):
    """At a node (x, y in {0, 1}) the blend weights are (1, 0, 0, 0): the model equals
    the one-state model of that node's coefficient row, exactly (bit for bit: the
    blended coefficients are 1 x C[i, j] + 0 x the others)."""
    rng, basis, n1s, n2s, coef = _table(seed, n1, n2, log)
    m = _model(basis, n1s, n2s, coef, log)
    wi, wo = _directions(rng, 9), _directions(rng, 9)
    f, _ = _corner_values(basis, coef, log, wi, wo)
    for i in range(n1):
        for j in range(n2):
            np.testing.assert_array_equal(m.evaluate(wi, wo, state=[n1s[i], n2s[j]]), f[i, j])


def test_two_state_out_of_range_error_names_the_state_and_clamp_holds_the_end_state():
    """extrapolation='error': a state outside the table raises ValueError naming the
    offending state (extinction or melt_fraction). extrapolation='clamp': each axis is
    held at its end node, so the value equals the bilinear reference at the clamped state."""
    rng, basis, n1s, n2s, coef = _table(11, 3, 4, True)
    m = _model(basis, n1s, n2s, coef, True)
    wi, wo = _directions(rng, 5), _directions(rng, 5)
    mid1, mid2 = 0.5 * (n1s[0] + n1s[-1]), 0.5 * (n2s[0] + n2s[-1])
    for state, name in [((n1s[-1] + 0.1, mid2), "extinction"), ((n1s[0] - 0.1, mid2), "extinction"),
                        ((mid1, n2s[-1] + 0.1), "melt_fraction"), ((mid1, n2s[0] - 1e-3), "melt_fraction")]:
        with pytest.raises(ValueError, match=name):
            m.evaluate(wi, wo, state=list(state))
        with pytest.raises(ValueError, match=name):
            m.evaluate_many(wi, wo, np.array([[mid1, mid2], state]))
    clamp = _model(basis, n1s, n2s, coef, True, extrapolation="clamp")
    _, v = _corner_values(basis, coef, True, wi, wo)
    for s1, s2 in [(n1s[-1] + 3.0, mid2), (n1s[0] - 0.5, mid2), (mid1, n2s[-1] + 1.0), (mid1, n2s[0] - 2.0),
                   (n1s[0] - 1.0, n2s[-1] + 1.0), (n1s[-1] + 1.0, n2s[0] - 1.0)]:
        c1, c2 = min(max(s1, n1s[0]), n1s[-1]), min(max(s2, n2s[0]), n2s[-1])
        np.testing.assert_allclose(clamp.evaluate(wi, wo, state=[s1, s2]), _blend(n1s, n2s, v, c1, c2, True),
                                   rtol=1e-10)


@pytest.mark.parametrize("log", [True, False])
def test_two_state_model_round_trips_through_json(log):
    """bm.loads(bm.dumps(m)): same to_dict, bit-identical evaluation and evaluate_many
    (all three reductions) at random states."""
    rng, basis, n1s, n2s, coef = _table(3, 4, 3, log)
    m = _model(basis, n1s, n2s, coef, log, extrapolation="clamp")
    back = bm.loads(bm.dumps(m))
    assert back.to_dict() == m.to_dict()
    assert tuple(back.state_name) == tuple(NAMES)
    wi, wo = _directions(rng, 8), _directions(rng, 8)
    states = np.column_stack([rng.uniform(n1s[0], n1s[-1], 5), rng.uniform(n2s[0], n2s[-1], 5)])
    for s in states:
        np.testing.assert_array_equal(back.evaluate(wi, wo, state=list(s)), m.evaluate(wi, wo, state=list(s)))
    for reduce in (None, "max", "path-max"):
        np.testing.assert_array_equal(back.evaluate_many(wi, wo, states, reduce=reduce),
                                      m.evaluate_many(wi, wo, states, reduce=reduce))


# --------------------------------------------------------------------------- evaluate_many and the path maximum

DENSE = 4001  # samples per straight piece of the path inside one grid cell


def _path(rng, kind, n1s, n2s):
    """A path (Q, 2) inside the table, of the given kind."""
    lo = np.array([n1s[0], n2s[0]])
    hi = np.array([n1s[-1], n2s[-1]])
    pt = lambda: rng.uniform(lo, hi)
    if kind == "random":
        return np.array([pt() for _ in range(rng.integers(2, 6))])
    if kind == "single":
        return pt()[None, :]
    if kind == "repeated":
        p = [pt() for _ in range(rng.integers(2, 5))]
        p = [q for q in p for _ in range(rng.integers(1, 4))]  # each point 1-3 times in a row
        return np.array(p)
    if kind == "grid-lines":  # along an s1 grid line, then along an s2 grid line, then to a node
        g1, g2 = float(rng.choice(n1s)), float(rng.choice(n2s))
        a, b = rng.uniform(n2s[0], n2s[-1], 2)
        return np.array([[g1, a], [g1, g2], [rng.uniform(n1s[0], n1s[-1]), g2], [n1s[-1], n2s[0]]])
    if kind == "many-cells":  # corner to corner and back across the table, zig-zag
        return np.array([lo, hi, [lo[0], hi[1]], [hi[0], lo[1]], 0.5 * (lo + hi)])
    if kind == "through-node":  # straight through a node: both grid lines crossed at one point
        pick = lambda nodes: rng.choice(nodes[1:-1]) if len(nodes) > 2 else rng.uniform(nodes[0], nodes[-1])
        node = np.array([pick(n1s), pick(n2s)])  # an interior node (or a point inside for a 2-node axis)
        step = rng.uniform(0.05, 1.0, 2) * (hi - lo) * rng.choice([-1.0, 1.0], 2)
        room = np.minimum(hi - node, node - lo) / np.abs(step)  # half-lengths that stay inside
        ends = np.array([node - min(1.0, room.min()) * step, node + min(1.0, room.min()) * step])
        return np.clip(ends, lo, hi)  # an ulp at the table's edge
    if kind == "table-edge":  # around the table's outer boundary
        return np.array([lo, [hi[0], lo[1]], hi, [lo[0], hi[1]], lo])
    if kind == "nodes":  # node to node: a path through grid corners only
        return np.array([[rng.choice(n1s), rng.choice(n2s)] for _ in range(rng.integers(2, 5))])
    raise AssertionError(kind)


def _path_reference(n1s, n2s, v, path, log):
    """(dense maximum, error bound of the dense maximum, corner upper bound), per direction.

    Every segment is cut where it crosses a grid line, so each piece lies in one cell
    (closed), and each piece is sampled at DENSE equally spaced points including its
    ends (the grid-line crossings and the path's vertices are thus sampled exactly).
    Along a piece, with t in [0, 1], x(t) = x0 + ax t and y(t) = y0 + ay t are linear,
    so the blended quantity g = sum of the bilinear weights x corner values is a
    quadratic in t with g'' = 2 ax ay (v00 - v10 - v01 + v11) (|ax|, |ay| <= 1: the
    piece is inside one cell). Its maximum is at a sampled end or at an interior point
    where g' = 0, and the nearest sample is within h/2 (h = 1/(DENSE-1)) of it, where
    g is lower by at most |g''| h^2 / 8. So the true maximum of g over the path is at
    most (dense max of g) + max |g''| h^2 / 8: multiplicatively exp(bound) for a log fit
    (g = ln f_r), additively for a linear one (g = f_r).
    Upper bound without sampling: every blend weight is in [0, 1] and they sum to 1, so
    g at any state of a cell is <= the cell's largest corner value (and exp is monotone).
    """
    t = np.linspace(0.0, 1.0, DENSE)
    h = 1.0 / (DENSE - 1)
    n_dir = v.shape[2]
    dense = np.full(n_dir, -np.inf)
    bound = np.zeros(n_dir)
    cells = set()
    if len(path) == 1:
        s1, s2 = path[0]
        cells.add((_cell(n1s, s1), _cell(n2s, s2)))
        dense = _blend(n1s, n2s, v, s1, s2, log)
    for a, b in zip(path[:-1], path[1:]):
        cuts = {0.0, 1.0}
        for ax_, nodes in ((0, n1s), (1, n2s)):
            if b[ax_] != a[ax_]:
                u = (nodes - a[ax_]) / (b[ax_] - a[ax_])
                cuts.update(float(x) for x in u[(u > 0) & (u < 1)])
        cuts = sorted(cuts)
        for u0, u1 in zip(cuts[:-1], cuts[1:]):
            mid = a + 0.5 * (u0 + u1) * (b - a)
            i, j = _cell(n1s, mid[0]), _cell(n2s, mid[1])
            cells.add((i, j))
            s = a[None, :] + (u0 + (u1 - u0) * t)[:, None] * (b - a)[None, :]
            x = (s[:, 0] - n1s[i]) / (n1s[i + 1] - n1s[i])
            y = (s[:, 1] - n2s[j]) / (n2s[j + 1] - n2s[j])
            # within the closed cell up to rounding
            assert np.all((x > -1e-9) & (x < 1 + 1e-9) & (y > -1e-9) & (y < 1 + 1e-9))
            g = (np.outer((1 - x) * (1 - y), v[i, j]) + np.outer(x * (1 - y), v[i + 1, j])
                 + np.outer((1 - x) * y, v[i, j + 1]) + np.outer(x * y, v[i + 1, j + 1]))
            val = np.exp(g) if log else g
            dense = np.maximum(dense, val.max(axis=0))
            ax, ay = x[-1] - x[0], y[-1] - y[0]
            g2 = np.abs(2 * ax * ay * (v[i, j] - v[i + 1, j] - v[i, j + 1] + v[i + 1, j + 1]))
            bound = np.maximum(bound, g2 * h * h / 8)
    corner = np.full(n_dir, -np.inf)
    for i, j in cells:
        c = np.max([v[i, j], v[i + 1, j], v[i, j + 1], v[i + 1, j + 1]], axis=0)
        corner = np.maximum(corner, np.exp(c) if log else c)
    return dense, bound, corner


PATH_KINDS = ["random", "single", "repeated", "grid-lines", "many-cells", "nodes", "through-node", "table-edge"]


@given(seed=st.integers(0, 2**32 - 1), n1=st.integers(2, 5), n2=st.integers(2, 5), log=st.booleans(),
       kind=st.sampled_from(PATH_KINDS))
@ref.FAST
def test_evaluate_many_states_max_and_path_max(seed, n1, n2, log, kind):
    """evaluate_many over states (Q, 2):
    reduce=None -> (N, Q), column q = the bilinear reference at state q;
    reduce='max' -> the max over the Q states of that reference;
    reduce='path-max' -> the max over the polyline joining the states (straight pieces):
      >= dense maximum x (1 - 1e-12) (sampled states lie on the path: a lower bound),
      <= dense maximum x exp(bound) (1 + 1e-12), the bound of ``_path_reference``
         (quadratic pieces between grid-line crossings, which are sampled exactly),
      <= dense maximum x (1 + 1e-6) (the issue's tolerance; the bound is asserted below
         1e-6 for these tables, so this follows from the previous line),
      <= the max over the corners of the cells the path touches (convex weights),
      >= reduce='max' (the path passes through its vertices)."""
    rng, basis, n1s, n2s, coef = _table(seed, n1, n2, log, basis=bm.SHBasis(3, 1, 2, 0))
    m = _model(basis, n1s, n2s, coef, log)
    wi, wo = _directions(rng, 6), _directions(rng, 6)
    _, v = _corner_values(basis, coef, log, wi, wo)
    path = _path(rng, kind, n1s, n2s)

    each = np.stack([_blend(n1s, n2s, v, s1, s2, log) for s1, s2 in path], axis=1)  # (N, Q)
    got = m.evaluate_many(wi, wo, path)
    assert got.shape == (6, len(path))
    np.testing.assert_allclose(got, each, rtol=1e-10)
    got_max = m.evaluate_many(wi, wo, path, reduce="max")
    assert got_max.shape == (6,)
    np.testing.assert_allclose(got_max, each.max(axis=1), rtol=1e-10)

    pm = m.evaluate_many(wi, wo, path, reduce="path-max")
    assert pm.shape == (6,)
    dense, bound, corner = _path_reference(n1s, n2s, v, path, log)
    if log:
        assert np.all(bound < 1e-6), bound  # the sampling is fine enough for the 1e-6 check
        upper = dense * np.exp(bound)
    else:
        assert np.all(bound < 1e-6 * dense), bound / dense
        upper = dense + bound
    assert np.all(pm >= dense * (1 - 1e-12)), (pm, dense)
    assert np.all(pm <= upper * (1 + 1e-12)), (pm, upper)
    assert np.all(pm <= dense * (1 + 1e-6)), (pm / dense - 1)
    assert np.all(pm <= corner * (1 + 1e-12)), (pm, corner)
    assert np.all(pm >= got_max * (1 - 1e-12))


def test_path_max_finds_an_interior_maximum_between_samples():
    """A case built so that the maximum is strictly inside a cell, away from every
    vertex and grid line: one cell, ln f_r corner values chosen through the constant
    coefficient only (the other coefficients are equal at the four corners), so along the
    diagonal path (0,0) -> (1,1) the blended log is
    g(t) = c00 (1-t)^2 + (c10 + c01) t(1-t) + c11 t^2 (+ common part),
    with c00 = c11 = 0 and c10 = c01 = a > 0: g = 2 a t (1 - t), maximal at t = 1/2,
    g(1/2) = a/2, while both ends (the given states) have g = 0. The constant basis
    function is y_0^0 = 1 / sqrt(4 pi), so a coefficient change c shifts ln f~ by
    c / sqrt(4 pi). Expected: path-max = f_common exp(a/2), 'max' = f_common."""
    basis = bm.SHBasis(2, 0, 2, 0)
    rng = np.random.default_rng(2)
    common = rng.normal(0, 0.3, basis.size)
    coef = np.tile(common, (2, 2, 1))
    a = 1.7
    coef[1, 0, 0] += a * math.sqrt(4 * math.pi)
    coef[0, 1, 0] += a * math.sqrt(4 * math.pi)
    m = _model(basis, np.array([0.0, 1.0]), np.array([0.0, 1.0]), coef, True)
    wi, wo = _directions(rng, 4), _directions(rng, 4)
    f0 = bm.SphericalHarmonicBRDF(basis, common, fanout=0.6, log=True).evaluate(wi, wo)
    f1 = bm.SphericalHarmonicBRDF(basis, coef[1, 0], fanout=0.6, log=True).evaluate(wi, wo)
    np.testing.assert_allclose(np.log(f1 / f0), a, rtol=1e-12)  # y_0^0 = 1/sqrt(4 pi) (orthonormal)
    path = np.array([[0.0, 0.0], [1.0, 1.0]])
    np.testing.assert_allclose(m.evaluate_many(wi, wo, path, reduce="max"), f0, rtol=1e-12)
    np.testing.assert_allclose(m.evaluate_many(wi, wo, path, reduce="path-max"), f0 * math.exp(a / 2), rtol=1e-12)
    np.testing.assert_allclose(m.evaluate(wi, wo, state=[0.5, 0.5]), f0 * math.exp(a / 2), rtol=1e-12)
    # the same path cut at a third: still the maximum at t = 1/2, inside the second piece
    path3 = np.array([[0.0, 0.0], [1 / 3, 1 / 3], [1.0, 1.0]])
    np.testing.assert_allclose(m.evaluate_many(wi, wo, path3, reduce="path-max"), f0 * math.exp(a / 2), rtol=1e-12)


# --------------------------------------------------------------------------- envelope


@given(seed=st.integers(0, 2**32 - 1), n1=st.integers(2, 4), n2=st.integers(2, 4), log=st.booleans())
@ref.FAST
def test_envelope_of_a_two_state_model_bounds_every_state(seed, n1, n2, log):
    """bm.Envelope(m) (no base, multiplier 1, no broadening) >= m at random interior and
    edge states: the bilinear weights are a convex blend, so the value at any state is
    <= the largest corner value of its cell <= the max over all nodes. The envelope is
    also compared with that max over the node models (written here) to 1e-12."""
    rng, basis, n1s, n2s, coef = _table(seed, n1, n2, log)
    m = _model(basis, n1s, n2s, coef, log)
    env = bm.Envelope(m)
    wi, wo = _directions(rng, 10), _directions(rng, 10)
    f, _ = _corner_values(basis, coef, log, wi, wo)
    e = env.evaluate(wi, wo)
    np.testing.assert_allclose(e, f.reshape(-1, f.shape[-1]).max(axis=0), rtol=1e-12)
    for s1, s2 in _interior_and_edge_states(rng, n1s, n2s):
        assert np.all(e >= m.evaluate(wi, wo, state=[s1, s2]) * (1 - 1e-12))
