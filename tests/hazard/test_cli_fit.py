"""hazard fit: from witness-screen files and tables to model files, and clear errors."""

import io
import json

import numpy as np
import pytest

import brdfmodels as bm
from brdfmodels import screen, validation
from hazard.cli import main


def write_test(folder, name, truth, incidence, groove, pixels=(48, 48), times=(0.0, 5.0)):
    t = screen.simulate_test(truth, test_id=name, incidence_deg=incidence, groove_angle_deg=groove, times_s=times,
                             state_of_time=lambda tt: 0.311 + 0.1189 * tt, temperature_of_time=lambda tt: 300 + 100 * tt,
                             pixels=pixels, gain_counts=400.0)
    return screen.save_test(t, folder)


def run(*argv):
    out, err = io.StringIO(), io.StringIO()
    return main([str(a) for a in argv], stdout=out, stderr=err), out.getvalue(), err.getvalue()


@pytest.fixture(scope="module")
def tests_folder(tmp_path_factory):
    folder = tmp_path_factory.mktemp("screen")
    truth = validation.SyntheticGroovedMetal()
    paths = [write_test(folder, f"t{k}", truth, inc, g) for k, (inc, g) in enumerate(validation.FIT_TESTS[:4])]
    return folder, paths


def test_fit_screen_dynamic_with_envelope(tests_folder):
    folder, paths = tests_folder
    code, out, err = run("fit", "screen", *paths, "-o", folder / "dyn.json", "--state", "time_s", "--states", "0,5",
                         "--envelope", "sh", "--envelope-output", folder / "env.json", "--samples-output", folder / "s.csv", "--force")
    assert code == 0, err
    model = bm.load(folder / "dyn.json")
    assert model.is_dynamic and model.state_name == "time_s" and model.basis.size == 37
    env = bm.load(folder / "env.json")
    samples = screen.Samples.from_csv(folder / "s.csv")
    assert np.all(env.evaluate(samples.wi, samples.wo) >= samples.brdf_per_sr * (1 - 1e-12))
    assert "'fraction_bounded': 1.0" in out


def test_fit_sh_ts5_from_samples_and_report(tests_folder):
    folder, paths = tests_folder
    run("fit", "screen", *paths, "-o", folder / "tmp.json", "--samples-output", folder / "s2.csv", "--force")
    code, out, err = run("fit", "sh", folder / "s2.csv", "-o", folder / "static.json", "--basis", "6,4,2,0", "--json", "--force",
                         "--report", "--quiet", "--smoothing", "1e-6")
    assert code == 0, err
    report, end = json.JSONDecoder().raw_decode(out)  # --report prints the cross-validation table first, then the fit
    doc = json.loads(out[end:])
    assert doc["rows"][0]["coefficients"] == 27 and doc["rows"][0]["smoothing"] == 1e-6  # --smoothing reaches the fit
    # the leave-one-test-out table: every setting of the grid that the four folds can fit, scored
    table = report["rows"]
    assert report["report"].startswith("leave-one-test-out") and len(table) >= 20
    assert {(r["lh_max"], r["mh_max"], r["fanout"]) for r in table} <= {
        (lh, mh, f) for lh in validation.DEFAULT_LH_MAXES for mh in validation.DEFAULT_MH_MAXES for f in validation.DEFAULT_FANOUTS}
    assert all(r["mh_max"] <= r["lh_max"] and np.isfinite(r["held_out_log_rms"]) and r["held_out_log_rms"] > 0 for r in table)
    # the choice: the fewest coefficients among settings within (1 + tolerance) of the lowest worst-fold error
    lowest = min(r["worst_fold_log_rms"] for r in table)
    ok = [r for r in table if r["worst_fold_log_rms"] <= (1 + validation.DEFAULT_BASIS_TOLERANCE) * lowest]
    best = report["best"]
    assert best in table and best in ok and best["coefficients"] == min(r["coefficients"] for r in ok)
    code, out, _ = run("fit", "ts5", folder / "s2.csv", "-o", folder / "ts5.json", "--maxeval", "400", "--force")
    assert code == 0 and isinstance(bm.load(folder / "ts5.json"), bm.TorranceSparrow5)


def test_fit_oxidation_cli(tmp_path):
    ox = bm.OxidationModel.stainless_steel()
    t = np.linspace(0, 12, 121)
    temp = np.minimum(293 + 500 * t, 1450)
    r = 0.62 * np.exp(-ox.extinction(t, temp))
    np.savetxt(tmp_path / "series.csv", np.c_[t, temp, r], delimiter=",", header="time_s,temperature_k,reflectance", comments="")
    code, out, err = run("fit", "oxidation", tmp_path / "series.csv", "-o", tmp_path / "ox.json")
    assert code == 0, err
    doc = json.loads((tmp_path / "ox.json").read_text())
    assert doc["activation_temperature_k"] == pytest.approx(9060, rel=1e-4) and "95 % CI" in out
    (tmp_path / "bad.csv").write_text("time_s,temperature_k,reflectance\n0,300,0.9\n1,abc,0.8\n")
    code, _, err = run("fit", "oxidation", tmp_path / "bad.csv", "-o", tmp_path / "b.json")
    assert code == 2 and "line 3, column 2 (temperature_k): expected a finite number" in err and err.count("\n") == 1
    assert "abc" not in err  # the file's contents are not quoted (issue 30)
    code, _, err = run("fit", "oxidation", tmp_path, "-o", tmp_path / "b.json")
    assert code == 2 and "a folder; expected a regular file (oxidation series)" in err


def test_fit_errors_are_one_line(tests_folder, tmp_path):
    folder, paths = tests_folder
    bad = tmp_path / "bad.toml"
    bad.write_text(paths[0].read_text().replace("counts = ", "count = "))
    for name in ("t0_ps.npy", "t0_frames.npz", "t0_pyro.csv"):
        (tmp_path / name).write_bytes((folder / name).read_bytes())
    code, out, err = run("fit", "screen", bad, "-o", tmp_path / "x.json")
    assert code == 2 and "calibration.counts: missing" in err and err.count("\n") == 1
    code, _, err = run("fit", "sh", folder / "nope.csv", "-o", tmp_path / "x.json")
    assert code == 2 and "cannot read the samples" in err
    run("fit", "screen", paths[0], "-o", tmp_path / "y.json", "--samples-output", tmp_path / "all.csv")
    lines = (tmp_path / "all.csv").read_text().splitlines()
    (tmp_path / "few.csv").write_text("\n".join(lines[:21]) + "\n")
    code, _, err = run("fit", "sh", tmp_path / "few.csv", "-o", tmp_path / "x.json")
    assert code == 2 and "underdetermined fit: 20 samples for 37 coefficients" in err
    (tmp_path / "exists.json").write_text("{}")
    code, _, err = run("fit", "screen", paths[0], "-o", tmp_path / "exists.json")
    assert code == 2 and "pass --force" in err


def test_fit_sh_two_states_from_named_columns(tests_folder, tmp_path):
    """``--state extinction,melt_fraction --states 'a,b;c,d'`` fits a two-state model from
    a samples table's named state columns (each sample tagged with its grid node here)."""
    folder, paths = tests_folder
    run("fit", "screen", *paths, "-o", folder / "tmp2.json", "--samples-output", folder / "s3.csv", "--force")
    s = screen.Samples.from_csv(folder / "s3.csv")
    k = np.arange(len(s))
    tagged = s.with_states({"extinction": np.where(k % 2, 1.5, 0.311), "melt_fraction": np.where((k // 2) % 2, 1.0, 0.0)})
    tagged.to_csv(tmp_path / "tagged.csv")
    code, out, err = run("fit", "sh", tmp_path / "tagged.csv", "-o", tmp_path / "two.json", "--basis", "4,2,2,0",
                         "--state", "extinction,melt_fraction", "--states", "0.311,1.5;0,1", "--force")
    assert code == 0, err
    model = bm.load(tmp_path / "two.json")
    assert model.state_dim == 2 and model.state_name == ("extinction", "melt_fraction")
    assert model.coefficients.shape == (2, 2, model.basis.size)
    code, _, err = run("fit", "sh", tmp_path / "tagged.csv", "-o", tmp_path / "bad.json", "--state", "extinction,melt_fraction",
                       "--states", "0.311,1.5", "--force")
    assert code == 2 and "--states" in err and "2 node list(s)" in err


@pytest.mark.parametrize("fail_at", ["envelope", "rename 1", "rename 2"])
def test_fit_files_are_one_unit(tests_folder, tmp_path, monkeypatch, fail_at):
    """hazard fit's model, envelope and samples files (separate paths) switch in together:
    a failure while writing the envelope, or at the second or third rename, leaves every
    final file as it was (old ones unchanged, new ones never created) and no temporary."""
    import brdfmodels.output_sets as unit
    from brdfmodels import fitting

    folder, paths = tests_folder
    old_model = tmp_path / "m.json"
    old_model.write_text("old model")
    env, smp = tmp_path / "sub" / "env.json", tmp_path / "s.csv"
    env.parent.mkdir()
    if fail_at == "envelope":
        def boom(*a, **k):
            raise RuntimeError("injected envelope failure")
        monkeypatch.setattr(fitting, "envelope_sh", boom)
    else:
        def step(name):
            if name == f"files: {fail_at}":
                raise OSError(28, "No space left on device (injected)")
        monkeypatch.setattr(unit, "_step", step)
    argv = ("fit", "screen", *paths, "-o", old_model, "--envelope", "sh", "--envelope-output", env, "--samples-output", smp, "--force")
    code, out, err = run(*argv)
    assert code == 1 and err.count("\n") == 1 and out == "", (code, err)
    assert old_model.read_text() == "old model" and not env.exists() and not smp.exists()
    assert sorted(p.name for p in tmp_path.rglob("*") if p.is_file()) == ["m.json"]  # no temporary or backup left
    monkeypatch.undo()
    code, out, err = run(*argv)
    assert code == 0, err
    assert bm.load(old_model).is_dynamic is False and bm.load(env) is not None and smp.exists() and f"wrote: {old_model}" in out
    assert sorted(p.name for p in tmp_path.rglob("*") if p.is_file()) == ["env.json", "m.json", "s.csv"]
