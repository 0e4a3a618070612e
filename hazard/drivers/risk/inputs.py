"""The random inputs of a risk analysis: what is uncertain, drawn how (``[uncertainty]``).

Every input has a name (the sensitivity analysis and the report use it) and a stated
distribution:

- ``pointing``: the beam axis error ``e = bias + N(0, sigma^2 I)`` in the beam's
  (right, up) tangent plane [rad]: the axis becomes ``normalize(a + e_r r + e_u u)``.
- ``material``: per target a log-normal BRDF scale ``exp(sigma z)`` (median 1), ``z``
  correlated across targets by rho (``z_t = sqrt(rho) z_0 + sqrt(1 - rho) z_t'``); and
  one of a set of materials per target, drawn with its weights.
- ``tilt``: per plate or disk target a surface-normal tilt ``delta ~ N(0, sigma^2 I)`` in
  the target's (tangent, normal x tangent) plane [rad], the normal becoming
  ``normalize(n + d_1 t_1 + d_2 t_2)``; with a correlation time tau the tilt wanders as
  a stationary Ornstein-Uhlenbeck process over the exposure (exact discretisation
  ``x_{j+1} = rho x_j + sqrt(1 - rho^2) sigma xi``, ``rho = exp(-dt / tau)``).
- ``visibility``: the meteorological visibility per operation, hence the attenuation.
- ``scintillation``: per point and path (direct, mirror) a standard normal ``z`` of the
  log-normal irradiance factor (:mod:`hazard.drivers.risk.physics`).
- ``observer_position``: per observer a Gaussian offset (horizontal per axis, height).

Draws are made group by group in a fixed order from one generator per chunk of draws, so
the same seed gives the same draws wherever a chunk runs.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields, replace

import numpy as np

__all__ = ["InputModel", "Draws", "GROUPS", "input_model"]

GROUPS = ("pointing", "material", "tilt", "visibility", "scintillation", "observer_position")


@dataclass
class Draws:
    """n draws of every active input (None: not uncertain). ``log_weight`` (n,) is
    ln(p/q) of importance sampling (0 for plain draws); ``component`` (n,) the proposal
    component each came from (0: the stated distributions)."""

    n: int
    pointing_rad: np.ndarray | None = None  # (n, 2) [right, up]
    scale_z: np.ndarray | None = None  # (n, T) standard normals of ln(scale) / sigma
    material_index: np.ndarray | None = None  # (n, T) int, -1: the scene's material
    tilt_rad: np.ndarray | None = None  # (n, T, K, 2) per target and wander node
    visibility_km: np.ndarray | None = None  # (n,)
    scint_z: np.ndarray | None = None  # (n, 2, M): direct, mirror
    offset_m: np.ndarray | None = None  # (n, M_obs, 3)
    log_weight: np.ndarray | None = None
    component: np.ndarray | None = None

    _GROUP_FIELDS = {"pointing": ("pointing_rad",), "material": ("scale_z", "material_index"), "tilt": ("tilt_rad",),
                     "visibility": ("visibility_km",), "scintillation": ("scint_z",), "observer_position": ("offset_m",)}

    def with_group(self, other: "Draws", group: str) -> "Draws":
        """These draws with input group ``group`` taken from ``other`` (pick-freeze)."""
        return replace(self, **{f: getattr(other, f) for f in self._GROUP_FIELDS[group]})

    def take(self, rows) -> "Draws":
        """The draws ``rows`` (an index array or a slice)."""
        out = {}
        for f in fields(self):
            v = getattr(self, f.name)
            out[f.name] = v[rows] if isinstance(v, np.ndarray) else v
        out["n"] = len(np.arange(self.n)[rows])
        return Draws(**out)


@dataclass(frozen=True)
class InputModel:
    """The scene's ``[uncertainty]`` resolved against its targets and points."""

    n_targets: int
    n_points: int  # observers first, then the map's cells
    n_observers: int
    pointing_sigma_rad: float
    pointing_bias_rad: tuple
    scale_sigma: float
    scale_rho: float
    choices: tuple  # per target: None, or the weights (normalised) of its alternative materials
    tilt_sigma_rad: float
    tilt_targets: tuple  # indices of the targets that tilt (plates and disks)
    wander_times_s: tuple | None  # the wander's nodes [s]; None: one tilt per operation
    wander_tau_s: float | None
    visibility: object  # VisibilityDistributionSpec | None
    scintillation: bool
    position_sigma_m: float
    height_sigma_m: float

    def active(self) -> list:
        """The input groups that vary between draws (the bias alone is not random)."""
        on = {"pointing": self.pointing_sigma_rad > 0, "material": self.scale_sigma > 0 or any(c is not None for c in self.choices),
              "tilt": self.tilt_sigma_rad > 0 and bool(self.tilt_targets), "visibility": self.visibility is not None,
              "scintillation": self.scintillation, "observer_position": (self.position_sigma_m > 0 or self.height_sigma_m > 0)
              and self.n_observers > 0}
        return [g for g in GROUPS if on[g]]

    @property
    def n_nodes(self) -> int:
        return 1 if self.wander_times_s is None else len(self.wander_times_s)

    def draw(self, rng: np.random.Generator, n: int) -> Draws:
        """n draws from the stated distributions (fixed order: see the module notes)."""
        d = Draws(n, log_weight=np.zeros(n), component=np.zeros(n, np.int64))
        if self.pointing_sigma_rad > 0 or any(self.pointing_bias_rad):
            d.pointing_rad = np.asarray(self.pointing_bias_rad, float) + self.pointing_sigma_rad * rng.standard_normal((n, 2))
        if self.scale_sigma > 0:
            z0 = rng.standard_normal((n, 1))
            zt = rng.standard_normal((n, self.n_targets))
            d.scale_z = math.sqrt(self.scale_rho) * z0 + math.sqrt(1.0 - self.scale_rho) * zt
        if any(c is not None for c in self.choices):
            d.material_index = np.full((n, self.n_targets), -1, np.int64)
            for t, w in enumerate(self.choices):
                if w is not None:
                    d.material_index[:, t] = rng.choice(len(w), size=n, p=np.asarray(w))
        if self.tilt_sigma_rad > 0 and self.tilt_targets:
            d.tilt_rad = self._tilts(rng, n)
        if self.visibility is not None:
            d.visibility_km = draw_visibility(self.visibility, rng, n)
        if self.scintillation:
            d.scint_z = rng.standard_normal((n, 2, self.n_points))
        if self.position_sigma_m > 0 or self.height_sigma_m > 0:
            off = rng.standard_normal((n, self.n_observers, 3))
            d.offset_m = off * np.array([self.position_sigma_m, self.position_sigma_m, self.height_sigma_m])
        return d

    def _tilts(self, rng, n) -> np.ndarray:
        """(n, T, K, 2) tilts: zero on targets that do not tilt; an OU path over the nodes."""
        k = self.n_nodes
        out = np.zeros((n, self.n_targets, k, 2))
        x = self.tilt_sigma_rad * rng.standard_normal((n, len(self.tilt_targets), 2))
        path = [x]
        times = self.wander_times_s or (0.0,)
        for j in range(1, k):
            rho = math.exp(-(times[j] - times[j - 1]) / self.wander_tau_s)
            x = rho * x + math.sqrt(max(1.0 - rho * rho, 0.0)) * self.tilt_sigma_rad * rng.standard_normal(x.shape)
            path.append(x)
        out[:, list(self.tilt_targets)] = np.stack(path, axis=2)
        return out


def draw_visibility(spec, rng, n) -> np.ndarray:
    """n visibilities [km] from a :class:`scenes.spec.VisibilityDistributionSpec`."""
    if spec.distribution == "lognormal":
        return spec.median_km * np.exp(spec.sigma * rng.standard_normal(n))
    if spec.distribution == "uniform":
        return rng.uniform(spec.low_km, spec.high_km, n)
    w = np.asarray(spec.weights, float)
    return np.asarray(spec.values_km, float)[rng.choice(len(w), size=n, p=w / w.sum())]


def _wander_times(u, scene, times_s) -> tuple | None:
    """The wander's nodes: the analysis times (dynamic) or the exposure, spaced at a
    quarter of the correlation time, at most ``wander_nodes`` of them."""
    if u.normal_wander_correlation_time_s is None:
        return None
    tau, cap = u.normal_wander_correlation_time_s, u.wander_nodes
    if len(times_s) > 1:
        idx = np.unique(np.round(np.linspace(0, len(times_s) - 1, min(cap, len(times_s)))).astype(int))
        return tuple(float(t) for t in np.asarray(times_s)[idx])
    t_end = scene.spec.exposure.duration_s
    k = int(min(cap, max(2, math.ceil(4 * t_end / tau) + 1)))
    return tuple(float(t) for t in np.linspace(0.0, t_end, k))


def input_model(scene, n_points: int, n_observers: int, times_s) -> InputModel:
    """The :class:`InputModel` of ``scene``'s ``[uncertainty]`` for ``n_points`` points
    (its ``n_observers`` observers first)."""
    u = scene.spec.uncertainty
    names = [t.name for t in scene.targets]
    choices = [None] * len(names)
    for c in u.materials:
        w = np.ones(len(c.materials)) if c.weights is None else np.asarray(c.weights, float)
        choices[names.index(c.target)] = tuple(float(x) for x in w / w.sum())
    tilt_targets = tuple(i for i, t in enumerate(scene.targets) if t.spec.shape in ("plate", "disk"))
    return InputModel(
        n_targets=len(names), n_points=n_points, n_observers=n_observers,
        pointing_sigma_rad=u.pointing_sigma_rad, pointing_bias_rad=tuple(u.pointing_bias_rad),
        scale_sigma=u.brdf_scale_sigma, scale_rho=u.brdf_scale_correlation, choices=tuple(choices),
        tilt_sigma_rad=math.radians(u.normal_tilt_sigma_deg), tilt_targets=tilt_targets,
        wander_times_s=_wander_times(u, scene, times_s), wander_tau_s=u.normal_wander_correlation_time_s,
        visibility=u.visibility, scintillation=u.scintillation is not None,
        position_sigma_m=u.observer_position_sigma_m, height_sigma_m=u.observer_height_sigma_m)
