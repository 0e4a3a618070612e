"""The report blocks written by the stages' frozen result types (issue 35 item 1): on random
values nobody tuned for (finite or not, optional parts present or absent), each type's
``to_dict`` gives exactly the keys of the schema model generated from its fields, and the
block, as report.json writes it (:func:`hazard.outputs.report.json_safe`, then JSON), validates
strictly against that model."""

from __future__ import annotations

import dataclasses
import json

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from hazard.outputs.report import json_safe
from hazard.outputs.report_schema import (AidedZone as AidedZoneBlock, AirspaceBlock, ExtendedSourceBlock, LimitingAperture, SamplingBlock,
                                         SdzBlock, SpillBlock, Uv24hBlock, VerdictBlock)
from hazard.physics import aperture
from hazard.physics.mpe import RepetitivePulseResult, UV24hResult, uv_24h_mpe
from hazard.pipeline.airspace import AirspaceCheck, FlightZoneCheck
from hazard.pipeline.extended_source import ExtendedMpe, ExtendedSourceSummary
from hazard.pipeline.sdz import AidedZone, DangerZone, MirrorBeam, MirrorReach, NominalZone, SdzDirections
from hazard.pipeline.spill import AidedNohd, SpillSummary, StoppedSpill
from hazard.pipeline.spots import BeamSampling, NotReflected
from hazard.pipeline.verdict import Verdict, VerdictCounts

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

CASES = [(verdicts, VerdictBlock), (samplings, SamplingBlock), (spills, SpillBlock), (extended, ExtendedSourceBlock),
         (airspaces, AirspaceBlock), (apertures, LimitingAperture), (danger_zones, SdzBlock)]


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
