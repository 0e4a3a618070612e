"""The report for the review board (hazard.outputs.review, `hazard report`, `hazard run --report`):
one self-contained HTML file with every section, its numbers as report.json holds them,
absent pieces said, clear errors; and (slow) the page in a real headless Chromium."""

from __future__ import annotations

import importlib.util
import io
import json
import os
import re
import shutil
import subprocess
from pathlib import Path

import markupsafe
import pytest

from hazard.outputs import review
from hazard.cli import main
from hazard.outputs.review import OBSERVERS_SHOWN, SECTIONS, fmt_distance, fmt_number, write_review
from tests._scene_text import PLATE_AT_50M

HAS_MPL = importlib.util.find_spec("matplotlib") is not None
NASTY = 'east <b>&amp;"'  # an observer name the page must escape

SCENE = PLATE_AT_50M + f"""
[[observers]]
name = "fan"
start_m = [-0.2, -0.2, 1.2]
end_m = [-4.0, -4.0, 1.2]
count = 60
[[observers]]
name = {json.dumps(NASTY)}
points_m = [[10.0, -17.0, 1.0]]
"""


def run(*argv):
    out, err = io.StringIO(), io.StringIO()
    code = main([str(a) for a in argv], stdout=out, stderr=err)
    return code, out.getvalue(), err.getvalue()


def esc(text: str) -> str:
    """``text`` as the page's autoescape writes it."""
    return str(markupsafe.escape(text))


def table(page: str, table_id: str) -> str:
    """The HTML of ``<table id=table_id>``."""
    m = re.search(rf'<table[^>]*id="{table_id}"[^>]*>(.*?)</table>', page, re.S)
    assert m, f"no table {table_id}"
    return m.group(1)


def body_rows(page: str, table_id: str) -> int:
    return table(page, table_id).split("<tbody>", 1)[1].count("<tr")


@pytest.fixture(scope="module")
def plate(tmp_path_factory):
    """`hazard run --report` (and --plot when matplotlib is there) on a 61-observer plate."""
    root = tmp_path_factory.mktemp("plate")
    (root / "scene.toml").write_text(SCENE)
    out = root / "out"
    code, stdout, err = run("run", root / "scene.toml", "-o", out, "--quiet", "--report", *(["--plot"] if HAS_MPL else []))
    assert code == 0, err
    return {"out": out, "stdout": stdout, "doc": json.loads((out / "report.json").read_text()),
            "html": (out / "report.html").read_text(encoding="utf-8")}


@pytest.fixture(scope="module")
def collimated(tmp_path_factory):
    """A collimated beam in clear air (infinite direct-beam NOHD), run without --plot."""
    root = tmp_path_factory.mktemp("collimated")
    (root / "scene.toml").write_text(PLATE_AT_50M.replace("divergence_rad = 0.001", "divergence_rad = 0.0"))
    out = root / "out"
    code, _, err = run("run", root / "scene.toml", "-o", out, "--quiet")
    assert code == 0, err
    return out


@pytest.fixture(scope="module")
def svc(tmp_path_factory):
    """steel_vs_copper: dynamic materials, a mirror beam, a changed verdict."""
    out = tmp_path_factory.mktemp("svc") / "out"
    code, _, err = run("run", "steel_vs_copper", "-o", out, "--quiet")
    assert code == 0, err
    write_review(out)
    return json.loads((out / "report.json").read_text()), (out / "report.html").read_text(encoding="utf-8")


def copy_out(src: Path, dst: Path, **changes) -> Path:
    """A copy of an output folder with report.json keys changed."""
    shutil.copytree(src, dst)
    if changes:
        doc = json.loads((dst / "report.json").read_text())
        doc.update(changes)
        (dst / "report.json").write_text(json.dumps(doc))
    return dst


def test_run_report_writes_one_self_contained_file(plate):
    page, out = plate["html"], plate["out"]
    assert f"wrote {out / 'report.html'}" in plate["stdout"]
    assert not [p for p in os.listdir(out) if p.endswith(".tmp")]  # written through a temporary, renamed
    assert "<script" not in page.lower() and "<link" not in page.lower() and "@import" not in page and "url(" not in page
    assert not re.search(r"https?://", page)
    assert all(v.startswith("data:image/") for v in re.findall(r'\bsrc="([^"]*)"', page))
    assert all(v.startswith("#") for v in re.findall(r'\bhref="([^"]*)"', page))


def test_every_section_heading(plate):
    for sid, title in SECTIONS.items():
        assert f'<section id="{sid}">' in plate["html"] and f">{esc(title)}</h2>" in plate["html"], title


def test_mpe_with_every_step(plate):
    page, m = plate["html"], plate["doc"]["mpe"]
    assert fmt_number(plate["doc"]["mpe_w_m2"], "W/m\u00b2", sig=6) == "50\u00a0W/m\u00b2"
    assert re.search(r'id="mpe-value"><strong>50\u00a0W/m\u00b2</strong>', page)
    assert f'id="mpe-standard">{m["standard_title"]} ({m["standard"]})' in page
    for key in ("table_row", "formula", "governing_limit"):
        assert esc(m[key]) in page, key
    for step in m["steps"]:
        assert esc(step) in page


def test_target_nohds_as_formatted(plate):
    page = plate["html"]
    for t in plate["doc"]["targets"]:
        row = [r for r in table(page, "targets-table").split("<tr>") if f">{esc(t['name'])}</a>" in r]
        assert len(row) == 1
        assert fmt_distance(t["nohd_static_m"]) in row[0] and fmt_distance(t["nohd_dynamic_m"]) in row[0]
    assert fmt_distance(0.5642) == "0.5642\u00a0m" and "0.5642\u00a0m" in page  # the plate's diffuse NOHD
    sdz = table(page, "sdz-table")
    assert fmt_distance(plate["doc"]["sdz"]["nohd_m"]) in sdz


def test_observers_worst_first_and_the_rest_counted(plate):
    page, doc = plate["html"], plate["doc"]
    n, hazardous = len(doc["observers"]), sum(o["hazardous"] for o in doc["observers"])
    assert n == 61 and 0 < hazardous < OBSERVERS_SHOWN
    assert body_rows(page, "observers-table") == OBSERVERS_SHOWN
    rest = n - OBSERVERS_SHOWN
    assert f"... and {rest} more observer point(s) not shown here (0 hazardous, {rest} below the MPE)" in page
    assert f"{hazardous} of {n} observer point(s) at or above the MPE" in page
    rows = table(page, "observers-table").split("<tbody>")[1].split("<tr>")[1:]
    worst = max(doc["observers"], key=lambda o: o["hazard_ratio"])
    assert f"<td>{esc(worst['name'])}</td>" in rows[0] and "HAZARD" in rows[0]
    assert all("HAZARD" in r for r in rows[:hazardous]) and "HAZARD" not in rows[hazardous].split("</td>")[2]


def test_text_is_escaped(plate):
    page = plate["html"]
    assert NASTY not in page and "<b>" not in page
    assert f"<td>{esc(NASTY)}</td>" in page  # the observer group's row of the scene summary


def test_scene_hash_and_versions(plate):
    page, doc = plate["html"], plate["doc"]
    assert f'id="scene-sha256">{doc["scene"]["sha256"]}<' in page
    assert doc["scene"]["sha256"] in table(page, "versions-table")
    for k, v in doc["versions"].items():
        assert f"<th scope=\"row\">{k}</th><td>{v}</td>" in page
    import hashlib

    assert hashlib.sha256((plate["out"] / "report.json").read_bytes()).hexdigest() in page  # the page names its source


def test_stages_run_and_skipped_with_reasons(plate):
    page, stages = plate["html"], plate["doc"]["stages"]
    assert body_rows(page, "stages-table") == len(stages)
    for s in stages:
        if not s["ran"]:
            assert f"<td><strong>skipped</strong></td><td>{esc(s['detail'])}</td>" in page


def test_assumptions_name_their_source(plate):
    rows = table(plate["html"], "assumptions-table")
    assert "extended_source.applied" in rows and "sdz.directions.kind" in rows and "never modelled" in rows


@pytest.mark.skipif(not HAS_MPL, reason="the pictures of --plot need matplotlib (pip install 'laser-hazard[render]')")
def test_plan_view_first_then_the_other_pictures(plate):
    names = re.findall(r'<img src="data:image/png;base64,[^"]*" alt="[^"]*" title="([^"]*)"', plate["html"])
    on_disk = sorted(p.name for p in plate["out"].glob("*.png"))
    assert names[0] == "plan.png" and names[1] == "elevation.png" and sorted(names) == on_disk
    assert "No 3-D renders: run hazard render" in plate["html"]  # absent, and said so


def test_absent_pictures_are_said_and_infinite_nohd_is_unbounded(collimated):
    write_review(collimated)
    page = (collimated / "report.html").read_text(encoding="utf-8")
    assert "No plan view: run with --plot" in page and "No time plots: run with --plot." in page
    assert "<img" not in page
    doc = json.loads((collimated / "report.json").read_text())
    assert doc["sdz"]["nohd_m"] == "inf" and fmt_distance("inf") == "unbounded"
    assert "<strong>unbounded</strong>" in table(page, "sdz-table") and "inf\u00a0m" not in page
    frame = doc.get("frame")
    assert (esc(frame["statement"]) in page) if frame else ("report.json states no coordinate frame" in page)


def test_map_outputs_of_the_run_are_listed(plate):
    maps, page = plate["doc"].get("map_outputs"), plate["html"]
    if maps is None:
        assert "report.json lists no map outputs" in page
        return
    names = maps.get("files", []) if isinstance(maps, dict) else maps
    for name in names:
        assert f'<td class="mono">{esc(name)}</td><td>yes</td>' in table(page, "map-outputs-table")
    for name, why in (maps.get("not_written") or {} if isinstance(maps, dict) else {}).items():
        assert esc(why) in table(page, "map-outputs-not-written") and f"map_outputs.not_written.{name}" in page


def test_frame_and_map_outputs_shown_generically(collimated, tmp_path):
    frame = {"kind": "site", "statement": "Site frame: x east, y north <local tangent plane>",
             "origin_deg_m": [52.123456789, 4.5, 12.0], "vertical": "EGM2008", "crs": "EPSG:4326", "refraction_k": 0.13}
    out = copy_out(collimated, tmp_path / "o", frame=frame, map_outputs=["danger_zone.geojson", "observers.csv"])
    write_review(out)
    page = (out / "report.html").read_text(encoding="utf-8")
    assert esc(frame["statement"]) in page
    for key in ("kind", "origin_deg_m", "vertical", "crs", "refraction_k"):
        assert f"frame.{key}" in page
    assert "52.12345679" in page and "EGM2008" in page and "EPSG:4326" in page and "0.13" in page
    maps = table(page, "map-outputs-table")
    assert "danger_zone.geojson</td><td>no" in maps and "observers.csv</td><td>yes" in maps


def test_partial_observer_list_and_stale_pictures_are_said(plate, tmp_path):
    which = "the 61 highest hazard ratios (every hazardous observer first); all 200000 are in observers.csv"
    out = copy_out(plate["out"], tmp_path / "o", observers_listed={"count": 200000, "listed": 61, "which": which})
    if HAS_MPL:
        old = (out / "report.json").stat().st_mtime - 3600
        os.utime(out / "plan.png", (old, old))
    write_review(out)
    page = (out / "report.html").read_text(encoding="utf-8")
    assert "report.json lists 61 of the 200000 observer points" in page and "observers_listed.which" in page
    assert ("plan.png</strong>" in page and "older than report.json" in page) or not HAS_MPL


def test_dynamic_targets_say_what_changed(svc):
    doc, page = svc
    copper = next(t for t in doc["targets"] if t["name"] == "copper")
    for key in ("nohd_static_m", "nohd_dynamic_m", "specular_nohd_static_m", "specular_nohd_dynamic_m"):
        assert fmt_distance(copper[key]) in table(page, "targets-table")
    assert f"diffuse NOHD {fmt_distance(copper['nohd_static_m'])} \u2192 {fmt_distance(copper['nohd_dynamic_m'])} +14.0\u00a0%" in page
    melt = next(t for t in doc["targets"] if t["name"] == "stainless")["melt"]["onset_s"]
    assert 3.4 < melt < 3.7 and f"melting from {fmt_number(melt, 's')}" in page  # stainless (3.524 s since issue 30's beam)
    # the rebuilt energy-conserving copper (issue 36) changes no observer's verdict here any more
    assert doc["verdict_changes"] == [] and "None: the dynamic material changes no observer's verdict." in page
    assert fmt_distance(doc["sdz"]["mirror_beams"][0]["nohd_m"]) in page


def test_changed_verdicts_are_listed_by_name(plate, tmp_path):
    out = copy_out(plate["out"], tmp_path / "o", verdict_changes=["arc-10m[32]", "road[4]"])
    write_review(out)
    page = (out / "report.html").read_text(encoding="utf-8")
    assert "2 observer point(s): arc-10m[32], road[4]." in page


def test_numbers_with_units_and_significant_figures():
    assert fmt_number(7958.845608, "m") == "7959\u00a0m"
    assert fmt_number(71264.96, "m") == "71\u202f265\u00a0m"
    assert fmt_number(0.000308345, "W") == "3.083\u00d710\u207b\u2074\u00a0W"
    assert fmt_number(None) == "none" and fmt_number("nan") == "undefined (NaN)" and fmt_number(True) == "yes"
    assert fmt_distance("inf") == "unbounded" and fmt_distance(None, none="no mirror beam") == "no mirror beam"


def test_missing_or_foreign_report_is_one_clear_line(tmp_path):
    with pytest.raises(ValueError, match=r"report\.json: missing; expected the report\.json that `hazard run"):
        write_review(tmp_path)
    code, out, err = run("report", tmp_path, "--quiet")
    assert code == 2 and out == "" and err.count("\n") == 1 and "Traceback" not in err
    assert err.startswith("hazard report: error: ") and "report.json: missing" in err
    (tmp_path / "report.json").write_text('{"format": "something-else"}')
    code, _, err = run("report", tmp_path, "--quiet")
    assert code == 2 and "format = 'something-else': expected 'laser-hazard.report'" in err
    code, _, err = run("report", tmp_path / "nope", "--quiet")
    assert code == 2 and "no such folder" in err and not (tmp_path / "nope").exists()


def test_cli_report_rewrites_the_same_page(plate, tmp_path):
    out = copy_out(plate["out"], tmp_path / "o")
    (out / "report.html").unlink()
    code, stdout, err = run("report", out, "--quiet")
    assert code == 0 and err == "" and stdout == f"wrote {out / 'map.html'}\nwrote {out / 'report.html'}\n"
    assert (out / "report.html").read_text(encoding="utf-8") == plate["html"]  # deterministic: same report, same page


def test_pdf_without_chromium_says_so_and_keeps_the_html(plate, tmp_path, monkeypatch):
    out = copy_out(plate["out"], tmp_path / "o")
    monkeypatch.setattr(review, "find_chromium", lambda: None)
    code, stdout, err = run("report", out, "--pdf", "--quiet")
    assert code == 1 and stdout == f"wrote {out / 'map.html'}\nwrote {out / 'report.html'}\n" and err.count("\n") == 1
    assert "PDF needs Chromium" in err and "the HTML was written" in err
    assert (out / "report.html").exists() and not (out / "report.pdf").exists()


# -- airspace and moving observers ---------------------------------------------------
@pytest.fixture(scope="module")
def airspace(tmp_path_factory):
    """The airspace example: a helicopter track, a slewing beam with firing windows, two
    flight zones the beam enters, a 532 nm laser (visual levels apply)."""
    out = tmp_path_factory.mktemp("airspace") / "out"
    code, _, err = run("run", "airspace", "-o", out, "--quiet", "--report", *(["--plot"] if HAS_MPL else []))
    assert code == 0, err
    return {"out": out, "doc": json.loads((out / "report.json").read_text()),
            "html": (out / "report.html").read_text(encoding="utf-8")}


def section(page: str, sid: str) -> str:
    m = re.search(rf'<section id="{sid}">(.*?)</section>', page, re.S)
    assert m, f"no section {sid}"
    return m.group(1)


def rows_of(page: str, table_id: str) -> list:
    return table(page, table_id).split("<tbody>", 1)[1].split("<tr>")[1:]


def test_airspace_tracks_zones_and_visual_distances(airspace):
    page, doc = airspace["html"], airspace["doc"]
    track = doc["tracks"][0]
    assert track["name"] == "helicopter" and not track["hazardous"] and track["first_exceedance_s"] is None
    (row,) = rows_of(page, "tracks-table")
    cells = row.split("</td>")
    assert cells[0].endswith(">helicopter") and cells[1] == '<td class="safe">below the MPE'  # the verdict first
    assert f">{fmt_number(track['exposure_ratio'])}<" in row and ">never<" in row and "SZED, CZED, LFED" in row
    assert fmt_number(track["peak_irradiance_w_m2"], "W/m\u00b2") in row and track["csv"] in row
    assert ("exposure_track_helicopter.png</a>" in row) == HAS_MPL
    zones = {z["name"]: z for z in doc["airspace"]["zones"]}
    assert zones["airfield LFZ"]["holds"] is False
    (lfz,) = [r for r in rows_of(page, "zones-table") if "<td>airfield LFZ</td>" in r]
    assert '<td class="hazard">EXCEEDED</td>' in lfz and "LFED 5\u00d710\u207b\u2074\u00a0W/m\u00b2" in lfz
    assert fmt_number(zones["airfield LFZ"]["worst_effective_irradiance_w_m2"], "W/m\u00b2") in lfz
    szed = doc["visual_interference"]["direct"]["szed_m"]
    assert fmt_distance(szed) == "4737\u00a0m"
    direct = [r for r in rows_of(page, "visual-table") if "direct beam" in r][0]
    assert direct.split("</td>")[3] == '<td class="num">4737\u00a0m'  # path, LFED, CZED, SZED
    assert "0 of 1 fixed observer(s) hazardous over time" in page and "<td>post</td>" in table(page, "fixed-over-time-table")
    assert esc(doc["motion"]["beam_state_step"]) in section(page, "airspace") and "motion.windows_s" in page
    verdict = section(page, "verdict")
    assert 'class="verdict bad"' in verdict and "0 of 1 moving observer(s) (tracks) at or above the MPE" in verdict
    assert "flight zone airfield LFZ (LFED): EXCEEDED" in verdict and "0 of 2 flight zone(s) hold their limit" in verdict
    if HAS_MPL:
        assert 'title="exposure_track_helicopter.png"' in section(page, "time")


def test_a_hazardous_track_and_a_broken_zone_make_the_verdict(airspace, tmp_path):
    doc = airspace["doc"]
    tracks = [dict(doc["tracks"][0], hazardous=True, first_exceedance_s=15.19, exposure_ratio=2.5)]
    zones = [dict(z, holds=True) for z in doc["airspace"]["zones"]]
    zones[1]["holds"] = False
    out = copy_out(airspace["out"], tmp_path / "o", tracks=tracks, airspace=dict(doc["airspace"], zones=zones),
                   any_hazard=False)  # a report whose any_hazard missed them: the page still counts them
    write_review(out)
    page = (out / "report.html").read_text(encoding="utf-8")
    verdict = section(page, "verdict")
    assert 'class="verdict bad"' in verdict and "No hazard found" not in verdict
    assert "1 of 1 moving observer(s) (tracks) at or above the MPE" in verdict
    assert "track helicopter: HAZARD, exposure ratio 2.5, first over the MPE at 15.19\u00a0s" in verdict
    assert "1 of 2 flight zone(s) hold their limit" in verdict and "flight zone range CFZ (CZED): EXCEEDED" in verdict
    assert "airfield LFZ" not in verdict and "report.json any_hazard = false" in verdict
    assert '<td class="hazard">HAZARD</td>' in rows_of(page, "tracks-table")[0]
    assert '<td>airfield LFZ</td><td class="safe">holds</td>' in table(page, "zones-table")


def test_no_motion_is_one_line_and_invisible_light_has_no_visual_levels(plate):
    page, doc = plate["html"], plate["doc"]
    assert doc["tracks"] == [] and doc["motion"] is None and doc["airspace"] is None
    part = section(page, "airspace")
    assert part.count("Nothing moves and no flight zones were given") == 1
    assert re.search(r'<p id="airspace-none">Nothing moves and no flight zones were given[^\n<]*</p>\n', part)
    for tid in ("tracks-table", "zones-table", "fixed-over-time-table"):
        assert f'id="{tid}"' not in page
    vi = doc["visual_interference"]
    assert not vi["applies"] and f"<strong>Not applicable</strong>: {esc(vi['reason'])}" in part
    direct = [r for r in rows_of(page, "visual-table") if "direct beam" in r][0]
    assert direct.count("not applicable") == 3 and fmt_distance(vi["direct"]["nohd_m"]) in direct
    assert "moving observer" not in section(page, "verdict")


def test_a_report_without_the_motion_keys_says_so(collimated, tmp_path):
    out = copy_out(collimated, tmp_path / "o")
    doc = json.loads((out / "report.json").read_text())
    for key in ("tracks", "motion", "visual_interference", "airspace"):
        doc.pop(key, None)
    (out / "report.json").write_text(json.dumps(doc))
    write_review(out)
    part = section((out / "report.html").read_text(encoding="utf-8"), "airspace")
    assert "report.json has no tracks, motion, visual_interference or airspace keys" in part and "<table" not in part


# -- the page in a real browser ------------------------------------------------------
CHROMIUM = "/usr/bin/chromium"  # Debian's; never `playwright install` (it downloads browsers)
BROWSER_ARGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
                "--disable-background-networking", "--disable-component-update", "--disable-sync"]
APT_TIMEOUT_S = 600


def _apt_install_chromium() -> str:
    """Try ``apt-get install -y chromium`` (then update and retry); '' on success, else why not."""
    if os.geteuid() != 0:
        return "not root, so apt-get cannot install it"
    if not shutil.which("apt-get"):
        return "no apt-get on this system"
    env = {**os.environ, "DEBIAN_FRONTEND": "noninteractive"}
    why = ""
    for cmd in (["apt-get", "install", "-y", "chromium"], ["apt-get", "update"], ["apt-get", "install", "-y", "chromium"]):
        if os.access(CHROMIUM, os.X_OK):
            return ""
        try:
            r = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=APT_TIMEOUT_S, check=False)
        except subprocess.TimeoutExpired:
            return f"`{' '.join(cmd)}` took over {APT_TIMEOUT_S} s"
        if r.returncode:
            why = f"`{' '.join(cmd)}` failed: {(r.stderr.strip().splitlines() or ['exit %d' % r.returncode])[-1]}"
    return "" if os.access(CHROMIUM, os.X_OK) else why or "apt-get ran but installed no /usr/bin/chromium"


@pytest.fixture(scope="session")
def os_chromium() -> str:
    """Debian's Chromium at /usr/bin/chromium, installed with apt-get when missing; the
    test is skipped (with apt's reason) only when apt cannot install it."""
    if not os.access(CHROMIUM, os.X_OK):
        why = _apt_install_chromium()
        if why:
            pytest.skip(f"needs Chromium at {CHROMIUM} (Debian: apt-get install chromium): {why}")
    return CHROMIUM


def _console_errors(page) -> list:
    errors = []
    page.on("pageerror", lambda e: errors.append(f"page error: {e}"))
    page.on("console", lambda m: errors.append(f"console {m.type}: {m.text}") if m.type in ("error", "warning") else None)
    return errors


def _not_blank(png: bytes, dark_fraction: float) -> None:
    """A screenshot with contrast (grey-level spread) and at least ``dark_fraction`` of its
    pixels dark (below half grey: text, lines), i.e. not one flat colour."""
    import numpy as np

    image = pytest.importorskip("PIL.Image", reason="counts the screenshot's pixels (Pillow comes with matplotlib)")
    grey = np.asarray(image.open(io.BytesIO(png)).convert("L"), float)
    assert grey.std() > 10.0 and (grey < 128).mean() > dark_fraction, (grey.std(), (grey < 128).mean())


def test_the_page_in_a_real_headless_chromium(plate, tmp_path, os_chromium):
    """The plate run's page (--report --plot, shared with the tests above) in Debian's
    Chromium: about 5 s on top of that run, so it runs by default."""
    sync_api = pytest.importorskip("playwright.sync_api", reason="needs playwright: pip install 'laser-hazard[test]' "
                                                                 "(it drives the OS's Chromium; never `playwright install`)")
    pytest.importorskip("matplotlib", reason="the plan view needs matplotlib (pip install 'laser-hazard[render]')")
    out = copy_out(plate["out"], tmp_path / "out")  # the PDF is written beside a copy
    doc = plate["doc"]
    with sync_api.sync_playwright() as p:
        # a fresh profile: Playwright takes --user-data-dir only through a persistent context
        browser = p.chromium.launch_persistent_context(str(tmp_path / "profile"), executable_path=os_chromium,
                                                       args=BROWSER_ARGS, headless=True, viewport={"width": 1280, "height": 900})
        try:
            page = browser.new_page()
            errors, requests = _console_errors(page), []
            page.on("request", lambda r: requests.append(r.url))
            page.goto((out / "report.html").resolve().as_uri(), wait_until="load")
            plan = page.locator('#plan img[title="plan.png"]')
            plan.scroll_into_view_if_needed()
            assert plan.is_visible() and plan.evaluate("img => img.complete && img.naturalWidth") > 0
            assert all(w > 0 for w in page.eval_on_selector_all("img", "imgs => imgs.map(i => i.naturalWidth)"))
            for tid, n in (("observers-table", min(OBSERVERS_SHOWN, len(doc["observers"]))),
                           ("targets-table", len(doc["targets"])), ("stages-table", len(doc["stages"]))):
                assert page.locator(f"#{tid}").is_visible()
                assert page.locator(f"#{tid} tbody tr").count() == n, tid
            assert page.locator("#mpe-value").inner_text() == "50\u00a0W/m\u00b2"
            shot = tmp_path / "report.png"
            page.screenshot(path=str(shot), full_page=True)
            plan_png = plan.screenshot()  # the plan view as the browser drew it
        finally:
            browser.close()
    assert errors == [] and shot.stat().st_size > 50_000
    _not_blank(shot.read_bytes(), dark_fraction=0.005)  # text on the page
    _not_blank(plan_png, dark_fraction=0.001)  # the picture drawn, not an empty frame
    assert all(u.startswith(("file:", "data:")) for u in requests), requests  # nothing fetched from outside
    pdf = write_review(out, pdf=True)[1]
    assert pdf.read_bytes()[:5] == b"%PDF-" and pdf.stat().st_size > 100_000
