"""The 2-D pictures of a run, as PNG bytes keyed by file name, for ``hazard run --plot``
(written in the same unit as report.json) and ``hazard render``: the plan view
(:mod:`hazard.pictures.plan_view`), the elevation view (:mod:`hazard.pictures.elevation_view`), the NOHD
against time per target and the exposure against time of the worst observers
(:func:`hazard.pictures.plots.time_figures`). matplotlib is imported when they are drawn."""

from __future__ import annotations

from pathlib import Path

__all__ = ["run_figures", "write_figures", "kept_render_entries", "FIXED_NAMES"]

FIXED_NAMES = ("plan.png", "elevation.png", "figures.json")  # the other names depend on the scene's targets and observers


def run_figures(result, *, worst=3, progress=None, rendered=None) -> dict:
    """Every picture of ``result`` as {file name: PNG bytes}, and ``figures.json``: for
    each picture, the report.json findings it draws and its panels' extents
    (:mod:`hazard.outputs.figure_index`); ``progress(name)`` is called before each is drawn (a
    bar or a line on a terminal). ``rendered``: the entries of pictures written
    elsewhere ({file name: entry}: ``hazard render``'s keepout.png, overview.png and
    lobe.gif, :mod:`hazard.pictures.render`), listed in the same figures.json."""
    from hazard.pictures.elevation_view import ElevationViewDisplay
    from hazard.outputs.figure_index import FIGURES_NAME, figures_document
    from hazard.pictures.plan_view import PlanViewDisplay
    from hazard.pictures.plots import time_figures

    out, index = {}, {}
    for name, display, view in (("plan.png", PlanViewDisplay, "plan"), ("elevation.png", ElevationViewDisplay, "elevation")):
        if progress is not None:
            progress(name)
        out[name], index[name] = display.from_result(result).png_and_entry(view)
    if progress is not None:
        progress("time plots")
    out.update(time_figures(result, worst=worst, index=index))
    out[FIGURES_NAME] = figures_document({**(rendered or {}), **index})
    return out


def write_figures(figures: dict, outdir) -> list:
    """Write each file through a temporary beside it, then rename (never half a PNG)."""
    out = Path(outdir)
    out.mkdir(parents=True, exist_ok=True)
    from brdfmodels.fileio import atomic_write

    return [atomic_write(out / name, lambda tmp, data=data: Path(tmp).write_bytes(data)) for name, data in figures.items()]


def kept_render_entries(unit) -> dict:
    """The figures.json entries of ``hazard render``'s 3-D pictures (views ``3d`` and
    ``animation``) in ``unit``'s folder that the new set keeps (written by render from
    the same scene), so that a ``hazard run --plot`` after a render, rewriting figures.json,
    still lists the pictures left beside it."""
    import json

    old = unit.out / "figures.json"
    try:
        entries = json.loads(old.read_text(encoding="utf-8")).get("figures", {}) if old.is_file() else {}
    except (OSError, ValueError):
        return {}
    return {n: e for n, e in entries.items() if isinstance(e, dict) and e.get("view") in ("3d", "animation")
            and unit.owners.get(n) == "render" and n not in unit.dropped_stale and (unit.out / n).is_file()}
