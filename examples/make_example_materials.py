"""Write the illustrative BRDF materials used by the bundled example scenes.

Run:  python examples/make_example_materials.py   (writes scenes/examples/*.json)

These are NOT measured fits. They are spherical-harmonic models whose shapes follow the
trends of Bailey et al., J. Laser Appl. 20(1), 2008, Table I:

* stainless_dynamic.json - glossy stainless over oxide extinction xi (the paper's preferred
  state label for stainless before melting): a specular lobe whose peak falls and
  broadens as xi grows from the paper's xi_0 = 0.311 (width 3 deg -> 6.6 deg at xi = 1.5,
  peak ~ f (3 deg / w)^2) and a diffuse part; the total reflectance follows
  R(xi)/R(xi_0) = f = exp(-(xi - xi_0)) (about 50 % drop at xi = 1). Built from
  energy-conserving parts (:func:`glossy_stainless`): two Gaussian lobes in
  direction-cosine space (narrow and broad, their amplitudes tabulated over xi so peak and
  lobe energy follow the design at every node) and a Lambertian, each scaled by a
  clamped state table.
* copper_glossy.json - a static glossy copper lobe (a Gaussian lobe in direction cosines)
  plus a mirror part (reflectance 0.3) and a Lambertian (0.01); the copper example scales
  it by a measured-style reflectance-factor series (cleaning raises the reflectance ~30 %,
  then oxidation drops it ~90 %), so its reflectance is kept <= 0.77 at every incidence
  (x 1.3 <= 1).

Until 2026-11 both were spherical-harmonic models of ``ln(floor + lobe(theta_h))`` in f~ =
cos_i cos_r f_r. A constant floor of f~ is a BRDF of floor / (cos_i cos_r): its
hemispherical reflectance grows as 1 / cos(theta_i) and the old files reached 1.47 (copper)
and 2.57 (stainless, xi_0) at 85 deg incidence, 4.4 and 11.2 at 89 deg; a low-order SH
expansion cannot hold the lobe without the floor (it rings). The closed-form parts
conserve energy at every incidence (a direction-cosine lobe integrates to at most
peak pi sigma^2). README "Materials" gives the before/after numbers.
* stainless_melt_brdf.json - a two-state DynamicBRDF over (oxide extinction, melt
  fraction) for the ``stainless_melt`` scene, made the way a measured one would be: the
  witness-screen simulator (:func:`brdfmodels.screen.simulate_test`, 2 % camera noise)
  films the synthetic truth :class:`brdfmodels.melt_truth.SyntheticMeltingSteel` (peak
  falls with oxidation, recovers to 1.3x on melting: paper Secs. V B 2, VI A, VIII B) at
  every node of the state grid, in the paper's six fit tests (Sec. VI A), the frames are
  reduced (:func:`brdfmodels.screen.reduce_test`) and fitted node by node
  (:func:`brdfmodels.fitting.fit_dynamic_sh` over two states, basis (8, 4, 2, 0)).

Run ``python examples/make_example_materials.py stainless_melt`` to remake only that one
(about 30 s), ``... glossy`` for stainless_dynamic and copper_glossy; with no argument
every material is remade.
"""

import math
import sys
from pathlib import Path

import numpy as np

import brdfmodels as bm
from brdfmodels import fitting, screen
from brdfmodels.melt_truth import SyntheticMeltingSteel
from brdfmodels.validation import FIT_TESTS, HELD_OUT_TESTS

OUT = Path(__file__).resolve().parents[1] / "scenes" / "examples"


# State grid of stainless_melt_brdf.json: oxide extinction from the paper's xi_0 = 0.311
# through the range a 5e6 W/m^2 spot reaches before and while it melts (xi ~ 1.4 at melt
# onset, ~ 2.4 at full melt; ThinPlateHeating.stainless_steel()), and a last node at 20 past
# the ~15 the plate reaches by 10 s (the molten truth does not depend on xi); melt fraction
# 0, 1/2, 1. Outside the grid the model holds the end states (extrapolation = "clamp").
MELT_EXTINCTION_NODES = (0.311, 0.6, 1.0, 1.4, 1.9, 2.5, 20.0)
MELT_FRACTION_NODES = (0.0, 0.5, 1.0)
# Camera gain [counts per W/m^2]: the molten peak (6.1 /sr at 230 W, 0.6 m) stays below the
# 60000-count saturation (at the simulator's default 200 a saturated peak is masked and the
# fit has to guess it: the paper changed neutral-density filters instead).
MELT_GAIN_COUNTS = 10.0


def melt_screen_samples(truth, grid, tests, seed):
    """Reduced witness-screen samples of ``truth`` at every state pair of ``grid`` (G, 2):
    frame k of each test films state ``grid[k]``; the samples carry the two state columns."""
    parts = []
    for k, (incidence, groove) in enumerate(tests):
        test = screen.simulate_test(truth, test_id=f"{incidence:g}deg-g{groove:g}", incidence_deg=incidence,
                                    groove_angle_deg=groove, times_s=np.arange(len(grid), dtype=float),
                                    state_of_time=lambda t: grid[int(t)], pixels=(72, 72), noise=0.02, seed=seed + k,
                                    gain_counts=MELT_GAIN_COUNTS)
        s = screen.reduce_test(test)
        node = s.time_s.astype(int)
        parts.append(s.with_states({"extinction": grid[node, 0], "melt_fraction": grid[node, 1]}))
    return screen.Samples.concatenate(parts)


def make_stainless_melt():
    """Fit stainless_melt_brdf.json (see the module docstring) and print its check against
    the truth: the peak at 20 deg and the held-out error (10, 30 deg; 40 deg grooves
    vertical) at each node."""
    truth = SyntheticMeltingSteel()
    xi, m = np.array(MELT_EXTINCTION_NODES), np.array(MELT_FRACTION_NODES)
    grid = np.array([(a, b) for a in xi for b in m])
    fit_samples = melt_screen_samples(truth, grid, FIT_TESTS, seed=0)
    fit = fitting.fit_dynamic_sh(fit_samples, bm.SHBasis(8, 4, 2, 0), [xi, m], state=["extinction", "melt_fraction"],
                                 extrapolation="clamp")
    bm.save(fit.model, OUT / "stainless_melt_brdf.json")
    held = melt_screen_samples(truth, grid, HELD_OUT_TESTS, seed=100)
    wi = bm.spherical_to_vector(math.radians(20.0), 0.0)
    wo = bm.mirror_direction(wi)
    print(f"stainless_melt_brdf.json: {len(fit_samples)} samples, {grid.shape[0]} nodes")
    for state in grid:
        sel = held.select((held.states["extinction"] == state[0]) & (held.states["melt_fraction"] == state[1]))
        f, d = fit.model.evaluate(sel.wi, sel.wo, state=state), sel.brdf_per_sr
        bright = d > 0.01 * d.max()
        print(f"  xi {state[0]:5.3g} m {state[1]:3.1f}: peak {float(fit.model.evaluate(wi, wo, state=state)):.3f} /sr "
              f"(truth {float(truth.peak(state[0], state[1], math.radians(20.0))):.3f}), held-out log-RMS "
              f"{np.sqrt(np.mean(np.log(f / d) ** 2)):.3f} (samples above 1 % of the largest: "
              f"{np.sqrt(np.mean(np.log(f[bright] / d[bright]) ** 2)):.3f})")


def main(names=()):
    if set(names) - {"stainless_melt", "glossy"}:
        raise SystemExit(f"unknown names {sorted(set(names) - {'stainless_melt', 'glossy'})}: expected stainless_melt, glossy or nothing")
    if "stainless_melt" in names or not names:
        make_stainless_melt()
    if "glossy" in names or not names:
        make_glossy()


# stainless_dynamic: the design of the earlier SH file (lobe width w = 3 + 3 (xi - xi_0) deg,
# peak ~ f (3/w)^2, lobe energy ~ f, diffuse ~ f) with the lobe's peak taken as the old
# file's value at 20 deg incidence (22.4 /sr at xi_0: steel_vs_copper's incidence), the
# diffuse part as the old floor's value at normal incidence (0.03 f /sr: a Lambertian of
# pi 0.03 f). A lobe of angular width w (exp(-(theta_h/w)^2)) is exp(-(delta/2w)^2) in the
# angle delta from the mirror direction: sigma = 2 w in direction cosines.
STAINLESS_XI = (0.311, 0.5, 0.8, 1.1, 1.5)
STAINLESS_PEAK_PER_SR = 22.4
COPPER_LOBE = dict(peak=41.0, sigma=0.0593)  # old file: 41.7 /sr at 10 deg, e-fold 3.4 deg from the mirror direction
COPPER_MIRROR, COPPER_DIFFUSE = 0.3, 0.01


def glossy_stainless():
    """stainless_dynamic.json (see the module docstring): narrow (3 deg) and broad (6.57 deg)
    lobes with amplitudes a(xi), b(xi) >= 0 solving, at each node, peak a + b = f (3/w)^2
    and energy a + b (w_b/w_a)^2 = f (both relative to the narrow lobe at xi_0)."""
    xi = np.array(STAINLESS_XI)
    f = np.exp(-(xi - 0.311))
    w = 3.0 + 3.0 * (xi - 0.311)
    ratio = (w[-1] / w[0]) ** 2
    peak = f * (w[0] / w) ** 2
    b = (f - peak) / (ratio - 1.0)
    a = peak - b
    assert np.all(a >= -1e-12) and np.all(b >= 0)
    a = np.maximum(a, 0.0)

    def part(model, values):
        return bm.Scaled(model, bm.StateTable(xi, values, "extinction", extrapolation="clamp"))

    sig = 2.0 * np.radians(w[[0, -1]])
    return bm.Sum([part(bm.create("gaussian-lobe", peak=STAINLESS_PEAK_PER_SR, sigma=float(sig[0])), a),
                   part(bm.create("gaussian-lobe", peak=STAINLESS_PEAK_PER_SR, sigma=float(sig[1])), b),
                   part(bm.Lambertian(math.pi * 0.03), f)])


def glossy_copper():
    """copper_glossy.json: Gaussian lobe + mirror + Lambertian (module docstring)."""
    return bm.Sum([bm.create("gaussian-lobe", **COPPER_LOBE), bm.Specular(reflectance=COPPER_MIRROR), bm.Lambertian(COPPER_DIFFUSE)])


def make_glossy():
    steel, copper = glossy_stainless(), glossy_copper()
    bm.save(steel, OUT / "stainless_dynamic.json")
    bm.save(copper, OUT / "copper_glossy.json")
    for name, m, st in (("stainless @ xi0", steel, 0.311), ("stainless @ 1.5", steel, 1.5), ("copper", copper, None)):
        r = [bm.hemispherical_reflectance(m, bm.spherical_to_vector(np.radians(t), 0.0), state=st, rtol=1e-4).value for t in (0, 20, 60, 85, 89)]
        print(f"{name}: DHR at 0/20/60/85/89 deg = " + " / ".join(f"{v:.3f}" for v in r))


if __name__ == "__main__":
    main(sys.argv[1:])
