"""figures.json (issue 34 item 1): every hazardous finding of report.json is drawn in a
picture, inside the picture's frame, with its label; a finding off the frame gets an
arrow with its distance. The findings are enumerated here from report.json alone, and
the places of those report.json locates (observers, tracks, flight zones, the danger
zone) are checked against the panels' extents independently of the pictures' own
"inside" answers."""

from __future__ import annotations

import json

import numpy as np
import pytest

import scenes
from tests._bundled import bundled

pytest.importorskip("matplotlib")

FAST = ["mirror_window"]  # analysis 0.3 s, the two views 2.2 s
SLOW = ["airspace", "binoculars", "plate", "range_clearance", "range_geo", "range_terrain", "risk", "stainless_melt",
        "witness_screen"]  # steel_vs_copper: tests/hazard/test_plan_view.py checks its hazard run --plot outputs


def hazardous_paths(doc) -> list:
    """report.json paths of every hazardous finding: the danger zones (naked and aided)
    and mirror beams with an NOHD > 0, the keep-out lobes that reach (NOHD > 0), every
    observer at or above the MPE, every moving observer, every exceeded flight zone,
    the direct beam's FAA distances (visible lasers) and the footprints with cells."""
    out = []
    z = doc.get("sdz") or {}
    if (z.get("nohd_m") or 0) > 0 and z.get("polygon_m"):
        out.append("sdz")
    out += [f"sdz.aided[{k}]" for k, a in enumerate(z.get("aided") or []) if (a.get("nohd_m") or 0) > 0 and a.get("polygon_m")]
    out += [f"sdz.mirror_beams[{k}]" for k, m in enumerate(z.get("mirror_beams") or []) if (m.get("nohd_m") or 0) > 0]
    for j, t in enumerate(doc["targets"]):
        out += [f"targets[{j}].keepout_{kind}" for kind in ("static", "dynamic")
                if t.get(f"keepout_{kind}") and (t[f"keepout_{kind}"].get("max_nohd_m") or 0) > 0]
    out += [f"observers[{i}]" for i, o in enumerate(doc["observers"]) if o["hazardous"]]
    out += [f"tracks[{k}]" for k in range(len(doc.get("tracks") or []))]
    out += [f"airspace.zones[{k}]" for k, a in enumerate((doc.get("airspace") or {}).get("zones") or []) if not a["holds"]]
    vi = doc.get("visual_interference") or {}
    if vi.get("applies"):
        out += [f"visual_interference.direct.{lv}_m" for lv in ("szed", "czed", "lfed") if (vi["direct"].get(f"{lv}_m") or 0) > 0]
    out += [f"footprint.{k}" for k, f in (doc.get("footprint") or {}).items() if f["cells"] > 0]
    return out


def _in(extent, xy, tol=1e-6) -> bool:
    x0, x1, y0, y1 = extent
    span = max(abs(x1 - x0), abs(y1 - y0))
    return min(x0, x1) - tol * span <= xy[0] <= max(x0, x1) + tol * span and min(y0, y1) - tol * span <= xy[1] <= max(y0, y1) + tol * span


def _plan_point(doc, path):
    """Where report.json puts a finding in the plan (world x, y), or None."""
    kind, _, rest = path.partition("[")  # report.json's positions are world coordinates, as the plan's axes
    if kind == "observers":
        return np.asarray(doc["observers"][int(rest[:-1])]["position_m"], float)[:2]
    if kind == "airspace.zones":
        return np.asarray(doc["airspace"]["zones"][int(rest[:-1])]["worst_point_m"], float)[:2]
    if kind == "tracks":
        return np.asarray(doc["tracks"][int(rest[:-1])]["worst_point_m"], float)[:2]
    return None


def check_coverage(doc, figures) -> list:
    """The hazardous findings of ``doc`` (report.json) that no spatial picture of
    ``figures`` (figures.json) draws inside a panel with its label shown (or points to
    with an arrow and its distance), with why; [] when all are drawn."""
    panels = {}
    drawn = {}
    for fname, entry in figures["figures"].items():
        if entry["view"] not in ("plan", "elevation"):
            continue
        for p in entry["panels"]:
            panels[(fname, p["title"])] = p["extent"]
        for f in entry["findings"]:
            for path, inside in zip(f["paths"], f["inside"]):
                drawn.setdefault(path, []).append((fname, f, inside))
    missing = []
    for path in hazardous_paths(doc):
        ok = []
        for fname, f, inside in drawn.get(path, []):
            if not f["label_shown"] or not inside:
                continue
            if f["how"] == "arrow":
                ok.append(f.get("distance_m", 0) > 0 and f"{f['distance_m'] / 1000:.3g} km" in f["label"] or
                          f"{f['distance_m']:.3g} m" in f["label"])
                continue
            where = _plan_point(doc, path) if entry_view(figures, fname) == "plan" else None
            ok.append(where is None or _in(panels[(fname, f["panel"])], where))
        if not any(ok):
            missing.append((path, [(fname, f["panel"], f["how"], inside, f["label_shown"]) for fname, f, inside in drawn.get(path, [])]))
    return missing


def entry_view(figures, fname) -> str:
    return figures["figures"][fname]["view"]


def _spatial_figures(result) -> dict:
    from hazard.pictures.elevation_view import ElevationViewDisplay
    from hazard.outputs.figure_index import figures_document
    from hazard.pictures.plan_view import PlanViewDisplay

    entries = {}
    for name, display, view in (("plan.png", PlanViewDisplay, "plan"), ("elevation.png", ElevationViewDisplay, "elevation")):
        entries[name] = display.from_result(result).png_and_entry(view)[1]
    return json.loads(figures_document(entries))


def _report(result) -> dict:
    from hazard.outputs.report import report_dict

    return json.loads(json.dumps(report_dict(result), allow_nan=False))


def _coverage(name):
    res = bundled(name)
    doc, figs = _report(res), _spatial_figures(res)
    assert not check_coverage(doc, figs), check_coverage(doc, figs)
    return doc, figs


@pytest.mark.parametrize("name", FAST + [pytest.param(n, marks=pytest.mark.slow) for n in SLOW])
def test_every_hazardous_finding_is_drawn_inside_a_panel_with_its_label(name):
    assert set(FAST + SLOW + ["steel_vs_copper"]) == set(scenes.examples())  # a new example is added here too
    doc, figs = _coverage(name)
    assert hazardous_paths(doc)  # every bundled example has something to draw


@pytest.mark.slow
def test_airspace_draws_its_flight_zones_track_and_faa_distances_with_arrows_off_the_frame():
    doc, figs = _coverage("airspace")
    plan = figs["figures"]["plan.png"]["findings"]
    arrows = {p: f for f in plan if f["how"] == "arrow" for p in f["paths"]}
    lfed = doc["visual_interference"]["direct"]["lfed_m"]  # 212 km: past every panel
    assert "visual_interference.direct.lfed_m" in arrows and arrows["visual_interference.direct.lfed_m"]["distance_m"] > 0.9 * lfed
    zones = [f for f in plan if f["paths"] == ["airspace.zones[0]"] and f["panel"].endswith("the range")]
    assert zones and zones[0]["inside"] == [True] and "EXCEEDED" in zones[0]["label"]
    assert zones[0]["bbox"] == [-1000.0, 1000.0, 8000.0, 10000.0]  # the scene file's outline of the airfield's zone
    assert any(f["paths"][0] == "tracks[0]" and f["inside"][0] for f in figs["figures"]["elevation.png"]["findings"])


def test_a_finding_off_the_frame_gets_an_arrow_inside_it_with_its_distance():
    from hazard.canvas import subplots
    from hazard.outputs.figure_index import arrow_to, figure_entry

    fig, ax = subplots(figsize=(4, 4))
    ax.set_xlim(-100, 100)
    ax.set_ylim(-100, 100)
    ax.set_title("panel")
    arrow_to(ax, ["airspace.zones[0]"], "zone", (0.0, 0.0), (0.0, 8000.0))
    entry = figure_entry(fig, "plan")
    (f,) = entry["findings"]
    assert f["how"] == "arrow" and f["inside"] == [True] and f["label_shown"]
    assert f["distance_m"] == pytest.approx(8000.0) and "8 km" in f["label"]
    assert entry["panels"][0]["extent"] == [-100.0, 100.0, -100.0, 100.0]  # the frame is not widened to the arrow's target
    x0, x1, y0, y1 = f["bbox"]
    assert -100 < x0 <= x1 < 100 and 0 < y0 <= y1 < 100  # its tip inside the frame, on the side of the target (north)


def test_a_finding_drawn_off_the_panel_is_not_inside_and_its_label_must_be_shown():
    from hazard.canvas import subplots
    from hazard.outputs.figure_index import figure_entry, mark

    fig, ax = subplots(figsize=(4, 4))
    ax.set_title("panel")
    ax.scatter([0.0, 500.0], [0.0, 0.0], label="observers at or above the MPE (2)")
    ax.set_xlim(-10, 10)
    ax.set_ylim(-10, 10)
    ax.legend()
    mark(ax, ["observers[0]", "observers[1]"], "observers at or above the MPE (2)", [[0.0, 0.0], [500.0, 0.0]])
    mark(ax, ["sdz"], "a label nobody drew", [[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]], "polygon")
    f1, f2 = figure_entry(fig, "plan")["findings"]
    assert f1["inside"] == [True, False] and f1["label_shown"]
    assert f2["inside"] == [True] and not f2["label_shown"]
    doc = {"sdz": {"nohd_m": 1.0, "polygon_m": [[0, 0]]}, "targets": [], "observers": [{"hazardous": True, "position_m": [0, 0, 0]},
                                                                                       {"hazardous": True, "position_m": [500, 0, 0]}],
           "scene": {"offset_m": [0, 0, 0]}}
    figs = {"figures": {"plan.png": figure_entry(fig, "plan")}}
    assert [m[0] for m in check_coverage(doc, figs)] == ["sdz", "observers[1]"]  # the checker finds both gaps


def test_an_unbounded_curve_still_makes_valid_json():
    import math

    from hazard.canvas import subplots
    from hazard.outputs.figure_index import figure_entry, figures_document, mark

    fig, ax = subplots(figsize=(3, 3))
    ax.set_title("target t: diffuse-lobe NOHD vs time")
    mark(ax, ["targets[0].keepout_dynamic"], ax.get_title(), [[0.0, 5.0], [1.0, math.inf]], "line")
    mark(ax, ["sdz"], ax.get_title(), [[math.nan, math.nan]], "points")
    doc = json.loads(figures_document({"nohd_time_t.png": figure_entry(fig, "time")}))
    a, b = doc["figures"]["nohd_time_t.png"]["findings"]
    assert a["bbox"] == [0.0, 0.0, 5.0, 5.0] and a["label_shown"] and b["bbox"] is None and b["inside"] == [False]
