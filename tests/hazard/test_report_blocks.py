"""The report blocks written by the stages' frozen result types (issue 35 item 1): on random
values nobody tuned for (finite or not, optional parts present or absent), each type's
``to_dict`` gives exactly the keys of the schema model generated from its fields, and the
block, as report.json writes it (:func:`hazard.outputs.report.json_safe`, then JSON), validates
strictly against that model."""

from __future__ import annotations

import dataclasses
import json

import pydantic
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from hazard.outputs.report import json_safe
from hazard.outputs.map_outputs import MapOutputs
from hazard.outputs.map_zones import ZONE_KINDS
from hazard.outputs.motion_outputs import MotionSection, TrackEntry
from hazard.outputs.report_schema import (AidedZone as AidedZoneBlock, AirspaceBlock, ExtendedSourceBlock, FrameBlock, LimitingAperture,
                                          MapOutputsBlock, MotionBlock, PathBlock, SamplingBlock, SdzBlock, SpillBlock, Uv24hBlock,
                                          VerdictBlock, VisualBlock)
from hazard.physics import aperture
from hazard.physics.mpe import RepetitivePulseResult, UV24hResult, uv_24h_mpe
from hazard.physics.visual import LevelDistances, TargetLevelDistances, VisualInterference
from hazard.pipeline.airspace import AirspaceCheck, FlightZoneCheck
from hazard.pipeline.extended_source import ExtendedMpe, ExtendedSourceSummary
from hazard.pipeline.motion_results import PathSummary, PathUv24h, WorstWindow
from hazard.pipeline.sdz import AidedZone, DangerZone, MirrorBeam, MirrorReach, NominalZone, SdzDirections
from hazard.pipeline.spill import AidedNohd, SpillSummary, StoppedSpill
from hazard.pipeline.spots import BeamSampling, NotReflected
from hazard.pipeline.verdict import Verdict, VerdictCounts
from scenes.dem import DemInfo
from scenes.geo_input import Conversion, FrameDescription
from scenes.motion import AimTrackDescription

FEW = settings(derandomize=True, deadline=None, max_examples=30)
MANY = settings(derandomize=True, deadline=None, max_examples=400)

num = st.floats(allow_nan=True, allow_infinity=True)  # a non-finite value is written as "inf"/"nan", never dropped
count = st.integers(min_value=0, max_value=10**9)
text = st.text(max_size=12)
maybe = st.none() | num


def _tuple(s, n=3):
    return st.lists(s, max_size=n).map(tuple)


verdicts = st.builds(Verdict, text, st.booleans(), st.booleans(), st.booleans(), _tuple(text),
                     st.builds(VerdictCounts, count, count, count, count, count, count), _tuple(text))
samplings = st.builds(BeamSampling, count, count, num, num, _tuple(text), _tuple(st.builds(NotReflected, text, text, num)), num,
                      maybe, maybe, maybe)
spills = st.builds(SpillSummary, num, num, num, _tuple(st.builds(StoppedSpill, text, num, num, num, num, num, text)), num,
                   _tuple(st.builds(AidedNohd, num, num, num, num, num)))
pulses = st.none() | st.builds(RepetitivePulseResult, num, text, _tuple(st.tuples(text, num)), num, num, num, _tuple(text))
at_alpha = st.none() | st.builds(ExtendedMpe, num, num, num, num, num, text, text, text, st.booleans(), _tuple(text), pulses)
extended = st.just(ExtendedSourceSummary(applied=False)) | st.builds(
    ExtendedSourceSummary, st.just(True), num, num, text, text, st.booleans(), count, count, at_alpha, at_alpha)
zone_checks = st.builds(FlightZoneCheck, text, text, maybe, num, num, st.booleans(), num, st.none() | st.tuples(num, num, num),
                        maybe, st.none() | text, num, num, count)
airspaces = st.builds(AirspaceCheck, _tuple(zone_checks), text, num, st.none() | text)
level_keys = st.sampled_from(["lfed", "czed", "szed"])
visuals = st.builds(VisualInterference, st.booleans(), num, num, text, st.booleans(), num,
                    st.dictionaries(level_keys, num), st.dictionaries(level_keys | st.just("nohd"), text), num, text,
                    st.none() | text, st.builds(LevelDistances, maybe, maybe, maybe, num),
                    st.dictionaries(text, st.builds(TargetLevelDistances, maybe, maybe, maybe, num, count), max_size=3), text)
apertures = st.builds(aperture.limiting_aperture, st.floats(180.0, 1e6), st.floats(1e-13, 3e4))  # the whole table's domain
flag = st.booleans()
span = st.none() | st.tuples(num, num)
polygon = _tuple(st.tuples(num, num), 4)
zone_fields = dict(nohd_m=num, polygon_m=polygon, area_m2=num, unbounded=flag, max_range_m=num, hazard_half_width_m=num,
                   contained=flag, escaping_directions=count, above_horizon=flag, escaping_bearing_deg=span,
                   escaping_elevation_deg=span, leaves_boundary=st.none() | flag, outside_boundary_m2=maybe)
reach_fields = dict(nohd_m=num, max_reach_m=num, contained=flag, above_horizon=flag, leaves_boundary=st.none() | flag)
aided_zones = st.builds(AidedZone, aid=st.builds(AidedNohd, num, num, num, num, num), **zone_fields)
mirror_beams = st.builds(MirrorBeam, target=text, rays=count, aided=st.none() | st.builds(MirrorReach, **reach_fields), **reach_fields)
danger_zones = st.builds(DangerZone, directions=st.builds(SdzDirections, text, flag, count, num, num, num, text, maybe, text),
                         nominal=st.none() | st.builds(NominalZone, polygon, num), aided=_tuple(aided_zones, 2),
                         mirror_beams=st.none() | _tuple(mirror_beams, 2), **zone_fields)

kinds = st.sampled_from(ZONE_KINDS)
map_outputs = st.builds(MapOutputs, _tuple(text), st.dictionaries(text, text, max_size=3), st.sampled_from(["local", "site"]),
                        st.dictionaries(kinds, count), st.dictionaries(kinds, text))
point = st.lists(num, min_size=2, max_size=3)
as_written = st.lists(st.integers(-90, 90) | num, min_size=2, max_size=3)  # as written: an int stays an int
conversions = st.builds(Conversion, text, as_written | st.lists(as_written, min_size=1, max_size=3), point | st.lists(point, min_size=1, max_size=3))
dems = st.builds(DemInfo, text, text, num, num, count, count, count, count, count, text)
frames = st.builds(FrameDescription, st.just("local"), text) | st.builds(
    FrameDescription, st.just("site"), text, st.tuples(num, num, num), num, text, text, num, num, st.tuples(num, num),
    st.none() | dems, _tuple(conversions))

pair, triple = st.tuples(num, num), st.tuples(num, num, num)
path_summaries = st.builds(
    PathSummary, text, st.sampled_from(["track", "fixed"]), num, num, triple, num, num, num, num, num,
    st.builds(WorstWindow, num, num, num, num), num, flag, st.none() | st.builds(PathUv24h, num, num, num, num, num, maybe, text),
    maybe, pair, count, num, num, flag, num, st.none() | pair, maybe)
track_entries = st.builds(TrackEntry, path_summaries, maybe, _tuple(st.sampled_from(["szed", "czed", "lfed"])), st.none() | text, text)
aim_tracks = st.none() | st.builds(AimTrackDescription, pair, count, maybe, maybe)
motion_sections = st.builds(MotionSection, pair, count, text, aim_tracks, st.none() | _tuple(pair), _tuple(text), num, flag, count,
                            _tuple(track_entries, 2), _tuple(text), num, text)

CASES = [(verdicts, VerdictBlock), (samplings, SamplingBlock), (spills, SpillBlock), (extended, ExtendedSourceBlock),
         (airspaces, AirspaceBlock), (visuals, VisualBlock), (apertures, LimitingAperture), (map_outputs, MapOutputsBlock),
         (frames, FrameBlock), (danger_zones, SdzBlock), (motion_sections, MotionBlock)]


def _written(block) -> dict:
    return json.loads(json.dumps(json_safe(block.to_dict())))


def _absent_ok(block, model) -> set:
    """The model's keys a block may leave out: the optional ones (written only in some cases)."""
    return {k for k, f in model.model_fields.items() if not f.is_required()}


def _check(block, model):
    doc = _written(block)
    assert set(doc) <= set(model.model_fields) and set(model.model_fields) - set(doc) <= _absent_ok(block, model)
    model.model_validate(doc, strict=True)
    fields = {f.name for f in dataclasses.fields(block)} - set(getattr(block, "NOT_IN_BLOCK", ()))
    assert set(model.model_fields) == fields  # the schema is the type's fields, nothing hand-written beside


@pytest.mark.parametrize("strategy, model", CASES, ids=[m.__name__ for _, m in CASES])
def test_every_block_validates_against_the_model_of_its_type(strategy, model):
    @FEW
    @given(strategy)
    def run(block):
        _check(block, model)

    run()


@pytest.mark.slow
@pytest.mark.parametrize("strategy, model", CASES, ids=[m.__name__ for _, m in CASES])
def test_every_block_validates_against_the_model_of_its_type_many(strategy, model):
    @MANY
    @given(strategy)
    def run(block):
        _check(block, model)

    run()


@FEW
@given(st.floats(180.0, 400.0), st.lists(st.floats(1e-9, 3e4), min_size=1, max_size=4), st.sampled_from(["ocular", "skin"]))
def test_the_uv_day_block_is_its_type_less_the_mpe_plus_what_it_writes_of_it(wavelength_nm, durations_s, kind):
    """``uv_24h``: UV24hResult's fields but ``mpe`` (of which it writes ``governing_limit`` and
    ``table_row``), with ``accumulation_s`` and ``unverified``."""
    doc = _written(uv_24h_mpe(wavelength_nm, durations_s, kind=kind))
    assert set(doc) == set(Uv24hBlock.model_fields)
    assert set(doc) - {"accumulation_s", "governing_limit", "table_row", "unverified"} == {f.name for f in dataclasses.fields(UV24hResult)} - {"mpe"}
    Uv24hBlock.model_validate(doc, strict=True)


def test_a_block_is_frozen_and_its_dict_a_copy():
    """Readers cannot change a stage's result: the dataclass is frozen and ``to_dict`` gives new lists."""
    z = FlightZoneCheck("z", "nohd", None, 0.0, 100.0, True, 0.0, None, None, None, 1.0, 10.0, 1)
    air = AirspaceCheck((z,), "m", 0.0)
    with pytest.raises(dataclasses.FrozenInstanceError):
        air.note = "changed"  # type: ignore[misc]
    air.to_dict()["zones"].clear()
    assert air.to_dict()["zones"] == [z.to_dict()] and "note" not in air.to_dict()


def test_the_map_outputs_are_read_only_and_their_dict_a_copy():
    """``map_outputs``: its mappings cannot be changed through the result, and ``to_dict``
    writes plain dicts in the order given (report.json's key order)."""
    counts = {k: i for i, k in enumerate(reversed(ZONE_KINDS))}
    m = MapOutputs(("zones.geojson",), {"zones.kml": "why"}, "local", counts, {"sdz": "none"})
    with pytest.raises(TypeError):
        m.features["sdz"] = 99  # type: ignore[index]
    d = m.to_dict()
    d["features"].clear()
    d["files"].append("x")
    assert m.to_dict() == {"files": ["zones.geojson"], "not_written": {"zones.kml": "why"}, "frame": "local", "features": counts,
                           "absent": {"sdz": "none"}}
    assert list(m.to_dict()) == ["files", "not_written", "frame", "features", "absent"]
    assert list(m.to_dict()["features"]) == list(reversed(ZONE_KINDS))
    with pytest.raises(pydantic.ValidationError):
        MapOutputsBlock.model_validate({**m.to_dict(), "frame": "geo"}, strict=True)  # only "local" or "site"
    with pytest.raises(pydantic.ValidationError):
        MapOutputsBlock.model_validate({**m.to_dict(), "absent": {"no_such_kind": "x"}}, strict=True)


def test_a_conversion_keeps_the_values_as_written():
    """``frame.converted[]``: the value as written (ints stay ints) and the metres, as lists again."""
    c = Conversion("laser.position_geo", [51, -1.5, 100], [[1.0, 2.0, 3.0]])
    assert c.given == (51, -1.5, 100) and c.m == ((1.0, 2.0, 3.0),)
    assert json.dumps(c.to_dict()) == '{"key": "laser.position_geo", "given": [51, -1.5, 100], "m": [[1.0, 2.0, 3.0]]}'
    local = FrameDescription("local", "words")
    assert local.to_dict() == {"kind": "local", "statement": "words"}
    with pytest.raises(pydantic.ValidationError):
        FrameBlock.model_validate({**local.to_dict(), "kind": "global"}, strict=True)


@FEW
@given(visuals)
def test_the_visual_block_is_written_in_its_fields_order_and_copied(vi):
    """``visual_interference``: ``to_dict`` writes the keys in the fields' order (report.json's
    order, ``reason`` absent when None), the targets' and ``direct``'s keys in theirs; the
    block is frozen and its dict a copy (a reader changing it leaves the stage's result)."""
    names = [f.name for f in dataclasses.fields(VisualInterference)]
    doc = vi.to_dict()
    assert list(doc) == [n for n in names if not (n == "reason" and vi.reason is None)]
    assert list(doc["direct"]) == ["lfed_m", "czed_m", "szed_m", "nohd_m"]
    assert all(list(t) == ["lfed_m", "czed_m", "szed_m", "nohd_m", "beam_states"] for t in doc["targets"].values())
    assert list(doc["targets"]) == list(vi.targets)
    doc["levels_w_m2"]["lfed"] = doc["levels"]["nohd"] = -1.0
    doc["targets"]["changed"] = {}
    assert vi.to_dict()["levels_w_m2"] == dict(vi.levels_w_m2) and "changed" not in vi.to_dict()["targets"]
    with pytest.raises(dataclasses.FrozenInstanceError):
        vi.direct.nohd_m = 0.0  # type: ignore[misc]
    for level in ("lfed", "czed", "szed", "nohd"):
        got, want = vi.direct.distance_m(level), doc["direct"][f"{level}_m"]
        assert got is want or got == want
    with pytest.raises(ValueError, match="level='sz'"):
        vi.direct.distance_m("sz")


@FEW
@given(aided_zones)
def test_an_aided_danger_zone_is_the_aids_keys_then_the_zones(zone):
    """``sdz.aided[]`` is written flat: :class:`AidedNohd`'s keys, then the zone's (its
    ``nohd_m`` the zone's); the schema model is both types' fields, nothing hand-written."""
    doc = _written(zone)
    aid = [f.name for f in dataclasses.fields(AidedNohd)]
    assert list(doc)[:len(aid)] == aid and doc["nohd_m"] == json.loads(json.dumps(json_safe(zone.nohd_m)))
    assert set(AidedZoneBlock.model_fields) == set(aid) | {f.name for f in dataclasses.fields(AidedZone)} - {"aid"}
    assert set(doc) <= set(AidedZoneBlock.model_fields)
    AidedZoneBlock.model_validate(doc, strict=True)


def test_the_mirror_beams_are_merged_into_a_copy_of_the_danger_zone():
    """The ``mirror_beams`` stage's beams join the ``sdz`` block by :func:`dataclasses.replace`: the
    sdz stage's own result keeps no ``mirror_beams`` key, the merged one writes them after ``aided``."""
    d = SdzDirections("aim", False, 1, 0.0, 0.0, 0.0, "bound", None, "")
    zone = DangerZone(directions=d, nohd_m=10.0, polygon_m=((0.0, 0.0), (1.0, 0.0), (0.0, 1.0)), area_m2=0.5, unbounded=False,
                      max_range_m=10.0, hazard_half_width_m=0.1, contained=True, escaping_directions=0, above_horizon=False)
    beam = MirrorBeam(target="m", rays=4, nohd_m=5.0, max_reach_m=5.0, contained=False, above_horizon=True)
    merged = dataclasses.replace(zone, mirror_beams=(beam,))
    assert "mirror_beams" not in zone.to_dict() and zone.mirror_beams is None
    assert list(merged.to_dict())[-2:] == ["aided", "mirror_beams"]
    assert merged.to_dict()["mirror_beams"] == [{"target": "m", "nohd_m": 5.0, "max_reach_m": 5.0, "rays": 4, "contained": False,
                                                 "above_horizon": True}]
    with pytest.raises(dataclasses.FrozenInstanceError):
        merged.nohd_m = 0.0  # type: ignore[misc]


#: The keys of a ``tracks[]`` entry in the order report.json wrote them before the types (issue 35): the
#: path's, then the entry's own (``pointing_*`` only for a track under a pointing buffer).
TRACK_KEYS = ["name", "kind", "peak_irradiance_w_m2", "peak_time_s", "worst_point_m", "peak_direct_w_m2", "peak_reflected_w_m2",
              "radiant_exposure_j_m2", "path_exposure_j_m2", "exposure_error_estimate_j_m2", "worst_window", "exposure_ratio",
              "hazardous", "uv_24h", "first_exceedance_s", "time_span_s", "samples", "base_step_s", "min_step_s", "adaptive",
              "lased_s", "pointing_bias_rad", "pointing_buffer_rad", "peak_effective_irradiance_w_m2", "visual_levels_reached",
              "csv", "group"]


@FEW
@given(track_entries)
def test_a_track_entry_is_the_paths_keys_then_its_own(entry):
    """``tracks[]`` and ``motion.fixed_observers[]`` are written flat, in the order report.json
    always had (:data:`TRACK_KEYS`; the pointing keys absent when None, ``uv_24h`` null); the
    schema model is both types' fields, nothing hand-written; the nested blocks in their fields' order."""
    doc = _written(entry)
    s = entry.summary
    absent = {k for k in ("pointing_bias_rad", "pointing_buffer_rad") if getattr(s, k) is None}
    assert list(doc) == [k for k in TRACK_KEYS if k not in absent]
    assert set(PathBlock.model_fields) == set(TRACK_KEYS)
    assert set(TRACK_KEYS) == {f.name for f in dataclasses.fields(PathSummary)} | {f.name for f in dataclasses.fields(TrackEntry)} - {"summary"}
    assert list(doc["worst_window"]) == ["duration_s", "exposure_j_m2", "mpe_radiant_exposure_j_m2", "ratio"]
    assert doc["uv_24h"] is None or list(doc["uv_24h"]) == ["dose_j_m2", "exposed_s", "limit_j_m2", "ratio", "window_end_s",
                                                            "first_exceedance_s", "label"]
    PathBlock.model_validate(doc, strict=True)


def test_a_track_entry_has_exactly_three_coordinates_and_two_times():
    """The fixed-length tuples of the types are lists of exactly that length in the schema."""
    s = PathSummary("t", "track", 1.0, 2.0, (0.0, 1.0, 2.0), 1.0, 0.0, 0.5, 0.6, 0.0, WorstWindow(0.25, 0.5, 1.0, 0.5), 0.5, False,
                    None, None, (0.0, 10.0), 11, 1.0, 1.0, True, 10.0)
    doc = TrackEntry(s, None, (), "track_t.csv", "g").to_dict()
    PathBlock.model_validate(doc, strict=True)
    for key, bad in (("worst_point_m", [0.0, 1.0]), ("time_span_s", [0.0, 1.0, 2.0]), ("pointing_bias_rad", [0.0])):
        with pytest.raises(pydantic.ValidationError):
            PathBlock.model_validate({**doc, key: bad}, strict=True)
    with pytest.raises(pydantic.ValidationError):
        PathBlock.model_validate({**doc, "hazardous": "no"}, strict=True)
    with pytest.raises(dataclasses.FrozenInstanceError):
        s.hazardous = True  # type: ignore[misc]
    d = s.to_dict()
    d["worst_point_m"].append(3.0)
    assert s.to_dict()["worst_point_m"] == [0.0, 1.0, 2.0]


@FEW
@given(st.builds(AimTrackDescription, pair, count, maybe, maybe))
def test_the_aim_track_leaves_out_the_rates_of_aim_points(aim):
    """``motion.aim_track``: the rates only for a schedule given by rates (absent, not null, otherwise)."""
    doc = _written(aim)
    assert list(doc)[:2] == ["times_s", "knots"]
    assert ("azimuth_rate_deg_s" in doc) == (aim.azimuth_rate_deg_s is not None)
    assert ("elevation_rate_deg_s" in doc) == (aim.elevation_rate_deg_s is not None)
