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
"""

from pathlib import Path

import numpy as np

import brdfmodels as bm

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


def main():
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
    main()
