"""Integrals and checks over a BRDF: hemispherical reflectance, envelope conservativeness.

Directional-hemispherical reflectance (DHR)
    ``rho(wi) = integral over the hemisphere of f_r(wi, wo) cos(theta_o) d omega_o``
    (Nicodemus et al., NBS Monograph 160, 1977). It is computed in half-vector space,
    ``wo = 2 (wi.h) h - wi`` with ``d omega_o = 4 (wi.h) d omega_h``, so a specular lobe
    (a function of theta_h) lies along one edge of the integration rectangle. The
    observer's horizon ``wo_z = 0`` is the curve ``theta_h = theta_max(phi_h) =
    (pi/2 + atan2(a, wi_z)) / 2`` with ``a = |wi_xy| cos(phi_h - phi_i)``; the variables
    ``(u, phi_h)`` with ``theta_h = u theta_max(phi_h)``, ``u in [0, 1]``, map the valid
    region exactly onto a rectangle, so the integrand has no discontinuity inside it.
    The rectangle is cut into cells graded geometrically towards ``u = 0`` (the mirror
    direction, lobes down to ~1e-6 rad wide) and through the retro direction; each cell is
    integrated with tensor Gauss-Legendre and compared with its four children; the cells
    with the largest differences are split until the summed difference meets the
    tolerance. Delta (mirror) lobes are added analytically.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np

from ._checks import directions, finite_scalar
from .states import grid_points

__all__ = ["hemispherical_reflectance", "hemispherical_reflectance_states", "DHRResult", "envelope_report", "EnvelopeReport"]

_NGL = 6
_GX, _GW = np.polynomial.legendre.leggauss(_NGL)


@dataclass(frozen=True)
class DHRResult:
    """Directional-hemispherical reflectance with its quadrature error estimate."""

    value: float
    error_estimate: float
    evaluations: int
    cells: int
    converged: bool
    specular_part: float
    wall_time_s: float

    def __float__(self):
        return self.value


def _theta_max(wi, phi):
    """Half-vector polar angle at which the reflected direction reaches the horizon."""
    a = math.hypot(wi[0], wi[1]) * np.cos(phi - math.atan2(wi[1], wi[0]))
    return 0.5 * (0.5 * math.pi + np.arctan2(a, wi[2]))


def _cell_integrals(model, wi, cells, state):
    """Gauss-Legendre integral of the warped integrand over each (u, phi_h) cell (n, 4)."""
    return _cell_integrals_with(lambda wo: model.evaluate_cos(np.broadcast_to(wi, wo.shape), wo, state=state), wi, cells)


def _cell_integrals_with(projected, wi, cells):
    """:func:`_cell_integrals` of ``projected(wo)`` (f_r cos(theta_o) at reflected directions
    ``wo`` (n, g*g, 3); shape (n, g*g), or (n, g*g, S) for S states at once): (n,) or (n, S)."""
    u0, u1, p0, p1 = cells.T
    uu = (0.5 * (u1 - u0))[:, None] * (_GX[None, :] + 1.0) + u0[:, None]  # (n, g)
    pp = (0.5 * (p1 - p0))[:, None] * (_GX[None, :] + 1.0) + p0[:, None]
    u = np.repeat(uu, _NGL, axis=1)  # (n, g*g): u varies slowest
    p = np.tile(pp, (1, _NGL))
    tmax = _theta_max(wi, p)
    theta = u * tmax
    st = np.sin(theta)
    h = np.stack([st * np.cos(p), st * np.sin(p), np.cos(theta)], axis=-1)
    wih = h @ wi
    wo = 2.0 * wih[..., None] * h - wi
    wo /= np.linalg.norm(wo, axis=-1, keepdims=True)
    # Round-off can put wo a hair below the horizon at u = 1; the BRDF is 0 there anyway.
    jac = 4.0 * np.maximum(wih, 0.0) * st * tmax  # d omega_h = sin(theta) d theta d phi = sin(theta) theta_max du d phi
    g = projected(wo)
    if g.ndim == 3:
        jac = jac[..., None]
    w = np.outer(_GW, _GW).ravel()
    area = 0.25 * (u1 - u0) * (p1 - p0)
    return np.einsum("ng...,g->n...", g * jac, w) * (area if g.ndim == 2 else area[:, None])


def _split(cells):
    c0, c1, p0, p1 = cells.T
    cm, pm = 0.5 * (c0 + c1), 0.5 * (p0 + p1)
    return np.concatenate(
        [
            np.stack([c0, cm, p0, pm], 1),
            np.stack([cm, c1, p0, pm], 1),
            np.stack([c0, cm, pm, p1], 1),
            np.stack([cm, c1, pm, p1], 1),
        ]
    )


def _estimate(model, wi, cells, state):
    """Fine value (sum over children) and error |coarse - fine| per cell."""
    coarse = _cell_integrals(model, wi, cells, state)
    fine = _cell_integrals(model, wi, _split(cells), state).reshape(4, -1).sum(axis=0)
    return fine, np.abs(fine - coarse)


def _initial_cells(wi):
    phi_i = math.atan2(wi[1], wi[0])
    theta_i = math.acos(min(max(wi[2], -1.0), 1.0))
    u_retro = theta_i / float(_theta_max(wi, np.array(phi_i)))
    u_breaks = [0.0, *10.0 ** np.arange(-7.0, 0.0), 0.25, 0.5, 0.75, 1.0]
    u_breaks = np.unique(np.clip(np.concatenate([u_breaks, [u_retro]]), 0.0, 1.0))
    p_breaks = np.linspace(-math.pi, math.pi, 17)
    p_breaks = np.unique(np.concatenate([p_breaks, [phi_i]]))
    cc = np.stack(np.meshgrid(np.arange(u_breaks.size - 1), np.arange(p_breaks.size - 1), indexing="ij"), -1).reshape(-1, 2)
    return np.stack(
        [u_breaks[cc[:, 0]], u_breaks[cc[:, 0] + 1], p_breaks[cc[:, 1]], p_breaks[cc[:, 1] + 1]], axis=1
    )


def hemispherical_reflectance(model, wi, *, state=None, rtol=1e-6, atol=1e-10, max_evaluations=2_000_000) -> DHRResult:
    """Directional-hemispherical reflectance of ``model`` at incidence ``wi``.

    Parameters
    ----------
    model : BRDFModel
    wi : array_like, shape (3,)
        Direction to the source in the surface frame (z > 0).
    state : float, optional
        Material state for dynamic models.
    rtol, atol : float
        Stop when the summed cell error estimate is below ``max(rtol * value, atol)``.
    max_evaluations : int
        Budget of BRDF evaluations; the result says whether it converged within it.

    Returns
    -------
    DHRResult
        ``value`` (dimensionless; includes delta lobes), ``error_estimate`` (absolute),
        evaluation count and convergence flag.
    """
    wi = directions("wi", wi)
    if wi.shape != (3,):
        raise ValueError(f"wi: expected one direction of shape (3,), got {wi.shape}")
    if not wi[2] > 0:
        raise ValueError(f"wi={wi.tolist()!r}: expected a direction above the surface (z > 0)")
    rtol = finite_scalar("rtol", rtol, minimum=0.0)
    atol = finite_scalar("atol", atol, minimum=0.0)
    start = time.perf_counter()
    spec = float(model.specular_reflectance(wi, state=state))
    per_cell = 5 * _NGL * _NGL
    cells = _initial_cells(wi)
    vals, errs = _estimate(model, wi, cells, state)
    evals = per_cell * cells.shape[0]
    while True:
        total, err = float(vals.sum()), float(errs.sum())
        if err <= max(rtol * abs(total + spec), atol):
            converged = True
            break
        # split the cells holding the largest errors (at least the worst one)
        order = np.argsort(errs)[::-1]
        cum = np.cumsum(errs[order])
        k = int(np.searchsorted(cum, 0.5 * err)) + 1
        k = min(max(k, 1), order.size)
        if evals + 4 * k * per_cell > max_evaluations:
            converged = False
            break
        chosen = order[:k]
        keep = np.ones(cells.shape[0], bool)
        keep[chosen] = False
        children = _split(cells[chosen])
        cv, ce = _estimate(model, wi, children, state)
        evals += per_cell * children.shape[0]
        cells = np.concatenate([cells[keep], children])
        vals = np.concatenate([vals[keep], cv])
        errs = np.concatenate([errs[keep], ce])
    return DHRResult(
        value=total + spec,
        error_estimate=err,
        evaluations=evals,
        cells=int(cells.shape[0]),
        converged=converged,
        specular_part=spec,
        wall_time_s=time.perf_counter() - start,
    )


def _projected_states(model, wi, states):
    """``projected(wo) -> (n, g, S)``: f_r cos(theta_o) of ``model`` at every state of
    ``states`` (S,) or (S, 2) (None: the static model); one basis evaluation and one GEMM
    for a spherical-harmonic table (``evaluate_many``), a loop over the states otherwise."""
    if states is None:
        return lambda wo: model.evaluate_cos(np.broadcast_to(wi, wo.shape), wo)[..., None]
    many = getattr(model, "evaluate_many", None)

    def projected(wo):
        flat = wo.reshape(-1, 3)
        if many is not None:
            v = many(np.broadcast_to(wi, flat.shape), flat, states, projected=True)
        else:
            v = np.stack([model.evaluate_cos(np.broadcast_to(wi, flat.shape), flat, state=s) for s in states], axis=-1)
        return v.reshape(*wo.shape[:-1], -1)

    return projected


def hemispherical_reflectance_states(model, wi, states=None, *, rtol=1e-3, atol=1e-10, max_evaluations=2_000_000):
    """Directional-hemispherical reflectance of ``model`` at incidence ``wi`` for many
    states at once (the quadrature of :func:`hemispherical_reflectance`, one cell grid for
    every state, refined where the summed error over the states is largest).

    Parameters
    ----------
    model : BRDFModel
    wi : array_like, shape (3,)
        Direction to the source in the surface frame (z > 0).
    states : array_like, shape (S,) or (S, 2), optional
        States of a dynamic model (None: a static model, S = 1).
    rtol, atol : float
        Stop when every state's error estimate is below ``max(rtol * value, atol)``.
    max_evaluations : int
        Budget of integrand evaluations (points x states).

    Returns
    -------
    value, error_estimate : ndarray, shape (S,)
        Dimensionless reflectance (delta lobes included) and its absolute error estimate.
    converged : bool
    """
    wi = directions("wi", wi)
    if wi.shape != (3,) or not wi[2] > 0:
        raise ValueError(f"wi={wi.tolist()!r}: expected one direction above the surface (z > 0), shape (3,)")
    states = None if states is None else np.asarray(states, float)
    sts = [None] if states is None else list(states)
    spec = np.array([float(model.specular_reflectance(wi, state=s if s is None or np.ndim(s) == 0 else np.asarray(s)))
                     for s in sts])
    projected = _projected_states(model, wi, states)
    per_cell = 5 * _NGL * _NGL * len(sts)

    def estimate(cells):
        coarse = _cell_integrals_with(projected, wi, cells)
        fine = _cell_integrals_with(projected, wi, _split(cells)).reshape(4, cells.shape[0], -1).sum(axis=0)
        return fine, np.abs(fine - coarse)

    cells = _initial_cells(wi)
    vals, errs = estimate(cells)
    evals = per_cell * cells.shape[0]
    while True:
        total, err = vals.sum(axis=0) + spec, errs.sum(axis=0)
        if np.all(err <= np.maximum(rtol * np.abs(total), atol)):
            return total, err, True
        score = (errs / np.maximum(np.abs(total), atol)).sum(axis=1)
        order = np.argsort(score)[::-1]
        k = min(max(int(np.searchsorted(np.cumsum(score[order]), 0.5 * score.sum())) + 1, 1), order.size)
        if evals + 4 * k * per_cell > max_evaluations:
            return total, err, False
        keep = np.ones(cells.shape[0], bool)
        keep[order[:k]] = False
        children = _split(cells[order[:k]])
        cv, ce = estimate(children)
        evals += per_cell * children.shape[0]
        cells, vals, errs = np.concatenate([cells[keep], children]), np.concatenate([vals[keep], cv]), np.concatenate([errs[keep], ce])


@dataclass(frozen=True)
class EnvelopeReport:
    """How well an envelope bounds a model over sampled direction pairs and states.

    ``fraction_bounded`` must be 1.0 for a conservative envelope; the ratios (envelope /
    model, over pairs where the model is > 0) say how much it over-predicts.
    """

    fraction_bounded: float
    median_ratio: float
    max_ratio: float
    min_ratio: float
    pairs: int
    states: int

    def __str__(self):
        return (
            f"bounded {100 * self.fraction_bounded:.4f} % of {self.pairs} pairs x {self.states} states; "
            f"over-prediction median {self.median_ratio:.3g}x, max {self.max_ratio:.3g}x"
        )


def envelope_report(envelope, model, wi, wo, states=None, *, rtol=1e-12) -> EnvelopeReport:
    """Check that ``envelope`` bounds ``model`` at every sampled pair and state.

    Parameters
    ----------
    envelope : BRDFModel
        The static bound (typically :class:`~brdfmodels.Envelope`).
    model : BRDFModel
        The model it must bound.
    wi, wo : array_like, shape (N, 3)
        Sampled direction pairs.
    states : array_like, optional
        States to check (default for dynamic models: the nodes, the midpoints between them
        and 64 evenly spread states).
    rtol : float
        Relative slack for rounding.
    """
    env = envelope.evaluate(wi, wo)
    if model.is_dynamic:
        if states is None and model.state_dim == 2:
            # bilinear cells: their corners (the nodes) and centres
            g = model.state_nodes()
            axes = [np.unique(g[:, d]) for d in range(2)]
            states = np.concatenate([g, grid_points([0.5 * (a[1:] + a[:-1]) if a.size > 1 else a for a in axes])])
        elif states is None:
            lo, hi = model.state_range
            nodes = model.state_nodes()
            nodes = nodes[(nodes >= lo) & (nodes <= hi)]
            mids = 0.5 * (nodes[1:] + nodes[:-1])
            states = np.unique(np.concatenate([nodes, mids, np.linspace(lo, hi, 64)]))
        states = np.asarray(states, dtype=float)
        states = states if model.state_dim == 2 else np.atleast_1d(states)
        vals = np.stack([model.evaluate(wi, wo, state=s) for s in states], axis=-1)
    else:
        states = np.array([np.nan])
        vals = model.evaluate(wi, wo)[..., None]
    env = np.broadcast_to(np.asarray(env)[..., None], vals.shape)
    bounded = env >= vals * (1.0 - rtol)
    pos = vals > 0
    ratio = env[pos] / vals[pos]
    return EnvelopeReport(
        fraction_bounded=float(bounded.mean()),
        median_ratio=float(np.median(ratio)) if ratio.size else float("nan"),
        max_ratio=float(ratio.max()) if ratio.size else float("nan"),
        min_ratio=float(ratio.min()) if ratio.size else float("nan"),
        pairs=int(np.prod(vals.shape[:-1])),
        states=int(len(states)),
    )
