"""Which stages a scene needs, and why the others are left out (decided before any work).

The stages, in order (pvlib's ModelChain steps and scikit-learn's Pipeline are the
models: each stage is a function of explicit inputs, the plan decides which run):

``mpe`` -> ``rays`` -> ``beam`` -> ``crossings`` -> ``direct`` -> ``spill`` -> ``sdz`` -> ``history`` -> ``specular`` -> ``line_of_sight`` ->
``static`` | ``dynamic`` -> ``exposure`` -> ``keepout`` -> ``mirror_beams`` -> ``footprint`` ->
``extended_source``.

What the plan cannot know before the beam is traced (a dynamic target the beam misses,
a mirror that is not lit, no spot at all) the stage itself reports as skipped, with the
reason.
"""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["Plan", "plan"]

@dataclass(frozen=True)
class Plan:
    """Per stage: run it or not, and why not (``reasons``).

    ``rays``: an Embree (or numpy) ray scene is needed (meshes, occluders, terrain, or a
    line of sight that something may block); ``line_of_sight``: observers' lines of sight
    must be traced; ``dynamic``: some target's material changes over time.
    """

    rays: bool
    line_of_sight: bool
    dynamic: bool
    specular: bool
    footprint: bool
    reasons: dict

    def skipped(self, name) -> str | None:
        """Why stage ``name`` is left out, or None when the plan runs it."""
        return self.reasons.get(name)


def _line_of_sight(scene) -> bool:
    return (bool(scene.occluders) or scene.terrain is not None or len(scene.targets) > 1
            or any(t.spec.shape == "mesh" for t in scene.targets))


def plan(scene) -> Plan:
    """The stages ``scene`` needs (:class:`Plan`), decided from the scene alone."""
    flat_only = all(t.spec.shape in ("plate", "disk") for t in scene.targets)
    los = _line_of_sight(scene)
    rays = los or not flat_only
    dynamic = any(t.material.is_dynamic for t in scene.targets)
    specular = any(t.material.has_specular or (t.back_material is not None and t.back_material.has_specular)
                   for t in scene.targets)
    observers = scene.observers is not None and len(scene.observers) > 0
    reasons = {}
    if not rays:
        reasons["rays"] = "flat targets and nothing to block a line of sight: beam hits computed analytically"
    if not dynamic:
        reasons["history"] = "no dynamic material"
        reasons["dynamic"] = "no dynamic material: no time loop"
    else:
        reasons["static"] = "static = the initial-state column of the dynamic map (no separate pass)"
    if not specular:
        reasons["specular"] = "no ideal-mirror (delta) lobe"
        reasons["mirror_beams"] = "no ideal-mirror (delta) lobe: no mirror beam to contain"
    if not los:
        reasons["line_of_sight"] = "nothing can block a line of sight (no occluders, no terrain, one target)"
    elif not observers:
        reasons["line_of_sight"] = "no observers"
    if scene.terrain is None:
        reasons["footprint"] = "no terrain"
    if not observers:
        reasons["direct"] = "no observers"
    if not any(o.layout != "points" and o.n_points >= 2 for o in scene.spec.observers):
        reasons["crossings"] = "no observer line, grid or shell (explicit points are not searched between)"
    return Plan(rays, los and observers, dynamic, specular, scene.terrain is not None, reasons)
