"""Scene files: pydantic v2 classes that validate a TOML scene at load.

Every class forbids unknown keys, so a misspelled key is an error with its path
(``targets[2].material.reflectance``). Units are SI and in the key names; wavelengths in
nm. The classes only validate; :mod:`scenes.scene` converts them once to numpy arrays.

Types are strict (``power_w = true`` or ``"5"`` is an error, not 1 W or 5 W), every number
must be finite and within a physical range, and the total work a scene asks for (observer
points, explicit points, targets, beam rays, table nodes, time steps, keep-out cells, risk
point evaluations) is bounded by the limits of :data:`brdfmodels.fileio.LIMITS` (raise them
with ``HAZARD_MAX_<NAME>``), each chosen from a measured cost (README, Input checks).
"""

from __future__ import annotations

import math
from typing import Annotated, Literal

from pydantic import BaseModel, ConfigDict, Field, field_validator, model_validator

from brdfmodels.fileio import check_limit

__all__ = [
    "SceneSpec",
    "LaserSpec",
    "ExposureSpec",
    "TargetSpec",
    "MaterialSpec",
    "HistorySpec",
    "OccluderSpec",
    "TerrainSpec",
    "ObserverSpec",
    "OpticsSpec",
    "AtmosphereSpec",
    "AnalysisSpec",
    "SectorSpec",
    "RangeSpec",
    "SiteSpec",
    "AimTrackSpec",
    "TargetTrackSpec",
    "MotionSpec",
    "AirZoneSpec",
    "AirspaceSpec",
    "STANDARD_KEYS",
    "uncertain_inputs",
    "risk_evaluations",
    "check_risk",
]

# the standards hazard.physics.mpe knows; kept here because scenes may not import hazard
STANDARD_KEYS = ("ansi-z136.1-2014", "iec-60825-1-2014", "ansi-z136.1-2007", "iec-60825-1-2007")

# the smallest non-zero divergence: a Gaussian beam's 1/e full angle is at least 2 lambda / (pi D) (D its 1/e diameter),
# 2.5e-9 rad at 400 nm through a 100 m aperture (the schema's extremes); 1e-308 made NOHDs of 1e305 m
DIVERGENCE_MIN_RAD = 1e-9

# coordinates and direction components [m]: |x| <= 1e8 m (beyond the Moon's orbit is not a scene)
Coord = Annotated[float, Field(ge=-1e8, le=1e8)]
Vec3 = Annotated[list[Coord], Field(min_length=3, max_length=3)]
Name = Annotated[str, Field(min_length=1, max_length=200)]
# a geodetic position (scenes.geo_input converts it to *_m before validation; needs a [site]):
# [lat_deg, lon_deg, height_m] (or [easting_m, northing_m, height_m] in a projected site.crs), or
# [lat_deg, lon_deg] standing on the terrain
GeoPos = Annotated[list[float], Field(min_length=2, max_length=3)]
_GEO = "geodetic form of {0}: [lat_deg, lon_deg, height_m], or [lat_deg, lon_deg] on the terrain (needs a [site])"
_AGL = "height above the terrain [m] of a two-number {0} (needs a [site] and a terrain)"


class _Strict(BaseModel):
    # strict: no bool -> number, no "5" -> 5; allow_inf_nan=False: every float finite
    model_config = ConfigDict(extra="forbid", frozen=True, strict=True, allow_inf_nan=False)


def _finite(v, name):
    for x in v if isinstance(v, list) else [v]:
        if not math.isfinite(x):
            raise ValueError(f"{name}: expected finite numbers, got {x!r}")
    return v


def _nonzero(v, name):
    if math.fsum(x * x for x in v) <= 0:
        raise ValueError(f"{name}: expected a non-zero direction vector, got {v!r}")
    return v


Time = Annotated[float, Field(ge=-1e9, le=1e9)]  # scenario time [s]


POINT_SPACING_MIN_M = 1e-6  # the least length [m] of an observer grid's edge or line holding several points
MOTION_STEP_MIN_S = 1e-6  # the least time between a moving thing's key times, or a firing window's length [s]


def _increasing(times, where):
    if any(b <= a for a, b in zip(times, times[1:])):
        raise ValueError(f"{where}={times!r}: expected strictly increasing times [s]")
    short = next((i for i, (a, b) in enumerate(zip(times, times[1:])) if b - a < MOTION_STEP_MIN_S), None)
    if short is not None:
        raise ValueError(f"{where}: times {short} and {short + 1} are {times[short + 1] - times[short]:.3g} s apart; expected at "
                         f"least {MOTION_STEP_MIN_S:g} s between the key times of a motion (a shorter one cannot be resolved)")
    return times


def _rows_match(times, rows, key):
    if rows is not None and len(rows) != len(times):
        raise ValueError(f"{key}: expected one row per time of times_s ({len(times)}), got {len(rows)}")


class AimTrackSpec(_Strict):
    """The laser's aim over scenario time: ``aim_m`` points at ``times_s`` (the aim point
    linear in time between them), or constant ``azimuth_rate_deg_s`` (clockwise from +y)
    and ``elevation_rate_deg_s`` from the ``[laser]`` aim over ``times_s = [t0, t1]``. Before
    the first and after the last time the aim holds."""

    times_s: list[Time] = Field(min_length=1, max_length=100_000, description=(
        "scenario times [s], strictly increasing (required): the key times of aim_m, or the span [t0, t1] of the rates"))
    aim_m: list[Vec3] | None = Field(default=None, description="aim points [m] at times_s (or aim_geo)")
    aim_geo: list[GeoPos] | None = Field(default=None, description="aim points [[lat_deg, lon_deg, height_m], ...] (needs a [site])")
    azimuth_rate_deg_s: float | None = Field(default=None, ge=-3600.0, le=3600.0, description="slew rate in bearing [deg/s], clockwise from +y")
    elevation_rate_deg_s: float | None = Field(default=None, ge=-3600.0, le=3600.0, description="slew rate in elevation [deg/s]")

    @model_validator(mode="after")
    def _one_form(self):
        _increasing(self.times_s, "times_s")
        rates = self.azimuth_rate_deg_s is not None or self.elevation_rate_deg_s is not None
        if (self.aim_m is not None) == rates:
            raise ValueError("give aim_m (aim points at times_s) or azimuth_rate_deg_s / elevation_rate_deg_s (rates from the "
                             "[laser] aim over times_s = [t0, t1]), exactly one")
        if rates and len(self.times_s) != 2:
            raise ValueError(f"times_s={self.times_s!r}: with rates, expected the span [t0, t1]")
        _rows_match(self.times_s, self.aim_m, "aim_m")
        return self


class TargetTrackSpec(_Strict):
    """A target moving: its ``center_m`` at ``times_s`` (linear between; held before and after;
    the shape keeps its orientation)."""

    times_s: list[Time] = Field(min_length=1, max_length=100_000, description="scenario times [s] of center_m, strictly increasing (required)")
    center_m: list[Vec3] | None = Field(default=None, description="the centre [m] at times_s (or center_geo)")
    center_geo: list[GeoPos] | None = Field(default=None, description="the centre as [[lat_deg, lon_deg, height_m], ...] (needs a [site])")

    @model_validator(mode="after")
    def _rows(self):
        _increasing(self.times_s, "times_s")
        if self.center_m is None:
            raise ValueError("center_m: the track's centres are required (or center_geo with a [site])")
        _rows_match(self.times_s, self.center_m, "center_m")
        return self


class SectorSpec(_Strict):
    """Where the beam may point: compass bearings clockwise from +y (north) and elevations
    above the horizontal, both [deg], each ``[low, high]``."""

    azimuth_deg: list[Annotated[float, Field(ge=-720.0, le=720.0)]] = Field(min_length=2, max_length=2, description=(
        "[low, high] compass bearings [deg], clockwise from +y (north with a [site]); 0 <= high - low <= 360 "
        "([350, 370] spans north); required"))
    elevation_deg: list[Annotated[float, Field(ge=-90.0, le=90.0)]] = Field(min_length=2, max_length=2, description=(
        "[low, high] elevations above the horizontal (the x-y plane) [deg], -90 to 90; required"))

    @model_validator(mode="after")
    def _order(self):
        a0, a1 = self.azimuth_deg
        if not 0 <= a1 - a0 <= 360:
            raise ValueError(f"azimuth_deg={self.azimuth_deg!r}: expected [low, high] with 0 <= high - low <= 360 (e.g. [350, 370] across north)")
        e0, e1 = self.elevation_deg
        if e1 < e0:
            raise ValueError(f"elevation_deg={self.elevation_deg!r}: expected [low, high]")
        return self


class LaserSpec(_Strict):
    """The laser: CW (``power_w``) or pulsed (``pulse_energy_j``, ``pulse_duration_s``, ``prf_hz``)."""

    wavelength_nm: float = Field(ge=180.0, le=1.0e6, description=(
        "wavelength [nm], 180 nm to 1 mm (the MPE tables' range; the UV rows, 180-400 nm, are [M]: see hazard.physics.mpe)"))
    power_w: float | None = Field(default=None, ge=1e-9, le=1e9, description="CW power [W], 1 nW to 1 GW")
    pulse_energy_j: float | None = Field(default=None, ge=1e-15, le=1e7, description="energy per pulse [J], 1 fJ to 10 MJ")
    pulse_duration_s: float | None = Field(default=None, ge=1e-13, le=3e4, description="pulse duration [s] (the MPE tables start at 1e-13 s)")
    prf_hz: float | None = Field(default=None, ge=1e-6, le=1e12, description="pulse repetition frequency [Hz], 1e-6 to 1e12")
    beam_diameter_m: float = Field(ge=1e-6, le=100.0, description="beam diameter at the aperture, 1/e points [m] (at least 1 um)")
    divergence_rad: float = Field(ge=0, le=math.pi, description="full-angle divergence, 1/e points [rad]")
    # scenes.conventions converts both values to these (the standards' form) at load, before validation
    diameter_definition: Literal["1/e", "1/e2", "d86", "fwhm"] = Field(default="1/e", description=(
        "level at which beam_diameter_m is given: '1/e' (default, the standards' irradiance 1/e points), '1/e2', 'd86' "
        "(86.5 % power) or 'fwhm'; converted at load to 1/e for a Gaussian beam (the report shows the conversion)"))
    divergence_definition: Literal["full_1/e", "full_1/e2", "full_d86", "full_fwhm", "half_1/e", "half_1/e2", "half_d86",
                                   "half_fwhm"] = Field(default="full_1/e", description=(
        "angle and level at which divergence_rad is given: '<full|half>_<1/e|1/e2|d86|fwhm>'; default 'full_1/e' (the "
        "standards' form); converted at load to the 1/e full angle for a Gaussian beam"))
    position_m: Vec3 | None = Field(default=None, description="the aperture [m] (or position_geo)")
    position_geo: GeoPos | None = Field(default=None, description=_GEO.format("position_m"))
    height_agl_m: float | None = Field(default=None, ge=0, le=1e5, description=_AGL.format("position_geo"))
    aim_m: Vec3 | None = Field(default=None, description="point the beam is aimed at [m] (or aim_geo)")
    aim_geo: GeoPos | None = Field(default=None, description=_GEO.format("aim_m"))
    aim_agl_m: float | None = Field(default=None, ge=0, le=1e5, description=_AGL.format("aim_geo"))
    direction: Vec3 | None = Field(default=None, description=(
        "beam direction, a vector of any length in the world frame (normalised; unitless), instead of aim_m"))
    polarization: Literal["unknown", "unpolarized"] = Field(default="unknown", description=(
        "the beam's polarisation for Fresnel mirrors (materials given by n and k): 'unknown' (default) takes the "
        "larger of the s and p reflectances, an upper bound for any polarisation; 'unpolarized' their mean (a randomly "
        "polarised laser). A material that names its own polarization keeps it"))
    pointing_error_rad: float = Field(default=0.0, ge=0, le=0.5, description=(
        "aiming error of the beam (boresight retention + tracking) [rad]: a bound, or one standard deviation "
        "with pointing_error_kind = 'sigma'"))
    pointing_error_kind: Literal["bound", "sigma"] = Field(default="bound", description=(
        "how pointing_error_rad is meant: 'bound' (default; the buffer is pointing_error_rad) or 'sigma' (one standard "
        "deviation; the buffer is pointing_error_sigmas of them)"))
    pointing_error_sigmas: float | None = Field(default=None, gt=0, le=10, description=(
        "with pointing_error_kind = 'sigma': the buffer is this many standard deviations (required: no default is assumed)"))
    pointing_error_source: str = Field(default="", max_length=1000, description="where the pointing error comes from (recorded in the report)")
    sector: SectorSpec | None = Field(default=None, description="the directions the beam may point in (default: the aim alone)")
    aim_track: AimTrackSpec | None = Field(default=None, description="the aim over scenario time (a slewing beam)")
    windows: list[Annotated[list[Time], Field(min_length=2, max_length=2)]] | None = Field(
        default=None, min_length=1, max_length=100_000, description="[[t0_s, t1_s], ...]: when lasing is allowed (scenario time)")

    @property
    def pointing_buffer_rad(self) -> float:
        """The buffer angle around the aim or sector [rad]: the bound, or sigmas x the standard deviation."""
        return self.pointing_error_rad * (self.pointing_error_sigmas if self.pointing_error_kind == "sigma" else 1.0)

    @field_validator("position_m", "aim_m", "direction")
    @classmethod
    def _finite_vec(cls, v, info):
        return None if v is None else _finite(v, info.field_name)

    @field_validator("divergence_rad")
    @classmethod
    def _divergence(cls, v):
        if 0 < v < DIVERGENCE_MIN_RAD:
            raise ValueError(f"{v!r} rad is below the diffraction limit of any beam a scene can describe (>= "
                             f"{DIVERGENCE_MIN_RAD:g} rad for 400 nm through 100 m); give 0 for a collimated beam "
                             f"(the infinite NOHD, conservative)")
        return v

    @field_validator("windows")
    @classmethod
    def _windows(cls, v):
        for i, w in enumerate(v or ()):
            if not w[1] > w[0]:
                raise ValueError(f"window {i} = {w!r}: expected [t0_s, t1_s] with t1_s > t0_s")
            if w[1] - w[0] < MOTION_STEP_MIN_S:
                raise ValueError(f"window {i} = {w!r}: lasts {w[1] - w[0]:.3g} s; expected at least {MOTION_STEP_MIN_S:g} s "
                                 f"(a shorter burst is a pulse: pulse_energy_j, pulse_duration_s, prf_hz)")
        return v

    @model_validator(mode="after")
    def _check(self):
        pulsed = [self.pulse_energy_j, self.pulse_duration_s, self.prf_hz]
        if self.power_w is None and any(p is None for p in pulsed):
            raise ValueError("give power_w (CW) or all of pulse_energy_j, pulse_duration_s, prf_hz (pulsed)")
        if self.power_w is not None and any(p is not None for p in pulsed):
            raise ValueError("give either power_w (CW) or the pulse keys, not both")
        if self.pulse_duration_s is not None and self.pulse_duration_s * self.prf_hz >= 1:
            raise ValueError(f"pulse_duration_s * prf_hz = {self.pulse_duration_s * self.prf_hz:g}: expected < 1")
        if self.position_m is None:
            raise ValueError("position_m: the laser's position is required (or position_geo with a [site])")
        if (self.aim_m is None) == (self.direction is None):
            raise ValueError("give exactly one of aim_m (or aim_geo) or direction")
        if self.aim_m is not None and math.dist(self.aim_m, self.position_m) <= 0:
            raise ValueError(f"aim_m={self.aim_m!r} equals position_m: expected an aim point away from the laser")
        if self.direction is not None:
            _nonzero(self.direction, "direction")
        if self.pointing_error_kind == "sigma" and self.pointing_error_sigmas is None:
            raise ValueError("pointing_error_kind = 'sigma' needs pointing_error_sigmas (the buffer in standard deviations, "
                             "from your range's rules: no default is assumed)")
        if self.pointing_error_kind == "bound" and self.pointing_error_sigmas is not None:
            raise ValueError("pointing_error_sigmas: only used with pointing_error_kind = 'sigma'; remove it")
        return self

    @property
    def average_power_w(self) -> float:
        return self.power_w if self.power_w is not None else self.pulse_energy_j * self.prf_hz


class ExposureSpec(_Strict):
    duration_s: float = Field(ge=1e-13, le=3e4, description="exposure duration the MPE applies to [s]")
    standard: Literal[STANDARD_KEYS] = Field(default="ansi-z136.1-2014", description=(
        "the MPE tables used (default 'ansi-z136.1-2014'; IEC 60825-1:2014 and both 2007 editions for comparison)"))
    extended_source: bool = Field(default=False, description=(
        "apply C_E per observer from the diffuse spot's angular subtense (default false: point-source MPE, conservative)"))
    optics: list[OpticsSpec] = Field(default_factory=list, max_length=16, description=(
        "optical aids anyone on the range might carry (binoculars, scopes): every target reports its NOHDs with each, "
        "beside those of the observer groups' optics"))


class OxidationSpec(_Strict):
    activation_temperature_k: float = Field(ge=0, le=1e6, description="activation temperature T0 of the oxidation law [K] (required)")
    rate_per_s: float = Field(ge=0, le=1e12, description="rate constant of the oxidation law [1/s] (required)")
    initial_extinction: float = Field(ge=0, le=1e3, description="extinction of the oxide at t = 0 [dimensionless] (required)")


_StateName = Literal["temperature_k", "extinction", "time_s", "reflectance_factor", "melt_fraction"]


class HistorySpec(_Strict):
    """How the target's state evolves.

    ``kind = "series"``: a measured series (``times_s`` and ``states`` inline, or a CSV
    ``file`` with columns ``time_s`` and the state). ``kind = "heating"``: a thin-plate
    heating model driven by the laser's peak irradiance on the spot. ``state`` may name two
    states (``["extinction", "melt_fraction"]``) for a two-state material; a series then
    gives ``states`` as pairs (or a CSV with both columns).
    """

    kind: Literal["series", "heating"] = Field(description=(
        "'series': a measured state series (times_s and states, or file); 'heating': the thin-plate heating model (required)"))
    state: _StateName | Annotated[list[_StateName], Field(min_length=2, max_length=2)] = Field(default="temperature_k", description=(
        "the state the material's BRDF is tabulated over (default 'temperature_k' [K]; extinction, melt_fraction and "
        "reflectance_factor are dimensionless, time_s [s]), or two names for a two-state material"))
    times_s: list[Annotated[float, Field(ge=-1e9, le=1e9)]] | None = Field(default=None, description=(
        "a series' times [s] from the start of the exposure, strictly increasing (with states; or file)"))
    states: (list[Annotated[float, Field(ge=-1e9, le=1e9)]]
             | list[Annotated[list[Annotated[float, Field(ge=-1e9, le=1e9)]], Field(min_length=2, max_length=2)]] | None) = Field(
        default=None, description="a series' state values at times_s, in the state's unit (pairs for two states)")
    file: Name | None = Field(default=None, description=(
        "a series as CSV with columns time_s and the state name(s); relative to the scene file"))
    plate: Literal["stainless_steel", "copper"] | None = Field(default=None, description=(
        "a heating history's plate material (required for kind = 'heating')"))
    thickness_m: float | None = Field(default=None, ge=1e-6, le=1.0, description="plate thickness [m], 1 um to 1 m")
    initial_reflectance: float | None = Field(default=None, ge=0, le=1, description=(
        "reflectance of the plate at t = 0 at the laser wavelength [0-1] (default: the stainless_steel or copper preset's)"))
    oxidation: OxidationSpec | None = Field(default=None, description="an oxidation law darkening the heated plate (default none)")
    rtol: float = Field(default=1e-7, ge=1e-14, le=0.1, description="heating ODE tolerance (1e-14 to 0.1)")
    extrapolation: Literal["error", "clamp"] = Field(default="clamp", description=(
        "a series' analysis times outside its times_s: 'clamp' (default; its end states are held) or 'error' (refused)"))

    @property
    def state_names(self) -> list:
        """The state's name, or the two names of a two-state history."""
        return [self.state] if isinstance(self.state, str) else list(self.state)

    @model_validator(mode="after")
    def _check(self):
        names = self.state_names
        if len(names) == 2:
            if names[0] == names[1]:
                raise ValueError(f"state={names!r}: expected two different state names")
            if "reflectance_factor" in names:
                raise ValueError("state: 'reflectance_factor' scales a static material; it cannot be one of two states")
        if self.states is not None and self.states and isinstance(self.states[0], list) != (len(names) == 2):
            raise ValueError(f"states: expected {'pairs [' + ', '.join(names) + ']' if len(names) == 2 else 'numbers'} "
                             f"for state = {self.state!r}")
        if self.kind == "series":
            inline = self.times_s is not None or self.states is not None
            if inline == (self.file is not None):
                raise ValueError("a series history needs times_s and states inline, or a file, not both")
            if inline:
                if self.times_s is None or self.states is None or len(self.times_s) != len(self.states) or len(self.times_s) < 2:
                    raise ValueError("times_s and states: expected two lists of the same length (at least 2)")
                if any(b <= a for a, b in zip(self.times_s, self.times_s[1:])):
                    raise ValueError("times_s: expected strictly increasing times")
        else:
            if self.plate is None:
                raise ValueError("a heating history needs plate = 'stainless_steel' or 'copper'")
            extra = [k for k in ("times_s", "states", "file") if getattr(self, k) is not None]
            if extra:
                raise ValueError(f"{', '.join(extra)}: only for kind = 'series' (a heating history computes its states)")
            if "time_s" in names:
                raise ValueError("state='time_s' is for series histories; a heating history gives temperature_k, extinction, "
                                 "melt_fraction or reflectance_factor")
        return self


def _check_table_keys(p: dict) -> None:
    """The measured-table keys of a material: ``dhr_tolerance`` (0 to 1), ``ignore_columns``
    (names), ``symmetry`` ("plane" or "none")."""
    t = p.get("dhr_tolerance", 0.05)
    if isinstance(t, bool) or not isinstance(t, (int, float)) or not 0 <= t <= 1:
        raise ValueError(f"dhr_tolerance={t!r}: expected the measurement's stated uncertainty of its hemispherical "
                         f"reflectance, 0 to 1")
    c = p.get("ignore_columns", [])
    if not isinstance(c, list) or not all(isinstance(x, str) and x for x in c):
        raise ValueError(f"ignore_columns={c!r}: expected a list of column names")
    if p.get("symmetry", "none") not in ("none", "plane"):
        raise ValueError(f"symmetry={p['symmetry']!r}: expected 'plane' (mirror one-sided data) or 'none'")


class MaterialSpec(BaseModel):
    """A BRDF: ``model`` plus its parameters inline, a saved model ``file`` (JSON), or a
    ``library`` material (:mod:`brdfmodels.library`, with provenance).

    Extra keys are the model's parameters; they are checked by building the model, so a
    misspelled parameter is an error that lists the model's parameters.
    """

    model_config = ConfigDict(extra="allow", frozen=True, strict=True, allow_inf_nan=False)

    model: Name | None = Field(default=None, description=(
        "a registered BRDF model's name (hazard models), its parameters as further keys; or 'table' with a measured file"))
    file: Name | None = Field(default=None, description="a saved BRDF (JSON), relative to the scene file")
    library: Name | None = Field(default=None, description="a material of the library (hazard models --materials), with provenance")
    groove_angle_deg: float = Field(default=0.0, ge=-360.0, le=360.0,
                                    description="angle of the material grooves from the target tangent [deg]")
    melt_tilt_deg: float = Field(default=0.0, ge=0.0, le=45.0,
                                 description="mean tilt of the surface normal at full melt (the slump) [deg], 0 to 45")
    melt_tilt_direction: Literal["up"] | Vec3 = Field(
        default="up", description="where the slump tilts the normal: 'up' (world +z) or a vector in the target frame")
    melt_wander_deg: float = Field(default=0.0, ge=0.0, le=30.0,
                                   description="bound on the random wander of the molten surface's normal [deg], 0 to 30")

    @model_validator(mode="after")
    def _check(self):
        if self.model == "table" and self.file is not None:  # a measured table: { model = "table", file = ..., outside = ... }
            keys = ("outside", "channel", "fill", "grid_deg", "dhr_tolerance", "ignore_columns", "symmetry")
            extra = set(self.model_extra or {}) - set(keys)
            if extra:
                raise ValueError(f"unexpected keys {sorted(extra)} next to model = 'table' and file "
                                 f"(expected {', '.join(keys)})")
            _check_table_keys(self.params)
            g = self.params.get("grid_deg", [2.0, 2.0, 10.0])
            if (not isinstance(g, list) or len(g) != 3 or not all(isinstance(x, (int, float)) and not isinstance(x, bool)
                                                                  and 0.1 <= x <= 45 for x in g)):
                raise ValueError(f"grid_deg={g!r}: expected three node spacings [theta_h, theta_d, phi_d] of 0.1 to 45 deg")
            nodes = math.prod(math.ceil((span - 1e-9) / x) + end for span, x, end in zip((90.0, 90.0, 180.0), g, (1, 1, 0)))
            check_limit("TABLE_NODES", nodes, f"grid_deg={g!r}: table nodes ((90/theta_h + 1) x (90/theta_d + 1) x (180/phi_d))")
            if self.params.get("fill", "envelope") not in ("envelope", "fit"):
                raise ValueError(f"fill={self.params['fill']!r}: expected 'envelope' or 'fit'")
            if self.params.get("outside", "envelope") not in ("error", "envelope", "fit"):
                raise ValueError(f"outside={self.params['outside']!r}: expected 'error', 'envelope' or 'fit'")
            return self
        given = [k for k in ("model", "file", "library") if getattr(self, k) is not None]
        if len(given) != 1:
            raise ValueError("give one of model (with its parameters inline), file or library"
                             + (f"; got {', '.join(given)}" if given else ""))
        if self.model is None and self.model_extra:
            raise ValueError(f"unexpected keys {sorted(self.model_extra)} next to {given[0]}")
        if self.library is not None:
            from brdfmodels.library import entry

            entry(self.library)  # raises ValueError listing the names
        if self.model is not None:
            import brdfmodels

            brdfmodels.create(self.model, **self.model_extra)  # raises ValueError naming the problem
        return self

    @property
    def params(self) -> dict:
        return dict(self.model_extra or {})


_SHAPES = Literal["plate", "disk", "box", "sphere", "cylinder", "mesh"]


class _Shape(_Strict):
    shape: _SHAPES = Field(description=(
        "plate, disk, box, sphere, cylinder or mesh (required); size_m gives the sizes, in the shape's frame: "
        "x along tangent, z along normal, y = normal x tangent"))
    center_m: Vec3 = Field(default=[0.0, 0.0, 0.0], description=(
        "the shape's centre [m] in the world frame (x, y horizontal, z up; east, north, up with a [site]); default the origin"))
    center_geo: GeoPos | None = Field(default=None, description=_GEO.format("center_m"))
    height_agl_m: float | None = Field(default=None, ge=0, le=1e5, description=_AGL.format("center_geo"))
    normal: Vec3 = Field(default=[0.0, 0.0, 1.0], description=(
        "the shape's z axis, a world vector of any length (unitless): a plate's or disk's front face normal, a cylinder's "
        "axis, a box's third edge; default up"))
    tangent: Vec3 = Field(default=[1.0, 0.0, 0.0], description=(
        "the shape's x axis (made perpendicular to normal; unitless): the first size of a plate or box, the material's "
        "groove direction; default +x"))
    size_m: list[Annotated[float, Field(ge=1e-6, le=1e6)]] | None = Field(default=None, description=(  # at least 1 um, as a beam
        "sizes [m], full lengths: plate [width along tangent, height along normal x tangent]; disk [diameter]; box "
        "[edge along tangent, edge along normal x tangent, edge along normal]; sphere [diameter]; cylinder [diameter, "
        "length along normal (the axis)]; mesh: none (required for the others)"))
    file: Name | None = Field(default=None, description=(
        "a mesh's file (STL, OBJ, PLY or OFF) in metres x scale, in the shape's frame; relative to the scene file"))
    scale: float = Field(default=1.0, ge=1e-6, le=1e6, description="a mesh file's units in metres (default 1: the file is in m)")

    @field_validator("center_m", "normal", "tangent")
    @classmethod
    def _finite_vec(cls, v, info):
        _finite(v, info.field_name)
        if info.field_name != "center_m":
            _nonzero(v, info.field_name)
        return v

    @model_validator(mode="after")
    def _sizes(self):
        need = {"plate": 2, "disk": 1, "box": 3, "sphere": 1, "cylinder": 2}
        if self.shape == "mesh":
            if self.file is None:
                raise ValueError("shape='mesh' needs file (STL, OBJ or PLY)")
        else:
            n = need[self.shape]
            if self.size_m is None or len(self.size_m) != n or any(not (s > 0 and math.isfinite(s)) for s in self.size_m):
                raise ValueError(f"size_m={self.size_m!r}: a {self.shape} needs {n} positive size(s) in m")
        n, t = self.normal, self.tangent
        cross = [n[1] * t[2] - n[2] * t[1], n[2] * t[0] - n[0] * t[2], n[0] * t[1] - n[1] * t[0]]
        if math.fsum(c * c for c in cross) <= 1e-18 * math.fsum(x * x for x in n) * math.fsum(x * x for x in t):
            raise ValueError(f"tangent={t!r} is parallel to normal={n!r}: expected a tangent along the surface")
        return self


class TargetSpec(_Shape):
    name: Name = Field(default="target", description="the target's name, unique among targets (default 'target')")
    material: MaterialSpec = Field(description="how the front face reflects (a BRDF; required)")
    back: MaterialSpec | None = Field(default=None, description=(
        "material of the back face (plates, disks, open meshes); without it a beam on the back reflects nothing, and the report says so"))
    history: HistorySpec | None = Field(default=None, description=(
        "how the target's state evolves under the beam (a dynamic BRDF); default none (a static material)"))
    track: TargetTrackSpec | None = Field(default=None, description="the target's centre over scenario time (a moving target)")


class OccluderSpec(_Shape):
    name: Name = Field(default="occluder", description="the occluder's name (default 'occluder'); it blocks rays and reflects nothing")


class SiteSpec(_Strict):
    """Where the scene is on the earth: the origin of its exact east-north-up frame
    (:mod:`scenes.geo`). With a site, every ``*_m`` position may be given in geodetic form
    ``*_geo`` and the terrain may be a DEM."""

    origin: list[float] = Field(min_length=3, max_length=3, description=(
        "[lat_deg, lon_deg, height_m] (WGS 84; the height in the vertical datum) of the frame's origin"))
    vertical: Literal["ellipsoid", "egm96"] = Field(default="ellipsoid", description=(
        "datum of every height given: 'ellipsoid' (WGS 84) or 'egm96' (orthometric, converted with PROJ's geoid grid "
        "us_nga_egm96_15.tif; an error names it when it is missing)"))
    crs: Name = Field(default="EPSG:4326", description=(
        "how *_geo positions are read: a geographic CRS takes [lat_deg, lon_deg, height_m], a projected one (e.g. UTM "
        "'EPSG:32611') [easting_m, northing_m, height_m]"))
    refraction_k: float = Field(default=0.13, ge=0.0, lt=1.0, description=(
        "atmospheric refraction coefficient: the ground falls (1 - k) d^2 / (2 R) below the beam instead of d^2 / (2 R) "
        "(an apparent rise k d^2 / (2 R) seen from the laser; 0.13: standard atmosphere; 0 switches it off). Beams reach "
        "past the geometric horizon, conservative for observers beyond it"))

    @field_validator("origin")
    @classmethod
    def _origin(cls, v):
        lat, lon, h = v
        if not (-90 < lat < 90 and -180 <= lon <= 360 and -1.2e4 <= h <= 1e5):
            raise ValueError(f"expected [lat_deg, lon_deg, height_m] with |lat| < 90, lon in [-180, 360], height in "
                             f"[-12 km, 100 km], got {v!r} (a pole has no east and north)")
        return v


class TerrainSpec(_Strict):
    """Ground: a heightmap (``file`` .npy of heights [m], ``origin_m`` and ``spacing_m``), a
    ``dem`` (``file`` a local GeoTIFF or DTED file, in its own CRS; needs a
    ``[site]``; resampled to ``resolution_m`` over ``extent_m`` about ``center_m``) or a
    procedural ``hill`` / ``valley`` (Gaussian bump) / ``flat`` ground."""

    kind: Literal["heightmap", "dem", "hill", "valley", "flat"] = Field(description=(
        "heightmap (.npy grid), dem (GeoTIFF or DTED, needs a [site]), or procedural hill, valley or flat (required)"))
    file: Name | None = Field(default=None, description="a heightmap's .npy or a dem's GeoTIFF/DTED file, relative to the scene file")
    nodata: Literal["error", "fill"] = Field(default="error", description=(
        "a DEM's missing cells in the analysis area: 'error', or 'fill' by GDAL's inverse-distance interpolation "
        "(rasterio.fill.fillnodata; the report gives how many were filled)"))
    origin_m: list[Coord] = Field(default=[0.0, 0.0], min_length=2, max_length=2, description=(
        "a heightmap's first node [x, y] [m] in the world frame (default [0, 0]); rows along y, columns along x"))
    spacing_m: float | None = Field(default=None, ge=1e-3, le=1e5, description="a heightmap's node spacing [m] (required for a heightmap)")
    center_m: Vec3 = Field(default=[0.0, 0.0, 0.0], description=(
        "centre [m] of a procedural hill or valley, or of a dem's resampled grid; default the origin"))
    center_geo: GeoPos | None = Field(default=None, description=_GEO.format("center_m") + "; a dem's grid centre")
    height_m: float = Field(default=10.0, ge=-1e5, le=1e5, description=(
        "a hill's height (a valley's depth) above center_m's z [m], default 10; a flat ground's height is center_m's z"))
    radius_m: float = Field(default=100.0, ge=1e-3, le=1e7, description=(
        "a hill's or valley's width [m], the Gaussian's standard deviation: height_m exp(-r^2 / (2 radius_m^2)); default 100"))
    extent_m: float = Field(default=500.0, ge=1e-3, le=1e7, description="half-width of the procedural ground [m]")
    resolution_m: float = Field(default=5.0, ge=1e-3, le=1e6, description="grid spacing [m] of procedural and dem ground, default 5")
    material: MaterialSpec | None = Field(default=None, description=(
        "how the ground reflects the beam that lands on it (static); default Lambertian of reflectance "
        "TERRAIN_DEFAULT_REFLECTANCE = 1, the most any diffuse ground can return (snow at 1 um reaches 0.8-0.9)"))

    @model_validator(mode="after")
    def _check(self):
        if self.kind == "heightmap" and (self.file is None or self.spacing_m is None):
            raise ValueError("a heightmap terrain needs file (.npy) and spacing_m")
        if self.kind == "dem" and self.file is None:
            raise ValueError("a dem terrain needs file (a local GeoTIFF or DTED file)")
        if self.kind != "dem" and self.nodata != "error":
            raise ValueError("nodata: only for kind = 'dem'")
        if self.kind != "heightmap" and self.extent_m / self.resolution_m > 2000:
            raise ValueError(f"extent_m / resolution_m = {self.extent_m / self.resolution_m:g}: at most 2000 cells per half-width")
        return self


class OpticsSpec(_Strict):
    magnification: float = Field(ge=1, le=1e4, description="magnification of the optical aid (e.g. 7 for 7x50 binoculars; required)")
    objective_diameter_m: float = Field(gt=0, le=100.0, description="objective (entrance) diameter [m] (0.05 for 7x50 binoculars; required)")
    transmission: float = Field(default=1.0, gt=0, le=1, description="optical transmission [0-1] (default 1, the conservative bound)")


class ObserverSpec(_Strict):
    """Observers: explicit ``points_m``, a ``line`` (``start_m``, ``end_m``, ``count``), a
    ``grid`` (``origin_m``, ``u_m``, ``v_m``, ``counts``) or a spherical ``shell``
    (``center_m``, ``radius_m``, ``count``, upper hemisphere)."""

    name: Name = Field(description="the group's name, unique among observer groups (required)")
    points_m: list[Vec3] | None = Field(default=None, description="explicit eye positions [[x, y, z], ...] [m] in the world frame")
    start_m: Vec3 | None = Field(default=None, description="a line's first point [m] (or a straight track's start)")
    end_m: Vec3 | None = Field(default=None, description="a line's last point [m]")
    count: int | None = Field(default=None, ge=1, description="points on a line (both ends included) or a shell")
    origin_m: Vec3 | None = Field(default=None, description="a grid's first corner [m]")
    u_m: Vec3 | None = Field(default=None, description="a grid's whole first edge [m] (a world vector from origin_m to the last column)")
    v_m: Vec3 | None = Field(default=None, description="a grid's whole second edge [m] (from origin_m to the last row)")
    counts: list[Annotated[int, Field(ge=1)]] | None = Field(default=None, min_length=2, max_length=2, description=(
        "a grid's [points along u_m, points along v_m], corners included"))
    center_m: Vec3 | None = Field(default=None, description="a shell's centre [m]")
    radius_m: float | None = Field(default=None, gt=0, le=1e8, description="a shell's radius [m] (points on the upper hemisphere)")
    points_geo: list[GeoPos] | None = Field(default=None, description=_GEO.format("each of points_m"))
    start_geo: GeoPos | None = Field(default=None, description=_GEO.format("start_m"))
    end_geo: GeoPos | None = Field(default=None, description=_GEO.format("end_m"))
    origin_geo: GeoPos | None = Field(default=None, description=_GEO.format("origin_m"))
    center_geo: GeoPos | None = Field(default=None, description=_GEO.format("center_m"))
    eye_height_m: float | None = Field(default=None, ge=0, le=1e5, description="height above the terrain [m]; replaces z")
    optics: OpticsSpec | None = Field(default=None, description="the optical aid every observer of the group uses (default: the naked eye)")
    kind: Literal["track"] | None = Field(default=None, description=(
        "'track': one observer moving (an aircraft): times_s with positions_m (or positions_geo), or start_m, "
        "velocity_m_s and duration_s"))
    times_s: list[Time] | None = Field(default=None, min_length=1, max_length=1_000_000, description="a track's times [s]")
    positions_m: list[Vec3] | None = Field(default=None, description="a track's positions [m] at times_s (linear between)")
    positions_geo: list[GeoPos] | None = Field(default=None, description=(
        "a track's positions [[lat_deg, lon_deg, height_m], ...] at times_s (along the geodesic between; needs a [site])"))
    velocity_m_s: Vec3 | None = Field(default=None, description="a straight flight line's velocity [m/s] from start_m")
    duration_s: float | None = Field(default=None, ge=MOTION_STEP_MIN_S, le=1e7, description="a straight flight line's duration [s]")
    start_time_s: Time | None = Field(default=None, description="a straight flight line's start time [s] (default 0)")

    @model_validator(mode="after")
    def _one_layout(self):
        if self.kind == "track":
            return self._track()
        for key in ("times_s", "positions_m", "velocity_m_s", "duration_s", "start_time_s"):
            if getattr(self, key) is not None:
                raise ValueError(f"{key}: only for a moving observer (kind = 'track')")
        layouts = {
            "points_m": self.points_m is not None,
            "line": self.start_m is not None or self.end_m is not None,
            "grid": self.origin_m is not None or self.u_m is not None or self.v_m is not None,
            "shell": self.radius_m is not None,
        }
        chosen = [k for k, v in layouts.items() if v]
        if len(chosen) != 1:
            raise ValueError(f"give exactly one layout (points_m, line, grid or shell), got {chosen or 'none'}")
        kind = chosen[0]
        if kind == "line" and (self.start_m is None or self.end_m is None or self.count is None):
            raise ValueError("a line needs start_m, end_m and count")
        if kind == "grid" and (self.origin_m is None or self.u_m is None or self.v_m is None or self.counts is None):
            raise ValueError("a grid needs origin_m, u_m, v_m and counts")
        if kind == "shell" and (self.center_m is None or self.count is None):
            raise ValueError("a shell needs center_m, radius_m and count")
        if kind == "points_m":
            if not self.points_m:
                raise ValueError("points_m: expected at least one point")
            for p in self.points_m:
                _finite(p, "points_m")
        if self.counts is not None and any(c < 1 for c in self.counts):
            raise ValueError(f"counts={self.counts!r}: expected positive counts")
        self._spread(kind)
        for key in ("count", "counts"):
            if getattr(self, key) is not None and key not in ({"line": ("count",), "grid": ("counts",), "shell": ("count",)}.get(kind) or ()):
                raise ValueError(f"{key}: not used by a {kind} layout; remove it")
        check_limit("OBSERVERS", self.n_points, f"observer points of {self.name!r}")
        return self

    def _spread(self, kind):
        """A grid edge or a line of several points must have a length (at least 1 um; its
        horizontal part at eye height, where the height is the terrain's): a zero u_m put
        a grid's columns on one another (issue 30 fuzz), the same point counted N times."""
        dims = 2 if self.eye_height_m is not None else 3
        where = " horizontal" if dims == 2 else ""
        if kind == "grid":
            edges = [("u_m", self.u_m, self.counts[0]), ("v_m", self.v_m, self.counts[1])]
        elif kind == "line":
            edges = [("end_m", [b - a for a, b in zip(self.start_m, self.end_m)], self.count)]
        else:
            return
        for key, edge, n in edges:
            if n > 1 and math.hypot(*edge[:dims]) < POINT_SPACING_MIN_M:
                what = "the grid's edge" if kind == "grid" else "the line from start_m"
                raise ValueError(f"{key}: {what} has a{where} length of {math.hypot(*edge[:dims]):.3g} m, so its {n} points "
                                 f"lie on one another; expected at least {POINT_SPACING_MIN_M:g} m (or one point along it)")

    def _track(self):
        others = [k for k in ("points_m", "end_m", "count", "origin_m", "u_m", "v_m", "counts", "center_m", "radius_m",
                              "eye_height_m") if getattr(self, k) is not None]
        if others:
            raise ValueError(f"{others[0]}: not used by a track (times_s with positions_m, or start_m, velocity_m_s and "
                             f"duration_s; heights are absolute)")
        line = [k for k in ("start_m", "velocity_m_s", "duration_s") if getattr(self, k) is not None]
        if self.positions_m is not None or self.times_s is not None:
            if line or self.start_time_s is not None:
                raise ValueError("give times_s with positions_m, or start_m with velocity_m_s and duration_s, not both")
            if self.positions_m is None or self.times_s is None:
                raise ValueError("a track needs times_s and positions_m (or positions_geo with a [site])")
            _increasing(self.times_s, "times_s")
            _rows_match(self.times_s, self.positions_m, "positions_m")
        elif len(line) != 3:
            raise ValueError("a track needs times_s with positions_m, or start_m, velocity_m_s and duration_s; "
                             f"got {line or 'none of them'}")
        return self

    def track_keys(self) -> tuple[list, list]:
        """A track's times [s] and positions [m] (a straight line: its two ends)."""
        if self.positions_m is not None:
            return list(self.times_s), [list(p) for p in self.positions_m]
        t0 = self.start_time_s or 0.0
        end = [a + b * self.duration_s for a, b in zip(self.start_m, self.velocity_m_s)]
        return [t0, t0 + self.duration_s], [list(self.start_m), end]

    @property
    def n_points(self) -> int:
        """Number of points this group makes (without building them; a track makes none:
        it is evaluated over time, :mod:`hazard.pipeline.motion`)."""
        if self.kind == "track":
            return 0
        if self.points_m is not None:
            return len(self.points_m)
        if self.counts is not None and self.origin_m is not None:
            return self.counts[0] * self.counts[1]
        return self.count or 0

    @property
    def layout(self) -> str:
        if self.kind == "track":
            return "track"
        if self.points_m is not None:
            return "points"
        if self.start_m is not None:
            return "line"
        if self.origin_m is not None:
            return "grid"
        return "shell"


class AtmosphereSpec(_Strict):
    attenuation_per_m: float | None = Field(default=None, ge=0, le=10.0, description=(
        "atmospheric attenuation coefficient mu [1/m] (Beer-Lambert exp(-mu d)); default none: no attenuation (conservative)"))
    visibility_km: float | None = Field(default=None, ge=1e-3, le=1e4, description=(
        "meteorological visibility [km], converted to mu by the Kruse model at the wavelength; instead of attenuation_per_m"))

    @model_validator(mode="after")
    def _one(self):
        if self.attenuation_per_m is not None and self.visibility_km is not None:
            raise ValueError("give attenuation_per_m or visibility_km, not both")
        return self


class AnalysisSpec(_Strict):
    """Accuracy knobs and outputs of an analysis."""

    # lower bounds: the MPE tables start at 1e-13 s; a 1e-308 s window overflowed the heating ODE's 1/h (no field named)
    time_end_s: float | None = Field(default=None, ge=1e-13, le=1e6, description="end of the history window [s], 1e-13 to 1e6 (default: exposure duration)")
    time_step_s: float | None = Field(default=None, ge=1e-15, le=1e6, description="time step of the dynamic analysis [s], 1e-15 to 1e6 (default: time_end_s / 100)")
    direction_grid_deg: float = Field(default=2.0, gt=0, le=30, description="keep-out lobe grid resolution [deg]")
    refine_levels: int = Field(default=3, ge=0, le=8, description=(
        "most 4-way splits of a keep-out lobe cell; cells are split only where the volume error estimate asks "
        "(default 3: needed by lobes down to 0.35 deg, nearly free on smooth ones; table in README 'Accuracy and speed')"))
    beam_samples: int = Field(default=256, ge=1, description=(
        "cells of the beam's coarsest grid (at least 16; refined adaptively where edges cross the beam until beam_rtol is met)"))
    beam_rtol: float = Field(default=1e-3, ge=1e-7, le=0.1, description=(
        "bound on the beam power left in cells that straddle an edge, relative to the beam power"))
    footprint_eye_height_m: float = Field(default=1.7, ge=0, le=1e4, description="eye height above the terrain for the ground footprint [m]")
    slump_step_deg: float = Field(default=2.0, ge=0.05, le=10.0, description=(
        "step of the normals a slumping target's keep-out lobe samples over its tilt and wander [deg] "
        "(table in README 'Accuracy and speed')"))

    @model_validator(mode="after")
    def _work(self):
        check_limit("BEAM_SAMPLES", self.beam_samples, "beam_samples")
        g = self.direction_grid_deg
        cells = max(2, round(90 / g)) * max(4, round(360 / g)) * 4.0**self.refine_levels if g >= 1e-6 else math.inf
        check_limit("KEEPOUT_CELLS", float(cells), f"keep-out cells at direction_grid_deg={g:g}, refine_levels={self.refine_levels}")
        return self
    outputs: list[Literal["report", "csv", "render"]] = Field(default=["report", "csv"], description=(
        "not read by the analysis (the command line chooses the files: hazard run --plot/--report, hazard render); "
        "accepted so older scenes load"))


RANGE_SPAN_MAX_M = 1e6  # a range boundary's extent [m]: the largest ranges are a few hundred km across


def range_span_outlier(xy) -> tuple | None:
    """``(k, span_m)`` when the boundary ``[[x, y], ...]`` [m] spans more than
    :data:`RANGE_SPAN_MAX_M` in x or y (k: the vertex farthest from the vertices' median,
    the likely typo), else None. A boundary too wide puts beams that leave the real range
    inside it: a lat / lon typed 0 put one vertex 3400 km off and was analysed silently."""
    a = [[float(x), float(y)] for x, y in xy]
    span = max(max(c) - min(c) for c in zip(*a))
    if span <= RANGE_SPAN_MAX_M:
        return None
    med = [sorted(c)[len(c) // 2] for c in zip(*a)]
    return max(range(len(a)), key=lambda i: math.dist(a[i], med)), span


class RangeSpec(_Strict):
    """The range: its boundary, a polygon of [x, y] points [m] (world coordinates)."""

    boundary_m: list[Annotated[list[Coord], Field(min_length=2, max_length=2)]] | None = Field(
        default=None, min_length=3, max_length=100_000, description="the boundary [[x, y], ...] [m] (or boundary_geo)")
    boundary_geo: list[Annotated[list[float], Field(min_length=2, max_length=2)]] | None = Field(
        default=None, min_length=3, max_length=100_000, description="the boundary as [[lat_deg, lon_deg], ...] (needs a [site])")

    @model_validator(mode="after")
    def _simple(self):
        from shapely.geometry import Polygon

        if self.boundary_m is None:
            raise ValueError("boundary_m: the range boundary is required (or boundary_geo with a [site])")

        poly = Polygon(self.boundary_m)
        if not poly.is_valid or poly.area <= 0:
            from shapely.validation import explain_validity

            why = explain_validity(poly) if not poly.is_valid else "no area (collinear points)"
            raise ValueError(f"boundary_m: expected a simple polygon (points in order around the range), got {why}")
        far = range_span_outlier(self.boundary_m)
        if far is not None:
            raise ValueError(f"boundary_m: the range spans {far[1] / 1e3:.4g} km (point {far[0]} is the farthest from the "
                             f"others); expected at most {RANGE_SPAN_MAX_M / 1e3:g} km across: a coordinate typed wrong? "
                             f"(leave out [range] for no boundary)")
        return self


class MotionSpec(_Strict):
    """How things that move are evaluated over scenario time (:mod:`hazard.pipeline.motion`):
    a base step, refined near beam crossings so that a narrow beam is not stepped over."""

    time_start_s: Time | None = Field(default=None, description="start [s] (default: the earliest time of the tracks, aim track and windows)")
    time_end_s: Time | None = Field(default=None, description="end [s] (default: the latest of them)")
    time_step_s: float = Field(default=0.1, gt=0, le=1e5, description="base time step [s]")
    adaptive: bool = Field(default=True, description=(
        "refine the step near beam crossings (a step of the 1/e radius / relative speed / samples_per_width); "
        "false: the base step only (it can step over a narrow beam)"))
    samples_per_width: int = Field(default=16, ge=2, le=1000, description="samples per 1/e beam radius crossed (error-vs-time table: README, Accuracy)")

    @model_validator(mode="after")
    def _span(self):
        if self.time_start_s is not None and self.time_end_s is not None and not self.time_end_s > self.time_start_s:
            raise ValueError(f"time_end_s={self.time_end_s!r}: expected after time_start_s={self.time_start_s!r}")
        return self


class AirZoneSpec(_Strict):
    """A flight zone: a polygon extruded from ``floor_agl_m`` to ``ceiling_agl_m`` above the
    terrain (above z = 0 without one), where the effective irradiance must stay below its
    ``limit`` (FAA levels, range-safety.md section 5)."""

    name: Name = Field(description="the zone's name, unique among zones (required)")
    limit: Literal["lfed", "czed", "szed", "nohd"] = Field(description=(
        "lfed: 50 nW/cm^2 (laser-free), czed: 5 uW/cm^2 (critical), szed: 100 uW/cm^2 (sensitive), nohd: the MPE"))
    boundary_m: list[Annotated[list[Coord], Field(min_length=2, max_length=2)]] | None = Field(
        default=None, min_length=3, max_length=100_000, description="the zone's outline [[x, y], ...] [m] (or boundary_geo)")
    boundary_geo: list[Annotated[list[float], Field(min_length=2, max_length=2)]] | None = Field(
        default=None, min_length=3, max_length=100_000, description="the outline as [[lat_deg, lon_deg], ...] (needs a [site])")
    floor_agl_m: float = Field(default=0.0, ge=0, le=1e5, description="floor above the terrain [m]")
    ceiling_agl_m: float = Field(gt=0, le=1e5, description="ceiling above the terrain [m] (2,000 ft = 609.6 m)")

    @model_validator(mode="after")
    def _shape(self):
        from shapely.geometry import Polygon

        if self.boundary_m is None:
            raise ValueError("boundary_m: the zone's outline is required (or boundary_geo with a [site])")
        if not self.ceiling_agl_m > self.floor_agl_m:
            raise ValueError(f"ceiling_agl_m={self.ceiling_agl_m!r}: expected above floor_agl_m={self.floor_agl_m!r}")
        poly = Polygon(self.boundary_m)
        if not poly.is_valid or poly.area <= 0:
            raise ValueError(f"boundary_m: expected a simple polygon with an area, got {self.boundary_m!r}")
        return self


class AirspaceSpec(_Strict):
    """Visual interference in the airspace (visible lasers): the weighting of the FAA
    levels and the flight zones to check."""

    visual_correction: Literal["photopic", "none"] = Field(default="photopic", description=(
        "photopic: the CIE 1924 V(lambda) visual correction factor; none: VCF = 1 (the most conservative)"))
    credit_attenuation: bool = Field(default=False, description=(
        "credit the atmosphere's attenuation for the visual-interference distances (the FAA zones usually do not)"))
    zones: list[AirZoneSpec] = Field(default_factory=list, max_length=1000, description="flight zones to check (default none)")

    @model_validator(mode="after")
    def _names(self):
        names = [z.name for z in self.zones]
        if len(set(names)) != len(names):
            raise ValueError(f"zones: names must be unique, got {names}")
        return self


def _check_weights(weights, n: int, what: str) -> None:
    """Relative weights: one per ``what``, at least one positive."""
    if len(weights) != n:
        raise ValueError(f"weights: {len(weights)} weight(s) for {n} {what}(s); expected one per {what}")
    if not sum(weights) > 0:
        raise ValueError("weights: expected at least one positive weight")


class VisibilityDistributionSpec(_Strict):
    """How the meteorological visibility varies between operations (the attenuation per
    draw follows from it by the Kruse model, :func:`hazard.physics.nohd.attenuation_from_visibility`)."""

    distribution: Literal["lognormal", "uniform", "discrete"] = Field(description=(
        "lognormal: median_km and sigma (of ln V); uniform: low_km to high_km; discrete: values_km with weights"))
    median_km: float | None = Field(default=None, ge=1e-3, le=1e4, description="median visibility [km] (lognormal)")
    sigma: float | None = Field(default=None, gt=0, le=5, description="standard deviation of ln(visibility) (lognormal)")
    low_km: float | None = Field(default=None, ge=1e-3, le=1e4, description="lowest visibility [km] (uniform)")
    high_km: float | None = Field(default=None, ge=1e-3, le=1e4, description="highest visibility [km] (uniform)")
    values_km: list[Annotated[float, Field(ge=1e-3, le=1e4)]] | None = Field(default=None, min_length=1, max_length=1000,
                                                                            description="visibilities [km] (discrete)")
    weights: list[Annotated[float, Field(ge=0, le=1e12)]] | None = Field(default=None, min_length=1, max_length=1000,
                                                                       description="their relative frequencies (discrete)")

    @model_validator(mode="after")
    def _keys(self):
        need = {"lognormal": ("median_km", "sigma"), "uniform": ("low_km", "high_km"), "discrete": ("values_km", "weights")}
        for k in need[self.distribution]:
            if getattr(self, k) is None:
                raise ValueError(f"{k}: required for distribution = {self.distribution!r}")
        other = [k for d, ks in need.items() if d != self.distribution for k in ks if getattr(self, k) is not None]
        if other:
            raise ValueError(f"{other[0]}: not used by distribution = {self.distribution!r} (it takes {', '.join(need[self.distribution])})")
        if self.distribution == "uniform" and not self.high_km > self.low_km:
            raise ValueError(f"high_km={self.high_km!r}: expected above low_km={self.low_km!r}")
        if self.distribution == "discrete":
            _check_weights(self.weights, len(self.values_km), "value")
        return self


class ScintillationSpec(_Strict):
    """Scintillation of the direct and mirror beams: log-normal irradiance with mean 1 and
    the Rytov variance of the path (range-safety.md section 6)."""

    cn2_m23: float | None = Field(default=None, gt=0, le=1e-10, description="refractive-index structure constant Cn^2 [m^(-2/3)]")
    turbulence: Literal["weak", "moderate", "strong"] | None = Field(default=None, description=(
        "a class instead of cn2_m23: weak 1e-16, moderate 1e-14, strong 1e-13 m^(-2/3) (the upper end of each class)"))
    wave: Literal["plane", "spherical"] = Field(default="plane", description=(
        "plane: sigma_R^2 = 1.23 Cn^2 k^(7/6) L^(11/6); spherical: 0.407 of it (the plane wave is the larger)"))
    aperture_m: float = Field(default=0.007, gt=0, le=1.0, description=(
        "receiving aperture for aperture averaging [m]; the eye's 7 mm pupil (binocular objectives are not credited)"))

    @model_validator(mode="after")
    def _one(self):
        if (self.cn2_m23 is None) == (self.turbulence is None):
            raise ValueError("give cn2_m23 or turbulence (a class), exactly one")
        return self


class MaterialChoiceSpec(_Strict):
    """A target whose material is one of several (measured or fitted samples), drawn per
    operation with the given weights."""

    target: Name = Field(description="the target's name (required)")
    materials: list[MaterialSpec] = Field(min_length=1, max_length=1000, description="the candidate materials (BRDFs), at least one")
    weights: list[Annotated[float, Field(ge=0, le=1e12)]] | None = Field(default=None, description="relative weights (default: equal)")

    @model_validator(mode="after")
    def _weights(self):
        if self.weights is not None:
            _check_weights(self.weights, len(self.materials), "material")
        return self


class ProbabilityMapSpec(_Strict):
    """The ground grid of the probability map (local metres), at eye height."""

    extent_m: Annotated[list[Coord], Field(min_length=4, max_length=4)] = Field(description="[x_min, x_max, y_min, y_max] [m]")
    spacing_m: float = Field(gt=0, le=1e6, description="cell size [m]")
    eye_height_m: float = Field(default=1.7, ge=0, le=1e4, description=(
        "height of the eye above the terrain [m]; without terrain, above z = 0"))

    @model_validator(mode="after")
    def _extent(self):
        x0, x1, y0, y1 = self.extent_m
        if not (x1 > x0 and y1 > y0):
            raise ValueError(f"extent_m={self.extent_m!r}: expected [x_min, x_max, y_min, y_max] with max > min")
        cells = math.ceil((x1 - x0) / self.spacing_m) * math.ceil((y1 - y0) / self.spacing_m)
        check_limit("OBSERVERS", cells, f"probability map cells ({cells})")
        return self


class UncertaintySpec(_Strict):
    """The random inputs of a probabilistic risk analysis (``hazard risk``) and how many
    operations are drawn. Every input is off (zero) unless given."""

    draws: int = Field(default=20_000, ge=1, le=100_000_000, description="simulated operations (Monte Carlo draws)")
    seed: int = Field(default=0, ge=0, le=2**63 - 1, description="random seed (the same seed gives the same results, serial or on a cluster)")
    sampling: Literal["auto", "plain", "importance"] = Field(default="auto", description=(
        "auto: importance sampling on pointing and tilt toward the hazardous directions when either is uncertain, "
        "else plain; plain: draws from the stated distributions only"))
    sensitivity_draws: int = Field(default=512, ge=0, le=10_000_000, description=(
        "base draws of the first-order Sobol indices (pick-freeze, one more set per uncertain input); 0: none"))
    pointing_sigma_rad: float = Field(default=0.0, ge=0, le=0.5, description="pointing error and jitter: 1-sigma per axis of a 2-D Gaussian [rad]")
    pointing_bias_rad: Annotated[list[Annotated[float, Field(ge=-0.5, le=0.5)]], Field(min_length=2, max_length=2)] = Field(
        default=[0.0, 0.0], description="boresight bias [right, up] of the beam axis [rad]")
    brdf_scale_sigma: float = Field(default=0.0, ge=0, le=5, description="log-normal BRDF scale per target: standard deviation of its ln (median 1)")
    brdf_scale_correlation: float = Field(default=0.0, ge=0, le=1, description="correlation of ln(scale) between targets (1: one draw for all)")
    materials: list[MaterialChoiceSpec] = Field(default_factory=list, max_length=1000, description=(
        "targets whose material is drawn from several (default none)"))
    normal_tilt_sigma_deg: float = Field(default=0.0, ge=0, le=30, description=(
        "surface-normal wander of plate and disk targets: 1-sigma per axis of a 2-D Gaussian tilt [deg]"))
    normal_wander_correlation_time_s: float | None = Field(default=None, gt=0, le=1e6, description=(
        "with it, the tilt wanders over the exposure as a random walk (Ornstein-Uhlenbeck, stationary sigma) with this correlation time [s]"))
    wander_nodes: int = Field(default=16, ge=2, le=256, description="times at which a wandering tilt is evaluated (at most)")
    visibility: VisibilityDistributionSpec | None = Field(default=None, description="visibility varying between draws (default: fixed)")
    scintillation: ScintillationSpec | None = Field(default=None, description="scintillation of the direct and mirror beams (default none)")
    observer_position_sigma_m: float = Field(default=0.0, ge=0, le=1e5, description="observer position: 1-sigma per horizontal axis [m]")
    observer_height_sigma_m: float = Field(default=0.0, ge=0, le=1e4, description="observer height: 1-sigma [m]")
    operations: float | None = Field(default=None, gt=0, le=1e12, description=(
        "operations (shots) per year: the chance of at least one exceedance per year, Poisson"))
    map: ProbabilityMapSpec | None = Field(default=None, description="a ground grid of exceedance probabilities (default none)")

    @model_validator(mode="after")
    def _choices(self):
        names = [m.target for m in self.materials]
        if len(set(names)) != len(names):
            raise ValueError(f"materials: one entry per target, got {names}")
        if self.normal_wander_correlation_time_s is not None and self.normal_tilt_sigma_deg == 0:
            raise ValueError("normal_wander_correlation_time_s: given without normal_tilt_sigma_deg (the wander's size)")
        return self


def uncertain_inputs(spec: "SceneSpec") -> list:
    """The ``[uncertainty]`` input groups that vary between draws, in the order of
    :data:`hazard.drivers.risk.inputs.GROUPS` (the rule of ``RiskModel.active``; the bias alone is
    not random, a tilt needs a plate or disk target, an observer spread needs observers)."""
    u = spec.uncertainty
    if u is None:
        return []
    on = {"pointing": u.pointing_sigma_rad > 0, "material": u.brdf_scale_sigma > 0 or bool(u.materials),
          "tilt": u.normal_tilt_sigma_deg > 0 and any(t.shape in ("plate", "disk") for t in spec.targets),
          "visibility": u.visibility is not None, "scintillation": u.scintillation is not None,
          "observer_position": (u.observer_position_sigma_m > 0 or u.observer_height_sigma_m > 0)
          and any(o.n_points for o in spec.observers)}
    return [g for g, v in on.items() if v]


def risk_evaluations(spec: "SceneSpec", draws: int | None = None, sensitivity_draws: int | None = None) -> float:
    """Point evaluations of a risk analysis: (draws + sensitivity_draws (1 + k)) x (observer
    points + map cells), k the uncertain inputs (the pick-freeze sample evaluates one more
    set per input, and only with k >= 2 and observers). ``draws`` and ``sensitivity_draws``
    override the scene's (``hazard risk --draws``)."""
    u = spec.uncertainty
    k = len(uncertain_inputs(spec))
    n_obs = sum(o.n_points for o in spec.observers)
    sens = u.sensitivity_draws if sensitivity_draws is None else sensitivity_draws
    sens = sens if (k >= 2 and n_obs > 0) else 0
    cells = 0
    if u.map is not None:
        x0, x1, y0, y1 = u.map.extent_m
        cells = math.ceil((x1 - x0) / u.map.spacing_m) * math.ceil((y1 - y0) / u.map.spacing_m)
    return float((draws or u.draws) + sens * (1 + k)) * (n_obs + cells)


def check_risk(spec: "SceneSpec", draws: int | None = None, sensitivity_draws: int | None = None) -> None:
    """A risk analysis the scene (with the ``hazard risk`` overrides) asks for: something
    random, and work within ``HAZARD_MAX_RISK_EVALUATIONS``; ValueError otherwise. Nothing to
    check without ``[uncertainty]``."""
    if spec.uncertainty is None:
        return
    if not uncertain_inputs(spec):
        raise ValueError("uncertainty: nothing is random (an empty table, or every spread zero: give pointing_sigma_rad, "
                         "brdf_scale_sigma, materials, normal_tilt_sigma_deg with a plate or disk, visibility, scintillation "
                         "or an observer spread with observers)")
    n = risk_evaluations(spec, draws, sensitivity_draws)
    check_limit("RISK_EVALUATIONS", n, "uncertainty: point evaluations ((draws + sensitivity_draws (1 + inputs)) x "
                                       "(observer points + map cells))")


# measured CPU seconds per unit of work (README, Input checks), for the estimate of TOTAL_WORK
WORK_S = dict(observer_step=5.7e-8,  # the flagship map at OBSERVER_STEPS: 11.4 s CPU for 2e8
              keepout_cell=1.5e-6,  # the worst keep-out lobe at KEEPOUT_CELLS: 14.6 s CPU for 1e7 cells
              keepout_cell_step=3.3e-8,  # a dynamic lobe: 17 s CPU for 5.2e8 cells x steps
              footprint_pair=1.15e-7)  # range_geo at 5 m integrated exactly: 85 s CPU for 7.4e8 node x sample x spot


def total_work(spec, n_obs, steps, cells) -> float:
    """The work estimates of a scene before any work (README, Input checks), each checked
    against its limit. ``FOOTPRINT_WORK`` = terrain nodes x beam_samples x spots (the ground
    footprint's near-field pairs at most: every node against every beam sample of every
    spot). ``WORK_CPU_S`` = spots x (observer points x steps x 5.7e-8 s + keep-out cells x
    1.5e-6 s + keep-out cells x steps x 3.3e-8 s + terrain nodes x beam_samples x 1.15e-7 s)
    (:data:`WORK_S`): the products of the single limits (targets x observers x steps, targets
    x keep-out cells, ...) in CPU seconds. spots = targets (+ 1 with terrain, whose ground
    reflects); steps = time steps (1 when static). A height map's nodes are known only when
    it is read (``TERRAIN_NODES``) and are not counted. Returns the estimate [s]."""
    t, a, k = spec.terrain, spec.analysis, WORK_S
    spots = len(spec.targets) + (t is not None)
    nodes = 0.0 if t is None or t.kind == "heightmap" else (2 * math.ceil(t.extent_m / t.resolution_m) + 1) ** 2.0
    check_limit("TERRAIN_NODES", nodes, "terrain: nodes ((2 extent_m / resolution_m + 1)^2)")  # the single limit speaks first
    fp = nodes * a.beam_samples * spots
    check_limit("FOOTPRINT_WORK", fp, f"ground footprint work: terrain nodes x beam_samples x spots ({nodes:.0f} x "
                f"{a.beam_samples} x {spots}; fewer with a coarser terrain.resolution_m, a smaller terrain.extent_m or "
                "fewer analysis.beam_samples)")
    cpu = spots * (k["observer_step"] * n_obs * steps + k["keepout_cell"] * cells + k["keepout_cell_step"] * cells * steps
                   + k["footprint_pair"] * nodes * a.beam_samples)
    check_limit("WORK_CPU_S", cpu, f"estimated CPU seconds: spots x (observer points x steps, keep-out cells (x steps), "
                f"terrain nodes x beam_samples, each x its measured cost) with {spots} spots, {n_obs} x {steps:.0f} "
                f"observer steps, {cells:.0f} keep-out cells, {nodes:.0f} x {a.beam_samples} footprint pairs; each within "
                "its own limit (HAZARD_MAX_TARGETS, HAZARD_MAX_OBSERVER_STEPS, HAZARD_MAX_KEEPOUT_CELLS, "
                "HAZARD_MAX_KEEPOUT_STATE_CELLS, HAZARD_MAX_FOOTPRINT_WORK) but not their product")
    return cpu


class SceneSpec(_Strict):
    """A scene file. Positions are in one right-handed world frame [m], z up: with a
    ``[site]`` the exact local east-north-up frame at the site's origin (x east, y north),
    else a local frame whose +y the bearings count from."""

    name: Name = Field(description="the scene's name (required; in every report)")
    description: str = Field(default="", max_length=100_000, description="free text for the report (default empty)")
    laser: LaserSpec = Field(description="the laser: power or pulses, beam (1/e diameter and full-angle divergence), position and aim (required)")
    exposure: ExposureSpec = Field(description="exposure duration and the standard the MPE comes from (required)")
    targets: list[TargetSpec] = Field(min_length=1, description="what the beam may hit and reflect from (at least one)")
    occluders: list[OccluderSpec] = Field(default=[], description="shapes that block rays and reflect nothing (default none)")
    terrain: TerrainSpec | None = Field(default=None, description="the ground (default none: nothing below the scene)")
    observers: list[ObserverSpec] = Field(default=[], description="where eyes may be: the MPE is checked at each point (default none)")
    atmosphere: AtmosphereSpec = Field(default_factory=AtmosphereSpec, description="attenuation along the paths (default none, conservative)")
    analysis: AnalysisSpec = Field(default_factory=AnalysisSpec, description="accuracy knobs (defaults as listed)")  # built per scene: its limit checks read HAZARD_MAX_* then
    range: RangeSpec | None = Field(default=None, description="the range boundary the danger zones are checked against (default none)")
    site: SiteSpec | None = Field(default=None, description="where the scene is on the earth (default none: a local frame only)")
    motion: MotionSpec | None = Field(default=None, description="time stepping of things that move (defaults as listed)")
    airspace: AirspaceSpec | None = Field(default=None, description="FAA visual-interference levels and flight zones (visible lasers)")
    uncertainty: UncertaintySpec | None = Field(default=None, description="the random inputs of hazard risk (default none)")

    @property
    def has_motion(self) -> bool:
        """Something moves or lasing stops: a track, an aim track, a target track or firing windows."""
        la = self.laser
        return (la.aim_track is not None or la.windows is not None or any(t.track is not None for t in self.targets)
                or any(o.kind == "track" for o in self.observers))

    @model_validator(mode="after")
    def _names(self):
        names = [t.name for t in self.targets]
        if len(set(names)) != len(names):
            raise ValueError(f"targets: names must be unique, got {names}")
        if self.terrain is not None and "terrain" in names:
            raise ValueError("targets: the name 'terrain' is the terrain's own (it reflects the beam that lands on it "
                             "under that name); choose another")
        obs = [o.name for o in self.observers]
        if len(set(obs)) != len(obs):
            raise ValueError(f"observers: names must be unique, got {obs}")
        if self.terrain is not None and self.terrain.kind == "dem" and self.site is None:
            raise ValueError("terrain.kind = 'dem' needs a [site] table (origin = [lat_deg, lon_deg, height_m]) to place "
                             "the DEM in the scene's frame")
        for i, m in enumerate(self.uncertainty.materials if self.uncertainty is not None else ()):
            if m.target not in names:
                raise ValueError(f"uncertainty.materials[{i}].target: {m.target!r} is not a target (targets: {names})")
        return self

    @model_validator(mode="after")
    def _work(self):
        n_obs = sum(o.n_points for o in self.observers)
        check_limit("OBSERVERS", n_obs, "observer points in all")
        check_limit("POINTS", sum(len(o.points_m) for o in self.observers if o.points_m is not None and o.kind != "track"),
                    "explicit observer points (points_m) in all")
        check_limit("TARGETS", len(self.targets), "targets")
        check_risk(self)
        a, steps = self.analysis, 1.0
        g = a.direction_grid_deg
        cells = max(2, round(90 / g)) * max(4, round(360 / g)) * 4.0**a.refine_levels
        if any(t.history is not None for t in self.targets):
            t_end = a.time_end_s or self.exposure.duration_s
            steps = t_end / (a.time_step_s or t_end / 100.0)
            check_limit("TIME_STEPS", steps, f"time steps (time_end_s {t_end:g} s / time_step_s {a.time_step_s or t_end / 100:g} s)")
            check_limit("OBSERVER_STEPS", n_obs * steps, f"observer points x time steps ({n_obs} x {steps:.0f})")
            # a dynamic lobe takes each cell's maximum over the states: 1e4 steps ran past 10 min
            check_limit("KEEPOUT_STATE_CELLS", cells * steps, f"keep-out cells x time steps ({cells:.0f} x {steps:.0f}; "
                        "fewer with a coarser analysis.direction_grid_deg or refine_levels, or a longer time_step_s")
        total_work(self, n_obs, steps, cells)
        return self
