"""Findings of a new-user fuzz run (935 mutated scene files through `hazard validate` and
`hazard run`, issue 12): each is now one clear line naming the field, the same from
`validate` and `run`, with nothing else on stderr (no NumPy warning, no traceback), or a
sane run. Before: multi-line crashes on a spot of underflowed power, a NaN beam direction
accepted, validate accepting what run refused (UV wavelengths, sub-table pulse
durations, a series too short, tiny tolerances), terrain grids of 16e6 nodes taking
minutes and 10 GB, "internal error" for an .npz height map, a lying .npy header or a
deeply nested material JSON, a target named like the terrain."""

from __future__ import annotations

import io
import json

import numpy as np
import pytest

from hazard.cli import main

from tests._scene_text import PLATE_AT_50M

BASE = PLATE_AT_50M + """[[observers]]
name = "east"
points_m = [[10.0, -17.0, 1.0]]
"""

TERRAIN = """
[terrain]
kind = "flat"
center_m = [0.0, 0.0, 0.0]
extent_m = 100.0
resolution_m = 5.0
"""

SERIES = """
[targets.history]
kind = "series"
state = "reflectance_factor"
times_s = [0.0, 1.0]
states = [1.0, 0.9]
extrapolation = "error"
"""


def _cli(*argv, env=None, monkeypatch=None):
    out, err = io.StringIO(), io.StringIO()
    code = main([str(a) for a in argv], stdout=out, stderr=err)
    return code, out.getvalue(), err.getvalue()


def _both(path, tmp_path):
    """(exit code, stderr) of validate and of run."""
    v = _cli("validate", path)
    r = _cli("run", path, "-o", tmp_path / "o", "--quiet")
    return (v[0], v[2]), (r[0], r[2])


def _one_line_error(stderr, *words):
    lines = [x for x in stderr.splitlines() if x.strip()]
    assert len(lines) == 1, stderr
    assert "Traceback" not in stderr and "Warning" not in stderr
    for w in words:
        assert w in lines[0], lines[0]


CASES = {
    "aim 1e-300 m from the laser": (BASE.replace("aim_m = [0.0, 0.0, 1.0]", "aim_m = [1e-300, -50.0, 1.0]"), ["laser.aim_m", "undefined"]),
    "a laser of 1e-300 W": (BASE.replace("power_w = 100.0", "power_w = 1e-300"), ["laser.power_w", "greater than or equal to 0.000000001"]),
    "below the UV rows": (BASE.replace("wavelength_nm = 1064.0", "wavelength_nm = 179.0"), ["laser.wavelength_nm", "180"]),
    "a beam of 1e-300 m": (BASE.replace("beam_diameter_m = 0.01", "beam_diameter_m = 1e-300"), ["laser.beam_diameter_m"]),
    "a series shorter than the analysis": (BASE.replace('material = { model = "lambertian", reflectance = 0.5 }',
                                                        'material = { model = "lambertian", reflectance = 0.5 }' + SERIES),
                                           ["targets[0].history", "covers [0, 1] s", "extrapolation = 'clamp'"]),
    "a terrain of 16e6 nodes": (BASE + TERRAIN.replace("resolution_m = 5.0", "resolution_m = 0.05"), ["terrain", "HAZARD_MAX_TERRAIN_NODES"]),
    "a target named terrain beside the terrain": (BASE.replace('name = "plate"', 'name = "terrain"') + TERRAIN, ["'terrain'"]),
    "a Fresnel index of 1e-308": (BASE.replace('{ model = "lambertian", reflectance = 0.5 }', '{ model = "specular", n = 1e-308 }'),
                                  ["targets[0].material", "n=1e-308"]),
    "a number of 5000 digits": (BASE.replace("power_w = 100.0", "power_w = " + "9" * 5000), ["not valid TOML", "digits"]),
    "a heating history with a series": (BASE.replace('material = { model = "lambertian", reflectance = 0.5 }',
                                                     'material = { model = "lambertian", reflectance = 0.5 }\n[targets.history]\n'
                                                     'kind = "heating"\nplate = "stainless_steel"\nstate = "reflectance_factor"\n'
                                                     "times_s = [0.0, 1.0]\nstates = [1.0, 1.0]\n"),
                                        ["targets[0].history", "only for kind = 'series'"]),
}


@pytest.mark.parametrize("name", sorted(CASES))
def test_validate_and_run_refuse_it_in_one_line(name, tmp_path):
    text, words = CASES[name]
    path = tmp_path / "s.toml"
    path.write_text(text)
    (vc, ve), (rc, re_) = _both(path, tmp_path)
    assert vc == rc == 2
    _one_line_error(ve, *words)
    _one_line_error(re_, *words)


def test_bad_height_maps_and_material_files_are_input_errors(tmp_path):
    np.savez(tmp_path / "hm.npz", h=np.zeros((4, 4)))
    with open(tmp_path / "liar.npy", "wb") as fh:  # a header promising 1e6 x 1e6 heights, 16 bytes of data
        np.lib.format.write_array_header_1_0(fh, {"descr": "<f8", "fortran_order": False, "shape": (1_000_000, 1_000_000)})
        fh.write(b"\0" * 16)
    (tmp_path / "deep.json").write_text('{"format": "brdfmodels.model", "version": 1, "model": ' + "[" * 100_000 + "]" * 100_000 + "}")
    heightmap = '[terrain]\nkind = "heightmap"\nfile = "{f}"\norigin_m = [-50.0, -60.0]\nspacing_m = 10.0\n'
    for text, words in ((BASE + heightmap.format(f="hm.npz"), ["terrain.file", "archive"]),
                        (BASE + heightmap.format(f="liar.npy"), ["terrain.file", "cannot read the heightmap"]),
                        (BASE.replace('{ model = "lambertian", reflectance = 0.5 }', '{ file = "deep.json" }'),
                         ["targets[0].material", "nesting too deep"])):
        path = tmp_path / "s.toml"
        path.write_text(text)
        (vc, ve), (rc, re_) = _both(path, tmp_path)
        assert vc == rc == 2, (ve, re_)
        _one_line_error(ve, *words)


@pytest.mark.parametrize("power, mu", [(1e-9, 0.0), (100.0, 10.0)])
def test_a_spot_of_underflowed_power_is_analysed(power, mu, tmp_path):
    """1 nW (the least power a scene takes; 1e-300 W is refused), or 100 W through 50 m
    at 10 /m (e^-500): the spot's means were 0/0 and the run crashed in several lines;
    now it runs and reports a safe, finite answer, the plate still in the beam."""
    text = BASE.replace("power_w = 100.0", f"power_w = {power!r}") + f"[atmosphere]\nattenuation_per_m = {mu!r}\n"
    path = tmp_path / "s.toml"
    path.write_text(text)
    code, out, err = _cli("run", path, "-o", tmp_path / "o", "--quiet")
    assert code == 0 and "Warning" not in err and "Traceback" not in err
    doc = json.loads((tmp_path / "o" / "report.json").read_text())
    assert [t["name"] for t in doc["targets"]] == ["plate"] and not doc["observers"][0]["hazardous"]
    assert doc["targets"][0]["hit"] == "beam"  # thick air is not a miss


@pytest.mark.parametrize("name, value, words", [("FILE_MB", "1e308", ["HAZARD_MAX_FILE_MB", "up to"]),
                                                  ("KEEPOUT_CELLS", "inf", ["HAZARD_MAX_KEEPOUT_CELLS='inf'", "up to"]),
                                                  ("DEPTH", "100000", ["HAZARD_MAX_DEPTH", "up to 200"])])
def test_absurd_limits_are_refused_in_one_line(name, value, words, tmp_path, monkeypatch):
    monkeypatch.setenv(f"HAZARD_MAX_{name}", value)
    path = tmp_path / "s.toml"
    path.write_text(BASE)
    code, _, err = _cli("validate", path)
    assert code == 2
    _one_line_error(err, *words)
