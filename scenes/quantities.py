"""Quantities with units in scene files: ``power = "20 kW"`` for ``power_w = 20000``.

Every key of the schema whose name ends in a unit (``power_w``, ``divergence_rad``,
``beam_diameter_m``, ``duration_s``, ``visibility_km``, ``irradiance_w_m2``, ...; the
suffixes are :data:`SUFFIX_UNITS`) may also be written without the suffix, as a quantity
string ``"<number> <unit>"`` that pint parses and converts to the suffixed key's unit
(``divergence = "0.1 deg"`` -> ``divergence_rad = 0.001745...``). A list of them (a
position, a list of times) is a list of such strings, each with its own unit
(``position = ["1 km", "2 km", "10 m"]``). The suffixed key also takes a quantity string
(``power_w = "20 kW"``); its bare numbers keep meaning the key's unit.

Refused (:class:`QuantityError`, naming the key path, the value and what was expected):
both forms of one key; a unit of the wrong dimension (an angle must be an angle: a bare
ratio such as ``"0.5"`` or ``"1 m/m"`` is not taken as radians); an unknown unit; a bare
number on the unsuffixed key (``power = 20``: W or kW?).

:func:`convert_units` rewrites the raw TOML mapping before validation (walking it with the
schema's field names) and returns the record of what was written with a unit; the loader
keeps it on the scene (:func:`as_written`). Geodetic positions (``*_geo``: degrees and
metres mixed) and unitless numbers take numbers only.
"""

from __future__ import annotations

import math
import re
import typing

from pydantic import BaseModel

__all__ = ["SUFFIX_UNITS", "IMPLIED_UNITS", "path_unit", "QuantityError", "convert_units", "convert_value", "unit_of_key", "sibling_key", "as_written",
           "as_written_lines", "other_forms", "schema_with_units"]

# key suffix (after the last "_" or two) -> the unit of the number stored under the key
SUFFIX_UNITS = {
    "w_m2": "W/m^2", "j_m2": "J/m^2", "m_s": "m/s", "deg_s": "deg/s", "per_m": "1/m", "per_s": "1/s", "m23": "m^(-2/3)",
    "m": "m", "km": "km", "nm": "nm", "rad": "rad", "deg": "deg", "s": "s", "w": "W", "j": "J", "k": "K", "hz": "Hz",
    "m2": "m^2", "m3": "m^3",
}
# keys that end like a unit but are not one (site.refraction_k is a dimensionless coefficient)
NOT_UNITS = frozenset({"refraction_k"})
_NUMBER = re.compile(r"\s*([+-]?(?:[0-9]+\.?[0-9]*|\.[0-9]+)(?:[eE][+-]?[0-9]+)?)\s*(\S.*?)?\s*")  # ASCII digits
MAX_TEXT = 100  # characters of one quantity string
# keys without a unit suffix whose numbers have a unit all the same (they take quantity strings too)
IMPLIED_UNITS = {"windows": "s"}


class QuantityError(ValueError):
    """A quantity string that cannot be used; the message names the key path."""


_REGISTRY = None


def _registry():
    global _REGISTRY
    if _REGISTRY is None:  # 0.6 s: built only when a scene writes a unit
        import pint

        _REGISTRY = pint.UnitRegistry()
    return _REGISTRY


def unit_of_key(key: str) -> str | None:
    """The unit (pint text) of the number under ``key`` from its suffix, longest suffix
    first (``velocity_m_s`` -> m/s); None for a key without a unit suffix."""
    if key in NOT_UNITS:
        return None
    parts = key.split("_")
    for n in (2, 1):
        if len(parts) > n and "_".join(parts[-n:]) in SUFFIX_UNITS:
            return SUFFIX_UNITS["_".join(parts[-n:])]
    return None


def sibling_key(key: str, fields) -> str | None:
    """The suffixed field among ``fields`` that the unsuffixed ``key`` stands for
    (``power`` -> ``power_w``), or None."""
    found = [f for f in fields if f.startswith(key + "_") and unit_of_key(f) is not None
             and unit_of_key(f) == SUFFIX_UNITS.get(f[len(key) + 1:])]
    return found[0] if len(found) == 1 else None


def _parse(text: str, unit: str, where: str) -> float:
    """One quantity string converted to ``unit``; QuantityError naming ``where``."""
    m = _NUMBER.fullmatch(text) if len(text) <= MAX_TEXT else None
    if m is None or m.group(2) is None:
        raise QuantityError(f"{where} = {text!r}: expected a number and a unit, like '{_example(unit)}' (the key's unit is {unit})")
    ureg = _registry()
    try:
        units = ureg.parse_units(m.group(2))
    except Exception as exc:  # pint's UndefinedUnitError, or a syntax error of its parser
        raise QuantityError(f"{where} = {text!r}: unknown unit {m.group(2)!r} ({' '.join(str(exc).split())}); expected a unit of "
                            f"{_dimension(unit)} such as {unit}") from None
    q = ureg.Quantity(float(m.group(1)), units)
    want = ureg.Quantity(1.0, ureg.parse_units(unit))
    # exact root units: pint takes radians as dimensionless, so "0.5" or "1 m/m" would pass as an angle
    if q.to_root_units().units != want.to_root_units().units:
        raise QuantityError(f"{where} = {text!r}: {m.group(2)!r} is not a unit of {_dimension(unit)}; expected e.g. "
                            f"'{_example(unit)}' (the key's unit is {unit})")
    value = float(q.to(want.units).magnitude)
    if not math.isfinite(value):
        raise QuantityError(f"{where} = {text!r}: expected a finite value")
    return value


def _dimension(unit: str) -> str:
    names = {"W": "power", "m": "length", "km": "length", "nm": "length", "rad": "angle", "deg": "angle", "s": "time",
             "J": "energy", "K": "temperature", "Hz": "frequency", "W/m^2": "irradiance", "J/m^2": "radiant exposure",
             "m/s": "speed", "deg/s": "angular rate", "1/m": "1/length", "1/s": "1/time", "m^2": "area", "m^3": "volume"}
    return names.get(unit, unit)


def _example(unit: str) -> str:
    return {"W": "20 kW", "m": "7 mm", "km": "23 km", "nm": "1064 nm", "rad": "0.5 mrad", "deg": "5 deg", "s": "250 ms",
            "J": "10 mJ", "Hz": "10 kHz", "K": "300 K", "W/m^2": "10 W/cm^2", "J/m^2": "1 J/cm^2", "m/s": "250 m/s",
            "deg/s": "2 deg/s", "1/m": "0.2 1/km"}.get(unit, f"1 {unit}")


def convert_value(value, unit: str, where: str, *, bare_ok: bool):
    """``value`` (a quantity string, a number, or nested lists of them) in ``unit``; bare
    numbers pass only when ``bare_ok`` (the suffixed key), else QuantityError."""
    if isinstance(value, str):
        return _parse(value, unit, where)
    if isinstance(value, list):
        return [convert_value(v, unit, f"{where}[{i}]", bare_ok=bare_ok) for i, v in enumerate(value)]
    if not bare_ok and isinstance(value, (int, float)) and not isinstance(value, bool):
        key = where.rsplit(".", 1)[-1].split("[")[0]
        raise QuantityError(f"{where} = {value!r}: a bare number without its unit is ambiguous here; write it with a unit "
                            f"('{value!r} {unit}' if {unit} is meant) or use the key {key}_{_suffix(unit)} (in {unit})")
    return value


def _suffix(unit: str) -> str:
    return next(s for s, u in SUFFIX_UNITS.items() if u == unit)


def _has_quantity(value) -> bool:
    """A string of the form "<number> <unit>" somewhere in ``value`` (other strings on a
    suffixed key are left to the schema: ``duration_s = "long"`` is not a valid number)."""
    if isinstance(value, str):
        m = _NUMBER.fullmatch(value) if len(value) <= MAX_TEXT else None
        return m is not None and m.group(2) is not None
    return isinstance(value, list) and any(_has_quantity(v) for v in value)


def _models_of(annotation) -> list:
    """The pydantic models inside a field's annotation (through Optional, list, Annotated)."""
    if isinstance(annotation, type) and issubclass(annotation, BaseModel):
        return [annotation]
    return [m for a in typing.get_args(annotation) for m in _models_of(a)]


def _walk(data, model, path: str, record: dict | None) -> bool:
    """Convert the quantities of ``data`` (a table of ``model``) in place into ``record``;
    with ``record`` None only say whether there is one (nothing changed, no copy needed)."""
    if not isinstance(data, dict):
        return False
    fields = model.model_fields
    found = False
    for key in list(data):
        value = data[key]
        where = f"{path}.{key}" if path else key
        if key in fields:
            sub = _models_of(fields[key].annotation)
            for i, item in (enumerate(value) if isinstance(value, list) else [(None, value)]) if sub else ():
                found = _walk(item, sub[0], where if i is None else f"{where}[{i}]", record) or found
                if found and record is None:
                    return True
            unit = unit_of_key(key) or IMPLIED_UNITS.get(key)
            if unit is not None and _has_quantity(value):
                if record is None:
                    return True
                data[key] = convert_value(value, unit, where, bare_ok=True)
                record[where] = {"as_written": value, "key": where, "value": data[key], "unit": unit}
            continue
        target = sibling_key(key, fields) if isinstance(key, str) else None
        if target is None:
            continue  # not a quantity: the schema reports an unknown key
        if record is None:
            return True
        twhere = f"{path}.{target}" if path else target
        if target in data:
            raise QuantityError(f"{where} = {value!r} and {twhere} = {data[target]!r}: the same value given twice; give one "
                                f"({key} with a unit, or {target} in {unit_of_key(target)})")
        unit = unit_of_key(target)
        assert unit is not None, target  # target is the unit-suffixed form of key (_unit_forms)
        data[target] = convert_value(value, unit, where, bare_ok=False)
        del data[key]
        record[where] = {"as_written": value, "key": twhere, "value": data[target], "unit": unit}
    return found or bool(record)


def convert_units(data: dict, model=None) -> tuple[dict, dict]:
    """The raw scene mapping with every quantity string converted (a copy where changed;
    ``data`` is not modified) and the record ``{key path as written: {"as_written",
    "key" (the suffixed key path), "value" (in its unit), "unit"}}``.

    Parameters
    ----------
    data : dict
        Parsed TOML of a scene (or a part of one, with ``model`` its class).
    model : type, optional
        The pydantic class of ``data`` (default :class:`scenes.spec.SceneSpec`).

    Raises
    ------
    QuantityError
        Both forms of a key, a unit of the wrong dimension, an unknown unit, a bare number
        on an unsuffixed key; the message names the key path.
    """
    import copy

    from .spec import SceneSpec

    record: dict = {}
    if not isinstance(data, dict) or not _walk(data, model or SceneSpec, "", None):
        return data, record  # nothing written with a unit: no copy (a 200 000-row track costs ~1 s to copy)
    out = copy.deepcopy(data)
    _walk(out, model or SceneSpec, "", record)
    return out, record


def other_forms(node: dict, key: str) -> list:
    """The keys of ``node`` that give the same value as ``key`` in its other form
    (``power`` for ``power_w`` and the reverse): a study that sets one removes them."""
    unit = unit_of_key(key)
    if unit is not None:
        return [k for k in node if k != key and key == f"{k}_{_suffix(unit)}"]
    return [k for k in node if isinstance(k, str) and k.startswith(key + "_") and unit_of_key(k) is not None
            and SUFFIX_UNITS.get(k[len(key) + 1:]) == unit_of_key(k)]


def as_written(scene) -> dict:
    """What the scene wrote with a unit: ``{key path as written: {"as_written": "20 kW",
    "key": "laser.power_w", "value": 20000.0, "unit": "W"}}`` (empty when no value had a
    unit); for report.json, ``hazard validate`` and the answer."""
    return dict(getattr(scene, "units_as_written", None) or {})


def _show(v) -> str:
    if isinstance(v, list):
        return "[" + ", ".join(_show(x) for x in v) + "]"
    return f"{v:.6g}" if isinstance(v, float) else str(v)


def as_written_lines(scene) -> list:
    """One line per value written with a unit: ``laser.power = "20 kW" -> laser.power_w = 20000 W``."""
    return [f"{k} = {_show(r['as_written']) if isinstance(r['as_written'], list) else repr(r['as_written'])} -> "
            f"{r['key']} = {_show(r['value'])} {r['unit']}" for k, r in as_written(scene).items()]


def path_unit(parts: list, model=None) -> tuple[list, str | None, bool]:
    """A scene field path (keys and list indices, as a study names it) resolved against
    the schema: ``(parts with an unsuffixed last key replaced by its suffixed one, unit of
    the last key or None, whether bare numbers mean that unit)``; ``["laser", "power"]`` ->
    ``(["laser", "power_w"], "W", False)``."""
    from .spec import SceneSpec

    model = model or SceneSpec
    keys = [p for p in parts if isinstance(p, str)]
    for key in keys[:-1]:
        f = model.model_fields.get(key)
        sub = _models_of(f.annotation) if f is not None else []
        if not sub:
            return list(parts), None, True
        model = sub[0]
    last = keys[-1] if keys else None
    if last is None or last in model.model_fields:
        unit = None if last is None else unit_of_key(last) or IMPLIED_UNITS.get(last)
        return list(parts), unit, True
    target = sibling_key(last, model.model_fields)
    if target is None:
        return list(parts), None, True
    i = max(j for j, p in enumerate(parts) if p == last)
    return [*parts[:i], target, *parts[i + 1:]], unit_of_key(target), False


def _unit_forms(model) -> dict:
    """``{unsuffixed key: suffixed key}`` of one schema class."""
    fields = model.model_fields
    out = {}
    for key in fields:
        unit = unit_of_key(key)
        if unit is not None:
            base = key[: -len(_suffix(unit)) - 1]
            if base and base not in fields and sibling_key(base, fields) == key:
                out[base] = key
    return out


def schema_with_units(schema: dict, model=None) -> dict:
    """The JSON schema of scene files with each unit-suffixed key's unsuffixed form
    (``power`` beside ``power_w``) as a property of its table, so that editors accept
    quantity strings (``power = "20 kW"``); ``schema`` is changed in place and returned."""
    from .spec import SceneSpec

    seen = set()
    todo = [model or SceneSpec]
    while todo:
        m = todo.pop()
        if m in seen:
            continue
        seen.add(m)
        todo += [s for f in m.model_fields.values() for s in _models_of(f.annotation)]
        node = schema if m is (model or SceneSpec) else schema.get("$defs", {}).get(m.__name__)
        if not isinstance(node, dict) or "properties" not in node:
            continue
        for base, key in _unit_forms(m).items():
            unit = unit_of_key(key)
            if unit is None:  # _unit_forms gives suffixed keys only
                continue
            node["properties"][base] = {
                "anyOf": [{"type": "string"}, {"type": "array"}],
                "description": (f"{key} written with a unit: a quantity string '<number> <unit>' (e.g. '{_example(unit)}'), "
                                f"or a list of them where {key} is a list; converted to {unit} at load. Give {base} or {key}, "
                                f"not both; a bare number here is an error (which unit?)")}
            if key in node.get("required", ()):  # required: one of the two forms
                node["required"] = [k for k in node["required"] if k != key]
                node.setdefault("allOf", []).append({"anyOf": [{"required": [key]}, {"required": [base]}]})
    return schema
