"""Scenario studies: generation, serial == Dask (embedded and existing scheduler), resume,
failures recorded, Monte Carlo summaries."""

import json

import numpy as np
import pytest

from hazard.drivers.study import MonteCarlo, Parameter, Study, load_study, run_study, scenarios, set_path


def plate_study(**kw):
    base = dict(name="t", scene="plate", kind="grid", parameters=(Parameter("laser.power_w", values=(10.0, 100.0, 1000.0)),))
    base.update(kw)
    return Study(**base)


def test_set_path():
    d = {"laser": {"power_w": 1.0}, "targets": [{"material": {"file": "a"}}]}
    set_path(d, "targets[0].material.file", "b")
    set_path(d, "laser.power_w", 2.0)
    assert d["targets"][0]["material"]["file"] == "b" and d["laser"]["power_w"] == 2.0
    with pytest.raises(ValueError, match="index 3 is out of range"):
        set_path(d, "targets[3].name", "x")
    with pytest.raises(ValueError, match="'nope' does not exist"):
        set_path(d, "nope.x", 1)
    # a missing leaf is never created (a misspelling would otherwise sweep nothing)
    with pytest.raises(ValueError, match="'powr_w' does not exist in the base scene"):
        set_path(d, "laser.powr_w", 3.0)
    assert d["laser"] == {"power_w": 2.0}


def test_schema_path_names_the_closest_field():
    from hazard.drivers.study import check_schema_path

    for ok in ("laser.power_w", "targets[0].material.rho_d", "observers[2].points_m", "analysis.beam_samples"):
        check_schema_path(ok)
    with pytest.raises(ValueError, match=r"'powr_w' is not a field of laser; did you mean 'laser.power_w'"):
        check_schema_path("laser.powr_w")
    with pytest.raises(ValueError, match=r"did you mean 'targets\[0\].material'"):
        check_schema_path("targets[0].materal.file")
    with pytest.raises(ValueError, match=r"targets is a list; expected an item of it, e.g. targets\[0\].name"):
        check_schema_path("targets.name")
    with pytest.raises(ValueError, match="laser is not a list"):
        check_schema_path("laser[0].power_w")
    with pytest.raises(ValueError, match="laser.power_w is a value, not a table"):
        check_schema_path("laser.power_w.x")


def _study_file(tmp_path, body):
    p = tmp_path / "s.toml"
    p.write_text('name = "x"\nscene = "plate"\n' + body)
    return p


def test_study_file_validated_in_full_before_work(tmp_path):
    sweep = '[sweep]\nkind = "grid"\n[[sweep.parameters]]\npath = "{}"\nvalues = {}\n'
    with pytest.raises(ValueError, match=r"sweep.parameters\[0\].path: .*did you mean 'laser.power_w'"):
        load_study(_study_file(tmp_path, sweep.format("laser.powr_w", "[1.0, 2.0]")))
    # a value of the wrong type, in the third scenario only: named with its scenario and path
    with pytest.raises(ValueError, match=r"1 of 3 distinct scenario.*scenario 2 \(laser.power_w = True\).*laser.power_w"):
        load_study(_study_file(tmp_path, sweep.format("laser.power_w", '[1.0, 2.0, true]')))
    # a text that is no quantity is refused by the units reader, naming the value's place in the study file
    with pytest.raises(ValueError, match=r"sweep.parameters\[0\].values\[2\] = 'lots': expected a number and a unit"):
        load_study(_study_file(tmp_path, sweep.format("laser.power_w", '[1.0, 2.0, "lots"]')))
    with pytest.raises(ValueError, match=r"2 of 3 distinct .*scenario 0 .*-1.0.*scenario 2 .*-5.0"):
        load_study(_study_file(tmp_path, sweep.format("laser.power_w", "[-1.0, 2.0, -5.0]")))
    # a random sweep: every drawn scenario is checked, not only the range's low end
    rng = '[sweep]\nkind = "random"\nsamples = 6\n[[sweep.parameters]]\npath = "laser.power_w"\nrange = [-1.0, 1.0]\n'
    with pytest.raises(ValueError, match=r"of 6 distinct scenario"):
        load_study(_study_file(tmp_path, rng))
    # a schema field the base scene leaves at its default is refused, not created
    with pytest.raises(ValueError, match=r"sweep.parameters\[0\].path: .*'eye_height_m' does not exist in the base scene"):
        load_study(_study_file(tmp_path, sweep.format("observers[0].eye_height_m", "[1.0, 2.0]")))
    # run_study checks a Study built in Python the same way, before any file is written
    with pytest.raises(ValueError, match="distinct scenario"):
        run_study(plate_study(parameters=(Parameter("laser.power_w", values=(10.0, -5.0)),)), tmp_path / "out", serial=True)
    assert not (tmp_path / "out").exists()


def test_cli_study_exit_codes_and_keep_going(tmp_path, monkeypatch):
    import hazard.pipeline.analysis
    from hazard.cli import main

    real = hazard.pipeline.analysis.analyze

    def flaky(scene, **kw):  # an injected run-time failure of the scenarios at 100 W and 1000 W
        if scene.spec.laser.power_w > 50:
            raise RuntimeError(f"injected at {scene.spec.laser.power_w:g} W")
        return real(scene, **kw)

    monkeypatch.setattr(hazard.pipeline.analysis, "analyze", flaky)
    p = _study_file(tmp_path, '[sweep]\nkind = "grid"\n[[sweep.parameters]]\npath = "laser.power_w"\nvalues = [10.0, 100.0, 1000.0, 20.0]\n')
    import io

    out, err = io.StringIO(), io.StringIO()
    assert main(["study", str(p), "-o", str(tmp_path / "a"), "--serial", "--quiet"], stdout=out, stderr=err) == 4
    assert err.getvalue().count("\n") == 1
    assert "1 of 4 scenarios failed, 2 not run (stopped at the first failure" in err.getvalue()
    assert "RuntimeError: injected at 100 W" in err.getvalue()
    doc = json.loads((tmp_path / "a" / "summary.json").read_text())
    assert (doc["failed"], doc["not_run"], doc["complete"]) == (1, 2, False)
    err = io.StringIO()
    assert main(["study", str(p), "-o", str(tmp_path / "b"), "--serial", "--quiet", "--keep-going"], stdout=out, stderr=err) == 4
    assert "2 of 4 scenarios failed;" in err.getvalue() and "not run" not in err.getvalue()
    doc = json.loads((tmp_path / "b" / "summary.json").read_text())
    assert (doc["succeeded"], doc["failed"], doc["not_run"]) == (2, 2, 0)
    assert list(doc["failure_kinds"]) == ["RuntimeError"]
    # fixed: the restart runs the failed scenarios again and exits 0
    monkeypatch.setattr(hazard.pipeline.analysis, "analyze", real)
    err = io.StringIO()
    assert main(["study", str(p), "-o", str(tmp_path / "b"), "--serial", "--quiet"], stdout=out, stderr=err) == 0
    assert "2 run now, 2 already done" in out.getvalue()
    assert err.getvalue() == ""


def test_scenario_generation():
    g = scenarios(Study("g", "plate", "grid", (Parameter("a.b", values=(1, 2)), Parameter("c", values=(3, 4, 5)))))
    assert len(g) == 6 and {tuple(s["overrides"].values()) for s in g} == {(a, c) for a in (1, 2) for c in (3, 4, 5)}
    lhs = scenarios(Study("l", "plate", "lhs", (Parameter("x", range=(0.0, 1.0)), Parameter("y", range=(1.0, 100.0), scale="log")), samples=20))
    x = np.array([s["overrides"]["x"] for s in lhs])
    assert sorted(np.floor(x * 20).astype(int)) == list(range(20))  # one sample per stratum
    y = np.log10([s["overrides"]["y"] for s in lhs])
    assert sorted(np.floor(y / 2 * 20).astype(int)) == list(range(20))
    mc = scenarios(Study("m", "plate", montecarlo=MonteCarlo(samples=5)))
    assert [s["mc"] for s in mc] == [0, 1, 2, 3, 4] and len({s["seed"] for s in mc}) == 5
    assert scenarios(Study("m", "plate", montecarlo=MonteCarlo(samples=5))) == mc  # deterministic


def _rows(res):
    return [{k: v for k, v in r.items() if k != "run_time_s"} for r in res.rows]


def test_serial_equals_dask_embedded_and_existing_scheduler(tmp_path):
    import os

    from distributed import Client

    from hazard.drivers.study import local_cluster

    user_trim = os.environ.get("MALLOC_TRIM_THRESHOLD_")  # before any cluster could set it
    study = plate_study(montecarlo=MonteCarlo(samples=2, brdf_scale_sigma=0.3, normal_tilt_deg=2.0), seed=3)
    serial = run_study(study, tmp_path / "serial", serial=True)
    dask = run_study(study, tmp_path / "dask", n_workers=2)
    assert _rows(serial) == _rows(dask) and len(serial.rows) == 6
    # a real scheduler and worker processes on loopback, reached by address
    with local_cluster(1) as cluster:
        remote = run_study(study, tmp_path / "remote", scheduler=cluster.scheduler_address)
        with Client(cluster) as client:  # workers run without Dask's aggressive malloc trimming
            env = client.run(lambda: os.environ.get("MALLOC_TRIM_THRESHOLD_"))
        assert list(env.values()) == [user_trim]
    assert _rows(remote) == _rows(serial)
    assert (tmp_path / "dask" / "results.csv").read_text().count("\n") == 7
    nohd = [r["nohd_static_m"] for r in serial.rows]
    assert len(set(np.round(nohd, 12))) == 6  # Monte Carlo draws change the result


def test_resume_after_a_kill_and_failures_recorded(tmp_path, monkeypatch):
    import hazard.pipeline.analysis

    real = hazard.pipeline.analysis.analyze

    def flaky(scene, **kw):  # an injected run-time failure (the scene itself is valid)
        if scene.spec.laser.power_w == 100.0:
            raise RuntimeError("injected power_w failure")
        return real(scene, **kw)

    monkeypatch.setattr(hazard.pipeline.analysis, "analyze", flaky)
    study = plate_study(parameters=(Parameter("laser.power_w", values=(10.0, 100.0, 1000.0, 50.0)),))
    first = run_study(study, tmp_path, serial=True, keep_going=True)
    assert first.failed == 1 and first.summary["failures"][0]["id"] == 1 and not first.ok
    assert "power_w" in first.summary["failures"][0]["error"]
    # "kill": drop two finished results; the restart runs those and the failed one
    for k in (2, 3):
        (tmp_path / "scenarios" / f"{k:05d}.json").unlink()
    again = run_study(study, tmp_path, serial=True, keep_going=True)
    assert again.ran == 3 and again.skipped == 1
    assert _rows(again) == _rows(first)
    monkeypatch.setattr(hazard.pipeline.analysis, "analyze", real)
    other = plate_study(seed=99)
    with pytest.raises(ValueError, match="holds results of another study"):
        run_study(other, tmp_path, serial=True)
    assert run_study(other, tmp_path, serial=True, force=True).ran == 3


def test_monte_carlo_percentiles_and_files(tmp_path):
    study = Study("mc", "plate", montecarlo=MonteCarlo(samples=30, brdf_scale_sigma=0.5), seed=1)
    res = run_study(study, tmp_path, serial=True)
    st = res.summary["statistics"]["nohd_static_m"]
    assert st["p50"] <= st["p95"] <= st["max"] and st["p95"] > st["p50"]
    vals = np.array([r["nohd_static_m"] for r in res.rows])
    scales = np.array([r["brdf_scales"][0] for r in res.rows])
    # the Lambertian NHZ scales with sqrt(BRDF scale): an analytic check of the draw's effect
    np.testing.assert_allclose(vals / np.sqrt(scales), vals[0] / np.sqrt(scales[0]), rtol=1e-9)
    doc = json.loads((tmp_path / "summary.json").read_text())
    assert doc["scenarios"] == 30 and doc["failed"] == 0
    assert (tmp_path / "summary.png").stat().st_size > 5000
    pq = pytest.importorskip("pyarrow.parquet")
    table = pq.read_table(tmp_path / "results.parquet").to_pydict()
    assert len(table["nohd_static_m"]) == 30 and table["nohd_static_m"][0] == pytest.approx(vals[0])


def test_load_study_errors(tmp_path):
    p = tmp_path / "s.toml"
    p.write_text('name = "x"\nscene = "plate"\n[sweep]\nkind = "grid"\n[[sweep.parameters]]\npath = "laser.power_w"\nrange = [1.0, 2.0]\n')
    with pytest.raises(ValueError, match="every parameter needs values"):
        load_study(p)
    p.write_text('name = "x"\nscenery = "plate"\n')
    with pytest.raises(ValueError, match=r"unknown keys \['scenery'\]"):
        load_study(p)
    p.write_text('name = "x"\nscene = "plate"\n[montecarlo]\nsamples = 3\nspread = 1\n')
    with pytest.raises(ValueError, match=r"montecarlo: unknown keys \['spread'\]"):
        load_study(p)


def test_dask_run_stops_at_the_first_failure(tmp_path, monkeypatch):
    """On Dask the remaining scenarios are cancelled after a failure (an in-process cluster,
    so the injected failure reaches the workers); --keep-going runs them all."""
    import hazard.pipeline.analysis
    from distributed import LocalCluster

    real = hazard.pipeline.analysis.analyze

    def flaky(scene, **kw):
        if scene.spec.laser.power_w == 10.0:
            raise RuntimeError("injected")
        return real(scene, **kw)

    monkeypatch.setattr(hazard.pipeline.analysis, "analyze", flaky)
    study = plate_study(parameters=(Parameter("laser.power_w", values=(10.0, 20.0, 30.0, 40.0, 50.0, 60.0)),))
    with LocalCluster(n_workers=1, threads_per_worker=1, processes=False, dashboard_address=None) as cluster:
        stop = run_study(study, tmp_path / "a", scheduler=cluster.scheduler_address)
        assert stop.failed == 1 and not stop.ok and stop.summary["failure_kinds"] == {"RuntimeError": "RuntimeError: injected"}
        assert stop.not_run + stop.ran == 6 and len(stop.rows) == stop.ran
        go = run_study(study, tmp_path / "b", scheduler=cluster.scheduler_address, keep_going=True)
    assert (go.failed, go.not_run, go.ran) == (1, 0, 6)


def test_every_bundled_study_loads_and_is_named_in_the_help():
    """``hazard study NAME``: each bundled study (hazard/studies/*.toml, package data)
    validates and ``hazard study --help`` names it (plate_power, the README's quick study,
    was added beside power_sweep)."""
    from hazard.cli import build_parser
    from hazard.drivers.study import examples

    names = set(examples())
    assert {"power_sweep", "montecarlo_binoculars", "plate_power"} <= names
    action = next(a for a in build_parser()._subparsers._group_actions[0].choices["study"]._actions if a.dest == "study")
    assert all(n in action.help for n in names), action.help
    for name in names:
        assert len(scenarios(load_study(name))) >= 2, name
    assert [p.values for p in load_study("plate_power").parameters] == [(1000.0, 10000.0, 100000.0)]
