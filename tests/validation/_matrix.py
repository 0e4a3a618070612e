"""The path matrix: every validation case also runs with nothing that matters changed.

"A result must not change when nothing that matters changes" (issue 29, item 6). A case
is a scene (built by the validation modules' own helpers, so it is the scene their
independent references check); each *variant* changes something that must not matter:

``occluder``
    an unrelated box far away: behind the laser, beyond a plane that separates it from
    every point of the scene (laser, aim, targets with their extent, observers, tracks)
    and that every beam direction of the scene leaves behind (``n . d < 0``), so no beam,
    no reflected path and no line of sight reaches it;
``second_target``
    a second (Lambertian) target the beam never lights, placed the same way and facing
    the scene;
``ground``
    flat ground far below every point of the scene (a scene that has terrain already is
    not given a second one). Where a beam direction of the scene goes down onto that
    ground, the ground's light is real and the variant's ground is black (Lambertian,
    reflectance 0): it still tests the terrain's ray paths and shadowing;
``backend``
    the other ray backend (``numpy`` instead of the default ``embree``);
``moved``
    the whole scene rigidly rotated and moved: every position and direction of the scene
    text (laser, aim, targets' centres, normals and tangents, occluders, observers, aim
    and target tracks). A scene where "up" matters (terrain, sectors, eye heights,
    shells, range boundaries, slumps toward 'up', slew rates in bearing and elevation)
    turns about the vertical only (by
    180 deg with terrain, which maps the terrain grid and its triangles onto themselves)
    and the sector's bearings turn with it.

Three parts are compared, each its own test: every observer's result (peak and static
irradiance, radiant exposure, verdict; and over time, when things move, each fixed
observer's and track's peak, exposure and verdict), every original target's spot (power, peak
irradiance, specular NOHD), and the direct beam's surface danger zone (NOHD, reach,
hazardous half-width, contained or not; its area lies in the map's plane, which a tilted
scene changes). Each value must equal the base run's to ``RTOL`` = 1e-6
relative, plus the sampling error both runs state where the engine states one (the spot
power's ``spot_power_error_w``), plus an absolute floor for values that are zero in one
run and round-off in the other: ``ATOL_MPE`` = 1e-9 x the MPE for observers and the
target's peak irradiance (a billionth of the MPE cannot change a verdict), ``ATOL_POWER``
= 1e-12 x the laser power for a spot's power. A case registers with one line::

    register("mirror-on-axis", lambda tmp: some_module._scene(...), fast=True)

(``tmp``: a fresh directory for cases that write material files.)

The harness never reads the engine's intermediate results: the references are the base
run's own outputs (a metamorphic test), the geometry is numpy.
"""

from __future__ import annotations

import copy
import math
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

import hazard
import scenes

RTOL = 1e-6
ATOL_MPE = 1e-9
ATOL_POWER = 1e-12  # x the laser power: the floor of a spot's power (an unlit target's Gaussian tail is round-off)
VARIANTS = ("occluder", "second_target", "ground", "backend", "moved")
CURVED_XFAIL = "issue 29 curved targets on the ray path"


class NotApplicable(Exception):
    """The variant cannot be built for this scene without changing what matters."""


@dataclass(frozen=True)
class Case:
    """A registered validation scene: ``build(tmp_path)`` returns a :class:`scenes.Scene`."""

    name: str
    build: Callable
    fast: tuple = ()  # the variants in the default run (the rest are slow)
    variants: tuple = VARIANTS  # the variants that apply (e.g. no second ground under terrain)
    xfail: dict = field(default_factory=dict)  # variant (every part) or (variant, part) -> reason (strict)


CASES: dict = {}


def register(name, build, *, fast=False, xfail=None, without=()):
    """Register a validation case (one line per case). ``fast``: True (every variant in
    the default run) or the variants that are; ``xfail``: {variant or (variant, part):
    reason} for known engine defects (strict xfails: a fix makes them fail); ``without``:
    variants that do not apply (said here, so a variant that cannot be built for a
    registered case is a failure, never a silent skip)."""
    if name in CASES:
        raise ValueError(f"case {name!r} registered twice")
    fast = VARIANTS if fast is True else tuple(fast or ())
    unknown = (set(fast) | set(without)) - set(VARIANTS)
    if unknown:
        raise ValueError(f"case {name!r}: {sorted(unknown)} are not variants (expected some of {VARIANTS})")
    CASES[name] = Case(name, build, fast, tuple(v for v in VARIANTS if v not in without), dict(xfail or {}))


# --------------------------------------------------------------------------- geometry of a scene's data


def _u(v):
    v = np.asarray(v, float)
    return v / np.linalg.norm(v)


def _observer_points(ob):
    pts = []
    for key in ("points_m", "positions_m"):
        pts += [np.asarray(p, float) for p in ob.get(key) or ()]
    for key in ("start_m", "end_m", "center_m"):
        if ob.get(key) is not None:
            pts.append(np.asarray(ob[key], float))
    if ob.get("velocity_m_s") is not None:
        pts.append(np.asarray(ob["start_m"], float) + np.asarray(ob["velocity_m_s"], float) * ob["duration_s"])
    if ob.get("origin_m") is not None:
        o, u, v = (np.asarray(ob[k], float) for k in ("origin_m", "u_m", "v_m"))
        pts += [o + i * u + j * v for i in (0, 1) for j in (0, 1)]  # u_m, v_m: the grid's sides
    if ob.get("radius_m") is not None:
        c, r = np.asarray(ob["center_m"], float), ob["radius_m"]
        pts += [c + s * r * e for s in (-1, 1) for e in np.eye(3)]
    return pts


def key_points(data):
    """Every point a path of the scene may join (N, 3): laser, aim(s), the targets' and
    occluders' extents, observers (layouts' corners, tracks)."""
    la = data["laser"]
    pts = [np.asarray(la["position_m"], float)]
    if la.get("aim_m") is not None:
        pts.append(np.asarray(la["aim_m"], float))
    pts += [np.asarray(p, float) for p in (la.get("aim_track") or {}).get("aim_m") or ()]
    for t in data.get("targets", []) + data.get("occluders", []):
        c = np.asarray(t.get("center_m", [0.0, 0.0, 0.0]), float)
        if t.get("size_m") is None:
            raise NotApplicable(f"{t.get('name', 'a mesh')}: a mesh's extent is not read here")
        ext = math.hypot(*t["size_m"]) * float(t.get("scale", 1.0))
        centres = [c] + [np.asarray(p, float) for p in (t.get("track") or {}).get("center_m") or ()]
        pts += [q + s * ext * e for q in centres for s in (-1, 1) for e in np.eye(3)]
    for ob in data.get("observers", []):
        pts += _observer_points(ob)
    return np.array(pts)


def beam_directions(data):
    """Unit directions the laser may point in (nominal aim, aim track, sector corners)."""
    la = data["laser"]
    p = np.asarray(la["position_m"], float)
    dirs = [_u(la["direction"]) if la.get("direction") is not None else _u(np.asarray(la["aim_m"], float) - p)]
    dirs += [_u(np.asarray(a, float) - p) for a in (la.get("aim_track") or {}).get("aim_m") or ()]
    dirs += _slew_directions(la, dirs[0])
    sec = la.get("sector")
    if sec:
        for az in np.linspace(*sec["azimuth_deg"], 9):
            for el in sec["elevation_deg"]:
                a, e = math.radians(az), math.radians(el)
                dirs.append(np.array([math.sin(a) * math.cos(e), math.cos(a) * math.cos(e), math.sin(e)]))
    return np.array(dirs)


def _slew_directions(la, d0):
    """Directions of an aim track given by rates (bearing clockwise from +y, elevation)
    over its times_s, every 1/64 of the span."""
    tr = la.get("aim_track") or {}
    if tr.get("azimuth_rate_deg_s") is None and tr.get("elevation_rate_deg_s") is None:
        return []
    t = np.linspace(tr["times_s"][0], tr["times_s"][-1], 65) - tr["times_s"][0]
    az = math.atan2(d0[0], d0[1]) + np.radians(tr.get("azimuth_rate_deg_s") or 0.0) * t
    el = math.asin(np.clip(d0[2], -1, 1)) + np.radians(tr.get("elevation_rate_deg_s") or 0.0) * t
    return list(np.stack([np.sin(az) * np.cos(el), np.cos(az) * np.cos(el), np.sin(el)], 1))


def _far_spot(data, standoff=1.0):
    """A point behind every beam direction and beyond every key point: returns (point,
    unit direction n from the scene towards it). The plane n . x = n . point - margin
    separates it from the scene, and every beam ray leaves that plane behind."""
    d = beam_directions(data)
    n = -_u(d.mean(axis=0))
    cone = float(np.max(d @ n))
    pointing = float(data["laser"].get("pointing_error_rad") or 0.0) * float(data["laser"].get("pointing_error_sigmas") or 1.0)
    if cone >= -math.sin(min(pointing + 0.05, 1.0)):
        raise NotApplicable(f"the beam directions span too wide a cone (max n.d = {cone:.3f}) to put anything behind them")
    pts = key_points(data)
    laser = np.asarray(data["laser"]["position_m"], float)
    span = float(np.ptp(pts, axis=0).max())
    reach = float(np.max((pts - laser) @ n))
    return laser + n * (reach + standoff * (0.5 * span + 50.0)), n


# --------------------------------------------------------------------------- variants


def add_occluder(data):
    c, _ = _far_spot(data)
    data.setdefault("occluders", []).append({"name": "unrelated-box", "shape": "box", "center_m": c.tolist(),
                                             "size_m": [3.0, 2.0, 4.0]})
    return data


def add_second_target(data):
    c, n = _far_spot(data, standoff=1.5)
    t = np.cross(n, [0.0, 0.0, 1.0]) if abs(n[2]) < 0.9 else np.cross(n, [1.0, 0.0, 0.0])
    data["targets"].append({"name": "unlit-plate", "shape": "plate", "center_m": c.tolist(), "normal": (-n).tolist(),
                            "tangent": _u(t).tolist(), "size_m": [2.0, 2.0],
                            "material": {"model": "lambertian", "reflectance": 0.9}})
    return data


def add_ground(data):
    if data.get("terrain") is not None:
        raise NotApplicable("the scene has terrain already")
    pts = key_points(data)
    span = float(np.ptp(pts, axis=0).max())
    depth = max(100.0, 0.5 * span)
    z = float(pts[:, 2].min()) - depth
    lo, hi = pts[:, :2].min(axis=0), pts[:, :2].max(axis=0)
    extent = 0.5 * float((hi - lo).max()) + depth
    ground = {"kind": "flat", "center_m": [*(0.5 * (lo + hi)).tolist(), z], "extent_m": extent, "resolution_m": extent / 10.0}
    if np.any(beam_directions(data)[:, 2] < 0) or data["laser"].get("pointing_error_rad"):
        ground["material"] = {"model": "lambertian", "reflectance": 0.0}  # a beam lands on it: its light is real
    data["terrain"] = ground
    return data


def _up_matters(data):
    la = data["laser"]
    slump = any((t.get("material") or {}).get("melt_tilt_deg") for t in data["targets"])
    rates = any((la.get("aim_track") or {}).get(k) is not None for k in ("azimuth_rate_deg_s", "elevation_rate_deg_s"))
    return bool(data.get("terrain") or la.get("sector") or data.get("range") or data.get("airspace") or slump or rates
                or any(ob.get("eye_height_m") is not None or ob.get("radius_m") is not None for ob in data.get("observers", [])))


_POINTS = {"position_m", "aim_m", "center_m", "points_m", "start_m", "end_m", "origin_m", "positions_m"}
_DIRECTIONS = {"direction", "normal", "tangent", "u_m", "v_m", "velocity_m_s"}
_SKIP = {"material", "back", "history", "terrain", "sector", "range", "size_m", "optics", "uncertainty", "analysis",
         "exposure", "atmosphere", "motion", "airspace", "site"}


def _transform(node, Q, T):
    """Rotate (Q) and move (T) every point and direction below ``node`` in place."""
    if isinstance(node, list):
        for x in node:
            _transform(x, Q, T)
        return
    if not isinstance(node, dict):
        return
    for key, val in node.items():
        if key in _SKIP:
            continue
        if key in _POINTS or key in _DIRECTIONS:
            arr = np.asarray(val, float)
            if arr.shape[-1:] != (3,):
                raise NotApplicable(f"{key}={val!r}: not a 3-vector")
            new = arr @ Q.T + (T if key in _POINTS else 0.0)
            node[key] = new.tolist()
        elif isinstance(val, (dict, list)):
            _transform(val, Q, T)


def move_rigidly(data, angles=(0.7, -0.4, 1.9), shift_m=(1234.5, -678.25, 42.0)):
    """Rotate the whole scene by the Euler angles (z, y, x) [rad] and shift it [m]."""
    if data.get("site") is not None:
        raise NotApplicable("a geodetic site fixes the frame")
    T = np.asarray(shift_m, float)
    if _up_matters(data):
        yaw = math.pi if data.get("terrain") else angles[0]
        Q = _rot_z(yaw)
        _move_up_dependent(data, yaw, Q, T)
    else:
        Q = _rot_z(angles[0]) @ _rot_y(angles[1]) @ _rot_x(angles[2])
    for shape in [*data.get("targets", []), *data.get("occluders", [])]:  # a default frame turns with the scene too
        shape.setdefault("normal", [0.0, 0.0, 1.0])
        shape.setdefault("tangent", [1.0, 0.0, 0.0])
    _transform(data, Q, T)
    return data


def _move_up_dependent(data, yaw, Q, T):
    """The parts of a scene tied to the vertical turn about it: terrain, sector, range."""
    ter = data.get("terrain")
    if ter is not None:
        if ter["kind"] not in ("flat", "hill", "valley"):
            raise NotApplicable(f"terrain kind {ter['kind']!r} is a fixed grid")
        ter["center_m"] = (Q @ np.asarray(ter.get("center_m", [0.0, 0.0, 0.0]), float) + T).tolist()
    sec = data["laser"].get("sector")
    if sec:
        sec["azimuth_deg"] = [a - math.degrees(yaw) for a in sec["azimuth_deg"]]  # bearings run clockwise
    rng = data.get("range")
    if rng:
        rng["boundary_m"] = [(Q[:2, :2] @ np.asarray(p, float) + T[:2]).tolist() for p in rng["boundary_m"]]


def _rot_z(a):
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def _rot_y(a):
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def _rot_x(a):
    c, s = math.cos(a), math.sin(a)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


_EDIT = {"occluder": add_occluder, "second_target": add_second_target, "ground": add_ground, "moved": move_rigidly}


def variant_scene(scene, variant):
    """(scene, backend) of ``variant`` of a loaded base scene."""
    if variant == "backend":
        return scene, "numpy"
    data = copy.deepcopy(scene.source_data)
    return scenes.from_data(_EDIT[variant](data), source=f"{variant}-variant", base_dir=scene.base_dir), "embree"


# --------------------------------------------------------------------------- comparison

PARTS = ("observers", "targets", "beam")


def summary(res, target_names):
    """The invariant outputs of a run: {part: {quantity: (values, allowed error)}}, per
    observer and per original target. The allowed error is 0 except for the spot power,
    whose sampling error the engine states (``spot_power_error_w``, a bound)."""
    o = res.observers
    zero = np.zeros(len(o))
    obs = {
        "peak_irradiance_w_m2": (np.asarray(o.peak_irradiance_w_m2, float), zero),
        "static_irradiance_w_m2": (np.asarray(o.static_irradiance_w_m2, float), zero),
        "radiant_exposure_j_m2": (np.asarray(o.radiant_exposure_j_m2, float), zero),
        "hazardous": (np.asarray(res.hazardous, bool), zero),
    }
    obs.update(_motion(res))
    by_name = {t.name: t for t in res.targets}
    ts = [by_name[n] for n in target_names]

    def col(key):
        return np.array([np.nan if getattr(t, key) is None else getattr(t, key) for t in ts], float)

    tgt = {
        "spot_power_w": (col("spot_power_w"), col("spot_power_error_w")),
        "peak_irradiance_w_m2": (col("peak_irradiance_w_m2"), np.zeros(len(ts))),
        "specular_nohd_static_m": (col("specular_nohd_static_m"), np.zeros(len(ts))),
    }
    sdz = res.sdz

    def one(key):
        v = None if sdz is None else getattr(sdz, key)
        return np.array([np.nan if v is None else v], bool if isinstance(v, bool) else float), np.zeros(1)

    beam = {f"sdz {k}": one(k) for k in ("nohd_m", "max_range_m", "hazard_half_width_m", "contained")}
    return {"observers": obs, "targets": tgt, "beam": beam}


def _motion(res):
    """Each evaluated path over time (fixed observers and tracks, in order): its peak
    irradiance, radiant exposure and verdict, under keys 'motion ...' (the names: key
    'motion names')."""
    paths = [] if res.motion is None else res.motion.paths
    if not paths:
        return {}
    zero = np.zeros(len(paths))

    def col(key, kind=float):
        return np.array([getattr(p.summary, key) for p in paths], kind), zero

    return {"motion peak_irradiance_w_m2": col("peak_irradiance_w_m2"), "motion radiant_exposure_j_m2":
            col("radiant_exposure_j_m2"), "motion hazardous": col("hazardous", bool),
            "motion names": ([f"{p.kind} {p.name}" for p in paths], zero)}


def differences(base, other, floors, who):
    """Every value of ``other`` (one part of :func:`summary`) that differs from ``base`` by
    more than RTOL relative plus the errors both runs state plus the floor (``floors``:
    quantity -> absolute floor): lines 'quantity [who]: base -> variant'."""
    lines = []
    if base.keys() != other.keys():
        return [f"quantities: {sorted(base)} -> {sorted(other)}"]
    for key, (b, eb) in base.items():
        v, ev = other[key]
        if key == "motion names":
            lines += [] if list(b) == list(v) else [f"motion paths: {b} -> {v}"]
            continue
        labels, floor = who, floors.get(key, 0.0)
        if key.startswith("motion "):
            labels, floor = base["motion names"][0], floors.get(key[len("motion "):], 0.0)
        if b.dtype == bool:
            bad = b != v
        else:
            same = (np.isnan(b) & np.isnan(v)) | (b == v)  # equal, an unbounded NOHD (inf) included
            with np.errstate(invalid="ignore"):  # inf - inf: the "same" above
                allowed = RTOL * np.maximum(np.abs(b), np.abs(v)) + eb + ev + floor
                bad = ~same & ~(np.abs(v - b) <= allowed)
        lines += [f"{key} [{labels[i]}]: {b[i]!r} -> {v[i]!r}" for i in np.flatnonzero(bad)]
    return lines


_RUNS: dict = {}


def run_pair(case, variant, tmp_path):
    """Summaries of the base and the variant run of a case (each computed once per
    session: the observer and the target checks share them), with names and floors."""
    key = (case.name, variant)
    if key not in _RUNS:
        scene = case.build(tmp_path)
        names = [t["name"] for t in scene.source_data["targets"]]
        base = hazard.analyze(scene)
        try:
            vscene, backend = variant_scene(scene, variant)
            other = hazard.analyze(vscene, backend=backend)
        except NotApplicable as exc:
            _RUNS[key] = exc
            raise
        floors = {"peak_irradiance_w_m2": ATOL_MPE * float(base.mpe_w_m2),  # observers' and targets' peaks
                  "static_irradiance_w_m2": ATOL_MPE * float(base.mpe_w_m2),
                  "radiant_exposure_j_m2": ATOL_MPE * float(base.mpe_radiant_exposure_j_m2),
                  "spot_power_w": ATOL_POWER * float(base.beam_power_w)}
        _RUNS[key] = (summary(base, names), summary(other, names), base.observers.labels, names, floors,
                      len(base.observers), len(other.observers))
    got = _RUNS[key]
    if isinstance(got, NotApplicable):
        raise got
    return got


def check(case, variant, part, tmp_path):
    """The differences of one part ('observers' or 'targets') of a case's variant."""
    base, other, labels, names, floors, n_base, n_other = run_pair(case, variant, tmp_path)
    if n_base != n_other:
        return [f"observer count: {n_base} -> {n_other}"]
    who = {"observers": labels, "targets": names, "beam": ["direct beam"]}[part]
    return differences(base[part], other[part], floors, who)
