"""The keep-out lobe: cells split only where the volume's error estimate asks, and a max
NOHD that does not depend on the grid."""

import copy
import math

import numpy as np
import pytest

import brdfmodels
import hazard
import scenes
from brdfmodels.fileio import read_toml
from hazard.physics import keepout, near_field_lobe

BACKSCATTER = {"model": "torrance-sparrow-5", "kb": 0.072, "kr": 16.125, "b": -29.917, "a": 0.959, "kd": 0.081}  # range_terrain's steel


@pytest.fixture(autouse=True)
def _point_form_lobes(monkeypatch):
    """These tests check the point-form lobe's grid, polish and volume against closed
    forms; the `plate` spot's lobe lies within its near field, where the lobe is the
    near-field integral's root (tested in tests/validation/test_near_field_lobes.py)."""
    monkeypatch.setattr(near_field_lobe, "ENABLED", False)


def _sharp(kr):
    """A five-parameter lobe about 2 kr rad wide with hemispherical reflectance < 1."""
    return {"model": "torrance-sparrow-5", "kb": 0.007 / kr**2, "kr": kr, "a": 1.0, "b": 0.0, "kd": 0.01}


def _spot(material, normal=(0.0, -1.0, 0.3)):
    """The `plate` scene's spot with another material on a plate tilted 17 deg."""
    path = scenes.example_path("plate")
    data = copy.deepcopy(read_toml(path))
    data["targets"][0].update(normal=list(normal), material=material)
    res = hazard.analyze(scenes.from_data(data, source="tilted plate", base_dir=path.parent))
    return res.spots[0], res.mpe_w_m2, res.attenuation_per_m


def test_polish_finds_a_peak_between_grid_points():
    peak = brdfmodels.spherical_to_vector(math.radians(33.3), math.radians(-71.7))
    fn = lambda w: 10.0 * np.exp(-np.sum((w - peak) ** 2, axis=-1) / 0.01**2)  # noqa: E731
    seeds = np.array([brdfmodels.spherical_to_vector(math.radians(33.0), math.radians(-72.0))])
    r, w, evals = keepout._polish_max(fn, seeds, math.radians(0.5))
    assert r == pytest.approx(10.0, rel=1e-12) and np.allclose(w, peak, atol=1e-6) and evals < 500


def test_off_specular_max_nohd_is_exact_at_any_depth():
    spot, mpe, mu = _spot(BACKSCATTER)
    lobes = [keepout.hazard_lobe(spot, mpe, mu, refine_levels=n) for n in (0, 3)]
    fn = keepout.nohd_range_fn(spot, mpe, mu, 1.0, None)
    wi = keepout.spot_directions(spot)
    best = lobes[0].max_range_m
    assert lobes[1].max_range_m == pytest.approx(best, rel=1e-12)
    assert best > fn(np.stack([wi * [-1, -1, 1], wi])).max() * (1 + 1e-6)  # the peak is off the mirror and retro directions
    # nothing on a fine patch around the maximum reaches further
    w0 = lobes[0].max_direction_local
    a = np.linspace(-0.01, 0.01, 201)
    e1 = np.cross(w0, [0.0, 0.0, 1.0])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(w0, e1)
    pts = w0 + a[:, None, None] * e1 + a[None, :, None] * e2
    pts /= np.linalg.norm(pts, axis=2, keepdims=True)
    assert fn(pts.reshape(-1, 3)).max() <= best * (1 + 1e-12)


def test_a_smooth_lobe_is_not_refined():
    spot, mpe, mu = _spot({"model": "lambertian", "reflectance": 0.5})
    base = keepout.hazard_lobe(spot, mpe, mu, refine_levels=0)
    deep = keepout.hazard_lobe(spot, mpe, mu, refine_levels=3)
    # only the cells holding the mirror and retro directions are split (two each: they lie
    # on the grid line phi = 90 deg), 3 more cells per split per level
    assert base.cells == 8100 and deep.cells <= 8100 + 4 * 3 * 3
    exact = 4 * math.pi / 15 * hazard.nohd_diffuse(spot.total_power_w, mpe, 0.5).nohd_m ** 3  # any tilt
    for lobe in (base, deep):
        assert abs(lobe.volume_m3 - exact) <= lobe.volume_error_m3 <= keepout.VOLUME_RTOL * exact


def test_a_lobe_sharper_than_the_grid_is_refined_around_it():
    spot, mpe, mu = _spot(_sharp(0.003))  # about 0.35 deg wide, on a 2 deg grid
    ref = keepout.hazard_lobe(spot, mpe, mu, refine_levels=6, rtol=1e-6)
    coarse = keepout.hazard_lobe(spot, mpe, mu, refine_levels=0)
    deep = keepout.hazard_lobe(spot, mpe, mu, refine_levels=3)
    err = lambda lb: abs(lb.volume_m3 - ref.volume_m3)  # noqa: E731
    assert err(coarse) > 1e-2 * ref.volume_m3 and coarse.volume_error_m3 >= err(coarse)  # the estimate flags it
    assert err(deep) < 1e-4 * ref.volume_m3 and deep.volume_error_m3 >= err(deep)
    assert deep.cells < 1.2 * coarse.cells  # refined where the lobe is, not everywhere
    assert deep.max_range_m == pytest.approx(ref.max_range_m, rel=1e-12)


def test_rtol_trades_the_estimate_for_cells():
    spot, mpe, mu = _spot(_sharp(0.01))
    loose, tight = (keepout.hazard_lobe(spot, mpe, mu, refine_levels=6, rtol=rt) for rt in (1e-2, 1e-4))
    assert tight.cells > loose.cells
    assert loose.volume_error_m3 <= 1e-2 * loose.volume_m3 and tight.volume_error_m3 <= 1e-4 * tight.volume_m3
    assert tight.volume_m3 == pytest.approx(loose.volume_m3, rel=1e-2)


def test_the_default_tolerance_is_read_when_called(monkeypatch):
    spot, mpe, mu = _spot(_sharp(0.01))
    monkeypatch.setattr(keepout, "VOLUME_RTOL", 1e-4)
    assert keepout.hazard_lobe(spot, mpe, mu).cells == keepout.hazard_lobe(spot, mpe, mu, rtol=1e-4).cells


def test_point_form_max_range_is_the_lobe_max_beyond_the_near_field(monkeypatch):
    # hazard.physics.visual takes the point-form lobe's largest range where it reaches the near field's
    # cap (near_field_lobe.near_field_reach_m): the near-field envelope stays within the cap, so the
    # lobe with the near field has the same largest range there
    from tests._bundled import bundled

    monkeypatch.setattr(near_field_lobe, "ENABLED", True)  # this module's default is the point form
    res = bundled("plate")
    sp = res.spots[0]
    reach = near_field_lobe.near_field_reach_m(sp)
    assert keepout.hazard_lobe(sp, res.mpe_w_m2, near_field=False, grid_deg=10.0, refine_levels=1).max_range_m < reach
    low = res.mpe_w_m2 / 1e4
    point = keepout.hazard_lobe(sp, low, near_field=False, grid_deg=10.0, refine_levels=1)
    full = keepout.hazard_lobe(sp, low, grid_deg=10.0, refine_levels=1)
    assert point.max_range_m >= reach and point.near_field is None
    assert full.near_field is not None, full.near_field
    assert full.max_range_m == pytest.approx(point.max_range_m, rel=1e-12)
