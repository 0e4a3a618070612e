"""A synthetic two-state truth for melting stainless steel (a test and example truth, not a
measurement).

Bailey et al., J. Laser Appl. 20(1), 2008 (the seed paper) saw, for stainless steel under a
1.06 um laser:

* Sec. V B 2 and VIII B: "the reflectance of the materials decreased as the samples were
  heated. The peak BRDF dropped to a fraction of the initial value, most likely due to
  the oxidation of the surface"; Sec. VII models that darkening by the oxide extinction
  xi (``R = R_0 exp(-xi)``, Eq. 41).
* Sec. V B 2: "After the surface began to melt, the BRDF peak returned to a value close
  to, or sometimes exceeding, its original value"; Sec. VIII B: "the specular peaks would
  reach or exceed their initial values".
* Sec. VI A: "After the surface melts, the grooving of the surface goes away and the
  reflection spots are no longer elliptical"; the molten metal slumps (the peak moves up
  on the screen) and wanders from moment to moment.

:class:`SyntheticMeltingSteel` puts numbers on that trend as a function of the two states
(oxide extinction xi, melt fraction m). Every number below is a choice made for a test
truth, stated so a test can redo it by hand; none is measured. The slump (a tilt of the
mean surface normal) and the wander are NOT in this BRDF: it lives in the surface frame
of the molten surface, and a scene tilts that frame (``melt_tilt_deg``,
``melt_wander_deg`` of a scene material).
"""

from __future__ import annotations

import math

import numpy as np

from ._checks import finite_scalar
from .models import BRDFModel

__all__ = ["SyntheticMeltingSteel"]


class SyntheticMeltingSteel(BRDFModel):
    """Analytic anisotropic BRDF of stainless steel over (oxide extinction, melt fraction).

    A Ward-like lobe in half-vector slopes (reciprocal), x along the grooves, plus a
    diffuse floor:

    ``f_r = kd / pi + ks exp(-(hx^2 / ax^2 + hy^2 / ay^2) / hz^2) / (4 pi ax ay sqrt(cos_i cos_r))``

    with ``h = (wi + wo) / |wi + wo|``. Its peak, in the mirror direction (h = normal), is
    ``kd / pi + ks / (4 pi ax ay cos_i)``.

    **Solid, oxidising (m = 0)**, with ``d = xi - xi_0`` (identical to
    :class:`brdfmodels.validation.SyntheticGroovedMetal`): ``ks_o = ks exp(-d)`` (the
    paper's ``R = R_0 exp(-(xi - xi_0))``, Eq. 41), ``ax_o = ax g``, ``ay_o = ay g`` with
    ``g = 1 + 0.6 d`` (the lobe broadens 60 % per unit of extinction), ``kd_o = kd (1 + 0.3
    d)``. The lobe's peak falls as ``exp(-d) / g^2``: to 0.123 of its initial value at
    xi = 1.4.

    **Molten (m = 1)**, whatever xi (the oxide is broken up in the melt pool): the lobe's
    reflectance recovers to ``ks_m = melt_reflectance_factor * ks`` and the lobe becomes
    isotropic (the grooves are gone, paper Sec. VI A) and narrower, of width
    ``a_m = sqrt(ax ay melt_reflectance_factor / melt_peak_factor)``, so its peak is
    ``melt_peak_factor`` (default 1.3) times the fresh metal's lobe peak (paper Secs. V B 2
    and VIII B: close to or above the initial value). ``kd_m = kd``.

    **Melting (0 < m < 1)**: each of ks, ax, ay, kd is interpolated geometrically (linearly
    in its logarithm) between the solid value at the current xi and the molten value, so
    the log of the lobe's peak is linear in m and rises monotonically to its molten value.

    Defaults: ks = 0.5, kd = 0.03, ax = 0.06, ay = 0.15 (those of SyntheticGroovedMetal),
    xi_0 = 0.311 (the paper's stainless-steel fit, Sec. VII), melt_peak_factor = 1.3,
    melt_reflectance_factor = 1.0 (a_m = 0.0832). At 20 deg incidence the peak f_r is
    4.71 /sr fresh (xi_0, m = 0), 0.59 /sr at (1.4, 0) and 6.13 /sr (1.299x fresh, the
    diffuse floor diluting the lobe's 1.3x) molten.

    Parameters
    ----------
    ks, kd : float
        Fresh lobe reflectance and diffuse reflectance (>= 0).
    ax, ay : float
        Fresh lobe widths (half-vector slopes) along and across the grooves (> 0).
    melt_peak_factor : float
        Molten lobe peak over the fresh lobe peak (> 0).
    melt_reflectance_factor : float
        Molten lobe reflectance over the fresh one (> 0).
    initial_extinction : float
        xi_0, the extinction of the fresh surface (>= 0).
    max_extinction : float
        Upper end of :attr:`state_range` (the formulas hold beyond it).

    Notes
    -----
    Synthetic: the trend is the paper's, the numbers are not measurements. It is not
    registered as a model (not for scenes); fit it (witness-screen simulation + SH fit) to
    make a scene material, as ``examples/make_example_materials.py`` does.
    """

    def __init__(self, ks=0.5, kd=0.03, ax=0.06, ay=0.15, *, melt_peak_factor=1.3, melt_reflectance_factor=1.0,
                 initial_extinction=0.311, max_extinction=20.0):
        self.ks = finite_scalar("ks", ks, minimum=0.0)
        self.kd = finite_scalar("kd", kd, minimum=0.0)
        self.ax = finite_scalar("ax", ax, minimum=0.0, strict_min=True)
        self.ay = finite_scalar("ay", ay, minimum=0.0, strict_min=True)
        self.melt_peak_factor = finite_scalar("melt_peak_factor", melt_peak_factor, minimum=0.0, strict_min=True)
        self.melt_reflectance_factor = finite_scalar("melt_reflectance_factor", melt_reflectance_factor, minimum=0.0,
                                                     strict_min=True)
        self.initial_extinction = finite_scalar("initial_extinction", initial_extinction, minimum=0.0)
        self.max_extinction = finite_scalar("max_extinction", max_extinction, minimum=self.initial_extinction,
                                            strict_min=True)
        self._freeze()

    @property
    def is_dynamic(self):
        return True

    @property
    def state_dim(self) -> int:
        return 2

    @property
    def state_name(self):
        return ("extinction", "melt_fraction")

    @property
    def state_range(self):
        return ((self.initial_extinction, self.max_extinction), (0.0, 1.0))

    @property
    def melt_width(self) -> float:
        """a_m: the molten (isotropic) lobe width, ``sqrt(ax ay rho_m / P_m)``."""
        return math.sqrt(self.ax * self.ay * self.melt_reflectance_factor / self.melt_peak_factor)

    def parameters(self, extinction, melt_fraction) -> dict:
        """ks, ax, ay, kd at the states (the formulas of the class docstring).

        Parameters
        ----------
        extinction : float or ndarray
            Oxide extinction xi (dimensionless, >= 0).
        melt_fraction : float or ndarray
            Molten fraction m in [0, 1].

        Returns
        -------
        dict of ndarray
            ``ks`` and ``kd`` (dimensionless reflectances), ``ax`` and ``ay`` (slopes).
        """
        xi = np.asarray(extinction, float)
        m = np.asarray(melt_fraction, float)
        if np.any(~np.isfinite(xi)) or np.any(xi < 0):
            raise ValueError(f"extinction={float(np.min(xi))!r}: expected finite values >= 0")
        if np.any(~np.isfinite(m)) or np.any((m < 0) | (m > 1)):
            bad = float(m[(m < 0) | (m > 1) | ~np.isfinite(m)].ravel()[0]) if m.ndim else float(m)
            raise ValueError(f"melt_fraction={bad!r}: expected values in [0, 1]")
        d = xi - self.initial_extinction
        g = 1.0 + 0.6 * d
        if np.any(g <= 0):
            raise ValueError(f"extinction={float(np.min(xi))!r}: expected values > initial_extinction - 1/0.6 "
                             f"= {self.initial_extinction - 1 / 0.6:g} (the lobe width 1 + 0.6 (xi - xi_0) must stay > 0)")
        solid = {"ks": self.ks * np.exp(-d), "ax": self.ax * g, "ay": self.ay * g, "kd": self.kd * (1.0 + 0.3 * d)}
        a_m = self.melt_width
        molten = {"ks": self.melt_reflectance_factor * self.ks, "ax": a_m, "ay": a_m, "kd": self.kd}
        return {k: _geometric_blend(solid[k], molten[k], m) for k in solid}

    def peak(self, extinction, melt_fraction, incidence_rad) -> np.ndarray:
        """f_r [1/sr] in the mirror direction: ``kd / pi + ks / (4 pi ax ay cos_i)``."""
        p = self.parameters(extinction, melt_fraction)
        return p["kd"] / math.pi + p["ks"] / (4.0 * math.pi * p["ax"] * p["ay"] * np.cos(incidence_rad))

    def _fr(self, wi, wo, state):
        s = np.asarray(state, float)
        p = self.parameters(s[..., 0], s[..., 1])
        h = wi + wo
        h = h / np.linalg.norm(h, axis=1, keepdims=True)
        hz = np.maximum(h[:, 2], 1e-12)
        e = (h[:, 0] ** 2 / p["ax"] ** 2 + h[:, 1] ** 2 / p["ay"] ** 2) / hz**2
        ward = np.exp(-e) / (4 * math.pi * p["ax"] * p["ay"] * np.sqrt(np.maximum(wi[:, 2] * wo[:, 2], 1e-300)))
        return p["kd"] / math.pi + p["ks"] * ward

    def _params(self):
        return {"ks": self.ks, "kd": self.kd, "ax": self.ax, "ay": self.ay, "melt_peak_factor": self.melt_peak_factor,
                "melt_reflectance_factor": self.melt_reflectance_factor, "initial_extinction": self.initial_extinction,
                "max_extinction": self.max_extinction}


def _geometric_blend(solid, molten, m):
    """``solid^(1 - m) molten^m``, linear in the logarithm (both > 0; a zero stays zero
    at the end it belongs to)."""
    solid = np.asarray(solid, float)
    with np.errstate(divide="ignore", invalid="ignore"):
        out = np.exp((1.0 - m) * np.log(solid) + m * np.log(molten))
    return np.where(m == 0, solid, np.where(m == 1, molten, out))
