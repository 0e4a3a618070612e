"""The report for the review board: one self-contained HTML file from an analysis folder.

``write_review(OUT)`` reads ``OUT/report.json`` (written by ``hazard run``), embeds the
pictures found in ``OUT`` (plan view first, then the elevation, the 3-D renders of
``hazard render`` and the time plots) as base64 data URIs, and writes ``OUT/report.html``
atomically (a temporary file beside it, then a rename). The page has its CSS inline, no
script and no external resource, so it can be mailed, archived or printed as it is;
``pdf=True`` also prints it to ``OUT/report.pdf`` with headless Chromium.

Every value on the page is read from report.json (each section names the keys it shows);
nothing is recomputed. Absent optional pieces (no plan view, no renders, no coordinate
frame) are said on the page, never silently left out. The page is rendered with jinja2
from ``hazard/templates/review.html.j2`` with autoescape on.

When ``OUT/risk.json`` (``hazard risk SCENE -o OUT``) is there, a section "Probabilistic
risk" shows its statement table (the worst rows), inputs, map picture
(``OUT/probability_map.png``) and notes, with a warning when it is of another scene text
than report.json (:func:`risk_section`; the pieces come from :mod:`hazard.outputs.risk_page`).
"""

from __future__ import annotations

import base64
import hashlib
import json
import math
import os
import shutil
import subprocess
import tempfile
from pathlib import Path

from brdfmodels.fileio import atomic_write, atomic_write_text, check_input_file
from scenes.conventions import beam_headline

from hazard.outputs.page_format import fmt_distance, fmt_number, fmt_percent_change, fmt_vector, optics_text, report_number, template_environment
from hazard.outputs.names import file_part
from hazard.outputs.report import NEVER_MODELLED, REPORT_FORMAT, REPORT_VERSION
from hazard.outputs.risk_page import inputs_rows, map_summary, statement_section
from hazard.pipeline.verdict import escape_way

__all__ = ["write_review", "review_html", "read_report", "find_chromium", "PdfError", "fmt_number", "fmt_distance",
           "HTML_NAME", "PDF_NAME", "OBSERVERS_SHOWN", "FIXED_OVER_TIME_SHOWN", "SECTIONS",
           "read_risk", "risk_section", "RISK_NAME", "RISK_SECTION", "RISK_ROWS_SHOWN"]

HTML_NAME = "report.html"
PDF_NAME = "report.pdf"
OBSERVERS_SHOWN = 30  # observer rows on the page (the worst, hazardous first); the rest are counted
FIXED_OVER_TIME_SHOWN = 10  # fixed observers evaluated over time shown (the worst); the rest are counted
VERDICT_CHANGES_SHOWN = 20  # observer names whose verdict changes static -> dynamic, listed by name
ECHO_MAX_CHARS = 20_000  # the scene echo appendix is cut here (said on the page; all of it is in report.json)
CHROMIUM_PATHS = ("/usr/bin/chromium",)
CHROMIUM_NAMES = ("chromium", "chromium-browser", "google-chrome")
CHROMIUM_FLAGS = ("--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking",
                  "--disable-component-update", "--disable-sync", "--no-first-run", "--no-pdf-header-footer")
PDF_TIMEOUT_S = 180.0
REQUIRED_KEYS = ("scene", "mpe", "targets", "observers", "stages")

# pictures in page order: (group, file names or a prefix ending in "*"); each PNG of the
# folder lands in the first group that claims it, the others in "other"
PICTURE_GROUPS = (
    ("plan", ("plan.png",)),
    ("elevation", ("elevation.png",)),
    ("renders", ("keepout.png", "overview.png", "lobe.gif")),
    ("nohd_time", ("nohd_time_*",)),
    ("exposure_track", ("exposure_track_*",)),
    ("exposure", ("exposure_*",)),
    ("risk", ("probability_map.png",)),  # hazard risk's map: in the "Probabilistic risk" section
)
CAPTIONS = {
    "plan.png": "Plan view (x east, y north): danger zone, aim line, keep-out lobe outlines, mirror beams, "
                "range rings, observers by verdict",
    "elevation.png": "Elevation view: distance along the aim's azimuth against height",
    "keepout.png": "3-D close view of the keep-out lobes at true scale",
    "overview.png": "3-D overview of everything hazardous",
    "lobe.gif": "The dynamic lobe over the history (animation; a PDF shows its first frame)",
    "probability_map.png": ("Probabilistic risk (hazard risk): the estimate of P(E > MPE) per map cell where resolved, hatched where "
                            "only the 95 % upper bound is known, observers overlaid"),
}
MIME = {".png": "image/png", ".gif": "image/gif"}
SECTIONS = {  # id -> heading, in page order
    "verdict": "Verdict",
    "scene": "Scene",
    "frame": "Coordinate frame",
    "laser": "Laser and exposure",
    "mpe": "Maximum permissible exposure (MPE)",
    "distances": "Hazard distances: NOHD and ENOHD",
    "targets": "Targets: static and dynamic hazard",
    "plan": "Plan view and elevation",
    "renders": "3-D renders",
    "time": "Time plots",
    "observers": "Observers",
    "steps": "Every number with its steps",
    "airspace": "Airspace and moving observers",
    "stages": "Stages run and skipped",
    "assumptions": "Assumptions and limits",
    "files": "Files and map outputs",
    "versions": "Versions and scene hash",
    "echo": "Appendix: the scene as analysed",
}
RISK_NAME = "risk.json"  # written by `hazard risk SCENE -o OUT` into the same folder: then a section of its own
RISK_SECTION = ("risk", "Probabilistic risk")  # placed after RISK_AFTER, only when OUT/risk.json exists
RISK_AFTER = "airspace"
RISK_ROWS_SHOWN = 20  # observers of risk.json on this page (the highest upper bound first); all are in risk.csv


class PdfError(RuntimeError):
    """The PDF could not be printed; the HTML was written (``html``: its path)."""

    def __init__(self, message: str, html: Path):
        super().__init__(message)
        self.html = html


# units by key suffix (report.json's naming convention), longest suffix first
_UNIT_SUFFIXES = (("_w_m2", "W/m\u00b2"), ("_j_m2", "J/m\u00b2"), ("_per_m", "1/m"), ("_deg_m", "\u00b0, \u00b0, m"),
                  ("_m2", "m\u00b2"), ("_m3", "m\u00b3"), ("_nm", "nm"), ("_km", "km"), ("_rad", "rad"),
                  ("_deg", "\u00b0"), ("_hz", "Hz"), ("_w", "W"), ("_j", "J"), ("_s", "s"), ("_m", "m"))


def _label_unit(key: str) -> tuple[str, str]:
    """A report.json key as a label and its unit: ``beam_diameter_m`` -> ("beam diameter", "m")."""
    for suffix, unit in _UNIT_SUFFIXES:
        if key.endswith(suffix) and len(key) > len(suffix):
            return key[: -len(suffix)].replace("_", " "), unit
    return key.replace("_", " "), ""


def _any_text(v, unit: str = "", sig: int = 6) -> str:
    """Any JSON value as one line of text (nested tables as ``key: value; ...``)."""
    if isinstance(v, dict):
        if not v:
            return "none"
        parts = []
        for k, x in v.items():
            label, u = _label_unit(k)
            parts.append(f"{label}: {_any_text(x, u, sig)}")
        return "; ".join(parts)
    if isinstance(v, (list, tuple)):
        if not v:
            return "none"
        if all(not isinstance(x, (dict, list)) for x in v):
            return fmt_vector(list(v), unit, sig=sig)
        return " | ".join(_any_text(x, unit, sig) for x in v)
    if isinstance(v, str) and not v.strip():
        return "not given"
    return fmt_number(v, unit, sig=sig, none="not given")


def kv_rows(d: dict | None, prefix: str, *, skip=(), skip_none: bool = False, sig: int = 6) -> list[dict]:
    """Rows ``{key, label, value}`` of a report.json table, each value with the unit its
    key names (``wavelength_nm`` -> nm) and ``key`` its path (``prefix.wavelength_nm``);
    ``skip``: keys shown elsewhere; ``skip_none``: leave out keys whose value is null."""
    rows = []
    for k, v in (d or {}).items():
        if k in skip or (skip_none and v is None):
            continue
        label, unit = _label_unit(k)
        many = isinstance(v, list) and len(v) > 1 and all(isinstance(x, dict) for x in v)
        rows.append({"key": f"{prefix}.{k}", "label": label, "value": _any_text(v, unit, sig),
                     "lines": [_any_text(x, unit, sig) for x in v] if many else None})  # a list of tables: one line each
    return rows


# -- reading -------------------------------------------------------------------------
def read_report(out_dir) -> tuple[dict, Path]:
    """report.json of an analysis folder, checked to be a laser-hazard report.

    Parameters
    ----------
    out_dir : str or Path
        The folder ``hazard run SCENE -o OUT`` wrote.

    Returns
    -------
    (dict, Path)
        The report and the path of report.json.

    Raises
    ------
    ValueError
        One line naming the file: no folder, no report.json, not JSON, not a laser-hazard
        report (``format``), a newer ``version``, or a required key missing.
    """
    out = Path(out_dir)
    if not out.is_dir():
        what = "not a folder" if out.exists() else "no such folder"
        raise ValueError(f"{out}: {what}; expected an output folder of `hazard run SCENE -o OUT` (holding report.json)")
    path = out / "report.json"
    if not path.exists():
        raise ValueError(f"{path}: missing; expected the report.json that `hazard run SCENE -o {out}` writes")
    text = Path(check_input_file(path, "report.json")).read_text(encoding="utf-8", errors="replace")
    try:
        doc = json.loads(text)
    except json.JSONDecodeError as exc:
        raise ValueError(f"{path}: not valid JSON (line {exc.lineno}: {exc.msg})") from None
    fmt = doc.get("format") if isinstance(doc, dict) else None
    if fmt != REPORT_FORMAT:
        raise ValueError(f"{path}: format = {fmt!r}: expected {REPORT_FORMAT!r} (a laser hazard report of `hazard run`)")
    version = doc.get("version")
    if not isinstance(version, int) or not 1 <= version <= REPORT_VERSION:
        raise ValueError(f"{path}: version = {version!r}: expected an integer from 1 to {REPORT_VERSION} "
                         "(a newer laser-hazard wrote it: update this one)")
    missing = [k for k in REQUIRED_KEYS if k not in doc]
    if missing:
        raise ValueError(f"{path}: key {missing[0]!r} missing: expected {', '.join(REQUIRED_KEYS)} (a truncated report?)")
    return doc, path


def _picture_group(name: str) -> str:
    for group, names in PICTURE_GROUPS:
        for n in names:
            if name == n or (n.endswith("*") and name.startswith(n[:-1])):
                return group
    return "other"


def _caption(name: str) -> str:
    if name in CAPTIONS:
        return CAPTIONS[name]
    stem = Path(name).stem
    if stem.startswith("nohd_time_"):
        return f"Diffuse lobe's maximum NOHD against time: {stem[len('nohd_time_'):]}"
    if stem.startswith("exposure_track_"):
        return (f"Irradiance and accumulated exposure against time along its path, in its own time steps: "
                f"moving observer {stem[len('exposure_track_'):]}")
    if stem.startswith("exposure_"):
        return f"Accumulated exposure and irradiance against the MPE: observer {stem[len('exposure_'):]}"
    return stem.replace("_", " ")


def collect_pictures(out: Path, report_mtime: float) -> dict:
    """The pictures of ``out`` (top level, PNG and GIF) grouped for the page, each as
    ``{name, caption, uri, kb, stale}``; ``stale``: older than report.json (a picture
    left from an earlier run). Groups in page order; each list sorted by name."""
    groups = {g: [] for g, _ in PICTURE_GROUPS} | {"other": []}
    files = sorted(p for p in out.iterdir() if p.suffix.lower() in MIME and p.is_file() and not p.name.startswith("."))
    for p in files:
        data = p.read_bytes()
        uri = f"data:{MIME[p.suffix.lower()]};base64,{base64.b64encode(data).decode('ascii')}"
        stale = p.stat().st_mtime < report_mtime - 1.0
        groups[_picture_group(p.name)].append({"name": p.name, "caption": _caption(p.name), "uri": uri,
                                               "kb": len(data) / 1024.0, "stale": stale})
    return groups


# -- sections ------------------------------------------------------------------------
def _sorted_observers(rows: list, ratio_key: str = "hazard_ratio") -> list:
    """Observer rows (or paths over time, by ``exposure_ratio``) hazardous first, then by
    the ratio, highest first (NaN counts as highest: never rounded toward safe)."""
    def key(r):
        ratio = report_number(r.get(ratio_key))
        ratio = math.inf if not isinstance(ratio, float) or math.isnan(ratio) else ratio
        return (not r.get("hazardous"), -ratio)

    return sorted(rows, key=key)


def _observer_row(r: dict) -> dict:
    """One observer as the page's table shows it (every value from report.json)."""
    mpe = report_number(r.get("mpe_w_m2"))
    static = report_number(r.get("static_irradiance_w_m2"))
    static_ratio = static / mpe if isinstance(static, float) and isinstance(mpe, float) and mpe > 0 else None
    before, after = bool(r.get("hazardous_static")), bool(r.get("hazardous"))
    return {
        "name": r.get("name", "?"), "position": fmt_vector(r.get("position_m"), sig=4),
        "verdict": "HAZARD" if after else "below MPE", "hazardous": after,
        "hazard_ratio": fmt_number(r.get("hazard_ratio")), "static_ratio": fmt_number(static_ratio),
        "change": "" if before == after else ("safe \u2192 HAZARD" if after else "HAZARD \u2192 safe"),
        "peak": fmt_number(r.get("peak_irradiance_w_m2"), "W/m\u00b2"),
        "direct": fmt_number(r.get("direct_irradiance_w_m2"), "W/m\u00b2"),
        "peak_time": fmt_number(r.get("peak_time_s"), "s"),
        "mpe": fmt_number(r.get("mpe_w_m2"), "W/m\u00b2"),
        "exposure_ratio": fmt_number(r.get("exposure_ratio")),
        "first_exceedance": fmt_number(r.get("first_exceedance_s"), "s", none="never"),
        "line_of_sight": fmt_number(r.get("line_of_sight")),
    }


def observers_section(doc: dict, shown: int = OBSERVERS_SHOWN) -> dict:
    """The observers table: the ``shown`` worst (hazardous first, highest hazard ratio
    first) and a statement counting the rest, so none is dropped silently."""
    rows = _sorted_observers(list(doc.get("observers") or []))
    listed = doc.get("observers_listed") or {"count": len(rows), "listed": len(rows), "which": "all"}
    total, n_listed = int(listed.get("count", len(rows))), len(rows)
    n_haz = sum(1 for r in rows if r.get("hazardous"))
    n_haz_static = sum(1 for r in rows if r.get("hazardous_static"))
    page = rows[:shown]
    rest = rows[len(page):]
    rest_haz = sum(1 for r in rest if r.get("hazardous"))
    more = ""
    if rest:
        more = (f"... and {len(rest)} more observer point(s) not shown here ({rest_haz} hazardous, "
                f"{len(rest) - rest_haz} below the MPE): all are in report.json and observers.csv.")
    partial = (f"report.json lists {n_listed} of the {total} observer points ({listed.get('which')}); "
               f"the counts below are over those {n_listed}." if n_listed < total else "")
    return {"rows": [_observer_row(r) for r in page], "shown": len(page), "listed": n_listed, "total": total,
            "hazardous": n_haz, "hazardous_static": n_haz_static, "more": more, "partial": partial,
            "at_least": bool(partial) and n_haz == n_listed}


# -- airspace and moving observers ---------------------------------------------------
MOTION_KEYS = ("tracks", "motion", "visual_interference", "airspace")
VISUAL_LEVELS = ("lfed", "czed", "szed")  # the FAA levels, farthest-reaching first (report.json's key order)


def _levels_reached(s: dict) -> str:
    """The FAA visual levels a path's effective peak reaches (``visual_levels_reached``)."""
    if s.get("peak_effective_irradiance_w_m2") is None:
        return "not a visible laser"
    reached = [str(x).upper() for x in s.get("visual_levels_reached") or []]
    return ", ".join(reached) if reached else "below the FAA levels"


def _path_row(s: dict, csv_present=None, plot=None) -> dict:
    """One path evaluated over time (a track, or a fixed observer under a moving beam) as
    the page's tables show it (every value from report.json)."""
    w = s.get("worst_window") or {}
    step = fmt_number(s.get("min_step_s"), "s", sig=3)
    base = fmt_number(s.get("base_step_s"), "s", sig=3)
    csv = s.get("csv")
    return {
        "name": s.get("name", "?"), "hazardous": bool(s.get("hazardous")),
        "verdict": "HAZARD" if s.get("hazardous") else "below the MPE",
        "ratio": fmt_number(s.get("exposure_ratio")),
        "window": (f"{fmt_number(w.get('duration_s'), 's')}: {fmt_number(w.get('exposure_j_m2'), 'J/m²')} of "
                   f"{fmt_number(w.get('mpe_radiant_exposure_j_m2'), 'J/m²')}" if w else "not stated"),
        "peak": fmt_number(s.get("peak_irradiance_w_m2"), "W/m²"), "peak_time": fmt_number(s.get("peak_time_s"), "s"),
        "point": fmt_vector(s.get("worst_point_m"), sig=4),
        "first_exceedance": fmt_number(s.get("first_exceedance_s"), "s", none="never"),
        "effective": fmt_number(s.get("peak_effective_irradiance_w_m2"), "W/m²", none="not visible"),
        "levels": _levels_reached(s),
        "exposure": fmt_number(s.get("radiant_exposure_j_m2"), "J/m²"),
        "path_exposure": fmt_number(s.get("path_exposure_j_m2"), "J/m²"),
        "error": fmt_number(s.get("exposure_error_estimate_j_m2"), "J/m²", sig=2),
        "samples": fmt_number(s.get("samples"), none="not stated"),
        "steps": f"smallest {step} (base {base}, {'adaptive' if s.get('adaptive') else 'fixed steps'})",
        "csv": csv, "csv_present": csv_present, "plot": plot,
    }


def _track_plots(tracks: list, pictures: dict) -> list:
    """Each track's ``exposure_track_<name>.png`` if embedded, else None; the names as
    :func:`hazard.pictures.plots.time_figures` makes them (file-safe, ``_2`` on a clash)."""
    taken, found = set(), {p["name"] for p in pictures.get("exposure_track", [])}
    out = []
    for t in tracks:
        name = f"exposure_track_{file_part(t.get('name', ''))}.png"
        k = 2
        while name in taken:
            name, k = f"exposure_track_{file_part(t.get('name', ''))}_{k}.png", k + 1
        taken.add(name)
        out.append(name if name in found else None)
    return out


def _zone_row(z: dict, i: int) -> dict:
    """One flight zone's check (``airspace.zones[i]``)."""
    holds = z.get("holds")
    return {
        "name": z.get("name", f"zone {i}"), "limit": str(z.get("limit", "?")).upper(),
        "limit_value": fmt_number(z.get("limit_w_m2"), "W/m²", none="none (cannot be exceeded)"),
        "band": (f"{fmt_distance(z.get('floor_agl_m'), none='ground')} to "
                 f"{fmt_distance(z.get('ceiling_agl_m'), none='no ceiling')}"),
        "holds": holds, "verdict": "holds" if holds else ("EXCEEDED" if holds is False else "not stated"),
        "worst": fmt_number(z.get("worst_effective_irradiance_w_m2"), "W/m²"),
        "time": fmt_number(z.get("worst_time_s"), "s", none="not lased"),
        "point": fmt_vector(z.get("worst_point_m"), sig=4), "path": z.get("worst_path") or "none",
        "vcf": fmt_number(z.get("vcf_applied"), sig=7),
        "spacing": fmt_distance(z.get("lattice_spacing_m"), none="not stated"),
        "times": fmt_number(z.get("times_checked"), none="not stated"),
    }


def _visual_view(vi) -> dict | None:
    """``visual_interference``: the FAA levels and their distances, for the direct beam and
    per target; for a non-visible laser the levels are not applicable (the reason said)."""
    if not isinstance(vi, dict):
        return None
    applies = bool(vi.get("applies"))
    limits = dict(vi.get("levels_w_m2") or {}) | {"nohd": vi.get("mpe_w_m2")}
    texts = vi.get("levels") or {}
    levels = [{"name": k.upper(), "limit": fmt_number(limits.get(k), "W/m²", none="not stated"),
               "text": texts.get(k, "")} for k in (*VISUAL_LEVELS, "nohd")]

    def cells(d: dict) -> list:
        out = [fmt_distance(d.get(f"{k}_m"), none="not stated") if applies else "not applicable" for k in VISUAL_LEVELS]
        return out + [fmt_distance(d.get("nohd_m"), none="not stated")]

    rows = [{"path": "direct beam (from the laser)", "key": "visual_interference.direct",
             "cells": cells(vi.get("direct") or {})}]
    rows += [{"path": f"target {name} (from the target)", "key": f"visual_interference.targets.{name}",
              "cells": cells(d or {})} for name, d in (vi.get("targets") or {}).items()]
    atten = fmt_number(vi.get("attenuation_per_m"), "1/m")
    return {"applies": applies, "reason": vi.get("reason") or "not stated", "levels": levels, "rows": rows,
            "wavelength": fmt_number(vi.get("wavelength_nm"), "nm", sig=6), "vcf": fmt_number(vi.get("vcf"), sig=7),
            "weighting": vi.get("weighting") or "not stated",
            "attenuation": (f"credited ({atten})" if vi.get("attenuation_credited") else "not credited (clear air)"),
            "source": vi.get("source"), "nohd_attenuation": vi.get("nohd_attenuation")}


def motion_section(doc: dict, out: Path, pictures: dict, shown: int = FIXED_OVER_TIME_SHOWN) -> dict:
    """Airspace and moving observers: the tracks (``tracks``), the fixed observers
    evaluated over time (``motion.fixed_observers``, the ``shown`` worst), the flight
    zones (``airspace``), the visual-interference distances (``visual_interference``) and
    the motion stage's method and notes (``motion``). ``moving``: anything moves or a
    flight zone was given (else the page says so in one line)."""
    tracks = list(doc.get("tracks") or [])
    motion = doc.get("motion") if isinstance(doc.get("motion"), dict) else None
    air = doc.get("airspace") if isinstance(doc.get("airspace"), dict) else None
    zones = list((air or {}).get("zones") or [])
    plots = _track_plots(tracks, pictures)  # named in report.json's order, as the pictures were
    plot_of = {id(t): plot for t, plot in zip(tracks, plots)}
    rows = [_path_row(t, (out / str(t["csv"])).is_file() if t.get("csv") else None, plot_of[id(t)])
            for t in _sorted_observers(tracks, "exposure_ratio")]
    fixed = _sorted_observers(list((motion or {}).get("fixed_observers") or []), "exposure_ratio")
    page, rest = fixed[:shown], fixed[shown:]
    rest_haz = sum(1 for r in rest if r.get("hazardous"))
    more = (f"... and {len(rest)} more fixed observer(s) not shown here ({rest_haz} hazardous, {len(rest) - rest_haz} "
            "below the MPE): all are in report.json motion.fixed_observers and the motion_* columns of observers.csv."
            if rest else "")
    notes = [{"text": str(n), "key": f"motion.notes[{i}]"} for i, n in enumerate((motion or {}).get("notes") or [])]
    return {
        "present": [k for k in MOTION_KEYS if k in doc], "moving": bool(tracks) or motion is not None or air is not None,
        "tracks": rows, "tracks_hazardous": sum(1 for t in tracks if t.get("hazardous")),
        "motion": motion,  # motion.seconds, its run time, is in the stages table
        "motion_rows": kv_rows(motion, "motion", skip=("fixed_observers", "notes", "method", "seconds")),
        "method": (motion or {}).get("method"), "notes": notes,
        "fixed": {"rows": [_path_row(r) for r in page], "total": len(fixed), "shown": len(page),
                  "hazardous": sum(1 for r in fixed if r.get("hazardous")), "more": more},
        "airspace": air, "zones": [_zone_row(z, i) for i, z in enumerate(zones)],
        "zones_held": sum(1 for z in zones if z.get("holds")),
        "air_rows": kv_rows(air, "airspace", skip=("zones",), sig=7),
        "visual": _visual_view(doc.get("visual_interference")),
        "plots": [p for p in plots if p],
    }


def _melt_text(m: dict | None) -> str:
    if not m:
        return ""
    if m.get("onset_s") is None:
        return "no melting in the run"
    text = f"melting from {fmt_number(m['onset_s'], 's')}"
    if m.get("full_melt_s") is not None:
        return text + f", all molten at {fmt_number(m['full_melt_s'], 's')}"
    return text + f", {fmt_number(m.get('max_fraction'), sig=2)} molten at the end"


def _state_text(t: dict) -> str:
    """The target's material history: which state and its range over the run."""
    name, span = t.get("state_name"), t.get("state_range")
    if not name:
        return "static material (no history): the dynamic values equal the static ones"
    names = [name] if isinstance(name, str) else list(name)
    spans = [span] if isinstance(name, str) else list(span or [])
    return "dynamic material: " + ", ".join(f"{n} from {fmt_number(s[0])} to {fmt_number(s[1])}"
                                            for n, s in zip(names, spans))


def _changes(t: dict) -> list:
    """What the dynamic material changes against the static one (NOHDs, keep-out volume)."""
    pairs = [("diffuse NOHD", t.get("nohd_static_m"), t.get("nohd_dynamic_m"), "m"),
             ("keep-out volume", (t.get("keepout_static") or {}).get("volume_m3"),
              (t.get("keepout_dynamic") or {}).get("volume_m3"), "m\u00b3"),
             ("specular NOHD", t.get("specular_nohd_static_m"), t.get("specular_nohd_dynamic_m"), "m")]
    out = []
    for what, a, b, unit in pairs:
        if a is None and b is None or a == b:
            continue
        fa, fb = (fmt_distance(a), fmt_distance(b)) if unit == "m" else (fmt_number(a, unit), fmt_number(b, unit))
        out.append(f"{what} {fa} \u2192 {fb} {fmt_percent_change(a, b)}".strip())
    return out


def _target_view(t: dict, i: int) -> dict:
    """One target's static and dynamic hazard as the page shows it (``targets[i]``)."""
    ko_s, ko_d = t.get("keepout_static") or {}, t.get("keepout_dynamic") or {}
    aided = [{"optics": f"{optics_text(a)} (transmission {fmt_number(a.get('transmission'))}, gain {fmt_number(a.get('gain'))})",
              "static": fmt_distance(a.get("nohd_static_m")), "dynamic": fmt_distance(a.get("nohd_dynamic_m")),
              "spec_static": fmt_distance(a.get("specular_nohd_static_m"), none="no mirror beam"),
              "spec_dynamic": fmt_distance(a.get("specular_nohd_dynamic_m"), none="no mirror beam")}
             for a in t.get("aided") or []]
    return {
        "index": i, "name": t.get("name", f"target {i}"), "hit": t.get("hit", "not stated"),
        "lit_side": t.get("lit_side", ""),
        "nohd_static": fmt_distance(t.get("nohd_static_m")), "nohd_dynamic": fmt_distance(t.get("nohd_dynamic_m")),
        "spec_static": fmt_distance(t.get("specular_nohd_static_m"), none="no mirror beam"),
        "spec_dynamic": fmt_distance(t.get("specular_nohd_dynamic_m"), none="no mirror beam"),
        "volume_static": fmt_number(ko_s.get("volume_m3"), "m\u00b3"),
        "volume_dynamic": fmt_number(ko_d.get("volume_m3"), "m\u00b3"),
        "spot_power": fmt_number(t.get("spot_power_w"), "W"),
        "peak_irradiance": fmt_number(t.get("peak_irradiance_w_m2"), "W/m\u00b2"),
        "spot_size": fmt_distance(t.get("spot_size_m")),
        "dynamic": bool(t.get("state_name")), "state": _state_text(t), "melt": _melt_text(t.get("melt")), "slump": t.get("slump"),
        "slump_rows": kv_rows(t.get("slump"), f"targets[{i}].slump", skip=("left_out", "method")),
        "changes": _changes(t), "aided": aided,
    }


def _sdz_view(z: dict | None) -> dict | None:
    """The laser surface danger zone (``sdz``): the direct beam's NOHD and reach, aided."""
    if not z:
        return None
    d = z.get("directions") or {}
    aided = [{"optics": optics_text(a),
              "gain": fmt_number(a.get("gain")), "enohd": fmt_distance(a.get("nohd_m")),
              "area": fmt_number(a.get("area_m2"), "m\u00b2", inf="unbounded"),
              "reach": fmt_distance(a.get("max_range_m")), "contained": fmt_number(a.get("contained"))}
             for a in z.get("aided") or []]
    boundary = ("no range boundary given" if "leaves_boundary" not in z else
                (f"LEAVES the range boundary: {fmt_number(z.get('outside_boundary_m2'), 'm²')} outside"
                 if z["leaves_boundary"] else "stays within the range boundary"))
    return {
        "directions": kv_rows(d, "sdz.directions"), "nohd": fmt_distance(z.get("nohd_m")), "unbounded": bool(z.get("unbounded")),
        "area": fmt_number(z.get("area_m2"), "m\u00b2", inf="unbounded"), "reach": fmt_distance(z.get("max_range_m")),
        "half_width": fmt_distance(z.get("hazard_half_width_m")), "contained": bool(z.get("contained")),
        "escaping": z.get("escaping_directions"), "count": d.get("count"), "way": escape_way(z),
        "above_horizon": bool(z.get("above_horizon")), "boundary": boundary, "aided": aided,
        "mirrors": [_mirror_view(m) for m in z.get("mirror_beams") or []],
    }


def _mirror_view(m: dict) -> dict:
    """One mirror beam's fate (``sdz.mirror_beams[i]``), aided when given."""
    a = m.get("aided") or {}
    return {"target": m.get("target", "?"), "nohd": fmt_distance(m.get("nohd_m")),
            "reach": fmt_distance(m.get("max_reach_m")), "contained": bool(m.get("contained")),
            "above_horizon": bool(m.get("above_horizon")), "leaves_boundary": bool(m.get("leaves_boundary")),
            "aided": fmt_distance(a.get("nohd_m")) if a else "", "aided_contained": a.get("contained")}


def _spill_view(beam: dict | None) -> dict:
    """The beam past the targets and where parts of it are stopped (``beam.spill``)."""
    sp = (beam or {}).get("spill") or {}
    stopped = [{"object": s.get("object", "?"), "power": fmt_number(s.get("power_w"), "W"),
                "range": fmt_distance(s.get("range_m")), "ratio": fmt_number(s.get("hazard_ratio")),
                "peak": fmt_number(s.get("peak_irradiance_w_m2"), "W/m\u00b2"), "reflected": s.get("reflected", "")}
               for s in sp.get("stopped") or []]
    aided = [{"optics": optics_text(a),
              "enohd": fmt_distance(a.get("nohd_m"))} for a in sp.get("aided") or []]
    return {"present": bool(sp), "leaves": fmt_number(sp.get("leaves_scene_w"), "W"),
            "nohd": fmt_distance(sp.get("nohd_m")), "aided": aided, "stopped": stopped}


def _footprint_rows(fp: dict | None) -> list:
    return [{"kind": k, "area": fmt_number(v.get("area_m2"), "m\u00b2"), "eye": fmt_distance(v.get("eye_height_m")),
             "cells": v.get("cells")} for k, v in (fp or {}).items()]


def mpe_section(doc: dict) -> dict:
    """The MPE with every step: standard and edition, table row, formula, governing limit,
    correction factors, the values with units, the pulse rules and C_E when applied."""
    m = doc.get("mpe") or {}
    ext = doc.get("extended_source") or {"applied": False}
    pulse = doc.get("pulse")
    return {
        "m": m, "irradiance": fmt_number(m.get("irradiance_w_m2"), "W/m\u00b2", sig=6),
        "exposure": fmt_number(m.get("radiant_exposure_j_m2"), "J/m\u00b2", sig=6),
        "used": fmt_number(doc.get("mpe_w_m2"), "W/m\u00b2", sig=6),
        "wavelength": fmt_number(m.get("wavelength_nm"), "nm", sig=6), "duration": fmt_number(m.get("duration_s"), "s", sig=6),
        "subtense": fmt_number(m.get("angular_subtense_rad"), "rad"),
        "aperture": fmt_number(1e3 * m["limiting_aperture_m"] if isinstance(m.get("limiting_aperture_m"), (int, float)) else None, "mm"),
        "factors": kv_rows(m.get("factors"), "mpe.factors"), "limits": [{"name": x.get("name"), "label": x.get("label", ""),
                                                          "h": fmt_number(x.get("radiant_exposure_j_m2"), "J/m\u00b2", sig=6)}
                                                         for x in m.get("limits") or []],
        "steps": list(m.get("steps") or []), "pulse": pulse,
        "pulse_rules": [{"rule": r.get("rule"), "h": fmt_number(r.get("per_pulse_radiant_exposure_j_m2"), "J/m\u00b2")}
                        for r in (pulse or {}).get("rules") or []],
        "ext": ext, "ext_rows": kv_rows(ext, "extended_source", skip=("applied", "mpe_smallest_alpha", "mpe_largest_alpha")),
        "ext_mpe": [(k, ext[k]) for k in ("mpe_smallest_alpha", "mpe_largest_alpha") if ext.get(k)],
    }


def _echo_rows(doc: dict) -> dict:
    """Laser, exposure and atmosphere as the scene gave them (``scene.echo``)."""
    echo = (doc.get("scene") or {}).get("echo") or {}
    laser = echo.get("laser") or {}
    pulsed = any(laser.get(k) is not None for k in ("pulse_energy_j", "pulse_duration_s", "prf_hz"))
    sc = doc.get("scene") or {}
    units = [{"key": f"scene.units_as_written.{k}", "label": k, "lines": None,
              "value": f"{r.get('as_written')} -> {r.get('key')} = {r.get('value')} {r.get('unit')}"}
             for k, r in (sc.get("units_as_written") or {}).items()]
    return {"laser": kv_rows(laser, "scene.echo.laser", skip_none=True), "pulsed": pulsed,
            "exposure": kv_rows(echo.get("exposure"), "scene.echo.exposure"),
            "atmosphere": kv_rows(echo.get("atmosphere"), "scene.echo.atmosphere"),
            "units": units, "beam": list((sc.get("beam_conventions") or {}).get("steps") or [])}


def _scene_view(doc: dict) -> dict:
    """Scene summary: name, description, source, hash, what it holds (``scene``)."""
    s = doc.get("scene") or {}
    echo = s.get("echo") or {}
    targets = [{"name": t.get("name", "?"), "shape": t.get("shape") or ("mesh" if t.get("file") else "?"),
                "material": _material_text(t.get("material") or {}),
                "history": "yes" if t.get("history") else "no"} for t in echo.get("targets") or []]
    groups = [{"name": o.get("name", "?"), "eye": fmt_distance(o.get("eye_height_m"), none="as given"),
               "optics": _any_text(o.get("optics")) if o.get("optics") else "naked eye"}
              for o in echo.get("observers") or []]
    text = _echo_text(echo)
    return {"name": s.get("name", "?"), "source": s.get("source", "not stated"), "sha256": s.get("sha256", "not stated"),
            "description": echo.get("description"), "offset": fmt_vector(s.get("offset_m"), "m"),
            "targets": targets, "groups": groups, "occluders": len(echo.get("occluders") or []),
            "terrain": _any_text({k: v for k, v in echo["terrain"].items() if v is not None}) if echo.get("terrain") else None,
            "boundary": (echo.get("range") or {}).get("boundary_m"),
            "echo_text": text[:ECHO_MAX_CHARS], "echo_cut": max(len(text) - ECHO_MAX_CHARS, 0)}


def _echo_text(echo: dict) -> str:
    """The scene echo as compact JSON: one line per key of each top-level table, one line
    per element of each top-level list."""
    def one(v):
        return json.dumps(v, ensure_ascii=False)

    lines = []
    for k, v in echo.items():
        if isinstance(v, dict) and v:
            lines += [f"{one(k)}: {{"] + [f"  {one(a)}: {one(b)}," for a, b in v.items()] + ["},"]
        elif isinstance(v, list) and v:
            lines += [f"{one(k)}: ["] + [f"  {one(x)}," for x in v] + ["],"]
        else:
            lines.append(f"{one(k)}: {one(v)},")
    return "\n".join(lines)


def _material_text(mat: dict) -> str:
    """A target's material in a few words: model, library entry or file, and parameters."""
    for key in ("library", "file"):
        if mat.get(key):
            return f"{key} {mat[key]}"
    params = {k: v for k, v in mat.items() if v is not None and k not in ("model", "file", "library")
              and not (k.startswith("melt_") or k == "groove_angle_deg")}
    return f"{mat.get('model', '?')}" + (f" ({_any_text(params)})" if params else "")


def _walk_left_out(obj, path: str, out: list) -> None:
    """Every ``left_out`` / ``not_modelled`` / ``assumptions`` statement in report.json."""
    if isinstance(obj, dict):
        for k, v in obj.items():
            p = f"{path}.{k}" if path else k
            if k in ("left_out", "not_modelled", "assumptions", "limitations") and v:
                for x in (v if isinstance(v, list) else [v]):
                    out.append({"text": str(x), "source": p})
            elif k not in ("observers", "echo", "polygon_m"):
                _walk_left_out(v, p, out)
    elif isinstance(obj, list):
        for i, v in enumerate(obj):
            _walk_left_out(v, f"{path}[{i}]", out)


def assumptions(doc: dict) -> list:
    """Assumptions and limits, each ``{text, source}`` naming the report.json key it comes
    from: notes, warnings, what was left out, point-source MPE, unverified table rows,
    partial observer lists, beam sampling, and what the tool never models."""
    items = [{"text": n, "source": f"notes[{i}]"} for i, n in enumerate(doc.get("notes") or [])]
    items += [{"text": f"warning: {w}", "source": f"warnings[{i}]"} for i, w in enumerate(doc.get("warnings") or [])]
    if (doc.get("mpe") or {}).get("unverified"):
        items.append({"text": "the MPE table row is marked unverified against the standard's text", "source": "mpe.unverified"})
    if not (doc.get("extended_source") or {}).get("applied", False):
        items.append({"text": "point-source MPE (C_E = 1) for every observer: conservative for extended spots",
                      "source": "extended_source.applied"})
    z = doc.get("sdz") or {}
    if (z.get("directions") or {}).get("kind") == "aim":
        items.append({"text": "danger zone over the aim alone: no pointing error was given", "source": "sdz.directions.kind"})
    for i, t in enumerate(doc.get("targets") or []):
        if t.get("hit") in ("wing only", "not reflected", "not hit"):
            items.append({"text": f"target {t.get('name')}: {t['hit']}", "source": f"targets[{i}].hit"})
        if t.get("spot_power_exact") is False:
            items.append({"text": f"target {t.get('name')}: intercepted power from beam samples, error up to "
                                  f"{fmt_number(t.get('spot_power_error_w'), 'W')}", "source": f"targets[{i}].spot_power_error_w"})
    not_refl = ((doc.get("beam") or {}).get("sampling") or {}).get("not_reflected") or []
    if not_refl:
        items.append({"text": f"not reflected: {', '.join(map(str, not_refl))}", "source": "beam.sampling.not_reflected"})
    skipped = [s.get("name", "?") for s in doc.get("stages") or [] if not s.get("ran")]
    if skipped:
        items.append({"text": f"{len(skipped)} stage(s) skipped: {', '.join(skipped)} (the reasons: section "
                              f"{SECTIONS['stages']!r})", "source": "stages[].ran, stages[].detail"})
    listed = doc.get("observers_listed") or {}
    if listed.get("which", "all") != "all":
        items.append({"text": f"observers listed: {listed['which']}", "source": "observers_listed.which"})
    motion = doc.get("motion") if isinstance(doc.get("motion"), dict) else {}
    items += [{"text": f"motion: {n}", "source": f"motion.notes[{i}]"} for i, n in enumerate(motion.get("notes") or [])]
    air = doc.get("airspace") if isinstance(doc.get("airspace"), dict) else {}
    if air.get("note"):
        items.append({"text": f"flight zones: {air['note']}", "source": "airspace.note"})
    maps = doc.get("map_outputs")
    for name, why in ((maps.get("not_written") or {}) if isinstance(maps, dict) else {}).items():
        items.append({"text": f"map output {name} not written: {why}", "source": f"map_outputs.not_written.{name}"})
    _walk_left_out(doc, "", items)
    items.append({"text": "never modelled by this tool: " + ", ".join(NEVER_MODELLED), "source": "laser-hazard (every run)"})
    return items


def _verdict(doc: dict, obs: dict) -> dict:
    """The headline: any hazard, and which kinds (observers, moving observers, flight
    zones, lobes, mirror beams, beam). A hazardous track or a flight zone that does not
    hold is a hazard even when report.json's ``any_hazard`` says otherwise (said)."""
    lines = []
    at_least = "at least " if obs["at_least"] else ""
    lines.append(f"{at_least}{obs['hazardous']} of {obs['total']} observer point(s) at or above the MPE "
                 f"(static material: {obs['hazardous_static']})")
    tracks = list(doc.get("tracks") or [])
    bad_tracks = [t for t in tracks if t.get("hazardous")]
    if tracks:
        lines.append(f"{len(bad_tracks)} of {len(tracks)} moving observer(s) (tracks) at or above the MPE over time")
    for t in bad_tracks:
        lines.append(f"track {t.get('name', '?')}: HAZARD, exposure ratio {fmt_number(t.get('exposure_ratio'))}"
                     + (f", first over the MPE at {fmt_number(t['first_exceedance_s'], 's')}"
                        if t.get("first_exceedance_s") is not None else ""))
    fixed = ((doc.get("motion") or {}) if isinstance(doc.get("motion"), dict) else {}).get("fixed_observers") or []
    if fixed:
        lines.append(f"over time (the beam or a target moves): {sum(1 for r in fixed if r.get('hazardous'))} of "
                     f"{len(fixed)} fixed observer(s) hazardous")
    zones = ((doc.get("airspace") or {}) if isinstance(doc.get("airspace"), dict) else {}).get("zones") or []
    bad_zones = [z for z in zones if z.get("holds") is False]
    if zones:
        lines.append(f"{len(zones) - len(bad_zones)} of {len(zones)} flight zone(s) hold their limit")
    for z in bad_zones:
        lines.append(f"flight zone {z.get('name', '?')} ({str(z.get('limit', '?')).upper()}): EXCEEDED, "
                     f"{fmt_number(z.get('worst_effective_irradiance_w_m2'), 'W/m²')} effective at "
                     f"{fmt_number(z.get('worst_time_s'), 's')} (limit {fmt_number(z.get('limit_w_m2'), 'W/m²')}, "
                     f"{z.get('worst_path') or 'path not stated'})")
    for t in doc.get("targets") or []:
        n = report_number(t.get("nohd_dynamic_m"))
        if isinstance(n, float) and n > 0:
            lines.append(f"target {t.get('name')}: diffuse NOHD {fmt_distance(n)}"
                         + (f", mirror beam NOHD {fmt_distance(t['specular_nohd_dynamic_m'])}"
                            if t.get("specular_nohd_dynamic_m") is not None else ""))
    z = doc.get("sdz") or {}
    if z:
        aided = "".join(f", through {optics_text(a)} optics {fmt_distance(a.get('nohd_m'))}" for a in z.get("aided") or [])
        lines.append(f"direct beam NOHD {fmt_distance(z.get('nohd_m'))}{aided}; danger zone "
                     + ("contained by backstops" if z.get("contained") else
                        f"NOT contained: {z.get('escaping_directions')} direction(s){escape_way(z)} reach the NOHD without "
                        "a backstop (no terrain or occluder across them; targets are not backstops)"))
    for s in ((doc.get("beam") or {}).get("spill") or {}).get("stopped") or []:
        ratio = report_number(s.get("hazard_ratio"))
        if isinstance(ratio, float) and not ratio < 1:
            lines.append(f"{fmt_number(s.get('power_w'), 'W')} of the beam stopped by {s.get('object')} at "
                         f"{fmt_distance(s.get('range_m'))}: hazard ratio {fmt_number(ratio)} on its way")
    any_hazard = doc.get("any_hazard")
    if any_hazard is not True and (bad_tracks or bad_zones):
        lines.append(f"report.json any_hazard = {json.dumps(any_hazard)}, but a moving observer is hazardous or a flight "
                     "zone does not hold: counted as a hazard here")
        any_hazard = True
    return {"any_hazard": any_hazard, "lines": lines, **_headline_view(doc, any_hazard)}


def _headline_view(doc: dict, any_hazard) -> dict:
    """report.json's ``verdict``: its headline as it is (the same text ``hazard run``
    printed, :func:`hazard.pipeline.verdict.verdict`), the zones not contained with why, the
    plausibility ``warnings``, the beam convention line (``beam``: the standards' 1/e form,
    given or the default, converted or not; "" for a report without it) and the box's style (``bad``: a hazard at the observers or
    in the zones; ``contained``: hazard zones exist, all contained; ``good``: none).
    A report without ``verdict`` (older) gets ``headline`` None: the page says so."""
    v = doc.get("verdict") if isinstance(doc.get("verdict"), dict) else {}
    bad = bool(v.get("hazard_at_observers") or v.get("hazard_zones")) if v else bool(any_hazard)
    style = "bad" if bad or (not v and any_hazard) else ("contained" if any_hazard else "good")
    scene = doc.get("scene") if isinstance(doc.get("scene"), dict) else {}
    return {"headline": v.get("headline"), "zones": [str(z) for z in v.get("zones") or []],
            "beam": beam_headline(scene.get("beam_conventions")),  # the answer's beam line, as stdout says it
            "at_observers": bool(v.get("hazard_at_observers")) if v else bool(any_hazard),
            "warnings": [str(w) for w in doc.get("warnings") or []], "style": style}


def _frame_view(doc: dict) -> dict | None:
    """The coordinate frame, every key shown (``frame``: kind, statement, origin, ...)."""
    f = doc.get("frame")
    if f is None:
        return None
    if not isinstance(f, dict):
        return {"statement": str(f), "rows": []}
    return {"statement": f.get("statement"), "kind": f.get("kind"), "rows": kv_rows(f, "frame", skip=("statement",), sig=10)}


def _map_outputs_view(maps, out: Path) -> dict | None:
    """``map_outputs``: a list of file names, or a table with ``files``, ``not_written``
    (name -> why) and further keys (shown as they are); each file checked in ``out``."""
    if maps is None:
        return None
    if isinstance(maps, dict):
        files, not_written = maps.get("files") or [], maps.get("not_written") or {}
        rows = kv_rows(maps, "map_outputs", skip=("files", "not_written"))
    else:
        files, not_written, rows = list(maps), {}, []
    return {"files": [{"name": str(n), "present": (out / str(n)).is_file()} for n in files],
            "not_written": [{"name": k, "why": str(v)} for k, v in not_written.items()], "rows": rows}


def _files_view(doc: dict, out: Path, report_path: Path, pictures: dict) -> dict:
    """The files of the folder this page was built from, and the map outputs listed."""
    embedded = [p["name"] for g in pictures.values() for p in g]
    tracks = [{"name": str(t["csv"]), "present": (out / str(t["csv"])).is_file()}
              for t in doc.get("tracks") or [] if t.get("csv")]
    return {"report": report_path.name, "csv": (out / "observers.csv").exists(), "track_csvs": tracks,
            "map_page": (out / "map.html").is_file(),  # written by hazard report before this page (hazard.outputs.map_page)
            "maps": _map_outputs_view(doc.get("map_outputs"), out),
            "embedded": embedded, "report_sha256": hashlib.sha256(report_path.read_bytes()).hexdigest()}


# -- probabilistic risk (hazard risk) ------------------------------------------------
def read_risk(out: Path) -> tuple[dict | None, str | None, Path]:
    """``OUT/risk.json`` as (doc, None), (None, why it cannot be shown) or (None, None)
    when the folder has none (no risk analysis: no section)."""
    path = Path(out) / RISK_NAME
    if not path.exists():
        return None, None, path
    try:
        doc = json.loads(Path(check_input_file(path, RISK_NAME)).read_text(encoding="utf-8", errors="replace"))
    except ValueError as exc:  # unreadable, not a regular file, or not JSON
        return None, f"{path.name} cannot be read: {exc}", path
    if not isinstance(doc, dict) or not isinstance(doc.get("observers"), list):
        return None, f"{path.name} is not the output of hazard risk (no observers list)", path
    return doc, None, path


def _risk_scene_check(risk: dict, report: dict) -> str:
    """A warning when risk.json is not of the scene text report.json analysed, else ""."""
    ours, theirs = (report.get("scene") or {}).get("sha256"), risk.get("scene_sha256")
    if theirs is None or ours is None:
        return (f"{RISK_NAME} or report.json states no scene hash: it cannot be checked that the probabilistic risk "
                "below is of the scene this page reports.")
    if theirs != ours:
        return (f"{RISK_NAME} is of a DIFFERENT scene text (sha256 {theirs}) than report.json (sha256 {ours}): the "
                "probabilistic risk below is not of the scene this page reports. Run hazard risk on this scene again.")
    return ""


def _risk_picture(risk: dict, pictures: list, risk_path: Path) -> tuple[dict | None, str]:
    """The embedded probability_map.png (stale: older than risk.json), or why there is none."""
    if risk.get("map") is None:
        return None, "No probability map: the risk analysis has no [uncertainty.map] (map: null)."
    if not pictures:
        return None, ("No probability_map.png in the folder: it is drawn with risk.html "
                      "(hazard.outputs.risk_page.write_risk_page); the map's numbers are in probability_map.csv.")
    p = pictures[0]
    stale = (risk_path.parent / p["name"]).stat().st_mtime < risk_path.stat().st_mtime - 1.0
    return p | {"stale": stale}, ""


def risk_section(out: Path, report: dict, pictures: list) -> dict | None:
    """The "Probabilistic risk" section from ``OUT/risk.json`` (None without one): the
    run, the statement table (the ``RISK_ROWS_SHOWN`` worst), the inputs, the map summary
    and picture (``pictures``: probability_map.png, embedded), the notes and what is left
    out, and a warning when risk.json is of another scene text than report.json."""
    risk, problem, path = read_risk(out)
    if risk is None:
        return None if problem is None else {"problem": problem}
    picture, absent = _risk_picture(risk, pictures, path)
    return {"problem": "", "mismatch": _risk_scene_check(risk, report), "scene": str(risk.get("scene", "?")),
            "sha256": str(risk.get("scene_sha256", "not stated")), "draws": fmt_number(risk.get("draws"), sig=10),
            "seed": str(risk.get("seed")), "sampling": str(risk.get("sampling", "not stated")),
            "mpe": f"{fmt_number(risk.get('mpe_w_m2'), 'W/m²', sig=6)} ({risk.get('standard', 'standard not stated')})",
            "criterion": str(risk.get("criterion", "not stated")), "statements": statement_section(risk, RISK_ROWS_SHOWN),
            "inputs": inputs_rows(risk), "map": map_summary(risk), "picture": picture, "picture_absent": absent,
            "notes": [str(n) for n in risk.get("notes") or []], "left_out": [str(n) for n in risk.get("left_out") or []]}


def _sections(risk) -> dict:
    """The page's sections in order: SECTIONS, with the risk section after RISK_AFTER when shown."""
    if risk is None:
        return dict(SECTIONS)
    out = {}
    for sid, title in SECTIONS.items():
        out[sid] = title
        if sid == RISK_AFTER:
            out[RISK_SECTION[0]] = RISK_SECTION[1]
    return out


def review_context(doc: dict, out: Path, report_path: Path, pictures: dict, observers=()) -> dict:
    """Everything the template shows, each part from its report.json keys (``observers``:
    names whose irradiance steps are shown besides the highest ten)."""
    from hazard.outputs.review_steps import analysed_times_text, steps_section

    obs = observers_section(doc)
    stages = doc.get("stages") or []
    risk = risk_section(out, doc, pictures.get("risk", []))
    if (risk is None or risk["problem"]) and pictures.get("risk"):  # a map without a readable risk.json: with the others
        pictures = pictures | {"other": pictures["other"] + pictures["risk"], "risk": []}
    return {
        "title": f"Laser reflection hazard: {(doc.get('scene') or {}).get('name', '?')}",
        "verdict": _verdict(doc, obs), "scene": _scene_view(doc), "echo": _echo_rows(doc),
        "beam": kv_rows(doc.get("beam"), "beam", skip=("spill", "sampling"), sig=4),
        "sampling": kv_rows((doc.get("beam") or {}).get("sampling"), "beam.sampling", sig=4),
        "attenuation": fmt_number(doc.get("attenuation_per_m"), "1/m"), "times": doc.get("times_s") or {},
        "mpe": mpe_section(doc), "sdz": _sdz_view(doc.get("sdz")), "spill": _spill_view(doc.get("beam")),
        "footprint": _footprint_rows(doc.get("footprint")),
        "targets": [_target_view(t, i) for i, t in enumerate(doc.get("targets") or [])],
        "verdict_changes": list(doc.get("verdict_changes") or []), "changes_shown": VERDICT_CHANGES_SHOWN,
        "pictures": pictures, "observers": obs, "moving": motion_section(doc, out, pictures),
        "ran": [s for s in stages if s.get("ran")], "skipped": [s for s in stages if not s.get("ran")],
        "skip_reason": {s.get("name"): s.get("detail", "") for s in stages if not s.get("ran")},
        "assumptions": assumptions(doc), "versions": doc.get("versions") or {},
        "frame": _frame_view(doc), "files": _files_view(doc, out, report_path, pictures),
        "risk": risk, "sections": _sections(risk), "report_format": doc.get("format"), "report_version": doc.get("version"),
        "fmt": fmt_number, "dist": fmt_distance,
        "steps": steps_section(doc, observers), "times_text": analysed_times_text(doc),
    }


# -- rendering and writing -----------------------------------------------------------
def review_html(out_dir, observers=()) -> str:
    """The review page of ``out_dir`` as HTML text (see :func:`write_review`)."""
    doc, path = read_report(out_dir)
    out = Path(out_dir)
    pictures = collect_pictures(out, path.stat().st_mtime)
    return template_environment().get_template("review.html.j2").render(**review_context(doc, out, path, pictures, observers))


def find_chromium() -> str | None:
    """A Chromium (or Chrome) binary: /usr/bin/chromium, else chromium, chromium-browser
    or google-chrome on PATH; None when there is none."""
    for p in CHROMIUM_PATHS:
        if os.path.isfile(p) and os.access(p, os.X_OK):
            return p
    for name in CHROMIUM_NAMES:
        found = shutil.which(name)
        if found:
            return found
    return None


def print_pdf(html_path: Path, pdf_path: Path, browser: str) -> Path:
    """Print ``html_path`` to ``pdf_path`` with headless ``browser`` (a temporary profile;
    the PDF goes to a temporary file beside ``pdf_path``, then is renamed into place).

    Raises
    ------
    PdfError
        The browser failed, timed out or wrote no PDF (its last stderr line said).
    """
    def write(tmp):
        with tempfile.TemporaryDirectory(prefix="hazard-chromium-") as profile:
            cmd = [browser, *CHROMIUM_FLAGS, f"--user-data-dir={profile}", f"--print-to-pdf={tmp}",
                   Path(html_path).resolve().as_uri()]
            try:
                res = subprocess.run(cmd, stdin=subprocess.DEVNULL, capture_output=True, timeout=PDF_TIMEOUT_S)
            except subprocess.TimeoutExpired:
                raise PdfError(f"{browser} did not print the PDF within {PDF_TIMEOUT_S:g} s; the HTML was written: "
                               f"{html_path}", html_path) from None
        with open(tmp, "rb") as fh:
            ok = fh.read(5) == b"%PDF-"
        if res.returncode != 0 or not ok:
            said = [line for line in res.stderr.decode("utf-8", "replace").splitlines() if line.strip()]
            raise PdfError(f"{browser} exited with code {res.returncode} without a PDF"
                           f"{': ' + said[-1].strip()[:200] if said else ''}; the HTML was written: {html_path}", html_path)

    return atomic_write(pdf_path, write)


def write_review(out_dir, *, pdf: bool = False, progress=None, observers=()) -> list[Path]:
    """Write the report for the review board, ``OUT/report.html`` (and ``report.pdf``).

    Parameters
    ----------
    out_dir : str or Path
        An output folder of ``hazard run`` (holding report.json; pictures of ``--plot``
        and ``hazard render`` in it are embedded).
    pdf : bool
        Also print the page to ``OUT/report.pdf`` with headless Chromium.
    progress : callable, optional
        Called with a short message before each step (``"writing report.html"``).
    observers : sequence of str
        Observer names whose irradiance is shown with its steps besides the ten highest
        hazard ratios (a name report.json does not list is said on the page).

    Returns
    -------
    list of Path
        The files written: report.html, then report.pdf when asked.

    Raises
    ------
    ValueError
        No report.json in ``out_dir``, or not a laser-hazard report (one line naming it).
    PdfError
        ``pdf=True`` and no Chromium was found, or it failed; report.html was written.
    """
    say = progress or (lambda msg: None)
    out = Path(out_dir)
    say("reading report.json and the pictures")
    html = review_html(out, observers)
    say(f"writing {HTML_NAME}")
    written = [atomic_write_text(out / HTML_NAME, html)]
    if pdf:
        browser = find_chromium()
        if browser is None:
            raise PdfError("PDF needs Chromium: none found (/usr/bin/chromium, or chromium, chromium-browser, "
                           f"google-chrome on PATH; Debian: apt-get install chromium); the HTML was written: {written[0]}",
                           written[0])
        say(f"printing {PDF_NAME} with {browser}")
        written.append(print_pdf(written[0], out / PDF_NAME, browser))
    return written
