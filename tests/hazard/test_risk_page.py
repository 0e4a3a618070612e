"""The page of a risk analysis (hazard.outputs.risk_page: risk.html, probability_map.png) and the
"Probabilistic risk" section of the review page (`hazard report` after `hazard risk`)."""

from __future__ import annotations

import importlib.util
import io
import json
import re
import shutil

import markupsafe
import pytest

import scenes
from hazard.cli import main
from hazard.outputs import risk_page as risk_page_module
from hazard.drivers.risk import run_risk
from hazard.outputs.risk_page import HTML_NAME, PNG_NAME, ROWS_SHOWN, fmt_p, risk_page, statement_section, write_risk_page

HAS_MPL = importlib.util.find_spec("matplotlib") is not None
HOSTILE = "<script>x</script>"

SCENE = open(scenes.example_path("plate")).read() + f"""
[[observers]]
name = {json.dumps(HOSTILE)}
points_m = [[3.0, -10.0, 1.7]]

[uncertainty]
draws = 400
brdf_scale_sigma = 0.5
pointing_sigma_rad = 0.002
normal_tilt_sigma_deg = 2.0
observer_position_sigma_m = 0.5
operations = 1000
sensitivity_draws = 32
[uncertainty.visibility]
distribution = "lognormal"
median_km = 10.0
sigma = 0.3
[uncertainty.scintillation]
turbulence = "strong"
[uncertainty.map]
extent_m = [-20, 20, -40, 0]
spacing_m = 8.0
"""


def esc(text: str) -> str:
    return str(markupsafe.escape(text))


def cli(*argv) -> str:
    out, err = io.StringIO(), io.StringIO()
    code = main([str(a) for a in argv], stdout=out, stderr=err)
    assert code == 0, err.getvalue()
    return out.getvalue()


@pytest.fixture(scope="module")
def risk(tmp_path_factory):
    """run_risk on the plate with a map, then write_risk_page."""
    out = tmp_path_factory.mktemp("risk")
    scene = scenes.loads(SCENE, base_dir=scenes.example_path("plate").parent)
    doc = run_risk(scene, out, serial=True).doc
    path = write_risk_page(doc, out)
    return {"doc": doc, "out": out, "path": path, "html": path.read_text(encoding="utf-8")}


@pytest.fixture(scope="module")
def folder(tmp_path_factory):
    """`hazard run`, `hazard report` (no risk yet), `hazard risk`, risk.html, `hazard report` in one folder."""
    root = tmp_path_factory.mktemp("review")
    scene_path = root / "scene.toml"
    scene_path.write_text(SCENE)
    out = root / "out"
    cli("run", scene_path, "-o", out, "--quiet")
    cli("report", out, "--quiet")
    before = (out / "report.html").read_text(encoding="utf-8")
    cli("risk", scene_path, "-o", out, "--serial", "--quiet")
    write_risk_page(json.loads((out / "risk.json").read_text()), out)
    cli("report", out, "--quiet")
    return {"out": out, "before": before, "html": (out / "report.html").read_text(encoding="utf-8"),
            "risk": json.loads((out / "risk.json").read_text())}


def test_page_is_written_whole_and_self_contained(risk):
    assert risk["path"] == risk["out"] / HTML_NAME
    page = risk["html"]
    assert not [p for p in risk["out"].iterdir() if p.name.endswith(".tmp")]
    assert "<script>" not in page and "<link" not in page.lower() and not re.search(r"https?://", page)
    assert all(v.startswith("data:image/png;base64,") for v in re.findall(r'\bsrc="([^"]*)"', page))


def test_page_has_every_statement_input_and_note(risk):
    page, doc = risk["html"], risk["doc"]
    assert len(doc["observers"]) == 3
    for r in doc["observers"]:
        assert f'<td class="stmt">{esc(r["statement"])}</td>' in page, r["name"]
    for i in doc["inputs"]:
        assert esc(i["distribution"]) in page, i["name"]
    for n in doc["notes"] + doc["left_out"]:
        assert esc(n) in page
    assert esc(doc["criterion"]) in page and esc(doc["mpe"]) in page and doc["scene_sha256"] in page
    assert "3 observer point(s) in risk.csv" in page


def test_rows_worst_first_and_small_numbers_scientific(risk):
    page, doc = risk["html"], risk["doc"]
    rows = re.findall(r'<td class="stmt">(.*?)</td>', page)
    resolved = sorted([r for r in doc["observers"] if r["hits"] > 0],  # stable: ties keep risk.json's order
                      key=lambda r: (-r["probability_exceed"], -r["probability_ci_high"]))
    unresolved = sorted([r for r in doc["observers"] if r["hits"] == 0], key=lambda r: -r["probability_ci_high"])
    assert rows == [esc(r["statement"]) for r in resolved + unresolved]
    his = [0.5, 2e-3, 0.9, 1e-5] + [1e-4] * 250
    many = doc | {"observers": [doc["observers"][0] | {"name": f"o{k}", "probability_ci_high": h} for k, h in enumerate(his)]}
    st = statement_section(many)
    part = st["unresolved"] if doc["observers"][0]["hits"] == 0 else st["resolved"]  # equal estimates: by the upper bound
    assert [r["name"] for r in part["rows"][:3]] == ["o2", "o0", "o1"] and part["rows"][-1]["name"] != "o3"
    assert part["shown"] == ROWS_SHOWN == 200 and part["total"] == 254 and "54 more" in part["more"]
    assert "risk.csv" in part["more"]
    assert fmt_p(3.2e-3) == "3.20e-3" and fmt_p(3.2e-3, sig=2) == "3.2e-3" and fmt_p(0.0) == "0" and fmt_p(0.0903) == "0.0903"
    assert fmt_p(None) == "none" and fmt_p(1e-6, sig=1) == "1e-6"


def test_page_escapes_a_hostile_observer_name(risk):
    assert HOSTILE not in risk["html"]
    assert esc(HOSTILE) in risk["html"]


@pytest.mark.skipif(not HAS_MPL, reason="matplotlib not installed")
def test_map_picture_saved_and_embedded(risk):
    import matplotlib.image

    png = risk["out"] / PNG_NAME
    assert png.is_file() and f'title="{PNG_NAME}"' in risk["html"]
    img = matplotlib.image.imread(png)[..., :3]
    h, w = img.shape[:2]
    middle = img[int(0.35 * h):int(0.65 * h), int(0.25 * w):int(0.55 * w)]  # inside the axes (the colour bar is on the right)
    coloured = (middle < 0.95).any(axis=-1).mean()
    assert coloured > 0.8, coloured
    assert 'id="map-rule"' in risk["html"] and "95 % upper bound" in risk["html"]


def test_no_matplotlib_is_said(risk, tmp_path, monkeypatch):
    shutil.copy(risk["out"] / "probability_map.csv", tmp_path)
    monkeypatch.setattr(risk_page_module, "_have_matplotlib", lambda: False)
    page = risk_page(risk["doc"], tmp_path)
    assert "matplotlib is not installed" in page and not (tmp_path / PNG_NAME).exists()
    no_map = risk_page(risk["doc"] | {"map": None}, tmp_path)
    assert 'id="map-none"' in no_map


def test_review_page_has_the_risk_section(folder):
    page, doc = folder["html"], folder["risk"]
    assert '<section id="risk">' in page and ">Probabilistic risk</h2>" in page and 'href="#risk"' in page
    for r in doc["observers"]:
        assert esc(r["statement"]) in page
    for i in doc["inputs"]:
        assert esc(i["distribution"]) in page
    assert HOSTILE not in page and esc(HOSTILE) in page
    assert 'id="risk-scene-mismatch"' not in page
    if HAS_MPL:
        assert f'title="{PNG_NAME}"' in page.split('<section id="risk">', 1)[1].split("</section>", 1)[0]


def test_review_page_without_risk_json_has_no_section(folder, tmp_path):
    assert 'id="risk"' not in folder["before"] and "Probabilistic risk" not in folder["before"]
    out = tmp_path / "out"
    shutil.copytree(folder["out"], out)
    (out / "risk.json").unlink()
    cli("report", out, "--quiet")
    page = (out / "report.html").read_text(encoding="utf-8")
    assert 'id="risk"' not in page
    if HAS_MPL:  # the map picture left in the folder is still shown, with the other pictures
        assert f'title="{PNG_NAME}"' in page


def test_review_warns_of_another_scene_or_a_broken_risk_json(folder, tmp_path):
    out = tmp_path / "out"
    shutil.copytree(folder["out"], out)
    doc = folder["risk"] | {"scene_sha256": "0" * 64}
    (out / "risk.json").write_text(json.dumps(doc))
    cli("report", out, "--quiet")
    page = (out / "report.html").read_text(encoding="utf-8")
    assert 'id="risk-scene-mismatch"' in page and "DIFFERENT scene text" in page
    (out / "risk.json").write_text("{not json")
    cli("report", out, "--quiet")
    page = (out / "report.html").read_text(encoding="utf-8")
    assert 'id="risk-problem"' in page and "risk.json cannot be read" in page
    if HAS_MPL:  # the map picture is not lost with the unreadable risk.json
        assert f'title="{PNG_NAME}"' in page
