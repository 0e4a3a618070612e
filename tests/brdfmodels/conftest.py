"""Example instances of every registered model, for the conformance suite."""

import numpy as np
import pytest

import brdfmodels as bm

# The five published parameter sets (Zhang et al., Optica Applicata 40(1), 2010, tables)
TS5_PUBLISHED = {
    "white_paint": dict(kb=5.708, kr=2.240, b=-58.722, a=0.452, kd=0.220),
    "cement": dict(kb=0.003, kr=2.961, b=-18.301, a=15.572, kd=0.067),
    "khaki_paint": dict(kb=0.0698, kr=0.478, b=-28.935, a=0.777, kd=0.107),
    "forged_steel": dict(kb=0.072, kr=16.125, b=-29.917, a=0.959, kd=0.081),
    "polyimide": dict(kb=5.439, kr=3.257, b=-23.098, a=0.495, kd=2.267),
}


def glossy_log_coefficients(basis, peak_sr=30.0, width_rad=0.12, diffuse_sr=0.05, fanout=0.6, seed=0):
    """Least-squares SH coefficients of ln f~ for an analytic glossy lobe (test helper)."""
    rng = np.random.default_rng(seed)
    n = 4000
    th = np.arccos(rng.uniform(0.02, 1, n))
    wi = bm.spherical_to_vector(np.arccos(rng.uniform(0.05, 1, n)), rng.uniform(-np.pi, np.pi, n))
    wo = bm.spherical_to_vector(th, rng.uniform(-np.pi, np.pi, n))
    h_t, *_ = bm.half_diff(wi, wo)
    fr = diffuse_sr + peak_sr * np.exp(-(h_t / width_rad) ** 2)
    y = np.log(wi[:, 2] * wo[:, 2] * fr)
    a = basis.evaluate_directions(wi, wo, fanout=fanout)
    coef, *_ = np.linalg.lstsq(a, y, rcond=None)
    return coef


def make_dynamic(basis=None, states=(300.0, 600.0, 900.0)):
    basis = basis or bm.SHBasis(8, 2, 2, 0)
    rows = [glossy_log_coefficients(basis, peak_sr=p, width_rad=w, diffuse_sr=d)
            for p, w, d in [(40.0, 0.10, 0.03), (15.0, 0.16, 0.05), (60.0, 0.09, 0.02)]]
    return bm.DynamicBRDF(basis, list(states), np.array(rows[: len(states)]), "temperature_k")


def make_two_state(basis=None):
    """A two-state (extinction x melt fraction) table: 3 x 2 nodes of glossy lobes."""
    basis = basis or bm.SHBasis(8, 2, 2, 0)
    rows = [glossy_log_coefficients(basis, peak_sr=p, width_rad=w, diffuse_sr=d)
            for p, w, d in [(40.0, 0.10, 0.03), (15.0, 0.16, 0.05), (60.0, 0.09, 0.02)]]
    coef = np.array([[rows[(i + j) % 3] for j in range(2)] for i in range(3)])
    return bm.DynamicBRDF(basis, [[0.311, 0.8, 1.5], [0.0, 1.0]], coef, ["extinction", "melt_fraction"])


def _small_table():
    """A tabulated Lambertian-plus-lobe on a coarse grid (envelope outside its range)."""
    th, td, pd = np.linspace(0, 70, 8), np.linspace(0, 80, 9), np.linspace(0, 150, 6)
    h = np.radians(th)[:, None, None]
    v = 0.1 + 2.0 * np.exp(-(h / 0.2) ** 2) + 0.0 * np.radians(td)[None, :, None] + 0.0 * np.radians(pd)[None, None, :]
    return bm.TabulatedBRDF(th, td, pd, v, outside="envelope")


def _small_scattered():
    """A scattered table of 300 random samples of a Lambertian plus a lobe."""
    rng = np.random.default_rng(5)
    wi = bm.spherical_to_vector(rng.uniform(0, 1.4, 300), rng.uniform(-np.pi, np.pi, 300))
    wo = bm.spherical_to_vector(rng.uniform(0, 1.4, 300), rng.uniform(-np.pi, np.pi, 300))
    f = bm.Lambertian(0.3).evaluate(wi, wo) + bm.GaussianLobe(1.0, 0.2).evaluate(wi, wo)
    return bm.ScatteredBRDF.from_samples(wi, wo, f)


def examples():
    """(id, model, state, physical) for every registered model."""
    basis = bm.SHBasis(8, 2, 2, 0)
    sh = bm.SphericalHarmonicBRDF(basis, glossy_log_coefficients(basis))
    dyn = make_dynamic(basis)
    table = bm.StateTable([300.0, 900.0], [1.0, 0.5], "temperature_k")
    out = [
        ("lambertian", bm.Lambertian(0.5), None, True),
        ("lambertian-black", bm.Lambertian(0.0), None, True),
        ("specular-const", bm.Specular(0.9), None, True),
        ("specular-fresnel", bm.Specular.for_material("cu", 1064.0), None, True),
        ("spherical-harmonic", sh, None, False),
        ("dynamic", dyn, 450.0, False),
        ("envelope", bm.Envelope(dyn, base=0.001, multiplier=1.2, fanout_h=0.5), None, False),
        ("sum", bm.Sum([bm.Lambertian(0.2), bm.Specular(0.3), sh]), None, False),
        ("scaled-const", bm.Scaled(bm.Lambertian(0.8), 0.5), None, True),
        ("scaled-table", bm.Scaled(dyn, table), 700.0, False),
        ("abg-fred-defaults", bm.ABg(0.0025, 0.001, 1.8), None, True),
        ("abg-g0", bm.ABg(0.2, 0.0, 0.0), None, True),
        ("gaussian-lobe", bm.GaussianLobe(2.0, 0.1), None, True),
        ("hel-metal", bm.Sum([bm.GaussianLobe(20.0, 0.05), bm.ABg(0.002, 0.001, 2.0), bm.Lambertian(0.05)]), None, True),
        ("table", _small_table(), None, False),
        ("scattered-table", _small_scattered(), None, False),
        ("dynamic-two-state", make_two_state(basis), [0.9, 0.3], False),
        ("envelope-two-state", bm.Envelope(make_two_state(basis), base=0.001), None, False),
        ("sum-two-state", bm.Sum([bm.Lambertian(0.1), bm.Scaled(make_two_state(basis), 0.5)]), [1.2, 0.7], False),
    ]
    for name, p in TS5_PUBLISHED.items():
        out.append((f"ts5-{name}", bm.TorranceSparrow5(**p), None, name in ("cement", "khaki_paint", "forged_steel")))
    return out


EXAMPLES = examples()


@pytest.fixture(params=EXAMPLES, ids=[e[0] for e in EXAMPLES])
def example(request):
    return request.param
