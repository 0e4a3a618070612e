"""Importance sampling toward the hazardous directions, for exceedance probabilities far
below 1/draws (Owen & Zhou, "Safe and effective importance sampling", JASA 95:135, 2000:
the defensive mixture).

The proposal is a mixture: with weight ``alpha_0 = 1/2`` the stated distributions, and
with the rest, shared equally, components that move one 2-D input toward a direction in
which the beam lands on a point:

- **direct**: the pointing error that puts the axis on the point (the direction to it in
  the beam's (right, up) tangent plane);
- **mirror by pointing**: the pointing error that puts a flat mirror's reflected beam on
  the point (aim at the point's image in the mirror plane: exact for the plane, kept
  when the aim lands on the mirror);
- **mirror by tilt**: the normal tilt of a flat mirror that reflects the nominal beam onto
  the point (the normal along the bisector of the reversed incidence and the direction
  to the point).

A component's spread is the angular size of the hazardous region (the beam's 1/e angle
times sqrt(ln(E0/MPE)), a tilt half of it, widened by an observer's position uncertainty),
at most the stated sigma. Only points whose on-axis irradiance could exceed the MPE (with
the strongest optics of the scene), that plain draws would rarely reach (the Rice chance
of landing within the spread, ``ncx2.cdf((sd/sigma)^2, 2, (d/sigma)^2)``, below 1e-2) and
that lie within 6.5 sigma of the mean get one; nearby directions share one; at most 64, the
observers' first (the map's cells take at most 8 beside them).

Each draw carries the weight ``w = p(x) / q(x) = 1 / (alpha_0 + sum_c alpha_c N_c(x_b)/p(x_b))``
over the moved input: the estimate ``mean(w 1{E > MPE})`` is unbiased whatever the
components are (they change only its variance), and ``w <= 1/alpha_0 = 2`` bounds the
variance at twice plain sampling's for any point the components do not help.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from hazard.physics.engine import specular_power_w
from hazard.drivers.risk.inputs import Draws

__all__ = ["Component", "Proposal", "proposal"]

ALPHA0 = 0.5
MAX_COMPONENTS = 64
MAP_COMPONENTS_BESIDE_OBSERVERS = 8  # the map's share when observers have components of their own
RARE_BELOW, FAR_SIGMAS = 1e-2, 6.5  # a component where plain draws would rarely land (Rice), out to 6.5 sigma


@dataclass(frozen=True)
class Component:
    """Moves ``block`` ("pointing", or "tilt" of target ``target``) to N(mean, sd^2 I)."""

    block: str
    target: int
    mean: tuple
    sd: float
    why: str


@dataclass(frozen=True)
class Proposal:
    components: tuple
    alpha0: float = ALPHA0

    def draw(self, model, rng, n: int) -> Draws:
        """n draws from the mixture (the stated distributions first, then the moves) and their weights."""
        d = model.draw(rng, n)
        c = len(self.components)
        if not c:
            return d
        probs = np.array([self.alpha0] + [(1 - self.alpha0) / c] * c)
        comp = rng.choice(c + 1, size=n, p=probs)
        z = rng.standard_normal((n, 2))
        d.component = comp
        for j, cp in enumerate(self.components, 1):
            rows = np.flatnonzero(comp == j)
            x = np.asarray(cp.mean) + cp.sd * z[rows]
            if cp.block == "pointing":
                d.pointing_rad[rows] = x
            else:
                d.tilt_rad[rows, cp.target, 0] = x
        d.log_weight = self.log_weight(model, d, probs)
        return d

    def log_weight(self, model, d: Draws, probs) -> np.ndarray:
        """ln(p/q) per draw."""
        terms = [np.full(d.n, math.log(probs[0]))]
        for j, cp in enumerate(self.components, 1):
            if cp.block == "pointing":
                x, m0, s0 = d.pointing_rad, np.asarray(model.pointing_bias_rad), model.pointing_sigma_rad
            else:
                x, m0, s0 = d.tilt_rad[:, cp.target, 0], np.zeros(2), model.tilt_sigma_rad
            lq = -((x - np.asarray(cp.mean)) ** 2).sum(1) / (2 * cp.sd**2) - 2 * math.log(cp.sd)
            lp = -((x - m0) ** 2).sum(1) / (2 * s0**2) - 2 * math.log(s0)
            terms.append(math.log(probs[j]) + lq - lp)
        t = np.stack(terms, axis=1)
        top = t.max(axis=1)
        return -(top + np.log(np.exp(t - top[:, None]).sum(axis=1)))


def _spread(theta_w, e0, limit, sigma, theta_pos=0.0):
    """Angular size of the hazardous region, widened by the observer's position
    uncertainty ``theta_pos`` seen at its distance (at most sigma); None when it cannot
    be hazardous."""
    if not e0 > limit:
        return None
    theta_h = theta_w * math.sqrt(math.log(e0 / limit))
    return min(sigma, math.hypot(max(theta_h, 0.5 * theta_w), theta_pos))


def _position_angle(ev, j, distance_m) -> float:
    """The observer's position uncertainty [rad] seen from ``distance_m`` (0 for map cells)."""
    m = ev.model
    return math.hypot(m.position_sigma_m, m.height_sigma_m) / max(distance_m, 1e-9) if j < ev.n_observers else 0.0


@dataclass
class _Cands:
    """Candidate components as arrays, in the order the points and mirrors are visited:
    block (0 pointing, 1 tilt), target index, mean (N, 2), sd (N,), point j, and the
    sentence ``why`` (``whys[kind]``: the text before and after the point's name)."""

    block: np.ndarray
    k: np.ndarray
    mean: np.ndarray
    sd: np.ndarray
    j: np.ndarray
    why: np.ndarray
    whys: list

    @staticmethod
    def empty() -> _Cands:
        return _Cands(np.zeros(0, int), np.zeros(0, int), np.zeros((0, 2)), np.zeros(0), np.zeros(0, int), np.zeros(0, int), [])

    def __add__(self, o: _Cands) -> _Cands:
        n = len(self.whys)
        return _Cands(*(np.concatenate([x, y]) for x, y in ((self.block, o.block), (self.k, o.k), (self.mean, o.mean), (self.sd, o.sd),
                                                           (self.j, o.j), (self.why, o.why + n))), self.whys + o.whys)

    def take(self, rows) -> _Cands:
        return _Cands(self.block[rows], self.k[rows], self.mean[rows], self.sd[rows], self.j[rows], self.why[rows], self.whys)


def _dot(v, a) -> np.ndarray:
    """Row-wise v @ a, bit for bit as the 1-D dot of each row (the sum of the three products in order)."""
    return (v * np.asarray(a, float)).sum(axis=1)


def _in_tangents(v, axis, right, up):
    """Tangent-plane coordinates (N, 2) of unit directions v (N, 3) and where they are in front of the axis."""
    c = _dot(v, axis)
    front = c > 1e-9
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.column_stack([_dot(v, right) / c, _dot(v, up) / c]), front


def _spreads(ev, js, theta_w, e0, limit, sigma, dist_m) -> np.ndarray:
    """:func:`_spread` of each point (scalar arithmetic, Python's math, as one point at a time); NaN where None."""
    out = [_spread(tw, e, limit, sigma, _position_angle(ev, j, d)) for j, tw, e, d in
           zip(js.tolist(), theta_w.tolist(), e0.tolist(), dist_m.tolist())]
    return np.array([np.nan if x is None else x for x in out], float)


def _exp(x: np.ndarray) -> np.ndarray:
    return np.array([math.exp(v) for v in x.tolist()], float)


def _make(block, k, mean, sd, js, kind, whys) -> _Cands:
    n = len(js)
    return _Cands(np.full(n, block), np.full(n, k), mean.reshape(n, 2), sd, js, np.full(n, kind), whys)


def _direct(ev, p, limit) -> _Cands:
    beam = ev.nominal.beam
    rel = p - beam.position_m
    r = np.linalg.norm(rel, axis=1)
    mean, front = _in_tangents(rel / r[:, None], beam.axis, ev.right, ev.up)
    w = (beam.diameter_m + r * beam.divergence_rad) / 2
    e0 = beam.power_w / (math.pi * w * w) * _exp(-ev.mu0 * r)
    js = np.arange(len(p))
    sd = _spreads(ev, js, w / r, e0, limit, ev.model.pointing_sigma_rad, r)
    ok = front & np.isfinite(sd)
    return _make(0, -1, mean[ok], sd[ok], js[ok], 0, [("direct beam on ", "")])


def _flat_mirrors(ev):
    for sp in ev.nominal.spots:
        if sp.material.has_specular and sp.target.spec.shape in ("plate", "disk") and sp.total_power_w > 0:
            frac = float(np.max(specular_power_w(sp, ev.nominal.states.get(sp.target.index)))) / sp.total_power_w
            yield sp, frac * math.exp(3 * ev.model.scale_sigma)


def _on_plates(t, x) -> np.ndarray:
    q = x - t.center_m
    a, b = _dot(q, t.tangent), _dot(q, np.cross(t.normal, t.tangent))
    s = t.spec.size_m
    return (np.abs(a) <= s[0] / 2) & (np.abs(b) <= s[1] / 2) if t.spec.shape == "plate" else a * a + b * b <= (s[0] / 2) ** 2


def _mirror(ev, p, limit) -> _Cands:
    """Per flat mirror, per point: the pointing that puts its mirror beam on the point,
    then the tilt that does (in that order, point by point)."""
    beam, lp, out, js = ev.nominal.beam, ev.nominal.beam.position_m, _Cands.empty(), np.arange(len(p))
    m = ev.model
    for sp, frac in _flat_mirrors(ev):
        t, c = sp.target, sp.centroid
        n = t.normal
        image = p - (2 * _dot(p - c, n))[:, None] * n
        rel = image - lp
        L = np.linalg.norm(rel, axis=1)
        w = (beam.diameter_m + L * beam.divergence_rad) / 2
        e0 = frac * beam.power_w / (math.pi * w * w) * _exp(-ev.mu0 * L)
        den = _dot(rel, n)
        parts = []
        if m.pointing_sigma_rad > 0:
            with np.errstate(divide="ignore", invalid="ignore"):
                hit = lp + rel * (float((c - lp) @ n) / den)[:, None]
            mean, front = _in_tangents(rel / L[:, None], beam.axis, ev.right, ev.up)
            sd = _spreads(ev, js, w / L, e0, limit, m.pointing_sigma_rad, L)
            ok = (np.abs(den) > 1e-12) & front & np.isfinite(sd) & _on_plates(t, hit)
            parts.append((js[ok] * 2, _make(0, -1, mean[ok], sd[ok], js[ok], 0, [(f"{t.name}'s mirror beam on ", " (pointing)")])))
        if t.index in m.tilt_targets and m.tilt_sigma_rad > 0 and m.wander_times_s is None:
            qc = p - c
            l2 = np.linalg.norm(qc, axis=1)
            n2 = qc / l2[:, None] - sp.mean_incoming
            n2 = n2 / np.linalg.norm(n2, axis=1)[:, None]
            n2 = np.where((_dot(n2, n) > 0)[:, None], n2, -n2)
            delta = np.column_stack([_dot(n2, t.tangent), _dot(n2, np.cross(n, t.tangent))]) / _dot(n2, n)[:, None]
            l2 = np.maximum(l2, 1e-9)
            sd = _spreads(ev, js, w / l2, e0, limit, 2 * m.tilt_sigma_rad, l2)
            ok = np.isfinite(sd)
            parts.append((js[ok] * 2 + 1, _make(1, t.index, delta[ok], sd[ok] / 2, js[ok], 0, [(f"{t.name}'s mirror beam on ", " (tilt)")])))
        if parts:
            both = parts[0][1] if len(parts) == 1 else parts[0][1] + parts[1][1]
            order = np.argsort(np.concatenate([q for q, _ in parts]), kind="stable")
            out = out + both.take(order)
    return out


def _keep(cands: _Cands, model, n_observers: int, name) -> list:
    """Candidates plain draws would rarely reach (Rice chance of landing within the spread
    below 1e-2) out to 6.5 sigma, one per cell of their own spread, at most 64: the
    observers' first (they are people), then the map's, evenly over the distance."""
    people = _pick(_distinct(cands.take(cands.j < n_observers), model, name), MAX_COMPONENTS)
    room = MAX_COMPONENTS - len(people) if not people else min(MAP_COMPONENTS_BESIDE_OBSERVERS, MAX_COMPONENTS - len(people))
    return people + _pick(_distinct(cands.take(cands.j >= n_observers), model, name), room)


def _pick(kept, n) -> list:
    if len(kept) > n:
        kept = [kept[i] for i in np.unique(np.linspace(0, len(kept) - 1, n).round().astype(int))] if n > 0 else []
    return [c for _, c in kept]


def _distinct(c: _Cands, model, name) -> list:
    """The rare and near candidates, the first of each cell of its own spread, nearest the
    stated mean first (ties in the candidates' order): (distance in sigmas, Component)."""
    from scipy.stats import ncx2

    if not len(c.sd):
        return []
    tilt = c.block == 1
    m0 = np.where(tilt[:, None], 0.0, np.asarray(model.pointing_bias_rad, float))
    s0 = np.where(tilt, model.tilt_sigma_rad, model.pointing_sigma_rad)
    dist = np.linalg.norm(c.mean - m0, axis=1) / s0
    rough = ncx2.cdf((c.sd / s0) ** 2, 2, dist**2)  # the chance of landing within sd of the mean (spec section 8)
    ok = np.flatnonzero((RARE_BELOW > rough) & (dist <= FAR_SIGMAS))
    key = np.column_stack([c.block[ok], c.k[ok], np.round(c.mean[ok] / c.sd[ok, None])]).astype(np.int64)
    _, first = np.unique(key, axis=0, return_index=True)  # the first candidate of each cell
    rows = ok[np.sort(first)]
    rows = rows[np.argsort(dist[rows], kind="stable")]
    return [(float(dist[i]), Component("pointing" if c.block[i] == 0 else "tilt", int(c.k[i]), (float(c.mean[i, 0]), float(c.mean[i, 1])),
                                       float(c.sd[i]), name(int(c.j[i])).join(c.whys[c.why[i]]))) for i in rows]


def proposal(ev) -> Proposal:
    """The mixture for ``ev``'s scene (deterministic: every process builds the same one)."""
    m = ev.model
    gain = float(ev.own_gain().max()) if len(ev.points_m) else 1.0
    limit = ev.mpe_w_m2 / gain
    cands = _Cands.empty()
    if m.pointing_sigma_rad > 0 and len(ev.points_m):
        cands = cands + _direct(ev, ev.points_m, limit)
    if (m.pointing_sigma_rad > 0 or m.tilt_sigma_rad > 0) and ev.nominal.spots and len(ev.points_m):
        cands = cands + _mirror(ev, ev.points_m, limit)
    return Proposal(tuple(_keep(cands, m, ev.n_observers, ev.point_name)))
