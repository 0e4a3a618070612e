"""Witness-screen BRDF measurement: reduction of camera frames, and a forward simulator.

Restates Bailey et al., J. Laser Appl. 20(1), 2008, Secs. II-III (spec
`witness-screen.md`). Lab frame: origin at the laser spot on the sample, +y along the
incident beam, +z up. A flat Lambertian screen is filmed by a camera; every pixel of a
frame gives f_r for one reflection direction at one moment of the sample's history.

* Eq. 6, pixel -> screen point:
  ``r(i, j) = r_ul + (i - i_top)(r_ll - r_ul)/(i_bottom - i_top) + (j - j_left)(r_ur - r_ul)/(j_right - j_left)``
* Eq. 13, responsivity from the point-source image U^P:
  ``R(i, j) = (1/E_C) U^P(i, j) U_C / U_C^P * r^3 / r_C^3``
* Eqs. 14-15: ``E_is = U / R``; ``f_r = E_is r^2 / (P cos(theta_is) cos(theta_rt))``
* Eq. 16 (expanded, tested equal):
  ``f_r = (E_C/P) (U U_C^P)/(U^P U_C) r_C^3 / r / (cos(theta_is) cos(theta_rt))``

All counts are background-subtracted. Pixels at or below background, saturated, outside
the screen rectangle, or seen from behind the sample carry no data and are masked.
"""

from __future__ import annotations

import csv
import math
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ._checks import finite_array, finite_scalar
from .fileio import atomic_write, atomic_write_text, read_csv_columns, read_toml
from .geometry import local_frame

__all__ = [
    "ScreenGeometry",
    "Calibration",
    "ScreenTest",
    "Samples",
    "screen_points",
    "responsivity",
    "frame_brdf",
    "frame_brdf_expanded",
    "reduce_test",
    "load_test",
    "simulate_test",
    "save_test",
    "group_by_state",
    "group_by_states",
    "state_column",
    "SpotSizeWarning",
]


class SpotSizeWarning(UserWarning):
    """The screen is closer than 20 spot sizes: the point-source approximation errs > 1 %."""


@dataclass(frozen=True)
class ScreenGeometry:
    """Screen corners [m] (lab frame) and the pixel rows/columns of its edges."""

    upper_left_m: np.ndarray
    upper_right_m: np.ndarray
    lower_left_m: np.ndarray
    top_row: float
    bottom_row: float
    left_col: float
    right_col: float

    def __post_init__(self):
        for name in ("upper_left_m", "upper_right_m", "lower_left_m"):
            v = finite_array(name, getattr(self, name))
            if v.shape != (3,):
                raise ValueError(f"{name}: expected a 3-vector [m], got shape {v.shape}")
            object.__setattr__(self, name, v)
        if not self.bottom_row > self.top_row:
            raise ValueError(f"bottom_row={self.bottom_row!r}: expected below top_row={self.top_row!r} (rows grow downwards)")
        if not self.right_col > self.left_col:
            raise ValueError(f"right_col={self.right_col!r}: expected right of left_col={self.left_col!r}")

    @property
    def normal(self) -> np.ndarray:
        """Unit screen normal, facing the origin (the sample)."""
        n = np.cross(self.upper_right_m - self.upper_left_m, self.lower_left_m - self.upper_left_m)
        n /= np.linalg.norm(n)
        return n if np.dot(n, -self.upper_left_m) > 0 else -n


@dataclass(frozen=True)
class Calibration:
    """Calibration values: meter irradiance E_C [W/m^2] at pixel (i_C, j_C) where the
    camera read U_C counts (background-subtracted)."""

    irradiance_w_m2: float
    pixel: tuple
    counts: float

    def __post_init__(self):
        finite_scalar("calibration.irradiance_w_m2", self.irradiance_w_m2, minimum=0.0, strict_min=True)
        finite_scalar("calibration.counts", self.counts, minimum=0.0, strict_min=True)
        if len(self.pixel) != 2:
            raise ValueError(f"calibration.pixel={self.pixel!r}: expected [row, column]")


def screen_points(geom: ScreenGeometry, rows, cols) -> np.ndarray:
    """Eq. 6: lab-frame screen point [m] of pixel (row i, column j); broadcasts."""
    i = np.asarray(rows, float)[..., None]
    j = np.asarray(cols, float)[..., None]
    return (geom.upper_left_m + (i - geom.top_row) * (geom.lower_left_m - geom.upper_left_m) / (geom.bottom_row - geom.top_row)
            + (j - geom.left_col) * (geom.upper_right_m - geom.upper_left_m) / (geom.right_col - geom.left_col))


def responsivity(point_counts, r_m, cal: Calibration, r_cal_m: float) -> np.ndarray:
    """Eq. 13: per-pixel responsivity R = (1/E_C) U^P U_C / U_C^P r^3 / r_C^3 [counts per W/m^2]."""
    up = np.asarray(point_counts, float)
    i_c, j_c = (int(round(p)) for p in cal.pixel)
    up_c = up[i_c, j_c]
    if not up_c > 0:
        raise ValueError(f"calibration.pixel={list(cal.pixel)}: the point-source image has no signal there ({up_c!r} counts)")
    return up * cal.counts / up_c * np.asarray(r_m) ** 3 / r_cal_m**3 / cal.irradiance_w_m2


def frame_brdf(counts, resp, r_m, cos_is, cos_rt, power_w) -> np.ndarray:
    """Eqs. 14-15 step by step: E_is = U / R, f_r = E_is r^2 / (P cos(theta_is) cos(theta_rt))."""
    with np.errstate(divide="ignore", invalid="ignore"):
        e_is = np.asarray(counts, float) / resp
        return e_is * np.asarray(r_m) ** 2 / (power_w * cos_is * cos_rt)


def frame_brdf_expanded(counts, point_counts, cal: Calibration, r_m, r_cal_m, cos_is, cos_rt, power_w) -> np.ndarray:
    """Eq. 16: f_r = (E_C / P) (U U_C^P) / (U^P U_C) r_C^3 / r / (cos(theta_is) cos(theta_rt))."""
    up = np.asarray(point_counts, float)
    i_c, j_c = (int(round(p)) for p in cal.pixel)
    with np.errstate(divide="ignore", invalid="ignore"):
        return (cal.irradiance_w_m2 / power_w) * (np.asarray(counts, float) * up[i_c, j_c]) / (up * cal.counts) \
            * r_cal_m**3 / np.asarray(r_m) / (cos_is * cos_rt)


@dataclass
class ScreenTest:
    """One test: geometry, sample orientation, laser, calibration, images and pyrometer."""

    test_id: str
    geometry: ScreenGeometry
    sample_normal: np.ndarray
    groove: np.ndarray
    incidence: np.ndarray  # propagation direction of the beam (lab frame), default +y
    power_w: float
    calibration: Calibration
    point_source: np.ndarray  # (H, W) counts, background included
    frames: np.ndarray  # (F, H, W) counts, background included
    times_s: np.ndarray  # (F,)
    background: float | np.ndarray
    saturation: float
    point_source_background: float | np.ndarray = 0.0
    pyrometer_times_s: np.ndarray | None = None
    pyrometer_temperatures_k: np.ndarray | None = None
    spot_size_m: float | None = None
    weight_floor: float = 1.0


@dataclass
class Samples:
    """Reduced samples: directions in the sample's surface frame (z = normal, x = grooves).

    Attributes
    ----------
    wi, wo : ndarray, shape (N, 3)
        Unit directions to the source and to the observer (surface frame).
    brdf_per_sr : ndarray, shape (N,)
        f_r [1/sr].
    time_s, temperature_k : ndarray, shape (N,)
        Time since irradiation start [s] and pyrometer temperature [K] (nan: none).
    test_id, frame_id, weight : ndarray, shape (N,)
        Test, frame within the test, relative fit weight.
    info : dict
        Free-form notes of the reduction.
    states : dict of str -> ndarray, shape (N,)
        Further named state columns (e.g. ``"extinction"``, ``"melt_fraction"``), in the
        unit their name gives; nan where a sample has none. Written after the fixed
        :attr:`COLUMNS` in CSV and Parquet; files without them still load.
    """

    wi: np.ndarray
    wo: np.ndarray
    brdf_per_sr: np.ndarray
    time_s: np.ndarray
    temperature_k: np.ndarray
    test_id: np.ndarray
    frame_id: np.ndarray
    weight: np.ndarray
    info: dict = field(default_factory=dict)
    states: dict = field(default_factory=dict)

    COLUMNS = ("wi_x", "wi_y", "wi_z", "wo_x", "wo_y", "wo_z", "brdf_per_sr", "time_s", "temperature_k", "test_id", "frame_id", "weight")

    def __post_init__(self):
        self.states = _check_state_columns(self.states, len(self.brdf_per_sr))

    def __len__(self):
        return len(self.brdf_per_sr)

    def with_states(self, columns) -> "Samples":
        """A copy with the named state columns added or replaced.

        Parameters
        ----------
        columns : dict of str -> array_like, shape (N,) (or a scalar, one value for all)
            State values per sample, e.g. ``{"extinction": xi, "melt_fraction": m}``.
        """
        n = len(self)
        full = {k: np.full(n, v, dtype=object) if np.ndim(v) == 0 else v for k, v in dict(columns).items()}
        return Samples(self.wi, self.wo, self.brdf_per_sr, self.time_s, self.temperature_k, self.test_id, self.frame_id,
                       self.weight, dict(self.info), {**self.states, **full})

    def select(self, mask) -> "Samples":
        m = np.asarray(mask)
        return Samples(self.wi[m], self.wo[m], self.brdf_per_sr[m], self.time_s[m], self.temperature_k[m], self.test_id[m],
                       self.frame_id[m], self.weight[m], dict(self.info), {k: v[m] for k, v in self.states.items()})

    @staticmethod
    def concatenate(parts) -> "Samples":
        """One table of ``parts``; a state column missing from some parts is nan there."""
        parts = list(parts)
        cat = lambda name: np.concatenate([getattr(p, name) for p in parts])
        names = list(dict.fromkeys(k for p in parts for k in p.states))
        states = {k: np.concatenate([p.states.get(k, np.full(len(p), np.nan)) for p in parts]) for k in names}
        return Samples(cat("wi"), cat("wo"), cat("brdf_per_sr"), cat("time_s"), cat("temperature_k"), cat("test_id"),
                       cat("frame_id"), cat("weight"), states=states)

    @property
    def header(self) -> tuple:
        """Column names of the table files: :attr:`COLUMNS`, then the state columns."""
        return self.COLUMNS + tuple(self.states)

    def to_csv(self, path) -> Path:
        import io

        buf = io.StringIO()
        w = csv.writer(buf)
        w.writerow(self.header)
        extra = list(self.states.values())
        for k in range(len(self)):
            w.writerow([*map(repr, self.wi[k].tolist()), *map(repr, self.wo[k].tolist()), repr(float(self.brdf_per_sr[k])),
                        repr(float(self.time_s[k])), repr(float(self.temperature_k[k])), self.test_id[k], int(self.frame_id[k]),
                        repr(float(self.weight[k])), *(repr(float(col[k])) for col in extra)])
        return atomic_write_text(path, buf.getvalue())

    def to_parquet(self, path) -> Path:
        """Write the table as Parquet (needs pyarrow: ``pip install pyarrow``); atomic."""
        try:
            import pyarrow as pa
            import pyarrow.parquet as pq
        except ImportError:
            raise ValueError("Parquet output needs pyarrow: pip install pyarrow (or use CSV)") from None
        cols = dict(zip(self.COLUMNS[:6], np.hstack([self.wi, self.wo]).T))
        cols.update(brdf_per_sr=self.brdf_per_sr, time_s=self.time_s, temperature_k=self.temperature_k,
                    test_id=np.asarray(self.test_id, str), frame_id=np.asarray(self.frame_id, np.int64), weight=self.weight)
        cols.update({k: np.asarray(v, float) for k, v in self.states.items()})
        return atomic_write(path, lambda tmp: pq.write_table(pa.table({k: cols[k] for k in self.header}), tmp))

    @classmethod
    def from_parquet(cls, path) -> "Samples":
        try:
            import pyarrow.parquet as pq
        except ImportError:
            raise ValueError("Parquet input needs pyarrow: pip install pyarrow (or use CSV)") from None
        t = pq.read_table(path).to_pydict()
        missing = [c for c in cls.COLUMNS if c not in t]
        if missing:
            raise ValueError(f"{path}: missing columns {missing}")
        g = lambda k: np.asarray(t[k], float)
        extra = _extra_columns(path, list(t))
        try:
            states = {k: g(k) for k in extra}
        except (TypeError, ValueError):
            raise ValueError(f"{path}: state columns {extra}: expected numbers") from None
        return cls(np.stack([g("wi_x"), g("wi_y"), g("wi_z")], 1), np.stack([g("wo_x"), g("wo_y"), g("wo_z")], 1), g("brdf_per_sr"),
                   g("time_s"), g("temperature_k"), np.asarray(t["test_id"]), np.asarray(t["frame_id"], int), g("weight"),
                   states=states)

    @classmethod
    def read(cls, path) -> "Samples":
        """CSV or Parquet by the file's suffix (a regular file of bounded size)."""
        from .fileio import check_input_file

        try:
            check_input_file(path, "samples")
        except ValueError:
            if Path(path).exists():
                raise
            raise ValueError(f"{path}: cannot read the samples (No such file or directory)") from None
        return cls.from_parquet(path) if str(path).endswith(".parquet") else cls.from_csv(path)

    def write(self, path) -> Path:
        return self.to_parquet(path) if str(path).endswith(".parquet") else self.to_csv(path)

    @classmethod
    def from_csv(cls, path) -> "Samples":
        path = Path(path)
        try:
            with open(path, newline="", encoding="utf-8") as fh:
                rows = list(csv.reader(fh))
        except OSError as exc:
            raise ValueError(f"{path}: cannot read the samples ({exc.strerror})") from None
        ncol = len(cls.COLUMNS)
        if not rows or tuple(rows[0][:ncol]) != cls.COLUMNS:
            raise ValueError(f"{path}: expected the columns {list(cls.COLUMNS)} (then any state columns)")
        extra = _extra_columns(path, rows[0])
        body = rows[1:]
        if not body:
            raise ValueError(f"{path}: no samples")
        width = ncol + len(extra)
        short = next((i for i, r in enumerate(body) if len(r) != width), None)
        if short is not None:
            raise ValueError(f"{path}: line {short + 2}: expected {width} values, got {len(body[short])}")
        cols = (0, 1, 2, 3, 4, 5, 6, 7, 8, 11, *range(ncol, width))
        try:
            num = np.array([[float(r[k]) for k in cols] for r in body])
            frame = np.array([int(r[10]) for r in body])
        except ValueError:  # name the cell, quote nothing of the file
            line, col = next((i + 2, k + 1) for i, r in enumerate(body) for k in (*cols, 10) if not _is_number(r[k], k == 10))
            raise ValueError(f"{path}: line {line}, column {col}: expected {'an integer' if col == 11 else 'a number'}") from None
        states = {name: num[:, 10 + i] for i, name in enumerate(extra)}
        return cls(num[:, 0:3], num[:, 3:6], num[:, 6], num[:, 7], num[:, 8], np.array([r[9] for r in body]),
                   frame, num[:, 9], states=states)


def _is_number(text, integer=False) -> bool:
    try:
        (int if integer else float)(text)
        return True
    except ValueError:
        return False


def _extra_columns(path, header) -> list:
    """The state columns of a table file: those after :attr:`Samples.COLUMNS`."""
    extra = [c for c in header if c not in Samples.COLUMNS]
    dup = sorted({c for c in header if list(header).count(c) > 1})
    if dup:
        raise ValueError(f"{path}: line 1: column {list(header).index(dup[0]) + 1} and another have the same name; "
                         f"expected each column once")
    return extra


def _check_state_columns(states, n: int) -> dict:
    """Named state columns as float arrays of length ``n`` (names not among COLUMNS)."""
    if not isinstance(states, dict):
        raise ValueError(f"states={type(states).__name__}: expected a dict of name -> values")
    out = {}
    for name, values in states.items():
        if not isinstance(name, str) or not name or name in Samples.COLUMNS or name in ("wi", "wo"):
            raise ValueError(f"states: column name {name!r}: expected a non-empty name other than {list(Samples.COLUMNS)}")
        try:
            v = np.asarray(values, float)
        except (TypeError, ValueError):
            raise ValueError(f"states[{name!r}]: expected numbers (nan for none)") from None
        if v.shape != (n,):
            raise ValueError(f"states[{name!r}]: expected shape ({n},) (one value per sample), got {v.shape}")
        if np.any(np.isinf(v)):
            raise ValueError(f"states[{name!r}] contains {float(v[np.isinf(v)][0])!r}: expected finite values (nan for none)")
        out[name] = v
    return out


def reduce_test(test: ScreenTest) -> Samples:
    """Reduce a test's frames to BRDF samples (Eqs. 6, 13-16), masking pixels without data.

    Raises ValueError for inconsistent inputs (mismatched shapes, nan counts, a
    calibration pixel outside the image, a pyrometer series that does not cover the
    frames, all pixels masked) and warns (:class:`SpotSizeWarning`) when the screen is
    nearer than 20 spot sizes.
    """
    g = test.geometry
    up_raw = finite_array("point_source", test.point_source, ndim=2)
    frames = np.asarray(test.frames, float)
    if frames.ndim != 3 or frames.shape[1:] != up_raw.shape:
        raise ValueError(f"frames: expected shape (F, {up_raw.shape[0]}, {up_raw.shape[1]}) like the point-source image, got {frames.shape}")
    if not np.all(np.isfinite(frames)):
        f = int(np.argwhere(~np.isfinite(frames))[0][0])
        raise ValueError(f"frames: frame {f} contains nan or inf counts")
    times = finite_array("times_s", test.times_s, ndim=1)
    if times.shape != (frames.shape[0],):
        raise ValueError(f"times_s: expected one time per frame ({frames.shape[0]}), got {times.shape[0]}")
    h, w = up_raw.shape
    i_c, j_c = (int(round(p)) for p in test.calibration.pixel)
    if not (0 <= i_c < h and 0 <= j_c < w):
        raise ValueError(f"calibration.pixel={list(test.calibration.pixel)} is outside the {h} x {w} image")
    if not (g.top_row >= -0.5 and g.bottom_row <= h - 0.5 and g.left_col >= -0.5 and g.right_col <= w - 0.5):
        raise ValueError(f"screen edges rows [{g.top_row}, {g.bottom_row}], columns [{g.left_col}, {g.right_col}] lie outside the {h} x {w} image")

    rows, cols = np.mgrid[0:h, 0:w]
    r_vec = screen_points(g, rows, cols)
    r = np.linalg.norm(r_vec, axis=-1)
    rhat = r_vec / r[..., None]
    cos_is = np.abs(rhat @ g.normal)
    frame = local_frame(test.sample_normal, test.groove)  # rows x (grooves), y, z (normal)
    cos_rt = rhat @ frame[2]
    r_c = float(r[i_c, j_c])

    if test.spot_size_m is not None:
        if r.min() < 20.0 * test.spot_size_m:
            warnings.warn(f"test {test.test_id}: the screen is {r.min():.3g} m away, under 20 spot sizes "
                          f"({20 * test.spot_size_m:.3g} m): point-source error above ~1 %", SpotSizeWarning, stacklevel=2)

    up = up_raw - test.point_source_background
    resp = responsivity(up, r, test.calibration, r_c)
    inside = (rows >= g.top_row) & (rows <= g.bottom_row) & (cols >= g.left_col) & (cols <= g.right_col)
    base_mask = inside & (up > 0) & (cos_rt > 0) & (cos_is > 0)
    if test.pyrometer_times_s is not None:
        pt = finite_array("pyrometer times_s", test.pyrometer_times_s, ndim=1)
        pk = finite_array("pyrometer temperatures_k", test.pyrometer_temperatures_k, ndim=1)
        if pt.shape != pk.shape or pt.size < 2:
            raise ValueError("pyrometer: expected two equal-length columns (time_s, temperature_k), at least two rows")
        if times.min() < pt.min() or times.max() > pt.max():
            raise ValueError(f"pyrometer: the series covers [{pt.min():g}, {pt.max():g}] s but the frames span "
                             f"[{times.min():g}, {times.max():g}] s")
        temps = np.interp(times, pt, pk)
    else:
        temps = np.full(times.shape, np.nan)
    wi_local = frame @ (-np.asarray(test.incidence, float) / np.linalg.norm(test.incidence))
    wo_local = rhat @ frame.T
    parts = []
    for f in range(frames.shape[0]):
        u = frames[f] - test.background
        ok = base_mask & (u > 0) & (frames[f] < test.saturation)
        if not np.any(ok):
            continue
        fr = frame_brdf(u[ok], resp[ok], r[ok], cos_is[ok], cos_rt[ok], test.power_w)
        n = int(ok.sum())
        parts.append(Samples(
            np.tile(wi_local, (n, 1)), wo_local[ok], fr, np.full(n, times[f]), np.full(n, temps[f]),
            np.full(n, test.test_id, dtype=object), np.full(n, f), np.maximum(u[ok], test.weight_floor) / np.maximum(u[ok].max(), 1.0),
        ))
    if not parts:
        raise ValueError(f"test {test.test_id}: every pixel is masked (at or below background, saturated, off-screen or behind the sample)")
    out = Samples.concatenate(parts)
    out.info = {"test_id": test.test_id, "frames": int(frames.shape[0]), "screen_distance_min_m": float(r.min()),
                "masked_fraction": float(1 - len(out) / (frames.shape[0] * h * w))}
    return out


def _test_schema():
    """Pydantic classes of a screen-test file: strict types, finite numbers, no unknown keys."""
    from typing import Annotated

    from pydantic import BaseModel, ConfigDict, Field

    class _S(BaseModel):
        model_config = ConfigDict(extra="forbid", strict=True, allow_inf_nan=False)

    Num = Annotated[float, Field(ge=-1e9, le=1e9)]
    Vec3 = Annotated[list[Num], Field(min_length=3, max_length=3)]
    File = Annotated[str, Field(min_length=1, max_length=1000)]

    class Screen(_S):
        upper_left_m: Vec3
        upper_right_m: Vec3
        lower_left_m: Vec3
        top_row: Num
        bottom_row: Num
        left_col: Num
        right_col: Num

    class Sample(_S):
        normal: Vec3
        groove: Vec3
        incidence: Vec3 | None = None
        spot_size_m: Annotated[float, Field(gt=0, le=10)] | None = None

    class Laser(_S):
        power_w: Annotated[float, Field(gt=0, le=1e9)]

    class Cal(_S):
        irradiance_w_m2: Annotated[float, Field(gt=0, le=1e12)]
        pixel: Annotated[list[Num], Field(min_length=2, max_length=2)]
        counts: Annotated[float, Field(gt=0, le=1e15)]

    class Images(_S):
        point_source: File
        frames: File
        background: Num = 0.0
        point_source_background: Num | None = None
        saturation: Annotated[float, Field(gt=0, le=1e15)]

    class Pyrometer(_S):
        file: File

    class ScreenTestSpec(_S):
        test_id: Annotated[str, Field(min_length=1, max_length=200)] | None = None
        screen: Screen
        sample: Sample
        laser: Laser
        calibration: Cal
        images: Images
        pyrometer: Pyrometer | None = None

    return ScreenTestSpec


def _validate_test(d, path):
    from pydantic import ValidationError

    try:
        _test_schema().model_validate(d)
    except ValidationError as exc:
        errs = sorted(exc.errors(include_url=False), key=lambda e: e["type"] != "missing")
        msgs = []
        for e in errs:
            where = "".join(f"[{p}]" if isinstance(p, int) else ("." if i else "") + str(p) for i, p in enumerate(e["loc"]))
            if e["type"] == "missing":
                msgs.append(f"{where}: missing")
            elif e["type"] == "extra_forbidden":
                msgs.append(f"{where}: unknown key (check its spelling)")
            else:
                inp = e.get("input")
                shown = "" if isinstance(inp, (dict, list)) else f" (got {inp!r})"
                msgs.append(f"{where}: {e['msg'].removeprefix('Value error, ')}{shown}")
        more = f" (and {len(msgs) - 1} more: {'; '.join(msgs[1:4])})" if len(msgs) > 1 else ""
        raise ValueError(f"{path}: {msgs[0]}{more}") from None


def _need(d, key, where):
    if key not in d:
        raise ValueError(f"{where}.{key}: missing")
    return d[key]


def load_test(path) -> ScreenTest:
    """Read a test description (TOML) and the files it names (.npy / .npz / CSV).

    Keys: ``test_id``; ``[screen]`` upper_left_m, upper_right_m, lower_left_m, top_row,
    bottom_row, left_col, right_col; ``[sample]`` normal, groove, incidence (beam
    direction, default [0, 1, 0]), spot_size_m; ``[laser]`` power_w; ``[calibration]``
    irradiance_w_m2, pixel, counts; ``[images]`` point_source (.npy), frames (.npz with
    arrays ``frames`` and ``times_s``), background, point_source_background, saturation;
    optional ``[pyrometer]`` file (CSV with columns time_s, temperature_k).
    """
    path = Path(path)
    d = read_toml(path)
    base = path.parent
    known = {"test_id", "screen", "sample", "laser", "calibration", "images", "pyrometer"}
    unknown = set(d) - known
    if unknown:
        raise ValueError(f"{path}: unknown keys {sorted(unknown)}; expected {sorted(known)}")
    _validate_test(d, path)
    s, smp, las, cal, img = (_need(d, k, "test") for k in ("screen", "sample", "laser", "calibration", "images"))
    geom = ScreenGeometry(*(np.asarray(_need(s, k, "screen"), float) for k in ("upper_left_m", "upper_right_m", "lower_left_m")),
                          *(float(_need(s, k, "screen")) for k in ("top_row", "bottom_row", "left_col", "right_col")))
    try:
        calib = Calibration(float(_need(cal, "irradiance_w_m2", "calibration")), tuple(_need(cal, "pixel", "calibration")),
                            float(_need(cal, "counts", "calibration")))
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{path}: {exc}") from None

    def load_array(name, key=None):
        from .fileio import check_input_file, check_limit

        p = base / name
        check_input_file(p, f"image file of {path}")
        try:
            arr = np.load(p, allow_pickle=False)
        except (OSError, ValueError, EOFError) as exc:  # NumPy's text may quote the file: only its kind is named
            raise ValueError(f"{path}: cannot read {name} ({type(exc).__name__}: not a .npy / .npz file of plain numbers?)") from None
        if key is not None:
            if key not in arr:
                raise ValueError(f"{path}: {name} has no array {key!r}")
            info = arr.zip.getinfo(f"{key}.npy") if hasattr(arr, "zip") else None
            if info is not None:  # a compressed member may unpack to far more than the file (zip bomb)
                check_limit("SAMPLES", info.file_size / 8, f"{path}: {name}[{key}] size (8-byte values)")
            arr = arr[key]
        check_limit("SAMPLES", arr.size, f"{path}: {name} values")
        if arr.dtype.kind not in "iuf":
            raise ValueError(f"{path}: {name}: expected numbers, got dtype {arr.dtype}")
        return np.asarray(arr, float)

    frames_file = _need(img, "frames", "images")
    pyro_t = pyro_k = None
    if "pyrometer" in d:
        pf = base / _need(d["pyrometer"], "file", "pyrometer")
        data = read_csv_columns(pf, ["time_s", "temperature_k"], "pyrometer file")
        pyro_t, pyro_k = data["time_s"], data["temperature_k"]
    return ScreenTest(
        test_id=str(d.get("test_id", path.stem)),
        geometry=geom,
        sample_normal=np.asarray(_need(smp, "normal", "sample"), float),
        groove=np.asarray(_need(smp, "groove", "sample"), float),
        incidence=np.asarray(smp.get("incidence", [0.0, 1.0, 0.0]), float),
        power_w=finite_scalar("laser.power_w", _need(las, "power_w", "laser"), minimum=0.0, strict_min=True),
        calibration=calib,
        point_source=load_array(_need(img, "point_source", "images")),
        frames=load_array(frames_file, "frames"),
        times_s=load_array(frames_file, "times_s"),
        background=float(img.get("background", 0.0)),
        saturation=float(_need(img, "saturation", "images")),
        point_source_background=float(img.get("point_source_background", img.get("background", 0.0))),
        pyrometer_times_s=pyro_t,
        pyrometer_temperatures_k=pyro_k,
        spot_size_m=smp.get("spot_size_m"),
    )


def save_test(test: ScreenTest, folder, name=None) -> Path:
    """Write a test as the files :func:`load_test` reads (the inverse of it): a TOML
    description plus ``NAME_ps.npy``, ``NAME_frames.npz`` and ``NAME_pyro.csv``. Each file
    is written atomically. Returns the TOML path."""
    import io

    folder = Path(folder)
    name = name or str(test.test_id)

    def save_npy(path, arr):
        atomic_write(path, lambda tmp: np.save(open(tmp, "wb"), arr))

    save_npy(folder / f"{name}_ps.npy", np.asarray(test.point_source))
    atomic_write(folder / f"{name}_frames.npz", lambda tmp: np.savez(open(tmp, "wb"), frames=test.frames, times_s=test.times_s))
    g = test.geometry
    lines = [
        f"test_id = {str(test.test_id)!r}".replace("'", '"'),
        "[screen]",
        f"upper_left_m = {g.upper_left_m.tolist()}",
        f"upper_right_m = {g.upper_right_m.tolist()}",
        f"lower_left_m = {g.lower_left_m.tolist()}",
        f"top_row = {g.top_row!r}",
        f"bottom_row = {g.bottom_row!r}",
        f"left_col = {g.left_col!r}",
        f"right_col = {g.right_col!r}",
        "[sample]",
        f"normal = {np.asarray(test.sample_normal, float).tolist()}",
        f"groove = {np.asarray(test.groove, float).tolist()}",
        f"incidence = {np.asarray(test.incidence, float).tolist()}",
    ]
    if test.spot_size_m is not None:
        lines.append(f"spot_size_m = {float(test.spot_size_m)!r}")
    lines += [
        "[laser]",
        f"power_w = {float(test.power_w)!r}",
        "[calibration]",
        f"irradiance_w_m2 = {float(test.calibration.irradiance_w_m2)!r}",
        f"pixel = {[int(p) for p in test.calibration.pixel]}",
        f"counts = {float(test.calibration.counts)!r}",
        "[images]",
        f'point_source = "{name}_ps.npy"',
        f'frames = "{name}_frames.npz"',
        f"background = {float(test.background)!r}",
        f"point_source_background = {float(test.point_source_background)!r}",
        f"saturation = {float(test.saturation)!r}",
    ]
    if test.pyrometer_times_s is not None:
        buf = io.StringIO()
        np.savetxt(buf, np.c_[test.pyrometer_times_s, test.pyrometer_temperatures_k], delimiter=",",
                   header="time_s,temperature_k", comments="", fmt="%.17g")
        atomic_write_text(folder / f"{name}_pyro.csv", buf.getvalue())
        lines += ["[pyrometer]", f'file = "{name}_pyro.csv"']
    return atomic_write_text(folder / f"{name}.toml", "\n".join(lines) + "\n")


def simulate_test(model, *, test_id="sim", incidence_deg=20.0, groove_angle_deg=0.0, power_w=230.0, distance_m=0.6,
                  screen_size_m=0.6, pixels=(96, 96), times_s=(0.0,), state_of_time=None, temperature_of_time=None,
                  calibration_irradiance_w_m2=5.0, point_source_intensity_w_sr=2.0, gain_counts=200.0, background=50.0,
                  saturation=60000.0, noise=0.01, seed=0, spot_size_m=0.005) -> ScreenTest:
    """Render a witness-screen test from a known BRDF (the forward model of the reduction).

    The sample sits at the origin with its normal at ``incidence_deg`` from the incoming
    beam (+y) in the horizontal plane, grooves at ``groove_angle_deg`` from horizontal;
    the screen (``screen_size_m`` square) faces the sample ``distance_m`` away, centred on
    the specular direction. ``state_of_time(t)`` gives the model's state at each frame
    time: a number, or a pair for a two-state model (``[extinction, melt_fraction]``). The camera's responsivity varies smoothly across the image
    (vignetting, ``gain_counts`` counts per W/m^2 at the centre); counts get multiplicative
    Gaussian noise (``noise``), a ``background`` and clip at ``saturation``.
    """
    rng = np.random.default_rng(seed)
    a = math.radians(incidence_deg)
    n = np.array([math.sin(a), -math.cos(a), 0.0])
    horiz = np.array([math.cos(a), math.sin(a), 0.0])
    g = math.radians(groove_angle_deg)
    groove = math.cos(g) * horiz + math.sin(g) * np.array([0.0, 0.0, 1.0])
    d_in = np.array([0.0, 1.0, 0.0])
    spec = d_in - 2 * np.dot(d_in, n) * n
    centre = distance_m * spec
    u = np.cross([0.0, 0.0, 1.0], spec)
    u /= np.linalg.norm(u)
    v = np.array([0.0, 0.0, 1.0])
    half = screen_size_m / 2
    h_px, w_px = pixels
    margin = 4
    geom = ScreenGeometry(centre - half * u + half * v, centre + half * u + half * v, centre - half * u - half * v,
                          float(margin), float(h_px - 1 - margin), float(margin), float(w_px - 1 - margin))
    rows, cols = np.mgrid[0:h_px, 0:w_px]
    r_vec = screen_points(geom, rows, cols)
    r = np.linalg.norm(r_vec, axis=-1)
    rhat = r_vec / r[..., None]
    cos_is = np.abs(rhat @ geom.normal)
    frame = local_frame(n, groove)
    cos_rt = rhat @ frame[2]
    yy, xx = (rows - h_px / 2) / h_px, (cols - w_px / 2) / w_px
    gain = gain_counts * (1.0 - 0.3 * (xx**2 + yy**2))  # counts per W/m^2

    def camera(e):
        c = gain * e * (1.0 + noise * rng.standard_normal(e.shape)) + background
        return np.minimum(c, saturation)

    # point source at the origin: E^P = I cos(theta_is) / r^2
    ps = camera(point_source_intensity_w_sr * cos_is / r**2)
    i_c, j_c = h_px // 2, w_px // 2
    cal = Calibration(calibration_irradiance_w_m2, (i_c, j_c), float(gain[i_c, j_c] * calibration_irradiance_w_m2))
    wi_local = frame @ (-d_in)
    wo_local = (rhat @ frame.T).reshape(-1, 3)
    frames = []
    for t in times_s:
        state = None if state_of_time is None else _frame_state(state_of_time(t))
        f = model.evaluate(np.broadcast_to(wi_local, wo_local.shape), wo_local, state=state).reshape(h_px, w_px)
        e_is = f * power_w * np.maximum(cos_rt, 0) * cos_is / r**2
        frames.append(camera(e_is))
    times = np.asarray(times_s, float)
    temps = None if temperature_of_time is None else np.array([temperature_of_time(t) for t in times])
    pyro_t = None if temps is None else np.concatenate([[times.min() - 1.0], times, [times.max() + 1.0]])
    pyro_k = None if temps is None else np.concatenate([[temps[0]], temps, [temps[-1]]])
    return ScreenTest(test_id, geom, n, groove, d_in, power_w, cal, ps, np.array(frames), times, background, saturation,
                      point_source_background=background, pyrometer_times_s=pyro_t, pyrometer_temperatures_k=pyro_k,
                      spot_size_m=spot_size_m)


def _frame_state(value):
    """One frame's model state: a float, or a float pair for a two-state model."""
    v = np.asarray(value, float)
    return float(v) if v.ndim == 0 else v


def state_column(samples: Samples, state: str) -> np.ndarray:
    """The values (N,) of one state column: ``"temperature_k"``, ``"time_s"`` or a named
    column of ``samples.states``; ValueError when it is unknown or some sample lacks it."""
    if state in ("temperature_k", "time_s"):
        values = getattr(samples, state)
    elif isinstance(state, str) and state in samples.states:
        values = samples.states[state]
    else:
        raise ValueError(f"state={state!r}: expected 'temperature_k', 'time_s' or a state column of the samples "
                         f"({sorted(samples.states) or 'none'})")
    if np.any(np.isnan(values)):
        why = " (no pyrometer series?)" if state == "temperature_k" else ""
        raise ValueError(f"state={state!r}: {int(np.isnan(values).sum())} samples have no {state}{why}")
    return values


def _nearest_node(values: np.ndarray, nodes, name: str) -> tuple:
    """``(nodes, index of the nearest node per value)``; ties go to the lower node."""
    nodes = finite_array(f"nodes of {name}", nodes, ndim=1)
    if nodes.size == 0:
        raise ValueError(f"nodes of {name}: expected at least one value, got an empty array")
    return nodes, np.abs(values[:, None] - nodes[None, :]).argmin(axis=1)


def group_by_state(samples: Samples, state: str, nodes) -> dict:
    """Group samples by the nearest of the state ``nodes``.

    Parameters
    ----------
    samples : Samples
    state : str
        ``"temperature_k"``, ``"time_s"`` or a named state column of ``samples.states``
        (e.g. ``"extinction"``).
    nodes : array_like, shape (T,)
        State values of the groups (in the state's unit).

    Returns
    -------
    dict
        node -> Samples (nodes with no samples are left out).
    """
    nodes, nearest = _nearest_node(state_column(samples, state), nodes, state)
    return {float(nodes[k]): samples.select(nearest == k) for k in range(nodes.size) if np.any(nearest == k)}


def group_by_states(samples: Samples, names, nodes_pair) -> dict:
    """Group samples on two states at once: each sample goes to the grid node whose
    coordinates are the nearest node of each state (per axis).

    Parameters
    ----------
    samples : Samples
    names : [str, str]
        Two state columns (see :func:`group_by_state`), e.g. ``["extinction", "melt_fraction"]``.
    nodes_pair : [array_like (n1,), array_like (n2,)]
        The nodes of each state.

    Returns
    -------
    dict
        (node_1, node_2) -> Samples, only for grid nodes that received samples.
    """
    names = list(names) if isinstance(names, (list, tuple)) else [names]
    if len(names) != 2 or names[0] == names[1]:
        raise ValueError(f"names={names!r}: expected two different state names such as ['extinction', 'melt_fraction']")
    if not isinstance(nodes_pair, (list, tuple)) or len(nodes_pair) != 2:
        raise ValueError(f"nodes_pair: expected two node arrays [nodes of {names[0]}, nodes of {names[1]}]")
    (n1, i1), (n2, i2) = (_nearest_node(state_column(samples, nm), nd, nm) for nm, nd in zip(names, nodes_pair))
    cell = i1 * n2.size + i2
    return {(float(n1[c // n2.size]), float(n2[c % n2.size])): samples.select(cell == c) for c in np.unique(cell)}
