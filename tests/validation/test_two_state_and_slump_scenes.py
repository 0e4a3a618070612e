"""The slump in scenes, end to end through ``hazard.analyze`` (issue 19), against the
reflection law written in this file.

A target's material may say ``melt_tilt_deg`` (alpha_max), ``melt_tilt_direction`` ("up":
world +z projected onto the plate; or a vector in the target frame x = tangent,
y = normal x tangent, z = normal) with a history that gives the melt fraction f(t). The
irradiance map then uses the mean normal tilted by alpha(t) = alpha_max f(t) towards the
unit direction d (perpendicular to n; rotation about n x d):

    n'(t) = cos(alpha) n + sin(alpha) d,

and a glossy lobe centred on the mirror direction peaks where the reflection law points,

    r = b - 2 (b . n') n'      (b = beam propagation direction, laser -> spot).

Scene: a 1 m plate at the origin facing -y, a laser 30 m away 20 deg below the plate's
normal in the y-z plane (so the nominal mirror direction is 20 deg above it), observers
on a dense arc of radius 20 m about the spot (far field: the spot is one point source),
every 0.05 deg along the great circle through the nominal and the fully tilted mirror
directions. Materials are narrow lobes whose peak is on the mirror direction by
construction: a Gaussian lobe in direction cosines, peak exp(-|beta - beta0|^2 / sigma^2)
(made dynamic with a unit StateTable over the melt fraction), or a two-state
spherical-harmonic model with only the constant and the halfway y_1^0 term,
ln f~ = c0 y_0^0 + c1 y_1^0(theta~_h), c1 > 0, whose maximum over the observer direction
is exactly theta_h = 0 (the mirror direction) - the fan-out
theta~_h = pi (theta_h / (pi/2))^0.6 and y_1^0 = sqrt(3 / (4 pi)) cos(theta~_h) are
written here (spec dynamic-sh-brdf.md sections 4, 5, 6).

Besides the peak's position, the map's values are checked against
E = P f_r(wi, wo; n') cos(theta_r') / R^2: the spot's whole power P (the 4 cm beam
footprint lies well inside the 1 m plate, nothing attenuates) scattered by the material
evaluated in the tilted surface frame, the observer's cosine taken from the tilted
normal (the molten facets are what reflect; the plate does not move, so P is unchanged).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

import brdfmodels as bm
import hazard
import scenes

DEG = math.pi / 180
INC = 20.0 * DEG  # incidence angle of the beam on the nominal plate
N0 = np.array([0.0, -1.0, 0.0])  # nominal plate normal (world)
TANGENT = np.array([1.0, 0.0, 0.0])
U_IN = np.array([0.0, -math.cos(INC), -math.sin(INC)])  # from the spot to the laser
BEAM = -U_IN  # beam propagation direction
L_LASER, R_ARC, SPACING = 30.0, 20.0, 0.05 * DEG
POWER, A, PHI = 100.0, 0.01, 1e-3
SIGMA, PEAK = 0.02, 100.0
# The reference takes the spot as a point at the aim point. The engine's point source is
# the spot's power centroid, which a diverging beam on a plate inclined by 20 deg moves by
# micrometres (observed: a 4e-7 rad turn of the lobe seen from 20 m). On a lobe this
# narrow (d ln f / d beta = 2 (beta - beta0) / sigma^2) that changes E by ~3e-5 relative
# a few degrees off the peak, and by more only where E < 1e-6 of the peak (hence the
# absolute part of the tolerance). It cannot move the peak by the arc's spacing.
MAP_RTOL = 2e-4


def unit(v):
    v = np.asarray(v, float)
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def target_frame():
    """x = tangent, y = normal x tangent, z = normal (scenes/spec.py)."""
    return np.array([TANGENT, np.cross(N0, TANGENT), N0])


def tilt_direction(direction):
    """d: 'up' -> world +z, or a target-frame vector -> world; projected onto the plate."""
    d = np.array([0.0, 0.0, 1.0]) if direction == "up" else np.asarray(direction, float) @ target_frame()
    return unit(d - (d @ N0) * N0)


def tilted_normal(alpha, d):
    """n rotated by alpha towards d (about n x d): cos(alpha) n + sin(alpha) d."""
    return math.cos(alpha) * N0 + math.sin(alpha) * d


def reflect(b, n):
    """Reflection law: r = b - 2 (b . n) n."""
    return b - 2.0 * (b @ n) * n


def angle(u, v):
    return math.atan2(np.linalg.norm(np.cross(u, v)), float(np.dot(u, v)))


def arc(direction, alpha_max, pad_deg=4.0):
    """Unit directions (K, 3) every SPACING along the great circle through the nominal
    mirror direction r0 and the fully tilted one r1 (for the tilt-free case: the circle
    the 5-degree tilt towards ``direction`` would use), from pad_deg before r0 to pad_deg
    past r1."""
    d = tilt_direction(direction)
    r0 = reflect(BEAM, N0)
    r1 = reflect(BEAM, tilted_normal(alpha_max if alpha_max > 0 else 5 * DEG, d))
    w = unit(r1 - (r1 @ r0) * r0)
    span = angle(r0, r1) if alpha_max > 0 else 10 * DEG
    phi = np.arange(round(-pad_deg * DEG / SPACING), round((span + pad_deg * DEG) / SPACING) + 1) * SPACING
    return np.cos(phi)[:, None] * r0 + np.sin(phi)[:, None] * w


def scene_text(material, history, points, *, power=POWER, time_end=10.0, time_step=1.0, normal=N0, laser=None):
    laser = [float(x) for x in (L_LASER * U_IN if laser is None else laser)]
    pts = [[float(x) for x in p] for p in points]
    return f"""
name = "slump"
[laser]
wavelength_nm = 1064.0
power_w = {power!r}
beam_diameter_m = {A!r}
divergence_rad = {PHI!r}
position_m = {laser!r}
aim_m = [0.0, 0.0, 0.0]
[exposure]
duration_s = {time_end!r}
[[targets]]
name = "plate"
shape = "plate"
center_m = [0.0, 0.0, 0.0]
normal = {[float(x) for x in normal]!r}
tangent = {[float(x) for x in TANGENT]!r}
size_m = [1.0, 1.0]
material = {material}
{history}
[[observers]]
name = "arc"
points_m = {pts!r}
[analysis]
time_end_s = {time_end!r}
time_step_s = {time_step!r}
"""


def melt_series(times, melt):
    return ("[targets.history]\nkind = \"series\"\nstate = \"melt_fraction\"\n"
            f"times_s = {[float(t) for t in times]!r}\nstates = {[float(f) for f in melt]!r}")


def gaussian_lobe_file(tmp_path):
    """Gaussian lobe about the mirror direction, dynamic through a unit factor over the
    melt fraction (a static material cannot take a history)."""
    lobe = bm.Scaled(bm.GaussianLobe(PEAK, SIGMA), bm.StateTable([0.0, 1.0], [1.0, 1.0], "melt_fraction"))
    bm.save(lobe, tmp_path / "lobe.json")
    return "lobe.json"


def gaussian_lobe_irradiance(wo, n):
    """E = P f_r cos(theta_r') / R^2 with f_r = PEAK exp(-|beta - beta0|^2 / SIGMA^2) in the
    frame of normal n: beta = wo's part along the surface, beta0 = the mirror direction's
    (= minus the incident direction's part along the surface)."""
    beta = wo - np.outer(wo @ n, n)
    beta0 = -(U_IN - (U_IN @ n) * n)
    f = PEAK * np.exp(-np.sum((beta - beta0) ** 2, axis=1) / SIGMA**2)
    return POWER * f * (wo @ n) / R_ARC**2


def run(text, tmp_path):
    res = hazard.analyze(scenes.loads(text, base_dir=tmp_path), keep_history=True)
    e = res.observers.irradiance_w_m2
    assert e is not None and e.shape == (len(res.observers), len(res.times_s))
    return res, e


@pytest.mark.parametrize("direction, tilt_deg", [("up", 5.0), ([1.0, 0.0, 0.0], 4.0), ([1.0, 1.0, 0.0], 8.0),
                                                 ([0.0, 1.0, 0.0], 3.0)])
def test_slumped_gaussian_lobe_peaks_on_the_tilted_mirror_direction(tmp_path, direction, tilt_deg):
    """Series melt fraction 0 -> 1 over 10 s (f(t) = t / 10). At every time t the observer of
    peak irradiance is within the arc's spacing of r = b - 2 (b.n') n' with n' the normal
    turned by tilt_deg x f(t) towards d (written here; d = world up projected, or the
    target-frame vector); at t = 0 that is the nominal mirror direction. The whole map
    E(observer, t) equals P f_r(n') cos(theta_r') / R^2 (2e-4: MAP_RTOL explains)."""
    alpha_max = tilt_deg * DEG
    dirs = arc(direction, alpha_max)
    md = f'"{direction}"' if isinstance(direction, str) else repr(direction)
    lobe = gaussian_lobe_file(tmp_path)
    material = f'{{ file = "{lobe}", melt_tilt_deg = {tilt_deg!r}, melt_tilt_direction = {md} }}'
    res, e = run(scene_text(material, melt_series([0.0, 10.0], [0.0, 1.0]), R_ARC * dirs), tmp_path)
    d = tilt_direction(direction)
    for k, t in enumerate(res.times_s):
        n = tilted_normal(alpha_max * t / 10.0, d)
        r = reflect(BEAM, n)
        np.testing.assert_allclose(e[:, k], gaussian_lobe_irradiance(dirs, n), rtol=MAP_RTOL, atol=1e-6 * e[:, k].max(),
                                   err_msg=f"t = {t}")
        # r(t) lies on the arc at t = 0 and t = end (and at every t when d is in the plane
        # of incidence); at other times it is off the arc, and the map values check it
        if k in (0, len(res.times_s) - 1) or direction in ("up", [0.0, 1.0, 0.0]):
            peak = dirs[np.argmax(e[:, k])]
            assert angle(peak, r) <= SPACING * (1 + 1e-9), (t, angle(peak, r) / DEG)
    assert angle(dirs[np.argmax(e[:, 0])], reflect(BEAM, N0)) <= SPACING * (1 + 1e-9)
    assert angle(dirs[np.argmax(e[:, -1])], reflect(BEAM, tilted_normal(alpha_max, d))) <= SPACING * (1 + 1e-9)
    assert res.times_s[-1] == pytest.approx(10.0)


def test_without_tilt_the_peak_does_not_move(tmp_path):
    """melt_tilt_deg = 0 with the same melting history: at every time the peak observer
    is the nominal mirror direction r0 = b - 2 (b.n) n, and the map is the nominal
    E = P f_r(n) cos(theta_r) / R^2."""
    dirs = arc("up", 0.0)
    material = f'{{ file = "{gaussian_lobe_file(tmp_path)}", melt_tilt_deg = 0.0 }}'
    res, e = run(scene_text(material, melt_series([0.0, 10.0], [0.0, 1.0]), R_ARC * dirs), tmp_path)
    r0 = reflect(BEAM, N0)
    for k in range(len(res.times_s)):
        assert angle(dirs[np.argmax(e[:, k])], r0) <= SPACING * (1 + 1e-9)
        np.testing.assert_allclose(e[:, k], gaussian_lobe_irradiance(dirs, N0), rtol=MAP_RTOL,
                                   atol=1e-6 * e[:, k].max())


# two-state SH lobe: ln f~ = c0(xi, f) y_0^0 + C1 y_1^0(theta~_h)
C1 = 20.0
Y00, Y10 = 1.0 / math.sqrt(4 * math.pi), math.sqrt(3.0 / (4 * math.pi))
XI_NODES, F_NODES = np.array([0.2, 8.0]), np.array([0.0, 1.0])
# ln f~ at the peak (theta_h = 0) per corner: about 0 (f~ ~ 1: a hemispherical reflectance
# of ~0.1), darker with oxide (xi), brighter again when molten (f)
LN_PEAK = np.array([[0.0, 0.3], [-0.7, -0.2]])  # [xi node, f node]
C0 = (LN_PEAK - C1 * Y10) / Y00


def sh_lobe_file(tmp_path):
    basis = bm.SHBasis(1, 0, 0, 0)
    assert basis.size == 2  # [constant, halfway y_1^0]
    coef = np.stack([C0, np.full_like(C0, C1)], axis=-1)  # (2, 2, 2)
    m = bm.DynamicBRDF(basis, states=[XI_NODES, F_NODES], coefficients=coef, state_name=["extinction", "melt_fraction"],
                       fanout=0.6, log=True)
    bm.save(m, tmp_path / "sh2.json")
    return "sh2.json"


def sh_lobe_irradiance(wo, n, xi, f):
    """E = P f_r cos(theta_r') / R^2 = P f~ / (cos(theta_i') R^2), with
    ln f~ = c0(xi, f) y_0^0 + C1 sqrt(3/(4 pi)) cos(pi (theta_h / (pi/2))^0.6),
    c0 bilinear in (xi, f) (the paper's rule along each axis; one cell here)."""
    x = (xi - XI_NODES[0]) / (XI_NODES[1] - XI_NODES[0])
    y = (f - F_NODES[0]) / (F_NODES[1] - F_NODES[0])
    c0 = (1 - x) * (1 - y) * C0[0, 0] + x * (1 - y) * C0[1, 0] + (1 - x) * y * C0[0, 1] + x * y * C0[1, 1]
    h = unit(U_IN[None, :] + wo)
    theta_h = np.arccos(np.clip(h @ n, -1.0, 1.0))
    ln_ft = c0 * Y00 + C1 * Y10 * np.cos(math.pi * (theta_h / (math.pi / 2)) ** 0.6)
    return POWER * np.exp(ln_ft) / ((U_IN @ n) * R_ARC**2)


def test_two_state_series_slump_follows_the_melt_fraction_of_the_pairs(tmp_path):
    """state = ["extinction", "melt_fraction"] with states = [[xi, f], ...] pairs, a
    two-state SH lobe (module docstring) and melt_tilt_deg = 5 'up': f(t) and xi(t) are
    the pairs interpolated linearly in time (written here with np.interp); the peak
    observer at every time is within the spacing of r = b - 2 (b.n') n',
    n' = n turned by 5 deg x f(t); the whole map equals P f~ / (cos(theta_i') R^2)."""
    tilt = 5.0 * DEG
    times, xi, melt = [0.0, 4.0, 7.0, 10.0], [0.3, 1.2, 1.4, 1.0], [0.0, 0.1, 0.6, 1.0]
    history = ("[targets.history]\nkind = \"series\"\nstate = [\"extinction\", \"melt_fraction\"]\n"
               f"times_s = {times!r}\nstates = {[[a, b] for a, b in zip(xi, melt)]!r}")
    material = f'{{ file = "{sh_lobe_file(tmp_path)}", melt_tilt_deg = 5.0 }}'
    dirs = arc("up", tilt)
    res, e = run(scene_text(material, history, R_ARC * dirs), tmp_path)
    d = tilt_direction("up")
    for k, t in enumerate(res.times_s):
        f_t, xi_t = np.interp(t, times, melt), np.interp(t, times, xi)
        n = tilted_normal(tilt * f_t, d)
        r = reflect(BEAM, n)
        peak = dirs[np.argmax(e[:, k])]
        assert angle(peak, r) <= SPACING * (1 + 1e-9), (t, angle(peak, r) / DEG)
        np.testing.assert_allclose(e[:, k], sh_lobe_irradiance(dirs, n, xi_t, f_t), rtol=MAP_RTOL,
                                   atol=1e-6 * e[:, k].max(), err_msg=f"t = {t}")


@pytest.mark.parametrize("two_state", [False, True])
def test_heating_history_slump_follows_the_plate_melt(tmp_path, two_state):
    """kind = "heating" (stainless plate, 0.2 mm) with state = "melt_fraction" (Gaussian
    lobe) or state = ["extinction", "melt_fraction"] (the two-state SH lobe): the plate is
    driven by the beam's peak irradiance on the spot, E0 = 4 P / (pi D^2), D = a + L phi
    (range-safety.md section 1; no attenuation, taken normal to the beam). The melt
    fraction f(t) is the public thin-plate model's at E0 (checked in closed form by
    test_two_state_and_slump.py in the loss-free case), and so are the target's reported
    melt onset and full-melt times. At t = 0 the peak is at the nominal mirror direction;
    at the end (fully molten) at the 5-degree tilted one; at every time within the
    spacing of r(t) for the normal turned by 5 deg x f(t) (the oxide extinction only
    scales the SH lobe: c0 carries it, the lobe's shape term C1 is the same everywhere)."""
    power, thickness, tilt = 3000.0, 2e-4, 5.0 * DEG
    d_beam = A + L_LASER * PHI
    e0 = 4 * power / (math.pi * d_beam**2)
    state = '["extinction", "melt_fraction"]' if two_state else '"melt_fraction"'
    history = ("[targets.history]\nkind = \"heating\"\nplate = \"stainless_steel\"\n"
               f"thickness_m = {thickness!r}\nstate = {state}")
    lobe = sh_lobe_file(tmp_path) if two_state else gaussian_lobe_file(tmp_path)
    material = f'{{ file = "{lobe}", melt_tilt_deg = 5.0 }}'
    dirs = arc("up", tilt)
    res, e = run(scene_text(material, history, R_ARC * dirs, power=power, time_end=3.0, time_step=0.05), tmp_path)
    # the engine's hottest point is conservative at the 1e-4 level (observed +1.8e-4: a beam
    # cell's nearest range, 3.6 mm nearer the laser); a drive 1e-3 off moves the melt
    # times by ~1e-3 s, the peak by ~1e-2 of the arc's spacing
    assert res.targets[0].peak_irradiance_w_m2 == pytest.approx(e0, rel=1e-3)
    assert res.targets[0].peak_irradiance_w_m2 >= e0 * (1 - 1e-9)
    heat = bm.ThinPlateHeating.stainless_steel(thickness_m=thickness).solve(res.times_s, e0)
    assert heat.full_melt_s is not None and heat.full_melt_s < res.times_s[-1] - 0.5  # molten well before the end
    assert heat.melt_onset_s > 0.2
    assert np.all((heat.extinction >= XI_NODES[0]) & (heat.extinction <= XI_NODES[-1]))
    melt = res.targets[0].melt
    assert melt["onset_s"] == pytest.approx(heat.melt_onset_s, rel=1e-3)
    assert melt["full_melt_s"] == pytest.approx(heat.full_melt_s, rel=1e-3)
    d = tilt_direction("up")
    worst = 0.0
    for k, _t in enumerate(res.times_s):
        r = reflect(BEAM, tilted_normal(tilt * heat.melt_fraction[k], d))
        worst = max(worst, angle(dirs[np.argmax(e[:, k])], r))
    assert worst <= SPACING * (1 + 1e-9), worst / DEG
    assert angle(dirs[np.argmax(e[:, 0])], reflect(BEAM, N0)) <= SPACING * (1 + 1e-9)
    assert angle(dirs[np.argmax(e[:, -1])], reflect(BEAM, tilted_normal(tilt, d))) <= SPACING * (1 + 1e-9)


# --------------------------------------------------------------------------- scene errors


def _load(text, tmp_path):
    return scenes.loads(text, base_dir=tmp_path)


POINTS = [[0.0, -18.0, 7.0]]


def test_melt_tilt_needs_a_history_that_gives_the_melt_fraction(tmp_path):
    """melt_tilt_deg without a history, or with a series whose state is not the melt
    fraction (here: extinction): SceneError naming melt_tilt_deg; melt_wander_deg alone
    likewise names melt_wander_deg."""
    static = '{ model = "gaussian-lobe", peak = 100.0, sigma = 0.02, melt_tilt_deg = 5.0 }'
    with pytest.raises(scenes.SceneError, match=r"targets\[0\]\.material\.melt_tilt_deg.*melt fraction"):
        _load(scene_text(static, "", POINTS), tmp_path)
    wander = '{ model = "gaussian-lobe", peak = 100.0, sigma = 0.02, melt_wander_deg = 2.0 }'
    with pytest.raises(scenes.SceneError, match="melt_wander_deg"):
        _load(scene_text(wander, "", POINTS), tmp_path)
    bm.save(bm.Scaled(bm.GaussianLobe(PEAK, SIGMA), bm.StateTable([0.0, 2.0], [1.0, 0.5], "extinction")),
            tmp_path / "ox.json")
    series = ("[targets.history]\nkind = \"series\"\nstate = \"extinction\"\n"
              "times_s = [0.0, 10.0]\nstates = [0.3, 1.0]")
    _load(scene_text('{ file = "ox.json" }', series, POINTS), tmp_path)  # valid without the tilt
    with pytest.raises(scenes.SceneError, match=r"targets\[0\]\.material\.melt_tilt_deg.*melt fraction"):
        _load(scene_text('{ file = "ox.json", melt_tilt_deg = 5.0 }', series, POINTS), tmp_path)


def test_melt_tilt_on_an_ideal_mirror_is_refused(tmp_path):
    """An ideal-mirror (delta) lobe is traced on the target's geometry, which the slump
    would not tilt: SceneError, with a heating history that gives the melt fraction (so
    only the delta lobe is wrong), for an inline mirror and for a dynamic one."""
    heating = "[targets.history]\nkind = \"heating\"\nplate = \"stainless_steel\"\nstate = \"reflectance_factor\""
    _load(scene_text('{ model = "specular", reflectance = 0.5 }', heating, POINTS), tmp_path)  # valid without
    with pytest.raises(scenes.SceneError, match="melt_tilt_deg.*ideal-mirror"):
        _load(scene_text('{ model = "specular", reflectance = 0.5, melt_tilt_deg = 5.0 }', heating, POINTS), tmp_path)
    bm.save(bm.Scaled(bm.Specular(reflectance=0.5), bm.StateTable([0.0, 1.0], [1.0, 0.8], "melt_fraction")),
            tmp_path / "mirror.json")
    series = melt_series([0.0, 10.0], [0.0, 1.0])
    _load(scene_text('{ file = "mirror.json" }', series, POINTS), tmp_path)  # valid without
    with pytest.raises(scenes.SceneError, match="melt_tilt_deg.*ideal-mirror"):
        _load(scene_text('{ file = "mirror.json", melt_tilt_deg = 5.0 }', series, POINTS), tmp_path)


def test_melt_tilt_direction_along_the_normal_is_refused(tmp_path):
    """melt_tilt_direction = [0, 0, 1] in the target frame is the normal itself: nothing to
    tilt towards; on a plate facing up, 'up' projects to zero the same way."""
    f = gaussian_lobe_file(tmp_path)
    series = melt_series([0.0, 10.0], [0.0, 1.0])
    with pytest.raises(scenes.SceneError, match="melt_tilt_direction"):
        _load(scene_text(f'{{ file = "{f}", melt_tilt_deg = 5.0, melt_tilt_direction = [0.0, 0.0, 1.0] }}', series,
                         POINTS), tmp_path)
    up_facing = scene_text(f'{{ file = "{f}", melt_tilt_deg = 5.0 }}', series, [[0.0, 18.0, 9.0]],
                           normal=[0.0, 0.0, 1.0], laser=[0.0, -10.0, 28.0])
    _load(up_facing.replace(", melt_tilt_deg = 5.0", ""), tmp_path)  # valid without the tilt
    with pytest.raises(scenes.SceneError, match="melt_tilt_direction"):
        _load(up_facing, tmp_path)


def test_two_state_history_declarations_are_checked(tmp_path):
    """state = ["extinction", "extinction"] is an error (two different states needed);
    a two-state series with plain numbers as states, or a one-state series with pairs,
    is an error naming states; the history's state names must be the material's, in
    its order."""
    f = sh_lobe_file(tmp_path)
    same = ("[targets.history]\nkind = \"series\"\nstate = [\"extinction\", \"extinction\"]\n"
            "times_s = [0.0, 10.0]\nstates = [[0.3, 0.3], [1.0, 1.0]]")
    with pytest.raises(scenes.SceneError, match="state.*two different"):
        _load(scene_text(f'{{ file = "{f}" }}', same, POINTS), tmp_path)
    numbers = ("[targets.history]\nkind = \"series\"\nstate = [\"extinction\", \"melt_fraction\"]\n"
               "times_s = [0.0, 10.0]\nstates = [0.3, 1.0]")
    with pytest.raises(scenes.SceneError, match="states"):
        _load(scene_text(f'{{ file = "{f}" }}', numbers, POINTS), tmp_path)
    pairs_for_one = ("[targets.history]\nkind = \"series\"\nstate = \"melt_fraction\"\n"
                     "times_s = [0.0, 10.0]\nstates = [[0.3, 0.0], [1.0, 1.0]]")
    with pytest.raises(scenes.SceneError, match="states"):
        _load(scene_text(f'{{ file = "{gaussian_lobe_file(tmp_path)}" }}', pairs_for_one, POINTS), tmp_path)
    good = ("[targets.history]\nkind = \"series\"\nstate = [\"extinction\", \"melt_fraction\"]\n"
            "times_s = [0.0, 10.0]\nstates = [[0.3, 0.0], [1.0, 1.0]]")
    _load(scene_text(f'{{ file = "{f}" }}', good, POINTS), tmp_path)  # the valid form loads
    swapped = ("[targets.history]\nkind = \"series\"\nstate = [\"melt_fraction\", \"extinction\"]\n"
               "times_s = [0.0, 10.0]\nstates = [[0.0, 0.3], [1.0, 1.0]]")
    with pytest.raises(scenes.SceneError, match="state"):
        _load(scene_text(f'{{ file = "{f}" }}', swapped, POINTS), tmp_path)
    one = "[targets.history]\nkind = \"series\"\nstate = \"melt_fraction\"\ntimes_s = [0.0, 10.0]\nstates = [0.0, 1.0]"
    with pytest.raises(scenes.SceneError, match="state"):
        _load(scene_text(f'{{ file = "{f}" }}', one, POINTS), tmp_path)  # two-state material, one-state history


def test_a_slumping_target_over_terrain_holds_its_initial_tilt_in_the_static_footprint(tmp_path):
    """A slumping target over flat ground (the matrix of test_path_matrix.py found the
    footprint stage raising 'plate: 1 states but a slump over 13 times'): the static
    footprint holds the initial state, melt fraction 0, so it is the footprint of the
    same scene without a slump, node for node; the dynamic one sees the tilted lobe. The
    laser stands 20 deg above the plate's normal, so the mirror lobe comes down to the
    ground (non-empty footprints)."""
    history = ("[targets.history]\nkind = \"heating\"\nplate = \"stainless_steel\"\n"
               "thickness_m = 0.0002\nstate = \"melt_fraction\"")
    lobe = gaussian_lobe_file(tmp_path)
    up = [0.0, -L_LASER * math.cos(INC), L_LASER * math.sin(INC)]
    ground = '[terrain]\nkind = "flat"\ncenter_m = [0.0, 0.0, -12.0]\nextent_m = 90.0\nresolution_m = 2.0\n'

    def run_with(tilt_deg):
        text = scene_text(f'{{ file = "{lobe}", melt_tilt_deg = {tilt_deg!r} }}', history, [[0.0, -18.0, 7.0]],
                          power=3000.0, time_end=3.0, time_step=0.25, laser=up)
        return hazard.analyze(scenes.loads(text.replace("[analysis]", ground + "[analysis]"), base_dir=tmp_path))

    slumped, flat = run_with(5.0), run_with(0.0)
    assert flat.footprint_static.area_m2 > 0
    assert np.array_equal(slumped.footprint_static.mask, flat.footprint_static.mask)
    np.testing.assert_array_equal(slumped.footprint_static.ratio, flat.footprint_static.ratio)
    assert not np.array_equal(slumped.footprint_dynamic.mask, flat.footprint_dynamic.mask)
