"""Benchmark: writing a large run's outputs against its analysis (issue 37 item 3).

Run on demand:  python -m tests.bench.bench_outputs   (or pytest tests/bench -m bench -s)

Scene: the bundled ``plate`` (100 W at 1064 nm on a Lambertian plate 50 m down range)
with its two observers replaced by a ``rows x rows`` grid at 1.5 m in front of the plate
(1000 x 1000: the 1e6-observer run of the README). Timed, median of ``repeat``, in one
process: ``hazard.analyze`` of a freshly loaded scene (the ray cache kept: a run builds its
14 triangles once), and the outputs ``hazard run`` writes after it: the map files
(:func:`hazard.outputs.map_outputs.map_files`) and report.json + observers.csv
(:func:`hazard.outputs.report.write_set`, each file fsynced; observers.csv on a worker thread
started before the map, :func:`hazard.outputs.report.csv_started`) into a temporary folder. Goal
(issue 37): outputs / analysis <= 1. CPU seconds (every thread) are printed beside the
wall times (with the system part: the kernel's page allocation and write-back of the
new files), and the machine's load after the run: on a shared machine CPU seconds are the steadier figure.
"""

from __future__ import annotations

import os
import shutil
import statistics
import tempfile
import time
from pathlib import Path

import hazard
import scenes
from hazard.outputs import report
from hazard.outputs.map_outputs import map_files

from ._floor import REPEAT

GRID = """[[observers]]
name = "map"
origin_m = [-50.0, -45.0, 1.5]
u_m = [100.0, 0.0, 0.0]
v_m = [0.0, 33.0, 0.0]
counts = [{rows}, {rows}]
"""


def scene_text(rows: int) -> str:
    """The plate example with a ``rows x rows`` observer grid instead of its two observers."""
    text = scenes.example_path("plate").read_text()
    return text.split("[[observers]]")[0] + GRID.format(rows=rows)


def _timed(fn, *args):
    """Wall, CPU and system CPU time [s] of ``fn(*args)``, and its result."""
    w, c, t = time.perf_counter(), time.process_time(), os.times()
    out = fn(*args)
    return time.perf_counter() - w, time.process_time() - c, os.times().system - t.system, out


def _outputs(result, folder: Path):
    with report.csv_started(result, folder) as csv:  # as `hazard run` does: observers.csv written while the map is made
        maps, section = map_files(result)
        return report.write_set(result, folder, extra=maps, sections={"map_outputs": section.to_dict()}, csv=csv)


def run(rows: int = 1000, repeat: int = REPEAT) -> dict:
    """Analysis and outputs, wall and CPU [s] (median of ``repeat``), and their ratio."""
    text = scene_text(rows)
    ana, out = [], []
    with tempfile.TemporaryDirectory() as tmp:
        for i in range(repeat):
            scene = scenes.loads(text)  # a fresh scene, as `hazard run` has: one analysed keeps its observers' points
            w, c, s, result = _timed(hazard.analyze, scene)
            ana.append((w, c, s))
            folder = Path(tmp) / f"o{i}"
            folder.mkdir()
            w, c, s, _ = _timed(_outputs, result, folder)
            out.append((w, c, s))
            del result
            shutil.rmtree(folder)
    a_w, a_c, a_s = (statistics.median(x) for x in zip(*ana))
    o_w, o_c, o_s = (statistics.median(x) for x in zip(*out))
    load = f"; load {os.getloadavg()[0]:.1f}" if hasattr(os, "getloadavg") else ""
    print(f"\noutputs of {rows * rows} observers: {o_w:.2f} s wall ({o_c:.2f} s CPU, {o_s:.2f} of it system) against the "
          f"analysis {a_w:.2f} s ({a_c:.2f} s CPU, {a_s:.2f} system): ratio {o_w / a_w:.2f} wall, {o_c / a_c:.2f} CPU{load}")
    return {"analysis_s": a_w, "outputs_s": o_w, "analysis_cpu_s": a_c, "outputs_cpu_s": o_c,
            "analysis_system_s": a_s, "outputs_system_s": o_s, "ratio": o_w / a_w}


if __name__ == "__main__":
    run()
