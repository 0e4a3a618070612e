"""Rows of text made column by column, without a Python object per row or per cell:
observers.csv's blocks and report.json's listed rows (:mod:`hazard.outputs.report`).

Each column's cells are made at once - floats and integers by orjson's numpy serializer
(a float's shortest digits that read back as the same double: ``0.1``, ``1.0``, ``-0.0``,
``0.00001``, ``1e-7``, ``1e16``, ``5e-324``; about 35 ns a value), bools and non-finite
floats from the texts the caller gives - each cell followed by the first character of
the text that follows it in the row, and the cells of each row are joined by pyarrow
(``binary_join_element_wise``). A column of one value throughout is one text; a column
with the bits of an earlier one (and the same texts after it) takes the earlier one's cells.

Used when orjson and pyarrow are both installed (:func:`row_tools`); the callers keep
their other writers otherwise. Below :mod:`hazard.outputs.report` (imports neither it
nor any other project module).
"""

from __future__ import annotations

from functools import lru_cache
from typing import NamedTuple

import numpy as np

__all__ = ["CellTexts", "CSV_TEXTS", "row_tools", "number_cells", "string_cells", "column_parts", "joined_rows", "joined_pieces"]


class CellTexts(NamedTuple):
    """The texts of a column's non-numeric cells: a bool, and a float that is not finite."""

    true: str
    false: str
    nan: str
    inf: str
    ninf: str


CSV_TEXTS = CellTexts("True", "False", "nan", "inf", "-inf")  # Python's str() of each (observers.csv)


def row_tools():
    """(orjson, pyarrow, pyarrow.compute), or None when either is not installed."""
    try:
        import orjson
        import pyarrow
        import pyarrow.compute
    except ImportError:
        return None
    return orjson, pyarrow, pyarrow.compute


def number_cells(tools, v: np.ndarray, end: str, per_row: int = 1):
    """Cells of a finite float64 (or integer) column by orjson, as a pyarrow string array.

    orjson writes ``[a,b,c]``; the ``]`` becomes a comma, every ``per_row``-th comma
    ``end``, and the cells are the text between them (each with its ``end``).

    Parameters
    ----------
    tools : tuple
        :func:`row_tools`.
    v : numpy.ndarray
        (n,) finite float64 values, or integers (any unit: the digits only); with
        ``per_row`` > 1, the values of ``per_row`` columns row after row (n * per_row
        values, :func:`_stack_parts`): each cell is a row's values, comma-separated.
    end : str
        One ASCII character written after each cell (a separator).
    per_row : int
        Values per cell.
    """
    orjson, pa, _ = tools
    text = np.frombuffer(orjson.dumps(np.ascontiguousarray(v), option=orjson.OPT_SERIALIZE_NUMPY), np.uint8).copy()
    if len(text) >= 2**31:  # pyarrow's string offsets are int32 (the callers' blocks are a few MB)
        raise ValueError(f"a column of {len(v)} values is {len(text)} bytes of text; expected under 2 GiB (write it in blocks)")
    text[-1] = ord(",")
    data = text[1:]
    stops = np.flatnonzero(data == ord(","))
    if len(stops) != len(v):  # cannot happen for numbers; a guard against a changed orjson layout
        raise RuntimeError(f"orjson wrote {len(stops)} cells for {len(v)} values")
    if per_row > 1:
        stops = stops[per_row - 1::per_row]
    if end != ",":
        data[stops] = ord(end)
    offsets = np.zeros(len(stops) + 1, np.int32)
    offsets[1:] = stops + 1
    return pa.StringArray.from_buffers(len(stops), pa.py_buffer(offsets), pa.py_buffer(data))


def string_cells(tools, names: list, end: str):
    """Each of ``names`` as orjson writes it (``"map[0]"``: quotes and escapes included)
    followed by ``end``, as a pyarrow string array: one ``orjson.dumps`` of the list, cut
    after each comma between its items (each ``","``; that comma and the closing ``]``
    made ``end``). A name with a comma next to a quote of its text (``","`` itself, ``a\\",``)
    writes one more ``","``: then each name is written on its own.

    Parameters
    ----------
    tools : tuple
        :func:`row_tools`.
    names : list of str
        The texts (not empty).
    end : str
        One ASCII character written after each cell (a separator).
    """
    orjson, pa, _ = tools
    text = np.frombuffer(orjson.dumps(names), np.uint8).copy()
    if len(text) >= 2**31:
        raise ValueError(f"{len(names)} names are {len(text)} bytes of text; expected under 2 GiB (write them in blocks)")
    data = text[1:]
    data[-1] = ord(end)
    q, c = ord('"'), ord(",")
    stops = np.append(np.flatnonzero((data[:-2] == q) & (data[1:-1] == c) & (data[2:] == q)) + 1, len(data) - 1)
    if len(stops) != len(names):  # a "," inside a name as well as between them
        return pa.array([orjson.dumps(n).decode() + end for n in names], pa.string())
    data[stops] = ord(end)
    offsets = np.zeros(len(stops) + 1, np.int32)
    offsets[1:] = stops + 1
    return pa.StringArray.from_buffers(len(stops), pa.py_buffer(offsets), pa.py_buffer(data))


def _float_cells(tools, v: np.ndarray, end: str, texts: CellTexts, repeated: bool | None = None):
    """:func:`number_cells` of a float64 column whose non-finite values take ``texts``. A
    column that repeats its values (:func:`_repeats`) has each distinct value (by its bits:
    -0.0 is not 0.0) written once and the cells taken by index (``repeated``: that judgement,
    when the caller made it)."""
    _, pa, pc = tools
    if _repeats(v) if repeated is None else repeated:
        enc = pc.dictionary_encode(pa.array(v.view(np.int64)))
        return _float_cells(tools, enc.dictionary.to_numpy().view(np.float64), end, texts, repeated=False).take(enc.indices)
    finite = np.isfinite(v)
    if finite.all():
        return number_cells(tools, v, end)
    keep = np.flatnonzero(finite)
    index = np.where(np.isnan(v), len(keep), np.where(v > 0, len(keep) + 1, len(keep) + 2))
    index[keep] = np.arange(len(keep))
    other = pa.array([texts.nan + end, texts.inf + end, texts.ninf + end], pa.string())
    cells = [number_cells(tools, v[keep], end), other] if len(keep) else [other]
    return pa.concat_arrays(cells).take(pa.array(index))


@lru_cache(maxsize=256)
def _one_text(tools, dtype: str, bits: bytes, texts: CellTexts) -> str:
    """The cell of a value (its dtype and bytes: a column's first value, written once for
    every block of a table), without the text after it."""
    v = np.frombuffer(bits, dtype)
    if v.dtype == bool:
        return texts.true if v[0] else texts.false
    if v.dtype.kind == "f" and not np.isfinite(v[0]):
        return texts.nan if np.isnan(v[0]) else (texts.inf if v[0] > 0 else texts.ninf)
    return tools[0].dumps(v, option=tools[0].OPT_SERIALIZE_NUMPY)[1:-1].decode()  # as number_cells writes it


def _repeats(v: np.ndarray) -> bool:
    """Whether a float64 column repeats its values enough that writing each distinct one
    once and taking the cells by index is the cheaper (a grid's coordinates: 27 against
    45 ns a value for the 1000 distinct x of a 16 384-row block), judged by its bits (-0.0
    is not 0.0) on 1024 random rows of it (:func:`_sample_rows`): under 80 % of them
    distinct (a column of up to ~2000 distinct values in a block of 32 768 rows)."""
    if len(v) <= 64:
        return False
    at = _sample_rows(len(v))
    sample = np.sort(v.view(np.int64)[at])
    return 5 * (1 + np.count_nonzero(sample[1:] != sample[:-1])) < 4 * len(at)  # the distinct values of the sample


@lru_cache(maxsize=8)
def _sample_rows(n: int) -> np.ndarray:
    """:func:`_repeats`' rows of a column of ``n``: 1024 (or all) drawn without
    replacement by a fixed seed (the same rows every run). A regular stride aliases with
    a grid's period: 7919 apart modulo 32 768 rows saw 870 distinct values of a column
    of 1000 (a 1000-wide grid's x), where random rows see 640 (the 80 % rule's 819 then
    never met by that grid's column, which the dictionary writes at 27 against 45 ns a value)."""
    if n <= 1024:
        return np.arange(n, dtype=np.int64)
    return np.sort(np.random.default_rng(7919).choice(n, 1024, replace=False))


def _kinds(tools, columns, afters):
    """Each column's values (contiguous), and what it is: ``("text", str)`` one value
    throughout; ``("same", j)`` the bits and texts of the earlier column ``j`` (and the same
    first character after it); ``("plain", None)`` cells of its own, each with the first
    character after it; ``("any", None)`` cells that take any literal text around them at
    no cost (bools by ``if_else`` of two texts, repeated values by the texts of the distinct
    ones)."""
    values, kinds, raws = [], [], []
    seen: dict = {}  # (dtype, texts, first character after, the first 64 values' bytes) -> the plain or any columns of that start
    for i, ((v, texts), after) in enumerate(zip(columns, afters)):
        v = np.asarray(v)
        v = np.ascontiguousarray(v) if v.dtype == bool or v.dtype.kind in "iu" else np.ascontiguousarray(v, np.float64)
        raw = v.view(np.int64 if v.dtype.itemsize == 8 else np.int8).reshape(len(v), -1)  # by bits: -0.0 is not 0.0
        values.append(v)
        raws.append(raw)
        if not len(v) or ((raw[:64] == raw[0]).all() and (raw == raw[0]).all()):  # one value throughout: one text
            kinds.append(["text", _one_text(tools, v.dtype.str, raw[0].tobytes(), texts) if len(v) else ""])
            continue
        key = (v.dtype.str, texts, after[0], raw[:64].tobytes())
        same = [j for j in seen.get(key, ()) if np.array_equal(raws[j], raw)]  # the same bits (dtypes equal: in the key)
        if same:
            kinds[same[0]][0] = "plain"  # its cells serve both: no literal text taken in
            kinds.append(["same", same[0]])
            continue
        seen.setdefault(key, []).append(i)
        kinds.append(["any", None] if v.dtype == bool or (v.dtype.kind == "f" and _repeats(v)) else ["plain", None])
    return values, kinds


def _row_items(kinds, afters, head) -> list:
    """The row as items: ``["lit", bytes]``, ``["arr", array]`` (a part of ``head``) or
    ``["col", i, lead, trail]`` (column ``i``'s cells: ``lead``, its text, ``trail``; the
    first character after a column always in its cells), consecutive literals merged, and
    each ASCII literal taken into the cells on its either side of an ``any`` column (the
    left one first)."""
    seq: list = []

    def lit(b: bytes):
        if b:
            if seq and seq[-1][0] == "lit":
                seq[-1][1] += b
            else:
                seq.append(["lit", b])

    for h in head:
        if isinstance(h, str):
            lit(h.encode())
        else:
            seq.append(["arr", h])
    for i, ((kind, text), after) in enumerate(zip(kinds, afters)):
        if kind == "text":
            lit(text.encode() + after.encode())
        else:
            seq.append(["col", i, b"", after[:1].encode()])
            lit(after[1:].encode())
    takes = [s[0] == "col" and kinds[s[1]][0] == "any" for s in seq]
    for k, s in enumerate(seq):
        if s[0] == "lit" and s[1].isascii():
            if k > 0 and takes[k - 1]:
                seq[k - 1][3], s[1] = seq[k - 1][3] + s[1], b""
            elif k + 1 < len(seq) and takes[k + 1]:
                seq[k + 1][2], s[1] = s[1], b""
    return [s for s in seq if s[0] != "lit" or s[1]]


def column_parts(tools, columns, afters, head=()) -> list:
    """The parts of every row (pyarrow string arrays, one cell each row, and str, the same
    text in every row) for :func:`joined_rows`: the literal text beside a column of bools
    or of repeated values taken into its cells (each part costs the join ~12 ns a row, a
    literal as much as a column).

    Parameters
    ----------
    tools : tuple
        :func:`row_tools`.
    columns : list of (numpy.ndarray, CellTexts)
        Each column's values (float64, integer or bool; all of one length) and its texts.
    afters : list of str
        The text after each column's cell in the row (a separator, the line's end); not
        empty, its first character ASCII.
    head : sequence of str or pyarrow string arrays
        Parts before the first column (a row's name).
    """
    values, kinds = _kinds(tools, columns, afters)
    made: dict = {}
    parts: list = []
    for s in _stacks(_row_items(kinds, afters, head), kinds, values):
        if s[0] == "stack":
            parts += _stack_parts(tools, [values[i] for i in s[1]], s[2].decode(), [columns[i][1] for i in s[1]])
            continue
        if s[0] != "col":
            parts.append(s[1].decode() if s[0] == "lit" else s[1])
            continue
        i, lead, trail = s[1:]
        j = kinds[i][1] if kinds[i][0] == "same" else i
        if j not in made:
            made[j] = _cells(tools, values[j], lead.decode(), trail.decode(), columns[j][1], kinds[j][0] == "any")
        parts.append(made[j])
    return parts


def _stacks(items: list, kinds, values) -> list:
    """:func:`_row_items` with each run of two or more consecutive float64 columns of cells
    of their own (``plain``, none an earlier column's ``same``), a comma alone between them,
    as one item ``["stack", [i, ...], trail]`` (``trail``: the last one's)."""
    shared = {k[1] for k in kinds if k[0] == "same"}

    def own(s) -> bool:
        return s[0] == "col" and kinds[s[1]][0] == "plain" and s[1] not in shared and values[s[1]].dtype == np.float64

    out: list = []
    run: list = []  # the current run's items
    for s in items + [["end"]]:
        if own(s) and run and run[-1][3] == b",":
            run.append(s)
            continue
        out += [["stack", [r[1] for r in run], run[-1][3]]] if len(run) > 1 else run
        run = [s] if own(s) else []
        if not run and s[0] != "end":
            out.append(s)
    return out


def _stack_parts(tools, vs: list, trail: str, texts: list) -> list:
    """The parts of a run of :func:`_stacks`: one (:func:`number_cells` of their values row
    after row, each cell a row's values and ``trail``) when every value is finite, else each
    column's own cells (its non-finite values' texts; a comma after each, ``trail`` after
    the last)."""
    rows = np.empty((len(vs[0]), len(vs)))
    for k, v in enumerate(vs):
        rows[:, k] = v
    if np.isfinite(rows).all():
        return [number_cells(tools, rows.reshape(-1), trail, per_row=len(vs))]
    return [_float_cells(tools, v, "," if k + 1 < len(vs) else trail, t, repeated=False) for k, (v, t) in enumerate(zip(vs, texts))]


def _cells(tools, v: np.ndarray, lead: str, trail: str, texts: CellTexts, repeated: bool):
    """A column's cells, each ``lead`` + its text + ``trail`` (``trail`` not empty, its first
    character ASCII; ``lead`` empty unless ``repeated``, or bools)."""
    _, pa, pc = tools
    if v.dtype == bool:
        return pc.if_else(pa.array(v), lead + texts.true + trail, lead + texts.false + trail)
    if v.dtype.kind in "iu":
        return number_cells(tools, v, trail)
    if not repeated:
        return _float_cells(tools, v, trail, texts, repeated=False)
    enc = pc.dictionary_encode(pa.array(v.view(np.int64)))  # each distinct value (by its bits) written once
    cells = _float_cells(tools, enc.dictionary.to_numpy().view(np.float64), trail[0], texts, repeated=False)  # distinct
    if lead or trail[1:]:
        cells = pc.binary_join_element_wise(lead, cells, trail[1:], "")
    return cells.take(enc.indices)


def joined_rows(tools, parts, n: int, drop_last: int = 0):
    """The rows' text, one row after another, as one bytes-like buffer (no copy of the joined text).

    Parameters
    ----------
    tools : tuple
        :func:`row_tools`.
    parts : list
        Each row's pieces in order: pyarrow string arrays (``n`` values: one per row,
        :func:`column_parts`) and str (the same text in every row); consecutive str are
        joined first (each part costs ~13 ns a row).
    n : int
        The number of rows.
    drop_last : int
        Bytes left off the end (a separator after the last row).
    """
    _, pa, pc = tools
    merged: list = []
    for p in parts:
        if isinstance(p, str) and merged and isinstance(merged[-1], str):
            merged[-1] += p
        elif not (isinstance(p, str) and not p):
            merged.append(p)
    if all(isinstance(p, str) for p in merged):  # every column one value (a block of one row)
        text = ("".join(merged) * n).encode()
        return text[:len(text) - drop_last]
    text = pc.binary_join_element_wise(*merged, "")
    off = np.frombuffer(text.buffers()[1], np.int32)[text.offset:text.offset + len(text) + 1]
    return text.buffers()[2].slice(int(off[0]), int(off[-1] - off[0]) - drop_last)


def joined_pieces(tools, parts, n: int, rows: int) -> list:
    """:func:`joined_rows` of ``rows`` rows at a time (the last piece the rest): the same
    text as one join, in pieces of a bounded size (the parts' cells made once for all ``n``)."""
    return [joined_rows(tools, [p if isinstance(p, str) else p[a:a + rows] for p in parts], min(rows, n - a))
            for a in range(0, n, rows)]
