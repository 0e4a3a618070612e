"""A DEM in DTED (issue 14 item 2: "anything GDAL reads, DTED included").

A level-0 DTED tile (121 x 121 posts over 1 deg, 30 arc-second spacing) written by GDAL's
DTED driver, heights rising 10 m per post southward: H(lat) = 1000 + 1200 (33 - lat) m,
linear, so bilinear interpolation is exact. Eye-height observers over it come back in
observers.csv at H(lat) + 1.7 m (the reference written here), to 5 mm.
"""

from __future__ import annotations

import csv
import io

import numpy as np
import pytest

rasterio = pytest.importorskip("rasterio")
pytest.importorskip("pyproj")

from hazard.cli import main  # noqa: E402


def _dted(path):
    from rasterio.io import MemoryFile
    from rasterio.shutil import copy
    from rasterio.transform import from_origin

    n = 121
    h = (1000 + 10 * np.arange(n)[:, None] + 0 * np.arange(n)[None, :]).astype("int16")
    tr = from_origin(-107.0 - 0.5 / 120, 33.0 + 0.5 / 120, 1 / 120, 1 / 120)
    with MemoryFile() as mem:
        with mem.open(driver="GTiff", width=n, height=n, count=1, dtype="int16", crs="EPSG:4326", transform=tr) as ds:
            ds.write(h, 1)
        copy(mem.name, str(path), driver="DTED")
    with rasterio.open(path) as ds:
        assert ds.driver == "DTED"


def h_ref(lat):
    return 1000.0 + 1200.0 * (33.0 - lat)


# The plate (4 m x 4 m) holds the whole beam (0.56 m across at 555 m): with 1 m x 1 m, 2 % of
# it went on to the terrain 2.2 km away, a 570 m wide terrain spot whose near-field ground
# footprint over the 121 x 121 nodes cost 46 s of CPU; this test is about the DEM's reading.
SCENE = """
name = "dted"
[site]
origin = [32.5, -106.5, 1600.0]
refraction_k = 0.13
[laser]
wavelength_nm = 1064.0
power_w = 10.0
beam_diameter_m = 0.01
divergence_rad = 0.001
position_geo = [32.5, -106.5]
height_agl_m = 2.0
aim_geo = [32.505, -106.5]
aim_agl_m = 2.0
[exposure]
duration_s = 10.0
[[targets]]
name = "plate"
shape = "plate"
center_geo = [32.505, -106.5]
height_agl_m = 2.0
normal = [0.0, -1.0, 0.0]
tangent = [1.0, 0.0, 0.0]
size_m = [4.0, 4.0]
material = { model = "lambertian", reflectance = 0.5 }
[terrain]
kind = "dem"
file = "n32_w107.dt0"
extent_m = 3000.0
resolution_m = 50.0
[[observers]]
name = "eyes"
points_geo = [[32.5, -106.49], [32.52, -106.5], [32.48, -106.51]]
eye_height_m = 1.7
"""


def test_a_dted_tile_is_read_in_its_own_crs(tmp_path):
    _dted(tmp_path / "n32_w107.dt0")
    (tmp_path / "s.toml").write_text(SCENE)
    err = io.StringIO()
    assert main(["run", str(tmp_path / "s.toml"), "-o", str(tmp_path / "o"), "--quiet"], stdout=io.StringIO(), stderr=err) == 0, err.getvalue()
    assert "DTED" in err.getvalue() and "vertical = 'egm96'" in err.getvalue()  # read as ellipsoidal here: said, not refused
    with open(tmp_path / "o" / "observers.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    lat = np.array([float(r["lat_deg"]) for r in rows])
    h = np.array([float(r["height_m"]) for r in rows])
    np.testing.assert_allclose(lat, [32.5, 32.52, 32.48], atol=1e-7)
    np.testing.assert_allclose(h, h_ref(lat) + 1.7, atol=5e-3)
