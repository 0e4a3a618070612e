"""One simulated operation: the peak irradiance at every point for one draw of the inputs.

Per draw the engine's own pieces run, nothing re-implemented:

0. The analysis's own stages (:data:`hazard.pipeline.analysis.REGISTRY`): ``mpe`` (the exposure
   limits, the attenuation) and ``rays`` (the ray scene, its BVH) run once per process
   (:data:`SHARED_STAGES`; a draw changes neither), and their results are handed to the
   stages a draw re-runs.
1. The beam: the scene's, its axis turned by the pointing error
   (:mod:`hazard.drivers.risk.inputs`). A turned beam is the input scene with its
   ``laser_direction`` turned (as the motion stage aims a beam), run through the stages
   ``beam`` and ``history`` (:data:`DRAW_STAGES`: the trace against the same ray scene,
   and the dynamic targets' state histories under its new spots); the observer-line
   crossings are not searched (the draw's points are the observers' and the map's). A beam
   whose 5-radius cone clears every target's bounding sphere (and no terrain can reflect)
   is not traced: it lights nothing.
2. The surfaces: the material of a lit face replaced by the drawn one and scaled by the
   drawn factor (:class:`brdfmodels.Scaled`); the normal of a plate or disk tilted by the
   drawn tilt (its material frames and mirror plane turn about its centre; the surface
   stays where it is: a wandering surface slope, not a moving target); the spots' power
   re-attenuated for the drawn visibility.
3. The irradiance: the diffuse and glossy lobes (:func:`hazard.physics.engine.spot_irradiance`),
   the mirror beams (:func:`hazard.physics.engine.specular_irradiance`, times the drawn
   scintillation factor of the mirror path), the direct beam (:func:`hazard.pipeline.direct.beam_at`,
   blocked by any object, times the direct path's factor), lines of sight against the ray
   scene (:func:`hazard.pipeline.irradiance_map.spot_line_of_sight`).
4. The peak over the analysis times (dynamic materials; with a wandering tilt each time
   takes its node's tilt), divided by the point-source MPE (the pulsed rule included,
   C_E not credited: conservative), naked eye. Observers' optics multiply it later.

Not redrawn per draw (said in the report): a pointing error's effect on the heating of a
dynamic target is followed, but the heating does not follow a drawn visibility or BRDF
scale (the history is the nominal attenuation's); scintillation path lengths are the
nominal geometry's.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, replace

import numpy as np

from hazard.pipeline.analysis import REGISTRY
from hazard.physics.engine import spot_irradiance, specular_irradiance
from hazard.physics.nohd import attenuation_from_visibility, group_gains
from hazard.pipeline import history
from hazard.pipeline import spots as beam_stage
from hazard.pipeline.direct import beam_at, clear_of_objects
from hazard.pipeline.irradiance_map import spot_line_of_sight
from hazard.pipeline.log import StageLog
from hazard.pipeline.plan import plan
from hazard.pipeline.stages import CrossingsResult, derive_plan, run_stages
from hazard.drivers.risk.inputs import Draws, input_model
from hazard.drivers.risk.physics import scintillation_sigma2

__all__ = ["Evaluator", "map_points", "map_shape", "turned_axis", "pointing_basis", "SHARED_STAGES", "DRAW_STAGES"]

CONE_RADII = 5.0  # a beam is taken to reach a target when its axis passes within 5 1/e radii of it (exp(-25) of the peak)
#: The analysis stages run once per process (a draw changes none of their inputs).
SHARED_STAGES = ("mpe", "rays")
#: The analysis stages run per traced beam, given the shared stages' results and the
#: skipped ``crossings`` (the draw's scene itself).
DRAW_STAGES = ("beam", "history")
derive_plan({n: REGISTRY[n] for n in DRAW_STAGES}, ("scene", "plan", *SHARED_STAGES, "crossings"))  # their needs are met


def pointing_basis(axis) -> tuple[np.ndarray, np.ndarray]:
    """(right, up) unit vectors across the beam axis: right horizontal, up = right x axis
    (a vertical beam takes +x as right)."""
    a = np.asarray(axis, float)
    r = np.cross(a, [0.0, 0.0, 1.0])
    if np.linalg.norm(r) < 1e-9:
        r = np.array([1.0, 0.0, 0.0]) - a[0] * a
    r /= np.linalg.norm(r)
    return r, np.cross(r, a)


def turned_axis(axis, right, up, e) -> np.ndarray:
    """The axis turned by the pointing error ``e`` = (right, up) [rad] (tangent-plane coordinates)."""
    v = np.asarray(axis, float) + e[0] * right + e[1] * up
    return v / np.linalg.norm(v)


def _rotation(n, n2) -> np.ndarray:
    """The smallest rotation taking unit vector n to unit vector n2 (Rodrigues)."""
    v, c = np.cross(n, n2), float(np.dot(n, n2))
    k = np.array([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]])
    return np.eye(3) + k + k @ k / (1.0 + c)


def tilted_normal(target, delta) -> np.ndarray:
    """``target``'s normal tilted by ``delta`` = (along the tangent, along n x tangent) [rad]."""
    n, t1 = target.normal, target.tangent
    v = n + delta[0] * t1 + delta[1] * np.cross(n, t1)
    return v / np.linalg.norm(v)


def map_shape(m) -> tuple[int, int]:
    """(rows, columns) of the map's cells (a :class:`scenes.spec.ProbabilityMapSpec`)."""
    x0, x1, y0, y1 = m.extent_m
    return math.ceil((y1 - y0) / m.spacing_m), math.ceil((x1 - x0) / m.spacing_m)


def map_points(scene) -> np.ndarray:
    """Cell centres (N, 3) of ``[uncertainty.map]`` at eye height over the terrain (over z = 0 without one)."""
    m = scene.spec.uncertainty.map
    if m is None:
        return np.empty((0, 3))
    ny, nx = map_shape(m)
    xs = m.extent_m[0] - scene.offset_m[0] + m.spacing_m * (np.arange(nx) + 0.5)
    ys = m.extent_m[2] - scene.offset_m[1] + m.spacing_m * (np.arange(ny) + 0.5)
    gx, gy = np.meshgrid(xs, ys)
    ground = scene.terrain.height_at(gx.ravel(), gy.ravel()) if scene.terrain is not None else np.full(gx.size, -scene.offset_m[2])
    return np.column_stack([gx.ravel(), gy.ravel(), np.asarray(ground, float) + m.eye_height_m])


@dataclass
class Traced:
    """A beam and what it lights: spots and the dynamic targets' states (index -> (T,...))."""

    beam: object
    spots: list
    states: dict


class Evaluator:
    """Everything a draw shares (ray scene, nominal trace, points, MPE), built once per process."""

    def __init__(self, scene, backend: str = "embree"):
        spec = scene.spec
        self.scene = scene
        self.plan = plan(scene)
        inputs = {"scene": scene, "plan": self.plan, "backend": backend, "threads": 1, "keep_history": None}
        self.shared = run_stages(REGISTRY, SHARED_STAGES, inputs, StageLog())  # stage name -> result, once per process
        self.exposure = self.shared["mpe"].exposure
        self.mpe_w_m2 = float(self.exposure.irradiance_w_m2)
        self.mu0 = self.shared["mpe"].attenuation_per_m
        self.ray_scene, self.tracer = self.shared["rays"].ray_scene, self.shared["rays"].tracer
        self.dynamic = any(t.material.is_dynamic for t in scene.targets)
        # every time a turned beam may need (a dynamic target it lights), not only the nominal beam's
        self.times_s = history.analysis_times(spec, self.dynamic, history.series_nodes(scene.targets))
        self.nominal = self.trace()
        obs = scene.observers
        self.n_observers = 0 if obs is None else len(obs)
        self.points_m = np.vstack([obs.block(0, self.n_observers) if self.n_observers else np.empty((0, 3)), map_points(scene)])
        self.model = input_model(scene, len(self.points_m), self.n_observers, self.times_s)
        self.right, self.up = pointing_basis(scene.laser_direction)
        self.alternatives = self._alternatives()
        self._spheres = [(t.mesh.vertices.mean(axis=0), float(np.linalg.norm(t.mesh.vertices - t.mesh.vertices.mean(axis=0), axis=1).max()))
                         for t in scene.targets]
        self._scint_sigma()

    # -- shared per process --------------------------------------------------------------
    @functools.cached_property
    def labels(self) -> list:
        """The observers' labels (risk.csv's names)."""
        return self.scene.observers.labels() if self.n_observers else []

    def point_name(self, j: int) -> str:
        """Observer j's label, or the map cell's position."""
        if j < self.n_observers:
            return repr(self.labels[j])
        x, y, _ = self.points_m[j] + self.scene.offset_m
        return f"map cell ({x:.6g}, {y:.6g})"

    def own_gain(self) -> np.ndarray:
        """Per point the fixed optical gain of its observer group (map cells: 1, the naked eye)."""
        g = np.ones(len(self.points_m))
        if self.n_observers:
            g[: self.n_observers] = group_gains(self.scene.observers.optics, self.scene.observers.group)
        return g

    def _alternatives(self) -> dict:
        from scenes.scene import alternative_material

        out = {}
        for c in self.scene.spec.uncertainty.materials:
            k = [t.name for t in self.scene.targets].index(c.target)
            out[k] = [alternative_material(self.scene, k, ms, f"uncertainty.materials[{c.target!r}].materials[{j}]")
                      for j, ms in enumerate(c.materials)]
        return out

    def _scint_sigma(self) -> None:
        """ln-variance of the scintillation factor per point: direct path (M,), mirror path per target (T, M)."""
        u = self.scene.spec.uncertainty.scintillation
        self.s2_direct = self.s2_mirror = None
        if u is None:
            return
        wl, p, lp = self.scene.spec.laser.wavelength_nm, self.points_m, self.scene.laser_position_m
        self.s2_direct = scintillation_sigma2(u, wl, np.linalg.norm(p - lp, axis=1))
        self.s2_mirror = np.stack([scintillation_sigma2(u, wl, np.linalg.norm(t.center_m - lp) + np.linalg.norm(p - t.center_m, axis=1))
                                   for t in self.scene.targets]) if self.scene.targets else np.zeros((0, len(p)))

    def trace(self, direction=None, beam=None) -> Traced:
        """The beam along ``direction`` (default: the scene's aim), its spots and the
        dynamic targets' states under it: the analysis's stages :data:`DRAW_STAGES` run on
        the scene aimed along ``direction``, with the shared stages' results
        (:data:`SHARED_STAGES`) as their inputs. ``beam``: that scene's
        :func:`~hazard.pipeline.spots.scene_beam` when the caller has it already."""
        scene = self.scene if direction is None else replace(self.scene, laser_direction=direction)
        inputs = {"scene": scene, "plan": self.plan, **self.shared, "crossings": CrossingsResult(scene)}
        h = run_stages(REGISTRY, DRAW_STAGES, inputs, StageLog())["history"]
        return Traced(beam_stage.scene_beam(scene) if beam is None else beam, h.traced.built.spots, h.states)

    def _reaches_any(self, beam) -> bool:
        if self.scene.terrain_target is not None:
            return True
        for c, r in self._spheres:
            rel = c - beam.position_m
            z = float(rel @ beam.axis)
            if z + r <= 0:
                continue
            w = float(beam.diameter_at(max(z + r, 0.0))) / 2
            off = float(np.linalg.norm(rel - z * beam.axis))
            if off <= r + CONE_RADII * w:
                return True
        return False

    def traced_for(self, e) -> Traced:
        """The nominal trace, or the beam turned by pointing error ``e`` [rad] traced again."""
        if e is None or not np.any(e):
            return self.nominal
        direction = turned_axis(self.nominal.beam.axis, self.right, self.up, e)
        beam = beam_stage.scene_beam(self.scene, direction)
        return self.trace(direction, beam) if self._reaches_any(beam) else Traced(beam, [], {})

    # -- one draw ----------------------------------------------------------------------
    def _surface(self, sp, d: Draws, i: int, node: int, mu: float):
        """Spot ``sp`` with draw i's material, scale, tilt at wander node ``node`` and attenuation."""
        import brdfmodels

        k = sp.target.index
        kw = {}
        if sp.side == "front" and d.material_index is not None and d.material_index[i, k] >= 0:
            kw["material"] = self.alternatives[k][d.material_index[i, k]]
        if d.scale_z is not None and k < d.scale_z.shape[1]:
            kw["material"] = brdfmodels.Scaled(kw.get("material", sp.material), math.exp(self.model.scale_sigma * d.scale_z[i, k]))
        if d.tilt_rad is not None and k < d.tilt_rad.shape[1] and np.any(d.tilt_rad[i, k, node]):
            n2 = tilted_normal(sp.target, d.tilt_rad[i, k, node])
            rot = _rotation(sp.target.normal, n2)
            kw["frames"] = sp.frames @ rot.T
            kw["target"] = replace(sp.target, normal=n2, tangent=rot @ sp.target.tangent)
        if mu != self.mu0:
            f = np.exp(-(mu - self.mu0) * sp.range_from_laser_m)
            kw["power_w"] = sp.power_w * f
            if sp.peak_irradiance_w_m2 is not None:
                kw["peak_irradiance_w_m2"] = sp.peak_irradiance_w_m2 * f
        return replace(sp, **kw) if kw else sp

    def _factors(self, d: Draws, i: int):
        """Scintillation factors of draw i: direct (M,), mirror per target (T, M); None without."""
        if d.scint_z is None:
            return None, None
        s_d, s_m = np.sqrt(self.s2_direct), np.sqrt(self.s2_mirror)
        return (np.exp(s_d * d.scint_z[i, 0] - self.s2_direct / 2),
                np.exp(s_m * d.scint_z[i, 1][None, :] - self.s2_mirror / 2))

    def _segments(self) -> list:
        """(wander node, analysis-time rows) pairs: each time takes the nearest node at or before it."""
        times = self.model.wander_times_s
        if times is None:
            return [(0, slice(None))]
        if len(self.times_s) == 1:
            return [(j, slice(None)) for j in range(len(times))]
        node = np.searchsorted(np.asarray(times), self.times_s + 1e-12, side="right") - 1
        return [(j, np.flatnonzero(node == j)) for j in range(len(times)) if np.any(node == j)]

    def _reflected(self, tr: Traced, d: Draws, i: int, p, mu, chi_m) -> np.ndarray:
        """Reflected irradiance (M, T) of draw i over the analysis times (T = 1 when static)."""
        m = len(p)
        t_all = len(self.times_s) if tr.states else 1
        e = np.zeros((m, t_all))
        peak_nodes = []
        for node, rows in self._segments():
            part = np.zeros((m, t_all))[:, rows] if tr.states else np.zeros((m, 1))
            for sp0 in tr.spots:
                sp = self._surface(sp0, d, i, node, mu)
                sk = tr.states.get(sp.target.index)
                sk = None if sk is None else sk[rows]
                los = spot_line_of_sight(self.ray_scene, sp, p)[0] if self.ray_scene is not None else None
                diff, _ = spot_irradiance(sp, p, np.ones(m), mu, sk, los)
                part += diff if diff.ndim == 2 else diff[:, None]
                if sp.material.has_specular:  # each observer's line of sight from its own reflection point
                    spec = specular_irradiance(sp, p, np.ones(m), mu, None, sk, ray_scene=self.ray_scene)
                    if chi_m is not None:
                        spec = spec * (chi_m[sp.target.index] if spec.ndim == 1 else chi_m[sp.target.index][:, None])
                    part += spec if spec.ndim == 2 else spec[:, None]
            if tr.states:
                e[:, rows] = part
            else:
                peak_nodes.append(part[:, 0])
        return e if tr.states else np.max(peak_nodes, axis=0)[:, None]

    def _direct(self, beam, p, mu) -> np.ndarray:
        """The direct beam through the naked eye's limiting aperture at points p (as the
        analysis's verdict, :mod:`hazard.physics.aperture`)."""
        from hazard.physics.aperture import Apertures, limiting_aperture_m
        from hazard.pipeline.direct import gaussian_aperture_w_m2

        out = np.zeros(len(p))
        half = limiting_aperture_m(self.scene.spec.laser.wavelength_nm, self.scene.spec.exposure.duration_s) / 2
        at = beam_at(beam, p, mu, half)
        if len(at.rows):
            clear = clear_of_objects(at, p, self.tracer)
            n = len(at.rows)
            eye = Apertures(np.full(n, half), np.full(n, half), np.ones(n), np.zeros(n, bool))
            through = gaussian_aperture_w_m2(beam, at.axial_m, at.offset_m, at.path_m, mu, eye)
            out[at.rows[clear]] = through[clear]
        return out

    def peak_ratio(self, d: Draws, i: int) -> np.ndarray:
        """Draw i: per point the naked eye's peak irradiance / MPE."""
        tr = self.traced_for(None if d.pointing_rad is None else d.pointing_rad[i])
        mu = self.mu0 if d.visibility_km is None else attenuation_from_visibility(float(d.visibility_km[i]), self.scene.spec.laser.wavelength_nm)
        p = self.points_m
        if d.offset_m is not None:
            p = p.copy()
            p[: self.n_observers] += d.offset_m[i]
        chi_d, chi_m = self._factors(d, i)
        e = self._reflected(tr, d, i, p, mu, chi_m) if tr.spots else np.zeros((len(p), 1))
        direct = self._direct(tr.beam, p, mu)
        if chi_d is not None:
            direct = direct * chi_d
        return (e + direct[:, None]).max(axis=1) / self.mpe_w_m2

    def ratios(self, d: Draws) -> np.ndarray:
        """(n, M) naked-eye peak irradiance / MPE of every draw."""
        out = np.empty((d.n, len(self.points_m)))
        for i in range(d.n):
            out[i] = self.peak_ratio(d, i)
        return out
