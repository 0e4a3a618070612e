"""Compare the bundled examples' outputs of two checkouts (before / after a change).

Run:  python examples/recheck_examples.py BEFORE_DIR AFTER_DIR [--names a,b] [--top 5] [--rtol 1e-6]

Each folder holds one sub-folder per example, as written by ``hazard run NAME -o DIR/NAME``
(report.json and observers.csv). For every example found in both, prints:

- the verdict: ``any_hazard`` and the hazardous observer points (of all), before -> after;
- the observers whose verdict flips, and the largest hazard-ratio changes (with the direct
  and reflected irradiance parts, and the new keys ``direct_point_irradiance_w_m2`` and
  ``aperture_diameter_m`` where the after-run has them, so a change can be traced to the
  limiting aperture or to the reflection);
- each target's NOHDs: diffuse static/dynamic, specular static/dynamic, the keep-out lobes'
  maximum NOHD and volume, and the same through each optical aid;
- the laser surface danger zone (direct-beam NOHD, area, reach, contained; through aids) and
  each mirror beam's NOHD and reach; the hazardous-ground footprint's area;
- the run time (the sum of the stages' seconds in report.json) and the stages that changed most.

Values are read from the files alone (nothing is recomputed), so the comparison can be redone
on any two output folders. A value that changes by more than ``--rtol`` (relative) is marked
``*`` (unchanged ones, ``=``, are listed with ``--all``). The script writes nothing.
"""

import argparse
import csv
import json
import math
import sys
from pathlib import Path

def _load(folder: Path):
    """report.json (dict) and observers.csv (dict name -> row dict of str) of one run, or None."""
    rep = folder / "report.json"
    if not rep.is_file():
        return None
    report = json.loads(rep.read_text())
    rows = {}
    obs = folder / "observers.csv"
    if obs.is_file():
        with obs.open(newline="") as f:
            rows = {r["name"]: r for r in csv.DictReader(f)}
    return report, rows


def _num(v):
    """A report value as float (``"inf"`` -> inf, None / "" -> None)."""
    if v is None or v == "":
        return None
    if isinstance(v, (str, bool, int, float)):
        return float(v)
    return None


def _fmt(v) -> str:
    if v is None:
        return "-"
    if isinstance(v, bool):
        return str(v)
    if isinstance(v, float) and math.isinf(v):
        return "inf"
    return f"{v:.4g}" if isinstance(v, float) else str(v)


def _changed(a, b, rtol: float) -> bool:
    if a is None or b is None or isinstance(a, bool) or isinstance(b, bool):
        return a != b
    if math.isinf(a) or math.isinf(b):
        return a != b
    return abs(b - a) > rtol * max(abs(a), abs(b), 1e-300)


def _pair(label: str, a, b, rtol: float) -> str:
    mark = "*" if _changed(a, b, rtol) else "="
    rel = ""
    if mark == "*" and isinstance(a, float) and isinstance(b, float) and a not in (0.0,) and math.isfinite(a) and math.isfinite(b):
        rel = f"  ({100.0 * (b - a) / abs(a):+.3g} %)"
    return f"  {mark} {label:44s} {_fmt(a):>12s} -> {_fmt(b):<12s}{rel}"


def _verdict(report, rows) -> tuple:
    """(any_hazard, hazardous points, all points) from observers.csv (every point), else report.json."""
    if rows:
        haz = sum(r["hazardous"] == "True" for r in rows.values())
        return bool(report.get("any_hazard")), haz, len(rows)
    obs = report.get("observers") or []
    return bool(report.get("any_hazard")), sum(bool(o.get("hazardous")) for o in obs), len(obs)


def observer_lines(rows_a: dict, rows_b: dict, top: int, rtol: float) -> list:
    """Verdict flips and the ``top`` largest hazard-ratio changes (by |log ratio|)."""
    common = [n for n in rows_a if n in rows_b]
    lines = []
    missing = (set(rows_a) ^ set(rows_b))
    if missing:
        lines.append(f"  ! observers in only one run: {len(missing)} (e.g. {sorted(missing)[:3]})")
    flips = [n for n in common if rows_a[n]["hazardous"] != rows_b[n]["hazardous"]]
    for n in flips:
        ra, rb = _num(rows_a[n]["hazard_ratio"]), _num(rows_b[n]["hazard_ratio"])
        to = "HAZARDOUS" if rows_b[n]["hazardous"] == "True" else "safe"
        lines.append(f"  FLIP {n}: hazard ratio {_fmt(ra)} -> {_fmt(rb)} (now {to})")
    change = []
    for n in common:
        ra, rb = _num(rows_a[n]["hazard_ratio"]), _num(rows_b[n]["hazard_ratio"])
        if ra is None or rb is None or not _changed(ra, rb, rtol):
            continue
        if ra > 0 and rb > 0:
            key = abs(math.log(rb / ra))
        else:
            key = math.inf
        change.append((key, n, ra, rb))
    change.sort(key=lambda c: -c[0])
    lines.append(f"  hazard ratio changed (rtol {rtol:g}) for {len(change)} of {len(common)} points; largest:")
    for _, n, ra, rb in change[:top]:
        a, b = rows_a[n], rows_b[n]
        parts = [f"{k.replace('_irradiance_w_m2', '')} {_fmt(_num(a.get(k)))} -> {_fmt(_num(b.get(k)))}"
                 for k in ("direct_irradiance_w_m2", "reflected_irradiance_w_m2") if k in a and k in b]
        extra = [f"{k} {_fmt(_num(b[k]))}" for k in ("direct_point_irradiance_w_m2", "aperture_diameter_m") if b.get(k, "")]
        lines.append(f"    {n}: ratio {_fmt(ra)} -> {_fmt(rb)} (x{_fmt(rb / ra) if ra else '-'}); W/m^2 "
                     + "; ".join(parts + extra))
    return lines


def _aided(t: dict) -> dict:
    return {f"{a['magnification']:g}x{1e3 * a['objective_diameter_m']:g}": a for a in t.get("aided") or []}


def target_lines(rep_a: dict, rep_b: dict, rtol: float) -> list:
    """Each target's NOHDs and keep-out lobes, and through each optical aid."""
    lines = []
    tb = {t["name"]: t for t in rep_b.get("targets") or []}
    for ta in rep_a.get("targets") or []:
        t = tb.get(ta["name"])
        if t is None:
            lines.append(f"  ! target {ta['name']} missing after")
            continue
        lines.append(f"  target {ta['name']}:")
        for k in ("nohd_static_m", "nohd_dynamic_m", "specular_nohd_static_m", "specular_nohd_dynamic_m",
                  "peak_irradiance_w_m2", "spot_power_w"):
            lines.append(_pair(k, _num(ta.get(k)), _num(t.get(k)), rtol))
        for side in ("keepout_static", "keepout_dynamic"):
            ka, kb = ta.get(side) or {}, t.get(side) or {}
            for k in ("max_nohd_m", "volume_m3"):
                lines.append(_pair(f"{side}.{k}", _num(ka.get(k)), _num(kb.get(k)), rtol))
        aa, ab = _aided(ta), _aided(t)
        for name in aa.keys() | ab.keys():
            for k in ("nohd_static_m", "nohd_dynamic_m", "specular_nohd_static_m", "specular_nohd_dynamic_m"):
                lines.append(_pair(f"aided {name} {k}", _num(aa.get(name, {}).get(k)), _num(ab.get(name, {}).get(k)), rtol))
    return lines


def zone_lines(rep_a: dict, rep_b: dict, rtol: float) -> list:
    """The laser surface danger zone, mirror beams, direct-beam spill and the ground footprint."""
    lines = ["  zones:"]
    za, zb = rep_a.get("sdz") or {}, rep_b.get("sdz") or {}
    for k in ("nohd_m", "max_range_m", "area_m2", "hazard_half_width_m", "contained", "escaping_directions"):
        lines.append(_pair(f"sdz.{k}", _val(za.get(k)), _val(zb.get(k)), rtol))
    aa, ab = _aided(za), _aided(zb)
    for name in aa.keys() | ab.keys():
        for k in ("nohd_m", "max_range_m", "area_m2"):
            lines.append(_pair(f"sdz aided {name} {k}", _num(aa.get(name, {}).get(k)), _num(ab.get(name, {}).get(k)), rtol))
    ma = {m["target"]: m for m in za.get("mirror_beams") or []}
    mb = {m["target"]: m for m in zb.get("mirror_beams") or []}
    for name in ma.keys() | mb.keys():
        for k in ("nohd_m", "max_reach_m", "contained"):
            lines.append(_pair(f"mirror beam {name} {k}", _val(ma.get(name, {}).get(k)), _val(mb.get(name, {}).get(k)), rtol))
    sa = ((rep_a.get("beam") or {}).get("spill") or {})
    sb = ((rep_b.get("beam") or {}).get("spill") or {})
    lines.append(_pair("beam.spill.nohd_m", _num(sa.get("nohd_m")), _num(sb.get("nohd_m")), rtol))
    fa, fb = rep_a.get("footprint") or {}, rep_b.get("footprint") or {}
    for side in ("static", "dynamic"):
        lines.append(_pair(f"footprint.{side}.area_m2", _num((fa.get(side) or {}).get("area_m2")),
                           _num((fb.get(side) or {}).get("area_m2")), rtol))
    return lines


def _val(v):
    return v if isinstance(v, bool) else _num(v)


def time_lines(rep_a: dict, rep_b: dict, top: int = 3) -> list:
    """Total stage time and the stages that changed most [s]."""
    sa = {s["name"]: s.get("seconds") or 0.0 for s in rep_a.get("stages") or []}
    sb = {s["name"]: s.get("seconds") or 0.0 for s in rep_b.get("stages") or []}
    lines = [f"  run time (sum of stages) {sum(sa.values()):.3g} s -> {sum(sb.values()):.3g} s"]
    diff = sorted(sa.keys() | sb.keys(), key=lambda n: -abs(sb.get(n, 0.0) - sa.get(n, 0.0)))
    for n in diff[:top]:
        lines.append(f"    stage {n}: {sa.get(n, 0.0):.3g} s -> {sb.get(n, 0.0):.3g} s")
    return lines


def compare(name: str, a, b, top: int, rtol: float, changed_only: bool) -> list:
    """The comparison of one example as printable lines."""
    (rep_a, rows_a), (rep_b, rows_b) = a, b
    va, vb = _verdict(rep_a, rows_a), _verdict(rep_b, rows_b)
    head = (f"== {name}: any_hazard {va[0]} -> {vb[0]}; hazardous observer points {va[1]} of {va[2]} -> "
            f"{vb[1]} of {vb[2]}")
    body = observer_lines(rows_a, rows_b, top, rtol) + target_lines(rep_a, rep_b, rtol) + zone_lines(rep_a, rep_b, rtol)
    if changed_only:
        body = [ln for ln in body if not ln.startswith("  = ")]
    return [head] + body + time_lines(rep_a, rep_b)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("before", type=Path, help="folder of the before-runs (one sub-folder per example)")
    ap.add_argument("after", type=Path, help="folder of the after-runs")
    ap.add_argument("--names", default="", help="comma-separated examples (default: every sub-folder in both)")
    ap.add_argument("--top", type=int, default=5, help="largest hazard-ratio changes listed per example")
    ap.add_argument("--rtol", type=float, default=1e-6, help="relative change counted as a change")
    ap.add_argument("--all", action="store_true", help="also list the values that did not change")
    args = ap.parse_args(argv)
    names = [n for n in args.names.split(",") if n] or sorted(
        p.name for p in args.before.iterdir() if (p / "report.json").is_file() and (args.after / p.name / "report.json").is_file())
    if not names:
        print(f"no example with report.json in both {args.before} and {args.after}", file=sys.stderr)
        return 2
    for name in names:
        a, b = _load(args.before / name), _load(args.after / name)
        if a is None or b is None:
            print(f"== {name}: report.json missing in {'before' if a is None else 'after'}")
            continue
        print("\n".join(compare(name, a, b, args.top, args.rtol, not args.all)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
