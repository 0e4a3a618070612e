"""Scattered measured BRDF samples as a model that honours every sample.

``ScatteredBRDF(theta_h_deg, theta_d_deg, phi_d_deg, values)`` (model ``scattered-table``)
holds measured f_r [1/sr] at scattered points of Rusinkiewicz's isotropic coordinates
(theta_h, theta_d, phi_d; :func:`brdfmodels.half_diff`) and interpolates them
barycentrically on a Delaunay triangulation of those points (``scipy.spatial.Delaunay``;
the barycentric transforms computed here, vectorised):

- at a sample the value is the sample's (to ~1e-7 relative: the points are moved by at
  most 1e-9 rad before the triangulation, so that every sample is a vertex and no
  simplex is flat);
- between samples the barycentric value is a convex combination of the 4 vertices of the
  enclosing simplex, so it never leaves their range (``between="linear"``);
- the triangulation is made in (theta_h cos 2 phi_d, theta_h sin 2 phi_d, theta_d)
  (:func:`_embed`): phi_d has period 180 deg (reciprocity: swapping wi and wo turns it by
  180 deg), so the model is exactly reciprocal; at theta_h = 0 (h on the normal) an
  isotropic BRDF does not depend on phi_d and the map is smooth there, where phi_d itself
  is rounding noise (a specular observer came out 10 % low in plain coordinates); a
  theta_d = 0 sample (wi = wo) is copied around its circle of phi_d for the same reason,
  and a pair within 1e-6 rad of wi = wo takes the largest value over that circle
  (continuous and conservative there);
- theta_d is weighed by ``THETA_D_SCALE`` = 0.3 in the triangulation (barycentric weights
  do not change with the scale; which samples form a simplex does): goniometers sample
  the incidence more coarsely than the scatter angles, and a specular lobe is nearly a
  function of theta_h alone, so simplices should join the same theta_h at neighbouring
  incidences. Measured on an ABg file (peak 10 /sr, 8 incidences 10 deg apart): the
  lowest ratio to the truth within 10 deg of the mirror direction at random incidences
  was 0.20 at weight 1, 0.86 at 0.3, 0.94 at 0.1 (whose wings reached 36x the truth);
  on a 5 deg Gaussian-lobe CSV 0.84, 0.88, 0.88;
- between samples, by default (``between="peak"``), the value is the larger of that convex
  combination and a peak-aware estimate, at most :data:`PEAK_CAP` = 4 times the convex
  combination: a linear interpolation of a lobe is low wherever the lobe is concave
  (near its peak: 0.83-0.88 of the truth on the files of
  tests/validation/test_measured_scene_refs.py), not conservative. Each sample carries the
  slope and curvature of log f from a weighted least-squares quadratic through its
  ``PEAK_K`` = 60 nearest samples (:func:`_local_quadratic`), in direction-cosine
  coordinates (:func:`_cosines`: X = beta_i + beta_o along and across D = beta_o - beta_i,
  and |D| / 2), where the log of a Gaussian lobe, elliptic or off the mirror direction, is
  quadratic; the estimate is exp(sum_k b_k p_k(x)), b_k the barycentric weights and p_k
  vertex k's quadratic (its own log value, its fit's slope and curvature) at x, each kept
  within the vertices' log range widened by log PEAK_CAP. It is exact at the samples and
  for a Gaussian lobe in direction cosines whose width is at least the sample spacing
  (the fits see its curvature). It cannot know a peak narrower than the spacing (a
  lobe's core between two measured incidences, as the ABg core of 2 deg between the
  .bsdf's incidences 10 deg apart: still 0.83 there), and the coordinates are singular
  where D = 0 (wi = wo, and the mirror direction at normal incidence): within about one
  spacing of normal incidence a peak can still be low (0.92 of a Gaussian of width
  1.15 spacings). ``between="linear"`` keeps the convex combination alone;
- samples at the same coordinates (a goniometer's repeated specular direction, mirrored
  copies, anisotropic rows that an isotropic table cannot separate, several states) are
  merged into their largest value, and :attr:`notes` says how many and how far apart.

Where no data reach the policy ``outside`` is explicit. It gives the values of guard
points on the boundary of the domain (theta_h up to 90 deg, theta_d 0 to 90 deg) wherever
no sample lies within the data's own spacing (the median distance between neighbouring
samples, 5 to 10 deg); the guards are vertices of the triangulation too, so between the
data's edge and the domain's boundary the value passes from the samples to the policy's:

- ``"envelope"`` (default, conservative and physically bounded): the largest of the
  ``NEAREST_K`` = 4 samples nearest in the points of :func:`_embed` [rad] (as many as a
  simplex has vertices): never the global maximum of a far-away specular peak;
- ``"fit"``: a spherical-harmonic fit of the samples (log space, horizon tacking;
  :func:`brdfmodels.fitting.fit_sh`), made on first use, capped at that envelope (an SH
  fit extrapolated to grazing angles reached 25 /sr where the data held 0.4): a shape
  below the envelope, never above it, so less conservative than "envelope";
- ``"error"``: a ValueError naming the direction's angles.

``dhr_tolerance`` is the measurement's stated uncertainty of the hemispherical reflectance
(absolute, default :data:`DHR_TOLERANCE` = 0.05): a scene refuses a table whose
reflectance exceeds 1 by more than that (:func:`scenes.scene._check_dhr`).
"""

from __future__ import annotations

import math

import numpy as np

from ._checks import finite_array
from .fileio import check_limit
from .geometry import isotropic_half_diff_rad
from .models import BRDFModel
from .registry import register

__all__ = ["ScatteredBRDF", "SCATTERED_OUTSIDE", "SCATTERED_BETWEEN", "DHR_TOLERANCE", "NEAREST_K", "THETA_D_SCALE",
           "PEAK_K", "PEAK_CAP", "isotropic_coordinates"]

SCATTERED_OUTSIDE = ("envelope", "fit", "error")
DHR_TOLERANCE = 0.05  # default stated uncertainty of a measured hemispherical reflectance (absolute)
NEAREST_K = 4  # samples whose largest value a direction outside the data's hull takes
THETA_D_SCALE = 0.3  # theta_d's weight in the triangulation (module notes)
GUARD_MIN_DEG = 5.0  # the guard points' spacing: the data's own (median nearest-neighbour distance), 5 to 10 deg
_JOGGLE_RAD = 1e-9  # the points are moved this much at most before the triangulation (every sample a vertex)
_SAME_RAD = 1e-8  # points of the interpolation this close [rad] are one (merged into the largest value)
_SPREAD_NOTED = 1e-6  # merged samples differing by more than this (relative) are said in the notes
_RETRO_COPIES = 72  # a theta_d = 0 sample (wi = wo) holds for every phi_d: copies every 2.5 deg
_RETRO_RAD = 1e-6  # a pair closer than this to wi = wo takes the largest value over its circle of phi_d
SCATTERED_BETWEEN = ("peak", "linear")
PEAK_K = 60  # neighbours of the local log-quadratic fit (10 coefficients)
PEAK_CAP = 4.0  # between samples the peak-aware value is at most this times the barycentric value
PEAK_Z_SCALE = 1.0  # |D| / 2 weighed as X (all three direction cosines, one metric) in the fits' neighbourhoods
_COPY = np.array([-1.0, -1.0, 1.0])  # a point of :func:`_cosines` and its reciprocal copy
_COPY_COEF = np.array([-1.0, -1.0, 1.0, 1.0, 1.0, 1.0, 1.0, -1.0, -1.0])  # :func:`_monomials`' coefficients at the copy
_PEAK_RCOND = 1e-7
_PEAK_SNAP = 1e-6  # barycentric weights below this are dropped from the peak-aware estimate  # directions the neighbours do not span get no slope or curvature (pseudo-inverse cut-off)


def isotropic_coordinates(wi, wo) -> np.ndarray:
    """(theta_h, theta_d, phi_d folded to [0, pi)) [rad] of flattened direction pairs, (N, 3)."""
    return np.column_stack(isotropic_half_diff_rad(wi, wo))


def _checked(name, deg, lo, hi) -> np.ndarray:
    v = finite_array(name, deg).ravel()
    if np.any(v < lo - 1e-9) or np.any(v > hi + 1e-9):
        j = int(np.flatnonzero((v < lo - 1e-9) | (v > hi + 1e-9))[0])
        raise ValueError(f"{name}[{j}] = {v[j]:.6g}: expected angles within [{lo:g}, {hi:g}] deg")
    return np.clip(v, lo, hi)


def _embed(th, td, pd) -> np.ndarray:
    """Points (M, 3) of the interpolation: (theta_h cos 2 phi_d, theta_h sin 2 phi_d, theta_d)
    [rad]. Polar in (theta_h, 2 phi_d): phi_d has period pi (reciprocity) and at theta_h = 0
    (h on the normal) an isotropic BRDF does not depend on phi_d, so the map is smooth there
    (in (theta_h, theta_d, phi_d) themselves a specular direction's phi_d is rounding noise)."""
    th, td, pd = (np.ravel(a) for a in (th, td, pd))
    return np.column_stack([th * np.cos(2 * pd), th * np.sin(2 * pd), td])


def _unembed(e) -> np.ndarray:
    """(theta_h, theta_d, phi_d) [rad] of points of :func:`_embed`."""
    return np.column_stack([np.hypot(e[:, 0], e[:, 1]), e[:, 2], np.mod(0.5 * np.arctan2(e[:, 1], e[:, 0]), math.pi)])


def _guards(spacing) -> np.ndarray:
    """Points around the domain's image (a cylinder: theta_h <= pi/2 its radius, theta_d
    from 0 to pi/2 its height) every ``spacing`` [rad], one spacing outside it (so that the
    joggle leaves no coordinate of the domain on or past the hull)."""
    top, pad = math.pi / 2, spacing
    n_a = max(8, math.ceil(2 * math.pi * (top + pad) / spacing))
    a = np.arange(n_a) * (2 * math.pi / n_a)
    z = np.linspace(-pad, top + pad, max(2, math.ceil((top + 2 * pad) / spacing) + 1))
    r_out = (top + pad) / math.cos(math.pi / n_a)
    side = np.column_stack([np.repeat(r_out * np.cos(a)[None], len(z), 0).ravel(),
                            np.repeat(r_out * np.sin(a)[None], len(z), 0).ravel(), np.repeat(z, n_a)])
    disk = [np.zeros((1, 2))]
    for r in np.arange(1, math.ceil((top + pad) / spacing)) * spacing:
        m = max(6, math.ceil(2 * math.pi * r / spacing))
        b = np.arange(m) * (2 * math.pi / m)
        disk.append(np.column_stack([r * np.cos(b), r * np.sin(b)]))
    d = np.vstack(disk)
    caps = [np.column_stack([d, np.full(len(d), h)]) for h in (-pad, top + pad)]
    return np.vstack([side] + caps)


def _merge(x_deg, f):
    """Samples at one point of the interpolation (:func:`_embed`, within 1e-8 rad) merged:
    the coordinate rows (N, 3) [deg] kept, the largest value of each, the number of rows
    merged and the largest relative spread among a merged group's values."""
    e = _embed(*np.radians(x_deg).T)
    key = np.round(e / _SAME_RAD).astype(np.int64)
    _, first, inv = np.unique(key, axis=0, return_index=True, return_inverse=True)
    inv = inv.ravel()
    hi = np.full(len(first), -np.inf)
    lo = np.full(len(first), np.inf)
    np.maximum.at(hi, inv, f)
    np.minimum.at(lo, inv, f)
    spread = float(np.max(np.where(hi > 0, (hi - lo) / np.where(hi > 0, hi, 1.0), 0.0))) if len(hi) else 0.0
    return x_deg[first], hi, len(f) - len(first), spread


def _barycentric_transforms(tri) -> np.ndarray:
    """scipy's ``Delaunay.transform`` layout, (n, 4, 3): the inverse of the edge matrix
    [v0 - v3, v1 - v3, v2 - v3] and the vertex v3 (NaN for a flat simplex)."""
    v = tri.points[tri.simplices]
    edges = np.transpose(v[:, :3] - v[:, 3:4], (0, 2, 1))
    out = np.full((len(v), 4, 3), np.nan)
    det = np.linalg.det(edges)
    scale = np.max(np.abs(edges), axis=(1, 2)) ** 3
    good = np.abs(det) > 1e-15 * np.maximum(scale, 1e-300)
    out[good, :3] = np.linalg.inv(edges[good])
    out[:, 3] = v[:, 3]
    return out


def _cosines(e) -> np.ndarray:
    """Direction-cosine coordinates (M, 3) of points of :func:`_embed`: with the direction
    pair (wi, wo) they stand for, X = beta_i + beta_o and D = beta_o - beta_i (beta: a
    direction's projection on the surface plane; X = beta - beta0 of Harvey's ABg and of
    the Gaussian lobe, 0 in the mirror direction), the components of X along and across D
    and |D| / 2. Swapping wi and wo (reciprocity) turns them into (-a, -b, c). Smooth in
    the direction pair except where D = 0 (wo = wi): the log of a Gaussian lobe in
    direction cosines, elliptic or off the mirror direction, is quadratic in them."""
    from .geometry import half_diff_to_directions

    q = _unembed(e)
    wi, wo = half_diff_to_directions(q[:, 0], np.zeros(len(q)), q[:, 1], q[:, 2])
    x, d = wi[:, :2] + wo[:, :2], wo[:, :2] - wi[:, :2]
    n = np.hypot(d[:, 0], d[:, 1])
    dh = np.where((n > 1e-12)[:, None], d / np.where(n > 1e-12, n, 1.0)[:, None], [1.0, 0.0])
    return np.column_stack([np.sum(x * dh, axis=1), x[:, 0] * dh[:, 1] - x[:, 1] * dh[:, 0], 0.5 * n])


def _monomials(d) -> np.ndarray:
    """The 9 non-constant monomials of a quadratic in 3 variables at offsets ``d`` (..., 3)."""
    x, y, z = d[..., 0], d[..., 1], d[..., 2]
    return np.stack([x, y, z, x * x, y * y, z * z, x * y, x * z, y * z], axis=-1)


def _local_quadratic(tq, pts, lv, tree, k=PEAK_K, chunk=20_000) -> np.ndarray:
    """The gradient and curvature of log f at each point of ``tq`` (M, 3) (already
    scaled, :func:`_cosines`): the coefficients (M, 9) of the monomials of
    :func:`_monomials` (offsets from the point) of the quadratic fitted by weighted least
    squares to the log values ``lv`` of its ``k`` nearest samples ``pts`` (``tree`` over
    them; weights (1 - d^2 / R^2)^2, R the distance of the (k + 1)-th, so the set of
    neighbours comes and goes with weight 0). Directions the neighbours do not span get
    no slope or curvature (pseudo-inverse cut at ``_PEAK_RCOND`` of the largest singular
    value). Exact where log f is quadratic in these coordinates."""
    out = np.empty((len(tq), 9))
    kk = min(k + 1, len(pts))
    for a in range(0, len(tq), chunk):
        c = tq[a:a + chunk]
        dist, j = tree.query(c, k=kk)
        w = np.clip(1.0 - dist[:, :-1] ** 2 / np.maximum(dist[:, -1:] ** 2, 1e-300), 0.0, None)  # sqrt of the weight
        m = _monomials(pts[j[:, :-1]] - c[:, None, :])
        design = np.concatenate([np.ones(m.shape[:2] + (1,)), m], axis=-1) * w[..., None]
        out[a:a + chunk] = np.einsum("nij,nj->ni", np.linalg.pinv(design, rcond=_PEAK_RCOND), lv[j[:, :-1]] * w)[:, 1:]
    return out


@register("scattered-table")
class ScatteredBRDF(BRDFModel):
    """Barycentric interpolation of scattered f_r [1/sr] samples in (theta_h, theta_d, phi_d).

    Parameters
    ----------
    theta_h_deg, theta_d_deg : array_like (N,)
        Half and difference angles of the samples, 0 to 90 deg.
    phi_d_deg : array_like (N,)
        Difference azimuths [deg], any real (folded modulo 180: reciprocity).
    values : array_like (N,)
        f_r [1/sr], finite and >= 0.
    outside : {"envelope", "fit", "error"}
        What directions beyond the samples' convex hull get (module notes).
    dhr_tolerance : float
        Stated absolute uncertainty of the measurement's hemispherical reflectance, 0 to 1.
    between : {"peak", "linear"}
        Between samples: "peak" (default) the larger of the barycentric value and a blend
        of local log-quadratic fits (exact for a Gaussian lobe; module notes), at most
        :data:`PEAK_CAP` times the barycentric value; "linear" the barycentric value alone.
    notes : list of str
        Provenance notes (a reader's wavelength interpolation, say); saved with the model.
        :attr:`notes` adds the merge note of duplicate samples.
    """

    def __init__(self, theta_h_deg, theta_d_deg, phi_d_deg, values, outside="envelope", dhr_tolerance=DHR_TOLERANCE,
                 notes=(), between="peak"):
        th = _checked("theta_h_deg", theta_h_deg, 0.0, 90.0)
        td = _checked("theta_d_deg", theta_d_deg, 0.0, 90.0)
        pd = np.mod(finite_array("phi_d_deg", phi_d_deg).ravel(), 180.0)
        f = finite_array("values", values).ravel()
        if not (len(th) == len(td) == len(pd) == len(f)) or len(f) < 1 or np.any(f < 0):
            raise ValueError(f"theta_h_deg, theta_d_deg, phi_d_deg, values: expected as many angles as values (finite, "
                             f">= 0), at least one; got {len(th)}, {len(td)}, {len(pd)}, {len(f)}")
        if outside not in SCATTERED_OUTSIDE:
            raise ValueError(f"outside={outside!r}: expected one of {list(SCATTERED_OUTSIDE)}")
        if between not in SCATTERED_BETWEEN:
            raise ValueError(f"between={between!r}: expected one of {list(SCATTERED_BETWEEN)}")
        tol = float(finite_array("dhr_tolerance", dhr_tolerance))
        if not 0.0 <= tol <= 1.0:
            raise ValueError(f"dhr_tolerance={tol!r}: expected an absolute reflectance uncertainty of 0 to 1")
        check_limit("SCATTERED_SAMPLES", len(f), "measured samples of a scattered table")
        x, f, n_merged, spread = _merge(np.column_stack([th, td, pd]), f)
        self.points_deg, self.values = x, f
        for arr in (self.points_deg, self.values):
            arr.flags.writeable = False
        self.outside, self.dhr_tolerance, self.between = outside, tol, between
        if isinstance(notes, str) or not all(isinstance(n, str) for n in notes):
            raise ValueError("notes: expected a list of strings")
        self.notes = tuple(notes) + ((f"{n_merged} sample(s) at the direction pair of another sample (isotropic "
                                      f"coordinates) were merged into the largest value; their values differed by up to "
                                      f"{100 * spread:.3g} %",) if spread > _SPREAD_NOTED else ())
        self._cache = {}  # the triangulation, the nearest-sample tree and the "fit" model, made on first use
        self._freeze()

    @classmethod
    def from_samples(cls, wi, wo, brdf_per_sr, *, outside="envelope", dhr_tolerance=DHR_TOLERANCE,
                     notes=(), between="peak") -> "ScatteredBRDF":
        """The model of measured samples (any reader's, :mod:`brdfmodels.io`): ``wi``, ``wo``
        (N, 3) directions to the source and to the observer, ``brdf_per_sr`` (N,) [1/sr]."""
        from ._checks import directions

        wi = directions("wi", wi).reshape(-1, 3)
        wo = directions("wo", wo).reshape(-1, 3)
        f = finite_array("brdf_per_sr", brdf_per_sr).ravel()
        if not (len(wi) == len(wo) == len(f)) or not len(f):
            raise ValueError("wi, wo, brdf_per_sr: expected as many directions as values, at least one")
        x = np.degrees(isotropic_coordinates(wi, wo))
        return cls(x[:, 0], x[:, 1], x[:, 2], f, outside, dhr_tolerance, notes, between)

    # -- evaluation ------------------------------------------------------------------------
    def _points(self):
        """The samples' points (:func:`_embed`), each theta_d = 0 sample (wi = wo: phi_d has
        no meaning there) copied around its circle of phi_d, merged; and their values."""
        x = np.radians(self.points_deg)
        retro = np.flatnonzero(x[:, 1] < _SAME_RAD)
        turn = np.repeat(np.arange(_RETRO_COPIES) * (math.pi / _RETRO_COPIES), len(retro))
        xr = np.tile(x[retro], (_RETRO_COPIES, 1))
        pts = np.vstack([x, np.column_stack([xr[:, 0], xr[:, 1], xr[:, 2] + turn])])
        _, first, inv = np.unique(np.round(_embed(*pts.T) / _SAME_RAD).astype(np.int64), axis=0, return_index=True,
                                  return_inverse=True)
        val = np.full(len(first), -np.inf)
        np.maximum.at(val, inv.ravel(), np.concatenate([self.values, np.tile(self.values[retro], _RETRO_COPIES)]))
        return _embed(*pts[first].T), val

    def _built(self):
        """The triangulation (None if the samples are too few or flat) of the samples'
        points and of guard points on the domain's boundary where no sample is within the
        data's own spacing (their values by the ``outside`` policy), the nearest-sample tree,
        the values and the number of sample points (the guards come after them)."""
        if "tri" not in self._cache:
            from scipy.spatial import Delaunay, QhullError, cKDTree

            e, val = self._points()
            tree = cKDTree(e)
            gap = float(np.median(tree.query(e, k=2)[0][:, 1])) if len(e) > 1 else math.radians(10.0)
            spacing = min(max(gap, math.radians(GUARD_MIN_DEG)), math.radians(10.0))  # the data's own sampling, 5-10 deg
            g = _guards(spacing)
            g = g[tree.query(g)[0] > spacing]
            gval = self._beyond(g, tree, val, placeholder=True)
            tri = None
            try:
                zs = THETA_D_SCALE
                pts = np.vstack([e, g]) * [1.0, 1.0, zs]  # joggled so that no simplex is flat (qhull's QJ left 27 % flat ones)
                pts = pts + np.random.default_rng(0).uniform(-_JOGGLE_RAD, _JOGGLE_RAD, pts.shape)
                tri = Delaunay(pts, qhull_options="Qbb Qc Qz Q12")
                tri._transform = _barycentric_transforms(tri)  # scipy's own took 21 s for 1.4e5 simplices
            except (QhullError, ValueError):  # too few or degenerate points: the policy everywhere
                tri = None
            self._cache.update(tri=tri, tree=tree, values=np.concatenate([val, gval]), n_data=len(e), spacing_rad=spacing,
                               z_scale=zs if tri is not None else 1.0, points=e)
        c = self._cache
        return c["tri"], c["tree"], c["values"], c["n_data"]

    def _interpolated(self, e):
        """Barycentric interpolation at points ``e`` (M, 3) and the weight it puts on guard
        points (0: the samples alone; NaN and 1 where no simplex holds a point)."""
        tri, _, val, n_data = self._built()
        out, guard = np.full(len(e), np.nan), np.ones(len(e))
        if tri is None:
            return out, guard
        e = e * [1.0, 1.0, self._cache["z_scale"]]
        s = tri.find_simplex(e)
        idx = np.flatnonzero(s >= 0)
        s = s[idx]
        t = tri.transform[s]
        b = np.einsum("mij,mj->mi", t[:, :3], e[idx] - t[:, 3])
        b = np.clip(np.column_stack([b, 1.0 - b.sum(axis=1)]), 0.0, None)  # rounding: keep a convex combination
        b /= b.sum(axis=1, keepdims=True)
        v = tri.simplices[s]
        out[idx] = np.sum(b * val[v], axis=1)
        guard[idx] = np.sum(b * (v >= n_data), axis=1)
        data = guard[idx] < 1.0 - 1e-9
        if self.between == "peak" and data.any():
            k = idx[data]
            out[k] = self._peak(e[k] / [1.0, 1.0, self._cache["z_scale"]], v[data], b[data], out[k], guard[k])
        return out, guard

    def _peak_fits(self):
        """Each vertex's point (:func:`_cosines`, scaled: 1 / the data's spacing) and its
        local log-quadratic's slope and curvature (:func:`_local_quadratic`; zero at guard
        points, whose value is the ``outside`` policy's), made on first use; None with
        fewer than 10 positive samples (no quadratic to fit)."""
        if "peak" not in self._cache:
            from scipy.spatial import cKDTree

            _, _, val, n_data = self._built()
            scale = np.array([1.0, 1.0, PEAK_Z_SCALE]) / self._cache["spacing_rad"]
            x = _cosines(self._vertices()) * scale
            pts = np.vstack([x[:n_data], x[:n_data] * _COPY])  # each sample and its reciprocal copy
            v = np.concatenate([val[:n_data], val[:n_data]])
            pos = v > 0
            coef = np.zeros((len(x), 9))
            if pos.sum() >= 2 * 10:
                coef[:n_data] = _local_quadratic(x[:n_data], pts[pos], np.log(v[pos]), cKDTree(pts[pos]))
            self._cache["peak"] = (x, coef) if pos.sum() >= 2 * 10 else None
        return self._cache["peak"]

    def _vertices(self):
        """The triangulation's vertices as points of :func:`_embed`: the samples' (before the
        joggle), then the guards'."""
        n = self._cache["n_data"]
        return np.vstack([self._cache["points"], self._cache["tri"].points[n:] / [1.0, 1.0, self._cache["z_scale"]]])

    def _peak(self, e, v, b, bary, guard):
        """Between samples (points ``e`` (M, 3) of :func:`_embed` in simplices of vertices
        ``v`` with barycentric weights ``b`` (M, 4), barycentric values ``bary``, weight
        ``guard`` on guard points): the larger of ``bary`` and exp(sum_k b_k p_k(x)), p_k
        vertex k's local log-quadratic (its log value, its fit's slope and curvature) at x
        (points of :func:`_cosines`; each vertex's reciprocal copy where nearer x), capped
        at PEAK_CAP^(1 - guard) ``bary``. Exact at the samples and where log f is
        quadratic in these coordinates (a Gaussian lobe in direction cosines)."""
        fits = self._peak_fits()
        if fits is None:
            return bary
        xv, coef = fits
        x = _cosines(e) * (np.array([1.0, 1.0, PEAK_Z_SCALE]) / self._cache["spacing_rad"])
        xk, ck = xv[v], coef[v]
        flip = np.sum((xk - x[:, None]) ** 2, axis=2) > np.sum((xk * _COPY - x[:, None]) ** 2, axis=2)
        xk = np.where(flip[..., None], xk * _COPY, xk)  # each vertex's reciprocal copy nearer x
        ck = np.where(flip[..., None], ck * _COPY_COEF, ck)
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            lf = np.log(self._cache["values"][v])
            p = lf + np.einsum("nki,nki->nk", ck, _monomials(x[:, None] - xk))
            span = math.log(PEAK_CAP)  # each vertex's quadratic kept within the vertices' range widened by the cap
            p = np.clip(p, np.min(lf, axis=1, keepdims=True) - span, np.max(lf, axis=1, keepdims=True) + span)
            b = np.where(b < _PEAK_SNAP, 0.0, b)  # the joggle's 1e-9 of a far vertex's quadratic: not at a sample
            b /= np.sum(b, axis=1, keepdims=True)
            est = np.exp(np.minimum(np.sum(b * p, axis=1), np.log(bary) + (1.0 - guard) * math.log(PEAK_CAP)))
        return np.where(np.isfinite(est), np.maximum(bary, est), bary)

    def at_coordinates(self, theta_h, theta_d, phi_d) -> np.ndarray:
        """f_r [1/sr] at coordinates [rad] (any theta_h, theta_d in [0, pi/2], phi_d any real;
        below-horizon combinations too: the interpolation works in coordinates)."""
        q = np.column_stack([np.ravel(theta_h), np.ravel(theta_d), np.mod(np.ravel(phi_d), math.pi)])
        retro = np.flatnonzero(q[:, 1] < _RETRO_RAD)
        if len(retro):  # wi = wo: phi_d has no meaning; the largest over its circle (continuous, conservative)
            ring = np.arange(_RETRO_COPIES) * (math.pi / _RETRO_COPIES)
            q = np.vstack([np.delete(q, retro, axis=0), np.column_stack([np.repeat(q[retro, 0], _RETRO_COPIES),
                           np.repeat(q[retro, 1], _RETRO_COPIES), np.tile(ring, len(retro))])])
            v = self._at(q)
            out = np.empty(len(v) - (_RETRO_COPIES - 1) * len(retro))
            keep = np.setdiff1d(np.arange(len(out)), retro)
            out[keep] = v[:len(keep)]
            out[retro] = v[len(keep):].reshape(len(retro), _RETRO_COPIES).max(axis=1)
            return out
        return self._at(q)

    def _at(self, q):
        """:meth:`at_coordinates` at rows ``q`` (M, 3) [rad] (phi_d already folded)."""
        e = _embed(*q.T)
        out, guard = self._interpolated(e)
        if self.outside == "error" and np.any(guard > 1e-9):
            h, d, p = np.degrees(q[np.argmax(guard > 1e-9)])
            raise ValueError(f"direction pair beyond the measured samples: theta_h {h:.4g} deg, theta_d {d:.4g} deg, "
                             f"phi_d {p:.4g} deg (outside = 'envelope' or 'fit' to go beyond)")
        miss = np.isnan(out)
        if miss.any():
            _, tree, val, n_data = self._built()
            out[miss] = self._beyond(e[miss], tree, val[:n_data])
        return out

    def _beyond(self, e, tree, val, placeholder=False):
        """The ``outside`` policy at points ``e`` (M, 3) no sample reaches (``placeholder``:
        the guards of the "error" policy take the envelope; it is never used)."""
        if self.outside == "error" and not placeholder:
            h, d, p = np.degrees(_unembed(e[:1]))[0]
            raise ValueError(f"direction pair beyond the measured samples: theta_h {h:.4g} deg, theta_d {d:.4g} deg, "
                             f"phi_d {p:.4g} deg (outside = 'envelope' or 'fit' to go beyond)")
        k = min(NEAREST_K, len(val))
        _, idx = tree.query(e, k=k)
        envelope = val[np.asarray(idx).reshape(len(e), k)].max(axis=1)
        return np.minimum(self._fitted_at(_unembed(e)), envelope) if self.outside == "fit" else envelope

    def _fitted_at(self, q):
        """The "fit" policy's spherical-harmonic fit of the samples at coordinates ``q`` [rad]."""
        from .geometry import half_diff_to_directions

        if "fit" not in self._cache:
            from .fitting import fit_sh
            from .sh import SHBasis

            x = np.radians(self.points_deg)
            wi, wo = half_diff_to_directions(x[:, 0], np.zeros(len(x)), x[:, 1], x[:, 2])
            keep = (wi[:, 2] > 1e-6) & (wo[:, 2] > 1e-6) & (self.values > 0)
            self._cache["fit"] = fit_sh(wi[keep], wo[keep], self.values[keep], SHBasis(8, 4, 2, 0)).model
        a, b = half_diff_to_directions(q[:, 0], np.zeros(len(q)), q[:, 1], q[:, 2])
        a[:, 2], b[:, 2] = np.maximum(a[:, 2], 1e-3), np.maximum(b[:, 2], 1e-3)  # below-horizon nodes: tacked
        return self._cache["fit"].evaluate(a, b)

    def _fr(self, wi, wo, state):
        x = isotropic_coordinates(wi, wo)
        return self.at_coordinates(x[:, 0], x[:, 1], x[:, 2])

    def inside(self, wi, wo) -> np.ndarray:
        """True where the samples alone give a direction pair's value (no guard point of the
        ``outside`` policy weighs in)."""
        from ._checks import directions

        x = isotropic_coordinates(directions("wi", wi).reshape(-1, 3), directions("wo", wo).reshape(-1, 3))
        out, guard = self._interpolated(_embed(*x.T))
        return ~np.isnan(out) & (guard <= 1e-9)

    def _params(self):
        return {"theta_h_deg": self.points_deg[:, 0].tolist(), "theta_d_deg": self.points_deg[:, 1].tolist(),
                "phi_d_deg": self.points_deg[:, 2].tolist(), "values": self.values.tolist(), "outside": self.outside,
                "dhr_tolerance": self.dhr_tolerance, "notes": list(self.notes), "between": self.between}
