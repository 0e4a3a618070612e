"""Stage ``crossings``: where a narrow beam crosses an observer line between its points.

A road sampled every 10 m can let a 0.3 m beam (the laser's own, or a mirror's) pass
between two points unseen. Along every line of observers (``start_m``/``end_m``/``count``,
the polyline through its points, following the terrain when placed at eye height) the
irradiance of the direct beam and of each mirror beam is searched between the points:
``SUBSAMPLES`` per segment, then the best interval again as finely, then a
golden-section search to the maximum. Where the highest
value found exceeds the line's own points by more than ``GAIN`` it is added as an
observer point of its own (group ``<line>:crossing``, the line's optics), so the map,
the lines of sight, the verdicts and the report treat it like any other. The first pass
locates a beam as long as one of its points lies within ~25 1/e radii of the beam's
axis (where the Gaussian is still above floating-point zero: a 10 m road's 16 cm spacing
finds a beam of 1 cm radius); lines of more than ``MAX_CANDIDATES / SUBSAMPLES``
segments get fewer points per segment.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from ..engine import specular_irradiance
from .direct import beam_at
from .plan import GRIDS_NOT_SEARCHED

__all__ = ["add_crossings", "SUBSAMPLES", "GAIN"]

SUBSAMPLES = 64  # points per segment of the line in the first pass, and again around the best one
GAIN = 1.01  # a crossing is kept when it beats the line's own points by more than this factor
MAX_CANDIDATES = 2_000_000  # first-pass points per line and beam (bounds memory on long lines)
FLOOR = 1e-4  # crossings weaker than this fraction of the MPE are not added


def _direct(beam, mu):
    """The laser's own beam, nothing in the way (the map checks the line of sight)."""
    def fn(p):
        at = beam_at(beam, p, mu)
        e = np.zeros(len(p))
        e[at.rows] = at.irradiance_w_m2
        return e
    return fn


def _mirror(spot, beam, mu):
    """The mirror beam's irradiance; for a dynamic material the highest over its state
    nodes (where the beam lands does not depend on the state, how bright it is does)."""
    states = spot.material.state_nodes() if spot.material.is_dynamic else None

    def fn(p):
        e = specular_irradiance(spot, p, np.ones(len(p)), mu, beam, states)
        return e if e.ndim == 1 else e.max(axis=1)
    return fn


def _densest(fn, pts):
    """The highest value of ``fn`` between consecutive points of a polyline (n, 3):
    ``SUBSAMPLES`` per segment, then as many over the two segments' worth around the
    best; returns (value, point)."""
    seg = pts[1:] - pts[:-1]
    per = int(max(2, min(SUBSAMPLES, MAX_CANDIDATES // max(len(seg), 1))))  # long lines: fewer per segment
    u = np.linspace(0.0, 1.0, per, endpoint=False)
    cand = (pts[:-1, None, :] + u[None, :, None] * seg[:, None, :]).reshape(-1, 3)
    e = fn(cand)
    k = int(np.argmax(e))
    i, j = divmod(k, per)
    t0 = i + (j - 1) / per
    t = np.clip(np.linspace(t0, t0 + 2.0 / per, SUBSAMPLES + 1), 0.0, len(seg) - 1e-12)
    idx = np.minimum(t.astype(int), len(seg) - 1)
    fine = pts[idx] + (t - idx)[:, None] * seg[idx]
    ef = fn(fine)
    q = int(np.argmax(ef))
    if ef[q] < e[k]:
        return float(e[k]), cand[k]
    return _golden(fn, fine[max(q - 1, 0)], fine[min(q + 1, len(fine) - 1)], float(ef[q]), fine[q])


def _golden(fn, a, b, best, at, iterations=60):
    """Golden-section search for the maximum of ``fn`` on the segment [a, b] (unimodal
    near a beam's crossing); the better of it and (best, at)."""
    g = (np.sqrt(5.0) - 1) / 2
    lo, hi = 0.0, 1.0
    x1, x2 = hi - g * (hi - lo), lo + g * (hi - lo)
    f1, f2 = (float(fn((a + x * (b - a))[None])[0]) for x in (x1, x2))
    for _ in range(iterations):
        if f1 >= f2:
            hi, x2, f2 = x2, x1, f1
            x1 = hi - g * (hi - lo)
            f1 = float(fn((a + x1 * (b - a))[None])[0])
        else:
            lo, x1, f1 = x1, x2, f2
            x2 = lo + g * (hi - lo)
            f2 = float(fn((a + x2 * (b - a))[None])[0])
    x, f = (x1, f1) if f1 >= f2 else (x2, f2)
    return (f, a + x * (b - a)) if f >= best else (best, at)


def _line_groups(scene):
    obs = scene.observers
    for g, spec in enumerate(scene.spec.observers):
        if spec.layout == "line" and spec.count >= 2:
            rows = np.flatnonzero(obs.group == g)
            yield g, spec.name, obs.positions_m[rows[np.argsort(obs.index_in_group[rows])]]


def add_crossings(scene, beam, spots, mu, mpe_w_m2):
    """The scene with an observer point added at each beam crossing of a line that falls
    between its points (see the module notes), and a one-line account. Crossings below
    ``FLOOR`` of the MPE (naked eye) are left out: even through optics of gain 1000 they
    stay under a tenth of it."""
    if scene.observers is None or not len(scene.observers):
        return scene, "no observers"
    sources = [("direct beam", _direct(beam, mu))] + [(f"mirror beam of {sp.target.name}", _mirror(sp, beam, mu))
                                                      for sp in spots if sp.material.has_specular]
    added, said = [], []
    for g, name, pts in _line_groups(scene):
        for label, fn in sources:
            at_points = float(fn(pts).max())
            value, point = _densest(fn, pts)
            if value >= FLOOR * mpe_w_m2 and value > GAIN * at_points:
                added.append((g, name, point))
                said.append(f"{name}: the {label} crosses between its points at "
                            f"[{point[0]:.6g}, {point[1]:.6g}, {point[2]:.6g}] m (local; its value is the map's)")
    if any(o.layout in ("grid", "shell") for o in scene.spec.observers):
        said.append(GRIDS_NOT_SEARCHED)
    if not added:
        return scene, "; ".join(["no beam crosses an observer line between its points"] + said)
    return dataclasses.replace(scene, observers=_with_points(scene.observers, added)), "; ".join(said)


def _with_points(obs, added):
    """``obs`` with the points of ``added`` ((line group, line name, point) each), one new
    group per line, named ``<line>:crossing``, with the line's optics."""
    names, optics = list(obs.group_names), list(obs.optics)
    pos, grp, idx = [obs.positions_m], [obs.group], [obs.index_in_group]
    new_group, count = {}, {}
    for g, name, point in added:
        if g not in new_group:
            new_group[g] = len(names)
            names.append(f"{name}:crossing")
            optics.append(obs.optics[g] if g < len(obs.optics) else None)
        k = new_group[g]
        pos.append(point[None])
        grp.append(np.array([k]))
        idx.append(np.array([count.get(k, 0)]))
        count[k] = count.get(k, 0) + 1
    return dataclasses.replace(obs, positions_m=np.vstack(pos), group=np.concatenate(grp), index_in_group=np.concatenate(idx),
                               group_names=tuple(names), optics=tuple(optics))
