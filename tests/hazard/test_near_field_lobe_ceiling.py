"""The near-field lobe's work ceiling (hazard.physics.near_field_lobe CEILING_FACTOR, the
integral's ``max_evaluations``).

The reproducer (tests/validation/test_curved_spot_power.py's rotated cylinder with a wall
behind and a screen in front) took 419 s: its cylinder's facets stand edge-on to the beam
(cos i ~ 1e-9), their leaves map onto 4294 triangles up to 6.5 km long holding 0.2 W of
the spot's 92 W, the spot's size is then 127 m (its near field 2.5 km) and the lobe's
first integral call (the scan's 143 first samples) bisected those triangles down to each
observer's distance: 674 million kernel evaluations against a budget of 500 000 checked
only between calls. Those facets were hits only through float32: the rays started at the
laser, 100 m out (``RayScene._ahead`` now starts them at the triangles' box, and the spot
is 3 mm across); the tests rebuild the old spot to keep the ceiling tested.
"""

from __future__ import annotations

import numpy as np
import pytest

import scenes
from hazard.physics import near_field, near_field_lobe
from hazard.physics.engine import near_field_w_m2
from hazard.physics.keepout import nohd_range_fn
from hazard.physics.mpe import ocular_mpe
from hazard.pipeline.spots import ray_scene, trace_beam
from tests.validation.test_curved_spot_power import _case

MPE_W_M2 = ocular_mpe(1064.0, 10.0).irradiance_w_m2  # the case's 1064 nm, 10 s: an input, not under test
ROTATION = (0.6586652289504804, 1.3672976968937096, -1.8623530121926877)


def _edge_on_cylinder_spot():
    """The reproducer's cylinder spot (its beam traced, no analysis), its rays started at
    the laser as before d7b260c: their float32 rounding 100 m out made the facets edge-on
    to the beam hits, and those leaves the kilometre-long triangles (rays started at the
    triangles' box give a spot 3 mm across). The ceiling is the safety net for any spot
    that still has such triangles."""
    from hazard.physics import rays

    text, _ = _case("cylinder", 100.0, 0.01, 0.0, 0.25, 0.5, 0.03125, 0.0625, (0, 0, 1), ROTATION, backstop=True, screen=True)
    scene = scenes.loads(text)
    ahead = rays.RayScene._ahead
    rays.RayScene._ahead = lambda self, o, d: (o, np.zeros(len(o)))  # every ray from the laser itself
    try:
        return next(s for s in trace_beam(scene, ray_scene(scene, "embree", 1), 0.0).built.spots if s.target.name == "t")
    finally:
        rays.RayScene._ahead = ahead


@pytest.fixture(scope="module")
def spot():
    return _edge_on_cylinder_spot()


def test_one_call_stops_at_the_ceiling(spot, monkeypatch):
    """A lobe function whose integral at a point 100 m above the spot costs 4 million
    evaluations (the case still has its kilometre-long triangles: a near field over 1 km)
    stops that call at ``CEILING_FACTOR x MAX_EVALUATIONS`` (past it by one depth's work at most) and
    decides the point by its bound (hazardous, counted in ``bound_points``); before, the
    call ran to its end."""
    monkeypatch.setattr(near_field_lobe, "MAX_EVALUATIONS", 100_000)
    fn = nohd_range_fn(spot, MPE_W_M2, 0.0, 1.0, None)
    assert fn.far_m > 1000.0
    dirs = np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0]])
    fn.prepare(dirs, np.asarray(fn.base(dirs), float))
    hot = fn.hazardous(fn.c + 100.0 * fn.frame[2][None, :])
    assert fn.evaluations <= 1_000_000, fn.evaluations  # the ceiling (4 x 100 000) and one depth's work; the call: 4.04 million
    assert hot.all() and fn.bound_points == 1


def test_below_the_ceiling_the_integral_is_the_same_bits(monkeypatch):
    """``max_evaluations`` at the work changes nothing (bit for bit); below it, the
    observers finished are the same bits and the others NaN (4 observers 3 cm from a
    sphere's spot, in blocks of 2)."""
    text, _ = _case("sphere", 50.0, 0.02, 0.0, 0.5, 0.0, 0.0, 0.0, (0, 0, 1), (0.3, -0.2, 0.1))
    scene = scenes.loads(text)
    spot = trace_beam(scene, ray_scene(scene, "embree", 1), 0.0).built.spots[0]
    monkeypatch.setattr(near_field, "_PAIR_BLOCK", 2 * len(spot.patches.sample))  # 2 observers a block
    ph = np.linspace(-np.pi, np.pi, 4, endpoint=False)
    dirs = np.stack([0.6 * np.cos(ph), 0.6 * np.sin(ph), np.full(len(ph), 0.8)], 1)
    pts = spot.centroid + 0.03 * dirs @ spot.mean_frame
    def work(p, **kw):
        before = near_field.STATS.snapshot()
        return near_field_w_m2(spot, p, np.ones(len(p)), 0.0, None, **kw), near_field.stats_since(before)["evaluations"]

    full, n = work(pts)
    assert np.array_equal(work(pts, max_evaluations=n)[0], full)
    block = max(1, near_field._PAIR_BLOCK // max(len(spot.points), len(spot.patches.sample)))  # observers a block
    assert block < len(pts)
    cut = work(pts, max_evaluations=work(pts[:block])[1])[0]  # the first block's work: the others not started
    assert np.array_equal(cut[:block], full[:block]) and np.isnan(cut[block:]).all()
    assert np.isnan(work(pts, max_evaluations=1)[0]).all()  # stopped within the first block
