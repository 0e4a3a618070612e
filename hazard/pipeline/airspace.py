"""Stage ``airspace``: whether each flight zone of ``[airspace]`` holds its limit.

A zone is a polygon extruded from ``floor_agl_m`` to ``ceiling_agl_m`` above the ground
(the terrain under each point, or z = 0 without one; range-safety.md section 5: "the zone
is a volume: test the beam path against the zone polyhedra, not a ground distance"). Its
limit is an effective irradiance VCF x E (``lfed``, ``czed``, ``szed``;
:mod:`hazard.physics.visual`) or the MPE (``nohd``, no VCF). It holds when the largest effective
irradiance inside it, at every time the laser lases, stays below the limit.

Where the largest value is looked for, at each analysed time (every beam state's time
and, for a slewing beam, the base time grid, at most ``TIMES_MAX`` of them):

- the direct beam: along its axis over the distances the zone's bounding box spans
  (``AXIS_SAMPLES`` samples), the first point inside the zone, bisected to 1e-9 of the
  distance: on the axis the irradiance falls with range, so that is the axis's largest
  value in the zone (reported whether the zone holds or not: the margin); blocked where
  something stands between the aperture and it;
- each mirror beam (an ideal-mirror target): along its axis, sampled, inside the zone;
- every reflection and the beam's off-axis edge: a lattice of points filling the zone
  (``LATTICE`` x ``LATTICE`` over its outline, ``LEVELS`` heights), with the lines of
  sight of the irradiance map.

With a pointing error (``[laser] pointing_error_rad``, the buffer b) the axis is also
searched along the directions of one ring (8 for a small buffer) on the cone of half-angle b about the aim.
The beam's edge grazing a zone the axes miss is found only at lattice points: the
lattice spacing is reported. Attenuation: credited for the visual levels only with
``[airspace] credit_attenuation = true``; the NOHD zones take the scene's.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from hazard.physics.engine import mirror_axis, specular_irradiance, spot_irradiance, spot_line_of_sight
from hazard.physics.visual import level_limit_w_m2

__all__ = ["AirspaceCheck", "FlightZoneCheck", "check_zones", "TIMES_MAX", "LATTICE", "LEVELS"]


@dataclass(frozen=True)
class FlightZoneCheck:
    """One flight zone's check (:func:`_zone_check`; report.json ``airspace.zones[]``).

    Attributes
    ----------
    name, limit : str
        The zone's name and the level it must hold (``"lfed"``, ``"czed"``, ``"szed"`` or ``"nohd"``).
    limit_w_m2 : float or None
        That level as an effective irradiance [W/m^2] (with the VCF applied; None: not finite).
    floor_agl_m, ceiling_agl_m : float
        The zone's floor and ceiling above ground [m].
    holds : bool
        The worst effective irradiance found stays below the limit.
    worst_effective_irradiance_w_m2 : float
        The worst effective irradiance found in the zone [W/m^2] (reported even where it holds).
    worst_point_m : tuple of float or None
        Where (world x, y, z [m]); None: nothing reached the zone.
    worst_time_s : float or None
        When [s]; None: nothing reached the zone.
    worst_path : str or None
        Which beam: ``"direct"`` or the mirror target's path; None: nothing reached the zone.
    vcf_applied : float
        The visual correction factor applied (unitless; 1 for ``nohd``).
    lattice_spacing_m : float
        The spacing of the zone's lattice of points [m].
    times_checked : int
        The lased analysed times checked.
    """

    name: str
    limit: str
    limit_w_m2: float | None
    floor_agl_m: float
    ceiling_agl_m: float
    holds: bool
    worst_effective_irradiance_w_m2: float
    worst_point_m: tuple[float, ...] | None
    worst_time_s: float | None
    worst_path: str | None
    vcf_applied: float
    lattice_spacing_m: float
    times_checked: int

    def to_dict(self) -> dict:
        return {"name": self.name, "limit": self.limit, "limit_w_m2": self.limit_w_m2, "floor_agl_m": self.floor_agl_m,
                "ceiling_agl_m": self.ceiling_agl_m, "holds": self.holds,
                "worst_effective_irradiance_w_m2": self.worst_effective_irradiance_w_m2,
                "worst_point_m": None if self.worst_point_m is None else list(self.worst_point_m),
                "worst_time_s": self.worst_time_s, "worst_path": self.worst_path, "vcf_applied": self.vcf_applied,
                "lattice_spacing_m": self.lattice_spacing_m, "times_checked": self.times_checked}


@dataclass(frozen=True)
class AirspaceCheck:
    """The flight zones' checks (:func:`check_zones`; report.json ``airspace``).

    Attributes
    ----------
    zones : tuple of FlightZoneCheck
        One per ``[[airspace.zones]]``, in the scene's order.
    method : str
        How the zones were searched, in words.
    visual_correction_factor : float
        The VCF the visual levels use (unitless; 0 for a laser that is not visible).
    note : str or None
        Why the visual levels cannot be exceeded (a laser that is not visible); None: the key is absent.
    """

    zones: tuple[FlightZoneCheck, ...]
    method: str
    visual_correction_factor: float
    note: str | None = None

    ABSENT_WHEN_NONE: ClassVar[tuple[str, ...]] = ("note",)

    def to_dict(self) -> dict:
        out = {"zones": [z.to_dict() for z in self.zones], "method": self.method, "visual_correction_factor": self.visual_correction_factor}
        if self.note is not None:
            out["note"] = self.note
        return out

TIMES_MAX = 2000
LATTICE = 24
LEVELS = 6
AXIS_SAMPLES = 512


class _Zone:
    """A zone in local coordinates: outline, floor and ceiling heights over the ground."""

    def __init__(self, zs, scene):
        from shapely.geometry import Polygon
        from shapely.prepared import prep

        off = np.asarray(scene.offset_m, float)
        self.spec = zs
        self.xy = np.asarray(zs.boundary_m, float) - off[:2]
        self.poly = Polygon(self.xy)
        self._prep = prep(self.poly)
        self.terrain = scene.terrain
        self.z0 = -off[2]

    def ground(self, x, y) -> np.ndarray:
        if self.terrain is None:
            return np.full(np.shape(x), self.z0)
        return self.terrain.height_at(x, y)

    def inside(self, p) -> np.ndarray:
        from shapely import contains_xy

        p = np.asarray(p, float).reshape(-1, 3)
        g = self.ground(p[:, 0], p[:, 1])
        band = (p[:, 2] >= g + self.spec.floor_agl_m) & (p[:, 2] <= g + self.spec.ceiling_agl_m)
        return band & contains_xy(self.poly, p[:, 0], p[:, 1])

    def distance_span_m(self, o) -> tuple[float, float]:
        """Nearest and farthest distance [m] from ``o`` to the zone's bounding box (from
        the lowest ground under it to the highest ceiling)."""
        x0, y0, x1, y1 = self.poly.bounds
        g = self.ground(self.xy[:, 0], self.xy[:, 1])
        lo = np.array([x0, y0, g.min() + self.spec.floor_agl_m - (0 if self.terrain is None else np.ptp(self.terrain.heights))])
        hi = np.array([x1, y1, g.max() + self.spec.ceiling_agl_m + (0 if self.terrain is None else np.ptp(self.terrain.heights))])
        near = float(np.linalg.norm(np.clip(o, lo, hi) - o))
        corners = np.array([[a, b, c] for a in (lo[0], hi[0]) for b in (lo[1], hi[1]) for c in (lo[2], hi[2])])
        return near, float(np.linalg.norm(corners - o, axis=1).max())

    def lattice(self) -> tuple[np.ndarray, float]:
        """Points filling the zone, and their horizontal spacing [m]."""
        from shapely import contains_xy

        x0, y0, x1, y1 = self.poly.bounds
        step = max(x1 - x0, y1 - y0) / LATTICE
        xs = np.arange(x0 + step / 2, x1, step)
        ys = np.arange(y0 + step / 2, y1, step)
        gx, gy = (a.ravel() for a in np.meshgrid(xs, ys))
        keep = contains_xy(self.poly, gx, gy)
        gx, gy = gx[keep], gy[keep]
        if not len(gx):  # a thin zone: its vertices
            gx, gy = self.xy[:, 0], self.xy[:, 1]
        g = self.ground(gx, gy)
        f = np.linspace(self.spec.floor_agl_m, self.spec.ceiling_agl_m, LEVELS)
        pts = np.concatenate([np.column_stack([gx, gy, g + h]) for h in f])
        return pts, step


def _times(result):
    """(time, direction, spots, tracer, ray_scene) at each analysed lasing time."""
    m = result.motion
    if m is None:
        return None
    run = m.run
    if run.motion.aim is None:
        t = np.asarray([bs.time_s for bs in run.states_list])
    else:
        from hazard.pipeline.motion import base_grid

        t = base_grid(run.motion, run.motion.t_start_s, run.motion.t_end_s)
        t = np.unique(np.concatenate([t[:: max(1, len(t) // TIMES_MAX)], run.key_times_s]))
    t = t[run.motion.windows.lased(t)]
    return [(float(ti), run.nominal_direction(ti)[0], run.states_list[int(run.state_index(np.array([ti]))[0])]) for ti in t]


def _axis_entry(zone, o, u, span_m) -> np.ndarray | None:
    """The first point of the ray o + s u (span[0] <= s <= span[1]) inside the zone, or None."""
    s = np.linspace(span_m[0], span_m[1], AXIS_SAMPLES)
    inside = zone.inside(o + s[:, None] * u)
    if not inside.any():
        return None
    k = int(np.argmax(inside))
    if k == 0:
        return o.copy()
    lo, hi = s[k - 1], s[k]
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        if zone.inside(o + mid * u)[0]:
            hi = mid
        else:
            lo = mid
        if hi - lo <= 1e-9 * max(hi, 1.0):
            break
    return o + hi * u


def _direct_at(result, p, u, tracer, mu) -> np.ndarray:
    """The direct beam along direction ``u`` at points ``p`` (N, 3), blocked by objects."""
    from hazard.pipeline.motion import blocked, gaussian_along_w_m2

    e, _, dist = gaussian_along_w_m2(result.beam, u, p, mu)
    live = np.flatnonzero(e > 0)
    if len(live) and tracer is not None:
        e[live] = np.where(blocked(tracer, result.beam.position_m, p[live], dist[live]), 0.0, e[live])
    return e


def _reflected_at(spots, p, mu, ray_scene, states) -> np.ndarray:
    """Every spot's reflection at points ``p`` (the largest over the history's states)."""
    e = np.zeros(len(p))
    for sp in spots:
        st = states.get(sp.target.index)
        los = spot_line_of_sight(ray_scene, sp, p)[0] if ray_scene is not None else None
        g = np.ones(len(p))
        r, _ = spot_irradiance(sp, p, g, mu, st, los)
        if sp.material.has_specular:  # each point's line of sight from its own reflection point
            r = r + specular_irradiance(sp, p, g, mu, None, st, ray_scene=ray_scene)
        e += r if r.ndim == 1 else r.max(axis=1)
    return e


def _reach_past(spots, o) -> float:
    """The farthest spot from the laser [m] (a mirror beam starts there)."""
    return max((float(np.linalg.norm(sp.centroid - o)) for sp in spots), default=0.0)


def _mirror_points(zone, spots, reach_m) -> np.ndarray:
    """Points along each mirror beam's axis inside the zone."""
    out = []
    for sp in spots:
        if sp.material.has_specular:
            s = np.linspace(0.0, reach_m, AXIS_SAMPLES)
            q = sp.centroid + s[:, None] * mirror_axis(sp)
            out.append(q[zone.inside(q)])
    return np.concatenate(out) if out else np.empty((0, 3))


def _zone_check(result, zone, steps, vcf, mu, lattice) -> FlightZoneCheck:
    """The worst effective irradiance in one zone over the analysed times."""
    key = zone.spec.limit
    e_lim = level_limit_w_m2(key, result.mpe_w_m2, vcf)
    eff = 1.0 if key == "nohd" else vcf
    o = np.asarray(result.scene.laser_position_m, float)
    span = zone.distance_span_m(o)  # the axis's part that can lie in the zone (its worst value is reported even where it holds)
    pts, spacing = lattice
    best: tuple[float, np.ndarray | None, float | None, str | None] = (0.0, None, None, None)  # value, point, time, path
    b = result.scene.spec.laser.pointing_buffer_rad
    for t, u0, spots, tracer, ray_scene in steps:
        ring = _pointing_ring(u0, b)
        entries = [e[None] for e in (_axis_entry(zone, o, u, span) for u in ring) if e is not None]
        p = np.concatenate([pts, _mirror_points(zone, spots, span[1] + _reach_past(spots, o))] + entries)
        direct = np.max([_direct_at(result, p, u, tracer, mu) for u in ring], axis=0)
        refl = _reflected_at(spots, p, mu, ray_scene, result.states)
        total = (direct + refl) * eff
        k = int(np.argmax(total))
        if total[k] > best[0]:
            best = (float(total[k]), p[k], t, "direct" if direct[k] >= refl[k] else _which(spots, p[k], mu, ray_scene, result.states))
    off = np.asarray(result.scene.offset_m, float)
    worst, point, t, path = best
    return FlightZoneCheck(name=zone.spec.name, limit=key, limit_w_m2=e_lim * eff if math.isfinite(e_lim) else None,
                           floor_agl_m=zone.spec.floor_agl_m, ceiling_agl_m=zone.spec.ceiling_agl_m,
                           holds=bool(worst < (e_lim * eff if math.isfinite(e_lim) else math.inf)),
                           worst_effective_irradiance_w_m2=worst, worst_point_m=None if point is None else tuple((point + off).tolist()),
                           worst_time_s=t, worst_path=path, vcf_applied=eff, lattice_spacing_m=spacing, times_checked=len(steps))


def _pointing_ring(u, b) -> list:
    """The aim, and with a pointing buffer b > 0 directions on the cone of half-angle b
    about it (the beam may point anywhere within it): the danger zone's cone at one ring
    (:func:`hazard.pipeline.sdz.cone_directions`, 8 directions for a small buffer)."""
    if b <= 0:
        return [u]
    from hazard.pipeline.sdz import cone_directions

    return list(cone_directions(np.asarray(u, float), b, b))


def _which(spots, p, mu, ray_scene, states) -> str | None:
    vals = [float(_reflected_at([sp], p[None], mu, ray_scene, states)[0]) for sp in spots]
    return spots[int(np.argmax(vals))].target.name if vals else None


def check_zones(result, first) -> AirspaceCheck:
    """report.json ``airspace``: per zone whether it holds, with the worst point and time
    (see the module notes). ``first``: (traced, tracer, ray_scene) of the analysis."""
    spec = result.scene.spec
    vi = result.visual_interference
    vcf_levels = vi.vcf if vi.applies else 0.0
    traced, tracer, ray_scene = first
    timed = _times(result)
    if timed is None:
        steps = [(0.0, np.asarray(result.scene.laser_direction, float), result.spots, tracer, ray_scene)]
    else:
        steps = [(t, u, bs.spots, bs.tracer, bs.ray_scene) for t, u, bs in timed]
    zones = []
    for zs in spec.airspace.zones:
        z = _Zone(zs, result.scene)
        mu = result.attenuation_per_m if zs.limit == "nohd" else vi.attenuation_per_m
        zones.append(_zone_check(result, z, steps, 1.0 if zs.limit == "nohd" else vcf_levels, mu, z.lattice()))
    note = None if vi.applies else (f"{spec.laser.wavelength_nm:g} nm is not visible: the visual levels (lfed, czed, szed) "
                                       f"cannot be exceeded; 'nohd' zones are checked against the MPE")
    return AirspaceCheck(zones=tuple(zones), method="hazard.pipeline.airspace: the direct beam's axis entry, each mirror beam's "
                         f"axis and a lattice of {LATTICE} x {LATTICE} x {LEVELS} points per zone, at every lased analysed time",
                         visual_correction_factor=vcf_levels, note=note)
