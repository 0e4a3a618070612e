"""hazard nohd / mpe options with units (issue 31 leftovers): ``--power "2 kW"`` as in scene
files; a unit of the wrong dimension, an unknown unit or a bare number on the unsuffixed
option is one clear line (exit 2), never a value read in the wrong unit."""

import io
import json
import math

import pytest

from hazard.cli import main


def run(*argv):
    out, err = io.StringIO(), io.StringIO()
    code = main(list(argv), stdout=out, stderr=err)
    return code, out.getvalue(), err.getvalue()


def _nohd_m(*argv):
    code, out, err = run("nohd", *argv, "--json")
    assert code == 0, err
    return json.loads(out)["nohd"]["nohd_m"]


def test_nohd_with_units_is_the_closed_form():
    """2 kW, MPE 5 mW/cm^2 = 50 W/m^2, 7 mm, 0.5 mrad: NOHD = (sqrt(4 P / (pi MPE)) - a) / phi."""
    expect = (math.sqrt(4 * 2000.0 / (math.pi * 50.0)) - 0.007) / 0.0005
    assert expect == pytest.approx(14258.99, abs=0.01)
    si = _nohd_m("--power-w", "2000", "--mpe-w-m2", "50", "--beam-diameter-m", "0.007", "--divergence-rad", "0.0005")
    units = _nohd_m("--power", "2 kW", "--mpe", "5 mW/cm^2", "--beam-diameter", "7 mm", "--divergence", "0.5 mrad")
    suffixed = _nohd_m("--power-w", "2 kW", "--mpe-w-m2", "50", "--beam-diameter-m", "0.7 cm", "--divergence-rad", "500 urad")
    assert si == pytest.approx(expect, rel=1e-12) and units == pytest.approx(expect, rel=1e-12)
    assert suffixed == pytest.approx(expect, rel=1e-12)
    # a divergence in degrees is converted, not read as rad: 0.0286479 deg = 0.5 mrad
    assert _nohd_m("--power", "2 kW", "--mpe-w-m2", "50", "--beam-diameter-m", "0.007", "--divergence",
                   f"{math.degrees(0.0005)!r} deg") == pytest.approx(expect, rel=1e-9)


def test_nohd_mpe_from_wavelength_and_duration_with_units():
    """1.064 um for 10 s: the MPE of 1064 nm, 10 s (50 W/m^2, ANSI Z136.1 C_A = 5)."""
    code, out, _ = run("mpe", "--wavelength", "1.064 um", "--duration", "10000 ms", "--json")
    assert code == 0 and json.loads(out)["irradiance_w_m2"] == pytest.approx(50.0)
    diffuse = _nohd_m("--kind", "diffuse", "--power", "10 W", "--wavelength", "1064 nm", "--duration", "10 s", "--reflectance", "1",
                      "--viewing-angle", "0 deg")
    assert diffuse == pytest.approx(math.sqrt(10.0 / (math.pi * 50.0)), rel=1e-9)  # sqrt(rho P cos / (pi MPE))


def test_mpe_pulse_train_options_take_units():
    a = run("mpe", "--wavelength-nm", "1064", "--duration-s", "1e-8", "--prf-hz", "1000", "--exposure-duration-s", "10", "--json")
    b = run("mpe", "--wavelength", "1064 nm", "--duration", "10 ns", "--prf", "1 kHz", "--exposure-duration", "10 s", "--json")
    assert a[0] == b[0] == 0 and json.loads(a[1]) == json.loads(b[1])


@pytest.mark.parametrize("argv, words", [
    (["nohd", "--power", "2 km", "--mpe-w-m2", "50"], ["--power = '2 km'", "'km' is not a unit of power"]),
    (["nohd", "--power-w", "2 J", "--mpe-w-m2", "50"], ["--power-w = '2 J'", "not a unit of power"]),
    (["nohd", "--power", "20", "--mpe-w-m2", "50"], ["--power = '20'", "ambiguous", "use --power-w (in W)"]),
    (["nohd", "--power-w", "5", "--mpe-w-m2", "50", "--divergence", "0.5"], ["--divergence = '0.5'", "ambiguous"]),
    (["nohd", "--power-w", "5", "--mpe-w-m2", "50", "--divergence-rad", "0.5 mm"], ["'mm' is not a unit of angle"]),
    (["nohd", "--power-w", "5", "--mpe", "50 W"], ["--mpe = '50 W'", "not a unit of irradiance"]),
    (["nohd", "--power-w", "5", "--mpe-w-m2", "50", "--visibility", "23 kg"], ["--visibility = '23 kg'", "not a unit of length"]),
    (["mpe", "--wavelength", "1064 nm", "--duration", "250 m"], ["--duration = '250 m'", "not a unit of time"]),
    (["mpe", "--wavelength", "1064 blorbs", "--duration-s", "1"], ["--wavelength = '1064 blorbs'", "unknown unit"]),
])
def test_a_wrong_unit_is_one_clear_line(argv, words):
    code, out, err = run(*argv)
    assert code == 2 and out == "" and err.count("\n") == 1 and "Traceback" not in err, (code, err)
    assert all(w in err for w in words), err
