"""Issue 34 item 4: every number on the review page with its steps.

The test reads the steps from report.html alone (the numbers shown), redoes each formula
here with math and scipy's Lambert W (the formulas of ANSI Z136.1 eq. B and the point
source, written in this file), and gets the value report.json holds to 1e-6: the steps
are the real ones, not decoration. Also: the analysed exposure window of a static scene.
"""

from __future__ import annotations

import html
import io
import json
import math
import re

import pytest
from scipy.optimize import brentq
from scipy.special import lambertw

import scenes
from hazard.cli import main
from hazard.outputs.review_steps import analysed_times_text

NUM = r"([-+]?(?:\d+\.?\d*(?:e[-+]?\d+)?|inf))"

# 532 nm (the FAA levels apply), attenuation (the Lambert W forms), binoculars (an ENOHD)
GREEN = (open(scenes.example_path("plate")).read()
         .replace("wavelength_nm = 1064.0", "wavelength_nm = 532.0")
         .replace("power_w = 100.0", "power_w = 5.0")
         + """
[[observers]]
name = "far-binoculars"
points_m = [[2.0, -30.0, 0.0]]
optics = { magnification = 7.0, objective_diameter_m = 0.05, transmission = 0.9 }
[atmosphere]
visibility_km = 5.0
""")


def cli(*argv) -> str:
    out, err = io.StringIO(), io.StringIO()
    code = main([str(a) for a in argv], stdout=out, stderr=err)
    assert code == 0, err.getvalue()
    return out.getvalue()


def _run(root, text, *report_args):
    scene = root / "scene.toml"
    scene.write_text(text)
    out = root / "out"
    cli("run", scene, "-o", out, "--quiet")
    cli("report", out, "--quiet", *report_args)
    page = (out / "report.html").read_text(encoding="utf-8")
    return json.loads((out / "report.json").read_text()), page


def _blocks(page: str) -> dict:
    """The steps section as {block id: (title, [lines], [report.json lines])}, text only."""
    sec = page.split('<section id="steps">', 1)[1].split("</section>", 1)[0]
    out = {}
    for bid, body in re.findall(r'<div class="steps" id="([^"]+)">(.*?)</div>', sec, re.S):
        title = html.unescape(re.search(r"<h4>(.*?)</h4>", body, re.S).group(1))
        lines = [html.unescape(x) for x in re.findall(r"<li>(.*?)</li>", body, re.S)]
        checks = [html.unescape(x) for x in re.findall(r'<p class="[^"]*">(.*?)</p>', body, re.S)]
        out[bid] = (title, lines, checks)
    return out


def _get(text: str, name: str) -> float:
    m = re.search(rf"(?:^|[ (,]){re.escape(name)} = {NUM}", text, re.M)
    assert m, (name, text)
    return float(m.group(1))


def _direct_range(p, limit, a, phi, mu, k):
    """ANSI Z136.1 eq. B: 4 K P exp(-mu R) / (pi (a + R phi)^2) = limit, solved for R."""
    d0 = math.sqrt(4 * k * p / (math.pi * limit))
    if d0 <= a:
        return 0.0
    if mu == 0:
        return (d0 - a) / phi
    z = mu * d0 / (2 * phi) * math.exp(mu * a / (2 * phi))
    return (2 * phi / mu * float(lambertw(z).real) - a) / phi


def _point_range(i, mpe, mu):
    """I exp(-mu R) / R^2 = MPE, solved for R."""
    r0 = math.sqrt(i / mpe)
    return r0 if mu == 0 else 2 / mu * float(lambertw(mu * r0 / 2).real)


def _reported(checks, key_part) -> float:
    line = next(c for c in checks if key_part in c)
    return float(re.search(rf"= {NUM}", line).group(1))


def _check_block(title, lines, checks, doc):
    text = "\n".join(lines)
    if title.startswith(("Direct-beam", "Spilled beam", "FAA")):
        if title.startswith("FAA"):
            m = re.search(rf"^E_lim / VCF = {NUM} / {NUM} = {NUM} W/m", text, re.M)
            limit = float(m.group(1)) / float(m.group(2))
            assert limit == pytest.approx(float(m.group(3)), rel=1e-9)
        else:
            limit = _get(text, "MPE")
        r = _direct_range(_get(text, "P"), limit, _get(text, "a"), _get(text, "phi"), _get(text, "mu"), _get(text, "K"))
        shown = _reported(checks, "report.json")
        return r, shown
    if "half-width" in title:  # max of (d / 2) sqrt(2 ln(D0 / d)): d* = D0 exp(-1/2), or the nearer end of the zone
        m = re.search(rf"^d\* = {NUM} \* exp\(-1/2\) = {NUM} m, at R\* = .* = {NUM} m \(the zone is drawn to {NUM} m\)", text, re.M)
        d0, d_star, r_star, length = (float(x) for x in m.groups())
        assert d_star == pytest.approx(d0 * math.exp(-0.5), rel=1e-9)
        m = re.search(rf"h = \({NUM} / 2\) \* sqrt\(2 ln\({NUM} / {NUM}\)\) = {NUM} m", text)
        d, d0b, d_b = float(m.group(1)), float(m.group(2)), float(m.group(3))
        assert d0b == d0 and d_b == d and (d == d_star or not 0 <= r_star <= length)
        return d / 2 * math.sqrt(2 * math.log(d0 / d)) * (1 + 1e-6), _reported(checks, "report.json")
    if "reflected lobe" in title:  # through an aid (ENOHD) K I in place of I
        k = _get(text, "K") if "ENOHD" in title else 1.0
        r = _point_range(k * _get(text, "I"), _get(text, "MPE"), _get(text, "mu"))
        return r, _reported(checks, "report.json")
    if "mirror beam NOHD" in title:
        return _mirror_range(_get(text, "rho"), _get(text, "E_peak"), _get(text, "v_t"), _get(text, "v_s"), _get(text, "MPE"),
                             _get(text, "mu")), _reported(checks, "report.json")
    raise AssertionError(title)


def _mirror_range(rho, e_peak, vt, vs, mpe, mu):
    """rho E_peak exp(-mu D) / ((1 + D v_t)(1 + D v_s)) = MPE, solved for D: the closed form for
    v_t = v_s (no attenuation: D = (sqrt(rho E / MPE) - 1) / v), else scipy's brentq."""
    if rho * e_peak < mpe:
        return 0.0
    if vt == vs and mu == 0:
        return (math.sqrt(rho * e_peak / mpe) - 1) / vt
    f = lambda d: math.log(rho * e_peak / mpe) - mu * d - math.log1p(d * vt) - math.log1p(d * vs)  # noqa: E731
    return brentq(f, 0.0, 1e12, xtol=1e-9, rtol=1e-13)


def _json_value(doc, checks):
    """The value report.json holds under the key the block names (not the page's copy)."""
    key = re.search(r"report\.json (\S+) =", checks[0]).group(1)
    if key.startswith("targets["):
        name, rest = re.match(r"targets\[(.*?)\]\.(.*)", key).groups()
        node = next(t for t in doc["targets"] if t["name"] == name)
    else:
        node, rest = doc, key
    for part in rest.split("."):
        m = re.match(r"(\w+)\[(\d+)\]$", part)
        node = node[m.group(1)][int(m.group(2))] if m else node[part]
    return float(node)


def _verify(doc, page):
    blocks = _blocks(page)
    done = 0
    for bid, (title, lines, checks) in blocks.items():
        if bid.startswith("steps-observer"):
            continue
        if any(line.startswith("no closed-form step") for line in lines):
            continue
        r, _ = _check_block(title, lines, checks, doc)
        assert r == pytest.approx(_json_value(doc, checks), rel=1e-6), (title, lines)
        done += 1
    return blocks, done


def _verify_observers(doc, blocks):
    rows = {r["name"]: r for r in doc["observers"]}
    seen = []
    for bid, (title, lines, _checks) in blocks.items():
        if not bid.startswith("steps-observer"):
            continue
        name = title.removeprefix("observer ")
        r = rows[name]
        text = "\n".join(lines)
        m = re.search(rf"E = E_direct \+ E_reflected = {NUM} \+ {NUM} = ", text)
        e = float(m.group(1)) + float(m.group(2))
        assert e == pytest.approx(r["peak_irradiance_w_m2"], rel=1e-6, abs=1e-300)
        m = re.search(rf"hazard ratio = E / MPE = {NUM} / {NUM} = ", text)
        assert float(m.group(1)) / float(m.group(2)) == pytest.approx(r["hazard_ratio"], rel=1e-6, abs=1e-300)
        m = re.search(rf"H = E t = {NUM} \* {NUM} = ", text)
        assert float(m.group(1)) * float(m.group(2)) == pytest.approx(r["radiant_exposure_j_m2"], rel=1e-6, abs=1e-300)
        seen.append(name)
    return seen


@pytest.fixture(scope="module")
def green(tmp_path_factory):
    return _run(tmp_path_factory.mktemp("green"), GREEN, "--observer", "west-behind-box", "--observer", "nobody")


def test_every_distance_redone_from_the_page(green):
    doc, page = green
    assert doc["attenuation_per_m"] > 0 and doc["visual_interference"]["direct"]["lfed_m"] is not None
    blocks, done = _verify(doc, page)
    titles = [b[0] for b in blocks.values()]
    assert any(t.startswith("Direct-beam NOHD") for t in titles)
    assert any(t.startswith("Direct-beam ENOHD through optics") for t in titles)  # the binoculars
    assert sum(t.startswith("FAA") for t in titles) == 3
    assert any("reflected lobe NOHD (static)" in t for t in titles)
    assert any("reflected lobe ENOHD through 7x50 optics (static)" in t for t in titles)  # the plate's lobe through binoculars
    assert done >= 7 and not any("half-width" in t for t in titles)  # with attenuation: a numerical search, no step
    assert not re.search(r"DIFFERS", page)


def test_observer_irradiance_redone_from_the_page(green):
    doc, page = green
    seen = _verify_observers(doc, _blocks(page))
    assert set(seen) == {r["name"] for r in doc["observers"]}  # three listed: all within the top ten
    assert 'id="steps-missing"' in page and "nobody" in page.split('id="steps-missing"', 1)[1][:300]


def test_plate_steps_and_the_analysed_window(tmp_path):
    doc, page = _run(tmp_path, open(scenes.example_path("plate")).read())
    blocks, done = _verify(doc, page)
    assert done == 3  # the LSDZ NOHD and its half-width (mu = 0: closed forms) and the Lambertian plate's lobe
    assert _verify_observers(doc, blocks)
    # the misreading: "Analysed times: 0 s to 0 s" for a 10 s exposure
    said = html.unescape(re.search(r'<p id="analysed-times">(.*?)</p>', page, re.S).group(1))
    assert "0 s to 10 s" in said and "do not change" in said and "0 s to 0 s" not in said


def test_analysed_window_of_a_time_run():
    doc = {"times_s": {"start": 0.0, "end": 30.0, "count": 301}, "mpe": {"duration_s": 10.0}}
    assert analysed_times_text(doc) == ("Analysed times: 0 s to 30 s (301 time steps, a span of 30 s); exposure duration "
                                        "10 s: the worst window of that duration within them.")
    doc["times_s"]["end"] = 5.0
    assert "the exposure integrated over the whole span" in analysed_times_text(doc)


def test_a_moving_observer_takes_its_worst_window():
    """A track's hazard ratio is its worst window's exposure, raised by the integral's
    relative error estimate, over that window's MPE (hazard.pipeline.motion_stage)."""
    from hazard.outputs.review_steps import steps_section

    h_w, err, path, limit = 0.1926532025278637, 2.155667067793576e-06, 0.2898293597913221, 0.5241469051493551
    ratio = h_w * (1 + err / path) / limit
    row = {"name": "heli", "peak_irradiance_w_m2": 24.9, "direct_irradiance_w_m2": 24.8, "reflected_irradiance_w_m2": 0.1,
           "mpe_w_m2": 25.4, "hazard_ratio": ratio, "radiant_exposure_j_m2": 0.29}
    track = {"name": "heli", "kind": "track", "exposure_error_estimate_j_m2": err, "path_exposure_j_m2": path,
             "worst_window": {"duration_s": 0.009, "exposure_j_m2": h_w, "mpe_radiant_exposure_j_m2": limit, "ratio": ratio}}
    doc = {"observers": [row], "tracks": [track], "times_s": {"start": 0.0, "end": 0.0, "count": 1}, "mpe": {"duration_s": 0.25},
           "motion": {"time_span_s": [0.0, 60.0]}}
    (b,) = steps_section(doc)["observers"]
    text = "\n".join(b["lines"])
    m = re.search(rf"= {NUM} \* \(1 \+ {NUM} / {NUM}\) / {NUM} = {NUM}$", text, re.M)
    a, e, p, lim, shown = (float(x) for x in m.groups())
    assert a * (1 + e / p) / lim == pytest.approx(ratio, rel=1e-6) and shown == pytest.approx(ratio, rel=1e-9)
    assert "H = E t" not in text  # a track's exposure is not E times the duration
    assert all(c["agrees"] for c in b["checks"])
    said = analysed_times_text(doc)
    assert "0 s to 0.25 s" in said and "from 0 s to 60 s" in said


def test_named_observers_beyond_the_top_ten_are_added():
    from hazard.outputs.review_steps import steps_section

    rows = [{"name": f"o{k}", "peak_irradiance_w_m2": float(k), "direct_irradiance_w_m2": 0.0, "reflected_irradiance_w_m2": float(k),
             "mpe_w_m2": 50.0, "hazard_ratio": k / 50.0, "radiant_exposure_j_m2": 10.0 * k} for k in range(30)]
    doc = {"observers": rows, "times_s": {"start": 0.0, "end": 0.0, "count": 1}, "mpe": {"duration_s": 10.0}}
    st = steps_section(doc, ["o3", "o29", "ghost"])
    titles = [b["title"] for b in st["observers"]]
    assert titles == [f"observer o{k}" for k in range(29, 19, -1)] + ["observer o3"]  # the ten highest, then o3
    assert st["missing"] == ["ghost"]
    assert all(c["agrees"] for b in st["observers"] for c in b["checks"])


def test_mirror_beam_nohd_redone_from_the_page_and_the_optics(tmp_path):
    """mirror_window: the glass window's mirror beam NOHD with its steps (it said "no
    closed-form step"), redone from the page and from the scene's optics alone: Fresnel
    R_s of n = 1.5 at 30 deg (the laser's polarisation unknown: the larger of R_s, R_p),
    the beam's peak 4 P / (pi (a + r phi)^2) at r = 100 m, its virtual source a / phi
    behind the laser, and D = p (sqrt(rho E / MPE) - 1)."""
    doc, page = _run(tmp_path, open(scenes.example_path("mirror_window")).read())
    blocks, done = _verify(doc, page)
    (title, lines, checks), = [b for b in blocks.values() if "mirror beam NOHD" in b[0]]
    text = "\n".join(lines)
    ci = math.cos(math.radians(30.0))
    ct = math.sqrt(1 - (math.sin(math.radians(30.0)) / 1.5) ** 2)
    rs, rp = ((ci - 1.5 * ct) / (ci + 1.5 * ct)) ** 2, ((1.5 * ci - ct) / (1.5 * ci + ct)) ** 2
    e_peak = 4 * 1000.0 / (math.pi * (0.192 + 100.0 * 8e-5) ** 2)
    p = 100.0 + 0.192 / 8e-5
    # the hottest sample's ray leaves the axis by ~1e-5 rad (the virtual source 2.5 km back): R_s within 1e-4
    assert _get(text, "rho") == pytest.approx(max(rs, rp), rel=1e-4)
    assert _get(text, "E_peak") == pytest.approx(e_peak, rel=1e-9)
    assert _get(text, "v_t") == pytest.approx(1 / p, rel=1e-9) and _get(text, "v_s") == pytest.approx(1 / p, rel=1e-9)
    nohd = p * (math.sqrt(max(rs, rp) * e_peak / doc["mpe_w_m2"]) - 1)
    assert doc["targets"][0]["specular_nohd_static_m"] == pytest.approx(nohd, rel=1e-4)
    assert "DIFFERS" not in page and done >= 2


def test_mirror_steps_of_an_astigmatic_beam_and_of_the_aperture_cap():
    """The other forms, on numbers typed here: v_t != v_s (bisection on the page, brentq
    here) and the aperture power cap (D = ln(cap / MPE) / mu); a curved side says why it
    has no step."""
    from hazard.outputs.review_steps import mirror_steps

    st = {"governed_by": "sample", "reflectance": 0.9, "incident_peak_w_m2": 5e4, "vergence_t_per_m": 2e-3,
          "vergence_s_per_m": 5e-4, "aperture_cap_w_m2": 1e9}
    ref = _mirror_range(0.9, 5e4, 2e-3, 5e-4, 25.0, 1e-4)
    b = mirror_steps("m", st, 25.0, 1e-4, ref, "k")
    assert b["result_m"] == pytest.approx(ref, rel=1e-9) and b["check"]["agrees"]
    cap = {"governed_by": "aperture power cap", "aperture_cap_w_m2": 3e5}
    b = mirror_steps("m", cap, 25.0, 2e-4, math.log(3e5 / 25.0) / 2e-4, "k")
    assert b["result_m"] == pytest.approx(math.log(12000.0) / 2e-4, rel=1e-12) and b["check"]["agrees"]
    b = mirror_steps("m", {"governed_by": "curved side"}, 25.0, 0.0, 123.0, "k")
    assert b["result_m"] is None and b["lines"][0].startswith("no closed-form step: a curved side")
