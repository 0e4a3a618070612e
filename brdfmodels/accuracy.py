"""Error against run time for the library's accuracy knobs.

Each function runs the same computation at increasing cost and returns rows of
(setting, result, error against the finest run, cost, seconds); :func:`format_table`
prints them. The knobs: the DHR quadrature tolerance (for a sharp specular lobe) and the
heating/oxidation solver tolerance.
"""

from __future__ import annotations

import math
import time

import numpy as np

from .analysis import hemispherical_reflectance
from .history import ThinPlateHeating
from .models import SphericalHarmonicBRDF
from .sh import SHBasis, zonal_coefficients

__all__ = ["sharp_sh_lobe", "dhr_error_table", "heating_tolerance_table", "format_table"]


def sharp_sh_lobe(width_deg: float = 2.0, peak_sr: float = 50.0, diffuse_sr: float = 0.02, lh_max: int = 32, fanout: float = 0.6):
    """An isotropic log-SH model whose ln f~ is ln(diffuse + peak exp(-(theta_h/w)^2))."""
    w = math.radians(width_deg)
    coef = zonal_coefficients(lambda th: np.log(diffuse_sr + peak_sr * np.exp(-((th / w) ** 2))), lh_max, fanout)
    basis = SHBasis(lh_max, 0, 0, 0)
    return SphericalHarmonicBRDF(basis, coef, fanout=fanout, log=True)


def dhr_error_table(model=None, wi=(0.0, 0.0, 1.0), rtols=(1e-2, 1e-3, 1e-4, 1e-5, 1e-6), reference_rtol=1e-9, state=None):
    """DHR quadrature: value, true error vs a tight reference, estimate, evaluations, time.

    Default model: :func:`sharp_sh_lobe` (a 2-degree specular lobe).
    """
    model = model if model is not None else sharp_sh_lobe()
    wi = np.asarray(wi, dtype=float)
    ref = hemispherical_reflectance(model, wi, state=state, rtol=reference_rtol, max_evaluations=50_000_000)
    rows = []
    for rt in rtols:
        r = hemispherical_reflectance(model, wi, state=state, rtol=rt)
        rows.append(
            {
                "rtol": rt,
                "dhr": r.value,
                "error": abs(r.value - ref.value),
                "error_estimate": r.error_estimate,
                "evaluations": r.evaluations,
                "time_s": r.wall_time_s,
            }
        )
    return rows


def heating_tolerance_table(plate=None, times_s=None, irradiance_w_m2=2e7, rtols=(1e-3, 1e-4, 1e-5, 1e-6, 1e-7, 1e-8), reference_rtol=1e-11):
    """Heating/oxidation ODE: max errors in T and xi vs a tight reference, and run time.

    Default: the paper's stainless plate (1/16 inch) at 2e7 W/m^2 for 3 s, through melting.
    """
    plate = plate if plate is not None else ThinPlateHeating.stainless_steel()
    times_s = np.linspace(0.0, 3.0, 301) if times_s is None else np.asarray(times_s, dtype=float)
    ref = plate.solve(times_s, irradiance_w_m2, rtol=reference_rtol)
    rows = []
    for rt in rtols:
        start = time.perf_counter()
        r = plate.solve(times_s, irradiance_w_m2, rtol=rt)
        rows.append(
            {
                "rtol": rt,
                "max_error_temperature_k": float(np.max(np.abs(r.temperature_k - ref.temperature_k))),
                "max_error_extinction": float(np.max(np.abs(r.extinction - ref.extinction))),
                "rhs_evaluations": r.solver_steps,
                "time_s": time.perf_counter() - start,
            }
        )
    return rows


def format_table(rows, title: str = "") -> str:
    """Rows of equal-keyed dicts as an aligned text table."""
    if not rows:
        return title
    keys = list(rows[0])
    cells = [[f"{r[k]:.3g}" if isinstance(r[k], float) else str(r[k]) for k in keys] for r in rows]
    widths = [max(len(k), *(len(c[i]) for c in cells)) for i, k in enumerate(keys)]
    lines = [title] if title else []
    lines.append("  ".join(k.rjust(w) for k, w in zip(keys, widths)))
    lines += ["  ".join(c.rjust(w) for c, w in zip(row, widths)) for row in cells]
    return "\n".join(lines)
