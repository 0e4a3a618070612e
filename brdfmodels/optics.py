"""Fresnel reflectance of a conductor or dielectric, and bundled optical constants.

Fresnel equations for a plane wave from vacuum/air (index 1) onto a medium of complex
index N = n + i k (Born & Wolf, *Principles of Optics*, 7th ed., Sec. 1.5.2 and 14.2):

    cos t = sqrt(1 - sin^2 i / N^2)              (principal branch: decaying wave)
    r_s = (cos i - N cos t) / (cos i + N cos t)
    r_p = (N cos i - cos t) / (N cos i + cos t)
    R   = (|r_s|^2 + |r_p|^2) / 2               (unpolarised)
    R   = max(|r_s|^2, |r_p|^2)                  ("worst": any polarisation state, since
                                                  the reflectance of any state lies between
                                                  |r_p|^2 and |r_s|^2)

At normal incidence R = ((n-1)^2 + k^2) / ((n+1)^2 + k^2).

Bundled tables (``brdfmodels/data``, provenance in each file's first line):
``"cu"`` (0.3-1.7 um) and ``"al"`` (McPeak et al. 2015, 0.15-1.7 um).
"""

from __future__ import annotations

from functools import lru_cache
from importlib import resources

import numpy as np

from ._checks import finite_scalar

__all__ = ["fresnel_reflectance", "optical_constants", "available_optical_constants", "POLARIZATIONS"]

_TABLES = {"cu": "cu_nk.csv", "al": "al_nk.csv"}


POLARIZATIONS = ("unpolarized", "worst")
N_MIN, N_MAX = 1e-4, 1e5  # refractive index bounds (n, and k up to N_MAX): N^2 neither under- nor overflows


def fresnel_reflectance(cos_incidence, n: float, k: float = 0.0, polarization: str = "unpolarized") -> np.ndarray:
    """Fresnel reflectance from air onto index ``n + i k``.

    Parameters
    ----------
    cos_incidence : array_like
        Cosine of the incidence angle (clipped to [0, 1]).
    n, k : float
        Real and imaginary parts of the refractive index (n > 0, k >= 0).
    polarization : {"unpolarized", "worst"}
        ``"unpolarized"``: the mean of s and p; ``"worst"``: the larger of the two, an
        upper bound for any polarisation state (a linearly polarised laser whose
        orientation to the plane of incidence is not known).

    Returns
    -------
    ndarray
        Reflectance in [0, 1] (dimensionless).
    """
    n = finite_scalar("n", n, minimum=N_MIN, maximum=N_MAX)
    k = finite_scalar("k", k, minimum=0.0, maximum=N_MAX)
    ci = np.clip(np.asarray(cos_incidence, dtype=float), 0.0, 1.0)
    big_n = complex(n, k)
    sin2 = 1.0 - ci * ci
    ct = np.sqrt(1.0 - sin2 / (big_n * big_n) + 0j)
    rs = (ci - big_n * ct) / (ci + big_n * ct)
    rp = (big_n * ci - ct) / (big_n * ci + ct)
    if polarization not in POLARIZATIONS:
        raise ValueError(f"polarization={polarization!r}: expected one of {list(POLARIZATIONS)}")
    r = np.maximum(np.abs(rs) ** 2, np.abs(rp) ** 2) if polarization == "worst" else 0.5 * (np.abs(rs) ** 2 + np.abs(rp) ** 2)
    return np.clip(r, 0.0, 1.0)


@lru_cache(maxsize=None)
def _table(material: str):
    text = resources.files("brdfmodels").joinpath("data", _TABLES[material]).read_text(encoding="utf-8")
    rows = [line for line in text.splitlines() if line and not line.startswith("#")][1:]
    data = np.array([[float(v) for v in row.split(",")] for row in rows])
    return data[:, 0] * 1000.0, data[:, 1], data[:, 2]


def available_optical_constants() -> list:
    """Names of the bundled optical-constant tables."""
    return sorted(_TABLES)


def optical_constants(material: str, wavelength_nm: float) -> tuple:
    """Complex index ``(n, k)`` of a bundled material at ``wavelength_nm``.

    Linear interpolation in the table; a wavelength outside it raises ValueError naming
    the table's range.
    """
    key = str(material).lower()
    if key not in _TABLES:
        raise ValueError(f"material={material!r}: expected one of {available_optical_constants()}")
    wl = finite_scalar("wavelength_nm", wavelength_nm, minimum=0.0, strict_min=True)
    x, n, k = _table(key)
    if not x[0] <= wl <= x[-1]:
        raise ValueError(f"wavelength_nm={wl!r} is outside the {key} table [{x[0]:g}, {x[-1]:g}] nm")
    return float(np.interp(wl, x, n)), float(np.interp(wl, x, k))
