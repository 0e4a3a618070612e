"""Static vs dynamic reflectance for stainless steel and copper under one beam.

Run:  python examples/static_vs_dynamic.py [--out DIR]

Analyses the bundled `steel_vs_copper` scene (a heating model with the paper's oxidation
fit for stainless; a measured-style reflectance series for copper), prints the NOHD of
each target with a static BRDF (initial state held) and with the dynamic one, lists the
observers whose verdict changes, and plots NOHD over time for both targets.
"""

import argparse
import os
import sys
from pathlib import Path

import hazard
import scenes
from hazard.pictures import plots


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default=os.path.join(os.path.dirname(__file__), "out"))
    args = ap.parse_args(argv)
    res = hazard.analyze(scenes.load(scenes.example_path("steel_vs_copper")))
    print(f"MPE {res.mpe_w_m2:g} W/m^2 for {res.mpe.duration_s:g} s")
    for t in res.targets:
        d = t.to_dict()
        print(f"{t.name:10s} NOHD static {d['nohd_static_m']:8.3f} m   dynamic {d['nohd_dynamic_m']:8.3f} m   "
              f"({t.state_name} over [{t.state_range[0]:.3g}, {t.state_range[1]:.3g}])")
    print("observers whose verdict changes:", ", ".join(res.verdict_changes()) or "none")
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    for k, t in enumerate(res.targets):
        p = plots.NOHDTimeDisplay.from_result(res, target=k).save(out / f"nohd_vs_time_{t.name}.png")
        print(f"plot: {p}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
