"""The JSON Schema of ``report.json`` (``hazard schema --report``), from the result types.

pydantic models mirror what :func:`hazard.outputs.report.report_dict` writes; the stage records'
entries are derived from the :class:`hazard.pipeline.results.Stage` dataclass's own fields (one
source of truth: a field added there is in the schema), the targets' from the keys of
:meth:`hazard.pipeline.results.TargetResult.to_dict` (a test checks the two agree), the observer
rows' from the columns of :func:`hazard.outputs.report.observer_columns` (the ``motion_*`` ones,
:data:`hazard.outputs.motion_outputs.MOTION_COLUMNS`, present only when something moves).

Every block forbids unknown keys (a misspelled or unannounced key fails validation) and
gives every value its JSON type; numbers may also be the strings ``"inf"``, ``"-inf"``,
``"nan"`` (:func:`hazard.outputs.report.json_safe`: JSON has no such numbers and an infinite
NOHD must not vanish). The blocks of the stages (issue 35):

- from the frozen result dataclasses' own fields (:func:`_from_dataclass`): ``mpe``
  (:class:`hazard.physics.mpe.MPEResult`, its ``factors``
  :class:`~hazard.physics.mpe.CorrectionFactors`), ``pulse``
  (:class:`~hazard.physics.mpe.RepetitivePulseResult`), ``uv_24h`` (:class:`~hazard.physics.mpe.UV24hResult`), ``frame.dem``
  (:class:`scenes.dem.DemInfo`), ``verdict`` (:class:`hazard.pipeline.verdict.Verdict`
  without ``warnings``), ``beam.sampling`` (:class:`hazard.pipeline.spots.BeamSampling`),
  ``beam.spill`` (:class:`hazard.pipeline.spill.SpillSummary`), ``extended_source``
  (:class:`hazard.pipeline.extended_source.ExtendedSourceSummary`), ``airspace``
  (:class:`hazard.pipeline.airspace.AirspaceCheck`), ``visual_interference``
  (:class:`hazard.physics.visual.VisualInterference`), ``limiting_aperture``
  (:class:`hazard.physics.aperture.LimitingAperture`), ``map_outputs``
  (:class:`hazard.outputs.map_outputs.MapOutputs`), ``frame`` (:class:`scenes.geo_input.FrameDescription`),
  ``sdz`` (:class:`hazard.pipeline.sdz.DangerZone`, ``mirror_beams`` merged in from that stage) with the aid's part of
  ``sdz.aided[]`` (:class:`hazard.pipeline.spill.AidedNohd`), ``targets[].specular_steps``
  (:class:`hazard.physics.specular.MirrorBeamSteps`), ``motion`` (:class:`hazard.outputs.motion_outputs.MotionSection`,
  its ``aim_track`` :class:`scenes.motion.AimTrackDescription`), ``tracks[]`` and ``motion.fixed_observers[]``
  (:class:`hazard.outputs.motion_outputs.TrackEntry`: the path's
  :class:`hazard.pipeline.motion_results.PathSummary` written flat, then its own keys): a field added there is in
  the schema.

A key a stage writes only in some cases (e.g. ``sdz.escaping_bearing_deg`` when the zone
escapes, ``sdz.leaves_boundary`` with a ``[range]``) is optional here, typed when present.
Left as free objects: ``scene.echo`` and ``scene.units_as_written`` (the scene file as
read), ``targets[].melt``/``slump``/``aided`` and ``keepout_*.near_field``.
"""

from __future__ import annotations

import dataclasses
from typing import Annotated, Any, Literal, Optional, get_args, get_origin, get_type_hints

from pydantic import BaseModel, ConfigDict, Field, TypeAdapter, create_model

from hazard.outputs.map_outputs import MapOutputs
from hazard.outputs.map_zones import ZONE_KINDS
from hazard.outputs.motion_outputs import MOTION_COLUMNS, MotionSection, TrackEntry
from hazard.outputs.report import REPORT_FORMAT, REPORT_VERSION
from hazard.physics.aperture import LimitingAperture as LimitingApertureInfo
from hazard.physics.mpe import CorrectionFactors, MPEResult, RepetitivePulseResult, UV24hResult
from hazard.physics.specular import MirrorBeamSteps
from hazard.physics.visual import TargetLevelDistances, VisualInterference
from hazard.pipeline.airspace import AirspaceCheck, FlightZoneCheck
from hazard.pipeline.sdz import AidedZone as SdzAidedZone
from hazard.pipeline.sdz import DangerZone
from hazard.pipeline.extended_source import ExtendedMpe as ExtendedMpeResult
from hazard.pipeline.extended_source import ExtendedSourceSummary
from hazard.pipeline.motion_results import PathSummary
from hazard.pipeline.results import Stage
from hazard.pipeline.spill import AidedNohd as SpillAidedNohd
from hazard.pipeline.spill import SpillSummary, StoppedSpill
from hazard.pipeline.spots import BeamSampling
from hazard.pipeline.verdict import Verdict
from scenes.dem import DemInfo
from scenes.geo_input import Conversion as GeoConversion
from scenes.geo_input import FrameDescription

__all__ = ["ReportModel", "report_schema", "validate_report"]

#: A JSON number, or the string a non-finite float is written as.
Number = float | Literal["inf", "-inf", "nan"]
Block = Optional[dict[str, Any]]  # a block whose inner keys are not typed here (null when absent)


ABSENT: Any = Field(default=None)  # a key written only in some cases (see the module notes): absent, or typed


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid")


def _json_type(hint: Any) -> Any:
    """The JSON type of a dataclass field's annotation: floats may be "inf"/"nan", a bare
    tuple is written as a list of str (the steps) unless the caller says otherwise, a
    ``tuple[X, ...]`` as a list of X, ``tuple[X, X]`` as a list of exactly two X, ``X | None`` as X's type or null, a nested dataclass as its own strict model
    (:func:`_from_dataclass`, named as the class)."""
    if hint is float:
        return Number
    if hint == (float | None) or hint == Optional[float]:
        return Optional[Number]
    if hint is tuple:
        return list[str]
    if type(None) in get_args(hint) and len(get_args(hint)) == 2:  # X | None: X's JSON type, or null
        return Optional[_json_type(next(a for a in get_args(hint) if a is not type(None)))]
    if get_origin(hint) is tuple and len(get_args(hint)) == 2 and get_args(hint)[1] is Ellipsis:
        return list[_json_type(get_args(hint)[0])]  # type: ignore[misc]
    if get_origin(hint) is tuple and len(set(get_args(hint))) == 1:  # tuple[X, X, X]: a list of exactly 3 X
        n = len(get_args(hint))
        return Annotated[list[_json_type(get_args(hint)[0])], Field(min_length=n, max_length=n)]  # type: ignore[misc]
    if dataclasses.is_dataclass(hint) and isinstance(hint, type):
        return _from_dataclass(hint, hint.__name__)
    return hint


def _from_dataclass(cls, name: str, *, override: Optional[dict[str, Any]] = None, add: Optional[dict[str, Any]] = None,
                    omit: tuple[str, ...] = (), optional: tuple[str, ...] = ()) -> type[BaseModel]:
    """A strict model with the fields of dataclass ``cls`` (types from its annotations via
    :func:`_json_type`; ``override``: field -> JSON type where its ``to_dict`` writes it
    otherwise; ``add``: keys its ``to_dict`` writes beyond the fields; ``omit``: fields its
    ``to_dict`` does not write as such: elsewhere in the report, or as the keys of ``add``). A field the class lists in its
    ``ABSENT_WHEN_NONE`` (its ``to_dict`` leaves the key out when the value is None), or
    ``optional`` names (keys its ``to_dict`` writes only in some cases), is an optional key,
    typed when present: as ``override`` says, else its annotation without None (never null)."""
    hints = get_type_hints(cls)
    over = dict(override or {})
    names = {f.name for f in dataclasses.fields(cls)}
    absent = set(getattr(cls, "ABSENT_WHEN_NONE", ())) | set(optional)
    if (set(omit) | absent) - names:
        raise TypeError(f"{cls.__name__} has no field(s) {sorted((set(omit) | absent) - names)} to omit or leave absent")

    def entry(name: str) -> tuple[Any, Any]:
        if name in over:
            return over.pop(name), (ABSENT if name in absent else ...)
        if name in absent:  # Optional[X] written only when set: X, or the key absent
            return _json_type(next(a for a in get_args(hints[name]) if a is not type(None))), ABSENT
        return _json_type(hints[name]), ...

    fields: dict[str, Any] = {f.name: entry(f.name) for f in dataclasses.fields(cls) if f.name not in omit}
    if over:
        raise TypeError(f"{cls.__name__} has no field(s) {sorted(over)}")
    fields.update({k: (t, ...) for k, t in (add or {}).items()})
    return create_model(name, __config__=ConfigDict(extra="forbid"), **fields)


StageRecord = _from_dataclass(Stage, "StageRecord")


class SceneEcho(_Strict):
    name: str
    source: Optional[str]
    sha256: str
    offset_m: list[Number] = Field(min_length=3, max_length=3)
    echo: dict[str, Any]
    units_as_written: dict[str, Any]
    beam_conventions: Any


class BeamBlock(_Strict):
    power_w: Number
    spill_w: Number
    blocked_w: Number
    sampling: Optional[SamplingBlock]  # type: ignore[valid-type]
    spill: Optional[SpillBlock]  # type: ignore[valid-type]


class TimesBlock(_Strict):
    start: Number
    end: Number
    count: int = Field(ge=1)


class KeepoutSummary(_Strict):
    """:meth:`hazard.physics.keepout.Lobe.summary` (a target without a spot: the empty lobe,
    without ``peak_intensity_w_sr`` and ``power_w``)."""

    max_nohd_m: Number
    peak_intensity_w_sr: Optional[Number] = None
    power_w: Optional[Number] = None
    max_direction: Optional[list[Number]]
    volume_m3: Number
    volume_error_m3: Number
    cells: int
    evaluations: int
    near_field: Block


# ``targets[].specular_steps``: :class:`hazard.physics.specular.MirrorBeamSteps`
MirrorBeamStepsBlock = _from_dataclass(MirrorBeamSteps, "MirrorBeamSteps")


class TargetReport(_Strict):
    """One entry of ``targets``: :meth:`hazard.pipeline.results.TargetResult.to_dict` and ``hit``."""

    name: str
    spot_power_w: Number
    spot_power_error_w: Number
    spot_power_exact: bool
    peak_irradiance_w_m2: Number
    mean_irradiance_w_m2: Number
    lit_side: str
    spot_size_m: Number
    nohd_static_m: Number
    nohd_dynamic_m: Number
    keepout_static: KeepoutSummary
    keepout_dynamic: KeepoutSummary
    specular_nohd_static_m: Optional[Number]
    specular_nohd_dynamic_m: Optional[Number]
    specular_direction: Optional[list[Number]]
    state_name: Any
    state_range: Optional[list[Any]]
    melt: Block
    slump: Block
    aided: list[Any]
    specular_steps: Optional[MirrorBeamStepsBlock]  # type: ignore[valid-type]
    hit: Literal["beam", "wing only", "not reflected", "not hit"]


class FootprintArea(_Strict):
    area_m2: Number
    eye_height_m: Number
    cells: int = Field(ge=0)


# ``limiting_aperture``: what the MPE is compared with, :class:`hazard.physics.aperture.LimitingAperture`
LimitingAperture = _from_dataclass(LimitingApertureInfo, "LimitingAperture")


class ObserversListed(_Strict):
    count: int = Field(ge=0)
    listed: int = Field(ge=0)
    which: str


_ROW_NUMBERS = ("peak_irradiance_w_m2", "direct_irradiance_w_m2", "direct_at_aim_irradiance_w_m2", "reflected_irradiance_w_m2",
                "peak_time_s", "static_irradiance_w_m2", "radiant_exposure_j_m2", "static_radiant_exposure_j_m2", "c_e",
                "mpe_w_m2", "mpe_radiant_exposure_j_m2", "hazard_ratio", "exposure_ratio")
_ROW_MAYBE = ("angular_subtense_rad", "first_exceedance_s", "direct_point_irradiance_w_m2", "aperture_diameter_m")  # null: n/a
_ROW_FLAGS = ("hazardous", "hazardous_static", "line_of_sight", "far_field")

_ROW_FIELDS: dict[str, Any] = {
    "name": (str, ...), "position_m": (list[Number], Field(min_length=3, max_length=3)),
    **{k: (Number, ...) for k in _ROW_NUMBERS}, **{k: (Optional[Number], ...) for k in _ROW_MAYBE},
    **{k: (bool, ...) for k in _ROW_FLAGS},
    **{k: (Optional[Number], None) for k in MOTION_COLUMNS},  # only when something moves
}
ObserverRow = create_model("ObserverRow", __config__=ConfigDict(extra="forbid"), **_ROW_FIELDS)


# -- the stages' blocks ---------------------------------------------------------------------


class MpeLimit(_Strict):
    """One candidate limit of :attr:`hazard.physics.mpe.MPEResult.limits`."""

    name: str
    radiant_exposure_j_m2: Number
    label: str


MpeBlock = _from_dataclass(MPEResult, "MpeBlock", override={"factors": _from_dataclass(CorrectionFactors, "CorrectionFactorsBlock"),
                                                             "limits": list[MpeLimit]}, add={"standard_title": str})


class PulseRule(_Strict):
    rule: str
    per_pulse_radiant_exposure_j_m2: Number


PulseBlock = _from_dataclass(RepetitivePulseResult, "PulseBlock", override={"rules": list[PulseRule], "pulses": Number, "pulse_groups": Number})


# ``uv_24h``: :meth:`hazard.physics.mpe.UV24hResult.to_dict`, the day's summed-dose limit (180-400 nm): its
# fields but ``mpe``, of which it writes ``governing_limit`` and ``table_row``, with the accumulation time and the [M] flag
Uv24hBlock = _from_dataclass(UV24hResult, "Uv24hBlock", omit=("mpe",), add={
    "accumulation_s": Number, "governing_limit": str, "table_row": str, "unverified": bool})


DemBlock = _from_dataclass(DemInfo, "DemBlock")  # frame.dem: scenes.dem.DemInfo
_AS_WRITTEN = list[Number] | list[list[Number]]  # [lat_deg, lon_deg(, height_m)] or x, y(, z) [m], or a list of them
# ``frame.converted[]``: :class:`scenes.geo_input.Conversion`, a ``*_geo`` value converted to the local frame
Conversion = _from_dataclass(GeoConversion, "Conversion", override={"given": _AS_WRITTEN, "m": _AS_WRITTEN})
# ``frame``: :class:`scenes.geo_input.FrameDescription`: the local frame (``kind``, ``statement``), or
# :meth:`scenes.geo.SiteFrame.describe` with ``dem`` and ``converted`` (:meth:`scenes.geo_input.GeoSite.describe`)
FrameBlock = _from_dataclass(FrameDescription, "FrameBlock", override={"dem": DemBlock, "converted": list[Conversion]})  # type: ignore[valid-type]


# ``extended_source``: :class:`hazard.pipeline.extended_source.ExtendedSourceSummary` (``applied`` alone when the
# stage did not apply C_E: its other keys optional; the MPE at a subtense :class:`~hazard.pipeline.extended_source.ExtendedMpe`)
ExtendedMpe = _from_dataclass(ExtendedMpeResult, "ExtendedMpe", override={"pulse": Optional[PulseBlock]})  # type: ignore[valid-type]
ExtendedSourceBlock = _from_dataclass(ExtendedSourceSummary, "ExtendedSourceBlock", optional=ExtendedSourceSummary.ONLY_WHEN_APPLIED,
                                      override={k: Optional[ExtendedMpe] for k in ("mpe_smallest_alpha", "mpe_largest_alpha")})  # type: ignore[valid-type]


# ``beam.sampling``: :class:`hazard.pipeline.spots.BeamSampling` (the ``tail_*`` bounds [W/m^2] with a sampled square)
SamplingBlock = _from_dataclass(BeamSampling, "SamplingBlock")


# ``beam.spill``: :class:`hazard.pipeline.spill.SpillSummary` (its ``aided[]`` :class:`~hazard.pipeline.spill.AidedNohd`,
# also the aid's part of ``sdz.aided[]``; its ``stopped[]`` :class:`~hazard.pipeline.spill.StoppedSpill`)
AidedNohd = _from_dataclass(SpillAidedNohd, "AidedNohd")
SpillBlock = _from_dataclass(SpillSummary, "SpillBlock", override={"stopped": list[_from_dataclass(StoppedSpill, "Stopped")],  # type: ignore[misc]
                                                                   "aided": list[AidedNohd]})  # type: ignore[valid-type]


# ``sdz``: :class:`hazard.pipeline.sdz.DangerZone` (the naked-eye zone's keys :class:`~hazard.pipeline.sdz.GroundZone`
# at its top level, ``directions`` :class:`~hazard.pipeline.sdz.SdzDirections`, ``nominal``
# :class:`~hazard.pipeline.sdz.NominalZone`, ``mirror_beams[]`` :class:`~hazard.pipeline.sdz.MirrorBeam`); ``aided[]``
# :class:`~hazard.pipeline.sdz.AidedZone`: the aid's keys (``AidedNohd``) then the zone's, written flat
class AidedZone(AidedNohd, _from_dataclass(SdzAidedZone, "AidedZoneFields", omit=("aid",))):  # type: ignore[valid-type,misc]
    """``sdz.aided[]``: the aid and its zone."""


SdzBlock = _from_dataclass(DangerZone, "SdzBlock", override={"aided": list[AidedZone]})


# ``verdict``: :class:`hazard.pipeline.verdict.Verdict` without ``warnings`` (report.json's top level)
VerdictBlock = _from_dataclass(Verdict, "VerdictBlock", omit=Verdict.NOT_IN_BLOCK)


# ``visual_interference``: :class:`hazard.physics.visual.VisualInterference` (``reason`` only for a laser that is not
# visible), ``direct`` :class:`~hazard.physics.visual.LevelDistances`, each of ``targets``
# :class:`~hazard.physics.visual.TargetLevelDistances`; the mappings' keys are the levels and the targets' names
VisualBlock = _from_dataclass(VisualInterference, "VisualBlock", override={  # type: ignore[misc]
    "levels_w_m2": dict[Literal["lfed", "czed", "szed"], Number],
    "levels": dict[Literal["lfed", "czed", "szed", "nohd"], str],
    "targets": dict[str, _from_dataclass(TargetLevelDistances, "TargetLevels")]})  # type: ignore[misc]


# ``airspace``: :class:`hazard.pipeline.airspace.AirspaceCheck` (``note`` only for a laser that is not visible),
# its zones :class:`~hazard.pipeline.airspace.FlightZoneCheck`
AirspaceBlock = _from_dataclass(AirspaceCheck, "AirspaceBlock", override={"zones": list[_from_dataclass(FlightZoneCheck, "FlightZone")]})  # type: ignore[misc]


# ``tracks[]`` and ``motion.fixed_observers[]``: :class:`hazard.outputs.motion_outputs.TrackEntry`, written flat: its
# :class:`hazard.pipeline.motion_results.PathSummary`'s keys (``worst_window``
# :class:`~hazard.pipeline.motion_results.WorstWindow`, ``uv_24h`` :class:`~hazard.pipeline.motion_results.PathUv24h`),
# then the entry's own
class PathBlock(_from_dataclass(TrackEntry, "TrackEntryFields", omit=("summary",)),  # type: ignore[misc]
                _from_dataclass(PathSummary, "PathSummaryFields")):  # type: ignore[misc]
    """A track or a fixed observer over time (``csv`` null for a fixed observer)."""


# ``motion``: :class:`hazard.outputs.motion_outputs.MotionSection` (``aim_track`` :class:`scenes.motion.AimTrackDescription`)
MotionBlock = _from_dataclass(MotionSection, "MotionBlock", override={"fixed_observers": list[PathBlock]})


# ``map_outputs``: :class:`hazard.outputs.map_outputs.MapOutputs` (:func:`~hazard.outputs.map_outputs.map_files`), the kinds of zone typed
MapOutputsBlock = _from_dataclass(MapOutputs, "MapOutputsBlock", override={"features": dict[Literal[ZONE_KINDS], int],  # type: ignore[valid-type]
                                                                           "absent": dict[Literal[ZONE_KINDS], str]})  # type: ignore[valid-type]


class ReportModel(_Strict):
    """``report.json`` (:func:`hazard.outputs.report.report_dict`; ``map_outputs`` added by
    ``hazard run`` when it writes the maps)."""

    model_config = ConfigDict(extra="forbid", title="laser-hazard report.json")

    format: Literal[REPORT_FORMAT]  # type: ignore[valid-type]
    version: Literal[REPORT_VERSION]  # type: ignore[valid-type]
    versions: dict[str, str]
    scene: SceneEcho
    frame: FrameBlock  # type: ignore[valid-type]
    mpe: MpeBlock  # type: ignore[valid-type]
    pulse: Optional[PulseBlock]  # type: ignore[valid-type]
    mpe_w_m2: Number
    uv_24h: Optional[Uv24hBlock]  # type: ignore[valid-type]  # 180-400 nm: the day's summed-dose limit (hazard.physics.mpe.uv_24h_mpe), null elsewhere
    extended_source: ExtendedSourceBlock  # type: ignore[valid-type]
    attenuation_per_m: Number
    limiting_aperture: LimitingAperture  # type: ignore[valid-type]
    beam: BeamBlock
    sdz: Optional[SdzBlock]  # type: ignore[valid-type]
    stages: list[StageRecord]  # type: ignore[valid-type]
    times_s: TimesBlock
    targets: list[TargetReport]
    footprint: Optional[dict[Literal["static", "dynamic"], FootprintArea]]
    observers: list[ObserverRow]  # type: ignore[valid-type]
    observers_listed: ObserversListed
    verdict_changes: list[str]
    verdict: VerdictBlock  # type: ignore[valid-type]
    hazard_at_observers: bool
    hazard_zones: bool
    any_hazard: bool
    warnings: list[str]
    notes: list[str]
    visual_interference: Optional[VisualBlock]  # type: ignore[valid-type]
    airspace: Optional[AirspaceBlock]  # type: ignore[valid-type]
    motion: Optional[MotionBlock]  # type: ignore[valid-type]
    tracks: list[PathBlock]
    map_outputs: Optional[MapOutputsBlock] = None  # type: ignore[valid-type]


def report_schema() -> dict:
    """The JSON Schema (draft 2020-12) of ``report.json``."""
    schema = TypeAdapter(ReportModel).json_schema(mode="validation")
    schema["$schema"] = "https://json-schema.org/draft/2020-12/schema"
    return schema


def validate_report(doc: dict) -> None:
    """Check a parsed ``report.json`` against :class:`ReportModel` (pydantic, strict types).

    Raises
    ------
    pydantic.ValidationError
        A key missing or unknown, or a value of the wrong type, with its path.
    """
    ReportModel.model_validate(doc, strict=True)
