"""Measured-BRDF readers: files written here from a known analytic BRDF, by each
format's definition (spec `range-safety.md` section 9), read back to that BRDF at their
grid points; malformed files give one error naming the line."""

from __future__ import annotations

import io
import json
import math

import numpy as np
import pytest

import brdfmodels as bm
from brdfmodels.io import read_astm_e1392, read_brdf_csv, read_bsdf, read_merl, read_samples

TRUTH = bm.TorranceSparrow5(kb=0.0698, kr=0.478, a=0.777, b=-28.935, kd=0.107)  # khaki paint (Zhang et al. 2010)


def _sph(theta, phi):
    return np.array([math.sin(theta) * math.cos(phi), math.sin(theta) * math.sin(phi), math.cos(theta)])


def _bsdf_text(aoi_deg, az_deg, rad_deg, symmetry="PlaneSymmetrical", truth=TRUTH):
    """A .bsdf file by the format's definition: per specular angle t (incidence from +x,
    the source at (sin t, 0, cos t)), the scattered direction is the specular one turned
    by the radial angle in the plane at the azimuth, azimuth 0 toward the normal."""
    lines = ["# written by the test", "Source  Measured", f"Symmetry  {symmetry}", "SpectralContent  Monochrome",
             "ScatterType  BRDF", "SampleRotation 1", "0", f"AngleOfIncidence {len(aoi_deg)}", " ".join(map(str, aoi_deg)),
             f"ScatterAzimuth {len(az_deg)}", " ".join(map(str, az_deg)), f"ScatterRadial {len(rad_deg)}",
             " ".join(map(str, rad_deg)), "", "Monochrome", "DataBegin"]
    expected = []
    for t in np.radians(aoi_deg):
        wi = np.array([math.sin(t), 0.0, math.cos(t)])
        spec = np.array([-math.sin(t), 0.0, math.cos(t)])
        toward = np.array([0.0, 0.0, 1.0]) - spec[2] * spec
        e1 = toward / np.linalg.norm(toward) if np.linalg.norm(toward) > 1e-12 else np.array([1.0, 0.0, 0.0])
        e2 = np.cross(spec, e1)
        lines.append("TIS 0.5")
        for a in np.radians(az_deg):
            row = []
            for r in np.radians(rad_deg):
                wo = math.cos(r) * spec + math.sin(r) * (math.cos(a) * e1 + math.sin(a) * e2)
                f = float(truth.evaluate(wi, wo)) if wo[2] > 0 else 0.0
                row.append(repr(f))
                if wo[2] > 0:
                    expected.append((wi, wo, f))
            lines.append(" ".join(row))
    lines.append("DataEnd")
    return "\n".join(lines) + "\n", expected


def test_bsdf_reads_back_the_analytic_brdf(tmp_path):
    text, expected = _bsdf_text([0, 20, 45], [0, 45, 90, 135, 180], [0, 2, 5, 10, 30, 60, 89])
    (tmp_path / "m.bsdf").write_text(text)
    s = read_bsdf(tmp_path / "m.bsdf")
    # plane-symmetric: each half written is mirrored, so every value appears twice
    assert len(s) == 2 * len(expected)
    np.testing.assert_allclose(s.brdf_per_sr, TRUTH.evaluate(s.wi, s.wo), rtol=1e-12)
    got = {tuple(np.round(np.r_[a, b], 9)) for a, b in zip(s.wi, s.wo)}
    assert all(tuple(np.round(np.r_[wi, wo], 9)) in got for wi, wo, _ in expected)


def test_bsdf_errors_name_the_line(tmp_path):
    text, _ = _bsdf_text([10], [0, 90], [1, 5])
    bad = text.replace("ScatterType  BRDF", "ScatterType  BTDF")
    (tmp_path / "a.bsdf").write_text(bad)
    with pytest.raises(ValueError, match="ScatterType: only BRDF data"):
        read_bsdf(tmp_path / "a.bsdf")
    lines = text.splitlines()
    k = lines.index("TIS 0.5") + 2  # the second value row
    lines[k] = lines[k].replace(lines[k].split()[0], "abc", 1)
    (tmp_path / "b.bsdf").write_text("\n".join(lines))
    with pytest.raises(ValueError, match=rf"line {k + 1}, column 1: data: expected a finite BRDF >= 0$"):
        read_bsdf(tmp_path / "b.bsdf")  # the value itself is not quoted (issue 30: no file contents in errors)
    (tmp_path / "c.bsdf").write_text(text.replace("DataEnd", "").rsplit("\n", 3)[0])
    with pytest.raises(ValueError, match="fewer than 2 x 2 values"):
        read_bsdf(tmp_path / "c.bsdf")


def _astm_text(rows):
    body = [f"NUM_POINTS {len(rows)}", "VARS theta_i,phi_i,theta_s,phi_s,BRDF"]
    body += [", ".join(repr(float(x)) for x in r) for r in rows]
    return "\n".join(body) + "\n"


def test_astm_e1392_reads_back_the_analytic_brdf(tmp_path):
    rng = np.random.default_rng(2)
    rows = []
    for _ in range(200):
        ti, pi_, ts, ps = rng.uniform(0, 1.4), rng.uniform(-math.pi, math.pi), rng.uniform(0, 1.5), rng.uniform(-math.pi, math.pi)
        rows.append((ti, pi_, ts, ps, float(TRUTH.evaluate(_sph(ti, pi_), _sph(ts, ps)))))
    rows.append(rows[0])  # a duplicate angle tuple is skipped
    (tmp_path / "m.astm").write_text(_astm_text(rows))
    s = read_astm_e1392(tmp_path / "m.astm")
    assert len(s) == 200
    np.testing.assert_allclose(s.brdf_per_sr, [r[4] for r in rows[:200]], rtol=1e-12)
    np.testing.assert_allclose(s.brdf_per_sr, TRUTH.evaluate(s.wi, s.wo), rtol=1e-12)
    (tmp_path / "bad.astm").write_text(_astm_text(rows[:3]).replace(repr(float(rows[1][2])), "x"))
    with pytest.raises(ValueError, match="line 4, column 3: data row: expected a number$"):
        read_astm_e1392(tmp_path / "bad.astm")


def test_generic_csv_in_brdf_and_reflectance_factor(tmp_path):
    rng = np.random.default_rng(4)
    ang = np.c_[rng.uniform(0, 80, 50), rng.uniform(-180, 180, 50), rng.uniform(0, 85, 50), rng.uniform(-180, 180, 50)].tolist()
    f = [float(TRUTH.evaluate(_sph(*np.radians(a[:2])), _sph(*np.radians(a[2:])))) for a in ang]
    head = "theta_i_deg,phi_i_deg,theta_r_deg,phi_r_deg"
    (tmp_path / "f.csv").write_text(head + ",brdf_per_sr\n" + "\n".join(",".join(map(repr, a + [v])) for a, v in zip(ang, f)))
    (tmp_path / "r.csv").write_text(head + ",reflectance_factor\n" + "\n".join(",".join(map(repr, a + [math.pi * v]))
                                                                                 for a, v in zip(ang, f)))
    for name in ("f.csv", "r.csv"):
        s = read_samples(tmp_path / name)
        np.testing.assert_allclose(s.brdf_per_sr, f, rtol=1e-12)
        np.testing.assert_allclose(s.brdf_per_sr, TRUTH.evaluate(s.wi, s.wo), rtol=1e-12)
    (tmp_path / "bad.csv").write_text(head + ",brdf_per_sr\n1,2,3,4,5\n1,2,3,nan,5\n")
    with pytest.raises(ValueError, match=r"line 3, column 4 \(phi_r_deg\): expected a finite number$"):
        read_brdf_csv(tmp_path / "bad.csv")
    (tmp_path / "two.csv").write_text(head + ",brdf_per_sr,reflectance_factor\n1,2,3,4,5,6\n")
    with pytest.raises(ValueError, match="line 1: expected columns"):
        read_brdf_csv(tmp_path / "two.csv")


def test_hazard_fit_takes_a_bsdf_file(tmp_path):
    from hazard.cli import main

    truth = bm.ABg(0.0025, 0.001, 1.8)
    text, _ = _bsdf_text([0, 15, 30, 45, 60], list(range(0, 181, 15)), [0.5, 1, 2, 4, 8, 15, 30, 50, 70], truth=truth)
    (tmp_path / "s.bsdf").write_text(text)
    out = io.StringIO()
    assert main(["fit", "abg", str(tmp_path / "s.bsdf"), "-o", str(tmp_path / "m.json"), "--json", "--quiet"],
                stdout=out, stderr=io.StringIO()) == 0
    row = json.loads(out.getvalue())["rows"][0]
    assert row["p_a"] == pytest.approx(0.0025, rel=1e-6) and row["p_g"] == pytest.approx(1.8, rel=1e-6)


def _merl_bytes(dims, truth, scale=(1 / 1500, 1.15 / 1500, 1.66 / 1500)):
    """A MERL .binary by its reference reader's definition: int32 dims (theta_h, theta_d,
    phi_d), then R, G, B blocks of float64 value / scale; theta_h at index i is
    (i / n_h)^2 pi / 2, theta_d and phi_d uniform (phi_d over [0, pi)); cells sampled at
    their centres; a cell whose directions dip below the horizon holds -1 (no data)."""
    nh, nd, npd = dims
    vals = np.empty((nh, nd, npd))
    for i in range(nh):
        th = ((i + 0.5) / nh) ** 2 * math.pi / 2
        h = np.array([math.sin(th), 0.0, math.cos(th)])
        for j in range(nd):
            td = (j + 0.5) / nd * math.pi / 2
            for k in range(npd):
                pd = (k + 0.5) / npd * math.pi
                d = np.array([math.sin(td) * math.cos(pd), math.sin(td) * math.sin(pd), math.cos(td)])
                wi = np.array([math.cos(th) * d[0] + math.sin(th) * d[2], d[1], -math.sin(th) * d[0] + math.cos(th) * d[2]])
                wo = 2 * (wi @ h) * h - wi
                vals[i, j, k] = float(truth.evaluate(wi, wo)) if wi[2] > 0 and wo[2] > 0 else -1.0
    out = np.asarray(dims, "<i4").tobytes()
    for s in scale:
        out += np.where(vals >= 0, vals / s, -1.0).astype("<f8").tobytes()
    return out


def test_merl_reads_back_the_analytic_brdf(tmp_path):
    (tmp_path / "m.binary").write_bytes(_merl_bytes((9, 9, 18), TRUTH))
    for channel in ("R", "B", "mean"):
        s = read_merl(tmp_path / "m.binary", channel)
        assert 0 < len(s) < 9 * 9 * 18  # the cells below the horizon are dropped
        np.testing.assert_allclose(s.brdf_per_sr, TRUTH.evaluate(s.wi, s.wo), rtol=1e-9)
    assert len(read_samples(tmp_path / "m.binary")) == len(s)
    (tmp_path / "short.binary").write_bytes(_merl_bytes((9, 9, 18), TRUTH)[:-8])
    with pytest.raises(ValueError, match=r"not a MERL file of the size its header gives .* the file has 34996\)$"):
        read_merl(tmp_path / "short.binary")
