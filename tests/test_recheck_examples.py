"""examples/recheck_examples.py: the before/after comparison of bundled examples' outputs."""

import csv
import importlib.util
import json
import math
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _script():
    spec = importlib.util.spec_from_file_location("recheck_examples", ROOT / "examples" / "recheck_examples.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def _write(folder: Path, ratios: dict, nohd_m: float, area_m2: float):
    """A minimal output folder: report.json and observers.csv of observers with ``ratios``."""
    folder.mkdir(parents=True)
    rows = [{"name": n, "hazard_ratio": repr(r), "hazardous": str(r >= 1.0), "direct_irradiance_w_m2": "0.0",
             "reflected_irradiance_w_m2": repr(50.0 * r)} for n, r in ratios.items()]
    with (folder / "observers.csv").open("w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    report = {"any_hazard": any(r >= 1.0 for r in ratios.values()),
              "targets": [{"name": "plate", "nohd_static_m": nohd_m, "nohd_dynamic_m": nohd_m, "aided": []}],
              "sdz": {"nohd_m": "inf", "area_m2": area_m2, "aided": [], "mirror_beams": []},
              "footprint": None, "stages": [{"name": "keepout", "seconds": 1.0}]}
    (folder / "report.json").write_text(json.dumps(report))


def test_flip_ratio_and_nohd_changes_are_listed(tmp_path, capsys):
    _write(tmp_path / "a" / "ex", {"p0": 2.0, "p1": 0.5, "p2": 0.1}, nohd_m=10.0, area_m2=100.0)
    _write(tmp_path / "b" / "ex", {"p0": 0.9, "p1": 0.5, "p2": 0.1}, nohd_m=8.0, area_m2=100.0)
    assert _script().main([str(tmp_path / "a"), str(tmp_path / "b")]) == 0
    out = capsys.readouterr().out
    assert "any_hazard True -> False; hazardous observer points 1 of 3 -> 0 of 3" in out
    assert "FLIP p0: hazard ratio 2 -> 0.9 (now safe)" in out
    assert "changed (rtol 1e-06) for 1 of 3 points" in out
    assert "p0: ratio 2 -> 0.9 (x0.45)" in out
    line = next(ln for ln in out.splitlines() if "nohd_static_m" in ln)
    assert line.startswith("  * ") and "(-20 %)" in line
    assert "sdz.area_m2" not in out  # unchanged values are listed only with --all
    assert _script().main([str(tmp_path / "a"), str(tmp_path / "b"), "--all"]) == 0
    assert "  = sdz.area_m2" in capsys.readouterr().out


def test_real_runs_power_doubled(tmp_path, capsys, monkeypatch):
    """Two real runs of the Lambertian plate, the second at twice the power: the lit
    observer's ratio x2 (the other is behind a box: 0 both times), the diffuse NOHD
    sqrt(rho P / (pi MPE)) x sqrt(2) and the lobe's volume (NOHD^3) x 2^1.5, from the formulas
    (the point-form lobe: the plate's lobe lies within its spot's near field, where
    hazard.physics.near_field_lobe integrates it; tests/validation/test_near_field_lobes.py)."""
    from hazard.physics import near_field_lobe
    from hazard.cli import main as hazard_main

    monkeypatch.setattr(near_field_lobe, "ENABLED", False)

    text = (ROOT / "scenes" / "examples" / "plate.toml").read_text()
    assert "power_w = 100.0" in text
    for side, power in (("a", 100.0), ("b", 200.0)):
        scene = tmp_path / f"plate_{side}.toml"
        scene.write_text(text.replace("power_w = 100.0", f"power_w = {power}"))
        assert hazard_main(["run", str(scene), "-o", str(tmp_path / side / "plate"), "--quiet", "--threads", "1"]) == 0
    capsys.readouterr()
    assert _script().main([str(tmp_path / "a"), str(tmp_path / "b")]) == 0
    out = capsys.readouterr().out
    assert "changed (rtol 1e-06) for 1 of 2 points" in out
    assert out.count("(x2)") == 1 and "east: ratio" in out
    vol = [ln for ln in out.splitlines() if "  * keepout_static.volume_m3" in ln][0].split()
    assert math.isclose(float(vol[4]) / float(vol[2]), 2 ** 1.5, rel_tol=2e-3)
    nohd = [ln for ln in out.splitlines() if "  * nohd_static_m" in ln][0].split()
    before, after = float(nohd[2]), float(nohd[4])
    assert math.isclose(before, math.sqrt(0.5 * 100.0 / (math.pi * 50.0)), rel_tol=1e-3)
    assert math.isclose(after, math.sqrt(0.5 * 200.0 / (math.pi * 50.0)), rel_tol=1e-3)
