"""Geometry of the airspace outputs: the direct beam's visual-interference volumes, the
flight zones' prisms and the tracks' paths, in world coordinates [m], for the map
outputs (:mod:`hazard.outputs.map_zones`) and the VTK output (:mod:`hazard.pictures.render`).

A level's volume around the direct beam is where VCF E >= E_lim (range-safety.md
sections 1 and 5): at axial distance z its radius is r(z) = w(z) sqrt(ln(VCF E0(z) /
E_lim)), E0(z) = 4 P exp(-mu z) / (pi (a + z phi)^2), w = (a + z phi) / 2, out to the
level's distance (r = 0 there). Plan outlines project it on the horizontal plane (its
half-width across the bearing is r(z), along it the axis's horizontal run).
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["level_radius_m", "visual_outline_xy", "visual_surface", "zone_prism", "track_polyline", "aim_directions"]

AXIAL_SAMPLES = 96  # samples along a level's volume (geometric in z: fine near the aperture)
AIM_SAMPLES_MAX = 64  # aim directions drawn for a slewing beam's volumes


def level_radius_m(z, power_w, diameter_m, divergence_rad, limit_w_m2, vcf, mu=0.0) -> np.ndarray:
    """Radius [m] of the volume where VCF E >= ``limit_w_m2`` at axial distances ``z`` [m]
    (0 where the axis itself is below)."""
    z = np.asarray(z, float)
    d = diameter_m + z * divergence_rad
    e0 = 4 * power_w * vcf * np.exp(-mu * z) / (math.pi * d * d)
    return np.where(e0 > limit_w_m2, 0.5 * d * np.sqrt(np.log(np.maximum(e0 / limit_w_m2, 1.0))), 0.0)


def _axial(reach_m) -> np.ndarray:
    if not reach_m > 0:
        return np.zeros(1)
    return np.concatenate([[0.0], np.geomspace(max(reach_m * 1e-6, 1e-3), reach_m, AXIAL_SAMPLES - 1)])


def aim_directions(result) -> np.ndarray:
    """The beam's directions to draw: the aim, and a slewing beam's track (at most
    ``AIM_SAMPLES_MAX``)."""
    from hazard.pipeline.pointing import aim_track_directions

    track, _ = aim_track_directions(result.scene)
    if not len(track):
        return np.asarray(result.scene.laser_direction, float)[None]
    idx = np.unique(np.linspace(0, len(track) - 1, min(len(track), AIM_SAMPLES_MAX)).round().astype(int))
    return track[idx]


def _level_args(result, level):
    vi = result.visual_interference
    la = result.scene.spec.laser
    from hazard.physics.visual import LEVELS_W_M2

    return (la.average_power_w, la.beam_diameter_m, la.divergence_rad, LEVELS_W_M2[level], vi.vcf,
            vi.attenuation_per_m), vi.direct.distance_m(level)


def visual_outline_xy(result, level):
    """The plan outline (shapely, world x, y) of a level's volume over the beam's
    directions, or None (no such volume)."""
    import shapely
    from shapely.geometry import Polygon

    args, reach = _level_args(result, level)
    if reach is None or not reach > 0 or not math.isfinite(reach):
        return None
    z = _axial(reach)
    r = level_radius_m(z, *args)
    o = np.asarray(result.scene.laser_position_m, float) + result.scene.offset_m
    polys = []
    for u in aim_directions(result):
        h = np.hypot(u[0], u[1])
        along = u[:2] / h if h > 1e-12 else np.array([1.0, 0.0])
        across = np.array([-along[1], along[0]])
        run = z * h
        left = o[:2] + run[:, None] * along + r[:, None] * across
        right = o[:2] + run[:, None] * along - r[:, None] * across
        ring = np.vstack([left, right[::-1]])
        if h <= 1e-12:  # a vertical beam: its widest circle
            ring = o[:2] + r.max() * np.column_stack([np.cos(np.linspace(0, 2 * np.pi, 65)), np.sin(np.linspace(0, 2 * np.pi, 65))])
        p = Polygon(ring)
        polys.append(p if p.is_valid else p.buffer(0))
    return shapely.unary_union(polys)


def visual_surface(result, level, segments: int = 24):
    """The level's volume about the aim as a surface (vertices (K, 3), quads as
    triangles (F, 3)), world coordinates; None without one."""
    from hazard.physics.beam import perp_basis

    args, reach = _level_args(result, level)
    if reach is None or not reach > 0 or not math.isfinite(reach):
        return None
    z = _axial(reach)
    r = level_radius_m(z, *args)
    u = np.asarray(result.scene.laser_direction, float)
    e1, e2 = perp_basis(u)
    o = np.asarray(result.scene.laser_position_m, float) + result.scene.offset_m
    ang = np.linspace(0, 2 * np.pi, segments, endpoint=False)
    ring = np.cos(ang)[:, None] * e1 + np.sin(ang)[:, None] * e2
    v = (o + z[:, None, None] * u + r[:, None, None] * ring[None]).reshape(-1, 3)
    i, j = np.meshgrid(np.arange(len(z) - 1), np.arange(segments), indexing="ij")
    a = (i * segments + j).ravel()
    b = (i * segments + (j + 1) % segments).ravel()
    c, d = a + segments, b + segments
    return v, np.concatenate([np.column_stack([a, b, d]), np.column_stack([a, d, c])])


def zone_prism(result, zone_spec, n_height: int = 2):
    """A flight zone as a closed prism: (vertices (2K, 3), faces) world coordinates, floor
    and ceiling over the ground under each vertex (z = 0 without terrain)."""
    scene = result.scene
    off = np.asarray(scene.offset_m, float)
    xy = np.asarray(zone_spec.boundary_m, float)
    if scene.terrain is not None:
        g = scene.terrain.height_at(xy[:, 0] - off[0], xy[:, 1] - off[1]) + off[2]
    else:
        g = np.zeros(len(xy))
    k = len(xy)
    lo = np.column_stack([xy, g + zone_spec.floor_agl_m])
    hi = np.column_stack([xy, g + zone_spec.ceiling_agl_m])
    faces = [[i, (i + 1) % k, k + (i + 1) % k, k + i] for i in range(k)]
    return np.vstack([lo, hi]), faces + [list(range(k))[::-1], list(range(k, 2 * k))]


def track_polyline(result, path) -> np.ndarray:
    """A path's sampled positions, world coordinates (N, 3)."""
    return np.asarray(path.positions_m, float) + np.asarray(result.scene.offset_m, float)
