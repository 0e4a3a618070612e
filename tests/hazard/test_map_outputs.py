"""Map outputs (issue 14 item 3): zones.geojson (RFC 7946), zones.kml, hazard.tif.

References written here: RFC 7946's rules (lon/lat order, closed rings, exterior rings
counter-clockwise by the shoelace sum, holes clockwise, no "crs" member), the geodesic
area on the WGS 84 ellipsoid (pyproj.Geod) against the footprint area the report gives,
the GeoTIFF's CRS and transform read back by rasterio and carried to lon/lat by pyproj.
"""

from __future__ import annotations

import io
import json
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest

pyproj = pytest.importorskip("pyproj")
rasterio = pytest.importorskip("rasterio")

from hazard.cli import main  # noqa: E402
from hazard.outputs.map_zones import ZONE_KINDS  # noqa: E402

# a site scene with every kind of zone but the sector's nominal one: a Lambertian board
# (ground footprint, keep-out lobe) beside a mirror (mirror beam), a pointing error (the
# danger zone's buffer), optics (aided zone), a range boundary and observers by lat/lon
SCENE = """
name = "geo_zones"
[site]
origin = [47.0, 8.0, 500.0]
[laser]
wavelength_nm = 1064.0
power_w = 50000.0
beam_diameter_m = 0.05
divergence_rad = 0.001
position_geo = [47.0, 8.0]
height_agl_m = 2.0
aim_m = [0.0, 300.0, 2.0]
pointing_error_rad = 1e-3
[exposure]
duration_s = 10.0
optics = [{ magnification = 7.0, objective_diameter_m = 0.05, transmission = 0.9 }]
[[targets]]
name = "board"
shape = "plate"
center_m = [-0.25, 300.0, 2.0]
normal = [0.0, -1.0, -1.0]
tangent = [1.0, 0.0, 0.0]
size_m = [0.5, 0.5]
material = { model = "lambertian", reflectance = 0.9 }
[[targets]]
name = "mirror"
shape = "plate"
center_m = [0.25, 300.0, 2.0]
normal = [-0.4, -1.0, 0.0]
tangent = [0.0, 0.0, 1.0]
size_m = [0.5, 0.5]
material = { model = "specular", reflectance = 0.8 }
[terrain]
kind = "flat"
center_m = [0.0, 200.0, 0.0]
extent_m = 400.0
resolution_m = 4.0
[range]
boundary_geo = [[46.996, 7.994], [46.996, 8.006], [47.006, 8.006], [47.006, 7.994]]
[[observers]]
name = "post"
points_geo = [[47.0025, 8.0005]]
eye_height_m = 1.7
[[observers]]
name = "spotters"
points_geo = [[47.0024, 7.9990], [47.0020, 8.0010]]
eye_height_m = 1.7
optics = { magnification = 7.0, objective_diameter_m = 0.05, transmission = 0.9 }
"""


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory) -> Path:
    d = tmp_path_factory.mktemp("maps")
    (d / "geo_zones.toml").write_text(SCENE)
    code = main(["run", str(d / "geo_zones.toml"), "-o", str(d / "out"), "--quiet"], stdout=io.StringIO(), stderr=io.StringIO())
    assert code == 0
    return d / "out"


def _report(out):
    return json.loads((out / "report.json").read_text())


def _geojson(out):
    return json.loads((out / "zones.geojson").read_text())


def _shoelace(ring) -> float:
    r = np.asarray(ring, float)
    return 0.5 * float(np.sum(r[:-1, 0] * r[1:, 1] - r[1:, 0] * r[:-1, 1]))


def _polygons(geom) -> list:
    if geom["type"] == "Polygon":
        return [geom["coordinates"]]
    if geom["type"] == "MultiPolygon":
        return list(geom["coordinates"])
    return []


def test_every_zone_kind_is_exported_or_said_absent(run_dir):
    doc = _geojson(run_dir)
    kinds = {f["properties"]["kind"] for f in doc["features"]}
    assert kinds == {"footprint", "sdz", "sdz_aided", "keepout_lobe", "mirror_beam", "mirror_beam_zone", "observer", "range_boundary", "laser", "target"}
    absent = doc["laser_hazard"]["absent"]
    assert set(absent) == {"sdz_nominal", "track", "airspace_zone", "visual_zone"} and "sector" in absent["sdz_nominal"]
    assert "not a visible laser" in absent["visual_zone"] and "no [airspace] zones" in absent["airspace_zone"]
    assert set(ZONE_KINDS) == kinds | set(absent)  # every kind the tool knows is either on the map or said absent
    assert _report(run_dir)["map_outputs"]["files"] == ["hazard.tif", "zones.geojson", "zones.kml"]


def test_geojson_follows_rfc7946(run_dir):
    from shapely.geometry import shape

    doc = _geojson(run_dir)
    assert doc["type"] == "FeatureCollection" and "crs" not in doc  # RFC 7946 section 4: WGS 84 lon/lat only
    n_poly = 0
    for f in doc["features"]:
        assert f["type"] == "Feature" and isinstance(f["properties"], dict)
        pts = np.asarray(shape(f["geometry"]).envelope.exterior.coords if f["geometry"]["type"] != "Point"
                         else [f["geometry"]["coordinates"]])
        # lon/lat order: the site is at 8 E, 47 N (swapped, the test would see 47, 8); the danger zone
        # reaches 36 km, the aided one 237 km (drawn whole: 2.13 deg of latitude, 0.1 deg across)
        reach_deg = 2.0 if f["properties"]["kind"] != "sdz_aided" else 2.5
        assert np.all(np.abs(pts[:, 0] - 8.0) < 2) and np.all(np.abs(pts[:, 1] - 47.0) < reach_deg), f["properties"]["kind"]
        for rings in _polygons(f["geometry"]):
            n_poly += 1
            for k, ring in enumerate(rings):
                assert len(ring) >= 4 and ring[0] == ring[-1]  # closed linear rings (section 3.1.6)
                area = _shoelace(ring)
                assert (area > 0) if k == 0 else (area < 0)  # right-hand rule: exterior CCW, holes CW
        assert shape(f["geometry"]).is_valid
    assert n_poly >= 6


def test_footprint_polygon_area_matches_the_report(run_dir):
    """The geodesic area of the dynamic footprint polygon on the ellipsoid vs the area the
    report gives (cells x dx^2 in the ENU plane at ~500 m height): equal within the
    height's scale (1 - 2 h / R = 1 - 1.6e-4) and the 1e-8 deg rounding."""
    from shapely.geometry import shape

    geod = pyproj.Geod(ellps="WGS84")
    feats = [f for f in _geojson(run_dir)["features"] if f["properties"]["kind"] == "footprint"
             and f["properties"]["variant"] == "dynamic"]
    assert len(feats) == 1
    area, _ = geod.geometry_area_perimeter(shape(feats[0]["geometry"]))
    reported = _report(run_dir)["footprint"]["dynamic"]
    assert reported["area_m2"] == reported["cells"] * 16.0 > 0
    assert abs(area) == pytest.approx(reported["area_m2"], rel=5e-4)


def test_observer_points_are_where_the_scene_put_them(run_dir):
    feats = {f["properties"]["name"]: f for f in _geojson(run_dir)["features"] if f["properties"]["kind"] == "observer"}
    lon, lat = feats["post"]["geometry"]["coordinates"]
    assert lat == pytest.approx(47.0025, abs=2e-8) and lon == pytest.approx(8.0005, abs=2e-8)  # 2 mm
    assert feats["spotters[0]"]["properties"]["verdict"] in ("below the MPE", "hazardous, aided")
    assert all("hazard_ratio" in f["properties"] and "standard" in f["properties"] for f in feats.values())


def test_kml_carries_the_same_features_styled(run_dir):
    ns = {"k": "http://www.opengis.net/kml/2.2"}
    root = ET.parse(run_dir / "zones.kml").getroot()
    marks = root.findall(".//k:Placemark", ns)
    feats = _geojson(run_dir)["features"]
    assert len(marks) == len(feats)
    styles = {s.get("id"): s.find("k:LineStyle/k:color", ns).text for s in root.findall(".//k:Style", ns)}
    assert styles["hazardous"] == "ff1c1ae4" and styles["aided"] == "ff00a5ff"  # aabbggrr: red, amber
    by_kind = {}
    for m in marks:
        kind = next(d.find("k:value", ns).text for d in m.findall(".//k:Data", ns) if d.get("name") == "kind")
        by_kind.setdefault(kind, []).append(m.find("k:styleUrl", ns).text)
    assert set(by_kind["sdz"]) == {"#hazardous"} and set(by_kind["sdz_aided"]) == {"#aided"}
    first = next(m for m in marks if m.find(".//k:Polygon", ns) is not None)
    text = first.find(".//k:outerBoundaryIs//k:coordinates", ns).text.split()
    lon, lat, _ = map(float, text[0].split(","))
    assert abs(lon - 8.0) < 0.5 and abs(lat - 47.0) < 0.5


def test_geotiff_crs_and_transform_read_back(run_dir):
    """The raster's CRS is the orthographic projection about the site; a hazardous cell's
    centre, carried to lon/lat by pyproj, lies in the footprint polygon of the GeoJSON."""
    from shapely.geometry import Point, shape

    with rasterio.open(run_dir / "hazard.tif") as ds:
        crs = ds.crs.to_dict()
        assert crs["proj"] == "ortho" and crs["lat_0"] == 47.0 and crs["lon_0"] == 8.0
        assert ds.count == 4 and ds.res == (4.0, 4.0) and "direct beam" in ds.descriptions[0]
        reflected = ds.read(2)
        rows, cols = np.nonzero(reflected >= 1.0)
        assert len(rows) == _report(run_dir)["footprint"]["dynamic"]["cells"]
        x, y = rasterio.transform.xy(ds.transform, rows, cols)  # cell centres
        to_ll = pyproj.Transformer.from_crs(ds.crs, "EPSG:4326", always_xy=True)
        lon, lat = to_ll.transform(np.asarray(x), np.asarray(y))
        assert "registration_m" in ds.tags()
    fp = next(shape(f["geometry"]) for f in _geojson(run_dir)["features"]
              if f["properties"]["kind"] == "footprint" and f["properties"]["variant"] == "dynamic")
    assert all(fp.contains(Point(a, b)) for a, b in zip(lon, lat))


def test_a_scene_without_site_writes_local_frame_files_named_so(tmp_path):
    code = main(["run", "range_terrain", "-o", str(tmp_path / "o"), "--quiet"], stdout=io.StringIO(), stderr=io.StringIO())
    assert code == 0
    out = tmp_path / "o"
    assert not (out / "zones.geojson").exists() and not (out / "zones.kml").exists()
    doc = json.loads((out / "zones_local_frame.json").read_text())
    assert doc["laser_hazard"]["frame"]["kind"] == "local" and "not placed on the earth" in doc["laser_hazard"]["frame"]["statement"]
    sdz = next(f for f in doc["features"] if f["properties"]["kind"] == "sdz")
    assert max(abs(c) for ring in sdz["geometry"]["coordinates"] for xy in ring for c in xy) > 100  # metres, not degrees
    with rasterio.open(out / "hazard_local_frame.tif") as ds:
        assert ds.crs is None and "local frame" in ds.tags()["frame"]
    rep = json.loads((out / "report.json").read_text())
    assert rep["frame"]["kind"] == "local" and "KML is WGS 84 only" in rep["map_outputs"]["not_written"]["zones.kml"]


@pytest.mark.parametrize("text", [SCENE, None], ids=["site", "local"])
def test_point_features_converted_at_once_are_the_one_by_one_values(text):
    """Point zones (20 000 observers on a large map) are converted in one call: each
    geometry equals what to_lonlat (with a site) or the local rounding gives one by one."""
    from shapely.geometry import mapping

    import hazard
    import scenes
    from hazard.outputs import map_outputs
    from hazard.outputs.map_zones import zones

    res = hazard.analyze(scenes.loads(text) if text else scenes.load(scenes.example_path("range_terrain")))
    zs, absent = zones(res)
    doc = map_outputs.geojson_document(res, zs, absent, {})
    site = res.scene.site
    height = map_outputs._height_fn(res, res.scene.spec.analysis.footprint_eye_height_m)
    n_points = 0
    for z, f in zip(zs, doc["features"]):
        one = (map_outputs.to_lonlat(z.geometry, site.frame, height, z.z_m) if site is not None else map_outputs._local(z.geometry))
        assert json.dumps(f["geometry"]) == json.dumps(mapping(one))
        n_points += z.geometry.geom_type == "Point"
    assert n_points >= 3 and len(doc["features"]) == len(zs)
