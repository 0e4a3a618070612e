"""Rows of text made column by column (:mod:`hazard.outputs.row_text`, issue 37 item 3):
observers.csv's blocks and report.json's listed rows by orjson's cells joined by pyarrow.

The oracle is Python itself: ``float(cell)`` of every cell must give the array's double
bit for bit (-0.0 is not 0.0), NaN and inf the texts asked for; ``json.loads`` of the rows
the very values. Doubles are drawn as random bit patterns (every exponent: subnormals,
huge, NaN payloads, +-0, +-inf), not from the engine.
"""

import json

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from hazard.outputs import report, row_text
from hazard.outputs.map_outputs import geojson_bytes

TOOLS = row_text.row_tools()
pytestmark = pytest.mark.skipif(TOOLS is None, reason="orjson or pyarrow is not installed")

_SPECIAL = np.array([0.0, -0.0, np.inf, -np.inf, np.nan, -np.nan, 5e-324, -5e-324, 2.2250738585072014e-308,
                     -2.2250738585072009e-308, 1.7976931348623157e308, -1.7976931348623157e308, 1e16, 1e15, 1e-5,
                     1e-7, 0.1, 1.0 / 3.0, 123456789.0, 1e22, 1e21, 9007199254740993.0, 2.0**53, 1.5]).view(np.uint64).tolist()
_BITS = st.lists(st.one_of(st.integers(0, 2**64 - 1), st.sampled_from(_SPECIAL),
                           st.integers(0, 2**52 - 1)), min_size=1, max_size=200)  # the last: subnormals (and +0)


def _doubles(n: int, seed: int) -> np.ndarray:
    """``n`` doubles from random bits: a third any bit pattern, a third subnormal (either
    sign), a third normal numbers of any exponent, with the specials spread through."""
    rng = np.random.default_rng(seed)
    bits = rng.integers(0, 2**64, n, dtype=np.uint64)
    sub = rng.integers(0, 2**52, n, dtype=np.uint64) | (rng.integers(0, 2, n, dtype=np.uint64) << np.uint64(63))
    bits = np.where(np.arange(n) % 3 == 1, sub, bits)
    at = np.linspace(0, n - 1, min(n, len(_SPECIAL))).astype(int)
    bits[at] = np.array(_SPECIAL, np.uint64)[: len(at)]
    return bits.view(np.float64)


def _cell_is(cell: str, x: float, blank: bool) -> bool:
    if x != x:
        return cell == ("" if blank else "nan")
    return np.float64(float(cell)).view(np.uint64) == np.float64(x).view(np.uint64)


def _csv_lines(columns, keys) -> list:
    n = len(columns[0])
    names = [f"o[{i}]" for i in range(n)]
    block = report._joined_block(TOOLS, [TOOLS[1].array(names)], columns, keys)
    lines = b"".join(bytes(p) for p in block).decode().split("\r\n")
    assert lines[-1] == "" and len(lines) == n + 1
    return [line.split(",") for line in lines[:-1]]


def _csv_round_trip(v, blank: bool):
    """``v`` as a column (and twice repeated, and as a column of one value) through the
    joined block writer: every cell reads back as its double, the names and flags too."""
    key = "first_exceedance_s" if blank else "x"
    for col in (v, np.repeat(v, 70), np.full(4, v[0])):  # distinct; repeating (each distinct value once); constant
        rows = _csv_lines([col, col > 0, col], [key, "hazardous", "y"])
        for i, (row, x) in enumerate(zip(rows, col.tolist())):
            name, a, flag, b = row
            assert name == f"o[{i}]" and flag == str(x > 0), row
            assert _cell_is(a, x, blank) and _cell_is(b, x, False), (row, x)


@settings(derandomize=True, deadline=None, max_examples=20)
@given(bits=_BITS, blank=st.booleans())
def test_csv_cells_round_trip_any_double(bits, blank):
    """Any float64 (random bit patterns), blank or not where NaN means "not applicable"."""
    _csv_round_trip(np.asarray(bits, np.uint64).view(np.float64), blank)


@pytest.mark.slow
@settings(derandomize=True, deadline=None, max_examples=500)
@given(bits=_BITS, blank=st.booleans())
def test_csv_cells_round_trip_any_double_many(bits, blank):
    _csv_round_trip(np.asarray(bits, np.uint64).view(np.float64), blank)


def _bulk(n: int, seed: int):
    v = _doubles(n, seed)
    rows = _csv_lines([v], ["first_exceedance_s"])
    cells = [r[1] for r in rows]
    nan = np.isnan(v)
    assert [c == "" for c in cells] == nan.tolist()
    got = np.array([float(c) if c else np.nan for c in cells])
    np.testing.assert_array_equal(got.view(np.uint64)[~nan], v.view(np.uint64)[~nan])


def test_csv_cells_round_trip_random_doubles():
    """2e4 random doubles (a third subnormal) in one block: every cell the same double."""
    _bulk(20_000, 1)


@pytest.mark.slow
def test_csv_cells_round_trip_random_doubles_many():
    """2e6 random doubles, a third subnormal."""
    for seed in range(4):
        _bulk(500_000, 10 + seed)


def test_csv_columns_equal_to_an_earlier_one_keep_their_own_texts():
    """A column with an earlier one's bits takes its cells; -0.0 and 0.0, or the same
    values with a different NaN text, are not taken for each other."""
    v = np.array([0.0, 1.5, np.nan, -2.0, 3.0] * 30)
    w = np.where(v == 0.0, -0.0, v)
    rows = _csv_lines([v, v, w, v], ["x", "y", "z", "first_exceedance_s"])
    for row, x, y in zip(rows, v.tolist(), w.tolist()):
        assert _cell_is(row[1], x, False) and _cell_is(row[2], x, False) and _cell_is(row[3], y, False), row
        assert _cell_is(row[4], x, True), row
    assert {r[3] for r in rows if r[1] == "0.0"} == {"-0.0"}


def test_integer_and_bool_columns():
    """Integers by orjson are Python's str() of each; bools the given texts."""
    n = np.array([0, -1, 2**63 - 1, -(2**63), 7] * 20, np.int64)
    u = np.array([0, 2**64 - 1, 5, 1, 9] * 20, np.uint64)
    parts = row_text.column_parts(TOOLS, [(n, row_text.CSV_TEXTS), (u, row_text.CSV_TEXTS), (n % 2 == 0, row_text.CSV_TEXTS)],
                                  [";", ";", "\n"])
    lines = bytes(row_text.joined_rows(TOOLS, parts, len(n))).decode().split("\n")[:-1]
    assert lines == [f"{a};{b};{a % 2 == 0}" for a, b in zip(n.tolist(), u.tolist())]


def _json_rows(cols, rows):
    text = bytes(report._rows_json(cols, rows)).decode()
    return json.loads("[" + text + "\n]")


def test_json_rows_load_as_the_values_for_any_double():
    """report.json's listed rows by orjson's cells: json.loads gives each double bit for bit
    (a whole number stays a float: ``1.0``), non-finite values as the row dicts give them
    (strings, or null where NaN means "not applicable"), ints and bools as they are."""
    v = _doubles(3000, 5)
    n = len(v)
    cols = {"labels": [f"o{i}" for i in range(n)], "position_m": np.column_stack([v, v[::-1], np.full(n, -0.0)]),
            "hazard_ratio": v, "first_exceedance_s": np.roll(v, 7), "count": np.arange(n) - 5, "hazardous": v > 1}
    want = json.loads(json.dumps(report.observer_rows(None, np.arange(n), cols)))
    got = _json_rows(cols, np.arange(n))
    assert len(got) == n
    for g, w in zip(got, want):
        assert list(g) == list(w)
        for k in w:
            a, b = (g[k], w[k]) if k != "position_m" else (tuple(g[k]), tuple(w[k]))
            assert type(a) is type(b), (k, a, b)
            if isinstance(a, float):
                assert np.float64(a).view(np.uint64) == np.float64(b).view(np.uint64), (k, a, b)
            elif isinstance(a, tuple):
                assert [np.float64(x).view(np.uint64) if isinstance(x, float) else x for x in a] == \
                       [np.float64(x).view(np.uint64) if isinstance(x, float) else x for x in b], (k, a, b)
            else:
                assert a == b, (k, a, b)


def test_geojson_bytes_same_values_and_never_a_hidden_nan():
    """The zones document by orjson loads as json.dumps's; a NaN is refused as json.dumps
    refuses it (orjson would write null), a real null is written by json.dumps."""
    doc = {"type": "FeatureCollection", "features": [{"type": "Feature", "geometry": {"type": "Point", "coordinates": (1e-5, -0.0)},
                                                      "properties": {"name": "a\"b", "hazard_ratio": 1.0 / 3.0, "n": 3}}]}
    text = geojson_bytes(doc)
    assert json.loads(text) == json.loads(json.dumps(doc)) and b" " not in text  # orjson's layout
    assert json.loads(text)["features"][0]["geometry"]["coordinates"][1] == 0.0
    assert str(json.loads(text)["features"][0]["geometry"]["coordinates"][1]) == "-0.0"
    with pytest.raises(ValueError):
        geojson_bytes({**doc, "bad": float("nan")})
    with_null = {**doc, "none": None}
    assert geojson_bytes(with_null) == json.dumps(with_null, indent=None, allow_nan=False).encode()


_SEPS = [",", ";", "|x|", ", \"k\": ", "|\u00e9|", "\r\n"]  # each a text no cell holds (its first character ASCII)


def _layout(bits, kinds, seps, head_text):
    """Columns of each kind: distinct (random bit patterns), finite (the same, NaN and inf
    made -0.0: consecutive ones with a comma between are one stacked part), repeated (each of ``bits`` 70
    times: written once each, the literal beside it taken into its cells), bools,
    one value throughout (a literal), and a copy of the first column (its cells shared)."""
    v = np.asarray(bits, np.uint64).view(np.float64)
    n = len(v) * 70
    cols = []
    for j, k in enumerate(kinds):
        w = np.roll(np.repeat(v, 70), 3 * j)
        d = _doubles(n, len(v) + j)
        cols.append({"distinct": d, "finite": np.where(np.isfinite(d), d, -0.0), "repeated": w, "bool": w > 0,
                     "one": np.full(n, v[0]), "copy": cols[0] if cols else w}[k])
    afters = [seps[j % len(seps)] for j in range(len(cols) - 1)] + ["\r\n"]
    return cols, afters, [head_text]


def _split_rows(text: str, head: str, afters, n: int) -> list:
    """Each row's cells, read off by the known texts between them (no cell holds one)."""
    rows, at = [], 0
    for _ in range(n):
        assert text.startswith(head, at)
        at += len(head)
        cells = []
        for sep in afters:
            end = text.index(sep, at)
            cells.append(text[at:end])
            at = end + len(sep)
        rows.append(cells)
    assert at == len(text)
    return rows


def _absorbed_round_trip(bits, kinds, seps, head_text, blank):
    texts = row_text.CSV_TEXTS._replace(nan="") if blank else row_text.CSV_TEXTS
    cols, afters, head = _layout(bits, kinds, seps, head_text)
    parts = row_text.column_parts(TOOLS, [(c, texts) for c in cols], afters, head)
    n = len(cols[0])
    text = bytes(row_text.joined_rows(TOOLS, parts, n))
    for k in (1, 37, n):  # the same text joined in pieces of k rows (observers.csv's blocks)
        pieces = row_text.joined_pieces(TOOLS, parts, n, k)
        assert len(pieces) == -(-n // k) and b"".join(bytes(p) for p in pieces) == text, k
    rows = _split_rows(text.decode(), head_text, afters, n)
    for j, c in enumerate(cols):
        for row, x in zip(rows, c.tolist()):
            if c.dtype == bool:
                assert row[j] == str(x), (j, row, x)
            else:
                assert _cell_is(row[j], x, blank), (j, row, x)
    return parts


_KINDS = st.lists(st.sampled_from(["distinct", "finite", "repeated", "bool", "one", "copy"]), min_size=1, max_size=7)


@settings(derandomize=True, deadline=None, max_examples=25)
@given(bits=_BITS, kinds=_KINDS, seps=st.lists(st.sampled_from(_SEPS[:-1]), min_size=1, max_size=4),
       head_text=st.sampled_from(["", "o[", "\u00e9[", "\"name\": "]), blank=st.booleans())
def test_literals_taken_into_the_cells_of_bools_and_repeated_values(bits, kinds, seps, head_text, blank):
    """Any mix of distinct, repeated, bool, constant and copied columns, with literal text
    (ASCII or not) between them: every cell reads back as its double (or bool, or the
    NaN text), the literals where they were, whichever cells took them in."""
    _absorbed_round_trip(bits, kinds, seps, head_text, blank)


@pytest.mark.slow
@settings(derandomize=True, deadline=None, max_examples=300)
@given(bits=_BITS, kinds=_KINDS, seps=st.lists(st.sampled_from(_SEPS[:-1]), min_size=1, max_size=4),
       head_text=st.sampled_from(["", "o[", "\u00e9[", "\"name\": "]), blank=st.booleans())
def test_literals_taken_into_the_cells_of_bools_and_repeated_values_many(bits, kinds, seps, head_text, blank):
    _absorbed_round_trip(bits, kinds, seps, head_text, blank)


def test_literals_beside_bools_and_repeated_values_leave_no_part_of_their_own():
    """The row text before, between and after a bool and a repeated column, and a constant
    column between them, are all inside their cells: the join has two parts, not five."""
    bits = np.array([1.5, -2.0, 0.25, 3.0], np.float64).view(np.uint64).tolist()
    parts = _absorbed_round_trip(bits, ["bool", "one", "repeated"], [";"], "o[", False)
    assert not any(isinstance(p, str) for p in parts) and len(parts) == 2


def test_consecutive_columns_of_finite_doubles_are_one_part():
    """Columns of distinct finite doubles with a comma alone between them are one part of
    the join (one orjson call on their values row after row), the row's other text around
    it; one holding NaN or inf leaves the run to each column's cells (its texts), and a
    column whose cells a later copy shares keeps its own part."""
    bits = np.array([1.5, -2.0, 0.25, 3.0], np.float64).view(np.uint64).tolist()
    def arrays(kinds, seps, blank=False) -> int:
        return sum(not isinstance(p, str) for p in _absorbed_round_trip(bits, kinds, seps, "", blank))

    assert arrays(["finite"] * 4, [","]) == 1  # a,b,c,d\r\n
    assert arrays(["finite"] * 4, [",", ",", ";"]) == 2  # a,b,c;d
    assert arrays(["finite"] * 4, [";", ","]) == 3  # a;b,c;d
    assert arrays(["distinct", "finite"], [","], blank=True) == 2  # NaN and inf in the first: no stack
    assert arrays(["finite", "copy", "finite"], [","]) == 3  # the first's cells serve the copy too


def test_repeated_values_judged_on_a_scrambled_sample():
    """A grid's x (1000 values, each 16 times in a block) is judged repeated (a sample
    strided by 64 would see 125 distinct values in 256); distinct doubles are not."""
    x = np.tile(np.linspace(-50.0, 50.0, 1000), 17)[:16_384]
    assert row_text._repeats(x)
    assert not row_text._repeats(_doubles(16_384, 3))
    assert not row_text._repeats(np.repeat(x[:5], 10))  # 50 rows: too few to judge


@pytest.mark.parametrize("width", [100, 999, 1000, 1024, 1500])
def test_grid_columns_of_a_csv_block_are_judged_repeated(width):
    """observers.csv's blocks are 32 768 rows: a grid ``width`` wide has that many distinct
    x in a block (and ~32 768 / width distinct y), each in many rows. Both are judged
    repeated, whatever the width's relation to the sample's rows (a sample 7919 rows apart
    modulo the block saw 870 distinct x of a 1000-wide grid in 1024 and wrote them one by
    one); a column of distinct values is not, nor one with each value in two rows."""
    from hazard.outputs.report import CSV_BLOCK_ROWS

    i = np.arange(CSV_BLOCK_ROWS)
    x, y = -50.0 + 0.1 * (i % width), 3.0 * (i // width) - 45.0
    assert row_text._repeats(x) and row_text._repeats(y)
    assert not row_text._repeats(_doubles(CSV_BLOCK_ROWS, 5))
    assert not row_text._repeats(np.repeat(_doubles(CSV_BLOCK_ROWS // 2, 6), 2))


_NAMES = ['a"b[1]', "x\\", "\u00e9t\u00e9[12]", "plain", "tab\there"]


@settings(derandomize=True, deadline=None, max_examples=60)
@given(names=st.lists(st.text(alphabet=st.sampled_from('ab,"\\[]0\u00e9\u2028\t '), max_size=6), min_size=1, max_size=30),
       end=st.sampled_from([",", ";", "\n"]))
def test_string_cells_are_each_names_orjson_text(names, end):
    """One orjson text of the list cut into its items: each name's own ``orjson.dumps``
    and ``end``, for names of commas, quotes, backslashes, brackets and non-ASCII (a comma
    beside a quote inside a name: each written on its own)."""
    import orjson

    cells = row_text.string_cells(TOOLS, names, end).to_pylist()
    assert cells == [orjson.dumps(n).decode() + end for n in names]


def _points(n: int, seed: int, names):
    from hazard.outputs.map_zones import ObserverPoints

    rng = np.random.default_rng(seed)
    p = rng.normal(size=(n, 3)) * 10.0 ** rng.integers(-3, 6, (n, 1))
    p[::7, 0] = -0.0
    haz = rng.random(n) < 0.4
    return ObserverPoints(np.arange(n), p, _doubles(n, seed), _doubles(n, seed + 1)[::-1].copy(), haz,
                          haz & (rng.random(n) < 0.5), [names[i % len(names)] for i in range(n)])


def _feature_text(op, common) -> bytes:
    """What the map wrote before: one dict per observer (map_zones.observer_zones), its
    values made JSON-safe, and orjson's text of the list."""
    import orjson

    from hazard.outputs import map_outputs
    from hazard.outputs.map_zones import observer_zones

    feats = [{"type": "Feature", "geometry": {"type": "Point", "coordinates": tuple(np.round(op.position_m[i, :2], 4).tolist())},
              "properties": {k: map_outputs._jsonable(v) for k, v in z.properties.items()}}
             for i, z in enumerate(observer_zones(op, common))]
    return orjson.dumps(feats)[1:-1]


@pytest.mark.parametrize("seed, names", [(0, _NAMES), (1, _NAMES), (2, _NAMES + [",", 'a",', ",b"])])
def test_map_observer_features_column_by_column_are_the_dicts_text(seed, names):
    """The observer points of the zones file made column by column: byte for byte orjson's
    text of the per-observer dicts, for doubles from random bits (NaN, inf as strings),
    -0.0 and large and small positions, names with quotes, backslashes, non-ASCII, and
    commas beside quotes (each name written on its own, :func:`row_text.string_cells`)."""
    from hazard.outputs import map_outputs

    op = _points(600, seed, names)
    common = {"standard": "ansi-z136.1-2014", "exposure_duration_s": 0.25, "mpe_w_m2": 1e-7, "wavelength_nm": 1064.0, "scene": "s"}
    assert map_outputs._observer_features(TOOLS, op, common) == _feature_text(op, common)
    assert map_outputs._observer_features(TOOLS, op, {}) == _feature_text(op, {})


def test_map_observer_features_left_to_the_dicts_where_their_text_differs():
    """A position not finite (orjson would write null: json.dumps refuses it), a name with
    ``null`` in it (the zones file then goes through json.dumps) or a common property that
    would replace a point's own: None, and the map writes the dicts as before."""
    from hazard.outputs import map_outputs

    op = _points(20, 3, ["o"])
    bad = _points(20, 3, ["o"])
    bad.position_m[3, 1] = np.nan
    assert map_outputs._observer_features(TOOLS, op, {"scene": "s"}) is not None
    assert map_outputs._observer_features(TOOLS, bad, {"scene": "s"}) is None
    assert map_outputs._observer_features(TOOLS, _points(20, 3, ["nullable"]), {"scene": "s"}) is None
    assert map_outputs._observer_features(TOOLS, op, {"name": "x"}) is None


def test_map_files_same_bytes_with_the_points_as_columns(monkeypatch):
    """The whole zones file and the map section of a grid run: the same with the observer
    points written column by column as with one zone dict each (the path kept for a site)."""
    import hazard
    import scenes
    from hazard.outputs import map_outputs

    text = scenes.example_path("plate").read_text().split("[[observers]]")[0]
    result = hazard.analyze(scenes.loads(text + '[[observers]]\nname = "g"\norigin_m = [-5.0, -45.0, 1.5]\n'
                                         'u_m = [10.0, 0.0, 0.0]\nv_m = [0.0, 33.0, 0.0]\ncounts = [30, 20]\n'))
    fast, section = map_outputs.map_files(result)
    assert section.features["observer"] == 600
    monkeypatch.setattr(map_outputs, "_geojson_text", lambda *a: None)
    slow, section2 = map_outputs.map_files(result)
    assert fast == slow and section == section2
