"""Error against cost over spherical-harmonic orders (held-out error, fit and evaluation time).

Run:  python examples/sh_order_table.py [--out DIR]

Single-state fits of the paper's protocol (simulated witness-screen data of an analytic
grooved-metal truth) for lh_max 4..16 and mh_max 0..6: held-out log-RMS error on the
10, 30 deg (horizontal grooves) and 40 deg (vertical grooves) tests, fit time, and
evaluation time per 1e6 direction pairs. Plots error vs evaluation cost if matplotlib is
installed.
"""

import argparse
import os
import sys
from pathlib import Path

from brdfmodels.accuracy import format_table
from brdfmodels.validation import order_error_table


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default=os.path.join(os.path.dirname(__file__), "out"))
    ap.add_argument("--quick", action="store_true", help="a small grid (for CI)")
    args = ap.parse_args(argv)
    kw = dict(lh_maxes=(4, 8), mh_maxes=(0, 4), eval_points=20_000) if args.quick else {}
    rows = order_error_table(**kw)
    print(format_table(rows, "SH order: held-out error vs cost"))
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        return 0
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    fig, ax = plt.subplots(figsize=(7, 4.5))
    for mh in sorted({r["mh_max"] for r in rows}):
        sel = [r for r in rows if r["mh_max"] == mh]
        ax.plot([r["eval_s_per_1e6"] for r in sel], [r["held_out_log_rms"] for r in sel], "o-", label=f"mh_max {mh}")
        for r in sel:
            ax.annotate(str(r["lh_max"]), (r["eval_s_per_1e6"], r["held_out_log_rms"]), fontsize=7)
    ax.set_xlabel("evaluation time per 1e6 direction pairs [s]")
    ax.set_ylabel("held-out log-RMS error")
    ax.set_title("SH order: error vs cost (labels: lh_max)")
    ax.legend()
    ax.grid(alpha=0.3)
    fig.savefig(out / "sh_order_table.png", dpi=110)
    print(f"plot: {out / 'sh_order_table.png'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
