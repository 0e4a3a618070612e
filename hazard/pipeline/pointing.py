"""The direct beam at observers over the pointing error (part of stage ``direct``).

The laser surface danger zone (:mod:`hazard.pipeline.sdz`) is where the beam may go
within its pointing error or sector; an observer standing in it must be judged by where
the beam may go, not by the nominal aim alone (range-safety.md section 3: personnel are
cleared from the zone because the beam may point there). With a pointing buffer
theta_b (``[laser] pointing_error_rad``, a bound or k sigma) about the aim, and/or a
``[laser] sector`` of azimuths and elevations, the beam may point in any direction of

    A = (sector, or the aim alone) widened by theta_b (plus the aim's cone when the aim
    lies outside the sector).

For an observer at distance L in direction u from the aperture, the nearest direction
of A is at angle delta = max(0, dist(u, core) - theta_b) (the core: the sector or the
aim; the widening by theta_b is a Minkowski sum on the sphere, exact). The Gaussian beam
pointed there gives (range-safety.md section 1; :class:`hazard.physics.beam.BeamGeometry`)

    E = P / (pi w^2) exp(-s^2) sqrt(1 + s^2 phi^2 / 4) exp(-mu L),
    z = L cos delta, r = L sin delta, w = (a + z phi) / 2, s = r / w,

its largest value over A (E falls with delta wherever 4 L / (a + L phi) > phi, i.e.
beyond micrometres of the aperture); the verdict's value is the power through the
observer's limiting aperture or its aid's collecting disk at offset ``r`` from that
axis (:mod:`hazard.physics.aperture`), also largest at the smallest ``r``. The distance from u to
the sector (azimuth [A0, A1] clockwise from +y, elevation [E0, E1]) is exact
(:func:`scenes.geometry.angle_to_sector_rad`, shared with the danger zone's directions):
inside it is 0; else the least angle to its edges, the two meridian arcs (the foot of u
on each arc's great circle, or an arc's
ends) and the two circles of elevation (at u's azimuth when it lies in [A0, A1], else
at their ends).

A slewing beam (``[laser] aim_track``) may stop anywhere along its track (a fault, a
hold): its directions join the core. They are sampled every ``AIM_TRACK_STEP_RAD`` or
finer (:func:`aim_track_directions`), and the distance to the continuous track is taken
as the least angle to a sample less half the largest gap between samples (the track
passes within half a gap of every sample's neighbourhood: never farther than the
estimate), so the core is never smaller than the track's.

What blocks it: the terrain and the occluders on the straight line from the aperture to
the eye (targets do not: within its pointing error the beam can slip off them, as the
danger zone assumes). The reflections are computed for the nominal aim only (said in
the stage detail).
"""

from __future__ import annotations

import math

import numpy as np

from scenes.geometry import angle_to_sector_rad, direction_in_sector

from hazard.pipeline.backstops import first_backstop_rays

__all__ = ["angle_to_sector_rad", "pointing_offset_rad", "beam_at_offset_w_m2", "pointing_worst_w_m2", "aim_track_directions"]

AIM_TRACK_STEP_RAD = 2e-4  # the aim track's directions: at most this apart (0.2 mrad; finer with a small buffer)
AIM_TRACK_MAX = 20000  # directions of an aim track (a longer track gets a coarser step, said by the gap)


def _angle(u, v) -> np.ndarray:
    """Angle [rad] between unit vectors (rows), accurate near 0 and pi (atan2 of the
    cross and dot products)."""
    return np.arctan2(np.linalg.norm(np.cross(u, v), axis=-1), np.einsum("...i,...i->...", u, v))


def aim_track_directions(scene, step_rad=None) -> tuple[np.ndarray, float]:
    """The aim track's directions (K, 3), consecutive ones at most ``step_rad`` apart
    (default: ``AIM_TRACK_STEP_RAD``, or a quarter of the pointing buffer if smaller), and
    the largest gap between them [rad]. Empty without an aim track."""
    from scenes.motion import motion_of

    motion = motion_of(scene)
    if motion is None or motion.aim is None:
        return np.empty((0, 3)), 0.0
    b = scene.spec.laser.pointing_buffer_rad
    step = step_rad or min(AIM_TRACK_STEP_RAD, b / 4 if b > 0 else AIM_TRACK_STEP_RAD)
    t0, t1 = motion.aim.span_s
    fine = np.linspace(t0, t1, 20001) if t1 > t0 else np.array([t0])
    u = motion.aim.direction(fine)
    turn = np.concatenate([[0.0], np.cumsum(_angle(u[1:], u[:-1]))])
    n = min(int(math.ceil(turn[-1] / step)) + 1, AIM_TRACK_MAX)
    idx = np.unique(np.searchsorted(turn, np.linspace(0.0, turn[-1], n)).clip(0, len(fine) - 1))
    d = u[idx]
    gap = float(_angle(d[1:], d[:-1]).max()) if len(d) > 1 else 0.0
    fine_gap = float(_angle(u[1:], u[:-1]).max()) if len(u) > 1 else 0.0
    return d, max(gap, fine_gap)


def _to_track_rad(u, track, gap) -> np.ndarray:
    """Least angle from u (N, 3) to the sampled track, less half the largest gap (>= 0)."""
    best = np.full(len(u), np.inf)
    for a0 in range(0, len(track), 512):
        best = np.minimum(best, np.arccos(np.clip(u @ track[a0:a0 + 512].T, -1.0, 1.0)).min(axis=1))
    return np.maximum(best - gap / 2, 0.0)


def pointing_offset_rad(scene, u, track=None) -> np.ndarray:
    """Angle delta [rad] from unit directions u (N, 3) (laser to observer) to the nearest
    direction the beam may point in (see the module notes); ``track``: the aim track's
    :func:`aim_track_directions` when the caller has them (made here otherwise)."""
    laser = scene.spec.laser
    b = laser.pointing_buffer_rad
    axis = np.asarray(scene.laser_direction, float)
    to_aim = _angle(u, axis[None])
    if laser.sector is None:
        core = to_aim
    else:
        core = angle_to_sector_rad(u, laser.sector)
        if not direction_in_sector(axis, laser.sector, b):  # the aim's cone is added to an aim outside the sector
            core = np.minimum(core, to_aim)
    track, gap = aim_track_directions(scene) if track is None else track
    if len(track):
        core = np.minimum(core, _to_track_rad(u, track, gap))
    return np.maximum(core - b, 0.0)


def beam_at_offset_w_m2(beam, distance_m, delta_rad, mu) -> tuple[np.ndarray, np.ndarray]:
    """Irradiance [W/m^2] at distance L from the aperture, angle delta off the axis of
    ``beam`` (:class:`hazard.physics.beam.BeamGeometry`, turned toward the point; see the module
    notes), and the beam's 1/e diameter there [m]."""
    L, delta = np.asarray(distance_m, float), np.asarray(delta_rad, float)
    z = np.maximum(L * np.cos(delta), 0.0)
    diameter = beam.diameter_at(z)
    s = np.stack([L * np.sin(delta) / (diameter / 2), np.zeros_like(z)], axis=-1)
    e = beam.irradiance_w_m2(s, z) * np.exp(-mu * L)
    return np.where(delta < np.pi / 2, e, 0.0), diameter


def pointing_worst_w_m2(scene, beam, observers, mu, ray_scene, aperture_fn) -> tuple[np.ndarray, np.ndarray]:
    """The largest irradiance [W/m^2] of ``beam`` (the laser's, at its aim) at each
    observer over the directions it may point in, in blocks on threads
    (:meth:`scenes.Observers.map_blocks`): (the aperture value the verdict uses, the point
    value at the eye). ``aperture_fn(rows, point_w_m2, axial_m, offset_m, path_m)`` gives
    the aperture value of those observers (:mod:`hazard.physics.aperture`; the power through a
    disk about the eye falls as the axis moves away, so the nearest direction is the
    worst for it too); ``ray_scene`` (None: nothing blocks) answers the line from the
    aperture to each eye through the targets."""
    out, point = np.zeros(len(observers)), np.zeros(len(observers))
    track = aim_track_directions(scene)  # once, not per block

    def block(a0, a1, p):
        out[a0:a1], point[a0:a1] = _worst(scene, beam, p, mu, ray_scene, lambda rows, *a: aperture_fn(a0 + rows, *a), track)

    observers.map_blocks(block)
    return out, point


def _worst(scene, beam, points_m, mu, ray_scene, aperture_fn, track=None) -> tuple[np.ndarray, np.ndarray]:
    """:func:`pointing_worst_w_m2` at points (N, 3)."""
    o = np.asarray(beam.position_m, float)
    rel = np.asarray(points_m, float).reshape(-1, 3) - o
    dist = np.linalg.norm(rel, axis=1)
    out, point = np.zeros(len(rel)), np.zeros(len(rel))
    live = np.flatnonzero(dist > 0)
    if not len(live):
        return out, point
    u = rel[live] / dist[live, None]
    delta = pointing_offset_rad(scene, u, track)
    e, _diameter = beam_at_offset_w_m2(beam, dist[live], delta, mu)
    ahead = delta < np.pi / 2
    ap = np.zeros(len(live))
    ap[ahead] = aperture_fn(live[ahead], e[ahead], dist[live[ahead]] * np.cos(delta[ahead]),
                            dist[live[ahead]] * np.sin(delta[ahead]), dist[live[ahead]])
    hit = np.flatnonzero((ap > 0) | (e > 0))
    if ray_scene is not None and len(hit):
        stop = first_backstop_rays(np.broadcast_to(o, (len(hit), 3)), u[hit], ray_scene, len(scene.targets))
        clear = stop >= dist[live[hit]] * (1 - 1e-9)
        e[hit], ap[hit] = np.where(clear, e[hit], 0.0), np.where(clear, ap[hit], 0.0)
    out[live], point[live] = ap, e
    return out, point
