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
    # an observer's height given twice, as a third number and as eye_height_m: the third was dropped silently
    # (issue 30 fuzz: points_geo [[32.608, -106.2905, 1.0]], 1 m above the ellipsoid, 1200 m under the ground,
    # stood at 1.7 m over it; a start_geo the same)
    ('points_geo = [[32.6080, -106.2905]]', 'points_geo = [[32.6080, -106.2905, 1.0]]',
     "observers[0].points_geo: three numbers [lat_deg, lon_deg, height_m] place the points by their height, and the "
     "group's eye_height_m would replace it"),
    # a range boundary's latitude typed 0 (issue 30 fuzz): one vertex 3400 km south, the range 3421 km across, analysed
    # silently, and every beam that leaves the real range "inside" it
    ('[[32.585, -106.325], [32.585, -106.275]', '[[0.0, -106.325], [32.585, -106.275]',
     "range.boundary_geo: the range spans 3421 km (point 0 = [0.0, -106.325] is the farthest from the others); expected at "
     "most 1000 km across"),
    ('start_geo = [32.6050, -106.3150]\nend_geo = [32.6050, -106.2850]',
     'start_geo = [32.6050, -106.3150, 1203.0]\nend_geo = [32.6050, -106.2850, 1203.0]', "observers[1].start_geo: three numbers"),
])
def test_geo_keys_that_cannot_be_meant_are_errors(old, new, says):
    with pytest.raises(scenes.SceneError) as exc:
        scenes.loads(_text(old, new), base_dir=scenes.example_path("range_geo").parent)
    assert says in str(exc.value)


def test_an_observer_height_given_twice_is_one_line_at_validate(tmp_path):
    """exit 2 and one stderr line naming the file and the key (``hazard validate`` and ``run`` share the check)."""
    import io

    from hazard.cli import main

    dem = scenes.example_path("range_geo").parent / "range_geo_dem.tif"
    text = _text('points_geo = [[32.6080, -106.2905]]', 'points_geo = [[32.6080, -106.2905, 1.0]]')
    (tmp_path / "s.toml").write_text(text.replace('file = "range_geo_dem.tif"', f'file = "{dem.as_posix()}"'))
    out, err = io.StringIO(), io.StringIO()
    assert main(["validate", str(tmp_path / "s.toml")], stdout=out, stderr=err) == 2
    lines = err.getvalue().strip().splitlines()
    assert len(lines) == 1 and "s.toml" in lines[0] and "observers[0].points_geo: three numbers" in lines[0], lines
