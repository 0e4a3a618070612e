"""Model registry and versioned JSON persistence.

Models register themselves with :func:`register` (a class decorator) under a canonical,
lower-case name. Third-party packages add models through the entry-point group
``brdfmodels.models`` (name = model name, value = ``module:Class``); they are loaded on
the first lookup. Saved models are JSON documents rebuilt by looking the model up by name
(never pickle); unknown keys, types and format versions are errors.
"""

from __future__ import annotations

import json
from importlib.metadata import entry_points
from pathlib import Path

from .fileio import atomic_write_text

__all__ = [
    "register",
    "create",
    "available_models",
    "model_class",
    "model_from_dict",
    "save",
    "load",
    "dumps",
    "loads",
    "FORMAT_NAME",
    "FORMAT_VERSION",
]

ENTRY_POINT_GROUP = "brdfmodels.models"
FORMAT_NAME = "brdfmodels.model"
FORMAT_VERSION = 1

_REGISTRY: dict = {}
_PLUGINS_LOADED = False


def register(name: str):
    """Class decorator: register a BRDF model class under ``name`` (case-insensitive)."""

    def deco(cls):
        key = name.lower()
        if key in _REGISTRY and _REGISTRY[key] is not cls:
            raise ValueError(f"model name {name!r} is already registered by {_REGISTRY[key].__qualname__}")
        cls.name = key
        _REGISTRY[key] = cls
        return cls

    return deco


def _load_plugins() -> None:
    global _PLUGINS_LOADED
    if _PLUGINS_LOADED:
        return
    _PLUGINS_LOADED = True
    for ep in entry_points(group=ENTRY_POINT_GROUP):
        if ep.name.lower() in _REGISTRY:
            continue
        cls = ep.load()
        register(ep.name)(cls)


def available_models() -> list:
    """Sorted canonical names of every registered model (built-in and plug-in)."""
    _load_plugins()
    return sorted(_REGISTRY)


def model_class(name: str):
    """The class registered under ``name``; ValueError listing the known names otherwise."""
    if not isinstance(name, str):
        raise ValueError(f"model={name!r}: expected a model name, one of {available_models()}")
    _load_plugins()
    try:
        return _REGISTRY[name.lower()]
    except KeyError:
        raise ValueError(f"model={name!r} is unknown: expected one of {available_models()}") from None


def create(name: str, **params):
    """Build a registered model by name from its parameters, e.g. ``create("lambertian", reflectance=0.5)``."""
    return model_class(name).from_params(params)


def model_from_dict(data: dict):
    """Rebuild a model from ``{"type": name, "params": {...}}`` (nested models allowed)."""
    if not isinstance(data, dict):
        raise ValueError(f"model: expected a mapping with 'type' and 'params', got {type(data).__name__}")
    unknown = set(data) - {"type", "params"}
    if unknown:
        raise ValueError(f"model: unknown keys {sorted(unknown)}; expected 'type' and 'params'")
    if "type" not in data:
        raise ValueError("model: missing 'type' (the model name)")
    return model_class(data["type"]).from_params(dict(data.get("params", {})))


def dumps(model) -> str:
    """Versioned JSON text of a model."""
    doc = {"format": FORMAT_NAME, "version": FORMAT_VERSION, "model": model.to_dict()}
    return json.dumps(doc, indent=1, allow_nan=False)


def _unique_keys(pairs) -> dict:
    """A JSON object whose keys are each given once (json keeps the last of a repeated key,
    silently: ``"reflectance": 0.5, "reflectance": 0.05`` read as 0.05)."""
    doc = dict(pairs)
    if len(doc) != len(pairs):
        raise ValueError("not a brdfmodels JSON document: a key is given twice in one object; expected each key once")
    return doc


def loads(text: str):
    """Model from the JSON text written by :func:`dumps`."""
    try:
        doc = json.loads(text, object_pairs_hook=_unique_keys)
    except json.JSONDecodeError as exc:
        raise ValueError(f"not a brdfmodels JSON document: {exc}") from None
    except RecursionError:  # arrays nested thousands deep
        raise ValueError("not a brdfmodels JSON document: nesting too deep") from None
    if not isinstance(doc, dict):
        raise ValueError("not a brdfmodels JSON document: expected an object at the top level")
    # the format is checked first and no value is quoted: a JSON file that is not a model file
    # (a credentials file, say) must not see its contents echoed in the error
    if doc.get("format") != FORMAT_NAME:
        raise ValueError(f"format: expected {FORMAT_NAME!r} (not a brdfmodels model file)")
    if doc.get("version") != FORMAT_VERSION:
        raise ValueError(f"version: this library reads version {FORMAT_VERSION} of {FORMAT_NAME!r} files")
    unknown = set(doc) - {"format", "version", "model"}
    if unknown:
        raise ValueError(f"{len(unknown)} unknown key(s) in model file; expected only format, version, model")
    if "model" not in doc:
        raise ValueError("missing 'model' (the model's type and params)")
    try:
        return model_from_dict(doc["model"])
    except ValueError as exc:  # its messages quote names (right for a scene's own fields), not a file's
        raise ValueError(_unquoted(str(exc), doc["model"])) from None


def _unquoted(message: str, node) -> str:
    """``message`` without the strings of the JSON ``node`` (keys and values) it quotes before
    its "expected ...": a model file is data, and its error names the key, not the text."""
    words, stack = set(), [node]
    while stack:
        x = stack.pop()
        if isinstance(x, dict):
            words.update(k for k in x if isinstance(k, str))
            stack.extend(x.values())
        elif isinstance(x, list):
            stack.extend(x)
        elif isinstance(x, str):
            words.add(x)
    head, sep, tail = message.partition("expected")
    for w in sorted(words, key=len, reverse=True):
        head = head.replace(repr(w), "(a string of the file)")
    return head + sep + tail


def save(model, path) -> Path:
    """Write ``model`` as versioned JSON to ``path`` atomically (temporary file, then rename)."""
    return atomic_write_text(path, dumps(model))


def load(path):
    """Read a model written by :func:`save`."""
    from .fileio import read_input_text

    path = Path(path)
    text = read_input_text(path, "model file")  # a regular file of bounded size
    try:
        return loads(text)
    except ValueError as exc:
        raise ValueError(f"{path}: {exc}") from None
