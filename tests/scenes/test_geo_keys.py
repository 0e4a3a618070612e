"""Geodetic keys that cannot be meant are errors naming the key (issue 14 item 1)."""

from __future__ import annotations

import pytest

pytest.importorskip("pyproj")
pytest.importorskip("rasterio")

import scenes  # noqa: E402


def _text(old, new):
    text = scenes.example_path("range_geo").read_text()
    assert old in text
    return text.replace(old, new)


@pytest.mark.parametrize("old,new,says", [
    # a height above the terrain beside a position that already has its height: it would be dropped silently
    ('center_geo = [32.6135, -106.2990]', 'center_geo = [32.6135, -106.2990, 1203.0]', "targets[0].height_agl_m: only with a two-number"),
    # an observer group standing on the terrain without an eye height
    ('points_geo = [[32.6080, -106.2905]]\neye_height_m = 1.7', 'points_geo = [[32.6080, -106.2905]]',
     "observers[0].points_geo: two numbers [lat_deg, lon_deg] stand on the terrain: give the group's eye_height_m"),
    ('origin = [32.60, -106.30, 1200.0]', 'origin = [95.0, -106.30, 1200.0]', "site.origin"),
])
def test_geo_keys_that_cannot_be_meant_are_errors(old, new, says):
    with pytest.raises(scenes.SceneError) as exc:
        scenes.loads(_text(old, new), base_dir=scenes.example_path("range_geo").parent)
    assert says in str(exc.value)
