"""Speed of ``hazard risk`` per draw against a complete floor.

Run on demand:  python -m tests.bench.bench_risk   (or pytest tests/bench -m bench -s)

Scene: the bundled ``risk`` example (a glass panel 1 km down range, 42 observers and a
40 x 35 map; pointing, BRDF scale, tilt, visibility, scintillation and position drawn).
The risk path draws the inputs (importance mixture), turns and re-traces the beam, tilts
and rescales the panel, evaluates the mirror beam and the direct beam at every point with
scintillation and takes the peak ratio. The floor is the engine work each draw cannot do
without, called directly: the same turned beams traced (:func:`trace_beam`), the same
points through :func:`specular_irradiance`, :func:`spot_irradiance` and the direct beam
(:func:`beam_at`), nothing drawn, tilted or weighted. Times are the median of 5 over 200
draws (20 with BENCH_QUICK=1), one thread.
"""

from __future__ import annotations

import statistics
import time

import numpy as np

import scenes
from brdfmodels.parallel import thread_limit
from hazard.physics.engine import spot_irradiance, specular_irradiance
from hazard.pipeline import spots as beam_stage
from hazard.pipeline.direct import beam_at
from hazard.drivers.risk.evaluate import turned_axis
from hazard.drivers.risk.run import shared

N = 200


def _floor(ev, d) -> float:
    p, m = ev.points_m, len(ev.points_m)
    t0 = time.perf_counter()
    for i in range(d.n):
        beam = beam_stage.scene_beam(ev.scene, turned_axis(ev.nominal.beam.axis, ev.right, ev.up, d.pointing_rad[i]))
        tr = beam_stage.trace_beam(ev.scene, ev.tracer, ev.mu0, beam)
        for sp in tr.built.spots:
            spot_irradiance(sp, p, np.ones(m), ev.mu0)
            specular_irradiance(sp, p, np.ones(m), ev.mu0)
        beam_at(beam, p, ev.mu0)
    return time.perf_counter() - t0


def run(n=N, repeat=5) -> dict:
    sc = scenes.load(scenes.example_path("risk"))
    ev, prop = shared(sc, "embree")
    paths, floors = [], []
    with thread_limit(1):
        for _ in range(repeat):
            t0 = time.perf_counter()
            d = prop.draw(ev.model, np.random.default_rng(0), n)
            ev.ratios(d)
            paths.append(time.perf_counter() - t0)
            floors.append(_floor(ev, d))
    t_path, t_floor = statistics.median(paths), statistics.median(floors)
    return {"draws": n, "points": len(ev.points_m), "per_draw_ms": 1e3 * t_path / n, "floor_per_draw_ms": 1e3 * t_floor / n,
            "ratio": t_path / t_floor}


if __name__ == "__main__":
    print(run())
