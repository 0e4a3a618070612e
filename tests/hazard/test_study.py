"""Scenario studies: generation, serial == Dask (embedded and existing scheduler), resume,
failures recorded, Monte Carlo summaries."""

import json

import numpy as np
import pytest

from hazard.study import MonteCarlo, Parameter, Study, load_study, run_study, scenarios, set_path


def plate_study(**kw):
    base = dict(name="t", scene="plate", kind="grid", parameters=(Parameter("laser.power_w", values=(10.0, 100.0, 1000.0)),))
    base.update(kw)
    return Study(**base)


def test_set_path():
    d = {"laser": {"power_w": 1.0}, "targets": [{"material": {"file": "a"}}]}
    set_path(d, "targets[0].material.file", "b")
    set_path(d, "laser.aim_m", [1.0, 2.0, 3.0])
    assert d["targets"][0]["material"]["file"] == "b" and d["laser"]["aim_m"] == [1.0, 2.0, 3.0]
    with pytest.raises(ValueError, match="index 3 is out of range"):
        set_path(d, "targets[3].name", "x")
    with pytest.raises(ValueError, match="'nope' does not exist"):
        set_path(d, "nope.x", 1)


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

    from hazard.study import local_cluster

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


def test_resume_after_a_kill_and_failures_recorded(tmp_path):
    study = plate_study(parameters=(Parameter("laser.power_w", values=(10.0, -5.0, 1000.0, 50.0)),))
    first = run_study(study, tmp_path, serial=True)
    assert first.failed == 1 and first.summary["failures"][0]["id"] == 1
    assert "power_w" in first.summary["failures"][0]["error"]
    # "kill": drop two finished results; the restart runs only those
    for k in (2, 3):
        (tmp_path / "scenarios" / f"{k:05d}.json").unlink()
    again = run_study(study, tmp_path, serial=True)
    assert again.ran == 2 and again.skipped == 2
    assert _rows(again) == _rows(first)
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
