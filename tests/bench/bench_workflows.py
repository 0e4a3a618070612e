"""Benchmarks of the workflows of issue 6 (run on demand):

    python -m tests.bench.bench_workflows

* study: 200 scenarios of the `plate` scene on an embedded LocalCluster (2 workers).
  Floor: 200 x the serial time of one scenario / 2 workers (perfect parallel speed-up),
  measured in the same run.
  The study is timed once (its time is already a sum over 200 scenarios); the lobe and
  the render, and their floors, are the median of 5.
* keep-out lobe at 0.25 deg (no refinement) of the glossy copper panel (`binoculars`).
  Floor: one BRDF evaluation call over the same number of directions, and the range from
  each intensity with attenuation (one vectorised Lambert W over as many values).
* render: `hazard.pictures.render.keepout` of `steel_vs_copper` (close view + overview + VTK).
  Floor: the same meshes made (the lobe surfaces) and two screenshots of them added as
  one MultiBlock, no styling, no legend, no log-distance copy.
"""

from __future__ import annotations

import statistics
import tempfile
import time
from pathlib import Path

import numpy as np

import hazard
import scenes
from hazard.drivers.study import MonteCarlo, Study, run_scenario, run_study, scenarios

from ._floor import median_s


def bench_study(n=200, workers=2):
    study = Study("bench", "plate", montecarlo=MonteCarlo(samples=n, brdf_scale_sigma=0.3), seed=0)
    import tomllib

    base = tomllib.loads(scenes.example_path("plate").read_text())
    sc = scenarios(study)
    t_one = []
    for s in sc[:10]:
        t0 = time.perf_counter()
        # one thread, as on the workers
        run_scenario(base, str(scenes.example_path("plate").parent), s, {"samples": n, "brdf_scale_sigma": 0.3, "normal_tilt_deg": 0.0}, 1)
        t_one.append(time.perf_counter() - t0)
    floor = statistics.median(t_one) * n / workers
    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.perf_counter()
        res = run_study(study, tmp, n_workers=workers)
        t = time.perf_counter() - t0
    assert res.failed == 0 and len(res.rows) == n
    return {"name": f"study, {n} scenarios, {workers} workers", "time_s": t, "floor_s": floor, "ratio": t / floor}


def bench_lobe(grid_deg=0.25):
    from hazard.physics.engine import projected_brdf, spot_directions
    from hazard.physics.keepout import hazard_lobe
    from hazard.physics.nohd import _lambertw0

    res = hazard.analyze(scenes.load(scenes.example_path("binoculars")))
    spot = res.spots[0]
    t, lobe = median_s(lambda: hazard_lobe(spot, res.mpe_w_m2, res.attenuation_per_m, grid_deg=grid_deg, refine_levels=0))
    rng = np.random.default_rng(0)
    wo = rng.normal(size=(lobe.evaluations, 3))
    wo[:, 2] = np.abs(wo[:, 2])
    wi = np.broadcast_to(spot_directions(spot), wo.shape)
    mu = max(res.attenuation_per_m, 1e-6)

    def by_hand():
        i = projected_brdf(spot.target.material, wi, wo) * spot.total_power_w
        # the range where I exp(-mu R) / R^2 = MPE: R = (2 / mu) W(mu / 2 sqrt(I / MPE))
        return 2.0 / mu * _lambertw0(0.5 * mu * np.sqrt(np.maximum(i, 0.0) / res.mpe_w_m2))

    floor, _ = median_s(by_hand)
    return {"name": f"keep-out lobe at {grid_deg} deg ({lobe.evaluations} evaluations)", "time_s": t, "floor_s": floor, "ratio": t / floor}


def bench_render():
    import pyvista as pv

    from hazard.pictures import render

    res = hazard.analyze(scenes.load(scenes.example_path("steel_vs_copper")))
    with tempfile.TemporaryDirectory() as tmp:
        render.keepout(res, Path(tmp) / "warm", force=True)  # VTK/OpenGL start-up
        t, _ = median_s(lambda: render.keepout(res, tmp, force=True))

        def floor_fn():
            blocks = render._scene_blocks(res, 3.0)  # the lobe surfaces, as the real path makes them
            for k in range(2):
                p = pv.Plotter(off_screen=True, window_size=[1280, 900])
                p.add_mesh(blocks)
                p.screenshot(str(Path(tmp) / f"floor{k}.png"))
                p.close()

        floor, _ = median_s(floor_fn)
    return {"name": "render (close view + overview + VTK)", "time_s": t, "floor_s": floor, "ratio": t / floor}


def run(verbose=True, study_scenarios=200, lobe_grid_deg=0.25, render=True):
    rows = (([bench_study(study_scenarios)] if study_scenarios else []) + [bench_lobe(lobe_grid_deg)]
            + ([bench_render()] if render else []))
    if verbose:
        for r in rows:
            print(f"{r['name']}: {r['time_s']:.2f} s; floor {r['floor_s']:.2f} s; ratio {r['ratio']:.2f}")
    return rows


if __name__ == "__main__":
    run()
