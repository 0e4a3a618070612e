"""The material library: entries equal to their published sources (written here), the
paper's own check (white paint DHR 73.4 % at normal incidence), copper's normal
reflectance at 1064 nm from its n, k, and scenes that name them."""

from __future__ import annotations

import io
import json

import numpy as np
import pytest

import brdfmodels as bm
import scenes
from brdfmodels.library import LIBRARY, material
from hazard.cli import main
from tests._scene_text import PLATE_AT_50M

# Zhang et al., Optica Applicata 40(1), 2010: kb, kr, b, a, kd (the paper's column order)
PUBLISHED = {
    "white-paint": (5.708, 2.240, -58.722, 0.452, 0.220),
    "cement": (0.003, 2.961, -18.301, 15.572, 0.067),
    "khaki-painted-steel": (0.0698, 0.478, -28.935, 0.777, 0.107),
    "forged-steel": (0.072, 16.125, -29.917, 0.959, 0.081),
    "polyimide": (5.439, 3.257, -23.098, 0.495, 2.267),
}


@pytest.mark.parametrize("name", sorted(PUBLISHED))
def test_five_parameter_entries_are_the_published_fits(name):
    kb, kr, b, a, kd = PUBLISHED[name]
    assert material(name) == bm.TorranceSparrow5(kb=kb, kr=kr, a=a, b=b, kd=kd)
    assert "Zhang" in LIBRARY[name].source and LIBRARY[name].wavelength_nm == 1060.0


def test_white_paint_reflects_73_4_percent_at_normal_incidence():
    assert bm.hemispherical_reflectance(material("white-paint"), [0.0, 0.0, 1.0]).value == pytest.approx(0.734, abs=1e-3)


def test_copper_mirror_at_1064_nm():
    n, k = 0.123, 7.245  # the bundled table at 1.064 um (shared data README: R = 0.991)
    r = ((n - 1) ** 2 + k ** 2) / ((n + 1) ** 2 + k ** 2)
    assert material("copper-mirror", 1064.0).specular_reflectance([0.0, 0.0, 1.0]) == pytest.approx(r, abs=1e-3)
    with pytest.raises(ValueError, match="wavelength"):
        material("copper-mirror")


def _scene(library, wavelength=1064.0):
    text = PLATE_AT_50M.replace('{ model = "lambertian", reflectance = 0.5 }', f'{{ library = "{library}" }}')
    return scenes.loads(text.replace("wavelength_nm = 1064.0", f"wavelength_nm = {wavelength}"))


def test_scenes_name_library_materials():
    assert _scene("forged-steel").targets[0].material == material("forged-steel")
    assert _scene("lambertian-0.99").targets[0].material == bm.Lambertian(0.99)
    assert _scene("forged-steel").warnings == []
    assert any("measured at 1060 nm" in w for w in _scene("forged-steel", 532.0).warnings)
    with pytest.raises(scenes.SceneError, match=r"hemispherical reflectance 7\.85\d* > 1 at 40 deg"):  # the worst incidence
        _scene("polyimide")  # the published fit returns more than it receives
    with pytest.raises(scenes.SceneError, match=r"library='tin': expected one of \['aluminium-mirror'"):
        _scene("tin")
    with pytest.raises(scenes.SceneError, match="give one of model"):
        scenes.loads(PLATE_AT_50M.replace('{ model = "lambertian", reflectance = 0.5 }',
                                          '{ library = "cement", model = "lambertian", reflectance = 0.5 }'))


def test_hazard_models_materials_lists_every_entry_with_its_source():
    out = io.StringIO()
    assert main(["models", "--materials", "--json"], stdout=out, stderr=io.StringIO()) == 0
    doc = json.loads(out.getvalue())
    assert set(doc) == set(LIBRARY) and all(v["source"] for v in doc.values())
    assert np.isclose(doc["cement"]["params"]["a"], 15.572)
