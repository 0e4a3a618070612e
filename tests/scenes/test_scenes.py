"""Scene loading: validation with field paths, conversion, re-centring, examples, schema."""

import json

import numpy as np
import pytest

import scenes

BASE = """
name = "t"
[laser]
wavelength_nm = 1064.0
power_w = 100.0
beam_diameter_m = 0.005
divergence_rad = 0.001
position_m = [0.0, -50.0, 0.0]
aim_m = [0.0, 0.0, 0.0]
[exposure]
duration_s = 10.0
standard = "ansi-z136.1-2014"
[[targets]]
name = "plate"
shape = "plate"
center_m = [0.0, 0.0, 0.0]
normal = [0.0, -1.0, 0.0]
tangent = [1.0, 0.0, 0.0]
size_m = [1.0, 1.0]
material = { model = "lambertian", reflectance = 0.5 }
[[occluders]]
shape = "box"
center_m = [-5.0, -8.0, 0.0]
size_m = [2.0, 2.0, 2.0]
[[observers]]
name = "east"
points_m = [[10.0, -17.0, 0.0]]
"""


def test_issue_example_loads():
    s = scenes.loads(BASE)
    assert s.name == "t" and len(s.targets) == 1 and len(s.occluders) == 1
    np.testing.assert_allclose(s.laser_direction, [0, 1, 0])
    assert s.observers.labels() == ["east"]


def test_examples_bundled_and_valid():
    ex = scenes.examples()
    assert {"witness_screen", "range_terrain", "steel_vs_copper", "mirror_window", "binoculars", "plate"} <= set(ex)
    for name, path in ex.items():
        s = scenes.load(path)
        assert s.name == name and len(s.targets) >= 1


@pytest.mark.parametrize(
    "old, new, message",
    [
        ("power_w = 100.0", "power_w = -5.0", "laser.power_w: Input should be greater than or equal to 0.000000001"),
        ("wavelength_nm = 1064.0", "wavelength_nm = 100.0", "laser.wavelength_nm: Input should be greater than or equal to 180"),
        ("wavelength_nm = 1064.0", "wavelength_nm = 179.0", "laser.wavelength_nm: Input should be greater than or equal to 180"),
        ("wavelength_nm = 1064.0", "wavelength_nm = 2e6", "laser.wavelength_nm: Input should be less than or equal to 1000000"),
        ("aim_m = [0.0, 0.0, 0.0]", "aim_m = [0.0, -50.0, 0.0]", "aim_m=[0.0, -50.0, 0.0] equals position_m"),
        ("duration_s = 10.0", "duration_s = \"long\"", "exposure.duration_s: Input should be a valid number"),
        ("standard = \"ansi-z136.1-2014\"", "standard = \"ansi-2014\"", "exposure.standard: Input should be 'ansi-z136.1-2014'"),
        ("size_m = [1.0, 1.0]", "size_m = [1.0]", "targets[0]: size_m=[1.0]: a plate needs 2"),
        ("reflectance = 0.5 }", "reflectivity = 0.5 }", "lambertian: unknown parameters ['reflectivity']"),
        ("model = \"lambertian\"", "model = \"lambert\"", "model='lambert' is unknown: expected one of"),
        ("name = \"plate\"\nshape", "colour = \"red\"\nname = \"plate\"\nshape", "targets[0].colour: unknown key"),
        ("points_m = [[10.0, -17.0, 0.0]]", "points_m = [[-5.0, -8.0, 0.5]]", "observers[0] (east): point [-5.0, -8.0, 0.5] is inside occluders[0] (box)"),
        ("tangent = [1.0, 0.0, 0.0]", "tangent = [0.0, 2.0, 0.0]", "is parallel to normal"),
        ("position_m = [0.0, -50.0, 0.0]", "position_m = [-5.0, -8.0, 0.5]",
         "laser.position_m = [-5.0, -8.0, 0.5] is inside occluders[0] (box); expected the laser in open air"),
    ],
)
def test_bad_scenes_name_the_field(old, new, message):
    assert old in BASE
    with pytest.raises(scenes.SceneError) as exc:
        scenes.loads(BASE.replace(old, new, 1), source="bad.toml")
    text = str(exc.value)
    assert text.startswith("bad.toml: ") and message in text, text
    assert "\n" not in text


def test_empty_target_list():
    start = BASE.index("[[targets]]")
    end = BASE.index("[[occluders]]")
    text = BASE[:start].replace('name = "t"\n', 'name = "t"\ntargets = []\n', 1) + BASE[end:]
    with pytest.raises(scenes.SceneError, match="targets: List should have at least 1 item"):
        scenes.loads(text)


def test_not_toml_and_missing_file(tmp_path):
    with pytest.raises(scenes.SceneError, match="not valid TOML"):
        scenes.loads("name = ")
    with pytest.raises(scenes.SceneError, match="cannot read the scene"):
        scenes.load(tmp_path / "nope.toml")


def test_dynamic_material_needs_history():
    text = BASE.replace('material = { model = "lambertian", reflectance = 0.5 }', 'material = { file = "stainless_dynamic.json" }')
    with pytest.raises(scenes.SceneError, match="depends on 'extinction'; give a history"):
        scenes.loads(text, base_dir=scenes.example_path("plate").parent)


def test_history_state_must_match_material():
    text = BASE.replace('material = { model = "lambertian", reflectance = 0.5 }', 'material = { file = "stainless_dynamic.json" }')
    text = text.replace("[[occluders]]", '[targets.history]\nkind = "series"\nstate = "temperature_k"\ntimes_s = [0.0, 1.0]\nstates = [300.0, 900.0]\n[[occluders]]')
    with pytest.raises(scenes.SceneError, match="history.state='temperature_k': the material depends on 'extinction'"):
        scenes.loads(text, base_dir=scenes.example_path("plate").parent)


def test_far_coordinates_are_recentred():
    # UTM-like coordinates: float32 would have a 0.5 m ulp; the local origin removes it
    off = np.array([500000.0, 5000000.0, 300.0])
    text = BASE
    for a, b in [("[0.0, -50.0, 0.0]", "[500000.0, 4999950.0, 300.0]"), ("aim_m = [0.0, 0.0, 0.0]", "aim_m = [500000.0, 5000000.0, 300.0]"),
                 ("center_m = [0.0, 0.0, 0.0]", "center_m = [500000.0, 5000000.0, 300.0]"),
                 ("center_m = [-5.0, -8.0, 0.0]", "center_m = [499995.0, 4999992.0, 300.0]"),
                 ("[[10.0, -17.0, 0.0]]", "[[500010.0, 4999983.0, 300.0]]")]:
        text = text.replace(a, b)
    s = scenes.loads(text)
    np.testing.assert_allclose(s.offset_m, off)
    np.testing.assert_allclose(s.observers.positions_m, [[10.0, -17.0, 0.0]], atol=1e-9)
    np.testing.assert_allclose(s.to_world(s.observers.positions_m), [[500010.0, 4999983.0, 300.0]])


def test_observer_layouts_and_eye_height():
    text = BASE.replace('[[observers]]\nname = "east"\npoints_m = [[10.0, -17.0, 0.0]]', """
[terrain]
kind = "hill"
center_m = [0.0, -20.0, 0.0]
height_m = 1.0
radius_m = 3.0
extent_m = 60.0
resolution_m = 1.0
[[observers]]
name = "line"
start_m = [-10.0, -20.0, 0.0]
end_m = [10.0, -20.0, 0.0]
count = 5
eye_height_m = 1.7
[[observers]]
name = "grid"
origin_m = [-10.0, -40.0, 20.0]
u_m = [20.0, 0.0, 0.0]
v_m = [0.0, 10.0, 0.0]
counts = [3, 2]
[[observers]]
name = "shell"
center_m = [0.0, 0.0, 0.0]
radius_m = 30.0
count = 10
""").replace("center_m = [-5.0, -8.0, 0.0]", "center_m = [-5.0, -8.0, 50.0]")
    s = scenes.loads(text)
    obs = s.observers
    assert len(obs) == 5 + 6 + 10
    line = obs.positions_m[:5]
    ground = s.terrain.height_at(line[:, 0], line[:, 1])
    np.testing.assert_allclose(line[:, 2] - ground, 1.7)
    assert np.all(obs.positions_m[11:, 2] > 0)
    np.testing.assert_allclose(np.linalg.norm(obs.positions_m[11:], axis=1), 30.0)


def test_json_schema_accepts_the_examples():
    import jsonschema
    import tomllib

    schema = scenes.json_schema()
    assert schema["title"] == "laser-hazard scene" and "laser" in schema["properties"]
    # jsonschema.validate checks the schema itself on every call (2.1 s for the 11 examples):
    # the same two checks, the schema once, then each example against it (0.2 s)
    cls = jsonschema.validators.validator_for(schema)
    cls.check_schema(schema)
    validator = cls(schema)
    for path in scenes.examples().values():
        validator.validate(tomllib.loads(path.read_text()))


def test_spec_standards_match_hazard():
    import hazard
    from scenes.spec import STANDARD_KEYS

    assert set(STANDARD_KEYS) == set(hazard.STANDARDS)


def test_echo_is_json():
    s = scenes.loads(BASE)
    assert json.loads(json.dumps(s.echo()))["laser"]["power_w"] == 100.0


def test_laser_below_the_terrain_is_an_error():
    """A laser under the ground would have its beam stopped at the aperture: every observer
    would look safe. It cannot be meant: an error naming the field and the ground height."""
    text = open(scenes.example_path("range_terrain")).read()
    assert "position_m = [0.0, -400.0, 3.0]" in text
    with pytest.raises(scenes.SceneError, match=r"laser.position_m = \[0.0, -400.0, -30.0\] is below the terrain"):
        scenes.loads(text.replace("position_m = [0.0, -400.0, 3.0]", "position_m = [0.0, -400.0, -30.0]"))


def test_terrain_heights_are_scipys_bilinear_interpolation():
    """Heightfield.height_at against scipy's RegularGridInterpolator (linear) on random
    heights, at random points and on the nodes and edges."""
    from scipy.interpolate import RegularGridInterpolator

    from scenes.geometry import Heightfield

    rng = np.random.default_rng(3)
    h = rng.normal(size=(17, 23)) * 10
    hf = Heightfield(-4.0, 7.0, 2.5, h)
    xs, ys = -4.0 + 2.5 * np.arange(23), 7.0 + 2.5 * np.arange(17)
    ref = RegularGridInterpolator((ys, xs), h, method="linear")
    x = np.concatenate([rng.uniform(xs[0], xs[-1], 2000), xs, np.full(17, xs[-1])])
    y = np.concatenate([rng.uniform(ys[0], ys[-1], 2000), np.full(23, ys[0]), ys])
    np.testing.assert_allclose(hf.height_at(x, y), ref(np.stack([y, x], 1)), rtol=1e-12, atol=1e-6)  # last row/column: clipped 1e-9 cell inside
