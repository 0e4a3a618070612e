"""A DEM is data read from a local file, never a recipe for reading others (issue 30 item 1).

A GDAL VRT can point at ``/vsicurl/http://...`` (so even ``hazard validate`` sent HTTP
requests: SSRF) or put any file's bytes (``/etc/passwd``) in a raw band, which came back as
terrain heights in observers.csv. Now a DEM opens only through the GTiff or DTED driver its
first bytes show, from a plain local path, with GDAL's network, raw VRT bands and sidecars
switched off while it is open. Each refusal is one line, exit 2, naming terrain.file.
Nonsense rasters (complex heights, rotated or singular geotransforms, 100-degree cells) are
refused the same way.
"""

from __future__ import annotations

import io
import socket
import warnings

import numpy as np
import pytest

rasterio = pytest.importorskip("rasterio")
pytest.importorskip("pyproj")

from hazard.cli import main  # noqa: E402

N = 200
GT = (-106.51, 1e-4, 0.0, 32.51, 0.0, -1e-4)  # GDAL order: x0, dx, rot, y0, rot, dy

SCENE = """
name = "dem"
[site]
origin = [32.5, -106.5, 1600.0]
[laser]
wavelength_nm = 1064.0
power_w = 10.0
beam_diameter_m = 0.01
divergence_rad = 0.001
position_geo = [32.5, -106.5]
height_agl_m = 2.0
aim_geo = [32.5005, -106.5]
aim_agl_m = 2.0
[exposure]
duration_s = 10.0
[[targets]]
name = "plate"
shape = "plate"
center_geo = [32.5005, -106.5]
height_agl_m = 2.0
normal = [0.0, -1.0, 0.0]
tangent = [1.0, 0.0, 0.0]
size_m = [1.0, 1.0]
material = { model = "lambertian", reflectance = 0.5 }
[terrain]
kind = "dem"
file = "FILE"
extent_m = 300.0
resolution_m = 20.0
[[observers]]
name = "eyes"
points_geo = [[32.5, -106.499], [32.501, -106.5]]
eye_height_m = 1.7
"""


def _cli(*argv):
    """(exit code, stdout, stderr); a raw NumPy / Python warning on the way fails the test."""
    out, err = io.StringIO(), io.StringIO()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        code = main([str(a) for a in argv], stdout=out, stderr=err)
    raw = [str(w.message) for w in caught if issubclass(w.category, (RuntimeWarning, UserWarning))]
    assert not raw, raw
    return code, out.getvalue(), err.getvalue()


def _scene(tmp_path, file_name):
    p = tmp_path / "s.toml"
    p.write_text(SCENE.replace("FILE", str(file_name)))
    return p


def _refused(tmp_path, file_name, *words):
    """validate and run both refuse the scene: exit 2, one line naming terrain.file and ``words``."""
    scene = _scene(tmp_path, file_name)
    for argv in (("validate", scene), ("run", scene, "-o", tmp_path / "out", "--quiet")):
        code, out, err = _cli(*argv)
        lines = err.strip().splitlines()
        assert code == 2 and len(lines) == 1, (code, err)
        assert "terrain.file" in lines[0] and "Traceback" not in err and "Warning" not in err, lines[0]
        for w in words:
            assert w in lines[0], lines[0]
    assert not (tmp_path / "out" / "observers.csv").exists()


def _vrt_over_url(port):
    return (f'<VRTDataset rasterXSize="{N}" rasterYSize="{N}"><SRS>EPSG:4326</SRS>'
            f'<GeoTransform>{", ".join(map(str, GT))}</GeoTransform><VRTRasterBand dataType="Float32" band="1">'
            f'<SimpleSource><SourceFilename relativeToVRT="0">/vsicurl/http://127.0.0.1:{port}/x.tif</SourceFilename>'
            f'<SourceBand>1</SourceBand></SimpleSource></VRTRasterBand></VRTDataset>')


def _vrt_raw(target):
    return (f'<VRTDataset rasterXSize="{N}" rasterYSize="{N}"><SRS>EPSG:4326</SRS>'
            f'<GeoTransform>{", ".join(map(str, GT))}</GeoTransform>'
            f'<VRTRasterBand dataType="Byte" band="1" subClass="VRTRawRasterBand">'
            f'<SourceFilename relativeToVRT="0">{target}</SourceFilename><ImageOffset>0</ImageOffset>'
            f'<PixelOffset>1</PixelOffset><LineOffset>1</LineOffset></VRTRasterBand></VRTDataset>')


@pytest.fixture
def listener():
    """A local TCP port that records whether anything connected to it."""
    srv = socket.socket()
    srv.bind(("127.0.0.1", 0))
    srv.listen(8)
    srv.setblocking(False)

    def connected():
        try:
            srv.accept()[0].close()
            return True
        except BlockingIOError:
            return False

    yield srv.getsockname()[1], connected
    srv.close()


def _tif(path, h, transform=None, dtype="float32", crs="EPSG:4326"):
    from rasterio.transform import Affine

    tr = transform or Affine.from_gdal(*GT)
    with rasterio.open(path, "w", driver="GTiff", width=h.shape[1], height=h.shape[0], count=1, dtype=dtype, crs=crs,
                       transform=tr) as ds:
        ds.write(h.astype(dtype), 1)


def test_a_plain_geotiff_is_read(tmp_path):
    _tif(tmp_path / "dem.tif", np.full((N, N), 1600.0))
    code, out, err = _cli("validate", _scene(tmp_path, "dem.tif"))
    assert code == 0 and err == "", err


@pytest.mark.parametrize("name", ["dem.vrt", "dem.tif"])
def test_a_vrt_pointing_at_a_url_is_refused_without_a_request(name, tmp_path, listener):
    port, connected = listener
    (tmp_path / name).write_text(_vrt_over_url(port))
    _refused(tmp_path, name, "not a GeoTIFF or DTED file", "VRT")
    assert not connected()


def test_the_fixed_ssrf_address_is_refused(tmp_path):
    (tmp_path / "dem.vrt").write_text(_vrt_over_url(9))
    _refused(tmp_path, "dem.vrt", "VRT")


def test_a_vrt_raw_band_over_another_file_is_refused(tmp_path):
    secret = tmp_path / "secret.txt"
    secret.write_bytes(b"hunter2-" * 5000)
    (tmp_path / "dem.vrt").write_text(_vrt_raw(secret))
    _refused(tmp_path, "dem.vrt", "refused")
    code, out, err = _cli("validate", _scene(tmp_path, "dem.vrt"))
    assert "hunter2" not in out + err


@pytest.mark.parametrize("file_name", ["/vsicurl/http://127.0.0.1:9/x.tif", "http://127.0.0.1:9/x.tif",
                                       "zip:///tmp/a.zip!/x.tif", "GTIFF_DIR:1:dem.tif", "/vsimem/x.tif"])
def test_urls_virtual_paths_and_subdatasets_are_refused(file_name, tmp_path):
    _refused(tmp_path, file_name, "local", "refused")


def test_another_gdal_format_is_refused(tmp_path):
    with rasterio.open(tmp_path / "dem.img", "w", driver="HFA", width=N, height=N, count=1, dtype="float32",
                       crs="EPSG:4326", transform=rasterio.transform.Affine.from_gdal(*GT)) as ds:
        ds.write(np.full((N, N), 1600.0, "float32"), 1)
    _refused(tmp_path, "dem.img", "not a GeoTIFF or DTED file")


def test_gdal_is_closed_while_a_dem_is_open(tmp_path, listener):
    """The second line of defence: under GDAL_CLOSED even GDAL's own VRT driver, opened
    directly, makes no request."""
    from scenes.dem import GDAL_CLOSED

    port, connected = listener
    (tmp_path / "net.vrt").write_text(_vrt_over_url(port))
    with rasterio.Env(**GDAL_CLOSED):
        with pytest.raises(rasterio.errors.RasterioError):
            with rasterio.open(tmp_path / "net.vrt") as ds:
                ds.read(1)
    assert not connected()


@pytest.mark.skipif(tuple(map(int, rasterio.__gdal_version__.split(".")[:2])) < (3, 12),
                    reason="GDAL < 3.12 ignores GDAL_VRT_ENABLE_RAWRASTERBAND (the driver check above is the defence)")
def test_gdal_reads_no_raw_band_while_a_dem_is_open(tmp_path):
    from scenes.dem import GDAL_CLOSED

    (tmp_path / "secret.txt").write_bytes(b"hunter2-" * 5000)
    (tmp_path / "raw.vrt").write_text(_vrt_raw(tmp_path / "secret.txt"))
    with rasterio.Env(**GDAL_CLOSED):
        with pytest.raises(rasterio.errors.RasterioError):
            with rasterio.open(tmp_path / "raw.vrt") as ds:
                ds.read(1)


@pytest.mark.parametrize("case, words", [
    ("complex", ["complex64", "real heights"]),
    ("rotated", ["rotated or sheared", "north-up"]),
    ("singular", ["not invertible"]),
    ("100-degree cells", ["100 deg", "at most 1 deg"]),
    ("100-degree cells, projected", ["cells of 1e+07 m", "at most 100000 m"]),
])
def test_nonsense_rasters_are_refused(case, words, tmp_path):
    from rasterio.transform import Affine

    h = np.full((N, N), 1600.0)
    kw = {"complex": dict(dtype="complex64"),
          "rotated": dict(transform=Affine(1e-4, 1e-5, GT[0], 1e-5, -1e-4, GT[3])),
          "singular": dict(transform=Affine(1e-4, 1e-4, GT[0], 1e-4, 1e-4, GT[3])),
          "100-degree cells": dict(transform=Affine(100.0, 0.0, -180.0, 0.0, -100.0, 90.0)),
          "100-degree cells, projected": dict(transform=Affine(1e7, 0.0, 0.0, 0.0, -1e7, 0.0), crs="EPSG:32613")}[case]
    _tif(tmp_path / "dem.tif", h + (5j if case == "complex" else 0), **kw)
    _refused(tmp_path, "dem.tif", *words)


def test_a_truncated_geotiff_is_an_input_error(tmp_path):
    """Its header reads, its cells do not: was RasterioIOError, exit 1."""
    _tif(tmp_path / "full.tif", np.full((N, N), 1600.0))
    data = (tmp_path / "full.tif").read_bytes()
    (tmp_path / "dem.tif").write_bytes(data[: len(data) // 2])
    _refused(tmp_path, "dem.tif", "cannot read the DEM's cells", "truncated")
