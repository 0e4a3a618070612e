"""Reflected irradiance at observers: beam sampling, spots, BRDF and specular reflection.

Physics (spec `dynamic-sh-brdf.md` section 3 and `laser-safety.md` section 3.1):

* The beam is Gaussian with 1/e diameter ``D(R) = a + R phi`` (the growth law of the NOHD
  formula). It is sampled by rays from a virtual source ``a / phi`` behind the aperture,
  with Gauss-Laguerre radial nodes (exact moments of the Gaussian) and uniform azimuths;
  each ray carries its share of the power. Rays that miss every target spill.
* A hit of power P on a surface reflects to an observer at distance R as
  ``E = f_r(wi, wo, state) cos(theta_r) P tau(R) K / R^2``, computed through
  ``f_r cos(theta_r)`` so grazing observers give no 0/0. Observers at least 20 spot sizes
  away see the spot as one point source (power-weighted centroid, mean direction and
  normal); nearer ones sum over the hits.
* An ideal-mirror (delta) lobe is traced as a reflected beam: image source, folded path
  ``R1 + z``, the same Gaussian beam growth, flat mirror at the spot (conservative for
  convex reflectors, which spread the beam more).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from brdfmodels import DynamicBRDF, Scaled, StateTable

__all__ = ["Beam", "Spot", "sample_beam", "trace_spots", "projected_brdf", "spot_irradiance", "specular_irradiance", "FAR_FIELD_SPOT_SIZES"]

FAR_FIELD_SPOT_SIZES = 20.0  # witness-screen rule: >= 20 spot sizes for ~1 % point-source error


@dataclass
class Beam:
    origins: np.ndarray
    directions: np.ndarray
    power_w: np.ndarray
    position_m: np.ndarray
    axis: np.ndarray
    diameter_m: float
    divergence_rad: float

    def diameter_at(self, range_m):
        """1/e beam diameter [m] at a range from the aperture."""
        return self.diameter_m + np.asarray(range_m) * self.divergence_rad


def _perp_basis(axis):
    a = np.array([1.0, 0.0, 0.0]) if abs(axis[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    e1 = np.cross(axis, a)
    e1 /= np.linalg.norm(e1)
    return e1, np.cross(axis, e1)


@lru_cache(maxsize=16)
def _laguerre(n):
    """Gauss-Laguerre nodes and weights (cached: an eigenvalue solve each time would also
    leave BLAS threads spinning into the next stage)."""
    return np.polynomial.laguerre.laggauss(n)


def sample_beam(position_m, axis, power_w, diameter_m, divergence_rad, n_samples) -> Beam:
    """Rays across a Gaussian beam (1/e diameter ``diameter_m`` at the aperture, full
    1/e divergence ``divergence_rad``), ``n_samples`` of them (rounded to a polar grid)."""
    axis = np.asarray(axis, float) / np.linalg.norm(axis)
    pos = np.asarray(position_m, float)
    if n_samples <= 1:
        return Beam(pos[None], axis[None], np.array([power_w]), pos, axis, diameter_m, divergence_rad)
    n_r = max(1, int(round(math.sqrt(n_samples / 4))))
    n_phi = max(4, int(math.ceil(n_samples / n_r)))
    u, w = _laguerre(n_r)  # int_0^inf f(u) e^-u du, u = rho^2
    rho = np.sqrt(u)
    psi = 2 * np.pi * (np.arange(n_phi) + 0.5) / n_phi
    rr, pp = np.meshgrid(rho, psi, indexing="ij")
    ww = np.repeat(w[:, None], n_phi, axis=1) / n_phi
    e1, e2 = _perp_basis(axis)
    tr = (np.cos(pp)[..., None] * e1 + np.sin(pp)[..., None] * e2) * rr[..., None]  # in units of the 1/e radius
    origins = pos + tr.reshape(-1, 3) * (diameter_m / 2)
    dirs = axis + tr.reshape(-1, 3) * (divergence_rad / 2)
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    weights = ww.ravel() / ww.sum()
    return Beam(origins, dirs, weights * power_w, pos, axis, diameter_m, divergence_rad)


@dataclass
class Spot:
    """The beam's hits on one target, with per-hit material frames (rows x, y, z)."""

    target: object
    points: np.ndarray
    power_w: np.ndarray
    incoming: np.ndarray  # propagation direction (towards the surface), unit
    frames: np.ndarray  # (n, 3, 3) material frames
    range_from_laser_m: np.ndarray

    @property
    def total_power_w(self) -> float:
        return float(self.power_w.sum())

    @property
    def centroid(self) -> np.ndarray:
        return (self.points * self.power_w[:, None]).sum(0) / self.total_power_w

    @property
    def mean_incoming(self) -> np.ndarray:
        d = (self.incoming * self.power_w[:, None]).sum(0)
        return d / np.linalg.norm(d)

    @property
    def mean_frame(self) -> np.ndarray:
        f = (self.frames * self.power_w[:, None, None]).sum(0)
        z = f[2] / np.linalg.norm(f[2])
        x = f[0] - np.dot(f[0], z) * z
        x /= np.linalg.norm(x)
        return np.stack([x, np.cross(z, x), z])

    @property
    def size_m(self) -> float:
        """Spot size: twice the power-weighted RMS radius (the 1/e diameter for a Gaussian)."""
        r2 = ((self.points - self.centroid) ** 2).sum(1)
        return float(2 * math.sqrt(max((r2 * self.power_w).sum() / self.total_power_w, 0.0)))

    @property
    def mean_range_m(self) -> float:
        return float((self.range_from_laser_m * self.power_w).sum() / self.total_power_w)


def _hit_normals(target, points, faces, ray_scene):
    mesh = target.mesh
    n = ray_scene.face_normals(faces)
    if mesh.analytic is not None:
        kind = mesh.analytic[0]
        if kind == "sphere":
            c, r = mesh.analytic[1], mesh.analytic[2]
            n = points - c
        elif kind == "cylinder":
            c, ax, r, half_h = mesh.analytic[1:]
            rel = points - c
            along = rel @ ax
            side = np.abs(along) < half_h * (1 - 1e-9)
            radial = rel - along[:, None] * ax
            n = np.where(side[:, None], radial, n)
        n = n / np.linalg.norm(n, axis=1, keepdims=True)
    return n


def _frames(target, normals):
    t = target.tangent
    x = t - (normals @ t)[:, None] * normals
    bad = np.linalg.norm(x, axis=1) < 1e-9
    if np.any(bad):  # tangent along the normal at this point: any perpendicular will do
        alt = np.cross(normals[bad], [0.0, 0.0, 1.0])
        alt[np.linalg.norm(alt, axis=1) < 1e-9] = np.cross(normals[bad][np.linalg.norm(alt, axis=1) < 1e-9], [1.0, 0.0, 0.0])
        x[bad] = alt
    x /= np.linalg.norm(x, axis=1, keepdims=True)
    y = np.cross(normals, x)
    g = target.groove_angle_rad
    xm = math.cos(g) * x + math.sin(g) * y
    ym = -math.sin(g) * x + math.cos(g) * y
    return np.stack([xm, ym, normals], axis=1)


def trace_spots(beam: Beam, targets, ray_scene):
    """First hits of the beam rays; returns (spots, spill_w, blocked_w).

    ``blocked_w`` is power stopped by occluders or terrain before any target.
    """
    hits = ray_scene.first_hit(beam.origins, beam.directions)
    spots = []
    n_targets = len(targets)
    on_target = hits.hit & (hits.obj >= 0) & (hits.obj < n_targets)
    for target in targets:
        sel = on_target & (hits.obj == target.index)
        if not np.any(sel):
            continue
        pts = hits.point[sel]
        normals = _hit_normals(target, pts, hits.face[sel], ray_scene)
        spots.append(Spot(target, pts, beam.power_w[sel], beam.directions[sel], _frames(target, normals), hits.t[sel]))
    spill = float(beam.power_w[~hits.hit].sum())
    blocked = float(beam.power_w[hits.hit & ~on_target].sum())
    return spots, spill, blocked


# -- BRDF evaluation over states ------------------------------------------------------------
def projected_brdf(model, wi, wo, states=None, row_scale=None, reduce=None) -> np.ndarray:
    """``f_r cos(theta_r)`` [1/sr] at pairs (N, 3), for no state (N,) or states (T,) -> (N, T),
    optionally multiplied by a per-row factor ``row_scale`` (N,).

    Dynamic SH models are evaluated as one basis evaluation and one matrix product over
    all states, with ``row_scale`` folded into the exponent; a state-table factor
    multiplies; other models loop over the states. ``reduce="max"`` returns the maximum
    over the states (N,) without forming (N, T) where the model allows: inside the
    dynamic SH evaluation, and as ``f x max(factor)`` for a static model scaled by a
    (non-negative) state-table factor.
    """
    if states is None:
        f = model.evaluate_cos(wi, wo)
        return f if row_scale is None else f * row_scale
    states = np.asarray(states, float)
    if isinstance(model, DynamicBRDF):
        return model.evaluate_many(wi, wo, states, projected=True, row_scale=row_scale, reduce=reduce)
    if isinstance(model, Scaled):
        table = isinstance(model.factor, StateTable)
        if reduce and not (table and model.model.is_dynamic):
            # the max of a product with a non-negative factor that does not vary with the
            # inner model's states (or an inner model that does not vary) factorises
            inner = projected_brdf(model.model, wi, wo, states if model.model.is_dynamic else None, row_scale, reduce)
            return inner * (float(np.max(model.factor(states))) if table else model.factor)
        inner = projected_brdf(model.model, wi, wo, states if model.model.is_dynamic else None, row_scale)
        if inner.ndim == 1:
            inner = inner[:, None]
        f = inner * (model.factor(states)[None, :] if table else model.factor)
        return f.max(axis=1) if reduce else f
    if not model.is_dynamic:
        f = model.evaluate_cos(wi, wo)
        if row_scale is not None:
            f = f * row_scale
        return f if reduce else np.repeat(f[:, None], states.size, axis=1)
    f = np.stack([model.evaluate_cos(wi, wo, state=float(s)) for s in states], axis=-1)
    f = f if row_scale is None else f * row_scale[:, None]
    return f.max(axis=1) if reduce else f


def _to_local(frames, v):
    """World vectors v (..., 3) into frames (3, 3) or per-row frames (N, 3, 3)."""
    if frames.ndim == 2:
        return v @ frames.T
    return np.einsum("nij,nj->ni", frames, v)


def spot_irradiance(spot: Spot, observers_m, gain, attenuation_per_m, states=None, visible=None, *, sparse=False):
    """BRDF-reflected irradiance [W/m^2] at observers (M, 3) from one spot.

    Returns ``(E, far)``: E of shape (M,) or (M, T) with states, and the far-field mask.
    ``visible`` (M,) is the line-of-sight mask (default: all visible); it is folded into
    the per-observer factor, so occluded observers cost no extra pass. With
    ``sparse=True`` it returns ``((rows, E_rows), far)``: when every observer is in the
    far field only the rows that receive light (maps skip everyone behind the surface or
    out of sight), otherwise all rows.
    """
    obs = np.asarray(observers_m, float)
    m = len(obs)
    model = spot.target.material
    c = spot.centroid
    rng = np.linalg.norm(obs - c, axis=1)
    far = rng >= FAR_FIELD_SPOT_SIZES * max(spot.size_m, 1e-9)
    vis = np.ones(m) if visible is None else np.asarray(visible, float)
    if np.all(far):
        fr = spot.mean_frame
        wi = _to_local(fr, -spot.mean_incoming)[None, :]
        wo = _to_local(fr, (obs - c) / rng[:, None])
        scale = spot.total_power_w * gain * vis / rng**2
        if attenuation_per_m:
            scale *= np.exp(-attenuation_per_m * rng)
        # observers behind the surface or out of sight receive nothing: evaluate the rest only
        live = (wo[:, 2] > 0) & (scale > 0)
        # wi is one direction (1, 3): the models broadcast it after checking it once
        if sparse:
            rows = np.flatnonzero(live)
            return (rows, projected_brdf(model, wi, wo[rows], states, scale[rows])), far
        if live.all():
            return projected_brdf(model, wi, wo, states, scale), far
        e = np.zeros((m,) if states is None else (m, len(states)))
        if live.any():
            e[live] = projected_brdf(model, wi, wo[live], states, scale[live])
        return e, far
    shape = (m,) if states is None else (m, len(states))
    e = np.zeros(shape)
    if np.any(far):
        fr = spot.mean_frame
        wi = _to_local(fr, -spot.mean_incoming)[None, :]
        d = (obs[far] - c) / rng[far, None]
        wo = _to_local(fr, d)
        scale = spot.total_power_w * np.exp(-attenuation_per_m * rng[far]) * gain[far] * vis[far] / rng[far] ** 2
        e[far] = projected_brdf(model, wi, wo, states, scale)
    near = np.flatnonzero(~far & (vis > 0))
    if len(near):
        wi_all = _to_local(spot.frames, -spot.incoming)
        for i in range(len(spot.points)):
            v = obs[near] - spot.points[i]
            r = np.linalg.norm(v, axis=1)
            wo = _to_local(spot.frames[i], v / np.maximum(r, 1e-300)[:, None])
            scale = spot.power_w[i] * np.exp(-attenuation_per_m * r) * gain[near] * vis[near] / np.maximum(r, 1e-300) ** 2
            e[near] += projected_brdf(model, np.broadcast_to(wi_all[i], wo.shape), wo, states, scale)
    return ((np.arange(m), e), far) if sparse else (e, far)


def specular_power_w(spot: Spot, states=None):
    """Power [W] in the delta (mirror) lobe of a spot, per state."""
    model = spot.target.material
    wi = _to_local(spot.frames, -spot.incoming)
    if states is None:
        return float((model.specular_reflectance(wi) * spot.power_w).sum())
    return np.array([(model.specular_reflectance(wi, state=float(s)) * spot.power_w).sum() for s in states])


def mirror_axis(spot: Spot) -> np.ndarray:
    n = spot.mean_frame[2]
    d = spot.mean_incoming
    r = d - 2 * np.dot(d, n) * n
    return r / np.linalg.norm(r)


def specular_irradiance(spot: Spot, observers_m, gain, attenuation_per_m, beam: Beam, states=None):
    """Irradiance [W/m^2] of the reflected (delta-lobe) beam at observers (M,) or (M, T).

    Image source with a folded path: ``E = P_s 4 / (pi D^2) exp(-4 rho^2 / D^2)
    exp(-mu R_f) K`` with ``R_f = R1 + z``, ``D = a + R_f phi``, z the distance along the
    mirror axis and rho the distance from it.
    """
    obs = np.asarray(observers_m, float)
    c = spot.centroid
    r_axis = mirror_axis(spot)
    v = obs - c
    z = v @ r_axis
    rho2 = np.maximum((v * v).sum(1) - z * z, 0.0)
    r_f = spot.mean_range_m + np.maximum(z, 0.0)
    dia = beam.diameter_m + r_f * beam.divergence_rad
    profile = 4.0 / (math.pi * dia**2) * np.exp(-4.0 * rho2 / dia**2) * np.exp(-attenuation_per_m * r_f) * gain
    profile = np.where(z > 0, profile, 0.0)
    p_s = specular_power_w(spot, states)
    return profile * p_s if states is None else profile[:, None] * p_s[None, :]


def spot_directions(spot: Spot):
    """Incidence direction of the spot in its mean material frame."""
    return _to_local(spot.mean_frame, -spot.mean_incoming)


__all__ += ["specular_power_w", "mirror_axis", "spot_directions"]
