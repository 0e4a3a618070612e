"""Outputs of an analysis: ``report.json`` (every step) and ``observers.csv``, atomically.

The whole set is written into a staging folder beside the output folder and switched in
as one unit (:mod:`brdfmodels.output_sets`), so a crash never leaves a half-written report nor
a new report beside an old table. An existing report is never overwritten unless asked
(``force=True``).
"""

from __future__ import annotations

import json
import math
import os
from contextlib import contextmanager
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from brdfmodels.fileio import atomic_write_text, current_umask, write_synced

from hazard.outputs._select import top_rows
from hazard.outputs.csv_text import GEO_COLUMNS, column_text, observer_geodetic
from hazard.outputs.motion_outputs import MOTION_COLUMNS, motion_columns, motion_sections, track_columns, track_files, visual_levels
from hazard.outputs.row_text import CSV_TEXTS, CellTexts, column_parts, joined_pieces, joined_rows, row_tools
from hazard.physics.aperture import limiting_aperture
from hazard.pipeline.verdict import Verdict, escape_way, verdict
from scenes.conventions import beam_headline
from scenes.geo_input import FrameDescription
from scenes.quantities import as_written_lines

if TYPE_CHECKING:  # annotations only
    from hazard.pipeline.sdz import DangerZone, MirrorBeam

__all__ = ["report_dict", "write_outputs", "OutputExistsError", "atomic_write_text", "observer_rows",
           "summary_text", "answer_text", "stages_text", "cause_shares"]

REPORT_FORMAT = "laser-hazard.report"
REPORT_VERSION = 1


class OutputExistsError(FileExistsError):
    pass


def _num(x):
    x = float(x)
    return x if math.isfinite(x) else None


# observers listed in report.json (highest hazard ratio first beyond it, every hazardous one first); all are in
# observers.csv. 1e4: report.json is the run's summary (a person, a review page, a script's json.load); at 1e5 its
# list was 79 MB at 1e6 observers and as long to write as the whole analysis (issue 37), a copy of observers.csv's rows.
JSON_OBSERVERS_MAX = 10_000

# observers.csv: each column and the observer_columns key it is read from
CSV_COLUMNS = ["name", "x_m", "y_m", "z_m", "static_irradiance_w_m2", "peak_irradiance_w_m2", "direct_irradiance_w_m2",
               "direct_at_aim_irradiance_w_m2", "reflected_irradiance_w_m2", "peak_time_s",
               "radiant_exposure_j_m2", "angular_subtense_rad", "c_e", "mpe_w_m2", "hazard_ratio", "exposure_ratio", "hazardous", "hazardous_static",
               "first_exceedance_s", "line_of_sight", "far_field", "direct_point_irradiance_w_m2", "aperture_diameter_m"]


def observer_columns(result) -> dict:
    """Every per-observer quantity of the report as one array each (computed once: the
    verdict properties of ``result`` are whole-array computations). Results built without
    analyze() fall back to the point-source MPE, no direct beam, and NaN subtense."""
    obs = result.observers
    m = len(obs)
    mpe_h = (obs.mpe_radiant_exposure_j_m2 if obs.mpe_radiant_exposure_j_m2 is not None
             else np.full(m, float(result.mpe_radiant_exposure_j_m2)))
    direct = obs.direct_irradiance_w_m2 if obs.direct_irradiance_w_m2 is not None else np.zeros(m)
    cols = {
        "position_m": _positions(obs) if hasattr(obs, "position_at") else np.asarray(obs.position_m, float).reshape(m, 3),
        "peak_irradiance_w_m2": obs.peak_irradiance_w_m2,
        "direct_irradiance_w_m2": direct,
        "direct_at_aim_irradiance_w_m2": obs.direct_at_aim_irradiance_w_m2 if obs.direct_at_aim_irradiance_w_m2 is not None else direct,
        "reflected_irradiance_w_m2": (obs.reflected_irradiance_w_m2 if obs.reflected_irradiance_w_m2 is not None
                                      else obs.peak_irradiance_w_m2),
        "peak_time_s": obs.peak_time_s,
        "static_irradiance_w_m2": obs.static_irradiance_w_m2,
        "radiant_exposure_j_m2": obs.radiant_exposure_j_m2,
        "static_radiant_exposure_j_m2": obs.static_radiant_exposure_j_m2,
        "angular_subtense_rad": obs.angular_subtense_rad if obs.angular_subtense_rad is not None else np.full(m, np.nan),
        "c_e": obs.c_e if obs.c_e is not None else np.ones(m),
        "mpe_w_m2": obs.mpe_w_m2 if obs.mpe_w_m2 is not None else np.full(m, float(result.mpe_w_m2)),
        "mpe_radiant_exposure_j_m2": mpe_h,
        "hazard_ratio": _ratio(obs.peak_irradiance_w_m2, result.observer_mpe_w_m2),  # result.hazard_ratio, by rows
        "exposure_ratio": _ratio(obs.radiant_exposure_j_m2, mpe_h),
        "hazardous": result.hazardous,
        "hazardous_static": result.hazardous_static,
        "first_exceedance_s": obs.first_exceedance_s,
        "line_of_sight": obs.line_of_sight,
        "far_field": obs.far_field,
        # the direct beam at the eye's centre and the aperture its verdict value is collected over (hazard.physics.aperture)
        "direct_point_irradiance_w_m2": (obs.direct_point_irradiance_w_m2 if getattr(obs, "direct_point_irradiance_w_m2", None)
                                         is not None else direct),
        "aperture_diameter_m": (obs.aperture_diameter_m if getattr(obs, "aperture_diameter_m", None) is not None
                                else np.full(m, np.nan)),
    }
    return _with_tracks(result, cols, m)


class _ByRows:
    """A column made by rows, ``fn(rows)`` (int array or slice), never whole unless asked
    (``np.asarray``: ``whole()``): at 1e7 observers each float column is 80 MB, the
    positions 240 MB (and 240 MB more for the generated points they are made from)."""

    def __init__(self, fn, m: int, whole=None):
        self._fn, self._m = fn, m
        self._whole = whole or (lambda: fn(slice(None)))

    def __len__(self):
        return self._m

    def __getitem__(self, rows):
        return self._fn(rows)

    def __array__(self, dtype=None, copy=None):
        return np.asarray(self._whole(), dtype)


def _positions(obs):
    """The observers' world positions [m] by rows (:meth:`hazard.pipeline.results.ObserverResult.position_at`)."""
    return _ByRows(obs.position_at, len(obs), lambda: obs.position_m)


def _ratio(num, den):
    """``num / den`` by rows (``den`` an array or a scalar): the values of the whole division."""
    if np.ndim(den):
        return _ByRows(lambda rows: num[rows] / den[rows], len(num))
    return _ByRows(lambda rows: num[rows] / den, len(num))


def _at(column, rows):
    """``column[rows]`` (an array, or a :class:`_ByRows` column without the whole of it)."""
    return column[rows] if isinstance(column, _ByRows) else np.asarray(column)[rows]


def _with_tracks(result, cols, m) -> dict:
    """The fixed observers' columns with the moving observers' rows after them (at each
    one's worst point, :mod:`hazard.outputs.motion_outputs`) and the ``motion_*`` columns; the
    row names under ``labels``."""
    cols["labels"] = result.observers.labels  # made by rows when read (hazard.pipeline.results.ObserverLabels)
    if getattr(result, "motion", None) is None:
        return cols
    tracks = track_columns(result, float(result.mpe_w_m2))
    extra = motion_columns(result, m, tracks)
    for k in list(cols):
        cols[k] = list(cols[k]) + tracks[k] if k == "labels" else np.concatenate([np.asarray(cols[k]), tracks[k]])
    cols.update(extra)
    return cols


def listed_rows(cols, m) -> np.ndarray:
    """Rows of report.json's observer list: every one up to ``JSON_OBSERVERS_MAX``, else
    the highest hazard ratios (every hazardous one first), in the scene's order."""
    if m <= JSON_OBSERVERS_MAX:
        return np.arange(m)
    ratio = np.array(cols["hazard_ratio"], float)  # made here, changed in place: the only copy
    np.nan_to_num(ratio, copy=False, nan=np.inf)  # a NaN ratio (unknown) counts as the highest
    over_time = np.asarray(cols["hazardous"], bool)  # hazardous over time (a moving beam) with a static ratio below 1
    ratio[over_time] = np.maximum(ratio[over_time], 1.0)  # ranks with the hazardous ones, which all come first
    return top_rows(ratio, JSON_OBSERVERS_MAX)


def observer_rows(result, rows=None, cols=None) -> list:
    """One dict per observer (``rows``: which; default all) for report.json, JSON-safe
    (:func:`json_safe`'s strings for non-finite values, null where NaN means "not
    applicable"), built column by column."""
    cols = observer_columns(result) if cols is None else cols
    labels = cols["labels"]
    rows = np.arange(len(labels)) if rows is None else rows
    maybe = _JSON_NULL
    keys = [k for k in cols if k not in ("position_m", "labels")]
    columns = [labels.take(rows) if hasattr(labels, "take") else [labels[i] for i in rows.tolist()]]
    for k in ["position_m"] + keys:
        a = _at(cols[k], rows)
        v = a.tolist()  # Python floats and bools, once
        if k in maybe:
            v = [_num(x) for x in v]
        elif a.dtype.kind == "f" and not np.isfinite(a).all():
            v = json_safe(v)
        columns.append(v)
    names = ["name", "position_m"] + keys
    return [dict(zip(names, vals)) for vals in zip(*columns)]


def observers_listed(result, cols) -> tuple[list, dict]:
    """report.json's observer rows and a statement of which are listed."""
    m = len(cols["labels"])
    rows = listed_rows(cols, m)
    return observer_rows(result, rows, cols), _listed_statement(m, len(rows))


def _listed_statement(m: int, n: int) -> dict:
    """report.json's ``observers_listed``: ``n`` of the ``m`` observers listed."""
    return {"count": m, "listed": int(n), "which": "all" if n == m else
            f"the {n} highest hazard ratios (every hazardous observer first); all {m} are in observers.csv"}


def json_safe(obj):
    """Non-finite floats as the strings "inf", "-inf", "nan" (JSON has no such numbers;
    an infinite NOHD - a collimated beam without attenuation - must not vanish)."""
    if isinstance(obj, float) and not math.isfinite(obj):
        return "nan" if math.isnan(obj) else ("inf" if obj > 0 else "-inf")
    if isinstance(obj, dict):
        return {k: json_safe(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [json_safe(v) for v in obj]
    return obj


def _frame(scene) -> FrameDescription:
    """The coordinate frame the report's positions are in (:mod:`scenes.geo` for a site)."""
    site = getattr(scene, "site", None)
    if site is None:
        return FrameDescription(kind="local", statement="the scene's local frame: x, y, z [m] as the scene file gives them "
                                "(no [site]: not placed on the earth)")
    return site.describe()


def report_dict(result, cols=None, *, row_dicts=True, verdict_doc: Verdict | None = None) -> dict:
    """The report as plain data: versions, scene echo and hash, MPE with its steps,
    stages, per-target NOHD and keep-out summaries, per-observer verdicts
    (``cols``: :func:`observer_columns` of ``result`` when the caller has them). With
    ``row_dicts=False`` the ``observers`` entry is the listed rows' indices into ``cols``
    (:func:`report_json_text` writes them from the columns, no dict per row).
    ``verdict_doc``: :func:`hazard.pipeline.verdict.verdict` of ``result`` (a frozen
    :class:`~hazard.pipeline.verdict.Verdict`) when the caller has it (computed once per run: the report, the printed answer and ``--fail-on-hazard``); not changed."""
    from hazard.pipeline.analysis import versions

    scene = result.scene
    fp = {}
    for key, f in (("static", result.footprint_static), ("dynamic", result.footprint_dynamic)):
        if f is not None:
            fp[key] = {"area_m2": f.area_m2, "eye_height_m": f.eye_height_m, "cells": int(f.mask.sum())}
    cols = observer_columns(result) if cols is None else cols
    listed: list | np.ndarray
    if row_dicts:
        listed, which = observers_listed(result, cols)
    else:
        listed = listed_rows(cols, len(cols["labels"]))
        which = _listed_statement(len(cols["labels"]), len(listed))
    v = verdict(result) if verdict_doc is None else verdict_doc
    doc = json_safe({
        "format": REPORT_FORMAT,
        "version": REPORT_VERSION,
        "versions": versions(),
        "scene": {"name": scene.name, "source": scene.source, "sha256": scene.text_sha256,
                  "offset_m": scene.offset_m.tolist(), "echo": scene.echo(),
                  "units_as_written": dict(getattr(scene, "units_as_written", None) or {}),  # scenes.quantities.as_written
                  "beam_conventions": getattr(scene, "beam_conventions", None)},
        "frame": _frame(scene).to_dict(),
        "mpe": result.mpe.to_dict(),
        "pulse": None if result.pulse is None else result.pulse.to_dict(),
        "mpe_w_m2": result.mpe_w_m2,
        "uv_24h": None if result.uv_24h is None else result.uv_24h.to_dict(),  # UV: the day's summed-dose limit (hazard.physics.mpe.UV24hResult)
        "extended_source": ({"applied": False} if getattr(result, "extended_source", None) is None
                            else result.extended_source.to_dict()),  # hazard.pipeline.extended_source.ExtendedSourceSummary
        "attenuation_per_m": result.attenuation_per_m,
        "limiting_aperture": limiting_aperture(scene.spec.laser.wavelength_nm, scene.spec.exposure.duration_s).to_dict(),
        "beam": {"power_w": result.beam_power_w, "spill_w": result.spill_w, "blocked_w": result.blocked_w,
                 "sampling": None if getattr(result, "beam_sampling", None) is None else result.beam_sampling.to_dict(),
                 "spill": None if getattr(result, "spill", None) is None else result.spill.to_dict()},
        "sdz": None if getattr(result, "sdz", None) is None else result.sdz.to_dict(),  # hazard.pipeline.sdz.DangerZone
        "stages": [s.to_dict() for s in result.stages],
        "times_s": {"start": float(result.times_s[0]), "end": float(result.times_s[-1]), "count": int(len(result.times_s))},
        "targets": [{**t.to_dict(), "hit": target_hit(t)} for t in result.targets],
        "footprint": fp or None,
        "observers": None,  # the listed rows below: JSON-safe already (observer_rows), not walked again
        "observers_listed": which,
        "verdict_changes": result.verdict_changes(),
        "verdict": v.to_dict(),  # the headline stdout and the review page print (hazard.pipeline.verdict.Verdict)
        "hazard_at_observers": v.hazard_at_observers,  # a listed observer, track or flight zone at or above its limit
        "hazard_zones": v.hazard_zones,  # a danger zone, mirror beam or keep-out lobe not contained or beyond the range
        "any_hazard": v.any_hazard,  # either, or any NOHD > 0 even contained (the old flag, kept for compatibility)
        "warnings": list(v.warnings),  # plausibility warnings (hazard.pipeline.plausibility): each can change the verdict
        "notes": list(result.notes),
        **motion_sections(result),
    })
    doc["observers"] = listed
    return doc


_MOTION_BLANK = MOTION_COLUMNS  # the motion_* columns: NaN where a fixed observer was not evaluated over time
_CSV_BLANK_NAN = {"angular_subtense_rad", "first_exceedance_s", "aperture_diameter_m", "direct_point_irradiance_w_m2", *_MOTION_BLANK}  # NaN there means "not applicable": an empty cell


def csv_cell(values, key) -> list:
    """One observers.csv column ``key`` as text (:func:`hazard.outputs.csv_text.column_text`): NaN
    an empty cell where it means "not applicable" (the keys of ``_CSV_BLANK_NAN``)."""
    return column_text(values, blank_nan=key in _CSV_BLANK_NAN)


def _csv_names(labels: list) -> list:
    """:func:`_csv_name` of each label (one scan of the joined text when none needs quotes)."""
    if not any(c in "\0".join(labels) for c in ',"\r\n'):
        return list(labels)
    return [_csv_name(x) for x in labels]


def _csv_name(label: str) -> str:
    """A name as the csv module writes it (quoted only when it holds , " or a line break)."""
    if any(c in label for c in ',"\r\n'):
        return '"' + label.replace('"', '""') + '"'
    return label


# observers.csv rows formatted at once (~8 MB of bytes by orjson and pyarrow), the text joined CSV_JOIN_ROWS rows at a
# time (4 MB pieces: one 8 MB text cost more system time than it saved, freed to the kernel and faulted in again; the
# other writers' blocks CSV_JOIN_ROWS rows at a time too, ~25 MB of Python text objects by the reprs). 32 768 rows
# spread a block's fixed costs (its columns' checks, ~30 calls, the GIL hand-overs around them) over twice the rows
# of 16 384: at 1e6 observers, the whole outputs, median of 9 alternated in one process, load 4-5, 0.89-1.09 ->
# 0.80-0.86 s CPU. 65 536 cut the user CPU again (0.70-0.77 -> 0.60-0.66 s) but its blocks' memory went back to the
# kernel and was faulted in again (text and write at 1e6: 2 250 -> 16 540 minor faults, 0.08 -> 0.23 s system).
CSV_BLOCK_ROWS = 32_768
CSV_JOIN_ROWS = 16_384


def _csv_chunks(result, cols, block_rows: int = CSV_BLOCK_ROWS, threads: int = 2):
    """observers.csv as bytes-like pieces: the header, then ``block_rows`` observers at a time (every
    observer, one row each, each column formatted from its array); with a [site], each
    position also as latitude, longitude and height. The bytes of the whole table at once;
    the memory of a few blocks (formatted on ``threads`` threads, :func:`_in_order`). Each block by pyarrow's CSV writer when it is installed
    (:func:`_arrow_block`), else by Python's reprs (:func:`_repr_block`): the same numbers."""
    pos = cols["position_m"]
    site = getattr(result.scene, "site", None) is not None and len(pos)
    rest = CSV_COLUMNS[4:] + [k for k in _MOTION_BLANK if k in cols]
    yield (",".join(CSV_COLUMNS[:4] + (GEO_COLUMNS if site else []) + rest) + "\r\n").encode()
    arrow = _arrow()
    tools = row_tools() if arrow else None

    def columns(a0, a1):  # the columns of rows a0:a1, on this thread (the geodetic transform included)
        p = pos[a0:a1]
        values = [p[:, 0], p[:, 1], p[:, 2]]
        if site:
            geo = observer_geodetic(result, p)
            values += [geo[:, 0], geo[:, 1], geo[:, 2]]
        return values + [_at(cols[k], slice(a0, a1)) for k in rest], ["x"] * len(values) + rest

    def other(a0, a1):  # rows a0:a1 by pyarrow's CSV writer, or by Python's reprs where a name needs quotes
        values, keys = columns(a0, a1)
        names = _arrow_names(arrow, cols["labels"], a0, a1) if arrow else None
        if names is None:
            return _repr_block, (cols["labels"][a0:a1], values, keys)
        return _arrow_block, (arrow, names, values, keys)

    def block(a0):
        a1 = min(a0 + block_rows, len(pos))
        if tools is not None and (names := _name_parts(tools, arrow, cols["labels"], a0, a1)) is not None:
            return _joined_block, (tools, names, *columns(a0, a1))
        return _each, ([other(b0, min(b0 + CSV_JOIN_ROWS, a1)) for b0 in range(a0, a1, CSV_JOIN_ROWS)],)  # their memory

    for piece in _in_order((block(a0) for a0 in range(0, len(pos), block_rows)), threads=threads if arrow else 0):
        yield from piece if isinstance(piece, list) else (piece,)  # a block's pieces


def _each(jobs) -> list:
    """``fn(*args)`` of each ``(fn, args)`` of ``jobs`` in turn: a block's text by the other writers, ``CSV_JOIN_ROWS``
    rows at a time (the Python text objects of one piece at a time, ~25 MB by the reprs)."""
    return [fn(*args) for fn, args in jobs]


def _in_order(jobs, threads: int):
    """``fn(*args)`` of each ``(fn, args)`` of ``jobs``, in order, on up to ``threads``
    threads (pyarrow's joins run without the GIL) with at most ``2 threads`` results
    waiting: the memory of a few blocks. One thread: the blocks made ahead while the
    consumer writes the last; 0 (or a process limited to one thread): made here."""
    from brdfmodels.parallel import default_threads

    if threads <= 0 or default_threads() <= 1:
        for fn, args in jobs:
            yield fn(*args)
        return
    threads = min(threads, default_threads())
    from collections import deque
    from concurrent.futures import ThreadPoolExecutor

    with ThreadPoolExecutor(threads) as pool:
        ahead: deque = deque()
        for fn, args in jobs:
            ahead.append(pool.submit(fn, *args))
            if len(ahead) > 2 * threads:
                yield ahead.popleft().result()
        while ahead:
            yield ahead.popleft().result()


def _repr_block(labels, values, keys) -> bytes:
    """Rows of observers.csv by Python's float reprs (:func:`csv_cell`)."""
    text = [_csv_names(labels)] + [csv_cell(v, k) for v, k in zip(values, keys)]
    return ("\r\n".join([",".join(r) for r in zip(*text)]) + "\r\n").encode()


def _arrow():
    """(pyarrow, pyarrow.compute, pyarrow.csv), or None when pyarrow is not installed."""
    try:
        import pyarrow
        import pyarrow.compute
        import pyarrow.csv
    except ImportError:
        return None
    return pyarrow, pyarrow.compute, pyarrow.csv


def _arrow_names(arrow, labels, a0, a1):
    """The names of rows ``a0:a1`` as a pyarrow string array, or None where one needs
    quotes (a comma, quote or line break in a group's name: the repr writer quotes it).
    Names of a grid group made as ``group[i]`` from the row's group and index."""
    pa, _, _ = arrow
    obs = getattr(labels, "observers", None)
    if obs is None:  # a list (the moving observers' rows appended)
        names = list(labels[a0:a1])
        return None if any(c in "\0".join(names) for c in ',"\r\n') else pa.array(names, pa.string())
    if any(c in n for n in obs.group_names for c in ',"\r\n'):
        return None
    return _group_names(arrow, obs, slice(a0, a1), list(obs.group_names))


def _group_names(arrow, obs, rows, bases: list):
    """Names of the observer table ``obs``'s rows ``rows`` (slice or int array) as a pyarrow
    string array: ``bases[g]`` for a group of one point, else ``bases[g]`` + ``[i]``
    (``bases``: each group's name, or its JSON text without the closing quote,
    :func:`_json_names`)."""
    pa, pc, _ = arrow
    g = obs.group[rows]
    index = pc.cast(pa.array(obs.index_in_group[rows]), pa.string())
    if len(g) and (g == g[0]).all() and obs.group_sizes[g[0]] > 1:  # rows of one grid (the common block): no take, no choice
        return pc.binary_join_element_wise(bases[g[0]] + "[", index, "]", "")
    base = pa.array(bases, pa.string()).take(pa.array(g))
    indexed = pc.binary_join_element_wise(base, "[", index, "]", "")
    return pc.if_else(pa.array(obs.group_sizes[g] == 1), base, indexed)


def _json_names(arrow, labels, rows):
    """The names of rows ``rows`` as JSON strings (``json.dumps`` of each), made from the
    groups' names (each escaped once) when ``labels`` is the observer table's."""
    pa, pc, _ = arrow
    obs = getattr(labels, "observers", None)
    if obs is None:
        names = labels.take(rows) if hasattr(labels, "take") else [labels[i] for i in rows.tolist()]
        return pa.array([json.dumps(n) for n in names], pa.string())
    bases = [json.dumps(n)[:-1] for n in obs.group_names]  # the closing quote after the index
    return pc.binary_join_element_wise(_group_names(arrow, obs, rows, bases), '"', "")


def _name_parts(tools, arrow, labels, a0, a1):
    """The names of rows ``a0:a1`` as parts of :func:`hazard.outputs.row_text.joined_rows`
    (a list), or None where one needs quotes: a block of one grid as its name + ``[`` and
    the indices (an integer array: a column of :func:`_joined_block`, followed by ``]``; no
    joined name array), else :func:`_arrow_names`."""
    obs = getattr(labels, "observers", None)
    if obs is not None and a1 > a0:
        g = obs.group[a0:a1]
        name = obs.group_names[g[0]]
        if obs.group_sizes[g[0]] > 1 and (g == g[0]).all() and not any(c in name for c in ',"\r\n'):
            return [name + "[", np.asarray(obs.index_in_group[a0:a1])]  # the indices a column of their own
    names = _arrow_names(arrow, labels, a0, a1)
    return None if names is None else [names]


def _joined_block(tools, names, values, keys):
    """Rows of observers.csv made column by column (:mod:`hazard.outputs.row_text`, with
    orjson and pyarrow): ``names`` (parts, :func:`_name_parts`), floats in orjson's shortest
    text that reads back as the same double (``1.0``, ``-0.0``, ``0.00001``, ``1e-7``,
    ``1e16``), nan and inf as repr writes them, an empty cell where NaN means "not
    applicable", True/False. A list of bytes-like pieces, ``CSV_JOIN_ROWS`` rows each
    (:func:`hazard.outputs.row_text.joined_pieces`)."""
    blank = CSV_TEXTS._replace(nan="")
    columns = [(v, blank if k in _CSV_BLANK_NAN else CSV_TEXTS) for v, k in zip(values, keys)]
    afters = [","] * (len(columns) - 1) + ["\r\n"]
    if isinstance(names[-1], np.ndarray):  # a grid's indices: a column followed by "],"
        head, columns, afters = names[:-1], [(names[-1], CSV_TEXTS)] + columns, ["],"] + afters
    else:
        head = [*names, ","]
    return joined_pieces(tools, column_parts(tools, columns, afters, head), len(values[0]), CSV_JOIN_ROWS)


_ARROW_OPTIONS = {"include_header": False, "quoting_style": "none", "eol": "\r\n"}


def _arrow_block(arrow, names, values, keys):
    """Rows of observers.csv by pyarrow's CSV writer: floats in their shortest text that
    reads back as the same double (``1``, ``-0``, ``0.00001``, ``1e+15``; Python's repr
    writes ``1.0``, ``-0.0``, ``1e-05``, ``1000000000000000.0``), nan and inf as repr does,
    an empty cell where NaN means "not applicable", True/False. A column with the bits of
    an earlier one (peak = static = reflected in a static scene) is formatted once, and
    one that has an earlier one's bits in most rows only in the others (the exposure ratio
    H / MPE_H is the hazard ratio E / MPE in 78 % of the rows of a static scene)."""
    pa, pc, csv = arrow
    arrays, done = [names], []
    for v, k in zip(values, keys):
        v = np.asarray(v)
        v = v.view(np.int8) if v.dtype == bool else np.ascontiguousarray(v, float)
        key = (v.dtype, k in _CSV_BLANK_NAN)
        same = [a for (w, kw, a) in done if kw == key and np.array_equal(w[:64], v[:64]) and np.array_equal(w.view(np.int8), v.view(np.int8))]
        if same:
            arrays.append(same[0])
            continue
        if v.dtype == np.int8:
            a = pc.if_else(pa.array(v.view(bool)), "True", "False")
        else:
            near = [(w, a) for (w, kw, a) in done if kw == key and np.count_nonzero(w[:64].view(np.int64) == v[:64].view(np.int64)) * 2 > min(len(v), 64)]
            a = _arrow_floats_like(arrow, v, key[1], *near[0]) if near else _arrow_floats(arrow, v, key[1])
        done.append((v, key, a))
        arrays.append(a)
    table = pa.Table.from_arrays(arrays, names=[str(i) for i in range(len(arrays))])
    sink = pa.BufferOutputStream()
    csv.write_csv(table, sink, csv.WriteOptions(**_ARROW_OPTIONS))
    return sink.getvalue()  # a pyarrow Buffer: bytes-like, written without a copy


def _arrow_floats(arrow, v: np.ndarray, blank: bool):
    """A float64 column for pyarrow's writer as a plain string array (NaN as null, an empty
    cell, where ``blank``). A column whose values repeat (grid coordinates, a constant MPE)
    has its distinct values (told apart by their bits: -0.0 is not 0.0) formatted once and
    taken by index: the writer is about twice as slow on a dictionary array as on the same
    text decoded (measured per 16 384-row block: 10.6 against 5.9 ms)."""
    pa, pc, _ = arrow
    nulls = _validity(np.isnan(v)) if blank else None
    bits = v.view(np.int64)
    if len(bits) and (bits == bits[0]).all():  # one value (a constant MPE, an unused column): one text, repeated
        return _repeated(pa, pc.cast(pa.array(v[:1]), pa.string())[0].as_py(), len(v), nulls)
    sample = bits[::max(1, len(bits) // 2048)]  # spread over the block (a grid's x repeats row by row)
    if len(np.unique(sample)) * 10 > 9 * len(sample):  # mostly distinct: every value formatted
        text = pc.cast(pa.array(v), pa.string())
    else:
        enc = pc.dictionary_encode(pa.array(bits))  # by hashing, in one pass
        text = pc.cast(pa.array(enc.dictionary.to_numpy().view(np.float64)), pa.string()).take(enc.indices)
    if nulls is None:
        return text
    return pa.StringArray.from_buffers(len(text), text.buffers()[1], text.buffers()[2], nulls, offset=text.offset)


def _arrow_floats_like(arrow, v: np.ndarray, blank: bool, w: np.ndarray, w_text):
    """:func:`_arrow_floats` of ``v``, the rows where it has the bits of ``w`` (whose text is
    ``w_text``) taken from ``w_text``, the others formatted (all of them when under half match)."""
    pa, _, _ = arrow
    differ = np.flatnonzero(v.view(np.int64) != w.view(np.int64))
    if 2 * len(differ) > len(v):
        return _arrow_floats(arrow, v, blank)
    index = np.arange(len(v))
    index[differ] = len(v) + np.arange(len(differ))
    return pa.concat_arrays([w_text, _arrow_floats(arrow, v[differ], blank)]).take(pa.array(index))


def _validity(null: np.ndarray):
    """An Arrow validity bitmap (bit set: a value) of the rows not ``null``, or None when every row has a value."""
    if not null.any():
        return None
    import pyarrow

    return pyarrow.py_buffer(np.packbits(~null, bitorder="little"))


def _repeated(pa, text: str, n: int, nulls=None):
    """A string array of ``n`` copies of ``text`` (made from its bytes, not by a writer per value)."""
    b = np.frombuffer(text.encode(), np.uint8)
    offsets = np.arange(n + 1, dtype=np.int32) * np.int32(len(b))
    return pa.StringArray.from_buffers(n, pa.py_buffer(offsets), pa.py_buffer(np.tile(b, n)), nulls)


def _csv_text(result, cols) -> str:
    """observers.csv as one text (:func:`_csv_chunks` joined)."""
    return b"".join(_csv_chunks(result, cols)).decode()


def _write_csv_synced(path: Path, result, cols, stop=None, threads: int = 2) -> None:
    """observers.csv written block by block into ``path`` and fsynced (:func:`write_synced`: past
    the page cache where the system allows), the blocks made on ``threads`` threads
    (:func:`_in_order`); ``stop`` (a :class:`threading.Event`): set, the writing ends after the
    block under way (the staging folder of a failed run is discarded: no partial table is ever
    switched in)."""
    write_synced(path, _csv_chunks(result, cols, threads=threads), stop=stop)


class CsvWriting:
    """observers.csv of ``result`` written into ``folder`` on a worker thread
    (:func:`csv_started`) while the caller makes the other outputs on its own: the map
    files and report.json are Python work holding the GIL, the table's joins, writes and
    fsync run without it. Two more threads make the table's blocks ahead of the writer
    from the start (once the file went past the page cache, holding one back while the
    caller worked cost wall time: at 1e6 observers, medians of 7-9 alternated, load 1.2-2.6,
    0.694 -> 0.614, 0.770 -> 0.717, 1.091 -> 1.031 s). :meth:`wait` returns when the file is
    written and synced, and raises the writer's error, if any."""

    def __init__(self, result, folder):
        import threading

        self.cols = observer_columns(result)  # once, for the table and the report (write_set)
        self.path = Path(folder) / "observers.csv"
        self._stop = threading.Event()
        self._error: BaseException | None = None
        self._thread = threading.Thread(target=self._run, args=(result,), name="observers.csv", daemon=True)
        self._thread.start()

    def _run(self, result) -> None:
        try:
            _write_csv_synced(self.path, result, self.cols, self._stop, threads=2)  # this thread writes
        except BaseException as exc:  # handed to the caller's wait()
            self._error = exc

    def wait(self) -> None:
        self._thread.join()
        if self._error is not None:
            raise self._error

    def stop(self) -> None:
        """End the writing early (the caller failed) and wait for the thread: nothing
        writes into the staging folder after this returns."""
        self._stop.set()
        self._thread.join()


@contextmanager
def csv_started(result, folder):
    """Start writing observers.csv of ``result`` into ``folder`` (a staging folder) on a
    worker thread; yields the :class:`CsvWriting` for :func:`write_set` (``csv=``). Leaving
    the block by an error stops the writer before the error goes on (the staging folder is
    discarded with it); leaving it normally waits for the file."""
    job = CsvWriting(result, folder)
    try:
        yield job
    except BaseException:
        job.stop()
        raise
    job.wait()


def report_json_text(doc: dict, cols=None) -> str:
    """report.json's text: indented one space per level, each listed observer's row on one
    line by json's C encoder (the indented encoding runs the per-element Python encoder:
    most of the writing at 1e5 listed observers). The same values; only the layout of
    the ``observers`` list differs from ``json.dumps(doc, indent=1)``. ``doc["observers"]``
    may be the listed rows' indices into the columns ``cols`` (:func:`report_dict` with
    ``row_dicts=False``): the rows are then written from the columns (:func:`_rows_json`)."""
    return b"".join(report_json_pieces(doc, cols)).decode()


def report_json_pieces(doc: dict, cols=None) -> list:
    """:func:`report_json_text` as UTF-8 pieces (bytes) to write one after another: the
    listed rows' text is not copied into one string with the rest."""
    import uuid

    mark = json.dumps(f"observers-{uuid.uuid4().hex}")
    before, after = json.dumps({**doc, "observers": json.loads(mark)}, indent=1, allow_nan=False).split(mark, 1)
    listed = doc["observers"]
    if isinstance(listed, np.ndarray):
        rows = _rows_json(cols, listed)
    else:
        rows = ",".join("\n  " + json.dumps(r, allow_nan=False) for r in listed).encode()
    if not rows:
        return [(before + "[]" + after).encode()]
    return [(before + "[").encode(), rows, ("\n ]" + after).encode()]


_JSON_TEXTS = CellTexts("true", "false", '"nan"', '"inf"', '"-inf"')  # as json_safe makes them (row_text's cells)
_JSON_NULL_TEXTS = CellTexts("true", "false", "null", "null", "null")  # not applicable: null
_JSON_NULL = {"angular_subtense_rad", "first_exceedance_s", "aperture_diameter_m", "direct_point_irradiance_w_m2",
              *MOTION_COLUMNS}  # NaN (or inf) there means "not applicable": JSON null


def _rows_json(cols, rows):
    """The rows ``rows`` of ``cols`` as report.json lists them (UTF-8 bytes-like) (``",\\n  "`` before each,
    the text of ``json.dumps`` of :func:`observer_rows`' dicts): by pyarrow when installed
    (each float's shortest round-trip digits, ``.0`` added where they read as an integer:
    json.loads gives the same float), else by json's encoder row by row."""
    arrow = _arrow()
    keys = [k for k in cols if k not in ("position_m", "labels")]
    values = {k: _at(cols[k], rows) for k in keys}
    if arrow is None or not len(rows) or any(v.dtype.kind not in "fbiu" for v in values.values()):
        return ",".join("\n  " + json.dumps(r, allow_nan=False) for r in observer_rows(None, rows, cols)).encode()
    pos = _at(cols["position_m"], rows)
    parts = ["\n  {\"name\": ", _json_names(arrow, cols["labels"], rows), ", \"position_m\": ["]
    if (tools := row_tools()) is not None:  # every column's cells by orjson, each with the separator after it
        columns = [(pos[:, 0], _JSON_TEXTS), (pos[:, 1], _JSON_TEXTS), (pos[:, 2], _JSON_TEXTS)]
        columns += [(values[k], _JSON_NULL_TEXTS if k in _JSON_NULL else _JSON_TEXTS) for k in keys]
        afters = [", ", ", "] + [f"], {json.dumps(k)}: " for k in keys[:1]] + [f", {json.dumps(k)}: " for k in keys[1:]] + ["},"]
        afters[2] = afters[2] if keys else "]},"
        return joined_rows(tools, column_parts(tools, columns, afters, parts), len(rows), drop_last=1)  # the last row's comma off
    columns = [(pos[:, 0], False), (pos[:, 1], False), (pos[:, 2], False)] + [(values[k], k in _JSON_NULL) for k in keys]
    before = ["", ", ", ", "] + [f"], {json.dumps(keys[0])}: "] * bool(keys) + [f", {json.dumps(k)}: " for k in keys[1:]]
    done: list = []  # (values, null, text) of the columns formatted so far
    for (v, null), sep in zip(columns, before):  # the text before each column ("]" closes the position)
        v = np.ascontiguousarray(v)
        b = v.view(np.int8).reshape(len(v), -1)
        same = [t for (w, nw, t) in done if nw == null and w.dtype == v.dtype and np.array_equal(w.view(np.int8), v.view(np.int8))]
        if same:
            text = same[0]
        elif (b == b[0]).all():  # one value throughout (a constant MPE, an unused column): its text once
            text = _json_numbers(arrow, v[:1], null)[0].as_py()
        else:
            text = _json_numbers(arrow, v, null)
        done.append((v, null, text))
        parts += [sep, text]
    parts.append("]},"[len(keys) > 0:])
    return _joined_rows(arrow, parts)


def _joined_rows(arrow, parts: list):
    """The rows' text (bytes-like, no copy, the last row's trailing comma off): ``parts``
    (pyarrow string arrays, at least one, and str: literal text and constant columns)
    joined row by row, consecutive str joined first (fewer parts per row: the joins of the
    1e5 listed rows of the 1e6-observer benchmark 0.13 -> 0.07 s CPU, the rows 0.38 -> 0.18 s)."""
    _, pc, _ = arrow
    merged: list = []
    for p in parts:
        if isinstance(p, str) and merged and isinstance(merged[-1], str):
            merged[-1] += p
        else:
            merged.append(p)
    text = pc.binary_join_element_wise(*merged, "")
    off = np.frombuffer(text.buffers()[1], np.int32)[text.offset:text.offset + len(text) + 1]
    return text.buffers()[2].slice(int(off[0]), int(off[-1] - 1 - off[0]))  # bytes-like, no copy; the last row's comma off


def _json_numbers(arrow, a: np.ndarray, null: bool):
    """A column's values as JSON text, as :func:`observer_rows` makes them: bools
    true/false, integers, floats exactly; a non-finite float null where ``null`` (not
    applicable), else the string "inf", "-inf" or "nan"."""
    pa, pc, _ = arrow
    if a.dtype.kind == "b":
        return pc.if_else(pa.array(a), "true", "false")
    if a.dtype.kind in "iu":
        return pc.cast(pa.array(a), pa.string())
    v = np.ascontiguousarray(a, float)
    text = pc.cast(pa.array(v), pa.string())
    finite = np.isfinite(v)
    whole = np.flatnonzero(finite & (v == np.trunc(v)))  # "1", "-0", "16791", or "1e+15" (a float to json already)
    if len(whole):
        plain = ~pc.match_substring(text.take(pa.array(whole)), "e").to_numpy(zero_copy_only=False)
        dot = np.zeros(len(v), bool)
        dot[whole[plain]] = True
        text = pc.binary_join_element_wise(text, pc.if_else(pa.array(dot), ".0", ""), "")
    if finite.all():
        return text
    if null:
        return pc.if_else(pa.array(finite), text, "null")
    other = np.where(np.isnan(v), '"nan"', np.where(v > 0, '"inf"', '"-inf"'))
    return pc.if_else(pa.array(finite), text, pa.array(other, pa.string()))


def write_set(result, folder, *, extra=None, sections=None, verdict_doc: Verdict | None = None,
              csv: CsvWriting | None = None) -> list:
    """Write report.json, observers.csv and the files of ``extra`` (name -> bytes) into
    ``folder`` (a staging folder of :class:`brdfmodels.output_sets.OutputUnit`), each fsynced;
    returns the names written. ``verdict_doc``: the run's verdict, when the caller has it
    (:func:`report_dict`). observers.csv is written on a worker thread while report.json
    is made and the other files written (:func:`csv_started`); ``csv``: that writer,
    started by the caller before it made ``extra`` (the map files), else started here."""
    if csv is None:
        with csv_started(result, folder) as job:
            return write_set(result, folder, extra=extra, sections=sections, verdict_doc=verdict_doc, csv=job)
    folder = Path(folder)
    if csv.path.parent != folder:
        raise ValueError(f"csv: observers.csv is being written into {csv.path.parent}; expected the folder {folder}")
    extra = {**track_files(result), **dict(extra or {})}
    names = ("report.json", "observers.csv") + tuple(extra)
    cols = csv.cols  # once, for the report and the table
    doc = report_dict(result, cols, row_dicts=False, verdict_doc=verdict_doc)  # the listed rows written from the columns
    doc.update(json_safe(dict(sections or {})))
    texts = {"report.json": report_json_pieces(doc, cols), **extra}
    mask = current_umask()  # read, not set: the process's mask never changes
    for n in names:
        if n == "observers.csv":  # written by blocks of rows from the columns, on the writer's thread
            continue
        write_synced(folder / n, texts[n])
        os.chmod(folder / n, 0o666 & ~mask)
    csv.wait()
    os.chmod(csv.path, 0o666 & ~mask)
    if (arrow := _arrow()) is not None:
        arrow[0].default_memory_pool().release_unused()  # the writers' text buffers back to the system
    return list(names)


def write_outputs(result, outdir, *, force=False, extra=None, sections=None) -> list:
    """Write report.json and observers.csv into ``outdir`` (created if needed), as one unit,
    with the files of ``extra`` (name -> bytes, e.g. ``plan.png``) in the same unit, and
    the report's further ``sections`` (key -> data, e.g. ``map_outputs``).

    The files are written into a staging folder beside ``outdir`` and switched in as one
    unit (:mod:`brdfmodels.output_sets`): ``outdir`` holds the previous complete set or the new
    one, never a mix. Previous outputs of ``hazard run`` need ``force``; files hazard did
    not write need ``force`` too and are kept. Returns the paths of the outputs.
    """
    from brdfmodels.output_sets import OutputFolderError, output_unit

    out = Path(outdir)
    if out.exists() and not out.is_dir():
        raise OutputExistsError(f"{out} exists and is not a folder")
    try:
        with output_unit(out, command="run", overwrite=force, force=force) as unit:
            names = write_set(result, unit.stage, extra=extra, sections=sections)
    except OutputFolderError as exc:
        raise OutputExistsError(str(exc)) from None
    return [out / n for n in names]


# -- the text summary of ``hazard run``: the answer first, the stage log on request ------
ANSWER_MAX_OBSERVERS = 20  # hazardous observers listed by name; the rest are counted (all are in observers.csv)
NEVER_MODELLED = ("multiple bounces", "transmission through windows", "diffraction",
                  "vaporisation or burn-through of the target")


def _nearest_spot(result, idx):
    """Distance [m] from observers ``idx`` to the nearest spot's centroid (the nearest
    target's centre when no spot is lit), and that target's name, per observer."""
    scene = result.scene
    if result.spots:
        centres = [scene.to_world(sp.centroid) for sp in result.spots]
        names = [sp.target.name for sp in result.spots]
    else:
        centres = [scene.to_world(t.center_m) for t in scene.targets]
        names = [t.name for t in scene.targets]
    if not centres:
        return np.full(len(idx), np.nan), [""] * len(idx)
    d = np.linalg.norm(result.observers.position_at(idx)[:, None, :] - np.asarray(centres)[None], axis=2)
    k = d.argmin(axis=1)
    return d[np.arange(len(idx)), k], [names[j] for j in k]


def _from_laser(result, idx) -> np.ndarray:
    """Distance [m] from observers ``idx`` to the laser's aperture."""
    laser = np.asarray(result.scene.to_world(result.scene.laser_position_m), float)
    return np.linalg.norm(result.observers.position_at(idx) - laser, axis=1)


CAUSE_SHARE_MIN = 0.01  # a contribution under this fraction of an observer's peak irradiance is left out of "cause"


def cause_shares(result, i) -> list:
    """Observer ``i``'s peak irradiance by cause: ``[(name, fraction of the peak), ...]``
    for the direct beam, the diffuse reflection (BRDF lobes, glossy included) and the
    specular one (mirror beams), largest first, each above ``CAUSE_SHARE_MIN``. The
    reflection is split at its peak: specular = min(mirror lobes' peak, reflected
    peak), diffuse = the rest; "reflection" when the split was not computed."""
    obs = result.observers
    peak = float(obs.peak_irradiance_w_m2[i])
    if not peak > 0:
        return []
    direct = 0.0 if obs.direct_irradiance_w_m2 is None else min(float(obs.direct_irradiance_w_m2[i]), peak)
    reflected = peak - direct
    at_aim = obs.direct_at_aim_irradiance_w_m2
    beam = ("direct beam" if at_aim is None or float(at_aim[i]) >= direct
            else "direct beam within its pointing error / sector / aim track")
    if obs.specular_irradiance_w_m2 is None:
        parts = [(beam, direct), ("reflection", reflected)]
    else:
        spec = min(max(float(obs.specular_irradiance_w_m2[i]), 0.0), reflected)
        parts = [(beam, direct), ("diffuse", reflected - spec), ("specular", spec)]
    parts = [(n, e / peak) for n, e in parts if e / peak > CAUSE_SHARE_MIN]
    return sorted(parts, key=lambda p: -p[1])


def _cause(result, i) -> str:
    """Why observer ``i`` is hazardous: each contribution above 1 % of its peak with its
    share (``diffuse 99.9 %``, :func:`cause_shares`), and whether the dynamic material
    raised the peak above the static one; "over time" when only the motion analysis
    finds it hazardous (a moving beam or target)."""
    obs = result.observers
    peak, static = float(obs.peak_irradiance_w_m2[i]), float(obs.static_irradiance_w_m2[i])
    shares = cause_shares(result, i)
    kind = " + ".join(f"{n} {100 * f:.3g} %" for n, f in shares) if shares else "nothing at the static peak"
    if not float(result.hazard_ratio[i]) >= 1.0:  # hazardous over time only (a moving beam or target)
        return f"over time (the beam or a target moves; the static peak, under the MPE: {kind})"
    if peak > static:
        mpe = result.observer_mpe_w_m2
        ratio_static = static / float(mpe if np.ndim(mpe) == 0 else mpe[i])
        return f"{kind}, dynamic (static material: ratio {ratio_static:.3g})"
    return f"{kind}, static"


def _warning_lines(warnings) -> list:
    """The plausibility warnings, above the verdict (each can change it)."""
    if not warnings:
        return []
    return ([f"CHECK FIRST: {len(warnings)} warning(s) that can change the verdict (also in report.json 'warnings'):"]
            + [f"  warning: {w}" for w in warnings])


def _metres(d) -> str:
    """A distance [m] for the table: whole metres from 100 m (no exponent: 11500, not
    1.15e+04), three significant digits below."""
    return f"{d:.0f}" if d >= 100 else f"{d:.3g}"


def _observer_table(result, hazardous, max_observers) -> list:
    """The hazardous observers, highest hazard ratio first: distance from the laser and
    from the nearest spot, the spot, the cause with its shares."""
    obs, ratio = result.observers, result.hazard_ratio
    order = hazardous[np.argsort(-ratio[hazardous], kind="stable")][:max_observers]
    dist, near = _nearest_spot(result, order)
    laser = _from_laser(result, order)
    labels = obs.labels.take(np.asarray(order, np.int64))
    w_obs, w_spot = max(map(len, labels + ["observer"])), max(map(len, near + ["nearest spot"]))
    lines = [f"  {'observer':{w_obs}s}  {'hazard ratio':>12s}  {'from laser [m]':>14s}  {'from spot [m]':>13s}  "
             f"{'nearest spot':{w_spot}s}  cause (share of the peak irradiance)"]
    for i, label, dl, d, name in zip(order, labels, laser, dist, near):
        lines.append(f"  {label:{w_obs}s}  {ratio[i]:12.4g}  {_metres(dl):>14s}  {_metres(d):>13s}  {name:{w_spot}s}  "
                     f"{_cause(result, i)}")
    if len(hazardous) > len(order):
        lines.append(f"  ... and {len(hazardous) - len(order)} more hazardous observer point(s) (all in observers.csv)")
    return lines


UNITS_SHOWN = 8  # values written with units echoed in the answer (all of them in report.json scene.units_as_written)


def _units_lines(scene) -> list:
    """The values the scene wrote with units, as read (issue 31: a slip is visible in the answer)."""
    written = as_written_lines(scene) if getattr(scene, "units_as_written", None) else []
    if not written:
        return []
    more = f"; ... and {len(written) - UNITS_SHOWN} more (report.json scene.units_as_written)" if len(written) > UNITS_SHOWN else ""
    return [f"  units as written: {'; '.join(written[:UNITS_SHOWN])}{more}"]


def _observer_lines(result, max_observers, v=None) -> list:
    """The warnings, the verdict's headline (:func:`hazard.pipeline.verdict.verdict`: the same text
    as report.json's and the review page's), the MPE, the zones not contained and the
    hazardous observers."""
    v = verdict(result) if v is None else v
    mpe = (f"{result.mpe_w_m2:.6g} W/m^2, {result.mpe.standard}, {result.mpe.duration_s:g} s"
           + (", C_E per observer" if getattr(getattr(result, "extended_source", None), "applied", False) else ""))
    static = f"; hazardous with the static material: {int(np.sum(result.hazardous_static))}" if result.states else ""
    lines = _warning_lines(v.warnings) + [f"Scene {result.scene.name!r}: {v.headline}.", f"  MPE {mpe}{static}"]
    beam = beam_headline(getattr(result.scene, "beam_conventions", None))
    lines += [f"  {beam}"] if beam else []
    lines += _units_lines(result.scene)
    lines += [f"  zone: {z}" for z in v.zones]
    hazardous = np.flatnonzero(result.hazardous)
    if not len(hazardous):
        return lines + ["  The observers are only the points the scene lists: anyone inside a NOHD below is at risk."]
    return lines + _observer_table(result, hazardous, max_observers)


WING_FRACTION = 1e-6  # a target where the beam's profile is below this of its on-axis value is in its wing only


def target_hit(t) -> str:
    """How the beam meets a target (report.json ``targets[i].hit``): ``"beam"``,
    ``"wing only"`` (its hottest point sees less than ``WING_FRACTION`` of the beam's
    on-axis irradiance at that range: the Gaussian's tail, 3.7 1/e radii off the axis or
    more; its NOHDs are still computed from that power, conservative), ``"not
    reflected"`` (power reaches it, nothing is reflected: ``lit_side`` says why) or
    ``"not hit"``."""
    if t.static_lobe is None:
        return "not reflected" if t.spot_power_w > 0 else "not hit"
    return "wing only" if t.beam_profile_fraction < WING_FRACTION else "beam"


def _melt_lines(t) -> list:
    """A target's melting (onset, full melt) and the slump its dynamic lobe covers."""
    out = []
    m = t.melt
    if m is not None:
        when = ("no melting in the run" if m["onset_s"] is None else f"melting from {m['onset_s']:.4g} s"
                + (f", all molten at {m['full_melt_s']:.4g} s" if m["full_melt_s"] is not None else
                   f", {m['max_fraction']:.2g} molten at the end"))
        out.append(f"    {when}")
    sl = t.slump
    if sl is not None:
        out.append(f"    slump: normal tilted up to {sl['tilt_deg']:.3g} deg with the melt fraction, wander within "
                   f"{sl['wander_deg']:.3g} deg once molten; the dynamic lobe covers their union ({sl['normals_sampled']} normals "
                   f"every {sl['step_deg']:.3g} deg; half the step gives {sl['max_nohd_half_step_m']:.4g} m there, the larger is reported)")
        out.append(f"    slump left out: {sl['left_out']}")
    return out


def _nohd_lines(result) -> list:
    """NOHD per target: diffuse (BRDF lobe) and specular (mirror beam), static and dynamic,
    with melting and the slump where the history knows them."""
    lines = ["NOHD per target (diffuse: BRDF lobe; specular: mirror beam beyond the target):"]
    for t in result.targets:
        d = t.to_dict()
        if t.static_lobe is None:
            lines.append(f"  {t.name}: nothing reflected ({t.lit_side})")
            continue
        if target_hit(t) == "wing only":
            lines.append(f"  {t.name}: the beam misses it; only its Gaussian wing reaches it ({t.spot_power_w:.3g} W; "
                         f"at most {t.beam_profile_fraction:.2g} of the beam's on-axis irradiance there)")
        spec = ("no mirror beam" if t.specular_nohd_static_m is None else
                f"specular static {t.specular_nohd_static_m:.4g} m, dynamic {t.specular_nohd_dynamic_m:.4g} m")
        lines.append(f"  {t.name}: diffuse static {d['nohd_static_m']:.4g} m, dynamic {d['nohd_dynamic_m']:.4g} m; {spec}")
        lines += _melt_lines(t)
        for a in t.aided:
            spec_a = "" if a["specular_nohd_dynamic_m"] is None else f"; specular {a['specular_nohd_dynamic_m']:.4g} m"
            lines.append(f"    through {a['magnification']:g}x{1e3 * a['objective_diameter_m']:g} optics (gain {a['gain']:.3g}): "
                         f"diffuse {a['nohd_dynamic_m']:.4g} m{spec_a}")
    sp = getattr(result, "spill", None)
    if sp is not None and sp.nohd_m:
        aided = "".join(f"; through {a.magnification:g}x{1e3 * a.objective_diameter_m:g} optics {a.nohd_m:.4g} m" for a in sp.aided)
        lines.append(f"  the beam past the targets ({sp.leaves_scene_w:.4g} W leaves the scene): direct-beam NOHD "
                     f"{sp.nohd_m:.4g} m from the laser{aided}")
    for d in () if sp is None else sp.stopped:
        way = (f" (up to {d.peak_irradiance_w_m2:.3g} W/m^2 on its way from {d.from_range_m:.4g} m, hazard ratio "
               f"{d.hazard_ratio:.3g}: an eye in it is at risk)" if d.hazard_ratio >= 1 else "")
        lines.append(f"  {d.power_w:.4g} W of the beam stopped by {d.object} at {d.range_m:.4g} m{way}: {d.reflected}")
    lines += _sdz_lines(getattr(result, "sdz", None))
    fs, fd = result.footprint_static, result.footprint_dynamic
    if fs is not None and fd is not None:
        lines.append(f"  hazardous ground from the reflections at {fs.eye_height_m:g} m eye height (analysis.footprint_eye_height_m): "
                     f"static {fs.area_m2:.4g} m^2, dynamic {fd.area_m2:.4g} m^2 (the direct beam's is the danger zone below)")
    return lines


def _sdz_lines(z: DangerZone | None) -> list:
    """The laser surface danger zone in a few lines (report.json ``sdz``)."""
    if z is None:
        return []
    d = z.directions
    where = {"aim": "the aim alone (no pointing error given: set [laser] pointing_error_rad)",
             "cone": f"the pointing cone of {d.buffer_rad:.3g} rad"
                     + (f" ({d.pointing_error_sigmas:g} sigma)" if d.pointing_error_kind == "sigma" else " (bound)"),
             "sector": f"the sector widened by {d.buffer_rad:.3g} rad"}[d.kind]
    if d.aim_track:
        where += " and the aim track (the beam may stop anywhere along its slew)"
    size = ("unbounded (a collimated beam in clear air: its NOHD is infinite; the polygon is drawn to 100 km)" if z.unbounded
            else f"{z.area_m2:.4g} m^2")
    lines = [f"  laser surface danger zone over {where}: {size}, out to {z.max_range_m:.4g} m "
             f"(direct-beam NOHD {z.nohd_m:.4g} m); "
             + ("contained by backstops" if z.contained else
                f"NOT contained: {z.escaping_directions} of {d.count} directions{escape_way(z)} reach the NOHD without a backstop "
                "(no terrain or occluder across them; targets are not backstops)"
                + (", some above the horizon" if z.above_horizon else ""))]
    if z.leaves_boundary:
        lines.append(f"    it LEAVES the range boundary: {z.outside_boundary_m2:.4g} m^2 outside")
    elif z.leaves_boundary is not None:
        lines.append("    it stays within the range boundary")
    for a in z.aided:
        lines.append(f"    through {a.aid.magnification:g}x{1e3 * a.aid.objective_diameter_m:g} optics: {a.area_m2:.4g} m^2 out to "
                     f"{a.max_range_m:.4g} m" + ("" if a.contained else ", not contained"))
    lines += [_mirror_line(m) for m in z.mirror_beams or () if m.nohd_m > 0]
    return lines


def _mirror_line(m: MirrorBeam) -> str:
    """One mirror beam's fate (report.json ``sdz.mirror_beams``)."""
    fate = ("contained by backstops" if m.contained else
            "NOT contained: it reaches its NOHD without a backstop (no terrain or occluder across it; targets are not "
            "backstops)" + (", above the horizon" if m.above_horizon else ""))
    if m.leaves_boundary:
        fate += "; it LEAVES the range boundary"
    a = m.aided
    if a and (not a.contained or a.leaves_boundary) and (m.contained and not m.leaves_boundary):
        fate += f"; through optics (NOHD {a.nohd_m:.4g} m) it is not contained" + (" and leaves the range" if a.leaves_boundary else "")
    return f"  mirror beam of {m.target} (specular NOHD {m.nohd_m:.4g} m, reaches {m.max_reach_m:.4g} m): {fate}"


def _not_modelled_lines(result) -> list:
    lines = ["Skipped in this run, and notes:"]
    lines += [f"  skipped {s.name}: {s.detail}" for s in result.stages if not s.ran]
    lines += [f"  note: {n}" for n in result.notes]
    lines.append(f"  never modelled: {', '.join(NEVER_MODELLED)}")
    return lines


def answer_text(result, max_observers=ANSWER_MAX_OBSERVERS, *, verdict_doc: Verdict | None = None) -> str:
    """What a range safety officer asks first, in plain text.

    Parameters
    ----------
    result : hazard.HazardResult
    max_observers : int
        Hazardous observers listed by name, highest hazard ratio (peak irradiance / MPE,
        unitless) first; the others are counted.
    verdict_doc : hazard.pipeline.verdict.Verdict, optional
        :func:`hazard.pipeline.verdict.verdict` of ``result`` when the caller has it (else
        computed here).

    Returns
    -------
    str
        The plausibility warnings (above the verdict: each can change it); the verdict's
        headline (:func:`hazard.pipeline.verdict.verdict`, the same text as report.json's
        ``verdict.headline`` and the review page's); the zones not contained, each with
        why; the hazardous observers with their hazard ratio, distance [m] from the laser
        and from the nearest spot, and cause (each contribution above 1 % of the peak
        with its share; static, or raised by the dynamic material); the NOHD [m] of
        every target (diffuse and specular, static and dynamic); the skipped stages,
        notes and what the tool never models.
    """
    lines = _observer_lines(result, max_observers, verdict_doc) + _motion_lines(result) + _nohd_lines(result) + _not_modelled_lines(result)
    return "\n".join(lines)


def _levels_text(result, s) -> str:
    eff, reached = visual_levels(result, s.peak_irradiance_w_m2)
    if eff is None:
        return ""
    return (f"; effective {eff:.4g} W/m^2: inside the {'/'.join(x.upper() for x in reached)} level(s)" if reached
            else f"; effective {eff:.4g} W/m^2: below the FAA levels")


def _motion_lines(result) -> list:
    """Moving observers, fixed ones under a moving beam, and the flight zones."""
    out = []
    m = getattr(result, "motion", None)
    for p in ([] if m is None else m.tracks()):
        s = p.summary  # hazard.pipeline.motion_results.PathSummary
        first = "" if s.first_exceedance_s is None else f", first over the MPE at t = {s.first_exceedance_s:.6g} s"
        uv = s.uv_24h
        where = (f"the UV dose within 24 h: {uv.dose_j_m2:.4g} J/m^2 over {uv.exposed_s:.4g} s exposed against {uv.limit_j_m2:.4g}"
                 if uv is not None and uv.ratio >= s.worst_window.ratio else f"in its worst {s.worst_window.duration_s:.3g} s window")
        out.append(f"  track {p.name}: {'HAZARD' if s.hazardous else 'below the MPE'} (exposure ratio "
                   f"{s.exposure_ratio:.3g} {where}{first}); peak "
                   f"{s.peak_irradiance_w_m2:.4g} W/m^2 at t = {s.peak_time_s:.6g} s; {s.samples} samples, "
                   f"smallest step {s.min_step_s:.3g} s" + _levels_text(result, s))
    out += [f"  note: {n}" for n in ([] if m is None else m.notes)]
    fixed = [] if m is None else m.fixed()
    if fixed:
        n = sum(p.summary.hazardous for p in fixed)
        out.append(f"  over time (the beam or a target moves): {n} of {len(fixed)} fixed observer(s) hazardous")
    air = getattr(result, "airspace", None)
    for z in () if air is None else air.zones:
        out.append(f"  flight zone {z.name} ({z.limit}): " + ("holds" if z.holds else
                   f"EXCEEDED: {z.worst_effective_irradiance_w_m2:.4g} W/m^2 effective at t = {z.worst_time_s:.6g} s "
                   f"(limit {z.limit_w_m2:.4g}, {z.worst_path})"))
    vi = getattr(result, "visual_interference", None)  # hazard.physics.visual.VisualInterference
    if vi is not None and vi.applies:
        d = vi.direct
        out.append(f"  visual interference, direct beam (VCF {vi.vcf:.4g}): LFED {d.lfed_m:.5g} m, CZED {d.czed_m:.5g} m, "
                   f"SZED {d.szed_m:.5g} m, NOHD {d.nohd_m:.5g} m")
    return (["Over time and in the airspace:"] + out) if out else []


def stages_text(result) -> str:
    """The stage log: every stage, ran or skipped, with its detail and run time [s]."""
    lines = ["Stages:"]
    for s in result.stages:
        lines.append(f"  {'ran    ' if s.ran else 'skipped'} {s.name:14s} {s.detail}" + (f" [{s.seconds:.3g} s]" if s.ran else ""))
    changed = result.verdict_changes()
    if changed:
        lines.append(f"  verdict changes static -> dynamic: {', '.join(changed[:10])}" + (" ..." if len(changed) > 10 else ""))
    return "\n".join(lines)


def summary_text(result, *, verbose=False, max_observers=ANSWER_MAX_OBSERVERS, verdict_doc: Verdict | None = None) -> str:
    """The text of ``hazard run``: :func:`answer_text`, then (``verbose``) :func:`stages_text`
    (``verdict_doc``: the run's verdict when the caller has it)."""
    text = answer_text(result, max_observers, verdict_doc=verdict_doc)
    return text + "\n" + stages_text(result) if verbose else text
