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

from ..engine import specular_power_w
from .inputs import Draws

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


def _in_tangent(v, axis, right, up):
    """Tangent-plane coordinates (right, up) of direction v about ``axis``; None behind it."""
    c = float(v @ axis)
    return None if c <= 1e-9 else np.array([v @ right, v @ up]) / c


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


def _direct(ev, p, limit) -> list:
    beam, out = ev.nominal.beam, []
    for j, q in enumerate(p):
        rel = q - beam.position_m
        r = float(np.linalg.norm(rel))
        mean = _in_tangent(rel / r, beam.axis, ev.right, ev.up)
        w = float(beam.diameter_at(r)) / 2
        sd = _spread(w / r, beam.power_w / (math.pi * w * w) * math.exp(-ev.mu0 * r), limit, ev.model.pointing_sigma_rad,
                     _position_angle(ev, j, r))
        if mean is not None and sd is not None:
            out.append(("pointing", -1, mean, sd, f"direct beam on {ev.point_name(j)}", j))
    return out


def _flat_mirrors(ev):
    for sp in ev.nominal.spots:
        if sp.material.has_specular and sp.target.spec.shape in ("plate", "disk") and sp.total_power_w > 0:
            frac = float(np.max(specular_power_w(sp, ev.nominal.states.get(sp.target.index)))) / sp.total_power_w
            yield sp, frac * math.exp(3 * ev.model.scale_sigma)


def _on_plate(t, x) -> bool:
    q = x - t.center_m
    a, b = q @ t.tangent, q @ np.cross(t.normal, t.tangent)
    s = t.spec.size_m
    return (abs(a) <= s[0] / 2 and abs(b) <= s[1] / 2) if t.spec.shape == "plate" else a * a + b * b <= (s[0] / 2) ** 2


def _mirror(ev, p, limit) -> list:
    beam, lp, out = ev.nominal.beam, ev.nominal.beam.position_m, []
    for sp, frac in _flat_mirrors(ev):
        t, c = sp.target, sp.centroid
        n = t.normal
        for j, q in enumerate(p):
            image = q - 2 * float((q - c) @ n) * n
            rel = image - lp
            L = float(np.linalg.norm(rel))
            w = float(beam.diameter_at(L)) / 2
            e0 = frac * beam.power_w / (math.pi * w * w) * math.exp(-ev.mu0 * L)
            den = float(rel @ n)
            if ev.model.pointing_sigma_rad > 0 and abs(den) > 1e-12:
                hit = lp + rel * (float((c - lp) @ n) / den)
                mean = _in_tangent(rel / L, beam.axis, ev.right, ev.up)
                sd = _spread(w / L, e0, limit, ev.model.pointing_sigma_rad, _position_angle(ev, j, L))
                if mean is not None and sd is not None and _on_plate(t, hit):
                    out.append(("pointing", -1, mean, sd, f"{t.name}'s mirror beam on {ev.point_name(j)} (pointing)", j))
            if t.index in ev.model.tilt_targets and ev.model.tilt_sigma_rad > 0 and ev.model.wander_times_s is None:
                u = (q - c) / np.linalg.norm(q - c)
                n2 = u - sp.mean_incoming
                n2 /= np.linalg.norm(n2)
                n2 = n2 if n2 @ n > 0 else -n2
                delta = np.array([n2 @ t.tangent, n2 @ np.cross(n, t.tangent)]) / float(n2 @ n)
                l2 = max(float(np.linalg.norm(q - c)), 1e-9)
                sd = _spread(w / l2, e0, limit, 2 * ev.model.tilt_sigma_rad, _position_angle(ev, j, l2))
                if sd is not None:
                    out.append(("tilt", t.index, delta, sd / 2, f"{t.name}'s mirror beam on {ev.point_name(j)} (tilt)", j))
    return out


def _keep(cands, model, n_observers: int) -> list:
    """Candidates plain draws would rarely reach (Rice chance of landing within the spread
    below 1e-2) out to 6.5 sigma, one per cell of their own spread, at most 64: the
    observers' first (they are people), then the map's, evenly over the distance."""
    people = _pick(_distinct([c for c in cands if c[5] < n_observers], model), MAX_COMPONENTS)
    room = MAX_COMPONENTS - len(people) if not people else min(MAP_COMPONENTS_BESIDE_OBSERVERS, MAX_COMPONENTS - len(people))
    return people + _pick(_distinct([c for c in cands if c[5] >= n_observers], model), room)


def _pick(kept, n) -> list:
    if len(kept) > n:
        kept = [kept[i] for i in np.unique(np.linspace(0, len(kept) - 1, n).round().astype(int))] if n > 0 else []
    return [c for _, c in kept]


def _distinct(cands, model) -> list:
    from scipy.stats import ncx2

    kept, seen = [], set()
    for block, k, mean, sd, why, _ in cands:
        m0, s0 = (np.asarray(model.pointing_bias_rad), model.pointing_sigma_rad) if block == "pointing" else (np.zeros(2), model.tilt_sigma_rad)
        dist = float(np.linalg.norm(np.asarray(mean) - m0)) / s0
        rough = float(ncx2.cdf((sd / s0) ** 2, 2, dist**2))  # the chance of landing within sd of the mean (spec section 8)
        if not (RARE_BELOW > rough and dist <= FAR_SIGMAS):
            continue
        key = (block, k, int(round(mean[0] / sd)), int(round(mean[1] / sd)))
        if key not in seen:
            seen.add(key)
            kept.append((dist, Component(block, k, (float(mean[0]), float(mean[1])), float(sd), why)))
    kept.sort(key=lambda x: x[0])
    return kept


def proposal(ev) -> Proposal:
    """The mixture for ``ev``'s scene (deterministic: every process builds the same one)."""
    m = ev.model
    gain = float(ev.own_gain().max()) if len(ev.points_m) else 1.0
    limit = ev.mpe_w_m2 / gain
    cands = []
    if m.pointing_sigma_rad > 0:
        cands += _direct(ev, ev.points_m, limit)
    if (m.pointing_sigma_rad > 0 or m.tilt_sigma_rad > 0) and ev.nominal.spots:
        cands += _mirror(ev, ev.points_m, limit)
    return Proposal(tuple(_keep(cands, m, ev.n_observers)))
