"""Things that move, in the scene's local frame over scenario time: observer tracks
(aircraft), the laser's aim, moving targets and the firing windows.

Scenario time is the scene's own clock [s] (``times_s`` of the tracks, ``[laser]
windows``); :mod:`hazard.pipeline.motion` evaluates the beam and its reflections on it.

- **Tracks** (``[[observers]] kind = "track"``): positions at times, linear in time
  between them in the local frame; with ``positions_geo`` in a ``[site]`` scene along the
  geodesic on the WGS 84 ellipsoid between the rows (pyproj ``Geod.inv``/``Geod.fwd``,
  Karney's algorithm; a great circle on the sphere to 0.5 %), the height linear in
  time, then converted exactly to the site frame and raised by the refraction rise like
  every observer (:mod:`scenes.geo`). A straight flight line (``start_m``,
  ``velocity_m_s``, ``duration_s``) is the two-row track. A track exists only within its
  times: outside them it receives nothing (it is not there).
- **The aim** (``[laser] aim_track``): aim points at times (the point linear in time, the
  direction its unit vector from the aperture), or constant bearing and elevation rates
  from the ``[laser]`` aim (bearing clockwise from +y, elevation above the horizontal).
  Before the first and after the last time the aim holds.
- **Target tracks**: the centre's displacement from the static ``center_m``, linear
  between rows, held outside them; the shape keeps its orientation.
- **Windows**: closed intervals of lasing; without ``windows`` the laser is on over the
  whole scenario.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, ClassVar

import numpy as np

if TYPE_CHECKING:  # annotations only
    from scenes.geo import SiteFrame
    from scenes.spec import MotionSpec

__all__ = ["TrackPath", "AimSchedule", "AimTrackDescription", "Windows", "TargetTrack", "Motion", "motion_of", "bearing_elevation", "check_aim_sector"]


def _segment(times, t):
    """Index k of the segment [times[k], times[k+1]] holding each t (clamped) and the
    fraction along it (0 at and before the first time, 1 at and after the last)."""
    times = np.asarray(times, float)
    t = np.asarray(t, float)
    if len(times) == 1:
        return np.zeros(t.shape, int), np.zeros(t.shape)
    k = np.clip(np.searchsorted(times, t, side="right") - 1, 0, len(times) - 2)
    f = np.clip((t - times[k]) / (times[k + 1] - times[k]), 0.0, 1.0)
    return k, f


def _lerp(times, rows, t) -> np.ndarray:
    rows = np.asarray(rows, float)
    k, f = _segment(times, t)
    if len(rows) == 1:
        return np.broadcast_to(rows[0], np.shape(t) + rows.shape[1:]).copy()
    return rows[k] + f[..., None] * (rows[k + 1] - rows[k])


def bearing_elevation(u) -> tuple[np.ndarray, np.ndarray]:
    """Bearing (clockwise from +y) and elevation [rad] of unit vectors (N, 3)."""
    u = np.asarray(u, float).reshape(-1, 3)
    return np.arctan2(u[:, 0], u[:, 1]), np.arctan2(u[:, 2], np.hypot(u[:, 0], u[:, 1]))


@dataclass
class TrackPath:
    """One moving observer: ``times_s`` (K,) and local positions (K, 3) at them, or a
    geodesic interpolation (``geo`` (K, 3): lat, lon [deg], ellipsoidal height [m], with
    the site frame and the scene offset)."""

    name: str
    group: int
    times_s: np.ndarray
    positions_m: np.ndarray
    optics: object = None
    geo: np.ndarray | None = None
    frame: SiteFrame | None = None
    offset_m: np.ndarray = field(default_factory=lambda: np.zeros(3))
    raise_local: bool = False  # a [site] scene: local positions are raised by the refraction rise as made

    @property
    def span_s(self) -> tuple[float, float]:
        return float(self.times_s[0]), float(self.times_s[-1])

    def present(self, t) -> np.ndarray:
        t = np.asarray(t, float)
        return (t >= self.times_s[0]) & (t <= self.times_s[-1])

    def at(self, t) -> np.ndarray:
        """Local positions [m] (N, 3) at times ``t`` (N,) (held outside the track's times)."""
        t = np.atleast_1d(np.asarray(t, float))
        if self.geo is not None and len(self.times_s) > 1:
            return self._geodesic(t)
        p = _lerp(self.times_s, self.positions_m, t)
        if self.raise_local and self.frame is not None:
            world = p + self.offset_m
            p[:, 2] += self.frame.refraction_rise_m(world[:, 0], world[:, 1])
        return p

    def _geodesic(self, t) -> np.ndarray:
        from pyproj import Geod

        assert self.geo is not None and self.frame is not None, "a geodesic track has its points and site frame"
        g = Geod(ellps="WGS84")
        k, f = _segment(self.times_s, t)
        a, b = self.geo[k], self.geo[k + 1]
        az, _, dist = g.inv(a[:, 1], a[:, 0], b[:, 1], b[:, 0])
        lon, lat, _ = g.fwd(a[:, 1], a[:, 0], az, np.asarray(dist) * f)
        h = a[:, 2] + f * (b[:, 2] - a[:, 2])
        world = self.frame.enu_m(np.asarray(lat), np.asarray(lon), h)
        world[:, 2] += self.frame.refraction_rise_m(world[:, 0], world[:, 1])
        return world - self.offset_m

    def speed_m_s(self) -> float:
        """The largest speed between rows [m/s] (the chord speed; 0 for one row)."""
        if len(self.times_s) < 2:
            return 0.0
        p = self.at(self.times_s)
        return float(np.max(np.linalg.norm(np.diff(p, axis=0), axis=1) / np.diff(self.times_s)))


@dataclass(frozen=True)
class AimTrackDescription:
    """The aim track as report.json's ``motion.aim_track`` says it (:meth:`AimSchedule.describe`).

    Attributes
    ----------
    times_s : tuple of 2 float
        The first and last time [s] of the schedule.
    knots : int
        Number of times given (aim points or the two ends of the rates).
    azimuth_rate_deg_s, elevation_rate_deg_s : float or None
        The bearing's and the elevation's rates [deg/s] of a schedule given by rates; None
        (the keys absent) for one given by aim points.
    """

    times_s: tuple[float, float]
    knots: int
    azimuth_rate_deg_s: float | None = None
    elevation_rate_deg_s: float | None = None

    ABSENT_WHEN_NONE: ClassVar[tuple[str, ...]] = ("azimuth_rate_deg_s", "elevation_rate_deg_s")

    def to_dict(self) -> dict:
        out: dict = {"times_s": list(self.times_s), "knots": self.knots}
        if self.azimuth_rate_deg_s is not None:
            out["azimuth_rate_deg_s"] = self.azimuth_rate_deg_s
        if self.elevation_rate_deg_s is not None:
            out["elevation_rate_deg_s"] = self.elevation_rate_deg_s
        return out


@dataclass
class AimSchedule:
    """The beam's direction over time: aim points (K, 3) at ``times_s``, or rates [rad/s]
    from the initial bearing and elevation over ``times_s = [t0, t1]``."""

    position_m: np.ndarray
    times_s: np.ndarray
    aims_m: np.ndarray | None = None
    start: tuple = (0.0, 0.0)  # bearing, elevation [rad] at t0 (rates)
    rates_rad_s: tuple = (0.0, 0.0)

    @property
    def span_s(self) -> tuple[float, float]:
        return float(self.times_s[0]), float(self.times_s[-1])

    def direction(self, t) -> np.ndarray:
        """Unit beam directions (N, 3) at times ``t``."""
        t = np.atleast_1d(np.asarray(t, float))
        if self.aims_m is not None:
            d = _lerp(self.times_s, self.aims_m, t) - self.position_m
            n = np.linalg.norm(d, axis=1)
            if not np.all(n > 0):
                raise ValueError("laser.aim_track: the aim passes through the laser's aperture (no direction there)")
            return d / n[:, None]
        tc = np.clip(t, self.times_s[0], self.times_s[-1]) - self.times_s[0]
        az = self.start[0] + self.rates_rad_s[0] * tc
        el = np.clip(self.start[1] + self.rates_rad_s[1] * tc, -np.pi / 2, np.pi / 2)
        return np.stack([np.sin(az) * np.cos(el), np.cos(az) * np.cos(el), np.sin(el)], axis=-1)

    def describe(self) -> AimTrackDescription:
        """What report.json says of the schedule (``motion.aim_track``)."""
        span = (float(self.times_s[0]), float(self.times_s[-1]))
        if self.aims_m is not None:
            return AimTrackDescription(span, int(len(self.times_s)))
        az, el = (math.degrees(r) for r in self.rates_rad_s)
        return AimTrackDescription(span, int(len(self.times_s)), az, el)


@dataclass
class Windows:
    """Closed lasing intervals (sorted, merged); None: always on."""

    intervals: np.ndarray | None

    def lased(self, t) -> np.ndarray:
        t = np.asarray(t, float)
        if self.intervals is None:
            return np.ones(t.shape, bool)
        on = np.zeros(t.shape, bool)
        for a, b in self.intervals:
            on |= (t >= a) & (t <= b)
        return on

    def edges(self) -> np.ndarray:
        return np.empty(0) if self.intervals is None else np.asarray(self.intervals, float).ravel()

    @staticmethod
    def of(windows) -> "Windows":
        if not windows:
            return Windows(None)
        w = sorted((float(a), float(b)) for a, b in windows)
        merged = [list(w[0])]
        for a, b in w[1:]:
            if a <= merged[-1][1]:
                merged[-1][1] = max(merged[-1][1], b)
            else:
                merged.append([a, b])
        return Windows(np.asarray(merged, float))


@dataclass
class TargetTrack:
    """A target's displacement [m] from its static centre over time."""

    index: int
    name: str
    times_s: np.ndarray
    displacement_m: np.ndarray

    @property
    def span_s(self) -> tuple[float, float]:
        return float(self.times_s[0]), float(self.times_s[-1])

    def at(self, t) -> np.ndarray:
        return _lerp(self.times_s, self.displacement_m, np.atleast_1d(np.asarray(t, float)))


@dataclass
class Motion:
    """Everything that moves in a scene, and the scenario's span [s]."""

    tracks: list
    aim: AimSchedule | None
    windows: Windows
    target_tracks: list
    t_start_s: float
    t_end_s: float
    spec: MotionSpec  # defaults when the scene has no [motion]

    def knots(self) -> np.ndarray:
        """Times inside the span where something changes its rate (must be sampled)."""
        ts = [self.t_start_s, self.t_end_s]
        for tr in self.tracks:
            ts += list(tr.times_s)
        if self.aim is not None:
            ts += list(self.aim.times_s)
        for tt in self.target_tracks:
            ts += list(tt.times_s)
        t = np.unique(np.asarray(ts, float))
        return t[(t >= self.t_start_s) & (t <= self.t_end_s)]

    @property
    def beam_moves(self) -> bool:
        return self.aim is not None or bool(self.target_tracks)


def _span(spec, parts) -> tuple[float, float]:
    ms = spec.motion
    lo = [p[0] for p in parts]
    hi = [p[1] for p in parts]
    t0 = ms.time_start_s if ms is not None and ms.time_start_s is not None else (min(lo) if lo else 0.0)
    t1 = ms.time_end_s if ms is not None and ms.time_end_s is not None else (max(hi) if hi else t0 + spec.exposure.duration_s)
    if not t1 > t0:  # e.g. every track a single instant
        t1 = t0 + spec.exposure.duration_s
    return float(t0), float(t1)


def aim_schedule(spec, laser_position_m, laser_direction, offset_m) -> AimSchedule | None:
    """The laser's aim over time from ``spec.laser.aim_track`` (None without one): aim
    points [m] in the scene frame (``offset_m`` subtracted), or azimuth / elevation rates
    [rad/s] from ``laser_direction``'s bearing."""
    at = spec.laser.aim_track
    if at is None:
        return None
    times = np.asarray(at.times_s, float)
    if at.aim_m is not None:
        return AimSchedule(laser_position_m, times, np.asarray(at.aim_m, float) - offset_m)
    az, el = bearing_elevation(laser_direction)
    rates = (math.radians(at.azimuth_rate_deg_s or 0.0), math.radians(at.elevation_rate_deg_s or 0.0))
    return AimSchedule(laser_position_m, times, None, (float(az[0]), float(el[0])), rates)


def _tracks(spec, offset_m, site) -> list:
    out = []
    for g, ob in enumerate(spec.observers):
        if ob.kind != "track":
            continue
        times, rows = ob.track_keys()
        geo = None if site is None else site.tracks.get(ob.name)
        out.append(TrackPath(ob.name, g, np.asarray(times, float), np.asarray(rows, float) - offset_m, ob.optics,
                             geo, None if site is None else site.frame, np.asarray(offset_m, float),
                             raise_local=site is not None))
    return out


SECTOR_CHECK_SAMPLES = 20001  # aim directions checked against [laser] sector over the aim track's span (and its knots)


def check_aim_sector(spec, aim: AimSchedule | None) -> None:
    """An aim outside ``[laser] sector`` at any time of the aim track is an error naming
    the first such time (the track sampled at ``SECTOR_CHECK_SAMPLES`` times and its
    knots; between linear aim points the direction follows a great-circle arc)."""
    sector = spec.laser.sector
    if sector is None or aim is None:
        return
    from .geometry import directions_in_sector

    t = np.unique(np.concatenate([np.linspace(*aim.span_s, SECTOR_CHECK_SAMPLES), aim.times_s]))
    u = aim.direction(t)
    ok = directions_in_sector(u, sector, tolerance_deg=1e-9)
    if not ok.all():
        i = int(np.argmin(ok))
        az, el = (np.degrees(x) for x in bearing_elevation(u))
        raise ValueError(f"laser.aim_track: at t = {t[i]:.6g} s the aim points at bearing {az[i]:.8g} deg, elevation "
                         f"{el[i]:.8g} deg: outside laser.sector (azimuth {sector.azimuth_deg} deg, elevation "
                         f"{sector.elevation_deg} deg)")


def samples_max() -> int:
    """Time samples a moving path may take (limit ``MOTION_SAMPLES``, ``HAZARD_MAX_MOTION_SAMPLES``)."""
    from brdfmodels.fileio import limit

    return int(limit("MOTION_SAMPLES"))


def check_base_steps(motion: Motion, t0: float, t1: float) -> int:
    """Samples of the base step over [t0, t1] (``floor((t1 - t0) / time_step_s) + 1``);
    ValueError naming ``motion.time_step_s`` and the limit when they exceed it."""
    from brdfmodels.fileio import check_limit

    step = motion.spec.time_step_s
    n = math.floor((t1 - t0) / step) + 1
    check_limit("MOTION_SAMPLES", n, f"motion: samples of the base step (time_step_s = {step:g} s over [{t0:g}, {t1:g}] s)")
    return n


def check_aim_aperture(aim: AimSchedule | None) -> None:
    """An aim track whose aim points pass within 1 um of the laser's aperture has no beam
    direction there: ValueError naming the first such segment (linear between aim points)."""
    if aim is None or aim.aims_m is None:
        return
    a = aim.aims_m - aim.position_m
    if len(a) == 1:
        d = np.linalg.norm(a, axis=1)
        k = 0
    else:
        p, q = a[:-1], a[1:]
        v = q - p
        tau = np.clip(-np.einsum("ij,ij->i", p, v) / np.maximum(np.einsum("ij,ij->i", v, v), 1e-300), 0.0, 1.0)
        d = np.linalg.norm(p + tau[:, None] * v, axis=1)
        k = int(np.argmin(d))
    if not np.all(d >= AIM_CLEARANCE_M):
        t = aim.times_s
        where = f"at t = {t[0]:.6g} s" if len(a) == 1 else f"between t = {t[k]:.6g} s and {t[k + 1]:.6g} s"
        raise ValueError(f"laser.aim_track: the aim passes through the laser's aperture {where} ({d[k]:.3g} m from it; "
                         f"expected at least {AIM_CLEARANCE_M:g} m: no beam direction there)")


AIM_CLEARANCE_M = 1e-6  # an aim point closer than this to the laser gives no direction (as laser.aim_m)


def check_motion(scene) -> None:
    """Before any work: a scene's motion can be sampled within the limits and its aim
    track always gives a direction (:func:`check_base_steps`, :func:`check_aim_aperture`)."""
    motion = motion_of(scene)
    if motion is None:
        return
    check_aim_aperture(motion.aim)
    check_base_steps(motion, motion.t_start_s, motion.t_end_s)


def motion_of(scene) -> Motion | None:
    """The scene's motion (None when nothing moves and lasing never stops)."""
    from .spec import MotionSpec

    spec = scene.spec
    if not spec.has_motion:
        return None
    offset = np.asarray(scene.offset_m, float)
    tracks = _tracks(spec, offset, scene.site)
    aim = aim_schedule(spec, np.asarray(scene.laser_position_m, float), np.asarray(scene.laser_direction, float), offset)
    tts = [TargetTrack(i, t.name, np.asarray(t.track.times_s, float),
                       np.asarray(t.track.center_m, float) - np.asarray(t.center_m, float))
           for i, t in enumerate(spec.targets) if t.track is not None]
    windows = Windows.of(spec.laser.windows)
    parts = [tr.span_s for tr in tracks] + ([aim.span_s] if aim is not None else []) + [tt.span_s for tt in tts]
    if windows.intervals is not None:
        parts.append((float(windows.intervals[0, 0]), float(windows.intervals[-1, 1])))
    t0, t1 = _span(spec, parts)
    return Motion(tracks, aim, windows, tts, t0, t1, spec.motion or MotionSpec())
