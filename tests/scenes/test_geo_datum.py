"""The EGM96 vertical datum (issue 14 item 1): orthometric heights H become ellipsoidal
heights h = H + N with the geoid undulation N of PROJ's grid ``us_nga_egm96_15.tif``.

The real grid is not installed here (the missing-grid error is tested in
tests/validation/test_geo_refs.py); a synthetic grid of constant N = 30 m under that name,
in a PROJ data folder of the test's own, proves the conversion is applied both ways, in a
fresh process (PROJ's data folders are process-wide).
"""

from __future__ import annotations

import subprocess
import sys
import textwrap

import pytest

pytest.importorskip("pyproj")
rasterio = pytest.importorskip("rasterio")

_CHILD = textwrap.dedent('''
    import sys, numpy as np, pyproj
    pyproj.datadir.append_data_dir(sys.argv[1])
    import scenes
    text = open(sys.argv[2]).read()
    scene = scenes.loads(text)
    frame = scene.site.frame
    # the target at orthometric 1250 m = ellipsoidal 1280 m: 80 m above the origin's 1200 m ellipsoidal height
    print(frame.h0_m, float(scene.offset_m[2]), float(frame.datum_height_m(np.array([32.6]), np.array([-106.3]), np.array([1300.0]))[0]))
''')

SCENE = """
name = "egm96"
[site]
origin = [32.6, -106.3, 1170.0]
vertical = "egm96"
[laser]
wavelength_nm = 1064.0
power_w = 10.0
beam_diameter_m = 0.01
divergence_rad = 0.001
position_m = [0.0, 0.0, 2.0]
aim_m = [0.0, 100.0, 80.0]
[exposure]
duration_s = 10.0
[[targets]]
name = "plate"
shape = "plate"
center_geo = [32.6, -106.3, 1250.0]
normal = [0.0, -1.0, 0.0]
tangent = [1.0, 0.0, 0.0]
size_m = [1.0, 1.0]
material = { model = "lambertian", reflectance = 0.5 }
"""


def test_orthometric_heights_take_the_geoid_grid(tmp_path):
    import numpy as np
    from rasterio.transform import from_origin

    grid = tmp_path / "proj"
    grid.mkdir()
    with rasterio.open(grid / "us_nga_egm96_15.tif", "w", driver="GTiff", width=361, height=181, count=1, dtype="float32",
                       crs="EPSG:4326", transform=from_origin(-180.5, 90.5, 1.0, 1.0)) as ds:
        ds.write(np.full((181, 361), 30.0, "float32"), 1)
    (tmp_path / "scene.toml").write_text(SCENE)
    out = subprocess.run([sys.executable, "-c", _CHILD, str(grid), str(tmp_path / "scene.toml")], capture_output=True, text=True)
    assert out.returncode == 0, out.stderr[-2000:]
    h0, target_z, back = map(float, out.stdout.split())
    assert h0 == pytest.approx(1200.0, abs=1e-6)  # 1170 m orthometric + N = 30 m
    assert target_z == pytest.approx(80.0, abs=1e-3)  # 1280 - 1200 (ENU z at the origin's vertical)
    assert back == pytest.approx(1270.0, abs=1e-6)  # ellipsoidal 1300 m -> orthometric 1270 m
