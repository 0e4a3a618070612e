"""The path matrix (issue 29, item 6): each validation case below, built by its own
module's helpers (the scenes the independent references check), also runs with an
unrelated far occluder, an unlit second target, flat ground far below, the other ray
backend, and the whole scene rotated and moved; every observer's result (and over time,
where things move), every original target's spot and the direct beam's danger zone must
equal the base run's to 1e-6 relative (see ``_matrix``): three tests per case and variant.

One line registers a case. ``fast`` cases run in the default suite (x their variants);
the whole matrix is ``@pytest.mark.slow``. A known engine defect is a strict
xfail carrying the numbers measured, so the integrator sees it flip when it is fixed.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

import scenes

from . import _matrix as mx
from . import _refs as ref
from . import test_crossings_surfaces as cs
from . import test_curved_reflectors as cr
from . import test_curved_spot_power as cv
from . import test_diffuse_and_back_face as db
from . import test_direct_beam as dbm
from . import test_motion_refs as mo
from . import test_polarization as po
from . import test_pointing_and_crossings as pc
from . import test_sdz as sd
from . import test_spot_power as sp
from . import test_specular_mirror as sm
from . import test_terrain_reflection as tr
from . import test_two_state_and_slump_scenes as ts

register = mx.register


# --------------------------------------------------------------------------- case builders (module helpers, fixed draws)


def _mirror(tmp, shape="plate"):
    """test_specular_mirror: 10 cm mirror 500 m out, on-axis / off-axis / missed observers."""
    pos, aim, n, t = sm._mirror_geometry(500.0, 0.02, 1e-3, math.radians(30), 0.4, 0.3, (0.2, -0.4, 0.7))
    beam = ref.Beam(1000.0, 0.02, 1e-3, pos, aim, mu=1e-4)
    size = (0.1, 0.1) if shape == "plate" else (0.1,)
    rdir = ref.reflect(beam.u, n)
    lit, _ = sm._lit_observer(beam, n, t, (0.1, 0.1), 0.6, -0.5, 300.0)
    miss, _ = sm._lit_observer(beam, n, t, (0.1, 0.1), 1.8, 0.2, 300.0)
    return sm._scene(beam, n, t, size, 0.8, [50.0 * rdir, 1500.0 * rdir, lit, miss], shape=shape)


def _mirror_nohd(tmp):
    """test_specular_mirror: the spec's example 10 (specular NOHD beyond a 5 cm mirror)."""
    pos, aim, n, t = sm._mirror_geometry(100.0, 3e-3, 1e-3, math.radians(40), 1.0, 0.0, (0.0, 0.0, 0.0))
    return sm._scene(ref.Beam(10.0, 3e-3, 1e-3, pos, aim), n, t, (0.05, 0.05), 0.9, [])


def _sphere(tmp):
    """test_curved_reflectors: 5 cm sphere 200 m out, observers 5-19 deg off back-reflection."""
    dirs = [(math.radians(p), az, 2000.0) for p, az in ((5.0, 0.3), (12.0, 2.0), (19.0, 4.0))]
    return cr._sphere_case(0.05, 200.0, 1.0, 0.5, 0.0, 0.9, dirs, (0.0, 0.0, 0.0))[1]


def _cylinder(tmp):
    """test_curved_reflectors: the fan of a cylinder, axis normal to the beam."""
    obs = [(math.radians(p), 2000.0) for p in (-30.0, 10.0, 60.0)]
    return cr._cylinder_case(0.05, 300.0, 1.0, 0.5, 1e-4, 0.8, obs, (0.3, 0.2, -0.5))[1]


def _lambertian(tmp, back_lit=False):
    """test_diffuse_and_back_face: a tilted Lambertian plate, observers on both sides (one
    with binoculars); ``back_lit``: lit on its back face, which has a back material."""
    R1, a, phi = 300.0, 0.02, 1e-3
    pos, c, n, t, size, D = db._plate(R1, a, phi, 4.0, 3.0, 0.2, -0.1, 25.0, 0.7, 0.4, (0.3, -0.5, 1.1), back_lit)
    beam = ref.Beam(1000.0, a, phi, pos, np.zeros(3), mu=2e-3)
    lit = -n if back_lit else n
    pts = [c + 400.0 * d for d in db._directions(lit, [(0.2, 0.0), (0.6, 2.0), (1.0, 4.0)])]
    pts += [c + 300.0 * d for d in db._directions(-lit, [(0.5, 1.0)])]
    optics = dict(magnification=7.0, objective_diameter_m=0.05, transmission=0.9)
    obs = [(f"o{i}", p, optics if i == 1 else None) for i, p in enumerate(pts)]
    return db._scene(beam, c, n, t, size, ref.lambertian(0.6), ref.lambertian(0.4) if back_lit else None, obs)


def _direct(tmp):
    """test_direct_beam: observers in the beam (axis, 1 w, 2 w, binoculars), in the
    target's shadow, beside it and behind a box on the way."""
    R, w = 300.0, (dbm.A + 300.0 * dbm.PHI) / 2
    optics = dict(magnification=7.0, objective_diameter_m=0.05, transmission=0.9)
    R2 = dbm.R_T + 200.0
    w2 = (dbm.A + R2 * dbm.PHI) / 2
    obs = [("axis", dbm._at(R), None), ("one-w", dbm._at(R, x=w), None), ("bino", dbm._at(R, x=w), optics),
           ("shadow", dbm._at(R2), None), ("spill", dbm._at(R2, x=0.8 * w2), None), ("behind-box", dbm._at(600.0, x=6.0), None)]
    return dbm._scene(obs, mu=1e-4, occluder=(np.array([3.0, -500.0, 0.0]), (1.0, 1.0, 1.0)))


def _spot(name):
    """test_spot_power: one of its named plates (no observers: the target's spot compares)."""
    return lambda tmp: scenes.loads(sp._named(name)[1][0])


def _shadowed(tmp):
    """test_spot_power: a plate partly hidden by a plate in front of it."""
    return scenes.loads(sp._shadowed_pair(100.0, 150.0, 0.05, 1e-3, (-0.05, 0.2, -0.1, 0.1), (-0.3, 0.3, -0.3, 0.3), 1e-4))


def _edges_on_axis(tmp):
    """test_spot_power: a strip behind a plate, both lower edges on the beam's axis and the
    strip's on the sampling cells' boundaries (its piece rays see the shadow)."""
    R_f, R_b, a, phi = 5.0, 6.0, math.exp(-3.0), math.exp(-7.0)
    D_f, D_b = a + R_f * phi, a + R_b * phi
    return scenes.loads(sp._shadowed_pair(R_f, R_b, a, phi, (0.0, D_f, 0.0, D_f), (-1.5 * D_b, 0.5 * D_b, 0.0, 0.125 * D_b)))


def _strip_box(tmp):
    """test_spot_power: a strip thinner than the coarse cells, half hidden by a box."""
    return scenes.loads(sp._strip_behind_box_text(-2.6875, 1.25, -0.234375, -0.203125, 0.0625))


def _thin_cylinder(tmp):
    """test_curved_spot_power: a 1/16 D cylinder along a screen's edge, between the cells' rays."""
    return scenes.loads(cv._case("cylinder", cv.SWEEP_R1, 0.01, math.exp(-7.0), 0.0625, 2.0, -0.021875, -0.4375, (1.0, 0.0, 0.0),
                                 (0.0, 0.0, 0.0), screen=True)[0])


def _sphere_rim(tmp):
    """test_curved_spot_power: a sphere's rim beside a screen's edge, between the rays of
    cells mixed only between the screen and empty beam."""
    return scenes.loads(cv._case("sphere", 50.0, math.exp(-3.0), 0.0, 1.0, 0.125, 0.103125, -0.0625, (0.75, 0.0, 1.0),
                                 (0.0, 0.0, 0.0), screen=True)[0])


def _terrain(tmp):
    """test_terrain_reflection: the spill past a small plate lands on flat ground."""
    return tr._scene([np.array([0.0, 30.0, 1.7]), np.array([20.0, 10.0, 5.0]), np.array([-15.0, 25.0, 10.0])], 0.6, 1e-3)


def _pointing(tmp):
    """test_pointing_and_crossings: observers inside, on and outside the pointing cone."""
    return pc._pointing_scene([(n, pc.LASER + R * pc._direction(t, psi)) for n, t, psi, R in pc._CONE_OBSERVERS])


def _sector(tmp):
    """test_pointing_and_crossings: observers inside a sector of bearings and elevations."""
    pts = [("far-from-aim", pc.LASER + 1500.0 * pc._azel(35.0, 3.0)), ("west", pc.LASER + 700.0 * pc._azel(-10.0, -1.0))]
    return pc._pointing_scene(pts, b=1e-3, sector=((-30.0, 40.0), (-2.0, 5.0)))


def _sdz_level(tmp):
    """test_sdz: a laser 30 m up aiming level with a 2 mrad pointing bound."""
    return sd._scene([0.0, 0.0, 30.0], [0.0, 1000.0, 30.0], pointing=2e-3)


def _sdz_down(tmp):
    """test_sdz: a cone aimed 20 deg down over flat ground (contained by it)."""
    o = np.array([10.0, -20.0, 40.0])
    d0 = np.array([math.sin(0.6) * math.cos(0.35), math.cos(0.6) * math.cos(0.35), -math.sin(0.35)])
    return sd._scene(o, o + 10.0 * d0, pointing=math.radians(2.0),
                     extra='[terrain]\nkind = "flat"\nextent_m = 5000.0\nresolution_m = 250.0\n')


def _slew(tmp):
    """test_motion_refs: a beam slewing 1 deg/s in bearing across a fixed point 5 km out
    (and a track observer standing there), over a backstop plate."""
    p = mo.LP + mo.R_X * mo.azel(90.0, 0.0)
    text = mo.scene(aim=mo.LP + 1000.0 * mo.azel(80.0, 0.0), aim_track={"times_s": [0.0, 20.0], "azimuth_rate_deg_s": 1.0},
                    observers=[mo.point_group("post", [p]), mo.track_rows("standing", [0.0, 20.0], [p, p])])
    return scenes.loads(text)


def _fresnel(tmp):
    """test_polarization: a glass (n = 1.5) mirror at 45 deg, the worst polarisation."""
    return po._scene(math.pi / 4, 1.5, 0.0)


def _mirror_grid(tmp):
    """test_crossings_surfaces: a mirror beam crossing a grid between its points."""
    n = np.array([-1.0, -1.0, 0.0]) / math.sqrt(2)
    target = cs._plate(normal=n, tangent=np.array([1.0, -1.0, 0.0]) / math.sqrt(2), material=ref.specular(0.9))
    text = ref.scene_text(power=cs.P, a=cs.A, phi=cs.PHI, position=np.array([0.0, -cs.R_T, 0.0]), aim=np.zeros(3), targets=[target])
    grid = cs._grid("wall", [-100.0, -53.0, -46.0], [0.0, 100.0, 0.0], [0.0, 0.0, 100.0], (11, 11))
    return scenes.loads(text.replace("[analysis]", grid + "[analysis]"))


def _slump(tmp):
    """test_two_state_and_slump_scenes: a Gaussian lobe slumping 'up' as a plate melts."""
    history = ("[targets.history]\nkind = \"heating\"\nplate = \"stainless_steel\"\n"
               "thickness_m = 0.0002\nstate = \"melt_fraction\"")
    material = f'{{ file = "{ts.gaussian_lobe_file(tmp)}", melt_tilt_deg = 5.0 }}'
    pts = ts.R_ARC * ts.arc("up", 5.0 * ts.DEG)[::40]
    return scenes.loads(ts.scene_text(material, history, pts, power=3000.0, time_end=3.0, time_step=0.25), base_dir=tmp)


# --------------------------------------------------------------------------- known defects
# None open. Fixed: the beam's cross-section was sampled on a grid whose transverse axes
# came from the world axes (hazard.physics.beam.perp_basis), so a rotated scene put the cells
# elsewhere on the target and moved its peak irradiance and specular NOHD by 1e-5 to
# 2e-4 (fresnel-glass-45: peak 52639.518 -> 52650.417 W/m^2, specular NOHD 1945.2745 ->
# 1945.4861 m; slump-heating: an observer on the slumped lobe's flank by 0.43 %); the
# grid now takes its e1 from the first target's tangent (hazard.pipeline.spots.scene_beam)
# and turns with the scene: the moved runs equal the base ones (1e-6).


# --------------------------------------------------------------------------- the register

FAST_NO_BACKEND = ("occluder", "second_target", "ground", "moved")  # the numpy backend traces spheres and terrain for 20-30 s

register("mirror-plate", _mirror, fast=True)
register("mirror-disk", lambda tmp: _mirror(tmp, "disk"))
register("mirror-nohd-example", _mirror_nohd)
register("sphere", _sphere, fast=FAST_NO_BACKEND)
register("cylinder", _cylinder)
register("lambertian-plate", _lambertian, fast=True)
register("lambertian-back-face", lambda tmp: _lambertian(tmp, back_lit=True))
register("direct-beam", _direct, fast=True)
register("spot-spec-slot", _spot("spec-slot-10x4mm"))
register("spot-tilted-45-cut", _spot("tilted-45-cut"))
register("spot-shadowed-pair", _shadowed)
register("spot-edges-on-axis", _edges_on_axis)
register("spot-strip-behind-box", _strip_box)
register("curved-thin-cylinder-screen", _thin_cylinder)
register("curved-sphere-rim-screen", _sphere_rim)
register("terrain-reflection", _terrain, fast=FAST_NO_BACKEND, without=("ground",))
register("pointing-cone", _pointing)
register("sector", _sector)
register("sdz-level-cone", _sdz_level)
register("sdz-down-cone-over-ground", _sdz_down, without=("ground", "backend"))  # numpy over 5 km of ground: 260 s
register("slewing-beam", _slew)
register("fresnel-glass-45", _fresnel)
register("mirror-beam-grid", _mirror_grid)
register("slump-heating", _slump)


# --------------------------------------------------------------------------- the tests


def _params(slow):
    out = []
    for case in mx.CASES.values():
        for v in case.variants:
            if (v in case.fast) == slow:
                continue
            for part in mx.PARTS:
                reason = case.xfail.get((v, part), case.xfail.get(v))
                marks = [pytest.mark.xfail(strict=True, reason=reason)] if reason else []
                out.append(pytest.param(case.name, v, part, marks=marks, id=f"{case.name}-{v}-{part}"))
    return out


def _check(name, variant, part, tmp_path):
    diffs = mx.check(mx.CASES[name], variant, part, tmp_path)  # NotApplicable: register the case ``without`` it
    assert not diffs, f"{name} / {variant} / {part}: {len(diffs)} values changed\n" + "\n".join(diffs[:20])


@pytest.mark.parametrize("name,variant,part", _params(slow=False))
def test_path_matrix_fast(name, variant, part, tmp_path):
    """The default subset: a handful of cases x the 5 variants (observers, targets)."""
    _check(name, variant, part, tmp_path)


@pytest.mark.slow
@pytest.mark.parametrize("name,variant,part", _params(slow=True))
def test_path_matrix_full(name, variant, part, tmp_path):
    """The rest of the matrix (the fast runs are above)."""
    _check(name, variant, part, tmp_path)
