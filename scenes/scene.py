"""Load a TOML scene, validate it, and convert it once to SI numpy arrays.

Coordinates are re-centred on a float64 local origin (the first target's centre) so that
Embree's float32 arithmetic is accurate; ``Scene.offset_m`` keeps the origin and every
output is reported in the file's own coordinates.
"""

from __future__ import annotations

import copy
import hashlib
import json
import math
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path

import numpy as np
from pydantic import ValidationError

import brdfmodels
from brdfmodels.fileio import check_limit, parse_toml, read_input_text

from .geometry import Heightfield, Mesh, direction_in_sector, input_path, observer_points, shape_mesh, terrain_heightfield
from .observers import BLOCK, GroupPoints, Observers, grid_generator, stored
from .spec import SceneSpec

__all__ = ["Scene", "Target", "Observers", "SceneError", "load", "loads", "from_data", "examples", "example_path", "json_schema"]


class SceneError(ValueError):
    """A scene that cannot be used; the message names the field path and what was expected."""


def _path(loc) -> str:
    out = ""
    for part in loc:
        if isinstance(part, int):
            out += f"[{part}]"
        elif isinstance(part, str) and not part.startswith(("function-", "literal[")) and part not in ("list", "float", "int"):
            out += ("." if out else "") + part
    return out or "(scene)"


def format_validation_error(exc: ValidationError, source: str) -> str:
    """One line for a pydantic validation error of ``source``: the first error's field path,
    message and value, then how many more (the next three shown)."""
    errs = exc.errors(include_url=False)
    msgs = []
    for e in errs:
        where = _path(e["loc"])
        msg = e["msg"].removeprefix("Value error, ")
        if e["type"] == "extra_forbidden":
            msg = "unknown key (check its spelling)"
        inp = e.get("input")
        shown = "" if isinstance(inp, dict) or e["type"] in ("missing", "extra_forbidden") else f" (got {inp!r})"
        msgs.append(f"{where}: {msg}{shown}")
    more = f" (and {len(msgs) - 1} more: {'; '.join(msgs[1:4])})" if len(msgs) > 1 else ""
    return f"{source}: {msgs[0]}{more}"


@dataclass
class Target:
    """A target converted for analysis (local coordinates)."""

    name: str
    index: int
    mesh: Mesh
    material: brdfmodels.BRDFModel
    groove_angle_rad: float
    normal: np.ndarray
    tangent: np.ndarray
    center_m: np.ndarray
    spec: object
    history: brdfmodels.History | None = None
    back_material: brdfmodels.BRDFModel | None = None  # the back face's material (static), if given
    slump: "Slump | None" = None  # how melting tilts the front face's normal, if the material says

    @property
    def is_dynamic(self) -> bool:
        return self.material.is_dynamic


@dataclass(frozen=True)
class Slump:
    """How melting moves the specular peak (material ``melt_tilt_deg``,
    ``melt_tilt_direction``, ``melt_wander_deg``): the mean normal tilts by
    ``tilt_rad x melt fraction`` towards ``direction`` (a unit vector perpendicular to the
    nominal normal, world frame), and wanders within ``wander_rad`` of that once melting
    has begun."""

    tilt_rad: float
    direction: np.ndarray
    wander_rad: float


@dataclass
class Scene:
    """A validated scene in SI units, local coordinates (``world = local + offset_m``)."""

    spec: SceneSpec
    source: str
    base_dir: Path | None
    text_sha256: str
    offset_m: np.ndarray
    laser_position_m: np.ndarray
    laser_direction: np.ndarray
    targets: list
    occluders: list = field(default_factory=list)
    terrain: Heightfield | None = None
    observers: Observers | None = None
    # the terrain as a reflector of the beam that lands on it (index: its object id in the ray scene)
    terrain_target: Target | None = None
    # plausibility warnings (values typical of unit mistakes); not errors
    warnings: list = field(default_factory=list)
    # the [site]: exact ENU frame, DEM and the geodetic positions converted (None: a local frame)
    site: object = None
    # the scene's keys as given (parsed TOML), to load it again elsewhere (a Dask worker)
    source_data: dict | None = field(default=None, repr=False)
    # values written with a unit: key path as written -> {as_written, key, value, unit} (scenes.quantities)
    units_as_written: dict = field(default_factory=dict)
    # the beam's diameter and divergence as given and converted to 1/e full angle (scenes.conventions)
    beam_conventions: dict | None = None

    @property
    def notes(self) -> list:
        """Notes every answer carries about how the scene was read (the beam's convention)."""
        from .conventions import beam_notes

        return beam_notes(self.beam_conventions)

    @property
    def name(self) -> str:
        return self.spec.name

    def to_world(self, p):
        return np.asarray(p, float) + self.offset_m

    def echo(self) -> dict:
        """The validated scene as plain data (for reports)."""
        return json.loads(self.spec.model_dump_json())


def _identity_factor(model):
    """Scale a static material by the reflectance factor R(t)/R(0) carried as the state."""
    # identity on [0, 1000]: factors above 1 are real (cleaning raises copper's reflectance)
    table = brdfmodels.StateTable([0.0, 1000.0], [0.0, 1000.0], "reflectance_factor", extrapolation="error")
    return brdfmodels.Scaled(model, table)


# incidence angles [deg] at which a material's hemispherical reflectance must be <= 1: the
# whole range to 89 deg (fitted SH models extrapolate at grazing incidence, where a floor
# of f~ = cos_i cos_r f_r grows as 1/cos_i: the old copper_glossy reached 4.4 at 89 deg)
DHR_INCIDENCES_DEG = (0.0, 20.0, 40.0, 60.0, 70.0, 80.0, 85.0, 89.0)
# azimuths of incidence [deg] from the material tangent (grooves); 90 only for an
# anisotropic material
DHR_AZIMUTHS_DEG = (0.0, 90.0)
DHR_TOLERANCE = 0.01  # allowed above 1, plus the quadrature's own error estimate
_DHR_CACHE: dict = {}


def _dhr_states(model):
    """Every state where :func:`_worst_dhr` looks: all nodes of the model's state table
    (clipped to its range) and the range's ends; None for a static model. Between nodes
    the reflectance is convex in the state (log-linear SH coefficients, linear factors and
    delta-lobe reflectances; bilinear cells convex along each axis), so its maximum over
    the whole state range, and over any history inside it, is at one of these states."""
    if not model.is_dynamic:
        return None
    nodes = np.asarray(model.state_nodes(), float)
    r = model.state_range
    if model.state_dim == 2:
        (a, b), (c, d) = r
        nodes = np.clip(nodes.reshape(-1, 2), [a, c], [b, d])
        corners = np.array([(a, c), (b, c), (a, d), (b, d)])
        return np.unique(np.concatenate([nodes, corners]), axis=0)
    lo, hi = r
    if not (math.isfinite(lo) and math.isfinite(hi)):
        raise SceneError(f"state range [{lo:g}, {hi:g}]: the energy check needs a finite state range")
    return np.unique(np.concatenate([np.clip(nodes.ravel(), lo, hi), [lo, hi]]))


def _isotropic(model, states) -> bool:
    """True when turning both directions by 90 deg about the normal leaves the BRDF
    unchanged at a few fixed direction pairs (then one azimuth of incidence suffices)."""
    rng = np.random.default_rng(0)
    wi, wo = (brdfmodels.spherical_to_vector(rng.uniform(0.1, 1.4, 8), rng.uniform(-3.1, 3.1, 8)) for _ in range(2))
    turn = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    for st in [None] if states is None else states[[0, -1]]:
        a, b = model.evaluate(wi, wo, state=st), model.evaluate(wi @ turn.T, wo @ turn.T, state=st)
        if not np.allclose(a, b, rtol=1e-9, atol=0.0):
            return False
    return True


def _worst_dhr(model):
    """The largest directional-hemispherical reflectance of ``model`` over
    :data:`DHR_INCIDENCES_DEG`, :data:`DHR_AZIMUTHS_DEG` and every state of
    :func:`_dhr_states`: ``(excess, value, error, theta_deg, phi_deg, state)`` with
    ``excess = value - error`` (the most it can be less). Cached per model."""
    key = brdfmodels.dumps(model)
    if key in _DHR_CACHE:
        return _DHR_CACHE[key]
    from brdfmodels.analysis import hemispherical_reflectance_states

    states = _dhr_states(model)
    worst = (-math.inf, 0.0, 0.0, 0.0, 0.0, None)
    for ph in DHR_AZIMUTHS_DEG if not _isotropic(model, states) else DHR_AZIMUTHS_DEG[:1]:
        for th in DHR_INCIDENCES_DEG:
            t, p = math.radians(th), math.radians(ph)
            try:
                v, e, _ = hemispherical_reflectance_states(model, [math.sin(t) * math.cos(p), math.sin(t) * math.sin(p), math.cos(t)],
                                                           states, rtol=1e-3, max_evaluations=4_000_000)
            except ValueError:  # a measured table that refuses directions without data (outside = "error")
                continue
            v = np.where(np.isfinite(v), v, math.inf)
            k = int(np.argmax(v - e))
            if v[k] - e[k] > worst[0]:
                worst = (float(v[k] - e[k]), float(v[k]), float(e[k]), th, ph, None if states is None else states[k])
    if len(_DHR_CACHE) > 256:
        _DHR_CACHE.clear()
    _DHR_CACHE[key] = worst
    return worst


def _check_dhr(model, where, factor=1.0, why=""):
    """SceneError if the directional-hemispherical reflectance (times ``factor``, the
    largest reflectance factor a history reaches) exceeds 1 (energy from nowhere:
    ``kd = 22``) at any incidence of :data:`DHR_INCIDENCES_DEG` (and azimuth, and state of
    a dynamic model: every node of its table)."""
    excess, v, e, th, ph, st = _worst_dhr(model)
    tol = _dhr_tolerance(model)
    if factor * excess > 1.0 + tol:
        at = f" at state {_fmt(st)}" if st is not None else ""
        az = f", azimuth {ph:g} deg from the tangent" if ph else ""
        raise SceneError(f"{where}: hemispherical reflectance {factor * v:.4g} > 1 at {th:g} deg incidence{az}{at}{why} (beyond the "
                         f"tolerance {tol:g}): "
                         f"the material reflects more than it receives; check its parameters")


def _dhr_tolerance(model) -> float:
    """How far past 1 a material's hemispherical reflectance may go: a measured table's
    stated uncertainty (``dhr_tolerance``), else ``DHR_TOLERANCE`` (quadrature rounding)."""
    return max(DHR_TOLERANCE, float(getattr(model, "dhr_tolerance", DHR_TOLERANCE)))


def _with_polarization(data, polarization):
    """A model's dict with every Fresnel mirror (``specular`` with ``n``) that does not
    name its polarization given ``polarization``."""
    if isinstance(data, dict):
        if data.get("type") == "specular" and "n" in data.get("params", {}) and "polarization" not in data["params"]:
            return {**data, "params": {**data["params"], "polarization": polarization}}
        return {k: _with_polarization(v, polarization) for k, v in data.items()}
    if isinstance(data, list):
        return [_with_polarization(v, polarization) for v in data]
    return data


def _model_file(file, base_dir):
    """A saved model (brdfmodels JSON) named by a material's ``file``; errors name it."""
    text = read_input_text(input_path(file, base_dir), "material file")
    try:
        return brdfmodels.loads(text)
    except ValueError as exc:
        raise ValueError(f"file={file!r}: {exc}") from None


def _table_material(spec, base_dir, wavelength_nm=None):
    """``{ model = "table", file = ... }``: a MERL ``.binary`` measurement, scattered
    samples (``.bsdf``, ``.astm``, angle ``.csv``) as a :class:`brdfmodels.ScatteredBRDF`
    (every sample honoured, barycentric between them; beyond them ``fill`` / ``outside``:
    the nearest samples' envelope by default), or gridded every ``grid_deg`` when given,
    or a saved table (JSON), with its ``outside`` policy (default "envelope": conservative)."""
    p = input_path(spec.file, base_dir)
    prm = spec.params
    outside, fill = prm.get("outside", "envelope"), prm.get("fill", "envelope")
    policy = "error" if outside == "error" else ("fit" if "fit" in (fill, outside) else "envelope")  # beyond scattered data
    scattered = p.suffix.lower() in (".bsdf", ".astm", ".e1392", ".csv")
    unused = [k for k in ("dhr_tolerance", "ignore_columns", "symmetry") if k in prm
              and (not scattered or (k == "dhr_tolerance" and "grid_deg" in prm))]
    if unused:
        raise ValueError(f"{unused[0]}: applies to a scattered table (a .bsdf, .astm, .e1392 or angle .csv file without "
                         f"grid_deg); expected it removed here")
    if p.suffix.lower() == ".binary":
        return brdfmodels.TabulatedBRDF.from_merl(p, channel=prm.get("channel", "mean"), outside=outside)
    if scattered:
        from brdfmodels.io import read_samples

        s = read_samples(p, wavelength_nm=wavelength_nm, ignore_columns=prm.get("ignore_columns", ()),
                         symmetry=prm.get("symmetry"))
        notes = tuple(s.info.get("notes", ())) + _state_note(s)
        if "grid_deg" in prm:
            dh, dd, dp = prm["grid_deg"]
            # theta_h and theta_d nodes end at 90 deg: beyond the last node the table's `outside` policy would
            # give the file's largest value (its peak) at grazing theta_d (a 5 deg grid's ABg file: DHR 1.73, refused)
            return brdfmodels.TabulatedBRDF.from_samples(s.wi, s.wo, s.brdf_per_sr, _nodes_to_90(dh), _nodes_to_90(dd),
                                                         np.arange(0.0, 180.0 - 1e-9, dp), fill=fill, outside=outside, notes=notes)
        return brdfmodels.ScatteredBRDF.from_samples(s.wi, s.wo, s.brdf_per_sr, outside=policy, notes=notes,
                                                     dhr_tolerance=prm.get("dhr_tolerance", brdfmodels.scattered.DHR_TOLERANCE))
    model = _model_file(spec.file, base_dir)
    if isinstance(model, brdfmodels.ScatteredBRDF):  # a saved scattered table, with this scene's policy
        return brdfmodels.ScatteredBRDF(**{**model.to_dict()["params"], "outside": policy})
    if not isinstance(model, brdfmodels.TabulatedBRDF):
        raise ValueError(f"file={spec.file!r}: model = 'table' needs a MERL .binary file or a saved table, got {model.name!r}")
    d = model.to_dict()["params"]
    return brdfmodels.TabulatedBRDF(d["theta_h_deg"], d["theta_d_deg"], d["phi_d_deg"], d["values"], outside)


def _nodes_to_90(step_deg):
    """Grid nodes [deg] every ``step_deg`` from 0, ending at 90 (the last step shorter when
    ``step_deg`` does not divide 90)."""
    return np.append(np.arange(0.0, 90.0 - 1e-9, step_deg), 90.0)


def _state_note(s) -> tuple:
    """A note when measured samples span several states (time, temperature or a named
    state): a static table holds them all, the largest at a shared direction pair."""
    cols = {"time_s": s.time_s, "temperature_k": s.temperature_k, **s.states}
    varied = [k for k, v in cols.items() if np.unique(v[np.isfinite(v)]).size > 1]
    if not varied:
        return ()
    return (f"the samples span several values of {', '.join(varied)}; the static table holds them together (the "
            f"largest at a shared direction pair, interpolated between); a dynamic fit (hazard fit sh) follows the state",)


def _material(spec, where, base_dir, polarization="unpolarized", wavelength_nm=None):
    """A target's (or the terrain's) BRDF; Fresnel mirrors take the laser's polarisation:
    ``"unknown"`` -> the larger of s and p (:func:`brdfmodels.optics.fresnel_reflectance`)."""
    try:
        if spec.library is not None:
            from brdfmodels.library import material

            model = material(spec.library, wavelength_nm)
        elif spec.model == "table":
            model = _table_material(spec, base_dir, wavelength_nm)
        elif spec.file is not None:
            model = _model_file(spec.file, base_dir)
        else:
            model = brdfmodels.create(spec.model, **spec.params)
        if model.has_specular:
            model = brdfmodels.model_from_dict(_with_polarization(model.to_dict(), "worst" if polarization == "unknown" else polarization))
    except ValueError as exc:
        raise SceneError(f"{where}: {exc}") from None
    gridded = spec.model == "table" and "grid_deg" in spec.params  # the grid's cells spread a peak narrower than them
    _check_dhr(model, where, why=f" (gridded at grid_deg = {spec.params['grid_deg']}: a finer grid, or none, keeps "
                                 f"the measured peak where it was)" if gridded else "")
    return model


TERRAIN_DEFAULT_REFLECTANCE = 1.0  # Lambertian: the most a diffuse ground can return (conservative)


@dataclass(frozen=True)
class TerrainReflector:
    """What a target's ``spec`` says for the terrain: its shape and (no) history."""

    shape: str = "terrain"
    history: None = None
    material_given: bool = False


class _TerrainMesh:
    """The terrain's triangles, built when first asked for (the ray scene builds its own)."""

    analytic = None

    def __init__(self, terrain):
        self._terrain, self._mesh = terrain, None

    def _built(self):
        if self._mesh is None:
            self._mesh = self._terrain.mesh()
        return self._mesh

    @property
    def vertices(self):
        return self._built().vertices

    @property
    def faces(self):
        return self._built().faces


def _terrain_target(spec, terrain, index, base_dir) -> Target:
    """The terrain as a reflector (a :class:`Target` named ``terrain``, object ``index``
    in the ray scene): ``[terrain] material`` or a Lambertian of reflectance
    ``TERRAIN_DEFAULT_REFLECTANCE``."""
    ms = spec.terrain.material
    if ms is None:
        material = brdfmodels.create("lambertian", reflectance=TERRAIN_DEFAULT_REFLECTANCE)
    else:
        _no_slump(ms, "terrain.material")
        material = _material(ms, "terrain.material", base_dir, spec.laser.polarization, spec.laser.wavelength_nm)
        if material.is_dynamic:
            raise SceneError(f"terrain.material: depends on {material.state_name!r}; expected a static material (the ground has no history)")
    h = terrain.heights
    ny, nx = h.shape
    centre = np.array([terrain.x0 + terrain.dx * (nx - 1) / 2, terrain.y0 + terrain.dx * (ny - 1) / 2, float(h.mean())])
    groove = math.radians(ms.groove_angle_deg) if ms is not None else 0.0
    return Target("terrain", index, _TerrainMesh(terrain), material, groove, np.array([0.0, 0.0, 1.0]), np.array([1.0, 0.0, 0.0]),
                  centre, TerrainReflector(material_given=ms is not None))


def _history(spec, where, base_dir):
    if spec is None or spec.kind != "series":
        return None
    if spec.file is not None:
        from brdfmodels.io import read_csv_columns

        want = list(spec.state_names)
        try:  # a CSV with a header line: time_s and the states (errors name the line and column, quote nothing)
            data = read_csv_columns(input_path(spec.file, base_dir), ["time_s", *want], f"{where}.file")
        except ValueError as exc:
            raise SceneError(f"{where}.file={spec.file!r}: {exc}") from None
        times = data["time_s"]
        states = data[want[0]] if len(want) == 1 else np.stack([data[w] for w in want], axis=1)
    else:
        times, states = spec.times_s, spec.states
    try:
        return brdfmodels.History(times, states, spec.state if isinstance(spec.state, str) else list(spec.state),
                                  extrapolation=spec.extrapolation)
    except ValueError as exc:
        raise SceneError(f"{where}: {exc}") from None


def _check_series_cover(spec: SceneSpec, targets) -> list:
    """A measured series with ``extrapolation = 'error'`` must cover the analysis times,
    0 to ``time_end_s`` (default the exposure duration), or the run would stop there; one
    with ``'clamp'`` that does not is a warning (returned): its end states are held (a
    history CSV cut after 4 s of 10 held its last row, a reflectance factor 0, for 6 s,
    unsaid)."""
    t_end = spec.analysis.time_end_s or spec.exposure.duration_s
    held = []
    for i, t in enumerate(targets):
        h = t.history
        if h is None or getattr(spec.targets[i].history, "extrapolation", None) not in ("error", "clamp"):
            continue
        t0, t1 = float(h.times_s[0]), float(h.times_s[-1])
        if (t0 > 0.0 or t1 < t_end) and spec.targets[i].history.extrapolation == "clamp":
            held.append(f"targets[{i}].history: the series covers [{t0:g}, {t1:g}] s of the analysis' [0, {t_end:g}] s; "
                        f"its end states are held (extrapolation = 'clamp') for {max(t0, 0.0) + max(t_end - t1, 0.0):g} s")
        elif t0 > 0.0 or t1 < t_end:
            raise SceneError(f"targets[{i}].history: the series covers [{t0:g}, {t1:g}] s but the analysis runs from 0 to "
                             f"{t_end:g} s; extend it, or set extrapolation = 'clamp' to hold its end states")
    return held


def _inside_solid(p, spec) -> np.ndarray:
    """Points strictly inside a closed primitive (box, sphere, cylinder)."""
    if spec.shape not in ("box", "sphere", "cylinder"):
        return np.zeros(len(p), bool)
    frame = brdfmodels.local_frame(spec.normal, spec.tangent)
    q = (p - np.asarray(spec.center_m)) @ frame.T
    s = spec.size_m
    if spec.shape == "box":
        return np.all(np.abs(q) < np.asarray(s) / 2 * (1 - 1e-9), axis=1)
    if spec.shape == "sphere":
        return np.linalg.norm(q, axis=1) < s[0] / 2 * (1 - 1e-9)
    return (np.hypot(q[:, 0], q[:, 1]) < s[0] / 2 * (1 - 1e-9)) & (np.abs(q[:, 2]) < s[1] / 2 * (1 - 1e-9))


def _material_notes(targets) -> list:
    """The notes a measured material carries (merged duplicate samples, a wavelength
    interpolated between two measured ones), each named by its target."""
    return [f"targets[{t.index}].material: {n}" for t in targets for n in getattr(t.material, "notes", ())]


def _buried_targets(targets, terrain) -> list:
    """Targets whose centre lies below the terrain: odd (the beam cannot reach them), said."""
    if terrain is None:
        return []
    out = []
    for t in targets:
        c = t.center_m
        if terrain.contains_xy(c[0], c[1]) and c[2] < float(terrain.height_at(c[0], c[1])):
            out.append(f"targets[{t.index}] ({t.name}): its centre is below the terrain there; the beam cannot reach what is buried")
    return out


def _warnings(spec: SceneSpec) -> list:
    """Plausibility warnings: values typical of unit mistakes, naming the field and the likely unit."""
    out = []
    la = spec.laser
    if la.divergence_rad > 0.05:
        out.append(f"laser.divergence_rad = {la.divergence_rad:g} rad is a very wide beam (> 0.05 rad): mrad meant?")
    elif la.divergence_rad >= DIVERGENCE_WIDE_RAD:
        out.append(f"laser.divergence_rad = {la.divergence_rad:g} rad ({1e3 * la.divergence_rad:g} mrad) is a wide beam for a "
                   f"range laser (10 to 50 mrad is a bare diode's, not a beam director's): mrad meant? (as rad the beam is "
                   f"1000x wider than the same number in mrad, and its NOHD about 1000x shorter)")
    if la.divergence_rad == 0:
        out.append("laser.divergence_rad = 0: an ideal collimated beam never spreads, so its direct-beam NOHD (and the danger "
                   "zone's) is infinite where the atmosphere does not attenuate it (report.json 'inf'); give the measured "
                   "full-angle divergence for a finite one")
    if la.sector is not None and la.aim_m is not None and not direction_in_sector(
            np.asarray(la.aim_m, float) - np.asarray(la.position_m, float), la.sector, la.pointing_buffer_rad):
        out.append(f"laser.sector = {la.sector.azimuth_deg} deg bearing, {la.sector.elevation_deg} deg elevation does not hold "
                   f"the aim (laser.aim_m): the danger zone covers both")
    if la.pointing_error_rad > 0.05:
        out.append(f"laser.pointing_error_rad = {la.pointing_error_rad:g} rad is over 50 mrad: mrad or deg meant?")
    if la.beam_diameter_m > 1.0:
        out.append(f"laser.beam_diameter_m = {la.beam_diameter_m:g} m is over 1 m: mm meant?")
    for g, ob in enumerate(spec.observers):
        if ob.eye_height_m is not None and ob.eye_height_m > 3.0:
            out.append(f"observers[{g}].eye_height_m = {ob.eye_height_m:g} m is above 3 m: cm or ft meant?")
    if spec.analysis.footprint_eye_height_m > 3.0:
        out.append(f"analysis.footprint_eye_height_m = {spec.analysis.footprint_eye_height_m:g} m is above 3 m: cm or ft meant?")
    vis = spec.atmosphere.visibility_km
    if vis is not None and vis < 0.05:
        out.append(f"atmosphere.visibility_km = {vis:g} km is under 50 m (dense fog): m meant?")
    out += _library_wavelength_warnings(spec)
    if spec.motion is not None and not spec.has_motion:
        out.append("motion: the scene has nothing that moves (no track, aim_track, target track or windows): the table is "
                   "not used")
    t_end = spec.analysis.time_end_s
    if t_end is not None and t_end < spec.exposure.duration_s and any(t.history is not None for t in spec.targets):
        out.append(f"analysis.time_end_s = {t_end:g} s ends before the exposure (exposure.duration_s = "
                   f"{spec.exposure.duration_s:g} s): states after it are not seen, and a dynamic NOHD may be low")
    return out + _magnitude_warnings(spec) + _beam_quality_warnings(spec) + _duration_warnings(spec)


DIVERGENCE_WIDE_RAD = 0.01  # full-angle divergence [rad] from which a range laser's beam is warned as wide (mrad meant?)
# M^2 of the beam the scene describes, from its 1/e full diameter d and divergence theta:
# with the 1/e^2 full quantities D = sqrt(2) d and Theta = sqrt(2) theta of a Gaussian,
# M^2 = pi D Theta / (4 lambda) = pi d theta / (2 lambda). d is the aperture's diameter,
# at least the waist's, so this is an upper bound of the true M^2: under 1 it is
# impossible (narrower than diffraction allows). Range lasers' beam directors deliver
# M^2 near 1 (single mode) to tens (multimode); above M2_PLAUSIBLE_MAX is a divergence
# in degrees (57.3x) or mrad (1000x) typed as rad, or a diameter in mm typed as m.
M2_PLAUSIBLE_MAX = 50.0


def beam_m2(wavelength_nm, beam_diameter_m, divergence_rad) -> float:
    """The beam quality factor M^2 [-] a 1/e full diameter [m] and full-angle divergence
    [rad] imply at ``wavelength_nm``: pi d theta / (2 lambda) (1/e^2 full quantities
    sqrt(2) times the 1/e ones; ISO 11146: M^2 = pi D Theta / (4 lambda))."""
    return math.pi * beam_diameter_m * divergence_rad / (2.0 * wavelength_nm * 1e-9)


def _beam_quality_warnings(spec: SceneSpec) -> list:
    """M^2 under 1 (impossible) or above ``M2_PLAUSIBLE_MAX`` (a unit slip), unless a
    warning on the divergence or the diameter already names the slip."""
    la = spec.laser
    if la.divergence_rad <= 0 or la.divergence_rad >= DIVERGENCE_WIDE_RAD or la.beam_diameter_m > 1.0:
        return []
    m2 = beam_m2(la.wavelength_nm, la.beam_diameter_m, la.divergence_rad)
    given = (f"laser.beam_diameter_m = {la.beam_diameter_m:g} m and divergence_rad = {la.divergence_rad:g} rad at "
             f"{la.wavelength_nm:g} nm imply M^2 = pi d theta / (2 lambda) = {m2:.3g} (1/e quantities)")
    if m2 < 1.0:
        return [f"{given}: under 1, narrower than diffraction allows, so no beam has them (the NOHD from them is too "
                f"long: conservative): check both values and their units"]
    if m2 > M2_PLAUSIBLE_MAX:
        return [f"{given}: above {M2_PLAUSIBLE_MAX:g}, more than a range laser's beam director delivers (near 1 single "
                f"mode, tens multimode): divergence in degrees (57.3x too wide as rad) or mrad typed as rad, or the "
                f"diameter in mm typed as m? A wider divergence shortens the NOHD; if both values are right, ignore this"]
    return []


# IEC 60825-1:2014 Table 8: the class 3B accessible emission limit of CW emission longer
# than 0.25 s, 315 nm to 1 mm, is 0.5 W. Under it a CW laser is class 3B or lower by its
# power, not the high-energy (class 4) laser a range analysis is for: a power in kW
# typed as W. (Pulsed lasers are classed by their pulse energy too: not checked here.)
CLASS_4_CW_MIN_W = 0.5


# A continuous beam watched for less than this is not an exposure anyone means on a range
# (the shortest aversion-response and scanning dwell times are ms; the tables reach 1e-13 s
# for single pulses); longer than this is a whole working day and more (the tables end at 3e4 s)
DURATION_PLAUSIBLE_S = (1e-6, 2.88e4)


def _duration_warnings(spec: SceneSpec) -> list:
    """``exposure.duration_s`` that the schema accepts but that is hardly meant: under 1 us
    for a continuous beam (ms or s typed as us?), over 8 h, or shorter than one pulse."""
    d, la = spec.exposure.duration_s, spec.laser
    if la.power_w is not None and d < DURATION_PLAUSIBLE_S[0]:
        return [f"exposure.duration_s = {d:g} s is under 1 us for a continuous beam (laser.power_w): the MPE is that of a "
                f"{d:g} s exposure, far above a continuous one's; ms or s meant?"]
    if la.pulse_duration_s is not None and d < la.pulse_duration_s:
        return [f"exposure.duration_s = {d:g} s is shorter than one pulse (laser.pulse_duration_s = {la.pulse_duration_s:g} s): "
                f"the exposure should span the pulses seen"]
    if d > DURATION_PLAUSIBLE_S[1]:
        return [f"exposure.duration_s = {d:g} s is over 8 h (a working day, 2.88e4 s): s typed for ms, or the whole day meant?"]
    return []


# Orders of magnitude beyond the bundled range (100 W .. 100 kW) that a unit slip gives:
# a power in mW or kW typed as W. (exposure.duration_s beyond the MPE tables' 3e4 s is
# already an error of the schema; inside it, _duration_warnings.)
POWER_PLAUSIBLE_W = (1e-3, 1e7)


def _library_wavelength_warnings(spec: SceneSpec) -> list:
    """A library material measured at another wavelength than the laser's (more than 5 %
    off): its reflectance there is not known."""
    from brdfmodels.library import LIBRARY

    out, wl = [], spec.laser.wavelength_nm
    for i, t in enumerate(spec.targets):
        for key, m in (("material", t.material), ("back", t.back)):
            lib = None if m is None else LIBRARY.get(m.library or "")
            if lib is not None and lib.wavelength_nm is not None and abs(wl / lib.wavelength_nm - 1) > 0.05:
                out.append(f"targets[{i}].{key}: library {m.library!r} was measured at {lib.wavelength_nm:g} nm, "
                           f"the laser is at {wl:g} nm: its reflectance there is not known")
    return out


def _magnitude_warnings(spec: SceneSpec) -> list:
    p = spec.laser.power_w
    if p is not None and p > POWER_PLAUSIBLE_W[1]:
        return [f"laser.power_w = {p:g} W is over 10 MW: mW or kW meant?"]
    if p is not None and p < POWER_PLAUSIBLE_W[0]:
        return [f"laser.power_w = {p:g} W is under 1 mW for a high-energy laser range: W or kW meant?"]
    if p is not None and p < CLASS_4_CW_MIN_W and spec.laser.wavelength_nm < 315.0:
        # the 0.5 W class 3B AEL starts at 315 nm: below, Table 8's limits are lower, so no class is claimed
        return [f"laser.power_w = {p:g} W is under {CLASS_4_CW_MIN_W:g} W, low for a high-energy range laser: kW typed as W? "
                f"(1000x the power is {p * 1e3:g} W; below 315 nm the class 3B limit is lower than 0.5 W, so the laser "
                f"may still be class 4)"]
    if p is not None and p < CLASS_4_CW_MIN_W:
        return [f"laser.power_w = {p:g} W is under {CLASS_4_CW_MIN_W:g} W, the class 3B limit for CW emission (IEC "
                f"60825-1:2014 Table 8): by its power the laser is class 3B or lower, not a high-energy range laser: kW "
                f"typed as W? (1000x the power is {p * 1e3:g} W)"]
    return []


NEAR_APERTURE_M = 1.0  # observer points this close to the laser aperture are named in a warning [m]


def _near_aperture(observers, laser_m, direction, groups=(), offset=0.0) -> list:
    """Observer points within ``NEAR_APERTURE_M`` of the aperture, said explicitly: on or in
    front of the aperture plane they are in the beam as it leaves (its full exit
    irradiance inside its diameter); behind it they are out of the beam (the laser emits
    forward only), not 0 W/m^2 by accident. A generated grid (``groups``: the observer
    groups of ``observers.parts``, in order; ``offset`` local to world) is checked only in
    the index window about the aperture (:func:`_near_rows`), every other part whole."""
    front, behind, names = 0, 0, []
    for rows, p in _near_rows(observers, laser_m, groups, offset):
        rel = p - laser_m
        near = np.flatnonzero(np.einsum("ij,ij->i", rel, rel) < NEAR_APERTURE_M ** 2)
        if len(near):
            ahead = rel[near] @ direction >= -1e-9  # on the plane within 1 nm (hazard.pipeline.direct.APERTURE_PLANE_TOL_M)
            front, behind = front + int(ahead.sum()), behind + int((~ahead).sum())
            names += [int(rows[i]) for i in near[:3 - len(names)]] if len(names) < 3 else []
    if not front + behind:
        return []
    labels = observers.labels()
    shown = ", ".join(labels[i] for i in names) + (", ..." if front + behind > len(names) else "")
    return [f"observers: {front + behind} point(s) within {NEAR_APERTURE_M:g} m of the laser aperture ({shown}): {front} on or "
            f"in front of the aperture plane are in the beam as it leaves (the exit irradiance inside its diameter), {behind} "
            f"behind it are out of the beam (the laser emits forward only; direct beam 0 W/m^2 there)"]


def _near_rows(observers, laser_m, groups, offset):
    """``(rows, points)`` blocks in row order holding every observer point within
    ``NEAR_APERTURE_M`` of ``laser_m`` (local): a generated grid's rows in the xy index
    window about it (:func:`_grid_candidates`, a superset: a point within the radius is
    within it in plan, whatever its height), the rest block by block."""
    parts = observers.parts if len(groups) == len(observers.parts) else ()
    for ob, part in zip(groups, parts):
        rows = None
        if not part.is_stored and ob.layout == "grid":
            rows = _grid_candidates(ob, np.asarray(laser_m, float) + offset, NEAR_APERTURE_M, xy=True)
        rows = np.arange(part.count) if rows is None else rows
        for a in range(0, len(rows), BLOCK):
            r = rows[a:a + BLOCK]
            yield part.start + r, part.at(r)
    if not parts:
        for a0, a1, p in observers.blocks():
            yield np.arange(a0, a1), p


def _check_laser_in_open_air(spec: SceneSpec, lp, offset, terrain) -> None:
    """A laser inside a target or occluder, or below the terrain, cannot be meant: its
    beam would be blocked at the aperture and every observer would look safe."""
    for solid_list, label in ((spec.targets, "targets"), (spec.occluders, "occluders")):
        for j, s in enumerate(solid_list):
            if _inside_solid(np.asarray(lp, float)[None], s)[0]:
                raise SceneError(f"laser.position_m = {list(map(float, lp))} is inside {label}[{j}] ({s.shape}); "
                                 f"expected the laser in open air")
    if terrain is not None:
        local = np.asarray(lp, float) - offset
        x, y = np.array([local[0]]), np.array([local[1]])
        if terrain.contains_xy(x, y)[0] and local[2] < terrain.height_at(x, y)[0] - 1e-6:
            raise SceneError(f"laser.position_m = {list(map(float, lp))} is below the terrain "
                             f"(ground at {float(terrain.height_at(x, y)[0] + offset[2]):.6g} m); expected the laser above it")


def _target(i, ts, offset, base_dir, polarization="unknown", wavelength_nm=None) -> Target:
    """Target ``i`` of the scene in local coordinates: its mesh, material (checked against
    its history) and back material."""
    where = f"targets[{i}]"
    try:
        mesh = shape_mesh(ts, base_dir)
    except ValueError as exc:
        raise SceneError(f"{where}: {exc}") from None
    mesh.vertices = mesh.vertices - offset
    if mesh.analytic is not None:
        mesh.analytic = (mesh.analytic[0], mesh.analytic[1] - offset, *mesh.analytic[2:])
    hist = _history(ts.history, f"{where}.history", base_dir)
    material = _front_material(ts, ts.material, hist, where, f"{where}.material", base_dir, polarization, wavelength_nm)
    back = None
    if ts.back is not None:
        _no_slump(ts.back, f"{where}.back")
        back = _material(ts.back, f"{where}.back", base_dir, polarization, wavelength_nm)
        if back.is_dynamic:
            raise SceneError(f"{where}.back: the back material depends on {back.state_name!r}; "
                             f"expected a static material (the history drives the front face only)")
    frame = brdfmodels.local_frame(ts.normal, ts.tangent)
    return Target(ts.name, i, mesh, material, math.radians(ts.material.groove_angle_deg), frame[2], frame[0],
                  np.asarray(ts.center_m, float) - offset, ts, hist, back, _slump(ts, frame, material, where))


def _front_material(ts, ms, hist, where, what, base_dir, polarization, wavelength_nm):
    """The front face's material ``ms`` of target ``ts`` (checked against its history)."""
    material = _material(ms, what, base_dir, polarization, wavelength_nm)
    if ts.history is not None:
        return _material_for_history(material, ts.history, hist, where)
    if material.is_dynamic:
        raise SceneError(f"{where}.history: the material depends on {_names_text(material.state_name)}; give a history")
    return material


def alternative_material(scene: "Scene", target_index: int, ms, what: str):
    """Material ``ms`` (a MaterialSpec) built as target ``target_index``'s front face
    would be: same polarization and wavelength, checked against its history."""
    t, laser = scene.targets[target_index], scene.spec.laser
    return _front_material(t.spec, ms, t.history, f"targets[{target_index}]", what, scene.base_dir, laser.polarization,
                           laser.wavelength_nm)


def _no_slump(ms, where) -> None:
    if ms.melt_tilt_deg or ms.melt_wander_deg:
        raise SceneError(f"{where}: melt_tilt_deg / melt_wander_deg are for a target's front material "
                         f"(the one its history drives)")


def _names_text(name) -> str:
    return repr(name) if isinstance(name, str) else repr(list(name))


def _material_for_history(material, hs, hist, where):
    """The material a history drives: checked against the history's state names and,
    for a series, its states' span (a static material with ``reflectance_factor`` is
    wrapped in an identity factor table)."""
    state = hs.state if isinstance(hs.state, str) else tuple(hs.state)
    base = None
    if state == "reflectance_factor" and not material.is_dynamic:
        base, material = material, _identity_factor(material)
    elif not material.is_dynamic:
        raise SceneError(
            f"{where}.history: the material is static; a history needs a dynamic material, "
            f"or state = 'reflectance_factor' to scale it"
        )
    elif material.state_name != state:
        raise SceneError(f"{where}.history.state={_names_text(state)}: the material depends on {_names_text(material.state_name)}")
    if hist is not None:  # the series' states must lie where the material is defined
        lo, hi = np.min(hist.states, axis=0), np.max(hist.states, axis=0)
        for s_ in (lo, hi):
            try:
                material.evaluate([0.0, 0.0, 1.0], [0.0, 0.0, 1.0], state=s_)
            except ValueError as exc:
                raise SceneError(f"{where}.history: states span [{_fmt(lo)}, {_fmt(hi)}]: {exc}") from None
        if base is not None:  # the static material times the largest factor the series reaches
            _check_dhr(base, f"{where}.material", float(hi), f" times the history's reflectance_factor {float(hi):g}")
    return material


def _fmt(v) -> str:
    return f"{float(v):g}" if np.ndim(v) == 0 else "(" + ", ".join(f"{float(x):g}" for x in v) + ")"


def _slump(ts, frame, material, where):
    """The target's :class:`Slump`, or None; its melt fraction must come from the
    history (a heating history, or a series with a ``melt_fraction`` state)."""
    ms = ts.material
    if ms.melt_tilt_deg == 0.0 and ms.melt_wander_deg == 0.0:
        return None
    hs = ts.history
    if hs is None or (hs.kind == "series" and "melt_fraction" not in hs.state_names):
        raise SceneError(f"{where}.material.melt_tilt_deg / melt_wander_deg: the slump follows the melt fraction; "
                         f"expected a heating history, or a series with state 'melt_fraction'")
    if material.has_specular:
        raise SceneError(f"{where}.material.melt_tilt_deg / melt_wander_deg: the material has an ideal-mirror (delta) lobe, "
                         f"traced on the target's geometry, which the slump would not tilt; expected a material without one "
                         f"(a measured or fitted BRDF)")
    n = frame[2]
    if ms.melt_tilt_direction == "up":
        d, label = np.array([0.0, 0.0, 1.0]), "world up"
    else:  # target frame (x = tangent, y = n x t, z = normal) -> world
        d, label = np.asarray(ms.melt_tilt_direction, float) @ frame, f"target-frame {ms.melt_tilt_direction}"
    d = d - (d @ n) * n
    if ms.melt_tilt_deg > 0 and not np.linalg.norm(d) > 1e-9:
        raise SceneError(f"{where}.material.melt_tilt_direction: {label} is along the normal; "
                         f"expected a direction with a part across the surface to tilt towards")
    d = d / np.linalg.norm(d) if np.linalg.norm(d) > 1e-9 else np.array(frame[0])
    return Slump(math.radians(ms.melt_tilt_deg), d, math.radians(ms.melt_wander_deg))


def _check_open_air(g, ob, spec, p) -> None:
    """Points ``p`` (world) of observer group ``g`` must not lie inside a closed solid."""
    for solid_list, label in ((spec.targets, "targets"), (spec.occluders, "occluders")):
        for j, s in enumerate(solid_list):
            inside = _inside_solid(p, s)
            if np.any(inside):
                k = int(np.argmax(inside))
                raise SceneError(
                    f"observers[{g}] ({ob.name}): point {p[k].tolist()} is inside {label}[{j}] ({s.shape}); "
                    f"expected observers in open air"
                )


def _check_above_terrain(g, ob, local, offset, terrain) -> None:
    """Points placed by height (not at eye height) must not lie below the terrain."""
    on = terrain.contains_xy(local[:, 0], local[:, 1])
    below = on & (local[:, 2] < terrain.height_at(local[:, 0], local[:, 1]) - 1e-6)
    if np.any(below):
        k = int(np.argmax(below))
        raise SceneError(f"observers[{g}] ({ob.name}): point {(local[k] + offset).tolist()} is below the terrain; use eye_height_m")


def _group_points(g, ob, spec, offset, terrain, rise=None) -> np.ndarray:
    """One observer group's points (world coordinates), placed at eye height over the
    terrain when asked, else raised by the site's refraction ``rise`` (x, y) -> dz,
    checked to be in open air (not in a solid, not underground)."""
    p = observer_points(ob)
    if ob.eye_height_m is None and rise is not None:
        p = p.copy()
        p[:, 2] += rise(p[:, 0], p[:, 1])
    if ob.eye_height_m is not None:
        local = p - offset
        if not np.all(terrain.contains_xy(local[:, 0], local[:, 1])):
            raise SceneError(f"observers[{g}] ({ob.name}): some points lie outside the terrain's extent")
        p = p.copy()
        p[:, 2] = terrain.height_at(local[:, 0], local[:, 1]) + offset[2] + ob.eye_height_m
    _check_open_air(g, ob, spec, p)
    if terrain is not None and ob.eye_height_m is None:  # eye-height points stand on it by construction
        _check_above_terrain(g, ob, p - offset, offset, terrain)
    return p


def _solid_radius_m(s) -> float:
    """Radius [m] of a sphere about a closed primitive's centre that holds it."""
    size = np.asarray(s.size_m, float)
    if s.shape == "box":
        return float(np.linalg.norm(size)) / 2
    if s.shape == "sphere":
        return float(size[0]) / 2
    return float(np.hypot(size[0] / 2, size[1] / 2))


def _grid_candidates(ob, centre_m, radius_m, xy=False) -> np.ndarray | None:
    """Rows of a grid group whose points may lie within ``radius_m`` of ``centre_m``
    (world): the index window around the ellipse that the sphere's disk maps to in the
    grid's (a, b) coordinates (xy only when placed at eye height, or when ``xy``: a
    point's height then may be anything); None when u and v are (nearly) parallel, so
    every row must be checked."""
    nu, nv = ob.counts
    o, u, v = (np.asarray(x, float) for x in (ob.origin_m, ob.u_m, ob.v_m))
    dims = slice(0, 2) if (xy or ob.eye_height_m is not None) else slice(0, 3)
    m = np.stack([u[dims], v[dims]], axis=1)
    gram = m.T @ m
    if nu < 2 or nv < 2 or np.linalg.det(gram) <= 1e-12 * gram[0, 0] * gram[1, 1]:
        return None
    inv = np.linalg.inv(gram)
    ab = inv @ (m.T @ (np.asarray(centre_m, float)[dims] - o[dims]))
    half = radius_m * np.sqrt(np.diag(inv))
    iu = np.arange(max(int(np.floor((ab[0] - half[0]) * (nu - 1))), 0), min(int(np.ceil((ab[0] + half[0]) * (nu - 1))), nu - 1) + 1)
    iv = np.arange(max(int(np.floor((ab[1] - half[1]) * (nv - 1))), 0), min(int(np.ceil((ab[1] + half[1]) * (nv - 1))), nv - 1) + 1)
    return (iv[:, None] * nu + iu[None, :]).ravel()


def _grid_corners_on_terrain(g, ob, offset, terrain) -> None:
    """A grid at eye height lies within the terrain's extent when its four corners do
    (a parallelogram inside a rectangle)."""
    o, u, v = (np.asarray(x, float) for x in (ob.origin_m, ob.u_m, ob.v_m))
    c = np.array([o, o + u, o + v, o + u + v]) - offset
    if not np.all(terrain.contains_xy(c[:, 0], c[:, 1])):
        raise SceneError(f"observers[{g}] ({ob.name}): some points lie outside the terrain's extent")


def _grid_part(g, ob, spec, offset, terrain, start, rise=None) -> GroupPoints:
    """A grid group as generated points (see :mod:`scenes.observers`), checked at load:
    the corners on the terrain, no point inside a solid (only the rows near each solid
    are generated), none below the terrain (every row, block by block)."""
    if ob.eye_height_m is not None:
        _grid_corners_on_terrain(g, ob, offset, terrain)
    at = grid_generator(ob, offset, terrain, rise)
    n = ob.counts[0] * ob.counts[1]
    for solid in list(spec.targets) + list(spec.occluders):
        if solid.shape not in ("box", "sphere", "cylinder"):
            continue
        rows = _grid_candidates(ob, solid.center_m, _solid_radius_m(solid))
        for a0 in range(0, n if rows is None else len(rows), BLOCK):
            idx = np.arange(a0, min(a0 + BLOCK, n)) if rows is None else rows[a0:a0 + BLOCK]
            _check_open_air(g, ob, spec, at(idx) + offset)
    if terrain is not None and ob.eye_height_m is None:
        for a0 in range(0, n, BLOCK):
            _check_above_terrain(g, ob, at(np.arange(a0, min(a0 + BLOCK, n))), offset, terrain)
    return GroupPoints(start, n, at, is_stored=False)


def _observers(spec, offset, terrain, rise=None) -> Observers:
    """Every observer group's points in local coordinates, with their group and index;
    grids generated where they are used (:mod:`scenes.observers`)."""
    parts, grp, idx, start = [], [], [], 0
    for g, ob in enumerate(spec.observers):
        if ob.eye_height_m is not None and terrain is None:
            raise SceneError(f"observers[{g}].eye_height_m: needs a terrain to stand on")
        if ob.layout == "track":  # evaluated over time (hazard.pipeline.motion): no static points
            part = GroupPoints(start, 0, stored(np.empty((0, 3))))
        elif ob.layout == "grid":
            part = _grid_part(g, ob, spec, offset, terrain, start, rise)
        else:
            p = _group_points(g, ob, spec, offset, terrain, rise) - offset
            part = GroupPoints(start, len(p), stored(p))
        parts.append(part)
        grp.append(np.full(part.count, g))
        idx.append(np.arange(part.count))
        start += part.count
    if not parts:
        return Observers.from_points(np.empty((0, 3)), np.empty(0, int), np.empty(0, int), ())
    return Observers(tuple(parts), np.concatenate(grp), np.concatenate(idx),
                     tuple(o.name for o in spec.observers), tuple(o.optics for o in spec.observers))


def _check_aim_track(spec, laser_local, direction, offset) -> None:
    """A slewing beam's aim stays in ``[laser] sector`` (:func:`scenes.motion.check_aim_sector`)."""
    from .motion import aim_schedule, check_aim_sector

    try:
        check_aim_sector(spec, aim_schedule(spec, laser_local, direction, offset))
    except ValueError as exc:
        raise SceneError(str(exc)) from None


def _check_triangles(total: int, where: str) -> None:
    """The mesh files' triangles read so far within HAZARD_MAX_MESH_TRIANGLES (one file is
    checked alone as it is read; this bounds their sum)."""
    try:
        check_limit("MESH_TRIANGLES", total, f"triangles of the mesh files in all (up to {where})")
    except ValueError as exc:
        raise SceneError(str(exc)) from None


def _beam_direction(spec: SceneSpec, lp) -> np.ndarray:
    """The laser's unit direction from ``aim_m`` (or ``direction``); SceneError when undefined."""
    if spec.laser.aim_m is not None:
        d = np.asarray(spec.laser.aim_m, float) - lp
    else:
        d = np.asarray(spec.laser.direction, float)
    norm = float(np.linalg.norm(d))
    if not (math.isfinite(norm) and norm > 1e-6):
        which = "aim_m" if spec.laser.aim_m is not None else "direction"
        raise SceneError(f"laser.{which}: the beam direction is undefined ({norm:.3g} m from the laser; expected an aim point "
                         f"at least 1 um away, or a non-zero direction)")
    return d / norm


def _bodies(spec: SceneSpec, offset, base_dir: Path | None):
    """Targets and occluder meshes in the scene's frame, the mesh files' triangles in all
    checked as each is read (100 files of 1e6 each: ~10 GB); also the series-cover notes."""
    targets, triangles = [], 0
    for i, ts in enumerate(spec.targets):
        targets.append(_target(i, ts, offset, base_dir, spec.laser.polarization, spec.laser.wavelength_nm))
        triangles += len(targets[-1].mesh.faces) if ts.shape == "mesh" else 0
        _check_triangles(triangles, f"targets[{i}]")
    held = _check_series_cover(spec, targets)
    occluders = []
    for i, os_ in enumerate(spec.occluders):
        try:
            m = shape_mesh(os_, base_dir)
        except ValueError as exc:
            raise SceneError(f"occluders[{i}]: {exc}") from None
        m.vertices = m.vertices - offset
        occluders.append(m)
        triangles += len(m.faces) if os_.shape == "mesh" else 0
        _check_triangles(triangles, f"occluders[{i}]")
    return targets, occluders, held


def _ground(spec: SceneSpec, offset, base_dir: Path | None, site, n_bodies: int):
    """The terrain in the scene's frame and its reflecting target (None, None without one)."""
    if spec.terrain is None:
        return None, None
    try:
        hf = site.heightfield if site is not None else terrain_heightfield(spec.terrain, base_dir)
    except ValueError as exc:
        raise SceneError(str(exc)) from None
    terrain = Heightfield(hf.x0 - offset[0], hf.y0 - offset[1], hf.dx, hf.heights - offset[2])
    return terrain, _terrain_target(spec, terrain, n_bodies, base_dir)


def _compile(spec: SceneSpec, source: str, base_dir: Path | None, text: str, site=None) -> Scene:
    offset = np.asarray(spec.targets[0].center_m, float)
    lp = np.asarray(spec.laser.position_m, float)
    d = _beam_direction(spec, lp)
    targets, occluders, held = _bodies(spec, offset, base_dir)
    terrain, terrain_target = _ground(spec, offset, base_dir, site, len(targets) + len(occluders))
    _check_laser_in_open_air(spec, lp, offset, terrain)

    observers = _observers(spec, offset, terrain, None if site is None else site.frame.refraction_rise_m)
    _check_aim_track(spec, lp - offset, d, offset)
    scene = Scene(
        spec=spec,
        source=source,
        base_dir=base_dir,
        text_sha256=hashlib.sha256(text.encode()).hexdigest(),
        offset_m=offset,
        laser_position_m=lp - offset,
        laser_direction=d,
        targets=targets,
        occluders=occluders,
        terrain=terrain,
        observers=observers,
        terrain_target=terrain_target,
        warnings=(_warnings(spec) + _buried_targets(targets, terrain) + _material_notes(targets)
                  + ([] if site is None else site.warnings)
                  + _near_aperture(observers, lp - offset, d, spec.observers, offset) + held),
        site=site,
    )
    _check_work(scene)
    return scene


def _check_work(scene: Scene) -> None:
    """The checks of a loaded scene that every verb runs before work (so ``hazard validate``
    refuses what ``run``, ``risk`` and ``study`` would): its motion within the limits and
    its aim track clear of the aperture (:func:`scenes.motion.check_motion`), a height
    map's footprint work (``FOOTPRINT_WORK``), and every
    material file of ``[uncertainty] materials`` readable and valid for its target."""
    from .motion import check_motion

    t, a = scene.spec.terrain, scene.spec.analysis
    try:
        check_motion(scene)
        if t is not None and t.kind == "heightmap":  # its nodes are known only now (scenes.spec.total_work counts the others)
            n, spots = scene.terrain.heights.size, len(scene.targets) + 1
            check_limit("FOOTPRINT_WORK", float(n) * a.beam_samples * spots, f"ground footprint work: height map nodes x "
                        f"beam_samples x spots ({n} x {a.beam_samples} x {spots}; fewer analysis.beam_samples)")
    except ValueError as exc:
        raise SceneError(str(exc)) from None
    u = scene.spec.uncertainty
    names = [t.name for t in scene.targets]
    for c in (u.materials if u is not None else ()):
        k = names.index(c.target)
        for j, ms in enumerate(c.materials):
            alternative_material(scene, k, ms, f"uncertainty.materials[{c.target!r}].materials[{j}]")


def _resolve_geo(data: dict, source: str, base_dir):
    """``*_geo`` positions converted to the site frame (:mod:`scenes.geo_input`); errors
    name the key."""
    from .geo import GeoError
    from .geo_input import resolve_geo

    def validate(cls, value, path):
        try:
            return cls.model_validate(value)
        except ValidationError as exc:
            msg = format_validation_error(exc, source).removeprefix(f"{source}: ")
            raise SceneError(f"{source}: {path}{'' if msg.startswith('(scene)') else '.'}{msg.removeprefix('(scene)')}") from None

    try:
        return resolve_geo(data, None if base_dir is None else Path(base_dir), validate)
    except GeoError as exc:
        raise SceneError(f"{source}: {exc}") from None


def _read_units(data: dict, source: str):
    """Quantity strings converted to the suffixed keys' units, then the beam's diameter and
    divergence to 1/e full angle (:mod:`scenes.quantities`, :mod:`scenes.conventions`);
    errors name the key."""
    from .conventions import ConventionError, convert_beam
    from .quantities import QuantityError, convert_units

    try:
        data, units = convert_units(data)
        data, beam = convert_beam(data)
    except (QuantityError, ConventionError) as exc:
        raise SceneError(f"{source}: {exc}") from None
    return data, units, beam


def loads(text: str, *, source: str = "<scene>", base_dir=None) -> Scene:
    """Scene from TOML text; relative file names resolve against ``base_dir``."""
    try:
        # parsing costs time and memory per byte (about 0.8 s of CPU per MB of scene: README, Input checks)
        check_limit("SCENE_MB", len(text) / 1e6, f"{source}: scene text size [MB]")
        data = parse_toml(text, source)  # bounded nesting; one-line errors
    except ValueError as exc:
        raise SceneError(str(exc)) from None
    return from_data(data, source=source, base_dir=base_dir, text=text)


def from_data(data: dict, *, source: str = "<scene>", base_dir=None, text=None) -> Scene:
    """Scene from already-parsed TOML data (a dict), e.g. a study's modified base scene."""
    if not isinstance(data, dict):
        raise SceneError(f"{source}: expected a table of scene keys, got {type(data).__name__}")
    if text is None:
        text = json.dumps(data, sort_keys=True, default=str)
    raw = copy.deepcopy(data)
    try:
        data, units, beam = _read_units(data, source)
        data, site = _resolve_geo(data, source, base_dir)
        spec = SceneSpec.model_validate(data)
    except SceneError:
        raise
    except ValidationError as exc:
        raise SceneError(format_validation_error(exc, source)) from None
    except RecursionError:
        raise SceneError(f"{source}: nesting too deep") from None
    except ValueError as exc:  # limits checked outside pydantic's own validators
        raise SceneError(f"{source}: {' '.join(str(exc).split())}") from None
    try:
        scene = _compile(spec, source, None if base_dir is None else Path(base_dir), text, site)
        scene.source_data, scene.units_as_written, scene.beam_conventions = raw, units, beam
        return scene
    except SceneError as exc:
        msg = str(exc)
        raise SceneError(msg if msg.startswith(source) else f"{source}: {msg}") from None


def load(path) -> Scene:
    """Read, validate and convert a TOML scene file. This is the one acceptance of a scene
    for every verb (``hazard validate``, ``run``, ``compare``, ``render``, ``risk`` and a
    study's scenarios): the schema, the limits, the files it names (``[uncertainty]``'s
    too) and the motion's checks (:func:`_check_work`); SceneError otherwise."""
    path = Path(path)
    try:
        text = read_input_text(path, "scene")  # regular file of bounded size, UTF-8
    except ValueError as exc:
        raise SceneError(str(exc)) from None
    return loads(text, source=str(path), base_dir=path.parent)


def examples() -> dict:
    """Bundled example scenes: name -> path of the TOML file."""
    folder = resources.files("scenes").joinpath("examples")
    return {Path(p.name).stem: Path(str(p)) for p in sorted(folder.iterdir(), key=lambda q: q.name) if p.name.endswith(".toml")}


def example_path(name: str) -> Path:
    ex = examples()
    if name not in ex:
        raise SceneError(f"example {name!r} is unknown: expected one of {sorted(ex)}")
    return ex[name]


def json_schema() -> dict:
    """JSON schema of scene files (for editors)."""
    from .quantities import schema_with_units

    schema = schema_with_units(SceneSpec.model_json_schema())  # power = "20 kW" beside power_w
    schema["$schema"] = "https://json-schema.org/draft/2020-12/schema"
    schema["title"] = "laser-hazard scene"
    return schema
