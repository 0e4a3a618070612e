"""The bundled examples describe beams a laser can have (issue 30/31 follow-up): none
carries the M^2 plausibility warning, while the slip it is for (a divergence typed in
degrees and read as rad) still warns on every one of their beams.

mirror_window (M^2 111), stainless_melt (58.7) and steel_vs_copper (118) warned: their
diameter x divergence products were wider than a multimode laser of their power class
delivers. Their beams are now 19.2 cm / 0.08 mrad, 8.25 cm / 0.25 mrad and 4.8 cm /
0.4 mrad (M^2 23, 30, 28), each with the same spot diameter at its target as before.
"""

import math
from pathlib import Path

import pytest

import scenes
from scenes.scene import M2_PLAUSIBLE_MAX

ROOT = Path(__file__).resolve().parents[2]
SCENES = {**{n: p for n, p in scenes.examples().items()},
          **{f"accuracy/{p.stem}": p for p in sorted((ROOT / "examples" / "accuracy").glob("*.toml"))}}


def _m2(wavelength_nm, d_m, theta_rad):
    """ISO 11146 M^2 = pi D Theta / (4 lambda) with the 1/e^2 full quantities D = sqrt(2) d,
    Theta = sqrt(2) theta of the 1/e ones."""
    return math.pi * (math.sqrt(2) * d_m) * (math.sqrt(2) * theta_rad) / (4 * wavelength_nm * 1e-9)


def _slips(w):
    return "imply M^2" in w or ("laser.divergence_rad" in w and "wide beam" in w and "mrad meant?" in w)


@pytest.mark.parametrize("name", sorted(SCENES))
def test_no_bundled_example_warns_about_its_beam(name):
    sc = scenes.load(SCENES[name])
    la = sc.spec.laser
    assert 1.0 <= _m2(la.wavelength_nm, la.beam_diameter_m, la.divergence_rad) <= M2_PLAUSIBLE_MAX
    assert not [w for w in sc.warnings if _slips(w)], sc.warnings


@pytest.mark.parametrize("name", sorted(SCENES))
def test_the_degrees_slip_of_every_bundled_beam_still_warns(name):
    """divergence_rad written as math.degrees(divergence_rad): 57.3x too wide."""
    path = SCENES[name]
    text = path.read_text()
    sc = scenes.load(path)
    theta = sc.spec.laser.divergence_rad
    line = next(ln for ln in text.splitlines() if ln.startswith("divergence_rad = "))
    assert float(line.split("=")[1]) == pytest.approx(theta)
    slipped = scenes.loads(text.replace(line, f"divergence_rad = {math.degrees(theta)!r}"), base_dir=path.parent)
    assert [w for w in slipped.warnings if _slips(w)], (name, slipped.warnings)


@pytest.mark.parametrize("name, spot_m, range_m", [("mirror_window", 0.2, 100.0), ("stainless_melt", 0.085, 10.0),
                                                   ("steel_vs_copper", 0.05, 5.0)])
def test_the_changed_beams_keep_their_spot(name, spot_m, range_m):
    """The beam at the target (1/e diameter a + z phi) is what it was (0.15 + 100 x 5e-4,
    0.08 + 10 x 5e-4, 0.04 + 5 x 2e-3 m): the spot irradiance and the heating histories
    are unchanged; the narrower divergence lengthens the direct and mirror-beam NOHDs."""
    la = scenes.load(scenes.example_path(name)).spec.laser
    assert la.beam_diameter_m + range_m * la.divergence_rad == pytest.approx(spot_m, rel=1e-12)
