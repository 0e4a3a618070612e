"""Monte Carlo over material variability: which NOHD covers 95 % of copper panels?

Run:  python examples/monte_carlo.py [--out DIR] [--samples N] [--serial]

Runs hazard/studies/montecarlo_binoculars.toml (BRDF scale spread ~2x, 0.5 deg rms
peak wander - the paper's sample-to-sample variability) and prints the percentiles of
the hazard distances.
"""

import argparse
import os
import sys
from dataclasses import replace
from pathlib import Path

from hazard.drivers.study import load_study, progress_bar, run_study

HERE = Path(__file__).resolve().parent


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default=os.path.join(HERE, "out", "monte_carlo"))
    ap.add_argument("--samples", type=int, default=None)
    ap.add_argument("--serial", action="store_true")
    args = ap.parse_args(argv)
    study = load_study(HERE.parent / "hazard" / "studies" / "montecarlo_binoculars.toml")
    if args.samples is not None:
        study = replace(study, montecarlo=replace(study.montecarlo, samples=args.samples))
    res = run_study(study, args.out, serial=args.serial, force=True, progress=progress_bar())
    for col in ("nohd_dynamic_m", "specular_nohd_dynamic_m", "hazardous_observers"):
        st = res.summary["statistics"][col]
        print(f"{col:26s} median {st['p50']:.4g}   95 % {st['p95']:.4g}   max {st['max']:.4g}")
    print(f"results: {res.outdir / 'results.csv'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
