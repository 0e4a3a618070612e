"""Scatter lobes about the specular direction as optical-design codes define them: ABg
(Harvey) and a Gaussian lobe, in direction-cosine space.

Zemax OpticStudio's vectors (spec `range-safety.md` section 9, [C] OpticStudio help
"Scatter Models"): beta0 and beta are the projections on the surface plane of the
specular and of the scattered unit vectors, ``|beta0| = sin theta_spec``, ``|beta| =
sin theta_s``; ``X = beta - beta0`` (``|X| <= 2``). In this package's surface frame
(z the normal, ``wi`` to the source, ``wo`` to the observer) the specular direction of
``wi`` is ``(-wi_x, -wi_y, wi_z)``, so ``X = (wo_x + wi_x, wo_y + wi_y)``: symmetric in
``wi`` and ``wo`` (both models are reciprocal).

- ABg [C, Zemax KB "Fitting ABg scattering coefficients"]: ``BSDF = A / (B + |X|^g)``;
  A >= 0, B > 1e-12 unless g = 0 (then the BSDF is the constant A / (B + 1), "effectively
  Lambertian"); the peak in the specular direction is A / B. FRED's defaults A = 0.0025,
  B = 0.001, g = 1.8 give a total integrated scatter of 0.041344 at normal incidence
  ([D], the spec's checkable value).
- Gaussian lobe ([C] OpticStudio: rotationally symmetric in direction-cosine space, sigma
  the dimensionless width, at most 5; the form [M]): ``BSDF = peak exp(-|X|^2 / sigma^2)``
  with ``peak`` its value in the specular direction [1/sr].

Compose them with a Lambertian or an ideal mirror by the sum (``bm.Sum([...])`` or ``+``),
as published HEL reflection fits do (Gaussian specular lobe + ABg scatter + Lambertian).
"""

from __future__ import annotations

import numpy as np

from ._checks import finite_scalar
from .models import BRDFModel
from .registry import register

__all__ = ["ABg", "GaussianLobe", "direction_cosine_offset"]


def direction_cosine_offset(wi, wo) -> np.ndarray:
    """|X| = |beta - beta0| for flattened direction pairs (N, 3): the distance in the
    surface plane between the projections of ``wo`` and of the mirror image of ``wi``."""
    return np.hypot(wo[:, 0] + wi[:, 0], wo[:, 1] + wi[:, 1])


@register("abg")
class ABg(BRDFModel):
    """ABg (Harvey) scatter: ``f_r = A / (B + |beta - beta0|^g)`` [1/sr].

    Parameters
    ----------
    a : float
        A, the numerator [1/sr] (>= 0; 0: no scatter).
    b : float
        B, the knee (> 1e-12 unless g = 0; >= 0).
    g : float
        The slope exponent, 0 to 10 (0: the constant A / (B + 1)).
    """

    def __init__(self, a, b, g):
        self.a = finite_scalar("a", a, minimum=0.0, maximum=1e12)
        self.g = finite_scalar("g", g, minimum=0.0, maximum=10.0)
        self.b = finite_scalar("b", b, minimum=0.0 if self.g == 0.0 else 1e-12, maximum=1e12)
        self._freeze()

    def _fr(self, wi, wo, state):
        x = direction_cosine_offset(wi, wo)
        return self.a / (self.b + (np.ones_like(x) if self.g == 0.0 else x ** self.g))

    def _params(self):
        return {"a": self.a, "b": self.b, "g": self.g}


@register("gaussian-lobe")
class GaussianLobe(BRDFModel):
    """Gaussian lobe about the specular direction in direction-cosine space:
    ``f_r = peak exp(-|beta - beta0|^2 / sigma^2)`` [1/sr].

    Parameters
    ----------
    peak : float
        Value in the specular direction [1/sr] (>= 0).
    sigma : float
        Width in direction cosines, (0, 5] (near 5 the lobe is close to Lambertian).
    """

    def __init__(self, peak, sigma):
        self.peak = finite_scalar("peak", peak, minimum=0.0, maximum=1e12)
        self.sigma = finite_scalar("sigma", sigma, minimum=1e-6, maximum=5.0)
        self._freeze()

    def _fr(self, wi, wo, state):
        x = direction_cosine_offset(wi, wo)
        return self.peak * np.exp(-(x / self.sigma) ** 2)

    def _params(self):
        return {"peak": self.peak, "sigma": self.sigma}
