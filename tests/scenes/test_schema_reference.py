"""The published scene schema describes itself (issue 31 item 5): every key has a
description stating its unit, docs/scene-reference.md is the current ``hazard schema
--markdown``, and the shape sizes say what they measure."""

from __future__ import annotations

import io
import json
import re
from pathlib import Path

import pytest

import scenes
from scenes.reference import UNIT_SUFFIXES, schema_markdown, schema_rows, unit_of

ROOT = Path(__file__).resolve().parents[2]


def _properties(schema: dict):
    """(table, key, property) of every property of the schema, the top level and every $defs table."""
    for table_name, table in [("SceneSpec", schema), *schema.get("$defs", {}).items()]:
        for key, prop in table.get("properties", {}).items():
            yield table_name, key, prop


def test_every_published_field_has_a_description():
    schema = scenes.json_schema()
    props = list(_properties(schema))
    assert len(props) > 150  # the whole schema was walked, not one table
    missing = [f"{t}.{k}" for t, k, p in props if len(p.get("description", "").strip()) < 10]
    assert missing == [], f"fields without a description: {missing}"


def test_a_field_named_with_a_unit_states_it():
    """``power_w`` says ``[W]``, ``size_m`` ``[m]``: the unit is in the words too."""
    bad = []
    for t, key, prop in _properties(scenes.json_schema()):
        unit = unit_of(key)
        if unit and not key.endswith("_geo") and f"[{unit}]" not in prop["description"]:
            bad.append(f"{t}.{key}: expected [{unit}] in {prop['description']!r}")
    assert bad == []


@pytest.mark.parametrize("key, unit", [("power_w", "W"), ("velocity_m_s", "m/s"), ("azimuth_rate_deg_s", "deg/s"),
                                       ("attenuation_per_m", "1/m"), ("cn2_m23", "m^(-2/3)"), ("size_m", "m"),
                                       ("refraction_k", ""), ("activation_temperature_k", "K"), ("wavelength_nm", "nm"),
                                       ("normal", ""), ("aim_geo", "deg, deg[, m]")])
def test_unit_of_a_key_name(key, unit):
    assert unit_of(key) == unit
    assert set(UNIT_SUFFIXES.values()) >= {"m", "s", "W", "rad", "deg", "J", "Hz"}


def test_shape_sizes_and_beam_convention_are_stated():
    """What a new user asks (issue 31): is size_m a diameter or an edge, which key is a
    cylinder's axis, which convention the beam's diameter and divergence follow."""
    schema = scenes.json_schema()
    shape = schema["$defs"]["TargetSpec"]["properties"]
    size = shape["size_m"]["description"]
    for part in ("plate [width along tangent", "disk [diameter]", "sphere [diameter]",
                 "cylinder [diameter, length along normal (the axis)]", "box [edge along tangent"):
        assert part in size
    assert "cylinder's axis" in shape["normal"]["description"]
    laser = schema["$defs"]["LaserSpec"]["properties"]
    assert "1/e" in laser["beam_diameter_m"]["description"] and "1/e" in laser["divergence_rad"]["description"]
    assert "full-angle" in laser["divergence_rad"]["description"]
    assert "world frame" in shape["center_m"]["description"]


def test_reference_rows_cover_every_key_path():
    rows = {r["key"]: r for r in schema_rows()}
    assert rows["laser.power_w"]["unit"] == "W" and rows["laser.power_w"]["default"] == "none"
    assert rows["laser.wavelength_nm"]["default"] == "required"
    assert rows["exposure.standard"]["default"] == '"ansi-z136.1-2014"'
    assert rows["targets[].size_m"]["type"] == "list of number"
    assert rows["targets[].material.model"]["description"]
    assert rows["uncertainty.map.extent_m"]["unit"] == "m"
    assert rows["observers[].optics.objective_diameter_m"]["type"] == "number"
    # every table of the schema appears under some key path
    schema = scenes.json_schema()
    n_props = sum(1 for _ in _properties(schema))
    assert len(rows) >= n_props


def test_scene_reference_doc_is_current():
    """docs/scene-reference.md is ``hazard schema --markdown``: regenerate it when a field changes
    (``hazard schema --markdown > docs/scene-reference.md``)."""
    from hazard import cli

    out = io.StringIO()
    assert cli.main(["schema", "--markdown"], stdout=out) == 0
    assert out.getvalue() == schema_markdown()
    doc = (ROOT / "docs" / "scene-reference.md").read_text(encoding="utf-8")
    assert doc == schema_markdown(), "docs/scene-reference.md is stale: run hazard schema --markdown > docs/scene-reference.md"
    # a table row per key, and the pipe inside a description does not break the table
    rows = [line for line in doc.splitlines() if line.startswith("| `")]
    assert len(rows) == len(schema_rows())
    assert all(len(re.findall(r"(?<!\\)\|", line)) == 6 for line in rows)


def test_schema_json_unchanged_by_markdown_flag(tmp_path):
    from hazard import cli

    assert cli.main(["schema", "-o", tmp_path / "s.json"]) == 0
    assert json.loads((tmp_path / "s.json").read_text()) == scenes.json_schema()
    assert cli.main(["schema", "--markdown", "-o", tmp_path / "s.md"]) == 0
    assert (tmp_path / "s.md").read_text() == schema_markdown() == (ROOT / "docs" / "scene-reference.md").read_text()
