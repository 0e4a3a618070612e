"""Accuracy against run time of the keep-out lobe's refinement (issue 12, item 6).

Run on demand:  python -m tests.bench.bench_keepout   (or pytest tests/bench -m bench -s)

Scenes: every bundled scene, plus two sharp lobes the 2-degree grid does not resolve (the
`plate` scene tilted 17 degrees, with a five-parameter lobe about 1 and 0.35 degrees wide:
``kr`` = 0.01 and 0.003). Each runs the whole analysis at ``refine_levels`` 0..4 (the
default ``VOLUME_RTOL``) and at ``VOLUME_RTOL`` 1e-2..1e-5 (the default depth). Errors of
the max NOHD and of the keep-out volume, over the static and dynamic lobes of every
target, are relative to a reference run at refine_levels 6 and VOLUME_RTOL 1e-6 (its own
volume estimate is below 1e-6 of the volume); "estimate" is the largest reported
``volume_error_m3`` relative to the volume. Times are best of 3: the keep-out stage and
the whole analysis, summed over the bundled scenes.
"""

from __future__ import annotations

import copy
import time
from contextlib import contextmanager

import numpy as np

import hazard
import scenes
from brdfmodels.fileio import read_toml
from hazard.physics import keepout
from scenes.spec import AnalysisSpec

LEVELS = (0, 1, 2, 3, 4)
RTOLS = (1e-2, 1e-3, 1e-4, 1e-5)
REFERENCE = {"refine_levels": 6, "rtol": 1e-6}
SHARP_KR = (0.01, 0.003)  # five-parameter kr: lobes about 1.1 and 0.35 deg wide (half maximum)


def _sharp(kr):
    """The `plate` scene tilted 17 deg with a sharp five-parameter lobe (DHR about 0.9)."""
    data = copy.deepcopy(read_toml(scenes.example_path("plate")))
    data["name"] = f"sharp-lobe-kr-{kr:g}"
    t = data["targets"][0]
    t["normal"] = [0.0, -1.0, 0.3]
    t["material"] = {"model": "torrance-sparrow-5", "kb": 0.007 / kr**2, "kr": kr, "a": 1.0, "b": 0.0, "kd": 0.01}
    return data


def scene_data() -> list:
    """(name, TOML data, base folder, bundled?) of every scene of the tables."""
    rows = [(n, read_toml(p), p.parent, True) for n, p in scenes.examples().items()]
    base = scenes.example_path("plate").parent
    return rows + [(f"sharp kr={kr:g}", _sharp(kr), base, False) for kr in SHARP_KR]


@contextmanager
def volume_rtol(value):
    """Set ``hazard.physics.keepout.VOLUME_RTOL`` (the default of every lobe) for a block."""
    old = keepout.VOLUME_RTOL
    keepout.VOLUME_RTOL = float(value)
    try:
        yield
    finally:
        keepout.VOLUME_RTOL = old


def _lobes(res) -> dict:
    """(target, kind) -> (max NOHD [m], volume [m^3], volume error estimate [m^3],
    BRDF evaluations); the dynamic lobe is left out where it is the static one."""
    out = {}
    for t in res.targets:
        for kind in ("static", "dynamic"):
            lb = getattr(t, f"{kind}_lobe")
            if lb is not None and not (kind == "dynamic" and lb is t.static_lobe):
                out[(t.name, kind)] = (lb.max_range_m, lb.volume_m3, lb.volume_error_m3, lb.evaluations)
    return out


def _run(data, base, refine_levels, rtol, repeat):
    """Lobes and the best-of-``repeat`` keep-out and whole-analysis times [s]."""
    d = copy.deepcopy(data)
    d.setdefault("analysis", {})["refine_levels"] = refine_levels
    scene = scenes.from_data(d, source=d["name"], base_dir=base)
    t_keep = t_all = np.inf
    with volume_rtol(rtol):
        for _ in range(repeat):
            t0 = time.perf_counter()
            res = hazard.analyze(scene)
            t_all = min(t_all, time.perf_counter() - t0)
            t_keep = min(t_keep, res.stage("keepout").seconds)
    return _lobes(res), t_keep, t_all


def _errors(lobes, ref) -> tuple:
    """Largest relative errors of max NOHD and volume, and the largest relative estimate."""
    rel = lambda a, b: abs(a - b) / abs(b) if b else abs(a)  # noqa: E731
    e_r = max([rel(lobes[k][0], ref[k][0]) for k in ref] + [0.0])
    e_v = max([rel(lobes[k][1], ref[k][1]) for k in ref] + [0.0])
    est = max([rel(lobes[k][2], 0.0) if not ref[k][1] else lobes[k][2] / ref[k][1] for k in ref] + [0.0])
    return e_r, e_v, est


def _row(settings, data_rows, refs, repeat):
    """One table row: errors over the bundled scenes, each sharp lobe's volume error, times."""
    row = {**settings, "nohd_error": 0.0, "volume_error": 0.0, "estimate": 0.0, "evaluations": 0, "keepout_s": 0.0,
           "analysis_s": 0.0}
    for name, data, base, bundled in data_rows:
        lobes, t_keep, t_all = _run(data, base, settings["refine_levels"], settings["rtol"], repeat)
        e_r, e_v, est = _errors(lobes, refs[name])
        if bundled:
            row["nohd_error"] = max(row["nohd_error"], e_r)
            row["volume_error"] = max(row["volume_error"], e_v)
            row["estimate"] = max(row["estimate"], est)
            row["evaluations"] += sum(v[3] for v in lobes.values())
            row["keepout_s"] += t_keep
            row["analysis_s"] += t_all
        else:
            row[f"{name} volume_error"] = e_v
            row[f"{name} nohd_error"] = e_r
            row[f"{name} keepout_s"] = t_keep
            row[f"{name} evaluations"] = sum(v[3] for v in lobes.values())
    return row


def run(verbose=True, repeat=3) -> dict:
    """Both tables (rows of dicts); prints them when ``verbose``."""
    data_rows = scene_data()
    refs = {name: _run(data, base, REFERENCE["refine_levels"], REFERENCE["rtol"], 1)[0] for name, data, base, _ in data_rows}
    default_levels = AnalysisSpec().refine_levels
    by_level = [_row({"refine_levels": n, "rtol": keepout.VOLUME_RTOL}, data_rows, refs, repeat) for n in LEVELS]
    by_rtol = [_row({"refine_levels": default_levels, "rtol": rt}, data_rows, refs, repeat) for rt in RTOLS]
    if verbose:
        for title, rows in (("refine_levels (VOLUME_RTOL %g)" % keepout.VOLUME_RTOL, by_level),
                            (f"VOLUME_RTOL (refine_levels {default_levels})", by_rtol)):
            print(f"keep-out lobe accuracy vs time: {title}; errors vs refine_levels 6, VOLUME_RTOL 1e-6")
            for r in rows:
                sharp = "; ".join(f"{n}: volume {r[f'{n} volume_error']:.1e} ({r[f'{n} evaluations']} evaluations, "
                                  f"{r[f'{n} keepout_s']:.3f} s)" for n, _, _, b in data_rows if not b)
                print(f"  refine_levels {r['refine_levels']} rtol {r['rtol']:g}: bundled max NOHD {r['nohd_error']:.1e}, "
                      f"volume {r['volume_error']:.1e} (estimate {r['estimate']:.1e}), {r['evaluations']} evaluations, "
                      f"keep-out {r['keepout_s']:.2f} s, analysis {r['analysis_s']:.2f} s; {sharp}")
    return {"refine_levels": by_level, "rtol": by_rtol}


if __name__ == "__main__":
    run()
