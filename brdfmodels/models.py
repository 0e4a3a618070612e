"""BRDF models: immutable, registered by name, vectorised over (..., 3) direction arrays.

Every model evaluates ``f_r(wi, wo)`` in sr^-1 through :meth:`BRDFModel.evaluate`:
zero when either direction is at or below the horizon, never nan, and finite (values are
capped at ``FR_MAX = 1e300`` sr^-1, reached only within ~1e-100 of the horizon for models
that diverge there). :meth:`BRDFModel.evaluate_cos` returns ``f_r cos(theta_r)`` computed
without dividing by ``cos(theta_r)`` where the model allows it (spec
`dynamic-sh-brdf.md` section 3): use it for irradiance at grazing observers.

Ideal mirrors carry a delta lobe that cannot be sampled: :class:`Specular` reports zero
for its finite part and exposes ``specular_reflectance(wi)`` so a ray tracer follows it
as a beam in the mirror direction.
"""

from __future__ import annotations

import inspect
import json
import math

import numpy as np

from ._checks import directions, finite_array, finite_scalar
from .geometry import half_diff_parts, normalize_sum
from .optics import N_MAX, N_MIN, POLARIZATIONS, fresnel_reflectance, optical_constants
from .parallel import map_blocks
from .registry import model_from_dict, register
from .sh import SHBasis
from .states import (
    StateTable,
    bilinear_rows,
    bilinear_weights,
    check_in_range,
    check_in_range_2d,
    check_policy,
    grid_points,
    interpolation_weights,
    interpolate_rows,
    path_pieces,
    quadratic_max,
    segment_extremes,
    state_axes,
    state_names,
)

__all__ = [
    "BRDFModel",
    "Lambertian",
    "Specular",
    "TorranceSparrow5",
    "SphericalHarmonicBRDF",
    "DynamicBRDF",
    "Envelope",
    "Sum",
    "Scaled",
    "FR_MAX",
]

FR_MAX = 1e300
_COS_FLOOR = 1e-100  # cosines below this are floored where a model divides by them
_EXP_MAX = 700.0  # largest exponent accepted in a parameter (TS5 b)
_LOG_FR_MAX = math.log(FR_MAX)  # exponents of log-SH models are capped here: f_r <= FR_MAX


def _prepare(wi, wo):
    wi = directions("wi", wi)
    wo = directions("wo", wo)
    try:
        wi, wo = np.broadcast_arrays(wi, wo)
    except ValueError:
        raise ValueError(f"wi and wo: shapes {wi.shape} and {wo.shape} do not broadcast") from None
    shape = wi.shape[:-1]
    return wi.reshape(-1, 3), wo.reshape(-1, 3), shape


class BRDFModel:
    """Base class of all BRDF models (immutable after construction).

    Subclasses implement ``_fr(wi, wo, state)`` on flattened, normalised direction pairs
    that are all above the horizon, and ``_params()`` for JSON persistence.
    """

    name = ""
    reciprocal = True

    # -- immutability ------------------------------------------------------------------
    def __setattr__(self, key, value):
        if self.__dict__.get("_frozen", False):
            raise AttributeError(f"{type(self).__name__} is immutable; build a new model instead")
        object.__setattr__(self, key, value)

    def _freeze(self):
        object.__setattr__(self, "_frozen", True)

    # -- state ---------------------------------------------------------------------------
    @property
    def is_dynamic(self) -> bool:
        """True when the model depends on a state (``state=`` is then required)."""
        return False

    @property
    def state_name(self):
        """Name and unit of the state (``"temperature_k"``, ...), or None."""
        return None

    @property
    def state_range(self):
        """(low, high) of the states the model is tabulated on, or None."""
        return None

    def state_nodes(self) -> np.ndarray:
        """States at which tabulated quantities change slope (empty for static models)."""
        return np.empty(0)

    @property
    def state_dim(self) -> int:
        """How many states the model depends on: 0 (static), 1, or 2 (a pair)."""
        return 1 if self.is_dynamic else 0

    def _single_state(self, st) -> bool:
        """True when a checked state is one state for all rows (or there is none)."""
        return st is None or np.ndim(st) == max(self.state_dim - 1, 0)

    def _check_state(self, state, shape):
        if not self.is_dynamic:
            return None
        if state is None:
            raise ValueError(
                f"state: {type(self).__name__} depends on {self.state_name}; pass state=<value in {_range_text(self.state_range)}>"
            )
        s = np.asarray(state, dtype=float)
        if self.state_dim == 2:
            if s.shape[-1:] != (2,):
                raise ValueError(f"state: {type(self).__name__} depends on the pair {list(self.state_name)}; "
                                 f"expected [value, value] (or an array of pairs), got shape {s.shape}")
            if s.ndim == 1:
                return s
            try:
                return np.broadcast_to(s, shape + (2,)).reshape(-1, 2)
            except ValueError:
                raise ValueError(f"state: shape {s.shape} does not broadcast to the direction shape {shape} + (2,)") from None
        if s.ndim == 0:
            return float(s)
        try:
            return np.broadcast_to(s, shape).ravel()
        except ValueError:
            raise ValueError(f"state: shape {s.shape} does not broadcast to the direction shape {shape}") from None

    # -- evaluation ----------------------------------------------------------------------
    def _fr(self, wi, wo, state):  # pragma: no cover - abstract
        raise NotImplementedError

    def _fr_cos(self, wi, wo, state):
        return self._fr(wi, wo, state) * wo[:, 2]

    def _evaluate_with(self, fn, wi, wo, state):
        wi, wo, shape = _prepare(wi, wo)
        st = self._check_state(state, shape)
        out = np.zeros(wi.shape[0])
        valid = (wi[:, 2] > 0.0) & (wo[:, 2] > 0.0)
        if np.any(valid):
            all_valid = bool(valid.all())
            a, b = (wi, wo) if all_valid else (wi[valid], wo[valid])
            s = st if (self._single_state(st) or all_valid) else st[valid]
            with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
                v = fn(a, b, s)
            v = np.minimum(np.nan_to_num(v, nan=FR_MAX, posinf=FR_MAX), FR_MAX)
            if all_valid:
                out = v
            else:
                out[valid] = v
        return out.reshape(shape)

    def evaluate(self, wi, wo, *, state=None) -> np.ndarray:
        """BRDF f_r [1/sr] at direction pairs.

        Parameters
        ----------
        wi, wo : array_like, shape (..., 3)
            Directions to the source and to the observer in the surface frame
            (z = normal, x = material tangent); normalised on entry, broadcast together.
        state : float or array_like, optional
            Material state (for dynamic models; ignored by static ones). An array
            broadcasts against the direction shape.

        Returns
        -------
        ndarray, shape (...)
            f_r in sr^-1; 0 where either direction is at or below the horizon.
        """
        return self._evaluate_with(self._fr, wi, wo, state)

    def evaluate_cos(self, wi, wo, *, state=None) -> np.ndarray:
        """Projected BRDF ``f_r cos(theta_r)`` [1/sr] (no 0/0 at grazing observers)."""
        return self._evaluate_with(self._fr_cos, wi, wo, state)

    # -- delta lobes ---------------------------------------------------------------------
    @property
    def has_specular(self) -> bool:
        """True when the model has an ideal-mirror (delta) lobe to trace as a beam."""
        return False

    def _spec(self, wi, state):
        return np.zeros(wi.shape[0])

    def specular_reflectance(self, wi, *, state=None) -> np.ndarray:
        """Reflectance of the delta lobe into the mirror direction (0 if none), shape (...)."""
        wi = directions("wi", wi)
        shape = wi.shape[:-1]
        flat = wi.reshape(-1, 3)
        st = self._check_state(state, shape)
        out = np.where(flat[:, 2] > 0.0, self._spec(flat, st), 0.0)
        return out.reshape(shape)

    # -- envelope support ------------------------------------------------------------------
    def _fr_segment_max(self, wi, wo, s_lo, s_hi, fanout_h):
        """Upper bound of f_r over states in [s_lo, s_hi] (exact for the built-in cases)."""
        return self._fr(wi, wo, None)

    def _spec_max(self, wi, nodes):
        return self._spec(wi, None)

    # -- persistence -----------------------------------------------------------------------
    def _params(self) -> dict:  # pragma: no cover - abstract
        raise NotImplementedError

    def to_dict(self) -> dict:
        """``{"type": name, "params": {...}}`` with JSON-ready values (exact round trip)."""
        return {"type": self.name, "params": self._params()}

    @classmethod
    def _decode(cls, params: dict) -> dict:
        return params

    @classmethod
    def from_params(cls, params: dict):
        """Build the model from a parameter mapping; unknown keys are errors."""
        sig = inspect.signature(cls.__init__)
        known = [p for p in sig.parameters if p != "self"]
        unknown = set(params) - set(known)
        if unknown:
            raise ValueError(f"{cls.name}: unknown parameters {sorted(unknown)}; expected some of {known}")
        missing = [k for k, p in sig.parameters.items() if k != "self" and p.default is inspect.Parameter.empty
                   and p.kind in (p.POSITIONAL_OR_KEYWORD, p.KEYWORD_ONLY) and k not in params]
        if missing:
            raise ValueError(f"{cls.name}: missing parameter{'s' if len(missing) > 1 else ''} {', '.join(missing)}; "
                             f"expected {known}")
        try:
            return cls(**cls._decode(dict(params)))
        except (TypeError, AttributeError, KeyError, IndexError, ZeroDivisionError, OverflowError) as exc:
            raise ValueError(f"{cls.name}: bad parameters ({type(exc).__name__}: {' '.join(str(exc).split())[:200]})") from None

    def __eq__(self, other):
        return type(self) is type(other) and self.to_dict() == other.to_dict()

    def __hash__(self):
        return hash(json.dumps(self.to_dict(), sort_keys=True))

    def __add__(self, other):
        if not isinstance(other, BRDFModel):
            return NotImplemented
        left = list(self.models) if isinstance(self, Sum) else [self]
        right = list(other.models) if isinstance(other, Sum) else [other]
        return Sum(left + right)

    def __repr__(self):
        items = ", ".join(f"{k}={_short_repr(v)}" for k, v in self._params().items())
        return f"{type(self).__name__}({items})"


def _range_text(r) -> str:
    if r is not None and isinstance(r[0], tuple):
        return "[" + ", ".join(f"[{lo!r}, {hi!r}]" for lo, hi in r) + "] (per state)"
    return f"[{r[0]!r}, {r[1]!r}]"


def _short_repr(v):
    text = repr(v)
    return text if len(text) < 60 else text[:57] + "..."


# ----------------------------------------------------------------------------------------
@register("lambertian")
class Lambertian(BRDFModel):
    """Ideal diffuse reflector: ``f_r = reflectance / pi``.

    Parameters
    ----------
    reflectance : float
        Directional-hemispherical reflectance rho in [0, 1].
    """

    def __init__(self, reflectance):
        self.reflectance = finite_scalar("reflectance", reflectance, minimum=0.0, maximum=1.0)
        self._freeze()

    def _fr(self, wi, wo, state):
        return np.full(wi.shape[0], self.reflectance / math.pi)

    def _params(self):
        return {"reflectance": self.reflectance}


# ----------------------------------------------------------------------------------------
@register("specular")
class Specular(BRDFModel):
    """Ideal mirror: a delta lobe in the mirror direction, traced as a beam.

    Its finite part is zero. The reflectance of the lobe is either a constant or the
    unpolarised Fresnel reflectance (:func:`brdfmodels.optics.fresnel_reflectance`) of a
    complex index ``n + i k`` at the incidence angle.

    Parameters
    ----------
    reflectance : float, optional
        Constant reflectance in [0, 1].
    n, k : float, optional
        Complex refractive index at the laser wavelength (give ``n``; ``k`` defaults to 0).
        Exactly one of ``reflectance`` and ``n`` must be given.
    polarization : {"unpolarized", "worst"}, optional
        With ``n``: the mean of the s and p reflectances (default), or the larger
        (``"worst"``: bounds any polarisation state).
    """

    def __init__(self, reflectance=None, n=None, k=None, polarization=None):
        if (reflectance is None) == (n is None):
            raise ValueError(
                f"Specular: give exactly one of reflectance (constant) or n (and k) for Fresnel; "
                f"got reflectance={reflectance!r}, n={n!r}"
            )
        if reflectance is not None:
            if k is not None:
                raise ValueError(f"k={k!r}: only used with n (Fresnel); a constant reflectance was given")
            if polarization is not None:
                raise ValueError(f"polarization={polarization!r}: only used with n (Fresnel); a constant reflectance was given")
            self.reflectance = finite_scalar("reflectance", reflectance, minimum=0.0, maximum=1.0)
            self.n = None
            self.k = None
            self.polarization = None
        else:
            self.reflectance = None
            self.n = finite_scalar("n", n, minimum=N_MIN, maximum=N_MAX)
            self.k = finite_scalar("k", 0.0 if k is None else k, minimum=0.0, maximum=N_MAX)
            self.polarization = "unpolarized" if polarization is None else polarization
            if self.polarization not in POLARIZATIONS:
                raise ValueError(f"polarization={polarization!r}: expected one of {list(POLARIZATIONS)}")
        self._freeze()

    @classmethod
    def for_material(cls, material: str, wavelength_nm: float) -> "Specular":
        """Fresnel mirror of a bundled material (``"cu"``, ``"al"``) at a wavelength."""
        n, k = optical_constants(material, wavelength_nm)
        return cls(n=n, k=k)

    def _fr(self, wi, wo, state):
        return np.zeros(wi.shape[0])

    @property
    def has_specular(self):
        return True

    def _spec(self, wi, state):
        if self.reflectance is not None:
            return np.full(wi.shape[0], self.reflectance)
        return fresnel_reflectance(wi[:, 2], self.n, self.k, self.polarization)

    def _params(self):
        if self.reflectance is not None:
            return {"reflectance": self.reflectance}
        extra = {} if self.polarization == "unpolarized" else {"polarization": self.polarization}
        return {"n": self.n, "k": self.k, **extra}


# ----------------------------------------------------------------------------------------
@register("torrance-sparrow-5")
class TorranceSparrow5(BRDFModel):
    """Five-parameter modified Torrance-Sparrow BRDF (Zhang et al., Optica Applicata 40(1), 2010).

    ``f_r = kb D(alpha) exp[b (1 - cos gamma)^a] G / (cos theta_i cos theta_r) + kd``

    with ``cos alpha = h.z`` (facet tilt), ``cos gamma = wi.h`` (local incidence angle).

    RECONSTRUCTED parts (the paper's equations were images; spec
    `five-parameter-brdf.md`): the "elliptical" facet distribution is taken as the
    Trowbridge-Reitz-type ellipsoid ``D = kr^2 cos a / (1 + (kr^2 - 1) cos^2 a)``
    (D(0) = 1), and the shadowing as the parameter-free Torrance-Sparrow V-groove term
    ``G = min(1, 2 cos a cos i / cos g, 2 cos a cos r / cos g)``. With the white-paint
    parameters this gives DHR = 0.734 at normal incidence, the paper's 73.4 %.

    Parameters
    ----------
    kb : float
        Specular coefficient (>= 0).
    kr : float
        Ratio of the ellipsoid axes (> 0); smaller gives a sharper peak.
    a : float
        Exponent of the relative Fresnel factor (> 0).
    b : float
        Coefficient of the relative Fresnel factor ``R0 = exp[b (1 - cos gamma)^a]``;
        often strongly negative for fitted data (a peak at backscatter). Not clamped;
        values above 700 would overflow and are rejected.
    kd : float
        Diffuse term [1/sr] (>= 0).
    """

    def __init__(self, kb, kr, a, b, kd):
        self.kb = finite_scalar("kb", kb, minimum=0.0)
        self.kr = finite_scalar("kr", kr, minimum=0.0, strict_min=True)
        self.a = finite_scalar("a", a, minimum=0.0, strict_min=True)
        self.b = finite_scalar("b", b, maximum=_EXP_MAX)
        self.kd = finite_scalar("kd", kd, minimum=0.0)
        self._freeze()

    def _fr(self, wi, wo, state):
        h = normalize_sum(wi, wo)
        ca = np.clip(h[:, 2], 0.0, 1.0)
        cg = np.clip(np.einsum("ij,ij->i", wi, h), 1e-300, 1.0)
        ci = np.maximum(wi[:, 2], _COS_FLOOR)
        cr = np.maximum(wo[:, 2], _COS_FLOOR)
        kr2 = self.kr * self.kr
        d = kr2 * ca / (1.0 + (kr2 - 1.0) * ca * ca)
        r0 = np.exp(self.b * np.power(np.maximum(1.0 - cg, 0.0), self.a))
        g_over = np.minimum(np.minimum(1.0 / (ci * cr), 2.0 * ca / (cg * cr)), 2.0 * ca / (cg * ci))
        return self.kb * d * r0 * g_over + self.kd

    def _params(self):
        return {"kb": self.kb, "kr": self.kr, "a": self.a, "b": self.b, "kd": self.kd}


# ----------------------------------------------------------------------------------------
def _check_basis(basis):
    if isinstance(basis, dict):
        basis = SHBasis.from_dict(basis)
    if not isinstance(basis, SHBasis):
        raise ValueError(f"basis={basis!r}: expected an SHBasis")
    return basis


def _check_fanout(name, value):
    return finite_scalar(name, value, minimum=0.0, strict_min=True, maximum=10.0)


_SH_CHUNK = 32768  # rows per block: the (K, chunk) basis stays in cache, memory stays O(chunk)


def _sh_eval(basis, fanout_h, fanout_d, log, wi, wo, coef, divide_r):
    """f~ / (cos i [cos r]) at direction pairs for coefficients (K,) or per-row (n, K)."""
    n = wi.shape[0]
    s = np.empty(n)

    def block(a, b):
        y = basis.design_transposed(*half_diff_parts(wi[a:b], wo[a:b]), fanout_h, fanout_d)
        s[a:b] = coef @ y if coef.ndim == 1 else np.einsum("kn,nk->n", y, coef[a:b])

    map_blocks(block, n, _SH_CHUNK)
    ci = np.maximum(wi[:, 2], _COS_FLOOR)
    cr = np.maximum(wo[:, 2], _COS_FLOOR)
    if log:
        v = s - np.log(ci)
        if divide_r:
            v -= np.log(cr)
        return np.exp(np.minimum(v, _LOG_FR_MAX))
    den = ci * cr if divide_r else ci
    return np.maximum(s, 0.0) / den


def _column_bound(col) -> float:
    """Upper bound of |basis column| over the sphere."""
    degrees = (col[1],) if col[0] != "hd" else (col[1], col[3])
    return math.prod(math.sqrt(2.0 * (2 * l + 1) / (4.0 * math.pi)) for l in degrees)


class _SHMixin:
    """Shared parameter handling of the spherical-harmonic models."""

    def _fanout_h(self, override):
        return self.fanout if override is None else override


@register("spherical-harmonic")
class SphericalHarmonicBRDF(_SHMixin, BRDFModel):
    """One-state spherical-harmonic BRDF (Bailey et al., J. Laser Appl. 20(1), 2008, Sec. IV).

    ``f~ = cos(theta_i) cos(theta_r) f_r`` (Eq. 17) is expanded in the basis of
    fanned-out (Eq. 34) halfway/difference angles; with ``log=True`` the expansion is of
    ``ln f~`` (separable logarithmic form, Eq. 33), otherwise of ``f~`` itself (a linear
    expansion is clipped at 0 so the BRDF stays non-negative).

    Parameters
    ----------
    basis : SHBasis
    coefficients : array_like, shape (K,)
    fanout : float
        Fan-out exponent s_e used by the fit (paper: 0.6).
    log : bool
        Whether the expansion is of ln f~.
    """

    def __init__(self, basis, coefficients, fanout=0.6, log=True):
        self.basis = _check_basis(basis)
        c = finite_array("coefficients", coefficients, ndim=1)
        if c.shape != (self.basis.size,):
            raise ValueError(f"coefficients: expected shape ({self.basis.size},) for this basis, got {c.shape}")
        c = c.copy()
        c.setflags(write=False)
        self.coefficients = c
        self.fanout = _check_fanout("fanout", fanout)
        self.log = bool(log)
        self._freeze()

    def _fr(self, wi, wo, state, fanout_h=None):
        return _sh_eval(self.basis, self._fanout_h(fanout_h), self.fanout, self.log, wi, wo, self.coefficients, True)

    def _fr_cos(self, wi, wo, state):
        return _sh_eval(self.basis, self.fanout, self.fanout, self.log, wi, wo, self.coefficients, False)

    def _fr_segment_max(self, wi, wo, s_lo, s_hi, fanout_h):
        return self._fr(wi, wo, None, fanout_h)

    @classmethod
    def _decode(cls, params):
        return params

    def _params(self):
        return {
            "basis": self.basis.to_dict(),
            "coefficients": self.coefficients.tolist(),
            "fanout": self.fanout,
            "log": self.log,
        }


@register("dynamic-spherical-harmonic")
class DynamicBRDF(_SHMixin, BRDFModel):
    """Spherical-harmonic BRDF over a table of one or two material states (paper Sec. IV H).

    Each coefficient is interpolated linearly in the state (per axis: bilinearly over two
    states, the paper's rule applied along each), so ``ln f~`` (or ``f~``) is a convex
    blend of the tabulated corners: its maximum over the table is at a node (spec
    section 9), and along a straight path inside one cell it is a quadratic in the path
    parameter (linear for one state), which :meth:`evaluate_many` maximises exactly.

    Parameters
    ----------
    basis : SHBasis
    states : array_like, shape (T,), or [nodes_1 (n1,), nodes_2 (n2,)]
        Strictly increasing state values; two arrays for a two-state table.
    coefficients : array_like, shape (T, K) or (n1, n2, K)
        One coefficient row per state (per state pair).
    state_name : str or [str, str]
        What the state is, with its unit: ``"temperature_k"``, ``"time_s"``,
        ``"extinction"``; two names for two states, e.g. ``["extinction", "melt_fraction"]``.
    fanout : float
        Fan-out exponent of the fits.
    log : bool
        Whether the expansion is of ln f~.
    extrapolation : {"error", "clamp"}
        Outside the table: ValueError naming the range (default), or hold the end states
        (per axis).
    """

    def __init__(self, basis, states, coefficients, state_name, fanout=0.6, log=True, extrapolation="error"):
        self.basis = _check_basis(basis)
        names = state_names(state_name)
        axes = state_axes(states, names)
        object.__setattr__(self, "_axes", axes)
        object.__setattr__(self, "_names", names)
        self.states = axes[0] if len(axes) == 1 else axes
        c = finite_array("coefficients", coefficients, ndim=len(axes) + 1)
        want = tuple(a.size for a in axes) + (self.basis.size,)
        if c.shape != want:
            what = "states x basis size" if len(axes) == 1 else "nodes_1 x nodes_2 x basis size"
            raise ValueError(f"coefficients: expected shape {want} ({what}), got {c.shape}")
        c = c.copy()
        c.setflags(write=False)
        self.coefficients = c
        self.fanout = _check_fanout("fanout", fanout)
        self.log = bool(log)
        self.extrapolation = check_policy(extrapolation)
        # |y_l^m| <= sqrt(2) sqrt((2l+1)/(4 pi)): bounds the exponent so evaluate_many can
        # skip its overflow guard when no coefficient set can reach exp's limit
        bound = np.array([_column_bound(col) for col in self.basis.columns])
        object.__setattr__(self, "_exponent_bound", float(np.max(np.abs(c) @ bound)))
        self._freeze()

    @property
    def is_dynamic(self):
        return True

    @property
    def state_dim(self) -> int:
        return len(self._axes)

    @property
    def state_name(self):
        return self._names[0] if len(self._names) == 1 else self._names

    @property
    def state_range(self):
        r = tuple((float(a[0]), float(a[-1])) for a in self._axes)
        return r[0] if len(r) == 1 else r

    def state_nodes(self):
        return self.states if len(self._axes) == 1 else grid_points(self._axes)

    def _checked(self, state) -> np.ndarray:
        if len(self._axes) == 1:
            return check_in_range(state, self._axes[0], self._names[0], self.extrapolation)
        return check_in_range_2d(state, self._axes, self._names, self.extrapolation)

    def _weights(self, q) -> np.ndarray:
        """Interpolation weights (nodes, Q) at checked states."""
        if len(self._axes) == 1:
            return interpolation_weights(self._axes[0], q)
        return bilinear_weights(self._axes, q)

    def coefficients_at(self, state) -> np.ndarray:
        """Interpolated coefficients (K,) at one state (a scalar, or a pair for two
        states), or (Q, K) at an array of them."""
        q = self._checked(state)
        single = np.ndim(q) == len(self._axes) - 1
        if len(self._axes) == 1:
            rows = interpolate_rows(self._axes[0], self.coefficients, np.atleast_1d(q))
        else:
            rows = bilinear_rows(self._axes, self.coefficients, q)
        return rows[0] if single else rows

    def at_state(self, state) -> SphericalHarmonicBRDF:
        """The one-state model at one state (a scalar, or a pair for two states)."""
        return SphericalHarmonicBRDF(self.basis, self.coefficients_at(state), self.fanout, self.log)

    def _fr(self, wi, wo, state, fanout_h=None, divide_r=True):
        coef = self.coefficients_at(state)
        return _sh_eval(self.basis, self._fanout_h(fanout_h), self.fanout, self.log, wi, wo, coef, divide_r)

    def _fr_cos(self, wi, wo, state):
        return self._fr(wi, wo, state, divide_r=False)

    def _fr_segment_max(self, wi, wo, s_lo, s_hi, fanout_h):
        return np.maximum(self._fr(wi, wo, s_lo, fanout_h), self._fr(wi, wo, s_hi, fanout_h))

    def _query(self, states, reduce):
        """``(columns, reducer)``: the states to evaluate (as interpolation weights, nodes x
        Q') and how the reduction combines the Q' exponents of a row block into one."""
        if len(self._axes) == 1:
            q = self._checked(np.atleast_1d(np.asarray(states, dtype=float)).ravel())
            if reduce == "path-max":
                # the path covers [min, max]: add the nodes inside it
                nodes = self._axes[0]
                q = np.concatenate([q, nodes[(nodes > q.min()) & (nodes < q.max())]])
            if reduce:
                # linear in the state between nodes: only the first and last state of each
                # node interval can hold the max (exact, not a bound)
                q = segment_extremes(self._axes[0], q)
            return self._weights(q), _row_max
        q = self._checked(np.asarray(states, dtype=float).reshape(-1, 2))
        if reduce != "path-max":
            return self._weights(q), _row_max
        starts, ends = path_pieces(self._axes, q)
        m = starts.shape[0]
        cols = np.concatenate([starts, 0.5 * (starts + ends), ends])

        def reducer(prod):  # exact max of each piece's quadratic, then over the pieces
            return quadratic_max(prod[:, :m], prod[:, m:2 * m], prod[:, 2 * m:]).max(axis=1)

        return self._weights(cols), reducer

    def evaluate_many(self, wi, wo, states, *, projected=False, row_scale=None, reduce=None, chunk_rows=16384, out=None,
                      threads=None) -> np.ndarray:
        """BRDF at N direction pairs and Q states as one basis evaluation and one GEMM.

        Parameters
        ----------
        wi, wo : array_like, shape (..., 3)
            Direction pairs (flattened to N rows).
        states : array_like, shape (Q,) or (Q, 2)
            States (pairs for a two-state table; policy ``extrapolation`` applies).
        projected : bool
            Return ``f_r cos(theta_r)`` instead of ``f_r``.
        row_scale : array_like, shape (N,), optional
            Non-negative factor per row (e.g. power / range^2 of an irradiance map). For
            log models it enters the exponent (no extra pass over the output); a zero
            row gives exactly 0.
        reduce : {None, "max", "path-max"}
            ``"max"``: only the maximum over the given states, shape (N,), reduced inside
            each block before the monotone steps (exp, clipping, the cosine division),
            so a log model takes N exponentials instead of N x Q and no (N, Q) array
            exists. ``"path-max"``: the maximum over the continuous path that joins the
            states in order by straight lines (a history sampled in time): exact, from
            the nodes inside the path's range (one state), or from each path piece's
            quadratic inside one grid cell, ends and vertex (two states).
        chunk_rows : int
            Rows per fused block (basis, GEMM, exp); tune for cache, not accuracy.
        out : ndarray, shape (N, Q) (or (N,) with ``reduce``), optional
            Output buffer.
        threads : int, optional
            Blocks run side by side on this many threads (default
            :func:`brdfmodels.parallel.default_threads`); results do not depend on it.

        Returns
        -------
        ndarray, shape (N, Q) or (N,)
            f_r [1/sr] (0 below the horizon).
        """
        if reduce not in (None, "max", "path-max"):
            raise ValueError(f"reduce={reduce!r}: expected None, 'max' or 'path-max'")
        wi, wo, _ = _prepare(wi, wo)
        if row_scale is not None:
            row_scale = finite_array("row_scale", row_scale, ndim=1, minimum=0.0)
            if row_scale.shape != (wi.shape[0],):
                raise ValueError(f"row_scale: expected shape ({wi.shape[0]},), got {row_scale.shape}")
        weights, reducer = self._query(states, reduce)
        coef = self.coefficients.reshape(-1, self.basis.size).T @ weights  # (K, Q)
        n = wi.shape[0]
        shape = (n,) if reduce else (n, coef.shape[1])
        if out is None:
            out = np.empty(shape)
        elif out.shape != shape:
            raise ValueError(f"out: expected shape {shape}, got {out.shape}")
        map_blocks(self._block_fn(wi, wo, coef, projected, row_scale, reducer if reduce else None, out), n, chunk_rows, threads)
        return out

    def _block_fn(self, wi, wo, coef, projected, row_scale, reducer, out):
        """The fused work on rows [s, e): basis, one GEMM, (reduce), exp or clip-divide."""
        k, nq = self.basis.size, coef.shape[1]
        if self.log:
            # augmented row -ln(cos i cos r) with coefficient 1: exp() gives f_r directly
            coef = np.vstack([coef, np.ones((1, nq))])
        guard = self._exponent_bound + 2.0 * -math.log(_COS_FLOOR) > _LOG_FR_MAX
        # a finite stand-in for log(0): exp() of it underflows to exactly 0 whatever Y c is
        log_zero = -(self._exponent_bound + 1000.0)

        def block(s, e):
            a, b = wi[s:e], wo[s:e]
            yb = np.empty((k + 1, e - s))
            self.basis.design_transposed(*half_diff_parts(a, b), self.fanout, self.fanout, out=yb[:k])
            ci, cr = a[:, 2], b[:, 2]
            valid = (ci > 0.0) & (cr > 0.0)
            if self.log:
                lc = np.log(np.maximum(ci, _COS_FLOOR))
                if not projected:
                    lc += np.log(np.maximum(cr, _COS_FLOOR))
                np.negative(lc, out=yb[k])
                if row_scale is not None:
                    rs = row_scale[s:e]
                    with np.errstate(divide="ignore"):
                        yb[k] += np.where(rs > 0, np.log(np.where(rs > 0, rs, 1.0)), log_zero)
            ys = yb if self.log else yb[:k]
            if reducer is not None:
                # max over states commutes with the monotone steps below (exp, clipping,
                # multiplying by a non-negative row factor): reduce the GEMM first
                out[s:e] = reducer(ys.T @ coef)
                blk = out[s:e, None]
            else:
                blk = out[s:e]
                np.matmul(ys.T, coef, out=blk)
            if self.log:
                # clip only when this block's exponent could pass ln(FR_MAX)
                if guard or (row_scale is not None and self._exponent_bound + yb[k].max() > _LOG_FR_MAX):
                    np.minimum(blk, _LOG_FR_MAX, out=blk)
                np.exp(blk, out=blk)
            else:
                np.maximum(blk, 0.0, out=blk)
                den = np.maximum(ci, _COS_FLOOR) * (1.0 if projected else np.maximum(cr, _COS_FLOOR))
                blk /= den[:, None]
                if row_scale is not None:
                    blk *= row_scale[s:e, None]
                np.minimum(blk, FR_MAX, out=blk)
            if not valid.all():
                blk[~valid] = 0.0

        return block

    def _params(self):
        return {
            "basis": self.basis.to_dict(),
            "states": self.states.tolist() if len(self._axes) == 1 else [a.tolist() for a in self._axes],
            "coefficients": self.coefficients.tolist(),
            "state_name": self.state_name if len(self._axes) == 1 else list(self._names),
            "fanout": self.fanout,
            "log": self.log,
            "extrapolation": self.extrapolation,
        }


def _row_max(prod: np.ndarray) -> np.ndarray:
    return prod.max(axis=1)


# ----------------------------------------------------------------------------------------
def _state_names(models):
    names = {m.state_name for m in models if m.is_dynamic}
    if len(names) > 1:
        raise ValueError(f"models depend on different states {sorted(map(str, names))}: a combination needs one state")
    return next(iter(names)) if names else None


def _intersect_ranges(ranges):
    """The common part of state ranges: (lo, hi), or one (lo, hi) per state of a pair."""
    if not ranges:
        return None
    if isinstance(ranges[0][0], tuple):
        return tuple(_intersect_ranges([r[d] for r in ranges]) for d in range(len(ranges[0])))
    return (max(r[0] for r in ranges), min(r[1] for r in ranges))


def _empty_range(r) -> bool:
    return any(_empty_range(x) for x in r) if isinstance(r[0], tuple) else r[0] > r[1]


def _union_nodes(node_sets, dim):
    """Nodes where any part's table changes slope: sorted values (one state), or the
    grid of the per-axis unions (two states: every part is bilinear inside its cells)."""
    sets = [n for n in node_sets if len(n)]
    if dim < 2:
        return np.unique(np.concatenate(sets)) if sets else np.empty(0)
    return grid_points([np.unique(np.concatenate([n[:, d] for n in sets])) for d in range(2)])


@register("sum")
class Sum(BRDFModel):
    """Sum of models, e.g. glossy + diffuse + mirror: ``f_r = sum_i f_i``.

    All dynamic parts must share one state (same ``state_name``); the combination's
    state range is the intersection of theirs.
    """

    def __init__(self, models):
        models = list(models)
        if not models:
            raise ValueError("models: expected at least one model, got an empty list")
        for i, m in enumerate(models):
            if not isinstance(m, BRDFModel):
                raise ValueError(f"models[{i}]={m!r}: expected a BRDF model")
        self.models = tuple(models)
        object.__setattr__(self, "_state_name", _state_names(self.models))
        self.reciprocal = all(m.reciprocal for m in self.models)
        if self.is_dynamic and _empty_range(self.state_range):
            ranges = [m.state_range for m in self.models if m.is_dynamic]
            raise ValueError(f"models: the dynamic parts' state ranges {ranges} do not overlap")
        self._freeze()

    @property
    def is_dynamic(self):
        return self._state_name is not None

    @property
    def state_name(self):
        return self._state_name

    @property
    def state_dim(self):
        return max(m.state_dim for m in self.models)

    @property
    def state_range(self):
        return _intersect_ranges([m.state_range for m in self.models if m.is_dynamic])

    def state_nodes(self):
        return _union_nodes([m.state_nodes() for m in self.models if m.is_dynamic], self.state_dim)

    def _fr(self, wi, wo, state):
        return sum(m._fr(wi, wo, state) for m in self.models)

    def _fr_cos(self, wi, wo, state):
        return sum(m._fr_cos(wi, wo, state) for m in self.models)

    @property
    def has_specular(self):
        return any(m.has_specular for m in self.models)

    def _spec(self, wi, state):
        return sum(m._spec(wi, state) for m in self.models)

    def _fr_segment_max(self, wi, wo, s_lo, s_hi, fanout_h):
        return sum(m._fr_segment_max(wi, wo, s_lo, s_hi, fanout_h) for m in self.models)

    @classmethod
    def _decode(cls, params):
        if "models" in params:
            params["models"] = [model_from_dict(m) if isinstance(m, dict) else m for m in params["models"]]
        return params

    def _params(self):
        return {"models": [m.to_dict() for m in self.models]}


@register("scaled")
class Scaled(BRDFModel):
    """A model multiplied by a factor, constant or following the state.

    ``f_r = factor(state) * f_inner``. A :class:`~brdfmodels.StateTable` factor makes the
    model dynamic, e.g. the oxidation reflectance factor ``R(t)/R(0) = exp(-(xi - xi_0))``
    tabulated over time or extinction.

    Parameters
    ----------
    model : BRDFModel
    factor : float or StateTable
        Non-negative factor (dimensionless).
    """

    def __init__(self, model, factor):
        if not isinstance(model, BRDFModel):
            raise ValueError(f"model={model!r}: expected a BRDF model")
        self.model = model
        if isinstance(factor, StateTable):
            if factor.values.min() < 0:
                raise ValueError(f"factor: table values must be >= 0, got {float(factor.values.min())!r}")
            if model.is_dynamic and model.state_name != factor.state_name:
                raise ValueError(
                    f"factor: its state {factor.state_name!r} differs from the model's {model.state_name!r}"
                )
            self.factor = factor
        else:
            self.factor = finite_scalar("factor", factor, minimum=0.0)
        self.reciprocal = model.reciprocal
        self._freeze()

    @property
    def _table(self):
        return isinstance(self.factor, StateTable)

    @property
    def is_dynamic(self):
        return self._table or self.model.is_dynamic

    @property
    def state_name(self):
        return self.factor.state_name if self._table else self.model.state_name

    @property
    def state_dim(self):
        return 1 if self._table else self.model.state_dim

    @property
    def state_range(self):
        r = [x.state_range for x in (self.factor, self.model) if getattr(x, "state_range", None) is not None]
        return _intersect_ranges(r)

    def state_nodes(self):
        own = [self.factor.states] if self._table else []
        return _union_nodes(own + [self.model.state_nodes()], self.state_dim)

    def _f(self, state):
        return self.factor(state) if self._table else self.factor

    def _fr(self, wi, wo, state):
        return self._f(state) * self.model._fr(wi, wo, state)

    def _fr_cos(self, wi, wo, state):
        return self._f(state) * self.model._fr_cos(wi, wo, state)

    @property
    def has_specular(self):
        return self.model.has_specular

    def _spec(self, wi, state):
        return self._f(state) * self.model._spec(wi, state)

    def _fr_segment_max(self, wi, wo, s_lo, s_hi, fanout_h):
        # max of a product <= product of maxima (exact when the factor is constant)
        fmax = max(float(self._f(s_lo)), float(self._f(s_hi))) if self._table else self.factor
        return fmax * self.model._fr_segment_max(wi, wo, s_lo, s_hi, fanout_h)

    @classmethod
    def _decode(cls, params):
        if isinstance(params.get("model"), dict):
            params["model"] = model_from_dict(params["model"])
        if isinstance(params.get("factor"), dict):
            params["factor"] = StateTable.from_dict(params["factor"])
        return params

    def _params(self):
        f = self.factor.to_dict() if self._table else self.factor
        return {"model": self.model.to_dict(), "factor": f}


# ----------------------------------------------------------------------------------------
@register("envelope")
class Envelope(BRDFModel):
    """Conservative static envelope of a (dynamic) model over all its states.

    ``f_env = multiplier * max_s max(f(s), f_h(s)) + base``, where the max over states is
    exact (a max over the tabulated nodes, spec section 9: coefficient interpolation is
    linear, so no state between two nodes exceeds both), ``f_h`` is the model
    reconstructed with a smaller halfway fan-out ``fanout_h`` (broader specular peak), and
    ``base`` [1/sr] and ``multiplier`` (>= 1) are the paper's conservative adjustments
    (Bailey et al. 2008, Sec. IV H). Keeping ``f`` inside the max makes the envelope never
    lower than the exact one, whatever ``fanout_h`` does. For combinations the bound is a
    sum or product of per-part maxima, which is conservative.

    Parameters
    ----------
    model : BRDFModel
    base : float
        Added to f_r [1/sr] (>= 0).
    multiplier : float
        Factor >= 1.
    fanout_h : float, optional
        Halfway fan-out exponent of the broadened reconstruction (SH parts only).
    """

    def __init__(self, model, base=0.0, multiplier=1.0, fanout_h=None):
        if not isinstance(model, BRDFModel):
            raise ValueError(f"model={model!r}: expected a BRDF model")
        self.model = model
        self.base = finite_scalar("base", base, minimum=0.0)
        self.multiplier = finite_scalar("multiplier", multiplier, minimum=1.0)
        self.fanout_h = None if fanout_h is None else _check_fanout("fanout_h", fanout_h)
        self.reciprocal = model.reciprocal
        if model.state_dim == 2:
            # bilinear inside each cell: a convex blend of its corners, so the max over
            # the whole table is a max over the grid points (in the common range)
            (lo1, hi1), (lo2, hi2) = model.state_range
            g = model.state_nodes()
            g = np.clip(g, [lo1, lo2], [hi1, hi2])
            nodes = np.unique(g, axis=0)
        elif model.is_dynamic:
            lo, hi = model.state_range
            nodes = model.state_nodes()
            nodes = nodes[(nodes >= lo) & (nodes <= hi)]
            nodes = np.unique(np.concatenate([[lo, hi], nodes]))
        else:
            nodes = np.empty(0)
        nodes.setflags(write=False)
        object.__setattr__(self, "_nodes", nodes)
        self._freeze()

    def _exact(self, wi, wo, fanout_h):
        if self._nodes.size == 0:
            return self.model._fr_segment_max(wi, wo, None, None, fanout_h)
        if self._nodes.ndim == 2:
            return np.max([self.model._fr_segment_max(wi, wo, p, p, fanout_h) for p in self._nodes], axis=0)
        if self._nodes.size == 1:
            s = float(self._nodes[0])
            return self.model._fr_segment_max(wi, wo, s, s, fanout_h)
        out = None
        for lo, hi in zip(self._nodes[:-1], self._nodes[1:]):
            v = self.model._fr_segment_max(wi, wo, float(lo), float(hi), fanout_h)
            out = v if out is None else np.maximum(out, v)
        return out

    def _fr(self, wi, wo, state):
        f = self._exact(wi, wo, None)
        if self.fanout_h is not None:
            f = np.maximum(f, self._exact(wi, wo, self.fanout_h))
        return self.multiplier * f + self.base

    @property
    def has_specular(self):
        return self.model.has_specular

    def _spec(self, wi, state):
        if self._nodes.size == 0:
            return self.multiplier * self.model._spec(wi, None)
        # delta-lobe reflectances are linear in the state between nodes: max at a node
        return self.multiplier * np.max([self.model._spec(wi, s if self._nodes.ndim == 2 else float(s)) for s in self._nodes], axis=0)

    @classmethod
    def _decode(cls, params):
        if isinstance(params.get("model"), dict):
            params["model"] = model_from_dict(params["model"])
        return params

    def _params(self):
        return {
            "model": self.model.to_dict(),
            "base": self.base,
            "multiplier": self.multiplier,
            "fanout_h": self.fanout_h,
        }
