"""The files of a risk analysis: ``risk.json``, ``risk.csv`` and the probability map
(``probability_map.csv``; with a ``[site]`` ``probability_map.tif`` and
``probability_contours.geojson`` in WGS 84, else ``probability_map_local_frame.tif`` and
``probability_contours_local_frame.json``). Every file is written whole (temporary,
then rename).

The contours are drawn from the cells whose 95 % upper bound reaches each level (a cell
whose interval straddles a level is inside it): conservative, never the estimate alone.
A cell without an exceedance in the draws is inside every level up to its zero-hit bound;
each feature counts those cells (``unresolved_cells``) and the collection states the bound
(``laser_hazard.zero_hit_bound``), so a contour that only restates the bound is told apart.
"""

from __future__ import annotations

import csv
import io
import json
import math
import uuid

import numpy as np

from brdfmodels.fileio import atomic_write_text, atomic_write

__all__ = ["write_outputs", "CSV_COLUMNS", "CONTOUR_LEVELS"]

CONTOUR_LEVELS = (1e-6, 1e-5, 1e-4, 1e-3, 1e-2, 1e-1)
CSV_COLUMNS = ["name", "x_m", "y_m", "z_m", "optical_gain", "probability_exceed", "probability_ci_low", "probability_ci_high", "ci_method",
               "hits", "draws", "effective_draws", "hazard_ratio_p50", "hazard_ratio_p95", "hazard_ratio_p99", "irradiance_p50_w_m2",
               "irradiance_p95_w_m2", "irradiance_p99_w_m2", "lit_fraction", "hazard_ratio_lit_p50", "hazard_ratio_lit_p95",
               "hazard_ratio_lit_p99", "probability_exceed_aided", "probability_per_year",
               "probability_per_year_ci_high", "driver", "sensitivity_of"]


def _cell(v) -> str:
    if v is None:
        return ""
    if isinstance(v, float):
        return repr(v) if math.isfinite(v) else ("inf" if v > 0 else "nan")
    return str(v)


def _csv_row(r: dict, draws: int, inputs: list) -> list:
    q, qe = r["hazard_ratio_quantiles"], r["irradiance_quantiles_w_m2"]
    ops, sens = r["operations"], r["sensitivity"]
    aided = max((a["probability_exceed"] for a in r["aided"]), default=None)
    first = (sens or {}).get("first_order") or {}
    ql = r.get("hazard_ratio_quantiles_lit") or {}
    vals = [r["name"], *r["position_m"], r["optical_gain"], r["probability_exceed"], r["probability_ci_low"], r["probability_ci_high"],
            r["ci_method"], r["hits"], draws, r["effective_draws"], q["p50"], q["p95"], q["p99"], qe["p50"], qe["p95"], qe["p99"],
            r.get("lit_fraction"), ql.get("p50"), ql.get("p95"), ql.get("p99"), aided,
            None if ops is None else ops["probability_at_least_one"], None if ops is None else ops["ci_high"],
            None if sens is None else sens["driver"], None if sens is None else sens["of"]]
    return [_cell(v) for v in vals] + [_cell(first.get(g)) for g in inputs]


def risk_csv(rows: list, draws: int, inputs: list) -> str:
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(CSV_COLUMNS + [f"sobol_{g}" for g in inputs])
    for r in rows:
        w.writerow(_csv_row(r, draws, inputs))
    return buf.getvalue()


def map_csv(mp: dict) -> str:
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(["x_m", "y_m", "z_m", "probability_exceed", "probability_ci_low", "probability_ci_high", "hits"])
    for j, p in enumerate(mp["points_m"]):
        w.writerow([_cell(float(p[0])), _cell(float(p[1])), _cell(float(p[2])), _cell(float(mp["probability"][j])),
                    _cell(float(mp["ci_low"][j])), _cell(float(mp["ci_high"][j])), int(mp["hits"][j])])
    return buf.getvalue()


def _grid(mp: dict, key: str) -> np.ndarray:
    """A map column as rows north to south (raster order)."""
    return np.asarray(mp[key], "float32").reshape(mp["shape"])[::-1, :]


def map_tiff(scene, mp: dict) -> bytes:
    """GeoTIFF of the map: band 1 the probability, 2 its 95 % upper bound, 3 the lower."""
    from rasterio.io import MemoryFile
    from rasterio.transform import from_origin

    from hazard.outputs.map_outputs import site_crs

    ny, nx = mp["shape"]
    d = mp["spacing_m"]
    transform = from_origin(mp["extent_m"][0], mp["extent_m"][2] + ny * d, d, d)  # the top edge of the last row
    bands = np.stack([_grid(mp, "probability"), _grid(mp, "ci_high"), _grid(mp, "ci_low")])
    with MemoryFile() as mem:
        with mem.open(driver="GTiff", width=nx, height=ny, count=3, dtype="float32", crs=site_crs(scene), transform=transform,
                      compress="deflate") as ds:
            ds.write(bands)
            ds.update_tags(scene=scene.name, scene_sha256=scene.text_sha256, eye_height_m=str(mp["eye_height_m"]),
                           method=mp["method"], frame="site orthographic (ENU on the ellipsoid)" if scene.site is not None else
                           "the scene's local frame (no [site]: no CRS)")
            for i, n in enumerate(["probability of exceeding the MPE", "95 % upper bound", "95 % lower bound"], 1):
                ds.set_band_description(i, n)
        return mem.read()


def contours(scene, mp: dict) -> dict:
    """GeoJSON of the cells whose upper bound reaches each level (lon/lat with a site)."""
    from shapely.geometry import box, mapping
    from shapely.ops import unary_union

    from hazard.outputs.map_outputs import to_lonlat

    pts, hi, h = mp["points_m"], np.asarray(mp["ci_high"]), mp["spacing_m"] / 2
    unresolved = np.asarray(mp["hits"]) <= 0
    floor = float(hi[unresolved].max()) if unresolved.any() else None  # what zero hits in these draws can bound
    feats = []
    for level in CONTOUR_LEVELS:
        sel = np.flatnonzero(hi >= level)
        if not len(sel):
            continue
        geom = unary_union([box(pts[j, 0] - h, pts[j, 1] - h, pts[j, 0] + h, pts[j, 1] + h) for j in sel])
        if scene.site is not None:
            z = float(np.mean(pts[sel, 2]))
            geom = to_lonlat(geom, scene.site.frame, None, z)
        feats.append({"type": "Feature", "geometry": mapping(geom),
                      "properties": {"kind": "probability_contour", "level": level, "cells": int(len(sel)),
                                     "unresolved_cells": int(unresolved[sel].sum()),
                                     "rule": "cells whose 95 % upper bound of P(E > MPE) is at or above the level"}})
    frame = "WGS 84 lon/lat" if scene.site is not None else "the scene's local frame [m] (no [site])"
    said = ("every cell has an exceedance in the draws" if floor is None else
            f"{int(unresolved.sum())} cell(s) had no exceedance in the draws: their 95 % upper bound, up to {floor:.3g}, puts "
            "them inside every contour at or below it (unresolved_cells per level); more draws resolve them")
    return {"type": "FeatureCollection", "features": feats, "laser_hazard": {"frame": frame, "scene": scene.name,
                                                                             "levels": list(CONTOUR_LEVELS),
                                                                             "zero_hit_bound": floor, "unresolved": said}}


def _map_files(scene, mp, outdir, notes) -> list:
    import importlib.util

    site = scene.site is not None
    written = ["probability_map.csv"]
    atomic_write_text(outdir / "probability_map.csv", map_csv(mp))
    gj = "probability_contours.geojson" if site else "probability_contours_local_frame.json"
    atomic_write_text(outdir / gj, json.dumps(contours(scene, mp)))
    written.append(gj)
    tif = "probability_map.tif" if site else "probability_map_local_frame.tif"
    if importlib.util.find_spec("rasterio") is None:
        notes.append(f"{tif} not written: rasterio is not installed (pip install 'laser-hazard[geo]')")
    else:
        data = map_tiff(scene, mp)
        atomic_write(outdir / tif, lambda tmp: open(tmp, "wb").write(data))
        written.append(tif)
    return written


def write_outputs(outdir, doc: dict, scene, mp: dict | None) -> list:
    """Write risk.json, risk.csv and the map files; returns the names written."""
    written = []
    if mp is not None:
        written += _map_files(scene, mp, outdir, doc["notes"])
        doc["map"]["files"] = list(written)
    inputs = doc["inputs_active"]
    atomic_write_text(outdir / "risk.csv", risk_csv(doc["observers"], doc["draws"], inputs))
    written.insert(0, "risk.csv")
    doc["files"] = ["risk.json", *written, "risk.html"] + (["probability_map.png"] if mp is not None else [])
    atomic_write_text(outdir / "risk.json", risk_json_text(doc))
    return doc["files"]


def risk_json_text(doc: dict) -> str:
    """risk.json's text: indented one space per level, but each observer's row on one line,
    encoded by json's C encoder (an indented encoding runs the per-element Python encoder:
    3.6 s against 1.0 s for 1e4 observers). The same values; only the layout of the
    ``observers`` list differs from ``json.dumps(doc, indent=1)``."""
    mark = f"observers-{uuid.uuid4().hex}"
    head = json.dumps({**doc, "observers": mark}, indent=1, allow_nan=False, default=_json_default)
    rows = [json.dumps(r, allow_nan=False, default=_json_default) for r in doc["observers"]]
    return head.replace(json.dumps(mark), "[" + ",".join("\n  " + r for r in rows) + "\n ]" if rows else "[]", 1)


def _json_default(v):
    if isinstance(v, np.generic):
        return v.item()
    if isinstance(v, np.ndarray):
        return v.tolist()
    raise TypeError(f"not JSON: {type(v).__name__}")
