"""Stage ``spill``: where the part of the beam that misses every target goes.

The beam's cells (:mod:`hazard.physics.beam`) that hit no target either stop on an occluder or
the terrain (where, how much) or leave the scene. What lands on the terrain is reflected
by it: the beam stage gives the terrain a spot of its own (target ``terrain``, its
``[terrain] material`` or a Lambertian of reflectance 1); occluders absorb. Along the part that leaves, the direct
beam keeps the full beam's profile (range-safety.md section 2): its hazard distance is
the direct-beam NOHD (:func:`hazard.physics.nohd.nohd_direct`) of the beam scaled by the highest
Gaussian value ``exp(-min |s|^2)`` among those cells, so a spill made only of the
beam's wings reaches less far than the whole beam. Through an optical aid the gain
``K = min(tau M^2, tau (D_o / 7 mm)^2)`` multiplies it (without the beam-size limit: an
upper bound).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hazard.physics.nohd import nohd_direct, optical_gain

__all__ = ["SpillSummary", "StoppedSpill", "AidedNohd", "spill_summary", "direct_nohds", "spill_profile", "hottest_spill_s"]


@dataclass(frozen=True)
class AidedNohd:
    """A direct-beam NOHD through one optical aid (:func:`direct_nohds`; report.json
    ``beam.spill.aided[]``, and the aid's part of ``sdz.aided[]``).

    Attributes
    ----------
    magnification : float
        The aid's angular magnification M (unitless), as the scene gives it.
    objective_diameter_m : float
        Its objective's diameter D_o [m].
    transmission : float
        Its transmission tau (unitless, 0-1).
    gain : float
        The optical gain ``K = min(tau M^2, tau (D_o / 7 mm)^2)`` (unitless; no beam-size limit: an upper bound).
    nohd_m : float
        The direct-beam NOHD through it [m].
    """

    magnification: float
    objective_diameter_m: float
    transmission: float
    gain: float
    nohd_m: float

    def to_dict(self) -> dict:
        return {"magnification": self.magnification, "objective_diameter_m": self.objective_diameter_m,
                "transmission": self.transmission, "gain": self.gain, "nohd_m": self.nohd_m}


@dataclass(frozen=True)
class StoppedSpill:
    """The part of the spill an occluder or the terrain stops (:func:`_stopped`; report.json ``beam.spill.stopped[]``).

    Attributes
    ----------
    object : str
        ``"occluders[k]"`` or ``"terrain"``.
    power_w : float
        The power it stops [W].
    range_m : float
        Its power-weighted mean range from the laser [m].
    peak_irradiance_w_m2 : float
        The highest irradiance of that part of the beam on its way [W/m^2] (at ``from_range_m``).
    hazard_ratio : float
        ``peak_irradiance_w_m2`` over the MPE (unitless): >= 1, an eye in it before it ends is at risk.
    from_range_m : float
        Where it parts from the rest of the beam [m] (the nearest target cutting it, else the aperture: 0).
    reflected : str
        What it does there, in words (the terrain reflects as target ``terrain``; occluders absorb).
    """

    object: str
    power_w: float
    range_m: float
    peak_irradiance_w_m2: float
    hazard_ratio: float
    from_range_m: float
    reflected: str

    def to_dict(self) -> dict:
        return {"object": self.object, "power_w": self.power_w, "range_m": self.range_m,
                "peak_irradiance_w_m2": self.peak_irradiance_w_m2, "hazard_ratio": self.hazard_ratio,
                "from_range_m": self.from_range_m, "reflected": self.reflected}


@dataclass(frozen=True)
class SpillSummary:
    """Stage ``spill``: the beam past the targets (:func:`spill_summary`; report.json ``beam.spill``).

    Attributes
    ----------
    leaves_scene_w : float
        The power that leaves the scene past every target and stopper [W] (at most the
        power of the beam cells with a ray that hits nothing).
    shared_w : float
        The power in beam cells shared by a target and a stopper [W]: it lands on one of them.
    peak_profile : float
        The spill's highest value of the beam's Gaussian profile ``exp(-min |s|^2)``
        (unitless, 0-1; 0: no spill leaves the scene).
    stopped : tuple of StoppedSpill
        What each occluder and the terrain stops.
    nohd_m : float
        The direct-beam NOHD along the spill that leaves [m] (0 without one).
    aided : tuple of AidedNohd
        The same through each optical aid of the scene (empty without a spill).
    """

    leaves_scene_w: float
    shared_w: float
    peak_profile: float
    stopped: tuple[StoppedSpill, ...]
    nohd_m: float
    aided: tuple[AidedNohd, ...]

    def to_dict(self) -> dict:
        return {"leaves_scene_w": self.leaves_scene_w, "shared_w": self.shared_w, "peak_profile": self.peak_profile,
                "stopped": [d.to_dict() for d in self.stopped], "nohd_m": self.nohd_m, "aided": [a.to_dict() for a in self.aided]}


def _stopped(cells, scene, outlines, target_range_m, mu, mpe_w_m2) -> list[StoppedSpill]:
    """Power [W] and mean range [m] of the beam stopped on each occluder and the terrain,
    what it does there (``reflected``), and the highest irradiance of that part of the
    beam on its way [W/m^2] (``peak_irradiance_w_m2``: its highest Gaussian value
    ``exp(-min |s|^2)`` at ``from_range_m``, where it parts from the rest of the beam: the
    nearest target whose edge cuts the beam cell holding that point (``target_range_m``:
    target index -> range [m]), else the aperture; with its ``hazard_ratio``): an eye in
    it before it ends is at risk."""
    laser = scene.spec.laser
    n_t, n_o = len(scene.targets), len(scene.occluders)
    centre = cells.labels[:, 0]
    out = []
    for k in np.unique(centre[centre >= n_t]):
        rows = centre == k
        p = float(cells.power_w[rows].sum())
        name = f"occluders[{int(k) - n_t}]" if k < n_t + n_o else "terrain"
        profile, _, leaf = spill_profile(cells, outlines, np.flatnonzero(np.any(cells.labels == k, axis=1)))
        cut = [target_range_m.get(int(j), 0.0) for j in (cells.labels[leaf] if leaf >= 0 else []) if 0 <= j < n_t]
        start = min(cut + [float(cells.t[rows].min())]) if cut else 0.0
        d = laser.beam_diameter_m + start * laser.divergence_rad
        peak = 4 * laser.average_power_w / (np.pi * d * d) * np.exp(-mu * start) * profile
        out.append(StoppedSpill(object=name, power_w=p, range_m=float((cells.t[rows] * cells.power_w[rows]).sum() / p),
                                peak_irradiance_w_m2=float(peak), hazard_ratio=float(peak / mpe_w_m2), from_range_m=start,
                                reflected=terrain_reflection(scene) if name == "terrain" else
                                "not reflected (occluders absorb: they have no material)"))
    return out


def terrain_reflection(scene) -> str:
    """How the terrain reflects the beam that lands on it, in words."""
    t = scene.terrain_target
    if t.spec.material_given:
        return f"reflected by the terrain's material ({t.material.name}), as the target 'terrain'"
    return (f"reflected diffusely as the target 'terrain': Lambertian of reflectance {t.material.reflectance:g} "
            f"(the default: the most a diffuse ground returns; give [terrain] material for the real ground)")


def _cell_profile(cells, row, outlines) -> tuple[float, np.ndarray | None]:
    """The largest ``exp(-|s|^2)`` over the part of leaf ``row`` outside every exact flat
    target's outline (those whose edges cross it); the whole cell's when another object
    shares it. Points within 1e-9 w of an outline count as covered, so two plates meeting
    edge to edge leave no gap. With it, the point s where it is found (None: none)."""
    from hazard.physics.beam import clip_to_box, r2_min_outside

    labels = set(cells.labels[row].tolist()) - {-1}
    s0, s1, t0, t1 = (float(v[0]) for v in cells.bounds(np.array([row])))
    if not labels or not labels <= set(outlines):
        return float(cells.max_profile(np.array([row]))[0]), np.array([min(max(0.0, s0), s1), min(max(0.0, t0), t1)])
    box = np.array([[s0, t0], [s1, t0], [s1, t1], [s0, t1]])
    holes = [(p, q) for p, q in ((clip_to_box(outlines[k], s0, s1, t0, t1), outlines[k]) for k in labels) if len(p)]
    r2, point = r2_min_outside(box, holes, n_edge=512, seam=1e-9, with_point=True)
    return float(np.exp(-r2)), point


def spill_profile(cells, outlines, rows=None) -> tuple[float, np.ndarray | None, int]:
    """The highest Gaussian value ``exp(-|s|^2)`` anywhere in the spill, where (s; None
    when there is no spill) and in which leaf (-1: none): over the leaves ``rows``
    (default: those with a ray that hits nothing), best first, stopping when no leaf left
    can beat it."""
    if rows is None:
        rows = np.flatnonzero(np.any(cells.labels == -1, axis=1))
    if not len(rows):
        return 0.0, None, -1
    bound = cells.max_profile(rows)
    order = np.argsort(-bound)
    best, at, leaf = 0.0, None, -1
    for q in order:
        if bound[q] <= best:
            break
        value, point = _cell_profile(cells, rows[q], outlines)
        if value > best:
            best, at, leaf = value, point, int(rows[q])
    return best, at, leaf


def hottest_spill_s(traced, n_targets) -> np.ndarray | None:
    """Where (beam coordinates s) the part of the beam that no target takes is hottest:
    the spill that leaves the scene and what ends on the terrain or an occluder
    (``n_targets``: object ids below it are targets)."""
    cells = traced.cells
    outlines = {k: v for k, v in traced.outlines.items() if k in cells.exact_targets}
    rows = np.flatnonzero(np.any((cells.labels == -1) | (cells.labels >= n_targets), axis=1))
    return spill_profile(cells, outlines, rows)[1]


def spill_summary(scene, traced, mu, mpe_w_m2, aids=()) -> SpillSummary:
    """What of the beam misses every target: how much leaves the scene (exact where the
    targets' powers are), its direct-beam NOHD [m] (naked and through each aid), and what
    stops the rest.

    The power no target takes and no stopper takes whole (``traced.built.spill_w``)
    leaves the scene only as far as beam cells meet nothing: at most the power of the
    cells with a ray that hits nothing. The rest (``shared_w``) lies in cells shared by a
    target and a stopper: it lands on one of them, counted with neither."""
    cells, laser = traced.cells, scene.spec.laser
    outlines = {k: v for k, v in traced.outlines.items() if k in cells.exact_targets}
    profile = spill_profile(cells, outlines)[0]
    ranges = {sp.target.index: float(sp.range_from_laser_m.min()) for sp in traced.built.spots if sp.target.index < len(scene.targets)}
    rest = float(traced.built.spill_w)
    leaves = min(rest, float(cells.power_w[np.any(cells.labels == -1, axis=1)].sum()))
    stopped = tuple(_stopped(cells, scene, outlines, ranges, mu, mpe_w_m2))
    nohd_m, aided = direct_nohds(laser, laser.average_power_w * profile, mpe_w_m2, mu, aids) if profile > 0 else (0.0, ())
    return SpillSummary(leaves_scene_w=leaves, shared_w=rest - leaves, peak_profile=profile, stopped=stopped, nohd_m=nohd_m, aided=aided)


def direct_nohds(laser, power_w, mpe_w_m2, mu, aids=()) -> tuple[float, tuple[AidedNohd, ...]]:
    """Direct-beam NOHD [m] of ``power_w`` in the laser's beam, naked, and through each
    aid (an :class:`AidedNohd` per aid with its gain ``K = min(tau M^2, tau (D_o / 7 mm)^2)``,
    no beam-size limit: an upper bound)."""
    naked = float(nohd_direct(power_w, mpe_w_m2, laser.beam_diameter_m, laser.divergence_rad, attenuation_per_m=mu).nohd_m)
    aided = []
    for a in aids:
        k = optical_gain(a.magnification, a.objective_diameter_m, a.transmission)
        r = nohd_direct(power_w, mpe_w_m2, laser.beam_diameter_m, laser.divergence_rad, attenuation_per_m=mu, optical_gain=k)
        aided.append(AidedNohd(magnification=a.magnification, objective_diameter_m=a.objective_diameter_m,
                               transmission=a.transmission, gain=k, nohd_m=float(r.nohd_m)))
    return naked, tuple(aided)
