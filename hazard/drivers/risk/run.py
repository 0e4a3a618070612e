"""Running a risk analysis: chunks of draws on Dask (or serially), resumable.

The draws are cut into chunks of a fixed size (set by the number of points, not by the
workers). Chunk c of the main sample draws from its own generator,
``SeedSequence([seed, 0, c])``; the sensitivity sample's chunk j draws its A and B sets
from ``[seed, 1, j]`` and ``[seed, 2, j]``. A chunk is a pure function of (scene,
settings, chunk), each process builds the shared work once (ray scene, nominal trace,
proposal: :class:`hazard.drivers.risk.evaluate.Evaluator`) and runs one thread, and the results
are combined in chunk order: the same seed gives identical results serially, on an
embedded ``LocalCluster`` or on an existing scheduler.

The chunks run on the task runner ``hazard study`` uses too (:mod:`hazard.drivers.runner`): each
finished chunk is written atomically to ``OUT/.risk/`` as it arrives; a restarted run with
the same scene and settings skips them (``meta.json`` holds the digest; a different
analysis in the same folder is an error unless ``force``).
"""

from __future__ import annotations

import copy
import hashlib
import json
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from brdfmodels.fileio import atomic_write

from hazard.drivers.runner import claim_folder, failure_kinds, run_tasks
from hazard.drivers.risk.columns import ColumnStore
from hazard.drivers.risk.stats import weighted_counts

__all__ = ["RiskSettings", "settings", "tasks", "run_task", "run_chunks", "Chunks", "ChunksFailed", "gather", "Gathered"]

VERSION = "risk-1"
POINT_VALUES_PER_CHUNK = 2_000_000  # draws x points held at once by one task (16 MB of float64)


@dataclass(frozen=True)
class RiskSettings:
    """A run's settings resolved from ``[uncertainty]`` and the command line."""

    draws: int
    seed: int
    sampling: str  # "plain" | "importance"
    sensitivity_draws: int
    chunk_draws: int
    n_points: int
    n_observers: int


def settings(scene, n_points: int, n_observers: int, *, draws=None, seed=None, sampling=None, sensitivity_draws=None,
             active=(), can_import=False) -> RiskSettings:
    """The run's settings: the scene's ``[uncertainty]`` overridden by the arguments;
    sampling "auto" is importance sampling when a proposal exists (``can_import``)."""
    u = scene.spec.uncertainty
    mode = sampling or u.sampling
    if mode == "auto":
        mode = "importance" if can_import else "plain"
    sens = u.sensitivity_draws if sensitivity_draws is None else sensitivity_draws
    if len(active) < 2 or n_observers == 0:
        sens = 0  # one uncertain input drives everything: nothing to apportion
    chunk = int(np.clip(POINT_VALUES_PER_CHUNK // max(n_points, 1), 16, 500))
    return RiskSettings(int(draws or u.draws), int(u.seed if seed is None else seed), mode, int(sens), chunk, n_points, n_observers)


def tasks(s: RiskSettings) -> list:
    """(kind, index, draws) of every chunk: "m" the main sample, "s" the sensitivity sample."""
    out = []
    for kind, total in (("m", s.draws), ("s", s.sensitivity_draws)):
        for c, a in enumerate(range(0, total, s.chunk_draws)):
            out.append((kind, c, min(s.chunk_draws, total - a)))
    return out


_SHARED: dict = {}  # per process: scene key -> (evaluator, proposal)


def scene_key(scene, backend: str) -> str:
    """What a process's shared work depends on: the scene's text and the ray backend."""
    return f"{scene.text_sha256}:{backend}"


def shared(scene, backend: str, key: str | None = None):
    """The (evaluator, proposal) of ``scene`` in this process, built once. ``scene`` may
    be a loaded scene or a payload ``(data, source, base_dir)`` to load (a Dask worker),
    then with its ``key``."""
    key = key or scene_key(scene, backend)
    if key not in _SHARED:
        from hazard.drivers.risk.evaluate import Evaluator
        from hazard.drivers.risk.importance import proposal

        if isinstance(scene, tuple):
            import scenes

            data, source, base_dir = scene
            scene = scenes.from_data(copy.deepcopy(data), source=source, base_dir=base_dir)
        ev = Evaluator(scene, backend)
        _SHARED.clear()  # one analysis per process at a time
        _SHARED[key] = (ev, proposal(ev))
    return _SHARED[key]


def _main_chunk(ev, prop, s: RiskSettings, index: int, n: int) -> dict:
    rng = np.random.default_rng(np.random.SeedSequence([s.seed, 0, index]))
    d = prop.draw(ev.model, rng, n) if s.sampling == "importance" else ev.model.draw(rng, n)
    r = ev.ratios(d)
    hits, sw, sw2 = weighted_counts(r[:, s.n_observers:] >= 1.0, np.exp(d.log_weight))
    return {"ratio": r[:, : s.n_observers], "log_weight": d.log_weight, "component": d.component,
            "map_hits": hits, "map_sum_w": sw, "map_sum_w2": sw2}


def _sensitivity_chunk(ev, s: RiskSettings, index: int, n: int) -> dict:
    a = ev.model.draw(np.random.default_rng(np.random.SeedSequence([s.seed, 1, index])), n)
    b = ev.model.draw(np.random.default_rng(np.random.SeedSequence([s.seed, 2, index])), n)
    out = {"A": ev.ratios(a)[:, : s.n_observers]}
    for g in ev.model.active():
        out[f"C_{g}"] = ev.ratios(b.with_group(a, g))[:, : s.n_observers]
    return out


def run_task(common, task) -> dict:
    """One chunk (see the module notes); arrays by name. ``common``: (the scene's key, the
    payload ``(data, source, base_dir, backend)``, the :class:`RiskSettings`). A NaN
    exposure ratio (a draw the engine could not evaluate) fails the chunk: counted as
    below the MPE it would pass for safe."""
    from brdfmodels.parallel import thread_limit

    key, payload, s = common
    ev, prop = shared(payload[:3], payload[3], key)
    kind, index, n = task
    with thread_limit(1):
        out = _main_chunk(ev, prop, s, index, n) if kind == "m" else _sensitivity_chunk(ev, s, index, n)
    bad = {k: int(np.isnan(v).any(axis=tuple(range(1, v.ndim))).sum()) for k, v in out.items()
           if (k == "ratio" or k == "A" or k.startswith("C_")) and v.size}
    if any(bad.values()):
        raise FloatingPointError(f"chunk {kind}{index}: {max(bad.values())} of {n} draws gave a NaN exposure ratio")
    return out


class ChunksFailed(RuntimeError):
    """Some chunks of draws failed: no result is written (the finished chunks are kept for
    a restart). ``failed`` and ``not_run`` count chunks; ``kinds`` maps each error kind to
    its first message."""

    def __init__(self, failed: int, total: int, not_run: int, kinds: dict, draws: int):
        self.failed, self.total, self.not_run, self.kinds, self.draws = failed, total, not_run, kinds, draws
        stop = f", {not_run} not run (stopped at the first failure; --keep-going runs the rest)" if not_run else ""
        super().__init__(f"{failed} of {total} chunks of draws failed ({draws} draws){stop}; no risk result is written "
                         f"(finished chunks are kept: a restart runs the rest); first of each kind: {'; '.join(kinds.values())}")


def _save(path: Path, arrays: dict) -> None:
    def write(tmp):
        with open(tmp, "wb") as f:
            np.savez(f, **arrays)

    atomic_write(path, write)


def digest_of(scene, s: RiskSettings, backend: str, prop) -> str:
    """What the chunks depend on: the scene text, the settings, the backend and the proposal."""
    text = json.dumps({"version": VERSION, "scene": scene.text_sha256, "settings": asdict(s), "backend": backend,
                       "proposal": repr(prop)}, sort_keys=True)
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def _prepare(outdir: Path, digest: str, force: bool) -> Path:
    cdir = outdir / ".risk"
    cdir.mkdir(parents=True, exist_ok=True)
    claim_folder(cdir / "meta.json", digest, json.dumps({"digest": digest}), force=force, finished=cdir.glob("*.npz"),
                 held=f"{outdir} holds chunks of another risk analysis")
    return cdir


@dataclass
class Chunks:
    """Every chunk's file in order (read back one at a time: :func:`gather`), and how many
    ran now and were found done."""

    main: list
    sensitivity: list
    ran: int
    reused: int


@dataclass
class Gathered:
    """The chunks reduced in chunk order: the draws' log weights (draws,), the map's sums
    (0 without chunks) and the per-draw observer arrays in a :class:`ColumnStore` (None
    without observers): "ratio" (draws, M), and "A", "C_<group>" (sensitivity draws, M)."""

    log_weight: np.ndarray
    map_hits: object
    map_sum_w: object
    map_sum_w2: object
    store: ColumnStore | None


def _load(path: Path, keys=None) -> dict:
    with np.load(path) as z:
        return {k: z[k] for k in (z.files if keys is None else keys)}


def gather(chunks: Chunks, s: RiskSettings, groups, folder) -> Gathered:
    """Read the chunks once, in order: the map's counts summed as they come (the same
    additions, in the same order, as summing the kept chunks), the observers' arrays copied
    into a :class:`ColumnStore` in ``folder`` (the caller closes it). Memory: one chunk."""
    rows = {"ratio": s.draws} if s.n_observers else {}
    if s.n_observers and chunks.sensitivity:
        rows.update({k: s.sensitivity_draws for k in ["A", *[f"C_{g}" for g in groups]]})
    store = ColumnStore(folder, rows, s.n_observers) if rows else None
    lw, hits, sw, sw2 = [], 0, 0, 0
    try:
        for p in chunks.main:
            c = _load(p)
            lw.append(c["log_weight"])
            hits, sw, sw2 = hits + c["map_hits"], sw + c["map_sum_w"], sw2 + c["map_sum_w2"]
            if store is not None:
                store.append("ratio", c["ratio"])
        for p in chunks.sensitivity if store is not None and "A" in rows else ():
            c = _load(p)
            for k in c:
                store.append(k, c[k])
    except BaseException:
        if store is not None:
            store.close()
        raise
    return Gathered(np.concatenate(lw) if lw else np.zeros(0), hits, sw, sw2, store)


def _name(task) -> str:
    return f"{task[0]}{task[1]:06d}.npz"


def run_chunks(scene, s: RiskSettings, outdir, *, backend="embree", serial=False, workers=2, scheduler=None, force=False,
               progress=None, keep_going=False) -> Chunks:
    """Every chunk of the run, computing the ones not yet in ``outdir``. Raises
    :class:`ChunksFailed` if any chunk failed (after the first, unless ``keep_going``)."""
    outdir = Path(outdir)
    digest = digest_of(scene, s, backend, shared(scene, backend)[1])
    cdir = _prepare(outdir, digest, force)
    todo = tasks(s)
    pending = [t for t in todo if not (cdir / _name(t)).exists()]
    say = progress or (lambda d, t: None)
    done = [len(todo) - len(pending)]
    say(done[0], len(todo))

    def record(task, arrays):
        _save(cdir / _name(task), arrays)
        done[0] += 1
        say(done[0], len(todo))

    if pending:
        payload = (scene.source_data, scene.source, None if scene.base_dir is None else str(scene.base_dir), backend)
        failed = run_tasks(run_task, (scene_key(scene, backend), payload, s), pending, record, serial=serial, workers=workers,
                           scheduler=scheduler, keep_going=keep_going)
        if failed:
            missing = [t for t in todo if not (cdir / _name(t)).exists()]
            raise ChunksFailed(len(failed), len(todo), len(missing) - len(failed), failure_kinds(e for _, e in failed),
                               sum(t[2] for t, _ in failed))
    return Chunks([cdir / _name(t) for t in todo if t[0] == "m"], [cdir / _name(t) for t in todo if t[0] == "s"], len(pending),
                  len(todo) - len(pending))
