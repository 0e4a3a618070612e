"""The verdict of an analysis, one function for every output.

:func:`verdict` feeds the stdout answer of ``hazard run`` (its headline line), report.json
(``verdict``, ``hazard_at_observers``, ``hazard_zones``, ``any_hazard``, ``warnings``) and
the review page's verdict box (which shows report.json's ``verdict.headline`` as it is),
so the three headlines are the same text.

Two questions are kept apart:

- ``hazard_at_observers``: someone the scene lists is at or above the limit: a fixed
  observer point (its peak, or over time when the beam or a target moves), a moving
  observer (track), or a flight zone whose FAA level is exceeded (aircrew are people in it);
- ``hazard_zones``: a hazard zone is not contained: the direct beam's danger zone (naked
  eye or through an optical aid of the scene) or a mirror beam reaches its NOHD without a
  backstop or leaves the range boundary; a target's diffuse keep-out lobe (NOHD > 0) is
  not inside the range boundary (without a ``[range]`` nothing bounds it: counted); a
  target's mirror NOHD > 0 whose beam was not traced is counted too.

``any_hazard`` (kept for compatibility) is wider: either of the two, or any NOHD > 0
anywhere, even contained. ``hazard run --fail-on-hazard {observers,zones,any}`` fails on
the first, the second, or either (:func:`fails`).
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any
from dataclasses import dataclass

import numpy as np

from hazard.pipeline.plausibility import answer_warnings

__all__ = ["Verdict", "VerdictCounts", "verdict", "fails", "zone_findings", "escape_way", "FAIL_ON_CHOICES"]

FAIL_ON_CHOICES = ("observers", "zones", "any")  # --fail-on-hazard WHICH (default observers)
CIRCLE_SEGS = 16  # segments per quarter circle of a lobe's disc; the disc is drawn about the circle (never inside it)


@dataclass(frozen=True)
class VerdictCounts:
    """Who the scene lists and how many of them are over their limit (report.json ``verdict.observers``).

    Attributes
    ----------
    hazardous, total : int
        Fixed observer points at or above the MPE (their peak, or over time), of all listed.
    tracks_hazardous, tracks : int
        Moving observers (tracks) over the MPE, of all tracks.
    flight_zones_exceeded, flight_zones : int
        Flight zones whose FAA level is exceeded somewhere in them, of all flight zones.
    """

    hazardous: int
    total: int
    tracks_hazardous: int
    tracks: int
    flight_zones_exceeded: int
    flight_zones: int

    def to_dict(self) -> dict:
        """report.json's ``verdict.observers``: the fields in their order."""
        return dataclasses.asdict(self)


@dataclass(frozen=True)
class Verdict:
    """The verdict of an analysis (:func:`verdict`; the module notes say what each flag means).

    Attributes
    ----------
    headline : str
        The one line stdout, report.json (``verdict.headline``) and the review page print.
    hazard_at_observers : bool
        A listed observer point, track or flight zone at or above its limit.
    hazard_zones : bool
        A hazard zone not contained or beyond the range boundary (``zones`` not empty).
    any_hazard : bool
        Either, or any NOHD > 0 anywhere, even contained.
    zones : tuple of str
        Each hazard zone not contained, and why.
    observers : VerdictCounts
        The counts the headline states.
    warnings : tuple of str
        The plausibility warnings (:func:`hazard.pipeline.plausibility.answer_warnings`):
        report.json's top-level ``warnings``, not part of its ``verdict`` block.
    """

    headline: str
    hazard_at_observers: bool
    hazard_zones: bool
    any_hazard: bool
    zones: tuple[str, ...]
    observers: VerdictCounts
    warnings: tuple[str, ...]

    #: fields report.json writes elsewhere than in its ``verdict`` block
    NOT_IN_BLOCK = ("warnings",)

    def to_dict(self) -> dict:
        """report.json's ``verdict`` block: every field but ``warnings`` (written at the top level)."""
        return {"headline": self.headline, "hazard_at_observers": self.hazard_at_observers, "hazard_zones": self.hazard_zones,
                "any_hazard": self.any_hazard, "zones": list(self.zones), "observers": self.observers.to_dict()}


def _observer_counts(result) -> VerdictCounts:
    """Hazardous fixed observer points, moving observers and exceeded flight zones."""
    tracks = [] if getattr(result, "motion", None) is None else result.motion.tracks()
    air = getattr(result, "airspace", None)
    zones = () if air is None else air.zones
    return VerdictCounts(hazardous=int(np.sum(result.hazardous)), total=len(result.observers),
                         tracks_hazardous=sum(bool(p.summary.hazardous) for p in tracks), tracks=len(tracks),
                         flight_zones_exceeded=sum(not z.holds for z in zones), flight_zones=len(zones))


def _observers_text(c: VerdictCounts) -> str:
    text = f"{c.hazardous} of {c.total} observer point(s) at or above the MPE"
    if c.tracks:
        text += f", {c.tracks_hazardous} of {c.tracks} moving observer(s) over the MPE"
    if c.flight_zones:
        text += f", {c.flight_zones_exceeded} of {c.flight_zones} flight zone(s) over their limit"
    return text


def escape_way(z) -> str:
    """Which way a zone escapes (``escaping_bearing_deg`` / ``escaping_elevation_deg``): ``z``
    a :class:`hazard.pipeline.sdz.GroundZone` or its report.json dict."""
    b: Any
    e: Any
    if isinstance(z, dict):  # report.json's (the review page reads the document)
        b, e = z.get("escaping_bearing_deg"), z.get("escaping_elevation_deg")
    else:  # hazard.pipeline.sdz.GroundZone
        b, e = z.escaping_bearing_deg, z.escaping_elevation_deg
    if not b:
        return ""
    bearing = f"bearing {b[0]:g} deg" if b[0] == b[1] else f"bearings {b[0]:g} to {b[1]:g} deg (clockwise)"
    elevation = f"elevation {e[0]:g} deg" if e[0] == e[1] else f"elevations {e[0]:g} to {e[1]:g} deg"
    return f" toward {bearing}, {elevation}"


def _not_backstops(result, nohd_m: float) -> str:
    """Why the beam is not stopped though it meets targets: targets are not backstops (and a
    fixed target beyond the zone's NOHD, ``nohd_m`` [m], could not end the zone anyway)."""
    lit = [t for t in result.targets if t.spot_power_w > 0]
    if not lit:
        return "no terrain or occluder stops it within the NOHD"
    total = max(float(result.beam_power_w), 1e-300)
    names = ", ".join(f"{t.name!r} ({100 * t.spot_power_w / total:.3g} % of the beam{_beyond(result, t.name, nohd_m)})"
                      for t in lit[:3])
    return (f"at the aim the beam meets target(s) {names}{', ...' if len(lit) > 3 else ''}, but a target is not a backstop "
            "(within the pointing error the beam can miss it; only the terrain and occluders stop the beam), and no terrain "
            "or occluder stops it within the NOHD")


def _beyond(result, name: str, nohd_m: float) -> str:
    """``", x m from the laser: beyond the NOHD"`` for a fixed target whose nearest vertex lies
    past ``nohd_m`` [m] (all of it beyond); empty for a nearer, a moving or an unknown target."""
    scene = getattr(result, "scene", None)
    target = next((t for t in getattr(scene, "targets", ()) if t.name == name), None)
    if scene is None or target is None or getattr(target.spec, "track", None) is not None:
        return ""
    mesh = getattr(target, "mesh", None)
    points = np.atleast_2d(target.center_m if mesh is None else mesh.vertices)
    distance_m = float(np.min(np.linalg.norm(np.subtract(points, scene.laser_position_m, dtype=np.float64), axis=-1)))
    if not distance_m > nohd_m:
        return ""
    return f", {distance_m / 1e3:.4g} km from the laser: beyond the NOHD" if distance_m >= 1e4 else \
        f", {distance_m:.4g} m from the laser: beyond the NOHD"


def _sdz_findings(result) -> list:
    """The direct beam's danger zone, naked and aided: not contained (why), or leaving the range."""
    z = getattr(result, "sdz", None)
    if z is None:
        return []
    out = []
    for label, zone in [("the direct beam's danger zone", z)] + [
            (f"the direct beam's danger zone through {a.aid.magnification:g}x{1e3 * a.aid.objective_diameter_m:g} optics", a)
            for a in z.aided]:
        nohd = zone.nohd_m or 0.0
        if not nohd > 0:
            continue
        if not zone.contained:
            out.append(f"{label} (NOHD {nohd:.4g} m) is NOT contained: {zone.escaping_directions} of {z.directions.count} "
                       f"direction(s){escape_way(zone)} reach the NOHD "
                       f"without a backstop{' (some above the horizon)' if zone.above_horizon else ''}: "
                       f"{_not_backstops(result, nohd)}")
        if zone.leaves_boundary:
            outside = math.nan if zone.outside_boundary_m2 is None else zone.outside_boundary_m2
            out.append(f"{label} (NOHD {nohd:.4g} m) LEAVES the range boundary: {outside:.4g} "
                       "m^2 of it outside")
    return out


def _mirror_findings(result) -> list:
    """Mirror beams not contained or leaving the range, and mirror NOHDs not traced."""
    z = getattr(result, "sdz", None)
    beams = () if z is None else z.mirror_beams or ()
    way = {t.name: _mirror_way(t) for t in result.targets}
    out = []
    for m in beams:
        for label, e in ((f"the mirror beam of {m.target!r}", m), (f"the mirror beam of {m.target!r} through optics", m.aided)):
            if e is None or not (e.nohd_m or 0) > 0:
                continue
            if not e.contained:
                out.append(f"{label} (specular NOHD {e.nohd_m:.4g} m{way.get(m.target, '')}) is NOT contained: no terrain "
                           f"or occluder stops it within its NOHD{' (it rises above the horizon)' if e.above_horizon else ''}; "
                           "a target is not a backstop")
            if e.leaves_boundary:
                out.append(f"{label} (specular NOHD {e.nohd_m:.4g} m) LEAVES the range boundary")
    traced = {m.target for m in beams}
    for t in result.targets:
        nohd = max([x for x in (t.specular_nohd_static_m, t.specular_nohd_dynamic_m) if x is not None] + [0.0])
        if nohd > 0 and t.name not in traced:
            out.append(f"the mirror beam of {t.name!r} (specular NOHD {nohd:.4g} m) was not traced for containment: "
                       "counted as not contained")
    return out


def _mirror_way(t) -> str:
    """``, toward bearing B deg, elevation E deg``: a target's mirror beam direction
    (``specular_direction``, world frame), or "" when it has none."""
    d = getattr(t, "specular_direction", None)
    if d is None or len(d) != 3 or not np.all(np.isfinite(d)) or not np.linalg.norm(d) > 0:
        return ""
    u = np.asarray(d, float) / np.linalg.norm(d)
    bearing = math.degrees(math.atan2(u[0], u[1])) % 360.0
    return f", toward bearing {bearing:.4g} deg, elevation {math.degrees(math.asin(max(-1.0, min(1.0, u[2])))):.3g} deg"


def _lobe_radius_m(t) -> float:
    """A target's largest diffuse NOHD [m], naked or through any aid."""
    naked = [lb.max_range_m for lb in (t.static_lobe, t.dynamic_lobe) if lb is not None]
    aided = [a.get(k) for a in t.aided for k in ("nohd_static_m", "nohd_dynamic_m")]
    return max([float(x) for x in naked + aided if x is not None] + [0.0])


def _lobe_findings(result) -> list:
    """Diffuse keep-out lobes (NOHD > 0) not inside the range boundary: the disc of their
    NOHD about each of the target's spots (its centre without a spot), drawn about the
    circle. Without a [range] nothing bounds them."""
    from shapely.geometry import Point

    from hazard.pipeline.sdz import boundary_polygon

    scene = result.scene
    boundary = boundary_polygon(scene)
    centres: dict[str, list[np.ndarray]] = {}
    for sp in result.spots:  # the terrain's spots too (a target of the results, not of the scene)
        centres.setdefault(sp.target.name, []).append(np.asarray(sp.centroid, float))
    for spec in scene.targets:  # no spot: the target's centre
        centres.setdefault(spec.name, [np.asarray(spec.center_m, float)])
    out = []
    for t in result.targets:
        r = _lobe_radius_m(t)
        if not r > 0:
            continue
        if boundary is None or t.name not in centres:
            out.append(f"the keep-out lobe of {t.name!r} (diffuse NOHD {r:.4g} m) is not bounded: "
                       + ("the scene has no [range] boundary to contain it" if boundary is None else "its spot is not known"))
            continue
        pad = r / math.cos(math.pi / (4 * CIRCLE_SEGS))
        for c in centres[t.name]:
            if not boundary.contains(Point(float(c[0]), float(c[1])).buffer(pad, quad_segs=CIRCLE_SEGS)):
                out.append(f"the keep-out lobe of {t.name!r} (diffuse NOHD {r:.4g} m about its spot) reaches beyond the "
                           "range boundary")
                break
    return out


def zone_findings(result) -> list:
    """Every hazard zone that is not contained, each with why (see the module notes)."""
    return _sdz_findings(result) + _mirror_findings(result) + _lobe_findings(result)


def _headline(c, obs, zones, any_hazard) -> str:
    text = _observers_text(c)
    k = f"{len(zones)} hazard zone(s) NOT contained or beyond the range boundary"
    if obs and zones:
        return f"HAZARD at the observers and in the zones: {text}; {k}"
    if obs:
        return (f"HAZARD at the observers: {text}; "
                + ("every hazard zone is contained" if any_hazard else "no hazard zone"))
    if zones:
        return f"HAZARD in the zones: no listed observer at or above its limit ({text}), but {k}"
    if any_hazard:
        return (f"No listed observer at or above its limit ({text}); the hazard zones (NOHD > 0) are contained by "
                "backstops and within the range boundary")
    return f"No hazard: {text}, and every NOHD is 0"


def verdict(result) -> Verdict:
    """The verdict of ``result`` (a :class:`hazard.HazardResult`).

    Returns
    -------
    Verdict
        The headline (the same line on stdout, in report.json and on the review page), the
        two questions of the module notes, ``any_hazard``, the zones not contained and why,
        the counts and the plausibility warnings.
    """
    c = _observer_counts(result)
    obs = bool(c.hazardous or c.tracks_hazardous or c.flight_zones_exceeded)
    zones = zone_findings(result)
    any_hazard = bool(result.any_hazard or obs or zones)
    return Verdict(headline=_headline(c, obs, zones, any_hazard), hazard_at_observers=obs, hazard_zones=bool(zones),
                   any_hazard=any_hazard, zones=tuple(zones), observers=c, warnings=tuple(answer_warnings(result)))


def fails(v: Verdict, which: str) -> bool:
    """Whether ``--fail-on-hazard which`` fails on verdict ``v``: ``observers``, ``zones`` or ``any`` (either)."""
    if which not in FAIL_ON_CHOICES:
        raise ValueError(f"--fail-on-hazard={which!r}: expected one of {list(FAIL_ON_CHOICES)}")
    return {"observers": v.hazard_at_observers, "zones": v.hazard_zones,
            "any": v.hazard_at_observers or v.hazard_zones}[which]
