"""``map.html``: the run's plan view as an interactive map page that works offline.

``write_map_page(OUT)`` reads what ``hazard run`` wrote into ``OUT`` (report.json and the
zones GeoJSON, ``zones.geojson`` with a ``[site]`` or ``zones_local_frame.json`` without)
and writes ``OUT/map.html``: one file with Leaflet (BSD-2-Clause, vendored in
``hazard/templates/vendor/leaflet`` with its licence and provenance) and the data inlined,
so it opens without any network. Nothing is recomputed: every outline is the GeoJSON's,
every number in a pop-up is report.json's (observers not listed there: observers.csv's,
else the GeoJSON's own properties), each pop-up naming its source.

The page shows one toggled layer per kind of finding (danger zones, hazardous ground,
keep-out lobes' ground outlines, mirror beams, tracks, flight zones, FAA visual zones,
observers at or above the MPE and below it, laser and targets, range boundary), pan and
zoom, a scale bar and the cursor's position: longitude and latitude (Web Mercator) with a
site, else the scene's local metres (``L.CRS.Simple``: 1 unit = 1 m, y north). Every kind
the run does not have is listed with the GeoJSON's reason; nothing is left out silently.

With terrain, a hillshade of the terrain grid as analysed (the scene is loaded again from
report.json's ``scene.source`` when that file still has the analysed text's sha256; else
the page says why there is none). With a site, the hillshade is placed by its corners in
Web Mercator; the page states the largest offset of a terrain node from its exact
position (the findings themselves are drawn at their exact longitude and latitude).
"""

from __future__ import annotations

import base64
import json
import math
import struct
import zlib
from pathlib import Path

import numpy as np
from brdfmodels.fileio import atomic_write_text

from hazard.outputs.review import fmt_distance, fmt_number, kv_rows, read_report

__all__ = ["MAP_NAME", "LAYERS", "write_map_page", "map_html", "map_data", "hillshade", "png_gray_alpha"]

MAP_NAME = "map.html"
VENDOR = "vendor/leaflet"  # under hazard/templates
HILLSHADE_MAX_PX = 1500  # the hillshade keeps every k-th node so that no side has more pixels (said on the page)
SUN_AZIMUTH_DEG, SUN_ALTITUDE_DEG = 315.0, 45.0  # the cartographers' north-west light
HILLSHADE_CONTRAST = 3.0  # opacity per unit of (lit / lit when flat - 1): gentle ranges still show their relief
OBSERVER_KEYS = (("peak_irradiance_w_m2", "peak irradiance"), ("mpe_w_m2", "MPE"), ("hazard_ratio", "hazard ratio"),
                 ("exposure_ratio", "exposure ratio"), ("radiant_exposure_j_m2", "radiant exposure"),
                 ("mpe_radiant_exposure_j_m2", "MPE (radiant exposure)"), ("first_exceedance_s", "first exceedance"))

# layer id -> (title, the GeoJSON kinds it draws, a test on the properties, style); drawn in this order:
# areas first, points last so that a click finds the point, hazardous observers over everything
LAYERS = {
    "visual_zone": ("FAA visual zones (SZED, CZED, LFED)", ("visual_zone",), None,
                    {"color": "#8e44ad", "weight": 1.5, "fillOpacity": 0.04, "dashArray": "6 4"}),
    "airspace_zone": ("Flight zones", ("airspace_zone",), None, {"color": "#1f6fb2", "weight": 2, "fillOpacity": 0.08}),
    "range_boundary": ("Range boundary", ("range_boundary",), None, {"color": "#222222", "weight": 2, "fill": False}),
    "sdz": ("Laser surface danger zone (direct beam)", ("sdz",), None,
            {"color": "#d7191c", "weight": 2, "fillOpacity": 0.18}),
    "sdz_nominal": ("Danger zone without the pointing buffer", ("sdz_nominal",), None,
                    {"color": "#d7191c", "weight": 1, "fillOpacity": 0.0, "dashArray": "4 4"}),
    "sdz_aided": ("Danger zone through optical aids", ("sdz_aided",), None,
                  {"color": "#f39c12", "weight": 2, "fillOpacity": 0.10}),
    "footprint": ("Hazardous ground at eye height", ("footprint",), None,
                  {"color": "#7b0d0d", "weight": 1, "fillColor": "#b2182b", "fillOpacity": 0.55}),
    "keepout_lobe": ("Keep-out lobes (ground outline)", ("keepout_lobe",), None,
                     {"color": "#2166ac", "weight": 2, "fillOpacity": 0.15}),
    "mirror_beam": ("Mirror beams", ("mirror_beam",), None, {"color": "#e66101", "weight": 3}),
    "mirror_beam_zone": ("Reflected-beam hazard zones (mirrors, with their width)", ("mirror_beam_zone",), None,
                         {"color": "#e66101", "weight": 1.5, "fillOpacity": 0.25}),
    "track": ("Moving observers' tracks", ("track",), None, {"color": "#1a9641", "weight": 3, "dashArray": "8 5"}),
    "laser_targets": ("Laser and targets", ("laser", "target"), None,
                      {"color": "#000000", "fillColor": "#ffffff", "radius": 7, "weight": 2.5, "fillOpacity": 1.0}),
    "observers_safe": ("Observers below the MPE", ("observer",), lambda p: p.get("hazard") in (None, "none"),
                       {"color": "#00441b", "fillColor": "#4daf4a", "radius": 4, "weight": 1, "fillOpacity": 0.9}),
    "observers_hazardous": ("Observers at or above the MPE", ("observer",), lambda p: p.get("hazard") not in (None, "none"),
                            {"color": "#67000d", "fillColor": "#e41a1c", "radius": 6, "weight": 1.5, "fillOpacity": 0.95}),
}
LEGEND_ORDER = ("observers_hazardous", "sdz", "sdz_aided", "footprint", "keepout_lobe", "mirror_beam", "mirror_beam_zone", "track",
                "airspace_zone", "visual_zone", "sdz_nominal", "range_boundary", "laser_targets", "observers_safe")  # findings first


# -- the hillshade ---------------------------------------------------------------------
def hillshade(heights_m: np.ndarray, dx_m: float, azimuth_deg: float = SUN_AZIMUTH_DEG,
              altitude_deg: float = SUN_ALTITUDE_DEG) -> np.ndarray:
    """Lambertian shading of a height grid (rows south to north, columns west to east).

    Parameters
    ----------
    heights_m : ndarray, shape (ny, nx)
        Ground heights [m] on a square grid; NaN where unknown.
    dx_m : float
        Node spacing [m].
    azimuth_deg, altitude_deg : float
        Direction of the light: azimuth clockwise from north, altitude above the horizon [deg].

    Returns
    -------
    ndarray, shape (ny, nx)
        cos of the angle between the ground's normal and the light, clipped to [0, 1]
        (1: facing the light; flat ground: sin(altitude)); NaN where a height is NaN.
    """
    h = np.asarray(heights_m, float)
    if min(h.shape) < 2:
        return np.full(h.shape, math.sin(math.radians(altitude_deg)))
    gy, gx = np.gradient(h, dx_m)  # d/dy (north), d/dx (east)
    az, alt = math.radians(azimuth_deg), math.radians(altitude_deg)
    light = np.array([math.cos(alt) * math.sin(az), math.cos(alt) * math.cos(az), math.sin(alt)])
    shade = (-gx * light[0] - gy * light[1] + light[2]) / np.sqrt(1.0 + gx * gx + gy * gy)
    return np.clip(shade, 0.0, 1.0)


def png_gray_alpha(gray: np.ndarray, alpha: np.ndarray) -> bytes:
    """An 8-bit grey + alpha PNG (rows top to bottom) from two uint8 arrays (zlib only)."""
    g = np.asarray(gray, np.uint8)
    a = np.asarray(alpha, np.uint8)
    rows = np.dstack([g, a]).reshape(g.shape[0], -1)
    raw = b"".join(b"\x00" + r.tobytes() for r in rows)

    def chunk(tag: bytes, data: bytes) -> bytes:
        return struct.pack(">I", len(data)) + tag + data + struct.pack(">I", zlib.crc32(tag + data) & 0xFFFFFFFF)

    head = struct.pack(">IIBBBBB", g.shape[1], g.shape[0], 8, 4, 0, 0, 0)
    return b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", head) + chunk(b"IDAT", zlib.compress(raw, 9)) + chunk(b"IEND", b"")


def _analysed_scene(doc: dict):
    """The scene report.json analysed, loaded again from its source when the file still
    holds that text (sha256); else (None, why not)."""
    import scenes

    info = doc.get("scene") or {}
    src = info.get("source")
    if not src or not Path(src).is_file():
        return None, f"the scene file {src or '(report.json names none)'} is not there to read the terrain from"
    try:
        scene = scenes.load(src)
    except Exception as exc:  # any failure to load leaves the page without a hillshade, said
        return None, f"the scene file {src} no longer loads ({str(exc).splitlines()[0][:160]})"
    if scene.text_sha256 != info.get("sha256"):
        return None, f"the scene file {src} has changed since the run (sha256 differs): its terrain may not be the analysed one"
    return scene, ""


def _terrain_grid(scene):
    """World x, y node coordinates [m], heights [m] and spacing of ``scene``'s terrain, every
    k-th node kept so that no side exceeds :data:`HILLSHADE_MAX_PX`; and k."""
    t, off = scene.terrain, np.asarray(scene.offset_m, float)
    k = max(1, math.ceil(max(t.heights.shape) / HILLSHADE_MAX_PX))
    h = np.asarray(t.heights, float)[::k, ::k] + off[2]
    x = t.x0 + off[0] + t.dx * k * np.arange(h.shape[1])
    y = t.y0 + off[1] + t.dx * k * np.arange(h.shape[0])
    return x, y, h, t.dx * k, k


def _mercator(lat_deg, lon_deg):
    return np.radians(lon_deg), np.log(np.tan(np.pi / 4 + np.radians(lat_deg) / 2))


def _site_placement(scene, x, y, h, d) -> tuple[list, float]:
    """Leaflet bounds [[lat S, lon W], [lat N, lon E]] of the hillshade's outer corners
    and the largest distance [m] of a node from its exact place on that image."""
    frame = scene.site.frame
    xe, ye = np.array([x[0] - d / 2, x[-1] + d / 2]), np.array([y[0] - d / 2, y[-1] + d / 2])
    cx, cy = np.meshgrid(xe, ye)
    lat, lon, _ = frame.geodetic(np.column_stack([cx.ravel(), cy.ravel(), np.full(4, float(np.nanmean(h)))]))
    bounds = [[float(lat.min()), float(lon.min())], [float(lat.max()), float(lon.max())]]
    iy = np.unique(np.linspace(0, len(y) - 1, 9).round().astype(int))
    ix = np.unique(np.linspace(0, len(x) - 1, 9).round().astype(int))
    gx, gy = np.meshgrid(x[ix], y[iy])
    gz = np.nan_to_num(h[np.ix_(iy, ix)], nan=float(np.nanmean(h)))
    tl, tn, _ = frame.geodetic(np.column_stack([gx.ravel(), gy.ravel(), gz.ravel()]))
    mx0, my0 = _mercator(bounds[0][0], bounds[0][1])
    mx1, my1 = _mercator(bounds[1][0], bounds[1][1])
    fx = ((gx.ravel() - xe[0]) / (xe[1] - xe[0]))  # where the image puts each node, as a fraction of its width
    fy = ((gy.ravel() - ye[0]) / (ye[1] - ye[0]))
    img_lon = np.degrees(mx0 + fx * (mx1 - mx0))
    img_lat = np.degrees(2 * np.arctan(np.exp(my0 + fy * (my1 - my0))) - np.pi / 2)
    r = float(frame.radius_m)
    err = np.hypot(np.radians(img_lat - tl) * r, np.radians(img_lon - tn) * r * np.cos(np.radians(tl)))
    return bounds, float(err.max())


def hillshade_layer(doc: dict) -> tuple[dict | None, str]:
    """The hillshade overlay (a PNG data URI, its bounds, and what it is), or why none."""
    if not ((doc.get("scene") or {}).get("echo") or {}).get("terrain"):
        return None, "the scene has no terrain (flat ground at z = 0): no hillshade"
    scene, why = _analysed_scene(doc)
    if scene is None:
        return None, f"no hillshade: {why}"
    if scene.terrain is None:
        return None, "the scene has no terrain grid: no hillshade"
    x, y, h, d, k = _terrain_grid(scene)
    shade = hillshade(h, d) / math.sin(math.radians(SUN_ALTITUDE_DEG))  # 1: lit as flat ground
    gray = np.where(shade < 1.0, 0, 255)[::-1].astype(np.uint8)  # image rows north to south
    alpha = np.nan_to_num(np.clip(np.abs(shade - 1.0) * HILLSHADE_CONTRAST, 0.0, 0.85) * 255.0, nan=0.0)
    alpha = alpha[::-1].round().astype(np.uint8)
    uri = "data:image/png;base64," + base64.b64encode(png_gray_alpha(gray, alpha)).decode()
    kind = (doc["scene"]["echo"]["terrain"] or {}).get("kind", "terrain")
    what = (f"hillshade of the analysed terrain ({kind}; {h.shape[1]} x {h.shape[0]} nodes every {d:g} m"
            f"{f', every {k}th node of the grid' if k > 1 else ''}; light from {SUN_AZIMUTH_DEG:g} deg at {SUN_ALTITUDE_DEG:g} deg: "
            f"slopes lit less than flat ground darkened, lit more lightened, {HILLSHADE_CONTRAST:g} x the difference; "
            "flat ground left clear)")
    if scene.site is not None:
        bounds, err_m = _site_placement(scene, x, y, h, d)
        what += (f"; placed by its corners in Web Mercator: a terrain node is within {err_m:.2g} m of its exact place "
                 "(the findings are drawn at their exact longitude and latitude)")
    else:
        bounds = [[float(y[0] - d / 2), float(x[0] - d / 2)], [float(y[-1] + d / 2), float(x[-1] + d / 2)]]
    return {"uri": uri, "bounds": bounds, "what": what}, ""


# -- the layers and their pop-ups ------------------------------------------------------
def read_zones(out: Path, doc: dict) -> tuple[dict | None, str, str]:
    """The run's zones GeoJSON (the one report.json's map_outputs names), its file name, and
    why it cannot be read ("" when it can)."""
    files = (doc.get("map_outputs") or {}).get("files") or []
    name = next((n for n in ("zones.geojson", "zones_local_frame.json") if n in files), None)
    if name is None:
        return None, "", "report.json lists no zones GeoJSON (map_outputs.files): run hazard run again to write it"
    path = out / name
    try:
        gj = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError) as exc:
        return None, name, f"{name} cannot be read: {exc}"
    if not isinstance(gj, dict) or not isinstance(gj.get("features"), list):
        return None, name, f"{name} is not the run's FeatureCollection"
    sha = (doc.get("scene") or {}).get("sha256")
    theirs = (gj.get("laser_hazard") or {}).get("scene_sha256")
    if sha and theirs and sha != theirs:
        return None, name, f"{name} is of another scene text (sha256 {theirs}) than report.json ({sha}): run hazard run again"
    return gj, name, ""


def _observer_sources(out: Path, doc: dict) -> dict:
    """name -> (row, source) for every observer: report.json's rows, then observers.csv's."""
    import csv

    rows = {}
    path = out / "observers.csv"
    if path.is_file():
        with open(path, newline="", encoding="utf-8") as fh:
            for r in csv.DictReader(fh):
                rows[r.get("name")] = ({k: _csv_value(v) for k, v in r.items()}, "observers.csv")
    for r in doc.get("observers") or []:
        rows[r.get("name")] = (r, "report.json observers")
    return rows


def _csv_value(v: str):
    if v in ("", None):
        return None
    if v in ("True", "False"):
        return v == "True"
    try:
        return float(v)
    except ValueError:
        return v


def _unit_of(key: str) -> str:
    return {"_w_m2": "W/m²", "_j_m2": "J/m²", "_s": "s"}.get(next((s for s in ("_w_m2", "_j_m2", "_s") if key.endswith(s)), ""), "")


def _observer_popup(p: dict, sources: dict) -> dict:
    """Name, verdict, irradiance, MPE and hazard ratio of one observer, with their source."""
    row, source = sources.get(p.get("name"), (None, ""))
    if row is None:  # not in report.json or observers.csv: the GeoJSON's own numbers
        row, source = p, "zones GeoJSON (the observer is in neither report.json nor observers.csv)"
    lines = [["verdict", str(p.get("verdict", "?")), None]]
    for key, _ in OBSERVER_KEYS:
        if key in row:
            v = row[key]
            text = "none" if v is None and key == "first_exceedance_s" else fmt_number(v, _unit_of(key), sig=4)
            lines.append([key, text, None if not isinstance(v, (int, float)) or isinstance(v, bool) else repr(float(v))])
    return {"title": f"observer {p.get('name', '?')}", "lines": lines, "source": source}


def _feature_popup(kind: str, p: dict, doc: dict) -> dict:
    """The properties of a zone as labelled rows with units (report.json's tables where they say more)."""
    skip = ("kind", "standard", "exposure_duration_s", "mpe_w_m2", "wavelength_nm", "scene", "what")
    extra = {}
    if kind == "track":
        extra = next((t for t in doc.get("tracks") or [] if t.get("name") == p.get("name")), {})
        extra = {k: extra[k] for k in ("peak_irradiance_w_m2", "peak_time_s", "radiant_exposure_j_m2") if k in extra}
    rows = kv_rows({k: v for k, v in p.items() if k not in skip} | extra, kind, sig=4)
    title = " ".join(str(x) for x in (LAYERS.get(kind, (kind,))[0] if kind in LAYERS else kind.replace("_", " "),
                                        p.get("name") or p.get("target") or p.get("level") or "", p.get("variant") or "") if x)
    return {"title": title, "what": p.get("what", ""), "source": "zones GeoJSON",
            "lines": [[r["key"], r["value"], None] for r in rows], "labels": {r["key"]: r["label"] for r in rows}}


def _feature_layer(p: dict) -> str | None:
    kind = p.get("kind")
    for lid, (_, kinds, test, _) in LAYERS.items():
        if kind in kinds and (test is None or test(p)):
            return lid
    return None


def map_layers(gj: dict, doc: dict, out: Path) -> tuple[list, list, dict]:
    """The layers in drawing order (id, title, style, features with pop-ups, hazardous
    count), the features no layer draws (listed on the page) and the pop-ups' row labels
    (key -> label; each pop-up row is [key, value as shown, exact value or None])."""
    sources = _observer_sources(out, doc)
    feats = {lid: [] for lid in LAYERS}
    stray, labels = [], {"verdict": "verdict", **dict(OBSERVER_KEYS)}
    for f in gj["features"]:
        p = dict(f.get("properties") or {})
        if p.get("kind") == "observer" and p.get("hazard") in (None, "none") and \
                (sources.get(p.get("name")) or ({},))[0].get("hazardous") is True:
            p["hazard"] = "naked eye"  # report.json (or observers.csv) says hazardous: drawn so whatever the GeoJSON says
        lid = _feature_layer(p)
        if lid is None:
            stray.append(str(p.get("kind")))
            continue
        popup = _observer_popup(p, sources) if p.get("kind") == "observer" else _feature_popup(p.get("kind", "?"), p, doc)
        labels.update(popup.pop("labels", {}))
        hazard = p.get("hazard", "none") or "none"
        feats[lid].append({"type": "Feature", "geometry": f.get("geometry"),
                           "properties": {"kind": p.get("kind"), "name": str(p.get("name") or p.get("target") or ""),
                                          "variant": p.get("variant"), "hazard": hazard, "popup": popup,
                                          "reach_reported_m": _reported_reach_m(p, doc), "rise_m": _rise_m(p)}})
    layers = []
    for lid, (title, kinds, _, style) in LAYERS.items():
        fs = feats[lid]
        layers.append({"id": lid, "title": title, "kinds": list(kinds), "style": style, "count": len(fs),
                       "legend_rank": LEGEND_ORDER.index(lid),
                       "hazardous": sum(f["properties"]["hazard"] not in ("none", "visual interference") for f in fs),
                       "features": fs})
    return layers, stray, labels


SHORT_REL, SHORT_ABS_M = 1e-3, 1.0  # a drawing this much shorter than report.json's reach is said to stop short
ENDS = {"sdz": "danger zone", "sdz_aided": "aided danger zone", "mirror_beam": "mirror beam"}  # far ends marked, labelled
FAR_LAYERS = ("sdz", "sdz_nominal", "sdz_aided", "mirror_beam", "visual_zone")  # beams: the first view starts at the site


def _coords(geom) -> np.ndarray:
    """Every vertex (x, y) of a GeoJSON geometry as an (N, 2) array."""
    pts = []

    def walk(c):
        if c and isinstance(c[0], (int, float)):
            pts.append(c[:2])
        else:
            for x in c or []:
                walk(x)

    walk((geom or {}).get("coordinates"))
    return np.asarray(pts, float).reshape(-1, 2)


def _has_pyproj() -> bool:
    try:
        import pyproj  # noqa: F401
    except ImportError:
        return False
    return True


def _distance_m(xy: np.ndarray, origin, site: bool) -> np.ndarray:
    """Horizontal distance [m] of points from ``origin``: local metres, or lon/lat [deg]
    along the WGS 84 ellipsoid (pyproj's geodesic), else (pyproj not installed where the
    page is made) on a sphere of the mean radius, within 0.6 % (said on the page)."""
    if not site:
        return np.hypot(xy[:, 0] - origin[0], xy[:, 1] - origin[1])
    try:
        from pyproj import Geod
    except ImportError:
        lon, lat = np.radians(xy[:, 0]), np.radians(xy[:, 1])
        lon0, lat0 = math.radians(origin[0]), math.radians(origin[1])
        a = np.sin((lat - lat0) / 2) ** 2 + math.cos(lat0) * np.cos(lat) * np.sin((lon - lon0) / 2) ** 2
        return 2 * 6_371_008.8 * np.arcsin(np.sqrt(np.clip(a, 0, 1)))
    n = len(xy)
    _, _, dist = Geod(ellps="WGS84").inv(np.full(n, float(origin[0])), np.full(n, float(origin[1])), xy[:, 0], xy[:, 1])
    return np.asarray(dist, float)


def _reported_reach_m(p: dict, doc: dict) -> float | None:
    """How far report.json says a danger zone reaches from the laser (``max_range_m``) or a
    mirror beam from its mirror (the specular NOHD, or the backstop that stops every ray of
    it sooner: ``sdz.mirror_beams[].max_reach_m``) [m]; None for other kinds."""
    kind = p.get("kind")
    if kind == "sdz":
        v = p.get("max_range_m")
    elif kind == "sdz_aided":
        rows = [a for a in (doc.get("sdz") or {}).get("aided") or [] if a.get("nohd_m") == p.get("nohd_m")]
        v = rows[0].get("max_range_m", p.get("nohd_m")) if rows else p.get("nohd_m")
    elif kind == "mirror_beam":
        v = p.get("reach_m", p.get("nohd_m"))  # the NOHD, or where the analysis stops every ray sooner
    else:
        return None
    try:
        return None if v is None else float(v)  # "inf" (JSON has no infinity) included
    except (TypeError, ValueError):
        return None


def _rise_m(p: dict) -> float | None:
    """A mirror beam's height change from its mirror to the end drawn [m] (GeoJSON properties)."""
    try:
        return float(p["end_height_m"]) - float(p["start_height_m"])
    except (KeyError, TypeError, ValueError):
        return None


def _end_mark(lid: str, f: dict, xy: np.ndarray, d: np.ndarray, site: bool) -> dict:
    """Where a danger zone or mirror beam is drawn to, and what report.json says it reaches
    when that is farther (``short``: the drawing stops before the hazard does)."""
    i = int(np.argmax(d))
    if lid == "mirror_beam":  # from its mirror (the line's first vertex), along the slant of the beam
        rise = f["properties"].get("rise_m") or 0.0
        drawn, origin = float(np.hypot(_distance_m(xy[i:i + 1], xy[0], site)[0], rise)), "its mirror"
    else:
        drawn, origin = float(d[i]), "the laser"
    reported = f["properties"].get("reach_reported_m")
    short = reported is not None and reported > drawn * (1 + SHORT_REL) + SHORT_ABS_M
    text = f"{ENDS[lid]} drawn to {fmt_number(drawn, 'm', sig=4)} from {origin}"
    if short:
        text += (f"; it reaches {fmt_number(reported, 'm', sig=4)} (report.json)" if math.isfinite(reported)
                 else "; it is unbounded (report.json: an infinite reach)") + ", beyond this drawing"
    return {"latlng": [float(xy[i, 1]), float(xy[i, 0])], "text": text, "short": short,
            "reported_m": reported if reported is None or math.isfinite(reported) else "inf", "drawn_m": drawn}


def _mark_reach(layers: list, site: bool) -> None:
    """Each layer's farthest vertex from the laser [m] (``reach_m``), and each danger zone's
    and mirror beam's far end (``end``, :func:`_end_mark`) to mark on the map."""
    laser = next((_coords(f["geometry"])[0] for lay in layers if lay["id"] == "laser_targets"
                  for f in lay["features"] if f["properties"]["kind"] == "laser"), None)
    for lay in layers:
        lay["reach_m"], lay["short"] = None, []
        for f in lay["features"]:
            xy = _coords(f["geometry"])
            if laser is not None and len(xy):
                d = _distance_m(xy, laser, site)
                lay["reach_m"] = max(lay["reach_m"] or 0.0, float(d.max()))
                if lay["id"] in ENDS:
                    f["properties"]["end"] = _end_mark(lay["id"], f, xy, d, site)
                    if f["properties"]["end"]["short"]:
                        lay["short"].append(f["properties"]["end"]["text"])
            f["properties"].pop("reach_reported_m", None)
            f["properties"].pop("rise_m", None)


THIN_LAYERS = ("sdz", "sdz_aided", "mirror_beam_zone")  # zones that can be metres wide and kilometres long
THIN_RATIO = 20.0  # a zone longer than this many times its width gets a band of at least THIN_BAND_PX on screen
THIN_BAND_PX = {"sdz": 12, "sdz_aided": 8, "mirror_beam_zone": 8}  # the band's width on screen [px] whatever the zoom (a
# Leaflet line's weight); the naked-eye zone's wider, so that the aided band drawn over it leaves it seen
EARTH_M = 6_371_008.8  # the sphere for the band's local metres (widths within 0.6 %: only the band's drawing uses them)


def _local_m(xy: np.ndarray, site: bool) -> tuple:
    """(metres (N, 2), back): ``xy`` in local metres (lon/lat on an equirectangular plane
    about their mean with a site) and the function taking metres back."""
    if not site:
        return xy, lambda m: m
    c = xy.mean(axis=0)
    k = np.array([math.cos(math.radians(c[1])), 1.0]) * math.pi / 180 * EARTH_M
    return (xy - c) * k, lambda m: np.asarray(m, float) / k + c


def _thin_band(lid: str, title: str, f: dict, site: bool) -> dict | None:
    """For a zone ``THIN_RATIO`` times longer than wide: its long axis (the middle line of
    its minimum rotated rectangle, [[lat, lng], [lat, lng]]), its width [m] and the text
    saying the band drawn along it is wider than the zone where the zone is thinner than
    ``THIN_BAND_PX`` on screen; None for a zone that is not thin."""
    from shapely.geometry import Polygon

    xy = _coords(f.get("geometry"))
    if lid not in THIN_LAYERS or len(xy) < 3:
        return None
    m, back = _local_m(xy, site)
    box = Polygon(m).minimum_rotated_rectangle
    if box.geom_type == "LineString":  # every vertex on one line: a zone of no width along it
        ends_m = np.asarray(box.coords, float)[[0, -1]]
        length, width = float(np.hypot(*(ends_m[1] - ends_m[0]))), 0.0
    elif box.geom_type == "Polygon":
        rect = np.asarray(box.exterior.coords, float)[:4]
        sides = np.hypot(*np.diff(np.vstack([rect, rect[:1]]), axis=0).T)
        k = int(np.argmax(sides[:2]))  # the long sides: k and k + 2
        length, width = float(sides[k]), float(sides[1 - k])
        ends_m = np.array([(rect[(k + 1) % 4] + rect[(k + 2) % 4]) / 2, (rect[(k + 3) % 4] + rect[k]) / 2])
    else:  # every vertex at one point: nothing to draw along
        return None
    if not length > THIN_RATIO * width:
        return None
    ends = back(ends_m)
    return {"axis": [[float(y), float(x)] for x, y in ends], "width_m": width, "band_px": THIN_BAND_PX[lid],
            "text": f"{title} {fmt_number(width, 'm', sig=3)} wide, {fmt_number(length, 'm', sig=3)} long: also drawn as a "
                    f"hatched band {THIN_BAND_PX[lid]} px wide on screen (exaggerated across the zone where it is thinner)"}


def _mark_thin(layers: list, site: bool) -> None:
    """Each thin zone's band (:func:`_thin_band`, property ``thin``), said in its layer's ``thin`` list."""
    for lay in layers:
        lay["thin"] = []
        for f in lay["features"]:
            band = _thin_band(lay["id"], lay["title"], f, site)
            if band is not None:
                f["properties"]["thin"] = band
                lay["thin"].append(band["text"])


def _extent(layers: list, skip=("visual_zone",)) -> list | None:
    """[[south, west], [north, east]] (Leaflet's lat, lng order) of every feature but ``skip``'s layers."""
    pts = [_coords(f.get("geometry")) for layer in layers if layer["id"] not in skip for f in layer["features"]]
    a = np.concatenate(pts) if pts else np.zeros((0, 2))
    if not len(a):
        return None
    return [[float(a[:, 1].min()), float(a[:, 0].min())], [float(a[:, 1].max()), float(a[:, 0].max())]]


def map_data(out_dir) -> dict:
    """Everything the page shows, from ``out_dir``'s report.json and zones GeoJSON."""
    doc, _ = read_report(out_dir)
    out = Path(out_dir)
    gj, gj_name, problem = read_zones(out, doc)
    verdict = doc.get("verdict") or {}
    data = {"scene": str((doc.get("scene") or {}).get("name", "?")), "headline": str(verdict.get("headline", "")),
            "zones_notes": [str(z) for z in verdict.get("zones") or []], "problem": problem, "geojson": gj_name,
            "frame": doc.get("frame") or {}, "site": False, "layers": [], "labels": {}, "absent": {}, "stray": [], "extent": None,
            "hillshade": None, "hillshade_absent": "", "distance_note": "", "observers_shown": "",
            "mpe": fmt_number(doc.get("mpe_w_m2"), "W/m²", sig=6)}
    if gj is None:
        return data
    info = gj.get("laser_hazard") or {}
    layers, stray, labels = map_layers(gj, doc, out)
    site = (info.get("frame") or {}).get("kind") == "site"
    data.update({"site": site, "layers": layers, "stray": stray, "labels": labels, "absent": dict(info.get("absent") or {}),
                 "frame": info.get("frame") or data["frame"], "observers_shown": str(info.get("observers", "")),
                 "extent": _extent(layers, skip=FAR_LAYERS) or _extent(layers, skip=()), "extent_all": _extent(layers, skip=())})
    _mark_reach(layers, site)
    _mark_thin(layers, site)
    if site and not _has_pyproj():
        data["distance_note"] = ("Distances from the laser are on a sphere (pyproj is not installed here: pip install "
                                 "'laser-hazard[geo]' for the ellipsoid's geodesics), within 0.6 %.")
    data["hillshade"], data["hillshade_absent"] = hillshade_layer(doc)
    return data


def _vendor(name: str) -> str:
    from importlib.resources import files

    return files("hazard").joinpath("templates", *VENDOR.split("/"), name).read_text(encoding="utf-8")


def _script_json(obj) -> str:
    """JSON for a ``<script type="application/json">`` element: every ``<`` escaped
    (``\\u003c``), so no text of the scene can end the element early."""
    text = json.dumps(obj, allow_nan=False, separators=(",", ":"), ensure_ascii=False)
    return text.replace("<", "\\u003c").replace("\u2028", "\\u2028").replace("\u2029", "\\u2029")


def map_html(out_dir) -> str:
    """The map page of ``out_dir`` as HTML text (see :func:`write_map_page`)."""
    import jinja2
    from markupsafe import Markup

    data = map_data(out_dir)
    env = jinja2.Environment(loader=jinja2.PackageLoader("hazard", "templates"), autoescape=True,
                             undefined=jinja2.StrictUndefined, trim_blocks=True, lstrip_blocks=True)
    leaflet_js = _vendor("leaflet.min.js").replace("</script", "<\\/script")
    return env.get_template("map.html.j2").render(
        data=data, dist=fmt_distance, data_json=Markup(_script_json(data)), leaflet_css=Markup(_vendor("leaflet.css")),
        leaflet_license=Markup(_vendor("LICENSE").replace("--", "- -")),
        leaflet_js=Markup(leaflet_js))


def write_map_page(out_dir, *, progress=None) -> Path:
    """Write ``OUT/map.html``: the run's plan view as an interactive map that works offline.

    Parameters
    ----------
    out_dir : str or Path
        An output folder of ``hazard run`` (report.json and its zones GeoJSON).
    progress : callable, optional
        Called with a short message before the page is written.

    Returns
    -------
    Path
        The page written (atomically: a temporary file beside it, then a rename).

    Raises
    ------
    ValueError
        No report.json in ``out_dir``, or not a laser-hazard report (one line naming it).
        A missing or unreadable zones GeoJSON is said on the page instead.
    """
    (progress or (lambda msg: None))(f"writing {MAP_NAME}")
    return atomic_write_text(Path(out_dir) / MAP_NAME, map_html(out_dir))
