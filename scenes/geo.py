"""The site frame: exact local east-north-up (ENU) coordinates about a surveyed origin.

A scene with a ``[site]`` table is analysed in the ENU frame of its ``origin`` (WGS 84
latitude, longitude and height): ``x`` east, ``y`` north, ``z`` up along the ellipsoid
normal at the origin, in metres. The conversion is exact, not a flat-earth approximation:

    geodetic (lat, lon, h)  --pyproj EPSG:4979 -> EPSG:4978-->  ECEF  --R (p - p0)-->  ENU

with the rotation R of the standard topocentric frame (e.g. Hofmann-Wellenhof,
Lichtenegger and Wasle, *GNSS*, 2008, eq. 10.25 / PROJ's ``topocentric`` conversion).
The earth's curvature is therefore in the coordinates themselves: ground 10 km from the
origin lies about d^2 / (2 R) = 7.8 m below its z = 0 plane.

**Refraction.** A beam near the ground bends down, following the earth in part, with the
atmosphere's refraction coefficient k = R / rho (rho the ray's radius of curvature; the
standard atmosphere's k = 0.13: Bomford, *Geodesy*, 4th ed., 1980, section 3.16). Seen
from the beam, the ground at horizontal distance d falls by (1 - k) d^2 / (2 R), not
d^2 / (2 R): the surveyor's curvature-and-refraction correction, or the effective earth
radius R / (1 - k). Rays in the analysis are straight, so refraction enters as an apparent
rise of the terrain by ``k d^2 / (2 R)`` over its exact ENU height, with d from the laser
(the beam's origin) and R the Gaussian mean radius of curvature at the origin. The
horizon of an eye at height h then lies at sqrt(2 R h / (1 - k)) instead of sqrt(2 R h):
the beam reaches past the geometric horizon, the conservative side for observers beyond
it. Every position goes into this apparent frame: the terrain and what stands on it, and
the points given with an absolute height (laser, aim, target and occluder centres, observer
points), so a mast behind a ridge is seen as a refracted beam sees it. (A ridge that
backstops the beam rises as the rest does: the geometry between them is the refracted
one; ``refraction_k = 0`` checks a backstop without refraction.) Directions (normals, the
beam's ``direction``, grid vectors) are not turned by the rise's slope, k d / R (2e-4 rad
at 10 km). Positions in report.json are in the apparent frame; observers.csv's latitude,
longitude and height are of the true positions.

**Vertical datum.** ``vertical = "ellipsoid"`` takes heights above the WGS 84 ellipsoid;
``"egm96"`` takes orthometric heights above the EGM96 geoid and converts them with PROJ's
geoid grid ``us_nga_egm96_15.tif`` when it is installed; without it the conversion is an
error naming the grid (PROJ's fallback would silently ignore the geoid, tens of metres).
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field

import numpy as np

__all__ = ["SiteFrame", "GeoError", "EGM96_GRID", "WGS84_A_M", "WGS84_F"]

EGM96_GRID = "us_nga_egm96_15.tif"  # PROJ's name for the EGM96 15' geoid grid
WGS84_A_M = 6378137.0  # semi-major axis [m] (NIMA TR8350.2, 3rd ed., table 3.1)
WGS84_F = 1.0 / 298.257223563  # flattening (idem)
_VERTICAL_CRS = {"egm96": "EPSG:4326+5773"}  # horizontal WGS 84 + EGM96 height


class GeoError(ValueError):
    """A geodetic input that cannot be used; the message names the field and the fix."""


def _pyproj():
    try:
        import pyproj
    except ImportError:
        raise GeoError("a [site] needs pyproj: pip install 'laser-hazard[geo]'") from None
    return pyproj


def enu_rotation(lat_deg: float, lon_deg: float) -> np.ndarray:
    """Rotation (3, 3) from ECEF offsets to ENU at geodetic latitude/longitude [deg]."""
    p, l = math.radians(lat_deg), math.radians(lon_deg)
    sp, cp, sl, cl = math.sin(p), math.cos(p), math.sin(l), math.cos(l)
    return np.array([[-sl, cl, 0.0], [-sp * cl, -sp * sl, cp], [cp * cl, cp * sl, sp]])


def gaussian_radius_m(lat_deg: float) -> float:
    """Gaussian mean radius of curvature sqrt(M N) of the WGS 84 ellipsoid at ``lat_deg`` [m]."""
    e2 = WGS84_F * (2 - WGS84_F)
    s2 = math.sin(math.radians(lat_deg)) ** 2
    return WGS84_A_M * math.sqrt(1 - e2) / (1 - e2 * s2)


@functools.lru_cache(maxsize=8)
def _vertical_transformer(vertical: str, to_ellipsoid: bool):
    """pyproj transformer between the datum's heights and ellipsoidal heights, or a GeoError
    naming the missing grid (PROJ's ballpark fallback would drop the geoid); made once per
    datum and direction (a DEM's load asks for it at every iteration)."""
    import warnings

    from pyproj.transformer import TransformerGroup

    src, dst = _VERTICAL_CRS[vertical], "EPSG:4979"
    with warnings.catch_warnings():  # pyproj's "Best transformation is not available": the GeoError below says it in full
        warnings.filterwarnings("ignore", message="Best transformation is not available", category=UserWarning)
        group = TransformerGroup(src, dst, always_xy=True) if to_ellipsoid else TransformerGroup(dst, src, always_xy=True)
    if not group.best_available or not group.transformers:
        missing = sorted({g.short_name for op in group.unavailable_operations for g in op.grids if not g.available})
        import pyproj

        raise GeoError(
            f"site.vertical = {vertical!r}: PROJ's geoid grid {', '.join(missing) or EGM96_GRID} is not installed "
            f"(searched {pyproj.datadir.get_data_dir()}); get it with `projsync --file {EGM96_GRID}` or set "
            f"PROJ_NETWORK=ON, or give heights above the ellipsoid with vertical = 'ellipsoid'")
    return group.transformers[0]


@dataclass
class SiteFrame:
    """The exact ENU frame of a surveyed origin, with the refraction rise about the laser.

    Parameters
    ----------
    origin_deg_m : (lat_deg, lon_deg, height_m), height in the ``vertical`` datum.
    vertical : "ellipsoid" or "egm96".
    crs : how ``*_geo`` positions are read: a geographic CRS takes [lat_deg, lon_deg,
        height_m], a projected one [easting_m, northing_m, height_m] (e.g. "EPSG:32611").
    refraction_k : refraction coefficient (apparent terrain rise k d^2 / (2 R)).
    """

    origin_deg_m: tuple
    vertical: str = "ellipsoid"
    crs: str = "EPSG:4326"
    refraction_k: float = 0.13
    laser_xy_m: tuple = (0.0, 0.0)
    radius_m: float = field(init=False)
    h0_m: float = field(init=False)  # the origin's height above the ellipsoid [m]
    _p0: np.ndarray = field(init=False)
    _rot: np.ndarray = field(init=False)

    def __post_init__(self):
        pyproj = _pyproj()
        lat, lon, h = (float(v) for v in self.origin_deg_m)
        self.h0_m = float(self.ellipsoidal_height_m(np.array([lat]), np.array([lon]), np.array([h]))[0])
        self._to_ecef = pyproj.Transformer.from_crs("EPSG:4979", "EPSG:4978", always_xy=True)
        self._p0 = np.array(self._to_ecef.transform(lon, lat, self.h0_m))
        self._rot = enu_rotation(lat, lon)
        self.radius_m = gaussian_radius_m(lat)
        try:
            self._input_crs = pyproj.CRS.from_user_input(self.crs)
        except pyproj.exceptions.CRSError as exc:
            raise GeoError(f"site.crs = {self.crs!r}: not a coordinate reference system PROJ knows ({exc})") from None
        if self._input_crs.is_geocentric:
            raise GeoError(f"site.crs = {self.crs!r}: expected a geographic or projected CRS, got a geocentric one")
        self._from_input = (None if self._input_crs.is_geographic
                            else pyproj.Transformer.from_crs(self._input_crs, "EPSG:4326", always_xy=True))

    # --- heights -------------------------------------------------------------------------
    def ellipsoidal_height_m(self, lat_deg, lon_deg, height_m) -> np.ndarray:
        """Heights above the ellipsoid [m] of heights given in the site's vertical datum."""
        if self.vertical == "ellipsoid":
            return np.asarray(height_m, float)
        t = _vertical_transformer(self.vertical, True)
        return np.asarray(t.transform(lon_deg, lat_deg, height_m)[2], float)

    def datum_height_m(self, lat_deg, lon_deg, h_ellipsoid_m) -> np.ndarray:
        """Heights in the site's vertical datum [m] of ellipsoidal heights."""
        if self.vertical == "ellipsoid":
            return np.asarray(h_ellipsoid_m, float)
        t = _vertical_transformer(self.vertical, False)
        return np.asarray(t.transform(lon_deg, lat_deg, h_ellipsoid_m)[2], float)

    # --- exact ENU -------------------------------------------------------------------------
    def enu_m(self, lat_deg, lon_deg, h_ellipsoid_m) -> np.ndarray:
        """Exact ENU (n, 3) [m] of geodetic points (ellipsoidal heights)."""
        x, y, z = self._to_ecef.transform(np.asarray(lon_deg, float), np.asarray(lat_deg, float), np.asarray(h_ellipsoid_m, float))
        d = np.stack([np.atleast_1d(x), np.atleast_1d(y), np.atleast_1d(z)], -1) - self._p0
        return d @ self._rot.T

    def geodetic(self, enu_m) -> tuple:
        """(lat_deg, lon_deg, h_ellipsoid_m) arrays of exact ENU points (n, 3) [m]."""
        ecef = np.atleast_2d(np.asarray(enu_m, float)) @ self._rot + self._p0
        lon, lat, h = self._to_ecef.transform(ecef[:, 0], ecef[:, 1], ecef[:, 2], direction="INVERSE")
        return np.atleast_1d(lat), np.atleast_1d(lon), np.atleast_1d(h)

    # --- refraction ------------------------------------------------------------------------
    def refraction_rise_m(self, x_m, y_m) -> np.ndarray:
        """Apparent rise of the terrain by refraction, k d^2 / (2 R) [m], at horizontal ENU
        positions (d from the laser)."""
        d2 = (np.asarray(x_m, float) - self.laser_xy_m[0]) ** 2 + (np.asarray(y_m, float) - self.laser_xy_m[1]) ** 2
        return self.refraction_k * d2 / (2.0 * self.radius_m)

    # --- input positions -------------------------------------------------------------------
    def input_to_geodetic(self, triples, where: str) -> tuple:
        """(lat_deg, lon_deg, height_m) of positions written in ``site.crs`` (n, 2 or 3)."""
        a = np.asarray(triples, float)
        if self._input_crs.is_geographic:
            lat, lon = a[:, 0], a[:, 1]
            bad = (np.abs(lat) > 90) | (np.abs(lon) > 540)
            if bad.any():
                k = int(np.argmax(bad))
                raise GeoError(f"{where}: {a[k].tolist()} is not [lat_deg, lon_deg, ...] (|lat| <= 90, |lon| <= 180)")
        else:
            lon, lat = self._from_input.transform(a[:, 0], a[:, 1], errcheck=False)
            lon, lat = np.asarray(lon, float), np.asarray(lat, float)
            if not (np.all(np.isfinite(lat)) and np.all(np.isfinite(lon))):
                raise GeoError(f"{where}: some [easting_m, northing_m] lie outside {self.crs}'s area")
        h = a[:, 2] if a.shape[1] == 3 else np.full(len(a), np.nan)
        return lat, lon, h

    def describe(self) -> dict:
        """What the report says of the frame."""
        lat, lon, h = self.origin_deg_m
        return {
            "kind": "site",
            "statement": (f"exact east-north-up frame of the WGS 84 point {abs(lat):.7f} {'N' if lat >= 0 else 'S'}, "
                          f"{abs(lon):.7f} {'E' if lon >= 0 else 'W'}, {h:.3f} m "
                          f"({'above the ellipsoid' if self.vertical == 'ellipsoid' else 'EGM96 orthometric'}); "
                          f"x east, y north, z up [m]. The terrain includes the earth's curvature and atmospheric "
                          f"refraction as an apparent rise k d^2 / (2 R) of the ground, k = {self.refraction_k:g}, "
                          f"R = {self.radius_m:.0f} m, d from the laser" + (" (switched off)" if self.refraction_k == 0 else
                          ": beams reach past the geometric horizon, as refracted beams do (conservative for observers "
                          "beyond it; a backstop ridge is raised as much: refraction_k = 0 checks it without)")),
            "origin_deg_m": [float(lat), float(lon), float(h)],
            "origin_ellipsoidal_height_m": self.h0_m,
            "vertical": self.vertical,
            "crs": self.crs,
            "refraction_k": self.refraction_k,
            "earth_radius_m": self.radius_m,
            "laser_xy_m": [float(v) for v in self.laser_xy_m],
        }
