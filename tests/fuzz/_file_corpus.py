"""Valid input files and their content mutants, for tests/fuzz/test_fuzz_files.py.

A *base* is a folder of valid files (a scene or study TOML and the data files it names)
plus the CLI verbs that apply to it. A *case* is (base, file, mutation, seed): the named
file's CONTENTS are mutated with a seeded RNG and the verbs run on the folder in-process
through ``hazard.cli.main``. :func:`run_case` classifies the outcome; anything but
"accepted with finite results" or "exit 2 with one line naming the file" is a defect.

Text mutations put ``SECRET`` into the file where they put a string, so an error that
quotes file contents is caught.
"""

from __future__ import annotations

import importlib.util
import io
import json
import math
import random
import re
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from hazard.cli import main
from tests._scene_text import PLATE_AT_50M
from tests.fuzz.test_fuzz_scenes import _end_box, _non_finite, _time_box, _Timeout

SECRET = "zq9SECRETzq9"
CASE_SECONDS = 120  # the issue's hang limit, per verb

BASE = PLATE_AT_50M + '[[observers]]\nname = "east"\npoints_m = [[10.0, -17.0, 1.0], [-5.0, -30.0, 1.0]]\n'
MATERIAL = 'material = { model = "lambertian", reflectance = 0.5 }'


@dataclass(frozen=True)
class Base:
    files: dict  # file name -> bytes (the first is the TOML the verbs read)
    verbs: tuple  # CLI verbs run on it besides validate
    targets: tuple  # the file names a mutation may hit


# -- valid files ---------------------------------------------------------------------
def _lambertian_rows(n, rng, degrees):
    """(theta_i, phi_i, theta_r, phi_r, brdf) rows of a reflectance-0.5 Lambertian."""
    rows = []
    for _ in range(n):
        a = [rng.uniform(0, 1.3), rng.uniform(-3.1, 3.1), rng.uniform(0, 1.4), rng.uniform(-3.1, 3.1)]
        a = [math.degrees(x) for x in a] if degrees else a
        rows.append([round(x, 6) for x in a] + [0.5 / math.pi])
    return rows


def _bsdf_text():
    from tests.fuzz.test_input_trust import _bsdf

    return _bsdf(aoi="10 30", value="0.16")


def _astm_text(rng):
    rows = _lambertian_rows(60, rng, degrees=False)
    return (f"# ASTM E1392\nNUM_POINTS {len(rows)}\nVARS theta_i,phi_i,theta_s,phi_s,brdf\n"
            + "".join(",".join(map(repr, r)) + "\n" for r in rows))


def _csv_text(rng):
    rows = _lambertian_rows(60, rng, degrees=True)
    return "theta_i_deg,phi_i_deg,theta_r_deg,phi_r_deg,brdf_per_sr\n" + "".join(",".join(map(repr, r)) + "\n" for r in rows)


def _material_json(tmp: Path) -> bytes:
    import brdfmodels

    brdfmodels.save(brdfmodels.Lambertian(0.5), tmp / "m.json")
    return (tmp / "m.json").read_bytes()


def _with_material(material):
    return BASE.replace(MATERIAL, material)


HISTORY = ('\n[targets.history]\nkind = "series"\nstate = "reflectance_factor"\nfile = "h.csv"\n'
           'extrapolation = "clamp"\n')
TRACK = ('[[observers]]\nname = "plane"\nkind = "track"\ntimes_s = [0.0, 5.0, 10.0]\n'
         'positions_m = [[-200.0, -20.0, 100.0], [0.0, -20.0, 100.0], [200.0, -20.0, 100.0]]\n')
UNCERTAINTY = ('[uncertainty]\ndraws = 64\nseed = 1\nsensitivity_draws = 8\npointing_sigma_rad = 0.0001\n'
               'brdf_scale_sigma = 0.3\nnormal_tilt_sigma_deg = 0.3\nobserver_position_sigma_m = 0.5\noperations = 500\n'
               '[uncertainty.visibility]\ndistribution = "lognormal"\nmedian_km = 15.0\nsigma = 0.4\n')
STUDY = ('name = "sweep"\nscene = "s.toml"\nseed = 1\n[sweep]\nkind = "grid"\n[[sweep.parameters]]\n'
         'path = "laser.power_w"\nvalues = [10.0, 100.0]\n')


def _dem_bases(tmp: Path) -> dict:
    """GeoTIFF and DTED DEM scenes (rasterio needed), and raster variants built by GDAL."""
    if importlib.util.find_spec("rasterio") is None or importlib.util.find_spec("pyproj") is None:
        return {}
    import rasterio
    from rasterio.transform import Affine

    from tests.scenes.test_dem_formats import SCENE as DTED_SCENE, _dted
    from tests.scenes.test_dem_trust import GT, SCENE as DEM_SCENE

    def tif(name, dtype="float32", count=1, shape=(200, 200), value=None, crs="EPSG:4326", **kw):
        h = np.full(shape, 1600.0) if value is None else np.full(shape, value)
        h = h + np.arange(shape[1])[None, :] * 0.1 if value is None else h
        with rasterio.open(tmp / name, "w", driver="GTiff", width=shape[1], height=shape[0], count=count, dtype=dtype,
                           crs=crs, transform=Affine.from_gdal(*GT[:5], GT[5] * 200 / shape[0]), **kw) as ds:
            for b in range(1, count + 1):
                ds.write(h.astype(dtype), b)
        return (tmp / name).read_bytes()

    scene = DEM_SCENE.replace("extent_m = 300.0", "extent_m = 200.0").encode()
    bases = {"geotiff": Base({"s.toml": scene.replace(b"FILE", b"dem.tif"), "dem.tif": tif("dem.tif")}, ("run",), ("dem.tif",))}
    _dted(tmp / "n32_w107.dt0")
    dted_scene = (DTED_SCENE.replace("extent_m = 3000.0", "extent_m = 1400.0").replace("resolution_m = 50.0", "resolution_m = 100.0")
                  .replace("[[32.5, -106.49], [32.52, -106.5], [32.48, -106.51]]", "[[32.5, -106.497], [32.503, -106.5]]"))
    bases["dted"] = Base({"s.toml": dted_scene.encode(), "n32_w107.dt0": (tmp / "n32_w107.dt0").read_bytes()}, ("run",),
                         ("n32_w107.dt0",))
    variants = {  # rasters GDAL writes that a DEM must not be
        "complex": dict(dtype="complex64"), "three_bands": dict(count=3), "int8": dict(dtype="int8", value=-100),
        "uint8_zero": dict(dtype="uint8", value=0), "all_nan": dict(dtype="float64", value=np.nan),
        "all_nodata": dict(value=-9999.0, nodata=-9999.0), "one_cell": dict(shape=(1, 1)), "two_cells": dict(shape=(1, 2)),
        "huge_value": dict(dtype="float64", value=1e308), "float_inf": dict(value=np.inf),
        "no_crs": dict(crs=None), "utm_crs": dict(crs="EPSG:32613"),
        "huge_declared": None,  # written below
    }
    for name, kw in variants.items():
        if name == "huge_declared":  # a few kB on disk, 1.6e11 bytes declared: never write the array
            with rasterio.open(tmp / "v.tif", "w", driver="GTiff", width=200_000, height=200_000, count=1, dtype="float32",
                               crs="EPSG:4326", transform=Affine.from_gdal(*GT), tiled=True, blockxsize=256, blockysize=256,
                               SPARSE_OK="TRUE") as ds:
                ds.write(np.full((1, 256, 256), 1600.0, dtype="float32"), window=((0, 256), (0, 256)))
            data = (tmp / "v.tif").read_bytes()
        else:
            data = tif("v.tif", **kw)
        bases[f"raster_{name}"] = Base({"s.toml": scene.replace(b"FILE", b"dem.tif"), "dem.tif": data}, ("run",), ())
    return bases


def build_bases(tmp: Path) -> dict:
    """Every base, its files as bytes (built once, in ``tmp``)."""
    rng = random.Random(7)
    bases = {
        "bsdf": Base({"s.toml": _with_material('material = { model = "table", file = "a.bsdf" }').encode(),
                      "a.bsdf": _bsdf_text().encode()}, ("run",), ("a.bsdf",)),
        "astm": Base({"s.toml": _with_material('material = { model = "table", file = "a.astm" }').encode(),
                      "a.astm": _astm_text(rng).encode()}, ("run",), ("a.astm",)),
        "brdf_csv": Base({"s.toml": _with_material('material = { model = "table", file = "t.csv" }').encode(),
                          "t.csv": _csv_text(rng).encode()}, ("run",), ("t.csv",)),
        "material_json": Base({"s.toml": _with_material('material = { file = "m.json" }').encode(), "m.json": _material_json(tmp)},
                              ("run",), ("m.json",)),
        "history_csv": Base({"s.toml": _with_material(MATERIAL + HISTORY).encode(),
                             "h.csv": b"time_s,reflectance_factor\n0,1\n4,0.8\n10,0.6\n"}, ("run",), ("h.csv",)),
        "track": Base({"s.toml": (BASE + TRACK).encode()}, ("run",), ("s.toml",)),
        "uncertainty": Base({"s.toml": (BASE + UNCERTAINTY).encode()}, ("risk",), ("s.toml",)),
        "study": Base({"study.toml": STUDY.encode(), "s.toml": BASE.encode()}, ("study",), ("study.toml", "s.toml")),
    }
    bases.update(_dem_bases(tmp))
    return bases


# -- content mutations ---------------------------------------------------------------
TEXT_MUTATIONS = ("truncate", "flip", "del_line", "dup_line", "del_col", "dup_col", "number", "string", "empty", "bom",
                  "utf16", "delim", "crlf", "garbage", "nul")
BINARY_MUTATIONS = ("truncate", "flip", "empty", "garbage", "zero_block", "ff_block", "as_is")
# the security review's cases (issue 30 item 1), as mutations of a named file: a GDAL VRT in a
# DEM's place that fetches a URL or reads another file's bytes as heights, the file a symlink to
# a credentials-like file outside the folder, or to a device. Refused, or read without quoting
SECURITY_MUTATIONS = ("vrt_url", "vrt_raw", "link_secret", "link_dev_zero")
SECRET_FILE = "".join(f"{SECRET},{i},0.5,{SECRET}\n" for i in range(64))  # rows a CSV reader might take
NUMBERS = ("nan", "inf", "-inf", "-0", "1e308", "-1e308", "1e-320", "-1", "0", "99999999999999999999", "4294967297",
           SECRET, '"' + SECRET + '"', "", "1e400", "0x10", "3.7")
_STR = re.compile(rb'"[^"\n]*"')
_NUM = re.compile(rb"(?<![\w.])[-+]?\d+(\.\d*)?([eE][-+]?\d+)?(?![\w.])")


def _lines(data):
    return data.split(b"\n")


def _split(line):
    for d in (b",", b"\t", b" "):
        if d in line:
            return d, line.split(d)
    return None, [line]


def _columns(data, rng, dup):
    lines = _lines(data)
    widths = [len(_split(ln)[1]) for ln in lines if _split(ln)[0] is not None]
    if not widths:
        return data
    j = rng.randrange(max(widths))  # a column some line has
    out = []
    for ln in lines:
        d, cells = _split(ln)
        if d is not None and j < len(cells):
            cells = cells[:j + 1] + cells[j:] if dup else cells[:j] + cells[j + 1:]
            ln = d.join(cells)
        out.append(ln)
    return b"\n".join(out)


def mutate(data: bytes, kind: str, rng: random.Random) -> bytes:
    """``data`` with one content mutation of ``kind`` (seeded by ``rng``)."""
    n = len(data)
    if kind == "truncate":
        return data[:rng.randrange(n)] if n else data
    if kind == "flip":
        b = bytearray(data)
        for _ in range(rng.randint(1, 8)):
            if b:
                b[rng.randrange(len(b))] ^= 1 << rng.randrange(8)
        return bytes(b)
    if kind in ("del_line", "dup_line"):
        lines = _lines(data)
        k = rng.randrange(len(lines))
        return b"\n".join(lines[:k] + ([lines[k]] * 2 if kind == "dup_line" else []) + lines[k + 1:])
    if kind in ("del_col", "dup_col"):
        return _columns(data, rng, kind == "dup_col")
    if kind == "number":
        hits = list(_NUM.finditer(data))
        if not hits:
            return data + SECRET.encode()
        m = rng.choice(hits)
        return data[:m.start()] + rng.choice(NUMBERS).encode() + data[m.end():]
    if kind == "string":  # a quoted string (a JSON key or value, a TOML string) or else a word
        hits = list(_STR.finditer(data)) or list(re.finditer(rb"[A-Za-z_]+", data))
        if not hits:
            return data + SECRET.encode()
        m = rng.choice(hits)
        return data[:m.start()] + (b'"' + SECRET.encode() + b'"' if data[m.start():m.start() + 1] == b'"' else SECRET.encode()) + data[m.end():]
    if kind == "empty":
        return b""
    if kind == "bom":
        return b"\xef\xbb\xbf" + data
    if kind == "utf16":
        return data.decode("latin-1").encode("utf-16")
    if kind == "delim":
        return data.replace(b",", rng.choice([b";", b"\t", b" ", b"|"]))
    if kind == "crlf":
        return data.replace(b"\n", b"\r\n")
    if kind == "garbage":
        return bytes(rng.randrange(256) for _ in range(rng.choice([1, 64, 4096])))
    if kind == "nul":
        k = rng.randrange(n + 1)
        return data[:k] + b"\0" + data[k:]
    if kind in ("zero_block", "ff_block"):
        k, m = rng.randrange(n), rng.randint(4, 512)
        return data[:k] + (b"\0" if kind == "zero_block" else b"\xff") * min(m, n - k) + data[k + m:]
    if kind == "as_is":
        return data
    raise ValueError(kind)


def _security(folder: Path, name: str, kind: str) -> None:
    """Put the security mutation ``kind`` in place of ``folder / name`` (a file outside the
    folder holds SECRET, as a credentials file would)."""
    from tests.scenes.test_dem_trust import _vrt_over_url, _vrt_raw

    secret = folder.parent / "outside" / "credentials.csv"
    secret.parent.mkdir(exist_ok=True)
    secret.write_text(SECRET_FILE)
    target = folder / name
    target.unlink(missing_ok=True)
    if kind == "vrt_url":  # port 9 (discard): nothing is fetched while GDAL's network is off
        target.write_text(_vrt_over_url(9))
    elif kind == "vrt_raw":
        target.write_text(_vrt_raw(secret))
    else:
        target.symlink_to(secret if kind == "link_secret" else Path("/dev/zero"))


def all_cases(bases: dict, seeds: int = 6) -> list:
    """(base, file, mutation, seed) for every base, mutable file, mutation and seed, and the
    security mutations once for each file they apply to."""
    cases = []
    for name, base in bases.items():
        if not base.targets:  # a raster variant as GDAL wrote it
            cases.append((name, "dem.tif", "as_is", 0))
        for f in base.targets:
            binary = f.endswith((".tif", ".dt0"))
            for kind in BINARY_MUTATIONS if binary else TEXT_MUTATIONS:
                if kind != "as_is":
                    cases.extend((name, f, kind, s) for s in range(seeds if kind not in ("empty", "bom", "utf16", "crlf") else 1))
            # a scene or study TOML is what the user names, and echoed by design: only the device
            security = SECURITY_MUTATIONS if binary else ("link_dev_zero",) if f.endswith(".toml") else SECURITY_MUTATIONS[2:]
            cases.extend((name, f, kind, 0) for kind in security)
    return cases


# -- running and classifying ---------------------------------------------------------
def _cli(argv):
    out, err = io.StringIO(), io.StringIO()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        old = _time_box(CASE_SECONDS)
        try:
            code = main([str(a) for a in argv], stdout=out, stderr=err)
        except _Timeout:
            code = "hang"
        except SystemExit as exc:  # argparse
            code = exc.code
        finally:
            _end_box(old)
    raw = [f"{w.category.__name__}: {w.message}" for w in caught
           if issubclass(w.category, (RuntimeWarning, UserWarning)) and "hazard" not in w.category.__module__]
    return code, out.getvalue(), err.getvalue(), raw


def _argv(verb, folder, main_file):
    out = folder / f"out_{verb}"
    return {"validate": ["validate", main_file],
            "run": ["run", main_file, "-o", out, "--quiet", "--force"],
            "risk": ["risk", main_file, "-o", out, "--serial", "--quiet", "--force"],
            "study": ["study", main_file, "-o", out, "--serial", "--quiet", "--force"]}[verb]


def run_case(bases, case, tmp: Path) -> str:
    """Run one case; returns "accepted" or "refused", or raises AssertionError naming the defect."""
    name, target, kind, seed = case
    base = bases[name]
    folder = tmp / f"{name}-{target}-{kind}-{seed}".replace("/", "_")
    folder.mkdir(parents=True, exist_ok=True)
    rng = random.Random(f"{name}/{target}/{kind}/{seed}")
    for f, data in base.files.items():
        if f == target and kind in SECURITY_MUTATIONS:
            _security(folder, f, kind)
        else:
            (folder / f).unlink(missing_ok=True)  # not through a link a former case left
            (folder / f).write_bytes(mutate(data, kind, rng) if f == target else data)
    main_file = folder / next(iter(base.files))
    label = f"{name}:{target}<-{kind}#{seed}"
    outcomes = {}
    for verb in ("validate", *base.verbs):
        code, out, err, raw = _cli(_argv(verb, folder, main_file))
        lines = [ln for ln in err.splitlines() if ln.strip() and not ln.startswith("hazard: warning:")]
        assert code != "hang", f"{label}: {verb} ran over {CASE_SECONDS} s"
        assert not raw, f"{label}: {verb}: raw warnings {raw[:3]}"
        assert "Traceback" not in err + out, f"{label}: {verb}: traceback {err[-300:]!r}"
        # data files are never quoted; a scene / study TOML field's bad value is echoed by design
        # next to the field's name ("model='x' is unknown", "(got 'x')"), and its name is printed
        shown = "" if target.endswith(".toml") else err + out
        assert SECRET not in shown, f"{label}: {verb}: quotes the file's contents: {err.strip()[:300]!r}"
        if code == 0:
            assert not lines, f"{label}: {verb}: exit 0 with stderr lines that are no warning: {lines[:2]!r}"
            outcomes[verb] = "accepted"
            for written in sorted((folder / f"out_{verb}").glob("*.json")):  # report.json, the study's and risk's
                bad = _non_finite(json.loads(written.read_text()))
                assert not bad, f"{label}: {verb}: non-finite numbers in {written.name} at {bad[:5]}"
            continue
        assert code == 2, f"{label}: {verb}: exit {code}: {err.strip()[-300:]!r}"
        assert len(lines) == 1, f"{label}: {verb}: {len(lines)} error lines: {err.strip()[:300]!r}"
        named = target if target != "dem.tif" or base.targets else "dem.tif"
        assert named in lines[0] or (kind == "as_is" and "terrain.file" in lines[0]), \
            f"{label}: {verb}: the error does not name {named}: {lines[0][:300]!r}"
        outcomes[verb] = "refused"
        break  # the next verb would refuse it too (tests/fuzz/test_validate_equals_run.py)
    return "refused" if "refused" in outcomes.values() else "accepted"
