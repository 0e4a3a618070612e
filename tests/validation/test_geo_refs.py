"""Scenes placed on the earth (``[site]``, ``*_geo`` positions, ``kind = "dem"`` terrain)
against references written here from the formulas and from pyproj / rasterio directly,
never from the engine's own geodesy (``scenes.geo``, ``scenes.geo_input``, ``scenes.dem``
are not imported and were not read when writing these references).

The reference chain (every test uses it):

- geodetic (lat, lon, h above the WGS 84 ellipsoid) -> ECEF with pyproj
  (``EPSG:4979 -> EPSG:4978``, ``always_xy``), itself checked against the closed form
  X = (N + h) cos(lat) cos(lon), Y = (N + h) cos(lat) sin(lon), Z = (N (1 - e^2) + h) sin(lat);
- ECEF -> the exact local east-north-up frame of the site's origin (lat0, lon0, h0):
  ENU = R (ECEF(p) - ECEF(origin)) with the rows of R
  e = (-sin lon0, cos lon0, 0), n = (-sin lat0 cos lon0, -sin lat0 sin lon0, cos lat0),
  u = (cos lat0 cos lon0, cos lat0 sin lon0, sin lat0);
- a projected input CRS (UTM) goes to geodetic through pyproj first;
- the radii of the ellipsoid at lat0: M = a (1 - e^2) / W^3 (meridian), N = a / W (prime
  vertical), W = sqrt(1 - e^2 sin^2 lat0); the Gaussian mean radius R = sqrt(M N); the
  normal-section radius in azimuth az (Euler) 1 / R_az = cos^2(az) / M + sin^2(az) / N;
- refraction (coefficient k): the engine traces straight rays over terrain raised by
  k d^2 / (2 R) (d the horizontal distance from the laser); a refracted ray has curvature
  k / R, so relative to it the ground falls by (1 - k) d^2 / (2 R); the horizon of an eye at
  height h is at sqrt(2 R h / (1 - k)).

The DEMs are GeoTIFFs written in the tests (rasterio) with analytic surfaces that bilinear
interpolation between cell centres reproduces exactly (planes, profiles piecewise linear
with their breakpoints on cell centres), so "the DEM surface" is known in closed form.
The engine's geometry is read from the loaded scene: ``offset_m`` (world position of the
first target's centre), ``laser_position_m``, the observer points and the terrain
heightfield (local = world - offset), and from the verdicts of ``hazard.analyze``.
"""

from __future__ import annotations

import csv
import io
import math
from pathlib import Path

import numpy as np
import pytest
import rasterio
from hypothesis import given
from hypothesis import strategies as st
from pyproj import Geod, Transformer
from rasterio.transform import Affine

import hazard
import scenes
from hazard.cli import main

from . import _refs as ref

# --------------------------------------------------------------------------- the reference chain

A_WGS84 = 6378137.0
F_WGS84 = 1 / 298.257223563
E2 = F_WGS84 * (2 - F_WGS84)

_GEO2ECEF = Transformer.from_crs("EPSG:4979", "EPSG:4978", always_xy=True)
_ECEF2GEO = Transformer.from_crs("EPSG:4978", "EPSG:4979", always_xy=True)
_GEOD = Geod(ellps="WGS84")


def ecef(lat, lon, h):
    """ECEF [m] of geodetic points (degrees, metres above the ellipsoid), by pyproj."""
    x, y, z = _GEO2ECEF.transform(np.asarray(lon, float), np.asarray(lat, float), np.asarray(h, float))
    return np.stack([np.asarray(x), np.asarray(y), np.asarray(z)], axis=-1)


def ecef_closed_form(lat, lon, h):
    """The same from the ellipsoid's formulas (a self-check of the pyproj chain)."""
    la, lo = np.radians(lat), np.radians(lon)
    n = A_WGS84 / np.sqrt(1 - E2 * np.sin(la) ** 2)
    return np.stack([(n + h) * np.cos(la) * np.cos(lo), (n + h) * np.cos(la) * np.sin(lo), (n * (1 - E2) + h) * np.sin(la)], axis=-1)


def enu_rotation(lat0, lon0):
    la, lo = math.radians(lat0), math.radians(lon0)
    return np.array([
        [-math.sin(lo), math.cos(lo), 0.0],
        [-math.sin(la) * math.cos(lo), -math.sin(la) * math.sin(lo), math.cos(la)],
        [math.cos(la) * math.cos(lo), math.cos(la) * math.sin(lo), math.sin(la)],
    ])


def enu(lat, lon, h, origin):
    """Exact ENU [m] of geodetic points in the frame of ``origin`` = (lat0, lon0, h0)."""
    lat0, lon0, h0 = origin
    d = ecef(lat, lon, h) - ecef(lat0, lon0, h0)
    return d @ enu_rotation(lat0, lon0).T


def enu_to_geodetic(p, origin):
    """(lat, lon, h) of ENU points (the inverse chain)."""
    lat0, lon0, h0 = origin
    q = np.asarray(p, float) @ enu_rotation(lat0, lon0) + ecef(lat0, lon0, h0)
    lon, lat, h = _ECEF2GEO.transform(q[..., 0], q[..., 1], q[..., 2])
    return np.asarray(lat), np.asarray(lon), np.asarray(h)


def radii(lat0):
    """(M, N, R = sqrt(M N)) of WGS 84 at latitude lat0 [deg]."""
    s = math.sin(math.radians(lat0))
    w = math.sqrt(1 - E2 * s * s)
    m, n = A_WGS84 * (1 - E2) / w**3, A_WGS84 / w
    return m, n, math.sqrt(m * n)


def radius_in_azimuth(lat0, az_deg):
    """Euler: the normal-section radius in azimuth az (clockwise from north)."""
    m, n, _ = radii(lat0)
    a = math.radians(az_deg)
    return 1.0 / (math.cos(a) ** 2 / m + math.sin(a) ** 2 / n)


def flat_earth(lat, lon, h, origin):
    """The flat-earth frame a careless implementation would use: x = N cos(lat0) dlon,
    y = M dlat, z = h - h0 (no curvature). Only to show it fails the tolerance."""
    lat0, lon0, h0 = origin
    m, n, _ = radii(lat0)
    dlon = (np.asarray(lon, float) - lon0 + 180.0) % 360.0 - 180.0
    return np.stack([n * math.cos(math.radians(lat0)) * np.radians(dlon), m * np.radians(np.asarray(lat, float) - lat0),
                     np.asarray(h, float) - h0 + 0 * dlon], axis=-1)


def destination(lat, lon, az_deg, dist_m):
    """The point at geodesic distance ``dist_m`` and azimuth ``az_deg`` (a way to place points)."""
    lo, la, _ = _GEOD.fwd(lon, lat, az_deg, dist_m)
    return float(la), float(lo)


def test_the_reference_chain_itself():
    """pyproj's geodetic -> ECEF agrees with the closed form to 1e-6 m, and the rotation is
    orthonormal: the origin is (0, 0, 0), a point straight up is (0, 0, h), a point 1 m up
    the normal of a point due east has no north component."""
    for lat, lon, h in [(32.6, -106.3, 1200.0), (70.0, 20.0, -50.0), (-33.9, 151.2, 3000.0), (-17.0, 179.99, 0.0)]:
        np.testing.assert_allclose(ecef(lat, lon, h), ecef_closed_form(lat, lon, h), atol=1e-6)
        r = enu_rotation(lat, lon)
        np.testing.assert_allclose(r @ r.T, np.eye(3), atol=1e-15)
        o = (lat, lon, h)
        np.testing.assert_allclose(enu(lat, lon, h, o), 0.0, atol=1e-9)
        np.testing.assert_allclose(enu(lat, lon, h + 123.0, o), [0.0, 0.0, 123.0], atol=1e-8)
        back = enu_to_geodetic(np.array([1000.0, -2000.0, 30.0]), o)
        np.testing.assert_allclose(enu(*back, o), [1000.0, -2000.0, 30.0], atol=1e-8)


# --------------------------------------------------------------------------- scene text

PLATE = 'shape = "plate"\nnormal = [0.0, -1.0, 0.0]\ntangent = [1.0, 0.0, 0.0]\nsize_m = [1.0, 1.0]\n' \
        'material = { model = "lambertian", reflectance = 0.5 }\n'


def vec(v):
    return "[" + ", ".join(repr(float(x)) for x in v) + "]"


def site_text(origin, *, vertical=None, crs=None, k=None):
    out = f"[site]\norigin = {vec(origin)}\n"
    if vertical is not None:
        out += f'vertical = "{vertical}"\n'
    if crs is not None:
        out += f'crs = "{crs}"\n'
    if k is not None:
        out += f"refraction_k = {float(k)!r}\n"
    return out


def geo_scene(origin, laser, aim, target, observers=(), *, crs=None, k=None, extra="", laser_extra="", target_extra="",
              power=10.0, sector=None, analysis="direction_grid_deg = 10.0\nrefine_levels = 0\n"):
    """A scene with a [site]: ``laser``, ``aim``, ``target`` are ``*_geo`` values (2 or 3
    numbers), ``observers`` a list of (name, [points...], eye_height or None)."""
    lines = ['name = "geo"', site_text(origin, crs=crs, k=k),
             "[laser]", "wavelength_nm = 1064.0", f"power_w = {float(power)!r}", "beam_diameter_m = 0.05",
             "divergence_rad = 0.0001", f"position_geo = {vec(laser)}", f"aim_geo = {vec(aim)}"]
    if sector is not None:
        lines.append("sector = { azimuth_deg = %s, elevation_deg = %s }" % (vec(sector[0]), vec(sector[1])))
    lines += [laser_extra, "[exposure]", "duration_s = 10.0", "[[targets]]", 'name = "plate"', f"center_geo = {vec(target)}",
              target_extra, PLATE]
    for name, pts, eye in observers:
        lines += ["[[observers]]", f'name = "{name}"', "points_geo = [" + ", ".join(vec(p) for p in pts) + "]"]
        if eye is not None:
            lines.append(f"eye_height_m = {float(eye)!r}")
    lines += [extra, "[analysis]", analysis]
    return "\n".join(lines) + "\n"


DEFAULT_K = 0.13  # the contract's default refraction coefficient


def apparent(points_enu, origin, laser_enu, k=DEFAULT_K):
    """The contract's analysis frame: exact ENU points raised by the refraction rise
    k D^2 / (2 R), D the horizontal distance from the laser, R = sqrt(M N) at the origin
    (every position, so that straight rays see what a refracted beam sees)."""
    p = np.array(points_enu, float).reshape(-1, 3)
    _, _, r = radii(origin[0])
    d2 = (p[:, 0] - laser_enu[0]) ** 2 + (p[:, 1] - laser_enu[1]) ** 2
    p[:, 2] += k * d2 / (2 * r)
    return p


def world_points(scene):
    """The engine's geometry in world (ENU) metres: laser, target centre, observers."""
    off = np.asarray(scene.offset_m, float)
    return (np.asarray(scene.laser_position_m, float) + off, off.copy(), np.asarray(scene.observers.positions_m, float) + off)


def terrain_world_z(scene, x, y):
    """The engine's terrain height [m] (world ENU z) at world (x, y)."""
    off = np.asarray(scene.offset_m, float)
    return np.asarray(scene.terrain.height_at(np.asarray(x, float) - off[0], np.asarray(y, float) - off[1])) + off[2]


# --------------------------------------------------------------------------- 1. surveyed points

# origins and the points around them: (origin, [(azimuth deg, distance m, height m), ...]);
# the last site straddles the antimeridian (points on both sides of lon 180)
SITES = [
    ((32.60, -106.30, 1200.0), [(10.0, 1000.0, 1203.0), (95.0, 5000.0, 1350.0), (200.0, 20000.0, 900.0), (300.0, 12000.0, 1200.0)]),
    ((70.0, 20.0, 15.0), [(0.0, 1000.0, 20.0), (90.0, 8000.0, 300.0), (180.0, 20000.0, -30.0), (45.0, 15000.0, 2000.0)]),
    ((-33.9, 151.2, 40.0), [(135.0, 1000.0, 41.5), (270.0, 7000.0, 400.0), (20.0, 20000.0, 10.0), (330.0, 3000.0, 2500.0)]),
    ((-16.9, 179.97, 5.0), [(90.0, 1000.0, 8.0), (80.0, 9000.0, 600.0), (100.0, 20000.0, 50.0), (270.0, 6000.0, 5.0)]),
]


def _site_points(origin, spec):
    pts = []
    for az, dist, h in spec:
        la, lo = destination(origin[0], origin[1], az, dist)
        pts.append((la, lo, h))
    return pts


@pytest.mark.parametrize("origin,spec", SITES, ids=["new-mexico", "70N", "sydney", "antimeridian"])
def test_surveyed_points_are_placed_in_the_exact_enu_frame(origin, spec):
    """Laser, aim, target and observers given by latitude, longitude and ellipsoidal height
    at 1-20 km: the engine's laser position, target centre (offset) and observer points equal
    the pyproj chain to < 1 mm. The flat-earth frame (x = N cos(lat0) dlon, y = M dlat,
    z = h - h0) is off by more than 1 cm at each of these points (at 1 km the curvature drop
    d^2 / (2 R) alone is 7.8 cm), so it would fail the same tolerance."""
    pts = _site_points(origin, spec)
    laser, target, *obs = pts
    aim = pts[2]
    # the antimeridian site also writes one longitude past 180 (the same meridian as -180 + x)
    if origin[1] > 179:
        assert any(lo < 0 for _, lo, _ in pts) and any(lo > 0 for _, lo, _ in pts)  # both sides of 180
        obs = [(la, lo + 360.0 if lo < 0 else lo, h) for la, lo, h in obs]
        assert any(lo > 180.0 for _, lo, _ in obs)
    text = geo_scene(origin, laser, aim, target, [("posts", obs, None)])
    scene = scenes.loads(text)
    got_laser, got_target, got_obs = world_points(scene)
    want = enu(*np.array(pts).T, origin)
    want_obs = enu(*np.array(obs).T, origin)
    tol = 1e-3
    np.testing.assert_allclose(got_laser, want[0], rtol=0, atol=tol)  # the rise is zero at the laser
    np.testing.assert_allclose(got_target, apparent(want[1], origin, want[0])[0], rtol=0, atol=tol)
    np.testing.assert_allclose(got_obs, apparent(want_obs, origin, want[0]), rtol=0, atol=tol)
    # the beam points from the laser to the (raised) aim point
    d = apparent(want[2], origin, want[0])[0] - want[0]
    np.testing.assert_allclose(scene.laser_direction, d / np.linalg.norm(d), atol=1e-9)
    # the conversions list says the same
    conv = {c["key"]: np.asarray(c["m"], float) for c in scene.site.conversions}
    np.testing.assert_allclose(conv["laser.position_geo"], want[0], atol=tol)
    np.testing.assert_allclose(np.reshape(conv["observers[0].points_geo"], (-1, 3)), want_obs, atol=tol)
    # the flat-earth frame is off by more than the tolerance (mostly in height)
    flat = flat_earth(*np.array(pts).T, origin)
    dist = np.linalg.norm(want[:, :2], axis=1)
    far = dist >= 999.0
    err = np.linalg.norm(flat - want, axis=1)
    assert np.all(err[far] > 10 * tol), err
    _, _, r = radii(origin[0])
    assert np.all(np.abs(flat[far, 2] - want[far, 2]) > 0.5 * dist[far] ** 2 / (2 * r)), (flat[:, 2], want[:, 2])


@pytest.mark.parametrize("origin,crs,utm_pts", [
    ((32.60, -106.30, 1200.0), "EPSG:32613", [(0.0, 0.0, 1203.0), (1500.0, 1000.0, 1250.0), (-9000.0, 14000.0, 1100.0)]),
    ((-33.9, 151.2, 40.0), "EPSG:32756", [(200.0, -300.0, 42.0), (4000.0, 2000.0, 300.0), (-15000.0, -12000.0, 5.0)]),
])
def test_projected_input_utm(origin, crs, utm_pts):
    """site.crs a UTM zone: positions are [easting, northing, height]; the reference goes
    UTM -> geodetic (pyproj) -> ECEF -> ENU. Offsets here are from the origin's own UTM
    coordinates (north and south hemisphere zones)."""
    to_utm = Transformer.from_crs("EPSG:4326", crs, always_xy=True)
    from_utm = Transformer.from_crs(crs, "EPSG:4326", always_xy=True)
    e0, n0 = to_utm.transform(origin[1], origin[0])
    pts = [(e0 + de, n0 + dn, h) for de, dn, h in utm_pts]
    laser, target, obs = pts[0], pts[1], pts[2]
    text = geo_scene(origin, laser, target, target, [("far", [obs], None)], crs=crs)
    scene = scenes.loads(text)
    got_laser, got_target, got_obs = world_points(scene)
    e, n, h = np.array(pts).T
    lon, lat = from_utm.transform(e, n)
    want = enu(lat, lon, h, origin)
    np.testing.assert_allclose(got_laser, want[0], atol=1e-3)
    np.testing.assert_allclose(got_target, apparent(want[1], origin, want[0])[0], atol=1e-3)
    np.testing.assert_allclose(got_obs[0], apparent(want[2], origin, want[0])[0], atol=1e-3)
    # reading the UTM numbers as if they were ENU metres (grid north is not true north, the
    # scale factor is not 1, no curvature) would be metres off
    naive = np.array(pts) - np.array([e0, n0, origin[2]])
    assert np.linalg.norm(naive[2] - want[2]) > 1.0


# --------------------------------------------------------------------------- 6. property test


@ref.FAST
@given(lat0=st.floats(-80.0, 80.0), lon0=st.floats(-180.0, 180.0), h0=st.floats(-100.0, 3000.0),
       legs=st.lists(st.tuples(st.floats(0.0, 360.0), st.floats(1.0, 30000.0), st.floats(-100.0, 3000.0)), min_size=3, max_size=6))
def test_random_sites_and_points_match_the_pyproj_chain(lat0, lon0, h0, legs):
    """Random origin (|lat| <= 80, any longitude, height -100..3000 m) and points within
    30 km at heights -100..3000 m: the engine's ENU equals the pyproj chain to < 1 mm."""
    origin = (lat0, lon0, h0)
    pts = [(*destination(lat0, lon0, az, dist), h) for az, dist, h in legs]
    laser, target, *obs = pts
    want = enu(*np.array(pts).T, origin)
    if np.linalg.norm(want[1] - want[0]) < 1.0 or any(np.linalg.norm(w - want[1]) < 1.0 for w in want[2:]):
        return  # an observer inside the plate, or an aim on the laser: not this test's subject
    scene = scenes.loads(geo_scene(origin, laser, target, target, [("o", obs, None)]))
    got_laser, got_target, got_obs = world_points(scene)
    np.testing.assert_allclose(got_laser, want[0], atol=1e-3)
    np.testing.assert_allclose(got_target, apparent(want[1], origin, want[0])[0], atol=1e-3)
    np.testing.assert_allclose(got_obs, apparent(want[2:], origin, want[0]), atol=1e-3)


# --------------------------------------------------------------------------- DEMs written here


def write_dem(path, array, transform, crs, nodata=None):
    """A single-band float64 GeoTIFF (rows from the top, as GDAL stores them)."""
    array = np.asarray(array, float)
    with rasterio.open(path, "w", driver="GTiff", height=array.shape[0], width=array.shape[1], count=1, dtype="float64",
                       crs=crs, transform=transform, nodata=nodata) as ds:
        ds.write(array, 1)
    return Path(path)


def surface_below(x, y, origin, dem_h, iterations=8):
    """Exact ENU z of the DEM surface straight below ENU (x, y): the point (x, y, z) whose
    ellipsoidal height equals the DEM's height at its own (lat, lon). Newton on z (dh/dz = 1
    to within the tilt of the normal, ~1e-3 over 10 km; 8 steps reach < 1e-9 m).
    ``dem_h(lat, lon)``: the DEM's analytic surface."""
    x, y = np.broadcast_arrays(np.asarray(x, float), np.asarray(y, float))
    z = np.zeros_like(x)
    for _ in range(iterations):
        lat, lon, h = enu_to_geodetic(np.stack([x, y, z], -1), origin)
        z = z - (h - dem_h(lat, lon))
    return z


def refraction_rise(x, y, origin, k, laser_xy=(0.0, 0.0)):
    """k d^2 / (2 R), d the horizontal distance from the laser, R = sqrt(M N) at lat0."""
    _, _, r = radii(origin[0])
    d2 = (np.asarray(x, float) - laser_xy[0]) ** 2 + (np.asarray(y, float) - laser_xy[1]) ** 2
    return k * d2 / (2 * r)


def min_clearance(p0, p1, terrain_z, must=(), n=6000):
    """Smallest height of the segment p0 -> p1 above the terrain (``terrain_z(x, y)``),
    sampled at n points and at the fractions ``must`` (the crest). Negative: blocked."""
    t = np.unique(np.concatenate([np.linspace(0.0, 1.0, n), np.asarray(must, float)]))
    t = t[(t > 1e-6) & (t < 1 - 1e-6)]
    p = p0[None, :] + t[:, None] * (p1 - p0)[None, :]
    return float(np.min(p[:, 2] - terrain_z(p[:, 0], p[:, 1])))


def lat_at_north(origin, y, h):
    """Latitude on the origin's meridian whose point at height h has ENU y (Newton)."""
    m, _, _ = radii(origin[0])
    lat = origin[0] + math.degrees(y / m)
    for _ in range(6):
        lat += math.degrees((y - float(enu(lat, origin[1], h, origin)[1])) / m)
    return lat


def lon_at_east(origin, lat, x, h):
    """Longitude at latitude ``lat`` whose point at height h has ENU x (Newton)."""
    _, n, _ = radii(lat)
    lon = origin[1] + math.degrees(x / (n * math.cos(math.radians(lat))))
    for _ in range(6):
        lon += math.degrees((x - float(enu(lat, lon, h, origin)[0])) / (n * math.cos(math.radians(lat))))
    return lon


# --------------------------------------------------------------------------- 2. a ridge

RIDGE_ORIGIN = (35.0, -106.0, 1000.0)
RIDGE_Y, RIDGE_H = 8000.0, 60.0  # the ridge's near crest edge: 8 km north, 60 m above the plain
DLAT = 1.0 / 3600.0  # DEM rows: 1 arc second (30.8 m)
SLOPE = 0.08  # the far hillside the eye-height observers stand on, rising 8 % from ~14 km
LASER_AGL = 3.0
# profile in DEM rows j from the crest's near edge (breakpoints on integer rows = cell
# centres, so bilinear interpolation in the DEM reproduces it exactly): plain, a flank
# 8 rows (246 m) up to the plateau, the plateau 13 rows (400 m), down in 6 rows, plain,
# then the hillside from row JS
J_BREAKS, H_BREAKS = [-8.0, 0.0, 13.0, 19.0], [0.0, RIDGE_H, RIDGE_H, 0.0]


class Ridge:
    """An east-west ridge in an EPSG:4326 DEM (ellipsoidal heights), constant along
    longitude; its crest's near edge sits exactly on the terrain row y = 8000 m."""

    def __init__(self, folder):
        o = RIDGE_ORIGIN
        self.origin = o
        self.lat_e = lat_at_north(o, RIDGE_Y, o[2] + RIDGE_H)
        self.row_m = radii(o[0])[0] * math.radians(DLAT)
        self.js = round(6000.0 / self.row_m)  # hillside from ~14 km
        j_lo, j_hi = -int(8600 / self.row_m) - 3, int(10000 / self.row_m) + 3
        j = np.arange(j_hi, j_lo - 1, -1)  # top row first
        dlon = 0.004
        lon_left = o[1] - 0.12
        ncol = int(round(0.24 / dlon))
        top = self.lat_e + (j_hi + 0.5) * DLAT
        grid = np.repeat(self.profile(j.astype(float))[:, None], ncol, axis=1)
        self.path = write_dem(Path(folder) / "ridge.tif", grid, Affine(dlon, 0.0, lon_left, 0.0, -DLAT, top), "EPSG:4326")

    def profile(self, j):
        j = np.asarray(j, float)
        return self.origin[2] + np.interp(j, J_BREAKS, H_BREAKS) + SLOPE * self.row_m * np.maximum(j - self.js, 0.0)

    def height(self, lat, lon):
        return self.profile((np.asarray(lat, float) - self.lat_e) / DLAT)

    def terrain_z(self, k):
        return lambda x, y: surface_below(x, y, self.origin, self.height) + refraction_rise(x, y, self.origin, k)

    def flat_terrain_z(self, x, y):
        """A flat-earth model's terrain (no curvature, no refraction): z = h - h0 at y = M dlat."""
        m, _, _ = radii(self.origin[0])
        lat = self.origin[0] + np.degrees(np.asarray(y, float) / m)
        return self.height(lat, 0.0) - self.origin[2]


@pytest.fixture(scope="module")
def ridge(tmp_path_factory):
    return Ridge(tmp_path_factory.mktemp("ridge"))


RIDGE_X = 17.0  # the observers' line runs 17 m east of the laser's meridian (off the grid's node columns)
P_DIRECT, A_DIRECT, PHI_DIRECT = 1.0e5, 0.05, 1.0e-4


def ridge_scene(ridge, k, observers, masts=()):
    """The laser on the plain at the origin (3 m above the DEM), a plate 4 km north, the
    terrain a 100 m grid whose row y = 8000 m is the crest's near edge. A sector of
    +-2 deg azimuth and +-1 deg elevation about north: every observer is judged by the
    direction that points at it (the direct beam on its axis, or nothing where the
    terrain stands on the line from the aperture)."""
    o = ridge.origin
    tgt = (lat_at_north(o, 4000.0, o[2]), o[1])
    obs = [("slope", observers, 1.7)]
    if masts:
        obs.append(("mast", masts, None))
    terrain = ('[terrain]\nkind = "dem"\nfile = "ridge.tif"\ncenter_m = [0.0, 8700.0, 0.0]\nextent_m = 8800.0\n'
               'resolution_m = 100.0\n[atmosphere]\nattenuation_per_m = 0.0\n')
    text = geo_scene(o, o[:2], tgt, tgt, obs, k=k, power=P_DIRECT, sector=([-2.0, 2.0], [-1.0, 1.0]),
                     laser_extra=f"height_agl_m = {LASER_AGL}\naim_agl_m = 2.0", target_extra="height_agl_m = 2.0", extra=terrain)
    text = text.replace("beam_diameter_m = 0.05", f"beam_diameter_m = {A_DIRECT}").replace(
        "divergence_rad = 0.0001", f"divergence_rad = {PHI_DIRECT}")
    return scenes.loads(text, base_dir=ridge.path.parent)


def _direct_on_axis(dist):
    d = A_DIRECT + dist * PHI_DIRECT
    return 4 * P_DIRECT / (math.pi * d * d)


def _eye_point(ridge, lat, lon, k, eye=1.7):
    """Reference ENU of an eye-height observer given by [lat, lon]: the DEM surface there
    (exact chain), raised by the refraction rise and the eye height."""
    x, y, _ = enu(lat, lon, float(ridge.height(lat, lon)), ridge.origin)
    return np.array([x, y, float(ridge.terrain_z(k)(x, y)) + eye])


def _boundary_on_slope(ridge, k, laser):
    """Distance north (on the observers' line) where an eye on the hillside sees the
    laser's aperture just over the crest: bisection on the exact clearance."""
    o = ridge.origin

    def clear(y):
        lat = lat_at_north(o, y, o[2])
        p = _eye_point(ridge, lat, lon_at_east(o, lat, RIDGE_X, o[2]), k)
        return min_clearance(laser, p, ridge.terrain_z(k), must=[(RIDGE_Y - laser[1]) / (p[1] - laser[1])], n=400)

    lo, hi = 14500.0, 17000.0
    assert clear(lo) < 0 < clear(hi)
    for _ in range(30):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if clear(mid) < 0 else (lo, mid)
    return 0.5 * (lo + hi)


def test_line_of_sight_over_a_dem_ridge_at_eye_height(ridge):
    """The direct beam over a 60 m ridge 8 km north, to eyes (1.7 m) on a hillside 15-16 km
    north. Reference: the straight line from the aperture to each eye against the exact
    terrain (the DEM surface below every point by the pyproj chain, so the ground falls
    d^2 / (2 R) with distance, plus the refraction rise k d^2 / (2 R)); the shadow edge is
    where that line grazes the crest's near edge. Observers at 12 m and 50 m either side of
    the edge for k = 0 and for k = 0.13, and one between the two edges (lit with
    refraction, hidden without). Each is >= 0.25 m clear of its line of sight's grazing
    point (checked), well above the grid's error: the crest edge is a grid node (exact),
    the curvature between 100 m nodes is linear to dx^2 / (8 R) = 0.2 mm, the hillside is
    planar. Lit eyes get the beam on its axis, 4 P / (pi (a + L phi)^2) (rtol 1e-6)."""
    o = ridge.origin
    laser = np.array([0.0, 0.0, LASER_AGL])  # the DEM is at h0 under the origin: the aperture 3 m up
    b = {k: _boundary_on_slope(ridge, k, laser) for k in (0.0, 0.13)}
    assert b[0.13] < b[0.0] - 10.0, b  # refraction lowers the ground ahead: the edge moves closer
    ys = [b[0.13] - 50.0, b[0.13] - 12.0, 0.5 * (b[0.13] + b[0.0]), b[0.0] + 12.0, b[0.0] + 50.0]
    pts = []
    for y in ys:
        lat = lat_at_north(o, y, o[2])
        pts.append((lat, lon_at_east(o, lat, RIDGE_X, o[2])))
    verdicts = {}
    for k in (0.0, 0.13):
        scene = ridge_scene(ridge, k, pts)
        got_laser, _, got_obs = world_points(scene)
        np.testing.assert_allclose(got_laser, laser, atol=1e-3)
        want = np.array([_eye_point(ridge, la, lo, k) for la, lo in pts])
        np.testing.assert_allclose(got_obs, want, atol=0.01)
        clear = np.array([min_clearance(laser, p, ridge.terrain_z(k), must=[(RIDGE_Y - laser[1]) / (p[1] - laser[1])]) for p in want])
        assert np.all(np.abs(clear) > 0.25), clear  # the references are unambiguous
        lit = clear > 0
        res = hazard.analyze(scene)
        direct = np.asarray(res.observers.direct_point_irradiance_w_m2)
        assert np.array_equal(direct > 0, lit), (k, clear, direct)
        dist = np.linalg.norm(want - laser, axis=1)
        np.testing.assert_allclose(direct[lit], [_direct_on_axis(d) for d in dist[lit]], rtol=1e-6)
        assert np.array_equal(np.asarray(res.hazardous), lit)
        verdicts[k] = lit
    assert list(verdicts[0.0]) == [False, False, False, True, True]
    assert list(verdicts[0.13]) == [False, False, True, True, True]
    # a flat earth (no curvature, no refraction) would light every one of them by > 1.5 m:
    # the ground 15.5 km out is 19 m lower than flat, the crest 5 m lower
    flat = [min_clearance(laser, np.array([0.0, y, ridge.flat_terrain_z(0.0, y) + 1.7]), ridge.flat_terrain_z,
                          must=[RIDGE_Y / y]) for y in ys]
    assert all(c > 1.5 for c in flat), flat


def test_refraction_is_applied_to_points_at_absolute_heights_too(ridge):
    """Masts 12 km north (beyond the ridge) given by [lat, lon, h]: a refracted ray (curvature
    k / R, bending down) from the aperture to a point at horizontal distance D runs
    k d (D - d) / (2 R) above the straight chord, so it clears the crest where
    chord + k d (D - d) / (2 R) > ground (the true ground, no rise). This is the same as the
    straight-ray frame of the contract (terrain raised by k d^2 / (2 R)) only when the mast
    point is raised by k D^2 / (2 R) as well: the apparent rise is a map of all space, not
    of the ground alone. Reference: the refracted ray. Masts 0.4 m below and above its
    shadow edge, and one 0.75 m above it (lit by the refracted beam; a straight ray to the
    unraised point, over the raised crest, would call it hidden: at 12 km the two edges
    are k D^2 / (2 R) = 1.47 m apart for k = 0.13). k = 0: both frames agree."""
    o = ridge.origin
    _, _, r = radii(o[0])
    laser = np.array([0.0, 0.0, LASER_AGL])
    lat = lat_at_north(o, 12000.0, o[2])
    lon = lon_at_east(o, lat, RIDGE_X, o[2])
    xy = enu(lat, lon, o[2], o)[:2]
    for k in (0.0, 0.13):
        true_ground = ridge.terrain_z(0.0)

        def refracted_clearance(p, k=k, true_ground=true_ground):  # called within this iteration
            t = np.unique(np.concatenate([np.linspace(0, 1, 4000), [RIDGE_Y / p[1]]]))[1:-1]
            q = laser[None, :] + t[:, None] * (p - laser)[None, :]
            dd = np.hypot(q[:, 0], q[:, 1])
            big = math.hypot(p[0], p[1])
            return float(np.min(q[:, 2] + k * dd * (big - dd) / (2 * r) - true_ground(q[:, 0], q[:, 1])))

        # the refracted ray's shadow edge on the mast: bisection in height
        lo_z, hi_z = 0.0, 200.0
        for _ in range(50):
            mid = 0.5 * (lo_z + hi_z)
            lo_z, hi_z = (mid, hi_z) if refracted_clearance(np.array([*xy, mid])) < 0 else (lo_z, mid)
        edge = 0.5 * (lo_z + hi_z)
        heights = [edge - 0.4, edge + 0.4, edge + 0.75]
        masts = []
        for z in heights:
            la, lo_, h = enu_to_geodetic(np.array([xy[0], xy[1], z]), o)
            masts.append((float(la), float(lo_), float(h)))
        eye_lat = lat_at_north(o, 16500.0, o[2])
        scene = ridge_scene(ridge, k, [(eye_lat, lon_at_east(o, eye_lat, RIDGE_X, o[2]))], masts=masts)
        _, _, got = world_points(scene)
        raised = apparent([[*xy, z] for z in heights], o, laser, k)
        np.testing.assert_allclose(got[1:], raised, atol=1e-3)  # exact ENU points, raised as the terrain is
        lit = [refracted_clearance(np.array([*xy, z])) > 0 for z in heights]
        assert lit == [False, True, True]
        direct = np.asarray(hazard.analyze(scene).observers.direct_irradiance_w_m2)[1:]
        # first the contract's own straight-ray frame (terrain and mast point raised alike):
        # the engine must at least do what it says
        contract = [min_clearance(laser, p, ridge.terrain_z(k), must=[RIDGE_Y / xy[1]]) > 0 for p in raised]
        assert list(direct > 0) == contract, (k, direct, contract)
        assert list(direct > 0) == lit, (
            f"k = {k}: masts at ENU z = {np.round(heights, 3).tolist()} m, 12 km north; the refracted beam's shadow edge "
            f"is at z = {edge:.3f} m, so the refracted beam reaches {lit}; the engine's direct irradiance {direct.tolist()} W/m^2 "
            f"(a straight ray over the raised crest to the unraised mast point puts the edge {k * 12000.0**2 / (2 * r):.2f} m higher)")


# --------------------------------------------------------------------------- 3. curvature and refraction

FLAT_ORIGIN = (47.0, 8.0, 500.0)


@pytest.fixture(scope="module")
def flat_dem(tmp_path_factory):
    """Constant ellipsoidal height h0 over -12..20 km north, +-12 km east (EPSG:4326)."""
    o = FLAT_ORIGIN
    m, n, _ = radii(o[0])
    dlat, dlon = 0.005, 0.005
    lat_lo, lat_hi = o[0] - math.degrees(12500 / m), o[0] + math.degrees(20500 / m)
    half_lon = math.degrees(12500 / (n * math.cos(math.radians(o[0] + 0.2))))
    nrow, ncol = int((lat_hi - lat_lo) / dlat) + 1, int(2 * half_lon / dlon) + 1
    path = tmp_path_factory.mktemp("flat") / "flat.tif"
    return write_dem(path, np.full((nrow, ncol), o[2]), Affine(dlon, 0, o[1] - half_lon, 0, -dlat, lat_hi), "EPSG:4326")


def _flat_scene(path, k, terrain, observers=(), laser_agl=2.0, sector=None, power=10.0):
    o = FLAT_ORIGIN
    tgt = (lat_at_north(o, 1000.0, o[2]), o[1])
    text = geo_scene(o, o[:2], tgt, tgt, observers, k=k, laser_extra=f"height_agl_m = {laser_agl}\naim_agl_m = 2.0",
                     target_extra="height_agl_m = 2.0", power=power, sector=sector,
                     extra=f'[terrain]\nkind = "dem"\nfile = "{path.name}"\n{terrain}[atmosphere]\nattenuation_per_m = 0.0\n')
    return scenes.loads(text, base_dir=path.parent)


@pytest.mark.parametrize("k", [None, 0.0, 0.3])
def test_the_ground_falls_with_the_curvature_and_rises_with_refraction(flat_dem, k):
    """A DEM of constant ellipsoidal height h0 (the origin's): at 10 km north, east and
    north-east the engine's terrain z is -d^2 / (2 R_az) + k d^2 / (2 R) (R_az by Euler's
    formula; R = sqrt(M N)) to < 2 cm (the parabola's neglected terms are < 1 mm at 10 km),
    and equals the exact chain (the ellipsoid surface at h0 straight below each node, plus
    k d^2 / (2 R)) to < 1 mm at every node of the 500 m grid. k = None: the default, 0.13."""
    kk = 0.13 if k is None else k
    o = FLAT_ORIGIN
    scene = _flat_scene(flat_dem, k, "extent_m = 10500.0\nresolution_m = 500.0\n")
    _, _, r = radii(o[0])
    for az, (x, y) in [(0.0, (0.0, 10000.0)), (90.0, (10000.0, 0.0)), (45.0, (7000.0, 7000.0)), (180.0, (0.0, -10000.0))]:
        d2 = x * x + y * y
        formula = -d2 / (2 * radius_in_azimuth(o[0], az)) + kk * d2 / (2 * r)
        got = float(terrain_world_z(scene, x, y))
        exact = float(surface_below(x, y, o, lambda la, lo: o[2]) + refraction_rise(x, y, o, kk))
        assert abs(got - formula) < 0.02, (az, got, formula)
        assert abs(got - exact) < 1e-3, (az, got, exact)
        assert abs(exact - formula) < 1e-3
    # every node
    t = scene.terrain
    ny, nx = t.heights.shape
    off = scene.offset_m
    xs, ys = np.meshgrid(t.x0 + off[0] + t.dx * np.arange(nx), t.y0 + off[1] + t.dx * np.arange(ny))
    assert t.dx == 500.0 and abs(xs.min() + 10500.0) < 1e-6 and abs(ys.max() - 10500.0) < 1e-6
    exact = surface_below(xs, ys, o, lambda la, lo: o[2]) + refraction_rise(xs, ys, o, kk)
    np.testing.assert_allclose(t.heights + off[2], exact, atol=1e-3)
    # a flat-earth terrain (z = 0 everywhere) is 7.8 m off at 10 km, and without refraction
    # the ground would be k d^2 / (2 R) = 1 m lower there
    assert float(terrain_world_z(scene, 0.0, 10000.0)) < -5.0


def test_the_refraction_rise_is_centred_on_the_laser_not_the_origin(flat_dem):
    """The rise is k d^2 / (2 R) with d from the laser: a laser standing 3 km east and 2 km
    north of the site's origin, k = 0.13: every node is the exact ellipsoid surface at h0
    plus k |xy - laser_xy|^2 / (2 R) (< 1 mm); centring it on the origin instead would be
    k (3.6 km)^2 / (2 R) = 0.13 m off under the laser."""
    o = FLAT_ORIGIN
    lat = lat_at_north(o, 2000.0, o[2])
    laser = (lat, lon_at_east(o, lat, 3000.0, o[2]))
    tgt = (lat_at_north(o, 3000.0, o[2]), o[1])
    text = geo_scene(o, laser, tgt, tgt, k=0.13, laser_extra="height_agl_m = 2.0\naim_agl_m = 2.0", target_extra="height_agl_m = 2.0",
                     extra=f'[terrain]\nkind = "dem"\nfile = "{flat_dem.name}"\nextent_m = 6000.0\nresolution_m = 500.0\n')
    scene = scenes.loads(text, base_dir=flat_dem.parent)
    lxy = enu(*laser, o[2], o)[:2]
    got_laser, _, _ = world_points(scene)
    z_under = float(surface_below(lxy[0], lxy[1], o, lambda la, lo: o[2]))
    np.testing.assert_allclose(got_laser, [lxy[0], lxy[1], z_under + 2.0], atol=1e-3)  # no rise under the laser
    t, off = scene.terrain, scene.offset_m
    ny, nx = t.heights.shape
    xs, ys = np.meshgrid(t.x0 + off[0] + t.dx * np.arange(nx), t.y0 + off[1] + t.dx * np.arange(ny))
    exact = surface_below(xs, ys, o, lambda la, lo: o[2]) + refraction_rise(xs, ys, o, 0.13, laser_xy=lxy)
    np.testing.assert_allclose(t.heights + off[2], exact, atol=1e-3)


def test_a_dem_in_utm_with_a_tilted_plane(tmp_path):
    """A plane in UTM zone 32N (EPSG:32632), h = h0 + 0.03 (E - E0) - 0.02 (N - N0)
    (ellipsoidal; bilinear interpolation in the DEM's own CRS reproduces it exactly): every
    terrain node's z is the exact ENU height of that plane straight below it plus the
    refraction rise, to < 1 mm (the engine was first seen 4.2 mm off here: GDAL's decimating
    bilinear read; it now keeps every step-th cell as it is, 7e-9 m off). Grid
    north is 0.7 deg off true north here and the UTM scale is 0.9996: reading the DEM along
    ENU axes would be metres off on this slope."""
    o = FLAT_ORIGIN
    to_utm = Transformer.from_crs("EPSG:4326", "EPSG:32632", always_xy=True)
    e0, n0 = to_utm.transform(o[1], o[0])

    def plane(e, n):
        return o[2] + 0.03 * (e - e0) - 0.02 * (n - n0)

    step = 30.0
    left, top = e0 - 7000.0, n0 + 7000.0
    ncell = int(14000 / step)
    ce = left + step * (np.arange(ncell) + 0.5)
    cn = top - step * (np.arange(ncell) + 0.5)
    path = write_dem(tmp_path / "utm.tif", plane(ce[None, :], cn[:, None]), Affine(step, 0, left, 0, -step, top), "EPSG:32632")
    scene = _flat_scene(path, 0.13, "extent_m = 5000.0\nresolution_m = 250.0\n")
    t, off = scene.terrain, scene.offset_m
    ny, nx = t.heights.shape
    xs, ys = np.meshgrid(t.x0 + off[0] + t.dx * np.arange(nx), t.y0 + off[1] + t.dx * np.arange(ny))

    def dem_h(lat, lon):
        e, n = to_utm.transform(lon, lat)
        return plane(np.asarray(e), np.asarray(n))

    exact = surface_below(xs, ys, o, dem_h) + refraction_rise(xs, ys, o, 0.13)
    np.testing.assert_allclose(t.heights + off[2], exact, atol=1e-3)
    # the plane read as if UTM axes were ENU axes (no convergence, no scale, no curvature)
    naive = 0.03 * xs - 0.02 * ys
    assert np.max(np.abs(naive - exact)) > 2.0


def _horizon(k, lat0, h_laser, h_eye):
    """Farthest eye (height h_eye over the ground) seen from h_laser due north: the ground
    falls d^2 / (2 M) (M the meridian radius: the normal section due north), rises
    k d^2 / (2 R): effective radius 1 / R_e = 1 / M - k / R, and the tangent line reaches
    sqrt(2 R_e h_laser) + sqrt(2 R_e h_eye)."""
    m, _, r = radii(lat0)
    re = 1.0 / (1.0 / m - k / r)
    return math.sqrt(2 * re * h_laser) + math.sqrt(2 * re * h_eye)


def test_the_horizon_with_and_without_refraction(flat_dem):
    """A laser 10 m over the flat DEM, eyes at 1.7 m due north around the horizon:
    sqrt(2 R_e h_L) + sqrt(2 R_e h_eye) is 16.0 km with k = 0 and 17.2 km with k = 0.13
    (the textbook sqrt(2 R h / (1 - k)) with R -> R_e). Eyes 500 m inside the geometric
    horizon, between the two and 500 m past the refracted one: the direct beam reaches
    the first with k = 0, the first two with k = 0.13, never the last. Each eye's line of
    sight is also checked against the exact ground (>= 0.2 m clear either way: the tangent
    line's height changes by sqrt(2 h_eye / R_e) ~ 7e-4 m/m near the eye; the 200 m grid
    is exact to dx^2 / (8 R_e) = 0.7 mm)."""
    o = FLAT_ORIGIN
    h_laser, eye = 10.0, 1.7
    d0, d13 = _horizon(0.0, o[0], h_laser, eye), _horizon(0.13, o[0], h_laser, eye)
    assert 15900 < d0 < 16100 and 17000 < d13 < 17300 and d13 / d0 == pytest.approx(1 / math.sqrt(1 - 0.13), rel=0.01)
    ds = [d0 - 500.0, 0.5 * (d0 + d13), d13 + 500.0]
    pts = [(lat_at_north(o, d, o[2]), o[1] + 1e-5) for d in ds]  # 0.76 m east of the node column
    laser = np.array([0.0, 0.0, h_laser])
    for k, want in ((0.0, [True, False, False]), (0.13, [True, True, False])):
        scene = _flat_scene(flat_dem, k, "center_m = [0.0, 9000.0, 0.0]\nextent_m = 9200.0\nresolution_m = 200.0\n",
                            observers=[("north", pts, eye)], laser_agl=h_laser, sector=([-2.0, 2.0], [-1.0, 1.0]), power=1e5)
        got_laser, _, got = world_points(scene)
        np.testing.assert_allclose(got_laser, laser, atol=1e-3)
        ground = lambda x, y, k=k: surface_below(x, y, o, lambda la, lo: o[2]) + refraction_rise(x, y, o, k)  # noqa: E731
        ref_pts = np.array([[*enu(la, lo, o[2], o)[:2], 0.0] for la, lo in pts])
        ref_pts[:, 2] = ground(ref_pts[:, 0], ref_pts[:, 1]) + eye
        np.testing.assert_allclose(got, ref_pts, atol=2e-3)
        clear = np.array([min_clearance(laser, p, ground) for p in ref_pts])
        assert list(clear > 0) == want and np.all(np.abs(clear) > 0.2), clear
        direct = np.asarray(hazard.analyze(scene).observers.direct_irradiance_w_m2)
        assert list(direct > 0) == want, (k, direct, clear)


# --------------------------------------------------------------------------- 4. bad input

PLANE_ORIGIN = (-23.5, 133.9, 600.0)
PLANE_STEP = 0.0005  # deg (55 m x 51 m cells)
PLANE_HALF = 0.06  # deg each side of the origin (~6.6 km north-south, ~6.1 km east-west)


def plane_h(lat, lon):
    """The plane DEM's surface: 600 m + 4000 m/deg east (3.9 %), - 2000 m/deg north (-1.8 %)."""
    return 600.0 + 4000.0 * (np.asarray(lon, float) - PLANE_ORIGIN[1]) - 2000.0 * (np.asarray(lat, float) - PLANE_ORIGIN[0])


def plane_dem(path, hole=None, nodata=-9999.0):
    """A plane in lat/lon (EPSG:4326, ellipsoidal heights), optionally with a rectangle of
    nodata cells ``hole = (row0, row1, col0, col1)`` (rows from the top)."""
    o = PLANE_ORIGIN
    n = int(round(2 * PLANE_HALF / PLANE_STEP))
    top, left = o[0] + PLANE_HALF, o[1] - PLANE_HALF
    lat_c = top - PLANE_STEP * (np.arange(n) + 0.5)
    lon_c = left + PLANE_STEP * (np.arange(n) + 0.5)
    grid = plane_h(lat_c[:, None], lon_c[None, :])
    if hole is not None:
        r0, r1, c0, c1 = hole
        grid[r0:r1, c0:c1] = nodata
    tr = Affine(PLANE_STEP, 0.0, left, 0.0, -PLANE_STEP, top)
    return write_dem(path, grid, tr, "EPSG:4326", nodata=nodata), lat_c, lon_c, grid


def _plane_scene(path, terrain="extent_m = 2000.0\nresolution_m = 100.0\n", observers=(), k=0.0, site_extra=""):
    o = PLANE_ORIGIN
    tgt = (lat_at_north(o, 500.0, o[2]), o[1])
    text = geo_scene(o, o[:2], tgt, tgt, observers, k=k, laser_extra="height_agl_m = 2.0\naim_agl_m = 2.0",
                     target_extra="height_agl_m = 2.0",
                     extra=f'[terrain]\nkind = "dem"\nfile = "{path.name}"\n{terrain}')
    return text.replace("[laser]", site_extra + "[laser]")


def _nearest_cell(x, y, lat_c, lon_c):
    """The DEM cell (row, col) whose centre is nearest the ENU point (x, y)."""
    la, lo, _ = enu_to_geodetic(np.array([x, y, 0.0]), PLANE_ORIGIN)
    return int(np.argmin(np.abs(lat_c - la))), int(np.argmin(np.abs(lon_c - lo)))


def test_nodata_under_the_analysis_area(tmp_path):
    """A 3 x 4 cell hole of nodata 300 m east, 200 m south of the laser, inside the 2 km
    analysis area: an error naming the nodata by default; with nodata = "fill" the scene
    loads, the terrain over the hole lies between the ENU heights of the lowest and highest
    DEM value within 3 cells of the hole (filling interpolates from the hole's edges; the
    plane spans ~30 m there, so this is a real bound, > 10 m checked), and nodes away from the hole
    are the exact plane (< 1 mm). A hole outside the analysis area is no error."""
    _, lat_c, lon_c, _ = plane_dem(tmp_path / "probe.tif")
    r, c = _nearest_cell(300.0, -200.0, lat_c, lon_c)
    hole = (r - 1, r + 2, c - 2, c + 2)
    path, lat_c, lon_c, grid = plane_dem(tmp_path / "hole.tif", hole)
    with pytest.raises(scenes.SceneError, match=r"(?i)no ?data"):
        scenes.loads(_plane_scene(path), base_dir=tmp_path)
    scene = scenes.loads(_plane_scene(path, 'extent_m = 2000.0\nresolution_m = 100.0\nnodata = "fill"\n'), base_dir=tmp_path)
    t, off = scene.terrain, scene.offset_m
    ny, nx = t.heights.shape
    xs, ys = np.meshgrid(t.x0 + off[0] + t.dx * np.arange(nx), t.y0 + off[1] + t.dx * np.arange(ny))
    got = t.heights + off[2]
    lat, lon, _ = enu_to_geodetic(np.stack([xs, ys, np.zeros_like(xs)], -1), PLANE_ORIGIN)
    # which nodes read the hole (their DEM stencil, one cell around the nearest centre)
    rows = np.clip(np.round((lat_c[0] - lat) / PLANE_STEP).astype(int), 0, len(lat_c) - 1)
    cols = np.clip(np.round((lon - lon_c[0]) / PLANE_STEP).astype(int), 0, len(lon_c) - 1)
    r0, r1, c0, c1 = hole
    near = (rows >= r0 - 1) & (rows < r1 + 1) & (cols >= c0 - 1) & (cols < c1 + 1)
    inside = (rows >= r0) & (rows < r1) & (cols >= c0) & (cols < c1)
    assert inside.sum() >= 2, inside.sum()  # some nodes stand over the hole
    band = grid[max(r0 - 3, 0):r1 + 3, max(c0 - 3, 0):c1 + 3]
    lo_h, hi_h = band[band > -9000].min(), band[band > -9000].max()
    assert hi_h - lo_h > 10.0
    z_lo = surface_below(xs[near], ys[near], PLANE_ORIGIN, lambda la, lo: lo_h)
    z_hi = surface_below(xs[near], ys[near], PLANE_ORIGIN, lambda la, lo: hi_h)
    assert np.all((got[near] >= z_lo - 1e-3) & (got[near] <= z_hi + 1e-3)), (got[near], z_lo, z_hi)
    far = ~((rows >= r0 - 3) & (rows < r1 + 3) & (cols >= c0 - 3) & (cols < c1 + 3))
    exact = surface_below(xs[far], ys[far], PLANE_ORIGIN, plane_h)
    np.testing.assert_allclose(got[far], exact, atol=1e-3)
    # a hole well outside the analysis area (4 km south-west) is not an error
    r2, c2 = _nearest_cell(-4500.0, -4500.0, lat_c, lon_c)
    path2, *_ = plane_dem(tmp_path / "hole_far.tif", (r2 - 1, r2 + 2, c2 - 1, c2 + 2))
    scenes.loads(_plane_scene(path2), base_dir=tmp_path)


def test_an_analysis_area_past_the_dem_is_an_error(tmp_path):
    """The DEM reaches 6.1 km east and west of the origin (6.6 km north and south): a 7 km
    half-width area reaches past it, a 5.5 km one does not; a 3 km one centred 2.5 km east
    fits (5.5 km east), centred 3.5 km east it does not (6.5 km east)."""
    path, *_ = plane_dem(tmp_path / "plane.tif")
    scenes.loads(_plane_scene(path, "extent_m = 5500.0\nresolution_m = 250.0\n"), base_dir=tmp_path)
    with pytest.raises(scenes.SceneError, match="DEM"):
        scenes.loads(_plane_scene(path, "extent_m = 7000.0\nresolution_m = 250.0\n"), base_dir=tmp_path)
    scenes.loads(_plane_scene(path, "center_m = [2500.0, 0.0, 0.0]\nextent_m = 3000.0\nresolution_m = 250.0\n"), base_dir=tmp_path)
    with pytest.raises(scenes.SceneError, match="DEM"):
        scenes.loads(_plane_scene(path, "center_m = [3500.0, 0.0, 0.0]\nextent_m = 3000.0\nresolution_m = 250.0\n"), base_dir=tmp_path)


@pytest.mark.filterwarnings("ignore:Best transformation is not available:UserWarning")
def test_egm96_without_its_grid_names_the_grid():
    """vertical = "egm96" needs PROJ's us_nga_egm96_15.tif (not installed here): a
    SceneError naming it, not a silent ellipsoidal reading (the geoid is tens of metres
    off the ellipsoid)."""
    o = (32.6, -106.3, 1200.0)
    text = geo_scene(o, (32.6, -106.3, 1203.0), (32.61, -106.3, 1210.0), (32.61, -106.3, 1210.0))
    text = text.replace("[laser]", 'vertical = "egm96"\n[laser]', 1)
    assert 'vertical = "egm96"' in text.split("[laser]")[0]
    with pytest.raises(scenes.SceneError, match="us_nga_egm96_15.tif"):
        scenes.loads(text)


def test_geo_keys_need_a_site_and_exclude_their_metre_twin():
    o = (32.6, -106.3, 1200.0)
    good = geo_scene(o, (32.6, -106.3, 1203.0), (32.61, -106.3, 1210.0), (32.61, -106.3, 1210.0))
    scenes.loads(good)
    no_site = good.split("[site]")[0] + "[laser]" + good.split("[laser]", 1)[1]
    assert "[site]" not in no_site
    with pytest.raises(scenes.SceneError, match=r"position_geo.*\[site\]"):
        scenes.loads(no_site)
    both = good.replace("[laser]\n", "[laser]\nposition_m = [0.0, 0.0, 3.0]\n", 1)
    with pytest.raises(scenes.SceneError, match="position"):
        scenes.loads(both)
    both_target = good.replace('name = "plate"\n', 'name = "plate"\ncenter_m = [0.0, 1000.0, 10.0]\n', 1)
    with pytest.raises(scenes.SceneError, match="center"):
        scenes.loads(both_target)


# --------------------------------------------------------------------------- 5. observers.csv


def test_observers_csv_gives_back_the_geodetic_positions(tmp_path):
    """`hazard run` on a site scene: observers.csv's lat_deg, lon_deg, height_m equal the
    positions given, for points with absolute heights to 1e-8 deg and 1 mm; for eye-height
    points (1.7 m over the DEM, with refraction k = 0.13) height_m = the DEM's height there
    + 1.7 m to 5 mm and lat/lon to 1e-7 deg (1 cm). The 5 mm covers the grid: between
    100 m nodes the terrain is bilinear, the curvature and refraction terms are quadratic,
    off by at most dx^2 (1 + k) / (8 R) = 0.2 mm; the height must not include the
    refraction rise (an apparent, not a real, height: 0.26 m at 5 km here)."""
    o = PLANE_ORIGIN
    path, *_ = plane_dem(tmp_path / "plane.tif")
    posts = [(*destination(o[0], o[1], az, d), h) for az, d, h in [(30.0, 1200.0, 700.0), (200.0, 4000.0, 900.0), (280.0, 2500.0, 650.0)]]
    eyes = [destination(o[0], o[1], az, d) for az, d in [(60.0, 1000.0), (150.0, 3000.0), (330.0, 5000.0)]]
    for la, lo, h in posts:
        assert h > plane_h(la, lo) + 5.0  # above the ground
    text = _plane_scene(path, "extent_m = 5500.0\nresolution_m = 100.0\n", observers=[("posts", posts, None), ("eyes", eyes, 1.7)],
                        k=0.13)
    scene_path = tmp_path / "site.toml"
    scene_path.write_text(text)
    out = tmp_path / "out"
    err = io.StringIO()
    code = main(["run", str(scene_path), "-o", str(out), "--quiet"], stdout=io.StringIO(), stderr=err)
    assert code == 0, err.getvalue()
    with open(out / "observers.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == 6
    assert {"lat_deg", "lon_deg", "height_m"} <= set(rows[0]), f"observers.csv columns: {list(rows[0])}"
    got = np.array([[float(r["lat_deg"]), float(r["lon_deg"]), float(r["height_m"])] for r in rows])
    np.testing.assert_allclose(got[:3, :2], np.array(posts)[:, :2], rtol=0, atol=1e-8)
    np.testing.assert_allclose(got[:3, 2], np.array(posts)[:, 2], rtol=0, atol=1e-3)
    np.testing.assert_allclose(got[3:, :2], np.array(eyes), rtol=0, atol=1e-7)
    want_h = [float(plane_h(la, lo)) + 1.7 for la, lo in eyes]
    np.testing.assert_allclose(got[3:, 2], want_h, rtol=0, atol=5e-3)
    # and the csv's x_m, y_m, z_m are the same points in the frame (world ENU or local:
    # whichever, the differences between rows are frame-independent)
    xyz = np.array([[float(r["x_m"]), float(r["y_m"]), float(r["z_m"])] for r in rows])
    laser_enu = np.zeros(2)  # the laser stands on the ground at the origin here
    ref_posts = apparent(enu(*np.array(posts).T, o), o, laser_enu[:2], 0.13)  # the frame's points are raised (apparent)
    np.testing.assert_allclose(xyz[1:3] - xyz[0], ref_posts[1:] - ref_posts[0], atol=1e-3)


# --------------------------------------------------------------------------- the bundled example


def _dem_bilinear(path):
    """The DEM's surface as the contract defines it, read with rasterio and interpolated
    here: bilinear between cell centres in the DEM's CRS (EPSG:4326 for the example)."""
    with rasterio.open(path) as ds:
        assert ds.crs.to_epsg() == 4326
        arr = ds.read(1).astype(float)
        tr = ds.transform

    def h(lat, lon):
        cf = (np.asarray(lon, float) - tr.c) / tr.a - 0.5
        rf = (np.asarray(lat, float) - tr.f) / tr.e - 0.5
        c0, r0 = np.floor(cf).astype(int), np.floor(rf).astype(int)
        tc, tr_ = cf - c0, rf - r0
        top = arr[r0, c0] * (1 - tc) + arr[r0, c0 + 1] * tc
        bottom = arr[r0 + 1, c0] * (1 - tc) + arr[r0 + 1, c0 + 1] * tc
        return top * (1 - tr_) + bottom * tr_

    return h


def _grid_bilinear(x0, y0, dx, heights, x, y):
    """Bilinear interpolation between the nodes of a regular grid (written here)."""
    fx, fy = (np.asarray(x, float) - x0) / dx, (np.asarray(y, float) - y0) / dx
    j, i = np.floor(fx).astype(int), np.floor(fy).astype(int)
    tx, ty = fx - j, fy - i
    below = heights[i, j] * (1 - tx) + heights[i, j + 1] * tx
    above = heights[i + 1, j] * (1 - tx) + heights[i + 1, j + 1] * tx
    return below * (1 - ty) + above * ty


def test_the_bundled_range_geo_example():
    """`range_geo` (a real-looking DEM, k = 0.13): every terrain node is the exact ENU height
    of the DEM surface below it plus k d^2 / (2 R) (< 1 mm). The laser (3 m over the ground
    at the survey mark), the target centre (2 m) and the eye-height posts and road ends
    (1.7 m) stand on the terrain: x, y where the chain puts the DEM's surface at their
    latitude and longitude (< 1 mm), z the terrain grid there (bilinear between the exact
    node heights computed here) plus their height (< 1 mm). The grid is 20 m: between nodes
    it departs from the DEM's own surface by up to ~1.3 cm at the road's west end (< 5 cm
    checked), the interpolation the contract states."""
    path = scenes.example_path("range_geo")
    dem = _dem_bilinear(path.parent / "range_geo_dem.tif")
    scene = scenes.load(path)
    o, k = (32.60, -106.30, 1200.0), 0.13
    t, off = scene.terrain, scene.offset_m
    ny, nx = t.heights.shape
    x0, y0 = t.x0 + off[0], t.y0 + off[1]
    xs, ys = np.meshgrid(x0 + t.dx * np.arange(nx), y0 + t.dx * np.arange(ny))
    exact = surface_below(xs, ys, o, dem) + refraction_rise(xs, ys, o, k)
    np.testing.assert_allclose(t.heights + off[2], exact, atol=1e-3)

    def standing(lat, lon, above):
        p = enu(lat, lon, dem(lat, lon), o)
        z_dem = p[2] + refraction_rise(p[0], p[1], o, k)
        z_grid = _grid_bilinear(x0, y0, t.dx, exact, p[0], p[1])
        assert abs(z_grid - z_dem) < 0.05
        return np.array([p[0], p[1], z_grid + above])

    got_laser, got_target, got_obs = world_points(scene)
    np.testing.assert_allclose(got_laser, standing(32.60, -106.30, 3.0), atol=1e-3)
    np.testing.assert_allclose(got_target, standing(32.6135, -106.2990, 2.0), atol=1e-3)
    np.testing.assert_allclose(got_obs[0], standing(32.6080, -106.2905, 1.7), atol=1e-3)
    np.testing.assert_allclose(got_obs[-2:], [standing(32.6240, -106.2990, 1.7), standing(32.6240, -106.3050, 1.7)], atol=1e-3)
    road = got_obs[1:26]  # the range road: 25 points from its west end to its east end
    np.testing.assert_allclose(road[[0, -1]], [standing(32.6050, -106.3150, 1.7), standing(32.6050, -106.2850, 1.7)], atol=1e-3)


@pytest.mark.slow
@ref.SLOW
@given(lat0=st.floats(-80.0, 80.0), lon0=st.floats(-180.0, 180.0), h0=st.floats(-100.0, 3000.0),
       legs=st.lists(st.tuples(st.floats(0.0, 360.0), st.floats(1.0, 30000.0), st.floats(-100.0, 3000.0)), min_size=3, max_size=8))
def test_random_sites_and_points_match_the_pyproj_chain_many(lat0, lon0, h0, legs):
    test_random_sites_and_points_match_the_pyproj_chain.hypothesis.inner_test(lat0, lon0, h0, legs)
