"""Every column of a measured file is used or refused: a wavelength column selects the
laser's rows (or interpolates the two nearest, with a note; refused when ambiguous), state
columns go into the samples' states, an unknown column is an error naming its position
(or skipped when listed in ``ignore_columns``); ASTM files with several value columns are
refused unless named by their wavelengths (``532nm, 1064nm``), which select the laser's as
the CSV's column does, and so does ``hazard fit --wavelength-nm``; one-sided data are mirrored when declared plane-symmetric. Files written here
from values typed in here."""

from __future__ import annotations

import math
import re

import numpy as np
import pytest

import brdfmodels as bm
import scenes
from brdfmodels.io import read_astm_e1392, read_brdf_csv, read_samples
from tests._scene_text import PLATE_AT_50M

HEAD = "theta_i_deg,phi_i_deg,theta_r_deg,phi_r_deg"


def _rows(extra=lambda k: []):
    """(theta_i, phi_i, theta_r, phi_r) rows and f_r = 0.1 + 0.001 k [1/sr] for row k."""
    angles = [(ti, 0, tr, pr) for ti in (10, 30) for tr in (10, 40) for pr in (0, 90, 180)]
    return [list(a) + [0.1 + 0.001 * k] + extra(k) for k, a in enumerate(angles)]


def _csv(tmp_path, header, rows, name="m.csv"):
    (tmp_path / name).write_text(header + "\n" + "\n".join(",".join(repr(x) if isinstance(x, float) else str(x) for x in r)
                                                          for r in rows) + "\n")
    return tmp_path / name


def _two_wavelengths(tmp_path):
    """The same angles at 532 nm (f 1/50 of the 1064 nm value) and at 1064 nm."""
    rows = [r + [1064] for r in _rows()] + [r[:4] + [r[4] / 50, 532] for r in _rows()]
    return _csv(tmp_path, HEAD + ",brdf_per_sr,wavelength_nm", rows), np.array([r[4] for r in _rows()])


def test_a_wavelength_column_selects_the_lasers_rows(tmp_path):
    path, f1064 = _two_wavelengths(tmp_path)
    with pytest.raises(ValueError, match=r"holds 2 wavelengths \(532, 1064 nm\); which one is ambiguous"):
        read_brdf_csv(path)
    s = read_brdf_csv(path, wavelength_nm=1064.2)
    np.testing.assert_allclose(s.brdf_per_sr, f1064, rtol=1e-15)
    np.testing.assert_allclose(read_brdf_csv(path, wavelength_nm=532).brdf_per_sr, f1064 / 50, rtol=1e-15)
    assert not any("nm" in n for n in s.info["notes"])  # no wavelength note (the rows are one-sided: that note only)


def test_between_two_wavelengths_the_rows_are_interpolated_with_a_note(tmp_path):
    path, f1064 = _two_wavelengths(tmp_path)
    t = (800.0 - 532.0) / (1064.0 - 532.0)
    s = read_brdf_csv(path, wavelength_nm=800.0)
    np.testing.assert_allclose(s.brdf_per_sr, (1 - t) * f1064 / 50 + t * f1064, rtol=1e-12)
    assert "interpolated linearly between the measured 532 and 1064 nm to the laser's 800 nm" in s.info["notes"][0]
    with pytest.raises(ValueError, match="1550 nm is outside the measured wavelengths"):
        read_brdf_csv(path, wavelength_nm=1550.0)


def test_a_scene_reads_the_rows_at_its_lasers_wavelength(tmp_path):
    """The issue's case: 532 and 1064 nm rows 50x apart were read as one set. The scene's
    1064 nm laser takes the 1064 nm rows: the table returns them at their directions."""
    path, f1064 = _two_wavelengths(tmp_path)
    (tmp_path / "s.toml").write_text(PLATE_AT_50M.replace('{ model = "lambertian", reflectance = 0.5 }',
                                                          '{ model = "table", file = "m.csv" }'))
    m = scenes.load(tmp_path / "s.toml").targets[0].material
    rows = np.array([r[:4] for r in _rows()], float)
    wi = bm.spherical_to_vector(np.radians(rows[:, 0]), np.radians(rows[:, 1]))
    wo = bm.spherical_to_vector(np.radians(rows[:, 2]), np.radians(rows[:, 3]))
    np.testing.assert_allclose(m.evaluate(wi, wo), f1064, rtol=1e-7)
    (tmp_path / "s.toml").write_text((tmp_path / "s.toml").read_text().replace("wavelength_nm = 1064.0", "wavelength_nm = 800.0"))
    sc = scenes.load(tmp_path / "s.toml")
    assert any("interpolated linearly between the measured 532 and 1064 nm" in w for w in sc.warnings)


def test_state_columns_go_into_the_samples_states(tmp_path):
    rows = _rows(lambda k: [0.1 * k, 0.5, 300 + k, 7.0])
    path = _csv(tmp_path, HEAD + ",brdf_per_sr,extinction,melt_fraction,temperature_k,state_oxide_um", rows)
    s = read_brdf_csv(path)
    assert sorted(s.states) == ["extinction", "melt_fraction", "oxide_um"]
    np.testing.assert_array_equal(s.states["extinction"], [0.1 * k for k in range(len(rows))])
    np.testing.assert_array_equal(s.states["oxide_um"], 7.0)
    np.testing.assert_array_equal(s.temperature_k, [300 + k for k in range(len(rows))])


def test_an_unknown_column_is_refused_by_position_unless_ignored(tmp_path):
    path = _csv(tmp_path, HEAD + ",brdf_per_sr,operator_notes", _rows(lambda k: [3]))
    with pytest.raises(ValueError, match=r"line 1, column 6: not a column this reader uses.*ignore_columns"):
        read_brdf_csv(path)
    s = read_brdf_csv(path, ignore_columns=["operator_notes"])
    assert len(s) == 12 and s.states == {}
    with pytest.raises(ValueError, match="ignore_columns: theta_r_deg is a column this reader needs"):
        read_brdf_csv(path, ignore_columns=["operator_notes", "theta_r_deg"])
    text = PLATE_AT_50M.replace('{ model = "lambertian", reflectance = 0.5 }', '{ model = "table", file = "m.csv" }')
    (tmp_path / "s.toml").write_text(text)
    with pytest.raises(scenes.SceneError, match="column 6: not a column"):
        scenes.load(tmp_path / "s.toml")
    (tmp_path / "s.toml").write_text(text.replace('file = "m.csv"', 'file = "m.csv", ignore_columns = ["operator_notes"]'))
    assert isinstance(scenes.load(tmp_path / "s.toml").targets[0].material, bm.ScatteredBRDF)


def test_an_astm_file_with_several_value_columns_is_refused_unless_the_others_are_ignored(tmp_path):
    rows = [[math.radians(r[0]), 0.0, math.radians(r[2]), math.radians(r[3]), r[4], 2 * r[4]] for r in _rows()]
    text = f"NUM_POINTS {len(rows)}\nVARS theta_i, phi_i, theta_s, phi_s, brdf_s, brdf_p\n"
    (tmp_path / "m.astm").write_text(text + "\n".join(", ".join(repr(float(x)) for x in r) for r in rows) + "\n")
    with pytest.raises(ValueError, match="VARS: expected five names used.*several value columns are refused"):
        read_astm_e1392(tmp_path / "m.astm")
    with pytest.raises(ValueError, match="ignore_columns names one of the four angle columns"):
        read_astm_e1392(tmp_path / "m.astm", ignore_columns=["phi_i", "brdf_p"])
    s = read_astm_e1392(tmp_path / "m.astm", ignore_columns=["brdf_p"])
    np.testing.assert_allclose(s.brdf_per_sr, [r[4] for r in rows], rtol=1e-15)


def test_one_sided_data_declared_plane_symmetric_are_mirrored(tmp_path):
    """phi_r 0 to 180 deg measured at phi_i = 0 and phi_i = 40 deg: with symmetry = "plane"
    each sample's mirror image about its plane of incidence (phi_r -> 2 phi_i - phi_r) is
    added, with its value."""
    rows = [[ti, pi, tr, pr, 0.2 + 0.001 * (tr + pr)] for ti in (20, 50) for pi in (0, 40) for tr in (10, 60) for pr in (30, 120)]
    path = _csv(tmp_path, HEAD + ",brdf_per_sr", rows)
    assert len(read_brdf_csv(path)) == len(rows)
    assert read_brdf_csv(path).info["notes"] == []  # phi_i 40 deg, phi_r 30 deg: the other side of that plane
    half = _csv(tmp_path, HEAD + ",brdf_per_sr", [r for r in rows if r[1] == 0], name="half.csv")
    one_sided = read_brdf_csv(half)  # undeclared: read as measured, and said
    assert any("all 8 samples off their plane of incidence lie on one side of it" in n for n in one_sided.info["notes"])
    assert read_brdf_csv(half, symmetry="none").info["notes"] == []  # declared not symmetric: nothing to say
    s = read_samples(path, symmetry="plane")
    assert len(s) == 2 * len(rows)
    want = {tuple(np.round(np.r_[bm.spherical_to_vector(math.radians(a), math.radians(b)),
                                  bm.spherical_to_vector(math.radians(c), math.radians(2 * b - d))], 9)): v
            for a, b, c, d, v in rows}
    got = {tuple(np.round(np.r_[x, y], 9)): v for x, y, v in zip(s.wi, s.wo, s.brdf_per_sr)}
    assert all(got.get(k) == v for k, v in want.items())
    with pytest.raises(ValueError, match="symmetry and ignore_columns are for CSV and ASTM files"):
        read_samples(tmp_path / "x.bsdf", symmetry="plane")


def test_a_table_brighter_than_its_light_is_refused_beyond_its_stated_uncertainty(tmp_path):
    """A constant f_r has hemispherical reflectance pi f_r (the projected hemisphere's
    solid angle is pi): 0.33 /sr gives 1.037, within the default tolerance 0.05, and loads;
    0.35 /sr gives 1.100 and is refused, naming the incidence and the value; a stated
    uncertainty of 0.2 (``dhr_tolerance``) accepts it."""
    angles = [(ti, 0, tr, pr) for ti in range(0, 81, 10) for tr in range(0, 90, 10) for pr in range(0, 360, 30)]
    text = PLATE_AT_50M.replace('{ model = "lambertian", reflectance = 0.5 }', '{ model = "table", file = "m.csv"MORE }')
    for value, more, refused in ((0.33, "", False), (0.35, "", True), (0.35, ", dhr_tolerance = 0.2", False)):
        _csv(tmp_path, HEAD + ",brdf_per_sr", [list(a) + [value] for a in angles])
        (tmp_path / "s.toml").write_text(text.replace("MORE", more))
        if refused:
            with pytest.raises(scenes.SceneError, match=r"hemispherical reflectance 1\.1 > 1 at 0 deg incidence \(beyond the "
                                                        r"tolerance 0\.05\)"):
                scenes.load(tmp_path / "s.toml")
        else:
            assert isinstance(scenes.load(tmp_path / "s.toml").targets[0].material, bm.ScatteredBRDF)


def test_a_table_of_several_states_says_so_in_the_scene(tmp_path):
    rows = _rows(lambda k: [0.1 * (k % 2)])
    _csv(tmp_path, HEAD + ",brdf_per_sr,extinction", rows)
    (tmp_path / "s.toml").write_text(PLATE_AT_50M.replace('{ model = "lambertian", reflectance = 0.5 }',
                                                          '{ model = "table", file = "m.csv" }'))
    sc = scenes.load(tmp_path / "s.toml")
    assert any("span several values of extinction; the static table holds them together" in w for w in sc.warnings)


def test_a_table_key_that_would_do_nothing_is_refused(tmp_path):
    _csv(tmp_path, HEAD + ",brdf_per_sr", _rows())
    text = PLATE_AT_50M.replace('{ model = "lambertian", reflectance = 0.5 }', '{ model = "table", file = "m.csv"MORE }')
    for more, words in ((", dhr_tolerance = 0.2, grid_deg = [5.0, 5.0, 30.0]", "dhr_tolerance: applies to a scattered table"),
                        (', symmetry = "sideways"', "symmetry='sideways': expected 'plane'")):
        (tmp_path / "s.toml").write_text(text.replace("MORE", more))
        with pytest.raises(scenes.SceneError, match=words):
            scenes.load(tmp_path / "s.toml")


def _astm(tmp_path, names, rows, name="m.astm"):
    text = f"NUM_POINTS {len(rows)}\nVARS theta_i, phi_i, theta_s, phi_s, {', '.join(names)}\n"
    (tmp_path / name).write_text(text + "\n".join(", ".join(repr(float(x)) for x in r) for r in rows) + "\n")
    return tmp_path / name


def _astm_rows(*columns):
    """ASTM rows (angles in radians) of :func:`_rows`, then f(k) of each of ``columns`` for row k."""
    return [[math.radians(r[0]), 0.0, math.radians(r[2]), math.radians(r[3])] + [c(r[4]) for c in columns] for r in _rows()]


def test_an_astm_file_with_value_columns_named_by_wavelength_selects_the_lasers(tmp_path):
    """libbsdf's convention: value columns named ``532nm, 1064nm``. The laser's column is
    taken (within 0.5 nm), the two nearest interpolated between with a note, none taken
    outside them or when no wavelength is given."""
    f = np.array([r[4] for r in _rows()])
    path = _astm(tmp_path, ["532nm", "1064nm"], _astm_rows(lambda v: v / 50, lambda v: v))
    np.testing.assert_allclose(read_astm_e1392(path, wavelength_nm=1064.3).brdf_per_sr, f, rtol=1e-15)
    np.testing.assert_allclose(read_samples(path, wavelength_nm=532.0).brdf_per_sr, f / 50, rtol=1e-15)
    t = (800.0 - 532.0) / (1064.0 - 532.0)
    s = read_astm_e1392(path, wavelength_nm=800.0)
    np.testing.assert_allclose(s.brdf_per_sr, (1 - t) * f / 50 + t * f, rtol=1e-12)
    assert "interpolated linearly between the measured 532 and 1064 nm to the laser's 800 nm" in s.info["notes"][0]
    with pytest.raises(ValueError, match=r"holds 2 wavelengths \(532, 1064 nm\); which one is ambiguous"):
        read_astm_e1392(path)
    with pytest.raises(ValueError, match=r"the laser's 1550 nm is outside the measured wavelengths \(532, 1064 nm\)"):
        read_astm_e1392(path, wavelength_nm=1550.0)
    one = _astm(tmp_path, ["brdf_532nm"], _astm_rows(lambda v: v), name="one.astm")
    np.testing.assert_allclose(read_astm_e1392(one).brdf_per_sr, f, rtol=1e-15)  # one column: no choice to make
    with pytest.raises(ValueError, match=r"the laser's 1064 nm is outside the measured wavelengths \(532 nm\)"):
        read_astm_e1392(one, wavelength_nm=1064.0)
    mixed = _astm(tmp_path, ["532nm", "brdf_p"], _astm_rows(lambda v: v, lambda v: v), name="mixed.astm")
    with pytest.raises(ValueError, match="several value columns are refused unless named by their wavelengths"):
        read_astm_e1392(mixed, wavelength_nm=532.0)


def test_an_astm_file_with_a_wavelength_column_of_the_rows_selects_the_lasers_rows(tmp_path):
    """A ``wavelength_nm`` VARS column: the rows at the laser's wavelength, as the CSV's
    column (the same angles at two wavelengths are not duplicates)."""
    f = np.array([r[4] for r in _rows()])
    rows = [r + [1064.0] for r in _astm_rows(lambda v: v)] + [r + [532.0] for r in _astm_rows(lambda v: v / 50)]
    path = _astm(tmp_path, ["brdf", "wavelength_nm"], rows)
    np.testing.assert_allclose(read_astm_e1392(path, wavelength_nm=1064.0).brdf_per_sr, f, rtol=1e-15)
    np.testing.assert_allclose(read_astm_e1392(path, wavelength_nm=532.0).brdf_per_sr, f / 50, rtol=1e-15)
    with pytest.raises(ValueError, match=r"holds 2 wavelengths \(532, 1064 nm\); which one is ambiguous"):
        read_astm_e1392(path)


def test_a_scene_takes_the_astm_column_at_its_lasers_wavelength(tmp_path):
    f = np.array([r[4] for r in _rows()])
    _astm(tmp_path, ["532nm", "1064nm"], _astm_rows(lambda v: v / 50, lambda v: v))
    (tmp_path / "s.toml").write_text(PLATE_AT_50M.replace('{ model = "lambertian", reflectance = 0.5 }',
                                                          '{ model = "table", file = "m.astm" }'))
    m = scenes.load(tmp_path / "s.toml").targets[0].material
    rows = np.array([r[:4] for r in _rows()], float)
    wi = bm.spherical_to_vector(np.radians(rows[:, 0]), np.radians(rows[:, 1]))
    wo = bm.spherical_to_vector(np.radians(rows[:, 2]), np.radians(rows[:, 3]))
    np.testing.assert_allclose(m.evaluate(wi, wo), f, rtol=1e-7)


def _abg_csv_two_wavelengths(tmp_path):
    """ABg (Harvey, direction cosines: A / (B + |beta - beta0|^g)) at 1064 nm (A 0.0025,
    B 0.001, g 1.8) and at 532 nm (A 0.004, B 0.002, g 1.5), written from the formula at
    the same angles, with a wavelength_nm column."""
    ang = [(ti, 0, tr, pr) for ti in (0, 20, 40) for tr in (0, 2, 5, 10, 20, 30, 45, 60) for pr in range(0, 360, 30)]
    rows = []
    for lam, (a, b, g) in ((1064, (0.0025, 0.001, 1.8)), (532, (0.004, 0.002, 1.5))):
        for ti, pi, tr, pr in ang:
            wi = bm.spherical_to_vector(math.radians(ti), math.radians(pi))
            wo = bm.spherical_to_vector(math.radians(tr), math.radians(pr))
            x = math.hypot(wo[0] + wi[0], wo[1] + wi[1])
            rows.append([ti, pi, tr, pr, a / (b + x ** g), lam])
    return _csv(tmp_path, HEAD + ",brdf_per_sr,wavelength_nm", rows)


@pytest.mark.parametrize("lam, want", [(1064, (0.0025, 1.8)), (532, (0.004, 1.5))])
def test_hazard_fit_takes_the_rows_at_its_wavelength(tmp_path, lam, want):
    import io
    import json

    from hazard.cli import main

    path = _abg_csv_two_wavelengths(tmp_path)
    out = io.StringIO()
    argv = ["fit", "abg", str(path), "-o", str(tmp_path / "m.json"), "--json", "--quiet", "--wavelength-nm", str(lam)]
    assert main(argv, stdout=out, stderr=io.StringIO()) == 0
    row = json.loads(out.getvalue())["rows"][0]
    assert row["p_a"] == pytest.approx(want[0], rel=1e-6) and row["p_g"] == pytest.approx(want[1], rel=1e-6)


def test_hazard_fit_names_the_wavelengths_a_file_holds(tmp_path):
    import io

    from hazard.cli import main

    path = _abg_csv_two_wavelengths(tmp_path)
    for extra, words in (([], r"holds 2 wavelengths \(532, 1064 nm\); which one is ambiguous"),
                         (["--wavelength-nm", "1550"], r"the laser's 1550 nm is outside the measured wavelengths \(532, 1064 nm\)")):
        err = io.StringIO()
        assert main(["fit", "sh", str(path), "-o", str(tmp_path / "m.json")] + extra, stdout=io.StringIO(), stderr=err) == 2
        assert re.search(words, err.getvalue()) and err.getvalue().count("\n") == 1, err.getvalue()
    err = io.StringIO()
    assert main(["fit", "sh", str(path), "-o", str(tmp_path / "m.json"), "--quiet", "--wavelength-nm", "800"],
                stdout=io.StringIO(), stderr=err) == 0
    assert "note: m.csv: f_r interpolated linearly between the measured 532 and 1064 nm to the laser's 800 nm" in err.getvalue()


def test_hazard_fit_says_when_the_file_names_no_wavelength(tmp_path):
    import io

    from hazard.cli import main

    two = _abg_csv_two_wavelengths(tmp_path)
    lines = two.read_text().splitlines()
    one = tmp_path / "one.csv"  # the 1064 nm rows without their wavelength column
    one.write_text("\n".join([lines[0].rsplit(",", 1)[0]] + [r.rsplit(",", 1)[0] for r in lines[1:] if r.endswith(",1064")]) + "\n")
    for path, said in ((one, True), (two, False)):
        err = io.StringIO()
        argv = ["fit", "abg", str(path), "-o", str(tmp_path / f"{path.stem}.json"), "--quiet", "--wavelength-nm", "1064"]
        assert main(argv, stdout=io.StringIO(), stderr=err) == 0, err.getvalue()
        assert ("one.csv names no wavelength" in err.getvalue() and "--wavelength-nm 1064 is not checked" in err.getvalue()) == said
