"""Map outputs of a run: ``zones.geojson``, ``zones.kml`` and ``hazard.tif``.

With a ``[site]`` (:mod:`scenes.geo`) the zones of :mod:`hazard.outputs.map_zones` are converted
exactly from the site's ENU frame to WGS 84 longitude and latitude (each vertex at its
ground's height, or its own for points) and written as

- ``zones.geojson``: RFC 7946 (lon/lat order, WGS 84, exterior rings counter-clockwise
  and holes clockwise, closed rings), one Feature per zone with its properties;
- ``zones.kml``: the same for Google Earth (OGC KML 2.2), styled: red hazardous (naked
  eye), amber aided-only, blue static and orange dynamic keep-out lobes, green observers
  below the MPE;
- ``hazard.tif``: a GeoTIFF of the peak hazard ratio at eye height over the terrain grid
  (band 1: reflections + direct beam; 2: reflections, dynamic; 3: reflections, static;
  4: direct beam), float32, NaN where not evaluated (beyond every NOHD: below 1). Its CRS
  is the ellipsoidal orthographic projection about the site origin, whose x, y are the ENU
  frame's exactly on the ellipsoid; a node at height h above it, d from the origin, is
  registered h d / R off (the file's tags give the largest: 0.35 m for 1.2 km at 1.9 km).

Without a site the same zones are written in the scene's local frame, named so:
``zones_local_frame.json`` (GeoJSON's shape, local metres: RFC 7946 allows no other CRS)
and ``hazard_local_frame.tif`` (no CRS); no KML (KML is WGS 84 only). Every file states
its frame; every kind of zone the run lacks is listed with the reason (``absent``).
"""

from __future__ import annotations

import json
import math
import xml.etree.ElementTree as ET
from collections import Counter
from dataclasses import dataclass
from types import MappingProxyType
from typing import Literal, Mapping

import numpy as np

from hazard.outputs.map_zones import ZONE_KINDS, Zone, common_properties, observer_zones, observers_on_map, zones
from hazard.outputs.row_text import CellTexts, column_parts, joined_rows, row_tools, string_cells

__all__ = ["MAP_NAMES", "MapOutputs", "map_files", "map_names", "geojson_document", "geojson_bytes", "kml_document", "hazard_tiff", "site_crs", "to_lonlat"]

DEGREE_DECIMALS = 8  # 1e-8 deg = 1.1 mm: below any outline's own resolution


MAP_NAMES = ("zones.geojson", "zones.kml", "hazard.tif", "zones_local_frame.json", "hazard_local_frame.tif")  # every one


@dataclass(frozen=True)
class MapOutputs:
    """What the map outputs of a run hold (:func:`map_files`; report.json ``map_outputs``).

    Attributes
    ----------
    files : tuple of str
        The map files written, sorted by name.
    not_written : Mapping of str to str
        Each map file not written (file name -> why), in the order they were considered.
    frame : {"local", "site"}
        The frame the files are in: the scene's local metres, or WGS 84 through its ``[site]``.
    features : Mapping of str to int
        Per kind of zone (:data:`hazard.outputs.map_zones.ZONE_KINDS`, in that order), the number of features drawn.
    absent : Mapping of str to str
        Each kind of zone the run has none of (in the order of ``ZONE_KINDS``) -> why.
    """

    files: tuple[str, ...]
    not_written: Mapping[str, str]
    frame: Literal["local", "site"]
    features: Mapping[str, int]
    absent: Mapping[str, str]

    def __post_init__(self) -> None:  # read-only views: no reader changes what the report writes
        for name in ("not_written", "features", "absent"):
            object.__setattr__(self, name, MappingProxyType(dict(getattr(self, name))))

    def to_dict(self) -> dict:
        return {"files": list(self.files), "not_written": dict(self.not_written), "frame": self.frame,
                "features": dict(self.features), "absent": dict(self.absent)}


def map_names(scene) -> tuple:
    """The map files a run of ``scene`` may write (for the output folder's check)."""
    if getattr(scene, "site", None) is not None:
        return ("zones.geojson", "zones.kml", "hazard.tif")
    return ("zones_local_frame.json", "hazard_local_frame.tif")


def _height_fn(result, eye_m):
    """World z [m] below plan points (N, 2): the terrain plus ``eye_m``, else the frame's 0."""
    scene = result.scene
    off = np.asarray(scene.offset_m, float)
    if scene.terrain is None:
        return lambda xy: np.zeros(len(xy))
    return lambda xy: scene.terrain.height_at(xy[:, 0] - off[0], xy[:, 1] - off[1]) + off[2] + eye_m


def to_lonlat(geom, frame, height, z_m=None):
    """``geom`` (world x, y) in lon/lat [deg], rings oriented by RFC 7946 section 3.1.6."""
    import shapely

    def fn(xy):
        if z_m is None:
            z = height(xy)
        else:
            z = np.asarray(z_m, float) if np.ndim(z_m) else np.full(len(xy), z_m)
        lat, lon, _ = frame.geodetic(np.column_stack([xy, z]))
        return np.round(np.column_stack([lon, lat]), DEGREE_DECIMALS)

    g = shapely.transform(geom, fn)
    return shapely.orient_polygons(g) if g.geom_type in ("Polygon", "MultiPolygon") else g


def _local(geom):
    import shapely

    g = shapely.transform(geom, lambda xy: np.round(xy, 4))
    return shapely.orient_polygons(g) if g.geom_type in ("Polygon", "MultiPolygon") else g


def _jsonable(v):
    if type(v) is float:  # the common cases first (20 000 observer features)
        return v if math.isfinite(v) else ("inf" if v > 0 else ("-inf" if v < 0 else "nan"))
    if type(v) in (str, bool, int) or v is None:
        return v
    if isinstance(v, float) and not np.isfinite(v):
        return "inf" if v > 0 else ("-inf" if v < 0 else "nan")
    if isinstance(v, (np.floating, np.integer)):
        return _jsonable(v.item())
    return v


_PLAIN = frozenset({str, bool, int, float, type(None)})  # the types _jsonable returns unchanged (a float when finite)


def _properties(zs) -> list:
    """Each zone's properties as the GeoJSON writes them (:func:`_jsonable` of each value).
    When every value of every zone is a str, bool, int, None or a finite float (the common
    case: 20 000 observer points), :func:`_jsonable` changes none of them and each dict is
    copied as it is: the types of all values checked at once, the floats' finiteness by
    their sum (a sum that overflows to inf sends the zones the value-by-value way)."""
    from itertools import chain

    values = list(chain.from_iterable(z.properties.values() for z in zs))
    if set(map(type, values)) <= _PLAIN and math.isfinite(sum(v for v in values if type(v) is float)):
        return [dict(z.properties) for z in zs]
    return [{k: _jsonable(v) for k, v in z.properties.items()} for z in zs]


def _points(zs, frame, height) -> dict:
    """GeoJSON geometry of each point zone (index -> mapping), all converted at once: the
    values :func:`to_lonlat` (``frame``) or :func:`_local` give one by one."""
    import shapely

    geoms = np.array([z.geometry for z in zs], dtype=object)
    point = (shapely.get_type_id(geoms) == 0) & ~shapely.is_empty(geoms) if len(zs) else np.zeros(0, bool)  # 0: Point
    at = [i for i in np.flatnonzero(point).tolist() if zs[i].z_m is None or type(zs[i].z_m) is float or not np.ndim(zs[i].z_m)]
    if not at:
        return {}
    xy = shapely.get_coordinates(geoms[at])
    if frame is None:
        out = np.round(xy, 4)
    else:
        known = np.array([zs[i].z_m is not None for i in at])
        z = np.where(known, np.array([zs[i].z_m if zs[i].z_m is not None else np.nan for i in at], float), 0.0)
        if not known.all():
            z[~known] = height(xy[~known])
        lat, lon, _ = frame.geodetic(np.column_stack([xy, z]))
        out = np.round(np.column_stack([lon, lat]), DEGREE_DECIMALS)
    return {i: {"type": "Point", "coordinates": tuple(c)} for i, c in zip(at, out.tolist())}


def geojson_document(result, zs, absent, frame_info) -> dict:
    """The FeatureCollection: lon/lat with a site, else local metres (and named so)."""
    _, which = observers_on_map(result)
    return _document(result, zs, absent, frame_info, which)


def _document(result, zs, absent, frame_info, which: str, mark: str = "") -> dict:
    """:func:`geojson_document` (``which``: the observers shown, :func:`observers_on_map`);
    an :class:`hazard.outputs.map_zones.ObserverPoints` among ``zs`` is the string ``mark``
    in its place among the features (its text made apart, :func:`_observer_features`)."""
    from shapely.geometry import mapping

    site = result.scene.site
    height = _height_fn(result, result.scene.spec.analysis.footprint_eye_height_m)
    feats: list = []
    own = [z for z in zs if isinstance(z, Zone)]
    points = _points(own, None if site is None else site.frame, height)
    props = _properties(own)
    for i, z in enumerate(own):
        g = points.get(i) or mapping(to_lonlat(z.geometry, site.frame, height, z.z_m) if site is not None else _local(z.geometry))
        feats.append({"type": "Feature", "geometry": g, "properties": props[i]})
    for k, z in enumerate(zs):  # the points' mark where they stand among the zones
        if not isinstance(z, Zone):
            feats.insert(k, mark)
    doc: dict = {"type": "FeatureCollection", "features": feats}
    doc["laser_hazard"] = {"frame": frame_info, "kinds": list(ZONE_KINDS), "absent": absent, "observers": which,
                           "scene": result.scene.name, "scene_sha256": result.scene.text_sha256}
    return doc


# --- KML -----------------------------------------------------------------------------------
_KML_NS = "http://www.opengis.net/kml/2.2"
_STYLES = {  # id -> (line aabbggrr, fill aabbggrr, width)
    "hazardous": ("ff1c1ae4", "661c1ae4", 2), "aided": ("ff00a5ff", "5500a5ff", 2),
    "static": ("ffb27200", "40b27200", 2), "dynamic": ("ff009fe6", "30009fe6", 2),
    "footprint": ("ff150fa5", "80150fa5", 1), "boundary": ("ff000000", "00000000", 2),
    "safe": ("ff739e00", "ff739e00", 1), "thing": ("ff333333", "ff333333", 1),
}


def _style(z) -> str:
    k, p = z.kind, z.properties
    if k == "keepout_lobe":
        return p.get("variant", "static")
    if k == "footprint":
        return "footprint"
    if k in ("range_boundary",):
        return "boundary"
    if k in ("laser", "target"):
        return "thing"
    if k in ("observer", "track", "airspace_zone"):
        return {"naked eye": "hazardous", "aided only": "aided"}.get(p.get("hazard"), "safe")
    if k == "visual_zone":
        return "aided"
    return "aided" if p.get("hazard") == "aided only" else "hazardous"


def _kml_coords(coords) -> str:
    return " ".join(f"{x:.{DEGREE_DECIMALS}f},{y:.{DEGREE_DECIMALS}f},0" for x, y in np.asarray(coords)[:, :2])


def _kml_geometry(parent, g) -> None:
    t = g.geom_type
    if t.startswith("Multi") or t == "GeometryCollection":
        multi = ET.SubElement(parent, "MultiGeometry")
        for part in g.geoms:
            _kml_geometry(multi, part)
    elif t == "Polygon":
        poly = ET.SubElement(parent, "Polygon")
        ring = ET.SubElement(ET.SubElement(poly, "outerBoundaryIs"), "LinearRing")
        ET.SubElement(ring, "coordinates").text = _kml_coords(g.exterior.coords)
        for h in g.interiors:
            ring = ET.SubElement(ET.SubElement(poly, "innerBoundaryIs"), "LinearRing")
            ET.SubElement(ring, "coordinates").text = _kml_coords(h.coords)
    elif t == "LineString":
        ET.SubElement(ET.SubElement(parent, "LineString"), "coordinates").text = _kml_coords(g.coords)
    elif t == "Point":
        ET.SubElement(ET.SubElement(parent, "Point"), "coordinates").text = _kml_coords(g.coords)


def _kml_styles(doc) -> None:
    for sid, (line, fill, width) in _STYLES.items():
        st = ET.SubElement(doc, "Style", id=sid)
        ls = ET.SubElement(st, "LineStyle")
        ET.SubElement(ls, "color").text, ET.SubElement(ls, "width").text = line, str(width)
        ET.SubElement(ET.SubElement(st, "PolyStyle"), "color").text = fill
        icon = ET.SubElement(st, "IconStyle")
        ET.SubElement(icon, "color").text = line
        ET.SubElement(icon, "scale").text = "0.8"


def _placemark(folder, z, feature) -> None:
    from shapely.geometry import shape

    pm = ET.SubElement(folder, "Placemark")
    p = z.properties
    ET.SubElement(pm, "name").text = str(p.get("name") or p.get("target") or z.kind) + (
        f" ({p['variant']})" if p.get("variant") else "")
    ET.SubElement(pm, "styleUrl").text = f"#{_style(z)}"
    data = ET.SubElement(pm, "ExtendedData")
    for k, v in feature["properties"].items():
        d = ET.SubElement(data, "Data", name=str(k))
        ET.SubElement(d, "value").text = json.dumps(v) if not isinstance(v, str) else v
    _kml_geometry(pm, shape(feature["geometry"]))


def kml_document(zs, geojson: dict) -> bytes:
    """KML 2.2 of the zones (from the GeoJSON's lon/lat geometry), one folder per kind."""
    ET.register_namespace("", _KML_NS)
    root = ET.Element("kml", xmlns=_KML_NS)
    doc = ET.SubElement(root, "Document")
    info = geojson["laser_hazard"]
    ET.SubElement(doc, "name").text = f"laser-hazard: {info['scene']}"
    ET.SubElement(doc, "description").text = (info["frame"]["statement"] + " Absent: "
                                              + "; ".join(f"{k}: {v}" for k, v in info["absent"].items() if v))
    _kml_styles(doc)
    folders = {}
    for z, f in zip(zs, geojson["features"]):
        if z.kind not in folders:
            folders[z.kind] = ET.SubElement(doc, "Folder")
            ET.SubElement(folders[z.kind], "name").text = z.kind
        _placemark(folders[z.kind], z, f)
    return b'<?xml version="1.0" encoding="UTF-8"?>\n' + ET.tostring(root, encoding="utf-8")


# --- GeoTIFF --------------------------------------------------------------------------------
def _bands(result) -> tuple[np.ndarray, list] | None:
    fd, fs = result.footprint_dynamic, result.footprint_static
    if fd is None or fd.ratio is None:
        return None
    direct = fd.direct_ratio if fd.direct_ratio is not None else np.zeros_like(fd.ratio)
    reflected = fd.ratio
    static = fs.ratio if fs is not None and fs.ratio is not None else np.full_like(fd.ratio, np.nan)
    total = np.where(np.isnan(reflected), direct, reflected + direct)  # not evaluated: the reflections are below 1
    names = ["peak hazard ratio at eye height: reflections (dynamic) + direct beam",
             "reflections, dynamic (max over time)", "reflections, static", "direct beam (nominal aim)"]
    return np.stack([total, reflected, static, direct]).astype("float32")[:, ::-1, :], names  # rows north to south


def site_crs(scene):
    """The PROJ string of the ellipsoidal orthographic projection about ``scene``'s site
    origin (its x, y are the ENU frame's on the ellipsoid); None without a site."""
    site = scene.site
    if site is None:
        return None
    lat, lon, _ = site.frame.origin_deg_m
    return f"+proj=ortho +lat_0={lat!r} +lon_0={lon!r} +x_0=0 +y_0=0 +ellps=WGS84 +units=m +no_defs"


def _registration_m(result) -> float:
    """Largest horizontal offset h d / R of a node from its orthographic position [m]."""
    site, t = result.scene.site, result.scene.terrain
    off = np.asarray(result.scene.offset_m, float)
    ny, nx = t.heights.shape
    x = t.x0 + off[0] + t.dx * np.array([0, nx - 1])
    y = t.y0 + off[1] + t.dx * np.array([0, ny - 1])
    d = float(np.max(np.hypot(*np.meshgrid(x, y))))
    h = float(np.max(np.abs(t.heights + off[2]))) + site.frame.h0_m
    return h * d / site.frame.radius_m


def hazard_tiff(result, frame_info) -> bytes | None:
    """The GeoTIFF of the hazard ratio at eye height (None without a footprint grid)."""
    got = _bands(result)
    if got is None:
        return None
    from rasterio.io import MemoryFile
    from rasterio.transform import from_origin

    bands, names = got
    t, off = result.scene.terrain, np.asarray(result.scene.offset_m, float)
    ny, nx = t.heights.shape
    transform = from_origin(t.x0 + off[0] - t.dx / 2, t.y0 + off[1] + t.dx * (ny - 1) + t.dx / 2, t.dx, t.dx)
    crs = site_crs(result.scene)
    tags = {"frame": frame_info["statement"], "nan": "not evaluated: beyond every target's NOHD (ratio below 1)",
            "sampling": (f"the ratio at each terrain node (every {t.dx:g} m) at eye height: a zone smaller than a cell can "
                         f"fall between nodes; the keepout_lobe outlines of zones.geojson are drawn from the lobes themselves"),
            "eye_height_m": str(result.footprint_dynamic.eye_height_m), "scene": result.scene.name,
            "scene_sha256": result.scene.text_sha256, "mpe_w_m2": repr(float(result.mpe_w_m2))}
    if crs is not None:
        tags["registration_m"] = f"{_registration_m(result):.3g} (largest offset h d / R of a node from its orthographic position)"
    with MemoryFile() as mem:
        with mem.open(driver="GTiff", width=nx, height=ny, count=4, dtype="float32", crs=crs, transform=transform,
                      nodata=float("nan"), compress="deflate") as ds:
            ds.write(bands)
            ds.update_tags(**tags)
            for i, n in enumerate(names, 1):
                ds.set_band_description(i, n)
        return mem.read()


def geojson_bytes(doc: dict) -> bytes:
    """The zones document as JSON text: by orjson when it is installed and its text holds no
    ``null`` (orjson writes a NaN as null, where ``json.dumps(allow_nan=False)`` refuses it:
    no number may vanish into a null), else by ``json.dumps``. The same values either way;
    orjson's layout has no spaces and its floats the shortest round-trip digits (``0.00001``,
    ``1e16`` where json writes ``1e-05``, ``1e+16``). 0.12 -> 0.02 s CPU for the 20 000 observer points of the
    1e6-observer benchmark."""
    try:
        import orjson
    except ImportError:
        return _json_bytes(doc)
    try:
        text = orjson.dumps(doc)
    except TypeError:  # a type orjson does not write (json's error, if any, comes below)
        return _json_bytes(doc)
    return text if b"null" not in text else _json_bytes(doc)


def _json_bytes(doc) -> bytes:
    return json.dumps(doc, indent=None, allow_nan=False).encode()


def _frame_info(result) -> dict:
    site = result.scene.site
    if site is not None:
        return site.frame.describe()
    return {"kind": "local", "statement": "the scene's local frame: x, y, z [m] as the scene file gives them "
            "(no [site]: not placed on the earth; no CRS)"}


_POINT_KEYS = ("kind", "name", "verdict", "hazard_ratio", "radiant_exposure_j_m2", "hazard", "z_m")  # an observer point's properties
_JSON_CELLS = CellTexts("true", "false", '"nan"', '"inf"', '"-inf"')  # as _jsonable makes a non-finite float


def _observer_features(tools, op, common: dict):
    """The GeoJSON text (bytes-like, the features one after another, comma-separated) of the
    observer points ``op`` in the scene's local frame, made column by column
    (:mod:`hazard.outputs.row_text`): the same bytes as orjson writes for the feature dicts
    :func:`geojson_document` makes of each (coordinates rounded to 0.1 mm, a non-finite
    ratio as a string); None where that text would not be orjson's (a position not finite,
    a ``null``) or a common property would replace a point's own."""
    orjson, pa, _ = tools
    p = op.position_m
    if not np.isfinite(p).all() or set(common) & set(_POINT_KEYS):
        return None
    common_text = orjson.dumps(common).decode()[1:-1]
    xy = np.round(p[:, :2], 4)
    names = string_cells(tools, list(op.names), ",")
    which = pa.array(op.hazardous.astype(np.int8) * (1 + op.aided.astype(np.int8)))  # below the MPE, hazardous, through an aid
    verdict = pa.array(['"below the MPE"', '"hazardous"', '"hazardous, aided"']).take(which)
    hazard = pa.array(['"none"', '"naked eye"', '"aided only"']).take(which)
    parts = column_parts(tools, [(xy[:, 0], _JSON_CELLS), (xy[:, 1], _JSON_CELLS)], [",", ']},"properties":{"kind":"observer","name":'],
                         ['{"type":"Feature","geometry":{"type":"Point","coordinates":['])
    parts += [names, '"verdict":', verdict, ',"hazard_ratio":']
    parts += column_parts(tools, [(op.hazard_ratio, _JSON_CELLS), (op.radiant_exposure_j_m2, _JSON_CELLS)],
                          [',"radiant_exposure_j_m2":', ',"hazard":'])
    parts += [hazard, ',"z_m":']
    parts += column_parts(tools, [(p[:, 2], _JSON_CELLS)], [("," + common_text if common_text else "") + "}},"])
    text = bytes(joined_rows(tools, parts, len(op), drop_last=1))
    return None if b"null" in text else text


def _geojson_text(result, zs, absent, frame) -> bytes | None:
    """The zones file of a run without a site with its observer points written column by
    column (:func:`_observer_features`): the bytes :func:`geojson_bytes` writes of
    :func:`geojson_document` (0.2 -> ~0.05 s CPU for the map of 20 000 observer points);
    None where they would not be orjson's (orjson or pyarrow not installed, a type orjson
    does not write, a ``null``)."""
    import uuid

    tools = row_tools()
    op = next((z for z in zs if not isinstance(z, Zone)), None)
    if tools is None or op is None:
        return None
    mark = f"observer-points-{uuid.uuid4().hex}"
    try:
        text = tools[0].dumps(_document(result, zs, absent, frame, op.which, mark))
    except TypeError:
        return None
    rows = None if b"null" in text else _observer_features(tools, op, common_properties(result))
    if rows is None:
        return None
    head, tail = text.split(tools[0].dumps(mark))
    return b"".join([head, rows, tail])


def _each_point(result, zs) -> list:
    """``zs`` with observer points (:class:`hazard.outputs.map_zones.ObserverPoints`) as one zone each."""
    common = common_properties(result)
    return [x for z in zs for x in ([z] if isinstance(z, Zone) else observer_zones(z, common))]


def map_files(result) -> tuple[dict, MapOutputs]:
    """The map files (name -> bytes) of ``result`` and report.json's ``map_outputs`` (its ``to_dict``)."""
    import importlib.util

    zs, absent = zones(result, points_as_columns=True)
    kinds: Counter[str] = Counter()
    for z in zs:
        kinds[z.kind] += 1 if isinstance(z, Zone) else len(z)
    frame = _frame_info(result)
    site = result.scene.site is not None
    names = map_names(result.scene)
    text = None if site else _geojson_text(result, zs, absent, frame)
    if text is None:  # a zone each, as geojson_document makes them
        op = next((z for z in zs if not isinstance(z, Zone)), None)  # its statement of the observers shown, made once
        zs = _each_point(result, zs)
        gj = geojson_document(result, zs, absent, frame) if op is None else _document(result, zs, absent, frame, op.which)
        text = geojson_bytes(gj)
    files = {names[0]: text}
    not_written = {}
    if site:
        files["zones.kml"] = kml_document(zs, gj)
    else:
        not_written["zones.kml"] = "KML is WGS 84 only: give the scene a [site] to place it on the earth"
    tif = names[-1]
    if importlib.util.find_spec("rasterio") is None:
        not_written[tif] = "rasterio is not installed: pip install 'laser-hazard[geo]'"
    else:
        data = hazard_tiff(result, frame)
        if data is None:
            not_written[tif] = "no ground grid at eye height (the scene has no terrain, or no spot to reflect)"
        else:
            files[tif] = data
    counts = {k: kinds[k] for k in ZONE_KINDS}
    return files, MapOutputs(files=tuple(sorted(files)), not_written=not_written, frame=frame["kind"], features=counts,
                             absent=absent)
