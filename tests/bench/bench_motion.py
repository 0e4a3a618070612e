"""Speed of the motion stage (moving observers) against a complete floor.

Run on demand:  python -m tests.bench.bench_motion   (or pytest tests/bench -m bench -s)

Scene: ``examples/accuracy/aircraft_crossing.toml`` with the aircraft flying a 10-minute
zig-zag across the beam (20 crossings at 100 m/s, 5 km out). The stage samples the base
step (0.1 s), refines every crossing and sums the direct beam and the plate's reflection.
The floor is all the work those samples need and no more: the same number of positions
and times through the Gaussian beam formula and the Lambertian plate's reflection, in
one vectorised pass (no step refinement, no line of sight, no windows). Times are the
median of 5.
"""

from __future__ import annotations

import math
import statistics
import time
from pathlib import Path

import numpy as np

import hazard
import scenes

SCENE = Path(__file__).resolve().parents[2] / "examples" / "accuracy" / "aircraft_crossing.toml"


def _zigzag_text() -> str:
    text = SCENE.read_text()
    times = np.arange(0.0, 601.0, 30.0)
    xs = np.where(np.arange(len(times)) % 2 == 0, -1500.0, 1500.0)
    rows = ", ".join(f"[{x}, 5000.0, 0.0]" for x in xs)
    track = (f'times_s = [{", ".join(repr(float(t)) for t in times)}]\npositions_m = [{rows}]\n')
    head, _ = text.split("start_m =")
    return head + track


def _floor(n: int) -> float:
    """The Gaussian beam and a Lambertian plate at n points, vectorised [s]."""
    rng = np.random.default_rng(0)
    p = np.column_stack([rng.uniform(-1500, 1500, n), np.full(n, 5000.0), np.zeros(n)])
    u = np.array([0.0, 1.0, 0.0])
    t0 = time.perf_counter()
    z = p @ u
    r2 = np.einsum("ij,ij->i", p, p) - z * z
    w = (0.01 + z * 9.8e-5) / 2
    e = 10.0 / (math.pi * w * w) * np.exp(-r2 / (w * w)) * np.exp(-1e-4 * z)
    d = p - np.array([0.0, 20000.0, 0.0])
    rr = np.linalg.norm(d, axis=1)
    e = e + 0.1 * 10.0 * np.maximum(-d[:, 1] / rr, 0) / (math.pi * rr * rr)
    _ = np.cumsum(e)
    return time.perf_counter() - t0


def run(repeat=5) -> dict:
    sc = scenes.loads(_zigzag_text())
    hazard.analyze(sc)  # warm-up
    times, samples = [], 0
    for _ in range(repeat):
        res = hazard.analyze(sc)
        times.append(res.stage("motion").seconds)
        samples = res.motion.tracks()[0].summary.samples
    floor = statistics.median(_floor(samples) for _ in range(repeat))
    t = statistics.median(times)
    return {"samples": samples, "crossings": 20, "motion_stage_s": t, "floor_s": floor, "ratio": t / max(floor, 1e-12)}


if __name__ == "__main__":  # pragma: no cover
    print(run())
