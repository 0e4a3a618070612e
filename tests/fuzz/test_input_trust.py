"""Closed inputs (issue 30, items 1, 2 and 4; a fuzz + security review of main).

- Input files are data: no error message quotes what a file holds (the ASTM, BSDF and
  angle-CSV readers, a material JSON's ``format``, history files and CSV headers echoed
  it); each names the file, the line and the column and what was expected.
- Every input error is exit 2 and one line naming the file and the key or line (an empty
  history CSV was an IndexError after a raw NumPy warning, a material JSON without
  ``model`` a KeyError, a BRDF table at grid_deg = 0.1 "out of memory"; ``--backend numpy``
  without rtree).
- Nonsense is refused (tracks and firing windows of 1e-300 s, a 1e-300 m plate, terrain
  1e-300 m across, .bsdf counts of 3.7 and NaN / 95 deg / 1e300 / inf angles that were
  truncated or dropped silently); the odd but possible is a warning in the stdout answer
  and report.json ``warnings`` (an observer at the aperture, now in the beam with the exit
  irradiance; a zero divergence, whose infinite NOHD now comes with its reason).
The DEM cases (VRT, SSRF, complex, rotated, 100-degree cells): tests/scenes/test_dem_trust.py.
"""

from __future__ import annotations

import io
import json
import math
import warnings

import pytest

from hazard.cli import main

from tests._scene_text import PLATE_AT_50M

SECRET = "hunter2-s3cr3t"
BASE = PLATE_AT_50M + """[[observers]]
name = "east"
points_m = [[10.0, -17.0, 1.0]]
"""
MATERIAL = 'material = { model = "lambertian", reflectance = 0.5 }'
SERIES = '\n[targets.history]\nkind = "series"\nstate = "reflectance_factor"\nfile = "{f}"\nextrapolation = "clamp"\n'


def _cli(*argv):
    """(exit code, stdout, stderr); a raw NumPy / Python warning on the way fails the test."""
    out, err = io.StringIO(), io.StringIO()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        code = main([str(a) for a in argv], stdout=out, stderr=err)
    raw = [str(w.message) for w in caught if issubclass(w.category, (RuntimeWarning, UserWarning))]
    assert not raw, raw
    return code, out.getvalue(), err.getvalue()


def _refused(tmp_path, text, *words, verbs=("validate", "run")):
    """Each verb: exit 2, one line on stderr holding ``words``, nothing of SECRET."""
    scene = tmp_path / "s.toml"
    scene.write_text(text)
    for verb in verbs:
        argv = ("validate", scene) if verb == "validate" else ("run", scene, "-o", tmp_path / "out", "--quiet", "--force")
        code, out, err = _cli(*argv)
        lines = [x for x in err.splitlines() if x.strip()]
        assert code == 2 and len(lines) == 1, (verb, code, err)
        assert "Traceback" not in err and "Warning" not in err and SECRET not in out + err, err
        for w in words:
            assert w in lines[0], lines[0]
    return lines[0]


def _bsdf(aoi="10", rad_count="2", rad="0 5", symmetry="PlaneSymmetrical", value="0.1"):
    return "\n".join(["Source  Measured", f"Symmetry  {symmetry}", "SpectralContent  Monochrome", "ScatterType  BRDF",
                      "SampleRotation 1", "0", f"AngleOfIncidence {len(aoi.split())}", aoi, "ScatterAzimuth 2", "0 90",
                      f"ScatterRadial {rad_count}", rad, "DataBegin"]
                     + [f"TIS 0.5\n{value} 0.1\n0.1 0.1" for _ in aoi.split()] + ["DataEnd", ""])


def _table(name):
    return BASE.replace(MATERIAL, f'material = {{ model = "table", file = "{name}" }}')


# -- 1. no file contents in error messages -------------------------------------------
@pytest.mark.parametrize("name, content, words", [
    ("hist.csv", f"{SECRET},x\n1,2\n", ["targets[0].history.file", "line 1", "missing time_s"]),
    ("passwd.csv", f"root:x:0:0:{SECRET}:/root:/bin/bash\nbin:x:1:1::/bin:\n", ["line 1", "expected CSV columns"]),
    ("bad.csv", f"time_s,reflectance_factor\n0,1\n1,{SECRET}\n", ["line 3, column 2 (reflectance_factor)", "finite number"]),
])
def test_history_files_are_not_echoed(name, content, words, tmp_path):
    (tmp_path / name).write_text(content)
    _refused(tmp_path, BASE.replace(MATERIAL, MATERIAL + SERIES.format(f=name)), *words)


@pytest.mark.parametrize("doc, words", [
    ({"format": SECRET, "version": 1}, ["file='m.json'", "format: expected 'brdfmodels.model'"]),
    ({SECRET: 1, "token": SECRET}, ["format: expected"]),
    ({"format": "brdfmodels.model", "version": 1}, ["file='m.json'", "missing 'model'"]),  # was KeyError, exit 1
])
def test_material_json_errors_name_the_file_not_its_contents(doc, words, tmp_path):
    (tmp_path / "m.json").write_text(json.dumps(doc))
    _refused(tmp_path, BASE.replace(MATERIAL, 'material = { file = "m.json" }'), "targets[0].material", *words)


@pytest.mark.parametrize("name, content, words", [
    ("a.astm", f"NUM_POINTS 1\nVARS theta_i,phi_i,theta_s,phi_s,e\n0.1,0.2,0.3,0.4,{SECRET}\n", ["line 3, column 5", "expected a number"]),
    ("b.astm", f"NUM_POINTS 1\nVARS {SECRET},b\n", ["line 2: VARS", "five names"]),
    ("c.bsdf", _bsdf(symmetry=SECRET), ["Symmetry: expected PlaneSymmetrical"]),
    ("d.bsdf", _bsdf(value=SECRET), ["line 15, column 1", "finite BRDF >= 0"]),
    ("e.bsdf", _bsdf().replace("DataEnd", SECRET), ["expected DataEnd"]),
    ("f.csv", f"theta_i_deg,phi_i_deg,theta_r_deg,phi_r_deg,{SECRET}\n1,2,3,4,5\n", ["line 1", "(the header has 5 column(s))"]),
    ("g.csv", f"theta_i_deg,phi_i_deg,theta_r_deg,phi_r_deg,brdf_per_sr\n1,2,3,{SECRET},5\n", ["line 2, column 4 (phi_r_deg)"]),
])
def test_measurement_files_are_not_echoed(name, content, words, tmp_path):
    (tmp_path / name).write_text(content)
    _refused(tmp_path, _table(name), "targets[0].material", *words, verbs=("validate",))


# -- 2. every input error is an input error ------------------------------------------
@pytest.mark.parametrize("content, words", [
    ("", ["empty file", "time_s, reflectance_factor"]),  # was IndexError after a NumPy UserWarning, exit 1
    ("time_s,reflectance_factor\n", ["no data rows"]),
    ("time_s,reflectance_factor\n0,1\n1\n", ["line 3: 1 cells, expected 2"]),
])
def test_empty_or_short_history_files_are_input_errors(content, words, tmp_path):
    (tmp_path / "h.csv").write_text(content)
    _refused(tmp_path, BASE.replace(MATERIAL, MATERIAL + SERIES.format(f="h.csv")), "targets[0].history.file='h.csv'", *words)


def test_a_table_grid_too_fine_is_refused_before_any_memory(tmp_path):
    """grid_deg = 0.1 (the documented minimum) makes 901 x 901 x 1800 = 1.461e9 nodes (the
    theta_h and theta_d nodes end at 90 deg): 12 GB."""
    (tmp_path / "a.bsdf").write_text(_bsdf())
    text = BASE.replace(MATERIAL, 'material = { model = "table", file = "a.bsdf", grid_deg = [0.1, 0.1, 0.1] }')
    line = _refused(tmp_path, text, "targets[0].material", "grid_deg", "HAZARD_MAX_TABLE_NODES")
    assert f"table nodes ((90/theta_h + 1) x (90/theta_d + 1) x (180/phi_d)) = {901 * 901 * 1800}" in line


def test_the_numpy_backend_without_rtree_is_an_input_error(tmp_path, monkeypatch):
    import importlib.util

    real = importlib.util.find_spec
    monkeypatch.setattr(importlib.util, "find_spec", lambda name, *a: None if name == "rtree" else real(name, *a))
    (tmp_path / "s.toml").write_text(BASE)
    code, out, err = _cli("run", tmp_path / "s.toml", "-o", tmp_path / "out", "--quiet", "--backend", "numpy")
    assert code == 2 and len(err.strip().splitlines()) == 1 and "rtree" in err and "laser-hazard[numpy-backend]" in err, err
    (tmp_path / "t.toml").write_text(BASE + '[terrain]\nkind = "flat"\nextent_m = 100.0\nresolution_m = 5.0\n')  # a ray scene
    code, out, err = _cli("run", tmp_path / "t.toml", "-o", tmp_path / "out", "--quiet", "--backend", "numpy")
    assert code == 2 and len(err.strip().splitlines()) == 1 and "rtree" in err, err


# -- 4. nonsense refused -------------------------------------------------------------
TRACK = '[[observers]]\nname = "plane"\nkind = "track"\ntimes_s = [0.0, {t}]\npositions_m = [[0.0, 0.0, 100.0], [10.0, 0.0, 100.0]]\n'


@pytest.mark.parametrize("case, text, words", [
    ("a track 2e-300 s long", BASE + TRACK.format(t="2e-300"), ["times_s", "times 0 and 1", "at least 1e-06 s"]),
    ("a straight track 2e-300 s long", BASE + '[[observers]]\nname = "plane"\nkind = "track"\nstart_m = [0.0, 0.0, 100.0]\n'
     'velocity_m_s = [10.0, 0.0, 0.0]\nduration_s = 2e-300\n', ["duration_s", "0.000001"]),
    ("a firing window of 1e-300 s", BASE.replace("divergence_rad = 0.001", "divergence_rad = 0.001\nwindows = [[0.0, 1e-300]]"),
     ["laser.windows", "lasts 1e-300 s", "pulse"]),
    ("a 1e-300 m plate", BASE.replace("size_m = [1.0, 1.0]", "size_m = [1e-300, 1.0]"), ["targets[0].size_m[0]", "0.000001"]),
    ("terrain 1e-300 m across", BASE + '[terrain]\nkind = "flat"\nextent_m = 1e-300\nresolution_m = 1e-300\n',
     ["terrain.extent_m", "0.001"]),
    ("height-map cells of 1e-300 m", BASE + '[terrain]\nkind = "heightmap"\nfile = "h.npy"\nspacing_m = 1e-300\n',
     ["terrain.spacing_m", "0.001"]),
], ids=lambda v: v if isinstance(v, str) and len(v) < 40 else "")
def test_nonsense_is_refused(case, text, words, tmp_path):
    _refused(tmp_path, text, *words)


@pytest.mark.parametrize("case, bsdf, words", [
    ("a count of 3.7", _bsdf(rad_count="3.7", rad="0 5 10"), ["line 11, column 2: ScatterRadial", "whole number"]),
    ("a NaN incidence", _bsdf(aoi="nan"), ["AngleOfIncidence: angle 1 of 1 is not finite"]),
    ("a 95 deg incidence", _bsdf(aoi="95"), ["AngleOfIncidence: angle 1 of 1 is out of range", "below 90"]),
    ("a 1e300 deg incidence", _bsdf(aoi="1e300"), ["AngleOfIncidence", "out of range"]),
    ("an infinite radial angle", _bsdf(rad="0 inf"), ["ScatterRadial: angle 2 of 2 is not finite"]),
], ids=lambda v: v if isinstance(v, str) and len(v) < 40 else "")
def test_bsdf_headers_are_whole_and_finite(case, bsdf, words, tmp_path):
    (tmp_path / "a.bsdf").write_text(bsdf)
    _refused(tmp_path, _table("a.bsdf"), "a.bsdf", *words, verbs=("validate",))


# -- 4. odd but possible: a warning in the answer and in report.json -----------------
def _run(tmp_path, text):
    scene = tmp_path / "s.toml"
    scene.write_text(text)
    code, out, err = _cli("run", scene, "-o", tmp_path / "out", "--quiet")
    assert code == 0, err
    return out, err, json.loads((tmp_path / "out" / "report.json").read_text())


def test_an_observer_at_the_aperture_is_in_the_beam(tmp_path):
    """On the aperture plane, on the axis: the exit irradiance P / (pi w0^2), w0 = a / 2
    (was 0 W/m^2: the beam began strictly in front of the aperture). Behind it: out of
    the beam, and both said in a warning."""
    text = BASE.replace("points_m = [[10.0, -17.0, 1.0]]", "points_m = [[0.0, -50.0, 1.0], [0.0, -50.5, 1.0]]")
    out, err, doc = _run(tmp_path, text)
    at, behind = doc["observers"][:2]
    exit_w_m2 = 100.0 / (math.pi * 0.005 ** 2)
    assert at["direct_point_irradiance_w_m2"] == pytest.approx(exit_w_m2, rel=1e-9)
    # the verdict's value: the power through the centred 7 mm pupil, 1 - exp(-rho^2 / w0^2)
    pupil = 100.0 * (1 - math.exp(-(3.5e-3 / 0.005) ** 2)) / (math.pi * 3.5e-3 ** 2)
    assert at["direct_irradiance_w_m2"] == pytest.approx(pupil, rel=1e-9)
    assert behind["direct_irradiance_w_m2"] == 0.0 and behind["direct_point_irradiance_w_m2"] == 0.0
    warning = [w for w in doc["warnings"] if "laser aperture" in w]
    assert len(warning) == 1 and "1 on or in front" in warning[0] and "1 behind it are out of the beam" in warning[0]
    assert "warning: observers: 2 point(s) within 1 m of the laser aperture" in out


def test_a_zero_divergence_says_why_its_nohd_is_infinite(tmp_path):
    out, err, doc = _run(tmp_path, BASE.replace("divergence_rad = 0.001", "divergence_rad = 0.0"))
    assert doc["sdz"]["nohd_m"] == "inf"
    reason = [w for w in doc["warnings"] if w.startswith("laser.divergence_rad = 0")]
    assert len(reason) == 1 and "infinite" in reason[0]
    assert f"warning: {reason[0]}" in out


@pytest.mark.parametrize("name, content, words", [
    ("m.gltf", '{"buffers": [{"uri": "/etc/passwd"}]}', ["expected a mesh file of type stl, obj, ply, off", "refused"]),
    ("m.obj", f"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 {SECRET}\n", ["cannot read the mesh as OBJ"]),
])
def test_mesh_files_are_read_alone_and_not_echoed(name, content, words, tmp_path):
    (tmp_path / name).write_text(content)
    text = BASE.replace('shape = "plate"', f'shape = "mesh"\nfile = "{name}"').replace("size_m = [1.0, 1.0]\n", "")
    _refused(tmp_path, text, "targets[0]", *words, verbs=("validate",))


def test_binary_headers_are_not_echoed(tmp_path):
    """A .npy header and a MERL file's first 12 bytes (its dims) were quoted by the errors."""
    header = b'{"descr": "' + SECRET.encode() + b'", "fortran_order": False, "shape": (2, 2), }'
    (tmp_path / "h.npy").write_bytes(b"\x93NUMPY\x01\x00" + len(header + b"\n").to_bytes(2, "little") + header + b"\n")
    _refused(tmp_path, BASE + '[terrain]\nkind = "heightmap"\nfile = "h.npy"\nspacing_m = 1.0\n',
             "terrain.file='h.npy'", "cannot read the heightmap")
    (tmp_path / "m.binary").write_bytes(SECRET.encode()[:12] + b"\0" * 20)
    line = _refused(tmp_path, _table("m.binary"), "not a MERL file", verbs=("validate",))
    assert str(int.from_bytes(SECRET.encode()[:4], "little")) not in line


def test_a_merl_file_without_data_is_an_input_error(tmp_path):
    """Every cell NaN: a raw NumPy 'All-NaN slice' warning, then an error naming no file."""
    (tmp_path / "m.binary").write_bytes(b"\x01\x00\x00\x00" * 3 + b"\xff" * 24)
    _refused(tmp_path, _table("m.binary"), "m.binary", "no cell of the MERL file has data", verbs=("validate",))


@pytest.mark.parametrize("boundary, words", [
    ("[[0.0, 0.0], [3000000.0, 0.0], [3000000.0, 10.0], [0.0, 10.0]]", "range: boundary_m: the range spans 3000 km"),
    ("[[-100.0, -100.0], [100.0, -100.0], [100.0, 100.0], [-100.0, 1200000.0]]", "the range spans 1200 km (point 3"),
])
def test_a_range_boundary_over_1000_km_across_is_refused(boundary, words, tmp_path):
    """A range boundary with a coordinate typed wrong (the fuzz's lat = 0: 3400 km off) put
    beams that leave the real range inside it, silently. 1000 km is past the largest
    ranges (a few hundred km across); 990 km is accepted."""
    assert "s.toml" in _refused(tmp_path, BASE + f"[range]\nboundary_m = {boundary}\n", words)


def test_a_range_boundary_of_990_km_is_accepted(tmp_path):
    out, err, doc = _run(tmp_path, BASE + "[range]\nboundary_m = [[-495000.0, -100.0], [495000.0, -100.0], [0.0, 1000.0]]\n")
    assert doc["targets"][0]["name"] == "plate"


GRID = '[[observers]]\nname = "g"\norigin_m = [-5.0, -30.0, 1.0]\nu_m = {u}\nv_m = [0.0, 10.0, 0.0]\ncounts = [3, 3]\n{eye}'
LINE = '[[observers]]\nname = "l"\nstart_m = [-5.0, -30.0, 1.0]\nend_m = {end}\ncount = 4\n{eye}'
FLAT = '[terrain]\nkind = "flat"\ncenter_m = [0.0, -20.0, 0.0]\nextent_m = 200.0\nresolution_m = 10.0\n'


@pytest.mark.parametrize("extra, words", [
    (GRID.format(u="[0.0, 0.0, 0.0]", eye=""), "observers[1]: u_m: the grid's edge has a length of 0 m, so its 3 points"),
    (GRID.format(u="[1e-9, 0.0, 0.0]", eye=""), "u_m: the grid's edge has a length of 1e-09 m"),
    (LINE.format(end="[-5.0, -30.0, 1.0]", eye=""), "observers[1]: end_m: the line from start_m has a length of 0 m, so its 4"),
    # at eye height only the horizontal part spreads the points (their height is the terrain's)
    (FLAT + GRID.format(u="[0.0, 0.0, 3.0]", eye="eye_height_m = 1.7\n"), "u_m: the grid's edge has a horizontal length of 0 m"),
    (FLAT + LINE.format(end="[-5.0, -30.0, 9.0]", eye="eye_height_m = 1.7\n"), "end_m: the line from start_m has a horizontal"),
])
def test_observer_points_laid_on_one_another_are_refused(extra, words, tmp_path):
    """A grid edge or a line of several points with no length: the fuzz's u_m = [0, 0, 0]
    was analysed as 9 points, 3 of each on one another (issue 30). Refused by the one
    acceptance of every verb (validate == run: tests/fuzz/test_validate_equals_run.py)."""
    assert "s.toml" in _refused(tmp_path, BASE + extra, words, verbs=("validate",))


def test_one_point_along_a_zero_edge_or_a_1_um_edge_is_accepted(tmp_path):
    for i, ok in enumerate((GRID.format(u="[0.0, 0.0, 0.0]", eye="").replace("[3, 3]", "[1, 3]"),
                            GRID.format(u="[1e-6, 0.0, 0.0]", eye=""))):
        (tmp_path / str(i)).mkdir()
        out, err, doc = _run(tmp_path / str(i), BASE + ok)
        assert sum(o["name"].startswith("g[") for o in doc["observers"]) == (3 if "[1, 3]" in ok else 9)
