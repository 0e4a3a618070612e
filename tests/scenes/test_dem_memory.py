"""A 1e7-cell DEM loads and builds its ray scene in bounded memory (issue 14 item 2).

Slow (writes a 1e7-cell GeoTIFF, two fresh processes): ``pytest -m slow``. Measured here
(tests/bench/bench_dem.py): peak resident memory 201 MB at 160 801 nodes, 353 MB at 641 601
and 735 MB at the 2e6-node limit, whatever the DEM's size: the window over the analysis
area is read in strips keeping every step-th cell, never the whole file at once.
"""

from __future__ import annotations

import pytest

pytest.importorskip("rasterio")
pytest.importorskip("pyproj")

from tests.bench import bench_dem  # noqa: E402


@pytest.mark.slow
def test_a_1e7_cell_dem_loads_in_memory_that_follows_the_grid(tmp_path):
    dem = bench_dem.write_dem(tmp_path / "dem.tif")
    coarse = bench_dem.run_case(dem, 4000.0, 20.0, tmp_path)
    fine = bench_dem.run_case(dem, 4000.0, 10.0, tmp_path)
    assert coarse["nodes"] == 401**2 and fine["nodes"] == 801**2
    assert coarse["triangles"] >= 2 * 400**2 and fine["triangles"] >= 2 * 800**2
    # memory follows the nodes: 4x the nodes costs well under 4x the memory, and stays far below the
    # ~1.6 GB that a full-resolution read of the DEM (1e7 nodes as float64 ENU points and mesh) would take
    assert coarse["peak_rss_mb"] < 400 and fine["peak_rss_mb"] < 700
