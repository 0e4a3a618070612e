"""3-D renders of keep-out zones (pyvista, off-screen), VTK files for ParaView, animations.

Imported only when a render is asked for (``hazard render``, ``hazard.pictures.render``): pyvista
and VTK are heavy. Two pictures (issue 18), each the 3-D view with a title strip and a
legend beside it (:mod:`hazard.pictures.picture`: the legend is never cut and its colours are the
ones drawn, :mod:`hazard.pictures.palette`):

* ``keepout.png``, the close view: framed on the lobes and targets, at true scale;
* ``overview.png``: everything hazardous - the lobes, mirror beams to their NOHD, the aim
  line to the danger zone's range, the hazardous ground and every observer. Where true
  scale would shrink the lobes to dots (the farthest of these more than
  ``COMPRESS_RATIO`` times the close view's radius from the site), distances beyond twice
  that radius are drawn on a log scale, ``r0 (1 + ln(r / r0))``, and said in the title;
  the range rings are labelled with true distances.

What they show, in the scene's local coordinates (the offset to the file's coordinates in
the title): the terrain coloured by the hazardous ground footprint at eye height (cells
hazardous in both analyses dark red, dynamic-only orange; a cell is drawn hazardous if any
of its corners is - conservative at the terrain's resolution, while the reported area
counts nodes x spacing^2), or, for a scene without ground, a reference plane under it;
range rings about the laser; targets, occluders, the laser beam up to each spot; the
static lobe (solid blue) and the dynamic lobe (orange wire: the static one shows through
it, the colours stay the legend's) - the surface at the NOHD in every reflection
direction, the dynamic one over the history in time order (two states, slump); observers
below the MPE small and green, those at or above it large and red, the worst named; each
target's NOHDs at its lobe's tip.

The VTK multiblock (``keepout.vtm``) carries the same meshes at true coordinates with
unit-suffixed arrays: ``nohd_m`` on lobes and mirror beams, ``hazard_ratio``,
``hazardous`` and ``peak_irradiance_w_m2`` on observers, ``hazardous_static`` /
``hazardous_dynamic`` on the terrain.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

import pyvista as pv

from hazard.pictures import palette as C
from hazard.physics.beam import perp_basis as _perp_basis
from hazard.physics.keepout import nohd_range_fn
from hazard.outputs.figure_index import finding_paths, lobe_paths, view_entry
from hazard.pictures.picture import TAG_PX, compose, text_px_min, write_png
from hazard.pictures.plan_view import LABELLED, nice_length_m, aim_reach_m, hazardous_labels
from hazard.outputs.finding_geometry import mirror_segments
from hazard.progress import terminal_bar

__all__ = ["keepout", "lobe_grid", "animate_lobe", "framings", "Framing", "ring_radii", "not_drawn"]

# every Plotter here is made with off_screen=True; the global pv.OFF_SCREEN is the CLI's to set (hazard._cli_env)
LINE_POINTS = 256  # points along a drawn line (a line bends on a log-distance picture)
ISO_VIEW = np.array([1.0, 1.0, 1.0])  # from the focal point toward the camera (pyvista's "iso")
COMPRESS_RATIO = 8.0  # the overview goes log-distance when everything lies this many close-view radii away


def lobe_grid(spot, mpe_w_m2, mu, states=None, resolution_deg=3.0) -> pv.StructuredGrid:
    """The hazard lobe of a spot as a surface: centroid + NOHD(w) w.

    The grid's pole is the mirror direction (where finite lobes peak), with rings at 0.1,
    0.3 and 1 deg around it, so a sharp specular tip is drawn at its full length;
    directions below the surface have NOHD 0."""
    fn = nohd_range_fn(spot, mpe_w_m2, mu, 1.0, states)
    wi = -spot.mean_incoming @ spot.mean_frame.T  # incidence in the material frame
    m = wi * np.array([-1.0, -1.0, 1.0])
    e1, e2 = _perp_basis(m)
    th = np.unique(np.concatenate([[0.0, 0.1, 0.3, 1.0], np.arange(resolution_deg, 180.0 + 1e-9, resolution_deg)]))
    th = np.radians(th)
    ph = np.radians(np.arange(-180.0, 180.0 + 1e-9, resolution_deg))
    tt, pp = np.meshgrid(th, ph, indexing="ij")
    w = np.cos(tt)[..., None] * m + np.sin(tt)[..., None] * (np.cos(pp)[..., None] * e1 + np.sin(pp)[..., None] * e2)
    r = np.where(w[..., 2] > 0, fn(w.reshape(-1, 3)).reshape(tt.shape), 0.0)
    world = w @ spot.mean_frame  # material frame -> scene frame
    pts = spot.centroid + r[..., None] * world
    grid = pv.StructuredGrid(pts[..., 0], pts[..., 1], pts[..., 2])
    grid["nohd_m"] = r.ravel(order="F")
    return grid


def _mesh(vertices, faces):
    f = np.hstack([np.full((len(faces), 1), 3), faces]).ravel()
    return pv.PolyData(np.asarray(vertices, float), f)


def _time_ordered_states(result, sp):
    """The dynamic lobe's states in time order, as the analysis takes them (a two-state
    history and a slump need the order; ``np.unique`` would flatten or reorder them)."""
    states = result.states.get(sp.target.index)
    return None if states is None else np.asarray(states)


def _scene_blocks(result, lobe_resolution_deg):
    """Every mesh in the scene's local coordinates (true distances): the VTK multiblock."""
    scene = result.scene
    blocks = pv.MultiBlock()
    for t in scene.targets:
        blocks[f"target_{t.name}"] = _mesh(t.mesh.vertices, t.mesh.faces)
    for i, m in enumerate(scene.occluders):
        blocks[f"occluder_{i}"] = _mesh(m.vertices, m.faces)
    if scene.terrain is not None:
        tm = scene.terrain.mesh()
        terr = _mesh(tm.vertices, tm.faces)
        if result.footprint_static is not None:
            terr["hazardous_static"] = result.footprint_static.mask.ravel().astype(np.uint8)
            terr["hazardous_dynamic"] = result.footprint_dynamic.mask.ravel().astype(np.uint8)
        blocks["terrain"] = terr
    for sp in result.spots:
        states = _time_ordered_states(result, sp)
        blocks[f"lobe_static_{sp.target.name}"] = lobe_grid(sp, result.mpe_w_m2, result.attenuation_per_m,
                                                            None if states is None else states[:1], lobe_resolution_deg)
        if states is not None:
            blocks[f"lobe_dynamic_{sp.target.name}"] = lobe_grid(sp, result.mpe_w_m2, result.attenuation_per_m, states, lobe_resolution_deg)
        blocks[f"beam_{sp.target.name}"] = pv.Line(scene.laser_position_m, sp.centroid, resolution=LINE_POINTS)
    for name, a, b in mirror_segments(result):
        line = pv.Line(a, b, resolution=LINE_POINTS)
        line["nohd_m"] = np.full(line.n_points, float(np.linalg.norm(b - a)))
        blocks[f"mirror_{name}"] = line
    reach = aim_reach_m(result)
    if reach > 0:
        blocks["aim"] = pv.Line(scene.laser_position_m, scene.laser_position_m + scene.laser_direction * reach, resolution=LINE_POINTS)
    _airspace_blocks(result, blocks)
    blocks["laser"] = pv.PolyData(np.asarray(scene.laser_position_m, float)[None])
    if len(result.observers):
        obs = pv.PolyData(np.asarray(scene.observers.positions_m, float))
        obs["hazard_ratio"] = result.hazard_ratio
        obs["hazardous"] = np.asarray(result.hazardous, np.uint8)
        obs["peak_irradiance_w_m2"] = result.observers.peak_irradiance_w_m2
        obs["static_irradiance_w_m2"] = result.observers.static_irradiance_w_m2
        blocks["observers"] = obs
    return blocks


def _airspace_blocks(result, blocks) -> None:
    """Tracks (irradiance and cumulative exposure per vertex), flight zones as prisms and
    the direct beam's visual-interference volumes, in the scene's local coordinates
    (:mod:`hazard.pipeline.airspace_geometry`)."""
    from hazard.pipeline.airspace_geometry import track_polyline, visual_surface, zone_prism

    off = np.asarray(result.scene.offset_m, float)
    for p in ([] if result.motion is None else result.motion.tracks()):
        xyz = track_polyline(result, p) - off
        line = pv.lines_from_points(xyz) if len(xyz) > 1 else pv.PolyData(xyz)
        line["irradiance_w_m2"] = p.irradiance_w_m2
        line["cumulative_exposure_j_m2"] = p.cumulative_j_m2
        line["time_s"] = p.times_s
        blocks[f"track_{p.name}"] = line
    rows = {z.name: z for z in (() if result.airspace is None else result.airspace.zones)}
    for zs in ([] if result.scene.spec.airspace is None else result.scene.spec.airspace.zones):
        v, faces = zone_prism(result, zs)
        mesh = pv.PolyData(v - off, np.concatenate([[len(f), *f] for f in faces]))
        mesh["holds"] = np.full(mesh.n_cells, int(rows[zs.name].holds if zs.name in rows else True), np.uint8)
        blocks[f"airspace_{zs.name}"] = mesh
    if result.visual_interference is not None and result.visual_interference.applies:
        for level in ("szed", "czed", "lfed"):
            surf = visual_surface(result, level)
            if surf is not None:
                blocks[f"visual_{level}"] = _mesh(surf[0] - off, surf[1])


@dataclass
class Framing:
    """What a picture frames, in drawn coordinates, and how distances are drawn: true
    within ``r0_m`` of ``centre_m``, beyond it on a log scale
    (``r0 (1 + ln(r / r0))``: continuous, with a continuous slope at ``r0``)."""

    bounds: np.ndarray  # (3, 2) drawn coordinates
    centre_m: np.ndarray
    r0_m: float = np.inf
    extent_m: float = 0.0  # the farthest framed point's true distance from the centre
    points: np.ndarray | None = None  # the framed points, drawn coordinates (set by :func:`framings`)

    @property
    def compressed(self) -> bool:
        return bool(np.isfinite(self.r0_m))

    def draw(self, points) -> np.ndarray:
        """Drawn coordinates of true ``points``: beyond ``r0_m`` from the centre a radius r is
        drawn at ``r0 (1 + ln(r / r0))``."""
        return self._radially(points, lambda r: self.r0_m * (1.0 + np.log(r / self.r0_m)))

    def undraw(self, points) -> np.ndarray:
        """True coordinates of drawn ``points`` (the inverse of :meth:`draw`)."""
        return self._radially(points, lambda r: self.r0_m * np.exp(np.minimum(r / self.r0_m - 1.0, 700.0)))

    def _radially(self, points, radius_of) -> np.ndarray:
        """``points`` moved along their direction from the centre: a radius r beyond
        ``r0_m`` goes to ``radius_of(r)``, nearer ones stay (the identity when not compressed)."""
        p = np.asarray(points, float)
        if not self.compressed:
            return p
        d = p - self.centre_m
        r = np.linalg.norm(d, axis=-1, keepdims=True)
        scale = np.where(r > self.r0_m, radius_of(np.maximum(r, self.r0_m)) / np.maximum(r, 1e-300), 1.0)
        return self.centre_m + d * scale

    def mesh(self, mesh):
        if not self.compressed:
            return mesh
        out = mesh.copy()
        out.points = self.draw(mesh.points)
        return out


def _points(mesh) -> np.ndarray:
    return np.asarray(mesh.points, float).reshape(-1, 3)


def _hazard_points(result, blocks) -> np.ndarray:
    """Everything the overview must hold: lobes, targets, laser, mirror beams to their
    NOHD, the aim line to the danger zone's range, the hazardous ground, every observer
    (the hazardous ones among them), the moving observers' tracks and the flight zones."""
    keep = ("lobe_", "target_", "mirror_", "beam_", "aim", "laser", "observers", "track_", "airspace_")
    pts = [_points(blocks[k]) for k in blocks.keys() if k.startswith(keep)]
    if result.footprint_dynamic is not None and result.footprint_dynamic.mask.any():
        t = result.scene.terrain
        iy, ix = np.nonzero(result.footprint_dynamic.mask)
        pts.append(np.stack([t.x0 + t.dx * ix, t.y0 + t.dx * iy, t.heights[iy, ix]], 1))
    return np.vstack(pts)


def _box(points, factor, minimum) -> np.ndarray:
    lo, hi = points.min(axis=0), points.max(axis=0)
    c, half = (lo + hi) / 2, np.maximum((hi - lo) / 2 * factor, minimum)
    return np.stack([c - half, c + half], 1)


def framings(result, blocks) -> dict:
    """The close view (the lobes and targets, true scale) and the overview (everything in
    :func:`_hazard_points`; on a log-distance scale beyond the close view's radius when
    that holds everything only at more than ``COMPRESS_RATIO`` times it). The close view
    holds the hazardous observers too."""
    near = np.vstack([_points(blocks[k]) for k in blocks.keys() if k.startswith(("lobe_", "target_"))])
    if "observers" in blocks.keys():  # hazardous observers near the lobes (not those far out on a mirror beam)
        obs = _points(blocks["observers"])[np.asarray(result.hazardous, bool)]
        c, r = near.mean(axis=0), float(np.ptp(near, axis=0).max())
        near = np.vstack([near, obs[np.linalg.norm(obs - c, axis=1) <= 2.0 * r]])
    focus = _box(near, 1.3, 0.05 * max(1e-3, float(np.ptp(near, axis=0).max())))
    centre = focus.mean(axis=1)
    r_focus = float(np.linalg.norm(focus[:, 1] - focus[:, 0]) / 2)
    pts = _hazard_points(result, blocks)
    extent = float(np.linalg.norm(pts - centre, axis=1).max())
    over = Framing(np.zeros((3, 2)), centre, r_focus if extent > COMPRESS_RATIO * r_focus else np.inf, extent)
    over.points = over.draw(pts)
    over.bounds = _box(over.points, 1.05, 1e-3)
    return {"keepout": Framing(focus, centre, np.inf, r_focus, near), "overview": over}


def _nice(x) -> float:
    """The largest 1, 2 or 5 x 10^k not above ``x``."""
    return nice_length_m(5.0 * x)


def ring_radii(extent_m, compressed) -> list:
    """Range-ring radii [m]: round steps (1, 2, 5 x 10^k) about a quarter of the extent,
    or, on a log-distance picture, a 1-2-5 sequence up to the extent."""
    if extent_m <= 0:
        return []
    if not compressed:
        step = _nice(extent_m / 4)
        return [k * step for k in range(1, int(extent_m // step) + 1)]
    lo = _nice(extent_m / 1e4)
    out, r = [], lo
    while r <= extent_m:
        out.append(r)
        r = _nice(r * 2.6)  # 1 -> 2 -> 5 -> 10
    return out[-6:]


def _ground_z(framing) -> float:
    """The height of the reference plane drawn under a scene without terrain: the lowest
    framed point."""
    return float(framing.bounds[2, 0])


def _add_ground(p, result, blocks, framing, legend):
    """The terrain coloured by the footprint (returns None), or a reference disc about the
    laser that holds every framed point (returns its drawn radius: the rings stop there)."""
    if "terrain" in blocks.keys():
        m = framing.mesh(blocks["terrain"])
        if not framing.compressed:
            m = m.clip_box(pv.Box(framing.bounds.ravel()), invert=False)
        if m.n_points == 0:
            return None
        legend.append(("terrain", C.GROUND, "patch"))
        if "hazardous_static" not in m.array_names:
            p.add_mesh(m, color=C.GROUND, opacity=0.9)
            return None
        # categorical per cell, conservative: a cell is hazardous if any corner is
        lvl_pt = m["hazardous_static"].astype(float) + m["hazardous_dynamic"].astype(float)
        faces = m.faces.reshape(-1, 4)[:, 1:] if m.faces.size else np.empty((0, 3), int)
        level = lvl_pt[faces].max(axis=1) if len(faces) else np.empty(0)
        m.cell_data["footprint_level"] = level
        p.add_mesh(m, scalars="footprint_level", preference="cell", cmap=[C.GROUND, C.DYNAMIC, C.FOOTPRINT], clim=[0, 2],
                   n_colors=3, show_scalar_bar=False, opacity=0.9)
        if (level == 2).any():
            legend.append((f"hazardous ground at {result.footprint_dynamic.eye_height_m:g} m eye height", C.FOOTPRINT, "patch"))
        if (level == 1).any():
            legend.append(("hazardous ground, dynamic analysis only", C.DYNAMIC, "patch"))
        return None
    laser = framing.draw(np.asarray(result.scene.laser_position_m, float)[None])[0]
    pts = framing.points
    radius = 1.08 * float(np.hypot(*(pts[:, :2] - laser[:2]).T).max())
    disc = pv.Disc(center=(laser[0], laser[1], _ground_z(framing)), inner=0.0, outer=max(radius, 1e-3), c_res=120)
    p.add_mesh(disc, color=C.GROUND, opacity=0.45)
    legend.append(("reference plane under the scene (the scene has no ground)", C.GROUND, "patch"))
    return radius


def _add_rings(p, result, framing, legend, limit=None):
    """Range rings about the laser on the ground (true distances, drawn compressed), out
    to the ground drawn."""
    laser = np.asarray(result.scene.laser_position_m, float)
    pts = framing.points
    drawn_laser = framing.draw(laser[None])[0]
    limit = limit or float(np.hypot(*(pts[:, :2] - drawn_laser[:2]).T).max())
    extent = framing.extent_m + float(np.linalg.norm(laser - framing.centre_m)) if framing.compressed else limit
    ang = np.linspace(0, 2 * np.pi, 241)
    labels, where = [], []
    for r in ring_radii(extent, framing.compressed):
        ring = laser + r * np.stack([np.cos(ang), np.sin(ang), np.zeros_like(ang)], 1)
        if result.scene.terrain is None:
            ring[:, 2] = _ground_z(framing)
        else:
            ring[:, 2] = result.scene.terrain.height_at(ring[:, 0], ring[:, 1]) + 0.2
        drawn = framing.draw(ring)
        if np.hypot(*(drawn[:, :2] - drawn_laser[:2]).T).max() > limit:
            continue
        p.add_mesh(pv.lines_from_points(drawn), color=C.RINGS, line_width=1.5)
        labels.append(f"{r / 1000:g} km" if r >= 1000 else f"{r:g} m")
        where.append(drawn[30])
    if labels:
        p.__dict__.setdefault("_hazard_tags", []).extend(labels)
        p.add_point_labels(np.array(where), labels, font_size=TAG_PX, text_color="#444444", shape_opacity=0.0, show_points=False,
                           always_visible=True)
        legend.append(("range rings about the laser" + (" (true distances)" if framing.compressed else ""), C.RINGS, "line"))


def _cut_away(mesh, axis, centre, towards_camera):
    """``mesh`` without its half toward the camera: cut by the plane through ``centre``
    that holds the lobe's ``axis`` and faces the camera, so a lobe inside shows whole."""
    n = towards_camera - np.dot(towards_camera, axis) * axis
    if np.linalg.norm(n) < 1e-9:  # the axis points at the camera: cut across it instead
        n = np.cross(axis, [0.0, 0.0, 1.0]) if abs(axis[2]) < 0.99 else np.array([1.0, 0.0, 0.0])
    return mesh.clip(normal=n / np.linalg.norm(n), origin=centre, invert=True)


def _add_lobes(p, result, blocks, framing, legend):
    """Static lobes solid blue; dynamic lobes orange with the half toward the camera cut
    away, so the static lobe inside keeps its own colour (no blend the legend lacks)."""
    toward = ISO_VIEW / np.linalg.norm(ISO_VIEW)
    rows = {t.name: t for t in result.targets}
    for name in blocks.keys():
        if name.startswith("lobe_static_"):
            p.add_mesh(framing.mesh(blocks[name]), color=C.STATIC, smooth_shading=True, ambient=0.45, diffuse=0.6, specular=0.0)
            _once(legend, ("static keep-out lobe (NOHD surface)", C.STATIC, "patch"))
        elif name.startswith("lobe_dynamic_"):
            target = name[len("lobe_dynamic_"):]
            sp = next(sp for sp in result.spots if sp.target.name == target)
            axis = np.asarray(rows[target].dynamic_lobe.max_direction_world, float)
            half = _cut_away(framing.mesh(blocks[name]), axis, framing.draw(sp.centroid[None])[0], toward)
            if half.n_cells:
                p.add_mesh(half, color=C.DYNAMIC, smooth_shading=True, ambient=0.45, diffuse=0.6, specular=0.0)
            _once(legend, ("dynamic keep-out lobe (its near half cut away)", C.DYNAMIC, "patch"))


def _add_objects(p, blocks, framing, tube, legend):
    for name in blocks.keys():
        mesh = blocks[name]
        if name.startswith("target_"):
            p.add_mesh(framing.mesh(mesh), color="#555555")
        elif name.startswith("occluder_"):
            p.add_mesh(framing.mesh(mesh), color=C.OCCLUDER, opacity=0.8)
            _once(legend, ("occluders", C.OCCLUDER, "patch"))
        elif name.startswith("beam_"):
            p.add_mesh(framing.mesh(mesh).tube(radius=tube), color=C.ZONE, lighting=False)
            _once(legend, ("laser beam to the targets", C.ZONE, "line"))
        elif name == "aim":
            p.add_mesh(framing.mesh(mesh), color=C.AIM, line_width=2.0, lighting=False)
            _once(legend, ("aim line to the danger zone's range", C.AIM, "line"))
        elif name.startswith("mirror_"):
            p.add_mesh(framing.mesh(mesh).tube(radius=tube), color=C.MIRROR, lighting=False)
            _once(legend, ("mirror beam to its NOHD or its backstop", C.MIRROR, "line"))
        elif name == "laser":
            p.add_mesh(framing.mesh(mesh), color="black", point_size=16, render_points_as_spheres=True)
            _once(legend, ("laser", "#000000", "marker"))


def airspace_entries(result) -> list:
    """(block name, report.json paths, legend text, colour, kind) of every moving
    observer's track (red over the MPE, else green) and flight zone (red exceeded, else
    blue) the 3-D pictures draw, their texts the plan view's
    (:func:`hazard.outputs.figure_index.track_lines`, :func:`hazard.outputs.figure_index.flight_zone_rings`)."""
    from hazard.outputs.figure_index import flight_zone_rings, track_lines

    paths = finding_paths(result)
    tracks = [] if getattr(result, "motion", None) is None else result.motion.tracks()
    out = [(f"track_{name}", ps, text, C.HAZARDOUS if t.summary.hazardous else C.SAFE, "line")
           for (ps, name, _, text), t in zip(track_lines(result, paths), tracks)]
    specs = [] if result.scene.spec.airspace is None else list(result.scene.spec.airspace.zones)
    out += [(f"airspace_{spec.name}", (path,), text, C.ZONE if exceeded else C.STATIC, "patch")
            for (path, _, exceeded, text, spec, _), spec in zip(flight_zone_rings(result), specs)]
    return out


def _add_airspace(p, result, blocks, framing, tube, legend):
    """Each track as a tube, each flight zone as a see-through prism with its edges; in a
    true-scale picture only those meeting its box (the close view: figures.json then says
    the others are not in it)."""
    for name, _, text, colour, kind in airspace_entries(result):
        if name not in blocks.keys():
            continue
        mesh = framing.mesh(blocks[name])
        lo, hi = np.asarray(mesh.bounds, float).reshape(3, 2).T
        if not framing.compressed and (np.any(lo > framing.bounds[:, 1]) or np.any(hi < framing.bounds[:, 0])):
            continue
        if kind == "line":
            p.add_mesh(mesh.tube(radius=tube) if mesh.n_cells else mesh, color=colour, lighting=False, point_size=8)
        else:
            p.add_mesh(mesh, color=colour, opacity=0.18, show_edges=True, edge_color=colour, line_width=1.5, lighting=False)
        legend.append((text, colour, kind))


def _add_observers(p, result, blocks, framing, legend):
    """Safe observers small and green; hazardous ones large and red, the worst numbered in
    the picture and named in the legend (a number is never cut at the picture's edge)."""
    if "observers" not in blocks.keys():
        return
    obs = framing.mesh(blocks["observers"])
    bad = np.asarray(result.hazardous, bool)
    if (~bad).any():
        p.add_mesh(pv.PolyData(obs.points[~bad]), color=C.SAFE, point_size=6, render_points_as_spheres=True, lighting=False)
        legend.append((f"observers below the MPE ({int((~bad).sum())})", C.SAFE, "marker"))
    if not bad.any():
        return
    p.add_mesh(pv.PolyData(obs.points[bad]), color=C.HAZARDOUS, point_size=18, render_points_as_spheres=True, lighting=False)
    labels, more = hazardous_labels(result, obs.points)
    p.__dict__.setdefault("_hazard_tags", []).extend(str(k + 1) for k in range(len(labels)))
    p.add_point_labels(np.array([xy for xy, _ in labels]), [str(k + 1) for k in range(len(labels))], font_size=TAG_PX, bold=True,
                       text_color="black", shape_color="white", shape_opacity=0.85, show_points=False, always_visible=True)
    extra = f"; {more} more in observers.csv" if more else ""
    legend.append((f"observers at or above the MPE ({int(bad.sum())}{extra}), the worst numbered:", C.HAZARDOUS, "marker"))
    legend += [(f"{k + 1}: {text}", None, "text") for k, (_, text) in enumerate(labels)]


def _add_nohd_labels(p, result, framing, legend):
    """Each target's name at its dynamic lobe's tip, and its NOHDs in the legend."""
    names, points = [], []
    rows = {t.name: t for t in result.targets}
    for sp in result.spots:
        tr = rows.get(sp.target.name)
        if tr is None or tr.dynamic_lobe is None:
            continue
        d = tr.to_dict()
        text = f"{tr.name}: NOHD static {d['nohd_static_m']:.3g} m, dynamic {d['nohd_dynamic_m']:.3g} m"
        if tr.specular_nohd_dynamic_m:
            text += f", mirror beam {tr.specular_nohd_dynamic_m:.4g} m"
        legend.append((text, None, "text"))
        names.append(tr.name)
        points.append(sp.centroid + tr.dynamic_lobe.max_direction_world * tr.dynamic_lobe.max_range_m)
    if points:
        p.__dict__.setdefault("_hazard_tags", []).extend(names)
        p.add_point_labels(framing.draw(np.array(points)), names, font_size=TAG_PX, text_color="black", shape_color="white",
                           shape_opacity=0.8, always_visible=True, show_points=False)


def _once(legend, entry):
    if entry not in legend:
        legend.append(entry)


def _draw(result, blocks, framing, window_size):
    """The 3-D scene (no text but short tags at points) and its legend entries."""
    p = pv.Plotter(off_screen=True, window_size=list(window_size))
    p.set_background("white")
    legend = []
    extent = float(np.max(framing.bounds[:, 1] - framing.bounds[:, 0]))
    tube = max(result.scene.spec.laser.beam_diameter_m, 2.5e-3 * extent)
    limit = _add_ground(p, result, blocks, framing, legend)
    _add_rings(p, result, framing, legend, limit)
    _add_lobes(p, result, blocks, framing, legend)
    _add_objects(p, blocks, framing, tube, legend)
    _add_airspace(p, result, blocks, framing, tube, legend)
    _add_observers(p, result, blocks, framing, legend)
    _add_nohd_labels(p, result, framing, legend)
    p.add_axes(labels_off=True, line_width=3)  # its X Y Z letters printed at 3 pt: said in the legend instead
    legend.append(("axes, lower left: red x (east), green y (north), blue z (up)", None, "text"))
    c = framing.bounds.mean(axis=1)
    p.camera_position = [tuple(c + ISO_VIEW), tuple(c), (0.0, 0.0, 1.0)]
    p.reset_camera(bounds=framing.bounds.ravel())
    return p, legend


def _world_to_clip(p, window_size) -> np.ndarray:
    """The camera's 4 x 4 matrix from drawn coordinates to clip coordinates (the view is
    |x|, |y| <= w after the projection)."""
    m = p.camera.GetCompositeProjectionTransformMatrix(window_size[0] / window_size[1], -1.0, 1.0)
    return np.array([[m.GetElement(i, j) for j in range(4)] for i in range(4)])


def _panel(result, framing, title, true_box=None) -> dict:
    """figures.json's panel of a 3-D picture: the box it is framed on in report.json's
    world frame [m] (a log-distance overview: the true box of everything it holds)."""
    off = np.asarray(result.scene.offset_m, float)
    if true_box is None:
        pts = framing.undraw(framing.points) if framing.compressed else framing.bounds.T
        true_box = np.stack([pts.min(axis=0), pts.max(axis=0)], 1)
    box = np.asarray(true_box, float) + off[:, None]
    scale = (f"true distances within {framing.r0_m:.4g} m of the site, a log scale beyond (r0 (1 + ln(r / r0)))"
             if framing.compressed else "true scale")
    return {"title": title, "x": "x east [m]", "y": "y north [m]", "z": "height [m]", "projection": "3-D perspective, "
            + scale, "extent": [float(v) for v in box[:2].ravel()], "extent_z": [float(v) for v in box[2]]}


def _notes(result, blocks, framing, legend) -> list:
    """What a 3-D picture draws, for figures.json (:func:`hazard.outputs.figure_index.view_entry`):
    (report.json paths, the legend text naming it, drawn points, kind, world points [m])
    for every lobe, mirror beam, the aim line (the danger zone), each hazardous observer
    and the hazardous ground."""
    paths, texts = finding_paths(result), [e[0] for e in legend]
    off = np.asarray(result.scene.offset_m, float)
    notes = []

    def add(ps, label, local, kind):
        local = np.asarray(local, float).reshape(-1, 3)
        notes.append(([q for q in ps if q], label, framing.draw(local), kind, local + off))

    lobes = [tuple(reversed(k.split("_", 2)[1:])) for k in blocks.keys() if k.startswith("lobe_")]  # (target, kind)
    for target, kind in lobes:
        label = "static keep-out lobe (NOHD surface)" if kind == "static" else "dynamic keep-out lobe (its near half cut away)"
        add(lobe_paths(paths, lobes, target, kind), label, _points(blocks[f"lobe_{kind}_{target}"]), "surface")
    for name in [k for k in blocks.keys() if k.startswith("mirror_")]:
        add([paths["mirror"].get(name[len("mirror_"):])], "mirror beam to its NOHD or its backstop", _points(blocks[name]), "line")
    if "aim" in blocks.keys():
        add([paths["zone"]], "aim line to the danger zone's range", _points(blocks["aim"]), "line")
    for name, ps, text, _, kind in airspace_entries(result):  # drawn, or outside the close view's box (said by "inside")
        if name in blocks.keys():
            add(list(ps), text, _points(blocks[name]), "line" if kind == "line" else "surface")
    _observer_notes(result, paths, texts, add)
    _footprint_notes(result, framing, paths, texts, add)
    return notes


def _observer_notes(result, paths, texts, add) -> None:
    """Each hazardous observer: the worst by their numbered legend line, the rest by the
    legend's count."""
    bad = np.flatnonzero(np.asarray(result.hazardous, bool))
    if not len(bad):
        return
    ratio = np.asarray(result.hazard_ratio, float)
    bad = bad[np.argsort(-ratio[bad], kind="stable")]
    pos = np.asarray(result.scene.observers.positions_m, float)
    rows = paths["observers"]
    for k, i in enumerate(bad[:LABELLED]):
        add([rows.get(int(i))], f"{k + 1}: {result.observers.labels[i]} ({ratio[i]:.3g} x MPE)", pos[i], "points")
    rest = bad[LABELLED:]
    group = next((t for t in texts if t.startswith("observers at or above the MPE")), "observers at or above the MPE")
    if len(rest):
        kept = [int(i) for i in rest if rows.get(int(i))]
        add([rows[i] for i in kept], group, pos[kept], "points")


def _footprint_notes(result, framing, paths, texts, add) -> None:
    """The hazardous ground nodes of each footprint drawn (the close view clips the
    terrain to its box)."""
    t = result.scene.terrain
    ground = [x for x in texts if x.startswith("hazardous ground")]
    if t is None or not ground:
        return
    for key, f in (("dynamic", result.footprint_dynamic), ("static", result.footprint_static)):
        if f is None or not f.mask.any() or f"footprint.{key}" not in paths["footprint"]:
            continue
        iy, ix = np.nonzero(f.mask)
        pts = np.stack([t.x0 + t.dx * ix, t.y0 + t.dx * iy, t.heights[iy, ix]], 1)
        if not framing.compressed:
            lo, hi = framing.bounds[:, 0], framing.bounds[:, 1]
            pts = pts[np.all((pts >= lo) & (pts <= hi), axis=1)]
        if len(pts):
            add([f"footprint.{key}"], ground[0], pts, "points")


def _title_lines(result, framing, title) -> list:
    scene = result.scene
    lines = [title, f"MPE {result.mpe_w_m2:.4g} W/m^2; local origin at {np.round(scene.offset_m, 3).tolist()} m (world = local + origin)"]
    if framing.compressed:
        lines.append(f"distances beyond {framing.r0_m:.3g} m from the site are drawn on a log scale (r0 (1 + ln(r / r0))): "
                     f"the rings give true distances; every lobe, beam, observer and hazardous ground is in the picture, "
                     f"out to {framing.extent_m:.4g} m")
    elsewhere = not_drawn(result)
    if elsewhere["paths"]:
        lines.append(elsewhere["label"])
    return lines


def not_drawn(result) -> dict:
    """The report.json findings the 3-D pictures do not draw - the direct beam's FAA
    distances, the danger zones through optics (the tracks and flight zones they draw:
    :func:`airspace_entries`) -, the line saying so and where they are drawn (``see``:
    the plan and elevation views)."""
    from hazard.outputs.figure_index import faa_marks

    paths = finding_paths(result)
    faa = faa_marks(result)
    out = [p for p, *_ in faa] + list(paths["aided"])
    what = [f"{n} {one if n == 1 else many}" for n, one, many in (
        (len(faa), "FAA distance", "FAA distances"), (len(paths["aided"]), "danger zone through optics", "danger zones through optics"))
        if n]
    label = f"not drawn here, see plan.png and elevation.png: {', '.join(what)}" if what else ""
    return {"paths": out, "label": label, "see": ["plan.png", "elevation.png"]}


def keepout(result, outdir, *, lobe_resolution_deg=3.0, window_size=(1280, 900), vtk=True, force=False) -> dict:
    """Render the keep-out zones of an analysis (off-screen) to ``outdir/keepout.png`` -
    the close view, framed on the lobes - and ``outdir/overview.png`` - everything
    hazardous (mirror beams to their NOHD, the aim line to the danger zone's range, the
    hazardous ground, every observer), on a log-distance scale where true scale would
    shrink the lobes to dots -, plus ``outdir/keepout.vtm`` for ParaView (true
    coordinates). Each picture is the 3-D view with a title strip above and its legend
    beside it (never cut; :func:`hazard.pictures.picture.compose`). Returns the paths written,
    under ``"layout"`` where the scene and the legend are in each picture [px], and under
    ``"figures"`` the pictures' figures.json entries ({file name:
    :func:`hazard.outputs.figure_index.view_entry`}: what each draws and whether the camera shows it)."""
    out = Path(outdir)
    out.mkdir(parents=True, exist_ok=True)
    png = out / "keepout.png"
    if png.exists() and not force:
        raise FileExistsError(f"{png} exists: pass --force to overwrite")
    paths, layout, index = {}, {}, {}
    with terminal_bar(4 if vtk else 3, "renders", unit="step", leave=True) as bar:  # terminals only
        bar.set_postfix_str("lobe surfaces")
        blocks = _scene_blocks(result, lobe_resolution_deg)
        frames = framings(result, blocks)
        bar.update()
        for name, title in (("keepout", f"{result.scene.name}: keep-out zones (close view)"), ("overview", f"{result.scene.name}: overview")):
            bar.set_postfix_str(f"{name}.png")
            p, legend = _draw(result, blocks, frames[name], window_size)
            img = p.screenshot(None, return_img=True)
            lines = _title_lines(result, frames[name], title)
            shown = set(lines) | {e[0] for e in legend} | set(p.__dict__.get("_hazard_tags", []))
            index[f"{name}.png"] = view_entry("3d", _panel(result, frames[name], title), _notes(result, blocks, frames[name], legend),
                                              _world_to_clip(p, window_size), shown)
            index[f"{name}.png"]["not_drawn"] = not_drawn(result)
            index[f"{name}.png"]["text_px_min"] = round(text_px_min(legend, lines, TAG_PX if p.__dict__.get("_hazard_tags") else None), 2)
            p.close()
            picture, layout[name] = compose(img, legend, lines)
            paths[name] = write_png(picture, out / f"{name}.png")
            bar.update()
        if vtk:
            bar.set_postfix_str("keepout.vtm")
            vtm = out / "keepout.vtm"
            blocks.save(str(vtm))
            paths["vtm"] = vtm
            bar.update()
    paths["png"] = paths["keepout"]
    paths["layout"] = layout
    paths["figures"] = index
    return paths


def _animation_notes(result, dyn, env, lobe_resolution_deg) -> tuple:
    """The animation's caption naming every lobe it draws, and its figures.json notes
    (the dynamic lobes' envelopes over the history, the other targets' static lobes)."""
    paths, off = finding_paths(result), np.asarray(result.scene.offset_m, float)
    dynamic = {sp.target.name for sp in dyn}
    lobes = [(sp.target.name, "dynamic" if sp.target.name in dynamic else "static") for sp in result.spots]
    groups = [(k, ", ".join(t for t, kk in lobes if kk == k)) for k in ("dynamic", "static")]
    caption = "keep-out lobes, colour NOHD [m]: " + "; ".join(
        f"{k}{' (the first frame: static)' if k == 'dynamic' else ''} {names}" for k, names in groups if names)
    notes = []
    for sp, (target, kind) in zip(result.spots, lobes):
        grid = env[[s.target.name for s in dyn].index(target)] if kind == "dynamic" else \
            lobe_grid(sp, result.mpe_w_m2, result.attenuation_per_m, None, lobe_resolution_deg)
        pts = _points(grid)
        own = lobe_paths(paths, lobes, target, kind) + (lobe_paths(paths, [], target, "static")[:1] if kind == "dynamic" else [])
        notes.append((own, caption, pts, "surface", pts + off))
    return caption, notes


def animate_lobe(result, outdir, *, max_frames=30, lobe_resolution_deg=4.0, window_size=(800, 600)) -> dict:
    """The dynamic lobe over the history: a GIF if imageio is installed (and its
    figures.json entry under ``"figures"``, :func:`hazard.outputs.figure_index.view_entry`),
    else PNG frames."""
    out = Path(outdir)
    frames_dir = out / "frames"
    frames_dir.mkdir(parents=True, exist_ok=True)
    dyn = [sp for sp in result.spots if sp.target.index in result.states]
    if not dyn:
        raise ValueError("animate_lobe: the scene has no dynamic material (nothing changes over time)")
    idx = np.unique(np.linspace(0, len(result.times_s) - 1, min(max_frames, len(result.times_s))).astype(int))
    # fixed camera: fit the envelope of all frames
    env = [lobe_grid(sp, result.mpe_w_m2, result.attenuation_per_m, _time_ordered_states(result, sp), lobe_resolution_deg) for sp in dyn]
    bounds = pv.MultiBlock(env).bounds
    caption, notes = _animation_notes(result, dyn, env, lobe_resolution_deg)
    paths = []
    with terminal_bar(len(idx), "lobe animation frames", unit="frame", leave=True) as bar:  # terminals only
        for n, i in enumerate(idx):
            p = pv.Plotter(off_screen=True, window_size=list(window_size))
            p.set_background("white")
            for sp in result.spots:
                p.add_mesh(_mesh(sp.target.mesh.vertices, sp.target.mesh.faces), color="#555555")
                st = result.states.get(sp.target.index)
                g = lobe_grid(sp, result.mpe_w_m2, result.attenuation_per_m, None if st is None else st[i:i + 1], lobe_resolution_deg)
                p.add_mesh(g, scalars="nohd_m", cmap="viridis", clim=[0, max(e["nohd_m"].max() for e in env)],
                           scalar_bar_args={"title": "NOHD [m]", "color": "black"})
            p.add_text(f"t = {result.times_s[i]:.3g} s", font_size=12, color="black")
            p.add_text(caption, position="upper_right", font_size=9, color="black")
            p.show_bounds(bounds=bounds, color="black", font_size=8)
            p.camera_position = "iso"
            p.reset_camera(bounds=bounds)
            f = frames_dir / f"frame_{n:03d}.png"
            p.screenshot(str(f))
            clip = _world_to_clip(p, window_size)
            p.close()
            paths.append(f)
            bar.update()
    result_paths = {"frames": paths}
    try:
        import imageio.v2 as imageio
    except ImportError:
        return result_paths
    title = f"{result.scene.name}: the dynamic keep-out lobe over the history"
    box = np.reshape(bounds, (3, 2))
    panel = _panel(result, Framing(box, box.mean(axis=1)), title, box)
    result_paths["figures"] = {"lobe.gif": view_entry("animation", panel, notes, clip, {caption})}
    gif = out / "lobe.gif"
    from brdfmodels.fileio import atomic_write

    atomic_write(gif, lambda tmp: imageio.mimsave(tmp, [imageio.imread(f) for f in paths], duration=0.15), keep_suffix=True)
    result_paths["gif"] = gif
    return result_paths
