"""The zones of a run as plan-view geometry in world x (east), y (north) [m], for maps.

Each :class:`Zone` is a shapely geometry with the properties a map shows (kind, target,
NOHD, standard, exposure). :mod:`hazard.outputs.map_outputs` writes them as GeoJSON, KML and a
GeoTIFF. Every kind the run has is exported; :data:`ZONE_KINDS` lists them all, and a kind
a run does not have is named in the file's ``absent`` list with the reason, never left out
silently:

- ``footprint``: the hazardous ground at eye height (static and dynamic), the union of
  the terrain cells whose node reaches the MPE (cell = node +- dx/2: its area equals the
  area the report gives);
- ``sdz``: the laser surface danger zone of the direct beam over the aim or sector with
  the pointing buffer; ``sdz_nominal`` without the buffer; ``sdz_aided`` through each
  optical aid;
- ``keepout_lobe``: the plan outline of each target's keep-out lobe (static, dynamic) at
  eye height over terrain, else its plan projection (:mod:`hazard.outputs.lobe_outline`);
- ``mirror_beam``: each target's mirror beam out to its specular NOHD;
  ``mirror_beam_zone``: its hazard zone with its width (naked eye and each aid with a
  longer specular NOHD), cut where the analysis stops the beam (:mod:`hazard.physics.mirror_zone`);
- ``observer``: every observer point with its verdict and hazard ratio;
- ``range_boundary``, ``laser``, ``target``: the range and what stands on it;
- ``track``: each moving observer's path (a 3-D line: each vertex at its own height)
  with its verdict; ``airspace_zone``: each ``[airspace]`` flight zone's outline with its
  floor, ceiling, limit and whether it holds; ``visual_zone``: the plan outline of the
  direct beam's SZED, CZED and LFED volumes (visible lasers; over a slewing beam's
  track), :mod:`hazard.pipeline.airspace_geometry`.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

__all__ = ["Zone", "ZONE_KINDS", "ObserverPoints", "zones", "observer_points", "observer_zones", "common_properties"]

ZONE_KINDS = ("footprint", "sdz", "sdz_nominal", "sdz_aided", "keepout_lobe", "mirror_beam", "mirror_beam_zone", "observer",
              "range_boundary", "laser", "target", "track", "airspace_zone", "visual_zone")


@dataclass
class Zone:
    """One map feature: a shapely geometry in world x, y [m], the heights [m] of its
    vertices' ground (for the geodetic conversion) and its properties."""

    kind: str
    geometry: object
    properties: dict = field(default_factory=dict)
    z_m: float | np.ndarray | None = None  # world height of a point, or of each vertex (None: the terrain / eye height below each)


def common_properties(result) -> dict:
    """The properties every zone of ``result`` ends with (standard, exposure, MPE, wavelength, scene)."""
    return _common(result)


def _common(result) -> dict:
    m = result.mpe
    return {"standard": m.standard, "exposure_duration_s": float(m.duration_s), "mpe_w_m2": float(result.mpe_w_m2),
            "wavelength_nm": float(m.wavelength_nm), "scene": result.scene.name}


def _cells_polygon(mask, x0, y0, dx):
    """Union of the squares (node +- dx/2) of the True nodes of ``mask`` (ny, nx), world [m]."""
    import shapely

    iy, ix = np.nonzero(mask)
    if not len(ix):
        return None
    x, y = x0 + dx * ix, y0 + dx * iy
    boxes = shapely.box(x - dx / 2, y - dx / 2, x + dx / 2, y + dx / 2)
    return shapely.coverage_union_all(boxes)


def _footprints(result, off) -> list:
    out = []
    t = result.scene.terrain
    for variant, f in (("static", result.footprint_static), ("dynamic", result.footprint_dynamic)):
        if f is None:
            continue
        g = _cells_polygon(f.mask, t.x0 + off[0], t.y0 + off[1], t.dx)
        if g is not None:
            out.append(Zone("footprint", g, {"variant": variant, "eye_height_m": f.eye_height_m, "area_m2": f.area_m2,
                                             "cell_m": t.dx, "hazard": "naked eye",
                                             "what": f"hazardous ground from the reflections at {f.eye_height_m:g} m eye height"}))
    return out


def _sdz(result) -> list:
    from shapely.geometry import Polygon

    z = getattr(result, "sdz", None)  # hazard.pipeline.sdz.DangerZone
    out: list = []
    if z is None:
        return out
    if z.polygon_m:
        out.append(Zone("sdz", Polygon(z.polygon_m), {
            "nohd_m": z.nohd_m, "max_range_m": z.max_range_m, "area_m2": z.area_m2,
            "unbounded": z.unbounded, "buffer_rad": z.directions.buffer_rad,
            "hazard": "naked eye", "what": "laser surface danger zone of the direct beam (with the pointing buffer)"}))
    if z.nominal is not None and z.nominal.polygon_m:
        out.append(Zone("sdz_nominal", Polygon(z.nominal.polygon_m), {
            "hazard": "naked eye", "what": "the danger zone without the pointing buffer"}))
    for a in z.aided:
        if a.polygon_m:
            out.append(Zone("sdz_aided", Polygon(a.polygon_m), {
                "magnification": a.aid.magnification, "objective_diameter_m": a.aid.objective_diameter_m,
                "nohd_m": a.nohd_m, "hazard": "aided only", "what": "danger zone through optics"}))
    return out


def _lobes(result, off) -> list:
    from hazard.outputs.finding_geometry import lobe_rings
    from shapely.geometry import Polygon

    rows = {t.name: t for t in result.targets}
    out = []
    for target, kind, cut, rings, holes in lobe_rings(result, off[:2]):
        lobe = None if rows.get(target) is None else getattr(rows[target], f"{kind}_lobe", None)
        nohd = None if lobe is None else float(lobe.max_range_m)
        for ring in rings:
            inner = [h for h in holes if Polygon(ring).contains(Polygon(h))]
            out.append(Zone("keepout_lobe", Polygon(ring, inner), {"target": target, "variant": kind, "cut": cut,
                                                                  "nohd_m": nohd, "hazard": "naked eye"}))
    return out


def _mirrors(result, off) -> list:
    from shapely.geometry import LineString

    from hazard.physics.mirror_zone import eye_rows
    from hazard.outputs.finding_geometry import mirror_lines

    rows = {t.name: t for t in result.targets}
    out = []
    for target, start, end, eye in mirror_lines(result):
        nohd, stop = next(((n, st) for e, _, _, n, st in eye_rows(result, rows[target]) if e == eye), (None, None))
        a, b = np.asarray(start) + off, np.asarray(end) + off
        # how far the hazard goes from the mirror: the NOHD, or sooner where every ray is stopped
        reach = nohd if stop is None or nohd is None or not (0.0 <= stop < nohd) else float(stop)
        out.append(Zone("mirror_beam", LineString([a[:2], b[:2]]), {"target": target, "nohd_m": nohd, "reach_m": reach, "hazard": eye,
                                                                     "start_height_m": float(a[2]), "end_height_m": float(b[2])}))
    return out


def _mirror_zones(result, off) -> list:
    from shapely.geometry import Polygon

    from hazard.physics.mirror_zone import mirror_zones

    out = []
    for m in mirror_zones(result):
        poly = Polygon(m.ring + off[:2])
        out.append(Zone("mirror_beam_zone", poly if poly.is_valid else poly.buffer(0), {
            "target": m.target, "nohd_m": m.nohd_m, "reach_m": m.reach_m, "max_half_width_m": m.max_half_width_m,
            "aperture_radius_m": m.aperture_radius_m, "exact_axis": m.exact_axis, "ranges_not_found": m.ranges_not_found,
            "hazard": m.eye, "eye": m.eye}))
    return out


MAP_OBSERVERS_MAX = 20_000  # observer points on a map: every hazardous one, then the highest ratios (all in observers.csv)


def observers_on_map(result, ratio: np.ndarray | None = None, haz: np.ndarray | None = None) -> tuple[np.ndarray, str]:
    """Which observers a map shows: all up to :data:`MAP_OBSERVERS_MAX`, else every
    hazardous one and then the highest hazard ratios; and a statement of which.
    ``ratio``, ``haz``: ``result.hazard_ratio`` and ``result.hazardous`` when the caller
    has them (each a whole-column computation); neither is changed."""
    ratio = result.hazard_ratio if ratio is None else ratio
    m = len(ratio)
    if m <= MAP_OBSERVERS_MAX:
        return np.arange(m), "all"
    from hazard.outputs._select import top_rows

    ratio = np.nan_to_num(np.array(ratio, float), copy=False, nan=np.inf)  # our copy, changed in place
    haz = np.asarray(result.hazardous if haz is None else haz, bool)
    n_haz = int(haz.sum())
    ratio[haz] = -np.inf  # the others by ratio (a ratio is >= 0: no other row is -inf)
    order = np.unique(np.concatenate([np.flatnonzero(haz), top_rows(ratio, MAP_OBSERVERS_MAX - n_haz)]))
    return order, f"{len(order)} of {m}: every hazardous one, then the highest hazard ratios (all in observers.csv)"


@dataclass(frozen=True)
class ObserverPoints:
    """The observer points a map shows (:func:`observers_on_map`), column by column: what
    :func:`zones` makes one ``observer`` :class:`Zone` of each row from (its properties:
    ``name``, ``verdict``, ``hazard_ratio``, ``radiant_exposure_j_m2``, ``hazard``, ``z_m``).

    Attributes
    ----------
    rows : numpy.ndarray
        (n,) the observers' rows in the result.
    position_m : numpy.ndarray
        (n, 3) world positions [m].
    hazard_ratio, radiant_exposure_j_m2 : numpy.ndarray
        (n,) peak irradiance / MPE [-] and radiant exposure [J/m^2].
    hazardous, aided : numpy.ndarray
        (n,) bool: above the MPE; its group looks through an optical aid.
    names : list of str
        (n,) the observers' names.
    which : str
        Which observers a map shows (:func:`observers_on_map`).
    """

    rows: np.ndarray
    position_m: np.ndarray
    hazard_ratio: np.ndarray
    radiant_exposure_j_m2: np.ndarray
    hazardous: np.ndarray
    aided: np.ndarray
    names: list
    which: str = "all"  # which observers are shown (observers_on_map's statement)

    kind = "observer"

    def __len__(self) -> int:
        return len(self.rows)


def observer_points(result) -> ObserverPoints:
    """The observer points a map of ``result`` shows, as columns (:class:`ObserverPoints`)."""
    obs = result.observers
    ratio = np.asarray(result.hazard_ratio, float)
    haz = np.asarray(result.hazardous, bool)
    rows, which = observers_on_map(result, ratio, haz)
    p = np.asarray(obs.position_at(rows), float).reshape(-1, 3)  # world, the rows shown only
    groups = obs.observers
    with_aid = np.array([o is not None for o in groups.optics], bool)
    aided = with_aid[groups.group[rows]] if len(p) and len(with_aid) else np.zeros(len(p), bool)
    return ObserverPoints(rows, p, ratio[rows], np.asarray(obs.radiant_exposure_j_m2, float)[rows],
                          haz[rows], aided, obs.labels.take(rows), which)  # the listed rows' names only


def _observers(result) -> list:
    return observer_zones(observer_points(result))


def observer_zones(op: ObserverPoints, common: dict | None = None) -> list:
    """One ``observer`` :class:`Zone` for each row of ``op``; with ``common``
    (:func:`common_properties`), its properties complete as :func:`zones` gives them
    (``kind`` first, ``common`` last)."""
    import shapely

    p = op.position_m
    ratio, haz, aided, h_exp = op.hazard_ratio.tolist(), op.hazardous.tolist(), op.aided.tolist(), op.radiant_exposure_j_m2.tolist()
    labels = op.names
    points = shapely.points(p[:, :2])  # made at once
    out = []
    for j, z in enumerate(p[:, 2].tolist()):
        verdict = ("hazardous, aided" if aided[j] else "hazardous") if haz[j] else "below the MPE"
        props = {"name": labels[j], "verdict": verdict, "hazard_ratio": ratio[j], "radiant_exposure_j_m2": h_exp[j],
                 "hazard": ("aided only" if aided[j] else "naked eye") if haz[j] else "none", "z_m": z}
        out.append(Zone("observer", points[j], props if common is None else {"kind": "observer", **props, **common}, z_m=z))
    return out


def _things(result, off) -> list:
    from shapely.geometry import Point, Polygon

    scene = result.scene
    lp = np.asarray(scene.laser_position_m, float) + off
    out = [Zone("laser", Point(lp[:2]), {"name": "laser", "power_w": float(scene.spec.laser.average_power_w)}, z_m=float(lp[2]))]
    for t in scene.spec.targets:
        c = np.asarray(t.center_m, float)
        out.append(Zone("target", Point(c[:2]), {"name": t.name}, z_m=float(c[2])))
    if scene.spec.range is not None:
        out.append(Zone("range_boundary", Polygon(scene.spec.range.boundary_m), {"what": "the range boundary"}))
    return out


def _airspace(result) -> list:
    """Tracks, flight zones and the direct beam's visual-interference outlines."""
    from shapely.geometry import LineString, Point, Polygon

    from hazard.pipeline.airspace_geometry import track_polyline, visual_outline_xy

    out = []
    for p in ([] if result.motion is None else result.motion.tracks()):
        xyz = track_polyline(result, p)
        s = p.summary  # hazard.pipeline.motion_results.PathSummary
        geom = LineString(xyz[:, :2]) if len(xyz) > 1 else Point(xyz[0, :2])
        out.append(Zone("track", geom, {"name": p.name, "verdict": "hazardous" if s.hazardous else "below the MPE",
                                        "hazard": "naked eye" if s.hazardous else "none", "exposure_ratio": s.exposure_ratio,
                                        "peak_time_s": s.peak_time_s, "first_exceedance_s": s.first_exceedance_s},
                        z_m=xyz[:, 2] if len(xyz) > 1 else float(xyz[0, 2])))
    zone_rows = {z.name: z.to_dict() for z in (() if result.airspace is None else result.airspace.zones)}
    for zs in ([] if result.scene.spec.airspace is None else result.scene.spec.airspace.zones):
        row = zone_rows.get(zs.name, {})
        out.append(Zone("airspace_zone", Polygon(zs.boundary_m), {
            "name": zs.name, "limit": zs.limit, "floor_agl_m": zs.floor_agl_m, "ceiling_agl_m": zs.ceiling_agl_m,
            "holds": row.get("holds"), "worst_effective_irradiance_w_m2": row.get("worst_effective_irradiance_w_m2"),
            "worst_time_s": row.get("worst_time_s"), "hazard": "none" if row.get("holds", True) else "naked eye"}, z_m=0.0))
    vi = result.visual_interference  # hazard.physics.visual.VisualInterference
    if vi is not None and vi.applies:
        for level in ("szed", "czed", "lfed"):
            g = visual_outline_xy(result, level)
            if g is not None and not g.is_empty:
                out.append(Zone("visual_zone", g, {"level": level, "distance_m": vi.direct.distance_m(level),
                                                   "limit_w_m2": vi.levels_w_m2[level], "vcf": vi.vcf, "path": "direct",
                                                   "hazard": "visual interference"}, z_m=0.0))
    return out


def zones(result, *, points_as_columns: bool = False) -> tuple[list, dict]:
    """Every zone of ``result`` (world x, y [m]) and the kinds absent with the reason.
    ``points_as_columns``: the observer points as one :class:`ObserverPoints` in their
    place (when there are any), not one :class:`Zone` each (their common properties,
    :func:`common_properties`, then added by the caller)."""
    off = np.asarray(result.scene.offset_m, float)
    if points_as_columns:
        op = observer_points(result)
        points: list = [op] if len(op) else []
    else:
        points = _observers(result)
    parts = {"footprint": _footprints(result, off) if result.scene.terrain is not None else [],
             "sdz": _sdz(result), "keepout_lobe": _lobes(result, off), "mirror_beam": _mirrors(result, off),
             "mirror_beam_zone": _mirror_zones(result, off),
             "observer": points, "things": _things(result, off), "airspace": _airspace(result)}
    common = _common(result)
    out = [z for zs in parts.values() for z in zs]
    for z in out:
        if isinstance(z, Zone):
            z.properties = {"kind": z.kind, **z.properties, **common}
    present = {z.kind for z in out}
    t = result.scene.terrain
    why = {"footprint": "no terrain (the ground footprint needs one)" if t is None
           else (f"no terrain node reaches the MPE at eye height (nodes every {t.dx:g} m: a zone smaller than that can fall "
                 f"between them; the keepout_lobe outlines, drawn from the lobes themselves, show it)"),
           "sdz": "no danger zone computed", "sdz_nominal": "no sector with a pointing buffer (only then is the sector without the buffer drawn apart)",
           "sdz_aided": "no optical aids", "keepout_lobe": "no lobe with a hazardous reach", "mirror_beam": "no mirror beam",
           "mirror_beam_zone": "no mirror beam",
           "observer": "no observers", "range_boundary": "no [range] boundary", "laser": "", "target": "",
           "track": "no moving observer (kind = 'track')", "airspace_zone": "no [airspace] zones",
           "visual_zone": ("not a visible laser (400-700 nm): the FAA visual levels do not apply"
                           if result.visual_interference is None or not result.visual_interference.applies else "no level reached")}
    absent = {k: why[k] for k in ZONE_KINDS if k not in present}
    return out, absent
