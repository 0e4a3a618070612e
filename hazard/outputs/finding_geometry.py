"""Plan geometry of findings shared by the pictures and the map outputs (zones.geojson): keep-out lobe rings and mirror-beam segments, scene-local or world metres."""

from __future__ import annotations

import math

import numpy as np


def lobe_rings(result, off_xy) -> list:
    """(target, kind, cut, exterior rings, holes) of every lobe's plan outline, world x, y."""
    from hazard.outputs.lobe_outline import lobe_outlines

    return [(o.target, o.kind, o.cut, [r + off_xy for r in o.rings()], [r + off_xy for r in o.holes()])
            for o in lobe_outlines(result)]


def mirror_lines(result) -> list:
    """(target, start, end, eye) of every mirror beam with a specular NOHD, scene-local
    3-D points [m], on its hazard zone's own axis (:func:`hazard.physics.mirror_zone.beam_axis`:
    on one flat plane the laser's axis reflected where it meets the plane, else from the
    spot's centroid along the reported direction or the mirror axis of the spot's mean
    normal), drawn to the naked eye's dynamic specular NOHD or, when every ray of it is
    stopped sooner, to where the analysis stops its farthest ray
    (``sdz.mirror_beams[].max_reach_m``): never past where the text says it ends; an
    infinite NOHD drawn 100 km. A beam only an optical aid makes hazardous is drawn to
    that aid's NOHD (the farthest such), ``eye`` naming the aid ("naked eye" otherwise)."""
    from hazard.physics.engine import mirror_axis
    from hazard.physics.mirror_zone import beam_axis, eye_rows

    out = []
    rows = {t.name: t for t in result.targets}
    for sp in result.spots:
        row = rows.get(sp.target.name)
        if not sp.material.has_specular or row is None:
            continue
        reach = [(eye, drawn_length_m(nohd, stop)) for eye, _, _, nohd, stop in eye_rows(result, row) if nohd]
        if not reach:
            continue
        eye, length = reach[0] if reach[0][0] == "naked eye" else max(reach, key=lambda e: e[1])
        axis = np.asarray(row.specular_direction, float) if row.specular_direction is not None else mirror_axis(sp)
        start, u, _ = beam_axis(sp, sp.centroid, axis)
        out.append((sp.target.name, start, start + u * length, eye))
    return out


def drawn_length_m(nohd_m, stop_m) -> float:
    """How far a mirror beam is drawn [m]: its NOHD (100 km when infinite), or where the analysis stops it when sooner."""
    length = float(nohd_m) if math.isfinite(nohd_m) else 1e5
    return float(stop_m) if stop_m is not None and math.isfinite(stop_m) and 0.0 <= stop_m < length else length


def mirror_segments(result) -> list:
    """(target, start, end) of every mirror beam (:func:`mirror_lines` without the eye)."""
    return [(name, a, b) for name, a, b, _ in mirror_lines(result)]
