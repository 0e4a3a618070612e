"""Fuzz the files a scene names (issue 30, item 7): their CONTENTS mutated, not the scene's fields.

Valid inputs are built here (a GeoTIFF DEM and a DTED tile written by GDAL, a Zemax
.bsdf, an ASTM E1392 table, a BRDF angle CSV, a brdfmodels material JSON, a history CSV,
a scene with a track observer, one with an ``[uncertainty]`` table, a study TOML; plus
rasters GDAL writes that are no DEM: complex, three bands, all NaN / nodata / inf, 1e308
heights, one cell, no CRS, a UTM CRS over degree cells, 200 000 x 200 000 cells declared).
Each case mutates one file with a seeded RNG (truncate, flip bits, delete / duplicate a
line or a column, a number replaced by NaN / inf / -0 / 1e308 / a huge count / a negative /
a string, a quoted string or key replaced, empty, BOM, UTF-16, another delimiter, CRLF,
garbage, a NUL, zeroed blocks) and runs ``hazard validate`` and then ``run`` / ``risk`` /
``study --serial`` as the CLI does, in-process (a verb after a refusal is not run: that
validate refuses what the others would is tests/fuzz/test_validate_equals_run.py).

Good: exit 0 with finite results (warnings stated), or exit 2 with one line naming the
mutated file. A defect: another exit code, a traceback, a raw NumPy / Python warning, a
run over 120 s of CPU (600 s wall), non-finite numbers in a JSON the verb writes, an error or answer that
quotes a data file (a scene or study TOML's bad value is echoed beside its field, by
design). Accepted nonsense cannot be told apart automatically: the accepted cases were
read, and what was nonsense is now refused, each with a regression test below.

Default: a seeded sample of the corpus; ``-m slow``: all of it.
"""

from __future__ import annotations

import random
import time
from collections import Counter

import pytest

from tests.fuzz._file_corpus import SECRET, SECURITY_MUTATIONS, all_cases, build_bases, run_case

SAMPLE = 75  # cases in the default run (seeded) of the 6-seed corpus (150 took 58 s CPU on 2 idle cores, 400 took 64 s under less work per case); -m slow: every case of 20 seeds


@pytest.fixture(scope="module")
def corpus(tmp_path_factory):
    bases = build_bases(tmp_path_factory.mktemp("bases"))
    return bases, all_cases(bases)


def _run_all(bases, cases, tmp):
    counts, failures = Counter(), []
    start = time.perf_counter()
    for case in cases:
        try:
            counts[run_case(bases, case, tmp)] += 1
        except AssertionError as exc:
            counts["defect"] += 1
            failures.append(str(exc).splitlines()[0][:400])
    print(f"\nfile fuzz: {len(cases)} cases, {dict(counts)}, {time.perf_counter() - start:.1f} s")
    assert not failures, f"{len(failures)} of {len(cases)}:\n" + "\n".join(failures[:30])
    return counts


def test_the_bases_are_accepted(corpus, tmp_path):
    """Unmutated, every base with real data is accepted by every verb (else the fuzz tests only refusals)."""
    bases, _ = corpus
    for name, base in bases.items():
        if base.targets:
            assert run_case(bases, (name, base.targets[0], "as_is", 0), tmp_path) == "accepted", name


def test_mutated_files_sample(corpus, tmp_path):
    bases, cases = corpus
    rng = random.Random(30)
    sample = rng.sample(cases, min(SAMPLE, len(cases)))
    counts = _run_all(bases, sample, tmp_path)
    assert counts["refused"] > 0 and counts["accepted"] > 0  # both outcomes occur: the classification is exercised


def test_the_security_cases(corpus, tmp_path):
    """Every security mutation (a VRT fetching a URL or reading another file as heights in a
    DEM's place, a named file that is a link to a credentials-like file or to /dev/zero), in
    the default run (each a refusal of about 10 ms): one line naming the file, nothing quoted."""
    bases, cases = corpus
    security = [c for c in cases if c[2] in SECURITY_MUTATIONS]
    assert {c[2] for c in security} == set(SECURITY_MUTATIONS)
    assert _run_all(bases, security, tmp_path)["refused"] == len(security)


@pytest.mark.slow
def test_mutated_files_every_case(corpus, tmp_path):
    bases, _ = corpus
    _run_all(bases, all_cases(bases, seeds=20), tmp_path)


# -- the defects the fuzz found, each a regression test --------------------------------
def _table_scene(tmp_path, name, text):
    from tests.fuzz._file_corpus import _with_material

    (tmp_path / name).write_text(text)
    (tmp_path / "s.toml").write_text(_with_material(f'material = {{ model = "table", file = "{name}" }}'))
    return tmp_path / "s.toml"


def _one_line_refusal(tmp_path, scene, *words):
    from tests.fuzz._file_corpus import _argv, _cli

    for verb in ("validate", "run"):
        code, out, err, raw = _cli(_argv(verb, tmp_path, scene))
        lines = err.strip().splitlines()
        assert code == 2 and len(lines) == 1 and not raw and "Traceback" not in err, (verb, code, err, raw)
        assert all(w in lines[0] for w in words), lines[0]
        assert SECRET not in err + out, lines[0]  # a data file is never quoted


@pytest.mark.parametrize("row, words", [
    ("1e308,20,26,6,0.159", ["line 3, column 1 (theta_i_deg)", "polar angle from 0 to 180 deg"]),
    ("54,99999999999999999999,26,6,0.159", ["line 3, column 2 (phi_i_deg)", "azimuth from -360 to 360 deg"]),
    ("54,20,-1,6,0.159", ["line 3, column 3 (theta_r_deg)", "polar angle"]),
    ("54,20,181,6,0.159", ["line 3, column 3 (theta_r_deg)", "polar angle"]),
    ("54,20,26,-361,0.159", ["line 3, column 4 (phi_r_deg)", "azimuth"]),
])
def test_brdf_csv_angles_are_spherical_angles(row, words, tmp_path):
    """An angle of 1e308 deg (or 1e20 deg of azimuth) was read as a direction (accepted, run
    to a result); each is now refused naming the line and the column, not the value."""
    head = "theta_i_deg,phi_i_deg,theta_r_deg,phi_r_deg,brdf_per_sr\n10,0,10,180,0.159\n"
    scene = _table_scene(tmp_path, "t.csv", head + row + "\n")
    _one_line_refusal(tmp_path, scene, "t.csv", *words)
    ok = _table_scene(tmp_path, "ok.csv", head + "90,-360,180,360,0.159\n")  # the range ends are angles
    from brdfmodels.io import read_brdf_csv

    assert len(read_brdf_csv(tmp_path / "ok.csv")) == 2 and ok.exists()


@pytest.mark.parametrize("row, column", [("1e308,1.5,0.2,0.0,0.159", 1), ("0.5,7.0,0.2,0.0,0.159", 2),
                                         ("0.5,1.5,-0.01,0.0,0.159", 3), ("0.5,1.5,0.2,-1e300,0.159", 4)])
def test_astm_angles_are_spherical_angles(row, column, tmp_path):
    """theta_i = 1e308 rad passed the reader's cos > 0 filter at random (cos(1e308) > 0)."""
    text = "NUM_POINTS 2\nVARS theta_i,phi_i,theta_s,phi_s,brdf\n0.2,0.0,0.2,3.14159,0.159\n" + row + "\n"
    scene = _table_scene(tmp_path, "a.astm", text)
    _one_line_refusal(tmp_path, scene, "a.astm", f"line 4, column {column}: data row: expected")


def test_a_dem_of_three_bands_is_refused(tmp_path):
    """An RGB image (three bands) was read as a DEM from its first band, silently."""
    rasterio = pytest.importorskip("rasterio")
    pytest.importorskip("pyproj")
    import numpy as np
    from rasterio.transform import Affine

    from tests.scenes.test_dem_trust import GT, N, SCENE

    with rasterio.open(tmp_path / "rgb.tif", "w", driver="GTiff", width=N, height=N, count=3, dtype="uint8",
                       crs="EPSG:4326", transform=Affine.from_gdal(*GT)) as ds:
        ds.write(np.full((3, N, N), 200, dtype="uint8"))
    (tmp_path / "s.toml").write_text(SCENE.replace("FILE", "rgb.tif"))
    _one_line_refusal(tmp_path, tmp_path / "s.toml", "terrain.file='rgb.tif'", "expected one band of heights, got 3 band(s)")


def test_a_brdf_csv_column_named_twice_is_refused(tmp_path):
    """theta_i_deg twice: the first was read and the second ignored, silently."""
    text = "theta_i_deg,theta_i_deg,phi_i_deg,theta_r_deg,phi_r_deg,brdf_per_sr\n10,50,0,10,180,0.159\n"
    scene = _table_scene(tmp_path, "t.csv", text)
    _one_line_refusal(tmp_path, scene, "t.csv", "line 1: column theta_i_deg appears 2 times; expected once")


def test_a_material_json_key_given_twice_is_refused(tmp_path):
    """json keeps the last of a repeated key: this file was read as reflectance 0.05."""
    from tests.fuzz._file_corpus import _with_material

    (tmp_path / "m.json").write_text('{"format": "brdfmodels.model", "version": 1, "model": {"type": "lambertian", '
                                     '"params": {"reflectance": 0.5, "reflectance": 0.05}}}')
    (tmp_path / "s.toml").write_text(_with_material('material = { file = "m.json" }'))
    _one_line_refusal(tmp_path, tmp_path / "s.toml", "targets[0].material", "m.json", "a key is given twice in one object")


@pytest.mark.parametrize("model, words", [
    ({"type": "zq9SECRETzq9", "params": {}}, ["model=(a string of the file) is unknown: expected one of"]),
    ({"type": "lambertian", "params": {"reflectance": 0.5, "zq9SECRETzq9": 1}},
     ["lambertian: unknown parameters [(a string of the file)]; expected some of ['reflectance']"]),
    ({"type": "lambertian", "params": {}, "zq9SECRETzq9": 1}, ["model: unknown keys [(a string of the file)]"]),
])
def test_a_material_json_is_not_quoted(model, words, tmp_path):
    """The model's type, its unknown keys and parameters were quoted from the file."""
    import json

    from tests.fuzz._file_corpus import _with_material

    (tmp_path / "m.json").write_text(json.dumps({"format": "brdfmodels.model", "version": 1, "model": model}))
    (tmp_path / "s.toml").write_text(_with_material('material = { file = "m.json" }'))
    _one_line_refusal(tmp_path, tmp_path / "s.toml", "file='m.json'", *words)
    (tmp_path / "m.json").write_text(json.dumps({"format": "brdfmodels.model", "version": 1, "model": model,
                                                 "zq9SECRETzq9": 1}))
    _one_line_refusal(tmp_path, tmp_path / "s.toml", "1 unknown key(s) in model file")


def test_bsdf_angles_past_their_count_are_refused(tmp_path):
    """AngleOfIncidence 2 over "10 30" and then "50": the third angle was dropped silently."""
    from tests.fuzz.test_input_trust import _bsdf

    text = _bsdf(aoi="10 30").replace("AngleOfIncidence 2\n10 30\n", "AngleOfIncidence 2\n10 30\n50\n")
    scene = _table_scene(tmp_path, "a.bsdf", text)
    _one_line_refusal(tmp_path, scene, "a.bsdf", "line 9: numbers outside a keyword's list")


@pytest.mark.parametrize("tis, words", [("nan", "TIS: expected a finite total integrated scatter >= 0"),
                                        ("inf", "TIS: expected a finite"), ("-0.5", "TIS: expected a finite"),
                                        (SECRET, "line 14, column 2: TIS: expected a number")])
def test_a_bsdf_tis_is_a_number(tis, words, tmp_path):
    """TIS nan / inf / a word was accepted (the value is not used: the file was nonsense all the same)."""
    from tests.fuzz.test_input_trust import _bsdf

    scene = _table_scene(tmp_path, "a.bsdf", _bsdf().replace("TIS 0.5", f"TIS {tis}", 1))
    _one_line_refusal(tmp_path, scene, "a.bsdf", words)


def test_a_dted_column_record_out_of_place_is_refused(tmp_path):
    """A DTED level-0 column record (3428 header bytes, then per column 8 + 121 x 2 + 4 bytes)
    whose longitude count is zeroed: GDAL logged a warning and read on (accepted, as heights)."""
    pytest.importorskip("rasterio")
    pytest.importorskip("pyproj")
    from tests.fuzz._file_corpus import _argv, _cli
    from tests.scenes.test_dem_formats import SCENE, _dted

    _dted(tmp_path / "n32_w107.dt0")
    (tmp_path / "s.toml").write_text(SCENE)
    assert _cli(_argv("validate", tmp_path, tmp_path / "s.toml"))[0] == 0  # intact: read
    data = bytearray((tmp_path / "n32_w107.dt0").read_bytes())
    at = 3428 + 60 * 254  # column 60 (lon -106.5), inside the analysis area
    assert data[at] == 0xAA and int.from_bytes(data[at + 4:at + 6], "big") == 60  # the record's sentinel and count
    data[at + 4:at + 6] = b"\0\0"
    (tmp_path / "n32_w107.dt0").write_bytes(bytes(data))
    # the count is under the column's checksum too, which is now verified first (GDAL: read error)
    _one_line_refusal(tmp_path, tmp_path / "s.toml", "terrain.file='n32_w107.dt0'", "damaged", "checksums match")


def test_a_dted_column_with_a_zeroed_block_is_refused(tmp_path):
    """Column 60's record intact (sentinel, counts) but 20 of its heights zeroed: GDAL's
    default read them as 0 m terrain, a hole 1000 m deep (accepted in the file fuzz, seeds
    zero_block 1, 3, 17); the column's checksum no longer matches and is now verified."""
    rasterio = pytest.importorskip("rasterio")
    pytest.importorskip("pyproj")
    from tests.scenes.test_dem_formats import SCENE, _dted

    _dted(tmp_path / "n32_w107.dt0")
    (tmp_path / "s.toml").write_text(SCENE)
    data = bytearray((tmp_path / "n32_w107.dt0").read_bytes())
    at = 3428 + 60 * 254  # column 60 (lon -106.5), inside the analysis area: 8 header bytes, 121 x 2 height bytes, checksum
    assert data[at] == 0xAA and int.from_bytes(data[at + 4:at + 6], "big") == 60
    heights = [int.from_bytes(data[at + 8 + 2 * k:at + 10 + 2 * k], "big") for k in range(121)]
    assert min(heights) >= 1000  # the tile's heights are 1000 to 2200 m: a zero is no height of it
    data[at + 8 + 2 * 50:at + 8 + 2 * 70] = bytes(40)
    (tmp_path / "n32_w107.dt0").write_bytes(bytes(data))
    with rasterio.Env(DTED_VERIFY_CHECKSUM="NO"), rasterio.open(tmp_path / "n32_w107.dt0") as ds:
        assert (ds.read(1)[:, 60] == 0).sum() == 20  # what was read as terrain before
    _one_line_refusal(tmp_path, tmp_path / "s.toml", "terrain.file='n32_w107.dt0'", "cannot read the DEM's cells",
                      "checksums")


@pytest.mark.parametrize("change, words", [
    (("ScatterType  BRDF\n", "ScattebType  BRDF\n"), "line 4: not a keyword of the .bsdf header; expected one of Source"),
    (("ScatterType  BRDF\n", ""), "the header has no ScatterType line; expected ScatterType BRDF"),
    (("SpectralContent  Monochrome\n", "Spect\0ralContent  Monochrome\n"), "line 3: not a keyword"),
    (("SpectralContent  Monochrome\n", ""), "the header has no SpectralContent line"),
    (("Symmetry  PlaneSymmetrical\n", "Symmetry  PlaneSymmetrical\nSymmetry  Asymmetrical\n"),
     "line 3: Symmetry is given a second time (first on line 2); expected each header keyword once"),
    (("Source  Measured\n", "Source  Measured\nSource  Measured\n"), "line 2: Source is given a second time"),
    (("DataEnd\n", ""), "the file ends after the last block without DataEnd (truncated?)"),
    (("DataEnd\n", "DataEnd\nTIS 0.5\n0.1 0.1\n0.1 0.1\nDataEnd\n"), "line 21, column 1: data after DataEnd"),
    (("DataEnd\n", "DataEnd\nDataEnd\n"), "line 21, column 1: data after DataEnd"),
], ids=["misspelled ScatterType", "no ScatterType", "a NUL in SpectralContent", "no SpectralContent", "Symmetry twice",
        "Source twice", "no DataEnd", "a block after DataEnd", "DataEnd twice"])
def test_a_bsdf_header_is_the_formats_and_the_file_ends_at_dataend(change, words, tmp_path):
    """Accepted in the whole-corpus file fuzz (bsdf: flip #17, nul #4/#8/#15, dup_line #8/#11/#13/#15,
    del_line #9): a damaged or missing ScatterType line was skipped and BRDF assumed (a BTDF,
    transmission, file whose line was lost would be read as reflection), a keyword given twice
    kept the last, a file cut at a block's end or with blocks after DataEnd was read as
    whole. Each is refused naming the line, never quoting it."""
    from tests.fuzz.test_input_trust import _bsdf

    text = _bsdf(aoi="10 30", value="0.16")
    assert change[0] in text
    scene = _table_scene(tmp_path, "a.bsdf", text.replace(change[0], change[1], 1))
    _one_line_refusal(tmp_path, scene, "a.bsdf", words)
    ok = _table_scene(tmp_path, "ok.bsdf", "# a comment\n" + text.replace("DataBegin", "Monochrome\nDataBegin"))
    from brdfmodels.io import read_bsdf

    assert len(read_bsdf(tmp_path / "ok.bsdf")) > 0 and ok.exists()  # comments and the channel line are the format's


def test_a_history_cut_short_says_its_end_states_are_held(tmp_path):
    """Accepted silently in the whole-corpus file fuzz (history_csv truncate #10): h.csv cut
    after "4,0" (of 4,0.8 and 10,0.6) held a reflectance factor 0 from 4 to 10 s with
    extrapolation = 'clamp': a quieter plate, unsaid. Now a warning in the stdout answer
    and report.json; the same file covering the analysis gives none."""
    import json

    from tests.fuzz._file_corpus import HISTORY, MATERIAL, _argv, _cli, _with_material

    (tmp_path / "s.toml").write_text(_with_material(MATERIAL + HISTORY))
    warning = "targets[0].history: the series covers [0, 4] s of the analysis' [0, 10] s; its end states are held " \
              "(extrapolation = 'clamp') for 6 s"
    for content, warned in ((b"time_s,reflectance_factor\n0,1\n4,0", True),
                            (b"time_s,reflectance_factor\n0,1\n4,0.8\n10,0.6\n", False)):
        (tmp_path / "h.csv").write_bytes(content)
        code, out, err, raw = _cli(_argv("run", tmp_path, tmp_path / "s.toml"))
        assert code == 0 and not raw, err
        doc = json.loads((tmp_path / "out_run" / "report.json").read_text())
        assert (warning in doc["warnings"]) == warned and (warning in out + err) == warned, (doc["warnings"], out)


def test_a_byte_order_mark_is_no_content(tmp_path):
    """A UTF-8 byte-order mark (Excel's "CSV UTF-8") made the first keyword or column name
    another word: a .bsdf with one was refused ("not a keyword"), a history CSV "missing
    time_s". Each is now read as the same file without it."""
    import json

    from brdfmodels.io import read_bsdf
    from tests.fuzz._file_corpus import HISTORY, MATERIAL, _argv, _cli, _with_material
    from tests.fuzz.test_input_trust import _bsdf

    text = _bsdf(aoi="10 30", value="0.16")
    (tmp_path / "a.bsdf").write_text(text)
    (tmp_path / "b.bsdf").write_bytes(b"\xef\xbb\xbf" + text.encode())
    plain, marked = read_bsdf(tmp_path / "a.bsdf"), read_bsdf(tmp_path / "b.bsdf")
    assert len(plain) == len(marked) > 0 and (plain.brdf_per_sr == marked.brdf_per_sr).all()
    (tmp_path / "s.toml").write_text(_with_material(MATERIAL + HISTORY))
    reports = []
    for bom in (b"", b"\xef\xbb\xbf"):
        (tmp_path / "h.csv").write_bytes(bom + b"time_s,reflectance_factor\n0,1\n4,0.8\n10,0.6\n")
        code, out, err, raw = _cli(_argv("run", tmp_path, tmp_path / "s.toml"))
        assert code == 0 and not raw, err
        reports.append(json.loads((tmp_path / "out_run" / "report.json").read_text())["observers"])
    assert reports[0] == reports[1]


@pytest.mark.parametrize("change, words", [
    (("VARS theta_i,phi_i,theta_s,phi_s,brdf", "VARS zq9SECRETzq9,phi_i,theta_s,phi_s,brdf"),
     "line 2: VARS: expected the angle columns theta_i, phi_i, theta_s, phi_s first"),
    (("VARS theta_i,phi_i,theta_s,phi_s,brdf", "VARS phi_i,theta_i,theta_s,phi_s,brdf"), "line 2: VARS: expected the angle"),
    (("VARS theta_i,phi_i,theta_s,phi_s,brdf\n", "VARS theta_i,phi_i,theta_s,phi_s,brdf\nVARS theta_i,phi_i,theta_s,phi_s,brdf\n"),
     "line 3: VARS is given a second time (first on line 2); expected it once"),
    (("NUM_POINTS 2\n", "NUM_POINTS 2\nNUM_POINTS 3\n"), "line 2: NUM_POINTS is given a second time"),
    (("NUM_POINTS 2\n", "zq9SECRETzq9 2\n"), "line 1: not a header keyword or a data row"),
    (("0.2,0.0,0.2,3.14159,0.159", "nan,0.0,0.2,3.14159,0.159"), "line 3: not a header keyword or a data row"),
], ids=["an angle renamed", "angles swapped", "VARS twice", "NUM_POINTS twice", "a damaged NUM_POINTS", "a NaN row"])
def test_an_astm_header_is_checked_not_skipped(change, words, tmp_path):
    """Accepted in the whole-corpus file fuzz (astm: string #1/#3, flip #19, dup_line #5): the
    four angle columns were read by position whatever VARS named them (phi_i before theta_i
    read azimuths as polar angles), a second VARS line was read over the first, and a line
    that was neither a keyword nor a number (a damaged NUM_POINTS, a row starting with nan)
    was skipped, its check or data with it."""
    text = "NUM_POINTS 2\nVARS theta_i,phi_i,theta_s,phi_s,brdf\n0.2,0.0,0.2,3.14159,0.159\n0.3,0.0,0.3,3.14159,0.159\n"
    assert change[0] in text
    scene = _table_scene(tmp_path, "a.astm", text.replace(change[0], change[1], 1))
    _one_line_refusal(tmp_path, scene, "a.astm", words)
    from brdfmodels.io import read_astm_e1392

    (tmp_path / "ok.astm").write_text("# a comment\n" + text)
    assert len(read_astm_e1392(tmp_path / "ok.astm")) > 0
