"""Outputs of an analysis: ``report.json`` (every step) and ``observers.csv``, atomically.

Each file is written to a temporary name in the output folder and renamed into place, so
a crash never leaves a half-written report. An existing report is never overwritten
unless asked (``force=True``).
"""

from __future__ import annotations

import csv
import io
import json
import math
import os
import shutil
import tempfile
from pathlib import Path

import numpy as np

from brdfmodels._io import atomic_write_text

__all__ = ["report_dict", "write_outputs", "OutputExistsError", "atomic_write_text", "observer_rows"]

REPORT_FORMAT = "laser-hazard.report"
REPORT_VERSION = 1


class OutputExistsError(FileExistsError):
    pass


def _num(x):
    x = float(x)
    return x if math.isfinite(x) else None


def observer_rows(result) -> list:
    obs = result.observers
    ratio = result.hazard_ratio
    m = len(obs)
    # per observer: the spot's angular subtense, C_E and the MPE used (hazard.extended_source);
    # results built without analyze() fall back to the point-source MPE
    alpha = obs.angular_subtense_rad if obs.angular_subtense_rad is not None else np.full(m, np.nan)
    c_e = obs.c_e if obs.c_e is not None else np.ones(m)
    mpe_w = obs.mpe_w_m2 if obs.mpe_w_m2 is not None else np.full(m, float(result.mpe_w_m2))
    mpe_h = (obs.mpe_radiant_exposure_j_m2 if obs.mpe_radiant_exposure_j_m2 is not None
             else np.full(m, float(result.mpe_radiant_exposure_j_m2)))
    rows = []
    for i, name in enumerate(obs.labels):
        rows.append({
            "name": name,
            "position_m": [float(v) for v in obs.position_m[i]],
            "peak_irradiance_w_m2": float(obs.peak_irradiance_w_m2[i]),
            "peak_time_s": float(obs.peak_time_s[i]),
            "static_irradiance_w_m2": float(obs.static_irradiance_w_m2[i]),
            "radiant_exposure_j_m2": float(obs.radiant_exposure_j_m2[i]),
            "static_radiant_exposure_j_m2": float(obs.static_radiant_exposure_j_m2[i]),
            "angular_subtense_rad": _num(alpha[i]),
            "c_e": float(c_e[i]),
            "mpe_w_m2": float(mpe_w[i]),
            "mpe_radiant_exposure_j_m2": float(mpe_h[i]),
            "hazard_ratio": float(ratio[i]),
            "exposure_ratio": float(obs.radiant_exposure_j_m2[i] / mpe_h[i]),
            "hazardous": bool(result.hazardous[i]),
            "hazardous_static": bool(result.hazardous_static[i]),
            "first_exceedance_s": _num(obs.first_exceedance_s[i]),
            "line_of_sight": bool(obs.line_of_sight[i]),
            "far_field": bool(obs.far_field[i]),
        })
    return rows


def _json_safe(obj):
    """Non-finite floats as the strings "inf", "-inf", "nan" (JSON has no such numbers;
    an infinite NOHD - a collimated beam without attenuation - must not vanish)."""
    if isinstance(obj, float) and not math.isfinite(obj):
        return "nan" if math.isnan(obj) else ("inf" if obj > 0 else "-inf")
    if isinstance(obj, dict):
        return {k: _json_safe(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_json_safe(v) for v in obj]
    return obj


def report_dict(result) -> dict:
    """The report as plain data: versions, scene echo and hash, MPE with its steps,
    stages, per-target NOHD and keep-out summaries, per-observer verdicts."""
    from .analysis import versions

    scene = result.scene
    fp = {}
    for key, f in (("static", result.footprint_static), ("dynamic", result.footprint_dynamic)):
        if f is not None:
            fp[key] = {"area_m2": f.area_m2, "eye_height_m": f.eye_height_m, "cells": int(f.mask.sum())}
    return _json_safe({
        "format": REPORT_FORMAT,
        "version": REPORT_VERSION,
        "versions": versions(),
        "scene": {"name": scene.name, "source": scene.source, "sha256": scene.text_sha256,
                  "offset_m": scene.offset_m.tolist(), "echo": scene.echo()},
        "mpe": result.mpe.to_dict(),
        "pulse": None if result.pulse is None else result.pulse.to_dict(),
        "mpe_w_m2": result.mpe_w_m2,
        "extended_source": getattr(result, "extended_source", None) or {"applied": False},
        "attenuation_per_m": result.attenuation_per_m,
        "beam": {"power_w": result.beam_power_w, "spill_w": result.spill_w, "blocked_w": result.blocked_w,
                 "sampling": getattr(result, "beam_sampling", None) or None},
        "stages": [s.to_dict() for s in result.stages],
        "times_s": {"start": float(result.times_s[0]), "end": float(result.times_s[-1]), "count": int(len(result.times_s))},
        "targets": [t.to_dict() for t in result.targets],
        "footprint": fp or None,
        "observers": observer_rows(result),
        "verdict_changes": result.verdict_changes(),
        "any_hazard": result.any_hazard,
        "notes": list(result.notes),
    })


CSV_COLUMNS = ["name", "x_m", "y_m", "z_m", "static_irradiance_w_m2", "peak_irradiance_w_m2", "peak_time_s",
               "radiant_exposure_j_m2", "angular_subtense_rad", "c_e", "mpe_w_m2", "hazard_ratio", "exposure_ratio", "hazardous", "hazardous_static",
               "first_exceedance_s", "line_of_sight", "far_field"]


def _csv_text(rows) -> str:
    buf = io.StringIO()
    w = csv.writer(buf)
    w.writerow(CSV_COLUMNS)
    for r in rows:
        x, y, z = r["position_m"]
        w.writerow([r["name"], repr(x), repr(y), repr(z)] + [
            "" if r[k] is None else (repr(r[k]) if isinstance(r[k], float) else r[k]) for k in CSV_COLUMNS[4:]
        ])
    return buf.getvalue()


def _write_synced(path: Path, text: str) -> None:
    with open(path, "w", encoding="utf-8", newline="") as fh:
        fh.write(text)
        fh.flush()
        os.fsync(fh.fileno())


def _fsync_dir(path: Path) -> None:
    try:
        fd = os.open(path, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


def write_outputs(result, outdir, *, force=False) -> list:
    """Write report.json and observers.csv into ``outdir`` (created if needed), as one unit.

    Both files are written (and fsynced) into a temporary folder beside ``outdir``, which
    is then renamed into place: a new ``outdir`` appears whole, and an existing one that
    holds only these outputs is swapped in two renames (never a new report beside an old
    table). If ``outdir`` also holds other files, report.json is removed first and renamed
    in last, so a report present is always the one matching the table. Nothing temporary
    is left behind after an exception.
    """
    out = Path(outdir)
    names = ("report.json", "observers.csv")
    targets = [out / n for n in names]
    if out.exists() and not out.is_dir():
        raise OutputExistsError(f"{out} exists and is not a folder")
    existing = [p for p in targets if p.exists()]
    if existing and not force:
        raise OutputExistsError(f"{existing[0]} exists: pass --force to overwrite")
    doc = report_dict(result)
    if "warnings" not in doc:  # plausibility warnings of the scene (unit mistakes)
        doc["warnings"] = list(getattr(result.scene, "warnings", None) or [])
    texts = {"report.json": json.dumps(doc, indent=1, allow_nan=False), "observers.csv": _csv_text(doc["observers"])}
    parent = out.parent if str(out.parent) else Path(".")
    parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{out.name}.", suffix=".tmp", dir=parent))
    try:
        mask = os.umask(0)
        os.umask(mask)
        for n in names:
            _write_synced(tmp / n, texts[n])
            os.chmod(tmp / n, 0o666 & ~mask)
        _fsync_dir(tmp)
        if not out.exists():
            os.chmod(tmp, 0o777 & ~mask)
            os.rename(tmp, out)  # one step: both outputs appear together
        else:
            swapped = False
            if not out.is_symlink() and set(os.listdir(out)) <= set(names):
                os.chmod(tmp, os.stat(out).st_mode & 0o7777)
                old = Path(tempfile.mkdtemp(prefix=f".{out.name}.", suffix=".old", dir=parent))
                try:
                    os.rename(out, old / "d")
                except OSError:  # e.g. a mount point: fall back to file renames
                    os.rmdir(old)
                else:
                    try:
                        os.rename(tmp, out)
                    except BaseException:
                        os.rename(old / "d", out)
                        raise
                    swapped = True
                    shutil.rmtree(old, ignore_errors=True)
            if not swapped:
                (out / "report.json").unlink(missing_ok=True)  # the report is the commit marker
                os.replace(tmp / "observers.csv", out / "observers.csv")
                os.replace(tmp / "report.json", out / "report.json")
                os.rmdir(tmp)
            _fsync_dir(out)
        _fsync_dir(parent)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    return targets


def summary_text(result) -> str:
    """A short human summary (stdout of ``hazard run``)."""
    lines = [f"Scene {result.scene.name!r}: MPE {result.mpe_w_m2:.6g} W/m^2 ({result.mpe.standard}, {result.mpe.duration_s:g} s)"]
    for s in result.stages:
        lines.append(f"  {'ran    ' if s.ran else 'skipped'} {s.name:14s} {s.detail}" + (f" [{s.seconds:.3g} s]" if s.ran else ""))
    for t in result.targets:
        d = t.to_dict()
        lines.append(f"  target {t.name}: NOHD static {d['nohd_static_m']:.4g} m, dynamic {d['nohd_dynamic_m']:.4g} m"
                     + (f"; mirror lobe beyond target: static {t.specular_nohd_static_m:.4g} m, dynamic {t.specular_nohd_dynamic_m:.4g} m"
                        if t.specular_nohd_static_m is not None else ""))
    n_h = int(np.sum(result.hazardous))
    lines.append(f"  observers: {len(result.observers)} points, {n_h} hazardous (static: {int(np.sum(result.hazardous_static))})")
    changed = result.verdict_changes()
    if changed:
        lines.append(f"  verdict changes static -> dynamic: {', '.join(changed[:10])}" + (" ..." if len(changed) > 10 else ""))
    for n in result.notes:
        lines.append(f"  note: {n}")
    return "\n".join(lines)
