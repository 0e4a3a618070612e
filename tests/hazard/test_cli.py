"""The hazard command line: values, steps, JSON, and one clear line on bad input."""

import io
import json
import subprocess
import sys

import pytest

from hazard.cli import main


def run(*argv):
    out, err = io.StringIO(), io.StringIO()
    code = main(list(argv), stdout=out, stderr=err)
    return code, out.getvalue(), err.getvalue()


def test_mpe_text_shows_every_step():
    code, out, err = run("mpe", "--wavelength-nm", "1064", "--duration-s", "10")
    assert code == 0 and err == ""
    assert "C_A (IEC C4) = 5" in out and "E = 10 C_A C_C W/m^2 = 10 * 5 * 1" in out and "E = H / t = 50 W/m^2" in out


def test_mpe_json_and_standard():
    code, out, _ = run("mpe", "--wavelength-nm", "1064", "--duration-s", "1e-8", "--standard", "iec-60825-1-2007", "--json")
    doc = json.loads(out)
    assert code == 0 and doc["radiant_exposure_j_m2"] == pytest.approx(0.05) and doc["standard_title"] == "IEC 60825-1:2007"


def test_mpe_skin_and_pulses():
    assert json.loads(run("mpe", "--wavelength-nm", "633", "--duration-s", "1e4", "--skin", "--json")[1])["irradiance_w_m2"] == pytest.approx(2000)
    code, out, _ = run("mpe", "--wavelength-nm", "1064", "--duration-s", "1e-8", "--prf-hz", "1000", "--exposure-duration-s", "10")
    assert code == 0 and "rule 3" in out and "per-pulse MPE = 0.002 J/m^2" in out


def test_nohd_with_computed_mpe_atmosphere_and_optics():
    code, out, _ = run(
        "nohd", "--power-w", "1", "--wavelength-nm", "1064", "--duration-s", "10",
        "--beam-diameter-m", "0.002", "--divergence-rad", "0.001", "--json",
    )
    doc = json.loads(out)
    assert code == 0 and round(doc["nohd"]["nohd_m"], 2) == 157.58 and doc["mpe"]["irradiance_w_m2"] == 50
    code, out, _ = run("nohd", "--kind", "diffuse", "--power-w", "10", "--mpe-w-m2", "50", "--reflectance", "1")
    assert code == 0 and "= 0.252313 m" in out
    code, out, _ = run("nohd", "--kind", "specular", "--power-w", "10", "--mpe-w-m2", "50", "--reflectance", "0.9",
                       "--beam-diameter-m", "0.003", "--divergence-rad", "0.001")
    assert code == 0 and "NOHD = 475.731 m" in out
    code, out, _ = run("nohd", "--power-w", "10", "--mpe-w-m2", "50", "--beam-diameter-m", "0.003", "--divergence-rad", "0.001",
                       "--magnification", "7", "--objective-diameter-m", "0.05", "--visibility-km", "23", "--wavelength-nm", "1064")
    assert code == 0 and "K = 49" in out and "Kruse" in out


@pytest.mark.parametrize(
    "argv, message",
    [
        (["mpe", "--wavelength-nm", "50", "--duration-s", "1"], "wavelength_nm=50.0 is outside the standards' tables"),
        (["mpe", "--wavelength-nm", "1064", "--duration-s", "1e6"], "duration_s=1000000.0 is outside the tables"),
        (["mpe", "--wavelength-nm", "1064", "--duration-s", "1", "--standard", "nope"], "expected one of ['ansi-z136.1-2007'"),
        (["nohd", "--power-w", "-5", "--mpe-w-m2", "50", "--beam-diameter-m", "0.003", "--divergence-rad", "0.001"], "power_w=-5.0: expected a number >= 0"),
        (["nohd", "--power-w", "5", "--mpe-w-m2", "50"], "--beam-diameter-m: required for --kind direct"),
        (["mpe", "--wavelength-nm", "abc", "--duration-s", "1"], "--wavelength-nm = 'abc': expected a number and a unit, like '1064 nm'"),
        (["frobnicate"], "invalid choice: 'frobnicate'"),
        (["run", "plate", "-o", "x", "--threads", "0"], "argument --threads: '0': expected an integer >= 1"),
        (["run", "plate", "-o", "x", "--threads", "two"], "argument --threads: 'two': expected an integer >= 1"),
        (["study", "s.toml", "-o", "x", "--workers", "0"], "argument --workers: '0': expected an integer >= 1"),
    ],
)
def test_bad_input_one_clear_line(argv, message):
    code, out, err = run(*argv)
    assert code == 2 and out == ""
    assert message in err and err.count("\n") == 1 and "Traceback" not in err


def test_console_script_installed():
    res = subprocess.run([sys.executable, "-m", "hazard.cli", "mpe", "--wavelength-nm", "532", "--duration-s", "0.25", "--json"],
                         capture_output=True, text=True)
    assert res.returncode == 0 and json.loads(res.stdout)["irradiance_w_m2"] == pytest.approx(25.4558441)


def test_run_with_one_thread_equals_default(tmp_path):
    reports = []
    for k, extra in enumerate(([], ["--threads", "1"])):
        code, _, _ = run("run", "witness_screen", "-o", str(tmp_path / str(k)), "--quiet", *extra)
        assert code == 0
        reports.append(json.loads((tmp_path / str(k) / "report.json").read_text())["observers"])
    assert reports[0] == reports[1]
