"""The tabulated BRDF against a table built here from a known BRDF: exact at the nodes,
between them a convex combination of its cell's corners (angles computed here from the
definition of Rusinkiewicz's coordinates), reciprocal, an explicit policy outside the
measured range, saved and loaded like any model, and built from a MERL file."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import brdfmodels as bm
import scenes
from brdfmodels.io import read_merl

from .test_io_readers import TRUTH, _merl_bytes

TH = np.linspace(0.0, 80.0, 17)
TD = np.linspace(0.0, 85.0, 18)
PD = np.linspace(0.0, 170.0, 18)


def _directions(th, td, pd):
    """wi, wo from (theta_h, theta_d, phi_d) [rad], phi_h = 0: h = (sin th, 0, cos th),
    d the difference vector in the half frame, wi = R_y(th) d, wo its mirror about h."""
    d = np.array([math.sin(td) * math.cos(pd), math.sin(td) * math.sin(pd), math.cos(td)])
    wi = np.array([math.cos(th) * d[0] + math.sin(th) * d[2], d[1], -math.sin(th) * d[0] + math.cos(th) * d[2]])
    h = np.array([math.sin(th), 0.0, math.cos(th)])
    return wi, 2 * (wi @ h) * h - wi


def _angles(wi, wo):
    """(theta_h, theta_d, phi_d mod pi) [rad] of a pair, from the definition."""
    wi, wo = np.asarray(wi, float) / np.linalg.norm(wi), np.asarray(wo, float) / np.linalg.norm(wo)
    h = (wi + wo) / np.linalg.norm(wi + wo)
    th, ph = math.acos(min(h[2], 1.0)), math.atan2(h[1], h[0])
    c, s = math.cos(-ph), math.sin(-ph)
    x1, y1, z1 = c * wi[0] - s * wi[1], s * wi[0] + c * wi[1], wi[2]
    c, s = math.cos(-th), math.sin(-th)
    d = np.array([c * x1 + s * z1, y1, -s * x1 + c * z1])
    return th, math.acos(max(min(d[2], 1.0), -1.0)), math.atan2(d[1], d[0]) % math.pi


def _table(outside="error"):
    v = np.empty((len(TH), len(TD), len(PD)))
    for i, a in enumerate(np.radians(TH)):
        for j, b in enumerate(np.radians(TD)):
            for k, c in enumerate(np.radians(PD)):
                wi, wo = _directions(a, b, c)
                # below the horizon: the value at the nearest direction above it (not 0)
                v[i, j, k] = float(TRUTH.evaluate(wi * [1, 1, 1] if wi[2] > 0 else wi * [1, 1, 0] + [0, 0, 1e-3],
                                                  wo if wo[2] > 0 else wo * [1, 1, 0] + [0, 0, 1e-3]))
    return bm.TabulatedBRDF(TH, TD, PD, v, outside), v


TABLE, VALUES = _table()


def test_exact_at_the_nodes():
    for i, j, k in [(0, 0, 0), (3, 5, 7), (8, 2, 17), (16, 0, 9), (10, 10, 0)]:
        wi, wo = _directions(*np.radians([TH[i], TD[j], PD[k]]))
        if wi[2] > 0 and wo[2] > 0:
            assert TABLE.evaluate(wi, wo) == pytest.approx(VALUES[i, j, k], rel=1e-12)


def _corners(th, td, pd):
    i = min(np.searchsorted(np.radians(TH), th, side="right") - 1, len(TH) - 2)
    j = min(np.searchsorted(np.radians(TD), td, side="right") - 1, len(TD) - 2)
    k = np.searchsorted(np.radians(PD), pd, side="right") - 1
    ks = [k, (k + 1) % len(PD)]
    return VALUES[np.ix_([i, i + 1], [j, j + 1], ks)]


@settings(max_examples=200, deadline=None)
@given(th=st.floats(0.0, 1.39), td=st.floats(0.0, 1.48), pd=st.floats(0.0, 6.28), ph=st.floats(-3.1, 3.1))
def test_between_nodes_within_the_cells_corners_and_reciprocal(th, td, pd, ph):
    wi, wo = _directions(th, td, pd)
    c, s = math.cos(ph), math.sin(ph)  # turn the pair about the normal: isotropic
    rot = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    wi, wo = rot @ wi, rot @ wo
    if wi[2] <= 1e-6 or wo[2] <= 1e-6:
        return
    a, b, p = _angles(wi, wo)
    corners = _corners(a, b, p)
    f = float(TABLE.evaluate(wi, wo))
    assert corners.min() * (1 - 1e-12) <= f <= corners.max() * (1 + 1e-12)
    assert float(TABLE.evaluate(wo, wi)) == pytest.approx(f, rel=1e-12)


def test_outside_the_measured_range_follows_the_policy():
    wi, wo = _directions(math.radians(85.0), math.radians(3.0), 0.5)  # theta_h 85 deg > 80: outside
    with pytest.raises(ValueError, match=r"outside the table: theta_h 85 deg.*outside = 'envelope' or 'fit'"):
        TABLE.evaluate(wi, wo)
    env, _ = _table("envelope")
    assert env.evaluate(wi, wo) == pytest.approx(VALUES.max(), rel=1e-12)
    fit, _ = _table("fit")
    got = float(fit.evaluate(wi, wo))
    assert np.isfinite(got) and got > 0


def test_saved_loaded_and_used_by_a_scene(tmp_path):
    from tests._scene_text import PLATE_AT_50M

    bm.save(TABLE.__class__(TH, TD, PD, VALUES, "envelope"), tmp_path / "table.json")
    m = bm.load(tmp_path / "table.json")
    assert m == bm.TabulatedBRDF(TH, TD, PD, VALUES, "envelope")
    (tmp_path / "s.toml").write_text(PLATE_AT_50M.replace('{ model = "lambertian", reflectance = 0.5 }', '{ file = "table.json" }'))
    s = scenes.load(tmp_path / "s.toml")
    assert s.targets[0].material == m


def test_from_merl(tmp_path):
    (tmp_path / "m.binary").write_bytes(_merl_bytes((9, 9, 18), TRUTH))
    t = bm.TabulatedBRDF.from_merl(tmp_path / "m.binary", channel="R")
    s = read_merl(tmp_path / "m.binary", channel="R")
    np.testing.assert_allclose(t.evaluate(s.wi, s.wo), s.brdf_per_sr, rtol=1e-9)  # the cell centres are its nodes


def test_a_scene_names_a_measured_table_by_model_and_file(tmp_path):
    from tests._scene_text import PLATE_AT_50M

    (tmp_path / "m.binary").write_bytes(_merl_bytes((9, 9, 18), TRUTH))
    bm.save(bm.TabulatedBRDF(TH, TD, PD, VALUES, "error"), tmp_path / "t.json")
    for mat, outside in (('{ model = "table", file = "m.binary" }', "envelope"),
                         ('{ model = "table", file = "m.binary", outside = "fit", channel = "G" }', "fit"),
                         ('{ model = "table", file = "t.json", outside = "envelope" }', "envelope")):
        (tmp_path / "s.toml").write_text(PLATE_AT_50M.replace('{ model = "lambertian", reflectance = 0.5 }', mat))
        m = scenes.load(tmp_path / "s.toml").targets[0].material
        assert isinstance(m, bm.TabulatedBRDF) and m.outside == outside
    (tmp_path / "s.toml").write_text(PLATE_AT_50M.replace('{ model = "lambertian", reflectance = 0.5 }',
                                                          '{ model = "table", file = "m.binary", outside = "maybe" }'))
    with pytest.raises(scenes.SceneError, match="outside='maybe'"):
        scenes.load(tmp_path / "s.toml")


def _random_pairs(n, seed):
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(n):
        a = _directions(rng.uniform(0, 1.5), rng.uniform(0, 1.5), rng.uniform(0, 2 * math.pi))
        if a[0][2] > 1e-3 and a[1][2] > 1e-3:
            out.append(a)
    return np.array([p[0] for p in out]), np.array([p[1] for p in out])


def test_gridding_scattered_samples_honours_the_samples_at_the_nodes():
    """Samples placed at the nodes (directions from the definition of the coordinates)
    come back at those nodes; every other node lies within the samples' range (a convex
    combination of neighbours, or the envelope of the nearest: never beyond the largest)."""
    th, td, pd = np.arange(0, 90, 10.0), np.arange(0, 90, 10.0), np.arange(0, 180, 30.0)
    pairs, at = [], []
    for i, a in enumerate(th):
        for j, b in enumerate(td):
            for k, c in enumerate(pd):
                wi, wo = _directions(*np.radians([a, b, c]))
                if wi[2] > 1e-3 and wo[2] > 1e-3:
                    pairs.append((wi, wo))
                    at.append((i, j, k))
    wi, wo = np.array([p[0] for p in pairs]), np.array([p[1] for p in pairs])
    f = TRUTH.evaluate(wi, wo)
    m = bm.TabulatedBRDF.from_samples(wi, wo, f, th, td, pd)
    got = np.array([m.values[i, j, k] for i, j, k in at])
    np.testing.assert_allclose(got, f, rtol=1e-7)  # the 1e-9 rad joggle of the triangulation
    assert f.min() * (1 - 1e-12) <= m.values.min() and m.values.max() <= f.max() * (1 + 1e-12)


def test_a_scene_grids_a_bsdf_file_into_a_table(tmp_path):
    from tests._scene_text import PLATE_AT_50M

    from .test_io_readers import _bsdf_text

    text, _ = _bsdf_text([0, 20, 40, 60], list(range(0, 181, 30)), [0, 2, 5, 10, 20, 40, 60, 80])
    (tmp_path / "m.bsdf").write_text(text)
    mat = '{ model = "table", file = "m.bsdf", grid_deg = [5.0, 5.0, 30.0], fill = "fit" }'
    (tmp_path / "s.toml").write_text(PLATE_AT_50M.replace('{ model = "lambertian", reflectance = 0.5 }', mat))
    sc = scenes.load(tmp_path / "s.toml")
    m = sc.targets[0].material
    # theta_h, theta_d: 0, 5, ..., 85 and the end node 90 (nothing beyond the grid); phi_d 0-150
    assert isinstance(m, bm.TabulatedBRDF) and m.values.shape == (19, 19, 6) and np.all(np.isfinite(m.values))
    s = bm.io.read_bsdf(tmp_path / "m.bsdf")
    low = float(np.min(m.evaluate(s.wi, s.wo) / s.brdf_per_sr))  # the grid cuts the lobe between its nodes: said
    assert low < 0.99 and any(f"down to {100 * low:.3g} % of a measured sample" in w for w in sc.warnings), sc.warnings
