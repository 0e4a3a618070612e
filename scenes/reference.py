"""The scene-file reference: one Markdown table of every key, from the published schema.

``hazard schema --markdown`` prints :func:`schema_markdown`; the repository keeps its output
as ``docs/scene-reference.md`` (a test checks it is current). Each row is one key path
(``laser.power_w``, ``targets[].size_m``), its type, its unit (from the unit suffix of the
key's name, the project's convention), its default and its description (the schema's
``Field(description=...)``, which states the unit, convention and default in words).
"""

from __future__ import annotations

import json

from .scene import json_schema

__all__ = ["UNIT_SUFFIXES", "schema_rows", "schema_markdown", "unit_of"]

# key-name suffix -> unit, longest match first (refraction_k is a dimensionless coefficient, not kelvin)
UNIT_SUFFIXES = {
    "_w_m2": "W/m^2", "_deg_s": "deg/s", "_m_s": "m/s", "_per_m": "1/m", "_per_s": "1/s", "_m23": "m^(-2/3)",
    "_rad": "rad", "_deg": "deg", "_km": "km", "_hz": "Hz", "_nm": "nm", "_m": "m", "_s": "s", "_w": "W", "_j": "J", "_k": "K",
}
_UNITLESS_K = ("refraction_k",)
_GEO_UNIT = "deg, deg[, m]"  # [lat_deg, lon_deg(, height_m)] (or projected [easting_m, northing_m, height_m])


def unit_of(key: str) -> str:
    """The unit a key's name states (``power_w`` -> ``W``), ``""`` when it names none."""
    if key in _UNITLESS_K:
        return ""
    if key.endswith("_geo"):
        return _GEO_UNIT
    for suffix in sorted(UNIT_SUFFIXES, key=len, reverse=True):
        if key.endswith(suffix):
            return UNIT_SUFFIXES[suffix]
    return ""


def _resolve(node: dict, defs: dict) -> dict:
    ref = node.get("$ref")
    return defs[ref.rsplit("/", 1)[1]] if ref else node


def _type(node: dict, defs: dict) -> str:
    """A short type text: number, integer, string, boolean, one of 'a', 'b', table, list of ..."""
    node = _resolve(node, defs)
    if "anyOf" in node:
        parts = [_type(n, defs) for n in node["anyOf"] if n.get("type") != "null"]
        return " or ".join(dict.fromkeys(parts))
    if "enum" in node:
        return "one of " + ", ".join(json.dumps(v) for v in node["enum"])
    if "const" in node:
        return json.dumps(node["const"])
    kind = node.get("type")
    if kind == "array":
        items = node.get("items", {})
        n = node.get("minItems") if node.get("minItems") == node.get("maxItems") else None
        return f"list of {n} {_type(items, defs)}" if n else f"list of {_type(items, defs)}"
    if kind == "object" or "properties" in node:
        return "table"
    return {"number": "number", "integer": "integer", "string": "string", "boolean": "boolean"}.get(kind, "any")


def _tables(node: dict, defs: dict) -> list:
    """(suffix, table schema) of the tables a property holds: a table, a list of tables, or optional ones."""
    node = _resolve(node, defs)
    if "anyOf" in node:
        return [x for n in node["anyOf"] for x in _tables(n, defs)]
    if "properties" in node:
        return [("", node)]
    if node.get("type") == "array":
        return [("[]" + s, t) for s, t in _tables(node.get("items", {}), defs)]
    return []


def _default(name: str, prop: dict, table: dict) -> str:
    if name in table.get("required", ()):
        return "required"
    # required in one of two forms (power_w or power = "20 kW"): scenes.quantities.schema_with_units
    either = [g for rule in table.get("allOf", ()) for g in rule.get("anyOf", ())]
    if any(name in g.get("required", ()) for g in either):
        return "required"
    if "default" not in prop:  # a default_factory: an empty list, or a table of its keys' defaults
        if prop.get("type") == "array":
            return "[]"
        is_table = "$ref" in prop or "properties" in prop or any("$ref" in n for n in prop.get("anyOf", ()))
        return "its keys' defaults" if is_table else "none"  # else an optional unit form (power = "20 kW")
    value = prop["default"]
    return "none" if value is None else json.dumps(value, separators=(", ", " = "))


def schema_rows(schema: dict | None = None) -> list[dict]:
    """One row per key path of the scene schema: ``key``, ``type``, ``unit``, ``default``,
    ``description``; tables are expanded in place (``targets[].material.model``)."""
    schema = json_schema() if schema is None else schema
    defs = schema.get("$defs", {})
    rows: list[dict] = []

    def walk(table: dict, prefix: str) -> None:
        for name, prop in table.get("properties", {}).items():
            key = prefix + name
            rows.append({"key": key, "type": _type(prop, defs), "unit": unit_of(name),
                         "default": _default(name, prop, table), "description": prop.get("description", "")})
            for suffix, sub in _tables(prop, defs):
                walk(sub, f"{key}{suffix}.")

    walk(schema, "")
    return rows


def _cell(text: str) -> str:
    return str(text).replace("|", "\\|").replace("\n", " ")


def schema_markdown(schema: dict | None = None) -> str:
    """The scene reference as Markdown: a short header and one table row per key path."""
    rows = schema_rows(schema)
    head = [
        "# Scene file reference",
        "",
        "<!-- generated by `hazard schema --markdown > docs/scene-reference.md`; a test checks it is current -->",
        "",
        "Every key a scene file (TOML) may hold, from the published JSON schema (`hazard schema`).",
        "Units are SI and in the key names (`_m` metres, `_s` seconds, `_w` watts, `_rad` radians,",
        "`_deg` degrees; `wavelength_nm` nanometres); `*_geo` keys are geodetic",
        "`[lat_deg, lon_deg, height_m]` and need a `[site]`. Positions are in one right-handed world",
        "frame, z up (with a `[site]`: east, north, up at its origin). Beam sizes follow the",
        "standards: the diameter and the full-angle divergence at the 1/e points of the irradiance.",
        "`targets[].size_m` is a full size (a sphere's or disk's diameter, a plate's edges),",
        "never a radius. `key[]` is a list of tables (`[[targets]]` in TOML).",
        "",
        "| key | type | unit | default | description |",
        "| --- | --- | --- | --- | --- |",
    ]
    body = [f"| `{r['key']}` | {_cell(r['type'])} | {_cell(r['unit'])} | {_cell(r['default'])} | {_cell(r['description'])} |"
            for r in rows]
    return "\n".join(head + body) + "\n"
