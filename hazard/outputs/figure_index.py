"""figures.json (issue 34 item 1): for every picture of a run, the report.json findings it
draws, where, with which label, and the extent of each panel, so that a reader (or a
test) can check that no finding is left out of the pictures.

The drawing code notes each finding as it draws it (:func:`mark`: the report.json paths,
the label shown, the drawn geometry in the panel's data coordinates); :func:`figure_entry`
reads the notes back after the figure is drawn, against the panels' final extents and
the text the figure really shows. A finding outside every panel's frame is drawn as an
arrow at the frame's edge with its distance (:func:`arrow_to`).

Paths are report.json's: ``sdz``, ``sdz.aided[0]``, ``sdz.mirror_beams[0]``,
``targets[0].keepout_dynamic``, ``observers[12]`` (the index in report.json's observer
list, tracks after the fixed points), ``tracks[0]``, ``airspace.zones[0]``,
``visual_interference.direct.szed_m``, ``footprint.dynamic``.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass

import numpy as np

from hazard.outputs.motion_outputs import visual_levels

__all__ = ["FIGURES_NAME", "mark", "drawn_findings", "arrow_to", "figure_entry", "figures_document", "report_observer_paths", "finding_paths",
           "track_lines", "flight_zone_rings", "faa_marks", "lobe_paths", "view_entry"]

FIGURES_NAME = "figures.json"
FORMAT = "laser-hazard-figures"
VERSION = 1


@dataclass
class _Mark:
    ax: object
    paths: tuple
    label: str
    kind: str  # "points" | "line" | "polygon" (the drawn geometry)
    xy: np.ndarray  # (K, 2) data coordinates of the panel
    how: str = "drawn"  # or "arrow": the finding is off the frame, an arrow points to it
    distance_m: float | None = None


def mark(ax, paths, label, xy, kind="points", *, how="drawn", distance_m=None):
    """Note that ``ax`` draws the findings ``paths`` (report.json paths) as ``kind`` at
    ``xy`` ((K, 2) data coordinates), shown with the text ``label`` (a legend entry, an
    annotation or a title)."""
    if not paths:
        return
    xy = np.asarray(xy, float).reshape(-1, 2)
    marks = ax.figure.__dict__.setdefault("_hazard_marks", [])
    marks.append(_Mark(ax, tuple(paths), str(label), kind, xy, how, distance_m))


def drawn_findings(ax) -> list:
    """(kind, xy (K, 2) data coordinates) of every finding noted as drawn in ``ax``
    (:func:`mark`): what a label placed in the panel should not cover."""
    return [(m.kind, m.xy) for m in ax.figure.__dict__.get("_hazard_marks", []) if m.ax is ax]


def _metres(d) -> str:
    return f"{d / 1000:.3g} km" if d >= 1000 else f"{d:.3g} m"


def arrow_to(ax, paths, name, origin_xy, target_xy, distance_m=None, *, colour="k", origin="the laser"):
    """An arrow inside ``ax``'s frame pointing from the frame toward ``target_xy`` (off
    the frame) labelled ``name`` and its distance from ``origin_xy`` (named ``origin``; or
    ``distance_m``) [m]; noted (:func:`mark`, how "arrow"). Call it once the limits are final."""
    x0, x1 = ax.get_xlim()
    y0, y1 = ax.get_ylim()
    c = np.array([(x0 + x1) / 2, (y0 + y1) / 2])
    half = np.array([(x1 - x0) / 2, (y1 - y0) / 2])
    t = np.asarray(target_xy, float)
    d = (t - c) / half  # in frame units: the edge is at max |d| = 1
    n = float(np.abs(d).max())
    k = sum(1 for m in ax.figure.__dict__.get("_hazard_marks", []) if m.ax is ax and m.how == "arrow")
    tip = c + half * d / max(n, 1e-12) * 0.97
    tail = c + half * d / max(n, 1e-12) * 0.84 - np.array([0.0, 0.08 * k]) * half  # near the edge; several: texts stacked
    dist = float(np.hypot(*(t - np.asarray(origin_xy, float)))) if distance_m is None else float(distance_m)
    label = f"{name}: off the frame, {_metres(dist)} from {origin}"
    ax.annotate(label, xy=tip, xytext=tail, fontsize=7, ha="center", va="center", color=colour, zorder=14,
                bbox=dict(boxstyle="round,pad=0.2", fc="white", ec=colour, lw=0.6, alpha=0.9),
                arrowprops=dict(arrowstyle="-|>", color=colour, lw=1.2))
    ax.set_xlim(x0, x1)
    ax.set_ylim(y0, y1)
    mark(ax, paths, label, tip, "points", how="arrow", distance_m=dist)


def _shown_texts(fig) -> set:
    """Every text the figure shows: titles, axis labels, annotations, legend entries."""
    out = set()
    legends = list(fig.legends)
    for ax in fig.axes:
        out |= {t.get_text() for t in ax.texts}
        out |= {ax.get_title(), ax.get_xlabel(), ax.get_ylabel()}
        if ax.get_legend() is not None:
            legends.append(ax.get_legend())
    for leg in legends:
        out |= {t.get_text() for t in leg.get_texts()}
    out |= {t.get_text() for t in fig.texts}
    return out


def _inside(m, extent) -> bool:
    """Whether the drawn geometry meets the panel's extent (x0, x1, y0, y1)."""
    from shapely.geometry import LineString, MultiPoint, Polygon, box

    x0, x1, y0, y1 = extent
    frame = box(min(x0, x1), min(y0, y1), max(x0, x1), max(y0, y1))
    xy = m.xy[np.all(np.isfinite(m.xy), axis=1)]
    if not len(xy):
        return False
    if m.kind == "polygon" and len(xy) >= 3:
        g = Polygon(xy)
        g = g if g.is_valid else g.buffer(0)
    elif m.kind in ("line", "polygon") and len(xy) >= 2:
        g = LineString(xy)
    else:
        g = MultiPoint(xy.tolist())
    return bool(g.intersects(frame))


def _panel(ax) -> dict:
    x0, x1 = ax.get_xlim()
    y0, y1 = ax.get_ylim()
    return {"title": ax.get_title(), "x": ax.get_xlabel(), "y": ax.get_ylabel(),
            "extent": [float(x0), float(x1), float(y0), float(y1)]}


def figure_entry(fig, view: str, dpi=None) -> dict:
    """What ``fig`` draws: its panels (title, axis labels, extent [x0, x1, y0, y1] in
    their data units) and every noted finding with its panel, whether its geometry meets
    the panel's extent, and whether its label is among the texts the figure shows; with
    ``dpi`` (the picture's, [px/in]) also ``text_px_min``, its smallest text's height in
    the picture [px] (:func:`hazard.canvas.smallest_text_px`: the printed report keeps it
    at least :data:`hazard.canvas.PRINT_MIN_PT` high)."""
    shown = _shown_texts(fig)
    panels = [ax for ax in fig.axes if ax.get_title()]
    findings = []
    for m in fig.__dict__.get("_hazard_marks", []):
        extent = _panel(m.ax)["extent"]
        ok = m.xy[np.all(np.isfinite(m.xy), axis=1)]  # an unbounded NOHD (inf) is drawn to the frame; JSON holds no inf
        bbox = None if not len(ok) else [float(ok[:, 0].min()), float(ok[:, 0].max()), float(ok[:, 1].min()), float(ok[:, 1].max())]
        if m.kind == "points" and len(m.xy) == len(m.paths) > 1:  # one point per finding: each its own answer
            x0, x1, y0, y1 = extent
            inside = ((m.xy[:, 0] >= min(x0, x1)) & (m.xy[:, 0] <= max(x0, x1)) & (m.xy[:, 1] >= min(y0, y1))
                      & (m.xy[:, 1] <= max(y0, y1))).tolist()
        else:
            inside = [_inside(m, extent)] * len(m.paths)
        findings.append({"paths": list(m.paths), "label": m.label, "label_shown": m.label in shown, "panel": m.ax.get_title(),
                         "how": m.how, "geometry": m.kind, "inside": inside,
                         "bbox": bbox, **({} if not finite(m.distance_m) else {"distance_m": float(m.distance_m)})})
    entry = {"view": view, "panels": [_panel(ax) for ax in panels], "findings": findings}
    if dpi is not None:
        from hazard.canvas import smallest_text_px

        entry["text_px_min"] = round(smallest_text_px(fig, dpi), 2)
    return entry


def figures_document(entries: dict) -> bytes:
    """figures.json: {file name: :func:`figure_entry`} with the format, the frame and how
    to read it."""
    doc = {"format": FORMAT, "version": VERSION,
           "frame": "plan and elevation views: report.json's world frame [m] (plan: x east, y north; elevation: distance "
                    "along the aim's azimuth from the laser, height); time plots: time [s] against their y axis; 3-D pictures (view '3d', "
                    "'animation'): the box they are framed on in the world frame [m] (extent, extent_z), 'inside' the camera's "
                    "answer (the drawn points projected into the view; a point behind a surface still counts as in the view)",
           "paths": "report.json paths of the findings each picture draws (observers[i]: the i-th row of report.json's "
                    "observer list); 'inside': the drawn geometry meets the panel's extent; 'how': 'arrow' for a finding "
                    "off the frame, shown by an arrow at the edge with its distance",
           "figures": entries}
    return (json.dumps(doc, indent=1, allow_nan=False) + "\n").encode()


def report_observer_paths(result) -> dict:
    """report.json's observer path (``observers[i]``) of each row of the observer table
    (fixed observers, then tracks), for the rows report.json lists."""
    from hazard.outputs.report import listed_rows, observer_columns

    cols = observer_columns(result)
    rows = listed_rows(cols, len(cols["labels"]))
    return {int(r): f"observers[{j}]" for j, r in enumerate(np.asarray(rows).tolist())}


def finite(x) -> bool:
    """``x`` is a finite number (not None)."""
    return x is not None and isinstance(x, (int, float)) and math.isfinite(x)


def finding_paths(result) -> dict:
    """The report.json paths of what the plan and elevation views draw: ``zone`` (the
    naked-eye danger zone, None without one), ``aided`` (one per optical aid),
    ``mirror`` (target name -> its mirror beam), ``lobe`` ((target name, kind) -> its
    keep-out lobe), ``target`` (name -> path), ``observers`` (row of the observer table
    -> path) and ``footprint`` (the footprints with cells)."""
    z = getattr(result, "sdz", None)
    targets = {t.name: f"targets[{j}]" for j, t in enumerate(result.targets)}
    mirror = dict(targets)
    mirror.update({m.target: f"sdz.mirror_beams[{k}]" for k, m in enumerate(() if z is None else z.mirror_beams or ())})
    foot = [f"footprint.{key}" for key, f in (("dynamic", result.footprint_dynamic), ("static", result.footprint_static))
            if f is not None and f.mask.any()]
    return {"zone": "sdz" if z is not None and z.polygon_m else None, "aided": [f"sdz.aided[{k}]" for k in range(0 if z is None else len(z.aided))],
            "mirror": mirror, "target": targets,
            "lobe": {(name, kind): f"{p}.keepout_{kind}" for name, p in targets.items() for kind in ("static", "dynamic")},
            "observers": report_observer_paths(result), "footprint": foot}


def track_lines(result, paths) -> list:
    """(paths, name, (N, 3) world positions, text) of every moving observer: its
    ``tracks[k]`` and its row of report.json's observer list, its verdict in the text."""
    from hazard.pipeline.airspace_geometry import track_polyline

    tracks = [] if getattr(result, "motion", None) is None else result.motion.tracks()
    m = len(result.observers)
    out = []
    for k, p in enumerate(tracks):
        s = p.summary  # hazard.pipeline.motion_results.PathSummary
        verdict = "OVER the MPE" if s.hazardous else "below the MPE"
        _, levels = visual_levels(result, s.peak_irradiance_w_m2)  # report.json's tracks[k].visual_levels_reached
        faa = f"; FAA levels reached: {', '.join(x.upper() for x in levels)}" if levels else ""
        text = f"track {p.name}: {verdict} (exposure ratio {float(s.exposure_ratio):.3g}{faa})"
        row = paths["observers"].get(m + k)
        out.append(((f"tracks[{k}]",) + ((row,) if row else ()), p.name, track_polyline(result, p), text))
    return out


def flight_zone_rings(result) -> list:
    """(path, (K, 2) world ring, exceeded, text, spec, worst point (3,) world) of every
    flight zone (``airspace.zones``)."""
    air = getattr(result, "airspace", None)
    zones = () if air is None else air.zones  # hazard.pipeline.airspace.FlightZoneCheck
    specs = [] if result.scene.spec.airspace is None else list(result.scene.spec.airspace.zones)
    out = []
    for k, (z, spec) in enumerate(zip(zones, specs)):
        exceeded = not z.holds
        text = (f"flight zone {z.name} ({z.limit.upper()}, {z.floor_agl_m:g}-{z.ceiling_agl_m:g} m AGL): "
                f"{'EXCEEDED' if exceeded else 'holds'} (worst {z.worst_effective_irradiance_w_m2:.3g} W/m^2, "
                f"limit {z.limit_w_m2:g} W/m^2)")
        worst = np.asarray(z.worst_point_m or [math.nan] * 3, float)  # world already (hazard.pipeline.airspace)
        out.append((f"airspace.zones[{k}]", np.asarray(spec.boundary_m, float), exceeded, text, spec, worst))
    return out


def faa_marks(result) -> list:
    """(path, text, world point on the aim) of the direct beam's FAA distances
    (``visual_interference.direct``; visible lasers only), the text saying when the beam
    is stopped before it (the danger zone's range, a contained zone)."""
    vi = getattr(result, "visual_interference", None)  # hazard.physics.visual.VisualInterference
    if vi is None or not vi.applies:
        return []
    z = getattr(result, "sdz", None)
    stop = float(z.max_range_m or math.inf) if z is not None and z.contained else math.inf
    scene = result.scene
    origin = np.asarray(scene.laser_position_m, float) + np.asarray(scene.offset_m, float)
    out = []
    for level in ("szed", "czed", "lfed"):
        d = vi.direct.distance_m(level)
        if not finite(d) or not d > 0:
            continue
        text = f"{level.upper()} {_metres(d)} along the beam"
        if d > stop:
            text += f" (the beam is stopped at {_metres(stop)}: not reached)"
        out.append((f"visual_interference.direct.{level}_m", text, origin + np.asarray(scene.laser_direction, float) * d))
    return out


def lobe_paths(paths, lobes, target, kind) -> list:
    """The report.json paths a drawn lobe outline stands for: its own, and a static
    lobe's also the dynamic one's when the target has no dynamic outline (its material
    does not change: the two are the same lobe)."""
    own = paths.get("lobe", {}).get((target, kind))
    out = [own] if own else []
    if kind == "static" and not any(t == target and k == "dynamic" for t, k, *_ in lobes):
        other = paths.get("lobe", {}).get((target, "dynamic"))
        out += [other] if other else []
    return out


def _clip_inside(clip, kind) -> list:
    """Whether projected geometry is in the view: ``clip`` (K, 4) homogeneous clip
    coordinates (in view: w > 0 and |x|, |y| <= w); one answer for a line or a surface
    (any part in view; a line also where it crosses the view between its points), else
    one per point."""
    w = clip[:, 3]
    front = w > 0
    ndc = np.where(front[:, None], clip[:, :2] / np.where(front, w, 1.0)[:, None], np.nan)
    each = front & np.all(np.abs(ndc) <= 1.0, axis=1)
    if kind == "points":
        return each.tolist()
    ok = bool(each.any())
    if not ok and kind == "line" and len(clip) >= 2:
        ok = _segments_cross_view(clip)
    return [ok]


def _segments_cross_view(clip, eps=1e-9) -> bool:
    """Whether a polyline of clip coordinates (K, 4) crosses the view between its
    points: each segment is first cut at the camera's plane (w = eps: a segment from
    behind the camera to in front of it keeps its front part), then projected."""
    from shapely.geometry import MultiLineString, box

    a, b = clip[:-1], clip[1:]
    keep = (a[:, 3] > eps) | (b[:, 3] > eps)
    a, b = a[keep], b[keep]

    def cut(p, q):  # p moved toward q onto w = eps where p is behind the camera
        wp, wq = p[:, 3], q[:, 3]
        t = np.clip((eps - wp) / np.where(wq != wp, wq - wp, 1.0), 0.0, 1.0)[:, None]
        return np.where((wp <= eps)[:, None], p + t * (q - p), p)

    a, b = cut(a, b), cut(b, a)
    if not len(a):
        return False
    segs = np.stack([a[:, :2] / a[:, 3:4], b[:, :2] / b[:, 3:4]], 1)
    return bool(MultiLineString([s.tolist() for s in segs]).intersects(box(-1.0, -1.0, 1.0, 1.0)))


def view_entry(view, panel, notes, world_to_clip, shown) -> dict:
    """The figures.json entry of a 3-D picture (``keepout.png``, ``overview.png``,
    ``lobe.gif``): its one ``panel`` (title, axis names, ``extent`` [x0, x1, y0, y1] and
    ``extent_z`` [z0, z1] in report.json's world frame [m], how distances are drawn) and
    the findings ``notes`` drawn in it, each (paths, label, (K, 3) drawn points, kind,
    (K, 3) world points [m]). Whether a finding is in the picture is the camera's answer:
    its drawn points projected by ``world_to_clip`` (4 x 4, drawn coordinates to clip
    coordinates) fall in the view; ``label_shown``: the label is among the texts
    ``shown`` (title lines, legend entries, point tags)."""
    findings = []
    for paths, label, drawn, kind, world in notes:
        if not paths:
            continue
        drawn = np.asarray(drawn, float).reshape(-1, 3)
        world = np.asarray(world, float).reshape(-1, 3)
        ok = np.all(np.isfinite(drawn), axis=1)
        clip = np.hstack([drawn[ok], np.ones((int(ok.sum()), 1))]) @ np.asarray(world_to_clip, float).T
        per = kind == "points" and len(paths) == len(drawn) > 1 and ok.all()
        inside = _clip_inside(clip, "points" if per else kind) if len(clip) else [False]
        inside = inside if per else [any(inside)] * len(paths)
        fin = world[np.all(np.isfinite(world), axis=1)]
        bbox = None if not len(fin) else [float(fin[:, 0].min()), float(fin[:, 0].max()), float(fin[:, 1].min()), float(fin[:, 1].max())]
        findings.append({"paths": list(paths), "label": label, "label_shown": label in shown, "panel": panel["title"],
                         "how": "drawn", "geometry": kind, "inside": inside, "bbox": bbox})
    return {"view": view, "panels": [panel], "findings": findings}
