"""A power sweep study on Dask: how far does the keep-out zone reach as power grows?

Run:  python examples/power_sweep.py [--out DIR] [--quick]

Runs hazard/studies/power_sweep.toml on an embedded Dask LocalCluster (2 workers),
writes results.csv/.parquet, summary.json and summary.png, and prints the table. A
restarted run skips finished scenarios. --quick: two powers, in this process.
"""

import argparse
import os
import sys
from dataclasses import replace
from pathlib import Path

from hazard.drivers.study import Parameter, load_study, progress_bar, run_study

HERE = Path(__file__).resolve().parent


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default=os.path.join(HERE, "out", "power_sweep"))
    ap.add_argument("--quick", action="store_true")
    args = ap.parse_args(argv)
    study = load_study(HERE.parent / "hazard" / "studies" / "power_sweep.toml")
    if args.quick:
        study = replace(study, parameters=(Parameter("laser.power_w", values=(1000.0, 10000.0)),))
    res = run_study(study, args.out, serial=args.quick, force=True, progress=progress_bar())
    for r in res.rows:
        print(f"power {r['in:laser.power_w']:>8g} W: NOHD static {r['nohd_static_m']:.2f} m, dynamic {r['nohd_dynamic_m']:.2f} m, "
              f"mirror {r['specular_nohd_dynamic_m']:.0f} m, {r['hazardous_observers']} hazardous observers")
    print(f"results: {res.outdir / 'results.csv'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
