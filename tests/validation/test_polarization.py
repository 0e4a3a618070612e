"""Fresnel mirrors and the laser's polarisation, against the Fresnel equations written
here (Born & Wolf 7th ed. 1.5.2): a scene whose laser polarisation is not known takes the
larger of R_s and R_p (a linearly polarised beam can be all s: at 45 deg on glass R_s is
1.8x the unpolarised mean, and the specular NOHD 1.4x longer), ``[laser] polarization =
"unpolarized"`` takes their mean. The specular NOHD is then the folded range R_f where
R 4P / (pi (a + R_f phi)^2) = MPE, minus the range to the mirror."""

from __future__ import annotations

import cmath
import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

import brdfmodels as bm
import hazard
import scenes
from hazard.physics.mpe import ocular_mpe

from . import _refs as ref

MPE = ocular_mpe(1064.0, 10.0).irradiance_w_m2  # an input, not under test
P, A, PHI, R_M = 2000.0, 0.02, 1e-3, 200.0


def fresnel_sp(theta, n, k=0.0):
    """(R_s, R_p) from air onto n + i k at incidence theta (written here)."""
    N = complex(n, k)
    ci = math.cos(theta)
    ct = cmath.sqrt(1 - math.sin(theta) ** 2 / (N * N))
    rs = (ci - N * ct) / (ci + N * ct)
    rp = (N * ci - ct) / (N * ci + ct)
    return abs(rs) ** 2, abs(rp) ** 2


def _scene(theta, n, k, polarization=None):
    """A Fresnel mirror 200 m north, turned so the beam meets it at ``theta``."""
    d = np.array([0.0, 1.0, 0.0])
    normal = np.array([math.sin(theta), -math.cos(theta), 0.0])  # angle theta with -d
    mirror = dict(name="mirror", shape="plate", center=np.array([0.0, R_M, 0.0]), normal=normal,
                  tangent=ref.unit(np.cross(normal, [0.0, 0.0, 1.0])), size=(3.0, 3.0),
                  material='{ model = "specular", n = %s, k = %s }' % (ref.fmt(n), ref.fmt(k)))
    text = ref.scene_text(power=P, a=A, phi=PHI, position=np.zeros(3), aim=np.array([0.0, R_M, 0.0]), targets=[mirror])
    if polarization:
        text = text.replace("[exposure]", f'polarization = "{polarization}"\n[exposure]')
    assert np.isclose(-d @ normal, math.cos(theta))
    return scenes.loads(text)


@ref.FAST
@given(theta=st.floats(0.1, 1.3), n=st.floats(1.3, 2.5), k=st.sampled_from([0.0, 0.5, 5.0]))
def test_unknown_polarization_takes_the_larger_of_s_and_p(theta, n, k):
    rs, rp = fresnel_sp(theta, n, k)
    worst, mean = max(rs, rp), 0.5 * (rs + rp)
    for pol, rho in ((None, worst), ("unpolarized", mean)):
        want = ref.folded_specular_range(P, rho, A, PHI, MPE) - R_M
        got = hazard.analyze(_scene(theta, n, k, pol)).targets[0].specular_nohd_static_m
        if want <= 0:
            assert got == 0.0
        else:
            assert got == pytest.approx(want, rel=2e-3)  # the beam's peak cell, as for every flat mirror


def test_glass_at_45_degrees_s_polarised_is_1_4x_the_unpolarised_distance():
    rs, rp = fresnel_sp(math.pi / 4, 1.5)
    assert rs / (0.5 * (rs + rp)) == pytest.approx(1.83, abs=0.01)
    worst = hazard.analyze(_scene(math.pi / 4, 1.5, 0.0)).targets[0].specular_nohd_static_m
    mean = hazard.analyze(_scene(math.pi / 4, 1.5, 0.0, "unpolarized")).targets[0].specular_nohd_static_m
    assert worst / mean > 1.3


def test_a_material_naming_its_polarization_keeps_it():
    m = bm.create("specular", n=1.5, polarization="unpolarized")
    wi = np.array([math.sin(0.8), 0.0, math.cos(0.8)])
    rs, rp = fresnel_sp(0.8, 1.5)
    assert m.specular_reflectance(wi) == pytest.approx(0.5 * (rs + rp), rel=1e-12)
    w = bm.create("specular", n=1.5, polarization="worst")
    assert w.specular_reflectance(wi) == pytest.approx(rs, rel=1e-12)
    assert bm.loads(bm.dumps(w)).polarization == "worst"
    with pytest.raises(ValueError, match="polarization"):
        bm.create("specular", reflectance=0.5, polarization="worst")
    with pytest.raises(ValueError, match="polarization"):
        bm.create("specular", n=1.5, polarization="circular")
