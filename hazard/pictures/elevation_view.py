"""The elevation view of a run (issue 18): the side view that says how high the hazard
reaches, for masts, towers, hillsides and aircraft.

Horizontal axis: distance along the aim's azimuth from the laser [m] (the view of
:func:`hazard.outputs.lobe_outline.elevation_frame`); vertical axis: height [m] in the scene's
world frame. Everything is projected across the aim onto that vertical plane: the aim
line to the danger zone's range, the terrain profile under the aim line and the eye
height above it (scenes with ground), the targets, the projection of every keep-out lobe
(static and dynamic, exact in radius, drawn outward between sampled angles), the mirror
beams to their NOHD, and the observers coloured by verdict with the worst hazardous ones
named. A projection keeps every height and loses the lateral offset: the plan view says
where across the aim a thing is. Two panels as in the plan view: the whole range (its
vertical scale exaggerated at most ``MAX_EXAGGERATION`` times, said on the axis) and the
site (at equal scale up to ``SITE_EQUAL_MAX_M`` long, a longer one with its heights
exaggerated between 1 and ``MAX_EXAGGERATION`` times, said too). The aim line ends at the danger zone's range and is never drawn
through the ground (dotted past its centre's first ground contact); the flight zones
(floor to ceiling over their span along the aim) and the tracks are drawn too (issue 34). Colours:
:mod:`hazard.pictures.palette`. Written by ``hazard run --plot`` (``elevation.png``) and by
``hazard render``. matplotlib is imported when it draws.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from hazard.pictures import palette as C
from hazard.outputs.figure_index import lobe_paths, mark
from hazard.outputs.label_place import place_labels
from hazard.pictures.plan_view import aim_reach_m, draw_mirrors, hull_outline, draw_hazardous, draw_lobe, draw_scale_bar, hazardous_labels, keep_texts_inside, label_points, legend_below, square_limits, two_lines, two_panels
from hazard.outputs.finding_geometry import mirror_segments
from hazard.pictures.plots import DisplayBase

__all__ = ["ElevationViewDisplay"]


@dataclass
class ElevationViewDisplay(DisplayBase):
    """Elevation-view data in (distance along the aim's azimuth, height) [m]."""

    FIGSIZE_IN = (10.2, 4.6)  # printed on a landscape A4 page (hazard.canvas.PRINTED_WIDTH_IN["wide"]): 6 pt text prints at 6 pt
    DPI = 165  # about as many pixels as the 15 in figure at 110 dpi had

    title: str
    laser_sz: np.ndarray  # (2,)
    aim_sz: np.ndarray  # (2, 2) the aim line from the laser to the zone's range
    targets: list = field(default_factory=list)  # (name, sz)
    lobes: list = field(default_factory=list)  # (target, kind, [rings (K, 2)])
    mirrors: list = field(default_factory=list)  # (name, sz start, sz end)
    profile: tuple | None = None  # (s (n,), ground height (n,), eye height above it [m])
    observers_sz: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))
    hazardous: np.ndarray = field(default_factory=lambda: np.zeros(0, bool))
    labels: list = field(default_factory=list)
    unlabelled: int = 0
    paths: dict = field(default_factory=dict)  # report.json paths of what is drawn (:func:`hazard.outputs.figure_index.finding_paths`)
    aim_past: np.ndarray | None = None  # (2, 2) the aim line past its centre's first meeting with the ground (dotted)
    aim_label: str = "aim line (to the danger zone's range)"
    tracks: list = field(default_factory=list)  # (paths, name, (N, 2) sz, text) moving observers
    flight_zones: list = field(default_factory=list)  # (path, (4, 2) sz box: along-aim span x floor-ceiling, exceeded, text, worst sz)
    mirror_zones: list = field(default_factory=list)  # (target, eye, (K, 2) sz outline): :func:`hazard.physics.mirror_zone.side_view_ring`
    occluders_cut: list = field(default_factory=list)  # (K, 2) sz rings: occluders' sections by the aim's vertical plane
    occluders_beside: list = field(default_factory=list)  # (K, 2) sz outlines: occluders that plane misses, projected

    @classmethod
    def from_result(cls, result) -> "ElevationViewDisplay":
        from hazard.outputs.lobe_outline import elevation_frame, lobe_outlines

        scene = result.scene
        view = elevation_frame(scene.laser_position_m, scene.laser_direction)
        up = np.array([0.0, float(scene.offset_m[2])])  # local z -> world height

        def sz(points):
            return view.to_2d(points) + up

        zone_reach = aim_reach_m(result)
        spots = {sp.target.name: sp.centroid for sp in result.spots}
        reach = max(zone_reach, 2.0 * max([float(np.linalg.norm(c - scene.laser_position_m)) for c in spots.values()] + [1.0]))
        reach = min(reach, 1e5)
        frame = sz(np.array([scene.laser_position_m, scene.laser_position_m + scene.laser_direction * reach]))  # the terrain drawn
        drawn = zone_reach if zone_reach > 0 else reach  # the aim line to the zone's range, never past it
        aim = sz(np.array([scene.laser_position_m, scene.laser_position_m + scene.laser_direction * drawn]))
        targets = [(t.name, sz(spots.get(t.name, t.center_m))) for t in scene.targets]
        lobes = [(o.target, o.kind, [r + up for r in o.rings()]) for o in lobe_outlines(result, view)]
        mirrors = [(name, sz(a), sz(b)) for name, a, b in mirror_segments(result)]
        obs = np.asarray(result.observers.position_m, float).reshape(-1, 3) - scene.offset_m  # world -> local, as sz takes
        obs_sz = sz(obs) if len(obs) else np.zeros((0, 2))
        labels, more = hazardous_labels(result, obs_sz)
        d = cls(f"{scene.name}: elevation view", sz(scene.laser_position_m), aim, targets, lobes, mirrors,
                _profile(scene, view, frame, obs_sz, up), obs_sz, np.asarray(result.hazardous, bool), labels, more)
        from hazard.physics.mirror_zone import mirror_zones, side_view_ring

        d.mirror_zones = [(m.target, m.eye, ring) for m in mirror_zones(result) if (ring := side_view_ring(m, sz)) is not None]
        d.aim_sz, d.aim_past = clip_at_ground(aim, d.profile)
        d.occluders_cut, d.occluders_beside = occluder_outlines(scene.occluders, view, sz)
        d.aim_label = "aim line (to the danger zone's range)" if zone_reach > 0 else "aim line"
        from hazard.outputs.figure_index import finding_paths, flight_zone_rings, track_lines

        d.paths = finding_paths(result)
        off = np.asarray(scene.offset_m, float)
        d.tracks = [(p, name, sz(xyz - off), text) for p, name, xyz, text in track_lines(result, d.paths)]
        d.flight_zones = [(path, _zone_box(result, spec, ring, lambda q: sz(q - off)), exceeded, text, sz(worst - off))
                          for path, ring, exceeded, text, spec, worst in flight_zone_rings(result)]
        return d

    def plot(self, axes=None):
        """Two panels: the whole range and the site. Returns (figure, axes)."""
        fig, axes = two_panels(axes, self.FIGSIZE_IN)
        limits = self.site_limits()
        for ax, title in ((axes[0], "the range"), (axes[1], "the site")):
            self._draw(ax)
            ax.set_xlabel("distance along the aim's azimuth from the laser [m]")
            ax.locator_params(axis="x", nbins=5)  # five-digit distances on a 4.5 in panel: fewer ticks, none touching
            ax.set_title(f"{self.title}: {title}")
            ax.grid(alpha=0.25)
        axes[1].set_xlim(limits[0], limits[1])
        long_site = limits[1] - limits[0] > SITE_EQUAL_MAX_M  # equal scale would flatten its heights to a line
        axes[1].set_ylim(*(self.site_heights() if long_site else limits[2:]))
        axes[1].set_ylabel("height [m] (vertical scale x10)")  # the longest label it can get, for the layout
        fig.tight_layout()
        fig.canvas.draw()
        for ax, equal in ((axes[0], None), (axes[1], limits[2:])):
            exaggeration = readable_heights(ax)
            if equal is not None and (exaggeration < 1.0 or not long_site):  # a short site, or heights beyond the distances
                ax.set_aspect("equal", adjustable="box")
                ax.set_ylim(*equal)
                exaggeration = 1.0
            ax.set_ylabel(f"height [m] (vertical scale x{exaggeration:.3g})" if abs(exaggeration - 1) > 0.05
                          else "height [m] (equal scale)")
        label_points(axes[1], self.labels)
        legend_below(fig, axes[1])
        for ax in axes:
            draw_scale_bar(ax, "lower right")
        fig.canvas.draw()
        for ax in axes:
            keep_texts_inside(ax)
            place_labels(ax)
        return fig, axes

    def site_limits(self) -> tuple:
        """s0, s1, z0, z1 [m] around the targets, their lobes and the hazardous observers
        (at least 20 m about each target), 10 % wider; equal scale."""
        pts = [sz[None] + 20.0 * np.array([[-1.0, -1.0], [1.0, 1.0]]) for _, sz in self.targets] or [self.laser_sz[None]]
        pts += [r for _, _, rings in self.lobes for r in rings]
        pts += [self.observers_sz[self.hazardous]] if self.hazardous.any() else []
        return square_limits(pts)

    def site_heights(self) -> tuple:
        """z0, z1 [m]: the heights of the site panel's contents (the targets, their lobes,
        the hazardous observers), 10 % (at least 1 m) wider each side: the heights of a
        site panel longer than ``SITE_EQUAL_MAX_M``, exaggerated at most
        ``MAX_EXAGGERATION`` times (:func:`readable_heights`) and at least not at all, so
        that a site kilometres long is not drawn flat."""
        pts = [sz[None] for _, sz in self.targets] or [self.laser_sz[None]]
        pts += [r for _, _, rings in self.lobes for r in rings]
        pts += [self.observers_sz[self.hazardous]] if self.hazardous.any() else []
        z = np.vstack(pts)[:, 1]
        pad = max(0.1 * float(np.ptp(z)), 1.0)
        return float(z.min()) - pad, float(z.max()) + pad

    def _draw(self, ax):
        if self.profile is not None:
            s, ground, eye = self.profile
            floor = ground.min() - max(1.0, 0.2 * float(np.ptp(ground)))
            ax.fill_between(s, ground, floor, color=C.GROUND, lw=0, label="terrain under the aim line")
            ax.plot(s, ground + eye, c="#4d7a3a", lw=0.8, ls=":", label=f"eye height ({eye:g} m) above it")
        self._draw_occluders(ax)
        ax.plot(*self.aim_sz.T, c=C.ZONE, lw=0.9, ls="--", label=self.aim_label)
        if self.aim_past is not None:
            ax.plot(*self.aim_past.T, c=C.ZONE, lw=0.6, ls=":", alpha=0.7,
                    label="aim line past its centre's ground contact (part of the beam goes on)")
        seen = set()
        for target, kind, rings in self.lobes:
            draw_lobe(ax, kind, rings, None if kind in seen else f"{kind} keep-out lobe (projected)")
            seen.add(kind)
            for ring in rings:
                mark(ax, lobe_paths(self.paths, self.lobes, target, kind), f"{kind} keep-out lobe (projected)", ring, "polygon")
        draw_mirrors(ax, self.paths, self.mirror_zones, self.mirrors)  # as in the plan view
        self._draw_airspace(ax)
        ax.plot(*self.laser_sz, marker="^", ms=10, c="k", ls="", label="laser")
        for i, (name, sz) in enumerate(self.targets):
            ax.plot(*sz, marker="s", ms=6, mfc="white", mec=C.TARGET, ls="", label="targets" if i == 0 else None)
            ax.annotate(name, sz, xytext=(4, 4 - 12 * (i % 2)), textcoords="offset points", fontsize=7)
        if len(self.observers_sz):
            safe = ~self.hazardous
            ax.scatter(*self.observers_sz[safe].T, s=6, c=C.SAFE, lw=0, zorder=11,  # over the crosses: a safe one beside a hazardous one stays seen
                       label=f"observers below the MPE ({int(safe.sum())})")
            rows = self.paths.get("observers", {})
            draw_hazardous(ax, self.observers_sz[self.hazardous], self.unlabelled,
                           [rows.get(int(i)) for i in np.flatnonzero(self.hazardous)])

    def _draw_occluders(self, ax):
        """Occluders the aim's vertical plane cuts, filled (what stands under or across the aim
        line); the others outlined dashed (beside the aim: the plan view says where)."""
        for i, ring in enumerate(self.occluders_cut):
            ax.fill(*ring.T, fc="#999999", ec="#555555", lw=0.8, zorder=3,
                    label="occluders cut by the aim's vertical plane" if i == 0 else None)
        for i, ring in enumerate(self.occluders_beside):
            ax.plot(*ring.T, c="#777777", lw=0.8, ls="--", zorder=3,
                    label="occluders beside the aim's plane (projected)" if i == 0 else None)

    def _draw_airspace(self, ax):
        """Flight zones as their along-aim span between floor and ceiling (exceeded: red
        hatched) and the moving observers' tracks projected, each named with its verdict."""
        for k, (path, box, exceeded, text, worst) in enumerate(self.flight_zones):
            colour = C.HAZARDOUS if exceeded else "#555555"
            ax.plot(*worst, marker="*", ms=9, c=colour, mec="k", ls="", zorder=12,
                    label="flight zones' worst points (FAA levels)" if k == 0 else None)
            closed = np.vstack([box, box[:1]])
            ax.fill(*closed.T, fc="none", ec=colour, lw=1.2, hatch="//" if exceeded else None, ls="-" if exceeded else "--")
            text = two_lines(text)  # as in the plan view: one line ran out of the panel
            ax.annotate(text, box.mean(axis=0), fontsize=6, ha="center", va="center", color=colour, zorder=11, wrap=True,
                        bbox=dict(boxstyle="round,pad=0.2", fc="white", ec=colour, lw=0.5, alpha=0.85))
            mark(ax, [path], text, closed, "polygon")
        for k, (paths, _name, pts, text) in enumerate(self.tracks):
            ax.plot(*pts.T, c="#6a3d9a", lw=1.4, label="moving observers' tracks (projected)" if k == 0 else None)
            ax.annotate(text, pts[0], xytext=(0, 8), textcoords="offset points", fontsize=6, color="#6a3d9a", zorder=11,
                        bbox=dict(boxstyle="round,pad=0.2", fc="white", ec="none", alpha=0.8))
            mark(ax, paths, text, pts, "line")


def occluder_outlines(occluders, view, sz) -> tuple:
    """(cut, beside): the closed (K, 2) rings in (distance, height) [m] of each occluder mesh's
    section by the view's vertical plane through the aim line, and, for an occluder that plane
    misses, the outline (convex hull) of its projection onto it. ``sz`` maps local points to
    the view's coordinates."""
    from shapely.geometry import MultiLineString
    from shapely.ops import polygonize

    cut, beside = [], []
    for mesh in occluders:
        segments = plane_section(mesh.vertices, mesh.faces, view.origin_m, view.n)
        if len(segments):
            lines = MultiLineString([sz(seg).tolist() for seg in segments])
            cut += [np.asarray(p.exterior.coords) for p in polygonize(lines.geoms)] or \
                   [np.asarray(line.coords) for line in lines.geoms]  # an open section (a plate edge-on): its segments
            continue
        beside.append(hull_outline(sz(np.asarray(mesh.vertices, float))))
    return cut, beside


def plane_section(vertices_m, faces, origin_m, normal) -> np.ndarray:
    """Segments (S, 2, 3) [m] where the triangles cross the plane through ``origin_m`` with
    unit ``normal``: on each edge whose ends lie on opposite sides, the point at which the
    signed distance is zero (linear along the edge). Triangles that only touch it are left out."""
    vertices_m = np.asarray(vertices_m, float)
    dist = (vertices_m - np.asarray(origin_m, float)) @ np.asarray(normal, float)  # signed, per vertex
    faces = np.asarray(faces)
    d = dist[faces]  # (F, 3)
    faces = faces[(d > 0).any(axis=1) & (d < 0).any(axis=1)]
    lo = np.minimum(faces, np.roll(faces, -1, axis=1))  # the three edges, each from its lower vertex index:
    hi = np.maximum(faces, np.roll(faces, -1, axis=1))  # the two triangles on an edge get the same point, bit for bit
    crossed = (dist[lo] > 0) != (dist[hi] > 0)  # (F', 3): two per crossing triangle
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.where(crossed, dist[lo] / (dist[lo] - dist[hi]), 0.0)
    points = vertices_m[lo] + t[..., None] * (vertices_m[hi] - vertices_m[lo])  # (F', 3, 3)
    two = crossed.sum(axis=1) == 2
    return points[two][crossed[two]].reshape(-1, 2, 3)


def clip_at_ground(aim, profile) -> tuple:
    """(the aim line (2, 2) up to where its centre first meets the ground under it, the
    rest (2, 2) or None): an aim line is never drawn through a hill. ``profile``: (s,
    ground height, eye height) of :func:`_profile`, or None (no ground: nothing to clip)."""
    if profile is None:
        return aim, None
    s, ground, _ = profile
    (s0, z0), (s1, z1) = aim
    if not s1 > s0:
        return aim, None
    on = (s > s0 + 1e-9) & (s <= s1)
    z = z0 + (s[on] - s0) * (z1 - z0) / (s1 - s0)
    below = np.flatnonzero(z < ground[on])
    if not len(below):
        return aim, None
    k = below[0]
    prev_s, prev_z, prev_g = (s0, z0, None) if k == 0 else (s[on][k - 1], z[k - 1], ground[on][k - 1])
    cut = s[on][k]
    if prev_g is not None:  # where the line crosses the ground between the two samples
        a, b = prev_z - prev_g, z[k] - ground[on][k]
        cut = prev_s + (s[on][k] - prev_s) * a / (a - b)
    hit = np.array([cut, z0 + (cut - s0) * (z1 - z0) / (s1 - s0)])
    return np.array([aim[0], hit]), np.array([hit, aim[1]])


SITE_EQUAL_MAX_M = 1000.0  # a site panel up to 1 km long is drawn at equal scale (a lobe's true shape); a longer one exaggerated
MAX_EXAGGERATION = 10.0  # the range panel's vertical exaggeration at most: a 1 deg slope is drawn at most 10 deg


def readable_heights(ax, max_exaggeration=MAX_EXAGGERATION) -> float:
    """Widen ``ax``'s height range (about its middle) so that its vertical exaggeration
    (height scale over distance scale) is at most ``max_exaggeration``: a nearly level
    beam is not drawn as a vertical line, a lobe metres tall not as a bar across a
    kilometre axis. Returns the exaggeration the panel shows (said on its axis)."""
    x0, x1 = ax.get_xlim()
    y0, y1 = ax.get_ylim()
    box = ax.get_window_extent()
    exaggeration = (box.height / (y1 - y0)) / (box.width / (x1 - x0))
    if exaggeration > max_exaggeration:
        half = 0.5 * (y1 - y0) * exaggeration / max_exaggeration
        mid = 0.5 * (y0 + y1)
        ax.set_ylim(mid - half, mid + half)
        exaggeration = max_exaggeration
    return float(exaggeration)


def _profile(scene, view, aim, obs_sz, up):
    """The terrain height under the aim line over the panel's distances, where the terrain
    grid reaches (or None)."""
    t = scene.terrain
    if t is None:
        return None
    s_all = np.concatenate([aim[:, 0], obs_sz[:, 0] if len(obs_sz) else [], [0.0]])
    s = np.linspace(min(0.0, s_all.min()) - 0.05 * np.ptp(s_all), s_all.max() + 0.05 * np.ptp(s_all), 2001)
    xy = view.origin_m[:2] + s[:, None] * view.a[:2]
    ny, nx = t.heights.shape
    inside = ((xy[:, 0] >= t.x0) & (xy[:, 0] <= t.x0 + t.dx * (nx - 1)) & (xy[:, 1] >= t.y0)
              & (xy[:, 1] <= t.y0 + t.dx * (ny - 1)))  # the terrain is not drawn past its edge
    if not inside.any():
        return None
    s = s[inside]
    ground = t.height_at(xy[inside, 0], xy[inside, 1]) + up[1]
    return s, ground, float(scene.spec.analysis.footprint_eye_height_m)


def _zone_box(result, spec, ring, to_sz) -> np.ndarray:
    """(4, 2) a flight zone in the elevation view: the span of its outline along the aim's
    azimuth, from its floor to its ceiling above the lowest ground under its outline."""
    scene = result.scene
    off = np.asarray(scene.offset_m, float)
    ground = (scene.terrain.height_at(ring[:, 0] - off[0], ring[:, 1] - off[1]) + off[2]) if scene.terrain is not None \
        else np.zeros(len(ring))
    s = to_sz(np.column_stack([ring, ground]))[:, 0]
    g = float(np.min(ground))
    lo, hi = g + float(spec.floor_agl_m), g + float(spec.ceiling_agl_m)
    return np.array([[s.min(), lo], [s.max(), lo], [s.max(), hi], [s.min(), hi]])
