"""Scenario studies: sweeps and Monte Carlo over a base scene, on Dask or serially.

A study (TOML, or :class:`Study` in Python) names a base scene, sweeps over any scene field
by its path (``laser.power_w``, ``targets[0].material.file``, ``laser.aim_m``) on a grid,
at random or on a Latin hypercube, and optionally draws Monte Carlo material variability
per scenario: a log-normal BRDF scale factor per target and a random tilt of each
target's surface normal (specular-peak wander). The paper observed sample-to-sample peak
and power spreads of ~2x and a peak movement of ~25 % of the lobe on melting (Bailey et
al. 2008, Table I); the defaults of :class:`MonteCarlo` are zero - set yours.

Execution: each scenario is a pure function of (base scene, overrides, seed), so a
Dask run (an embedded ``LocalCluster`` or an existing scheduler) gives exactly the results
of a serial run. Each result is written atomically as it finishes
(``OUTDIR/scenarios/NNNNN.json``); a restarted study skips finished scenarios and runs
failed ones again. Serial and Dask runs share one runner with ``hazard risk``
(:mod:`hazard.drivers.runner`). Each process (the serial run's, each Dask worker) keeps a bounded
stage memo over the scenarios it runs (:class:`hazard.pipeline.stages.StageMemo`,
:func:`process_memo`): a scenario reuses the stages whose inputs it does not change (a
sweep of ``analysis.direction_grid_deg`` reuses all before the keep-out lobes), with the
same row. Every scenario's scene is validated before any work; a scenario that
still fails at run time is recorded with its error and stops the study (``keep_going``
runs the rest); either way the result says so and ``hazard study`` exits 4. At the end: ``results.csv``
(and ``results.parquet`` with pyarrow), ``summary.json`` (percentiles for Monte Carlo)
and, with matplotlib, ``summary.png``.
"""

from __future__ import annotations

import copy
import functools
import hashlib
import json
import math
import re
import time
import uuid
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from brdfmodels.fileio import atomic_write, atomic_write_text, read_toml

from hazard.pipeline.stages import StageMemo
from hazard.progress import progress_callback, progress_to
from hazard.drivers.runner import claim_folder, failure_kinds, local_cluster, run_tasks

__all__ = ["Study", "Parameter", "MonteCarlo", "load_study", "scenarios", "run_scenario", "run_study", "local_cluster", "StudyResult", "set_path",
           "check_schema_path", "validate_scenarios", "failure_kinds", "scenario_task", "process_memo", "drop_memo"]

_PATH_RE = re.compile(r"([A-Za-z_][A-Za-z0-9_]*)(\[(\d+)\])?")


def _split(path: str):
    parts = []
    for token in path.split("."):
        m = _PATH_RE.fullmatch(token)
        if not m:
            raise ValueError(f"path={path!r}: {token!r} is not a key or key[index]")
        parts.append(m.group(1))
        if m.group(3) is not None:
            parts.append(int(m.group(3)))
    return parts


def set_path(data: dict, path: str, value):
    """Set ``value`` at a scene field path such as ``targets[0].material.file`` (in place).

    The field must already be in ``data``: a missing key (a misspelling, or a field the
    base scene leaves at its default) is an error, never created.
    """
    parts = _split(path)
    node = data
    for i, key in enumerate(parts[:-1]):
        nxt = parts[i + 1]
        try:
            node = node[key]
        except (KeyError, IndexError, TypeError):
            if isinstance(key, int):
                raise ValueError(f"path={path!r}: index {key} is out of range (the list has {len(node)} items)") from None
            raise ValueError(f"path={path!r}: {key!r} does not exist in the base scene") from None
        if isinstance(nxt, int) and not isinstance(node, list):
            raise ValueError(f"path={path!r}: {key!r} is not a list")
    last = parts[-1]
    if isinstance(last, int):
        if not isinstance(node, list) or last >= len(node):
            raise ValueError(f"path={path!r}: index {last} is out of range (the list has {len(node) if isinstance(node, list) else 0} items)")
    elif not isinstance(node, dict):
        raise ValueError(f"path={path!r}: cannot set {last!r} on a {type(node).__name__}")
    else:
        from scenes.quantities import other_forms

        others = other_forms(node, last)
        if last not in node and not others:
            raise ValueError(f"path={path!r}: {last!r} does not exist in the base scene (a swept field must be set in the base "
                             f"scene, so the sweep changes a value the scene states; add {last} there)")
        for k in others:  # power = "20 kW" in the base, laser.power_w swept: the sweep's value replaces it
            del node[k]
    node[last] = value


def _join(parts) -> str:
    return "".join(f"[{p}]" if isinstance(p, int) else (f".{p}" if i else p) for i, p in enumerate(parts))


def _parameter_units(p, where: str) -> None:
    """A swept parameter's values and range with units (``"20 kW"``) converted, in place, to
    the unit of the scene key its path names; an unsuffixed path (``laser.power``) becomes the
    suffixed key (``laser.power_w``), so the results' columns are numbers in that unit."""
    from scenes.quantities import convert_value, path_unit

    if not isinstance(p, dict) or not isinstance(p.get("path"), str):
        return
    try:
        parts = _split(p["path"])
    except ValueError:
        return  # Parameter says what is wrong with the path
    parts, unit, bare_ok = path_unit(parts)
    if unit is None:
        return
    for key in ("values", "range"):
        if isinstance(p.get(key), list):
            p[key] = convert_value(p[key], unit, f"{where}.{key}", bare_ok=bare_ok)
    p["path"] = _join(parts)


def _schema_types(tp) -> list:
    """The concrete alternatives of a type annotation (Annotated, Optional and unions unwrapped)."""
    import types
    import typing

    origin = typing.get_origin(tp)
    if origin is typing.Annotated:
        return _schema_types(typing.get_args(tp)[0])
    if origin is typing.Union or origin is types.UnionType:
        return [t for a in typing.get_args(tp) for t in _schema_types(a)]
    return [tp] if tp is not type(None) else []


def check_schema_path(path: str) -> None:
    """Raise ValueError unless ``path`` names a field of the scene schema
    (:class:`scenes.spec.SceneSpec`): each key a field of its table, each ``[i]`` on a list.
    A misspelled key is named with the closest valid names. Below a material (whose extra
    keys are its model's parameters) any key is accepted here; building the scene checks it."""
    import difflib
    import typing

    from pydantic import BaseModel

    from scenes.spec import SceneSpec

    options, done = [SceneSpec], []
    for part in _split(path):
        models = [t for t in options if isinstance(t, type) and issubclass(t, BaseModel)]
        if isinstance(part, str) and not models and any(typing.get_origin(t) is list for t in options):
            raise ValueError(f"path={path!r}: {'.'.join(done)} is a list; expected an item of it, e.g. {'.'.join(done)}[0].{part}")
        if isinstance(part, int):
            lists = [t for t in options if typing.get_origin(t) is list]
            if not lists:
                raise ValueError(f"path={path!r}: {'.'.join(done) or 'the scene'} is not a list (no [{part}])")
            options = [a for t in lists for a in _schema_types(typing.get_args(t)[0])]
            done[-1] += f"[{part}]"
            continue
        if any(m.model_config.get("extra") == "allow" for m in models) and not any(part in m.model_fields for m in models):
            return  # a model's parameter: checked when the scene is built
        fields = {k: f for m in models for k, f in m.model_fields.items()}
        if part not in fields:
            where = ".".join(done) or "the scene"
            if not fields:
                raise ValueError(f"path={path!r}: {where} is a value, not a table (no field {part!r} under it)")
            close = difflib.get_close_matches(part, sorted(fields), n=3, cutoff=0.6)
            hint = f"did you mean {' or '.join(repr('.'.join([*done, c])) for c in close)}?" if close else f"expected one of {sorted(fields)}"
            raise ValueError(f"path={path!r}: {part!r} is not a field of {where}; {hint}")
        options = _schema_types(fields[part].annotation)
        done.append(part)


@dataclass(frozen=True)
class Parameter:
    """One swept field: explicit ``values`` (grid), or a ``range`` (random / Latin hypercube)
    on a ``linear`` or ``log`` scale."""

    path: str
    values: tuple | None = None
    range: tuple | None = None
    scale: str = "linear"

    def __post_init__(self):
        _split(self.path)
        if (self.values is None) == (self.range is None):
            raise ValueError(f"parameter {self.path!r}: give values (grid) or range (random, lhs), not both")
        if self.range is not None:
            lo, hi = self.range
            if not (math.isfinite(lo) and math.isfinite(hi) and hi > lo):
                raise ValueError(f"parameter {self.path!r}: range={list(self.range)} must be [low, high] with high > low")
            if self.scale == "log" and lo <= 0:
                raise ValueError(f"parameter {self.path!r}: a log range needs low > 0")
        if self.scale not in ("linear", "log"):
            raise ValueError(f"parameter {self.path!r}: scale={self.scale!r}: expected 'linear' or 'log'")

    def draw(self, u):
        lo, hi = self.range
        if self.scale == "log":
            return float(math.exp(math.log(lo) + u * (math.log(hi) - math.log(lo))))
        return float(lo + u * (hi - lo))


@dataclass(frozen=True)
class MonteCarlo:
    """Material variability drawn per scenario: BRDF scale factor ``exp(N(0, sigma))`` per
    target, and a surface-normal tilt of ``normal_tilt_deg`` rms (isotropic direction)."""

    samples: int = 0
    brdf_scale_sigma: float = 0.0
    normal_tilt_deg: float = 0.0

    def __post_init__(self):
        if self.samples < 0 or self.brdf_scale_sigma < 0 or self.normal_tilt_deg < 0:
            raise ValueError("montecarlo: samples, brdf_scale_sigma and normal_tilt_deg must be >= 0")


@dataclass(frozen=True)
class Study:
    """A study: base scene, sweep, Monte Carlo, seed."""

    name: str
    scene: str
    kind: str = "grid"  # grid | random | lhs
    parameters: tuple = ()
    samples: int = 0  # for random / lhs
    montecarlo: MonteCarlo = field(default_factory=MonteCarlo)
    seed: int = 0
    base_dir: str | None = None

    def __post_init__(self):
        if self.kind not in ("grid", "random", "lhs"):
            raise ValueError(f"sweep.kind={self.kind!r}: expected 'grid', 'random' or 'lhs'")
        if self.kind == "grid" and any(p.values is None for p in self.parameters):
            raise ValueError("sweep.kind='grid': every parameter needs values")
        if self.kind != "grid":
            if any(p.range is None for p in self.parameters):
                raise ValueError(f"sweep.kind={self.kind!r}: every parameter needs a range")
            if self.samples < 1:
                raise ValueError(f"sweep.samples={self.samples!r}: expected >= 1 for a {self.kind} sweep")

    def digest(self) -> str:
        d = asdict(self)
        d.pop("base_dir")
        return hashlib.sha256(json.dumps(d, sort_keys=True, default=str).encode()).hexdigest()[:16]


def _study_schema():
    """Pydantic classes of a study file (strict types, finite numbers, bounded sizes)."""
    from typing import Annotated, Any, Literal

    from pydantic import BaseModel, ConfigDict, Field, field_validator

    class _S(BaseModel):
        model_config = ConfigDict(extra="forbid", strict=True, allow_inf_nan=False)

    class ParameterSpec(_S):
        path: Annotated[str, Field(min_length=1, max_length=500)]
        values: Annotated[list[Any], Field(min_length=1, max_length=100_000)] | None = None
        range: Annotated[list[float], Field(min_length=2, max_length=2)] | None = None
        scale: Literal["linear", "log"] = "linear"

        @field_validator("values")
        @classmethod
        def _finite_values(cls, v):
            stack = list(v or ())
            while stack:
                x = stack.pop()
                if isinstance(x, list):
                    stack.extend(x)
                elif isinstance(x, dict):
                    stack.extend(x.values())
                elif isinstance(x, float) and not math.isfinite(x):
                    raise ValueError(f"expected finite numbers, got {x!r}")
            return v

    class SweepSpec(_S):
        kind: Literal["grid", "random", "lhs"] = "grid"
        samples: Annotated[int, Field(ge=0)] = 0
        parameters: Annotated[list[ParameterSpec], Field(max_length=100)] = []

    class MonteCarloSpec(_S):
        samples: Annotated[int, Field(ge=0)] = 0
        brdf_scale_sigma: Annotated[float, Field(ge=0, le=10)] = 0.0
        normal_tilt_deg: Annotated[float, Field(ge=0, le=90)] = 0.0

    class StudySpec(_S):
        name: Annotated[str, Field(min_length=1, max_length=200)] | None = None
        scene: Annotated[str, Field(min_length=1, max_length=1000)]
        seed: Annotated[int, Field(ge=0, le=2**63 - 1)] = 0
        sweep: SweepSpec = SweepSpec()
        montecarlo: MonteCarloSpec = MonteCarloSpec()

    return StudySpec


def examples() -> dict:
    """Bundled example studies: name -> path (``hazard study power_sweep -o out``)."""
    from importlib import resources

    try:  # an installed wheel: hazard/studies/*.toml
        found = {Path(p.name).stem: Path(str(p)) for p in resources.files("hazard.studies").iterdir() if p.name.endswith(".toml")}
    except (ModuleNotFoundError, TypeError, FileNotFoundError, NotADirectoryError):
        found = {}
    if not found:  # the package's folder itself
        folder = Path(__file__).resolve().parents[1] / "studies"
        found = {p.stem: p for p in folder.glob("*.toml")} if folder.is_dir() else {}
    return dict(sorted(found.items()))


def load_study(path) -> Study:
    """Read a study TOML (or a bundled example's name): ``name``, ``scene`` (path or
    bundled name), ``seed``; ``[sweep]`` kind, samples and ``[[sweep.parameters]]``
    (path, values | range, scale); ``[montecarlo]`` samples, brdf_scale_sigma,
    normal_tilt_deg. The whole file is validated (types, ranges, the number of
    scenarios, the base scene and every swept path) before any work."""
    path = Path(path)
    if not path.exists() and str(path) in examples():
        path = examples()[str(path)]
    d = read_toml(path)
    known = {"name", "scene", "seed", "sweep", "montecarlo"}
    if set(d) - known:
        raise ValueError(f"{path}: unknown keys {sorted(set(d) - known)}; expected {sorted(known)}")
    if "scene" not in d:
        raise ValueError(f"{path}: scene: missing (a scene file or a bundled example's name)")
    sw = d.get("sweep", {})
    if set(sw) - {"kind", "samples", "parameters"}:
        raise ValueError(f"{path}: sweep: unknown keys {sorted(set(sw) - {'kind', 'samples', 'parameters'})}")
    params = []
    for i, p in enumerate(sw.get("parameters", [])):
        try:
            _parameter_units(p, f"sweep.parameters[{i}]")
        except ValueError as exc:
            raise ValueError(f"{path}: {exc}") from None
        if set(p) - {"path", "values", "range", "scale"}:
            raise ValueError(f"{path}: sweep.parameters[{i}]: unknown keys {sorted(set(p) - {'path', 'values', 'range', 'scale'})}")
        try:
            params.append(Parameter(p["path"], tuple(p["values"]) if "values" in p else None,
                                    tuple(p["range"]) if "range" in p else None, p.get("scale", "linear")))
        except KeyError:
            raise ValueError(f"{path}: sweep.parameters[{i}].path: missing") from None
        except ValueError as exc:
            raise ValueError(f"{path}: sweep.parameters[{i}]: {exc}") from None
    mc = d.get("montecarlo", {})
    if set(mc) - {"samples", "brdf_scale_sigma", "normal_tilt_deg"}:
        raise ValueError(f"{path}: montecarlo: unknown keys {sorted(set(mc) - {'samples', 'brdf_scale_sigma', 'normal_tilt_deg'})}")
    from pydantic import ValidationError

    try:
        _study_schema().model_validate(d)
    except ValidationError as exc:
        from scenes.scene import format_validation_error

        raise ValueError(format_validation_error(exc, str(path))) from None
    try:
        study = Study(name=str(d.get("name", path.stem)), scene=str(d["scene"]), kind=sw.get("kind", "grid"), parameters=tuple(params),
                      samples=int(sw.get("samples", 0)), montecarlo=MonteCarlo(**mc), seed=int(d.get("seed", 0)), base_dir=str(path.parent))
    except ValueError as exc:
        raise ValueError(f"{path}: {exc}") from None
    _check_study(study, path)
    return study


def _check_study(study: Study, path) -> None:
    """Before any work: the number of scenarios is within the limit, every swept path is a
    field of the scene schema and of the base scene, and every scenario's scene validates."""
    from brdfmodels.fileio import check_limit

    n = math.prod(len(p.values) for p in study.parameters) if study.kind == "grid" else study.samples
    n *= max(1, study.montecarlo.samples)
    try:
        check_limit("SCENARIOS", n, "scenarios")
        for i, p in enumerate(study.parameters):
            try:
                check_schema_path(p.path)
            except ValueError as exc:
                raise ValueError(f"sweep.parameters[{i}].path: {exc}") from None
        validate_scenarios(study)
    except ValueError as exc:
        raise ValueError(f"{path}: {' '.join(str(exc).split())}") from None


def validate_scenarios(study: Study, shown: int = 3) -> int:
    """Build and validate the scene of every scenario (each distinct set of swept values
    once; the Monte Carlo draws only tilt normals and scale BRDFs). Raises one ValueError
    naming how many scenarios are invalid and, for the first ``shown``, the scenario, its
    swept values and the scene's error (which names the field path). Returns the number of
    distinct scenes checked."""
    import scenes

    base, base_dir = base_data(study)
    key = (study.digest(), hashlib.sha256(json.dumps(base, sort_keys=True, default=str).encode()).hexdigest(), str(base_dir))
    if key in _VALIDATED:  # load_study checked it; run_study need not build every scene again
        return _VALIDATED[key]
    for i, p in enumerate(study.parameters):  # a path the base scene lacks: one error, not one per scenario
        try:
            set_path(copy.deepcopy(base), p.path, None)
        except ValueError as exc:
            raise ValueError(f"sweep.parameters[{i}].path: {exc}") from None
    seen, bad = set(), []
    for sc in scenarios(study):
        key = json.dumps(sc["overrides"], sort_keys=True, default=str)
        if key in seen:
            continue
        seen.add(key)
        try:
            data = copy.deepcopy(base)
            for p, value in sc["overrides"].items():
                set_path(data, p, value)
            scenes.from_data(data, source=f"scene={study.scene!r}", base_dir=base_dir)
        except ValueError as exc:
            what = ", ".join(f"{p} = {v!r}" for p, v in sc["overrides"].items()) or "the base scene"
            bad.append(f"scenario {sc['id']} ({what}): {' '.join(str(exc).split())}")
    if bad:
        more = f"; and {len(bad) - shown} more" if len(bad) > shown else ""
        raise ValueError(f"{len(bad)} of {len(seen)} distinct scenario scene(s) are invalid: " + "; ".join(bad[:shown]) + more)
    if len(_VALIDATED) > 64:
        _VALIDATED.clear()
    _VALIDATED[key] = len(seen)
    return len(seen)


_VALIDATED: dict = {}  # (study digest, base scene hash, folder) -> distinct scenes checked


def _lhs(n, d, rng):
    """Latin hypercube: one sample per stratum in each dimension, randomly paired."""
    u = (np.arange(n)[:, None] + rng.uniform(size=(n, d))) / n
    for j in range(d):
        u[:, j] = u[rng.permutation(n), j]
    return u


def scenarios(study: Study) -> list:
    """The study's scenarios: dicts with ``id``, ``overrides`` (path -> value), ``mc`` (draw
    index or None) and ``seed`` (a per-scenario seed derived from the study seed)."""
    rng = np.random.default_rng(study.seed)
    if not study.parameters:
        points = [{}]
    elif study.kind == "grid":
        grids = np.meshgrid(*[np.arange(len(p.values)) for p in study.parameters], indexing="ij")
        points = [{p.path: p.values[int(g.flat[k])] for p, g in zip(study.parameters, grids)} for k in range(grids[0].size)]
    else:
        u = rng.uniform(size=(study.samples, len(study.parameters))) if study.kind == "random" else _lhs(study.samples, len(study.parameters), rng)
        points = [{p.path: p.draw(u[k, j]) for j, p in enumerate(study.parameters)} for k in range(study.samples)]
    mc_n = study.montecarlo.samples
    out = []
    for point in points:
        for m in (range(mc_n) if mc_n else [None]):
            out.append({"id": len(out), "overrides": point, "mc": m})
    seeds = np.random.SeedSequence(study.seed).spawn(len(out))
    for sc, ss in zip(out, seeds):
        sc["seed"] = int(ss.generate_state(1)[0])
    return out


def base_data(study: Study):
    """(the base scene's parsed TOML, the folder its relative paths are read from) of
    ``study``: a file (relative to the study file's folder first) or a bundled example."""
    import scenes

    path = Path(study.scene)
    if not path.is_absolute() and study.base_dir is not None and (Path(study.base_dir) / path).exists():
        path = Path(study.base_dir) / path
    if not path.exists():
        if study.scene not in scenes.examples():
            raise ValueError(f"scene={study.scene!r}: not a file and not a bundled example ({sorted(scenes.examples())})")
        path = scenes.example_path(study.scene)
    return read_toml(path), path.parent


def _tilt(vec, tilt_rad, rng):
    from hazard.physics.beam import perp_basis as _perp_basis

    v = np.asarray(vec, float)
    v = v / np.linalg.norm(v)
    e1, e2 = _perp_basis(v)
    # isotropic small tilt: two Gaussian components of variance tilt^2 / 2, so the rms
    # tilt angle is tilt_rad
    tx, ty = rng.normal(0.0, tilt_rad / math.sqrt(2.0), 2)
    ang = math.hypot(tx, ty)
    if ang == 0.0:
        return v.tolist()
    axis = (tx * e1 + ty * e2) / ang  # the normal tips towards this direction
    return (math.cos(ang) * v + math.sin(ang) * axis).tolist()


def run_scenario(base: dict, base_dir: str, scenario: dict, mc: dict, threads=None, memo=None) -> dict:
    """Analyse one scenario; returns its row (inputs, outputs, run time, or the error).

    ``threads`` goes to :func:`hazard.analyze`; on a cluster each scenario gets one
    (the workers are the parallelism), in a serial run it uses every CPU. ``memo``: a
    :class:`hazard.pipeline.stages.StageMemo` shared by a serial run's scenarios (the
    stages whose inputs a scenario does not change are reused; the row is the same,
    ``run_time_s`` then the scenario's own share).
    """
    import brdfmodels
    import scenes

    from hazard.pipeline.analysis import analyze

    start = time.perf_counter()
    row = {"id": scenario["id"], "mc": scenario["mc"], "seed": scenario["seed"], **{f"in:{k}": v for k, v in scenario["overrides"].items()}}
    try:
        data = copy.deepcopy(base)
        for path, value in scenario["overrides"].items():
            set_path(data, path, value)
        rng = np.random.default_rng(scenario["seed"])
        scales = []
        if scenario["mc"] is not None:
            for t in data.get("targets", []):
                if mc["normal_tilt_deg"] > 0:
                    n = np.asarray(t.get("normal", [0.0, 0.0, 1.0]), float)
                    t["normal"] = _tilt(n, math.radians(mc["normal_tilt_deg"]), rng)
                    tan = np.asarray(t.get("tangent", [1.0, 0.0, 0.0]), float)
                    nn = np.asarray(t["normal"])
                    t["tangent"] = (tan - np.dot(tan, nn) * nn).tolist()
                scales.append(float(np.exp(mc["brdf_scale_sigma"] * rng.standard_normal())) if mc["brdf_scale_sigma"] > 0 else 1.0)
        scene = scenes.from_data(data, source=f"scenario {scenario['id']}", base_dir=base_dir)
        for t, s in zip(scene.targets, scales):
            if s != 1.0:
                t.material = brdfmodels.Scaled(t.material, s)
        with progress_to(None):  # the study draws one bar; none per scenario (nor in Dask workers)
            res = analyze(scene, threads=threads, memo=memo)
        tr = [t.to_dict() for t in res.targets]
        row.update({
            "nohd_static_m": max([t["nohd_static_m"] for t in tr], default=0.0),
            "nohd_dynamic_m": max([t["nohd_dynamic_m"] for t in tr], default=0.0),
            "specular_nohd_dynamic_m": max([t["specular_nohd_dynamic_m"] or 0.0 for t in tr], default=0.0),
            "keepout_volume_static_m3": sum(t["keepout_static"]["volume_m3"] for t in tr),
            "keepout_volume_dynamic_m3": sum(t["keepout_dynamic"]["volume_m3"] for t in tr),
            "ground_area_static_m2": res.footprint_static.area_m2 if res.footprint_static else None,
            "ground_area_dynamic_m2": res.footprint_dynamic.area_m2 if res.footprint_dynamic else None,
            "hazardous_observers": int(np.sum(res.hazardous)),
            "hazardous_observers_static": int(np.sum(res.hazardous_static)),
            "mpe_w_m2": res.mpe_w_m2,
            "brdf_scales": scales,
            "error": None,
        })
    except Exception as exc:  # a failing scenario is recorded, the study goes on
        row["error"] = f"{type(exc).__name__}: {' '.join(str(exc).split())}"
    row["run_time_s"] = time.perf_counter() - start
    return row


#: Stage results each process of a study (the serial run's, or each Dask worker) keeps for
#: its next scenarios (a few scenarios' worth: a Monte Carlo study changes every stage's
#: inputs and must not grow without bound).
MEMO_ENTRIES = 64
_MEMOS: dict[str, StageMemo] = {}  # per process: the study run's token -> its memo (one run at a time)


def process_memo(token: str) -> StageMemo:
    """This process's stage memo for the study run ``token`` (a new one, the memos of other
    runs dropped, on the run's first scenario here): a memo lives for one driver call, as
    the module-level settings it does not key on may change between calls."""
    memo = _MEMOS.get(token)
    if memo is None:
        _MEMOS.clear()
        memo = _MEMOS[token] = StageMemo(max_entries=MEMO_ENTRIES)
    return memo


def drop_memo(token: str) -> None:
    """Drop this process's stage memo of the study run ``token`` (at the run's end)."""
    _MEMOS.pop(token, None)


def scenario_task(common, scenario) -> dict:
    """One scenario's row as a task of :func:`hazard.drivers.runner.run_tasks`: ``common`` = (base
    scene data, base folder, Monte Carlo settings, the run's token, threads (None: every
    CPU, a serial run; 1 on a Dask worker)); the stages whose inputs the scenario does not
    change are reused from this process's earlier scenarios of the run (:func:`process_memo`)."""
    base, base_dir, mc, token, threads = common
    return run_scenario(base, base_dir, scenario, mc, threads=threads, memo=process_memo(token))

OUTPUT_COLUMNS = ["nohd_static_m", "nohd_dynamic_m", "specular_nohd_dynamic_m", "keepout_volume_static_m3", "keepout_volume_dynamic_m3",
                  "ground_area_static_m2", "ground_area_dynamic_m2", "hazardous_observers", "hazardous_observers_static", "run_time_s"]


@dataclass
class StudyResult:
    rows: list
    summary: dict
    outdir: Path
    ran: int
    skipped: int
    failed: int
    not_run: int = 0  # scenarios left undone after the first failure (without keep_going)

    @property
    def ok(self) -> bool:
        """Every scenario ran and none failed."""
        return self.failed == 0 and self.not_run == 0


def _safe(obj):
    if isinstance(obj, float) and not math.isfinite(obj):
        return "inf" if obj > 0 else ("-inf" if obj < 0 else "nan")
    if isinstance(obj, dict):
        return {k: _safe(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_safe(v) for v in obj]
    if isinstance(obj, np.generic):
        return obj.item()
    return obj


def _summary(study: Study, rows: list, total: int | None = None) -> dict:
    ok = [r for r in rows if r.get("error") is None]
    total = len(rows) if total is None else total
    failures = [{"id": r["id"], "error": r["error"]} for r in rows if r.get("error")]
    out = {"study": study.name, "digest": study.digest(), "scenarios": total, "succeeded": len(ok), "failed": len(failures),
           "not_run": total - len(rows), "complete": len(ok) == total, "failures": failures,
           "failure_kinds": failure_kinds(f["error"] for f in failures)}
    stats = {}
    for col in OUTPUT_COLUMNS:
        vals = np.array([r[col] for r in ok if isinstance(r.get(col), (int, float)) and r.get(col) is not None], float)
        vals = vals[np.isfinite(vals)]
        if vals.size:
            stats[col] = {"min": float(vals.min()), "p50": float(np.percentile(vals, 50)), "p95": float(np.percentile(vals, 95)),
                          "p99": float(np.percentile(vals, 99)), "max": float(vals.max()), "mean": float(vals.mean())}
    out["statistics"] = stats
    return out


def _write_table(rows, outdir: Path):
    import csv
    import io

    inputs = sorted({k for r in rows for k in r if k.startswith("in:")})
    cols = ["id", "mc", "seed", *inputs, *OUTPUT_COLUMNS, "mpe_w_m2", "error"]
    buf = io.StringIO()
    w = csv.writer(buf)
    w.writerow(cols)
    for r in rows:
        w.writerow(["" if r.get(c) is None else (json.dumps(r[c]) if isinstance(r.get(c), (list, dict)) else r.get(c)) for c in cols])
    atomic_write_text(outdir / "results.csv", buf.getvalue())
    try:
        import pyarrow as pa
        import pyarrow.parquet as pq
    except ImportError:
        return
    table = {c: [None if r.get(c) is None else (json.dumps(r[c]) if isinstance(r.get(c), (list, dict)) else r.get(c)) for r in rows] for c in cols}
    table = {c: [str(v) if v is not None and c.startswith("in:") else v for v in vals] for c, vals in table.items()}
    atomic_write(outdir / "results.parquet", lambda tmp: pq.write_table(pa.table(table), tmp))


def _plot(study, rows, outdir):
    try:
        import matplotlib  # noqa: F401  (the [render] extra; no backend is selected: the figure has its own Agg canvas)
    except ImportError:
        return None
    from hazard.canvas import subplots

    ok = [r for r in rows if r.get("error") is None]
    if not ok:
        return None
    fig, axes = subplots(1, 2, figsize=(10, 4))
    inputs = sorted({k for r in ok for k in r if k.startswith("in:") and isinstance(r[k], (int, float))})
    ax = axes[0]
    if inputs:
        x = np.array([r[inputs[0]] for r in ok], float)
        ax.scatter(x, [r["nohd_static_m"] for r in ok], s=12, label="static")
        ax.scatter(x, [r["nohd_dynamic_m"] for r in ok], s=12, label="dynamic")
        ax.set_xlabel(inputs[0][3:])
        if np.all(x > 0) and x.max() / max(x.min(), 1e-300) > 50:
            ax.set_xscale("log")
    else:
        ax.plot([r["nohd_static_m"] for r in ok], "o", label="static")
        ax.plot([r["nohd_dynamic_m"] for r in ok], "o", label="dynamic")
        ax.set_xlabel("scenario")
    ax.set_ylabel("max NOHD [m]")
    ax.legend()
    ax.grid(alpha=0.3)
    ax = axes[1]
    d = np.sort([r["nohd_dynamic_m"] for r in ok])
    ax.plot(d, np.arange(1, d.size + 1) / d.size, drawstyle="steps-post")
    ax.axhline(0.95, ls=":", c="k")
    ax.set_xlabel("dynamic NOHD [m]")
    ax.set_ylabel("fraction of scenarios")
    ax.set_title("distribution (dotted: 95 %)")
    ax.grid(alpha=0.3)
    fig.suptitle(f"study {study.name}: {len(ok)} scenarios")
    fig.tight_layout()
    return atomic_write(outdir / "summary.png", lambda tmp: fig.savefig(tmp, dpi=100), keep_suffix=True)


def run_study(study: Study, outdir, *, scheduler=None, serial=False, n_workers=2, force=False, progress=None,
              keep_going=False) -> StudyResult:
    """Run a study; finished scenarios in ``outdir`` are kept (resume).

    Parameters
    ----------
    scheduler : str, optional
        Address of an existing Dask scheduler (``tcp://host:port``); default: an embedded
        ``LocalCluster`` with ``n_workers`` processes.
    serial : bool
        Run in this process without Dask (same results).
    force : bool
        Start over if ``outdir`` holds a different study's results.
    progress : callable, optional
        Called with (done, total) as scenarios finish (:func:`progress_bar` draws a bar
        on a terminal). The scenarios' own progress bars (keep-out lobes) are not drawn.
    keep_going : bool
        Run every scenario even after one fails; by default the study stops at the first
        failure (the rest are ``not_run``). Either way the result's ``ok`` is False and
        ``summary`` counts the failures with the first error of each kind; a failed or
        unrun scenario runs again on the next start.

    Every scenario's scene is validated first (:func:`validate_scenarios`), so a study
    with an invalid value does no work.
    """
    validate_scenarios(study)
    from brdfmodels.output_sets import output_unit

    outdir = Path(outdir)
    # results.csv/.parquet, summary.json and summary.png switch in as one unit; study.json and
    # scenarios/ are the resumable working files, kept across runs
    with output_unit(outdir, command="study", overwrite=True, force=force, working=("study.json", "scenarios"),
                     claims=("results.csv", "results.parquet", "summary.json", "summary.png")) as unit:
        return _run_study(study, outdir, unit.stage, scheduler=scheduler, serial=serial, n_workers=n_workers, force=force, progress=progress,
                          keep_going=keep_going)


def _run_study(study: Study, outdir: Path, stage: Path, *, scheduler, serial, n_workers, force, progress, keep_going) -> StudyResult:
    """:func:`run_study`: scenarios in ``outdir/scenarios``, the final files in ``stage``."""
    outdir = Path(outdir)
    sdir = outdir / "scenarios"
    sdir.mkdir(parents=True, exist_ok=True)
    digest = study.digest()
    claim_folder(outdir / "study.json", digest, json.dumps({"name": study.name, "digest": digest, "study": _safe(asdict(study))},
                                                           indent=1, default=str),
                 force=force, finished=sdir.glob("*.json"), held=f"{outdir} holds results of another study")
    base, base_dir = base_data(study)
    todo = scenarios(study)
    done_ids = {int(p.stem) for p in sdir.glob("*.json") if json.loads(p.read_text()).get("error") is None}  # failures run again
    pending = [s for s in todo if s["id"] not in done_ids]
    mc = asdict(study.montecarlo)
    total, finished = len(todo), len(todo) - len(pending)
    say = progress or (lambda d, t: None)
    say(finished, total)

    def record(_, row):
        nonlocal finished
        atomic_write_text(sdir / f"{row['id']:05d}.json", json.dumps(_safe(row), default=str))
        finished += 1
        say(finished, total)

    for s in pending:  # a failure of an earlier start is replaced, not kept beside a success
        (sdir / f"{s['id']:05d}.json").unlink(missing_ok=True)
    if pending:
        token = uuid.uuid4().hex  # this run's stage memo in each process (never another run's)
        run_tasks(scenario_task, (base, str(base_dir), mc, token, None if serial else 1), pending, record, serial=serial,
                  workers=n_workers, scheduler=scheduler, keep_going=keep_going, failure_of=lambda row: row["error"],
                  raise_errors=True, teardown=functools.partial(drop_memo, token))
    rows = sorted((json.loads(p.read_text()) for p in sdir.glob("*.json")), key=lambda r: r["id"])
    rows = [r for r in rows if r["id"] < total]
    summary = _summary(study, rows, total)
    _write_table(rows, stage)
    atomic_write_text(stage / "summary.json", json.dumps(_safe(summary), indent=1))
    _plot(study, rows, stage)
    skipped = total - len(pending)
    return StudyResult(rows, summary, outdir, finished - skipped, skipped, summary["failed"], summary["not_run"])


def progress_bar(stream=None):
    """A ``progress(done, total)`` callback for :func:`run_study`: a bar of the scenarios
    done on ``stream`` (default stderr), drawn only when it is a terminal
    (:func:`hazard.progress.progress_callback`)."""
    return progress_callback("scenarios", unit="scenario", leave=True, stream=stream)
