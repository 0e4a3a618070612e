"""Power intercepted by spheres and cylinders (the ray tracer sees them as inscribed
polyhedra), against a reference written from range-safety.md section 1 alone.

Reference: the Gaussian power over the set of beam rays that meet the exact surface.
Rays are the lines of constant transverse coordinate s (units of the 1/e radius): origin
``pos + (a/2) s``, direction ``u + (phi/2) s``, density ``exp(-|s|^2) / pi``. The set of s
whose ray meets a convex body is convex; in polar coordinates about the image of the
body's centre its boundary radius rho(theta) is found by bisection on the exact
ray-sphere / ray-capped-cylinder test, and the radial integral is closed:
``int_0^rho t exp(-|c + t e|^2) dt = exp(-(|c|^2 - b^2)) [(e^{-b^2} - e^{-(rho + b)^2}) / 2
- b sqrt(pi)/2 (erf(rho + b) - erf(b))]``, b = c . e; the angle by the periodic
trapezoid rule (4096 nodes, doubled until two sums agree to 1e-7: an outline with corners
converges as 1/n^2). Every intersection is solved from the line's point nearest
the body's centre (ranges of 100s of m against mm radii cancel otherwise: 0.2 % found).
Nothing here calls the engine's outline code.

Checked: the engine's spot power is never below the exact value (less 1e-6 relative for
the reference's own accuracy, which its converged angular rule keeps under ~3e-8) and
exceeds it by no more than its stated ``spot_power_error_w``: where nothing else shows inside the outline it is the exact
surface's power, elsewhere the rays' total plus the bound on the power the facets lose.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from scipy.special import erf

import hazard
import scenes

from . import _refs as ref

P = 1000.0


def _hits(beam, s, shape, centre, axis, r, half):
    """Whether the rays at transverse coordinates s (N, 2) meet the exact body ahead of the aperture."""
    tr = s[:, :1] * beam.e1 + s[:, 1:] * beam.e2
    o = beam.pos + tr * (beam.a / 2)
    v = beam.u + tr * (beam.phi / 2)
    v = v / np.linalg.norm(v, axis=1, keepdims=True)
    shift = ((centre - o) * v).sum(1)  # to each line's point nearest the centre: no cancellation below
    q = o + shift[:, None] * v - centre
    if shape == "sphere":
        return ((q * q).sum(1) <= r * r) & (shift > 0)
    qa, va = q @ axis, v @ axis
    qp, vp = q - qa[:, None] * axis, v - va[:, None] * axis
    A, B, C = (vp * vp).sum(1), 2 * (qp * vp).sum(1), (qp * qp).sum(1) - r * r
    disc = B * B - 4 * A * C
    par = A < 1e-15
    sq = np.sqrt(np.maximum(disc, 0.0))
    with np.errstate(divide="ignore", invalid="ignore"):
        lo1 = np.where(par, np.where(C <= 0, -np.inf, np.inf), (-B - sq) / (2 * A))
        hi1 = np.where(par, np.where(C <= 0, np.inf, -np.inf), (-B + sq) / (2 * A))
        ok1 = par | (disc >= 0)
        ta, tb = (-half - qa) / va, (half - qa) / va
    flat = np.abs(va) < 1e-15
    lo2 = np.where(flat, np.where(np.abs(qa) <= half, -np.inf, np.inf), np.minimum(ta, tb))
    hi2 = np.where(flat, np.where(np.abs(qa) <= half, np.inf, -np.inf), np.maximum(ta, tb))
    lo, hi = np.maximum(lo1, lo2), np.minimum(hi1, hi2)
    return ok1 & (lo <= hi) & (hi + shift > 0)


def _screened(beam, s, screen):
    """Whether the rays at s (N, 2) cross the square plate ``screen`` = (centre, normal,
    tangent, side) ahead of the aperture."""
    cp, n, t, side = screen
    tr = s[:, :1] * beam.e1 + s[:, 1:] * beam.e2
    o = beam.pos + tr * (beam.a / 2)
    v = beam.u + tr * (beam.phi / 2)
    dist = ((cp - o) @ n) / (v @ n)
    x = o + dist[:, None] * v - cp
    return (dist > 0) & (np.abs(x @ t) <= side / 2) & (np.abs(x @ np.cross(n, t)) <= side / 2)


ANGLE_RTOL = 1e-7  # the angular rule doubled until two successive sums agree to this (its error then ~1/3 of it)
MAX_ANGLES = 2**19


def exact_fraction(beam, shape, centre, axis, r, half, n_theta=4096, screen=None, inner=None):
    """Fraction of the beam's power on rays meeting the exact body (module notes), less
    those a plate ``screen`` in front of it stops (the lit set stays convex when the
    plate's edge crosses it; ``inner``, a point of the body whose ray is lit, is then the
    polar centre). The angular rule starts at ``n_theta`` nodes and doubles (the new
    nodes between the old) until two successive sums agree to ``ANGLE_RTOL``: a smooth
    outline converges at once, a cornered one (a cylinder seen side-on, a screen's edge
    across it) as 1/n^2 - a thin disc's tail seen side-on was 1.3e-5 low at 4096 nodes."""
    rel = (centre if inner is None else inner) - beam.pos
    z = rel @ beam.u
    w = (beam.a + z * beam.phi) / 2
    c = np.array([rel @ beam.e1, rel @ beam.e2]) / w  # the centre's image (on its own ray)
    hits = _hits if screen is None else (lambda b, q, *a: _hits(b, q, *a) & ~_screened(b, q, screen))
    th = 2 * math.pi * np.arange(n_theta) / n_theta
    total = _radial_sum(hits, beam, c, th, (shape, centre, axis, r, half))
    while n_theta < MAX_ANGLES:
        more = total + _radial_sum(hits, beam, c, th + math.pi / n_theta, (shape, centre, axis, r, half))
        n_theta, th = 2 * n_theta, 2 * math.pi * np.arange(2 * n_theta) / (2 * n_theta)
        if abs(more / 2 - total) <= ANGLE_RTOL * abs(more / 2):
            return float(more * (2 * math.pi / n_theta) / math.pi)
        total = more
    raise AssertionError(f"the reference's angular rule did not converge to {ANGLE_RTOL} in {MAX_ANGLES} nodes")


def _radial_sum(hits, beam, c, th, body):
    """The sum over the angles ``th`` of the Gaussian's integral from the polar centre
    ``c`` out to the lit set's boundary (bisected on the exact ray test)."""
    e = np.stack([np.cos(th), np.sin(th)], axis=1)
    n_theta = len(th)
    lo, hi = np.zeros(n_theta), np.full(n_theta, 1e-3)
    while True:
        inside = hits(beam, c + hi[:, None] * e, *body)
        if not inside.any():
            break
        lo = np.where(inside, hi, lo)
        hi = np.where(inside, 2 * hi, hi)
    for _ in range(64):
        mid = 0.5 * (lo + hi)
        inside = hits(beam, c + mid[:, None] * e, *body)
        lo, hi = np.where(inside, mid, lo), np.where(inside, hi, mid)
    rho = 0.5 * (lo + hi)
    b = e @ c
    radial = np.exp(-(c @ c - b * b)) * (0.5 * (np.exp(-b * b) - np.exp(-(rho + b) ** 2))
                                          - b * math.sqrt(math.pi) / 2 * (erf(rho + b) - erf(b)))
    return float(radial.sum())


def _case(shape, R1, a, phi, f, fl, ox, oz, axis_dirn, rot, backstop=False, rtol=None, screen=False):
    """A sphere (diameter f D) or cylinder (diameter f D, length fl D, axis along
    ``axis_dirn``) centred at (ox, oz) D off a beam along +y from (0, -R1, 0); the scene
    rotated by ``rot``; with ``backstop`` a wide plate just behind the body (the rays
    beside the facets hit it behind the exact surface: still the outline's power); with
    ``screen`` a wide plate just in front whose edge crosses the body's middle 0.3 of its
    radius to one side (the lit part stays convex; the engine then takes the rays' total
    plus its faceting bound)."""
    Q = ref.euler_rotation(*rot)
    D = a + R1 * phi
    centre0 = np.array([ox * D, 0.0, oz * D])
    ax0 = ref.unit(axis_dirn)
    tangent0 = ref.unit(np.cross(ax0, [0.3, 0.5, 0.7]))
    pos, aim, centre, axis, tangent = (Q @ v for v in (np.array([0.0, -R1, 0.0]), np.zeros(3), centre0, ax0, tangent0))
    beam = ref.Beam(P, a, phi, pos, aim)
    r = f * D / 2
    half = fl * D / 2 if shape == "cylinder" else 0.0
    size = (2 * r,) if shape == "sphere" else (2 * r, 2 * half)
    targets = [dict(name="t", shape=shape, center=centre, normal=axis, tangent=tangent, size=size, material=ref.lambertian(0.5))]
    if backstop:
        reach = r + half + 1e-3 * D
        targets.append(dict(name="wall", shape="plate", center=Q @ (centre0 + np.array([0.0, reach, 0.0])), normal=Q @ [0, -1.0, 0],
                            tangent=Q @ [1.0, 0, 0], size=(20 * D + 4 * (r + half),) * 2, material=ref.lambertian(0.5)))
    scr = None
    if screen:
        reach = r + half + 1e-3 * D
        side = 20 * D + 4 * (r + half)
        cp0 = centre0 + np.array([-0.3 * r - side / 2, -reach, 0.0])
        scr = (Q @ cp0, Q @ np.array([0.0, -1.0, 0.0]), Q @ np.array([1.0, 0.0, 0.0]), side)
        targets.append(dict(name="screen", shape="plate", center=scr[0], normal=scr[1], tangent=scr[2], size=(side, side),
                            material=ref.lambertian(0.5)))
    analysis = "direction_grid_deg = 10.0\nrefine_levels = 0\n" + (f"beam_rtol = {rtol!r}\n" if rtol else "")
    text = ref.scene_text(power=P, a=a, phi=phi, position=pos, aim=aim, targets=targets, analysis=analysis)
    across = np.array([1.0, 0.0, 0.0]) - (ax0[0] * ax0 if shape == "cylinder" else 0.0)  # +x, across a cylinder's axis
    lean = 0.4 * r * across / np.linalg.norm(across) if np.linalg.norm(across) > 0.1 else np.zeros(3)
    inner = None if scr is None else Q @ (centre0 + lean)  # inside the body, its ray beside the screen's edge
    return text, P * exact_fraction(beam, shape, centre, axis, r, half, screen=scr, inner=inner)


def _check(text, expected):
    res = hazard.analyze(scenes.loads(text))
    t = next(t for t in res.targets if t.name == "t")
    got, bound = t.spot_power_w, t.spot_power_error_w
    slack = 1e-6 * expected + 1e-12 * P  # the reference's own accuracy (the trapezoid rule at an outline's corners)
    assert got >= expected - slack, f"spot power {got!r} below the exact {expected!r} (a faceted 'safe')"
    assert got - expected <= bound + slack, f"engine - exact = {got - expected:.4g} W exceeds the stated bound {bound:.4g} W"
    return got, bound


def test_sphere_in_beam_example_exact():
    """The README's beam_rtol example (r 5 cm, 3.6 cm off a 12 cm beam's axis at 100 m):
    exact 389.18 W; at the default beam_rtol the engine's value is within its bound of it
    and never below (it was 0.21 W below at 1e-5, beyond its 0.029 W bound)."""
    beam = ref.Beam(P, 0.02, 1e-3, [0.0, -100.0, 1.5], [0.0, 0.0, 1.5])
    expected = P * exact_fraction(beam, "sphere", np.array([0.03, 0.0, 1.52]), np.array([0.0, -1.0, 0.0]), 0.05, 0.0)
    assert abs(expected - 389.18) < 0.005  # the value the example's header quotes
    res = hazard.analyze(scenes.load(_example_path()))
    t = res.targets[0]
    assert expected - 1e-9 * expected <= t.spot_power_w <= expected + t.spot_power_error_w + 1e-9 * expected


def _example_path():
    from pathlib import Path

    return Path(__file__).resolve().parents[2] / "examples" / "accuracy" / "sphere_in_beam.toml"


@pytest.mark.parametrize("shape, f, fl, ox, oz, axis", [
    ("sphere", 0.8, 0.0, 0.3, 0.2, (0, -1, 0)),
    ("sphere", 6.0, 0.0, -0.5, 1.0, (0, 0, 1)),  # larger than the beam
    ("cylinder", 0.5, 3.0, 0.2, -0.1, (0, 0, 1)),  # axis across the beam
    ("cylinder", 4.0, 0.5, 0.6, 0.0, (0.3, -1.0, 0.2)),  # axis nearly along the beam, wider than it
])
@pytest.mark.parametrize("backstop, screen", [(False, False), (True, False), (False, True)])
def test_curved_spot_power_named(shape, f, fl, ox, oz, axis, backstop, screen):
    """Named spheres and cylinders, alone, with a wall right behind them and with a plate
    in front hiding part of them (the rays' total plus the faceting bound): exact <=
    engine <= exact + stated bound."""
    text, expected = _case(shape, 150.0, 0.02, 1e-3, f, fl, ox, oz, axis, (0.3, -0.2, 0.1), backstop, screen=screen)
    _check(text, expected)


CURVED_ARGS = dict(
    shape=st.sampled_from(["sphere", "cylinder"]), R1=ref.log_uniform(5.0, 2000.0), a=ref.log_uniform(2e-3, 0.05),
    phi=st.sampled_from([0.0, 1e-4, 5e-4, 2e-3]), f=ref.log_uniform(0.05, 10.0), fl=ref.log_uniform(0.05, 10.0),
    ox=st.floats(-1.5, 1.5), oz=st.floats(-1.5, 1.5),
    axis_dirn=st.tuples(st.floats(-1, 1), st.floats(-1, 1), st.floats(-1, 1)).filter(lambda v: math.hypot(*v) > 0.1),
    rot=st.tuples(st.floats(-math.pi, math.pi), st.floats(-math.pi, math.pi), st.floats(-math.pi, math.pi)),
    backstop=st.booleans(), screen=st.booleans(),
)


def _property(shape, R1, a, phi, f, fl, ox, oz, axis_dirn, rot, backstop, screen):
    text, expected = _case(shape, R1, a, phi, f, fl, ox, oz, axis_dirn, rot, backstop, screen=screen)
    _check(text, expected)


@ref.settings(ref.FAST, max_examples=3)  # 1.4 s CPU per example (12 took 25 s, 6 took 8.3 s CPU); the slow sweep draws 120
@given(**CURVED_ARGS)
def test_curved_spot_power_property(**kw):
    """Random spheres and cylinders (diameter 0.05-10 D: far smaller and far larger than
    the beam; cylinder length 0.05-10 D, any axis; offsets up to 1.5 D; collimated and
    diverging beams; whole scene rotated; half of them in front of a wall, half partly
    behind a plate): exact <= engine <= exact + stated bound."""
    _property(**kw)


@pytest.mark.slow
@ref.SLOW
@given(**CURVED_ARGS)
def test_curved_spot_power_sweep(**kw):
    """Larger sweep of ``test_curved_spot_power_property``. Its two misses (a strict xfail
    until 2026-11-27: engine - exact 1.08e-8 W over a stated bound of 5.2e-9 W for a thin
    disc of 4 mm seen side-on in a beam's tail, 4.6e-4 W) were the reference's: its
    4096-node angular rule was 1.3e-5 low at the disc's corners; doubled until it
    converges (``ANGLE_RTOL``), engine - exact is 4.87e-9 W, within the bound."""
    _property(**kw)


SWEEP_R1 = math.exp(2.0)  # the sweep's range [m]


@pytest.mark.parametrize("shape, a, phi, f, fl, ox, oz, axis", [
    ("cylinder", 0.01, math.exp(-7.0), 0.0625, 2.0, -0.021875, -0.4375, (1.0, 0.0, 0.0)),  # was 2.27 W of 17.47
    pytest.param("cylinder", 0.01, math.exp(-7.0), 0.125, 2.0, 0.01875, -0.0625, (1.0, 0.0, 0.0),
                 marks=pytest.mark.slow),  # was 36.1 W of 68.8
    pytest.param("cylinder", math.exp(-3.0), math.exp(-7.0), 0.25, 2.0, 0.021875, -0.375, (1.0, 0.0, 0.0),
                 marks=pytest.mark.slow),  # was 80.3 W of 83.1 (2.7 s)
    ("sphere", 0.01, 1e-4, 0.5, 0.5, 0.10625, 0.125, (0.0, 1.0, 0.0)),  # was 118.3 W of 132.2
])
def test_thin_body_between_the_cells_rays_behind_a_screen(shape, a, phi, f, fl, ox, oz, axis, R1=SWEEP_R1):
    """Found on 2026-11-26 by a sweep with the screen's edge and the bodies on the cells'
    boundaries (R1 = e^2 m, unrotated): a thin cylinder along the screen's edge, or a sphere,
    whose middle lay between every ray of the coarse cells it crossed. Its vertices (the
    only seeds of the refinement) were all at its ends or beyond the screen, so the rays
    saw only its ends: the engine gave as little as 13 % of the exact power, below it
    with a bound that did not cover it. Now every cell its projected hull meets is split
    to half its width (``beam._seed_cells``). exact <= engine <= exact + stated bound."""
    text, expected = _case(shape, R1, a, phi, f, fl, ox, oz, axis, (0.0, 0.0, 0.0), screen=True)
    _check(text, expected)


def test_sphere_rim_beside_a_screen_edge_between_rays():
    """The same sweep (R1 = 50 m, collimated): a sphere of one beam diameter whose rim
    passed between the rays of coarse cells mixed only between the screen (an exact
    plate) and empty beam. Such cells were never refined, and a cell whose five rays all
    missed but which the sphere's rim crossed gave the sphere nothing: 395.61 W (bound
    1.29 W) of the exact 396.77 W. Now a cell mixed between exact plates and empty beam
    is refined where a sampled target's hull meets it (``beam._needs_split``), and the
    power of a sampled target's hull inside leaves with no ray on it and one on nothing
    is added to its bound (``beam._unseen_power``). exact <= engine <= exact + bound."""
    test_thin_body_between_the_cells_rays_behind_a_screen("sphere", math.exp(-3.0), 0.0, 1.0, 0.125, 0.103125, -0.0625,
                                                           (0.75, 0.0, 1.0), R1=50.0)


@pytest.mark.parametrize("backstop", [False, True])
def test_sphere_rim_between_rays_on_a_wall_behind_it(backstop):
    """Found on 2026-11-27 with a wall behind the body as well as the screen in front (R1 =
    50 m, collimated, the grid along x and z): a sphere of one beam diameter whose top
    poked 1/32 of the radius into a coarsest cell (side w/2) between its five rays, which
    all met the wall behind it. The cell was never split (not mixed) and, none of its rays
    meeting nothing, gave the sphere nothing (the cap holds 1.97 W): at beam_rtol 3e-3
    (1.7 s; 2.8 s at the default 1e-3, 423.089 W, bound 1.145 W) 423.356 W (bound 1.983 W)
    of the exact 424.817 W; without the wall 425.673 W (bound 4.300 W). Now a ray whose
    hit lies deeper than the target's nearest point counts like one that meets nothing
    (``beam._unseen_power``): the wall changes nothing, 425.673 W either way.
    exact <= engine <= exact + bound."""
    text, expected = _case("sphere", 50.0, math.exp(-3.0), 0.0, 1.0, 0.5, -0.125, -0.234375, (0.0, 0.0, 1.0), (0.0, 0.0, 0.0),
                           backstop, 3e-3, screen=True)
    _check(text, expected)


# every case here is slow (the unscreened 1e-4 one took 93 s of the default suite): the default run keeps
# test_curved_spot_power_property and the named cases (exact <= engine <= exact + bound at the default beam_rtol)
@pytest.mark.parametrize("rtol, backstop", [pytest.param(1e-4, False, marks=pytest.mark.slow),
                                            pytest.param(1e-4, True, marks=pytest.mark.slow),
                                             pytest.param(1e-5, False, marks=pytest.mark.slow),
                                             pytest.param(1e-5, True, marks=pytest.mark.slow)])
@pytest.mark.parametrize("screen", [False, pytest.param(True, marks=pytest.mark.slow)])
def test_curved_spot_power_fine_rtol(rtol, backstop, screen):
    """At the fine beam_rtol levels of the README's table the sphere_in_beam geometry's
    power stays within its bound of the exact value, on both paths (before: 0.21 W below
    the exact 389.18 W with bounds of 0.057 / 0.029 W)."""
    text, expected = _case("sphere", 100.0, 0.02, 1e-3, 5.0 / 6.0, 0.0, 0.25, 1.0 / 6.0, (0, -1, 0), (0, 0, 0), backstop, rtol,
                           screen)
    _check(text, expected)


@pytest.mark.parametrize("rot", [pytest.param((0.0, 0.0, 0.0), marks=pytest.mark.slow), (0.7, -0.4, 1.9),
                                 pytest.param((-2.1, 0.3, 0.9), marks=pytest.mark.slow)])  # ~4 s each
def test_screen_in_front_stays_exact_in_a_turned_scene(rot):
    """Found on 2026-11-27 by the path matrix's "moved" variant on the sphere-rim case: the
    whole scene turned, the wide screen in front of the sphere lost its exact outline
    integral (447.26 W, bound 0) for the rays' total (473.88 W, bound 43.9 W) and its peak
    irradiance rose by 7e-5. A cell's ray inside the screen's outline, a float32 graze past
    its edge, went on to the sphere behind and counted as "something in front" of the
    screen. Hits beyond a target's plane are no such evidence (``beam.before_plane``).
    Reference (range-safety.md 1): the screen (20 D wide) is a half-plane whose edge lies
    d = 3/64 D from the beam's axis: power P erfc(d/w)/2, peak E0 exp(-d^2/w^2),
    E0 = P / (pi w^2), w = D/2; in every orientation of the scene."""
    a = math.exp(-3.0)
    text, _ = _case("sphere", 50.0, a, 0.0, 1.0, 0.125, 0.103125, -0.0625, (0.75, 0.0, 1.0), rot, screen=True)
    screen = next(t for t in hazard.analyze(scenes.loads(text)).targets if t.name == "screen")
    w, d = a / 2, (0.103125 - 0.15) * -a  # the edge 0.3 r = 0.15 D left of the sphere's centre
    assert screen.spot_power_w == pytest.approx(P * math.erfc(d / w) / 2, rel=1e-6)
    assert screen.spot_power_error_w <= 1e-9 * P
    assert screen.peak_irradiance_w_m2 == pytest.approx(P / (math.pi * w * w) * math.exp(-(d / w) ** 2), rel=1e-9)
