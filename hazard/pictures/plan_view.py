"""The plan view of a run (issue 13 item 8): what a range safety officer pins on the wall.

World x (east) and y (north, +y) in metres, equal scale, with a scale bar and a north
arrow: the laser surface danger zone (naked eye filled, through each optical aid
outlined), the aim line, the range boundary, the targets with their diffuse hazard
circles (radius: the target's longest diffuse NOHD, a plan-view bound of its lobe) and
mirror beams (the specular NOHD along the mirror axis, projected), the hazardous ground
at eye height (terrain footprints), terrain contours and the observers coloured by
verdict, the worst hazardous ones labelled. Issue 18 adds the outline of every
keep-out lobe (static and dynamic, :mod:`hazard.outputs.lobe_outline`: the section at the
footprint's eye height over terrain, else the plan projection of the lobe at any height)
and range rings about the laser (the range panel) and the targets (the site panel).
Issue 34 adds the flight zones, the moving observers' tracks and the direct beam's FAA
distances (an arrow with the distance for one off the frame), mirror beams drawn to
where the analysis stops them with each beam's end said, the hazardous ground as cells
at their true size, and notes for figures.json (:mod:`hazard.outputs.figure_index`) of every
finding drawn. Colours: :mod:`hazard.pictures.palette`. Written by ``hazard run --plot`` (``plan.png`` with the
other outputs, as one unit) and by ``hazard render``. matplotlib is imported when it
draws.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from hazard.pictures import palette as C
from hazard.outputs.label_place import place_labels
from hazard.physics.mirror_zone import mirror_zones
from hazard.pictures.plots import DisplayBase
from hazard.outputs.finding_geometry import drawn_length_m as _drawn_length_m, lobe_rings, mirror_lines, mirror_segments

__all__ = ["legend_below", "two_lines", "PlanViewDisplay", "hazardous_labels", "lobe_rings", "label_points", "mirror_segments", "mirror_lines"]

MIRROR_LABEL = "mirror beams (to the specular NOHD, or where a backstop stops them)"
MIRROR_ZONE_LABEL = "mirror beams' hazard zones (their width; dashed: through optics)"
SITE_CONTEXT = 3.0  # the site panel also frames occluders and safe observers this many half-widths about the hazard
MIN_ZONE_PT = 4.0  # a danger zone drawn narrower than this [pt] is also outlined exaggerated across the aim, and said
LABELLED = 8  # hazardous observers named in a picture (the worst by hazard ratio); the rest are counted


@dataclass
class PlanViewDisplay(DisplayBase):
    """Plan-view data in world x, y [m] (see the module notes); ``plot`` only draws."""

    FIGSIZE_IN = (10.2, 5.6)  # printed on a landscape A4 page (hazard.canvas.PRINTED_WIDTH_IN["wide"]): 6 pt text prints at 6 pt
    DPI = 165  # as many pixels as the 15 in figure at 110 dpi had

    title: str
    laser_xy: np.ndarray
    aim_xy: np.ndarray  # (2, 2): the aim line from the laser to the zone's range
    zone: np.ndarray | None  # (K, 2) the naked-eye LSDZ ring
    zone_label: str
    aided_zones: list = field(default_factory=list)  # (label, ring)
    nominal: np.ndarray | None = None  # (K, 2) a sector's zone without the pointing buffer
    boundary: np.ndarray | None = None
    targets: list = field(default_factory=list)  # (name, xy, diffuse NOHD [m], longest aided diffuse NOHD [m], framed)
    mirrors: list = field(default_factory=list)  # (name, xy start, xy end)
    footprint_xy: np.ndarray | None = None  # (N, 2) hazardous ground nodes
    footprint_cell_m: float = 0.0
    contours: tuple | None = None  # (x (nx,), y (ny,), heights (ny, nx))
    observers_xy: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))
    hazardous: np.ndarray = field(default_factory=lambda: np.zeros(0, bool))
    aided: np.ndarray = field(default_factory=lambda: np.zeros(0, bool))  # observers with optics
    occluders: list = field(default_factory=list)  # (K, 2) plan outlines (convex hulls)
    lobes: list = field(default_factory=list)  # (target, kind, cut, [exterior rings (K, 2)], [holes]) world x, y
    labels: list = field(default_factory=list)  # (xy, text): the worst hazardous observers
    unlabelled: int = 0  # hazardous observers not named in the picture
    paths: dict = field(default_factory=dict)  # report.json paths of what is drawn (:func:`hazard.outputs.figure_index.finding_paths`)
    tracks: list = field(default_factory=list)  # (paths, name, (N, 2) xy, text) moving observers
    flight_zones: list = field(default_factory=list)  # (path, (K, 2) ring, exceeded, text, spec, worst point)
    faa: list = field(default_factory=list)  # (path, text, world point) FAA visual-interference distances
    ends: list = field(default_factory=list)  # (xy, text): where the danger zone and each mirror beam end, and why
    mirror_zones: list = field(default_factory=list)  # (target, eye, (K, 2) ring, xy start, unit plan direction): :mod:`hazard.physics.mirror_zone`

    @classmethod
    def from_result(cls, result) -> "PlanViewDisplay":
        scene = result.scene
        off = np.asarray(scene.offset_m, float)
        z = getattr(result, "sdz", None)
        laser = np.asarray(scene.laser_position_m, float) + off
        reach = aim_reach_m(result)
        aim = np.array([laser[:2], laser[:2] + np.asarray(scene.laser_direction, float)[:2] * reach])
        zone = np.asarray(z.polygon_m, float) if z is not None and z.polygon_m else None
        aim = clip_to_zone(aim, zone)
        aided = [(f"LSDZ through {a.aid.magnification:g}x{1e3 * a.aid.objective_diameter_m:g} optics", np.asarray(a.polygon_m, float))
                 for a in (() if z is None else z.aided)]
        boundary = np.asarray(scene.spec.range.boundary_m, float) if scene.spec.range is not None else None
        obs = result.observers
        nominal = np.asarray(z.nominal.polygon_m, float) if z is not None and z.nominal is not None else None
        with_optics = np.array([o is not None for o in obs.observers.optics], bool)
        d = cls(f"{scene.name}: plan view", laser[:2], aim, zone, _zone_label(z), aided, nominal, boundary,
                   _targets(result, off), _mirrors(result, off), *_footprint(result, off), _contours(scene, off),
                   np.asarray(obs.position_m, float)[:, :2] if len(obs.position_m) else np.zeros((0, 2)),
                   np.asarray(result.hazardous, bool),
                   with_optics[obs.observers.group] if len(obs.position_m) and len(with_optics) else np.zeros(len(obs.position_m), bool),
                   _occluders(scene, off), lobe_rings(result, off[:2]), *hazardous_labels(result, np.asarray(obs.position_m, float)[:, :2]
                                                                                            if len(obs.position_m) else np.zeros((0, 2))))
        from hazard.outputs.figure_index import faa_marks, finding_paths, flight_zone_rings, track_lines

        d.paths = finding_paths(result)
        d.tracks = [(p, name, xyz[:, :2], text) for p, name, xyz, text in track_lines(result, d.paths)]
        d.flight_zones = flight_zone_rings(result)
        d.faa = faa_marks(result)
        d.ends = beam_ends(result, d.aim_xy[1], off)
        d.mirror_zones = _mirror_zone_rings(result, off)
        return d

    def plot(self, axes=None):
        """Two panels: the whole range (the zone may reach tens of km) and the site (laser,
        targets, observers, hazardous ground). Returns (figure, axes)."""
        fig, axes = two_panels(axes, self.FIGSIZE_IN)
        for ax, title, limits in ((axes[0], "the range", None), (axes[1], "the site", self.site_limits())):
            self._draw_ground(ax)
            self._draw_zones(ax)
            self._draw_lobes(ax)
            self._draw_objects(ax)
            self._draw_airspace(ax)
            ax.set_aspect("equal", adjustable="box" if limits is not None else "datalim")
            if limits is not None:
                ax.set_xlim(limits[0], limits[1])
                ax.set_ylim(limits[2], limits[3])
            ax.set_xlabel("x (east) [m]")
            ax.locator_params(axis="x", nbins=5)  # five-digit distances on a 4.5 in panel: fewer ticks, none touching
            ax.set_ylabel("y (north) [m]")
            ax.set_title(f"{self.title}: {title}")
        label_points(axes[1], self.labels)
        legend_below(fig, axes[1])
        fig.tight_layout()
        fig.canvas.draw()  # settle the limits before the scale bars and the arrows
        for ax in axes:
            draw_scale_bar(ax, quiet_corner(ax, self._key_points()))
            _north_arrow(ax)
        _range_rings(axes[0], [self.laser_xy], "from the laser")
        framed = [(name, xy) for name, xy, r, ra, f in self.targets if f]
        what = f"from {framed[0][0]}" if len(framed) == 1 else "from the targets" if framed else "from the laser"
        _range_rings(axes[1], [xy for _, xy in framed] or [self.laser_xy], what)
        self._draw_faa(axes[0])
        for ax in axes:
            self._draw_thin_zone(ax)
        fig.canvas.draw()
        for ax in axes:
            keep_texts_inside(ax)
            place_labels(ax)
        return fig, axes

    def _draw_airspace(self, ax):
        """Flight zones (exceeded: red hatched) and the moving observers' tracks, each named
        with its verdict."""
        from hazard.outputs.figure_index import mark

        for k, (path, ring, exceeded, text, _, worst) in enumerate(self.flight_zones):
            colour = C.HAZARDOUS if exceeded else "#555555"
            ax.plot(*worst[:2], marker="*", ms=9, c=colour, mec="k", ls="", zorder=12,
                    label="flight zones' worst points (FAA levels)" if k == 0 else None)
            closed = np.vstack([ring, ring[:1]])
            ax.fill(*closed.T, fc="none", ec=colour, lw=1.4, hatch="//" if exceeded else None, ls="-" if exceeded else "--")
            text = two_lines(text)  # one line of ~95 characters ran out of a 4.5 in panel
            ax.annotate(text, ring.mean(axis=0), fontsize=6, ha="center", va="center",
                        color=colour, zorder=11, bbox=dict(boxstyle="round,pad=0.2", fc="white", ec=colour, lw=0.5, alpha=0.85))
            mark(ax, [path], text, closed, "polygon")
        for k, (paths, _name, xy, text) in enumerate(self.tracks):
            ax.plot(*xy.T, c="#6a3d9a", lw=1.4, label="moving observers' tracks" if k == 0 else None)
            ax.annotate("", xy=xy[-1], xytext=xy[max(0, len(xy) - 2)], arrowprops=dict(arrowstyle="-|>", color="#6a3d9a"))
            ax.annotate(text, xy[0], xytext=(0, -10), textcoords="offset points", fontsize=6, color="#6a3d9a", zorder=11,
                        bbox=dict(boxstyle="round,pad=0.2", fc="white", ec="none", alpha=0.8))
            mark(ax, paths, text, xy, "line")

    def _draw_faa(self, ax):
        """The direct beam's FAA distances on the aim: a tick and its name in the frame,
        else an arrow at the edge with the distance."""
        from hazard.outputs.figure_index import arrow_to, mark

        x0, x1 = ax.get_xlim()
        y0, y1 = ax.get_ylim()
        for path, text, xyz in self.faa:
            xy = np.asarray(xyz, float)[:2]
            if x0 <= xy[0] <= x1 and y0 <= xy[1] <= y1:
                ax.plot(*xy, marker="D", ms=5, mfc="#ffd92f", mec="k", ls="", zorder=12)
                ax.annotate(text, xy, xytext=(6, 0), textcoords="offset points", fontsize=6, va="center", zorder=12,
                            bbox=dict(boxstyle="round,pad=0.2", fc="#fff7bc", ec="none", alpha=0.9))
                mark(ax, [path], text, xy)
            else:
                arrow_to(ax, [path], text, self.laser_xy, xy)
        ax.set_xlim(x0, x1)
        ax.set_ylim(y0, y1)

    def site_limits(self) -> tuple:
        """x0, x1, y0, y1 [m] around the targets: their diffuse hazard circles (naked and
        aided, at least 20 m), the hazardous observers and the hazardous ground, 10 %
        wider; then widened to the occluders and the safe observers within
        ``SITE_CONTEXT`` times that frame's half-width of its centre (what stands
        around the hazard; the range panel shows the rest)."""
        pts = [np.asarray(xy, float)[None] + max(r, ra, 20.0) * np.array([[-1.0, -1.0], [1.0, 1.0]])
               for name, xy, r, ra, framed in self.targets if framed] or [self.laser_xy[None]]
        pts += [self.observers_xy[self.hazardous]] if self.hazardous.any() else []
        pts += [self.footprint_xy] if self.footprint_xy is not None and len(self.footprint_xy) else []
        pts += [ring for lobe in self.lobes for ring in lobe[3]]
        x0, x1, y0, y1 = square_limits(pts)
        near = _near_points([np.asarray(r, float).reshape(-1, 2) for r in self.occluders] + [self.observers_xy[~self.hazardous]],
                            ((x0 + x1) / 2, (y0 + y1) / 2), SITE_CONTEXT * (x1 - x0) / 2)
        return square_limits(pts + near) if near else (x0, x1, y0, y1)

    def _draw_ground(self, ax):
        if self.contours is not None:
            x, y, h = self.contours
            if np.ptp(h) > 0:
                lo, hi = float(h.min()), float(h.max())
                cs = ax.contour(x, y, h, levels=np.linspace(lo + 0.1 * (hi - lo), hi - 0.05 * (hi - lo), 7), colors="#b0b0b0", linewidths=0.6)
                ax.clabel(cs, fontsize=6, fmt="%.0f m")
        if self.footprint_xy is not None and len(self.footprint_xy):
            from matplotlib.collections import PolyCollection

            from hazard.outputs.figure_index import mark

            s = self.footprint_cell_m
            label = f"hazardous ground at eye height, every spot summed ({s:g} m cells, drawn at their size)"
            cells = cell_squares(self.footprint_xy, s)
            ax.add_collection(PolyCollection(cells, facecolors=C.FOOTPRINT, edgecolors=C.FOOTPRINT, lw=0.3, alpha=0.6, label=label,
                                             zorder=2))
            ax.update_datalim(cells.reshape(-1, 2))
            mark(ax, self.paths.get("footprint", []), label, cells.reshape(-1, 2), "points")
        if self.boundary is not None:
            ring = np.vstack([self.boundary, self.boundary[:1]])
            ax.plot(*ring.T, c="k", lw=1.5, label="range boundary")

    def _draw_zones(self, ax):
        from hazard.outputs.figure_index import mark

        if self.zone is not None:
            ax.fill(*self.zone.T, fc="#e41a1c", alpha=0.25, ec="#e41a1c", lw=1.0, label=self.zone_label)
            mark(ax, [self.paths.get("zone")] if self.paths.get("zone") else [], self.zone_label, self.zone, "polygon")
        if self.nominal is not None:
            ax.plot(*self.nominal.T, c="#e41a1c", lw=0.8, ls=":", label="the sector without the buffer (the band between is the buffer zone)")
        for k, ((label, ring), ls) in enumerate(zip(self.aided_zones, ("--", ":", "-.") * 8)):
            ax.plot(*ring.T, c="#984ea3", lw=1.0, ls=ls, label=label)
            mark(ax, self.paths.get("aided", [])[k:k + 1], label, ring, "polygon")
        ax.plot(*self.aim_xy.T, c="#e41a1c", lw=0.8, ls="--", label="aim line")
        for xy, text in self.ends:
            right, above = xy[0] > self.laser_xy[0], xy[1] > self.laser_xy[1]  # the text toward the laser: inside the frame
            ax.plot(*xy, marker="o", ms=5, mfc="white", mec="k", ls="", zorder=9)
            ax.annotate(text.replace(" (", "\n(", 1), xy, xytext=(-6 if right else 6, -8 if above else 8), textcoords="offset points",
                        fontsize=6, zorder=9,
                        ha="right" if right else "left", va="top" if above else "bottom",
                        bbox=dict(boxstyle="round,pad=0.15", fc="white", ec="none", alpha=0.8))

    def _draw_thin_zone(self, ax):
        """Each danger zone (naked eye, through each optical aid) drawn narrower than
        ``MIN_ZONE_PT`` (a 37 km x 2 m zone is a line at range scale): also its outline
        widened across the aim to that width (a cone stays a cone, the along-aim lengths
        are true), with a label giving its true width and the factor. Call once the
        limits are final."""
        a, b = (np.asarray(p, float) for p in self.aim_xy)
        if not np.hypot(*(b - a)) > 0:
            return
        u = (b - a) / np.hypot(*(b - a))
        zones = [] if self.zone is None else [(self.zone, "danger zone", "#e41a1c", "////", self.paths.get("zone"))]
        aided = self.paths.get("aided", [])
        zones += [(ring, label.replace("LSDZ", "danger zone"), "#984ea3", "\\\\", aided[k] if k < len(aided) else None)
                  for k, (label, ring) in enumerate(self.aided_zones)]
        for ring, name, colour, hatch, path in zones:
            if ring is not None and len(ring) >= 3:
                _widen_thin(ax, ring, a, u, name, colour, hatch, path)
        for k, (target, eye, ring, start, along) in enumerate(self.mirror_zones):  # labels staggered along the beams
            _widen_thin(ax, ring, start, along, f"mirror-beam zone of {target} ({eye})", C.MIRROR, "xx",
                        self.paths.get("mirror", {}).get(target), (0.5, 0.25, 0.75, 0.15, 0.85)[k % 5])

    def _draw_lobes(self, ax):
        from hazard.outputs.figure_index import lobe_paths, mark

        seen = set()
        for target, kind, cut, rings, holes in self.lobes:
            draw_lobe(ax, kind, rings, None if (kind, cut) in seen else f"{kind} keep-out lobe, {cut}")
            seen.add((kind, cut))
            for ring in rings:
                mark(ax, lobe_paths(self.paths, self.lobes, target, kind), f"{kind} keep-out lobe, {cut}", ring, "polygon")
            for ring in holes:
                ax.plot(*ring.T, c=C.STATIC if kind == "static" else C.DYNAMIC, lw=0.8, ls=":")

    def _draw_objects(self, ax):
        ax.plot(*self.laser_xy, marker="^", ms=10, c="k", ls="", label="laser")
        for i, ring in enumerate(self.occluders):
            label = "occluders" if i == 0 else None
            if len(ring) > 2:
                ax.fill(*ring.T, fc="#999999", ec="#555555", lw=0.8, label=label)
            else:  # a wall edge-on, or a rod: drawn thick so it shows at any scale
                ax.plot(*ring.T, c="#555555", lw=3.0, marker="s" if len(ring) == 1 else None, ms=4, label=label)
        for i, (name, xy, nohd, aided, _) in enumerate(self.targets):
            ax.plot(*xy, marker="s", ms=6, mfc="white", mec=C.TARGET, ls="", label="targets" if i == 0 else None)
            if nohd > 0:
                ax.add_patch(matplotlib_circle(xy, nohd, C.DIFFUSE, ":", "target's longest diffuse NOHD, any direction" if i == 0 else None))
            if aided > nohd:
                ax.add_patch(matplotlib_circle(xy, aided, "#a65628", "-.", "target's diffuse NOHD through optics" if i == 0 else None))
            ax.annotate(name, xy, xytext=(4, 4 - 12 * (i % 2)), textcoords="offset points", fontsize=7)
        draw_mirrors(ax, self.paths, [z[:3] for z in self.mirror_zones], self.mirrors)
        if len(self.observers_xy):
            safe = ~self.hazardous
            ax.scatter(*self.observers_xy[safe].T, s=6, c=C.SAFE, lw=0, zorder=11,  # over the crosses: a safe one beside a hazardous one stays seen
                       label=f"observers below the MPE ({int(safe.sum())})")
            if self.aided.any():
                ax.scatter(*self.observers_xy[self.aided].T, s=40, marker="D", facecolors="none", edgecolors="k", lw=0.8,
                           label=f"observers with optics ({int(self.aided.sum())})")
            draw_hazardous(ax, self.observers_xy[self.hazardous], self.unlabelled, self._hazardous_paths())

    def _key_points(self) -> np.ndarray:
        """(K, 2) what a scale bar must not cover: the laser, the targets, the beams'
        ends and the observers."""
        pts = [self.laser_xy[None], self.observers_xy.reshape(-1, 2)]
        pts += [np.asarray(xy, float)[None] for _, xy, *_ in self.targets]
        pts += [np.array([a, b]) for _, a, b in self.mirrors] + [np.asarray(xy, float)[None] for xy, _ in self.ends]
        return np.vstack(pts)

    def _hazardous_paths(self) -> list:
        rows = self.paths.get("observers", {})
        return [rows.get(int(i)) for i in np.flatnonzero(self.hazardous)]


def two_lines(text: str) -> str:
    """A flight zone's label broken after its name (``"name (...): verdict"``), or as it is."""
    return text.replace("): ", "):\n", 1)


def _metres(d) -> str:
    return f"{d / 1000:.3g} km" if d >= 1000 else f"{d:.3g} m"


def beam_ends(result, aim_end_xy, off) -> list:
    """(xy, text) where the drawn danger zone's aim line, each aided danger zone and each
    mirror beam (naked eye and through each aid) end, world x, y, and why there: the NOHD
    (with the lit targets named when the beam passes them: a target is not a backstop), a
    backstop, or the 100 km drawn of an unbounded zone. The same reach and reason as the
    text (report.json ``sdz``), so picture and text agree."""
    z = getattr(result, "sdz", None)
    out: list = []
    if z is None:
        return out + _mirror_ends(result, off)
    laser = (np.asarray(result.scene.laser_position_m, float) + off)[:2]
    aim = np.asarray(result.scene.laser_direction, float)[:2]
    horizontal = float(np.hypot(*aim))
    if z.polygon_m:
        r = float(z.max_range_m or 0.0)
        why = _zone_why(result, z, r)
        run = float(np.hypot(*(np.asarray(aim_end_xy, float) - laser)))
        text = f"danger zone ends at {_metres(min(r, 1e5))} ({why})"
        if horizontal > 0 and run < 0.99 * min(r, 1e5) * horizontal:  # the aim's own direction stops sooner
            text = f"aim line ends at {_metres(run / horizontal)}; the zone reaches {_metres(min(r, 1e5))} ({why})"
        out.append((np.asarray(aim_end_xy, float), text))
    for a in z.aided:
        r = float(a.max_range_m or 0.0)
        if not (a.polygon_m and r > float(z.max_range_m or 0.0) * (1 + 1e-9) and horizontal > 0):
            continue  # an aided zone ending where the naked one does shares its end mark
        ring = np.asarray(a.polygon_m, float)
        end = clip_to_zone(np.array([laser, laser + aim * min(r, 1e5)]), ring)[1]
        eye = f"{a.aid.magnification:g}x{1e3 * a.aid.objective_diameter_m:g} optics"
        out.append((end, f"danger zone through {eye} ends at {_metres(min(r, 1e5))} ({_zone_why(result, a, r)})"))
    out += _mirror_ends(result, off)
    return out


def _passed_targets(result, reach_m) -> str:
    """``"; 'a', 'b' not a backstop (the beam can miss it)"`` for the lit targets a danger
    zone reaching ``reach_m`` [m] from the laser runs past (the text's reason,
    :mod:`hazard.pipeline.verdict`; a target beyond the zone's end is not named), or ""."""
    near = {sp.target.name: float(np.min(sp.range_from_laser_m)) for sp in result.spots if len(sp.range_from_laser_m)}
    lit = [t.name for t in result.targets if t.spot_power_w > 0 and near.get(t.name, math.inf) < reach_m]
    if not lit:
        return ""
    names = ", ".join(repr(n) for n in lit[:3]) + (", ..." if len(lit) > 3 else "")
    return f"; {names} not a backstop: the beam can miss {'it' if len(lit) == 1 else 'them'}"


def _zone_why(result, zone, reach_m) -> str:
    """Why a danger zone ``zone`` (:class:`hazard.pipeline.sdz.GroundZone`: report.json ``sdz`` or one of its ``aided``) ends at ``reach_m``."""
    passes = _passed_targets(result, reach_m)
    if zone.contained:
        return "every direction stopped by a backstop"
    if not math.isfinite(reach_m) or reach_m > 1e5:
        return "unbounded: drawn to 100 km" + passes
    return "its NOHD" + passes


def _mirror_ends(result, off) -> list:
    """(xy, text) where each mirror beam's line ends and, for each aid whose zone is drawn
    farther, where that zone ends, world x, y, with why (report.json ``sdz.mirror_beams``)."""
    from hazard.physics.mirror_zone import eye_rows

    out = []
    rows = {t.name: t for t in result.targets}
    for name, a, b, eye in mirror_lines(result):
        length = float(np.linalg.norm(b - a))
        u = (b - a) / length if length > 0 else np.zeros(3)
        for e, _, _, nohd, stop in eye_rows(result, rows[name]):
            drawn = _drawn_length_m(float(nohd), stop) if nohd else 0.0
            if e != eye and not drawn > length * (1 + 1e-9):
                continue  # an aid's beam ending where the drawn line does shares its end mark
            full = min(float(nohd), 1e5)
            why = "stopped by a backstop" if drawn < full * (1 - 1e-9) else "its specular NOHD"
            whom = "" if eye == "naked eye" or e != eye else f", hazardous only through {eye}"
            through = "" if e == eye else f" through {e}"
            out.append(((a + u * drawn + off)[:2], f"mirror beam of {name}{through} ends at {_metres(drawn)} ({why}{whom})"))
    return out


def _widen_thin(ax, zone, a, u, name, colour, hatch, path, along=0.5) -> None:
    """``zone`` (K, 2) [m] about the aim from ``a`` along ``u``, if drawn narrower than
    ``MIN_ZONE_PT`` in ``ax``: also outlined widened across the aim to that width, hatched,
    labelled ``name`` with its true width and the factor, noted for figures.json under
    ``path``."""
    from hazard.outputs.figure_index import mark

    n = np.array([-u[1], u[0]])
    width_m = float(np.ptp((zone - a) @ n))
    ends = ax.transData.transform(np.array([a, a + n * max(width_m, 1e-9)]))
    width_pt = float(np.hypot(*(ends[1] - ends[0]))) * 72.0 / ax.figure.dpi
    if width_pt >= MIN_ZONE_PT:
        return
    factor = MIN_ZONE_PT / max(width_pt, 1e-9)
    ring = widen_across(zone, a, u, factor)
    x0, x1, y0, y1 = (*ax.get_xlim(), *ax.get_ylim())
    ax.fill(*ring.T, fc="none", ec=colour, lw=0.9, hatch=hatch, zorder=3)
    label = f"{name} {_metres(width_m)} wide,\ndrawn exaggerated (x{factor:.3g} across the aim)"
    at = _visible_middle(a, u, float(np.max((zone - a) @ u)), (x0, x1, y0, y1), along)
    side = 1.0 if (at @ n) <= ((np.array([x0 + x1, y0 + y1]) / 2) @ n) else -1.0  # the text toward the frame's middle
    ax.annotate(label, at, xytext=tuple(8 * side * n), textcoords="offset points", fontsize=6, color=colour, zorder=9,
                ha="left" if side * n[0] >= 0 else "right", va="center",
                bbox=dict(boxstyle="round,pad=0.15", fc="white", ec=colour, lw=0.5, alpha=0.9))
    ax.set_xlim(x0, x1)
    ax.set_ylim(y0, y1)
    mark(ax, [path] if path else [], label, ring, "polygon")


def _visible_middle(a, u, length_m, limits, along=0.5) -> np.ndarray:
    """The middle of the part of the aim (from ``a`` along ``u``, ``length_m`` long) in
    the frame ``limits`` (x0, x1, y0, y1) - where a label of the zone is seen -, or 55 %
    along it when no part is in the frame."""
    from shapely.geometry import LineString, box

    x0, x1, y0, y1 = limits
    seen = LineString([a, a + u * length_m]).intersection(box(min(x0, x1), min(y0, y1), max(x0, x1), max(y0, y1)))
    if seen.is_empty or seen.length <= 0:
        return a + u * 0.55 * length_m
    return np.asarray(seen.interpolate(along, normalized=True).coords[0], float)


def widen_across(ring, origin, direction, factor) -> np.ndarray:
    """``ring`` (K, 2) [m] with every point's offset across the line through ``origin``
    along the unit ``direction`` multiplied by ``factor`` (its offset along it kept)."""
    u = np.asarray(direction, float)
    n = np.array([-u[1], u[0]])
    d = np.asarray(ring, float) - origin
    return origin + np.outer(d @ u, u) + np.outer(factor * (d @ n), n)


def clip_to_zone(aim, ring) -> np.ndarray:
    """The aim line (2, 2) cut where it leaves the danger zone's outline ``ring`` (K, 2)
    (a zone reaching farther in other directions than along the aim), or as it is
    without an outline."""
    if ring is None or len(ring) < 3:
        return aim
    from shapely.geometry import LineString, Point, Polygon

    poly = Polygon(ring)
    poly = poly if poly.is_valid else poly.buffer(0)
    inside = LineString(aim).intersection(poly)
    parts = [g for g in getattr(inside, "geoms", [inside]) if g.geom_type == "LineString" and not g.is_empty]
    if not parts:
        return aim
    start = Point(aim[0])
    first = min(parts, key=lambda g: g.distance(start))  # the run from the laser
    pts = np.asarray(first.coords, float)
    end = pts[np.argmax(np.hypot(*(pts - aim[0]).T))]
    return np.array([aim[0], end])


def aim_reach_m(result) -> float:
    """How far the aim line is drawn [m]: the danger zone's range, at most 100 km (an
    unbounded zone is drawn to 100 km, never to 0); 0 without a zone."""
    r = 0.0 if result.sdz is None else float(result.sdz.max_range_m or 0.0)
    return min(r, 1e5) if math.isfinite(r) else 1e5


def square_limits(points) -> tuple:
    """x0, x1, y0, y1 [m]: a square about the points (a list of (K, 2) arrays), 10 % wider,
    at least 20 m across."""
    p = np.vstack(points)
    lo, hi = p.min(axis=0), p.max(axis=0)
    c, half = (lo + hi) / 2, max(float((hi - lo).max()) * 0.55, 10.0)
    return c[0] - half, c[0] + half, c[1] - half, c[1] + half


def legend_below(fig, ax, fontsize=7):
    """The legend of ``ax``'s labelled artists below the figure's panels, in two columns
    (beside them it took 40 % of the width a printed page gives the picture)."""
    handles, labels = ax.get_legend_handles_labels()
    if handles:
        fig.legend(handles, labels, loc="upper center", bbox_to_anchor=(0.5, 0.0), ncol=2, fontsize=fontsize, framealpha=0.9)


def two_panels(axes, figsize) -> tuple:
    """(figure, axes): the two panels given, or new ones (on their own Agg canvas: no backend switched)."""
    if axes is None:
        from hazard.canvas import subplots

        _, axes = subplots(1, 2, figsize=figsize)
    return axes[0].figure, axes


def draw_lobe(ax, kind, rings, label):
    """A lobe's outline rings: static filled blue (face 25 % opaque, the edge the legend's
    colour), dynamic dashed orange."""
    colour = C.STATIC if kind == "static" else C.DYNAMIC
    for ring in rings:
        if kind == "static":
            ax.fill(*ring.T, fc=colour + "40", ec=colour, lw=1.2, label=label)
        else:
            ax.plot(*ring.T, c=colour, lw=1.6, ls="--", label=label)
        label = None


def draw_hazardous(ax, xy, unlabelled, paths=None):
    """Observers at or above the MPE: large red crosses on top, counted in the legend;
    noted for figures.json under ``paths`` (report.json paths, one per point, None:
    not listed)."""
    from hazard.outputs.figure_index import mark

    more = f"; {unlabelled} more unnamed, see observers.csv" if unlabelled else ""
    label = f"observers at or above the MPE ({len(xy)}{more})"
    xy = np.asarray(xy, float).reshape(-1, 2)
    ax.scatter(*xy.T, s=70, c=C.HAZARDOUS, marker="X", edgecolors="k", lw=0.6, zorder=10, label=label)
    keep = [k for k, p in enumerate(paths or []) if p]
    mark(ax, [paths[k] for k in keep], label, xy[keep], "points")


def draw_mirrors(ax, paths, zones, lines) -> None:
    """Mirror beams' hazard zones (``zones``: (target, eye, (K, 2) ring)) filled, solid for
    the naked eye and dashed through optics, and their lines (``lines``: (target, start,
    end)), each recorded for figures.json; the plan and elevation views draw them alike."""
    for i, (name, eye, ring) in enumerate(zones):
        ax.fill(*ring.T, fc=C.MIRROR, alpha=0.3 if eye == "naked eye" else 0.12, ec=C.MIRROR, lw=0.8,
                ls="-" if eye == "naked eye" else "--", label=MIRROR_ZONE_LABEL if i == 0 else None)
        mark_mirror_zone(ax, paths, name, ring)
    for i, (name, a, b) in enumerate(lines):
        ax.plot([a[0], b[0]], [a[1], b[1]], c=C.MIRROR, lw=1.6, label=MIRROR_LABEL if i == 0 else None)
        mark_mirror(ax, paths, name, a, b)


def mark_mirror(ax, paths, name, a, b):
    """Note a mirror beam drawn from ``a`` to ``b`` (figures.json)."""
    from hazard.outputs.figure_index import mark

    path = paths.get("mirror", {}).get(name)
    mark(ax, [path] if path else [], MIRROR_LABEL, np.array([a, b]), "line")


def mark_mirror_zone(ax, paths, name, ring):
    """Note a mirror beam's hazard zone drawn as ``ring`` (figures.json)."""
    from hazard.outputs.figure_index import mark

    path = paths.get("mirror", {}).get(name)
    mark(ax, [path] if path else [], MIRROR_ZONE_LABEL, np.asarray(ring, float), "polygon")


def hazardous_labels(result, xy) -> tuple:
    """The ``LABELLED`` worst hazardous observers as (xy, "name (ratio)") at ``xy`` (their
    2-D positions in the picture), and how many hazardous ones are left unnamed."""
    ratio = np.asarray(result.hazard_ratio, float)
    idx = np.flatnonzero(np.asarray(result.hazardous, bool))
    idx = idx[np.argsort(-ratio[idx], kind="stable")]
    labels = [(xy[i], f"{result.observers.labels[i]} ({ratio[i]:.3g} x MPE)") for i in idx[:LABELLED]]
    return labels, max(0, len(idx) - LABELLED)


def label_points(ax, labels):
    """Name points with boxed labels in two columns at the panel's sides (points left of
    the middle on the left), each in its points' top-to-bottom order with a leader line,
    so that clustered points do not hide each other's names."""
    if not labels:
        return
    x0, x1 = ax.get_xlim()
    y0, y1 = ax.get_ylim()
    mid = (x0 + x1) / 2
    for side, xa, ha in ((True, 0.02, "left"), (False, 0.98, "right")):
        group = sorted([lb for lb in labels if (lb[0][0] < mid) == side], key=lambda lb: -lb[0][1])
        for k, (xy, text) in enumerate(group):
            ax.annotate(text, xy, xytext=(xa, 0.78 - 0.06 * k), textcoords="axes fraction", fontsize=6, ha=ha,
                        va="center", zorder=12, annotation_clip=False,
                        bbox=dict(boxstyle="round,pad=0.2", fc="white", ec=C.HAZARDOUS, lw=0.6, alpha=0.9),
                        arrowprops=dict(arrowstyle="-", color=C.HAZARDOUS, lw=0.5, alpha=0.8))
    ax.set_xlim(x0, x1)
    ax.set_ylim(y0, y1)


def keep_texts_inside(ax, pad_px=2.0):
    """Shift every text placed at a data point of ``ax`` (labels of targets, ends, rings,
    FAA distances, flight zones) that runs out of the panel back inside it by the pixels
    it overhangs (call once the limits are final): a label is never cut by its panel's
    edge or drawn over the next panel. A leader line keeps an annotation tied to its
    point."""
    from matplotlib.text import Annotation

    r = ax.figure.canvas.get_renderer()
    frame = ax.get_window_extent(r)
    for t in ax.texts:
        note = isinstance(t, Annotation)
        data = t.xycoords == "data" if note else t.get_transform() == ax.transData
        if not data or not t.get_visible() or not t.get_text().strip() or (note and not t._check_xy(r)):
            continue
        box = t.get_window_extent(r)
        shift = np.array([_overhang(box.x0, box.x1, frame.x0 + pad_px, frame.x1 - pad_px),
                          _overhang(box.y0, box.y1, frame.y0 + pad_px, frame.y1 - pad_px)])
        if not shift.any():
            continue
        if note and t.anncoords == "offset points":
            t.xyann = tuple(np.asarray(t.xyann, float) + shift * 72.0 / ax.figure.dpi)
        elif note and t.anncoords == "data":
            t.xyann = tuple(ax.transData.inverted().transform(ax.transData.transform(t.xyann) + shift))
        elif not note:
            t.set_position(tuple(ax.transData.inverted().transform(ax.transData.transform(t.get_position()) + shift)))


def _overhang(lo, hi, frame_lo, frame_hi) -> float:
    """The shift [px] that brings [lo, hi] inside [frame_lo, frame_hi] (0: inside; a box
    wider than the frame is aligned on its low side)."""
    if lo < frame_lo:
        return frame_lo - lo
    return min(0.0, frame_hi - hi) if hi - lo <= frame_hi - frame_lo else frame_lo - lo


def _near_points(groups, centre, radius_m) -> list:
    """The points of ``groups`` ((K, 2) arrays) within ``radius_m`` of ``centre`` (a
    square about it), as a list of arrays (empty ones left out)."""
    out = []
    for g in groups:
        g = np.asarray(g, float).reshape(-1, 2)
        near = g[np.all(np.abs(g - np.asarray(centre, float)) <= radius_m, axis=1)]
        if len(near):
            out.append(near)
    return out


def _distinct(points, tol_m) -> list:
    """Points more than ``tol_m`` apart (the first of each cluster)."""
    out = []
    for p in points:
        if all(np.hypot(*(np.asarray(p) - q)) > tol_m for q in out):
            out.append(np.asarray(p, float))
    return out


def _range_rings(ax, centres, what):
    """Labelled circles about each centre at a round spacing (1, 2 or 5 x 10^k m), about a
    quarter of the panel; the first ring's label says what they are centred on (``what``,
    e.g. "from the laser")."""
    x0, x1 = ax.get_xlim()
    y0, y1 = ax.get_ylim()
    step = nice_length_m(max(x1 - x0, y1 - y0) * 1.25)  # about a quarter of the panel
    for n, c in enumerate(_distinct(centres, step / 2)):  # targets closer than half a step share their rings
        corners = np.array([[x0, y0], [x0, y1], [x1, y0], [x1, y1]]) - c
        far = float(np.hypot(corners[:, 0], corners[:, 1]).max())
        for k in range(1, int(far // step) + 1):
            r = k * step
            ax.add_patch(matplotlib_circle(c, r, C.RINGS, "-", f"range rings {what}" if n == 0 and k == 1 else None, lw=0.5))
            for a in (np.pi / 4, -3 * np.pi / 4):
                p = c + r * np.array([np.cos(a), np.sin(a)])
                if x0 < p[0] < x1 and y0 < p[1] < y1:
                    text = f"{r / 1000:g} km" if r >= 1000 else f"{r:g} m"
                    text += f" {what}" if k == 1 else ""  # the first ring says what the rings are centred on
                    ax.text(*p, text, fontsize=6, color="#555555", ha="center",
                            va="center", bbox=dict(boxstyle="round,pad=0.1", fc="white", ec="none", alpha=0.7), zorder=3)
                    break
    ax.set_xlim(x0, x1)
    ax.set_ylim(y0, y1)


def matplotlib_circle(xy, r, colour, style, label=None, lw=0.8):
    from matplotlib.patches import Circle

    return Circle(xy, r, fill=False, ec=colour, lw=lw, ls=style, label=label)


def _zone_label(z) -> str:
    if z is None:
        return "LSDZ"
    d = z.directions
    what = {"aim": "aim only", "cone": f"pointing cone {d.buffer_rad:.2g} rad", "sector": "sector + buffer"}[d.kind]
    what += " + aim track" if d.aim_track else ""
    state = "contained" if z.contained else "NOT contained"
    return f"laser surface danger zone ({what}; {state})"


def _targets(result, off) -> list:
    out = []
    for t in result.targets:
        src = next((sp for sp in result.spots if sp.target.name == t.name), None)
        xy = (src.centroid if src is not None else next((x.center_m for x in result.scene.targets if x.name == t.name),
                                                       np.zeros(3))) + off
        nohd = t.to_dict().get("nohd_dynamic_m") or 0.0
        aided = max([a.get("nohd_dynamic_m") or 0.0 for a in t.aided] + [0.0])
        framed = t.name != "terrain" and t.spot_power_w >= 1e-6 * result.beam_power_w  # lit by more than the beam's far tail
        out.append((t.name, np.asarray(xy, float)[:2], _finite_or_0(nohd), _finite_or_0(aided), framed))
    return out


def _occluders(scene, off) -> list:
    """Plan outlines (convex hulls of the vertices) of the occluders, world x, y: a closed
    ring, or the two ends of a wall seen edge-on (a vertical plate)."""
    return [hull_outline(np.asarray(m.vertices, float)[:, :2] + off[:2]) for m in scene.occluders]


def hull_outline(points_2d) -> np.ndarray:
    """The convex hull of 2-D points [m] as drawn: a closed ring (K, 2), the two ends of a
    segment (a wall seen edge-on) or one point (a rod seen end-on)."""
    from shapely.geometry import MultiPoint

    hull = MultiPoint(np.asarray(points_2d, float).tolist()).convex_hull
    if hull.geom_type == "Polygon":
        return np.asarray(hull.exterior.coords)
    return np.asarray(hull.coords)[:2]


def _finite_or_0(x) -> float:
    return float(x) if math.isfinite(x) else 0.0


def _mirror_zone_rings(result, off) -> list:
    """(target, eye, ring, start, unit plan direction) of every mirror beam's zone, world
    x, y (:func:`hazard.physics.mirror_zone.mirror_zones`), widest eye first."""
    out = []
    for m in sorted(mirror_zones(result), key=lambda m: -m.max_half_width_m * m.reach_m):
        ring = m.ring + off[:2]
        start = ring[0] / 2 + ring[-1] / 2  # the zone's first section's middle: on the axis at the mirror
        mid = len(ring) // 2
        tip = ring[mid - 1] / 2 + ring[mid] / 2
        d = tip - start
        if np.hypot(*d) > 0:
            out.append((m.target, m.eye, ring, start, d / np.hypot(*d)))
    return out


def _mirrors(result, off) -> list:
    return [(name, (a + off)[:2], (b + off)[:2]) for name, a, b in mirror_segments(result)]


def cell_squares(xy, cell_m) -> np.ndarray:
    """(N, 4, 2) the corners of the ``cell_m`` squares centred on the nodes ``xy`` [m]."""
    h = 0.5 * float(cell_m)
    corners = np.array([[-h, -h], [h, -h], [h, h], [-h, h]])
    return np.asarray(xy, float)[:, None, :] + corners[None]


def _footprint(result, off):
    """The hazardous ground nodes (world x, y) of the static or the dynamic footprint, and
    the terrain's cell size [m]."""
    masks = [f.mask for f in (result.footprint_dynamic, result.footprint_static) if f is not None]
    terrain = result.scene.terrain
    if not masks or terrain is None or not any(m.any() for m in masks):
        return None, 0.0
    iy, ix = np.nonzero(np.logical_or.reduce(masks))
    xy = np.stack([terrain.x0 + terrain.dx * ix, terrain.y0 + terrain.dx * iy], axis=1) + off[:2]
    return xy, float(terrain.dx)


def _contours(scene, off):
    t = scene.terrain
    if t is None:
        return None
    ny, nx = t.heights.shape
    k = max(1, max(ny, nx) // 400)  # at most ~400 x 400 nodes drawn
    x = t.x0 + t.dx * np.arange(0, nx, k) + off[0]
    y = t.y0 + t.dx * np.arange(0, ny, k) + off[1]
    return x, y, t.heights[::k, ::k] + off[2]


def nice_length_m(span) -> float:
    """A 1, 2 or 5 x 10^k length near a fifth of ``span``."""
    raw = span / 5
    e = 10 ** math.floor(math.log10(raw))
    return max(m * e for m in (1, 2, 5) if m * e <= raw) if raw >= e else e


def quiet_corner(ax, points, frac=(0.3, 0.15)) -> str:
    """The lower or upper right, or the lower left corner of ``ax`` (the north arrow has
    the upper left) holding the fewest of ``points`` (data x, y) in a box ``frac`` of
    the panel: where a scale bar covers nothing (ties: lower left)."""
    x0, x1 = ax.get_xlim()
    y0, y1 = ax.get_ylim()
    u = (np.asarray(points, float).reshape(-1, 2) - [x0, y0]) / [x1 - x0, y1 - y0]  # axes fraction
    boxes = {"lower left": ((0, frac[0]), (0, frac[1])), "lower right": ((1 - frac[0], 1), (0, frac[1])),
             "upper right": ((1 - frac[0], 1), (1 - frac[1], 1))}
    counts = {k: int(np.sum((u[:, 0] >= a) & (u[:, 0] <= b) & (u[:, 1] >= c) & (u[:, 1] <= d)))
              for k, ((a, b), (c, d)) in boxes.items()}
    return min(boxes, key=lambda k: counts[k])  # dicts keep order: lower left wins a tie


def draw_scale_bar(ax, loc="lower left"):
    """A scale bar of a round length [m] (about a fifth of the x span) on ``ax``."""
    from mpl_toolkits.axes_grid1.anchored_artists import AnchoredSizeBar

    x0, x1 = ax.get_xlim()
    length = nice_length_m(x1 - x0)
    label = f"{length / 1000:g} km" if length >= 1000 else f"{length:g} m"
    ax.add_artist(AnchoredSizeBar(ax.transData, length, label, loc, pad=0.5, frameon=True, size_vertical=0))


def _north_arrow(ax):
    ax.annotate("N", xy=(0.06, 0.95), xytext=(0.06, 0.83), xycoords="axes fraction", ha="center", va="center",
                fontsize=11, fontweight="bold", arrowprops=dict(arrowstyle="-|>", color="k", lw=1.5))
