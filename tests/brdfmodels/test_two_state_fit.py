"""Two-state dynamic SH fits (issue 19): Samples' named state columns, grouping on two
states, fit_dynamic_sh over (extinction, melt_fraction), the synthetic melting-steel truth
and the bundled stainless_melt material made from it."""

from __future__ import annotations

import math

import numpy as np
import pytest

import brdfmodels as bm
import scenes
from brdfmodels import fitting, screen
from brdfmodels.melt_truth import SyntheticMeltingSteel
from brdfmodels.validation import SyntheticGroovedMetal

NAMES = ["extinction", "melt_fraction"]
XI = np.array([0.311, 0.8, 1.5])
M = np.array([0.0, 1.0])


def _hemisphere(rng, n, min_cos=0.15):
    c = rng.uniform(min_cos, 1.0, n)
    p = rng.uniform(-math.pi, math.pi, n)
    s = np.sqrt(1.0 - c * c)
    return np.stack([s * np.cos(p), s * np.sin(p), c], axis=1)


def _known_model(basis):
    """A two-state DynamicBRDF from known coefficients (a constant plus small harmonics)."""
    rng = np.random.default_rng(7)
    coef = 0.3 * rng.standard_normal((XI.size, M.size, basis.size))
    coef[..., 0] += 2.0
    return bm.DynamicBRDF(basis, [XI, M], coef, NAMES)


def _node_samples(model, nodes, rng, n=600):
    """Noise-free samples of ``model`` at each state pair of ``nodes``, carrying the pair
    exactly in their state columns."""
    parts = []
    for k, (a, b) in enumerate(nodes):
        wi, wo = _hemisphere(rng, n), _hemisphere(rng, n)
        f = model.evaluate(wi, wo, state=[a, b])
        s = screen.Samples(wi, wo, f, np.zeros(n), np.full(n, np.nan), np.full(n, f"node{k}", dtype=object),
                           np.zeros(n, int), np.ones(n))
        parts.append(s.with_states({"extinction": a, "melt_fraction": b}))
    return screen.Samples.concatenate(parts)


def _grid(xi=XI, m=M):
    return [(float(a), float(b)) for a in xi for b in m]


# -- fit_dynamic_sh over two states ---------------------------------------------------------
def test_two_state_fit_recovers_known_coefficients():
    basis = bm.SHBasis(4, 2, 2, 0)
    truth = _known_model(basis)
    samples = _node_samples(truth, _grid(), np.random.default_rng(0))
    fit = fitting.fit_dynamic_sh(samples, basis, [XI, M], state=NAMES, horizon=False, rcond=1e-12)
    model = fit.model
    assert model.state_dim == 2 and tuple(model.state_name) == tuple(NAMES)
    assert model.coefficients.shape == (XI.size, M.size, basis.size)
    np.testing.assert_allclose(model.coefficients, truth.coefficients, rtol=0, atol=1e-9)
    assert set(fit.fits) == set(_grid())
    # between the nodes too: bilinear in the same coefficients
    rng = np.random.default_rng(1)
    wi, wo = _hemisphere(rng, 200), _hemisphere(rng, 200)
    st = np.c_[rng.uniform(XI[0], XI[-1], 200), rng.uniform(0, 1, 200)]
    np.testing.assert_allclose(model.evaluate(wi, wo, state=st), truth.evaluate(wi, wo, state=st), rtol=1e-8)


def test_two_state_grouping_takes_the_nearest_node_per_axis():
    rng = np.random.default_rng(2)
    n = 6
    s = screen.Samples(_hemisphere(rng, n), _hemisphere(rng, n), np.ones(n), np.zeros(n), np.full(n, np.nan),
                       np.array(["t"] * n, dtype=object), np.zeros(n, int), np.ones(n),
                       states={"extinction": [0.30, 0.5, 0.6, 1.2, 1.6, 0.79], "melt_fraction": [0.1, 0.49, 0.51, 0.9, 0.0, 0.2]})
    groups = screen.group_by_states(s, NAMES, [XI, M])
    # nearest per axis: xi 0.30 -> 0.311, 0.5 -> 0.311 (0.189 < 0.3), 0.6 -> 0.8, 1.2 -> 1.5 (0.3 < 0.4),
    # 1.6 -> 1.5, 0.79 -> 0.8; m below 0.5 -> 0, above -> 1
    want = {(0.311, 0.0): [0, 1], (0.8, 1.0): [2], (1.5, 1.0): [3], (1.5, 0.0): [4], (0.8, 0.0): [5]}
    assert set(groups) == set(want)
    for key, rows in want.items():
        np.testing.assert_array_equal(groups[key].states["extinction"], np.asarray(s.states["extinction"])[rows])


def test_two_state_fit_names_the_missing_nodes():
    basis = bm.SHBasis(4, 2, 2, 0)
    nodes = [g for g in _grid() if g not in ((0.8, 1.0), (1.5, 0.0))]
    samples = _node_samples(_known_model(basis), nodes, np.random.default_rng(3), n=80)
    with pytest.raises(ValueError) as exc:
        fitting.fit_dynamic_sh(samples, basis, [XI, M], state=NAMES)
    text = str(exc.value)
    assert "(0.8, 1.0)" in text and "(1.5, 0.0)" in text and "3 x 2 grid" in text, text
    assert "(0.311, 0.0)" not in text


def test_two_state_fit_bad_arguments():
    basis = bm.SHBasis(4, 2, 2, 0)
    samples = _node_samples(_known_model(basis), _grid(), np.random.default_rng(4), n=60)
    with pytest.raises(ValueError, match=r"states: expected two node arrays \[nodes of extinction, nodes of melt_fraction\]"):
        fitting.fit_dynamic_sh(samples, basis, XI, state=NAMES)
    with pytest.raises(ValueError, match=r"state=\['extinction', 'extinction'\]: expected"):
        fitting.fit_dynamic_sh(samples, basis, [XI, XI], state=["extinction", "extinction"])
    with pytest.raises(ValueError, match=r"state='oxide': expected 'temperature_k', 'time_s' or a state column"):
        fitting.fit_dynamic_sh(samples, basis, [XI, M], state=["oxide", "melt_fraction"])
    with pytest.raises(ValueError, match=r"strictly increasing"):
        fitting.fit_dynamic_sh(samples, basis, [XI[::-1], M], state=NAMES)
    # a node whose group is too small for the basis names the node
    few = samples.select(np.r_[np.ones(60 * 5, bool), np.zeros(60, bool)])
    few = screen.Samples.concatenate([few, _node_samples(_known_model(basis), [(1.5, 1.0)], np.random.default_rng(5), n=5)])
    with pytest.raises(ValueError, match=r"state extinction=1.5, melt_fraction=1: underdetermined fit: 5 samples"):
        fitting.fit_dynamic_sh(few, basis, [XI, M], state=NAMES)


def test_one_state_fit_on_a_named_column():
    """The one-state path groups on a named state column as on time_s."""
    basis = bm.SHBasis(4, 2, 2, 0)
    coef = _known_model(basis).coefficients[:, 0, :]
    truth = bm.DynamicBRDF(basis, XI, coef, "extinction")
    rng = np.random.default_rng(6)
    parts = []
    for a in XI:
        wi, wo = _hemisphere(rng, 300), _hemisphere(rng, 300)
        parts.append(screen.Samples(wi, wo, truth.evaluate(wi, wo, state=a), np.zeros(300), np.full(300, np.nan),
                                    np.array(["t"] * 300, dtype=object), np.zeros(300, int), np.ones(300),
                                    states={"extinction": np.full(300, a)}))
    fit = fitting.fit_dynamic_sh(screen.Samples.concatenate(parts), basis, XI, state="extinction", horizon=False, rcond=1e-12)
    assert fit.model.state_name == "extinction"
    np.testing.assert_allclose(fit.model.coefficients, coef, rtol=0, atol=1e-9)


# -- Samples state columns ----------------------------------------------------------------------
def _table():
    rng = np.random.default_rng(8)
    n = 7
    s = screen.Samples(_hemisphere(rng, n), _hemisphere(rng, n), rng.uniform(0.1, 3, n), np.arange(n) * 0.5,
                       np.full(n, 900.0), np.array([f"t{k % 2}" for k in range(n)], dtype=object), np.arange(n), np.ones(n))
    return s.with_states({"extinction": rng.uniform(0.3, 2.0, n), "melt_fraction": np.r_[0.0, 0.0, 0.25, 0.5, 1.0, 1.0, np.nan]})


def _same(a, b):
    np.testing.assert_array_equal(a.wi, b.wi)
    np.testing.assert_array_equal(a.brdf_per_sr, b.brdf_per_sr)
    assert list(a.states) == list(b.states)
    for k in a.states:
        np.testing.assert_array_equal(a.states[k], b.states[k])
    assert [str(x) for x in a.test_id] == [str(x) for x in b.test_id]


def test_state_columns_survive_csv(tmp_path):
    s = _table()
    s.write(tmp_path / "s.csv")
    header = (tmp_path / "s.csv").read_text().splitlines()[0].split(",")
    assert header == [*screen.Samples.COLUMNS, "extinction", "melt_fraction"]
    _same(s, screen.Samples.read(tmp_path / "s.csv"))


def test_state_columns_survive_parquet(tmp_path):
    pytest.importorskip("pyarrow")
    s = _table()
    s.write(tmp_path / "s.parquet")
    _same(s, screen.Samples.read(tmp_path / "s.parquet"))


def test_old_tables_without_state_columns_still_load(tmp_path):
    s = _table()
    old = screen.Samples(s.wi, s.wo, s.brdf_per_sr, s.time_s, s.temperature_k, s.test_id, s.frame_id, s.weight)
    old.write(tmp_path / "old.csv")
    assert (tmp_path / "old.csv").read_text().splitlines()[0] == ",".join(screen.Samples.COLUMNS)
    back = screen.Samples.read(tmp_path / "old.csv")
    assert back.states == {} and len(back) == len(s)
    np.testing.assert_array_equal(back.time_s, s.time_s)


def test_state_columns_through_select_and_concatenate():
    s = _table()
    sub = s.select(s.time_s >= 1.0)
    np.testing.assert_array_equal(sub.states["extinction"], s.states["extinction"][s.time_s >= 1.0])
    plain = screen.Samples(s.wi[:2], s.wo[:2], s.brdf_per_sr[:2], s.time_s[:2], s.temperature_k[:2], s.test_id[:2],
                           s.frame_id[:2], s.weight[:2])
    both = screen.Samples.concatenate([s, plain])
    assert len(both) == len(s) + 2 and list(both.states) == ["extinction", "melt_fraction"]
    assert np.all(np.isnan(both.states["extinction"][-2:]))  # missing there: nan
    with pytest.raises(ValueError, match=r"state='extinction': 2 samples have no extinction"):
        screen.group_by_state(both, "extinction", XI)


def test_state_column_checks():
    s = _table()
    with pytest.raises(ValueError, match=r"states\['extinction'\]: expected shape \(7,\)"):
        s.with_states({"extinction": [1.0, 2.0]})
    with pytest.raises(ValueError, match=r"column name 'time_s': expected a non-empty name other than"):
        s.with_states({"time_s": np.zeros(len(s))})
    with pytest.raises(ValueError, match=r"state='melt': expected 'temperature_k', 'time_s' or a state column of the samples "
                                         r"\(\['extinction', 'melt_fraction'\]\)"):
        screen.group_by_state(s, "melt", [0.0, 1.0])
    with pytest.raises(ValueError, match=r"state='melt_fraction': 1 samples have no melt_fraction"):
        screen.group_by_states(s, NAMES, [XI, M])


def test_csv_with_a_short_row_names_the_line(tmp_path):
    s = _table()
    s.write(tmp_path / "s.csv")
    lines = (tmp_path / "s.csv").read_text().splitlines()
    lines[3] = ",".join(lines[3].split(",")[:-1])
    (tmp_path / "bad.csv").write_text("\n".join(lines) + "\n")
    with pytest.raises(ValueError, match=r"bad.csv: line 4: expected 14 values, got 13"):
        screen.Samples.read(tmp_path / "bad.csv")


# -- the synthetic melting-steel truth ----------------------------------------------------------
def _peak_by_hand(xi, m, theta_i):
    """The class docstring's formulas, written out: kd/pi + ks/(4 pi ax ay cos_i) with
    log-linear blends in m of the oxidised solid at xi and the molten values."""
    ks, kd, ax, ay = 0.5, 0.03, 0.06, 0.15
    d = xi - 0.311
    g = 1.0 + 0.6 * d
    solid = (ks * math.exp(-d), ax * g, ay * g, kd * (1 + 0.3 * d))
    a_m = math.sqrt(ax * ay * 1.0 / 1.3)
    molten = (ks, a_m, a_m, kd)
    k_s, a_x, a_y, k_d = (s ** (1 - m) * v**m for s, v in zip(solid, molten))
    return k_d / math.pi + k_s / (4 * math.pi * a_x * a_y * math.cos(theta_i))


@pytest.mark.parametrize("theta_deg", [0.3, 20.0, 40.0])
def test_melting_truth_peak_falls_with_oxide_and_recovers_above_initial(theta_deg):
    truth = SyntheticMeltingSteel()
    th = math.radians(theta_deg)
    wi = bm.spherical_to_vector(th, 0.7)
    wo = bm.mirror_direction(wi)
    peak = lambda xi, m: float(truth.evaluate(wi, wo, state=[xi, m]))
    for xi, m in [(0.311, 0.0), (1.4, 0.0), (1.4, 0.5), (2.3, 1.0), (0.311, 1.0), (0.9, 0.25)]:
        assert peak(xi, m) == pytest.approx(_peak_by_hand(xi, m, th), rel=1e-12)
    fresh = peak(0.311, 0.0)
    # before melting the peak falls with oxidation (paper Secs. V B 2, VIII B) ...
    pre = [peak(xi, 0.0) for xi in (0.311, 0.6, 1.0, 1.4, 2.0)]
    assert all(b < a for a, b in zip(pre, pre[1:])) and pre[3] < 0.15 * fresh
    # ... and melting brings it back, at full melt above the initial value (1.3x the lobe)
    during = [peak(1.4, m) for m in (0.0, 0.25, 0.5, 0.75, 1.0)]
    assert all(b > a for a, b in zip(during, during[1:]))
    assert 1.29 * fresh < peak(1.4, 1.0) < 1.3 * fresh
    assert peak(1.4, 1.0) == pytest.approx(peak(9.0, 1.0), rel=1e-14)  # molten: the oxide is gone


def test_melting_truth_is_the_grooved_metal_before_melting_and_reciprocal():
    truth = SyntheticMeltingSteel()
    rng = np.random.default_rng(9)
    wi, wo = _hemisphere(rng, 300, 0.05), _hemisphere(rng, 300, 0.05)
    for xi in (0.311, 0.9, 1.5):
        np.testing.assert_allclose(truth.evaluate(wi, wo, state=[xi, 0.0]), SyntheticGroovedMetal().evaluate(wi, wo, state=xi),
                                   rtol=1e-14)
    st = np.c_[rng.uniform(0.311, 3.0, 300), rng.uniform(0.0, 1.0, 300)]
    np.testing.assert_allclose(truth.evaluate(wi, wo, state=st), truth.evaluate(wo, wi, state=st), rtol=1e-13)
    # molten: isotropic (no groove direction left)
    np.testing.assert_allclose(truth.evaluate(wi, wo, state=[1.0, 1.0]),
                               truth.evaluate(bm.rotate_about_normal(wi, 0.9), bm.rotate_about_normal(wo, 0.9), state=[1.0, 1.0]),
                               rtol=1e-12)
    assert truth.state_dim == 2 and truth.state_name == ("extinction", "melt_fraction")
    with pytest.raises(ValueError, match=r"melt_fraction=1.5: expected values in \[0, 1\]"):
        truth.evaluate(wi[:1], wo[:1], state=[1.0, 1.5])
    with pytest.raises(ValueError, match=r"state: SyntheticMeltingSteel depends on the pair"):
        truth.evaluate(wi[:1], wo[:1], state=1.0)


def test_witness_screen_films_a_two_state_truth():
    """simulate_test takes a pair per frame; noise-free frames reduce back to the truth."""
    truth = SyntheticMeltingSteel()
    pairs = np.array([[0.311, 0.0], [1.4, 0.5]])
    test = screen.simulate_test(truth, times_s=(0.0, 1.0), state_of_time=lambda t: pairs[int(t)], noise=0.0,
                                gain_counts=5.0, pixels=(24, 24))
    s = screen.reduce_test(test)
    node = s.time_s.astype(int)
    want = truth.evaluate(s.wi, s.wo, state=pairs[node])
    np.testing.assert_allclose(s.brdf_per_sr, want, rtol=1e-9)


# -- the bundled example material ---------------------------------------------------------------
def test_stainless_melt_material():
    path = scenes.example_path("stainless_melt").parent / "stainless_melt_brdf.json"
    assert path.stat().st_size < 300_000
    model = bm.load(path)
    assert isinstance(model, bm.DynamicBRDF) and tuple(model.state_name) == tuple(NAMES)
    (xi_lo, xi_hi), (m_lo, m_hi) = model.state_range
    assert xi_lo == pytest.approx(0.311) and xi_hi >= 16.0 and (m_lo, m_hi) == (0.0, 1.0)
    wi = bm.spherical_to_vector(math.radians(20.0), 0.0)
    wo = bm.mirror_direction(wi)
    peak = lambda xi, m: float(model.evaluate(wi, wo, state=[xi, m]))
    truth = SyntheticMeltingSteel()
    for xi, m in [(0.311, 0.0), (1.4, 0.0), (1.4, 1.0)]:  # the fit follows the truth's peak within 10 %
        assert peak(xi, m) == pytest.approx(float(truth.peak(xi, m, math.radians(20.0))), rel=0.1)
    assert peak(1.4, 0.0) < 0.2 * peak(0.311, 0.0) and peak(1.4, 1.0) > 1.2 * peak(0.311, 0.0)
