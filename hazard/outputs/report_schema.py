"""The JSON Schema of ``report.json`` (``hazard schema --report``), from the result types.

pydantic models mirror what :func:`hazard.outputs.report.report_dict` writes; the stage records'
entries are derived from the :class:`hazard.pipeline.results.Stage` dataclass's own fields (one
source of truth: a field added there is in the schema), the targets' from the keys of
:meth:`hazard.pipeline.results.TargetResult.to_dict` (a test checks the two agree), the observer
rows' from the columns of :func:`hazard.outputs.report.observer_columns` (the ``motion_*`` ones,
:data:`hazard.outputs.motion_outputs.MOTION_COLUMNS`, present only when something moves).

Typed blocks forbid unknown keys (a misspelled or unannounced key fails validation) and
give every value its JSON type; numbers may also be the strings ``"inf"``, ``"-inf"``,
``"nan"`` (:func:`hazard.outputs.report.json_safe`: JSON has no such numbers and an infinite
NOHD must not vanish). The blocks written by the MPE, SDZ, spill, verdict, motion and map
modules (``mpe``, ``pulse``, ``sdz``, ``beam.spill``, ``verdict``, ``motion``, ...) are
objects whose inner keys are not yet typed here.
"""

from __future__ import annotations

import dataclasses
from typing import Any, Literal, Optional, get_type_hints

from pydantic import BaseModel, ConfigDict, Field, TypeAdapter, create_model

from hazard.outputs.motion_outputs import MOTION_COLUMNS
from hazard.outputs.report import REPORT_FORMAT, REPORT_VERSION
from hazard.pipeline.results import Stage

__all__ = ["ReportModel", "report_schema", "validate_report"]

#: A JSON number, or the string a non-finite float is written as.
Number = float | Literal["inf", "-inf", "nan"]
Block = Optional[dict[str, Any]]  # a block whose inner keys are not typed here (null when absent)


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid")


def _from_dataclass(cls, name: str) -> type[BaseModel]:
    """A strict model with the fields of dataclass ``cls`` (types from its annotations;
    floats may be written as "inf"/"nan")."""
    hints = get_type_hints(cls)
    fields: dict[str, Any] = {f.name: (Number if hints[f.name] is float else hints[f.name], ...) for f in dataclasses.fields(cls)}
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
    sampling: Block
    spill: Block


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
    hit: Literal["beam", "wing only", "not reflected", "not hit"]


class FootprintArea(_Strict):
    area_m2: Number
    eye_height_m: Number
    cells: int = Field(ge=0)


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


class ReportModel(_Strict):
    """``report.json`` (:func:`hazard.outputs.report.report_dict`; ``map_outputs`` added by
    ``hazard run`` when it writes the maps)."""

    model_config = ConfigDict(extra="forbid", title="laser-hazard report.json")

    format: Literal[REPORT_FORMAT]  # type: ignore[valid-type]
    version: Literal[REPORT_VERSION]  # type: ignore[valid-type]
    versions: dict[str, str]
    scene: SceneEcho
    frame: dict[str, Any]
    mpe: dict[str, Any]
    pulse: Block
    mpe_w_m2: Number
    uv_24h: Block  # 180-400 nm: the day's summed-dose limit (hazard.physics.mpe.uv_24h_mpe), null elsewhere
    extended_source: dict[str, Any]
    attenuation_per_m: Number
    limiting_aperture: dict[str, Any]
    beam: BeamBlock
    sdz: Block
    stages: list[StageRecord]  # type: ignore[valid-type]
    times_s: TimesBlock
    targets: list[TargetReport]
    footprint: Optional[dict[Literal["static", "dynamic"], FootprintArea]]
    observers: list[ObserverRow]  # type: ignore[valid-type]
    observers_listed: ObserversListed
    verdict_changes: list[str]
    verdict: dict[str, Any]
    hazard_at_observers: bool
    hazard_zones: bool
    any_hazard: bool
    warnings: list[Any]
    notes: list[str]
    visual_interference: Block
    airspace: Block
    motion: Block
    tracks: list[dict[str, Any]]
    map_outputs: Block = None


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
