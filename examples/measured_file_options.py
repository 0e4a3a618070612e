"""What each material option does to the error of a measured file in a scene (README table).

Run:  PYTHONPATH=. python examples/measured_file_options.py [--pairs N]

Writes the two files of ``tests/validation/test_measured_scene_refs.py`` from their truths
(Lambertian 0.3 + a 15 deg Gaussian lobe as a CSV every 5 deg; ABg A 0.015, B 0.0015,
g 2 as a PlaneSymmetrical ``.bsdf`` at 8 incidences 0-70 deg), loads each as a scene's
``material = { model = "table", file = ... }`` with each option, and prints the ratio
of the material's f_r to the truth: at the file's own samples (min-max), at random
direction pairs (incidence 0-80 deg, outgoing uniform in solid angle above 3 deg
elevation: 1st percentile / median / 99th) and the lowest within 10 deg of the mirror
direction (incidence 0-70 deg), and the load time (CPU seconds of the scene load and the
first evaluation, where the triangulation and peak fits are built). Imports the truths and writers from the test
module (run from the repository root).
"""

import argparse
import math
import tempfile
import time
from pathlib import Path

import numpy as np

import brdfmodels as bm
import scenes
from brdfmodels.io import read_samples
from tests._scene_text import PLATE_AT_50M
from tests.validation.test_measured_scene_refs import CSV_TI, _bsdf_text, _csv_text, abg_truth, lobe_truth

OPTIONS = (("default", ""), ('between="linear"', None), ('fill = "fit"', ', fill = "fit"'), ("grid_deg = [2, 2, 10]", ", grid_deg = [2, 2, 10]"),
           ("grid_deg = [5, 5, 30]", ", grid_deg = [5, 5, 30]"))


def _sph(theta, phi):
    return np.stack([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)], axis=-1)


def random_pairs(n, seed=0):
    """wi at 0-80 deg incidence (any azimuth), wo uniform in solid angle with cos > 0.05."""
    rng = np.random.default_rng(seed)
    wi = _sph(np.radians(rng.uniform(0.0, 80.0, n)), rng.uniform(-math.pi, math.pi, n))
    wo = _sph(np.arccos(rng.uniform(0.05, 1.0, n)), rng.uniform(-math.pi, math.pi, n))
    return wi, wo


def near_peak_pairs(n, seed=1):
    """wi at 0-70 deg; wo within 10 deg of the mirror direction (uniform in solid angle)."""
    rng = np.random.default_rng(seed)
    wi = _sph(np.radians(rng.uniform(0.0, 70.0, n)), rng.uniform(-math.pi, math.pi, n))
    m = wi * [-1.0, -1.0, 1.0]
    a = np.cross(m, [0.0, 0.0, 1.0])
    a[np.linalg.norm(a, axis=1) < 1e-9] = [1.0, 0.0, 0.0]
    a /= np.linalg.norm(a, axis=1, keepdims=True)
    b = np.cross(m, a)
    c = rng.uniform(math.cos(math.radians(10.0)), 1.0, n)
    q = rng.uniform(-math.pi, math.pi, n)
    s = np.sqrt(1.0 - c * c)[:, None]
    wo = c[:, None] * m + s * (np.cos(q)[:, None] * a + np.sin(q)[:, None] * b)
    keep = wo[:, 2] > 0.05
    return wi[keep], wo[keep]


def measure(path, truth, extra, pairs, near):
    """Ratios model / truth and load time of ``path`` with the material keys ``extra``."""
    scene = path.parent / "s.toml"
    scene.write_text(PLATE_AT_50M.replace('{ model = "lambertian", reflectance = 0.5 }',
                                          f'{{ model = "table", file = "{path.name}"{extra} }}'))
    s = read_samples(path)
    t0 = time.process_time()
    try:
        if extra is None:  # Python only: the convex combination alone, no peak-aware estimate
            m = bm.ScatteredBRDF.from_samples(s.wi, s.wo, s.brdf_per_sr, between="linear")
        else:
            m = scenes.load(scene).targets[0].material
        at_samples = m.evaluate(s.wi, s.wo) / s.brdf_per_sr
    except scenes.SceneError as exc:
        return {"refused": str(exc)[:80]}
    load_s = time.process_time() - t0
    r = m.evaluate(*pairs) / truth(*pairs)
    rn = m.evaluate(*near) / truth(*near)
    return {"samples": (float(at_samples.min()), float(at_samples.max())), "pairs": tuple(np.percentile(r, [1, 50, 99])),
            "near_min": float(rn.min()), "load_s": load_s}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--pairs", type=int, default=20_000)
    args = ap.parse_args(argv)
    pairs, near = random_pairs(args.pairs), near_peak_pairs(args.pairs // 4)
    with tempfile.TemporaryDirectory() as d:
        files = {"CSV": (Path(d) / "m.csv", lobe_truth), "`.bsdf`": (Path(d) / "m.bsdf", abg_truth)}
        files["CSV"][0].write_text(_csv_text(lobe_truth, CSV_TI, list(range(0, 86, 5)), list(range(0, 360, 5))))
        files["`.bsdf`"][0].write_text(_bsdf_text(abg_truth))
        print("| file, option | at samples | random pairs (1 % / median / 99 %) | lowest near peak | load (CPU) |")
        print("| --- | --- | --- | --- | --- |")
        for label, (path, truth) in files.items():
            for name, extra in OPTIONS:
                res = measure(path, truth, extra, pairs, near)
                if "refused" in res:
                    print(f"| {label}, {name} | refused: {res['refused']} | | | |", flush=True)
                    continue
                lo, hi = res["samples"]
                smp = f"{lo:.4f}" if abs(hi - lo) < 5e-5 else f"{lo:.2f}-{hi:.2f}"
                print(f"| {label}, `{name}` | {smp} | {' / '.join(f'{x:.3f}' for x in res['pairs'])} | "
                      f"{res['near_min']:.3f} | {res['load_s']:.1f} s |", flush=True)


if __name__ == "__main__":
    main()
