"""Keep-out zones: the hazard lobe (NOHD per reflection direction) and its ground footprint.

For a spot of power P and a direction w above it, the far-field radiant intensity is
``I(w) = f_r(wi, w) cos(theta_r) P K`` [W/sr] and the hazard range is the R solving
``I e^{-mu R} / R^2 = MPE`` (:func:`hazard.nohd.range_from_intensity`). The lobe is
``R(w)`` over the hemisphere; its volume is ``integral R^3 / 3 d omega``. The dynamic
lobe uses, per direction, the maximum intensity over the history's states.

The direction grid (``grid_deg``) is refined adaptively: a cell whose 2x2 Gauss values
of R^3 differ by more than ``rtol``, or that contains the mirror or retro direction, is
split in four, up to ``refine_levels`` times. The volume error estimate is the
difference between the 2x2 Gauss rule and the midpoint rule on the final cells.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

import brdfmodels
from brdfmodels.parallel import block_rows, map_blocks

from .engine import Spot, projected_brdf, spot_directions, spot_irradiance, specular_irradiance
from .nohd import range_from_intensity

__all__ = ["Lobe", "hazard_lobe", "ground_footprint", "Footprint"]

_G = 0.5 / math.sqrt(3.0)  # 2-point Gauss abscissae at 0.5 +- _G on [0, 1]


@dataclass
class Lobe:
    """Hazard lobe of one spot: ranges on the final cells of the direction grid."""

    theta_rad: np.ndarray
    phi_rad: np.ndarray
    solid_angle_sr: np.ndarray
    range_m: np.ndarray
    volume_m3: float
    volume_error_m3: float
    max_range_m: float
    max_direction_local: np.ndarray
    max_direction_world: np.ndarray
    evaluations: int
    cells: int

    def summary(self) -> dict:
        return {
            "max_nohd_m": self.max_range_m,
            "max_direction": self.max_direction_world.tolist(),
            "volume_m3": self.volume_m3,
            "volume_error_m3": self.volume_error_m3,
            "cells": self.cells,
            "evaluations": self.evaluations,
        }


def _range_fn(spot: Spot, mpe_w_m2, mu, gain, states):
    model = spot.material
    wi = spot_directions(spot)
    power = spot.total_power_w * gain

    def fn(wo):
        f = projected_brdf(model, wi[None, :], wo, states, reduce="max")  # the lobe: max over the states
        return range_from_intensity(f * power, mpe_w_m2, mu)

    return fn


def _cell_points(cells):
    """2x2 Gauss points in (cos theta, phi) of each cell (n, 4): returns (n, 4, 3) and weights."""
    c0, c1 = np.cos(cells[:, 0]), np.cos(cells[:, 1])
    p0, p1 = cells[:, 2], cells[:, 3]
    pts = []
    for a in (0.5 - _G, 0.5 + _G):
        for b in (0.5 - _G, 0.5 + _G):
            c = c0 + a * (c1 - c0)
            p = p0 + b * (p1 - p0)
            s = np.sqrt(np.maximum(1 - c * c, 0))
            pts.append(np.stack([s * np.cos(p), s * np.sin(p), c], -1))
    return np.stack(pts, 1)


def _contains(cells, theta, phi):
    return (cells[:, 0] <= theta) & (theta <= cells[:, 1]) & (cells[:, 2] <= phi) & (phi <= cells[:, 3])


def hazard_lobe(spot: Spot, mpe_w_m2, attenuation_per_m=0.0, *, gain=1.0, states=None, grid_deg=2.0, refine_levels=3, rtol=0.05) -> Lobe:
    """NOHD per reflection direction over the hemisphere above a spot.

    Parameters
    ----------
    spot : Spot
    mpe_w_m2 : float
        MPE [W/m^2] for the exposure duration.
    attenuation_per_m : float
    gain : float
        Optical gain of the viewer (1: naked eye).
    states : array_like, optional
        States of the history: the lobe is the per-direction maximum over them.
    grid_deg : float
        Initial direction-grid resolution [deg].
    refine_levels : int
        Maximum number of 4-way splits of a cell.
    rtol : float
        Split a cell when its Gauss values of R^3 differ by more than this fraction.
    """
    fn = _range_fn(spot, mpe_w_m2, attenuation_per_m, gain, states)
    th = np.linspace(0, math.pi / 2, max(2, int(round(90 / grid_deg))) + 1)
    ph = np.linspace(-math.pi, math.pi, max(4, int(round(360 / grid_deg))) + 1)
    tt, pp = np.meshgrid(np.arange(len(th) - 1), np.arange(len(ph) - 1), indexing="ij")
    cells = np.stack([th[tt.ravel()], th[tt.ravel() + 1], ph[pp.ravel()], ph[pp.ravel() + 1]], 1)
    wi = spot_directions(spot)
    mirror_t, mirror_p = brdfmodels.vector_to_spherical(wi * np.array([-1, -1, 1]))
    retro_t, retro_p = brdfmodels.vector_to_spherical(wi)
    evals = 0
    done_cells, done_vals = [], []
    best_r, best_dir = 0.0, np.array([0.0, 0.0, 1.0])
    for level in range(refine_levels + 1):
        pts = _cell_points(cells)
        r = fn(pts.reshape(-1, 3)).reshape(-1, 4)
        evals += r.size
        k = int(np.argmax(r))
        if r.flat[k] > best_r:
            best_r, best_dir = float(r.flat[k]), pts.reshape(-1, 3)[k]
        r3 = r**3
        spread = (r3.max(1) - r3.min(1)) / np.maximum(r3.max(1), 1e-300)
        split = (spread > rtol) | _contains(cells, mirror_t, mirror_p) | _contains(cells, retro_t, retro_p)
        split &= r3.max(1) > 0
        if level == refine_levels:
            split[:] = False
        done_cells.append(cells[~split])
        done_vals.append(r[~split])
        if not np.any(split):
            break
        c = cells[split]
        tm, pm = 0.5 * (c[:, 0] + c[:, 1]), 0.5 * (c[:, 2] + c[:, 3])
        cells = np.concatenate([
            np.stack([c[:, 0], tm, c[:, 2], pm], 1), np.stack([tm, c[:, 1], c[:, 2], pm], 1),
            np.stack([c[:, 0], tm, pm, c[:, 3]], 1), np.stack([tm, c[:, 1], pm, c[:, 3]], 1),
        ])
    cells = np.concatenate(done_cells)
    vals = np.concatenate(done_vals)
    omega = (np.cos(cells[:, 0]) - np.cos(cells[:, 1])) * (cells[:, 3] - cells[:, 2])
    # exact peak directions: the mirror and retro directions (finite lobes peak there)
    special = np.stack([wi * np.array([-1, -1, 1]), wi])
    rs = fn(special)
    evals += 2
    if rs.max() > best_r:
        best_r, best_dir = float(rs.max()), special[int(np.argmax(rs))]
    centre_t, centre_p = 0.5 * (cells[:, 0] + cells[:, 1]), 0.5 * (cells[:, 2] + cells[:, 3])
    centre = brdfmodels.spherical_to_vector(centre_t, centre_p)
    r_mid = fn(centre)
    evals += len(centre)
    vol_gauss = float((omega * (vals**3).mean(1)).sum() / 3.0)
    vol_mid = float((omega * r_mid**3).sum() / 3.0)
    return Lobe(
        theta_rad=centre_t,
        phi_rad=centre_p,
        solid_angle_sr=omega,
        range_m=vals.mean(1),
        volume_m3=vol_gauss,
        volume_error_m3=abs(vol_gauss - vol_mid),
        max_range_m=best_r,
        max_direction_local=best_dir,
        max_direction_world=best_dir @ spot.mean_frame,
        evaluations=evals,
        cells=len(cells),
    )


@dataclass
class Footprint:
    """Where the reflected irradiance at eye height reaches the MPE on the terrain grid."""

    mask: np.ndarray  # (ny, nx) over the terrain heightfield
    area_m2: float
    eye_height_m: float


def ground_footprint(spots, beam, terrain, ray_scene, mpe_w_m2, attenuation_per_m, eye_height_m, *, states_by_target=None, max_range_m=np.inf) -> Footprint:
    """Hazardous ground area: terrain nodes whose eye-height point receives at least the
    MPE at some time, the irradiance summed over every spot (BRDF and specular lobes, each
    with its own line of sight) as in the observer map, max over the states in time
    (``states_by_target``: target index -> states on one common time grid, absent for
    static materials).

    ``max_range_m`` is how far one spot alone can exceed the MPE: with one spot only the
    nodes within it are evaluated. With several spots their sum can exceed the MPE where
    none does alone, so every node is evaluated. Rays are traced only where the
    unoccluded sum exceeds the MPE (occlusion can only lower it). Nodes go in blocks
    (bounded memory, threads).
    """
    states_by_target = states_by_target or {}
    ny, nx = terrain.heights.shape
    xs = terrain.x0 + terrain.dx * np.arange(nx)
    ys = terrain.y0 + terrain.dx * np.arange(ny)
    mask = np.zeros((ny, nx), bool)
    if not spots:
        return Footprint(mask, 0.0, eye_height_m)
    ix, iy = np.arange(nx), np.arange(ny)
    if len(spots) == 1 and np.isfinite(max_range_m):
        c = spots[0].centroid
        ix = np.flatnonzero(np.abs(xs - c[0]) <= max_range_m)
        iy = np.flatnonzero(np.abs(ys - c[1]) <= max_range_m)
    if not len(ix) or not len(iy):
        return Footprint(mask, 0.0, eye_height_m)
    gx, gy = np.meshgrid(xs[ix], ys[iy])
    pts = np.stack([gx.ravel(), gy.ravel(), terrain.heights[np.ix_(iy, ix)].ravel() + eye_height_m], 1)
    hot = np.zeros(len(pts), bool)
    n_t = max([len(v) for v in states_by_target.values()] + [1])

    def block(a, b):
        p = pts[a:b]
        gain = np.ones(b - a)
        parts = []
        for spot in spots:
            states = states_by_target.get(spot.target.index)
            e, _ = spot_irradiance(spot, p, gain, attenuation_per_m, states)
            if spot.material.has_specular:
                e = e + specular_irradiance(spot, p, gain, attenuation_per_m, beam, states)
            parts.append(e if e.ndim == 2 else e[:, None])
        over = sum(parts).max(axis=1) >= mpe_w_m2  # as for observers: ratio >= 1
        if ray_scene is not None and over.any():
            for spot, e in zip(spots, parts):
                idx = np.flatnonzero(over & (e.max(axis=1) > 0))
                if len(idx):
                    start = ray_scene.off_surface(spot.centroid, spot.mean_frame[2])
                    e[idx[ray_scene.occluded(np.broadcast_to(start, (len(idx), 3)), p[idx])]] = 0.0
            rows = np.flatnonzero(over)
            over[rows] = sum(e[rows] for e in parts).max(axis=1) >= mpe_w_m2
        hot[a:b] = over

    map_blocks(block, len(pts), block_rows(n_t * len(spots), max(1, len(pts))))
    mask[np.ix_(iy, ix)] = hot.reshape(len(iy), len(ix))
    return Footprint(mask, float(mask.sum() * terrain.dx**2), eye_height_m)
