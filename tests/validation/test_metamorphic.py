"""Metamorphic properties of the whole analysis (issue 29, item 7), on random geometry:

- power linearity: scaling the laser power by k scales every irradiance and exposure by k
  (the engine's adaptive sampling is relative to the beam power, so exactly, to
  round-off), and each NOHD follows its own formula: the range r solving
  k c h(r) = MPE given the base root r0 of c h(r0) = MPE, i.e. h(r) = h(r0) / k, with
  h = exp(-mu r) / (a + r phi)^2 for the direct beam (laser-safety.md 3.1),
  exp(-mu r) / r^2 for a Lambertian lobe (far field) and exp(-mu r) / (1 + r / p)^2 for
  a flat mirror (p the virtual source's distance to the mirror: the image source,
  range-safety.md 4); the verdict is k E_base >= MPE;
- observer order and grouping: permuting the observer points and splitting them into
  other groups gives every point the same results;
- a Lambertian plate split into two halves edge to edge reflects what the whole does:
  the spot powers add exactly, and at an observer R away the two far-field point sources
  at the halves' power centroids differ from the whole's only to second order in the
  spot's size s over R (the first-order terms cancel about the power centroid): within
  4 (s / R)^2;
- a finer time step never lowers a peak: a target whose reflectance changes over time
  (a measured series, or the heating model), analysed at steps dt and dt / 2 (the finer
  grid holds every coarser time): no observer's peak irradiance is lower.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import hazard
import scenes

from . import _refs as ref

RTOL = 1e-9  # round-off: an exact relation computed twice
FEW = settings(ref.FAST, max_examples=6)  # two whole analyses per example: the default run stays short


def _frame(tilt, az):
    """Plate normal facing the laser (which stands on -y), tilted by ``tilt`` about an
    axis at azimuth ``az`` in the x-z plane; and a tangent."""
    axis = np.array([math.cos(az), 0.0, math.sin(az)])
    M = ref.rotation_matrix(axis, tilt)
    return M @ np.array([0.0, -1.0, 0.0]), M @ np.array([1.0, 0.0, 0.0])


def _around(n, dists, angles):
    """Observer points in front of a plate of normal n: (theta from n, azimuth) at dists."""
    e1, e2 = ref.transverse_basis(n)
    return [d * (math.cos(t) * n + math.sin(t) * (math.cos(p) * e1 + math.sin(p) * e2)) for d, (t, p) in zip(dists, angles)]


def _root(log_h, r0, k):
    """r with h(r) = h(r0) / k (h decreasing; ``log_h`` its logarithm): log bisection."""
    target = log_h(r0) - math.log(k)
    lo, hi = 1e-9, 1e12
    for _ in range(300):
        mid = math.sqrt(lo * hi)
        lo, hi = (mid, hi) if log_h(mid) > target else (lo, mid)
    return math.sqrt(lo * hi)


# --------------------------------------------------------------------------- power linearity

LIN_ARGS = dict(
    R1=ref.log_uniform(30.0, 500.0), a=ref.log_uniform(5e-3, 0.05), phi=ref.log_uniform(2e-4, 2e-3),
    f=ref.log_uniform(0.3, 3.0), tilt=st.floats(0.0, 1.0), az=st.floats(0.0, 2 * math.pi),
    mirror=st.booleans(), mu=st.sampled_from([0.0, 1e-4, 1e-3]), k=ref.log_uniform(0.01, 100.0),
    power=ref.log_uniform(1.0, 1e4),
    obs=st.lists(st.tuples(st.floats(0.05, 1.3), st.floats(0.0, 2 * math.pi), ref.log_uniform(20.0, 2000.0)),
                 min_size=2, max_size=5),
)


def _lin_scene(power, R1, a, phi, f, tilt, az, mirror, mu, obs):
    n, t = _frame(tilt, az)
    D = a + R1 * phi
    size = (f * D, f * D)
    beam = ref.Beam(power, a, phi, [0.0, -R1, 0.0], np.zeros(3), mu=mu)
    # a mirror's observers within a few divergences of its reflected axis (in its beam)
    spread = 2 * phi if mirror else 1.0
    pts = _around(ref.reflect(beam.u, n) if mirror else n, [d for _, _, d in obs], [(th * spread, p) for th, p, _ in obs])
    pts.append(np.array([0.3 * D, 3 * R1, 0.0]))  # down the beam past the target (its spill, or its shadow)
    target = dict(name="t", shape="plate", center=np.zeros(3), normal=n, tangent=t, size=size,
                  material=ref.specular(0.9) if mirror else ref.lambertian(0.7))
    return scenes.loads(ref.scene_text(power=power, a=a, phi=phi, position=beam.pos, aim=np.zeros(3), targets=[target],
                                       observers=[(f"o{i}", p, None) for i, p in enumerate(pts)], mu=mu)), beam, size


def _power_linearity(R1, a, phi, f, tilt, az, mirror, mu, k, power, obs):
    base_scene, beam, size = _lin_scene(power, R1, a, phi, f, tilt, az, mirror, mu, obs)
    base = hazard.analyze(base_scene)
    scaled = hazard.analyze(_lin_scene(k * power, R1, a, phi, f, tilt, az, mirror, mu, obs)[0])
    ob, os_ = base.observers, scaled.observers
    for key in ("peak_irradiance_w_m2", "static_irradiance_w_m2", "direct_irradiance_w_m2", "reflected_irradiance_w_m2",
                "radiant_exposure_j_m2"):
        np.testing.assert_allclose(getattr(os_, key), k * np.asarray(getattr(ob, key)), rtol=RTOL, atol=0, err_msg=key)
    ratio = k * np.asarray(ob.peak_irradiance_w_m2) / base.mpe_w_m2
    clear = np.abs(ratio - 1) > 1e-9  # a ratio on the MPE itself may round either way
    assert np.array_equal(np.asarray(scaled.hazardous)[clear], (ratio >= 1)[clear])
    tb, tk = base.targets[0], scaled.targets[0]
    assert tk.spot_power_w == pytest.approx(k * tb.spot_power_w, rel=RTOL)
    _check_nohds(base, scaled, beam, mu, k, mirror, size)


def _check_nohds(base, scaled, beam, mu, k, mirror, size):
    """Each NOHD follows its formula from the base run's value."""
    a, phi = beam.a, beam.phi
    n0, nk = base.sdz.nohd_m, scaled.sdz.nohd_m
    if n0 is not None and n0 > 0:
        want = _root(lambda r: -mu * r - 2 * math.log(a + r * phi), n0, k)
        assert nk == pytest.approx(want, rel=1e-7), "direct-beam NOHD"
    tb, tk = base.targets[0], scaled.targets[0]
    if mirror:
        d0 = tb.specular_nohd_static_m
        if d0 and d0 > 0 and math.isfinite(d0):
            p = float(np.linalg.norm(beam.pos - beam.source)) + float(np.linalg.norm(beam.pos))  # source -> mirror centre
            want = _root(lambda r: -mu * r - 2 * math.log1p(r / p), d0, k)
            # the sample setting the NOHD lies within half the mirror's diagonal of its centre:
            # its own p differs by at most h, which moves the scaled root by about |sqrt(k) - 1| h
            h = 0.5 * math.hypot(*size)
            assert abs(tk.specular_nohd_static_m - want) <= abs(math.sqrt(k) - 1) * h * 1.01 + 1e-7 * want
    else:
        r0 = tb.static_lobe.max_range_m if tb.static_lobe is not None else 0.0
        raised = [(lb.near_field or {}).get("directions_raised", 0) for lb in (tb.static_lobe, tk.static_lobe)]
        if r0 > 0 and not any(raised):  # both the point form's NOHD (the near-field integral left every node alone)
            want = _root(lambda r: -mu * r - 2 * math.log(r), r0, k)
            assert tk.static_lobe.max_range_m == pytest.approx(want, rel=1e-7), "Lambertian lobe NOHD"
        elif r0 > 0:  # a lobe near its spot (hazard.physics.near_field_lobe): more power never shortens it
            assert (tk.static_lobe.max_range_m - r0) * (k - 1) >= 0, "lobe NOHD monotone in power"


@FEW
@given(**LIN_ARGS)
def test_power_linearity(**kw):
    """Scale the power by k (0.01-100): irradiances and exposures x k, NOHDs by their
    formulas, verdicts k E >= MPE; random plates (Lambertian or flat mirror, 0.3-3 beam
    diameters, tilted up to 57 deg) 30-500 m out, mu in {0, 1e-4, 1e-3}."""
    _power_linearity(**kw)


@pytest.mark.slow
@ref.SLOW
@given(**LIN_ARGS)
def test_power_linearity_sweep(**kw):
    """Larger sweep of ``test_power_linearity``."""
    _power_linearity(**kw)


# --------------------------------------------------------------------------- observer order and grouping

GROUP_ARGS = dict(
    R1=ref.log_uniform(30.0, 500.0), tilt=st.floats(0.0, 1.0), az=st.floats(0.0, 2 * math.pi),
    obs=st.lists(st.tuples(st.floats(0.0, 1.5), st.floats(0.0, 2 * math.pi), ref.log_uniform(5.0, 3000.0)),
                 min_size=3, max_size=8),
    seed=st.integers(0, 2**32 - 1), mirror=st.booleans(),
)


def _group_scene(R1, n, t, groups, mirror):
    target = dict(name="t", shape="plate", center=np.zeros(3), normal=n, tangent=t, size=(0.3, 0.2),
                  material=ref.specular(0.9) if mirror else ref.lambertian(0.7))
    text = ref.scene_text(power=2000.0, a=0.02, phi=1e-3, position=[0.0, -R1, 0.0], aim=np.zeros(3), targets=[target],
                          mu=1e-4)
    for g, pts in enumerate(groups):
        text += f'[[observers]]\nname = "g{g}"\npoints_m = [{", ".join(ref.vec(p) for p in pts)}]\n'
    return scenes.loads(text)


def _grouping(R1, tilt, az, obs, seed, mirror):
    n, t = _frame(tilt, az)
    pts = _around(n, [d for _, _, d in obs], [(th, p) for th, p, _ in obs])
    pts.append(np.array([0.05, 2 * R1, 0.02]))  # in the beam beyond the target
    rng = np.random.default_rng(seed)
    order = rng.permutation(len(pts))
    cuts = np.sort(rng.choice(np.arange(1, len(pts)), size=rng.integers(0, len(pts) - 1), replace=False))
    groups = [[pts[i] for i in part] for part in np.split(order, cuts)]
    one = hazard.analyze(_group_scene(R1, n, t, [pts], mirror))
    many = hazard.analyze(_group_scene(R1, n, t, groups, mirror))
    for key in ("peak_irradiance_w_m2", "static_irradiance_w_m2", "radiant_exposure_j_m2", "first_exceedance_s"):
        a = np.asarray(getattr(one.observers, key), float)[order]
        b = np.asarray(getattr(many.observers, key), float)
        np.testing.assert_allclose(b, a, rtol=RTOL, atol=0, err_msg=key)
    assert np.array_equal(np.asarray(many.hazardous), np.asarray(one.hazardous)[order])


@FEW
@given(**GROUP_ARGS)
def test_observer_order_and_grouping(**kw):
    """Observers permuted and split into random groups: each point's results unchanged."""
    _grouping(**kw)


@pytest.mark.slow
@ref.SLOW
@given(**GROUP_ARGS)
def test_observer_order_and_grouping_sweep(**kw):
    """Larger sweep of ``test_observer_order_and_grouping``."""
    _grouping(**kw)


# --------------------------------------------------------------------------- a plate split in two halves

SPLIT_ARGS = dict(
    R1=ref.log_uniform(30.0, 500.0), fw=ref.log_uniform(0.3, 3.0), fh=ref.log_uniform(0.3, 3.0),
    cut=st.floats(0.2, 0.8), ox=st.floats(-0.5, 0.5), oz=st.floats(-0.5, 0.5), tilt=st.floats(0.0, 1.0),
    az=st.floats(0.0, 2 * math.pi), mu=st.sampled_from([0.0, 1e-4]),
    obs=st.lists(st.tuples(st.floats(0.0, 1.4), st.floats(0.0, 2 * math.pi), ref.log_uniform(2e3, 2e4)), min_size=1, max_size=4),
)


def _split_scene(R1, center, n, t, pieces, mu, pts):
    """``pieces``: (x0, x1) along the tangent of a plate of height hgt: one target each."""
    x, y, _ = ref.plate_frame(n, t)
    targets = []
    for i, (x0, x1, hgt) in enumerate(pieces):
        c = center + 0.5 * (x0 + x1) * x
        targets.append(dict(name=f"p{i}", shape="plate", center=c, normal=n, tangent=t, size=(x1 - x0, hgt),
                            material=ref.lambertian(0.6)))
    return scenes.loads(ref.scene_text(power=1000.0, a=0.02, phi=1e-3, position=[0.0, -R1, 0.0], aim=np.zeros(3),
                                       targets=targets, observers=[(f"o{i}", p, None) for i, p in enumerate(pts)], mu=mu))


def _split(R1, fw, fh, cut, ox, oz, tilt, az, mu, obs):
    D = 0.02 + R1 * 1e-3
    w, hgt = fw * D, fh * D
    center = np.array([ox * D, 0.0, oz * D])
    n, t = _frame(tilt, az)
    pts = [center + p for p in _around(n, [d for _, _, d in obs], [(th, p) for th, p, _ in obs])]
    xc = -w / 2 + cut * w
    whole = hazard.analyze(_split_scene(R1, center, n, t, [(-w / 2, w / 2, hgt)], mu, pts))
    halves = hazard.analyze(_split_scene(R1, center, n, t, [(-w / 2, xc, hgt), (xc, w / 2, hgt)], mu, pts))
    p_whole, err_whole = whole.targets[0].spot_power_w, whole.targets[0].spot_power_error_w
    p_halves = sum(tr.spot_power_w for tr in halves.targets)
    err_halves = sum(tr.spot_power_error_w for tr in halves.targets)
    assert abs(p_halves - p_whole) <= err_whole + err_halves + 1e-9 * p_whole, "the spot powers add"
    s = math.hypot(w, hgt)
    dist = np.linalg.norm(np.asarray(pts) - center, axis=1)
    tol = 4 * (s / dist) ** 2 + (err_whole + err_halves) / max(p_whole, 1e-300) + RTOL
    e_whole = np.asarray(whole.observers.reflected_irradiance_w_m2)
    e_halves = np.asarray(halves.observers.reflected_irradiance_w_m2)
    assert np.all(np.abs(e_halves - e_whole) <= tol * e_whole + 1e-12 * whole.mpe_w_m2), (e_whole, e_halves, tol)


@FEW
@given(**SPLIT_ARGS)
def test_diffuse_plate_split_in_two_halves(**kw):
    """A Lambertian plate (0.3-3 beam diameters a side, off-centre, tilted) vs its two
    halves edge to edge (cut at 20-80 %): spot powers add, observers 2-20 km away get the
    same irradiance within 4 (s / R)^2 (second order of the far-field point sources)."""
    _split(**kw)


@pytest.mark.slow
@ref.SLOW
@given(**SPLIT_ARGS)
def test_diffuse_plate_split_in_two_halves_sweep(**kw):
    """Larger sweep of ``test_diffuse_plate_split_in_two_halves``."""
    _split(**kw)


# --------------------------------------------------------------------------- a finer time step

STEP_ARGS = dict(
    kind=st.sampled_from(["series", "heating"]), R1=ref.log_uniform(10.0, 100.0), tilt=st.floats(0.0, 0.8),
    az=st.floats(0.0, 2 * math.pi), steps=st.integers(3, 12),
    series=st.lists(st.floats(0.0, 1.0), min_size=3, max_size=7),
    obs=st.lists(st.tuples(st.floats(0.0, 1.4), st.floats(0.0, 2 * math.pi), ref.log_uniform(5.0, 500.0)), min_size=1, max_size=4),
)


def _history(kind, series, t_end):
    if kind == "series":  # nodes off the step grid, ending dark: the brightest moment falls between steps
        states = list(series) + [0.0]
        times = np.linspace(0.0, 0.9 * t_end, len(states)) * np.linspace(1.0, 0.93, len(states)) + 0.0137
        return ('[targets.history]\nkind = "series"\nstate = "reflectance_factor"\n'
                f"times_s = {ref.vec(times)}\nstates = {ref.vec(states)}\n")
    return ('[targets.history]\nkind = "heating"\nplate = "stainless_steel"\nthickness_m = 0.0002\n'
            'state = "reflectance_factor"\n')


def _step_scene(kind, R1, n, t, series, pts, dt, t_end=3.0):
    target = dict(name="t", shape="plate", center=np.zeros(3), normal=n, tangent=t, size=(0.2, 0.2),
                  material=ref.lambertian(0.8))
    text = ref.scene_text(power=3000.0, a=0.01, phi=1e-3, position=[0.0, -R1, 0.0], aim=np.zeros(3), targets=[target],
                          observers=[(f"o{i}", p, None) for i, p in enumerate(pts)], duration_s=t_end,
                          analysis=f"time_end_s = {ref.fmt(t_end)}\ntime_step_s = {ref.fmt(dt)}\n")
    return scenes.loads(text.replace("[[observers]]", _history(kind, series, t_end) + "[[observers]]", 1))


def _finer_step(kind, R1, tilt, az, steps, series, obs):
    n, t = _frame(tilt, az)
    pts = _around(n, [d for _, _, d in obs], [(th, p) for th, p, _ in obs])
    dt = 3.0 / steps
    coarse = hazard.analyze(_step_scene(kind, R1, n, t, series, pts, dt))
    fine = hazard.analyze(_step_scene(kind, R1, n, t, series, pts, dt / 2))
    assert set(np.round(coarse.times_s, 9)) <= set(np.round(fine.times_s, 9)), "the finer grid holds the coarse times"
    pc, pf = np.asarray(coarse.observers.peak_irradiance_w_m2), np.asarray(fine.observers.peak_irradiance_w_m2)
    assert np.all(pf >= pc * (1 - RTOL)), (pc, pf)


@FEW
@given(**STEP_ARGS)
def test_a_finer_time_step_never_lowers_a_peak(**kw):
    """A Lambertian plate whose reflectance factor follows a measured series (nodes off
    the step grid, ending at 0, so its brightest moment falls between steps) or the
    stainless-steel heating model; steps dt and dt/2: no peak lower."""
    _finer_step(**kw)


@pytest.mark.slow
@ref.SLOW
@given(**STEP_ARGS)
def test_a_finer_time_step_never_lowers_a_peak_sweep(**kw):
    """Larger sweep of ``test_a_finer_time_step_never_lowers_a_peak``."""
    _finer_step(**kw)


def test_the_peak_holds_a_measured_series_brightest_moment():
    """Reflectance factor linear between the series' nodes (0.1, 0.9, 0.2, 1.0, 0.0): the
    brightest moment is the node at 1.0, so each observer's peak is at least its
    irradiance under a constant factor 1.0 (the reflected irradiance is linear in the
    factor), whatever the step."""
    n, t = _frame(0.3, 1.0)
    pts = _around(n, [50.0, 200.0], [(0.1, 0.0), (0.6, 1.0)])
    one = hazard.analyze(_step_scene("series", 30.0, n, t, [1.0, 1.0, 1.0, 1.0], pts, 0.5))
    got = hazard.analyze(_step_scene("series", 30.0, n, t, [0.1, 0.9, 0.2, 1.0], pts, 0.5))
    full = np.asarray(one.observers.peak_irradiance_w_m2)
    assert full.min() > 0
    assert np.all(np.asarray(got.observers.peak_irradiance_w_m2) >= full * (1 - RTOL))
