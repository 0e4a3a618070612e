"""scenes: what is where.

Lasers, targets (primitives or meshes, each with a BRDF material and optionally a state
history), occluders, terrain, observers and atmosphere, from TOML files validated at load
(pydantic, unknown keys are errors with their path) and converted once to SI numpy
arrays in local coordinates (``Scene.offset_m`` is the float64 origin).
"""

from .scene import Observers, Scene, SceneError, Target, example_path, examples, from_data, json_schema, load, loads
from .spec import SceneSpec

__all__ = ["Observers", "Scene", "SceneError", "SceneSpec", "Target", "example_path", "examples", "from_data", "json_schema", "load", "loads"]
