"""Write the bundled example DEM ``scenes/examples/range_geo_dem.tif``.

A synthetic but range-like terrain, in the format of a real one: a GeoTIFF in WGS 84
geographic coordinates (EPSG:4326) at 1 arc-second (about 31 m x 26 m here, SRTM's
spacing), heights above the WGS 84 ellipsoid [m], float32, deflate-compressed, nodata
-32768. The site is an invented desert range at 32.60 N, 106.30 W: a basin floor at about
1200 m sloping gently to the east, a ridge 2.5 km north of the firing point running east-
west (the natural backstop behind the targets, about 90 m high), a small hill to the
west and a few random ondulations (fixed seed). Not a survey of any real place.

Run: ``python examples/make_range_geo_dem.py [OUT.tif]``.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from brdfmodels.fileio import atomic_write

LAT0, LON0 = 32.60, -106.30  # the firing point
ARCSEC = 1.0 / 3600.0
HALF_CELLS = 160  # 2 x 160 + 1 cells each way: +-160 arc-seconds, about 4.9 km north-south, 4.2 km east-west


def heights_m(lat: np.ndarray, lon: np.ndarray) -> np.ndarray:
    """Ellipsoidal heights [m] of the invented terrain at geodetic positions [deg]."""
    north_m = (lat - LAT0) * 110_900.0
    east_m = (lon - LON0) * 93_800.0
    h = 1200.0 + 0.004 * east_m  # the basin floor, tilting up 4 m/km to the east
    h += 90.0 / (1.0 + np.exp(-(north_m - 2500.0) / 120.0))  # the ridge (a 90 m step over ~0.5 km)
    h += 35.0 * np.exp(-((east_m + 1800.0) ** 2 + (north_m - 600.0) ** 2) / (2 * 350.0**2))  # the west hill
    rng = np.random.default_rng(20261124)
    for _ in range(12):  # gentle ondulations, 1-4 m
        e0, n0 = rng.uniform(-4000, 4000, 2)
        h += rng.uniform(1.0, 4.0) * np.exp(-((east_m - e0) ** 2 + (north_m - n0) ** 2) / (2 * rng.uniform(200, 600) ** 2))
    return h


def write(out: Path) -> Path:
    """Write the DEM GeoTIFF to ``out`` (cell centres on whole arc-seconds)."""
    import rasterio
    from rasterio.transform import from_origin

    n = 2 * HALF_CELLS + 1
    lats = LAT0 + ARCSEC * (HALF_CELLS - np.arange(n))  # rows from north to south
    lons = LON0 + ARCSEC * (np.arange(n) - HALF_CELLS)
    lon, lat = np.meshgrid(lons, lats)
    h = heights_m(lat, lon).astype("float32")
    transform = from_origin(lons[0] - ARCSEC / 2, lats[0] + ARCSEC / 2, ARCSEC, ARCSEC)
    out.parent.mkdir(parents=True, exist_ok=True)

    def write_tif(tmp):
        with rasterio.open(tmp, "w", driver="GTiff", width=n, height=n, count=1, dtype="float32", crs="EPSG:4326",
                           transform=transform, nodata=-32768.0, compress="deflate", predictor=3, tiled=True,
                           blockxsize=128, blockysize=128) as ds:
            ds.write(h, 1)
            ds.update_tags(description="invented desert range for laser-hazard's range_geo example; heights above WGS 84 [m]",
                           source="examples/make_range_geo_dem.py")

    atomic_write(out, write_tif)
    return out


if __name__ == "__main__":
    default = Path(__file__).resolve().parents[1] / "scenes" / "examples" / "range_geo_dem.tif"
    path = write(Path(sys.argv[1]) if len(sys.argv) > 1 else default)
    print(f"wrote {path} ({path.stat().st_size / 1024:.0f} KB)")
