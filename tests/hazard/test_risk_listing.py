"""Issue 34 item 3: risk shows where the risk is.

The listings (``hazard risk``'s lines, risk.html, the review page's section) put the
resolved points (an exceedance seen) first by the estimate, ties by the upper bound, and
the unresolved (zero hits: only the upper bound) apart; the hazard ratio's quantiles
among the lit draws (an all-zero column is explained); the map picture draws the estimate
where resolved and hatches the cells where only a bound is known.

Expected values come from the definitions (inverted-CDF quantiles by numpy, integer
weights by repetition), not from the functions under test.
"""

from __future__ import annotations

import importlib.util
import io
import re

import markupsafe
import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from hazard.cli import _risk_listing
from hazard.outputs.risk_page import (MAP_LEVELS, UNRESOLVED_COLOUR, ZERO_QUANTILES, map_layers, map_png, risk_page, split_rows,
                              statement_section)
from hazard.drivers.risk.results import lit_quantiles
from tests.validation._refs import FAST, SLOW

HAS_MPL = importlib.util.find_spec("matplotlib") is not None
DRAWS = 20000


def _row(name, p, hi, hits, q=(0.0, 0.0, 0.0), lit=0.005):
    return {"name": name, "position_m": [0.0, 0.0, 1.7], "optical_gain": 1.0, "probability_exceed": p, "probability_ci_low": 0.0,
            "probability_ci_high": hi, "ci_method": "clopper-pearson-effective", "hits": hits, "effective_draws": float(DRAWS),
            "hazard_ratio_quantiles": dict(zip(("p50", "p95", "p99"), q)),
            "irradiance_quantiles_w_m2": dict(zip(("p50", "p95", "p99"), q)), "lit_fraction": lit,
            "hazard_ratio_quantiles_lit": {"p50": 0.2, "p95": 1.5, "p99": 3.0} if lit else {"p50": None, "p95": None, "p99": None},
            "aided": [], "operations": None, "sensitivity": None,
            "statement": f"P(E > MPE) = {p:g}, 95 % CI [0, {hi:g}], {DRAWS:,} draws ({name})"}


def _issue_doc():
    """The issue's run: the hot spot P = 1.5e-4, one P = 2e-14 (importance weights: a wide
    bound) and nineteen zeros whose zero-hit bound is above the hot spot's upper bound."""
    rows = [_row(f"zero-{k}", 0.0, 4.6e-3, 0) for k in range(19)]
    rows.insert(5, _row("tiny", 2e-14, 4.6e-3, 1))
    rows.insert(12, _row("hot", 1.5e-4, 3.1e-4, 14))
    rows.insert(3, _row("warm", 1e-5, 4.6e-3, 2))
    rows.insert(7, _row("warm-tie", 1e-5, 6e-3, 3))
    return {"scene": "risk", "draws": DRAWS, "duration_s": 10.0, "operations": 500, "observers": rows, "inputs": [], "notes": [],
            "left_out": [], "files": [], "map": None, "mpe_w_m2": 50.0, "mpe": "x", "standard": "ansi", "criterion": "c",
            "scene_sha256": "0" * 64, "run": {}}


def test_the_hot_spot_comes_first_and_the_zeros_apart():
    doc = _issue_doc()
    resolved, unresolved = split_rows(doc["observers"])
    assert [r["name"] for r in resolved] == ["hot", "warm-tie", "warm", "tiny"]  # estimate, ties by the upper bound
    assert [r["name"] for r in unresolved] == [f"zero-{k}" for k in range(19)]  # equal bounds: risk.json's order kept
    buf = io.StringIO()
    _risk_listing(doc, buf)
    lines = buf.getvalue().splitlines()
    assert lines[0].startswith("  resolved") and "4 point(s)" in lines[0]
    assert "(hot)" in lines[1] and "(warm-tie)" in lines[2] and "(tiny)" in lines[4]
    assert lines[5].startswith("  unresolved") and "19 point(s)" in lines[5] and "0.0046" in lines[5]
    assert lines[-1] == "    ... 14 more unresolved point(s) in risk.csv"


def test_page_lists_resolved_and_unresolved_in_labelled_tables(tmp_path):
    doc = _issue_doc()
    page = risk_page(doc, tmp_path)
    head, rest = page.split('id="risk-table-unresolved"', 1)
    resolved_cells = re.findall(r'<td class="stmt">(.*?)</td>', head)
    assert [re.search(r"\(([^()]*)\)$", c).group(1) for c in resolved_cells] == ["hot", "warm-tie", "warm", "tiny"]
    assert len(re.findall(r'<td class="stmt">', rest)) == 19
    assert "Resolved points" in head and "Unresolved points" in head
    assert re.search(r"4 resolved \(at least one exceedance in the 20\W000 draws\), 19 unresolved", page)
    assert markupsafe.escape(ZERO_QUANTILES) in page  # the 0 / 0 / 0 column is explained
    assert "lit in 0.5 % of the operations; then 0.2 / 1.5 / 3</td>" in page


def test_no_sentence_without_an_all_zero_quantile_row():
    doc = _issue_doc()
    doc["observers"] = [_row("a", 0.3, 0.35, 6000, q=(0.1, 2.0, 4.0), lit=0.9), _row("b", 0.0, 1.5e-4, 0, q=(0.0, 1e-3, 0.1), lit=0.2)]
    st = statement_section(doc)
    assert st["zero_quantiles"] == "" and st["resolved"]["total"] == 1 and st["unresolved"]["total"] == 1


def _inverted_cdf(v, q):
    return float(np.quantile(v, q, method="inverted_cdf"))


@FAST
@given(st.integers(0, 2**32 - 1), st.floats(0.0, 0.999))
def test_lit_quantiles_are_the_quantiles_of_the_lit_draws(seed, p_dark):
    rng = np.random.default_rng(seed)
    own = rng.lognormal(0.0, 2.0, (300, 4)) * (rng.random((300, 4)) >= p_dark)
    own[:, 3] = 0.0  # a point never lit
    frac, q = lit_quantiles(own, None)
    for j in range(3):
        lit = own[:, j][own[:, j] > 0]
        assert frac[j] == pytest.approx(len(lit) / 300, abs=1e-15)
        for i, x in enumerate((0.5, 0.95, 0.99)):
            if len(lit):
                assert q[i, j] == _inverted_cdf(lit, x)
            else:
                assert np.isnan(q[i, j])
    assert frac[3] == 0.0 and np.isnan(q[:, 3]).all()


@pytest.mark.slow
@SLOW
@given(st.integers(0, 2**32 - 1))
def test_lit_quantiles_weighted_equal_repeated_draws(seed):
    """Integer weights: the weighted quantiles are those of the draws repeated weight times."""
    rng = np.random.default_rng(seed)
    own = rng.lognormal(0.0, 1.0, (60, 2)) * (rng.random((60, 2)) < 0.6)
    w = rng.integers(1, 6, 60).astype(float)
    frac, q = lit_quantiles(own, w)
    for j in range(2):
        rep = np.repeat(own[:, j], w.astype(int))
        lit = rep[rep > 0]
        assert frac[j] == pytest.approx(len(lit) / len(rep), rel=1e-12)
        for i, x in enumerate((0.5, 0.95, 0.99)):
            assert q[i, j] == _inverted_cdf(lit, x)


def test_lit_quantiles_weighted_small_case():
    own = np.array([[0.0], [1.0], [2.0], [3.0]])
    frac, q = lit_quantiles(own, np.array([5.0, 1.0, 1.0, 2.0]))
    assert frac[0] == pytest.approx(4 / 9, rel=1e-12)
    # lit draws 1, 2, 3 with weights 1, 1, 2: CDF 0.25, 0.5, 1 -> p50 = 2, p95 = p99 = 3
    assert q[:, 0].tolist() == [2.0, 3.0, 3.0]


def _cells():
    """A 6 x 5 map (10 m cells): two resolved cells, one below the floor, the rest zero hits."""
    xs, ys = np.meshgrid(np.arange(5) * 10.0, np.arange(6) * 10.0)
    x, y = xs.ravel(), ys.ravel()
    hits = np.zeros(x.size)
    p = np.zeros(x.size)
    hi = np.full(x.size, 1.8e-4)
    hits[7], p[7], hi[7] = 40, 2e-3, 2.8e-3  # x 20, y 10
    hits[22], p[22], hi[22] = 1, 5e-8, 9e-4  # below the floor 1e-6
    return {"x": x, "y": y, "hi": hi, "p": p, "hits": hits}


def test_map_layers_estimate_where_resolved_bound_where_not():
    lay = map_layers(_cells(), 10.0)
    assert lay["resolved_cells"] == 2 and lay["unresolved_cells"] == 28 and lay["below_floor"] == 1
    assert lay["bound"] == 1.8e-4 and lay["estimate"][1, 2] == 2e-3 and lay["unresolved"][0, 0] and not lay["unresolved"][1, 2]
    assert np.isnan(lay["estimate"][lay["unresolved"]]).all()
    legacy = map_layers({**_cells(), "p": None, "hits": None}, 10.0)
    assert legacy["legacy"] and legacy["unresolved_cells"] == 30 and legacy["bound"] == 2.8e-3


@pytest.mark.skipif(not HAS_MPL, reason="matplotlib not installed")
def test_map_picture_draws_the_estimate_and_hatches_the_rest():
    from matplotlib import colormaps
    from matplotlib.image import imread

    doc = {"scene": "s", "draws": DRAWS, "observers": [], "map": {"spacing_m": 10.0, "eye_height_m": 1.7}}
    png, seen = map_png(doc, _cells())
    assert seen["unresolved_cells"] == 28 and seen["resolved_cells"] == 2
    assert any("P <= 1.8e-4" in s and re.search(r"no exceedance in 20\W000 draws", s) for s in seen["legend"])
    assert any("below the floor 1e-6" in s for s in seen["legend"])
    img = np.round(imread(io.BytesIO(png))[..., :3] * 255).astype(int)

    def count(rgb, tol=6):
        return int(np.all(np.abs(img - np.asarray(rgb)) <= tol, axis=-1).sum())

    band = int(np.searchsorted(MAP_LEVELS, 2e-3, side="right")) - 1  # 1e-3 .. 1e-2
    colour = colormaps["YlOrRd"](np.linspace(0.12, 1.0, len(MAP_LEVELS) - 1))[band][:3]
    grey = [int(UNRESOLVED_COLOUR[k:k + 2], 16) for k in (1, 3, 5)]
    assert count(np.round(np.asarray(colour) * 255)) > 500  # the resolved cell, in its band (a 10 m cell is ~70 px wide)
    assert count(grey) > 5000  # the hatched cells' ground


def test_contours_count_the_cells_only_bounded():
    """A level at or below the zero-hit bound holds every unresolved cell: each feature
    says how many, and the collection states the bound."""
    from types import SimpleNamespace

    pytest.importorskip("shapely")
    from hazard.outputs.risk_outputs import contours

    c = _cells()
    mp = {"points_m": np.column_stack([c["x"], c["y"], np.full(c["x"].size, 1.7)]), "ci_high": c["hi"], "hits": c["hits"],
          "spacing_m": 10.0}
    doc = contours(SimpleNamespace(site=None, name="s"), mp)
    by_level = {f["properties"]["level"]: f["properties"] for f in doc["features"]}
    assert doc["laser_hazard"]["zero_hit_bound"] == 1.8e-4 and "28 cell(s) had no exceedance" in doc["laser_hazard"]["unresolved"]
    assert by_level[1e-4] == by_level[1e-4] | {"cells": 30, "unresolved_cells": 28}  # 1.8e-4 >= 1e-4: all inside
    assert by_level[1e-3] == by_level[1e-3] | {"cells": 1, "unresolved_cells": 0}  # only the 2.8e-3 cell
    assert 1e-2 not in by_level


@pytest.mark.skipif(not HAS_MPL, reason="matplotlib not installed")
def test_map_names_only_resolved_points_with_their_estimate_and_no_name_covers_another():
    """A road of 20 points 2 m apart across the map (issue 34 item 3 re-check: the 20
    highest were named, zero-hit ones too, and a road's names covered each other): the
    resolved ones are named with their estimate, the highest first, at most 8; none of
    the zero-hit ones; no two names overlap."""
    est = [3e-4, 1e-4, 2e-5, 7e-6, 4e-7]  # five resolved points in the middle of the road
    obs = []
    for k in range(20):
        p = est[k - 8] if 8 <= k < 13 else 0.0
        obs.append({"name": f"road[{k}]", "position_m": [5.0 + 2.0 * k, 25.0, 1.7], "probability_exceed": p,
                    "probability_ci_high": 2e-3 if p else 1.5e-4, "hits": 3 if p else 0})
    doc = {"scene": "s", "draws": DRAWS, "observers": obs, "map": {"spacing_m": 10.0, "eye_height_m": 1.7}}
    _, seen = map_png(doc, _cells())
    names = [t for t, _ in seen["labels"] if t.startswith("road[")]
    assert sorted(names) == sorted(f"road[{8 + i}]: P {p}" for i, p in enumerate(("3.0e-4", "1.0e-4", "2.0e-5", "7.0e-6", "4.0e-7")))
    assert seen["labelled"] == 5 and seen["drawn"] == 20 and seen["unresolved_drawn"] == 15
    boxes = np.array([b for t, b in seen["labels"] if t.startswith("road[")])
    for i in range(len(boxes)):
        for j in range(i + 1, len(boxes)):
            a, b = boxes[i], boxes[j]
            assert a[2] <= b[0] or b[2] <= a[0] or a[3] <= b[1] or b[3] <= a[1], (names[i], names[j])


@pytest.mark.skipif(not HAS_MPL, reason="matplotlib not installed")
def test_map_prints_its_smallest_text_at_6_pt_on_the_portrait_page():
    """probability_map.png goes full width on a portrait A4 page (210 mm less 2 x 12 mm
    margins) in the review page and risk.html (issue 34 leftover d)."""
    from matplotlib.image import imread

    from tests.hazard.test_picture_print import printed_pt

    doc = {"scene": "s", "draws": DRAWS, "observers": [], "map": {"spacing_m": 10.0, "eye_height_m": 1.7}}
    png, seen = map_png(doc, _cells())
    width_px = imread(io.BytesIO(png)).shape[1]
    assert width_px == seen["width_px"]
    assert printed_pt(seen["text_px_min"], width_px, page_in=(210.0 - 2 * 12.0) / 25.4) >= 6.0


def test_a_point_without_a_sensitivity_driver_says_why():
    """risk.html's driver cell read "none: no index defined (of none: the irradiance does not
    vary ...)" where no sensitivity draw varied the irradiance: it now says that once."""
    from hazard.outputs.risk_page import _driver_text

    why = "none: the irradiance does not vary over the 16 sensitivity draws (raise sensitivity_draws)"
    assert _driver_text({"of": why, "draws": 16, "first_order": {"tilt": None}, "driver": None}) == why
    assert "of none" not in _driver_text({"of": why, "driver": None})
    assert _driver_text({"of": "exceedance", "draws": 16, "first_order": {"tilt": 0.5}, "driver": "tilt"}).startswith("tilt (first-order")
