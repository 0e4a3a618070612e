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

from typing import NamedTuple

import numpy as np

__all__ = ["CellTexts", "CSV_TEXTS", "row_tools", "number_cells", "column_parts", "joined_rows"]


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


def number_cells(tools, v: np.ndarray, end: str):
    """Cells of a finite float64 (or integer) column by orjson, as a pyarrow string array.

    orjson writes ``[a,b,c]``; the ``]`` becomes a comma, every comma ``end``, and the
    cells are the text between them (each with its ``end``).

    Parameters
    ----------
    tools : tuple
        :func:`row_tools`.
    v : numpy.ndarray
        (n,) finite float64 values, or integers (any unit: the digits only).
    end : str
        One ASCII character written after each cell (a separator).
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
    if end != ",":
        data[stops] = ord(end)
    offsets = np.zeros(len(v) + 1, np.int32)
    offsets[1:] = stops + 1
    return pa.StringArray.from_buffers(len(v), pa.py_buffer(offsets), pa.py_buffer(data))


def _float_cells(tools, v: np.ndarray, end: str, texts: CellTexts):
    """:func:`number_cells` of a float64 column whose non-finite values take ``texts``. A
    column that mostly repeats its values (a grid's coordinates; judged on 256 rows spread
    over it) has each distinct value (by its bits: -0.0 is not 0.0) written once and the
    cells taken by index (27 against 45 ns a value for 1000 distinct x of a 16 384-row block)."""
    _, pa, pc = tools
    bits = v.view(np.int64)
    sample = bits[::max(1, len(bits) // 256)]
    if len(v) > 64 and 4 * len(np.unique(sample)) < len(sample):
        enc = pc.dictionary_encode(pa.array(bits))
        return _float_cells(tools, enc.dictionary.to_numpy().view(np.float64), end, texts).take(enc.indices)
    finite = np.isfinite(v)
    if finite.all():
        return number_cells(tools, v, end)
    keep = np.flatnonzero(finite)
    index = np.where(np.isnan(v), len(keep), np.where(v > 0, len(keep) + 1, len(keep) + 2))
    index[keep] = np.arange(len(keep))
    other = pa.array([texts.nan + end, texts.inf + end, texts.ninf + end], pa.string())
    cells = [number_cells(tools, v[keep], end), other] if len(keep) else [other]
    return pa.concat_arrays(cells).take(pa.array(index))


def _one_text(tools, v: np.ndarray, texts: CellTexts) -> str:
    """The cell of a column's first value, without the text after it."""
    if v.dtype == bool:
        return texts.true if v[0] else texts.false
    if v.dtype.kind == "f" and not np.isfinite(v[0]):
        return texts.nan if np.isnan(v[0]) else (texts.inf if v[0] > 0 else texts.ninf)
    return tools[0].dumps(v[:1], option=tools[0].OPT_SERIALIZE_NUMPY)[1:-1].decode()  # as number_cells writes it


def column_parts(tools, columns, afters) -> list:
    """The parts of every row (pyarrow string arrays, one cell each row, and str, the same
    text in every row) for :func:`joined_rows`.

    Parameters
    ----------
    tools : tuple
        :func:`row_tools`.
    columns : list of (numpy.ndarray, CellTexts)
        Each column's values (float64, integer or bool; all of one length) and its texts.
    afters : list of str
        The text after each column's cell in the row (a separator, the line's end); not
        empty, its first character ASCII.
    """
    _, pa, pc = tools
    parts: list = []
    done: list = []  # (values, texts, first character after, cells) of the columns made so far
    for (v, texts), after in zip(columns, afters):
        v = np.asarray(v)
        v = np.ascontiguousarray(v) if v.dtype == bool or v.dtype.kind in "iu" else np.ascontiguousarray(v, np.float64)
        raw = v.view(np.int64 if v.dtype.itemsize == 8 else np.int8).reshape(len(v), -1)  # by bits: -0.0 is not 0.0
        if not len(v) or (raw == raw[0]).all():  # one value throughout (a constant MPE, an unused column): one text
            parts += [_one_text(tools, v, texts) if len(v) else "", after]
            continue
        same = [c for (w, t, e, c) in done if t == texts and e == after[0] and w.dtype == v.dtype
                and np.array_equal(w[:64].view(np.int8), v[:64].view(np.int8)) and np.array_equal(w.view(np.int8), v.view(np.int8))]
        if same:
            cells = same[0]
        elif v.dtype == bool:
            cells = pc.if_else(pa.array(v), texts.true + after[0], texts.false + after[0])
        elif v.dtype.kind in "iu":
            cells = number_cells(tools, v, after[0])
        else:
            cells = _float_cells(tools, v, after[0], texts)
        done.append((v, texts, after[0], cells))
        parts += [cells, after[1:]]
    return parts


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
