"""Plots as "Display" objects: they store computed data (``from_...``) and only draw it
(``plot``), so a figure can be restyled without recomputing (scikit-learn's pattern).
matplotlib is imported when a Display draws, never by ``import hazard``."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

import brdfmodels

__all__ = ["BRDFPlaneDisplay", "NOHDTimeDisplay", "ExposureDisplay", "ErrorTableDisplay"]


def _axes(ax):
    import matplotlib

    if ax is None:
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        fig, ax = plt.subplots(figsize=(7, 4.5))
        return fig, ax
    return ax.figure, ax


class _Display:
    def save(self, path, **plot_kw) -> Path:
        fig, _ = self.plot(**plot_kw)
        path = Path(path)
        tmp = path.with_name("." + path.name + ".tmp" + path.suffix)
        fig.savefig(tmp, dpi=110)
        tmp.replace(path)
        import matplotlib.pyplot as plt

        plt.close(fig)
        return path


def _state_label(name, s) -> str:
    """``extinction = 0.8``, or ``(extinction, melt_fraction) = (0.8, 0.5)``."""
    if isinstance(name, str):
        return f"{name} = {float(s):g}"
    return f"({', '.join(name)}) = ({', '.join(f'{float(x):g}' for x in s)})"


@dataclass
class BRDFPlaneDisplay(_Display):
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
class NOHDTimeDisplay(_Display):
    """Max NOHD of a target over the history: the static line against the dynamic curve."""

    times_s: np.ndarray
    nohd_dynamic_m: np.ndarray
    nohd_static_m: float
    target: str

    @classmethod
    def from_result(cls, result, target=0, *, grid_deg=5.0):
        from .keepout import _range_fn

        spot = result.spots[target]
        states = result.states.get(spot.target.index)
        wi = -spot.mean_incoming @ spot.mean_frame.T
        th = np.radians(np.arange(0, 90, grid_deg))
        ph = np.radians(np.arange(-180, 180, grid_deg))
        tt, pp = np.meshgrid(th, ph)
        dirs = np.vstack([brdfmodels.spherical_to_vector(tt.ravel(), pp.ravel()), wi * [-1, -1, 1], wi])
        if states is None:
            r = float(_range_fn(spot, result.mpe_w_m2, result.attenuation_per_m, 1.0, None)(dirs).max())
            return cls(result.times_s, np.full(len(result.times_s), r), r, spot.target.name)
        per_t = np.array([_range_fn(spot, result.mpe_w_m2, result.attenuation_per_m, 1.0, states[j:j + 1])(dirs).max() for j in range(len(states))])
        return cls(result.times_s, per_t, float(per_t[0]), spot.target.name)

    def plot(self, ax=None):
        fig, ax = _axes(ax)
        ax.plot(self.times_s, self.nohd_dynamic_m, label="dynamic")
        ax.axhline(self.nohd_static_m, ls="--", c="k", label="static (initial state)")
        ax.set_xlabel("time [s]")
        ax.set_ylabel("max NOHD [m]")
        ax.set_title(f"target {self.target}")
        ax.legend()
        ax.grid(alpha=0.3)
        return fig, ax


@dataclass
class ExposureDisplay(_Display):
    """An observer's irradiance and accumulated exposure over time against the MPE."""

    times_s: np.ndarray
    irradiance_w_m2: np.ndarray
    exposure_j_m2: np.ndarray
    mpe_exposure_j_m2: np.ndarray
    observer: str

    @classmethod
    def from_result(cls, result, observer=0):
        from . import mpe as _mpe

        e = result.observers.irradiance_w_m2
        if e is None:
            raise ValueError("the result kept no irradiance history: analyze(scene, keep_history=True)")
        t = result.times_s
        row = e[observer]
        cum = np.concatenate([[0.0], np.cumsum(0.5 * (row[1:] + row[:-1]) * np.diff(t))]) if len(t) > 1 else row * 0
        spec = result.scene.spec
        el = np.clip(t - t[0], _mpe.DURATION_MIN_S, _mpe.DURATION_MAX_S)
        limit = np.array([_mpe.ocular_mpe(spec.laser.wavelength_nm, x, standard=spec.exposure.standard).radiant_exposure_j_m2 for x in el])
        return cls(t, row, cum, limit, result.observers.labels[observer])

    def plot(self, ax=None):
        fig, ax = _axes(ax)
        ax.semilogy(self.times_s[1:], np.maximum(self.exposure_j_m2[1:], 1e-12), label="accumulated exposure H(t)")
        ax.semilogy(self.times_s[1:], self.mpe_exposure_j_m2[1:], "k--", label="MPE for the elapsed time")
        ax2 = ax.twinx()
        ax2.plot(self.times_s, self.irradiance_w_m2, c="tab:orange", alpha=0.6, label="irradiance")
        ax2.set_ylabel("irradiance [W/m^2]", color="tab:orange")
        ax.set_xlabel("time [s]")
        ax.set_ylabel("radiant exposure [J/m^2]")
        ax.set_title(f"observer {self.observer}")
        ax.legend(loc="lower right", fontsize=8)
        ax.grid(alpha=0.3, which="both")
        return fig, ax


@dataclass
class ErrorTableDisplay(_Display):
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
