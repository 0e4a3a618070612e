"""Tour of the BRDF library: build every kind of model, evaluate it, plot it.

Run:  python examples/brdf_tour.py [--out DIR]

Prints, for each model, the BRDF in the plane of incidence at 30 deg incidence and its
directional-hemispherical reflectance (with the quadrature's error estimate), then the
conservativeness report of an envelope over a dynamic (heated) material, and writes a
plot of the in-plane BRDFs (log scale) when matplotlib is installed.
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

import numpy as np

import brdfmodels as bm
from brdfmodels.accuracy import sharp_sh_lobe
from brdfmodels.fileio import atomic_write


def dynamic_steel():
    """A dynamic SH material whose specular peak drops and broadens as it heats."""
    basis = bm.SHBasis(16, 0, 2, 0)
    states = np.array([300.0, 900.0, 1400.0])
    rows = []
    for width_deg, peak in [(2.0, 40.0), (4.0, 10.0), (7.0, 3.0)]:
        w = np.radians(width_deg)
        rows.append(bm.sh.zonal_coefficients(lambda th, peak=peak, w=w: np.log(0.02 + peak * np.exp(-((th / w) ** 2))), 16))
    coef = np.zeros((3, basis.size))
    coef[:, :17] = rows  # the halfway columns come first in the separable basis
    return bm.DynamicBRDF(basis, states, coef, "temperature_k")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default=os.path.join(os.path.dirname(__file__), "out"), help="output folder for the plot")
    args = ap.parse_args(argv)

    dyn = dynamic_steel()
    models = {
        "lambertian 0.5": bm.Lambertian(0.5),
        "TS5 white paint": bm.TorranceSparrow5(kb=5.708, kr=2.240, b=-58.722, a=0.452, kd=0.220),
        "TS5 forged steel": bm.TorranceSparrow5(kb=0.072, kr=16.125, b=-29.917, a=0.959, kd=0.081),
        "SH 2-deg lobe": sharp_sh_lobe(),
        "steel @ 300 K": dyn.at_state(300.0),
        "steel @ 1400 K": dyn.at_state(1400.0),
        "steel envelope": bm.Envelope(dyn, base=0.005, multiplier=1.2, fanout_h=0.5),
        "Cu mirror + diffuse": bm.Specular.for_material("cu", 1064.0) + bm.Lambertian(0.005),
    }
    theta_i = np.radians(30.0)
    wi = bm.spherical_to_vector(theta_i, 0.0)
    angles = np.radians(np.linspace(-89.0, 89.0, 357))
    wo = bm.spherical_to_vector(np.abs(angles), np.where(angles < 0, 0.0, np.pi))  # in-plane, mirror at +30
    print(f"{'model':22s} {'f_r(mirror) 1/sr':>16s} {'f_r(normal) 1/sr':>16s} {'DHR':>8s} {'+-':>8s}")
    curves = {}
    for name, m in models.items():
        f = m.evaluate(wi, wo)
        curves[name] = f
        r = bm.hemispherical_reflectance(m, wi, rtol=1e-5)
        mirror = float(m.evaluate(wi, bm.mirror_direction(wi)))
        print(f"{name:22s} {mirror:16.4g} {float(m.evaluate(wi, [0, 0, 1])):16.4g} {r.value:8.4f} {r.error_estimate:8.1e}")

    rng = np.random.default_rng(0)
    n = 20000
    wi_s = bm.spherical_to_vector(np.arccos(rng.uniform(0.05, 1, n)), rng.uniform(-np.pi, np.pi, n))
    wo_s = bm.spherical_to_vector(np.arccos(rng.uniform(0.05, 1, n)), rng.uniform(-np.pi, np.pi, n))
    for label, env in [("exact envelope", bm.Envelope(dyn)), ("paper-adjusted", models["steel envelope"])]:
        print(f"{label:15s}: {bm.envelope_report(env, dyn, wi_s, wo_s)}")

    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        print("matplotlib not installed: no plot (pip install 'laser-hazard[render]')", file=sys.stderr)
        return 0
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    fig, ax = plt.subplots(figsize=(8, 5))
    for name, f in curves.items():
        ax.semilogy(np.degrees(angles), np.maximum(f, 1e-4), label=name)
    ax.set_xlabel("reflection angle in the plane of incidence [deg] (mirror at +30)")
    ax.set_ylabel("BRDF f_r [1/sr]")
    ax.set_title("BRDF models at 30 deg incidence")
    ax.legend(fontsize=8)
    ax.grid(True, which="both", alpha=0.3)
    atomic_write(out / "brdf_tour.png", lambda tmp: fig.savefig(tmp, dpi=110), keep_suffix=True)
    print(f"plot: {out / 'brdf_tour.png'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
