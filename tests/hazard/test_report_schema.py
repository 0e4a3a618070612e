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
from hazard.outputs.report_schema import ObserverRow, StageRecord, TargetReport, report_schema, validate_report
from hazard.pipeline.results import Stage
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
])
def test_schema_rejects(edit, where, validator):
    doc = _doc("plate")
    assert not list(validator.iter_errors(doc))
    bad = copy.deepcopy(doc)
    edit(bad)
    errors = list(validator.iter_errors(bad))
    assert errors and any(where in (list(e.path) + [e.message]) or where in e.message for e in errors), \
        [(list(e.path), e.message) for e in errors]
    with pytest.raises(ValidationError, match=where):
        validate_report(bad)


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


def test_cli_prints_the_schema():
    out, err = io.StringIO(), io.StringIO()
    assert main(["schema", "--report"], stdout=out, stderr=err) == 0
    assert json.loads(out.getvalue()) == report_schema()
    out, err = io.StringIO(), io.StringIO()
    assert main(["schema", "--report", "--markdown"], stdout=out, stderr=err) == 2
    assert "--report and --markdown" in err.getvalue()
