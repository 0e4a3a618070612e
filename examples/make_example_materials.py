"""Write the illustrative BRDF materials used by the bundled example scenes.

Run:  python examples/make_example_materials.py   (writes scenes/examples/*.json)

These are NOT measured fits. They are spherical-harmonic models whose shapes follow the
trends of Bailey et al., J. Laser Appl. 20(1), 2008, Table I:

* stainless_dynamic.json - DynamicBRDF over oxide extinction xi (the paper's preferred
  state label for stainless before melting): a glossy, groove-elongated specular lobe
  whose peak falls and broadens as xi grows from the paper's xi_0 = 0.311; the total
  reflectance follows R(xi)/R(xi_0) = exp(-(xi - xi_0)) (about 50 % drop at xi = 1).
  Basis (8, 4, 2, 0): the paper's 37 stainless harmonics.
* copper_glossy.json - a static glossy copper lobe plus a Fresnel mirror part; the copper
  example scales it by a measured-style reflectance-factor series (cleaning raises the
  reflectance ~30 %, then oxidation drops it ~90 %).
* stainless_melt_brdf.json - a two-state DynamicBRDF over (oxide extinction, melt
  fraction) for the ``stainless_melt`` scene, made the way a measured one would be: the
  witness-screen simulator (:func:`brdfmodels.screen.simulate_test`, 2 % camera noise)
  films the synthetic truth :class:`brdfmodels.melt_truth.SyntheticMeltingSteel` (peak
  falls with oxidation, recovers to 1.3x on melting: paper Secs. V B 2, VI A, VIII B) at
  every node of the state grid, in the paper's six fit tests (Sec. VI A), the frames are
  reduced (:func:`brdfmodels.screen.reduce_test`) and fitted node by node
  (:func:`brdfmodels.fitting.fit_dynamic_sh` over two states, basis (8, 4, 2, 0)).

Run ``python examples/make_example_materials.py stainless_melt`` to remake only that one
(about 30 s); with no argument every material is remade.
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


def lobe_coefficients(basis, width_deg, peak, diffuse, anisotropy):
    """Zonal lobe ln(diffuse + peak exp(-(theta_h/w)^2)) plus a cos(2 phi_h) elongation."""
    w = np.radians(width_deg)
    zonal = bm.sh.zonal_coefficients(lambda th: np.log(diffuse + peak * np.exp(-((th / w) ** 2))), basis.lh_max, 0.6)
    coef = np.zeros(basis.size)
    for k, col in enumerate(basis.columns):
        kind, l, m = col
        if kind == "h" and m == 0:
            coef[k] = zonal[l]
        elif kind == "h" and m == 2 and l >= 2:
            coef[k] = anisotropy * zonal[l]  # elongates the lobe along the grooves
    return coef


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
    if "stainless_melt" in names or not names:
        make_stainless_melt()
    if names and set(names) != {"stainless_melt"}:
        raise SystemExit(f"unknown names {sorted(set(names) - {'stainless_melt'})}: expected stainless_melt or nothing")
    if names:
        return
    basis = bm.SHBasis(8, 4, 2, 0)
    xi = np.array([0.311, 0.5, 0.8, 1.1, 1.5])
    factor = np.exp(-(xi - 0.311))
    # lobe width grows with oxidation; peak ~ f / w^2 keeps the lobe's albedo ~ f
    widths = 3.0 + 3.0 * (xi - 0.311)
    rows = [lobe_coefficients(basis, w, 13.0 * f * (3.0 / w) ** 2, 0.03 * f, 0.15) for w, f in zip(widths, factor)]
    steel = bm.DynamicBRDF(basis, xi, np.array(rows), "extinction", fanout=0.6, log=True, extrapolation="clamp")
    bm.save(steel, OUT / "stainless_dynamic.json")

    cu_basis = bm.SHBasis(10, 4, 2, 0)  # the paper's 47 copper harmonics
    cu_lobe = bm.SphericalHarmonicBRDF(cu_basis, lobe_coefficients(cu_basis, 2.0, 30.0, 0.01, 0.05))
    copper = bm.Sum([cu_lobe, bm.Specular(reflectance=0.3), bm.Lambertian(0.01)])
    bm.save(copper, OUT / "copper_glossy.json")
    for name, m in (("stainless @ xi0", steel.at_state(0.311)), ("stainless @ 1.5", steel.at_state(1.5)), ("copper", copper)):
        r = bm.hemispherical_reflectance(m, bm.spherical_to_vector(np.radians(20), 0.0), rtol=1e-4)
        print(f"{name}: DHR at 20 deg = {r.value:.3f}")


if __name__ == "__main__":
    main(sys.argv[1:])
