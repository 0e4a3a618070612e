"""Renders for real (off-screen): pixels, VTK arrays, animation, and the light import."""

import io
import subprocess
import sys

import numpy as np
import pytest

from hazard.cli import main
from tests._bundled import bundled
from tests.hazard.test_picture_print import printed_pt

pv = pytest.importorskip("pyvista")


@pytest.fixture(scope="module")
def mirror_result():
    return bundled("steel_vs_copper")


def _rgb(path):
    import imageio.v2 as imageio

    return np.asarray(imageio.imread(path))[..., :3].astype(int)


def test_keepout_render_shows_both_lobes(mirror_result, tmp_path):
    from hazard.pictures import render

    paths = render.keepout(mirror_result, tmp_path)
    r0, r1, c0, c1 = paths["layout"]["keepout"]["scene"]
    img = _rgb(paths["keepout"])[r0:r1, c0:c1]
    assert img.shape[:2] == (900, 1280)
    non_white = np.any(img < 235, axis=-1).mean()
    assert non_white > 0.05  # not a blank picture (colours per legend entry: tests/hazard/test_pictures.py)
    assert paths["overview"].stat().st_size > 10_000
    for name in ("keepout", "overview"):  # printed on a landscape A4 page: the smallest text at least 6 pt (issue 34 leftover d)
        width_px = _rgb(paths[name]).shape[1]
        assert printed_pt(paths["figures"][f"{name}.png"]["text_px_min"], width_px) >= 6.0, name
    with pytest.raises(FileExistsError):
        render.keepout(mirror_result, tmp_path)
    blocks = pv.read(paths["vtm"])
    names = list(blocks.keys())
    assert {"lobe_static_stainless", "lobe_dynamic_copper", "observers"} <= set(names)
    assert "nohd_m" in blocks["lobe_dynamic_copper"].array_names
    assert {"hazard_ratio", "peak_irradiance_w_m2"} <= set(blocks["observers"].array_names)
    lobe = blocks["lobe_static_stainless"]
    assert lobe["nohd_m"].max() == pytest.approx(mirror_result.targets[0].static_lobe.max_range_m, rel=0.05)


def test_lobe_animation(mirror_result, tmp_path):
    from hazard.pictures import render

    anim = render.animate_lobe(mirror_result, tmp_path, max_frames=4, window_size=(320, 240))
    assert len(anim["frames"]) == 4 and all(f.stat().st_size > 2000 for f in anim["frames"])
    assert anim["gif"].stat().st_size > 5000


def test_render_cli_and_static_scene(tmp_path):
    out, err = io.StringIO(), io.StringIO()
    code = main(["render", "range_terrain", "-o", str(tmp_path), "--quiet"], stdout=out, stderr=err)
    assert code == 0, err.getvalue()
    assert (tmp_path / "keepout.png").exists() and not (tmp_path / "lobe.gif").exists()  # static: no animation
    assert (tmp_path / "plan.png").stat().st_size > 20_000 and "plan.png" in out.getvalue()
    img = _rgb(tmp_path / "keepout.png")
    footprint = np.all(np.abs(img - np.array([165, 15, 21])) <= 40, axis=-1)  # hazard.pictures.palette.FOOTPRINT, shaded
    assert footprint.sum() > 1000  # the hazardous ground footprint is drawn


def test_import_hazard_does_not_load_pyvista():
    code = "import sys, hazard, scenes; hazard.analyze; print('pyvista' in sys.modules, 'matplotlib' in sys.modules, 'distributed' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False False False"


def test_framing_draws_far_points_on_a_log_scale_and_undraws_them():
    """Framing.draw: true within r0 of the centre, r0 (1 + ln(r / r0)) beyond (written here),
    along the same direction; undraw is its inverse; not compressed (r0 = inf): the identity."""
    from hazard.pictures.render import Framing

    rng = np.random.default_rng(7)
    c = np.array([10.0, -5.0, 2.0])
    p = c + rng.normal(size=(500, 3)) * 10 ** rng.uniform(-2, 5, size=(500, 1))
    f = Framing(np.zeros((3, 2)), c, 100.0)
    r = np.linalg.norm(p - c, axis=1)
    drawn = f.draw(p)
    want = np.where(r > 100.0, 100.0 * (1 + np.log(np.maximum(r, 100.0) / 100.0)), r)
    assert np.allclose(np.linalg.norm(drawn - c, axis=1), want, rtol=1e-12)
    assert np.allclose(f.undraw(drawn), p, rtol=1e-9, atol=1e-9)
    flat = Framing(np.zeros((3, 2)), c)
    assert np.array_equal(flat.draw(p), p) and np.array_equal(flat.undraw(p), p)
