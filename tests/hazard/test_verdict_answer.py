"""Issue 31, items 3 and 4: plausibility in the answer, an answer that cannot be misread.

The issue's scene, written here: a 20 W, 1064 nm beam (1/e diameter a = 20 mm, full-angle
divergence phi = 0.05 mrad) aimed 12 km north at a Lambertian plate, observers in the beam
500 m and 10 km from the laser. Its direct-beam NOHD is (sqrt(4P / (pi MPE)) - a) / phi =
13.9 km (ANSI eq. B; MPE 10 C_A C_C W/m^2 = 50 W/m^2 at 1064 nm for 10 s, C_A = 5). Each
slip of the issue's table (a divergence meant in mrad, typed in degrees, kW typed as W, a
20 m beam) must put its warning in the answer ABOVE the verdict, in report.json
``warnings`` and in the review page's verdict box; the right scene gets none.
"""

from __future__ import annotations

import html
import io
import json
import math
import re
from types import SimpleNamespace

import numpy as np
import pytest

import scenes
from hazard.cli import main
from hazard.outputs.report import cause_shares

P, LAM_M, A, PHI = 20.0, 1064e-9, 0.02, 5e-5
MPE = 10 * 5.0 * 1.0  # ANSI Z136.1-2014, 1064 nm, 10 s: 10 C_A C_C W/m^2 with C_A = 5, C_C = 1
R_T = 12_000.0  # laser -> plate [m], due north
APERTURE_M = 7e-3  # the limiting aperture at 1064 nm (ANSI Table 8): the direct beam is averaged over it
IN_BEAM = {"in-beam-500": 500.0, "in-beam-10km": 10_000.0}  # observers on the axis, range from the laser [m]


def scene_text(power=P, a=A, phi=PHI, observers=True, backstop=False, boundary_m=None) -> str:
    """The issue's scene; ``backstop``: a wall 5 m behind the plate; ``boundary_m``: a
    square [range] of that half-side about the laser."""
    out = ['name = "slip"', "[laser]", "wavelength_nm = 1064.0", f"power_w = {power!r}", f"beam_diameter_m = {a!r}",
           f"divergence_rad = {phi!r}", "position_m = [0.0, 0.0, 2.0]", f"aim_m = [0.0, {R_T!r}, 2.0]",
           "[exposure]", "duration_s = 10.0",
           "[[targets]]", 'name = "plate"', 'shape = "plate"', f"center_m = [0.0, {R_T!r}, 2.0]", "normal = [0.0, -1.0, 0.0]",
           "tangent = [1.0, 0.0, 0.0]", "size_m = [2.0, 2.0]", 'material = { model = "lambertian", reflectance = 0.5 }']
    if backstop:
        out += ["[[occluders]]", 'shape = "box"', f"center_m = [0.0, {R_T + 5.0!r}, 2.0]", "size_m = [60.0, 2.0, 60.0]"]
    if boundary_m is not None:
        b = boundary_m
        out += ["[range]", f"boundary_m = [[{-b!r}, {-b!r}], [{b!r}, {-b!r}], [{b!r}, {b!r}], [{-b!r}, {b!r}]]"]
    names = dict(IN_BEAM) if observers else {}
    for name, y in names.items():
        out += ["[[observers]]", f'name = "{name}"', f"points_m = [[0.0, {y!r}, 2.0]]"]
    out += ["[[observers]]", 'name = "side-500"', "points_m = [[100.0, 500.0, 2.0]]"]
    out += ["[analysis]", "direction_grid_deg = 10.0", "refine_levels = 0"]
    return "\n".join(out) + "\n"


def run_scene(tmp_path, text, *flags, name="s"):
    path = tmp_path / f"{name}.toml"
    path.write_text(text)
    out, err = io.StringIO(), io.StringIO()
    code = main(["run", str(path), "-o", str(tmp_path / name), "--quiet", *flags], stdout=out, stderr=err)
    return code, out.getvalue(), err.getvalue(), tmp_path / name


def headline_index(out: str) -> int:
    lines = out.splitlines()
    return next(i for i, line in enumerate(lines) if line.startswith("Scene 'slip': "))


def warned_above_the_verdict(out: str, *needles) -> list:
    """The answer's warning lines above the verdict line that hold every needle."""
    lines = out.splitlines()
    above = lines[:headline_index(out)]
    assert above and above[0].startswith("CHECK FIRST: ")
    return [w for w in above if w.startswith("  warning: ") and all(n in w for n in needles)]


def e_direct(R, a=A, phi=PHI, power=P):
    """The on-axis direct beam averaged over the 7 mm aperture: a Gaussian of 1/e radius
    w = (a + R phi) / 2 has (1 - exp(-x)) / x of its peak 4 P / (pi (a + R phi)^2) on a
    centred disk of radius r, x = (r / w)^2."""
    d = a + R * phi
    x = (APERTURE_M / d) ** 2  # (r / w)^2 with r = D / 2, w = d / 2
    return 4 * power / (math.pi * d * d) * (1 - math.exp(-x)) / x


def nohd_direct(power=P, a=A, phi=PHI):
    return max((math.sqrt(4 * power / (math.pi * MPE)) - a) / phi, 0.0)


# -- the right scene: the two columns, the shares, no warning --------------------------------
@pytest.fixture(scope="module")
def right(tmp_path_factory):
    return run_scene(tmp_path_factory.mktemp("right"), scene_text())


def table_rows(out):
    """(name, hazard ratio, from laser [m], from spot [m], spot, cause) per table row."""
    rows = []
    for line in out.splitlines():
        m = re.match(r"^  (\S+)\s+([0-9.e+-]+)\s+([0-9.e+-]+)\s+([0-9.e+-]+)  (\S+)\s+(.+)$", line)
        if m:
            rows.append((m[1], float(m[2]), float(m[3]), float(m[4]), m[5], m[6]))
    return rows


def test_the_right_scene_has_no_warning_and_two_labelled_distances(right):
    code, out, err, folder = right
    assert code == 0 and err == "" and "CHECK FIRST" not in out and "warning:" not in out
    assert nohd_direct() == pytest.approx(13_873.0, abs=1.0)  # the "true NOHD 13.9 km"
    lines = out.splitlines()
    assert lines[0].startswith("Scene 'slip': HAZARD at the observers") and "2 of 3 observer point(s) at or above the MPE" in lines[0]
    header = next(line for line in lines if line.lstrip().startswith("observer "))
    assert "from laser [m]" in header and "from spot [m]" in header and "nearest spot" in header
    rows = {r[0]: r for r in table_rows(out)}
    assert set(rows) == set(IN_BEAM)  # side-500 is 100 m off the axis: not hazardous, not listed
    for name, R in IN_BEAM.items():
        _, ratio, from_laser, from_spot, spot, cause = rows[name]
        assert ratio == pytest.approx(e_direct(R) / MPE, rel=1e-3)  # 4 significant digits printed
        assert from_laser == pytest.approx(R, abs=0.5) and from_spot == pytest.approx(R_T - R, abs=1.0) and spot == "plate"
        # the plate's diffuse light there is rho P / (pi (R_T - R)^2) ~ 1e-6 W/m^2: far under 1 %, not named
        assert cause == "direct beam 100 %, static"
    assert e_direct(10_000.0) / MPE == pytest.approx(1.88, abs=0.005)  # the 10 km observer: 1.88 x MPE
    doc = json.loads((folder / "report.json").read_text())
    assert doc["warnings"] == [] and doc["hazard_at_observers"] is True


# -- the slips of the table -------------------------------------------------------------
def _check_everywhere(tmp_path, text, needles_list, name):
    """Each needle set is a warning above the verdict, in report.json and in the review
    page's verdict box; returns the report."""
    code, out, err, folder = run_scene(tmp_path, text, name=name)
    assert code == 0
    doc = json.loads((folder / "report.json").read_text())
    rep_out, rep_err = io.StringIO(), io.StringIO()
    assert main(["report", str(folder)], stdout=rep_out, stderr=rep_err) == 0
    page = html.unescape((folder / "report.html").read_text())
    box = page[page.index('id="verdict"'):page.index('id="scene"')]
    for needles in needles_list:
        (w,) = warned_above_the_verdict(out, *needles)
        text_w = w[len("  warning: "):]
        assert text_w in doc["warnings"] and f"warning: {text_w}" in box
        assert box.index(text_w) < box.index(doc["verdict"]["headline"])  # above the headline on the page too
    return out, doc


def _nohd_said(out) -> float:
    return float(re.search(r"the direct beam's NOHD \(([0-9.e+-]+) m\)", out)[1])


def test_divergence_meant_as_mrad_warns_above_the_verdict(tmp_path):
    """divergence_rad = 0.05 meant as 0.05 mrad: 1000x too wide, NOHD 13.9 m; the 10 km
    observer reads 'safe'. The check started above 0.05 rad; now at 0.01 rad."""
    n = nohd_direct(phi=0.05)
    assert n == pytest.approx(13.87, abs=0.01)
    out, doc = _check_everywhere(tmp_path, scene_text(phi=0.05), [
        ("laser.divergence_rad = 0.05 rad (50 mrad) is a wide beam", "mrad meant?"),
        ("the direct beam's NOHD (", "m) is under 1/100 of the distance to the nearest lit spot (on 'plate') (12000 m away)",
         "divergence_rad")], "mrad")
    assert _nohd_said(out) == pytest.approx(n, rel=1e-3)
    assert doc["hazard_at_observers"] is False  # the slip's answer: still wrong, but said to be doubtful above it


@pytest.mark.parametrize("phi, warned", [(0.011, True), (0.0099, False)])
def test_the_wide_divergence_check_starts_at_10_mrad(phi, warned):
    sc = scenes.loads(scene_text(phi=phi))
    assert any("is a wide beam for a range laser" in w for w in sc.warnings) is warned


def test_divergence_typed_in_degrees_warns_by_the_beams_m2(tmp_path):
    """0.05 mrad written in degrees (0.002865) and read as rad: 57.3x too wide, NOHD 242 m.
    M^2 = pi D Theta / (4 lambda) with the 1/e^2 full quantities D = sqrt(2) a, Theta =
    sqrt(2) phi: 84.6 (the right beam's is 1.48)."""
    phi_deg = math.degrees(PHI)
    m2 = math.pi * (math.sqrt(2) * A) * (math.sqrt(2) * phi_deg) / (4 * LAM_M)
    assert m2 == pytest.approx(84.6, abs=0.1) and math.pi * 2 * A * PHI / (4 * LAM_M) == pytest.approx(1.476, abs=1e-3)
    assert nohd_direct(phi=phi_deg) == pytest.approx(242.1, abs=0.5)
    _check_everywhere(tmp_path, scene_text(phi=phi_deg), [(f"imply M^2 = pi d theta / (2 lambda) = {m2:.3g}", "degrees")], "deg")


def test_power_in_kw_typed_as_w_warns(tmp_path):
    """power_w = 0.02 (20 W written as 0.02 kW): a class 3B power (under 0.5 W), NOHD 51 m."""
    n = nohd_direct(power=0.02)
    assert n == pytest.approx(51.4, abs=0.1)
    out, _ = _check_everywhere(tmp_path, scene_text(power=0.02), [
        ("laser.power_w = 0.02 W is under 0.5 W", "class 3B", "kW typed as W"),
        ("the direct beam's NOHD (", "kW typed as W")], "kw")
    assert _nohd_said(out) == pytest.approx(n, rel=1e-3)


def test_a_20_m_beam_is_warned_on_stdout_not_only_stderr(tmp_path):
    """beam_diameter_m = 20, divergence 0.5: 4 P / (pi a^2) = 0.064 W/m^2 < MPE from the
    aperture on; it was a warning on stderr only and 'no observer point reaches the MPE'."""
    assert 4 * P / (math.pi * 20.0 ** 2) < MPE
    out, doc = _check_everywhere(tmp_path, scene_text(a=20.0, phi=0.5), [
        ("laser.beam_diameter_m = 20 m is over 1 m: mm meant?",), ("laser.divergence_rad = 0.5 rad", "mrad meant?"),
        ("the direct beam is below the MPE from its aperture on (NOHD 0 m)",)], "wide")
    assert doc["hazard_at_observers"] is False


@pytest.mark.parametrize("phi", [1.5e-5, 4e-5, 1.69e-3, 1.71e-3])
def test_m2_bounds(phi):
    """With a = 20 mm at 1064 nm, M^2 = 1 at phi = 2 lambda / (pi a) = 33.9 urad (narrower
    is impossible: diffraction) and 50 at 1.693 mrad (wider is warned as a slip)."""
    edge1, edge50 = 2 * LAM_M / (math.pi * A), 50 * 2 * LAM_M / (math.pi * A)
    assert edge1 == pytest.approx(3.387e-5, rel=1e-3) and edge50 == pytest.approx(1.6935e-3, rel=1e-3)
    m2 = math.pi * A * phi / (2 * LAM_M)
    warned = [w for w in scenes.loads(scene_text(phi=phi)).warnings if "imply M^2" in w]
    assert len(warned) == (m2 < 1 or m2 > 50)
    if warned:
        assert f"= {m2:.3g} (1/e quantities)" in warned[0]
        assert (("under 1, narrower than diffraction allows" in warned[0]) if m2 < 1 else ("above 50" in warned[0]))


def test_a_target_that_reflects_nothing_is_warned(tmp_path):
    text = scene_text().replace('{ model = "lambertian", reflectance = 0.5 }', '{ model = "lambertian", reflectance = 0.0 }')
    code, out, _, folder = run_scene(tmp_path, text, name="black")
    w = warned_above_the_verdict(out, "targets[0] (plate): the beam reaches it", "reflects nothing")
    assert code == 0 and len(w) == 1
    assert w[0][len("  warning: "):] in json.loads((folder / "report.json").read_text())["warnings"]


def test_a_spots_reflectance_is_integrated_once_per_run(tmp_path, monkeypatch):
    """report.json, the answer and the exit code each ask for the verdict: the lit spot's
    hemispherical reflectance (seconds for a measured table) is integrated once, and a
    material is never given another's value (a Lambertian's is its reflectance)."""
    import brdfmodels as bm
    import brdfmodels.analysis as bma
    from hazard.pipeline import plausibility

    calls = []
    real = bma.hemispherical_reflectance
    monkeypatch.setattr(bma, "hemispherical_reflectance", lambda *a, **k: calls.append(a[0]) or real(*a, **k))
    text = scene_text().replace('{ model = "lambertian", reflectance = 0.5 }', '{ model = "lambertian", reflectance = 0.0 }')
    code, out, _, _ = run_scene(tmp_path, text, name="black2")
    assert code == 0 and "reflects nothing" in out and len(calls) == 1
    up = np.eye(3)
    for rho in (0.0, 0.5, 0.25):  # the same incidence, another material each time
        sp = SimpleNamespace(mean_frame=up, mean_incoming=np.array([0.0, 0.0, -1.0]), material=bm.Lambertian(rho))
        assert plausibility._spot_reflectance(sp) == pytest.approx(rho, abs=1e-12)
        assert plausibility._spot_reflectance(sp) == pytest.approx(rho, abs=1e-12)  # remembered
    assert len(calls) == 4


# -- cause shares ---------------------------------------------------------------------------------
def _result(peak, direct, specular, at_aim=None):
    obs = SimpleNamespace(peak_irradiance_w_m2=np.array([peak]), direct_irradiance_w_m2=np.array([direct]),
                          specular_irradiance_w_m2=None if specular is None else np.array([specular]),
                          direct_at_aim_irradiance_w_m2=None if at_aim is None else np.array([at_aim]))
    return SimpleNamespace(observers=obs)


@pytest.mark.parametrize("peak, direct, spec, at_aim, expected", [
    (100.0, 60.0, 30.0, None, [("direct beam", 0.6), ("specular", 0.3), ("diffuse", 0.1)]),
    (100.0, 1e-15, 0.0, None, [("diffuse", 1.0)]),  # the "direct beam + diffuse" where direct was 1e-17
    (100.0, 0.5, 0.0, None, [("diffuse", 0.995)]),  # 0.5 % of the total: left out
    (100.0, 2.0, 0.0, None, [("diffuse", 0.98), ("direct beam", 0.02)]),
    (100.0, 0.0, None, None, [("reflection", 1.0)]),  # not split
    (10.0, 10.0, 0.0, 4.0, [("direct beam within its pointing error / sector / aim track", 1.0)]),
    (10.0, 0.0, 50.0, None, [("specular", 1.0)]),  # a mirror peak above the reflected total: capped at it
])
def test_cause_lists_contributions_above_1_percent_with_their_shares(peak, direct, spec, at_aim, expected):
    got = cause_shares(_result(peak, direct, spec, at_aim), 0)
    assert [n for n, _ in got] == [n for n, _ in expected]
    assert [f for _, f in got] == pytest.approx([f for _, f in expected], abs=1e-12)


# -- --fail-on-hazard: which kind of hazard fails --------------------------------------------
# observers: in-beam observers (hazardous); zones: the beam past the plate (a target is not
# a backstop) unless a wall stops it inside the 20 km range, and the plate's 0.25 m keep-out
# lobe (sqrt(rho P / (pi MPE))) inside it.
CASES = {"observers only": dict(backstop=True, boundary_m=20_000.0),
         "zones only": dict(observers=False, boundary_m=20_000.0),
         "neither": dict(observers=False, backstop=True, boundary_m=20_000.0)}
EXPECTED = {  # flag -> exit code per case
    "observers only": {None: 0, "": 3, "=observers": 3, "=zones": 0, "=any": 3},
    "zones only": {None: 0, "": 0, "=observers": 0, "=zones": 3, "=any": 3},
    "neither": {None: 0, "": 0, "=observers": 0, "=zones": 0, "=any": 0},
}


@pytest.mark.parametrize("case", list(CASES))
def test_fail_on_hazard_exit_codes(case, tmp_path, monkeypatch):
    """... and each run computes its verdict once (issue 35): report.json, the printed answer
    (or ``--json``, on the last run) and the exit code share it."""
    import hazard.outputs.report as report
    import hazard.pipeline.verdict as verdict_module

    calls = []
    real = verdict_module.verdict
    counting = lambda result: calls.append(result) or real(result)  # noqa: E731
    monkeypatch.setattr(verdict_module, "verdict", counting)  # the CLI's import
    monkeypatch.setattr(report, "verdict", counting)  # report.py's own name
    text = scene_text(**CASES[case])
    assert math.sqrt(0.5 * P / (math.pi * MPE)) < 0.26  # the lobe: well inside the range
    codes, per_run = {}, []
    for flag in EXPECTED[case]:
        flags = ["--force"] + ([] if flag is None else [f"--fail-on-hazard{flag}"]) + (["--json"] if flag == "=any" else [])
        calls.clear()
        codes[flag], out, _, folder = run_scene(tmp_path, text, *flags, name="f")
        per_run.append(len(calls))
    doc = json.loads((folder / "report.json").read_text())
    assert doc["hazard_at_observers"] is (case == "observers only") and doc["hazard_zones"] is (case == "zones only")
    assert codes == EXPECTED[case]
    assert per_run == [1] * len(EXPECTED[case])
    assert json.loads(out)["verdict"] == doc["verdict"]  # the last run's --json


def test_fail_on_hazard_refuses_an_unknown_choice(tmp_path):
    path = tmp_path / "s.toml"
    path.write_text(scene_text())
    err = io.StringIO()
    code = main(["run", str(path), "-o", str(tmp_path / "o"), "--fail-on-hazard=everything"], stdout=io.StringIO(), stderr=err)
    assert code == 2 and "invalid choice: 'everything'" in err.getvalue()


# -- one headline everywhere ---------------------------------------------------------------------
def _headline_everywhere(name, tmp_path):
    out, err = io.StringIO(), io.StringIO()
    code = main(["run", name, "-o", str(tmp_path / "o"), "--quiet", "--report"], stdout=out, stderr=err)
    assert code == 0, err.getvalue()
    doc = json.loads((tmp_path / "o" / "report.json").read_text())
    headline = doc["verdict"]["headline"]
    first = next(line for line in out.getvalue().splitlines() if line.startswith(f"Scene {name!r}: "))
    assert first == f"Scene {name!r}: {headline}."
    page = html.unescape((tmp_path / "o" / "report.html").read_text())
    head = re.search(r'<div class="head">\s*<span class="(\w+)">(.*?)</span>\.', page, re.S)
    assert head is not None and head[2] == headline
    _beam_line_agrees(out.getvalue().splitlines(), page)
    mp = re.search(r'<p id="headline" class="(\w*)">(.*?)</p>', html.unescape((tmp_path / "o" / "map.html").read_text()), re.S)
    assert mp is not None and mp[2] == headline and (mp[1] == "hazard") is headline.startswith("HAZARD")  # map.html too
    bad = doc["hazard_at_observers"] or doc["hazard_zones"]
    assert (head[1] == "hazard") is bad and headline.startswith("HAZARD") is bad
    assert doc["any_hazard"] is (doc["any_hazard"] or bad)  # any_hazard covers both
    return doc


FAST_EXAMPLES = ("plate", "binoculars", "mirror_window", "range_terrain", "risk")  # about 1-2 s each; the rest take 2-30 s


@pytest.mark.parametrize("name", [n if n in FAST_EXAMPLES else pytest.param(n, marks=pytest.mark.slow)
                                  for n in sorted(scenes.examples())])
def test_one_headline_on_stdout_report_json_and_the_review_page(name, tmp_path):
    doc = _headline_everywhere(name, tmp_path)
    if name == "range_geo":  # it said "no observer point reaches the MPE" on stdout and "HAZARD" on the page
        assert doc["hazard_at_observers"] is False and doc["hazard_zones"] is False and doc["any_hazard"] is True
        assert doc["verdict"]["headline"].startswith("No listed observer at or above its limit (0 of 29")


def _beam_line_agrees(answer_lines, page):
    """The beam convention line at the top of stdout's answer is in the review page's
    verdict box too (issue 31 item 2: said at the top of every answer)."""
    top = next(i for i, line in enumerate(answer_lines) if line.startswith("Scene "))  # below the warnings
    (beam,) = [line.strip() for line in answer_lines[top + 1:top + 3] if line.startswith("  beam: ")]
    box = page[page.index('id="verdict"'):page.index('id="scene"')]
    assert f'<p class="beam">{beam}</p>' in box


def test_the_beam_convention_heads_the_review_page_as_it_heads_stdout(tmp_path):
    """1/e^2 values converted: the same beam line on stdout and in the page's verdict box."""
    text = scene_text().replace("[exposure]", 'diameter_definition = "1/e2"\ndivergence_definition = "full_1/e2"\n[exposure]', 1)
    code, out, _, folder = run_scene(tmp_path, text, name="e2")
    assert code == 0 and main(["report", str(folder)], stdout=io.StringIO(), stderr=io.StringIO()) == 0
    page = html.unescape((folder / "report.html").read_text())
    _beam_line_agrees(out.splitlines(), page)
    assert "(both definitions given in the scene; the scene's values converted to it: see the notes)" in page


def _pages_agree(name, result, folder):
    """The headline of stdout's answer, report.json and report.html for one analysis,
    written by the functions ``hazard run --report`` calls (left out: the map files and
    map.html, whose headline the CLI test above checks, and the output folder's unit)."""
    from hazard.outputs.report import summary_text, write_set
    from hazard.outputs.review import write_review

    folder.mkdir()
    write_set(result, folder)
    write_review(folder)
    doc = json.loads((folder / "report.json").read_text())
    headline = doc["verdict"]["headline"]
    answer = summary_text(result).splitlines()
    assert answer[0] == f"Scene {name!r}: {headline}."
    page = html.unescape((folder / "report.html").read_text())
    head = re.search(r'<div class="head">\s*<span class="(\w+)">(.*?)</span>\.', page, re.S)
    assert head is not None and head[2] == headline
    _beam_line_agrees(answer, page)
    bad = doc["hazard_at_observers"] or doc["hazard_zones"]
    assert (head[1] == "hazard") is bad and headline.startswith("HAZARD") is bad
    return doc


@pytest.mark.parametrize("name", sorted(set(scenes.examples()) - set(FAST_EXAMPLES)))
def test_one_headline_everywhere_for_the_slower_examples_from_the_shared_analysis(name, tmp_path):
    """The fast equivalent of the test above for the examples it runs only under ``-m slow``
    (issue 31: every bundled example, by default): the session's one analysis of the
    example (tests/_bundled.py, shared with the modules that read it) written out as
    ``hazard run --report`` writes it."""
    from tests._bundled import bundled

    doc = _pages_agree(name, bundled(name), tmp_path / "o")
    if name == "range_geo":
        assert doc["hazard_at_observers"] is False and doc["hazard_zones"] is False and doc["any_hazard"] is True


def test_every_bundled_example_has_its_headline_checked_by_default():
    """Eleven bundled examples: the fast five by the CLI, the rest from the shared analysis."""
    names = set(scenes.examples())
    assert len(names) >= 11 and set(FAST_EXAMPLES) <= names


# -- properties on random input nobody tuned -----------------------------------------------------
from hypothesis import given, settings  # noqa: E402
from hypothesis import strategies as st  # noqa: E402

from hazard.pipeline.sdz import escaping_span_deg  # noqa: E402

FAST = settings(max_examples=25, derandomize=True, deadline=None, database=None)
SLOW = settings(max_examples=300, derandomize=True, deadline=None, database=None)


def _span_case(start, width, n, elevations):
    """n bearings spread over [start, start + width] (clockwise, mod 360) and the
    elevations: the span said must be [start, start + width] (the largest gap is the rest
    of the circle, 360 - width > width / (n - 1) when width < 180)."""
    b = np.radians((start + np.linspace(0.0, width, n)) % 360.0)
    e = np.radians(np.resize(np.asarray(elevations, float), n))
    dirs = np.stack([np.sin(b) * np.cos(e), np.cos(b) * np.cos(e), np.sin(e)], axis=1)
    (first, last), (lo, hi) = escaping_span_deg(dirs)
    assert first == pytest.approx(start % 360.0, abs=2e-3) or abs(first - start % 360.0) == pytest.approx(360.0, abs=2e-3)
    assert (last - first) % 360.0 == pytest.approx(width, abs=3e-3)
    assert lo == pytest.approx(min(np.resize(elevations, n)), abs=2e-3) and hi == pytest.approx(max(np.resize(elevations, n)), abs=2e-3)


@FAST
@given(start=st.floats(0.0, 720.0), width=st.floats(0.0, 170.0), n=st.integers(2, 40),
       elevations=st.lists(st.floats(-80.0, 80.0), min_size=1, max_size=5))
def test_the_escaping_span_holds_every_bearing_even_across_north(start, width, n, elevations):
    _span_case(start, width, n, elevations)


@pytest.mark.slow
@SLOW
@given(start=st.floats(0.0, 720.0), width=st.floats(0.0, 170.0), n=st.integers(2, 40),
       elevations=st.lists(st.floats(-80.0, 80.0), min_size=1, max_size=5))
def test_the_escaping_span_holds_every_bearing_even_across_north_slow(start, width, n, elevations):
    _span_case(start, width, n, elevations)


def _m2_case(a, phi, wl_nm):
    text = scene_text(a=a, phi=phi).replace("wavelength_nm = 1064.0", f"wavelength_nm = {wl_nm!r}")
    m2 = math.pi * (math.sqrt(2) * a) * (math.sqrt(2) * phi) / (4 * wl_nm * 1e-9)  # ISO 11146 with the 1/e^2 full quantities
    warned = [w for w in scenes.loads(text).warnings if "imply M^2" in w]
    if phi >= 0.01 or a > 1.0:  # the divergence or diameter warning names the slip already
        assert warned == []
    elif m2 < 1 or m2 > 50:
        assert len(warned) == 1 and f"= {m2:.3g} (1/e quantities)" in warned[0]
    elif not (0.999 < m2 < 1.001 or 49.95 < m2 < 50.05):  # the printed digits decide nothing at the edges
        assert warned == []


def _log(lo, hi):
    return st.floats(math.log(lo), math.log(hi)).map(math.exp)


@FAST
@given(a=_log(1e-3, 2.0), phi=_log(1e-6, 0.02), wl_nm=st.floats(400.0, 11_000.0))
def test_the_m2_warning_follows_the_formula(a, phi, wl_nm):
    _m2_case(a, phi, wl_nm)


@pytest.mark.slow
@SLOW
@given(a=_log(1e-3, 2.0), phi=_log(1e-6, 0.02), wl_nm=st.floats(400.0, 11_000.0))
def test_the_m2_warning_follows_the_formula_slow(a, phi, wl_nm):
    _m2_case(a, phi, wl_nm)


# -- a keep-out lobe against the range boundary ----------------------------------------------
@pytest.fixture(scope="module")
def plate_result():
    """The bundled plate: a 100 W beam centred on a Lambertian plate (rho 0.5) at the origin;
    its keep-out lobe is the disc of NOHD sqrt(rho P / (pi MPE)) = 0.5642 m about the spot."""
    import hazard

    return hazard.analyze(scenes.load(scenes.example_path("plate")))


def _lobe_case(plate_result, monkeypatch, edges):
    """A rectangular range [x0, x1] x [y0, y1] about the spot: the lobe is said to reach
    beyond it exactly when an edge is nearer than the NOHD (edges within 0.1 % of it are
    not judged: the spot's centroid is sampled)."""
    from shapely.geometry import box

    import hazard.pipeline.sdz as sdz
    from hazard.pipeline.verdict import zone_findings

    r = math.sqrt(0.5 * 100.0 / (math.pi * MPE))
    assert r == pytest.approx(0.5642, abs=1e-4)
    x0, x1, y0, y1 = -edges[0], edges[1], -edges[2], edges[3]
    monkeypatch.setattr(sdz, "boundary_polygon", lambda scene: box(x0, y0, x1, y1))
    said = [z for z in zone_findings(plate_result) if "keep-out lobe of 'plate'" in z]
    nearest = min(edges)
    if abs(nearest - r) > 1e-3 * r:
        assert len(said) == (nearest < r)
        if said:
            assert said[0] == f"the keep-out lobe of 'plate' (diffuse NOHD {r:.4g} m about its spot) reaches beyond the range boundary"


@pytest.mark.parametrize("edges", [(0.55, 5.0, 5.0, 5.0), (0.58, 5.0, 5.0, 5.0), (5.0, 5.0, 5.0, 0.5), (0.6, 0.6, 0.6, 0.6)])
def test_a_keep_out_lobe_beyond_the_range_is_a_zone_hazard(edges, plate_result, monkeypatch):
    _lobe_case(plate_result, monkeypatch, edges)


@FAST
@given(edges=st.tuples(*[st.floats(0.05, 3.0)] * 4))
def test_a_keep_out_lobe_beyond_the_range_property(edges, plate_result):
    with pytest.MonkeyPatch.context() as mp:
        _lobe_case(plate_result, mp, edges)


# -- a target past the zone's NOHD: the zone's text says it could not end the zone anyway --------
def test_a_target_beyond_the_nohd_is_said_to_be_beyond_it(right, tmp_path):
    """At 2 W the direct-beam NOHD is (sqrt(4 P / (pi MPE)) - a) / phi = 4.11 km, short of the
    plate at 12 km: the zone's finding names the plate with its range and 'beyond the NOHD'
    (it read as if the plate met the hazardous beam); at 20 W (NOHD 13.9 km) it does not."""
    power = 2.0
    assert nohd_direct(power) < R_T < nohd_direct()
    code, out, _, _ = run_scene(tmp_path, scene_text(power=power))
    assert code == 0
    zone = next(line for line in out.splitlines() if "danger zone (NOHD" in line and "NOT contained" in line)
    assert f"NOHD {nohd_direct(power):.4g} m" in zone
    assert "'plate' (" in zone and f"{R_T / 1e3:g} km from the laser: beyond the NOHD" in zone  # 12 km
    near = next(line for line in right[1].splitlines() if "danger zone (NOHD" in line and "NOT contained" in line)
    assert "'plate' (" in near and "beyond the NOHD" not in near
