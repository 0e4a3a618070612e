"""A tabulated BRDF: measured values on a grid in half/difference coordinates.

``TabulatedBRDF(theta_h_deg, theta_d_deg, phi_d_deg, values)`` holds f_r [1/sr] at the
nodes of a (theta_h, theta_d, phi_d) grid (Rusinkiewicz's coordinates, isotropic: no
phi_h; :func:`brdfmodels.half_diff`) and interpolates it trilinearly: between nodes the
value is a convex combination of the cell's 8 corners, so it never leaves their range
(monotone, no overshoot). phi_d is folded to [0, 180) deg, which makes the model exactly
reciprocal (swapping wi and wo turns phi_d by 180 deg and leaves theta_h, theta_d).

Directions outside the measured range (theta_h or theta_d beyond the grid's nodes) follow
an explicit policy, ``outside``:

- ``"error"``: a ValueError naming the direction's angles and the range;
- ``"envelope"`` (conservative): the table's largest value (what the material was seen to
  return at most);
- ``"fit"``: a spherical-harmonic fit of the table (log space, with the SH fit's horizon
  tacking for the directions no data reach; :func:`brdfmodels.fitting.fit_sh`), made on
  first use.

:meth:`TabulatedBRDF.from_merl` builds one from a MERL ``.binary`` file,
:meth:`TabulatedBRDF.from_samples` grids scattered samples (any reader's) onto nodes. Save and load it
like any model (its values travel in the JSON), so a scene takes it as
``material = { file = "table.json" }``.
"""

from __future__ import annotations

import math

import numpy as np

from ._checks import finite_array
from .geometry import isotropic_half_diff_rad
from .models import BRDFModel
from .registry import register
from .scattered import ScatteredBRDF
from .states import cell_fraction

__all__ = ["TabulatedBRDF", "OUTSIDE_POLICIES"]

OUTSIDE_POLICIES = ("error", "envelope", "fit")


def _nodes(name, deg, lo, hi):
    v = finite_array(name, deg).ravel()
    if v.size < 1 or np.any(np.diff(v) <= 0) or v[0] < lo or v[-1] > hi:
        raise ValueError(f"{name}: expected strictly increasing angles within [{lo:g}, {hi:g}] deg")
    return np.radians(v)


def _axis_weights(nodes, x):
    """Lower node index and weight of the upper one, for x inside [nodes[0], nodes[-1]]."""
    i, t = cell_fraction(nodes, x)
    return i, np.clip(t, 0.0, 1.0)


@register("table")
class TabulatedBRDF(BRDFModel):
    """Trilinear interpolation of f_r [1/sr] on a (theta_h, theta_d, phi_d) grid.

    Parameters
    ----------
    theta_h_deg, theta_d_deg : array_like
        Increasing node angles in [0, 90] deg.
    phi_d_deg : array_like
        Increasing node angles in [0, 180) deg (periodic: folded modulo 180).
    values : array_like, shape (n_h, n_d, n_phi)
        f_r [1/sr] at the nodes, finite and >= 0. Nodes whose directions dip below the
        horizon (theta_h + theta_d > 90 deg, depending on phi_d) are never looked up
        themselves but weigh in the cells next to them: give them the neighbouring
        measured value, not 0 (a 0 there pulls grazing values down).
    outside : {"error", "envelope", "fit"}
        What directions outside the theta_h / theta_d range get (module notes).
    notes : sequence of str
        What the table's maker wants said (a gridding's shortfall below the samples); a
        scene shows them among its warnings. Not saved with the table.
    """

    def __init__(self, theta_h_deg, theta_d_deg, phi_d_deg, values, outside="error", notes=()):
        self.theta_h = _nodes("theta_h_deg", theta_h_deg, 0.0, 90.0)
        self.theta_d = _nodes("theta_d_deg", theta_d_deg, 0.0, 90.0)
        self.phi_d = _nodes("phi_d_deg", phi_d_deg, 0.0, 180.0 - 1e-12)
        v = finite_array("values", values)
        shape = (len(self.theta_h), len(self.theta_d), len(self.phi_d))
        if v.shape != shape or np.any(v < 0):
            raise ValueError(f"values: expected shape {shape} of finite values >= 0, got shape {v.shape}")
        if outside not in OUTSIDE_POLICIES:
            raise ValueError(f"outside={outside!r}: expected one of {list(OUTSIDE_POLICIES)}")
        self.values = np.array(v, float)
        for arr in (self.theta_h, self.theta_d, self.phi_d, self.values):
            arr.flags.writeable = False  # immutable like every model
        self.outside = outside
        self.notes = tuple(str(n) for n in notes)
        self._fit_cache = []  # the "fit" policy's SH model, made on first use
        self._freeze()

    @classmethod
    def from_merl(cls, path, channel="mean", outside="envelope", step=1) -> "TabulatedBRDF":
        """The table of a MERL ``.binary`` file (cell centres as nodes; cells without
        data take the largest of the file, conservative), every ``step``-th node."""
        from .io import merl_grid

        (th, td, pd), v = merl_grid(path, channel)
        if not np.any(np.isfinite(v)):
            raise ValueError(f"{path}: no cell of the MERL file has data (every value negative or not finite)")
        v = np.where(np.isnan(v), np.nanmax(v), v)
        sl = slice(None, None, step)
        return cls(th[sl], td[sl], pd[sl], v[sl, sl, sl], outside)

    @classmethod
    def from_samples(cls, wi, wo, brdf_per_sr, theta_h_deg, theta_d_deg, phi_d_deg, *, fill="envelope",
                     outside="envelope", notes=()) -> "TabulatedBRDF":
        """A table of scattered samples (any reader's, :mod:`brdfmodels.io`) on the given
        nodes: each node takes the samples' interpolation there
        (:class:`brdfmodels.ScatteredBRDF`, peak-aware: at least the convex combination of
        the neighbouring samples, at most PEAK_CAP times it), a node
        beyond the samples' hull ``fill``: ``"envelope"`` (the largest of the 4 nearest
        samples, conservative) or ``"fit"`` (a spherical-harmonic fit of the samples). The
        grid adds its own error between nodes (a peak between nodes is cut); the scattered
        model itself has none at the samples. ``notes`` (a reader's) are kept, and a
        shortfall of the grid below a sample of more than 1 % is added to them."""
        if fill not in ("envelope", "fit"):
            raise ValueError(f"fill={fill!r}: expected 'envelope' or 'fit'")
        axes = [_nodes(n, a, 0.0, hi) for n, a, hi in (("theta_h_deg", theta_h_deg, 90.0), ("theta_d_deg", theta_d_deg, 90.0),
                                                        ("phi_d_deg", phi_d_deg, 180.0 - 1e-12))]
        scattered = ScatteredBRDF.from_samples(wi, wo, brdf_per_sr, outside=fill)
        h, d, p = np.meshgrid(*axes, indexing="ij")
        values = scattered.at_coordinates(h, d, p).reshape(h.shape)
        table = cls(*(np.degrees(a) for a in axes), values, outside, notes=notes)
        f = np.ravel(brdf_per_sr)
        ratio = table.evaluate(wi, wo)[f > 0] / f[f > 0]
        if ratio.size and ratio.min() < 0.99:  # said, not hidden: the grid cuts peaks between its nodes
            k = int(np.argmin(ratio))
            note = (f"gridded on {len(axes[0])} x {len(axes[1])} x {len(axes[2])} nodes, the table returns down to "
                    f"{100 * ratio[k]:.3g} % of a measured sample ({int((ratio < 0.99).sum())} of {ratio.size} samples more "
                    f"than 1 % below); without a grid every sample is returned")
            table = cls(*(np.degrees(a) for a in axes), values, outside, notes=tuple(notes) + (note,))
        return table

    def _interpolate(self, th, td, pd):
        ih, th_t = _axis_weights(self.theta_h, th)
        idd, td_t = _axis_weights(self.theta_d, td)
        n_p = len(self.phi_d)
        if n_p == 1:
            ip, ip1, pt = np.zeros(len(pd), np.intp), np.zeros(len(pd), np.intp), np.zeros(len(pd))
        else:  # periodic over [0, pi): the cell past the last node wraps to the first
            ext = np.append(self.phi_d, self.phi_d[0] + np.pi)
            x = np.where(pd < self.phi_d[0], pd + np.pi, pd)
            ip = np.clip(np.searchsorted(ext, x, side="right") - 1, 0, n_p - 1)
            pt = np.clip((x - ext[ip]) / (ext[ip + 1] - ext[ip]), 0.0, 1.0)
            ip1 = (ip + 1) % n_p
        h1 = np.minimum(ih + 1, len(self.theta_h) - 1)
        d1 = np.minimum(idd + 1, len(self.theta_d) - 1)
        v = self.values
        out = np.zeros(len(th))
        for a, wa in ((ih, 1 - th_t), (h1, th_t)):
            for b, wb in ((idd, 1 - td_t), (d1, td_t)):
                out += wa * wb * ((1 - pt) * v[a, b, ip] + pt * v[a, b, ip1])
        return out

    def _fr(self, wi, wo, state):
        th, td, pd = isotropic_half_diff_rad(wi, wo)
        tol = 1e-12
        inside = ((th >= self.theta_h[0] - tol) & (th <= self.theta_h[-1] + tol)
                  & (td >= self.theta_d[0] - tol) & (td <= self.theta_d[-1] + tol))
        out = np.empty(len(th))
        out[inside] = self._interpolate(th[inside], td[inside], pd[inside])
        if not inside.all():
            out[~inside] = self._outside(wi[~inside], wo[~inside], th[~inside], td[~inside])
        return out

    def _outside(self, wi, wo, th, td):
        if self.outside == "error":
            k = 0
            raise ValueError(f"direction pair outside the table: theta_h {math.degrees(th[k]):.4g} deg, theta_d "
                             f"{math.degrees(td[k]):.4g} deg; the table spans theta_h [{math.degrees(self.theta_h[0]):.4g}, "
                             f"{math.degrees(self.theta_h[-1]):.4g}], theta_d [{math.degrees(self.theta_d[0]):.4g}, "
                             f"{math.degrees(self.theta_d[-1]):.4g}] deg (outside = 'envelope' or 'fit' to go beyond)")
        if self.outside == "envelope":
            return np.full(len(th), float(self.values.max()))
        return self._fitted().evaluate(wi, wo)

    def _fitted(self):
        if not self._fit_cache:
            from .fitting import fit_sh
            from .geometry import half_diff_to_directions
            from .sh import SHBasis

            h, d, p = np.meshgrid(self.theta_h, self.theta_d, self.phi_d, indexing="ij")
            wi, wo = half_diff_to_directions(h.ravel(), np.zeros(h.size), d.ravel(), p.ravel())
            f = self.values.ravel()
            keep = (wi[:, 2] > 1e-6) & (wo[:, 2] > 1e-6) & (f > 0)
            self._fit_cache.append(fit_sh(wi[keep], wo[keep], f[keep], SHBasis(8, 4, 2, 0)).model)
        return self._fit_cache[0]

    def _params(self):
        return {"theta_h_deg": np.degrees(self.theta_h).tolist(), "theta_d_deg": np.degrees(self.theta_d).tolist(),
                "phi_d_deg": np.degrees(self.phi_d).tolist(), "values": self.values.tolist(), "outside": self.outside}
