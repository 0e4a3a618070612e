"""The observer table of a run: every observer in observers.csv, the verdict arrays
computed once (a 1e6-observer map was O(M^2) to write: each row recomputed the whole
hazard-ratio array), and report.json listing at most ``JSON_OBSERVERS_MAX`` observers,
the highest hazard ratios first, with a statement of which are listed."""

import csv
import io
import json

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import hazard
import scenes
from hazard.outputs import report

SCENE = """
name = "table"
[laser]
wavelength_nm = 1064.0
power_w = 100.0
beam_diameter_m = 0.005
divergence_rad = 0.001
position_m = [0.0, -50.0, 0.0]
aim_m = [0.0, 0.0, 0.0]
[exposure]
duration_s = 10.0
[[targets]]
name = "plate"
shape = "plate"
center_m = [0.0, 0.0, 0.0]
normal = [0.0, -1.0, 0.0]
tangent = [1.0, 0.0, 0.0]
size_m = [1.0, 1.0]
material = { model = "lambertian", reflectance = 0.9 }
[[observers]]
name = "field, west"
origin_m = [-3.0, -4.0, -1.0]
u_m = [6.0, 0.0, 0.0]
v_m = [0.0, -40.0, 2.0]
counts = [9, 21]
"""


@pytest.fixture(scope="module")
def result():
    return hazard.analyze(scenes.loads(SCENE))


def test_csv_has_every_observer_with_the_arrays_values(tmp_path, result):
    report.write_outputs(result, tmp_path / "o")
    with open(tmp_path / "o" / "observers.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == len(result.observers) >= 9 * 21  # the grid, and any crossing point added between its points
    assert rows[0]["name"] == "field, west[0]"  # a name with a comma comes back whole
    ratio = np.array([float(r["hazard_ratio"]) for r in rows])
    np.testing.assert_array_equal(ratio, result.hazard_ratio)  # repr: exact round trip
    np.testing.assert_array_equal([r["hazardous"] == "True" for r in rows], result.hazardous)
    x = np.array([[float(r[k]) for k in ("x_m", "y_m", "z_m")] for r in rows])
    np.testing.assert_array_equal(x, result.observers.position_m)
    assert all(r["first_exceedance_s"] == "" for r, h in zip(rows, result.hazardous) if not h)
    assert result.hazardous.any() and not result.hazardous.all()  # the test means something


def test_json_lists_all_observers_below_the_limit(tmp_path, result):
    doc = report.report_dict(result)
    assert len(doc["observers"]) == len(result.observers)
    m = len(result.observers)
    assert doc["observers_listed"] == {"count": m, "listed": m, "which": "all"}


def test_json_lists_the_highest_ratios_above_the_limit_and_says_so(monkeypatch, tmp_path, result):
    monkeypatch.setattr(report, "JSON_OBSERVERS_MAX", 10)
    report.write_outputs(result, tmp_path / "o")
    doc = json.loads((tmp_path / "o" / "report.json").read_text())
    listed = doc["observers"]
    m = len(result.observers)
    assert len(listed) == 10 and doc["observers_listed"]["listed"] == 10 and doc["observers_listed"]["count"] == m
    assert f"all {m} are in observers.csv" in doc["observers_listed"]["which"]
    top = np.sort(result.hazard_ratio)[::-1][:10]
    np.testing.assert_allclose(sorted((o["hazard_ratio"] for o in listed), reverse=True), top)
    names = [o["name"] for o in listed]
    order = [result.observers.labels.index(n) for n in names]
    assert order == sorted(order)  # in the scene's order
    with open(tmp_path / "o" / "observers.csv", newline="") as fh:
        assert len(list(csv.DictReader(fh))) == m  # the table still has every observer


def test_a_target_the_beam_misses_is_said_to_get_only_its_wing(tmp_path):
    """A plate whose near edge is 0.15 m off the axis of a beam of 1/e radius 27.5 mm at
    50 m sees at most exp(-(0.15 / 0.0275)^2) ~ 1e-13 of the beam's on-axis irradiance:
    report.json says "wing only" and the answer says the beam misses it (it read as an
    ordinary lit target). A beam far wider than its target, or thick air, is still
    "beam": the profile, not the power, decides."""
    text = SCENE.replace("center_m = [0.0, 0.0, 0.0]", "center_m = [0.65, 0.0, 0.0]")
    res = hazard.analyze(scenes.loads(text))
    doc = report.report_dict(res)
    frac = res.targets[0].beam_profile_fraction  # exp(-(0.15 / 0.0275)^2) = 1.2e-13 at the plate's near edge
    assert frac == pytest.approx(np.exp(-(0.15 / 0.0275) ** 2), rel=0.05) and doc["targets"][0]["hit"] == "wing only"
    assert "the beam misses it; only its Gaussian wing reaches it" in report.answer_text(res)
    assert report.report_dict(hazard.analyze(scenes.loads(SCENE)))["targets"][0]["hit"] == "beam"
    thick = SCENE.replace("[exposure]", "[exposure]\n").replace("[[targets]]", "[atmosphere]\nattenuation_per_m = 10.0\n[[targets]]")
    assert report.report_dict(hazard.analyze(scenes.loads(thick)))["targets"][0]["hit"] == "beam"  # e^-500 of air, on axis
    far = SCENE.replace("position_m = [0.0, -50.0, 0.0]", "position_m = [0.0, -1e8, 0.0]")
    assert report.report_dict(hazard.analyze(scenes.loads(far)))["targets"][0]["hit"] == "beam"  # a 1e5 m beam on a 1 m plate


def _csv_module_text(result) -> bytes:
    """observers.csv written here with the csv module from the analysis's arrays: str() of
    each Python float (its repr), True/False, an empty cell where NaN means "not applicable"."""
    import io

    cols = report.observer_columns(result)
    blank = {"angular_subtense_rad", "first_exceedance_s", "aperture_diameter_m", "direct_point_irradiance_w_m2"}
    names = report.CSV_COLUMNS[4:]
    buf = io.StringIO()
    w = csv.writer(buf)  # QUOTE_MINIMAL, "\r\n": the format observers.csv promises
    w.writerow(report.CSV_COLUMNS)
    pos = np.asarray(cols["position_m"]).tolist()
    values = {k: np.asarray(cols[k]).tolist() for k in names}
    for i, label in enumerate(cols["labels"]):
        row = [label, *pos[i]]
        for k in names:
            v = values[k][i]
            row.append("" if (k in blank and v != v) else v)
        w.writerow(row)
    return buf.getvalue().encode()


def test_streamed_csv_is_the_csv_module_table_byte_for_byte(monkeypatch, tmp_path, result):
    """observers.csv is written in blocks of rows (issue 37 item 3). Without pyarrow (or
    where a name needs quotes, as "field, west" does here) the file equals the table the
    csv module writes from the arrays, whatever the block size."""
    expected = _csv_module_text(result)
    report.write_outputs(result, tmp_path / "o")
    assert (tmp_path / "o" / "observers.csv").read_bytes() == expected  # the comma in the name: Python's writer
    monkeypatch.setattr(report, "_arrow", lambda: None)  # as without pyarrow
    cols = report.observer_columns(result)
    for rows in (1, 2, 7, 10_000):
        assert b"".join(report._csv_chunks(result, cols, rows)) == expected
    monkeypatch.setattr(report, "CSV_JOIN_ROWS", 3)  # a block written 3 rows at a time
    for rows in (7, 10_000):
        assert b"".join(report._csv_chunks(result, cols, rows)) == expected


def _read_back_exact(data: bytes, result):
    """Check observers.csv's ``data`` against ``result``'s arrays: the header as the csv
    module writes the column names, every float cell the same double (bits: -0.0 is not
    0.0), an empty cell only where NaN means "not applicable", True/False, the names."""
    rows = list(csv.reader(io.StringIO(data.decode(), newline="")))
    cols = report.observer_columns(result)
    assert rows[0] == report.CSV_COLUMNS and len(rows) == len(result.observers) + 1
    assert [r[0] for r in rows[1:]] == list(cols["labels"])
    blank = {"angular_subtense_rad", "first_exceedance_s", "aperture_diameter_m", "direct_point_irradiance_w_m2"}
    pos = np.asarray(cols["position_m"])
    want = {"x_m": pos[:, 0], "y_m": pos[:, 1], "z_m": pos[:, 2], **{k: np.asarray(cols[k]) for k in report.CSV_COLUMNS[4:]}}
    for j, k in enumerate(report.CSV_COLUMNS[1:], start=1):
        cells = [r[j] for r in rows[1:]]
        if want[k].dtype == bool:
            assert cells == [str(x) for x in want[k].tolist()], k
            continue
        v = want[k].astype(float)
        if k in blank:
            assert [c == "" for c in cells] == np.isnan(v).tolist(), k
            cells = ["nan" if c == "" else c for c in cells]
        got = np.array([float(c) for c in cells])
        np.testing.assert_array_equal(got.view(np.int64)[~np.isnan(v)], v.view(np.int64)[~np.isnan(v)], err_msg=k)
        assert np.isnan(got).tolist() == np.isnan(v).tolist(), k


@pytest.mark.parametrize("writer", ["joined", "arrow"])
def test_csv_by_pyarrow_reads_back_every_number_exactly(tmp_path, monkeypatch, writer):
    """With pyarrow, the blocks are made column by column: with orjson its cells joined by
    pyarrow (``joined``), else pyarrow's CSV writer (``arrow``); both the shortest
    round-trip digits: the header unchanged, every number read back bit for bit, whatever
    the block size."""
    pytest.importorskip("pyarrow")
    if writer == "joined":
        pytest.importorskip("orjson")
    else:
        monkeypatch.setattr(report, "row_tools", lambda: None)
    ran = []

    def spy(name):
        fn = getattr(report, name)
        return lambda *a: (ran.append(name), fn(*a))[1]

    for name in ("_joined_block", "_arrow_block", "_repr_block"):
        monkeypatch.setattr(report, name, spy(name))
    res = hazard.analyze(scenes.loads(SCENE.replace('name = "field, west"', 'name = "field"')))
    report.write_outputs(res, tmp_path / "o")
    data = (tmp_path / "o" / "observers.csv").read_bytes()
    _read_back_exact(data, res)
    assert set(ran) == {f"_{writer}_block"}  # that writer made every block
    cols = report.observer_columns(res)
    for rows in (1, 2, 7, 10_000):
        assert b"".join(report._csv_chunks(res, cols, rows)) == data
    monkeypatch.setattr(report, "CSV_JOIN_ROWS", 3)  # a block's text joined (or written) in pieces of 3 rows
    for rows in (7, 10_000):
        assert b"".join(report._csv_chunks(res, cols, rows)) == data


def _bits_round_trip(bits, blank):
    """One column of float64 values given by their bits through pyarrow's block writer:
    each cell reads back as the same double (NaN: empty in a "not applicable" column)."""
    v = np.asarray(bits, np.uint64).view(np.float64)
    _column_round_trip(v, blank)
    _column_round_trip(np.repeat(v, 3), blank)  # repeated values: formatted once (a dictionary column)
    _column_round_trip(np.full(4, v[0]), blank)  # one value throughout (a constant column): formatted once, no hash


def _column_round_trip(v, blank):
    arrow = report._arrow()
    names = arrow[0].array([f"o[{i}]" for i in range(len(v))])
    key = "first_exceedance_s" if blank else "x"
    lines = bytes(report._arrow_block(arrow, names, [v, v > 0], [key, "hazardous"])).decode().split("\r\n")
    assert lines[-1] == "" and len(lines) == len(v) + 1
    for line, x in zip(lines, v.tolist()):
        name, cell, flag = line.split(",")
        assert flag == str(x > 0)
        if x != x:
            assert cell == ("" if blank else "nan")
        else:
            assert np.float64(float(cell)).view(np.uint64) == np.float64(x).view(np.uint64), (cell, x)


_SPECIAL = np.array([0.0, -0.0, np.inf, -np.inf, np.nan, -np.nan, 5e-324, -2.2250738585072014e-308, 1.7976931348623157e308,
                     1e16, 1e15, 1e-5, 1e-4, 0.1, 1.0 / 3.0, 123456789.0, 1e22, 1e21]).view(np.uint64).tolist()
_BITS = st.lists(st.one_of(st.integers(0, 2**64 - 1), st.sampled_from(_SPECIAL)), min_size=1, max_size=200)


@settings(derandomize=True, deadline=None, max_examples=20)
@given(bits=_BITS, blank=st.booleans())
def test_arrow_cells_round_trip_any_double(bits, blank):
    """Any float64 (random bit patterns: subnormals, huge, NaN payloads, -0.0, inf)."""
    pytest.importorskip("pyarrow")
    _bits_round_trip(bits, blank)


@pytest.mark.slow
@settings(derandomize=True, deadline=None, max_examples=500)
@given(bits=_BITS, blank=st.booleans())
def test_arrow_cells_round_trip_any_double_many(bits, blank):
    pytest.importorskip("pyarrow")
    _bits_round_trip(bits, blank)


def _cell_is(cell, x, blank):
    if x != x:
        return cell == ("" if blank else "nan")
    return np.float64(float(cell)).view(np.uint64) == np.float64(x).view(np.uint64)


@settings(derandomize=True, deadline=None, max_examples=10)
@given(bits=_BITS, other=_BITS, blank=st.booleans())
def test_arrow_cells_of_a_column_mostly_equal_to_an_earlier_one(bits, other, blank):
    """A column with an earlier column's bits in most rows (its text taken from that
    column's, the other rows formatted): every cell of both reads back as its own double."""
    _mostly_equal_round_trip(bits, other, blank)


@pytest.mark.slow
@settings(derandomize=True, deadline=None, max_examples=300)
@given(bits=_BITS, other=_BITS, blank=st.booleans())
def test_arrow_cells_of_a_column_mostly_equal_to_an_earlier_one_many(bits, other, blank):
    _mostly_equal_round_trip(bits, other, blank)


def _mostly_equal_round_trip(bits, other, blank):
    arrow = report._arrow() or pytest.skip("pyarrow is not installed")
    v = np.asarray(bits, np.uint64).view(np.float64)
    w = v.copy()
    changed = w[1::2]  # every other row, up to the other draw's length: at most half
    changed[:len(other)] = np.asarray(other, np.uint64).view(np.float64)[:len(changed)]
    key = "first_exceedance_s" if blank else "x"
    names = arrow[0].array([f"o[{i}]" for i in range(len(v))])
    lines = bytes(report._arrow_block(arrow, names, [v, w], [key, key])).decode().split("\r\n")
    assert lines[-1] == "" and len(lines) == len(v) + 1
    for line, x, y in zip(lines, v.tolist(), w.tolist()):
        _, a, b = line.split(",")
        assert _cell_is(a, x, blank) and _cell_is(b, y, blank), (line, x, y)


def test_csv_reprs_of_repeated_and_signed_values():
    """A column's repeated values are formatted once: -0.0, NaN and inf keep their own text."""
    v = np.array([0.0, -0.0, np.nan, np.inf, -np.inf, 1e-300, 0.1] * 50 + [2.5] * 30)
    assert report.csv_cell(v, "x") == [repr(x) for x in v.tolist()]
    assert report.csv_cell(v, "first_exceedance_s") == ["" if x != x else repr(x) for x in v.tolist()]
    flags = np.array([True, False, False] * 9)
    assert report.csv_cell(flags, "hazardous") == [str(x) for x in flags.tolist()]


def test_report_rows_are_json_safe_column_by_column():
    """report.json's observer rows are built from the columns: a non-finite value is the
    string "inf"/"-inf"/"nan" (JSON has no such numbers), NaN where it means "not
    applicable" is null, bools stay bools; the file puts one row per line."""
    inf, nan = float("inf"), float("nan")
    cols = {"labels": ["a", "b,c", "d"], "position_m": np.array([[0.0, 1.0, 2.0], [3.0, 4.0, 5.0], [6.0, 7.0, 8.0]]),
            "hazard_ratio": np.array([0.5, inf, nan]), "first_exceedance_s": np.array([nan, 2.0, -inf]),
            "hazardous": np.array([False, True, True])}
    rows = report.observer_rows(None, np.arange(3), cols)
    assert rows == [
        {"name": "a", "position_m": [0.0, 1.0, 2.0], "hazard_ratio": 0.5, "first_exceedance_s": None, "hazardous": False},
        {"name": "b,c", "position_m": [3.0, 4.0, 5.0], "hazard_ratio": "inf", "first_exceedance_s": 2.0, "hazardous": True},
        {"name": "d", "position_m": [6.0, 7.0, 8.0], "hazard_ratio": "nan", "first_exceedance_s": None, "hazardous": True}]
    doc = {"format": "x", "observers": rows, "after": {"k": [1, 2]}}
    text = report.report_json_text(doc)
    assert json.loads(text) == doc
    assert [line.rstrip(",") for line in text.splitlines() if line.startswith("  {")] == ["  " + json.dumps(r) for r in rows]
    assert json.loads(report.report_json_text({"observers": []})) == {"observers": []}


def _same(a, b) -> bool:
    """``a`` and ``b`` equal with the same types throughout (a float is not an int; floats by bits)."""
    if type(a) is not type(b):
        return False
    if isinstance(a, dict):
        return list(a) == list(b) and all(_same(a[k], b[k]) for k in a)
    if isinstance(a, list):
        return len(a) == len(b) and all(_same(x, y) for x, y in zip(a, b))
    if isinstance(a, float):
        return np.float64(a).view(np.int64) == np.float64(b).view(np.int64)
    return a == b


def _rows_from_columns(cols, rows):
    text = bytes(report._rows_json(cols, rows)).decode()
    assert all(line.startswith("  {") for line in text.split("\n")[1:])  # one row per line
    return json.loads("[" + text + "\n]")


@pytest.mark.parametrize("cells", ["orjson", "pyarrow"])
def test_report_rows_written_from_the_columns_are_the_row_dicts(monkeypatch, cells):
    """report.json's listed rows written from the columns (orjson's cells, or without it
    pyarrow's float text with ".0" where it reads as an integer) load as the very dicts
    observer_rows builds: every float the same double, ints stay ints, non-finite values as
    strings or null, names escaped."""
    if cells == "pyarrow":
        monkeypatch.setattr(report, "row_tools", lambda: None)
    inf, nan = float("inf"), float("nan")
    specials = np.array([0.5, inf, nan, -0.0, 1e15, 1e16, 1e-5, 5e-324, 1.0 / 3.0, 16791.0, -inf, 1e22])
    n = len(specials)
    cols = {"labels": [f"o{i}" for i in range(n - 3)] + ['quote " here', "b,c", "\u00e9t\u00e9"],
            "position_m": np.column_stack([specials[::-1], np.arange(n) * 0.1, -np.arange(n) * 1e3]),
            "hazard_ratio": specials, "first_exceedance_s": np.roll(specials, 1), "count": np.arange(n) - 4,
            "hazardous": np.arange(n) % 3 == 0, "motion_peak_irradiance_w_m2": np.roll(specials, 5)}
    for rows in (np.arange(n), np.array([3, 0, 11]), np.array([7])):
        want = report.observer_rows(None, rows, cols)
        got = _rows_from_columns(cols, rows)
        assert _same(got, json.loads(json.dumps(want))), (got, want)
    pytest.importorskip("pyarrow")
    assert bytes(report._rows_json(cols, np.arange(n))).decode() != ",".join("\n  " + json.dumps(r) for r in report.observer_rows(None, np.arange(n), cols))


def test_report_json_of_a_run_has_the_row_dicts(tmp_path, result):
    """The written report.json's observers (from the columns) equal report_dict's row dicts."""
    report.write_outputs(result, tmp_path / "o")
    doc = json.loads((tmp_path / "o" / "report.json").read_text())
    want = json.loads(json.dumps(report.report_dict(result)["observers"]))
    assert len(want) == len(result.observers) and _same(doc["observers"], want)


def test_observers_hazardous_over_time_are_listed_before_higher_static_ratios(monkeypatch):
    # a moving beam makes an observer hazardous over time while its static ratio stays below 1:
    # report.json's list (cut at JSON_OBSERVERS_MAX) must still hold every hazardous observer
    monkeypatch.setattr(report, "JSON_OBSERVERS_MAX", 4)
    ratio = np.array([0.9, 0.01, 0.8, np.nan, 0.7, 0.02, 2.0, 0.6])
    hazardous = np.array([False, True, False, False, False, True, True, False])  # rows 1 and 5 over time only
    rows = report.listed_rows({"hazard_ratio": ratio, "hazardous": hazardous}, len(ratio))
    assert rows.tolist() == [1, 3, 5, 6]  # the three hazardous and the unknown (NaN) ratio, in the scene's order
    assert ratio[1] == 0.01  # the caller's column is not changed


def test_rows_json_names_of_groups_escaped_once_each():
    """report.json's names made from the groups (each group's JSON text once, ``[i]`` put
    inside its closing quote) load as the row dicts' names: quotes, backslashes and
    non-ASCII in a grid group's and a one-point group's name, rows in any order."""
    pytest.importorskip("pyarrow")
    from hazard.pipeline.results import ObserverLabels
    from scenes.observers import Observers

    group = np.array([0] * 9 + [1] + [2] * 3)
    index = np.array(list(range(9)) + [0] + list(range(3)))
    obs = Observers.from_points(np.arange(39.0).reshape(13, 3), group, index, ['yard "B" \u00e9t\u00e9 \\ 1', 'tower "T"', "plain"])
    cols = {"labels": ObserverLabels(obs), "position_m": obs.take(np.arange(13)), "hazard_ratio": np.linspace(0.0, 2.0, 13),
            "hazardous": np.arange(13) > 6}
    rows = np.array([9, 0, 7, 12, 10])
    got = _rows_from_columns(cols, rows)
    assert [r["name"] for r in got] == ['tower "T"', 'yard "B" \u00e9t\u00e9 \\ 1[0]', 'yard "B" \u00e9t\u00e9 \\ 1[7]', "plain[2]", "plain[0]"]
    assert _same(got, json.loads(json.dumps(report.observer_rows(None, rows, cols))))
    block = np.arange(9)  # rows of one grid: the names by one join
    assert [r["name"] for r in _rows_from_columns(cols, block)] == [f'yard "B" \u00e9t\u00e9 \\ 1[{i}]' for i in range(9)]


def test_csv_written_beside_the_caller_is_the_same_set(tmp_path, result):
    """observers.csv written on its worker thread while the caller makes the map files
    (``csv_started``, as ``hazard run`` does) or within ``write_set``: the same bytes in
    every file as the table made in one piece on this thread."""
    a, b = tmp_path / "a", tmp_path / "b"
    a.mkdir(), b.mkdir()
    report.write_set(result, a, extra={"x.bin": b"x"})
    with report.csv_started(result, b) as job:
        names = report.write_set(result, b, extra={"x.bin": b"x"}, csv=job)
    assert names == ["report.json", "observers.csv", "x.bin"]
    assert (a / "observers.csv").read_bytes() == (b / "observers.csv").read_bytes() == \
        report._csv_text(result, report.observer_columns(result)).encode()
    for n in ("report.json", "x.bin"):
        ra, rb = (a / n).read_text(), (b / n).read_text()
        assert ra.split('"seconds"')[0] == rb.split('"seconds"')[0] and len(ra) > 0


def test_a_failure_beside_the_csv_writer_stops_it_before_going_on(tmp_path, result):
    """The caller fails while observers.csv is being written: the writer is stopped and
    joined before the error goes on (nothing writes into a staging folder being discarded)."""
    with pytest.raises(RuntimeError, match="map failed"):
        with report.csv_started(result, tmp_path) as job:
            raise RuntimeError("map failed")
    assert not job._thread.is_alive() and job._stop.is_set()


def test_the_csv_writers_error_reaches_the_caller(tmp_path, result):
    """A writer that cannot write (no such folder) raises its error in the caller."""
    with pytest.raises(FileNotFoundError):
        with report.csv_started(result, tmp_path / "missing") as job:
            pass
    assert not job._thread.is_alive()


def test_write_set_refuses_a_csv_writer_of_another_folder(tmp_path, result):
    """A writer started for another folder is named, not joined to this set."""
    (tmp_path / "a").mkdir(), (tmp_path / "b").mkdir()
    with report.csv_started(result, tmp_path / "a") as job:
        with pytest.raises(ValueError, match="observers.csv is being written into"):
            report.write_set(result, tmp_path / "b", csv=job)
