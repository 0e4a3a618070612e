"""Real spherical harmonics and the pruned halfway/difference basis of the dynamic BRDF.

Convention (spec `dynamic-sh-brdf.md` section 5, paper Eqs. 27-28): orthonormal real
harmonics **without** the Condon-Shortley phase,

    y_l^0  = N_l^0 P_l^0(cos theta)
    y_l^m  = sqrt(2) N_l^m P_l^m(cos theta) cos(m phi)     (m > 0)
    y_l^-m = sqrt(2) N_l^m P_l^m(cos theta) sin(m phi)     (m > 0)

with P_l^m the associated Legendre functions without the (-1)^m factor. They equal
``sqrt(2) (-1)^m Re/Im`` of SciPy's ``sph_harm_y`` (which includes the phase). The
normalised Legendre values come from the standard three-term recurrence on fully
normalised functions (no factorials), accurate to ~1e-13 up to l = 64 including the poles.

The BRDF basis (paper Sec. IV C, spec section 7) keeps, for reciprocity and symmetry about
the plane of incidence, only m >= 0 (cosine) terms with even m in the difference part:
``0 <= m_h <= min(l_h, mh_max)`` and ``m_d`` even, ``0 <= m_d <= min(l_d, md_max)``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache

import numpy as np

__all__ = ["SHBasis", "real_sph_harm", "fan_out", "zonal_coefficients"]

_INV_SQRT_4PI = 1.0 / math.sqrt(4.0 * math.pi)
_SQRT2 = math.sqrt(2.0)
HALF_PI = 0.5 * math.pi


def fan_out(theta, exponent: float) -> np.ndarray:
    """Angle fan-out of paper Eq. 34: ``theta~ / pi = (theta / (pi/2)) ** exponent``.

    Maps [0, pi/2] onto [0, pi]; inputs are clipped to [0, pi/2] first.
    """
    t = np.clip(np.asarray(theta, dtype=float), 0.0, HALF_PI) / HALF_PI
    if exponent == 1.0:
        return math.pi * t
    return math.pi * np.power(t, exponent)


def _recurrence(l: int, m: int):
    """(a, b) of the normalised three-term recurrence
    ``P_l^m = a (x P_{l-1}^m - b P_{l-2}^m)`` (l >= m + 2)."""
    a = math.sqrt((4 * l * l - 1) / (l * l - m * m))
    b = math.sqrt(((l - 1) ** 2 - m * m) / (4 * (l - 1) ** 2 - 1))
    return a, b


def _legendre_table(x: np.ndarray, s: np.ndarray, lmax: int, mmax: int) -> dict:
    """Fully normalised P_l^m (incl. 1/sqrt(4 pi)), no Condon-Shortley phase.

    Returns a dict ``(l, m) -> array`` for 0 <= m <= min(l, mmax), 0 <= l <= lmax.
    ``x = cos(theta)``, ``s = sin(theta) >= 0``.
    """
    out = {}
    pmm = np.full_like(x, _INV_SQRT_4PI)
    for m in range(0, min(lmax, mmax) + 1):
        if m > 0:
            pmm = math.sqrt((2 * m + 1) / (2 * m)) * s * pmm
        out[(m, m)] = pmm
        if m + 1 > lmax:
            continue
        p_lm1 = pmm
        p_l = math.sqrt(2 * m + 3) * x * pmm
        out[(m + 1, m)] = p_l
        for l in range(m + 2, lmax + 1):
            a, b = _recurrence(l, m)
            p_new = a * (x * p_l - b * p_lm1)
            p_lm1, p_l = p_l, p_new
            out[(l, m)] = p_l
    return out


def _cos_multiples(c: np.ndarray, s: np.ndarray, mmax: int, *, with_sin: bool = False):
    """cos(m phi) (and sin(m phi)) for m = 0..mmax from cos(phi), sin(phi) by recurrence."""
    cos_m = [np.ones_like(c)]
    sin_m = [np.zeros_like(c)]
    for _ in range(1, mmax + 1):
        # angle addition keeps both sequences accurate
        cos_m.append(cos_m[-1] * c - sin_m[-1] * s)
        sin_m.append(sin_m[-1] * c + cos_m[-2] * s)
    return (cos_m, sin_m) if with_sin else cos_m


def real_sph_harm(l: int, m: int, theta, phi) -> np.ndarray:
    """Real orthonormal spherical harmonic y_l^m (no Condon-Shortley phase).

    Parameters
    ----------
    l, m : int
        Degree l >= 0 and order -l <= m <= l (m < 0: sine terms).
    theta, phi : array_like
        Polar angle and azimuth [rad].
    """
    if not (isinstance(l, (int, np.integer)) and l >= 0):
        raise ValueError(f"l={l!r}: expected an integer >= 0")
    if not (isinstance(m, (int, np.integer)) and abs(m) <= l):
        raise ValueError(f"m={m!r}: expected an integer with |m| <= l={l}")
    theta, phi = np.broadcast_arrays(np.asarray(theta, float), np.asarray(phi, float))
    table = _legendre_table(np.cos(theta), np.abs(np.sin(theta)), int(l), abs(int(m)))
    p = table[(int(l), abs(int(m)))]
    if m == 0:
        return p.copy()
    if m > 0:
        return _SQRT2 * p * np.cos(m * phi)
    return _SQRT2 * p * np.sin(-m * phi)


def _check_order(name: str, value) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 0:
        raise ValueError(f"{name}={value!r}: expected an integer >= 0")
    if value > 128:
        raise ValueError(f"{name}={value!r}: expected an order <= 128 (the basis is tested to l = 64)")
    return int(value)


@dataclass(frozen=True)
class SHBasis:
    """Pruned spherical-harmonic basis in fanned-out halfway/difference angles.

    Parameters
    ----------
    lh_max, mh_max : int
        Maximum degree and order of the halfway harmonics (``mh_max = 0``: isotropic).
    ld_max, md_max : int
        Maximum degree and order of the difference harmonics; only even ``md`` are kept
        (reciprocity).
    separable : bool
        True: the separable form of paper Eq. 33, columns
        ``[constant] + [y_h(lh >= 1)] + [y_d(ld >= 1)]`` (the two constant terms are the
        same function and are kept once). False: the full product form of Eq. 29, columns
        ``y_h(lh, mh) * y_d(ld, md)`` for every pair.

    Notes
    -----
    Sizes in the paper's settings (separable): (8, 4, 2, 0) -> 37, (10, 4, 2, 0) -> 47,
    (8, 0, 2, 0) -> 11.
    """

    lh_max: int
    mh_max: int
    ld_max: int
    md_max: int
    separable: bool = True

    def __post_init__(self):
        for name in ("lh_max", "mh_max", "ld_max", "md_max"):
            object.__setattr__(self, name, _check_order(name, getattr(self, name)))
        if not isinstance(self.separable, (bool, np.bool_)):
            raise ValueError(f"separable={self.separable!r}: expected True or False")
        object.__setattr__(self, "separable", bool(self.separable))

    # -- term lists --------------------------------------------------------------------
    @property
    def terms_h(self) -> tuple:
        """(l, m) of the halfway harmonics, l = 0 included."""
        return tuple((l, m) for l in range(self.lh_max + 1) for m in range(min(l, self.mh_max) + 1))

    @property
    def terms_d(self) -> tuple:
        """(l, m) of the difference harmonics (even m), l = 0 included."""
        return tuple((l, m) for l in range(self.ld_max + 1) for m in range(0, min(l, self.md_max) + 1, 2))

    @property
    def columns(self) -> tuple:
        """Descriptor of every column: ('h', l, m), ('d', l, m) or ('hd', lh, mh, ld, md)."""
        if self.separable:
            cols = [("h", 0, 0)]
            cols += [("h", l, m) for (l, m) in self.terms_h if l > 0]
            cols += [("d", l, m) for (l, m) in self.terms_d if l > 0]
            return tuple(cols)
        return tuple(("hd", lh, mh, ld, md) for (lh, mh) in self.terms_h for (ld, md) in self.terms_d)

    @property
    def size(self) -> int:
        """Number of basis functions K."""
        nh, nd = len(self.terms_h), len(self.terms_d)
        return nh + nd - 1 if self.separable else nh * nd

    def to_dict(self) -> dict:
        return {
            "lh_max": self.lh_max,
            "mh_max": self.mh_max,
            "ld_max": self.ld_max,
            "md_max": self.md_max,
            "separable": self.separable,
        }

    @classmethod
    def from_dict(cls, data: dict) -> "SHBasis":
        known = {"lh_max", "mh_max", "ld_max", "md_max", "separable"}
        unknown = set(data) - known
        if unknown:
            raise ValueError(f"basis: unknown keys {sorted(unknown)}; expected {sorted(known)}")
        return cls(**data)

    # -- evaluation -----------------------------------------------------------------------
    @staticmethod
    def _fill(rows, theta, cph, sph, terms, mmax, fanout, skip_l0=False):
        """Write y_l^m(fan_out(theta), phi) of ``terms`` into the successive ``rows``.

        The hot path of every SH evaluation: the recurrence of :func:`_legendre_table`
        (kept as the reference that :func:`real_sph_harm` and the tests use; same
        coefficients, same order of operations up to where sqrt(2) is applied) run in
        place in the output rows, so each term costs four passes over one row and no
        temporaries. Orders m not in ``terms`` (odd m of the difference part) go through
        three rotating scratch rows.
        """
        n = np.shape(theta)[0]
        tt = fan_out(theta, fanout)
        x = np.cos(tt)
        s = np.sin(tt, out=tt)  # tt is in [0, pi]: sin >= 0 up to rounding
        np.abs(s, out=s)
        where = {}
        for lm in terms:
            if not (skip_l0 and lm[0] == 0):
                where[lm] = len(where)
        lmax = max(l for l, _ in terms)
        cos_m = _cos_multiples(cph, sph, mmax) if mmax > 0 else None
        scratch = [np.empty(n) for _ in range(3)]
        tmp = np.empty(n)
        pmm = np.full(n, _INV_SQRT_4PI)
        for m in range(0, min(lmax, mmax) + 1):
            if m > 0:
                np.multiply(s, math.sqrt((2 * m + 1) / (2 * m)), out=tmp)
                pmm *= tmp
            col = [lm for lm in where if lm[1] == m]
            if not col:
                continue
            top = max(l for l, _ in col)
            free = list(scratch)

            def dest(l, m=m, free=free):  # called within this iteration only
                r = where.get((l, m))
                return rows[r] if r is not None else free.pop()

            # column m scaled by sqrt(2) from its first element (the recurrence is linear)
            p_lm1 = None
            p_l = dest(m)
            np.multiply(pmm, _SQRT2 if m > 0 else 1.0, out=p_l)
            for l in range(m + 1, top + 1):
                d = dest(l)
                if l == m + 1:
                    np.multiply(x, p_l, out=d)
                    d *= math.sqrt(2 * m + 3)
                else:
                    a, b = _recurrence(l, m)
                    np.multiply(x, p_l, out=d)
                    np.multiply(p_lm1, b, out=tmp)
                    d -= tmp
                    d *= a
                if p_lm1 is not None and (l - 2, m) not in where:
                    free.append(p_lm1)  # a scratch row no longer needed
                p_lm1, p_l = p_l, d
            if m > 0:
                for (l, _) in col:
                    rows[where[(l, m)]] *= cos_m[m]
        return len(where)

    def design_transposed(self, theta_h, cph, sph, theta_d, cpd, spd, fanout_h, fanout_d, out=None):
        """Basis values as a (K, N) array from half/diff angles and azimuth cosines/sines.

        This is the hot-path entry point (no input checks); ``out`` may be a reusable
        (K, N) buffer. Rows are written in place, in the order of :attr:`columns`.
        """
        n = np.shape(theta_h)[0]
        if out is None:
            out = np.empty((self.size, n))
        if self.separable:
            k = self._fill(out, theta_h, cph, sph, self.terms_h, self.mh_max, fanout_h)
            if self.ld_max > 0:
                self._fill(out[k:], theta_d, cpd, spd, self.terms_d, self.md_max, fanout_d, skip_l0=True)
        else:
            nh, nd = len(self.terms_h), len(self.terms_d)
            vh = np.empty((nh, n))
            vd = np.empty((nd, n))
            self._fill(vh, theta_h, cph, sph, self.terms_h, self.mh_max, fanout_h)
            self._fill(vd, theta_d, cpd, spd, self.terms_d, self.md_max, fanout_d)
            for i in range(nh):
                np.multiply(vh[i], vd, out=out[i * nd:(i + 1) * nd])
        return out

    def evaluate(self, theta_h, phi_h, theta_d, phi_d, *, fanout=0.6, fanout_h=None) -> np.ndarray:
        """Design matrix (N, K) at half/diff angles [rad] (1-d arrays of length N).

        ``fanout`` is the exponent of Eq. 34 for both angles; ``fanout_h`` overrides it for
        the halfway angle (a smaller value broadens the specular lobe).
        """
        th, ph, td, pd = (np.atleast_1d(np.asarray(a, dtype=float)) for a in (theta_h, phi_h, theta_d, phi_d))
        th, ph, td, pd = (a.ravel() for a in np.broadcast_arrays(th, ph, td, pd))
        fh = fanout if fanout_h is None else fanout_h
        return self.design_transposed(th, np.cos(ph), np.sin(ph), td, np.cos(pd), np.sin(pd), fh, fanout).T

    def evaluate_directions(self, wi, wo, *, fanout=0.6, fanout_h=None) -> np.ndarray:
        """Design matrix (N, K) at direction pairs (..., 3) in the surface frame."""
        from ._checks import directions
        from .geometry import half_diff_parts

        wi = directions("wi", wi)
        wo = directions("wo", wo)
        wi, wo = np.broadcast_arrays(wi, wo)
        parts = [p.ravel() for p in half_diff_parts(wi.reshape(-1, 3), wo.reshape(-1, 3))]
        fh = fanout if fanout_h is None else fanout_h
        return self.design_transposed(*parts, fh, fanout).T


@lru_cache(maxsize=8)
def _gauss_legendre(n: int):
    from scipy.special import roots_legendre

    return roots_legendre(n)


def zonal_coefficients(profile, lh_max: int, fanout: float = 0.6, *, quadrature_points: int = 4096) -> np.ndarray:
    """Coefficients of an isotropic halfway profile in the zonal harmonics y_l^0(theta~_h).

    Projects ``g(theta_h)`` (a function of the halfway angle [rad] on [0, pi/2]) onto
    ``y_l^0`` of the fanned-out angle over the whole sphere, ``c_l = 2 pi integral
    g y_l^0 sin(theta~) d theta~``, by Gauss-Legendre quadrature in cos(theta~). The
    result orders like :attr:`SHBasis.columns` of ``SHBasis(lh_max, 0, 0, 0)``.

    Use it to build a model from an in-plane profile of ln f~ (log models) or f~.
    """
    lh_max = _check_order("lh_max", lh_max)
    x, w = _gauss_legendre(int(quadrature_points))
    tt = np.arccos(x)  # theta~ in [0, pi]
    theta_h = HALF_PI * (tt / math.pi) ** (1.0 / fanout)
    g = np.asarray(profile(theta_h), dtype=float)
    table = _legendre_table(x, np.sqrt(1 - x * x), lh_max, 0)
    return np.array([2 * math.pi * np.sum(w * g * table[(l, 0)]) for l in range(lh_max + 1)])
