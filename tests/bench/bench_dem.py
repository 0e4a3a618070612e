"""Benchmark: a DEM of 1e7 cells loads and builds its ray scene in bounded memory (issue 14).

Run on demand:  python -m tests.bench.bench_dem   (the slow test tests/scenes/test_dem_memory.py runs it too)

A 3200 x 3200 GeoTIFF (1.02e7 float32 cells, 3 m cells in UTM zone 32N, tiled) is written
once; a scene with a [site] at its centre reads it at ``resolution_m`` over +-``extent_m``.
Each case runs in a fresh process and reports its wall time and its own peak resident
memory (VmHWM; ``ru_maxrss`` would include the parent's, see ``PEAK_RSS``): the reading
is windowed and decimated by GDAL, so memory follows the analysis grid (nodes), not the
DEM's size (the whole DEM as float64 would be 82 MB, its ENU nodes at full resolution
245 MB, their Embree mesh far more).
"""

from __future__ import annotations

import json
import subprocess
import sys
import tempfile
import textwrap
from pathlib import Path

CELLS = 3200  # per side: 1.02e7 cells
PIXEL_M = 3.0
CENTRE_EN = (500_000.0, 5_200_000.0)  # UTM 32N: about 46.95 N, 9.0 E


def write_dem(path: Path) -> Path:
    """A smooth synthetic DEM (heights 400-700 m), tiled and deflated, in EPSG:32632."""
    import numpy as np
    import rasterio
    from rasterio.transform import from_origin

    half = CELLS * PIXEL_M / 2
    transform = from_origin(CENTRE_EN[0] - half, CENTRE_EN[1] + half, PIXEL_M, PIXEL_M)
    with rasterio.open(path, "w", driver="GTiff", width=CELLS, height=CELLS, count=1, dtype="float32", crs="EPSG:32632",
                       transform=transform, tiled=True, blockxsize=256, blockysize=256, compress="deflate") as ds:
        for r0 in range(0, CELLS, 256):  # written in strips: the writer itself stays small
            rows = np.arange(r0, min(r0 + 256, CELLS))[:, None]
            cols = np.arange(CELLS)[None, :]
            h = 550 + 150 * np.sin(rows / 400.0) * np.cos(cols / 300.0)
            ds.write(h.astype("float32"), 1, window=rasterio.windows.Window(0, r0, CELLS, len(rows)))
    return path


# The child's own peak resident memory [MB]. Not getrusage(RUSAGE_SELF).ru_maxrss: on Linux,
# exec() folds the pre-exec image's high-water mark (the forked copy of the parent: a pytest
# session's 1.5 GB) into the child's ru_maxrss; VmHWM is the high-water mark of the child's
# own address space, made fresh at exec.
PEAK_RSS = textwrap.dedent('''
    import resource
    def own_peak_rss_mb():
        try:
            with open("/proc/self/status") as f:
                return next(int(line.split()[1]) for line in f if line.startswith("VmHWM:")) / 1024
        except (OSError, StopIteration):  # not Linux: ru_maxrss (bytes on macOS, KiB elsewhere)
            import sys
            r = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
            return r / 2**20 if sys.platform == "darwin" else r / 1024
    def inherited_maxrss_mb():
        return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
''')

_CHILD = PEAK_RSS + textwrap.dedent('''
    import json, sys, time
    import scenes
    from hazard.pipeline.spots import ray_scene
    t0 = time.perf_counter()
    scene = scenes.load(sys.argv[1])
    t1 = time.perf_counter()
    rs = ray_scene(scene, "embree", 2)
    t2 = time.perf_counter()
    print(json.dumps({"load_s": t1 - t0, "ray_scene_s": t2 - t1, "triangles": int(rs.n_triangles),
                      "nodes": int(scene.terrain.heights.size),
                      "peak_rss_mb": own_peak_rss_mb(), "ru_maxrss_mb": inherited_maxrss_mb()}))
''')


def scene_text(dem: Path, extent_m: float, resolution_m: float) -> str:
    return textwrap.dedent(f'''
        name = "dem-memory"
        [site]
        origin = [46.9521, 9.0, 550.0]
        crs = "EPSG:32632"
        [laser]
        wavelength_nm = 1064.0
        power_w = 1000.0
        beam_diameter_m = 0.05
        divergence_rad = 0.001
        position_geo = [{CENTRE_EN[0]}, {CENTRE_EN[1]}]
        height_agl_m = 2.0
        aim_geo = [{CENTRE_EN[0]}, {CENTRE_EN[1] + 500.0}]
        aim_agl_m = 2.0
        [exposure]
        duration_s = 10.0
        [[targets]]
        name = "plate"
        shape = "plate"
        center_geo = [{CENTRE_EN[0]}, {CENTRE_EN[1] + 500.0}]
        height_agl_m = 2.0
        normal = [0.0, -1.0, 0.0]
        tangent = [1.0, 0.0, 0.0]
        size_m = [1.0, 1.0]
        material = {{ model = "lambertian", reflectance = 0.5 }}
        [terrain]
        kind = "dem"
        file = "{dem}"
        center_m = [0.0, 0.0, 0.0]
        extent_m = {extent_m}
        resolution_m = {resolution_m}
    ''')


def run_case(dem: Path, extent_m: float, resolution_m: float, folder: Path) -> dict:
    path = folder / f"dem_{extent_m:g}_{resolution_m:g}.toml"
    path.write_text(scene_text(dem, extent_m, resolution_m))
    out = subprocess.run([sys.executable, "-c", _CHILD, str(path)], capture_output=True, text=True)
    if out.returncode:
        raise RuntimeError(f"case extent {extent_m:g} m, resolution {resolution_m:g} m failed: {out.stderr[-2000:]}")
    return {"extent_m": extent_m, "resolution_m": resolution_m, **json.loads(out.stdout.strip().splitlines()[-1])}


CASES = ((4000.0, 20.0), (4000.0, 10.0), (3500.0, 5.0), (2000.0, 3.0))  # the last two: about the 2e6-node limit


def run(cases=CASES, verbose=True) -> list:
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        dem = write_dem(folder / "dem.tif")
        rows = [run_case(dem, e, r, folder) for e, r in cases]
    if verbose:
        print(f"DEM {CELLS} x {CELLS} = {CELLS * CELLS:.3g} cells at {PIXEL_M:g} m")
        print(f"{'extent_m':>9} {'res_m':>6} {'nodes':>9} {'triangles':>10} {'load_s':>7} {'rays_s':>7} {'peak_MB':>8}")
        for r in rows:
            print(f"{r['extent_m']:9.0f} {r['resolution_m']:6.1f} {r['nodes']:9d} {r['triangles']:10d} {r['load_s']:7.2f} "
                  f"{r['ray_scene_s']:7.2f} {r['peak_rss_mb']:8.0f}")
    return rows


if __name__ == "__main__":
    run()
