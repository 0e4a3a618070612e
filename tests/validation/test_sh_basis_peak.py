"""Basis selection of the dynamic SH BRDF proven at the specular peak (issue 32 item 5).

The truth is typed in here (numpy only, no library model): an anisotropic specular lobe
in half-vector slopes, elongated across the grooves (x = grooves), whose peak grows and
then shrinks as the surface oxidises (5.9, 7.2 and 1.1 /sr at t = 0, 5, 10 s), whose
centre wanders along the grooves (slope 0.06 t/10 s) and whose widths grow, with a Schlick
factor in theta_d and a diffuse part that rises with time. It is sampled directly
(unsaturated, 2 % log-normal noise), on a flat-screen-like grid of +-26.6 deg around the
specular direction of each test: the peak itself is in the data.

Protocol (seed 000, Sec. V; spec dynamic-sh-brdf.md section 13), typed in: fit with
incidence -20, 0.3, 5, 20, 40 deg (grooves horizontal: plane of incidence along the
grooves) and 20 deg (grooves vertical: plane of incidence across them); predict the
held-out 10 and 30 deg (horizontal) and 40 deg (vertical, the out-of-plane set) at each
state. Goal: log-RMS <= 0.30 on every held-out set at every state, here on the test's truth,
on a GGX truth nobody tuned for, on a more diffuse variant (three noise draws) and on the
grooved metal of brdfmodels.validation sampled at its peak. The error is computed
here from its definition, sqrt(mean(ln(f_model / f_true)^2)), against the noise-free truth.
"""

import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from brdfmodels import validation
from brdfmodels.fitting import fit_dynamic_sh
from brdfmodels.screen import Samples
from brdfmodels.sh import SHBasis

from ._refs import FAST

FIT = ((-20.0, 0.0), (0.3, 0.0), (5.0, 0.0), (20.0, 0.0), (40.0, 0.0), (20.0, 90.0))  # (incidence, groove) deg
HELD = ((10.0, 0.0), (30.0, 0.0), (40.0, 90.0))
TIMES = (0.0, 5.0, 10.0)
GOAL = 0.30


def truth_fr(wi, wo, t_s):
    """f_r [1/sr] of the moving anisotropic lobe plus diffuse part at time t_s [s]."""
    tau = np.asarray(t_s, float) / 10.0
    ks = 0.6 * (1 + 2.0 * np.sin(math.pi * tau)) * np.exp(-1.2 * tau)  # grows, then shrinks
    ax, ay = 0.05 * (1 + 0.5 * tau), 0.14 * (1 + 0.3 * tau)  # slope widths along / across the grooves
    cx = 0.06 * tau  # the lobe centre wanders along the grooves
    kd = 0.03 + 0.05 * tau  # oxide: more diffuse
    h = wi + wo
    h = h / np.linalg.norm(h, axis=1, keepdims=True)
    sx, sy = h[:, 0] / h[:, 2], h[:, 1] / h[:, 2]
    e = (sx - cx) ** 2 / ax**2 + sy**2 / ay**2
    fresnel = 0.6 + 0.4 * (1 - np.sum(h * wi, 1)) ** 5
    return kd / math.pi + ks * fresnel * np.exp(-e) / (4 * math.pi * ax * ay * np.sqrt(wi[:, 2] * wo[:, 2]))


def test_directions(inc_deg, groove_deg, n=31, half_deg=26.6):
    """wi and a flat-screen grid of wo (n x n, +-half_deg about the specular direction)
    in the surface frame; the plane of incidence is at groove_deg from the grooves (x)."""
    a, g = math.radians(inc_deg), math.radians(groove_deg)
    wi = np.array([math.sin(a) * math.cos(g), math.sin(a) * math.sin(g), math.cos(a)])
    spec = np.array([-wi[0], -wi[1], wi[2]])
    v = np.array([-math.sin(g), math.cos(g), 0.0])  # normal of the plane of incidence
    u = np.cross(v, spec)
    t = np.tan(np.radians(np.linspace(-half_deg, half_deg, n)))
    a_, b_ = np.meshgrid(t, t, indexing="ij")
    wo = spec + a_.reshape(-1, 1) * u + b_.reshape(-1, 1) * v
    wo /= np.linalg.norm(wo, axis=1, keepdims=True)
    wo = wo[wo[:, 2] > 0.05]
    return np.broadcast_to(wi, wo.shape).copy(), wo


test_directions.__test__ = False  # a helper, not a test


def make_samples(tests, *, noise=0.02, seed=0, n=31, truth=truth_fr):
    """Directly sampled ``truth`` (no camera, no saturation) of ``tests`` at TIMES."""
    rng = np.random.default_rng(seed)
    wi_l, wo_l, f_l, t_l, id_l = [], [], [], [], []
    for inc, g in tests:
        wi, wo = test_directions(inc, g, n)
        for t in TIMES:
            f_l.append(truth(wi, wo, t) * np.exp(noise * rng.standard_normal(len(wo))))
            wi_l.append(wi), wo_l.append(wo), t_l.append(np.full(len(wo), t)), id_l.append(np.full(len(wo), f"{inc:g}deg-g{g:g}"))
    m = sum(len(f) for f in f_l)
    return Samples(np.vstack(wi_l), np.vstack(wo_l), np.concatenate(f_l), np.concatenate(t_l), np.full(m, np.nan),
                   np.concatenate(id_l), np.zeros(m, int), np.ones(m))


def held_out_errors(model, times=TIMES, truth=truth_fr):
    """(test, time) -> log-RMS of the model against the noise-free ``truth``."""
    out = {}
    for inc, g in HELD:
        wi, wo = test_directions(inc, g)
        for t in times:
            out[(f"{inc:g}deg-g{g:g}", t)] = float(np.sqrt(np.mean(np.log(model.evaluate(wi, wo, state=t) / truth(wi, wo, t)) ** 2)))
    return out


@pytest.fixture(scope="module")
def fit_samples():
    return make_samples(FIT)


def _dynamic(samples, lh, mh, fanout, times=TIMES, smoothing=0.0):
    """One SH fit per state (the library's dynamic fit) with basis (lh, mh, 2, 0)."""
    return fit_dynamic_sh(samples, SHBasis(lh, mh, 2, 0), list(times), state="time_s", fanout=fanout, smoothing=smoothing).model


def _chosen(samples, best, times=TIMES):
    """The dynamic fit with a choose_sh_basis row's setting (its smoothing included)."""
    return _dynamic(samples, best["lh_max"], best["mh_max"], best["fanout"], times=times, smoothing=best["smoothing"])


def _unit(v):
    v = np.asarray(v, float)
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


@FAST
@given(st.lists(st.floats(-1.0, 1.0), min_size=6, max_size=6), st.floats(0.0, 10.0))
def test_truth_is_reciprocal_anisotropic_and_moving(xyz, t):
    """The truth is reciprocal; its peak is where the lobe centre has wandered to (slope
    cx = 0.06 t/10 s along the grooves), and it is wider across the grooves than along."""
    wi = _unit([[xyz[0], xyz[1], 0.2 + abs(xyz[2])]])
    wo = _unit([[xyz[3], xyz[4], 0.2 + abs(xyz[5])]])
    assert truth_fr(wi, wo, t)[0] == pytest.approx(truth_fr(wo, wi, t)[0], rel=1e-12)
    # normal incidence along z: h = normalize(z + wo); h slope s -> wo of slope 2s/(1-s^2)
    cx = 0.06 * t / 10.0
    wi0 = np.array([[0.0, 0.0, 1.0]])

    def at_slope(sx, sy):
        h = _unit([[sx, sy, 1.0]])
        return truth_fr(wi0, 2 * h[0, 2] * h - wi0, t)[0]

    peak = at_slope(cx, 0.0)
    assert peak > at_slope(cx + 0.02, 0.0) and peak > at_slope(cx - 0.02, 0.0)
    assert at_slope(cx, 0.05) > at_slope(cx + 0.05, 0.0)  # wider across (y) than along (x)


def test_samples_hold_the_unsaturated_peak(fit_samples):
    """The data reach the peak (no clipping): at each state the largest sample of the
    0.3 deg test is within the 2 % noise (5 sigma) of the truth's maximum over the
    screen, and the peaks grow and shrink: 5.9, 7.2, 1.1 /sr."""
    wi, wo = test_directions(0.3, 0.0, n=301)
    peaks = []
    for t in TIMES:
        top = truth_fr(wi, wo, t).max()
        got = fit_samples.brdf_per_sr[(fit_samples.test_id == "0.3deg-g0") & (fit_samples.time_s == t)].max()
        assert abs(math.log(got / top)) < 5 * 0.02 + 0.02  # + grid spacing of the 31 x 31 screen
        peaks.append(top)
    assert peaks[1] > peaks[0] > 4.0 and peaks[2] < 0.2 * peaks[1]


def test_smoothing_bounds_the_extrapolation_at_the_first_state():
    """The mechanism of the default (Tikhonov smoothing, issue 32 item 5), fast: on the
    more diffuse variant at t = 0 the truncated-SVD fit with (10, 8, 0.4) predicts the
    out-of-plane set to 0.44 (measured; the erratic extrapolation beyond the elevation the
    fit tests reached), the same basis with the smoothing strength the selection picks
    there, 1e-6, to 0.23 (<= 0.30), the in-plane sets staying at about 0.1."""
    samples = make_samples(FIT, truth=_more_diffuse)
    first = samples.select(samples.time_s == 0.0)
    smooth = held_out_errors(_dynamic(first, 10, 8, 0.4, times=(0.0,), smoothing=1e-6), times=(0.0,), truth=_more_diffuse)
    assert max(smooth.values()) <= GOAL, smooth
    tsvd = held_out_errors(_dynamic(first, 10, 8, 0.4, times=(0.0,)), times=(0.0,), truth=_more_diffuse)
    assert tsvd[("40deg-g90", 0.0)] > GOAL + 0.1
    assert max(v for (k, _), v in tsvd.items() if k != "40deg-g90") < 0.15  # the in-plane sets were fine


@pytest.mark.slow
def test_default_selection_reaches_the_goal_on_every_held_out_set(fit_samples):
    """choose_sh_basis with its defaults, folds per state: its choice, fitted per state,
    predicts every held-out set of the protocol at every state to <= 0.30 log-RMS; the
    unregularised table ranked by the older rule (mean of folds, tolerance 0.3) does not."""
    best, table = validation.choose_sh_basis(fit_samples, state="time_s")
    assert len(table) == 96 * len(validation.DEFAULT_SMOOTHINGS) and all(len(r["fold_log_rms"]) == 6 * len(TIMES) for r in table)
    errs = held_out_errors(_chosen(fit_samples, best))
    assert max(errs.values()) <= GOAL, (best, errs)
    _, tsvd = validation.choose_sh_basis(fit_samples, state="time_s", smoothings=(0.0,))
    old = validation.cheapest_within(tsvd, 0.3, key="held_out_log_rms")
    old_errs = held_out_errors(_chosen(fit_samples, old))
    assert max(old_errs.values()) > GOAL, (old, old_errs)


def ggx_truth_fr(wi, wo, t_s):
    """A second truth, written after the selection rule was set and never used to tune it
    (issue 32 item 5): an anisotropic Trowbridge-Reitz (GGX) lobe, long-tailed unlike the
    Gaussian above, wider across the grooves (slope widths 0.07 / 0.18 growing 80 % / 20 %
    over 10 s), whose centre wanders ACROSS the grooves (slope -0.05 t/10 s), whose
    amplitude falls and partly recovers (0.7 (1 - 0.6 tau + 0.3 tau^2)), Schlick F0 0.9,
    diffuse 0.05 -> 0.07. f_r = kd/pi + ks F D(h) / (4 cos_i cos_r) [1/sr], reciprocal."""
    tau = np.asarray(t_s, float) / 10.0
    ks = 0.7 * (1.0 - 0.6 * tau + 0.3 * tau ** 2)
    ax, ay = 0.07 * (1 + 0.8 * tau), 0.18 * (1 + 0.2 * tau)
    h = wi + wo
    h = h / np.linalg.norm(h, axis=1, keepdims=True)
    sx, sy = h[:, 0] / h[:, 2], h[:, 1] / h[:, 2] + 0.05 * tau
    d = 1.0 / (math.pi * ax * ay * h[:, 2] ** 4 * (1 + sx ** 2 / ax ** 2 + sy ** 2 / ay ** 2) ** 2)
    fresnel = 0.9 + 0.1 * (1 - np.sum(h * wi, 1)) ** 5
    return (0.05 + 0.02 * tau) / math.pi + ks * fresnel * d / (4 * wi[:, 2] * wo[:, 2])


@FAST
@given(st.lists(st.floats(-1.0, 1.0), min_size=6, max_size=6), st.floats(0.0, 10.0))
def test_the_second_truth_is_reciprocal_and_its_peak_moves_across_the_grooves(xyz, t):
    wi = _unit([[xyz[0], xyz[1], 0.2 + abs(xyz[2])]])
    wo = _unit([[xyz[3], xyz[4], 0.2 + abs(xyz[5])]])
    assert ggx_truth_fr(wi, wo, t)[0] == pytest.approx(ggx_truth_fr(wo, wi, t)[0], rel=1e-12)
    cy, wi0 = -0.05 * t / 10.0, np.array([[0.0, 0.0, 1.0]])

    def at_slope(sx, sy):
        h = _unit([[sx, sy, 1.0]])
        return ggx_truth_fr(wi0, 2 * h[0, 2] * h - wi0, t)[0]

    assert at_slope(0.0, cy) > max(at_slope(0.0, cy + 0.02), at_slope(0.0, cy - 0.02), at_slope(0.02, cy))


@pytest.mark.slow
def test_default_selection_reaches_the_goal_on_a_second_untuned_truth():
    """The default selection (folds per state) on the GGX truth, sampled like the first:
    its choice predicts every held-out set at every state to <= 0.30 log-RMS (measured:
    (8, 6, 0.4) with smoothing 1e-5, 0.248 in-plane and 0.218 out-of-plane, worst state;
    the truncated-SVD selection's (4, 2, 0.4): 0.255 / 0.227)."""
    samples = make_samples(FIT, truth=ggx_truth_fr)
    best, _ = validation.choose_sh_basis(samples, state="time_s")
    errs = held_out_errors(_chosen(samples, best), truth=ggx_truth_fr)
    assert max(errs.values()) <= GOAL, (best, errs)


def _more_diffuse(wi, wo, t_s):
    """The first truth with a diffuse part 0.10 instead of 0.03 at t = 0 (+0.07 / pi)."""
    return truth_fr(wi, wo, t_s) + 0.07 / math.pi


@pytest.mark.slow
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_default_selection_on_the_more_diffuse_variant(seed):
    """A strict xfail until the Tikhonov smoothing (issue 32 item 5, later round): the
    truncated-SVD choice (8, 8, 0.4) predicted the out-of-plane set to 0.304-0.308, low by
    up to 12x where the held-out 40 deg vertical-groove screen reaches 69 deg from the normal
    across the grooves (the fit tests: 48 deg). The default selection now predicts every
    held-out set to <= 0.30 for every noise draw."""
    samples = make_samples(FIT, truth=_more_diffuse, seed=seed)
    first = samples.select(samples.time_s == 0.0)
    best, _ = validation.choose_sh_basis(first)
    errs = held_out_errors(_chosen(first, best, times=(0.0,)), times=(0.0,), truth=_more_diffuse)
    assert max(errs.values()) <= GOAL, (best, errs)


def grooved_metal_fr(wi, wo, t_s):
    """The grooved metal of brdfmodels.validation (SyntheticGroovedMetal, its defaults),
    typed in again: kd (1 + 0.3 (s - 0.311)) / pi + ks e^-(s - 0.311) exp(-(hx^2/ax^2 +
    hy^2/ay^2) / hz^2) / (4 pi ax ay sqrt(cos_i cos_r)), widths 0.06 / 0.15 growing 60 % per
    unit of the oxide state s = 0.311 + 0.1189 t [1/s]; ks 0.5, kd 0.03."""
    s = 0.311 + (1.5 - 0.311) * np.asarray(t_s, float) / 10.0
    grow = 1.0 + 0.6 * (s - 0.311)
    ax, ay = 0.06 * grow, 0.15 * grow
    h = wi + wo
    h = h / np.linalg.norm(h, axis=1, keepdims=True)
    e = (h[:, 0] ** 2 / ax ** 2 + h[:, 1] ** 2 / ay ** 2) / h[:, 2] ** 2
    lobe = np.exp(-e) / (4 * math.pi * ax * ay * np.sqrt(wi[:, 2] * wo[:, 2]))
    return 0.03 * (1 + 0.3 * (s - 0.311)) / math.pi + 0.5 * np.exp(-(s - 0.311)) * lobe


@pytest.mark.slow
def test_default_selection_on_the_grooved_metal_sampled_at_its_peak():
    """The grooved metal sampled directly (not through the saturating camera) at t = 0:
    the truncated-SVD choice (8, 6, 0.4) predicted the out-of-plane set to 0.373 (4.4x high
    at 1 % of the directions, beyond the measured elevation); the default selection now
    predicts every held-out set to <= 0.30."""
    samples = make_samples(FIT, truth=grooved_metal_fr)
    first = samples.select(samples.time_s == 0.0)
    best, _ = validation.choose_sh_basis(first)
    errs = held_out_errors(_chosen(first, best, times=(0.0,)), times=(0.0,), truth=grooved_metal_fr)
    assert max(errs.values()) <= GOAL, (best, errs)
