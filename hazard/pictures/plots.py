"""Plots as "Display" objects: they store computed data (``from_...``) and only draw it
(``plot``), so a figure can be restyled without recomputing (scikit-learn's pattern).
matplotlib is imported when a Display draws, never by ``import hazard``."""

from __future__ import annotations

import io
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

import brdfmodels
from hazard.outputs.names import file_part

__all__ = ["BRDFPlaneDisplay", "NOHDTimeDisplay", "ExposureDisplay", "ErrorTableDisplay", "time_figures"]


def _axes(ax):
    """(figure, axes): ``ax``'s, or a new figure on its own Agg canvas (no backend switched)."""
    if ax is None:
        from hazard.canvas import subplots

        return subplots(figsize=(7, 4.5))
    return ax.figure, ax


class DisplayBase:
    """Base of the Display objects: ``save`` (atomic PNG), ``png_bytes`` and
    ``png_and_entry`` around the subclass's ``plot(**kw) -> (fig, ax)``. ``DPI``: the
    pictures' resolution [px/in]; with the figure's size [in] it sets how large its text
    prints (:data:`hazard.canvas.PRINT_MIN_PT`)."""

    DPI = 110

    def save(self, path, **plot_kw) -> Path:
        fig, _ = self.plot(**plot_kw)
        path = Path(path)
        from brdfmodels.fileio import atomic_write

        # a legend beside or below the axes stays whole
        atomic_write(path, lambda tmp: fig.savefig(tmp, dpi=self.DPI, bbox_inches="tight"), keep_suffix=True)
        return path  # a figure drawn here is in no pyplot manager (nothing to close); a caller's ``ax`` stays the caller's

    def png_bytes(self, **plot_kw) -> bytes:
        """The figure as PNG bytes (a figure drawn here is in no pyplot manager: nothing to close)."""
        return self.png_and_entry("", **plot_kw)[0]

    def png_and_entry(self, view, **plot_kw) -> tuple:
        """(PNG bytes, figures.json entry (:func:`hazard.outputs.figure_index.figure_entry`, read
        after the figure is saved: the panels' final extents))."""
        from hazard.outputs.figure_index import figure_entry

        fig, _ = self.plot(**plot_kw)
        buf = io.BytesIO()
        fig.savefig(buf, format="png", dpi=self.DPI, bbox_inches="tight")  # a legend below the axes stays whole
        return buf.getvalue(), figure_entry(fig, view, dpi=self.DPI)


def _state_label(name, s) -> str:
    """``extinction = 0.8``, or ``(extinction, melt_fraction) = (0.8, 0.5)``."""
    if isinstance(name, str):
        return f"{name} = {float(s):g}"
    return f"({', '.join(name)}) = ({', '.join(f'{float(x):g}' for x in s)})"


@dataclass
class BRDFPlaneDisplay(DisplayBase):
    """BRDF in the plane of incidence: model curves (per state) and measured samples."""

    angles_deg: np.ndarray
    curves: dict  # label -> f_r (1/sr)
    incidence_deg: float
    samples_deg: np.ndarray | None = None
    samples_fr: np.ndarray | None = None

    @classmethod
    def from_model(cls, model, incidence_deg, *, states=None, samples=None, tolerance_deg=1.5, n=721):
        ang = np.linspace(-89.5, 89.5, n)
        wi = brdfmodels.spherical_to_vector(np.radians(incidence_deg), 0.0)
        wo = brdfmodels.spherical_to_vector(np.radians(np.abs(ang)), np.where(ang < 0, 0.0, np.pi))
        curves = {}
        for s in ([None] if states is None else list(states)):
            label = "model" if s is None else _state_label(model.state_name, s)
            curves[label] = model.evaluate(np.broadcast_to(wi, wo.shape), wo, state=s)
        sd = sf = None
        if samples is not None:
            ti, pi = brdfmodels.vector_to_spherical(samples.wi)
            to, po = brdfmodels.vector_to_spherical(samples.wo)
            near_i = np.abs(np.degrees(ti) - abs(incidence_deg)) < tolerance_deg
            in_plane = np.minimum(np.abs(np.sin(po - pi)), 1.0) < np.sin(np.radians(tolerance_deg))
            sel = near_i & in_plane
            same_side = np.cos(po - pi) > 0
            sd = np.where(same_side[sel], -1.0, 1.0) * np.degrees(to[sel])
            sf = samples.brdf_per_sr[sel]
        return cls(ang, curves, float(incidence_deg), sd, sf)

    def plot(self, ax=None):
        fig, ax = _axes(ax)
        for label, f in self.curves.items():
            ax.semilogy(self.angles_deg, np.maximum(f, 1e-6), label=label)
        if self.samples_deg is not None and len(self.samples_deg):
            ax.semilogy(self.samples_deg, self.samples_fr, ".", ms=3, alpha=0.5, label="measured")
        ax.axvline(self.incidence_deg, ls=":", c="k", lw=0.8)
        ax.set_xlabel("reflection angle in the plane of incidence [deg] (specular at +theta_i)")
        ax.set_ylabel("BRDF f_r [1/sr]")
        ax.set_title(f"incidence {self.incidence_deg:g} deg")
        ax.legend(fontsize=8)
        ax.grid(alpha=0.3, which="both")
        return fig, ax


@dataclass
class NOHDTimeDisplay(DisplayBase):
    """Max NOHD of a target over the history: the static line against the dynamic curve
    (a target whose material does not change: one flat line over the window)."""

    times_s: np.ndarray
    nohd_dynamic_m: np.ndarray
    nohd_static_m: float
    target: str
    mpe_w_m2: float | None = None  # the MPE the NOHD is the distance to (point source)
    dynamic: bool = True  # the target's material changes over the times
    paths: tuple = ()  # report.json paths it draws (figures.json)

    @classmethod
    def from_result(cls, result, target=0, *, grid_deg=5.0):
        """``target``: index into ``result.spots`` (the lit targets)."""
        from hazard.physics.keepout import nohd_range_fn

        spot = result.spots[target]
        states = result.states.get(spot.target.index)
        wi = -spot.mean_incoming @ spot.mean_frame.T
        th = np.radians(np.arange(0, 90, grid_deg))
        ph = np.radians(np.arange(-180, 180, grid_deg))
        tt, pp = np.meshgrid(th, ph)
        dirs = np.vstack([brdfmodels.spherical_to_vector(tt.ravel(), pp.ravel()), wi * [-1, -1, 1], wi])
        mpe = float(result.mpe_w_m2)
        if states is None:
            r = float(nohd_range_fn(spot, result.mpe_w_m2, result.attenuation_per_m, 1.0, None)(dirs).max())
            t = np.asarray(result.times_s, float)
            if len(t) < 2:  # a static analysis has one time: the line spans the exposure window
                t = np.array([t[0], t[0] + result.scene.spec.exposure.duration_s])
            return cls(t, np.full(len(t), r), r, spot.target.name, mpe, False)
        fns = [nohd_range_fn(spot, result.mpe_w_m2, result.attenuation_per_m, 1.0, states[j:j + 1]) for j in range(len(states))]
        per_t = np.array([fn.max_range(dirs) if hasattr(fn, "max_range") else fn(dirs).max() for fn in fns])  # near field only where it can matter
        return cls(result.times_s, per_t, float(per_t[0]), spot.target.name, mpe, True)

    def plot(self, ax=None):
        fig, ax = _axes(ax)
        if self.dynamic:
            ax.plot(self.times_s, self.nohd_dynamic_m, c="tab:blue", label="dynamic")
            ax.axhline(self.nohd_static_m, ls="--", c="k", label="static (initial state)")
        else:
            ax.plot(self.times_s, self.nohd_dynamic_m, c="tab:blue", label="static material (no change over time)")
        j = int(np.argmax(self.nohd_dynamic_m))
        top = float(self.nohd_dynamic_m[j])
        where = f"at t = {float(self.times_s[j]):.4g} s" if self.dynamic else "(constant)"
        ax.plot([self.times_s[j]], [top], "o", c="tab:red", label=f"max {top:.4g} m {where}")
        ax.set_ylim(0.0, 1.1 * max(top, self.nohd_static_m) or 1.0)
        ax.set_xlabel("time [s]")
        mpe = "" if self.mpe_w_m2 is None else f" to E = MPE = {self.mpe_w_m2:.4g} W/m^2"
        ax.set_ylabel(f"max NOHD{mpe} [m]")
        ax.set_title(f"target {self.target}: diffuse-lobe NOHD vs time")
        _mark_curve(ax, self.paths, self.times_s, self.nohd_dynamic_m)
        ax.legend(fontsize=8)
        ax.grid(alpha=0.3)
        return fig, ax


@dataclass
class ExposureDisplay(DisplayBase):
    """An observer's irradiance and accumulated exposure over time against the MPE."""

    times_s: np.ndarray
    irradiance_w_m2: np.ndarray
    exposure_j_m2: np.ndarray
    mpe_exposure_j_m2: np.ndarray
    observer: str
    mpe_w_m2: float | None = None  # the observer's MPE [W/m^2] (the hazard ratio's limit, with C_E when applied)
    first_exceedance_s: float = math.nan  # from the analysis (NaN: none in the window)
    hazard_ratio: float | None = None
    ratio_text: str = "peak E / MPE"
    duration_s: float | None = None  # the exposure duration whose MPE the verdict uses [s]
    rule: str = "peak"  # the verdict's rule: "peak" (E(t) > the duration's MPE) or "window" (a window's H > its MPE)
    paths: tuple = ()  # report.json paths it draws (figures.json)
    uv_day_j_m2: float | None = None  # 180-400 nm, where the UV day rule governs: the day's summed-dose limit [J/m^2]
    uv_day_text: str = ""  # its legend: the exposed time in 24 h it is for

    @classmethod
    def from_result(cls, result, observer=0, *, irradiance_w_m2=None):
        """``irradiance_w_m2``: the observer's history over ``result.times_s`` when the
        result kept none (:func:`time_figures` recomputes it)."""
        from hazard.physics import mpe as _mpe

        if irradiance_w_m2 is None:
            e = result.observers.irradiance_w_m2
            if e is None:
                raise ValueError("the result kept no irradiance history: analyze(scene, keep_history=True)")
            irradiance_w_m2 = e[observer]
        t = np.asarray(result.times_s, float)
        row = np.asarray(irradiance_w_m2, float)
        spec = result.scene.spec
        if len(t) < 2:  # static: the irradiance holds over the exposure window
            t = t[0] + np.linspace(0.0, spec.exposure.duration_s, 201)
            row = np.full(len(t), row[0])
        cum = np.concatenate([[0.0], np.cumsum(0.5 * (row[1:] + row[:-1]) * np.diff(t))])
        el = np.clip(t - t[0], _mpe.DURATION_MIN_S, _mpe.DURATION_MAX_S)
        limit = np.array([_mpe.ocular_mpe(spec.laser.wavelength_nm, x, standard=spec.exposure.standard).radiant_exposure_j_m2 for x in el])
        obs = result.observers
        mpe = np.broadcast_to(np.asarray(result.observer_mpe_w_m2, float), (len(obs),))[observer] if len(obs) else result.mpe_w_m2
        return cls(t, row, cum, limit, obs.labels[observer], float(mpe), float(obs.first_exceedance_s[observer]),
                   float(result.hazard_ratio[observer]), duration_s=float(spec.exposure.duration_s),
                   **_uv_day_static(getattr(result, "uv_24h", None), float(mpe), getattr(result.mpe, "irradiance_w_m2", math.inf),
                                    float(spec.exposure.duration_s)))

    @classmethod
    def from_path(cls, result, path):
        """A moving observer's samples (:class:`hazard.pipeline.motion.SummarisedPath`) over its
        own time steps; the hazard ratio is its worst window's exposure ratio."""
        from hazard.physics import mpe as _mpe

        spec = result.scene.spec
        t = np.asarray(path.times_s, float)
        el = np.clip(t - t[0], _mpe.DURATION_MIN_S, _mpe.DURATION_MAX_S)
        limit = np.array([_mpe.ocular_mpe(spec.laser.wavelength_nm, x, standard=spec.exposure.standard).radiant_exposure_j_m2
                          for x in el])
        s = path.summary  # hazard.pipeline.motion_results.PathSummary
        first = math.nan if s.first_exceedance_s is None else float(s.first_exceedance_s)
        return cls(t, path.irradiance_w_m2, path.cumulative_j_m2, limit, f"{path.name} ({path.kind})",
                   float(result.mpe_w_m2), first, float(s.exposure_ratio),
                   f"worst {s.worst_window.duration_s:.3g} s window's H / MPE", duration_s=float(spec.exposure.duration_s),
                   rule="window", **_uv_day_path(s))

    def verdict_exceedance_s(self) -> float:
        """The first time the verdict's rule is broken [s] (NaN: never in the window).

        ``rule == "peak"`` (a fixed observer, hazard ratio = peak E / MPE): the first time
        E(t) reaches the MPE of the exposure duration (``mpe_w_m2``), the limit the verdict
        compares with. ``rule == "window"`` (a moving observer): the analysis's own first
        exceedance of its worst window.
        """
        if self.rule != "peak" or self.mpe_w_m2 is None:
            return self.first_exceedance_s
        over = np.flatnonzero(np.asarray(self.irradiance_w_m2, float) >= self.mpe_w_m2)
        return float(self.times_s[over[0]]) if len(over) else math.nan

    def _limit_text(self) -> str:
        t = "the exposure duration" if self.duration_s is None else f"{self.duration_s:.4g} s"
        return f"the MPE for {t}"

    def _limits_and_exceedance(self, ax) -> None:
        """The elapsed-time MPE curve (for reading only), the verdict's limit as radiant
        exposure and the exceedance marked by the verdict's own rule."""
        ax.semilogy(self.times_s[1:], self.mpe_exposure_j_m2[1:], "k--", lw=0.9,
                    label="MPE for the elapsed time t [J/m^2] (for reading; not the verdict's rule)")
        limit = self._limit_text()
        if self.rule == "peak" and self.mpe_w_m2 is not None and self.duration_s is not None:
            h = self.mpe_w_m2 * self.duration_s
            ax.axhline(h, c="k", lw=1.2, label=f"{limit} as exposure: {self.mpe_w_m2:.4g} W/m^2 x {self.duration_s:.4g} s "
                                                f"= {h:.4g} J/m^2")
        if self.uv_day_j_m2 is not None:
            ax.axhline(self.uv_day_j_m2, c="tab:purple", ls="-.", lw=1.2, label=self.uv_day_text)
        t = self.verdict_exceedance_s()
        rule = f"E(t) first at or above {limit}" if self.rule == "peak" else f"{self.ratio_text} first over 1"
        if np.isfinite(t):
            ax.axvline(t, c="tab:red", lw=1.2, label=f"exceedance by the verdict's rule ({rule}): t = {t:.4g} s")
        elif self.hazard_ratio is not None and self.hazard_ratio > 1:
            ax.plot([], [], " ", label=f"exceeds by another rule of the MPE (hazard ratio {self.hazard_ratio:.3g}; see the report)")
        else:
            ax.plot([], [], " ", label=f"no exceedance in the window ({rule}: never)")

    def plot(self, ax=None):
        fig, ax = _axes(ax)
        ax.semilogy(self.times_s[1:], np.maximum(self.exposure_j_m2[1:], 1e-12), c="tab:blue", label="accumulated exposure H(t) [J/m^2]")
        self._limits_and_exceedance(ax)
        ax2 = ax.twinx()
        e = np.asarray(self.irradiance_w_m2, float)
        top = float(e.max()) if len(e) else 0.0
        # the axis spans what matters: from 1e-9 of the peak (a Gaussian's far tail, 1e-300, would squash it) and the MPE
        levels = e[e > 1e-9 * top].tolist() + ([] if self.mpe_w_m2 is None else [self.mpe_w_m2])
        if levels:  # log: the MPE stays visible beside a peak orders of magnitude above it
            ax2.set_yscale("log")
            ax2.set_ylim(min(levels) / 2.0, max(levels) * 2.0)
        ax2.plot(self.times_s, np.maximum(e, min(levels) / 4.0) if levels else e, c="tab:orange", alpha=0.7,
                 label="irradiance E(t) [W/m^2]")
        if self.mpe_w_m2 is not None:
            ax2.axhline(self.mpe_w_m2, c="tab:orange", ls=":", lw=1.2,
                        label=f"{self._limit_text()}: {self.mpe_w_m2:.4g} W/m^2 (the verdict's limit)")
        ax2.set_ylabel("irradiance [W/m^2]", color="tab:orange")
        ax.set_xlabel("time [s]")
        ax.set_ylabel("radiant exposure [J/m^2]")
        ratio = "" if self.hazard_ratio is None else f" ({self.ratio_text} = {self.hazard_ratio:.3g})"
        ax.set_title(f"observer {self.observer}{ratio}")
        _mark_curve(ax, self.paths, self.times_s[1:], np.maximum(self.exposure_j_m2[1:], 1e-12))
        h1, l1 = ax.get_legend_handles_labels()
        h2, l2 = ax2.get_legend_handles_labels()
        ax.legend(h1 + h2, l1 + l2, loc="upper center", bbox_to_anchor=(0.5, -0.13), ncol=2, fontsize=8)
        ax.grid(alpha=0.3, which="both")
        return fig, ax


def _uv_day_static(uv, mpe_w_m2, single_w_m2, duration_s) -> dict:
    """The UV day's limit for :class:`ExposureDisplay` of a fixed observer, when it governs
    its MPE (:func:`hazard.pipeline.limits.exposure_limits` lowered the MPE ``mpe_w_m2`` to
    the day's average, below the one exposure's ``single_w_m2``): the summed dose of all the
    day's exposures, ``uv.radiant_exposure_j_m2`` (``uv``: :class:`hazard.physics.mpe.UV24hResult`, or None)."""
    avg = None if uv is None else uv.average_irradiance_w_m2
    if avg is None or avg > mpe_w_m2 * (1 + 1e-9) or not avg < single_w_m2 * (1 - 1e-12):
        return {}
    return {"uv_day_j_m2": float(uv.radiant_exposure_j_m2),
            "uv_day_text": (f"UV day's limit: the doses of {uv.total_on_time_s:.4g} s exposed in 24 h add up to at most "
                            f"{uv.radiant_exposure_j_m2:.4g} J/m^2 (governs; [M]); this plot is one {duration_s:.4g} s "
                            f"exposure, held to its share (the MPE line)")}


def _uv_day_path(summary) -> dict:
    """The UV day's limit for :class:`ExposureDisplay` of a moving observer, when its 24 h
    dose ratio is the path's exposure ratio (``uv_24h`` of
    :func:`hazard.pipeline.motion_stage.path_summary`, a :class:`~hazard.pipeline.motion_results.PathSummary`)."""
    uv = summary.uv_24h
    if uv is None or uv.ratio < summary.worst_window.ratio:
        return {}
    return {"uv_day_j_m2": float(uv.limit_j_m2),
            "uv_day_text": (f"UV day's limit for {uv.exposed_s:.4g} s exposed in 24 h: {uv.limit_j_m2:.4g} J/m^2 "
                            f"(the path's dose in 24 h / limit = {uv.ratio:.3g}, governs; [M])")}


@dataclass
class ErrorTableDisplay(DisplayBase):
    """Error against run time (or evaluations) from a table's rows, one line per group."""

    series: dict = field(default_factory=dict)  # group -> (x, y)
    xlabel: str = ""
    ylabel: str = ""

    @classmethod
    def from_rows(cls, rows, x, y, group=None):
        series = {}
        for r in rows:
            key = "all" if group is None else str(r[group])
            series.setdefault(key, ([], []))
            series[key][0].append(float(r[x]))
            series[key][1].append(float(r[y]))
        return cls({k: (np.array(a), np.array(b)) for k, (a, b) in series.items()}, x, y)

    def plot(self, ax=None):
        fig, ax = _axes(ax)
        for k, (x, y) in self.series.items():
            ok = (x > 0) & (y > 0)
            ax.loglog(x[ok], y[ok], "o-", label=k)
        ax.set_xlabel(self.xlabel)
        ax.set_ylabel(self.ylabel)
        ax.legend(fontsize=8)
        ax.grid(alpha=0.3, which="both")
        return fig, ax


def _mark_curve(ax, paths, x, y):
    """Note (figures.json) that ``ax`` draws the findings ``paths`` as the curve x, y,
    labelled by its title."""
    from hazard.outputs.figure_index import mark

    mark(ax, paths, ax.get_title(), np.column_stack([np.asarray(x, float), np.asarray(y, float)]), "line")


def _unique(name, taken) -> str:
    stem, ext = name.rsplit(".", 1)
    out, k = name, 2
    while out in taken:
        out, k = f"{stem}_{k}.{ext}", k + 1
    return out


def _observer_histories(result, rows):
    """Irradiance histories (len(rows), T) [W/m^2] of observers ``rows`` over
    ``result.times_s``, recomputed by the analysis's own irradiance map
    (:func:`hazard.pipeline.irradiance_map.irradiance_map`) on just those points, with the
    result's spots, states, beam, direct beam and (when the scene needs one) the cached
    ray scene for lines of sight. Returns (histories, None) or (None, reason) when the
    recomputed peaks do not reproduce the result's."""
    from scenes.observers import Observers

    from hazard.physics.aperture import observer_apertures
    from hazard.physics.nohd import group_gains
    from hazard.pipeline import spots as beam_stage
    from hazard.pipeline.irradiance_map import MapInputs, irradiance_map
    from hazard.pipeline.plan import plan

    scene, obs, rows = result.scene, result.observers, np.asarray(rows, np.int64)
    table = obs.observers
    gain = group_gains(table.optics, table.group[rows])
    points = Observers.from_points(table.take(rows), table.group[rows], table.index_in_group[rows], table.group_names, table.optics)
    ray_scene = None
    if plan(scene).line_of_sight and result.spots:
        backend = result.stage("rays").detail.split(":", 1)[0]
        ray_scene = beam_stage.ray_scene(scene, backend if backend in ("embree", "numpy") else "embree", 1)
    spec = scene.spec
    direct = obs.direct_irradiance_w_m2
    inp = MapInputs(result.spots, result.beam, result.states, result.times_s, points, gain, result.attenuation_per_m,
                    spec.exposure.duration_s, spec.laser.wavelength_nm, spec.exposure.standard, float(result.mpe_w_m2),
                    ray_scene, True, 1, direct_w_m2=direct[rows] if direct is not None and direct[rows].any() else None,
                    apertures=observer_apertures(table.optics, table.group[rows], spec.laser.wavelength_nm, spec.exposure.duration_s))
    out = irradiance_map(inp)
    if not np.allclose(out.peak_w_m2, obs.peak_irradiance_w_m2[rows], rtol=1e-9, atol=0.0):
        return None, "the recomputed irradiance does not reproduce the analysis's peak irradiance"
    return out.history_w_m2, None


def time_figures(result, *, worst=3, index=None) -> dict:
    """Pictures over time of an analysis (:func:`hazard.analyze`) as PNG bytes by file name.

    * ``nohd_time_<target>.png``: :class:`NOHDTimeDisplay` for every lit target (every
      spot: a target with a reflection lobe); a target whose material does not change
      gets a flat line over the window.
    * ``exposure_track_<name>.png``: every moving observer's irradiance and exposure over
      its own time steps (:meth:`ExposureDisplay.from_path`).
    * ``exposure_<observer>.png``: :class:`ExposureDisplay` for the ``worst`` observers
      with the highest hazard ratio (``result.hazard_ratio``; ties: the first row). When
      the result kept no irradiance history their histories are recomputed on just those
      points with the analysis's own irradiance map, checked against the result's peak
      irradiance; if that check fails, ``exposure_omitted.txt`` says which observers,
      why, and how to get them (``analyze(scene, keep_history=True)``).

    Names are made file-safe (``file_part``) and kept unique. matplotlib is needed (the
    ``[render]`` extra); it is imported here, not by ``import hazard``. ``index`` (a dict)
    receives each picture's figures.json entry by file name.
    """
    from hazard.outputs.figure_index import finding_paths

    out, index = {}, ({} if index is None else index)
    paths = finding_paths(result)

    def add(name, display, view):
        out[name], index[name] = display.png_and_entry(view)

    for k, spot in enumerate(result.spots):
        d = NOHDTimeDisplay.from_result(result, k)
        d.paths = tuple(paths["lobe"].get((spot.target.name, kind)) for kind in ("static", "dynamic")
                        if paths["lobe"].get((spot.target.name, kind)))
        add(_unique(f"nohd_time_{file_part(spot.target.name)}.png", out), d, "time")
    m = len(result.observers)
    for k, p in enumerate([] if getattr(result, "motion", None) is None else result.motion.tracks()):
        d = ExposureDisplay.from_path(result, p)
        d.paths = (f"tracks[{k}]",) + ((paths["observers"][m + k],) if m + k in paths["observers"] else ())
        add(_unique(f"exposure_track_{file_part(p.name)}.png", out), d, "time")
    ratio = np.asarray(result.hazard_ratio, float)
    if worst <= 0 or not len(ratio):
        return out
    rows = np.argsort(-ratio, kind="stable")[:worst]
    hist = result.observers.irradiance_w_m2
    if hist is not None:
        histories = hist[rows]
    else:
        histories, why = _observer_histories(result, rows)
        if histories is None:
            labels = ", ".join(result.observers.labels[i] for i in rows)
            out["exposure_omitted.txt"] = (
                f"exposure plots of the {len(rows)} worst observer(s) by hazard ratio ({labels}) omitted: the analysis kept "
                f"no irradiance history and {why}; run analyze(scene, keep_history=True) to get them\n").encode()
            return out
    for i, e in zip(rows, histories):
        d = ExposureDisplay.from_result(result, int(i), irradiance_w_m2=e)
        d.paths = (paths["observers"][int(i)],) if int(i) in paths["observers"] else ()
        add(_unique(f"exposure_{file_part(d.observer)}.png", out), d, "time")
    return out
