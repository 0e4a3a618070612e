"""Benchmark: what the ray-scene cache saves a study on a large terrain (issue 12, item 6).

Run on demand:  python -m tests.bench.bench_ray_cache   (or pytest tests/bench -m bench -s)

Scene: the bundled `range_terrain` with its ground at 1.7 m resolution (about 1e6
triangles). Timed, best of 3: the triangles of the scene (targets, bunker, terrain mesh:
paid by every scenario either way), the Embree build (:class:`hazard.physics.rays.RayScene`: a
miss) and :func:`hazard.physics.rays.cached_ray_scene` on a hit (the content hash and the lookup).
The saving per scenario that shares the geometry is the build minus the hit.
"""

from __future__ import annotations

import copy


import scenes
from brdfmodels.fileio import read_toml
from hazard.physics import rays
from hazard.pipeline.spots import ray_meshes as _meshes  # the meshes in the order analyze uses
from hazard.physics.rays import RayScene, cached_ray_scene

from .bench_whole_run import _best


def run(resolution_m=1.7, verbose=True, repeat=3) -> dict:
    path = scenes.example_path("range_terrain")
    data = copy.deepcopy(read_toml(path))
    data["terrain"]["resolution_m"] = resolution_m
    scene = scenes.from_data(data, source="range_terrain (fine ground)", base_dir=path.parent)
    t_mesh, meshes = _best(lambda: _meshes(scene), repeat)
    t_build, built = _best(lambda: RayScene(meshes), repeat)
    rays.clear_ray_cache()
    cached_ray_scene(meshes)  # the miss
    t_hit, hit = _best(lambda: cached_ray_scene(meshes), repeat)
    assert hit is cached_ray_scene(meshes) and hit.n_triangles == built.n_triangles
    rays.clear_ray_cache()
    out = {"triangles": built.n_triangles, "meshes_s": t_mesh, "build_s": t_build, "hit_s": t_hit,
           "saved_s": t_build - t_hit, "nbytes": built.nbytes}
    if verbose:
        print(f"ray scene of {built.n_triangles} triangles ({built.nbytes / 1e6:.0f} MB): Embree build {t_build:.2f} s, "
              f"cache hit {t_hit:.3f} s (hash + lookup), saved {out['saved_s']:.2f} s per scenario; "
              f"the triangles themselves {t_mesh:.2f} s (paid either way)")
    return out


if __name__ == "__main__":
    run()
