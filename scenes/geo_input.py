"""Geodetic positions in a scene file: every ``*_m`` position may be given as ``*_geo``.

In a site scene every position then goes into the *apparent* frame of refraction
(:mod:`scenes.geo`): the exact ENU point raised by k d^2 / (2 R), as the terrain is, so the
straight rays of the analysis see the geometry a refracted beam sees. ``conversions``
keep the exact ENU points.

``X_geo = [lat_deg, lon_deg, height_m]`` (read in ``site.crs``; the height in the site's
vertical datum) is converted exactly to the site's ENU frame and replaces ``X_m`` before the
scene is validated. ``X_geo = [lat_deg, lon_deg]`` (two numbers) stands on the terrain,
raised by the table's ``height_agl_m`` (the laser's aim by ``aim_agl_m``; default 0; observers
use their ``eye_height_m``).
Errors name the ``*_geo`` key; the conversions are kept for the report.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass, field
from typing import ClassVar, Literal

import numpy as np

from .dem import DemInfo
from .geo import GeoError, SiteFrame
from .spec import RANGE_SPAN_MAX_M, range_span_outlier

__all__ = ["Conversion", "FrameDescription", "GeoSite", "resolve_geo"]


def _frozen(v):
    """Nested lists as nested tuples (the values unchanged: an int stays an int)."""
    return tuple(_frozen(x) for x in v) if isinstance(v, (list, tuple)) else v


def _listed(v):
    """Nested tuples back to nested lists (as JSON writes them)."""
    return [_listed(x) for x in v] if isinstance(v, (list, tuple)) else v


@dataclass(frozen=True)
class Conversion:
    """One ``*_geo`` value converted to the site frame (report.json ``frame.converted[]``).

    Attributes
    ----------
    key : str
        The scene key as written, e.g. ``"laser.position_geo"``.
    given : tuple
        The value as written: ``(lat_deg, lon_deg(, height_m))`` [deg, deg, m], or a tuple of them.
    m : tuple
        The position(s) it became in the site frame: x, y(, z) [m], or a tuple of them.
    """

    key: str
    given: tuple
    m: tuple

    def __post_init__(self) -> None:
        object.__setattr__(self, "given", _frozen(self.given))
        object.__setattr__(self, "m", _frozen(self.m))

    def to_dict(self) -> dict:
        return {"key": self.key, "given": _listed(self.given), "m": _listed(self.m)}


@dataclass(frozen=True)
class FrameDescription:
    """The coordinate frame report.json's positions are in (report.json ``frame``): the
    scene's local frame (``kind`` and ``statement`` alone), or a site's
    (:meth:`scenes.geo.SiteFrame.describe`, with its DEM and conversions, :meth:`GeoSite.describe`).

    Attributes
    ----------
    kind : {"local", "site"}
        The scene's local metres, or an exact east-north-up frame on WGS 84.
    statement : str
        The frame in words.
    origin_deg_m : tuple of float or None
        The site origin: latitude, longitude [deg], height [m] in the site's vertical datum.
    origin_ellipsoidal_height_m : float or None
        The origin's height above the ellipsoid [m].
    vertical : str or None
        The vertical datum of input heights (``"ellipsoid"`` or ``"egm96"``).
    crs : str or None
        The CRS ``*_geo`` positions are read in.
    refraction_k : float or None
        The refraction coefficient k (unitless).
    earth_radius_m : float or None
        The earth radius R of the refraction rise k d^2 / (2 R) [m].
    laser_xy_m : tuple of float or None
        The laser's x, y in the site frame [m].
    dem : DemInfo or None
        The terrain file read (None: no DEM).
    converted : tuple of Conversion or None
        The ``*_geo`` values converted, in the order read (empty: none).

    Every field that is None is absent from the block (a local frame writes ``kind`` and ``statement`` only).
    """

    kind: Literal["local", "site"]
    statement: str
    origin_deg_m: tuple[float, ...] | None = None
    origin_ellipsoidal_height_m: float | None = None
    vertical: str | None = None
    crs: str | None = None
    refraction_k: float | None = None
    earth_radius_m: float | None = None
    laser_xy_m: tuple[float, ...] | None = None
    dem: DemInfo | None = None
    converted: tuple[Conversion, ...] | None = None

    ABSENT_WHEN_NONE: ClassVar[tuple[str, ...]] = ("origin_deg_m", "origin_ellipsoidal_height_m", "vertical", "crs", "refraction_k",
                                                   "earth_radius_m", "laser_xy_m", "dem", "converted")

    def to_dict(self) -> dict:
        out: dict = {"kind": self.kind, "statement": self.statement}
        for name in self.ABSENT_WHEN_NONE:
            v = getattr(self, name)
            if v is None:
                continue
            if name == "dem":
                out[name] = dict(v.__dict__)
            elif name == "converted":
                out[name] = [c.to_dict() for c in v]
            else:
                out[name] = list(v) if isinstance(v, tuple) else v
        return out

# table -> position stems that take a *_geo form (observers' points is a list of positions)
_STEMS = {"laser": ("position", "aim"), "target": ("center",), "occluder": ("center",), "terrain": ("center",),
          "observer": ("points", "start", "end", "origin", "center")}


@dataclass
class GeoSite:
    """The site frame of a scene, its terrain as built for placing points, and what was converted."""

    frame: SiteFrame
    heightfield: object = None  # scenes.geometry.Heightfield in the site frame (before re-centring)
    dem: object = None  # scenes.dem.DemInfo
    conversions: list = field(default_factory=list)
    on_terrain: set = field(default_factory=set)  # "path.stem" of positions placed on the (raised) terrain
    tracks: dict = field(default_factory=dict)  # observer track name -> (K, 3) lat, lon [deg], ellipsoidal height [m]

    @property
    def warnings(self) -> list:
        """Odd but usable inputs: a DTED (heights above mean sea level by its specification,
        MIL-PRF-89020B) read as ellipsoidal heights."""
        if self.dem is not None and self.dem.driver == "DTED" and self.frame.vertical == "ellipsoid":
            return [f"terrain.file={self.dem.file!r} is DTED, whose heights are above mean sea level (EGM96), but "
                    f"site.vertical = 'ellipsoid' reads them as heights above the ellipsoid (the geoid is tens of metres "
                    f"away): set vertical = 'egm96' if the file follows its specification"]
        return []

    def describe(self) -> FrameDescription:
        """The site frame as report.json's ``frame`` says it (:meth:`scenes.geo.SiteFrame.describe`,
        the DEM read and the conversions made)."""
        d = self.frame.describe()
        return FrameDescription(**{**d, "origin_deg_m": tuple(d["origin_deg_m"]), "laser_xy_m": tuple(d["laser_xy_m"])},
                                dem=self.dem, converted=tuple(Conversion(**c) for c in self.conversions))


def _tables(data: dict):
    """(kind, path, table) of every table that may hold positions."""
    if isinstance(data.get("laser"), dict):
        yield "laser", "laser", data["laser"]
    for key, kind in (("targets", "target"), ("occluders", "occluder"), ("observers", "observer")):
        for i, t in enumerate(data.get(key) if isinstance(data.get(key), list) else []):
            if isinstance(t, dict):
                yield kind, f"{key}[{i}]", t
    if isinstance(data.get("terrain"), dict):
        yield "terrain", "terrain", data["terrain"]


def _moving(data: dict):
    """(path, table, key) of the positions of things that move (absolute heights only):
    an aim track's aim points, a target track's centres, an observer track's positions,
    and the airspace zones' outlines."""
    laser = data.get("laser") if isinstance(data.get("laser"), dict) else {}
    if isinstance(laser.get("aim_track"), dict):
        yield "laser.aim_track", laser["aim_track"], "aim"
    for i, t in enumerate(data.get("targets") if isinstance(data.get("targets"), list) else []):
        if isinstance(t, dict) and isinstance(t.get("track"), dict):
            yield f"targets[{i}].track", t["track"], "center"
    for i, t in enumerate(data.get("observers") if isinstance(data.get("observers"), list) else []):
        if isinstance(t, dict) and "positions_geo" in t:
            yield f"observers[{i}]", t, "positions"
    air = data.get("airspace") if isinstance(data.get("airspace"), dict) else {}
    for i, z in enumerate(air.get("zones") if isinstance(air.get("zones"), list) else []):
        if isinstance(z, dict):
            yield f"airspace.zones[{i}]", z, "boundary"


def _geo_keys(data: dict) -> list:
    found = [f"{path}.{k}" for kind, path, t in _tables(data) for k in t if k.endswith("_geo") or k.endswith("_agl_m")]
    found += [f"{path}.{stem}_geo" for path, t, stem in _moving(data) if f"{stem}_geo" in t]
    if isinstance(data.get("range"), dict) and "boundary_geo" in data["range"]:
        found.append("range.boundary_geo")
    return found


def _rows(value, where: str, many: bool) -> np.ndarray:
    rows = value if many else [value]
    if (not isinstance(rows, list) or not rows or not all(isinstance(r, list) and len(r) in (2, 3) for r in rows)
            or not all(isinstance(x, (int, float)) and not isinstance(x, bool) for r in rows for x in r)):
        shape = "a list of [lat_deg, lon_deg(, height_m)]" if many else "[lat_deg, lon_deg, height_m] or [lat_deg, lon_deg]"
        raise GeoError(f"{where}: expected {shape}, got {value!r}")
    if len({len(r) for r in rows}) != 1:
        raise GeoError(f"{where}: expected all points with a height or all without, got {value!r}")
    a = np.asarray(rows, float)
    if not np.all(np.isfinite(a)):
        raise GeoError(f"{where}: expected finite numbers, got {value!r}")
    return a


def _on_terrain(site: GeoSite, lat, lon, agl, where: str) -> np.ndarray:
    """ENU of points at ``agl`` above the terrain at (lat, lon): the point's horizontal
    position depends on its height, so iterate (mm in two steps)."""
    hf, frame = site.heightfield, site.frame
    if hf is None:
        raise GeoError(f"{where}: two numbers [lat_deg, lon_deg] stand on the terrain, and the scene has none; "
                       f"give [lat_deg, lon_deg, height_m]")
    h = np.full(len(lat), frame.h0_m)
    for _ in range(4):
        p = frame.enu_m(lat, lon, h)
        if not np.all(hf.contains_xy(p[:, 0], p[:, 1])):
            raise GeoError(f"{where}: a point lies outside the terrain's extent")
        z = hf.height_at(p[:, 0], p[:, 1]) - frame.refraction_rise_m(p[:, 0], p[:, 1]) + agl
        h = frame.geodetic(np.stack([p[:, 0], p[:, 1], z], -1))[2]
    p[:, 2] = z + frame.refraction_rise_m(p[:, 0], p[:, 1])
    return p


def _convert(site: GeoSite, value, where: str, many: bool, agl: float, keep_z: bool) -> list:
    a = _rows(value, where, many)
    lat, lon, h = site.frame.input_to_geodetic(a, where)
    if a.shape[1] == 3:
        p = site.frame.enu_m(lat, lon, site.frame.ellipsoidal_height_m(lat, lon, h))
    else:
        p = _on_terrain(site, lat, lon, 0.0 if keep_z else agl, where)
    out = p.tolist()
    site.conversions.append({"key": where, "given": value, "m": out if many else out[0]})
    return out if many else out[0]


def _agl(t: dict, key: str, path: str):
    v = t.pop(key, None)
    if v is not None and (not isinstance(v, (int, float)) or isinstance(v, bool) or not 0 <= v <= 1e5):
        raise GeoError(f"{path}.{key}: expected a height above the terrain of 0 to 1e5 m, got {v!r}")
    return v


def _resolve_table(site: GeoSite, kind: str, path: str, t: dict) -> None:
    """Replace the table's ``*_geo`` positions by ``*_m``; a two-number one stands on the
    terrain raised by its height key (``height_agl_m``; the laser's aim ``aim_agl_m``)."""
    agl_keys = {"position": "height_agl_m", "center": "height_agl_m", "aim": "aim_agl_m"} if kind != "observer" else {}
    agl = {k: _agl(t, k, path) for k in set(agl_keys.values()) if kind in ("laser", "target", "occluder")}
    for stem in _STEMS[kind]:
        key = f"{stem}_geo"
        if key not in t:
            continue
        if f"{stem}_m" in t:
            raise GeoError(f"{path}: give {stem}_m or {key}, not both")
        keep_z = kind == "observer" and t.get("eye_height_m") is not None
        if kind == "observer" and not keep_z and isinstance(t[key], list) and _two_numbers(t[key], stem == "points"):
            raise GeoError(f"{path}.{key}: two numbers [lat_deg, lon_deg] stand on the terrain: give the group's eye_height_m "
                           f"(or [lat_deg, lon_deg, height_m])")
        if keep_z and _rows(t[key], f"{path}.{key}", stem == "points").shape[1] == 3:  # two heights: one would be dropped
            raise GeoError(f"{path}.{key}: three numbers [lat_deg, lon_deg, height_m] place the points by their height, and "
                           f"the group's eye_height_m would replace it: give [lat_deg, lon_deg] to stand at eye height, or "
                           f"drop eye_height_m")
        height = 0.0
        if _two_numbers(t[key], stem == "points"):  # a height above the terrain is used only here; else said below
            site.on_terrain.add(f"{path}.{stem}")
            height = agl.pop(agl_keys.get(stem), None) or 0.0
        t[f"{stem}_m"] = _convert(site, t.pop(key), f"{path}.{key}", stem == "points", float(height), keep_z)
    for k, v in agl.items():
        if v is not None:
            raise GeoError(f"{path}.{k}: only with a two-number {'aim' if k == 'aim_agl_m' else 'position/center'}_geo "
                           f"([lat_deg, lon_deg] on the terrain)")


def _two_numbers(value, many: bool) -> bool:
    rows = value if many else [value]
    return isinstance(rows, list) and bool(rows) and all(isinstance(r, list) and len(r) == 2 for r in rows)


def _raise_points(site: GeoSite, data: dict) -> None:
    """The apparent frame of refraction: the laser's and the objects' positions with an
    absolute height go up by k d^2 / (2 R) as the terrain does (what stands on the terrain
    is there already; observers are raised as their points are made)."""
    for kind, path, t in _tables(data):
        if kind not in ("laser", "target", "occluder"):
            continue
        for stem in _STEMS[kind]:
            v = t.get(f"{stem}_m")
            if f"{path}.{stem}" in site.on_terrain or not (isinstance(v, list) and len(v) == 3):
                continue
            if all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in v):
                t[f"{stem}_m"] = _raised(site, v)
    for _path, t, stem in _moving(data):  # an aim track's points and a target track's centres (observer tracks: as made)
        rows = t.get(f"{stem}_m")
        if stem in ("aim", "center") and isinstance(rows, list):
            t[f"{stem}_m"] = [_raised(site, v) if _numbers3(v) else v for v in rows]


def _numbers3(v) -> bool:
    return isinstance(v, list) and len(v) == 3 and all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in v)


def _raised(site: GeoSite, v) -> list:
    return [v[0], v[1], v[2] + float(site.frame.refraction_rise_m(v[0], v[1]))]


def _boundary(site: GeoSite, rng: dict) -> None:
    if "boundary_m" in rng:
        raise GeoError("range: give boundary_m or boundary_geo, not both")
    rng["boundary_m"] = _outline(site, rng.pop("boundary_geo"), "range.boundary_geo")


def _resolve_moving(site: GeoSite, data: dict) -> None:
    """Moving things' ``*_geo`` rows to ``*_m`` (three numbers: absolute heights; outlines:
    two). An observer track keeps its geodetic rows too (``site.tracks``): it is
    interpolated along the geodesic, not the chord (:mod:`scenes.motion`)."""
    for path, t, stem in _moving(data):
        key = f"{stem}_geo"
        if key not in t:
            continue
        if f"{stem}_m" in t:
            raise GeoError(f"{path}: give {stem}_m or {key}, not both")
        if stem == "boundary":
            p = _outline(site, t.pop(key), f"{path}.{key}")
            t["boundary_m"] = p
            continue
        a = _rows(t[key], f"{path}.{key}", True)
        if a.shape[1] != 3:
            raise GeoError(f"{path}.{key}: a moving position needs its height: [[lat_deg, lon_deg, height_m], ...]")
        lat, lon, h = site.frame.input_to_geodetic(a, f"{path}.{key}")
        h = site.frame.ellipsoidal_height_m(lat, lon, h)
        if stem == "positions":
            site.tracks[str(t.get("name"))] = np.column_stack([lat, lon, h])
        t[f"{stem}_m"] = _convert(site, t.pop(key), f"{path}.{key}", True, 0.0, False)


def _outline(site: GeoSite, value, where: str) -> list:
    """[[lat, lon], ...] to [[x, y], ...] in the site frame (at the origin's height)."""
    a = _rows(value, where, True)
    lat, lon, _ = site.frame.input_to_geodetic(a, where)
    p = site.frame.enu_m(lat, lon, np.full(len(lat), site.frame.h0_m))
    out = p[:, :2].tolist()
    far = range_span_outlier(out) if where == "range.boundary_geo" else None
    if far is not None:
        raise GeoError(f"{where}: the range spans {far[1] / 1e3:.4g} km (point {far[0]} = {a[far[0]].tolist()} is the "
                       f"farthest from the others); expected at most {RANGE_SPAN_MAX_M / 1e3:g} km across: a latitude or "
                       f"longitude typed wrong? (leave out [range] for no boundary)")
    site.conversions.append({"key": where, "given": a.tolist(), "m": out})
    return out


def _laser_xy(frame: SiteFrame, laser: dict) -> tuple:
    """The laser's horizontal ENU position, which the refraction rise is measured from: exact
    for a point given with its height; for one on the terrain (not built yet) at the
    origin's height, which moves it h d / R (0.5 m for 300 m at 10 km: the rise 10 km away
    then moves 0.1 mm)."""
    if isinstance(laser.get("position_m"), list) and len(laser["position_m"]) == 3:
        return float(laser["position_m"][0]), float(laser["position_m"][1])
    a = _rows(laser.get("position_geo"), "laser.position_geo", False)
    lat, lon, h = frame.input_to_geodetic(a, "laser.position_geo")
    h = frame.ellipsoidal_height_m(lat, lon, h) if a.shape[1] == 3 else np.full(1, frame.h0_m)
    p = frame.enu_m(lat, lon, h)
    return float(p[0, 0]), float(p[0, 1])


def _terrain(site: GeoSite, data: dict, base_dir, validate) -> None:
    from .geometry import terrain_heightfield
    from .spec import TerrainSpec

    t = data["terrain"]
    _resolve_table(site, "terrain", "terrain", t)
    spec = validate(TerrainSpec, t, "terrain")
    if spec.kind == "dem":
        from .dem import dem_heightfield

        site.heightfield, site.dem = dem_heightfield(spec, site.frame, base_dir, spec.center_m[:2])
    else:
        site.heightfield = terrain_heightfield(spec, base_dir)


def resolve_geo(data: dict, base_dir, validate) -> tuple[dict, GeoSite | None]:
    """``data`` with every ``*_geo`` position converted to ``*_m`` in the site frame, and the
    site (None without a ``[site]`` table). ``validate(cls, value, path)`` validates a table."""
    keys = _geo_keys(data)
    if "site" not in data:
        if keys:
            raise GeoError(f"{keys[0]}: a geodetic position or height above the terrain needs a [site] table "
                           f"(origin = [lat_deg, lon_deg, height_m])")
        return data, None
    from .spec import SiteSpec

    data = copy.deepcopy(data)
    s = validate(SiteSpec, data["site"], "site")
    laser = data.get("laser") if isinstance(data.get("laser"), dict) else {}
    frame = SiteFrame(tuple(s.origin), s.vertical, s.crs, s.refraction_k)
    if "position_m" in laser or "position_geo" in laser:
        frame.laser_xy_m = _laser_xy(frame, laser)
    site = GeoSite(frame)
    if isinstance(data.get("terrain"), dict):
        _terrain(site, data, base_dir, validate)
    for kind, path, t in _tables(data):
        if kind != "terrain":
            _resolve_table(site, kind, path, t)
    if isinstance(data.get("range"), dict) and "boundary_geo" in data["range"]:
        _boundary(site, data["range"])
    _resolve_moving(site, data)
    _raise_points(site, data)
    return data, site
