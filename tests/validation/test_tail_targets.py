"""A target the sampled beam misses but its Gaussian tail still reaches is said, never dropped.

The engine samples the beam on a square of +-4 1/e radii (``hazard.beam.HALF_WIDTH``); a target
wholly outside it gets no spot, so its reflection of the tail is not computed (issue 29's edge,
found for separate mirror targets beside a narrow high-power beam). Reference written here:
the Gaussian beam E = P / (pi w^2) exp(-(r / w)^2), w = (a + z phi) / 2 (1/e radius), at the
target's nearest edge (a plate normal to the axis: its near edge at z = the plate's range).
"""

from __future__ import annotations

import math
import re

import numpy as np
import pytest

import hazard
import scenes

from . import _refs as ref

P, A, PHI, Z, MPE = 1e5, 4e-3, 1e-5, 100.0, 50.0  # 1064 nm, 10 s: 50 W/m^2
W = (A + Z * PHI) / 2


def _scene(s_edge, size=0.02, shape="box"):
    """A box (a plate: ``shape``) whose near face is ``s_edge`` 1/e radii beside the beam's
    axis, its front face at Z."""
    dims = (size, size, size) if shape == "box" else (size, size)
    y = Z + (size / 2 if shape == "box" else 0.0)
    plate = dict(name="beside", shape=shape, center=np.array([s_edge * W + size / 2, y, 1.5]), normal=np.array([0.0, -1.0, 0.0]),
                 tangent=np.array([1.0, 0.0, 0.0]), size=dims, material=ref.lambertian(0.5))
    return scenes.loads(ref.scene_text(power=P, a=A, phi=PHI, position=np.array([0.0, 0.0, 1.5]), aim=np.array([0.0, Z, 1.5]),
                                       targets=[plate]))


def _tail_notes(res):
    return [n for n in res.notes if "outside the sampled beam" in n]


@pytest.mark.parametrize("s_edge", [4.3, 4.5, 4.8])
def test_a_target_in_the_beams_tail_is_said(s_edge):
    res = hazard.analyze(_scene(s_edge))
    assert res.mpe_w_m2 == MPE
    want = P / (math.pi * W * W) * math.exp(-s_edge**2)
    assert want >= 0.01 * MPE  # the design: the tail there still matters
    (note,) = _tail_notes(res)
    assert "'beside'" in note and "NOT computed" in note
    s_got = float(re.search(r"([0-9.]+) w from its axis", note).group(1))
    e_got = float(re.search(r"gives up to ([0-9.e+-]+) W/m\^2", note).group(1))
    assert s_got == pytest.approx(s_edge, rel=2e-3)
    assert e_got == pytest.approx(want, rel=6e-3)  # printed to 3 digits


def test_a_target_far_in_the_tail_is_not_said():
    """At 6 radii the tail gives P/(pi w^2) e^-36 = 1.2e-6 W/m^2: below 1 % of the MPE."""
    assert P / (math.pi * W * W) * math.exp(-36.0) < 0.01 * MPE
    assert _tail_notes(hazard.analyze(_scene(6.0))) == []


def test_a_lit_target_is_not_said():
    """A box across the axis is lit by the sampled beam, and a plate beside it gets its spot
    from its exact outline (erf over the polygon, whatever the sampled square): no tail note."""
    assert _tail_notes(hazard.analyze(_scene(-1.0))) == []
    res = hazard.analyze(_scene(4.5, shape="plate"))
    assert [sp.target.name for sp in res.spots] == ["beside"] and _tail_notes(res) == []
