"""The page of a risk analysis: ``OUT/risk.html`` from risk.json (``hazard risk``).

:func:`risk_page` renders one self-contained HTML page from the risk.json dict (the
``doc`` of :func:`hazard.drivers.risk.run_risk`) with ``hazard/templates/risk.html.j2``: the run's
header (scene, MPE, criterion, draws, seed, sampling, run mode), the statistical
statement per observer in two lists: the resolved points (at least one exceedance among
the draws) by the estimate, the highest first (ties by the 95 % upper bound), and apart the
unresolved points (no exceedance: only the upper bound is known) by that bound; the
uncertain inputs, the probability map (drawn from ``OUT/probability_map.csv``: the
estimate where resolved, hatched cells where only a bound is known; embedded as base64
and saved as ``OUT/probability_map.png``) and the notes and what the model leaves out,
verbatim.
:func:`write_risk_page` writes it to ``OUT/risk.html`` atomically.

Every value is read from risk.json (and the map from probability_map.csv); nothing is
recomputed. The numbers are formatted by :mod:`hazard.outputs.review`'s helpers, probabilities in
plain scientific notation below 0.01 (``3.2e-3``). The pieces (statement rows, inputs,
map summary) are also used by the review page's "Probabilistic risk" section.
"""

from __future__ import annotations

import base64
import csv
import importlib.util
import io
import math
from pathlib import Path

import numpy as np

from brdfmodels.fileio import atomic_write, atomic_write_text, check_input_file

from hazard.outputs.label_place import place_labels, text_boxes
from hazard.outputs.page_format import fmt_number, fmt_vector, optics_text, plain_number, report_number, template_environment
from hazard.outputs.risk_outputs import CONTOUR_LEVELS

__all__ = ["risk_page", "write_risk_page", "risk_context", "statement_section", "split_rows", "estimate_first", "is_resolved", "inputs_rows", "map_summary", "map_png",
           "read_map_csv", "fmt_p", "HTML_NAME", "PNG_NAME", "MAP_CSV_NAME", "ROWS_SHOWN", "MAP_TITLE", "MAP_LEVELS"]

HTML_NAME = "risk.html"
PNG_NAME = "probability_map.png"
MAP_CSV_NAME = "probability_map.csv"
ROWS_SHOWN = 200  # observer rows per list on the page (resolved, unresolved); the rest are counted
MAP_LABELS_SHOWN = 8  # resolved observers named on the map with their estimate (the highest); the others are drawn unlabelled
MAP_LEVELS = (1e-6, 1e-5, 1e-4, 1e-3, 1e-2, 1e-1, 1.0)  # the map's colour bands (log scale)
MAP_TITLE = "P(E > MPE): the estimate where resolved, hatched where only a bound is known"
UNDER_COLOUR = "#d6e2ee"  # resolved cells whose estimate is below the floor MAP_LEVELS[0]
UNRESOLVED_COLOUR = "#eeeeee"  # cells without an exceedance in the draws (hatched)
MAP_CAPTION = ("Probabilistic risk: per map cell at the eye height, the estimate of P(E > MPE) where at least one draw "
               "exceeded the MPE (bands of a factor 10; a resolved estimate below 1e-6 pale blue), hatched grey where no "
               "draw did (only the 95 % upper bound is known, stated in the legend); observer points black, the highest "
               "estimates named")
CONTOUR_RULE = ("The probability contours ({files}) hold the cells whose 95 % upper bound of P(E > MPE) is at or above each "
                "level ({levels}): a cell whose interval straddles a level is inside it. They are conservative, never "
                "drawn from the estimate alone.")


# -- numbers -------------------------------------------------------------------------
def fmt_p(x, sig: int = 3, none: str = "none") -> str:
    """A probability, ratio or index as text: fixed notation from 0.01 to 1e7 (``0.0903``),
    else plain scientific notation (``3.2e-3``); 0 as ``0``; JSON null as ``none``."""
    v = report_number(x)
    if v is None:
        return none
    if not isinstance(v, float) or not math.isfinite(v):
        return fmt_number(v)
    if v == 0:
        return "0"
    if 1e-2 <= abs(v) < 1e7:
        return plain_number(v, sig)
    mant, _, exp = f"{v:.{sig - 1}e}".partition("e")
    return f"{mant}e{int(exp)}"


def _interval(d: dict, p="probability_exceed", lo="probability_ci_low", hi="probability_ci_high") -> str:
    return f"{fmt_p(d.get(p))} [{fmt_p(d.get(lo))}, {fmt_p(d.get(hi))}]"


# -- the statement table -------------------------------------------------------------
def _num_or_worst(r: dict, k: str) -> float:
    x = report_number(r.get(k))
    return math.inf if not isinstance(x, float) or math.isnan(x) else x


def estimate_first(r: dict) -> tuple:
    """Sort key: highest estimate of P(E > MPE) first, ties by the highest 95 % upper
    bound (null and NaN count as worst)."""
    return (-_num_or_worst(r, "probability_exceed"), -_num_or_worst(r, "probability_ci_high"))


worst_first = estimate_first  # the listings' order (hazard risk's terminal lines, risk.html, the review page)


def is_resolved(r: dict) -> bool:
    """A point with at least one exceedance among the draws (``hits`` > 0): its estimate is
    known. Without hits only an upper bound is known (the estimate 0 is no finding)."""
    hits = report_number(r.get("hits"))
    if isinstance(hits, float):
        return hits > 0
    return _num_or_worst(r, "probability_exceed") > 0  # hits not stated: an estimate above 0 was seen


def split_rows(observers: list) -> tuple[list, list]:
    """The observer rows as (resolved, unresolved): the resolved by the estimate (ties by
    the upper bound), the unresolved (zero hits) by the upper bound, the highest first."""
    rows = list(observers or [])
    resolved = sorted((r for r in rows if is_resolved(r)), key=estimate_first)
    unresolved = sorted((r for r in rows if not is_resolved(r)), key=lambda r: -_num_or_worst(r, "probability_ci_high"))
    return resolved, unresolved


def _aided_text(aided: list) -> str:
    """The optics with the highest probability (``aided``), or why there is none."""
    if not aided:
        return "no optics in the scene"
    a = max(aided, key=lambda a: report_number(a.get("probability_exceed")) or 0.0)
    return f"{_interval(a)} through {optics_text(a)} (gain {fmt_number(a.get('gain'), sig=3)})"


def _operations_text(ops) -> str:
    if not ops:
        return "not given"
    return (f"{_interval(ops, 'probability_at_least_one', 'ci_low', 'ci_high')} in "
            f"{fmt_number(ops.get('n'), sig=6)} operations")


def _driver_text(sens) -> str:
    """The input with the largest first-order Sobol index (``sensitivity``)."""
    if not sens:
        return "no sensitivity sample"
    of = {"exceedance": "of the exceedance", "log_ratio": "of ln(E / MPE): under 10 exceedances in the sample"}
    of_text = of.get(sens.get("of"), f"of {sens.get('of')}")
    driver = sens.get("driver")
    if driver is None:  # "of" then says why (risk.results: no sensitivity draw varied the irradiance)
        why = str(sens.get("of") or "no index defined")
        return why if why.startswith("none") else f"none: no index defined ({why})"
    index = (sens.get("first_order") or {}).get(driver)
    return f"{driver} (first-order index {fmt_p(index)}, {of_text}; {fmt_number(sens.get('draws'))} base draws)"


def _lit_text(r: dict) -> str:
    """How often the point was lit at all and the hazard ratio's quantiles then."""
    frac = report_number(r.get("lit_fraction"))
    if not isinstance(frac, float):
        return "not stated"
    if frac == 0:
        return "never lit in the draws"  # (weighted as the estimate when importance sampled)
    ql = r.get("hazard_ratio_quantiles_lit") or {}
    return (f"lit in {fmt_p(100 * frac, sig=3)} % of the operations; then "
            f"{' / '.join(fmt_p(ql.get(k)) for k in ('p50', 'p95', 'p99'))}")


def _all_zero(q: dict) -> bool:
    return all(report_number(q.get(k)) == 0.0 for k in ("p50", "p95", "p99"))


def statement_row(r: dict, draws=None) -> dict:
    """One observer of risk.json as the statement table shows it."""
    q = r.get("hazard_ratio_quantiles") or {}
    hits = fmt_number(r.get("hits"), none="not stated")
    n_eff = report_number(r.get("effective_draws"))
    if isinstance(n_eff, float) and n_eff != report_number(draws):
        hits += f" (effective draws {fmt_number(n_eff, sig=4)})"
    return {"name": str(r.get("name", "?")), "position": fmt_vector(r.get("position_m"), sig=4),
            "p": fmt_p(r.get("probability_exceed")), "lo": fmt_p(r.get("probability_ci_low")),
            "hi": fmt_p(r.get("probability_ci_high")), "method": str(r.get("ci_method", "not stated")), "hits": hits,
            "quantiles": [fmt_p(q.get(k)) for k in ("p50", "p95", "p99")], "quantiles_zero": _all_zero(q), "lit": _lit_text(r),
            "gain": fmt_number(r.get("optical_gain"), sig=3),
            "aided": _aided_text(r.get("aided")), "operations": _operations_text(r.get("operations")),
            "driver": _driver_text(r.get("sensitivity")), "statement": str(r.get("statement", "not stated"))}


ZERO_QUANTILES = ("A hazard ratio p50 / p95 / p99 of 0 / 0 / 0 is no error: the quantiles are over all draws, and a point "
                  "lit (E > 0) in under 1 % of them has all three at 0, as a pointing error usually carries the beam or the "
                  "glint past it. The column 'when lit' gives the share of the operations that light it (the draws weighted as "
                  "the estimate is) and the hazard ratio's quantiles among them.")
RATIO_MEANS = ("hazard ratio: per draw the observer's exposure over the {t} exposure against the MPE for {t} (the peak "
               "irradiance over the analysis times / the MPE; for an irradiance constant over the exposure this is H / MPE_H)")


def _part(rows: list, draws, shown: int, what: str) -> dict:
    page, rest = rows[:shown], rows[shown:]
    more = (f"... and {len(rest)} more {what} observer point(s) not shown here: all are in risk.csv and risk.json "
            "observers." if rest else "")
    return {"rows": [statement_row(r, draws) for r in page], "shown": len(page), "total": len(rows), "more": more}


def statement_section(doc: dict, shown: int = ROWS_SHOWN) -> dict:
    """The statement tables: the resolved points (at least one exceedance among the draws)
    by the estimate, the highest first (ties by the upper bound), and apart from them the
    unresolved points (no exceedance: only the 95 % upper bound is known) by the upper
    bound; up to ``shown`` rows each, a line counting the rest (all are in risk.csv)."""
    resolved, unresolved = split_rows(doc.get("observers") or [])
    draws = doc.get("draws")
    res, unres = _part(resolved, draws, shown, "resolved"), _part(unresolved, draws, shown, "unresolved")
    zero = any(r["quantiles_zero"] for r in res["rows"] + unres["rows"])
    return {"resolved": res, "unresolved": unres, "total": len(resolved) + len(unresolved), "shown": res["shown"] + unres["shown"],
            "rows": res["rows"] + unres["rows"], "operations": fmt_number(doc.get("operations"), sig=6, none="not given"),
            "draws": fmt_number(draws, sig=10), "zero_quantiles": ZERO_QUANTILES if zero else "",
            "ratio_means": RATIO_MEANS.format(t=fmt_number(doc.get("duration_s"), "s"))}


def inputs_rows(doc: dict) -> list:
    """The uncertain inputs (``inputs``): name, whether drawn, the distribution as stated."""
    return [{"name": str(i.get("name", "?")), "active": "yes" if i.get("active") else "no",
             "distribution": str(i.get("distribution", "not stated"))} for i in doc.get("inputs") or []]


# -- the header ----------------------------------------------------------------------
def _importance_lines(imp) -> list | None:
    if not imp:
        return None
    share = report_number(imp.get("alpha0"))
    head = (f"{fmt_number(100 * share, sig=3)} % of the draws from the stated distributions"
            if isinstance(share, float) else "share of the stated distributions not stated")
    return [head] + [f"component {k + 1}: {c}" for k, c in enumerate(imp.get("components") or [])]


def header_rows(doc: dict) -> list:
    """The run in rows ``{label, value, key, lines}`` (the review page's key-value table)."""
    run = doc.get("run") or {}
    mpe = (f"{fmt_number(doc.get('mpe_w_m2'), 'W/m²', sig=6)}: {doc.get('mpe', 'not stated')} "
           f"({doc.get('standard', 'standard not stated')})")
    rows = [("scene", doc.get("scene", "?"), "scene"), ("scene text sha256", doc.get("scene_sha256", "not stated"), "scene_sha256"),
            ("MPE", mpe, "mpe_w_m2, mpe, standard"), ("exposure duration", fmt_number(doc.get("duration_s"), "s"), "duration_s"),
            ("criterion (an exceedance)", doc.get("criterion", "not stated"), "criterion"),
            ("draws (simulated operations)", fmt_number(doc.get("draws"), sig=10), "draws"), ("seed", str(doc.get("seed")), "seed"),
            ("sampling", doc.get("sampling", "not stated"), "sampling"),
            ("importance sampling", None if doc.get("importance") else "none (plain sampling)", "importance"),
            ("sensitivity draws (Sobol base sample)", fmt_number(doc.get("sensitivity_draws"), sig=10), "sensitivity_draws"),
            ("draws per chunk", fmt_number(doc.get("chunk_draws"), sig=10), "chunk_draws"),
            ("operations (per year)", fmt_number(doc.get("operations"), sig=6, none="not given"), "operations"),
            ("run", f"{run.get('mode', 'not stated')}; {run.get('chunks', '?')} chunk(s): {run.get('ran', '?')} run now, "
                    f"{run.get('reused', '?')} reused; {fmt_number(run.get('seconds'), 's', sig=3)}", "run")]
    lines = {"importance": _importance_lines(doc.get("importance"))}
    return [{"label": label, "value": "" if value is None else str(value), "key": key, "lines": lines.get(key)}
            for label, value, key in rows]


# -- the map -------------------------------------------------------------------------
def map_summary(doc: dict) -> dict | None:
    """The map's summary rows (``map``) and the contour rule; None without a map."""
    m = doc.get("map")
    if m is None:
        return None
    ny, nx = (list(m.get("shape") or []) + [None, None])[:2]
    total = ny * nx if isinstance(ny, int) and isinstance(nx, int) else None
    ext = m.get("extent_m") or [None] * 4
    counts = m.get("cells_upper_at_least") or {}
    rows = [("cells", f"{ny} × {nx} (rows south to north × columns west to east)", "map.shape"),
            ("spacing", fmt_number(m.get("spacing_m"), "m"), "map.spacing_m"),
            ("extent", f"x {fmt_vector(ext[:2], 'm', sig=6)}, y {fmt_vector(ext[2:], 'm', sig=6)}", "map.extent_m"),
            ("eye height", fmt_number(m.get("eye_height_m"), "m"), "map.eye_height_m"),
            ("largest probability (estimate)", fmt_p(m.get("max_probability")), "map.max_probability"),
            ("interval method", str(m.get("method", "not stated")), "map.method")]
    rows += [(f"cells with upper bound ≥ {fmt_p(float(level), sig=1)}", f"{n}" + (f" of {total}" if total else ""),
              f"map.cells_upper_at_least.{level}") for level, n in counts.items()]
    files = [str(f) for f in m.get("files") or []]
    contour_files = [f for f in files if "contours" in f] or ["probability_contours*.json"]
    rule = CONTOUR_RULE.format(files=", ".join(contour_files), levels=", ".join(fmt_p(x, sig=1) for x in CONTOUR_LEVELS))
    return {"rows": [{"label": a, "value": b, "key": c, "lines": None} for a, b, c in rows], "rule": rule, "files": files}


def read_map_csv(path) -> dict:
    """x_m, y_m, probability_ci_high and (when present) probability_exceed and hits of
    ``probability_map.csv`` as arrays (``p``/``hits`` None when the columns are absent);
    ValueError naming the file when a column is missing or a value is not a number."""
    path = Path(path)
    with open(check_input_file(path, MAP_CSV_NAME), newline="", encoding="utf-8") as fh:
        reader = csv.DictReader(fh)
        need = ("x_m", "y_m", "probability_ci_high")
        missing = [c for c in need if c not in (reader.fieldnames or [])]
        if missing:
            raise ValueError(f"{path}: column {missing[0]!r} missing (expected {', '.join(need)})")
        extra = [c for c in ("probability_exceed", "hits") if c in (reader.fieldnames or [])]
        cols = need + tuple(extra) if len(extra) == 2 else need
        try:
            rows = [[float(r[c]) for c in cols] for r in reader]
        except (TypeError, ValueError):
            raise ValueError(f"{path}: line {reader.line_num}: not a number in {', '.join(cols)}") from None
    a = np.asarray(rows, float).reshape(-1, len(cols))
    full = len(cols) == 5
    return {"x": a[:, 0], "y": a[:, 1], "hi": a[:, 2], "p": a[:, 3] if full else None, "hits": a[:, 4] if full else None}


def _grid(cells: dict, spacing, key: str = "hi") -> tuple:
    """Cell edges (x, y) and the column ``key`` as a grid (rows south to north; NaN where
    the CSV has no cell)."""
    x, y, v = cells["x"], cells["y"], cells[key]
    d = report_number(spacing)
    if not isinstance(d, float) or not d > 0:
        steps = np.diff(np.unique(np.concatenate([x, y])))
        d = float(steps[steps > 0].min()) if (steps > 0).any() else 1.0
    ix, iy = np.rint((x - x.min()) / d).astype(int), np.rint((y - y.min()) / d).astype(int)
    grid = np.full((iy.max() + 1, ix.max() + 1), np.nan)
    grid[iy, ix] = v
    xe = x.min() - d / 2 + d * np.arange(grid.shape[1] + 1)
    ye = y.min() - d / 2 + d * np.arange(grid.shape[0] + 1)
    return xe, ye, grid


def map_layers(cells: dict, spacing) -> dict:
    """What the map picture draws: the estimate where resolved (NaN elsewhere), the mask of
    the unresolved cells (no exceedance in the draws), the largest upper bound among them,
    and the counts. A CSV without the estimate and hits columns: every cell drawn as
    unresolved by its upper bound (said by ``legacy``)."""
    xe, ye, hi = _grid(cells, spacing, "hi")
    if cells.get("p") is None:
        unresolved = np.isfinite(hi)
        est = np.full(hi.shape, np.nan)
    else:
        hits = _grid(cells, spacing, "hits")[2]
        est = _grid(cells, spacing, "p")[2]
        unresolved = np.isfinite(hits) & (hits <= 0)
        est = np.where(np.isfinite(hits) & (hits > 0), est, np.nan)
    bound = float(np.nanmax(np.where(unresolved, hi, np.nan))) if unresolved.any() else None
    resolved = np.isfinite(est)
    return {"xe": xe, "ye": ye, "estimate": est, "unresolved": unresolved, "bound": bound, "legacy": cells.get("p") is None,
            "resolved_cells": int(resolved.sum()), "unresolved_cells": int(unresolved.sum()),
            "below_floor": int((resolved & (est < MAP_LEVELS[0])).sum())}


def _hatch_cells(ax, layers: dict) -> None:
    """The unresolved cells as grey hatched rectangles, one per run of cells in a row."""
    from matplotlib.collections import PatchCollection
    from matplotlib.patches import Rectangle

    xe, ye, mask = layers["xe"], layers["ye"], layers["unresolved"]
    rects = []
    for iy in range(mask.shape[0]):
        row = np.concatenate([[False], mask[iy], [False]]).astype(int)
        starts, ends = np.flatnonzero(np.diff(row) == 1), np.flatnonzero(np.diff(row) == -1)
        rects += [Rectangle((xe[a], ye[iy]), xe[b] - xe[a], ye[iy + 1] - ye[iy]) for a, b in zip(starts, ends)]
    if rects:
        ax.add_collection(PatchCollection(rects, facecolor=UNRESOLVED_COLOUR, edgecolor="#9a9a9a", hatch="///", linewidth=0.0,
                                          zorder=1))


def _draw_observers(ax, observers: list, xe, ye) -> dict:
    """Observer points inside the map as black dots; the ``MAP_LABELS_SHOWN`` resolved ones
    with the highest estimates named with it (a zero-hit point has no estimate to name:
    named, the 20 of a road crowded each other illegible and hid the hot spot), placed
    apart (:func:`hazard.outputs.label_place.place_labels`)."""
    import matplotlib.patheffects as pe

    inside = [r for r in sorted(observers, key=worst_first)
              if len(r.get("position_m") or []) >= 2 and xe[0] <= r["position_m"][0] <= xe[-1] and ye[0] <= r["position_m"][1] <= ye[-1]]
    if inside:
        xy = np.array([r["position_m"][:2] for r in inside], float)
        ax.scatter(xy[:, 0], xy[:, 1], s=22, c="black", edgecolors="white", linewidths=0.8, zorder=3)
    halo = [pe.withStroke(linewidth=2.5, foreground="white")]
    named = [r for r in inside if is_resolved(r)][:MAP_LABELS_SHOWN]
    for r in named:
        ax.annotate(f"{r.get('name', '?')}: P {fmt_p(r.get('probability_exceed'), sig=2)}", r["position_m"][:2], xytext=(5, 4),
                    textcoords="offset points", fontsize=8, zorder=4, path_effects=halo, parse_math=False, annotation_clip=True)
    return {"drawn": len(inside), "labelled": len(named), "outside": len(observers) - len(inside),
            "unresolved_drawn": sum(not is_resolved(r) for r in inside)}


def _legend_text(layers: dict, draws) -> list:
    """The legend's lines for the hatched and the below-floor cells (counted), each said."""
    n = fmt_number(draws)
    lines = []
    if layers["unresolved_cells"]:
        what = ("the CSV has no estimate or hits columns: every cell drawn by its bound" if layers["legacy"] else
                f"no exceedance in {n} draws")
        lines.append(f"hatched: {layers['unresolved_cells']} cell(s), {what}; only the 95 % upper bound is known, "
                     f"P <= {fmt_p(layers['bound'], sig=2)}")
    if layers["below_floor"]:
        lines.append(f"pale blue: {layers['below_floor']} resolved cell(s) with an estimate below the floor "
                     f"{fmt_p(MAP_LEVELS[0], sig=1)}")
    return lines


def map_png(doc: dict, cells: dict) -> tuple[bytes, dict]:
    """The map picture (PNG bytes) of ``cells`` (:func:`read_map_csv`): the estimate where
    resolved, hatched cells where only the upper bound is known, observers overlaid; and
    what was drawn (observers drawn, labelled and left outside; cell counts; the bound)."""
    from matplotlib import colormaps
    from matplotlib.colors import BoundaryNorm, ListedColormap
    from matplotlib.patches import Patch

    from hazard.canvas import new_figure, smallest_text_px

    m = doc.get("map") or {}
    layers = map_layers(cells, m.get("spacing_m"))
    xe, ye = layers["xe"], layers["ye"]
    colours = colormaps["YlOrRd"](np.linspace(0.12, 1.0, len(MAP_LEVELS) - 1))
    cmap = ListedColormap(colours).with_extremes(under=UNDER_COLOUR, bad=(0, 0, 0, 0))
    norm = BoundaryNorm(MAP_LEVELS, cmap.N)
    fig = new_figure((8.0, 7.6), 110, layout="constrained")  # an Agg canvas: the labels are placed on its renderer
    ax = fig.add_subplot()
    few = max(layers["estimate"].shape) <= 60  # cells large enough on the page to outline
    mesh = ax.pcolormesh(xe, ye, np.ma.masked_invalid(layers["estimate"]), cmap=cmap, norm=norm, zorder=2,
                         edgecolors=(1, 1, 1, 0.35) if few else "face", linewidth=0.3 if few else 0.0)
    _hatch_cells(ax, layers)
    bar = fig.colorbar(mesh, ax=ax, extend="min", ticks=MAP_LEVELS, shrink=0.85)
    bar.ax.set_yticklabels([fmt_p(x, sig=1) for x in MAP_LEVELS])
    bar.set_label(f"estimate of P(E > MPE), resolved cells (below {fmt_p(MAP_LEVELS[0], sig=1)}: pale blue)")
    seen = _draw_observers(ax, doc.get("observers") or [], xe, ye)
    lines = _legend_text(layers, doc.get("draws"))
    handles = []
    if layers["unresolved_cells"]:
        handles.append(Patch(facecolor=UNRESOLVED_COLOUR, edgecolor="#9a9a9a", hatch="///", label=lines[0]))
    if layers["below_floor"]:
        handles.append(Patch(facecolor=UNDER_COLOUR, label=lines[-1]))
    if handles:
        fig.legend(handles=handles, loc="outside lower center", fontsize=8, frameon=False)
    ax.set_xlim(xe[0], xe[-1])
    ax.set_ylim(ye[0], ye[-1])
    ax.set_aspect("equal")
    ax.ticklabel_format(style="plain", useOffset=False)
    ax.set_xlabel("x (east) [m]")
    ax.set_ylabel("y (north) [m]")
    fig.suptitle(MAP_TITLE, fontsize=12)
    ax.set_title(f"scene {doc.get('scene', '?')}: {fmt_number(doc.get('draws'))} draws, eye height "
                 f"{fmt_number(m.get('eye_height_m'), 'm')}; {layers['resolved_cells']} cell(s) resolved, "
                 f"{layers['unresolved_cells']} only bounded", fontsize=9, color="#5a5a5a", parse_math=False)
    ax.grid(True, color="#888888", linewidth=0.3, alpha=0.5)
    fig.canvas.draw()
    place_labels(ax)  # no name over another (a road's neighbouring points)
    fig.canvas.draw()
    seen["labels"] = [(t.get_text(), box.tolist()) for t, box in text_boxes(ax)]  # the names and their boxes [x0, y0, x1, y1] px
    seen["text_px_min"], seen["width_px"] = smallest_text_px(fig, fig.dpi), int(round(fig.get_figwidth() * fig.dpi))  # its print size
    buf = io.BytesIO()
    fig.savefig(buf, format="png")
    seen |= {k: layers[k] for k in ("resolved_cells", "unresolved_cells", "below_floor", "bound")} | {"legend": lines}
    return buf.getvalue(), seen


def _have_matplotlib() -> bool:
    return importlib.util.find_spec("matplotlib") is not None


def _map_picture(doc: dict, out: Path) -> tuple[dict | None, str]:
    """Draw the map, save ``OUT/probability_map.png`` and return it as the page's picture
    (or None) with a line saying what was drawn, or why there is no picture."""
    csv_path = out / MAP_CSV_NAME
    if not csv_path.is_file():
        return None, f"no map picture: {MAP_CSV_NAME} is not in {out}"
    if not _have_matplotlib():
        return None, "no map picture: matplotlib is not installed (pip install 'laser-hazard[render]')"
    try:
        cells = read_map_csv(csv_path)
    except ValueError as exc:
        return None, f"no map picture: {exc}"
    if not len(cells["hi"]):
        return None, f"no map picture: {MAP_CSV_NAME} has no cells"
    data, seen = map_png(doc, cells)
    atomic_write(out / PNG_NAME, lambda tmp: Path(tmp).write_bytes(data))
    uri = f"data:image/png;base64,{base64.b64encode(data).decode('ascii')}"
    said = (f"{seen['resolved_cells']} cell(s) resolved (the estimate drawn), {seen['unresolved_cells']} without an "
            f"exceedance (hatched: only the upper bound known)" + "".join(f"; {x}" for x in seen["legend"])
            + f". {seen['drawn']} observer point(s) drawn, {seen['labelled']} named with their estimate (the highest resolved; "
            f"the {seen.get('unresolved_drawn', 0)} without an exceedance unnamed)"
            + (f"; {seen['outside']} outside the map not drawn" if seen["outside"] else "") + f"; saved as {PNG_NAME}.")
    return {"name": PNG_NAME, "caption": MAP_CAPTION, "uri": uri, "kb": len(data) / 1024.0, "stale": False}, said


def map_view(doc: dict, out: Path) -> dict | None:
    """The map section: summary rows, the contour rule and the picture (drawn now)."""
    summary = map_summary(doc)
    if summary is None:
        return None
    picture, said = _map_picture(doc, out)
    return summary | {"picture": picture, "said": said}


# -- the page ------------------------------------------------------------------------
def risk_context(doc: dict, out_dir) -> dict:
    """Everything risk.html.j2 shows, each part from its risk.json keys (the map is drawn
    and saved as ``OUT/probability_map.png`` here)."""
    out = Path(out_dir)
    return {"title": f"Probabilistic laser hazard risk: {doc.get('scene', '?')}", "header": header_rows(doc),
            "criterion": str(doc.get("criterion", "not stated")), "statements": statement_section(doc),
            "inputs": inputs_rows(doc), "map": map_view(doc, out), "notes": [str(n) for n in doc.get("notes") or []],
            "left_out": [str(n) for n in doc.get("left_out") or []], "files": [str(f) for f in doc.get("files") or []],
            "mpe": f"{fmt_number(doc.get('mpe_w_m2'), 'W/m²', sig=6)} ({doc.get('standard', 'standard not stated')})",
            "scene_sha256": str(doc.get("scene_sha256", "not stated"))}


def risk_page(doc: dict, out_dir: Path) -> str:
    """The risk page of ``doc`` (risk.json's content) as HTML text: self-contained (CSS
    inline, the map as a data URI, no script). Draws and saves ``OUT/probability_map.png``
    when the run has a map and ``OUT/probability_map.csv`` is there."""
    return template_environment().get_template("risk.html.j2").render(**risk_context(doc, out_dir))


def write_risk_page(doc: dict, out_dir) -> Path:
    """Write ``OUT/risk.html`` (and ``OUT/probability_map.png`` with a map) atomically;
    returns the page's path."""
    out = Path(out_dir)
    return atomic_write_text(out / HTML_NAME, risk_page(doc, out))
