"""Keep-out zones: the hazard lobe (NOHD per reflection direction) and its ground footprint.

For a spot of power P and a direction w above it, the far-field radiant intensity is
``I(w) = f_r(wi, w) cos(theta_r) P K`` [W/sr] and the hazard range is the R solving
``I e^{-mu R} / R^2 = MPE`` (:func:`hazard.physics.nohd.range_from_intensity`). The lobe is
``R(w)`` over the hemisphere; its volume is ``integral R^3 / 3 d omega``. The dynamic
lobe uses, per direction, the maximum intensity over the history's states.

Near the spot (a direction whose point-form range is within ``FAR_FIELD_SPOT_SIZES``
spot sizes) ``R(w)`` is the farthest root of the near-field integral over the spot
instead (:mod:`hazard.physics.near_field_lobe`: a spot stretched by grazing incidence has a lobe
elongated along it), never below the point form.

The direction grid (``grid_deg``) is refined only where the volume's error estimate
asks: cells with the largest estimates, and those holding the mirror or retro
direction, are split in four, up to ``refine_levels`` times, until the estimated
volume error is within ``rtol`` (default ``VOLUME_RTOL``) of the volume. The maximum
range does not depend on the grid: it is polished by a local search from the best
evaluated directions.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

import brdfmodels
from brdfmodels.parallel import block_rows, map_blocks

from hazard.physics.engine import Spot, path_states, projected_brdf, brdf_bound, frame_groups, point_form, spot_directions, spot_irradiance, spot_line_of_sight, specular_irradiance
from hazard.physics.near_field_lobe import near_lobe_fn
from hazard.physics.nohd import range_from_intensity
from hazard.progress import terminal_bar

__all__ = ["Lobe", "hazard_lobe", "ground_footprint", "Footprint"]

_G = 0.5 / math.sqrt(3.0)  # 2-point Gauss abscissae at 0.5 +- _G on [0, 1]
VOLUME_RTOL = 1e-3  # default target of the estimated volume error, relative to the volume
POLISH_SEEDS = 4  # best grid points kept as seeds of the polish (besides the mirror and retro directions)
POLISH_FRACTION = 0.9  # seeds below this fraction of the best value are not polished
POLISH_RTOL = 1e-12  # the polish stops when its quadratic model predicts less gain than this, relative to the range
POLISH_MIN_SHRINK = 64  # ... once its stencil is this many times smaller than at the start
POLISH_TOL_RAD = 1e-7  # ... or when its step is below this angle [rad]


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
    normals: int = 1  # surface normals each direction's range is the max over (a slumping spot's union)
    peak_intensity_w_sr: float | None = None  # I = f_r cos(theta_r) P toward max_direction (None: a slumping spot's union)
    spot_power_w: float | None = None  # P: the spot's power times the viewer's gain [W]
    near_field: dict | None = None  # hazard.physics.near_field_lobe.NearLobeFn.info: the directions integrated near the spot


    def summary(self) -> dict:
        return {
            "max_nohd_m": self.max_range_m, "peak_intensity_w_sr": self.peak_intensity_w_sr, "power_w": self.spot_power_w,
            "max_direction": self.max_direction_world.tolist(),
            "volume_m3": self.volume_m3,
            "volume_error_m3": self.volume_error_m3,
            "cells": self.cells,
            "evaluations": self.evaluations,
            "near_field": self.near_field,
        }


def nohd_range_fn(spot: Spot, mpe_w_m2, mu, gain, states, slump_step_rad=None, near_field=True):
    """``fn(wo (N, 3)) -> NOHD [m]`` in the spot's mean frame: the max over the history's
    path of states (:func:`hazard.physics.engine.path_states`) and, for a slumping spot over the
    whole history, over the normals the molten surface may take
    (:func:`hazard.physics.slump.union_range_fn`); ``near_field=False``: the point form
    alone (no :mod:`hazard.physics.near_field_lobe`)."""
    model = spot.material
    power = spot.total_power_w * gain
    if states is not None and spot.slump is not None and spot.slump.moves and len(states) == len(spot.slump.tilt_rad):
        from hazard.physics.slump import union_range_fn

        def range_of(wi, wo, st):
            return range_from_intensity(projected_brdf(model, wi, wo, st, reduce="path-max") * power, mpe_w_m2, mu)

        return union_range_fn(spot, states, range_of, lambda s: path_states(model, s), slump_step_rad)
    wi = spot_directions(spot)
    st = None if states is None else path_states(model, states)
    groups = frame_groups(spot)  # once: the lobe asks for the intensity many times

    def intensity(wo):
        """Radiant intensity I = f_r cos(theta_r) P [W/sr] toward wo (the max over the history);
        a spot of several frames (curved) sums each frame's (:func:`point_form`)."""
        if groups is not None:
            wo = np.asarray(wo, float)
            return point_form(spot, wo @ spot.mean_frame, np.full(len(wo), power), st, reduce="path-max", groups=groups)[0]
        return projected_brdf(model, wi[None, :], wo, st, reduce="path-max") * power

    def fn(wo):
        return range_from_intensity(intensity(wo), mpe_w_m2, mu)

    fn.intensity = intensity
    if not near_field:
        return fn
    lobe = near_lobe_fn(spot, fn, mpe_w_m2, mu, gain, st)
    if gain > 1.0 and lobe is not fn:  # an aid (K >= 1) sees at least what the naked eye sees, per direction
        lobe.floor = nohd_range_fn(spot, mpe_w_m2, mu, 1.0, states)
    return lobe


def _grid_cells(grid_deg):
    """Cells (n, 4) = (theta0, theta1, phi0, phi1) [rad] of the initial direction grid."""
    th = np.linspace(0, math.pi / 2, max(2, int(round(90 / grid_deg))) + 1)
    ph = np.linspace(-math.pi, math.pi, max(4, int(round(360 / grid_deg))) + 1)
    tt, pp = np.meshgrid(np.arange(len(th) - 1), np.arange(len(ph) - 1), indexing="ij")
    return np.stack([th[tt.ravel()], th[tt.ravel() + 1], ph[pp.ravel()], ph[pp.ravel() + 1]], 1)


def _solid_angle(cells):
    """Solid angle [sr] of each cell."""
    return (np.cos(cells[:, 0]) - np.cos(cells[:, 1])) * (cells[:, 3] - cells[:, 2])


def _centres(cells):
    """Midpoint of each cell in (cos theta, phi): (theta [rad], phi [rad])."""
    return np.arccos(0.5 * (np.cos(cells[:, 0]) + np.cos(cells[:, 1]))), 0.5 * (cells[:, 2] + cells[:, 3])


def _cell_points(cells):
    """2x2 Gauss points in (cos theta, phi) of each cell (n, 4): returns (n, 4, 3)."""
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


def _evaluate(fn, cells):
    """Ranges [m] at the 2x2 Gauss points (n, 4) and the midpoint (n,) of each cell, in
    one call; also returns the Gauss points (n, 4, 3)."""
    n = len(cells)
    pts = _cell_points(cells)
    mid = brdfmodels.spherical_to_vector(*_centres(cells))
    r = fn(np.concatenate([pts.reshape(-1, 3), mid.reshape(-1, 3)]))
    return r[: 4 * n].reshape(n, 4), r[4 * n:], pts


def _cell_volumes(cells, r, r_mid):
    """Volume [m^3] of each cell by the 2x2 Gauss rule, and its error estimate [m^3]:
    the difference from the midpoint rule (second order, so it bounds the Gauss rule's
    error on resolved cells)."""
    omega = _solid_angle(cells)
    vol = omega * (r**3).mean(1) / 3.0
    return vol, np.abs(vol - omega * r_mid**3 / 3.0)


def _richardson(vol, parent_vol):
    """Error estimate [m^3] of cells just made by :func:`_quarter` from parents of volume
    ``parent_vol`` (n,): the difference between a parent's Gauss volume and the sum of
    its four children's, shared equally among them (an estimate of the parent's error,
    so a conservative one of the children's)."""
    n = len(parent_vol)
    diff = np.abs(parent_vol - vol.reshape(4, n).sum(0))
    return np.tile(diff / 4.0, 4)


def _to_split(err, allowance_m3, forced):
    """Cells to split: the fewest, largest-error cells such that the errors of the cells
    kept sum to at most ``allowance_m3``, plus the ``forced`` ones."""
    order = np.argsort(err)
    split = np.ones(len(err), bool)
    split[order[np.cumsum(err[order]) <= allowance_m3]] = False
    return (split & (err > 0)) | forced


def _quarter(c):
    """Each cell (n, 4) split in four at its (theta, phi) midpoint: (4n, 4)."""
    tm, pm = 0.5 * (c[:, 0] + c[:, 1]), 0.5 * (c[:, 2] + c[:, 3])
    return np.concatenate([
        np.stack([c[:, 0], tm, c[:, 2], pm], 1), np.stack([tm, c[:, 1], c[:, 2], pm], 1),
        np.stack([c[:, 0], tm, pm, c[:, 3]], 1), np.stack([tm, c[:, 1], pm, c[:, 3]], 1),
    ])


def _top_points(r, pts, k):
    """The ``k`` largest values of ``r`` (any shape) and their directions ``pts`` (..., 3)."""
    flat = r.ravel()
    idx = np.argpartition(flat, -k)[-k:] if flat.size > k else np.arange(flat.size)
    return flat[idx], pts.reshape(-1, 3)[idx]


_STENCIL = np.array([[1, 0], [-1, 0], [0, 1], [0, -1], [1, 1], [1, -1], [-1, 1], [-1, -1]], float)


def _on_sphere(w, h, ab):
    """Directions ``w + h (a e1 + b e2)`` on the upper hemisphere, (e1, e2) a tangent
    basis at each unit vector w (n, 3), for offsets ``ab`` (n, m, 2) in units of the
    step ``h`` (n,) [rad]: returns (n, m, 3)."""
    ref = np.where(np.abs(w[:, 2:3]) < 0.9, [[0.0, 0.0, 1.0]], [[1.0, 0.0, 0.0]])
    e1 = np.cross(w, ref)
    e1 /= np.linalg.norm(e1, axis=1, keepdims=True)
    e2 = np.cross(w, e1)
    d = w[:, None] + h[:, None, None] * (ab[..., :1] * e1[:, None] + ab[..., 1:] * e2[:, None])
    d[..., 2] = np.maximum(d[..., 2], 0.0)
    return d / np.linalg.norm(d, axis=2, keepdims=True)


def _model_step(f0, f):
    """Maximum of the quadratic through a 3x3 stencil (centre ``f0`` (n,), the others
    ``f`` (n, 8) in ``_STENCIL`` order), in units of the stencil's step, at most 2 long,
    and the gain the quadratic predicts there [m]; where the quadratic is not concave,
    the best stencil point and an infinite gain (not converged)."""
    g = np.stack([f[:, 0] - f[:, 1], f[:, 2] - f[:, 3]], 1) / 2.0
    hxx, hyy = f[:, 0] + f[:, 1] - 2 * f0, f[:, 2] + f[:, 3] - 2 * f0
    hxy = (f[:, 4] - f[:, 5] - f[:, 6] + f[:, 7]) / 4.0
    det = hxx * hyy - hxy * hxy
    concave = (hxx < 0) & (det > 0)
    safe = np.where(concave, det, 1.0)
    s = -np.stack([hyy * g[:, 0] - hxy * g[:, 1], hxx * g[:, 1] - hxy * g[:, 0]], 1) / safe[:, None]
    s *= np.minimum(1.0, 2.0 / np.maximum(np.linalg.norm(s, axis=1), 1e-300))[:, None]
    gain = (g * s).sum(1) + 0.5 * (hxx * s[:, 0] ** 2 + 2 * hxy * s[:, 0] * s[:, 1] + hyy * s[:, 1] ** 2)
    return np.where(concave[:, None], s, _STENCIL[f.argmax(1)]), np.where(concave, gain, np.inf)


def _polish_max(fn, seeds, step_rad, max_iterations=60):
    """Local maximum of the range [m] from each seed direction (k, 3): a 3x3 stencil in
    the tangent plane and a step to the maximum of its quadratic; the stencil shrinks by
    4 once that maximum lies inside it (or nothing improved). A seed is done when the
    stencil has shrunk ``POLISH_MIN_SHRINK``-fold (so finer features than the grid are
    looked at) and the quadratic predicts a gain below ``POLISH_RTOL`` of the range, or
    when the stencil is below ``POLISH_TOL_RAD``. Returns the best range, its direction and the
    evaluations; every value it returns was evaluated, so it can only raise a grid
    maximum towards the true one."""
    w = np.array(seeds, float)
    r = fn(w)
    evals = len(w)
    h = np.full(len(w), float(step_rad))
    for _ in range(max_iterations):
        idx = np.flatnonzero(h > POLISH_TOL_RAD)
        if not len(idx):
            break
        st = _on_sphere(w[idx], h[idx], np.broadcast_to(_STENCIL, (len(idx), 8, 2)))
        f = fn(st.reshape(-1, 3)).reshape(-1, 8)
        s, gain = _model_step(r[idx], f)
        cand = _on_sphere(w[idx], h[idx], s[:, None, :])
        vals = np.concatenate([f, fn(cand[:, 0])[:, None]], 1)
        evals += vals.size
        pts = np.concatenate([st, cand], 1)
        j = vals.argmax(1)
        best = vals[np.arange(len(j)), j]
        better = best > r[idx]
        w[idx[better]], r[idx[better]] = pts[better, j[better]], best[better]
        inside = np.linalg.norm(s, axis=1) <= 1.0
        h[idx] *= np.where(better & ~inside, 1.0, 0.25)
        done = inside & (gain <= POLISH_RTOL * np.maximum(r[idx], 1e-300)) & (h[idx] <= step_rad / POLISH_MIN_SHRINK)
        h[idx[done]] = 0.0  # converged
    k = int(np.argmax(r))
    return float(r[k]), w[k], evals


def _refine(fn, grid_deg, refine_levels, rtol, special, r_special, level_done=None):
    """Adaptive cells of the lobe (see :func:`hazard_lobe`): returns the final cells,
    their Gauss ranges (n, 4) [m], volumes and error estimates [m^3], the best
    evaluated points (seeds of the polish: values [m], directions) and the evaluations.
    ``level_done()``, if given, is called after each level (progress)."""
    sp_t, sp_p = brdfmodels.vector_to_spherical(special)
    cells, kept, evals, parent_vol = _grid_cells(grid_deg), [], 0, None
    seeds_r, seeds_w = r_special, special
    vol_kept = err_kept = 0.0
    for level in range(refine_levels + 1):
        r, r_mid, pts = _evaluate(fn, cells)
        evals += 5 * len(cells)
        seeds_r, seeds_w = _top_points(np.concatenate([seeds_r, r.ravel()]), np.concatenate([seeds_w, pts.reshape(-1, 3)]), POLISH_SEEDS)
        vol, err = _cell_volumes(cells, r, r_mid)
        if parent_vol is not None:
            err = _richardson(vol, parent_vol)
        split = np.zeros(len(cells), bool)
        if level < refine_levels:
            forced = np.zeros(len(cells), bool)
            for t, p, rs in zip(sp_t, sp_p, r_special):
                forced |= _contains(cells, t, p) & ((r.max(1) > 0) | (rs > 0))
            split = _to_split(err, 0.5 * (rtol * (vol_kept + vol.sum()) - err_kept), forced)
        kept.append((cells[~split], r[~split], vol[~split], err[~split]))
        vol_kept += float(vol[~split].sum())
        err_kept += float(err[~split].sum())
        if level_done is not None:
            level_done()
        if not split.any():
            break
        cells, parent_vol = _quarter(cells[split]), vol[split]
    out = [np.concatenate([k[i] for k in kept]) for i in range(4)]
    return (*out, seeds_r, seeds_w, evals)


def hazard_lobe(spot: Spot, mpe_w_m2, attenuation_per_m=0.0, *, gain=1.0, states=None, grid_deg=2.0, refine_levels=3,
                rtol=None, near_field=True) -> Lobe:
    """NOHD per reflection direction over the hemisphere above a spot.

    Parameters
    ----------
    spot : Spot
    mpe_w_m2 : float
        MPE [W/m^2] for the exposure duration.
    attenuation_per_m : float
        Atmospheric attenuation coefficient [1/m].
    gain : float
        Optical gain of the viewer (1: naked eye).
    states : array_like, optional
        States of the history: the lobe is the per-direction maximum over them.
    grid_deg : float
        Initial direction-grid resolution [deg].
    refine_levels : int
        Maximum number of 4-way splits of a cell.
    rtol : float, optional
        Target of the estimated volume error, relative to the volume (default: the
        module's ``VOLUME_RTOL`` when called, chosen from the table of
        ``tests/bench/bench_keepout.py``). At each level the
        cells with the largest error estimates are split until the estimates of the
        cells kept take at most half of the budget left (``rtol`` x volume minus the
        estimates already kept). The cells holding the mirror or retro direction are
        always split (a lobe narrower than a cell still gets its volume).
    near_field : bool
        False: the point form alone (its maximum range is the lobe's wherever it reaches
        :func:`hazard.physics.near_field_lobe.near_field_reach_m`).

    Notes
    -----
    Each cell's volume is the 2x2 Gauss rule in (cos theta, phi). Its error estimate is
    the difference from the midpoint rule on the initial grid (pessimistic where the
    lobe is smooth) and, on a split cell's children, the difference between the
    parent's volume and the children's sum (shared among them). ``volume_error_m3`` is
    the sum of the final cells' estimates (absolute values: no cancellation).

    The maximum range is the largest of every evaluated direction, the exact mirror and
    retro directions, and a local search (:func:`_polish_max`) from the best of them, so
    it does not depend on the grid down to ``POLISH_TOL_RAD``.
    """
    rtol = VOLUME_RTOL if rtol is None else float(rtol)
    fn = nohd_range_fn(spot, mpe_w_m2, attenuation_per_m, gain, states, near_field=near_field)
    wi = spot_directions(spot)
    special = np.stack([wi * np.array([-1, -1, 1]), wi])  # mirror, retro
    extra = getattr(fn, "special", None)  # a slumping spot: the mirror directions of its tilted normals
    if extra is not None and len(extra):
        special = np.concatenate([special, extra])
    r_special = fn(special)
    what = f"keep-out lobe {spot.target.name}" + (" (dynamic)" if states is not None and np.size(states) > 1 else "")
    with terminal_bar(refine_levels + 1, what, unit="level") as bar:  # terminals only
        cells, r, vol, err, seeds_r, seeds_w, evals = _refine(fn, grid_deg, refine_levels, rtol, special, r_special, bar.update)
    best_r, best_dir, n_polish = 0.0, np.array([0.0, 0.0, 1.0]), 0
    seeds_r, seeds_w = np.concatenate([r_special, seeds_r]), np.concatenate([special, seeds_w])
    if seeds_r.max() > 0:  # polish the seeds within POLISH_FRACTION of the best value
        near = seeds_r >= POLISH_FRACTION * seeds_r.max()
        best_r, best_dir, n_polish = _polish_max(fn, seeds_w[near], math.radians(grid_deg) / 4)
    centre_t, centre_p = _centres(cells)
    peak_i = getattr(fn, "intensity", None) or getattr(getattr(fn, "base", None), "intensity", None)  # a NearLobeFn wraps it
    peak_i = None if peak_i is None or best_r <= 0 else float(peak_i(best_dir[None, :])[0])
    return Lobe(
        theta_rad=centre_t,
        phi_rad=centre_p,
        solid_angle_sr=_solid_angle(cells),
        range_m=r.mean(1),
        volume_m3=float(vol.sum()),
        volume_error_m3=float(err.sum()),
        max_range_m=best_r,
        max_direction_local=best_dir,
        max_direction_world=best_dir @ spot.mean_frame,
        evaluations=evals + n_polish + 2,
        cells=len(cells),
        normals=getattr(fn, "samples", 1),
        peak_intensity_w_sr=peak_i,
        spot_power_w=float(spot.total_power_w * gain),
        near_field=getattr(fn, "info", None),
    )


@dataclass
class Footprint:
    """Where the reflected irradiance at eye height reaches the MPE on the terrain grid.

    ``ratio``: the peak reflected hazard ratio (irradiance / MPE) at each node's eye-height
    point; with the line of sight traced where the unoccluded sum reaches the MPE, the
    unoccluded sum elsewhere (an upper bound, below 1); NaN where not evaluated (beyond the
    longest NOHD of a single spot: below 1). ``direct_ratio``: the laser's own beam there
    (nominal aim, naked eye, line of sight traced), when computed."""

    mask: np.ndarray  # (ny, nx) over the terrain heightfield
    area_m2: float
    eye_height_m: float
    ratio: np.ndarray | None = None
    direct_ratio: np.ndarray | None = None


def _spot_lobes(spot, p, gain, mu, states, bound=False):
    """A spot's BRDF and mirror lobes at points ``p`` (rows x T each; the mirror None
    without one), every line of sight clear; ``bound``: the BRDF lobe an upper bound near
    the spot where the integral over its triangles would be needed (see
    :func:`hazard.physics.engine.spot_irradiance`)."""
    e, _ = spot_irradiance(spot, p, gain, mu, states, bound=bound)
    m = specular_irradiance(spot, p, gain, mu, None, states) if spot.material.has_specular else None
    return (e if e.ndim == 2 else e[:, None]), (None if m is None else m if m.ndim == 2 else m[:, None])


def _clip_to_sight(spot, lobe_pair, over, p, gain, mu, states, ray_scene):
    """Lines of sight, in place, on the rows ``over`` the spot reaches: the BRDF lobe takes
    the spot's, the mirror lobe each point's own from its reflection point."""
    e, m = lobe_pair
    idx = np.flatnonzero(over & ((e if m is None else e + m).max(axis=1) > 0))
    if not len(idx):
        return
    e[idx] *= spot_line_of_sight(ray_scene, spot, p[idx])[0][:, None]
    if m is not None:
        mi = specular_irradiance(spot, p[idx], gain[idx], mu, None, states, ray_scene=ray_scene)
        m[idx] = mi if mi.ndim == 2 else mi[:, None]


def _exact_where(parts, top, spots, p, gain, mu, states_by_target, mpe_w_m2):
    """Rows whose summed upper bound ``top`` reaches the MPE: the bounded spots' BRDF
    lobes integrated exactly there, in place, and ``top`` updated."""
    rows = np.flatnonzero(top >= mpe_w_m2)
    redo = [i for i, spot in enumerate(spots) if spot.patches is not None and brdf_bound(spot.material) is not None]
    if not len(rows) or not redo:
        return
    for i in redo:
        e, _ = spot_irradiance(spots[i], p[rows], gain[rows], mu, states_by_target.get(spots[i].target.index))
        parts[i][0][rows] = e if e.ndim == 2 else e[:, None]
    top[rows] = sum(e[rows] if m is None else e[rows] + m[rows] for e, m in parts).max(axis=1)


def ground_footprint(spots, beam, terrain, ray_scene, mpe_w_m2, attenuation_per_m, eye_height_m, *, states_by_target=None,
                     max_range_m=np.inf, bound_below_mpe=True) -> Footprint:
    """Hazardous ground area: terrain nodes whose eye-height point receives at least the
    MPE at some time, the irradiance summed over every spot (BRDF and specular lobes, each
    with its own line of sight) as in the observer map, max over the states in time
    (``states_by_target``: target index -> states on one common time grid, absent for
    static materials).

    ``max_range_m`` is how far one spot alone can exceed the MPE (from a point source):
    with one spot only the nodes within it of the spot's outline are evaluated (the box
    about its centroid widened by :attr:`hazard.physics.engine.Spot.extent_m`, so a spot
    stretched by grazing incidence is covered along its whole length). With several spots their sum can exceed the MPE where
    none does alone, so every node is evaluated. Rays are traced only where the
    unoccluded sum exceeds the MPE (occlusion can only lower it). Nodes go in blocks
    (bounded memory, threads).

    ``bound_below_mpe``: near a spot whose material has a proven bound of ``f_r cos``
    (:func:`hazard.physics.engine.brdf_bound`, a Lambertian ground), the
    integral over its triangles is first replaced by an upper bound
    (:func:`hazard.physics.near_field.near_field_irradiance`); only nodes whose bounded
    sum reaches the MPE are integrated. The mask is the exact one; a node left at its
    bound keeps it as its ``ratio`` (below 1, conservative). False: every node integrated.
    """
    states_by_target = states_by_target or {}
    ny, nx = terrain.heights.shape
    xs = terrain.x0 + terrain.dx * np.arange(nx)
    ys = terrain.y0 + terrain.dx * np.arange(ny)
    mask = np.zeros((ny, nx), bool)
    ratio = np.full((ny, nx), np.nan, np.float32)
    if not spots:
        return Footprint(mask, 0.0, eye_height_m, ratio)
    ix, iy = np.arange(nx), np.arange(ny)
    if len(spots) == 1 and np.isfinite(max_range_m):  # out to the NOHD from any point of the spot
        c, reach = spots[0].centroid, max_range_m + spots[0].extent_m
        ix = np.flatnonzero(np.abs(xs - c[0]) <= reach)
        iy = np.flatnonzero(np.abs(ys - c[1]) <= reach)
    if not len(ix) or not len(iy):
        return Footprint(mask, 0.0, eye_height_m, ratio)
    gx, gy = np.meshgrid(xs[ix], ys[iy])
    pts = np.stack([gx.ravel(), gy.ravel(), terrain.heights[np.ix_(iy, ix)].ravel() + eye_height_m], 1)
    hot = np.zeros(len(pts), bool)
    peak = np.zeros(len(pts))
    n_t = max([len(v) for v in states_by_target.values()] + [1])

    def block(a, b):
        p = pts[a:b]
        gain = np.ones(b - a)
        parts = [_spot_lobes(spot, p, gain, attenuation_per_m, states_by_target.get(spot.target.index), bound_below_mpe)
                 for spot in spots]
        top = sum(e if m is None else e + m for e, m in parts).max(axis=1)
        if bound_below_mpe:
            _exact_where(parts, top, spots, p, gain, attenuation_per_m, states_by_target, mpe_w_m2)
        over = top >= mpe_w_m2  # as for observers: ratio >= 1
        if ray_scene is not None and over.any():
            for spot, lobe_pair in zip(spots, parts):
                _clip_to_sight(spot, lobe_pair, over, p, gain, attenuation_per_m, states_by_target.get(spot.target.index), ray_scene)
            rows = np.flatnonzero(over)
            top[rows] = sum(e[rows] if m is None else e[rows] + m[rows] for e, m in parts).max(axis=1)
            over[rows] = top[rows] >= mpe_w_m2
        hot[a:b], peak[a:b] = over, top / mpe_w_m2

    map_blocks(block, len(pts), block_rows(n_t * len(spots), max(1, len(pts))))
    mask[np.ix_(iy, ix)] = hot.reshape(len(iy), len(ix))
    ratio[np.ix_(iy, ix)] = peak.reshape(len(iy), len(ix))
    return Footprint(mask, float(mask.sum() * terrain.dx**2), eye_height_m, ratio)
