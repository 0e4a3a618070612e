"""Benchmark: a whole run, scene file to keep-out (issue 12, item 6).

Run on demand:  python -m tests.bench.bench_whole_run   (or pytest tests/bench -m bench -s)

Scene (files in a temporary folder, as a user has them): the hazard-map benchmark's
plate (`bench_engine`: a 37-harmonic dynamic SH material over a 100-step history, a
~1e5-triangle terrain, 1e6 observers at eye height) with the default keep-out grid and
refinement. Timed: ``scenes.load(path)`` + ``hazard.analyze`` (every stage, the
extended-source pass included), the ray cache emptied before each run so that every run
builds its Embree scene. Floor, measured in the same run, each part on its own (best of
3): reading and parsing the scene file and the material file; the Embree build of the
same triangles; the observers' points (the grid formula and the terrain heights, made
once); the map's (1e6 x 37) @ (37 x 100) matrix product; the occlusion query of
the same 1e6 segments; and one BRDF evaluation of the keep-out lobes' 2x2 Gauss points on
the initial grid (static and dynamic). Reported: time, floor, ratio (no goal yet), and
where the time above the floor goes.
"""

from __future__ import annotations

import tempfile
import time
import tomllib
from pathlib import Path

import numpy as np

import brdfmodels as bm
import hazard
import scenes
from hazard import rays
from hazard.engine import projected_brdf, spot_directions
from hazard.keepout import _cell_points, _grid_cells
from hazard.rays import RayScene

from .bench_engine import SCENE, points_seconds


def _write_scene(folder: Path, rows=1000, n_states=100) -> Path:
    """The benchmark scene and its material file in ``folder``; returns the scene path."""
    rng = np.random.default_rng(0)
    basis = bm.SHBasis(8, 4, 2, 0)
    nodes = np.linspace(300.0, 1500.0, 13)
    coef = rng.normal(scale=0.15, size=(nodes.size, basis.size))
    coef[:, 0] = -11.0  # DC term: a physical material (hemispherical reflectance < 1 at every state)
    bm.save(bm.DynamicBRDF(basis, nodes, coef, "temperature_k"), folder / "material.json")
    text = SCENE.format(material="material.json", rows=rows, dt=10.0 / (n_states - 1))
    text = text.replace("direction_grid_deg = 10.0\nrefine_levels = 0\n", "")  # the defaults
    path = folder / "scene.toml"
    path.write_text(text)
    return path


def _best(fn, repeat=3):
    """Smallest wall time [s] of ``repeat`` calls of ``fn``, and its last result."""
    best, out = np.inf, None
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t0)
    return best, out


def _whole(path, repeat):
    """Best of ``repeat`` whole runs: time [s], its load time [s], the scene and the result."""
    best = (np.inf, 0.0, None, None)
    for _ in range(repeat):
        rays.clear_ray_cache()  # every run builds its ray scene, whether or not analyze caches it
        t0 = time.perf_counter()
        scene = scenes.load(path)
        t1 = time.perf_counter()
        res = hazard.analyze(scene)
        t2 = time.perf_counter()
        if t2 - t0 < best[0]:
            best = (t2 - t0, t1 - t0, scene, res)
    return best


def _floor_parts(path, scene, res) -> dict:
    """Each part of the floor [s], best of 3."""
    parts = {}
    parts["read"], _ = _best(lambda: (tomllib.loads(path.read_text()), bm.load(path.parent / "material.json")))
    parts["points"] = points_seconds(scene)  # the grid at eye height (made block by block inside the run)
    meshes = [(t.mesh.vertices, t.mesh.faces, t.index) for t in scene.targets]
    terrain = scene.terrain.mesh()
    meshes.append((terrain.vertices, terrain.faces, len(scene.targets)))
    parts["embree_build"], tracer = _best(lambda: RayScene(meshes))
    n_obs, n_t = len(scene.observers), len(res.times_s)
    k = scene.targets[0].material.basis.size
    rng = np.random.default_rng(0)
    y, c, out = rng.normal(size=(n_obs, k)), rng.normal(size=(k, n_t)), np.empty((n_obs, n_t))
    parts["gemm"], _ = _best(lambda: np.matmul(y, c, out=out))
    time.sleep(0.5)  # let BLAS threads stop spinning before the Embree query
    start = np.broadcast_to(res.spots[0].centroid + 1e-3 * res.spots[0].mean_frame[2], (n_obs, 3))
    parts["occlusion"], _ = _best(lambda: tracer.occluded(start, scene.observers.positions_m))
    sp = res.spots[0]
    wo = _cell_points(_grid_cells(scene.spec.analysis.direction_grid_deg)).reshape(-1, 3)
    wi = np.broadcast_to(spot_directions(sp), wo.shape)
    states = res.states[sp.target.index]
    parts["keepout_evaluation"], _ = _best(lambda: (projected_brdf(sp.material, wi, wo, states[:1], reduce="max"),
                                                    projected_brdf(sp.material, wi, wo, np.unique(states), reduce="max")))
    return parts


def run(rows=1000, n_states=100, verbose=True, repeat=3) -> dict:
    with tempfile.TemporaryDirectory() as tmp:
        path = _write_scene(Path(tmp), rows, n_states)
        t, t_load, scene, res = _whole(path, repeat)
        assert res.observers.peak_irradiance_w_m2.shape == (len(scene.observers),) and len(res.times_s) == n_states
        assert res.targets[0].dynamic_lobe.max_range_m > 0
        parts = _floor_parts(path, scene, res)
        n_tri = len(scene.terrain.mesh().faces)
    floor = sum(parts.values())
    stages = {s.name: s.seconds for s in res.stages if s.seconds > 0}  # a skipped stage may still take time
    stages["untimed"] = t - t_load - sum(stages.values())  # between and outside the stages
    if verbose:
        split = ", ".join(f"{k} {v:.2f}" for k, v in parts.items())
        where = ", ".join(f"{k} {v:.2f}" for k, v in stages.items() if v >= 0.01)
        print(f"whole run (load + analyze), {len(scene.observers):.0e} observers x {n_states} states, "
              f"{n_tri} terrain triangles: {t:.2f} s (load {t_load:.2f} s; {where}); "
              f"floor {floor:.2f} s ({split}); ratio {t / floor:.2f}")
    return {"time_s": t, "floor_s": floor, "ratio": t / floor, "load_s": t_load, "stages": stages, "floor_parts": parts}


if __name__ == "__main__":
    run()
