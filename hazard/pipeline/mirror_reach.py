"""Stage ``mirror_beams``: where each mirror beam ends, beside the danger zone.

A mirror (a target with an ideal specular lobe) sends a hazardous beam out to its
specular NOHD (:func:`hazard.physics.specular.specular_nohd`); the range must contain it like the
direct beam (range-safety.md section 3: reflections are folded into the zone). For each
lit mirror, every spot sample's reflected ray (``d - 2 (d . n) n``, the reflection law on
the sample's surface normal) is cast from the sample against the terrain and the
occluders (through the targets, as the danger zone does) and ends at min(first backstop,
NOHD), with the target's largest specular NOHD (static or dynamic; naked eye, and the
largest through the scene's optical aids) taken for every sample (conservative).

Reported per mirror (report.json ``sdz.mirror_beams``): the NOHD, how far the rays reach,
whether every ray is stopped by a backstop before the NOHD (``contained``), whether one
rises above the horizon without a backstop, and, with a ``[range]``, whether a ray's
ground track leaves the boundary. The mirror beam's own width about the sample rays is
not cast (its rays are the samples'): said in the stage detail.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from hazard.physics.specular import mirror_directions
from hazard.pipeline.backstops import first_backstop_rays
from hazard.pipeline.sdz import UNBOUNDED_DRAW_M, MirrorBeam, MirrorReach, boundary_polygon

__all__ = ["mirror_beams", "summary"]


def _longest_nohd(row) -> tuple[float, float]:
    """The target's largest specular NOHD [m], naked eye and through any aid (0: none)."""
    naked = max(x for x in (row.specular_nohd_static_m, row.specular_nohd_dynamic_m, 0.0) if x is not None)
    aided = [x for a in row.aided for x in (a.get("specular_nohd_static_m"), a.get("specular_nohd_dynamic_m")) if x is not None]
    return naked, max([naked] + aided)


def _rays(spot) -> tuple[np.ndarray, np.ndarray]:
    """Origins (N, 3) and unit reflected directions (N, 3) of a spot's samples."""
    r = mirror_directions(spot)
    r /= np.linalg.norm(r, axis=1, keepdims=True)
    return np.asarray(spot.points, float) + 1e-6 * max(spot.size_m, 1e-3) * r, r


def _one(scene, spot, nohd_m, ray_scene, boundary) -> MirrorBeam:
    """One mirror's beam out to ``nohd_m`` (see the module notes)."""
    from shapely.geometry import LineString, MultiLineString

    o, r = _rays(spot)
    stop = first_backstop_rays(o, r, ray_scene, len(scene.targets))
    reach = np.minimum(stop, nohd_m)
    stopped = np.isfinite(stop) & (stop <= nohd_m)
    leaves = None
    if boundary is not None and nohd_m > 0:
        ends = o + r * np.minimum(reach, UNBOUNDED_DRAW_M)[:, None]
        lines = MultiLineString([LineString([a[:2], b[:2]]) for a, b in zip(o, ends) if np.hypot(*(b - a)[:2]) > 0])
        outside = lines.difference(boundary) if not lines.is_empty else lines
        leaves = bool(outside.length > 1e-9)
    return MirrorBeam(target=spot.target.name, nohd_m=nohd_m, max_reach_m=float(reach.max()), rays=int(len(r)),
                      contained=bool(nohd_m <= 0 or stopped.all()), above_horizon=bool(nohd_m > 0 and np.any(~stopped & (r[:, 2] > 0))),
                      leaves_boundary=leaves)


def mirror_beams(scene, rows, spots, ray_scene) -> tuple[MirrorBeam, ...]:
    """Per lit mirror target: its beam's reach and containment, naked and aided
    (report.json ``sdz.mirror_beams``; see the module notes)."""
    by_name = {r.name: r for r in rows}
    boundary = boundary_polygon(scene)
    out = []
    for sp in spots:
        row = by_name.get(sp.target.name)
        if row is None or not sp.material.has_specular:
            continue
        naked, aided = _longest_nohd(row)
        entry = _one(scene, sp, naked, ray_scene, boundary)
        if aided > naked:
            a = _one(scene, sp, aided, ray_scene, boundary)
            entry = replace(entry, aided=MirrorReach(nohd_m=a.nohd_m, max_reach_m=a.max_reach_m, contained=a.contained,
                                                     above_horizon=a.above_horizon, leaves_boundary=a.leaves_boundary))
        out.append(entry)
    return tuple(out)


def summary(entries) -> str:
    """One line for the stage log."""
    if not entries:
        return "no lit mirror"
    parts = []
    for e in entries:
        fate = "contained by backstops" if e.contained else (
            f"reaches its NOHD {e.nohd_m:.4g} m without a backstop" + (", above the horizon" if e.above_horizon else ""))
        if e.leaves_boundary:
            fate += ", LEAVES the range boundary"
        parts.append(f"{e.target}: {fate} ({e.rays} sample rays; the beam's width about them not cast)")
    return "; ".join(parts)
