"""Stage ``motion``: the beam and its reflections over scenario time at moving observers
(aircraft tracks) and, when the beam or a target moves, at the fixed observers.

What one path (an observer's position over time) receives at time t:

- **direct beam** (range-safety.md sections 1-2): the Gaussian beam along the aim at t,
  ``E = P / (pi w^2) exp(-r^2 / w^2) sqrt(1 + r^2 phi^2 / (4 w^2)) exp(-mu L)``, w = (a +
  z phi) / 2 the 1/e radius at the axial distance z, r the distance from the axis, L from
  the aperture; zero where something lies on the segment from the aperture to the eye
  (terrain, occluders and the targets where they are at t) or the laser is not lasing
  (``[laser] windows``). The verdict's value is the power through the limiting aperture
  about the eye, or through the group's aid's collecting disk (:mod:`hazard.physics.aperture`,
  as for fixed observers; the line to the eye's centre decides what blocks it).
- **reflections**: the spots of the beam at t (:func:`hazard.pipeline.spots.trace_beam`
  on the scene with the aim and target positions of t: a *beam state*), evaluated as the
  irradiance map does (:func:`hazard.physics.engine.spot_irradiance`, the mirror lobes by
  :func:`hazard.physics.engine.specular_irradiance`), with the line of sight from each spot.
  When the beam moves, beam states are traced at key times chosen so that the spot moves
  at most half the beam's 1/e diameter at the target between them (at most
  ``BEAM_STATES_MAX``; a coarser step is said), and each time takes its nearest state.
- **dynamic materials**: the state at the *dwell time* of the spot, the lased time during
  which the surface under the spot's centre has been under the spot (for a beam held on
  a target: the lased time since lasing began; windows pause it, cooling between them is
  not modelled: the state is held), read off the target's history (the static analysis's
  ``history`` stage), taking the larger of the two bracketing history states.

Time steps. The path's own grid is the base step (``[motion] time_step_s``) with every
knot of the tracks, the aim track and the windows' edges (both sides of an edge). With
``adaptive = true`` it is refined, a priori, where the path comes within
``CROSSING_REACH`` 1/e radii, plus the largest aperture radius (an aperture collects
power that far from the eye), of a beam axis (the direct beam and each mirror beam): the
transverse offset from the axis is linear across a step, its closest approach is exact,
and the part of the step within reach gets a step of w / (n |dr/dt|) (n =
``samples_per_width``), so a fast aircraft crossing a narrow beam is sampled across it;
and a posteriori, where E changes by more than ``REL_CHANGE`` between neighbours (the
wide lobes of diffuse and glossy reflections), by halving, ``REFINE_PASSES`` times.

Pointing error (``[laser] pointing_error_rad``, the buffer b, a bound or k sigma): a
track is sampled again under constant biases of the aim across itself, each toward one
of the track's closest approaches to the aim (at most ``BIAS_CANDIDATES``, clipped to b),
and the worst is kept (``pointing_bias_rad`` in its summary): a track passing within b of
the beam may be crossed through the axis. The reflections stay those of the scheduled
aim. Fixed observers' pointing error is the static analysis's (the beam held anywhere
within it, :mod:`hazard.pipeline.pointing`).

Exposure along a path: the peak; the radiant exposure as the largest integral of E over
any window of ``[exposure] duration_s`` (trapezoids); the path's whole integral; and the
verdict: the largest ratio of the exposure in any window of length T to the MPE at T
(:func:`hazard.physics.mpe.ocular_mpe`, as radiant exposure), over T from the smallest step to
the exposure duration (``WINDOW_DURATIONS`` log-spaced): for a crossing this includes its
effective duration sqrt(pi) w / v (range-safety.md section 2). The integral's error is
estimated by comparing the trapezoid sum with the sum over every second sample (its
Richardson estimate, a third of the difference); its relative size raises every
window's exposure the verdict uses, never lowers it. Pulsed lasers also take the per-pulse rule on the peak.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from hazard.physics.engine import spot_irradiance, spot_line_of_sight, specular_irradiance
from hazard.physics.nohd import optical_gain
from hazard.physics.aperture import aperture_irradiance_w_m2, observer_apertures
from hazard.pipeline.motion_results import PathSummary

if TYPE_CHECKING:  # annotations only
    from hazard.physics.beam import BeamGeometry
    from scenes.motion import Motion
    from scenes.scene import Scene

__all__ = ["PathResult", "SummarisedPath", "MotionRun", "bias_frame", "BEAM_STATES_MAX", "FIXED_OBSERVERS_MAX"]

BEAM_STATES_MAX = 200  # beam states traced when the beam or a target moves (a coarser key step is said)
FIXED_OBSERVERS_MAX = 2000  # fixed observers evaluated over time when the beam moves (beyond: said, static verdict only)
SAMPLES_MAX = 2_000_000  # default samples per path: the limit is HAZARD_MAX_MOTION_SAMPLES (scenes.motion.samples_max)
CROSSING_REACH = 5.0  # 1/e radii from an axis where the a-priori refinement applies (exp(-25) beyond)
REL_CHANGE = 0.25  # a-posteriori refinement: neighbours differing by more than this fraction
REFINE_PASSES = 12
MIN_STEP_S = 1e-7
WINDOW_DURATIONS = 48


@dataclass
class BeamState:
    """The beam at a key time: its direction, the scene as it is then, its spots and the
    tracer that answers lines through that scene."""

    time_s: float
    direction: np.ndarray
    scene: object
    spots: list
    tracer: object
    ray_scene: object | None


@dataclass(frozen=True, eq=False)
class PathResult:
    """One path's samples: times [s], positions [m] (the analysis frame), whether the laser
    was on, and the direct and reflected irradiance [W/m^2] at the eye (or the aid) at each;
    ``bias_rad``: the constant pointing bias [rad] (right, up) it was sampled under."""

    name: str
    group: int
    kind: str  # "track" or "fixed"
    times_s: np.ndarray
    positions_m: np.ndarray
    lased: np.ndarray
    direct_w_m2: np.ndarray
    reflected_w_m2: np.ndarray
    base_step_s: float
    adaptive: bool
    bias_rad: tuple[float, float] = (0.0, 0.0)

    @property
    def irradiance_w_m2(self) -> np.ndarray:
        return self.direct_w_m2 + self.reflected_w_m2

    @property
    def cumulative_j_m2(self) -> np.ndarray:
        e = self.irradiance_w_m2
        return np.concatenate([[0.0], np.cumsum(0.5 * (e[1:] + e[:-1]) * np.diff(self.times_s))])


@dataclass(frozen=True, eq=False)
class SummarisedPath(PathResult):
    """A path's samples and what they mean: ``summary``
    (:class:`hazard.pipeline.motion_results.PathSummary`, of
    :func:`hazard.pipeline.motion_stage.path_summary`)."""

    summary: PathSummary = field(kw_only=True)

    @classmethod
    def of(cls, path: PathResult, summary: PathSummary) -> SummarisedPath:
        """``path``'s samples with their summary."""
        return cls(**{f.name: getattr(path, f.name) for f in dataclasses.fields(PathResult)}, summary=summary)


@dataclass
class MotionRun:
    """Everything the motion stage needs, built once."""

    scene: Scene
    motion: Motion
    mu: float
    mpe_w_m2: float
    pulse_limit_w_m2: float | None
    states: dict
    history_times_s: np.ndarray
    states_list: list  # BeamState per key time
    key_times_s: np.ndarray
    backend: str
    threads: int
    notes: list = field(default_factory=list)
    key_step_text: str = ""
    dwell_keys_s: np.ndarray | None = None  # per beam state: lased time of the surface under its spot before it (made once)
    beam: BeamGeometry | None = None  # hazard.physics.beam.BeamGeometry of the static analysis (its profile; the axis is the direction of t)
    aperture_reach_m: float = 0.0  # the largest collecting radius of any path's eye or aid (hazard.physics.aperture)

    # -- the schedule ----------------------------------------------------------------
    bias_rad: tuple = (0.0, 0.0)  # a constant pointing bias across the aim (bias_frame): the worst within the buffer

    def nominal_direction(self, t) -> np.ndarray:
        """The scheduled aim (N, 3) at times ``t``."""
        t = np.atleast_1d(np.asarray(t, float))
        if self.motion.aim is None:
            return np.broadcast_to(np.asarray(self.scene.laser_direction, float), (len(t), 3))
        return self.motion.aim.direction(t)

    def direction(self, t) -> np.ndarray:
        """The beam's direction (N, 3): the scheduled aim turned by ``bias_rad``."""
        u = self.nominal_direction(t)
        theta = math.hypot(*self.bias_rad)
        if theta == 0.0:
            return u
        e1, e2 = bias_frame(u)
        across = (self.bias_rad[0] * e1 + self.bias_rad[1] * e2) / theta
        return math.cos(theta) * u + math.sin(theta) * across

    def state_index(self, t) -> np.ndarray:
        """The beam state each time takes (the nearest key time)."""
        k = self.key_times_s
        if len(k) == 1:
            return np.zeros(np.shape(t), int)
        i = np.clip(np.searchsorted(k, t), 1, len(k) - 1)
        return np.where(np.abs(t - k[i - 1]) <= np.abs(k[i] - t), i - 1, i)


def bias_frame(u) -> tuple[np.ndarray, np.ndarray]:
    """Two unit vectors across aims u (N, 3): e1 horizontal (to the right of the aim), e2
    = e1 x u (upward); for a vertical aim e1 = +x."""
    u = np.asarray(u, float).reshape(-1, 3)
    e1 = np.cross(u, [0.0, 0.0, 1.0])
    n = np.linalg.norm(e1, axis=1)
    e1 = np.where(n[:, None] > 1e-12, e1 / np.maximum(n, 1e-300)[:, None], [1.0, 0.0, 0.0])
    return e1, np.cross(e1, u)


# -- time grids ------------------------------------------------------------------------
def base_grid(motion, t0: float, t1: float) -> np.ndarray:
    """The base step over [t0, t1] with every knot and both sides of each window edge."""
    from scenes.motion import check_base_steps

    step = motion.spec.time_step_s
    n = check_base_steps(motion, t0, t1) - 1  # checked at load over the whole span (scenes.motion.check_motion)
    edges = motion.windows.edges()
    parts = [t0 + step * np.arange(n + 1), [t1], motion.knots(), edges, np.nextafter(edges, -np.inf), np.nextafter(edges, np.inf)]
    t = np.unique(np.concatenate([np.asarray(x, float).ravel() for x in parts]))
    return t[(t >= t0) & (t <= t1)]


def lased_time_s(run: MotionRun, t) -> np.ndarray:
    """Lased seconds from the scenario's start to each time (sorted times)."""
    t = np.asarray(t, float)
    w = run.motion.windows
    if w.intervals is None:
        return t - run.motion.t_start_s
    a, b = w.intervals[:, 0], w.intervals[:, 1]
    return np.clip(t[:, None] - a[None], 0.0, (b - a)[None]).sum(axis=1)


# -- beam states -------------------------------------------------------------------------
def _moved_target(t, d):
    """Target ``t`` displaced by ``d`` [m] (mesh, centre and analytic centre)."""
    mesh = dataclasses.replace(t.mesh, vertices=t.mesh.vertices + d)
    if mesh.analytic is not None:
        mesh.analytic = (mesh.analytic[0], np.asarray(mesh.analytic[1], float) + d, *mesh.analytic[2:])
    return dataclasses.replace(t, mesh=mesh, center_m=np.asarray(t.center_m, float) + d)


def _scene_at(scene, motion, t: float, direction):
    """The scene with the aim and the targets' positions at time t."""
    targets = list(scene.targets)
    for tt in motion.target_tracks:
        targets[tt.index] = _moved_target(targets[tt.index], tt.at(t)[0])
    return dataclasses.replace(scene, laser_direction=np.asarray(direction, float), targets=targets)


def _key_times(run: MotionRun, grid: np.ndarray) -> tuple[np.ndarray, str]:
    """Key times where the beam is traced: the spot moves at most half its 1/e diameter at
    the target between them (aim turn x range, and the targets' displacement)."""
    motion, scene = run.motion, run.scene
    if not motion.beam_moves:
        return np.array([motion.t_start_s]), "the beam and targets do not move: one beam state"
    la = scene.spec.laser
    rng = min((float(np.linalg.norm(t.center_m - scene.laser_position_m)) for t in scene.targets), default=1.0)
    allow = 0.5 * max(la.beam_diameter_m + rng * la.divergence_rad, 1e-6)
    u = run.nominal_direction(grid)
    turn = np.concatenate([[0.0], np.arccos(np.clip(np.einsum("ij,ij->i", u[1:], u[:-1]), -1, 1))]) * rng
    for tt in motion.target_tracks:
        turn = turn + np.concatenate([[0.0], np.linalg.norm(np.diff(tt.at(grid), axis=0), axis=1)])
    moved = np.cumsum(turn)
    n = int(math.ceil(moved[-1] / allow)) + 1
    coarse = n > BEAM_STATES_MAX
    n = min(n, BEAM_STATES_MAX)
    marks = np.linspace(0.0, moved[-1], n) if moved[-1] > 0 else np.zeros(1)
    idx = np.unique(np.searchsorted(moved, marks).clip(0, len(grid) - 1))
    step = moved[-1] / max(len(idx) - 1, 1)
    text = (f"{len(idx)} beam state(s) traced; the spot moves {step:.3g} m between them "
            f"({step / (2 * allow):.3g} 1/e beam diameters at the nearest target, {rng:.4g} m)")
    if coarse:
        text += f" - capped at {BEAM_STATES_MAX} states: coarser than the half-diameter step asked"
    return grid[idx], text


def beam_states(run: MotionRun, grid: np.ndarray, first) -> None:
    """Trace the beam at the key times (``first``: the static analysis's own trace, used
    when nothing moves)."""
    from hazard.pipeline import spots as beam_stage

    run.key_times_s, run.key_step_text = _key_times(run, grid)
    if not run.motion.beam_moves:
        traced, tracer, ray_scene = first
        run.states_list = [BeamState(float(run.key_times_s[0]), np.asarray(run.scene.laser_direction, float), run.scene,
                                     traced.built.spots, tracer, ray_scene)]
        return
    out = []
    moving = bool(run.motion.target_tracks)
    _, tracer0, ray0 = first
    for t in run.key_times_s:
        u = run.nominal_direction(t)[0]
        sc = _scene_at(run.scene, run.motion, float(t), u)
        ray_scene, tracer = ray0, tracer0
        if moving:
            ray_scene = beam_stage.ray_scene(sc, run.backend, run.threads) if ray0 is not None else None
            tracer = ray_scene if ray_scene is not None else beam_stage.FlatScene(sc.targets)
        traced = beam_stage.trace_beam(sc, tracer, run.mu)
        out.append(BeamState(float(t), u, sc, traced.built.spots, tracer, ray_scene))
    run.states_list = out


# -- irradiance at samples -------------------------------------------------------------
def gaussian_along_w_m2(beam, u, p, mu) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The Gaussian beam of ``beam`` (:class:`hazard.physics.beam.BeamGeometry`: power, diameter,
    divergence, aperture) pointed along unit directions ``u`` (N, 3) or (3,), at points
    ``p`` (N, 3): its irradiance [W/m^2] (:meth:`~hazard.physics.beam.BeamGeometry.irradiance_w_m2`,
    attenuated along the path; 0 behind the aperture), 1/e radius [m] and path [m]."""
    rel = np.asarray(p, float) - beam.position_m
    z = rel @ u if np.ndim(u) == 1 else np.einsum("ij,ij->i", rel, u)
    dist = np.linalg.norm(rel, axis=1)
    w = beam.diameter_at(np.maximum(z, 0.0)) / 2
    s = np.stack([np.sqrt(np.maximum(dist**2 - z**2, 0.0)) / w, np.zeros_like(z)], axis=1)
    e = beam.irradiance_w_m2(s, np.maximum(z, 0.0)) * np.exp(-mu * dist)
    return np.where(z > 0, e, 0.0), w, dist


def blocked(tracer, origin, p, dist) -> np.ndarray:
    """Whether something of ``tracer`` lies on the segment from ``origin`` to each point."""
    hits = tracer.first_hit(np.broadcast_to(origin, (len(p), 3)), p - origin)
    return hits.hit & (hits.t < dist * (1 - 1e-9))


def _direct_w_m2(run: MotionRun, p, t, state_idx, optics) -> np.ndarray:
    """The direct beam at points ``p`` (N, 3) at times ``t`` (see the module notes),
    through the limiting aperture or the aid's collecting disk (:mod:`hazard.physics.aperture`)."""
    beam = run.beam
    assert beam is not None, "the motion stage's run carries the static analysis's beam"
    u = run.direction(t)
    e, w, dist = gaussian_along_w_m2(beam, u, p, run.mu)
    z = np.einsum("ij,ij->i", np.asarray(p, float) - beam.position_m, np.broadcast_to(u, np.shape(p)))
    r = np.sqrt(np.maximum(dist**2 - z**2, 0.0))
    spec = run.scene.spec
    ap = observer_apertures([optics], np.zeros(len(e), int), spec.laser.wavelength_nm, spec.exposure.duration_s)
    tilt = np.sqrt(1.0 + (r / w) ** 2 * (beam.divergence_rad / 2) ** 2)
    through = aperture_irradiance_w_m2(beam.power_w * np.exp(-run.mu * dist) * tilt, w, r, ap)
    e = np.where(run.motion.windows.lased(t) & (z > 0), through, 0.0)
    live = np.flatnonzero(e > 0)
    for k in np.unique(state_idx[live]):
        rows = live[state_idx[live] == k]
        e[rows] = np.where(blocked(run.states_list[k].tracer, beam.position_m, p[rows], dist[rows]), 0.0, e[rows])
    return e


def _state_columns(run: MotionRun, tau) -> tuple[np.ndarray, np.ndarray]:
    """For dwell times ``tau``: the two bracketing history rows (clamped to the history)."""
    ht = run.history_times_s
    j1 = np.clip(np.searchsorted(ht, tau), 0, len(ht) - 1)
    return np.maximum(j1 - 1, 0), j1


def _spot_w_m2(run: MotionRun, sp, p, gain, tau, los, ray_scene) -> np.ndarray:
    """One spot's irradiance at points (N, 3) with dwell times ``tau`` (N,): the BRDF lobe
    with the spot's line of sight ``los``, the mirror lobe with each point's own from its
    reflection point (``ray_scene``; None: every line clear)."""
    st = run.states.get(sp.target.index)
    g = np.full(len(p), gain)
    if st is None:
        e, _ = spot_irradiance(sp, p, g, run.mu, None, los)
        if sp.material.has_specular:
            e = e + specular_irradiance(sp, p, g, run.mu, None, None, ray_scene=ray_scene)
        return e
    j0, j1 = _state_columns(run, tau)
    # the whole history (a slumping spot pairs each state with its own tilt), then each row's two columns
    e, _ = spot_irradiance(sp, p, g, run.mu, st, los)
    if sp.material.has_specular:
        e = e + specular_irradiance(sp, p, g, run.mu, None, st, ray_scene=ray_scene)
    rows = np.arange(len(p))
    return np.maximum(e[rows, j0], e[rows, j1])


def _reflected_w_m2(run: MotionRun, p, t, state_idx, gain, tau) -> np.ndarray:
    """Every spot's reflection at points ``p`` at times ``t`` (lased only)."""
    out = np.zeros(len(p))
    lased = run.motion.windows.lased(t)
    for k in np.unique(state_idx[lased]):
        rows = np.flatnonzero(lased & (state_idx == k))
        bs = run.states_list[k]
        for sp in bs.spots:
            if bs.ray_scene is not None:
                los = spot_line_of_sight(bs.ray_scene, sp, p[rows])[0]
            else:
                los = np.ones(len(rows), bool)
            out[rows] += _spot_w_m2(run, sp, p[rows], gain, tau[rows], los.astype(float), bs.ray_scene)
    return out


def _dwell_s(run: MotionRun, t) -> np.ndarray:
    """Dwell time [s] of the spot at each time (see the module notes)."""
    lased = lased_time_s(run, t)
    if not run.motion.beam_moves or not run.states:
        return lased
    k = run.state_index(t)
    lk = lased_time_s(run, run.key_times_s)
    return _key_dwell_s(run)[k] + np.maximum(lased - lk[k], 0.0)


def _key_dwell_s(run: MotionRun) -> np.ndarray:
    """Per beam state, the lased time the surface now under the spot's centre has spent
    under the spot before this state: the earlier states whose centre lies within the
    spot's radius of it, each for its own lased interval (made once per run)."""
    if run.dwell_keys_s is not None:
        return run.dwell_keys_s
    lk = lased_time_s(run, run.key_times_s)
    held = np.diff(lk)  # lased seconds each state is held for, up to the next key time
    c = np.array([_spot_centre(run, bs) for bs in run.states_list])
    r = np.array([_spot_radius(bs) for bs in run.states_list])
    dwell = np.zeros(len(c))
    for i in range(1, len(c)):
        near = np.linalg.norm(c[:i] - c[i], axis=1) <= r[i]  # NaN (no spot then) is never near
        dwell[i] = float(held[:i][near].sum())
    run.dwell_keys_s = dwell
    return dwell


def _spot_centre(run, bs) -> np.ndarray:
    """The first spot's centroid in its target's own frame (the target's displacement taken off)."""
    if not bs.spots:
        return np.full(3, np.nan)
    sp = bs.spots[0]
    d = next((tt.at(bs.time_s)[0] for tt in run.motion.target_tracks if tt.index == sp.target.index), np.zeros(3))
    return np.asarray(sp.centroid, float) - d


def _spot_radius(bs) -> float:
    return 0.5 * max(bs.spots[0].size_m, 1e-9) if bs.spots else 0.0


def evaluate(run: MotionRun, positions, t, optics) -> tuple[np.ndarray, np.ndarray]:
    """Direct and reflected irradiance [W/m^2] at ``positions`` (N, 3) at times ``t``."""
    k = run.state_index(t)
    gain = 1.0 if optics is None else optical_gain(optics.magnification, optics.objective_diameter_m, optics.transmission)
    direct = _direct_w_m2(run, positions, t, k, optics)
    reflected = _reflected_w_m2(run, positions, t, k, gain, _dwell_s(run, t)) if any(bs.spots for bs in run.states_list) else np.zeros(len(t))
    return direct, reflected
