"""The 2-D pictures of a run, as PNG bytes keyed by file name, for ``hazard run --plot``
(written in the same unit as report.json) and ``hazard render``: the plan view
(:mod:`hazard.plan_view`), the elevation view (:mod:`hazard.elevation_view`), the NOHD
against time per target and the exposure against time of the worst observers
(:func:`hazard.plots.time_figures`). matplotlib is imported when they are drawn."""

from __future__ import annotations

from pathlib import Path

__all__ = ["run_figures", "write_figures", "FIXED_NAMES"]

FIXED_NAMES = ("plan.png", "elevation.png")  # the other names depend on the scene's targets and observers


def run_figures(result, *, worst=3, progress=None) -> dict:
    """Every picture of ``result`` as {file name: PNG bytes}; ``progress(name)`` is called
    before each is drawn (a bar or a line on a terminal)."""
    from .elevation_view import ElevationViewDisplay
    from .plan_view import PlanViewDisplay
    from .plots import time_figures

    out = {}
    for name, display in (("plan.png", PlanViewDisplay), ("elevation.png", ElevationViewDisplay)):
        if progress is not None:
            progress(name)
        out[name] = display.from_result(result).png_bytes()
    if progress is not None:
        progress("time plots")
    out.update(time_figures(result, worst=worst))
    return out


def write_figures(figures: dict, outdir) -> list:
    """Write each file through a temporary beside it, then rename (never half a PNG)."""
    out = Path(outdir)
    out.mkdir(parents=True, exist_ok=True)
    from brdfmodels._io import atomic_write

    return [atomic_write(out / name, lambda tmp, data=data: Path(tmp).write_bytes(data)) for name, data in figures.items()]
