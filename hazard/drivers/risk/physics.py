"""Scintillation statistics of the direct and mirror beams (spec `range-safety.md` section 6).

- Rytov variance of a plane wave, ``sigma_R^2 = 1.23 Cn^2 k^(7/6) L^(11/6)`` (Andrews &
  Phillips, *Laser Beam Propagation through Random Media*, 2nd ed., Eq. 8.13); a spherical
  wave has ``beta_0^2 = 0.5 Cn^2 k^(7/6) L^(11/6) = 0.407 sigma_R^2``.
- Scintillation index from weak to strong turbulence (Andrews, Phillips, Hopen &
  Al-Habash, JOSA A 16(6):1417, 1999; plane-wave closed form):
  ``sigma_I^2 = exp[0.49 s / (1 + 1.11 s^(6/5))^(7/6) + 0.51 s / (1 + 0.69 s^(6/5))^(5/6)] - 1``
  with ``s = sigma_R^2``; it tends to ``s`` as ``s -> 0`` and to 1 in saturation.
- Aperture averaging (Churnside, weak turbulence, plane wave):
  ``A = [1 + 1.07 (k D^2 / (4 L))^(7/6)]^-1``. For the eye's 7 mm pupil A ~ 1 at km
  ranges: no relief. A binocular objective's larger aperture is deliberately not
  credited (it would lower the tail).
- The irradiance factor is log-normal with mean 1: ``ln chi ~ N(-sigma^2/2, sigma^2)``,
  ``sigma^2 = ln(1 + sigma_I^2)``.

The log-normal model understates the tails in saturation (the spec's pitfall: gamma-gamma
is heavier); the report says so when ``sigma_R^2 > 1`` on any path.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["CN2_CLASSES_M23", "rytov_variance", "scintillation_index", "aperture_averaging", "log_sigma2", "scintillation_sigma2"]

# the upper end of each class (range-safety.md section 6: weak <= 1e-16, moderate 1e-15 - 1e-14, strong ~1e-13)
CN2_CLASSES_M23 = {"weak": 1e-16, "moderate": 1e-14, "strong": 1e-13}


def rytov_variance(cn2_m23: float, wavelength_nm: float, path_m, wave: str = "plane") -> np.ndarray:
    """Rytov variance (plane wave) or beta_0^2 (spherical wave) over paths [m]."""
    k = 2 * math.pi / (wavelength_nm * 1e-9)
    s = 1.23 * cn2_m23 * k ** (7 / 6) * np.asarray(path_m, float) ** (11 / 6)
    return s * (0.5 / 1.23) if wave == "spherical" else s


def scintillation_index(rytov: np.ndarray) -> np.ndarray:
    """sigma_I^2 from weak to strong turbulence (Andrews et al. 1999, plane wave)."""
    s = np.asarray(rytov, float)
    s65 = s ** 1.2
    return np.expm1(0.49 * s / (1 + 1.11 * s65) ** (7 / 6) + 0.51 * s / (1 + 0.69 * s65) ** (5 / 6))


def aperture_averaging(wavelength_nm: float, aperture_m: float, path_m) -> np.ndarray:
    """Churnside's factor A (<= 1) for an aperture of diameter ``aperture_m`` [m]."""
    k = 2 * math.pi / (wavelength_nm * 1e-9)
    L = np.maximum(np.asarray(path_m, float), 1e-12)
    return 1.0 / (1.0 + 1.07 * (k * aperture_m**2 / (4 * L)) ** (7 / 6))


def log_sigma2(index: np.ndarray) -> np.ndarray:
    """Variance of ln(chi) for a log-normal factor of mean 1 and scintillation index ``index``."""
    return np.log1p(np.asarray(index, float))


def scintillation_sigma2(spec, wavelength_nm: float, path_m) -> np.ndarray:
    """Variance of ln(chi) over paths [m] for a :class:`scenes.spec.ScintillationSpec`."""
    cn2 = spec.cn2_m23 if spec.cn2_m23 is not None else CN2_CLASSES_M23[spec.turbulence]
    rytov = rytov_variance(cn2, wavelength_nm, path_m, spec.wave)
    return log_sigma2(aperture_averaging(wavelength_nm, spec.aperture_m, path_m) * scintillation_index(rytov))
