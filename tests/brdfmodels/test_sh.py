"""Real spherical harmonics and the pruned basis (spec sections 5-7)."""

import numpy as np
import pytest
from scipy.special import sph_harm_y

import brdfmodels as bm


@pytest.mark.parametrize("args, size", [((8, 4, 2, 0), 37), ((10, 4, 2, 0), 47), ((8, 0, 2, 0), 11)])
def test_paper_basis_sizes(args, size):
    # Bailey et al. 2008 Sec. IV C and VIII: 37 (stainless), 47 (copper), 11 (isotropic)
    assert bm.SHBasis(*args).size == size
    assert len(bm.SHBasis(*args).columns) == size


def test_full_product_size():
    b = bm.SHBasis(8, 4, 2, 0, separable=False)
    assert b.size == len(b.terms_h) * len(b.terms_d) == 35 * 3


def test_pruning_rules():
    b = bm.SHBasis(6, 2, 6, 4)
    assert all(m <= min(l, 2) for l, m in b.terms_h)
    assert all(m % 2 == 0 and m <= min(l, 4) for l, m in b.terms_d)


@pytest.mark.parametrize("l,m", [(0, 0), (1, 1), (2, -1), (5, 3), (12, -7), (30, 30), (64, 17), (64, 0)])
def test_matches_scipy_without_condon_shortley(l, m):
    rng = np.random.default_rng(l * 100 + m)
    theta = np.concatenate([rng.uniform(0, np.pi, 50), [0.0, np.pi, 1e-9]])
    phi = rng.uniform(-np.pi, np.pi, theta.size)
    y = bm.real_sph_harm(l, m, theta, phi)
    ref = sph_harm_y(l, abs(m), theta, phi) * (-1) ** abs(m)  # remove the CS phase
    if m > 0:
        ref = np.sqrt(2) * ref.real
    elif m < 0:
        ref = np.sqrt(2) * ref.imag
    else:
        ref = ref.real
    np.testing.assert_allclose(y, ref, atol=3e-13 * max(1, np.abs(ref).max()))


def test_orthonormal_by_quadrature():
    # Gauss-Legendre in cos(theta) x uniform phi integrates products up to degree 2L exactly
    lmax = 16
    x, w = np.polynomial.legendre.leggauss(lmax + 2)
    phi = np.linspace(0, 2 * np.pi, 2 * lmax + 4, endpoint=False)
    tt, pp = np.meshgrid(np.arccos(x), phi, indexing="ij")
    ww = np.outer(w, np.full(phi.size, 2 * np.pi / phi.size))
    terms = [(l, m) for l in range(lmax + 1) for m in range(-l, l + 1)]
    ys = np.array([bm.real_sph_harm(l, m, tt, pp).ravel() for l, m in terms])
    gram = (ys * ww.ravel()) @ ys.T
    np.testing.assert_allclose(gram, np.eye(len(terms)), atol=1e-12)


def test_stable_to_degree_64_at_poles():
    for l in (32, 64):
        y = bm.real_sph_harm(l, 0, np.array([0.0, np.pi]), np.array([0.0, 0.0]))
        np.testing.assert_allclose(y, np.sqrt((2 * l + 1) / (4 * np.pi)) * np.array([1, (-1) ** l]), rtol=1e-12)


def test_fan_out():
    assert bm.fan_out(np.pi / 2, 0.6) == pytest.approx(np.pi)
    assert bm.fan_out(0.0, 0.6) == 0.0
    assert bm.fan_out(np.pi / 4, 1.0) == pytest.approx(np.pi / 2)


def test_design_matrix_columns_are_harmonics():
    b = bm.SHBasis(4, 2, 2, 2)
    rng = np.random.default_rng(0)
    th, ph, td, pd = rng.uniform(0, np.pi / 2, 20), rng.uniform(-3, 3, 20), rng.uniform(0, np.pi / 2, 20), rng.uniform(-3, 3, 20)
    y = b.evaluate(th, ph, td, pd, fanout=0.6)
    assert y.shape == (20, b.size)
    for k, col in enumerate(b.columns):
        kind, l, m = col
        ang_t, ang_p = (th, ph) if kind == "h" else (td, pd)
        ref = bm.real_sph_harm(l, m, bm.fan_out(ang_t, 0.6), ang_p)
        np.testing.assert_allclose(y[:, k], ref, atol=1e-14)


@pytest.mark.parametrize("args", [(8, 4, 2, 0, True), (12, 6, 6, 4, True), (5, 5, 7, 3, False), (0, 0, 3, 1, True)])
def test_design_matrix_higher_orders_and_skipped_orders(args):
    # the in-place recurrence: odd difference orders go through scratch rows, the shared
    # constant is kept once (separable), the product form multiplies both parts
    *orders, separable = args
    b = bm.SHBasis(*orders, separable=separable)
    rng = np.random.default_rng(sum(orders))
    n = 40
    th = np.concatenate([rng.uniform(0, np.pi / 2, n - 3), [0.0, np.pi / 2, 1e-12]])
    td = np.concatenate([rng.uniform(0, np.pi / 2, n - 3), [np.pi / 2, 0.0, np.pi / 2 - 1e-12]])
    ph, pd = rng.uniform(-np.pi, np.pi, n), rng.uniform(-np.pi, np.pi, n)
    y = b.evaluate(th, ph, td, pd, fanout=0.6, fanout_h=0.45)
    for k, col in enumerate(b.columns):
        if col[0] == "hd":
            _, lh, mh, ld, md = col
            ref = bm.real_sph_harm(lh, mh, bm.fan_out(th, 0.45), ph) * bm.real_sph_harm(ld, md, bm.fan_out(td, 0.6), pd)
        else:
            kind, l, m = col
            ang_t, ang_p, f = (th, ph, 0.45) if kind == "h" else (td, pd, 0.6)
            ref = bm.real_sph_harm(l, m, bm.fan_out(ang_t, f), ang_p)
        np.testing.assert_allclose(y[:, k], ref, atol=1e-13, err_msg=str(col))


def test_phi_h_terms_vanish_at_mirror():
    # at theta_h = 0 every column with mh > 0 is 0, so the arbitrary phi_h does not matter
    b = bm.SHBasis(8, 4, 2, 0)
    y = b.evaluate([0.0, 0.0], [0.0, 1.0], [0.3, 0.3], [0.0, 0.0])
    np.testing.assert_allclose(y[0], y[1], atol=1e-15)


@pytest.mark.parametrize("bad", [-1, 1.5, "8", 200])
def test_bad_orders(bad):
    with pytest.raises(ValueError, match="lh_max"):
        bm.SHBasis(bad, 0, 0, 0)
