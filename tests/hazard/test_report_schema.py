"""report.json's JSON Schema (hazard.outputs.report_schema, ``hazard schema --report``): every
bundled example's report validates; a wrong type, an unknown or a missing key does not."""

from __future__ import annotations

import copy
import dataclasses
import io
import json
from pathlib import Path

import jsonschema
import pytest
from pydantic import ValidationError

import scenes
from hazard.cli import main
from hazard.outputs.motion_outputs import MOTION_COLUMNS
from hazard.outputs.report import observer_columns, report_dict
from hazard.outputs.report_schema import (DemBlock, MpeBlock, ObserverRow, PulseBlock, StageRecord, TargetReport, Uv24hBlock, VerdictBlock,
                                          SamplingBlock, SpillBlock, ExtendedSourceBlock, AirspaceBlock,
                                          report_schema, validate_report)
from hazard.physics.mpe import MPEResult, RepetitivePulseResult, uv_24h_mpe
from hazard.pipeline.results import Stage
from hazard.pipeline.airspace import AirspaceCheck, FlightZoneCheck
from hazard.pipeline.extended_source import NOT_APPLIED, ExtendedMpe, ExtendedSourceSummary
from hazard.pipeline.spill import AidedNohd, SpillSummary, StoppedSpill
from hazard.pipeline.spots import BeamSampling, NotReflected
from hazard.pipeline.verdict import Verdict, VerdictCounts, verdict
from scenes.dem import DemInfo
from tests._bundled import bundled

EXAMPLES = sorted(Path(p).stem for p in Path(scenes.example_path("plate")).parent.glob("*.toml"))
SLOW_EXAMPLES = {"range_geo"}  # ~20 s on a loaded machine; the others are shared with other test modules (tests._bundled)


@pytest.fixture(scope="module")
def validator():
    schema = report_schema()
    jsonschema.Draft202012Validator.check_schema(schema)
    return jsonschema.Draft202012Validator(schema)


def _doc(name):
    # through JSON, as the file is read back (tuples -> lists, keys -> str)
    return json.loads(json.dumps(report_dict(bundled(name))))


def test_bundled_examples_are_listed():
    assert len(EXAMPLES) >= 10 and "plate" in EXAMPLES


@pytest.mark.parametrize("name", [pytest.param(n, marks=pytest.mark.slow) if n in SLOW_EXAMPLES else n for n in EXAMPLES])
def test_every_bundled_example_validates(name, validator):
    doc = _doc(name)
    errors = [f"{list(e.path)}: {e.message}" for e in validator.iter_errors(doc)]
    assert not errors, errors[:5]
    validate_report(doc)


def test_written_report_json_validates(tmp_path, validator):
    """The file ``hazard run`` writes (with its ``map_outputs`` section)."""
    code = main(["run", scenes.example_path("plate"), "-o", str(tmp_path / "out"), "--quiet"],
                stdout=io.StringIO(), stderr=io.StringIO())
    assert code == 0
    doc = json.loads((tmp_path / "out" / "report.json").read_text())
    assert "map_outputs" in doc
    assert not list(validator.iter_errors(doc))
    validate_report(doc)


def _flat(errors) -> list:
    """The errors and, under an ``anyOf`` (a block or null), the errors of each branch."""
    return [x for e in errors for x in [e] + _flat(e.context or [])]


@pytest.mark.parametrize("edit, where", [
    (lambda d: d.__setitem__("mpe_w_m2", "fifty"), "mpe_w_m2"),  # a number as a word
    (lambda d: d["stages"][0].__setitem__("ran", "yes"), "ran"),  # a bool as a string
    (lambda d: d["stages"][0].__setitem__("seconds", True), "seconds"),  # a bool is not a number
    (lambda d: d["targets"][0].__setitem__("nohd_static_m", None), "nohd_static_m"),
    (lambda d: d["observers"][0].__setitem__("hazardous", 1), "hazardous"),
    (lambda d: d["observers"][0].__setitem__("position_m", [0.0, 1.0]), "position_m"),  # not 3 coordinates
    (lambda d: d["times_s"].__setitem__("count", 1.5), "count"),
    (lambda d: d.__setitem__("format", "other"), "format"),
    (lambda d: d.__setitem__("nohd_m", 3.0), "nohd_m"),  # an unknown key
    (lambda d: d["targets"][0].__setitem__("nohd_statc_m", 3.0), "nohd_statc_m"),  # misspelled
    (lambda d: d.pop("any_hazard"), "any_hazard"),  # a key missing
    (lambda d: d["targets"][0].__setitem__("hit", "grazed"), "hit"),
    # the stages' blocks (issue 35): typed inside, no unknown key
    (lambda d: d["mpe"]["factors"].__setitem__("C_X", 1.0), "C_X"),
    (lambda d: d["mpe"]["limits"][0].__setitem__("radiant_exposure_j_m2", None), "radiant_exposure_j_m2"),
    (lambda d: d["verdict"]["observers"].__setitem__("total", "3"), "total"),
    (lambda d: d["verdict"].__setitem__("warnings", []), "warnings"),  # written at the top level only
    (lambda d: d["sdz"].__setitem__("nohd_mm", 1.0), "nohd_mm"),
    (lambda d: d["sdz"]["directions"].__setitem__("count", 2.5), "count"),
    (lambda d: d["sdz"]["polygon_m"].__setitem__(0, ["0", 0.0]), "polygon_m"),
    (lambda d: d["beam"]["spill"].pop("leaves_scene_w"), "leaves_scene_w"),
    (lambda d: d["beam"]["sampling"].__setitem__("rays", 1.5), "rays"),
    (lambda d: d["frame"].__setitem__("kind", "global"), "kind"),
    (lambda d: d["extended_source"].__setitem__("aplied", True), "aplied"),
    (lambda d: d["limiting_aperture"].__setitem__("diameter_mm", 7.0), "diameter_mm"),
    (lambda d: d.__setitem__("tracks", [{"name": "t"}]), "peak_irradiance_w_m2"),
    (lambda d: d.__setitem__("motion", {"notes": []}), "time_span_s"),
    (lambda d: d.__setitem__("airspace", {"zones": [], "method": "m", "visual_correction_factor": 1.0, "nte": "x"}), "nte"),
    (lambda d: d.__setitem__("map_outputs", {"files": [], "not_written": {}, "frame": "local", "features": {"lobe": 1},
                                             "absent": {}}), "lobe"),
])
def test_schema_rejects(edit, where, validator):
    doc = _doc("plate")
    assert not list(validator.iter_errors(doc))
    bad = copy.deepcopy(doc)
    edit(bad)
    errors = list(validator.iter_errors(bad))
    assert errors and any(where in (list(e.path) + [e.message]) or where in e.message for e in _flat(errors)), \
        [(list(e.path), e.message) for e in errors]
    with pytest.raises(ValidationError, match=where):
        validate_report(bad)


# the free objects left in the schema: the scene as read, and the targets' melt, slump, aids and
# near-field lobe (module notes of hazard.outputs.report_schema); every other object lists its keys
FREE = {"SceneEcho.echo", "SceneEcho.units_as_written", "SceneEcho.beam_conventions", "KeepoutSummary.near_field",
        "TargetReport.state_name", "TargetReport.state_range", "TargetReport.melt", "TargetReport.slump", "TargetReport.aided"}
_TYPED = {"type", "$ref", "anyOf", "oneOf", "allOf", "enum", "const"}


def _loose(schema: dict, where: str, node) -> set:
    """The properties under ``node`` whose schema leaves keys or types open."""
    if not isinstance(node, dict):
        return set()
    loose = set()
    if not (_TYPED & set(node)) or node.get("additionalProperties") is True or (node.get("type") == "object" and "properties" not in node
                                                                                   and not isinstance(node.get("additionalProperties"), dict)):
        loose.add(where)
    if node.get("type") == "object" and "properties" in node and node.get("additionalProperties") is not False:
        loose.add(where + " (extra keys)")
    for key in ("items", "additionalProperties"):
        loose |= _loose(schema, where, node.get(key)) if isinstance(node.get(key), dict) else set()
    for alt in node.get("anyOf", []) + node.get("prefixItems", []):
        loose |= _loose(schema, where, alt)
    return loose


def test_only_the_documented_objects_are_free():
    """Every block of the stages (mpe, pulse, sdz, beam sampling and spill, verdict, motion,
    tracks, frame, extended_source, airspace, map_outputs, ...) lists its keys and their
    types: no free object, no additionalProperties loophole (issue 35)."""
    schema = report_schema()
    loose = set()
    for name, model in [("ReportModel", schema)] + list(schema["$defs"].items()):
        assert model.get("additionalProperties") is False, name
        for key, sub in model["properties"].items():
            loose |= _loose(schema, f"{name}.{key}", sub)
    assert loose == FREE


def test_non_finite_numbers_are_the_strings_report_writes(validator):
    doc = _doc("plate")
    doc["targets"][0]["nohd_static_m"] = "inf"
    doc["mpe_w_m2"] = "nan"
    assert not list(validator.iter_errors(doc))
    validate_report(doc)


def test_schema_follows_the_result_types():
    """The stage entries are the Stage dataclass's fields; targets the keys of
    TargetResult.to_dict (plus ``hit``); observer rows observer_columns' keys."""
    assert set(StageRecord.model_fields) == {f.name for f in dataclasses.fields(Stage)} == set(Stage("a", True, "").to_dict())
    result = bundled("plate")
    assert set(TargetReport.model_fields) == set(result.targets[0].to_dict()) | {"hit"}
    cols = set(observer_columns(result)) - {"labels"}
    assert set(ObserverRow.model_fields) == cols | {"name"} | set(MOTION_COLUMNS)
    # the blocks generated from the MPE's, the pulse train's and the DEM's dataclasses: their fields
    # and what their to_dict writes (issue 35)
    fields = {f.name for f in dataclasses.fields(MPEResult)} | {"standard_title"}
    assert set(MpeBlock.model_fields) == fields == set(result.mpe.to_dict())
    pulse = RepetitivePulseResult(1.0, "single pulse", (("single pulse", 1.0),), 1.0, 1.0, 1.0, ("step",))
    assert set(PulseBlock.model_fields) == {f.name for f in dataclasses.fields(RepetitivePulseResult)} == set(pulse.to_dict())
    PulseBlock.model_validate(json.loads(json.dumps(pulse.to_dict())), strict=True)
    assert set(Uv24hBlock.model_fields) == set(uv_24h_mpe(355.0, [60.0]).to_dict())
    assert set(DemBlock.model_fields) == {f.name for f in dataclasses.fields(DemInfo)}
    # the verdict: Verdict's fields but warnings (report.json's top level), its counts VerdictCounts'
    v = verdict(result)
    assert set(VerdictBlock.model_fields) == {f.name for f in dataclasses.fields(Verdict)} - {"warnings"} == set(v.to_dict())
    assert set(VerdictBlock.model_fields["observers"].annotation.model_fields) == {f.name for f in dataclasses.fields(VerdictCounts)}
    VerdictBlock.model_validate(json.loads(json.dumps(v.to_dict())), strict=True)
    # beam.sampling: BeamSampling's fields, the tail_* keys present with a sampled square only (never null)
    assert set(SamplingBlock.model_fields) == {f.name for f in dataclasses.fields(BeamSampling)} == set(result.beam_sampling.to_dict())
    bare = BeamSampling(9, 2, 0.01, 1e-3, ("a",), (NotReflected("b", "back", 0.5),), 4.0)
    assert set(bare.to_dict()) == set(SamplingBlock.model_fields) - set(BeamSampling.ABSENT_WHEN_NONE)
    SamplingBlock.model_validate(json.loads(json.dumps(bare.to_dict())), strict=True)
    with pytest.raises(ValidationError, match="tail_limit_w_m2"):
        SamplingBlock.model_validate({**bare.to_dict(), "tail_limit_w_m2": None}, strict=True)
    # beam.spill: SpillSummary's fields, its stopped[] StoppedSpill's, its aided[] AidedNohd's
    spill = SpillSummary(1.0, 0.0, 0.5, (StoppedSpill("terrain", 0.2, 300.0, 10.0, 2.0, 0.0, "reflected"),), 40.0,
                         (AidedNohd(7, 0.05, 0.9, 44.1, 250.0),))
    doc = json.loads(json.dumps(spill.to_dict()))
    assert set(SpillBlock.model_fields) == {f.name for f in dataclasses.fields(SpillSummary)} == set(doc)
    assert set(doc["stopped"][0]) == {f.name for f in dataclasses.fields(StoppedSpill)}
    assert set(doc["aided"][0]) == {f.name for f in dataclasses.fields(AidedNohd)}
    SpillBlock.model_validate(doc, strict=True)
    with pytest.raises(dataclasses.FrozenInstanceError):  # a stage's result is not changed by its readers
        spill.nohd_m = 0.0  # type: ignore[misc]
    # extended_source: ExtendedSourceSummary's fields ({"applied": false} alone when not applied), ExtendedMpe's
    assert set(ExtendedSourceBlock.model_fields) == {f.name for f in dataclasses.fields(ExtendedSourceSummary)}
    assert NOT_APPLIED.to_dict() == {"applied": False} and result.extended_source.to_dict() == {"applied": False}
    at = ExtendedMpe(0.01, 6.7, 0.1, 10.0, 67.0, "row", "f", "label", False, ("s1",), None)
    ext = ExtendedSourceSummary(True, 1.5e-3, 0.1, "d63", "specular: C_E = 1", True, 3, 0, at, None)
    doc = json.loads(json.dumps(ext.to_dict()))
    assert set(doc) == set(ExtendedSourceBlock.model_fields) and set(doc["mpe_smallest_alpha"]) == {f.name for f in dataclasses.fields(ExtendedMpe)}
    ExtendedSourceBlock.model_validate(doc, strict=True)
    with pytest.raises(ValidationError, match="alpha_min_rad"):  # written only when applied, and never null
        ExtendedSourceBlock.model_validate({**doc, "alpha_min_rad": None}, strict=True)
    # airspace: AirspaceCheck's fields (note only for a laser that is not visible), its zones FlightZoneCheck's
    zone = FlightZoneCheck("z", "lfed", 5e-4, 0.0, 300.0, False, 1e-3, (1.0, 2.0, 3.0), 0.0, "direct", 0.5, 50.0, 1)
    air = AirspaceCheck((zone,), "lattice", 0.5)
    doc = json.loads(json.dumps(air.to_dict()))
    assert set(doc) == set(AirspaceBlock.model_fields) - {"note"} and set(doc["zones"][0]) == {f.name for f in dataclasses.fields(FlightZoneCheck)}
    assert set(AirspaceBlock.model_fields) == {f.name for f in dataclasses.fields(AirspaceCheck)}
    AirspaceBlock.model_validate(doc, strict=True)
    AirspaceBlock.model_validate({**doc, "note": "not visible"}, strict=True)


def test_cli_prints_the_schema():
    out, err = io.StringIO(), io.StringIO()
    assert main(["schema", "--report"], stdout=out, stderr=err) == 0
    assert json.loads(out.getvalue()) == report_schema()
    out, err = io.StringIO(), io.StringIO()
    assert main(["schema", "--report", "--markdown"], stdout=out, stderr=err) == 2
    assert "--report and --markdown" in err.getvalue()
