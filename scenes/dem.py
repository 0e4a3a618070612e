"""DEM terrain: a raster of ground heights (a local GeoTIFF or DTED file, nothing else) placed in
the site's exact ENU frame.

The analysis grid is regular in the local frame: nodes every ``resolution_m`` over
``[cx - extent_m, cx + extent_m]`` (and the same in y). For each node the DEM surface point
straight below it is found exactly: its geodetic latitude and longitude (pyproj), the
DEM's height there (bilinear between the raster's cell centres, in the DEM's own CRS),
converted to the ellipsoid and back to ENU. The horizontal position of a point depends
slightly on its height (1.6 m per km of height at 10 km), so the node's geodetic position
is iterated until the point lies on the node's vertical to 1 mm. The earth's curvature is
thus in the geometry; the refraction rise (:mod:`scenes.geo`) is then added.

Memory is bounded by the analysis grid, not the DEM: only the window over the analysis
area is read (GDAL reads just those blocks), in strips of rows, keeping every step-th cell
(no coarser than half the grid's resolution).
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass

import numpy as np

from .geo import GeoError, SiteFrame
from .geometry import Heightfield, input_path

__all__ = ["DemInfo", "dem_heightfield", "dem_path", "GDAL_CLOSED", "DEM_DRIVERS"]

_TOL_M = 1e-3  # the node's point lies on its vertical to this [m]


@dataclass(frozen=True)
class DemInfo:
    """What the report says of a DEM terrain."""

    file: str
    crs: str
    pixel_m: float  # the DEM's native cell size (along its rows) [m]
    read_pixel_m: float  # the cell size of the window as read [m]
    window_cells: int  # cells read
    dem_cells: int  # cells in the whole file
    filled_cells: int  # nodata cells filled (nodata = "fill")
    nodes: int  # analysis grid nodes
    iterations: int
    driver: str = ""  # GDAL's driver of the file (GTiff, DTED, ...)


def _grid(spec, frame: SiteFrame, centre_xy):
    n = int(math.ceil(spec.extent_m / spec.resolution_m))
    from brdfmodels.fileio import check_limit

    check_limit("TERRAIN_NODES", (2 * n + 1) ** 2, "terrain: nodes ((2 extent_m / resolution_m + 1)^2)")
    xs = centre_xy[0] + spec.resolution_m * np.arange(-n, n + 1)
    ys = centre_xy[1] + spec.resolution_m * np.arange(-n, n + 1)
    return xs, ys


# GDAL configuration while a DEM is open: a DEM is data read from a local file, never a
# recipe for fetching others. Only the GTiff and DTED drivers open it (a VRT, which can point
# at a URL or at any file's bytes, never does); on top of that nothing can reach the network
# (/vsicurl/ accepts no file name, no HTTP retries, no proxy), a VRT could not run Python nor
# (GDAL >= 3.12, which honours the option) read raw bands of other files, and no .aux.xml
# sidecar is read or written (GDAL_PAM_ENABLED).
GDAL_CLOSED = {
    "CPL_VSIL_CURL_ALLOWED_EXTENSIONS": ".hazard-no-network",  # /vsicurl/ refuses every name before any request
    "GDAL_HTTP_MAX_RETRY": "0",
    "GDAL_HTTP_TIMEOUT": "1",
    "GDAL_HTTP_CONNECTTIMEOUT": "1",
    "GDAL_HTTP_PROXY": "",
    "GDAL_HTTP_NETRC": "NO",
    "GDAL_VRT_ENABLE_RAWRASTERBAND": "NO",
    "GDAL_VRT_RAWRASTERBAND_ALLOWED_SOURCE": "ONLY_REMOTE",  # and remote is closed above
    "GDAL_VRT_ENABLE_PYTHON": "NO",
    "GDAL_PAM_ENABLED": "NO",
    "GDAL_DISABLE_READDIR_ON_OPEN": "EMPTY_DIR",  # no directory listing (local or remote) to find sidecars
    "CPL_VSIL_CURL_USE_HEAD": "NO",
    # a DTED column whose checksum does not match is a read error, not heights: GDAL's default
    # (NO) read a zeroed block of a column as 0 m terrain (a hole 1000 m deep in the file fuzz)
    "DTED_VERIFY_CHECKSUM": "YES",
}
DEM_DRIVERS = ("GTiff", "DTED")
_MAGIC = ((b"II*\0", "GTiff"), (b"MM\0*", "GTiff"), (b"II+\0", "GTiff"), (b"MM\0+", "GTiff"), (b"UHL1", "DTED"))
_PIXEL_DEG_MAX = 1.0  # a DEM's cell: at most 1 deg (coarse global DEMs: 5 arc-min) ...
_PIXEL_M_MAX = 1e5  # ... or 100 km in a projected CRS


def dem_path(file: str, base_dir=None):
    """The local regular file a scene's ``terrain.file`` names, and the GDAL driver its
    first bytes show (GTiff or DTED); GeoError for anything else: a URL, a GDAL virtual
    path (``/vsi...``), a subdataset name (``DRIVER:...``), a VRT or any other format."""
    from brdfmodels.fileio import check_input_file

    name = str(file)
    if "://" in name or name.startswith("/vsi") or re.match(r"^[A-Z][A-Z0-9_]+:", name):  # GDAL subdatasets: NETCDF:, GTIFF_DIR:
        raise GeoError(f"terrain.file={name!r}: expected the path of a local GeoTIFF or DTED file; URLs, GDAL virtual "
                       f"file systems (/vsi...) and subdataset names are refused (a DEM is read only as a local file)")
    path = input_path(name, base_dir).absolute()
    check_input_file(path, "terrain.file")
    try:
        with open(path, "rb") as fh:
            head = fh.read(4)
    except OSError as exc:
        raise GeoError(f"terrain.file={name!r}: cannot read the DEM ({exc.strerror})") from None
    driver = next((d for magic, d in _MAGIC if head == magic), None)
    if driver is None:
        raise GeoError(f"terrain.file={name!r}: not a GeoTIFF or DTED file (its first bytes are neither a TIFF nor a DTED "
                       f"header); other formats, VRT included, are refused: convert with gdal_translate -of GTiff")
    return path, driver


def _open(spec, base_dir):
    """The DEM opened by its own driver only (call inside ``rasterio.Env(**GDAL_CLOSED)``),
    its georeferencing and cells checked (:func:`_check_raster`)."""
    import rasterio

    path, driver = dem_path(spec.file, base_dir)
    try:
        ds = rasterio.open(path, driver=driver)
    except (OSError, ValueError, rasterio.errors.RasterioError):
        raise GeoError(f"terrain.file={spec.file!r}: cannot read the DEM as {driver} (a damaged or truncated file?)") from None
    try:
        _check_raster(ds, spec, driver)
    except BaseException:
        ds.close()
        raise
    return ds


def _check_raster(ds, spec, driver) -> None:
    """A DEM the grid can be read from: its own driver, one real-valued band, a CRS, a
    north-up invertible geotransform and cells of a plausible size."""
    where = f"terrain.file={spec.file!r}"
    if ds.driver != driver or ds.driver not in DEM_DRIVERS:
        raise GeoError(f"{where}: opened by GDAL's {ds.driver} driver; expected {driver} (only GeoTIFF and DTED are read)")
    if ds.count != 1 or ds.subdatasets:  # an RGB image or a stack is not a DEM: which band would be the heights?
        raise GeoError(f"{where}: expected one band of heights, got {ds.count} band(s) and {len(ds.subdatasets)} subdataset(s)")
    if np.dtype(ds.dtypes[0]).kind not in "iuf":
        raise GeoError(f"{where}: band 1 holds {ds.dtypes[0]} values; expected real heights (integers or floats), "
                       f"not complex numbers")
    if ds.crs is None:
        raise GeoError(f"{where}: the DEM has no CRS; expected a georeferenced raster (GeoTIFF, DTED)")
    t = ds.transform
    if not all(math.isfinite(x) for x in (t.a, t.b, t.c, t.d, t.e, t.f)) or t.a * t.e - t.b * t.d == 0:
        raise GeoError(f"{where}: its geotransform {tuple(t)[:6]} is not invertible; expected a north-up grid (pixel sizes != 0)")
    if t.b != 0 or t.d != 0:
        raise GeoError(f"{where}: its geotransform is rotated or sheared (terms {t.b:g}, {t.d:g}); expected a north-up grid: "
                       f"warp it first (gdalwarp -t_srs <its CRS> in.tif out.tif)")
    size = max(abs(t.a), abs(t.e))
    if ds.crs.is_geographic:
        lo, hi = sorted((ds.bounds.bottom, ds.bounds.top))
        if size > _PIXEL_DEG_MAX or lo < -90 or hi > 90:
            raise GeoError(f"{where}: cells of {size:g} deg covering latitudes {lo:g} to {hi:g}; expected cells of at most "
                           f"{_PIXEL_DEG_MAX:g} deg within -90 to 90 (is the geotransform in the CRS's units?)")
    elif size * ds.crs.linear_units_factor[1] > _PIXEL_M_MAX:
        raise GeoError(f"{where}: cells of {size * ds.crs.linear_units_factor[1]:g} m; expected at most {_PIXEL_M_MAX:g} m "
                       f"(is the geotransform in the CRS's units?)")


def _to_dem(ds, to_crs, lat, lon):
    """Geodetic positions -> fractional (row, col) of the raster's cell centres
    (``to_crs``: pyproj transformer from EPSG:4326 to the DEM's CRS, always_xy)."""
    x, y = to_crs.transform(lon, lat)
    inv = ~ds.transform
    x, y = np.asarray(x, float), np.asarray(y, float)
    col, row = inv.a * x + inv.b * y + inv.c, inv.d * x + inv.e * y + inv.f
    return row - 0.5, col - 0.5


def _pixel_m(ds) -> float:
    """The DEM's cell size in metres (degrees converted at the raster's centre latitude)."""
    a, e = ds.transform.a, ds.transform.e
    if ds.crs.is_geographic:
        lat = (ds.bounds.top + ds.bounds.bottom) / 2
        return min(abs(a) * 111_320.0 * math.cos(math.radians(lat)), abs(e) * 110_574.0)
    return min(abs(a), abs(e)) * ds.crs.linear_units_factor[1]


def _read_window(ds, spec, rows, cols):
    """The raster window over the analysis area (2 cells of margin), every ``step``-th cell
    in each direction (no coarser than half the grid's resolution), read in strips of rows
    so that memory follows the grid; returns (heights with NaN for nodata, row0, col0,
    (step, step)). Cells are taken as they are, not resampled: GDAL's decimating bilinear
    read was measured 4 mm off on a 3.6 % plane, the cells themselves are exact."""
    import rasterio
    from rasterio.windows import Window

    r0, r1 = int(math.floor(np.min(rows))) - 2, int(math.ceil(np.max(rows))) + 3
    c0, c1 = int(math.floor(np.min(cols))) - 2, int(math.ceil(np.max(cols))) + 3
    if r0 < -2 or c0 < -2 or r1 > ds.height + 2 or c1 > ds.width + 2:
        raise GeoError(f"terrain: the analysis area (extent_m = {spec.extent_m:g} m about center) reaches past the DEM "
                       f"{spec.file!r} (rows {r0 + 2}..{r1 - 3}, columns {c0 + 2}..{c1 - 3} of {ds.height} x {ds.width}); "
                       f"reduce extent_m or use a larger DEM")
    r0, c0, r1, c1 = max(r0, 0), max(c0, 0), min(r1, ds.height), min(c1, ds.width)
    step = max(1, int(spec.resolution_m / (2 * _pixel_m(ds))))
    r1, c1 = r0 + step * ((r1 - 1 - r0) // step + 1), c0 + step * ((c1 - 1 - c0) // step + 1)  # whole steps
    r1, c1 = min(r1, r0 + step * ((ds.height - 1 - r0) // step) + 1), min(c1, c0 + step * ((ds.width - 1 - c0) // step) + 1)
    strip = max(step, (1 << 22) // max(c1 - c0, 1) // step * step)  # ~4e6 cells per read
    parts = []
    with _DamageReport() as damage:
        for a in range(r0, r1, strip):
            w = Window(c0, a, c1 - c0, min(strip, r1 - a))
            try:
                block = ds.read(1, window=w, masked=True)[::step, ::step]
            except rasterio.errors.RasterioError:
                raise GeoError(f"terrain.file={spec.file!r}: cannot read the DEM's cells in rows {a}..{a + w.height - 1} "
                               f"(a damaged or truncated file? DTED columns are read only where their checksums match)") from None
            parts.append(np.ma.filled(block.astype(float), np.nan))
    if damage.seen:
        raise GeoError(f"terrain.file={spec.file!r}: GDAL found a damaged record in the cells over the analysis area (a "
                       f"DTED column whose header does not match its place); expected an intact DEM")
    return np.vstack(parts), r0, c0, (float(step), float(step))


class _DamageReport:
    """Within ``with``: whether GDAL logged a record that does not match its place (the DTED
    driver's "... count (n) of column c doesn't match expected value", which it reads on from,
    as heights). rasterio logs GDAL's warnings to the ``rasterio._err`` logger."""

    def __enter__(self):
        import logging

        outer = self

        class _Handler(logging.Handler):
            def emit(self, record):
                outer.seen = outer.seen or "doesn't match expected value" in record.getMessage()

        self.seen, self._handler = False, _Handler(logging.WARNING)
        self._logger = logging.getLogger("rasterio._err")
        self._logger.addHandler(self._handler)
        return self

    def __exit__(self, *exc):
        self._logger.removeHandler(self._handler)
        return False


def _fill(h, spec) -> int:
    """Nodata cells: an error, or filled by GDAL's interpolation; the count filled."""
    bad = ~np.isfinite(h)
    if not bad.any():
        return 0
    if spec.nodata == "error":
        raise GeoError(f"terrain.file={spec.file!r}: {int(bad.sum())} of {h.size} DEM cells over the analysis area have no "
                       f"data; set terrain.nodata = 'fill' to interpolate them (stated in the report), or use a complete DEM")
    from rasterio.fill import fillnodata

    filled = fillnodata(np.where(bad, 0.0, h).astype("float32"), mask=(~bad).astype("uint8"), max_search_distance=max(h.shape))
    if not np.all(np.isfinite(filled)) or bad.all():
        raise GeoError(f"terrain.file={spec.file!r}: no DEM data over the analysis area to fill from")
    h[bad] = filled[bad]
    return int(bad.sum())


def _sample(h, rows, cols) -> np.ndarray:
    """Bilinear heights at fractional (row, col) of the read window's cell centres."""
    from scipy.ndimage import map_coordinates

    return map_coordinates(h, [rows, cols], order=1, mode="nearest")


def _surface_enu(frame, xx, yy, sample_height):
    """ENU z of the DEM surface straight below the nodes (xx, yy): iterate the node's
    geodetic position until its surface point lies on the node's vertical."""
    z = np.zeros_like(xx)
    for it in range(1, 9):
        lat, lon, _ = frame.geodetic(np.stack([xx, yy, z], -1))
        h = frame.ellipsoidal_height_m(lat, lon, sample_height(lat, lon))
        p = frame.enu_m(lat, lon, h)
        off = np.hypot(p[:, 0] - xx, p[:, 1] - yy)
        dz, z = np.max(np.abs(p[:, 2] - z)), p[:, 2]
        if dz < _TOL_M and np.max(off) < _TOL_M:
            return z, it
    raise GeoError("terrain: the DEM surface did not converge onto the grid's verticals (a DEM with cliffs of "
                   "kilometres between cells?)")


def dem_heightfield(spec, frame: SiteFrame, base_dir=None, centre_xy=(0.0, 0.0)) -> tuple[Heightfield, DemInfo]:
    """The DEM terrain ``spec`` as a heightfield in the site's apparent ENU frame [m]."""
    xs, ys = _grid(spec, frame, centre_xy)
    xx, yy = (a.ravel() for a in np.meshgrid(xs, ys))
    import rasterio

    with rasterio.Env(**GDAL_CLOSED), _open(spec, base_dir) as ds:
        import pyproj

        to_crs = pyproj.Transformer.from_crs("EPSG:4326", ds.crs, always_xy=True)
        lat, lon, _ = frame.geodetic(np.stack([xx, yy, np.zeros_like(xx)], -1))
        rows, cols = _to_dem(ds, to_crs, lat, lon)
        h, r0, c0, step = _read_window(ds, spec, rows, cols)
        filled = _fill(h, spec)

        def at(lat_, lon_):
            r, c = _to_dem(ds, to_crs, lat_, lon_)
            return _sample(h, (r - r0) / step[0], (c - c0) / step[1])  # kept cell i: source cell r0 + i step

        z, iterations = _surface_enu(frame, xx, yy, at)
        info = DemInfo(str(spec.file), ds.crs.to_string(), _pixel_m(ds), _pixel_m(ds) * max(step), int(h.size),
                       int(ds.width * ds.height), filled, int(xx.size), iterations, ds.driver)
    if np.abs(z).max() > 1e5:
        raise GeoError(f"terrain.file={spec.file!r}: heights beyond 100 km; expected metres")
    z = z + frame.refraction_rise_m(xx, yy)
    return Heightfield(float(xs[0]), float(ys[0]), spec.resolution_m, z.reshape(len(ys), len(xs))), info
