"""The near-field keep-out notes: one note per kind, every target inside the near field named
with its own reach (a scene with many small spots printed one long note per target)."""
from types import SimpleNamespace as NS

from hazard.pipeline.lobes import near_field_lobe_notes


def _spot(name, size_m, slump=None):
    return NS(target=NS(name=name), size_m=size_m, slump=slump)


def _row(name, reach_m, near_field):
    return NS(name=name, dynamic_lobe=NS(max_range_m=reach_m, near_field=near_field))


def _nf(n, step_m):
    return {"directions_integrated": n, "grid_theta_deg": [0, 45, 89.5], "grid_phi_deg": 30.0, "scan_step_max_m": step_m}


def test_one_note_per_kind_names_every_near_lobe():
    spots = [_spot("a", 0.5), _spot("b", 0.2), _spot("t_far", 0.01), _spot("t_melt", 0.3, slump=object()), _spot("t_dark", 1.0)]
    rows = [_row("a", 3.25, _nf(12, 0.01)), _row("b", 1.5e-9, _nf(4, 2e-8)),
            _row("t_far", 5.0, _nf(3, 0.1)),        # 5 m > 20 x 0.01 m: far field, no note
            _row("t_melt", 0.75, None),              # slumping: point form
            _row("t_dark", 0.0, _nf(1, 0.1))]        # no lobe: no note
    notes = near_field_lobe_notes(spots, rows)
    assert len(notes) == 2
    integrated, point_form = notes
    assert "a 3.25 m (spot size 0.5 m, 12 direction(s)" in integrated
    assert "b 1.5e-09 m (spot size 0.2 m, 4 direction(s)" in integrated
    assert "polar rows 0, 45, 89.5 deg, azimuth step 30 deg" in integrated
    assert "t_far" not in integrated and "t_melt" not in integrated and "t_dark" not in integrated
    assert "t_melt 0.75 m (spot size 0.3 m, 2 RMS radii; a slumping spot)" in point_form
    assert "not a keep-out distance there" in point_form


def test_no_near_lobe_no_note():
    assert near_field_lobe_notes([_spot("a", 0.01)], [_row("a", 5.0, _nf(3, 0.1))]) == []
