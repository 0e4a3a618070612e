"""Mirror beams in the danger-zone verdict (report.json ``sdz.mirror_beams``) and a beam
below the MPE from its aperture on, against geometry written here.

A flat mirror 200 m down range turns the beam by the reflection law r = d - 2 (d.n) n;
its specular NOHD is the folded range R_f where rho 4P / (pi (a + R_f phi)^2) = MPE, minus
the 200 m to the mirror (laser-safety.md 3.1). The reflected ray then ends on the first
backstop before R_f - 200 m or is not contained; its ground track leaves a square range
boundary of half-side L exactly when it gets past x = L (the ray runs along +x from
x = 0). A mirror beam that leaves the range or reaches its NOHD in the open is a hazard
(`--fail-on-hazard=zones` exits 3; report.json ``hazard_zones``) even with no observer in
the scene (it said "contained by backstops ... within the range boundary" and exited 0).
The default `--fail-on-hazard` (observers) exits 0 there: no listed observer is at risk.
"""

from __future__ import annotations

import io
import math
import re

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

import hazard
import scenes
from hazard.cli import main
from hazard.physics.mpe import ocular_mpe

from . import _refs as ref

MPE = ocular_mpe(1064.0, 10.0).irradiance_w_m2  # an input, not under test
P, A, PHI, RHO, R_M = 200.0, 0.02, 1e-3, 0.9, 200.0


def _mirror_nohd():
    return ref.folded_specular_range(P, RHO, A, PHI, MPE) - R_M


def _text(out_dir_m, *, wall_x=None, boundary=None, power=P):
    """Scene text: the laser at the origin aiming north at a 2 m mirror that turns the
    beam to ``out_dir_m``; a 400 m tall wall across x = ``wall_x``; a square boundary."""
    d = np.array([0.0, 1.0, 0.0])
    r = ref.unit(out_dir_m)
    n = ref.unit(r - d)  # reflection law: r = d - 2 (d.n) n for n along r - d
    tangent = ref.unit(np.cross(n, [0.0, 0.0, 1.0]))
    mirror = dict(name="mirror", shape="plate", center=np.array([0.0, R_M, 0.0]), normal=-n if n @ d > 0 else n,
                  tangent=tangent, size=(2.0, 2.0), material=ref.specular(RHO))
    text = ref.scene_text(power=power, a=A, phi=PHI, position=np.zeros(3), aim=np.array([0.0, R_M, 0.0]), targets=[mirror])
    extra = ""
    if wall_x is not None:
        extra += f'[[occluders]]\nshape = "box"\ncenter_m = {ref.vec([wall_x, R_M, 0.0])}\nsize_m = [1.0, 40.0, 400.0]\n'
    if boundary is not None:
        L = boundary
        extra += f"[range]\nboundary_m = [[{-L}, {-L}], [{L}, {-L}], [{L}, {L}], [{-L}, {L}]]\n"
    return text.replace("[analysis]", extra + "[analysis]")


def _scene(out_dir_m, **kw):
    return scenes.loads(_text(out_dir_m, **kw))


def _entry(res):
    (entry,) = res.sdz.mirror_beams
    return entry


def test_a_mirror_beam_in_the_open_is_not_contained_and_is_a_hazard():
    nohd = _mirror_nohd()
    res = hazard.analyze(_scene([1.0, 0.0, -0.05], boundary=nohd / 2))  # descending: every ray below the horizon
    assert res.targets[0].specular_nohd_static_m == pytest.approx(nohd, rel=1e-3)
    e = _entry(res)
    assert e.nohd_m == pytest.approx(nohd, rel=1e-3) and e.max_reach_m == pytest.approx(nohd, rel=1e-3)
    # no terrain: nothing stops it; its ground track (along +x from x ~ 0) crosses x = nohd / 2
    assert e.contained is False and e.leaves_boundary is True and e.above_horizon is False
    assert res.any_hazard
    import json

    from hazard.outputs.report import report_dict
    from hazard.outputs.report_schema import validate_report

    validate_report(json.loads(json.dumps(report_dict(res))))  # sdz.mirror_beams[].leaves_boundary against its schema (issue 35)


def test_a_mirror_beam_inside_a_large_range_still_reaches_its_nohd_in_the_open():
    e = _entry(hazard.analyze(_scene([1.0, 0.0, 0.0], boundary=2 * _mirror_nohd() + 400)))
    assert e.contained is False and e.leaves_boundary is False


def test_a_wall_before_the_nohd_contains_the_mirror_beam():
    nohd = _mirror_nohd()
    wall = nohd / 2
    e = _entry(hazard.analyze(_scene([1.0, 0.0, 0.0], wall_x=wall, boundary=nohd)))
    assert e.contained is True and e.leaves_boundary is False
    assert e.max_reach_m == pytest.approx(wall - 0.5, rel=1e-3)  # the wall's near face; the rays start within 1 m of x = 0


def test_a_wall_beyond_the_nohd_contains_nothing():
    e = _entry(hazard.analyze(_scene([1.0, 0.0, 0.0], wall_x=1.5 * _mirror_nohd())))
    assert e.contained is False and e.leaves_boundary is None


@ref.FAST
@given(rise=st.floats(0.01, 0.5), side=st.sampled_from([1.0, -1.0]))
def test_a_rising_mirror_beam_is_above_the_horizon(rise, side):
    e = _entry(hazard.analyze(_scene([side, 0.0, rise])))
    assert e.contained is False and e.above_horizon is True


def test_mirror_beam_hazard_exits_3_with_no_observer(tmp_path):
    path = tmp_path / "m.toml"
    path.write_text(_text([1.0, 0.0, 0.0], boundary=_mirror_nohd() / 2))
    out = io.StringIO()
    code = main(["run", str(path), "-o", str(tmp_path / "o"), "--fail-on-hazard=zones"], stdout=out, stderr=io.StringIO())
    assert code == 3
    assert "zone: the mirror beam of 'mirror'" in out.getvalue() and "LEAVES the range boundary" in out.getvalue()
    way = re.search(r"mirror beam of 'mirror' \(specular NOHD [0-9.e+]+ m, toward bearing ([0-9.e+-]+) deg, "
                    r"elevation ([0-9.e+-]+) deg\) is NOT contained", out.getvalue())
    assert float(way[1]) == pytest.approx(90.0, abs=0.1) and float(way[2]) == pytest.approx(0.0, abs=0.1)  # r = +x: east, level
    code = main(["run", str(path), "-o", str(tmp_path / "o"), "--force", "--fail-on-hazard"], stdout=io.StringIO(),
                stderr=io.StringIO())
    assert code == 0  # no observer
    assert "mirror beam of mirror" in out.getvalue() and "LEAVES the range boundary" in out.getvalue()


def test_a_beam_below_the_mpe_at_its_aperture_has_an_empty_contained_zone():
    """P = 1 mW over a 2 cm aperture: 4P / (pi a^2) = 3.2 W/m^2 < MPE, so the direct-beam
    NOHD is 0: nothing hazardous to stop (it said 'NOT contained: every direction')."""
    power = 1e-3
    assert 4 * power / (math.pi * A * A) < MPE
    res = hazard.analyze(_scene([1.0, 0.0, 0.0], power=power))
    z = res.sdz
    assert z.nohd_m == 0.0 and z.contained is True and z.escaping_directions == 0 and z.area_m2 == 0.0
