"""Extended sources: C_E per observer from the diffuse spot's angular subtense.

A diffusely reflecting spot that subtends more than alpha_min = 1.5 mrad at the eye
images onto a larger retinal area than a point source, and the standard allows a larger
MPE (ANSI Z136.1-2014 extended-source MPE with C_E; IEC 60825-1:2014 Table A.1 with C6;
values and factors from the project's spec `laser-safety.md` section 2.4, labels as
there: [C] read in a cited source, [M] general knowledge, unverified):

* C_E = 1 for alpha < alpha_min; alpha / alpha_min for alpha_min <= alpha <= alpha_max;
  above alpha_max: alpha_max / alpha_min (2014 editions, [C] akufcsak) or
  alpha^2 / (alpha_min alpha_max) with alpha_max = 100 mrad (2007 editions, [C]
  Laser-Studio, EU AORD 2006/25/EC).
* alpha_min = 1.5 mrad; alpha_max (2014) = 5 mrad (t < 625 us), 200 t^0.5 mrad
  (625 us - 0.25 s), 100 mrad (t > 0.25 s); 2007: 100 mrad always [C].
* T2 = 10 * 10^((alpha - 1.5) / 98.5) s (alpha in mrad), 10 s below 1.5 mrad and 100 s
  above 100 mrad [C]; it enters the t >= 10 s extended-source rows, which
  :func:`hazard.physics.mpe.ocular_mpe` labels [M] (row structure of IEC 60825-1:2014 Table A.1,
  unverified); a report note says so whenever such a row governs.

The MPE itself always comes from :func:`hazard.physics.mpe.ocular_mpe` (and, for pulsed lasers,
:func:`hazard.physics.mpe.repetitive_pulse_mpe`) called with the subtense, so C_E, T2, alpha_max
per pulse duration and the photochemical limit (which has no C_E) are applied exactly
as in the point-source path.

Conventions (all chosen so that the subtense is never overstated):

* **Spot size**: the 1/e diameter of the spot, i.e. ``2 sqrt(2 lambda)`` with lambda the
  power-weighted second moment of the spot along an axis. A spot that holds the whole
  beam on a plate or disk (no spill, nothing blocked, one target) has the Gaussian beam
  footprint's moments, exact. Any other spot uses the scatter of its beam samples about
  the centroid, which leaves out the spread within each sample and so is never larger
  than the true moments (a few per cent smaller at the default beam sampling), capped
  by the whole beam's footprint. Known limitation: where a target's edge cuts the beam,
  the engine places an edge sample at the centroid of its whole beam cell, part of which
  is off the target, so the scatter of a truncated spot can come out slightly high
  (measured: +0.7 % in alpha for a 5 cm plate in a 10 cm beam at 16384 beam samples,
  -13 % at the default 256). For a Gaussian spot the
  1/e diameter holds 1 - 1/e = 63 % of the power, the d63 diameter IEC uses for beam
  and apparent-source sizes (spec section 3.1: "IEC uses d63"); it is what
  ``Spot.size_m`` reports for a round spot.
* **Projection**: the spot's second moments are projected onto the plane perpendicular
  to the line of sight and the **smaller** principal 1/e diameter is used. For a round
  spot of diameter D seen at angle theta from its normal this is ``D |cos theta|`` (the
  foreshortened extent); for an elongated spot (oblique incidence) it is the
  foreshortened minor axis. The standard averages the two angular dimensions of a
  non-circular source (IEC 60825-1:2014 clause 4.3 d, [M] unverified here); the minimum
  is never larger than that mean, so the C_E used is never larger than the standard's.
* **Subtense**: ``alpha = 2 atan(D_proj / (2 R))``, R the distance from the spot's
  power-weighted centroid to the eye; never larger than the small-angle ``D_proj / R``
  (they differ by < 0.1 % up to alpha_max = 100 mrad).
* **Several spots**: the smallest subtense (so the smallest C_E) among the spots the
  observer is in front of; an observer in front of none keeps C_E = 1.
* **Point sources**: specular (mirror) reflections and direct beams are point sources
  (C_E = 1). An observer that receives any specular irradiance keeps C_E = 1; one in
  the laser's own beam adds the two exposures as fractions of their MPEs
  (``E_d / MPE + E_r / (C_E MPE)``: the effective C_E reported lies between); when the
  analysis does not say which observers do (no ``specular_irradiance_w_m2``), every
  observer keeps C_E = 1 as soon as any spot's material has a specular lobe.
* **Viewing optics**: binoculars magnify the retinal image (alpha x M); the unmagnified
  subtense is used, which understates C_E (conservative).
* **Field of view**: alpha enters C_E and T2 with the limits above (C_E stops growing at
  alpha_max in the 2014 editions; T2 at 100 mrad). The photochemical limit (400-600 nm,
  t >= 10 s) is on the irradiance averaged over its field of view gamma_ph (11 mrad to
  110 mrad with duration, spec section 2.4): :func:`hazard.physics.mpe.ocular_mpe` raises it by
  (alpha / gamma_ph)^2 for alpha > gamma_ph (the lower of that and the tables' radiance
  form, never below the point value). That factor is the fraction of a uniform disk's
  irradiance inside gamma_ph; for a Gaussian spot of 1/e diameter alpha the fraction is
  1 - exp(-(gamma_ph / alpha)^2), never more, and the smaller principal axis used for an
  elongated spot overstates it too, so the MPE is never overstated for such spots. A
  spot whose reflected radiance is concentrated in a small part of it (a hot core in a
  wide halo) is not covered by that bound (nor by C_E's). The thermal limit's acceptance
  angle alpha_max would only *reduce* the irradiance counted; it is not applied
  (conservative).

The point-source MPE stays the default: ``[exposure] extended_source = true`` opts in.
Keep-out lobes, NOHDs and the ground footprint stay point-source (conservative).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, ClassVar

import numpy as np

from hazard.physics import mpe as _mpe

if TYPE_CHECKING:  # annotations only (results imports this module's summary type for its own)
    from hazard.pipeline.results import Stage

__all__ = [
    "ExtendedMpe",
    "ExtendedSourceSummary",
    "NOT_APPLIED",
    "ExtendedSourceMPE",
    "spot_subtense_rad",
    "observer_subtense_rad",
    "extended_source_mpe",
    "apply_extended_source",
    "extended_source_of",
    "ExtendedSourceResult",
    "MAX_EXACT_ALPHAS",
    "BIN_RATIO",
]

ALPHA_MIN_RAD = _mpe.ALPHA_MIN_RAD
# 2014 editions: C_E is constant above alpha_max (<= 100 mrad for every duration) and T2 is
# constant above 100 mrad, so the thermal MPE does not change above 100 mrad (the
# photochemical limit, 400-600 nm and t >= 10 s, keeps growing above gamma_ph: not clamped then).
ALPHA_SATURATION_2014_RAD = 0.1
MAX_EXACT_ALPHAS = 4096  # distinct subtenses evaluated exactly (ocular_mpe ~15 us each, pulsed ~50 us)
BIN_RATIO = 1.001  # beyond that: log bins of 0.1 %, each subtense rounded DOWN to its bin's lower edge
# (the MPE never decreases with alpha - C_E grows, T2^-0.25 shrinks more slowly below 100 mrad -
# so a rounded-down subtense never raises the MPE; tests check it on a grid)


# ----------------------------------------------------------------------------------------
def _second_moments(spot):
    """Power-weighted covariance (3, 3) of the spot's hit points about its centroid."""
    p = np.asarray(spot.power_w, float)
    tot = float(p.sum())
    if tot <= 0 or len(p) < 2:
        return np.zeros((3, 3))
    d = np.asarray(spot.points, float) - spot.centroid
    return (d * (p / tot)[:, None]).T @ d


def _minor_second_moment(cov, u):
    """Smaller principal second moment of ``cov`` (3, 3) projected onto the plane
    perpendicular to each unit row of ``u`` (M, 3): the two principal moments sum to
    tr(C) - u.C.u and multiply to u.adj(C).u (the cofactor of the u-u entry)."""
    adj = np.column_stack([np.cross(cov[:, 1], cov[:, 2]), np.cross(cov[:, 2], cov[:, 0]), np.cross(cov[:, 0], cov[:, 1])])
    half = 0.5 * (np.trace(cov) - np.einsum("ij,ij->i", u @ cov, u))
    prod = np.maximum(np.einsum("ij,ij->i", u @ adj, u), 0.0)
    big = half + np.sqrt(np.maximum(half * half - prod, 0.0))
    return np.divide(prod, big, out=np.zeros_like(big), where=big > 0)  # prod / lambda_max: no cancellation


def _beam_footprint_moments(spot, beam_diameter_m):
    """Second moments (3, 3) of an untruncated Gaussian beam of 1/e diameter D on the
    spot's mean plane: the beam's transverse moments (D^2 / 8 per axis) carried along
    the beam direction b onto the plane of normal n (x -> x - b (n.x) / (n.b)). None when
    the beam grazes the plane."""
    b = np.asarray(spot.mean_incoming, float)
    n = np.asarray(spot.mean_frame[2], float)
    bn = float(b @ n)
    if not (beam_diameter_m and math.isfinite(beam_diameter_m)) or abs(bn) < 1e-9:
        return None
    m = np.eye(3) - np.outer(b, n) / bn
    return m @ ((beam_diameter_m**2 / 8.0) * (np.eye(3) - np.outer(b, b))) @ m.T


def spot_subtense_rad(spot, eyes_m, beam_diameter_m=None, whole=False):
    """Angular subtense [rad] of one spot at eyes (M, 3) (local scene coordinates), and
    the mask of eyes in front of its surface.

    ``alpha = 2 atan(D / (2 R))`` with D the smaller principal 1/e diameter of the spot
    projected onto the plane perpendicular to the line of sight (``D |cos theta|`` for a
    round spot of 1/e diameter D seen at theta from its normal) and R the distance to the
    spot's centroid. Eyes behind the surface (cos theta <= 0) get alpha = 0.

    The spot's second moments: with ``whole=True`` (the spot holds the whole beam, on a
    flat target) those of the Gaussian beam footprint of 1/e diameter ``beam_diameter_m``
    on the spot's plane, exact. Otherwise the scatter of the spot's samples about its
    centroid - the moments *between* samples, which leave out the spread within each
    sample and so never exceed the true ones (conservative) - and, with
    ``beam_diameter_m``, at most those of the whole beam's footprint.
    """
    eyes = np.asarray(eyes_m, float).reshape(-1, 3)
    c = np.asarray(spot.centroid, float)
    n = np.asarray(spot.mean_frame[2], float)
    v = eyes - c
    r = np.linalg.norm(v, axis=1)
    safe = np.maximum(r, 1e-300)
    u = v / safe[:, None]
    front = (u @ n > 0) & (r > 0)
    foot = _beam_footprint_moments(spot, beam_diameter_m) if beam_diameter_m is not None else None
    if whole and foot is not None:
        lam_min = _minor_second_moment(foot, u)
    else:
        lam_min = _minor_second_moment(_second_moments(spot), u)
        if foot is not None:
            lam_min = np.minimum(lam_min, _minor_second_moment(foot, u))
    diameter = 2.0 * np.sqrt(2.0 * np.maximum(lam_min, 0.0))  # 1/e diameter along the minor axis
    alpha = 2.0 * np.arctan(diameter / (2.0 * safe))
    return np.where(front, alpha, 0.0), front


def _beam_diameter_at(beam, spot):
    """The beam's 1/e diameter [m] at the spot's mean range (None if unknown)."""
    try:
        return float(beam.diameter_at(spot.mean_range_m))
    except (AttributeError, TypeError, ValueError):
        return None


WHOLE_BEAM_RTOL = 1e-6  # a spot holds the whole beam when spill and blocked power are below this fraction


def _holds_whole_beam(result, spot) -> bool:
    """The only spot, on a plate or disk, with no spill and nothing blocked: its moments
    are the beam footprint's (no truncation)."""
    try:
        flat = spot.target.spec.shape in ("plate", "disk")
        lost = float(result.spill_w) + float(result.blocked_w)
        power = float(result.beam_power_w)
    except (AttributeError, TypeError, ValueError):
        return False
    return flat and len(result.spots) == 1 and power > 0 and lost <= WHOLE_BEAM_RTOL * power


def observer_subtense_rad(spots, eyes_m, beam=None, whole=()):
    """Per-eye subtense [rad]: the smallest over the spots the eye is in front of (the
    smallest C_E, conservative); 0 (point source) for an eye in front of none. ``beam``
    (with ``diameter_at(range_m)``) bounds each spot by the whole beam's footprint;
    ``whole`` flags the spots that hold the whole beam (see :func:`spot_subtense_rad`)."""
    eyes = np.asarray(eyes_m, float).reshape(-1, 3)
    alpha = np.full(len(eyes), np.inf)
    for k, sp in enumerate(spots):
        a, front = spot_subtense_rad(sp, eyes, None if beam is None else _beam_diameter_at(beam, sp),
                                     whole=bool(whole[k]) if k < len(whole) else False)
        alpha = np.where(front, np.minimum(alpha, a), alpha)
    return np.where(np.isfinite(alpha), alpha, 0.0)


# ----------------------------------------------------------------------------------------
@dataclass
class ExtendedSourceMPE:
    """Per-observer C_E and MPE, with the MPE evaluations behind them.

    ``alpha_eval_rad`` is the subtense the MPE was evaluated at: the subtense itself
    (``exact=True``), or rounded down to a 0.1 % log bin when there are more than
    ``MAX_EXACT_ALPHAS`` distinct values (the MPE does not decrease with alpha, so a
    rounded-down alpha gives an MPE no larger than the exact one).
    """

    angular_subtense_rad: np.ndarray
    alpha_eval_rad: np.ndarray
    c_e: np.ndarray
    mpe_w_m2: np.ndarray
    exact: bool
    evaluations: dict = field(default_factory=dict)  # alpha_eval -> (MPEResult, pulse result or None, MPE W/m^2)

    @property
    def unverified(self) -> bool:
        return any(r.unverified for r, _, _ in self.evaluations.values())


def _mpe_at(alpha, wavelength_nm, duration_s, standard, pulse_duration_s, prf_hz):
    """MPE [W/m^2] for one subtense: the single-exposure ocular MPE and, for a pulse
    train, per-pulse MPE x PRF (both with the subtense), the lower governing - exactly as
    the point-source MPE stage does with alpha = 0."""
    res = _mpe.ocular_mpe(wavelength_nm, duration_s, standard=standard, angular_subtense_rad=alpha)
    e = res.irradiance_w_m2
    pulse = None
    if prf_hz is not None:
        pulse = _mpe.repetitive_pulse_mpe(wavelength_nm, pulse_duration_s, prf_hz, duration_s, standard=standard,
                                          angular_subtense_rad=alpha)
        e = min(e, pulse.per_pulse_radiant_exposure_j_m2 * prf_hz)
    return res, pulse, e


def extended_source_mpe(alpha_rad, wavelength_nm, duration_s, *, standard=_mpe.DEFAULT_STANDARD,
                        pulse_duration_s=None, prf_hz=None, max_exact=MAX_EXACT_ALPHAS) -> ExtendedSourceMPE:
    """C_E and MPE [W/m^2] for an array of subtenses (vectorised over distinct values).

    ``ocular_mpe`` is scalar, so it runs once per distinct subtense. Subtenses at or
    below alpha_min are evaluated at 0 (identical: C_E = 1, T2 = 10 s, point-source row);
    in the 2014 editions subtenses above 100 mrad are evaluated at 100 mrad (identical:
    C_E and T2 no longer change). With more than ``max_exact`` distinct values left, each
    is rounded down to a log bin of ratio ``BIN_RATIO``: the MPE is then at most 0.1 % low
    (0.2 % where it grows as alpha^2: C_E in the 2007 editions above 100 mrad, and the
    photochemical limit above its field of view gamma_ph; the first bin above alpha_min
    falls back to the point-source MPE).
    C_E is reported for the duration of the exposure (``correction_factors``, spec 2.4).
    """
    std = _mpe.check_standard(standard)
    alpha = np.asarray(alpha_rad, float)
    if np.any(~np.isfinite(alpha)) or np.any(alpha < 0):
        raise ValueError("angular subtenses must be finite and >= 0")
    ev = np.where(alpha <= ALPHA_MIN_RAD, 0.0, alpha)
    if int(std[-4:]) >= 2014 and not (400 <= wavelength_nm < 600 and duration_s >= 10):
        ev = np.minimum(ev, ALPHA_SATURATION_2014_RAD)  # (the photochemical limit keeps growing above gamma_ph)
    uniq, inv = np.unique(ev, return_inverse=True)
    exact = len(uniq) <= max_exact
    if not exact:
        above = ev > 0
        k = np.floor(np.log(ev[above] / ALPHA_MIN_RAD) / math.log(BIN_RATIO))
        binned = np.minimum(ALPHA_MIN_RAD * BIN_RATIO**k, ev[above])  # never above the value (float safety)
        binned = np.where(binned <= ALPHA_MIN_RAD, 0.0, binned)  # the first bin's edge is alpha_min: a point source
        ev = ev.copy()
        ev[above] = binned
        uniq, inv = np.unique(ev, return_inverse=True)
    evaluations = {}
    mpe_u = np.empty(len(uniq))
    ce_u = np.empty(len(uniq))
    for i, a in enumerate(uniq):
        res, pulse, e = _mpe_at(float(a), wavelength_nm, duration_s, std, pulse_duration_s, prf_hz)
        evaluations[float(a)] = (res, pulse, e)
        mpe_u[i] = e
        ce_u[i] = res.factors.C_E
    inv = inv.reshape(alpha.shape)
    return ExtendedSourceMPE(alpha, ev, ce_u[inv], mpe_u[inv], exact, evaluations)


# ----------------------------------------------------------------------------------------
def _specular_observers(result, m):
    """Mask of observers that receive (or may receive) specular irradiance."""
    spec_e = getattr(result.observers, "specular_irradiance_w_m2", None)
    if spec_e is not None:
        spec_e = np.asarray(spec_e, float)
        return (spec_e.reshape(m, -1) > 0).any(axis=1) if spec_e.size else np.zeros(m, bool), True
    any_specular = any(getattr(sp, "material", None) is not None and sp.material.has_specular
                       or sp.target.material.has_specular for sp in result.spots)
    return np.full(m, any_specular), False


def _point_source_only(result, alpha, m, seconds):
    """C_E = 1 and the scalar MPE for every observer; a skipped stage (its time: the
    subtense, still computed for the report)."""
    from hazard.pipeline.results import Stage

    return ExtendedSourceResult(
        angular_subtense_rad=alpha, c_e=np.ones(m), mpe_w_m2=np.full(m, float(result.mpe_w_m2)),
        mpe_radiant_exposure_j_m2=np.full(m, float(result.mpe_radiant_exposure_j_m2)), first_exceedance_s=None,
        summary=NOT_APPLIED, notes=(),
        record=Stage("extended_source", False, "point-source MPE (conservative); set [exposure] extended_source = true to apply "
                     "C_E (the spot subtense is still computed for the report)", seconds))


def _with_direct_beam(obs, mpe_point, mpe_ext):
    """The MPE [W/m^2] of observers that also receive the laser's own beam (a point
    source, MPE ``mpe_point``) beside the extended spot (``mpe_ext``): the exposures add
    as fractions of their limits (``E_d / MPE_point + E_r / MPE_ext``), so the MPE of the
    total is ``E / (E_d / MPE_point + E_r / MPE_ext)`` (exactly ``mpe_point`` for the
    direct beam alone)."""
    direct = getattr(obs, "direct_irradiance_w_m2", None)
    if direct is None or not np.any(direct > 0):
        return mpe_ext
    total = obs.peak_irradiance_w_m2
    refl = np.maximum(total - direct, 0.0)
    both = (direct > 0) & (total > 0)
    frac = np.where(both, direct / mpe_point + refl / mpe_ext, 1.0)
    return np.where(both, total / frac, mpe_ext)


def _observer_mpe(result, ext, specular, m, t_exp):
    """Per-observer ``(c_e, mpe_w_m2, first_exceedance_s, notes)``: for observers also in
    the direct beam, C_E is the ratio of their combined MPE to the point-source one; a
    static map's first exceedance with it (None: unchanged)."""
    obs = result.observers
    mpe_obs = _with_direct_beam(obs, float(result.mpe_w_m2), ext.mpe_w_m2)
    mixed = mpe_obs != ext.mpe_w_m2  # with the direct beam: the effective factor of the sum
    c_e = np.where(specular, 1.0, np.where(mixed, mpe_obs / float(result.mpe_w_m2), ext.c_e))
    first, notes = None, []
    if len(result.times_s) == 1 and m:  # static: exceeded from the start or never (the map's rule, with the observer's MPE)
        changed = mpe_obs != float(result.mpe_w_m2)
        first = np.where(changed, np.where(obs.static_irradiance_w_m2 > mpe_obs, result.times_s[0], np.nan),
                         obs.first_exceedance_s)
    elif m:
        notes.append("extended source: first_exceedance_s of dynamic materials uses the point-source MPE "
                     "(the earliest possible time; conservative)")
    return c_e, mpe_obs, first, notes


def _stage_detail(c_e, alpha, ext, specular, known, n_above, m) -> str:
    if m:
        parts = [f"C_E from the spot subtense: {c_e.min():.4g} .. {c_e.max():.4g}, "
                 f"{n_above} of {m} observers above alpha_min ({1e3 * ALPHA_MIN_RAD:g} mrad)",
                 f"alpha {1e3 * alpha.min():.4g} .. {1e3 * alpha.max():.4g} mrad",
                 f"MPE {ext.mpe_w_m2.min():.6g} .. {ext.mpe_w_m2.max():.6g} W/m^2"]
    else:
        parts = ["no observers"]
    n_spec = int(specular.sum())
    if n_spec:
        parts.append(f"{n_spec} observer(s) kept at C_E = 1 (specular irradiance"
                     + ("" if known else ": a target has a mirror lobe and the per-observer specular part is not known")
                     + ")")
    if not ext.exact:
        parts.append(f"{len(ext.evaluations)} MPE evaluations on 0.1 % log bins of alpha (rounded down)")
    else:
        parts.append(f"{len(ext.evaluations)} exact MPE evaluation(s)")
    return "; ".join(parts)


@dataclass(frozen=True)
class ExtendedMpe:
    """The MPE at one angular subtense, every step (report.json ``extended_source.mpe_smallest_alpha``
    and ``mpe_largest_alpha``; :func:`_mpe_entry`).

    Attributes
    ----------
    alpha_rad : float
        The apparent source's angular subtense alpha [rad].
    c_e : float
        The extended-source correction factor C_E at it (unitless, >= 1).
    alpha_max_rad : float
        alpha_max [rad] (C_E stops growing beyond it).
    T2_s : float
        The time T2 [s] of the thermal limit for an extended source.
    mpe_w_m2 : float
        The MPE there [W/m^2].
    table_row, formula, label : str
        The standard's table row, its formula and the limit's label.
    unverified : bool
        The row is labelled [M] (not verified against the printed standard).
    steps : tuple of str
        Every step of the calculation, as a safety officer redoes it by hand.
    pulse : RepetitivePulseResult or None
        The repetitive-pulse rules at this subtense (None: continuous wave).
    """

    alpha_rad: float
    c_e: float
    alpha_max_rad: float
    T2_s: float
    mpe_w_m2: float
    table_row: str
    formula: str
    label: str
    unverified: bool
    steps: tuple[str, ...]
    pulse: _mpe.RepetitivePulseResult | None

    def to_dict(self) -> dict:
        return {"alpha_rad": self.alpha_rad, "c_e": self.c_e, "alpha_max_rad": self.alpha_max_rad, "T2_s": self.T2_s,
                "mpe_w_m2": self.mpe_w_m2, "table_row": self.table_row, "formula": self.formula, "label": self.label,
                "unverified": self.unverified, "steps": list(self.steps),
                "pulse": None if self.pulse is None else self.pulse.to_dict()}


@dataclass(frozen=True)
class ExtendedSourceSummary:
    """The stage's summary: report.json ``extended_source`` (``{"applied": false}`` alone when C_E
    was not applied: the fields of :attr:`ONLY_WHEN_APPLIED` are then None and not written).

    Attributes
    ----------
    applied : bool
        C_E applied per observer (``[exposure] extended_source = true``).
    alpha_min_rad, alpha_max_rad : float
        alpha_min [rad] (a point source below it: C_E = 1) and alpha_max [rad] at the exposure duration.
    spot_size, point_sources : str
        How the spot's size and subtense are taken, and which observers keep C_E = 1, in words.
    exact : bool
        The per-observer MPEs are exact (every subtense evaluated; else interpolated conservatively).
    observers_above_alpha_min, observers_kept_specular : int
        Observers that see a subtense above alpha_min; observers kept at C_E = 1 (specular irradiance).
    mpe_smallest_alpha, mpe_largest_alpha : ExtendedMpe or None
        The MPE calculation at the smallest and the largest subtense applied (None: no such subtense).
    """

    applied: bool
    alpha_min_rad: float | None = None
    alpha_max_rad: float | None = None
    spot_size: str | None = None
    point_sources: str | None = None
    exact: bool | None = None
    observers_above_alpha_min: int | None = None
    observers_kept_specular: int | None = None
    mpe_smallest_alpha: ExtendedMpe | None = None
    mpe_largest_alpha: ExtendedMpe | None = None

    ONLY_WHEN_APPLIED: ClassVar[tuple[str, ...]] = (
        "alpha_min_rad", "alpha_max_rad", "spot_size", "point_sources", "exact", "observers_above_alpha_min",
        "observers_kept_specular", "mpe_smallest_alpha", "mpe_largest_alpha")

    def to_dict(self) -> dict:
        if not self.applied:
            return {"applied": False}
        return {"applied": True, "alpha_min_rad": self.alpha_min_rad, "alpha_max_rad": self.alpha_max_rad,
                "spot_size": self.spot_size, "point_sources": self.point_sources, "exact": self.exact,
                "observers_above_alpha_min": self.observers_above_alpha_min, "observers_kept_specular": self.observers_kept_specular,
                "mpe_smallest_alpha": None if self.mpe_smallest_alpha is None else self.mpe_smallest_alpha.to_dict(),
                "mpe_largest_alpha": None if self.mpe_largest_alpha is None else self.mpe_largest_alpha.to_dict()}


NOT_APPLIED = ExtendedSourceSummary(applied=False)  # the point-source MPE everywhere


def _mpe_entry(a, v) -> ExtendedMpe:
    res, pulse, e = v
    return ExtendedMpe(alpha_rad=a, c_e=res.factors.C_E, alpha_max_rad=res.factors.alpha_max_rad, T2_s=res.factors.T2_s,
                       mpe_w_m2=e, table_row=res.table_row, formula=res.formula, label=res.label,
                       unverified=res.unverified, steps=tuple(res.steps), pulse=pulse)


def _summary(spec, ext, known, n_above, n_spec, t_exp) -> ExtendedSourceSummary:
    """The report's ``extended_source`` block."""
    applied = [(a, v) for a, v in sorted(ext.evaluations.items()) if a > 0]
    laser = spec.laser
    return ExtendedSourceSummary(
        applied=True,
        alpha_min_rad=ALPHA_MIN_RAD,
        alpha_max_rad=_mpe.correction_factors(laser.wavelength_nm, t_exp, 0.0, spec.exposure.standard).alpha_max_rad,
        spot_size="1/e (d63) diameter from the spot's second moments (the Gaussian beam footprint when one flat target "
                  "holds the whole beam, else the scatter of the beam samples: a lower bound); smaller principal axis "
                  "projected perpendicular to the line of sight; "
                  "alpha = 2 atan(D / 2R) from the spot centroid; smallest over the spots an observer faces",
        point_sources="observers receiving specular irradiance keep C_E = 1"
                      + ("" if known else " (not known per observer: every observer when a target has a mirror lobe)"),
        exact=ext.exact,
        observers_above_alpha_min=n_above,
        observers_kept_specular=n_spec,
        # the MPE calculation at the smallest and the largest subtense applied (every step)
        mpe_smallest_alpha=_mpe_entry(*applied[0]) if applied else None,
        mpe_largest_alpha=_mpe_entry(*applied[-1]) if len(applied) > 1 else None,
    )


def _subtense_by_block(result, observers, whole) -> np.ndarray:
    """:func:`observer_subtense_rad` of every observer, in blocks on threads (their
    points generated per block: scenes.observers)."""
    alpha = np.zeros(len(observers))

    def block(a0, a1, p):
        alpha[a0:a1] = observer_subtense_rad(result.spots, p, result.beam, whole)

    observers.map_blocks(block)
    return alpha


@dataclass(frozen=True)
class ExtendedSourceResult:
    """Stage ``extended_source`` (:func:`extended_source_of`): per observer the spot's
    angular subtense [rad], C_E, the MPE [W/m^2] and [J/m^2]; the first exceedance [s]
    recomputed with that MPE (static maps with C_E applied; None: the map's stands); the
    report's ``extended_source`` block, the notes it adds and its stage record."""

    angular_subtense_rad: np.ndarray
    c_e: np.ndarray
    mpe_w_m2: np.ndarray
    mpe_radiant_exposure_j_m2: np.ndarray
    first_exceedance_s: np.ndarray | None
    summary: ExtendedSourceSummary
    notes: tuple[str, ...]
    record: Stage

    def observer_fields(self) -> dict:
        """The :class:`hazard.pipeline.results.ObserverResults` fields this stage sets, by name."""
        out = {"angular_subtense_rad": self.angular_subtense_rad, "c_e": self.c_e, "mpe_w_m2": self.mpe_w_m2,
               "mpe_radiant_exposure_j_m2": self.mpe_radiant_exposure_j_m2}
        if self.first_exceedance_s is not None:
            out["first_exceedance_s"] = self.first_exceedance_s
        return out


def extended_source_of(result) -> ExtendedSourceResult:
    """The per-observer subtense, C_E and MPE of an analysis result (read, not changed).

    With ``[exposure] extended_source = true``: the subtense, C_E and MPE from the spot
    subtense (see the module notes), a ran stage record and the report's summary.
    Otherwise C_E = 1 and the scalar point-source MPE everywhere (the subtense is still
    reported), and a skipped stage. For static materials the first exceedance is
    recomputed with the per-observer MPE.
    """
    from hazard.pipeline.results import Stage

    t0 = time.perf_counter()
    scene = result.scene
    spec, m = scene.spec, len(result.observers)
    whole = [_holds_whole_beam(result, sp) for sp in result.spots]
    alpha = _subtense_by_block(result, scene.observers, whole) if (m and result.spots) else np.zeros(m)
    t_exp = spec.exposure.duration_s
    if not spec.exposure.extended_source:
        return _point_source_only(result, alpha, m, time.perf_counter() - t0)
    laser, pulsed = spec.laser, result.pulse is not None
    specular, known = _specular_observers(result, m)
    alpha_used = np.where(specular, 0.0, alpha)
    ext = extended_source_mpe(alpha_used, laser.wavelength_nm, t_exp, standard=spec.exposure.standard,
                              pulse_duration_s=laser.pulse_duration_s if pulsed else None,
                              prf_hz=laser.prf_hz if pulsed else None)
    uv_notes = []
    if laser.wavelength_nm < 400:  # C_E = 1 in the UV; keep the analysis's limit (it holds the UV 24 h accumulation)
        ext.mpe_w_m2 = np.minimum(ext.mpe_w_m2, float(result.mpe_w_m2))
        uv_notes.append(f"extended source: no C_E in the UV (180-400 nm); every observer keeps the analysis's MPE, "
                        f"{float(result.mpe_w_m2):.6g} W/m^2 (with the UV 24 h accumulation), not the single-exposure "
                        f"values of the extended_source block")
    c_e, mpe_obs, first, notes = _observer_mpe(result, ext, specular, m, t_exp)
    notes = uv_notes + list(notes)
    n_above = int((alpha_used > ALPHA_MIN_RAD).sum())
    if any(v[0].unverified for a, v in ext.evaluations.items() if a > 0):
        notes.append("extended source: the governing MPE row for some observers is labelled [M] "
                     "(extended-source rows for t >= 10 s, IEC 60825-1:2014 Table A.1 structure, or the photochemical limit "
                     "averaged over gamma_ph in the 2014 editions: unverified)")
    if n_above:
        notes.append("extended source: keep-out lobes, NOHDs and the ground footprint use the point-source MPE (conservative)")
    return ExtendedSourceResult(
        angular_subtense_rad=alpha, c_e=c_e, mpe_w_m2=mpe_obs, mpe_radiant_exposure_j_m2=mpe_obs * t_exp,
        first_exceedance_s=first, summary=_summary(spec, ext, known, n_above, int(specular.sum()), t_exp), notes=tuple(notes),
        record=Stage("extended_source", True, _stage_detail(c_e, alpha, ext, specular, known, n_above, m),
                     time.perf_counter() - t0))


def apply_extended_source(result):
    """Set :func:`extended_source_of` on ``result`` in place (returns it): the observers'
    ``angular_subtense_rad``, ``c_e``, ``mpe_w_m2``, ``mpe_radiant_exposure_j_m2`` (and a
    static map's ``first_exceedance_s``), ``result.extended_source``, its notes and stage
    record. For results built outside :func:`hazard.analyze` (which assembles a new result
    from the stage's instead); ``hazard_ratio``, ``hazardous`` and ``hazardous_static``
    then use the per-observer MPE.
    """
    ext = extended_source_of(result)
    for name, value in ext.observer_fields().items():
        setattr(result.observers, name, value)
    result.notes.extend(ext.notes)
    result.extended_source = ext.summary
    result.stages.append(ext.record)
    return result
