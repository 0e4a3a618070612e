"""Surface state histories: oxidation, thin-plate laser heating, time -> state maps.

Physics from Bailey et al., J. Laser Appl. 20(1), 2008, Sec. VII (restated in spec
`oxidation-and-history.md`):

* Wagner parabolic oxidation ``dx/dt = kappa / x`` with Arrhenius rate
  ``kappa = kappa_0 exp(-T_0 / T)``; reflectance ``R = R_0 exp(-xi)`` with extinction
  ``xi = 2 x / a``. Integrated:
  ``xi(t_{j+1})^2 = xi(t_j)^2 + d_0 * integral exp(-T_0 / T(t)) dt``.
* Lumped thin-plate heating (per unit area)
  ``rho c_p h dT/dt = (1 - R(t)) E(t) - n_f [eps sigma (T^4 - T_amb^4) + h_c (T - T_amb)]``
  coupled with ``d(xi^2)/dt = d_0 exp(-T_0 / T)`` and a melting plateau at ``T_melt``
  that absorbs the latent heat (enthalpy formulation).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np
from scipy import special

from ._checks import finite_array, finite_scalar
from .states import StateTable, check_policy, state_names

__all__ = ["OxidationModel", "ThinPlateHeating", "HeatingResult", "History", "STEFAN_BOLTZMANN_W_M2_K4"]

STEFAN_BOLTZMANN_W_M2_K4 = 5.670374419e-8  # CODATA 2018, exact in the 2019 SI

_GL_X, _GL_W = np.polynomial.legendre.leggauss(20)
_SERIES_N = np.arange(1, 51)
_SERIES_LOGFACT = special.gammaln(_SERIES_N + 1.0)


def _log_h(x: np.ndarray) -> np.ndarray:
    """ln h(x), h(x) = 1 - x e^x E1(x) (> 0), accurate for x > 0 of any size.

    Small x: SciPy's ``exp1`` (the subtraction loses at most log10(x) < 2 digits for
    x <= 60). Large x: the asymptotic series ``h = sum_{n>=1} (-1)^(n+1) n! / x^n``,
    truncated after 50 terms (the last term is below 1e-24 of h for x > 60).
    """
    x = np.asarray(x, dtype=float)
    out = np.empty_like(x)
    small = x <= 60.0
    if np.any(small):
        xs = x[small]
        out[small] = np.log(-np.expm1(np.log(xs) + xs + np.log(special.exp1(xs))))
    if np.any(~small):
        xl = x[~small][:, None]
        terms = np.exp(_SERIES_LOGFACT - _SERIES_N * np.log(xl))
        signs = np.where(_SERIES_N % 2 == 1, 1.0, -1.0)
        out[~small] = np.log(np.sum(signs * terms, axis=1))
    return out


def _arrhenius_integrals(t: np.ndarray, temp: np.ndarray, t0: float) -> np.ndarray:
    """Exact integrals of exp(-T0 / T(t)) over each interval of a piecewise-linear T(t)."""
    dt = np.diff(t)
    ta, tb = temp[:-1], temp[1:]
    out = np.zeros(dt.size)
    if t0 == 0.0:
        return dt.copy()
    xa, xb = t0 / ta, t0 / tb
    live = dt > 0
    near = live & (np.abs(xa - xb) < 0.5)
    far = live & ~near
    if np.any(near):
        # exponent changes by < 0.5 over the interval: 20-point Gauss-Legendre is exact to
        # rounding for this analytic, nearly constant integrand
        a, b, h = ta[near][:, None], tb[near][:, None], dt[near][:, None]
        tt = a + (b - a) * 0.5 * (_GL_X + 1.0)
        out[near] = (0.5 * h * (_GL_W * np.exp(-t0 / tt))).sum(axis=1)
    if np.any(far):
        # closed form: d/dT [T e^{-x} h(x)] = e^{-T0/T} with x = T0/T  (x e^x E1(x) identity)
        a, b = ta[far], tb[far]
        lfa = np.log(a) - xa[far] + _log_h(xa[far])
        lfb = np.log(b) - xb[far] + _log_h(xb[far])
        hi = np.maximum(lfa, lfb)
        lo = np.minimum(lfa, lfb)
        diff = np.exp(hi) * -np.expm1(lo - hi)  # |F(b) - F(a)|
        out[far] = diff * dt[far] / np.abs(b - a)
    return out


class OxidationModel:
    """Wagner parabolic oxidation with an Arrhenius rate (paper Sec. VII).

    Parameters
    ----------
    activation_temperature_k : float
        T_0 [K] (>= 0). Paper's stainless-steel fit: 9060 K.
    rate_per_s : float
        d_0 = 4 kappa_0 / a^2 [1/s] (>= 0). Paper: 935 /s.
    initial_extinction : float
        xi_0 (>= 0). Paper: 0.311.
    """

    def __init__(self, activation_temperature_k, rate_per_s, initial_extinction):
        self.activation_temperature_k = finite_scalar("activation_temperature_k", activation_temperature_k, minimum=0.0)
        self.rate_per_s = finite_scalar("rate_per_s", rate_per_s, minimum=0.0)
        self.initial_extinction = finite_scalar("initial_extinction", initial_extinction, minimum=0.0)

    @classmethod
    def stainless_steel(cls) -> "OxidationModel":
        """The paper's stainless-steel fit: T_0 = 9060 K, d_0 = 935 /s, xi_0 = 0.311."""
        return cls(9060.0, 935.0, 0.311)

    def rate(self, temperature_k) -> np.ndarray:
        """d(xi^2)/dt = d_0 exp(-T_0 / T) [1/s]."""
        t = np.maximum(np.asarray(temperature_k, dtype=float), 1e-300)
        return self.rate_per_s * np.exp(-self.activation_temperature_k / t)

    def extinction(self, times_s, temperatures_k) -> np.ndarray:
        """Oxide extinction xi at each time of a piecewise-linear temperature history.

        Parameters
        ----------
        times_s : array_like, shape (N,)
            Non-decreasing times [s]; a repeated time is a temperature jump.
        temperatures_k : array_like, shape (N,)
            Absolute temperatures [K] (> 0) at those times; linear in between.

        Returns
        -------
        ndarray, shape (N,)
            xi(t), with xi(times_s[0]) = initial_extinction. Each interval's Arrhenius
            integral is exact to ~1e-13 relative (closed form via the exponential
            integral, or Gauss-Legendre where the exponent hardly changes).
        """
        t = finite_array("times_s", times_s, ndim=1)
        temp = finite_array("temperatures_k", temperatures_k, ndim=1)
        if t.shape != temp.shape:
            raise ValueError(f"temperatures_k: expected shape {t.shape} (one per time), got {temp.shape}")
        if t.size == 0:
            raise ValueError("times_s: expected at least one time, got an empty array")
        if np.any(np.diff(t) < 0):
            i = int(np.argmin(np.diff(t)))
            raise ValueError(f"times_s: expected non-decreasing times, got {t[i]!r} then {t[i + 1]!r}")
        if np.any(temp <= 0):
            raise ValueError(f"temperatures_k contains {float(temp.min())!r}: expected absolute temperatures > 0 K")
        integrals = _arrhenius_integrals(t, temp, self.activation_temperature_k)
        xi2 = self.initial_extinction**2 + self.rate_per_s * np.concatenate([[0.0], np.cumsum(integrals)])
        return np.sqrt(xi2)

    def reflectance_factor(self, times_s, temperatures_k) -> np.ndarray:
        """R(t) / R(t_0) = exp(-(xi(t) - xi_0)) (dimensionless)."""
        return np.exp(-(self.extinction(times_s, temperatures_k) - self.initial_extinction))

    def to_dict(self) -> dict:
        return {
            "activation_temperature_k": self.activation_temperature_k,
            "rate_per_s": self.rate_per_s,
            "initial_extinction": self.initial_extinction,
        }

    def __repr__(self):
        return (
            f"OxidationModel(T0={self.activation_temperature_k:g} K, d0={self.rate_per_s:g} /s, "
            f"xi0={self.initial_extinction:g})"
        )


@dataclass(frozen=True)
class HeatingResult:
    """Output of :meth:`ThinPlateHeating.solve` (arrays of shape (N,) at the requested times)."""

    times_s: np.ndarray
    temperature_k: np.ndarray
    extinction: np.ndarray
    reflectance: np.ndarray
    reflectance_factor: np.ndarray
    melt_fraction: np.ndarray
    solver_steps: int
    wall_time_s: float
    melt_onset_s: float | None = None  # first time the plate reaches T_melt [s] (None: not in the run)
    full_melt_s: float | None = None  # first time all of it is molten [s]

    def history(self, state="extinction", extrapolation: str = "error") -> "History":
        """A :class:`History` of one output, ``"extinction"``, ``"temperature_k"``,
        ``"reflectance_factor"``, ``"melt_fraction"`` or ``"time_s"``, or of two of them
        as a two-state history (``["extinction", "melt_fraction"]``)."""
        choices = {
            "extinction": self.extinction,
            "temperature_k": self.temperature_k,
            "reflectance_factor": self.reflectance_factor,
            "melt_fraction": self.melt_fraction,
            "time_s": self.times_s,
        }
        names = [state] if isinstance(state, str) else list(state)
        for name in names:
            if name not in choices:
                raise ValueError(f"state={name!r}: expected one of {sorted(choices)}, or a list of two of them")
        if len(names) == 1:
            return History(self.times_s, choices[names[0]], names[0], extrapolation=extrapolation)
        if len(names) != 2 or names[0] == names[1]:
            raise ValueError(f"state={state!r}: expected one name or two different names")
        return History(self.times_s, np.stack([choices[n] for n in names], axis=1), names, extrapolation=extrapolation)


class ThinPlateHeating:
    """Lumped thin-plate laser heating with oxidation and a melting plateau.

    Per unit area of the irradiated spot (spec `oxidation-and-history.md`):

    ``dH/dt = (1 - R) E(t) - n_f [eps sigma (T^4 - T_amb^4) + h_c (T - T_amb)]``,
    ``d(xi^2)/dt = d_0 exp(-T_0 / T)``, ``R = R_0 exp(-(xi - xi_0))``,

    where H [J/m^2] is the enthalpy above ambient; T(H) rises linearly with slope
    ``1 / (rho c_p h)``, holds at ``T_melt`` while ``rho L h`` of latent heat is absorbed
    (melt fraction 0 -> 1), then rises again. There is no vaporisation model: a
    temperature far above melting means the plate would have burnt through. The system
    is stiff (T^4, Arrhenius); it is integrated with an implicit method (Radau).

    Parameters
    ----------
    thickness_m, density_kg_m3, specific_heat_j_kg_k : float
        Plate thickness h, density rho, specific heat c_p (all > 0).
    initial_reflectance : float
        R at t = 0 (in [0, 1]) for the laser wavelength.
    emissivity : float
        Total hemispherical emissivity in [0, 1].
    convection_w_m2_k : float
        Convective coefficient h_c (>= 0).
    ambient_temperature_k : float
        T_amb (> 0); the plate starts at this temperature.
    melt_temperature_k, latent_heat_j_kg : float
        Melting point and latent heat of fusion.
    oxidation : OxidationModel, optional
        None: reflectance stays at ``initial_reflectance``.
    faces : {1, 2}
        Faces losing heat (2: front and back).
    """

    def __init__(
        self,
        thickness_m,
        density_kg_m3,
        specific_heat_j_kg_k,
        initial_reflectance,
        emissivity,
        melt_temperature_k,
        latent_heat_j_kg,
        convection_w_m2_k=10.0,
        ambient_temperature_k=293.15,
        oxidation=None,
        faces=2,
    ):
        self.thickness_m = finite_scalar("thickness_m", thickness_m, minimum=0.0, strict_min=True)
        self.density_kg_m3 = finite_scalar("density_kg_m3", density_kg_m3, minimum=0.0, strict_min=True)
        self.specific_heat_j_kg_k = finite_scalar("specific_heat_j_kg_k", specific_heat_j_kg_k, minimum=0.0, strict_min=True)
        self.initial_reflectance = finite_scalar("initial_reflectance", initial_reflectance, minimum=0.0, maximum=1.0)
        self.emissivity = finite_scalar("emissivity", emissivity, minimum=0.0, maximum=1.0)
        self.melt_temperature_k = finite_scalar("melt_temperature_k", melt_temperature_k, minimum=0.0, strict_min=True)
        self.latent_heat_j_kg = finite_scalar("latent_heat_j_kg", latent_heat_j_kg, minimum=0.0)
        self.convection_w_m2_k = finite_scalar("convection_w_m2_k", convection_w_m2_k, minimum=0.0)
        self.ambient_temperature_k = finite_scalar("ambient_temperature_k", ambient_temperature_k, minimum=0.0, strict_min=True)
        if self.melt_temperature_k <= self.ambient_temperature_k:
            raise ValueError(
                f"melt_temperature_k={self.melt_temperature_k!r}: expected above ambient_temperature_k={self.ambient_temperature_k!r}"
            )
        if oxidation is not None and not isinstance(oxidation, OxidationModel):
            raise ValueError(f"oxidation={oxidation!r}: expected an OxidationModel or None")
        self.oxidation = oxidation
        if faces not in (1, 2):
            raise ValueError(f"faces={faces!r}: expected 1 or 2")
        self.faces = int(faces)

    # Handbook values at 300 K: Incropera & DeWitt, Fundamentals of Heat and Mass Transfer,
    # 6th ed., Table A.1 (rho, c_p); melting points and latent heats from the CRC Handbook of
    # Chemistry and Physics. Emissivities of oxidising metal are rough [M]; set your own.
    @classmethod
    def stainless_steel(cls, thickness_m=1.5875e-3, initial_reflectance=0.6, **kw) -> "ThinPlateHeating":
        """AISI 304 plate (paper: 1/16 inch), with the paper's oxidation fit by default."""
        kw.setdefault("oxidation", OxidationModel.stainless_steel())
        kw.setdefault("emissivity", 0.4)
        return cls(thickness_m, 7900.0, 477.0, initial_reflectance, melt_temperature_k=1670.0, latent_heat_j_kg=2.7e5, **kw)

    @classmethod
    def copper(cls, thickness_m=3.175e-3, initial_reflectance=0.95, **kw) -> "ThinPlateHeating":
        """Pure copper plate (paper: 1/8 inch); no oxidation model (copper does not follow it)."""
        kw.setdefault("emissivity", 0.1)
        return cls(thickness_m, 8933.0, 385.0, initial_reflectance, melt_temperature_k=1358.0, latent_heat_j_kg=2.05e5, **kw)

    # -- model pieces ----------------------------------------------------------------------
    @property
    def _heat_capacity(self):
        return self.density_kg_m3 * self.specific_heat_j_kg_k * self.thickness_m  # J/(m^2 K)

    @property
    def _h_solid(self):
        return self._heat_capacity * (self.melt_temperature_k - self.ambient_temperature_k)

    @property
    def _h_latent(self):
        return self.density_kg_m3 * self.latent_heat_j_kg * self.thickness_m

    def temperature_from_enthalpy(self, enthalpy_j_m2):
        """T [K] and melt fraction from the enthalpy above ambient [J/m^2]."""
        hgt = np.asarray(enthalpy_j_m2, dtype=float)
        c = self._heat_capacity
        hs, hl = self._h_solid, self._h_latent
        temp = np.where(
            hgt < hs,
            self.ambient_temperature_k + hgt / c,
            np.where(hgt <= hs + hl, self.melt_temperature_k, self.melt_temperature_k + (hgt - hs - hl) / c),
        )
        frac = np.clip((hgt - hs) / hl, 0.0, 1.0) if hl > 0 else (hgt >= hs).astype(float)
        return np.maximum(temp, 1.0), frac

    def _xi0(self):
        return self.oxidation.initial_extinction if self.oxidation is not None else 0.0

    def _rhs(self, irradiance):
        sigma = STEFAN_BOLTZMANN_W_M2_K4
        eps, hc, ta, nf = self.emissivity, self.convection_w_m2_k, self.ambient_temperature_k, self.faces
        r0, xi0 = self.initial_reflectance, self._xi0()
        ox = self.oxidation

        def rhs(t, y):
            temp, _ = self.temperature_from_enthalpy(y[0])
            temp = float(temp)
            xi = math.sqrt(max(y[1], 0.0))
            refl = r0 * math.exp(-(xi - xi0))
            losses = nf * (eps * sigma * (temp**4 - ta**4) + hc * (temp - ta))
            d_h = (1.0 - refl) * irradiance(t) - losses
            d_q = float(ox.rate(temp)) if ox is not None else 0.0
            return [d_h, d_q]

        return rhs

    def solve(self, times_s, irradiance_w_m2, *, rtol=1e-8, atol_scale=1e-10, method="Radau") -> HeatingResult:
        """Integrate the heating/oxidation system.

        Parameters
        ----------
        times_s : array_like, shape (N,)
            Increasing output times [s]; integration starts at ``times_s[0]`` from ambient.
        irradiance_w_m2 : float or (times_s, values) pair
            Laser irradiance on the spot [W/m^2]: a constant, or a piecewise-linear table
            (zero outside it). Table knots are integration breakpoints.
        rtol : float
            Relative tolerance of the implicit solver (the accuracy knob; see
            :func:`brdfmodels.accuracy.heating_tolerance_table`).
        atol_scale : float
            Absolute tolerance as a fraction of the melting enthalpy scale.
        method : str
            An implicit ``solve_ivp`` method: "Radau", "BDF" or "LSODA".

        Returns
        -------
        HeatingResult
        """
        t = finite_array("times_s", times_s, ndim=1)
        if t.size < 2 or np.any(np.diff(t) <= 0):
            raise ValueError("times_s: expected at least two strictly increasing times")
        rtol = finite_scalar("rtol", rtol, minimum=1e-14, maximum=0.1)
        if method not in ("Radau", "BDF", "LSODA"):
            raise ValueError(f"method={method!r}: expected an implicit method, one of ['Radau', 'BDF', 'LSODA']")
        if isinstance(irradiance_w_m2, tuple):
            if len(irradiance_w_m2) != 2:
                raise ValueError("irradiance_w_m2: expected a constant or a (times_s, values) pair")
            et = finite_array("irradiance_w_m2 times", irradiance_w_m2[0], ndim=1)
            ev = finite_array("irradiance_w_m2", irradiance_w_m2[1], ndim=1, minimum=0.0)
            if et.shape != ev.shape:
                raise ValueError(f"irradiance_w_m2: {et.size} times but {ev.size} values")

            def irr(tt, et=et, ev=ev):
                return float(np.interp(tt, et, ev, left=0.0, right=0.0))

            breaks = et[(et > t[0]) & (et < t[-1])]
        else:
            e0 = finite_scalar("irradiance_w_m2", irradiance_w_m2, minimum=0.0)

            def irr(tt, e0=e0):
                return e0

            breaks = np.empty(0)
        rhs = self._rhs(irr)
        scale_h = max(self._h_solid + self._h_latent, 1.0)
        atol = [atol_scale * scale_h, atol_scale * max(self._xi0() ** 2, 1.0)]
        knots = np.unique(np.concatenate([[t[0], t[-1]], breaks]))
        y = np.array([0.0, self._xi0() ** 2])
        sol_h = np.empty(t.size)
        sol_q = np.empty(t.size)
        sol_h[0], sol_q[0] = y
        steps = 0
        from scipy.integrate import solve_ivp  # here: scipy.integrate costs 0.27 s at import

        events = self._melt_events()
        crossed = [None, None]  # melt onset, full melt [s]: the enthalpy reaching H_s, H_s + H_l
        start = time.perf_counter()
        for a, b in zip(knots[:-1], knots[1:]):
            sel = np.flatnonzero((t > a) & (t <= b))
            t_eval = np.unique(np.append(t[sel], b))  # always end at the knot
            res = solve_ivp(rhs, (a, b), y, method=method, t_eval=t_eval, rtol=rtol, atol=atol, events=events)
            if not res.success:
                raise RuntimeError(f"heating integration failed on [{a}, {b}] s: {res.message}")
            for k, te in enumerate(res.t_events):
                if crossed[k] is None and len(te):
                    crossed[k] = float(te[0])
            steps += int(res.nfev)
            sol_h[sel] = res.y[0, : sel.size]
            sol_q[sel] = res.y[1, : sel.size]
            y = res.y[:, -1]
        wall = time.perf_counter() - start
        temp, frac = self.temperature_from_enthalpy(sol_h)
        xi = np.sqrt(np.maximum(sol_q, 0.0))
        factor = np.exp(-(xi - self._xi0()))
        return HeatingResult(
            times_s=t,
            temperature_k=temp,
            extinction=xi,
            reflectance=self.initial_reflectance * factor,
            reflectance_factor=factor,
            melt_fraction=frac,
            solver_steps=steps,
            wall_time_s=wall,
            melt_onset_s=crossed[0],
            full_melt_s=crossed[1],
        )

    def _melt_events(self):
        """``solve_ivp`` events at the enthalpies where melting starts and ends (located by
        the solver's root finding, not by the output grid)."""
        hs, hl = self._h_solid, self._h_latent

        def onset(t, y):
            return y[0] - hs

        def full(t, y):
            return y[0] - (hs + hl)

        for ev in (onset, full):
            ev.direction = 1.0
        return [onset, full]


class History:
    """A material history: time -> state (or a pair of states), piecewise linear.

    Parameters
    ----------
    times_s : array_like, shape (N,)
        Strictly increasing times [s].
    states : array_like, shape (N,) or (N, 2)
        State values at those times (e.g. extinction, temperature_k); two columns for a
        two-state history.
    state_name : str or [str, str]
        Name and unit of the state (two names for two states, e.g.
        ``["extinction", "melt_fraction"]``); must match the dynamic model it drives.
    extrapolation : {"error", "clamp"}
        Outside [times_s[0], times_s[-1]]: raise (default) or hold the end states.
    """

    def __init__(self, times_s, states, state_name, extrapolation="error"):
        policy = check_policy(extrapolation)
        names = state_names(state_name)
        if len(names) == 1:
            self._tables = (StateTable(times_s, states, "time_s", policy),)
            self.state_name = names[0]
            return
        v = finite_array("states", states, ndim=2)
        if v.shape[1:] != (2,):
            raise ValueError(f"states: expected shape (N, 2) (one column per state of {names}), got {v.shape}")
        self._tables = tuple(StateTable(times_s, v[:, d], "time_s", policy) for d in range(2))
        self.state_name = names

    @property
    def times_s(self) -> np.ndarray:
        return self._tables[0].states

    @property
    def states(self) -> np.ndarray:
        """States at ``times_s``: (N,), or (N, 2) for two states."""
        if len(self._tables) == 1:
            return self._tables[0].values
        return np.stack([t.values for t in self._tables], axis=1)

    @property
    def state_dim(self) -> int:
        return len(self._tables)

    @property
    def state_names(self) -> tuple:
        """The state's name, or the two names of a two-state history."""
        return (self.state_name,) if isinstance(self.state_name, str) else self.state_name

    def state_at(self, times_s) -> np.ndarray:
        """State at the given times [s] (linear interpolation; (..., 2) for two states)."""
        if len(self._tables) == 1:
            return self._tables[0](times_s)
        return np.stack([t(times_s) for t in self._tables], axis=-1)

    @classmethod
    def from_temperature_series(cls, times_s, temperatures_k, oxidation=None, state_name="temperature_k"):
        """A measured pyrometer series as a history of temperature, or of oxide
        extinction (``state_name="extinction"``, needs ``oxidation``)."""
        if state_name == "temperature_k":
            return cls(times_s, temperatures_k, "temperature_k")
        if state_name == "extinction":
            if oxidation is None:
                raise ValueError("oxidation: an OxidationModel is needed for an extinction history")
            return cls(times_s, oxidation.extinction(times_s, temperatures_k), "extinction")
        raise ValueError(f"state_name={state_name!r}: expected 'temperature_k' or 'extinction'")

    def to_dict(self) -> dict:
        return {
            "times_s": self.times_s.tolist(),
            "states": self.states.tolist(),
            "state_name": self.state_name if isinstance(self.state_name, str) else list(self.state_name),
            "extrapolation": self._tables[0].extrapolation,
        }

    def __repr__(self):
        return f"History({self.state_name}: {self.times_s.size} points over [{self.times_s[0]:g}, {self.times_s[-1]:g}] s)"
