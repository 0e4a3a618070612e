"""A line crossing a mirror beam that the mirror's edge cuts at the beam's axis (found by the
bundled-example recheck of issue 29, ``steel_vs_copper``'s arc-10m): the crossings stage
searches the point value, whose maximum is on the image of the edge, where the pupil
gets only half the beam; the line's listed maximum must still not be below the
aperture value at a point of the line a few millimetres into the lit side.

The expected value is written from the formulas alone: the unfolded Gaussian (1/e radius
w = (D + theta z) / 2) through a 7 mm disk wholly inside the lit half (the non-central
chi-square fraction), times the Fresnel s-reflectance of glass at 45 deg."""

from __future__ import annotations

import math

from scipy.stats import ncx2

import hazard
import scenes

P_W, D_M, THETA_RAD, N_GLASS = 1000.0, 0.02, 0.001, 1.5
SCENE = f"""
name = "edge_cut_mirror"
[laser]
wavelength_nm = 1064.0
power_w = {P_W}
beam_diameter_m = {D_M}
divergence_rad = {THETA_RAD}
position_m = [0.0, -10.0, 0.0]
aim_m = [0.0, 0.0, 0.0]
[exposure]
duration_s = 10.0
[[targets]]
name = "mirror"
shape = "plate"
center_m = [0.1414213562373095, -0.1414213562373095, 0.0]   # its edge on the beam's axis: only the +x half is lit
normal = [-0.7071067811865476, -0.7071067811865476, 0.0]
tangent = [0.7071067811865476, -0.7071067811865476, 0.0]
size_m = [0.4, 0.4]
material = {{ model = "specular", n = {N_GLASS} }}
[[observers]]
name = "line"
start_m = [-10.0, -1.0, 0.0]
end_m = [-10.0, 1.0, 0.0]
count = 4
"""


def _expected_aperture_w_m2(offset_m: float) -> float:
    """The mirror beam through a 7 mm pupil centred ``offset_m`` into the lit half at the
    line (10 m to the mirror + 10 m back): the disk lies wholly in the lit half when
    ``offset_m`` >= its radius."""
    a, z = 3.5e-3, 20.0
    w = (D_M + THETA_RAD * z) / 2
    ti = math.radians(45.0)
    tt = math.asin(math.sin(ti) / N_GLASS)
    r_s = ((math.cos(ti) - N_GLASS * math.cos(tt)) / (math.cos(ti) + N_GLASS * math.cos(tt))) ** 2
    frac = ncx2.cdf(2 * a * a / (w * w), 2, 2 * offset_m ** 2 / (w * w))
    return r_s * P_W * frac / (math.pi * a * a)


def test_line_maximum_is_not_below_the_aperture_value_inside_the_lit_half():
    res = hazard.analyze(scenes.loads(SCENE), threads=1)
    names = set(res.observers.observers.group_names)
    assert names == {"line", "line:crossing"}, names  # the crossing was found; every point is on the line
    listed_max = float(res.observers.peak_irradiance_w_m2.max())
    assert listed_max >= _expected_aperture_w_m2(7e-3) * (1 - 1e-3)
