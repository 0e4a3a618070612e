"""Stages ``rays`` and ``beam``: the ray scene, and the beam's spots on the targets.

The beam's cross-section is integrated by :mod:`hazard.physics.beam` (exact cell and outline
powers, adaptive refinement with an error bound) and turned into spots by
:func:`hazard.physics.engine.build_spots`.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from hazard.physics.beam import HALF_WIDTH, TAIL_MARGIN, BeamGeometry, CellSampling, sample_cells, tail_bounds_w_m2, tail_half_width
from hazard.physics.engine import SpotBuild, build_spots, flat_outlines
from hazard.physics.nohd import optical_gain
from hazard.pipeline.results import TargetResult
from hazard.physics.visual import applies as visual_applies
from hazard.physics.visual import level_limit_w_m2, visual_correction_factor
from hazard.pipeline.limits import exposure_limits
from hazard.pipeline.lobes import scene_aids

__all__ = ["BeamSampling", "NotReflected", "BeamStage", "TailSquare", "ray_scene", "sampled_square", "scene_beam", "trace_beam", "unlit_targets", "tail_notes"]


class FlatScene:
    """Beam hits on plates and disks by ray-plane intersection (no ray library)."""

    def __init__(self, targets):
        self.targets = targets
        self.scale_m = 1.0

    def face_normals(self, faces):
        return np.stack([self.targets[f].normal for f in faces]) if len(faces) else np.empty((0, 3))

    def first_hit(self, origins, directions):
        from hazard.physics.rays import Hits

        o = np.asarray(origins, float)
        d = np.asarray(directions, float)
        d = d / np.linalg.norm(d, axis=1, keepdims=True)
        n = len(o)
        best_t = np.full(n, np.inf)
        best = np.full(n, -1)
        for t in self.targets:
            den = d @ t.normal
            with np.errstate(divide="ignore", invalid="ignore"):
                tt = ((t.center_m - o) @ t.normal) / den
            p = o + d * np.where(np.isfinite(tt), tt, 0)[:, None]
            q = p - t.center_m
            x = q @ t.tangent
            y = q @ np.cross(t.normal, t.tangent)
            s = t.spec.size_m
            inside = (np.abs(x) <= s[0] / 2) & (np.abs(y) <= s[1] / 2) if t.spec.shape == "plate" else (x * x + y * y <= (s[0] / 2) ** 2)
            ok = np.isfinite(tt) & (tt > 0) & inside & (tt < best_t)
            best_t[ok] = tt[ok]
            best[ok] = t.index
        hit = best >= 0
        point = np.where(hit[:, None], o + d * np.where(hit, best_t, 0)[:, None], np.nan)
        return Hits(hit, best_t, best, best, point)


def ray_meshes(scene) -> list:
    """(vertices, faces, object id) of the targets, then the occluders, then the terrain."""
    meshes = [(t.mesh.vertices, t.mesh.faces, t.index) for t in scene.targets]
    base = len(scene.targets)
    meshes += [(m.vertices, m.faces, base + i) for i, m in enumerate(scene.occluders)]
    if scene.terrain is not None:
        tm = scene.terrain.mesh()
        meshes.append((tm.vertices, tm.faces, base + len(scene.occluders)))
    return meshes


def ray_scene(scene, backend, threads):
    """The ray scene of every object (Embree, or trimesh's numpy engine), from the cache
    when an earlier analysis (a study's scenario) had the same geometry."""
    from hazard.physics.rays import cached_ray_scene

    return cached_ray_scene(ray_meshes(scene), backend=backend, threads=threads)


@dataclass
class BeamStage:
    """The beam (:class:`hazard.physics.beam.BeamGeometry`), its cells, the spots built from
    them (:class:`hazard.physics.engine.SpotBuild`) and the notes the stage leaves."""

    beam: BeamGeometry
    cells: CellSampling
    built: SpotBuild
    notes: list[str]
    detail: str
    outlines: dict[int, np.ndarray]  # flat targets' projected outlines: index -> upper-bound polygon in s
    square: TailSquare | None = None  # the sampled square


def scene_beam(scene, direction=None) -> BeamGeometry:
    """The laser's beam from the scene (along ``direction``, unit; default: the aim); its
    sampling grid is aligned with the first target's tangent (or normal), so it turns
    with the scene."""
    laser = scene.spec.laser
    reference = [v for t in scene.targets[:1] for v in (t.tangent, t.normal)]
    return BeamGeometry.create(scene.laser_position_m, scene.laser_direction if direction is None else direction,
                               laser.average_power_w, laser.beam_diameter_m, laser.divergence_rad, reference)


def mirror_aperture_m(spec) -> float:
    """The limiting aperture [m] a mirror beam's power is averaged over: the exposure's
    (:func:`hazard.physics.mpe.ocular_mpe`) when it is the retina's 7 mm, else 1 mm, the cornea's
    below 0.3 s and the smallest any band uses (the corneal aperture grows with the
    elapsed time the map checks: the smallest is the conservative one)."""
    from hazard.physics.mpe import ocular_mpe

    aperture = ocular_mpe(spec.laser.wavelength_nm, spec.exposure.duration_s, standard=spec.exposure.standard).limiting_aperture_m
    return aperture if aperture >= 7e-3 else 1e-3


@dataclass
class TailSquare:
    """The sampled beam square chosen for a scene (:func:`sampled_square`): half-width
    ``half_width`` [1/e radii] (a whole number of the base grid's cells beyond 4), cells per
    side ``n0``, the limit it was sized for [W/m^2] and the bounds on what it leaves out
    (:func:`hazard.physics.beam.tail_bounds_w_m2`) [W/m^2]."""

    half_width: float
    n0: int
    limit_w_m2: float
    peak_bound_w_m2: float
    power_bound_w_m2: float

    def detail(self) -> str:
        worst = max(self.peak_bound_w_m2, self.power_bound_w_m2)
        return (f"beam sampled over +-{self.half_width:.4g} w ({self.n0} x {self.n0} coarsest cells); what lies outside gives at most "
                f"{worst:.3g} W/m^2 after one reflection ({worst / self.limit_w_m2:.3g} of the smallest limit, "
                f"{self.limit_w_m2:.4g} W/m^2)")


def sampled_square(scene, beam, n0_base: int) -> TailSquare:
    """The beam square for a scene: half-width ``L >= 4`` 1/e radii such that the beam
    outside it, after any one reflection (reflectance 1), stays below ``TAIL_MARGIN`` of the
    smallest limit any observer is held to (the MPE over the largest optical-aid gain, and
    the flight zones' levels (:func:`_zone_limits_w_m2`);
    :func:`hazard.physics.beam.tail_half_width`), rounded up to whole cells of the base grid
    (``n0_base`` cells over +-4 w), so the cells inside +-4 w are the base grid's."""
    spec = scene.spec
    gain = max([1.0] + [optical_gain(a.magnification, a.objective_diameter_m, a.transmission) for a in scene_aids(scene)])
    mpe_w_m2 = exposure_limits(spec).irradiance_w_m2
    limit = min([mpe_w_m2 / gain] + _zone_limits_w_m2(spec, mpe_w_m2))
    aperture_m = mirror_aperture_m(spec)
    want = max(beam.half_width, tail_half_width(beam.power_w, beam.diameter_m, beam.divergence_rad, limit, aperture_m))
    step = 2 * HALF_WIDTH / n0_base
    extra = max(0, math.ceil((want - HALF_WIDTH) / step - 1e-9))
    half = HALF_WIDTH + extra * step
    peak, power = tail_bounds_w_m2(half, beam.power_w, beam.diameter_m, beam.divergence_rad, aperture_m)
    return TailSquare(half, n0_base + 2 * extra, limit, peak, power)


def _zone_limits_w_m2(spec, mpe_w_m2: float) -> list:
    """The irradiances [W/m^2] at which the scene's flight zones reach their levels
    (:func:`hazard.physics.visual.level_limit_w_m2`: the FAA levels over the VCF, or the MPE
    ``mpe_w_m2``)."""
    air = spec.airspace
    if air is None or not air.zones:
        return []
    wl = spec.laser.wavelength_nm
    vcf = visual_correction_factor(wl, air.visual_correction) if visual_applies(wl) else 0.0
    return [e for e in (level_limit_w_m2(z.limit, mpe_w_m2, vcf) for z in air.zones) if math.isfinite(e)]


def trace_beam(scene, tracer, mu, beam=None) -> BeamStage:
    """Sample the beam (default: :func:`scene_beam`) against every object and build the
    targets' spots. The sampled square is sized per beam (:func:`sampled_square`)."""
    spec, laser = scene.spec, scene.spec.laser
    beam = scene_beam(scene) if beam is None else beam
    square = sampled_square(scene, beam, _level0_cells(spec.analysis.beam_samples))
    beam = dataclasses.replace(beam, half_width=square.half_width)
    outlines = flat_outlines(beam, scene.targets)
    cells = sample_cells(beam, tracer, scene.targets, n0=square.n0, rtol=spec.analysis.beam_rtol,
                         outlines={k: v[1] for k, v in outlines.items()})
    built = build_spots(beam, cells, scene.targets, tracer, mu, outlines, scene.terrain_target, TAIL_MARGIN * square.limit_w_m2)
    aperture_m = mirror_aperture_m(spec)
    for sp in built.spots:
        sp.aperture_m = aperture_m
    notes = _curved_mesh_notes(built.spots, aperture_m)
    if built.spill_w > 1e-3 * laser.average_power_w:
        notes.append(f"{100 * built.spill_w / laser.average_power_w:.3g} % of the beam misses every target (spill)")
    if built.blocked_w > 1e-3 * laser.average_power_w:
        notes.append(f"{100 * built.blocked_w / laser.average_power_w:.3g} % of the beam is stopped by an occluder or the terrain "
                     f"(before a target or past them; see the spill)")
    notes.extend(_unreflected_notes(built.unreflected))
    if max(square.peak_bound_w_m2, square.power_bound_w_m2) > TAIL_NOTE_FRACTION * square.limit_w_m2:
        notes.append(f"the beam is sampled over its widest square, {square.detail()}: reflections of the beam beyond it are NOT computed")
    return BeamStage(beam, cells, built, notes, square.detail() + "; " + _beam_detail(cells, built, laser.average_power_w),
                     {k: v[0] for k, v in outlines.items()}, square)


def _curved_mesh_notes(spots, aperture_m) -> list:
    """A note per spot on a curved mesh with a mirror lobe: how its reflection is computed."""
    from hazard.physics.mesh_mirror import MESH_MIRROR_RAYS, MIN_RAYS_IN_APERTURE, is_curved_mesh

    out = []
    for sp in spots:
        if sp.material.has_specular and is_curved_mesh(sp.target):
            curved = sp.target.mesh.curved_faces()
            out.append(f"target {sp.target.name!r}: a curved mesh ({int(curved.sum())} of {len(curved)} facets curved): its mirror "
                       f"beam is traced as a smooth surface (interpolated vertex normals) with about {MESH_MIRROR_RAYS} rays and "
                       f"averaged over the {1e3 * aperture_m:.3g} mm limiting aperture: binned where at least "
                       f"{MIN_RAYS_IN_APERTURE} rays cross it (two sampling standard deviations added), ray tubes elsewhere")
    return out


def _level0_cells(beam_samples: int) -> int:
    """Cells per side of the beam's coarsest grid: about ``beam_samples`` cells in all (at least 4 x 4)."""
    return max(4, int(round(math.sqrt(beam_samples))))


def _beam_detail(cells, built, power_w) -> str:
    exact = f"; exact outline integrals for {', '.join(built.exact)}" if built.exact else ""
    for name, n, p, floor in built.negligible:
        exact += (f"; {n} tail cell(s) on {name!r} beyond +-{HALF_WIDTH:g} w left out of its spot's samples (incident below "
                  f"{floor:.3g} W/m^2 there; their {p:.3g} W kept in its total)")
    if built.unreflected:
        exact += "; not reflected: " + ", ".join(f"{n} ({s} face, {p:.4g} W)" if s != "unresolved" else f"{n} (unresolved cells, {p:.4g} W)"
                                                 for n, s, p in built.unreflected)
    return (f"{cells.rays_traced} rays over {cells.levels_used} level(s) of cells; {len(built.spots)} spot(s); "
            f"spill {built.spill_w:.4g} W, blocked {built.blocked_w:.4g} W; intercepted-power error bound "
            f"{built.error_w:.3g} W ({built.error_w / power_w:.2g} of the beam, added to the spots){exact}")


@dataclass(frozen=True)
class NotReflected:
    """Beam power that reached a target but is not reflected (report.json ``beam.sampling.not_reflected[]``).

    Attributes
    ----------
    target : str
        The target's name.
    side : str
        The face lit (``"front"``/``"back"``) that does not reflect, or ``"unresolved"``
        (beam cells too coarse to tell).
    power_w : float
        The power that reached it there [W].
    """

    target: str
    side: str
    power_w: float

    def to_dict(self) -> dict:
        return {"target": self.target, "side": self.side, "power_w": self.power_w}


@dataclass(frozen=True)
class BeamSampling:
    """The beam stage's accuracy (report.json ``beam.sampling``; :func:`beam_sampling`).

    Attributes
    ----------
    rays : int
        Rays traced over all levels of beam cells.
    levels : int
        Refinement levels of cells used.
    rtol : float
        The relative tolerance asked for (``[analysis] beam_rtol``, unitless).
    error_bound_w : float
        Bound on the power misassigned between objects [W] (added to the spots: conservative).
    exact_targets : tuple of str
        Targets whose spot power is the exact outline integral.
    not_reflected : tuple of NotReflected
        Power that reached a target but is not reflected, per target and face.
    half_width_w : float
        The sampled square's half-width, in 1/e beam radii ``w`` (not watts: the name's ``w``
        is the beam radius).
    tail_point_bound_w_m2, tail_aperture_bound_w_m2, tail_limit_w_m2 : float or None
        With a sampled square (:class:`TailSquare`): the bounds [W/m^2] on the irradiance the
        square leaves out (at a point after a flat or diffuse reflection; over the limiting
        aperture) and the limit [W/m^2] they were held below. None without a square: the keys
        are then absent from report.json (:attr:`ABSENT_WHEN_NONE`).
    """

    rays: int
    levels: int
    rtol: float
    error_bound_w: float
    exact_targets: tuple[str, ...]
    not_reflected: tuple[NotReflected, ...]
    half_width_w: float
    tail_point_bound_w_m2: float | None = None
    tail_aperture_bound_w_m2: float | None = None
    tail_limit_w_m2: float | None = None

    ABSENT_WHEN_NONE: ClassVar[tuple[str, ...]] = ("tail_point_bound_w_m2", "tail_aperture_bound_w_m2", "tail_limit_w_m2")

    def to_dict(self) -> dict:
        """report.json's ``beam.sampling``: the fields in their order, the ``tail_*`` keys only with a square."""
        out = {"rays": self.rays, "levels": self.levels, "rtol": self.rtol, "error_bound_w": self.error_bound_w,
               "exact_targets": list(self.exact_targets), "not_reflected": [n.to_dict() for n in self.not_reflected],
               "half_width_w": self.half_width_w}
        for key in self.ABSENT_WHEN_NONE:
            if getattr(self, key) is not None:
                out[key] = getattr(self, key)
        return out


def beam_sampling(cells, built, rtol, square=None) -> BeamSampling:
    """The beam stage's accuracy for the report: rays, levels, the bound on the power
    misassigned between objects [W], which targets got exact outline integrals, and the
    sampled square (:class:`TailSquare`): its half-width [1/e radii] and the bounds [W/m^2]
    on what it leaves out (point after a flat or diffuse reflection; limiting aperture)."""
    tail = {} if square is None else {"tail_point_bound_w_m2": float(square.peak_bound_w_m2),
                                      "tail_aperture_bound_w_m2": float(square.power_bound_w_m2),
                                      "tail_limit_w_m2": float(square.limit_w_m2)}
    return BeamSampling(rays=int(cells.rays_traced), levels=int(cells.levels_used), rtol=float(rtol),
                        error_bound_w=float(built.error_w), exact_targets=tuple(built.exact),
                        not_reflected=tuple(NotReflected(n, s, float(p)) for n, s, p in built.unreflected),
                        half_width_w=float(cells.half_width), **tail)


def unlit_targets(targets, spots, unreflected) -> list:
    """A row for every target without a spot (after the spots' rows, same order as the
    file), so no target disappears from a report: what reached it and why nothing reflects."""
    lit = {sp.target.index for sp in spots}
    why: dict[str, list[tuple[str, float]]] = {}
    for name, side, p in unreflected:
        why.setdefault(name, []).append((side, p))
    rows = []
    for t in targets:
        if t.index in lit:
            continue
        parts = why.get(t.name, [])
        power = float(sum(p for _, p in parts))
        side = "; ".join(f"{s} face lit, not reflected" if s != "unresolved" else "only unresolved beam cells" for s, _ in parts) or "not lit"
        rows.append(TargetResult(t.name, power, 0.0, None, None, None, None, None, None, None, lit_side=side))
    return rows


TAIL_NOTE_FRACTION = 0.01  # a target the sampled beam misses is said where the tail there reaches this fraction of the MPE
TAIL_EDGE_POINTS = 65  # points per mesh edge where its distance from the beam's axis is taken
TAIL_EDGE_BLOCK = 8192  # edges taken at once (8192 x 66 points: 13 MB a block)


def tail_notes(scene, beam, spots, mpe_w_m2: float, mu: float) -> list[str]:
    """A note for every target the sampled beam (+-``beam.half_width`` 1/e radii, sized by
    :func:`sampled_square` so that this happens only where the square reached its largest,
    ``MAX_HALF_WIDTH``) does not light but whose nearest edge lies where the beam's Gaussian
    tail still reaches ``TAIL_NOTE_FRACTION`` of the MPE: its reflection of that tail is NOT
    computed (a mirror there reflects up to the tail's irradiance), so it is said, never dropped.

    The nearest approach is taken over the mesh's edges (:func:`_nearest_in_beam`; a face
    the axis pierces is lit by the sampled beam). The tail's irradiance there:
    ``P / (pi w^2) exp(-s^2) exp(-mu z)``."""
    lit = {sp.target.index for sp in spots}
    terrain = getattr(scene, "terrain_target", None)
    out = []
    for t in scene.targets:
        if t.index in lit or t is terrain:
            continue
        s_min, z = _nearest_in_beam(beam, t.mesh)
        if s_min is None or s_min <= beam.half_width:
            continue  # behind the laser, or inside the sampled square (the beam stage says why it is unlit)
        w = float(beam.diameter_at(z)) / 2
        e = beam.power_w / (math.pi * w * w) * math.exp(-s_min * s_min - mu * z)
        if e >= TAIL_NOTE_FRACTION * mpe_w_m2:
            out.append(f"target {t.name!r} lies outside the sampled beam (+-{beam.half_width:.4g} w), {s_min:.3g} w from its axis, "
                       f"where the beam's Gaussian tail still gives up to {e:.3g} W/m^2 ({e / mpe_w_m2:.3g} x MPE): "
                       f"its reflection of that tail is NOT computed")
    return out


def _nearest_in_beam(beam, mesh):
    """Smallest distance from the beam's axis [1/e radii] over a mesh's edges, and the axial
    distance [m] there; (None, None) when no edge is in front of the laser. Per edge: the
    point nearest the axis line (closed form) and ``TAIL_EDGE_POINTS`` points along it (the
    radius grows along the axis, so the nearest in radii can lie elsewhere)."""
    f = np.asarray(mesh.faces)
    v = np.asarray(mesh.vertices, float)
    edges = np.unique(np.sort(np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]]), axis=1), axis=0)
    a, b = v[edges[:, 0]], v[edges[:, 1]]

    def transverse(x):
        return x - (x @ beam.axis)[:, None] * beam.axis

    best, at = np.inf, None
    for lo in range(0, len(edges), TAIL_EDGE_BLOCK):  # in blocks: 66 points an edge of a 3e5-face mesh were 9 GB at once
        ea, eb = a[lo:lo + TAIL_EDGE_BLOCK], b[lo:lo + TAIL_EDGE_BLOCK]
        ta, te = transverse(ea - beam.position_m), transverse(eb - ea)
        u_star = np.clip(-(ta * te).sum(1) / np.maximum((te * te).sum(1), 1e-300), 0.0, 1.0)
        u = np.concatenate([u_star[:, None], np.broadcast_to(np.linspace(0.0, 1.0, TAIL_EDGE_POINTS), (len(ea), TAIL_EDGE_POINTS))], axis=1)
        pts = ea[:, None, :] + u[..., None] * (eb - ea)[:, None, :]
        s, z = beam.to_s(pts.reshape(-1, 3))
        r = np.where((z > 0) & np.all(np.isfinite(s), axis=1), np.linalg.norm(s, axis=1), np.inf)
        k = int(np.argmin(r))
        if r[k] < best:
            best, at = float(r[k]), float(z[k])
    if not np.isfinite(best):
        return None, None
    return best, at


def _unreflected_notes(unreflected) -> list:
    notes = []
    for name, side, p in unreflected:
        if side == "unresolved":
            notes.append(f"target {name!r}: at most {p:.4g} W reaches it in unresolved beam cells and is not reflected")
        elif side == "back":
            notes.append(f"target {name!r}: the lit side is the back ({p:.4g} W) and it has no back material: "
                         f"nothing was reflected from it (give targets.back to model the back face)")
        else:
            notes.append(f"target {name!r}: {p:.4g} W lands on its {side} faces and is not reflected (mixed sides: the other side carries more)")
    return notes
