"""MPE to the letter of ANSI Z136.1-2014 and IEC 60825-1:2014 (issue 33).

Every expected value here is typed by hand from the standards' tables (edition, table and
row cited in a comment beside it) or from the published worked examples (source in a
comment, numbers only); none is computed with :mod:`hazard.mpe`'s own tables or factors.
Rows the project could not read in the standard's text are marked [M] as in
``hazard/mpe.py``; there the test pins the protective choice the code documents.
"""

import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import hazard as hz

ANSI, IEC = "ansi-z136.1-2014", "iec-60825-1-2014"
REL = 1e-9  # formulas typed in full: agreement to rounding of doubles
J_CM2 = 1e4  # 1 J/cm^2 = 1e4 J/m^2 (and W/cm^2 -> W/m^2)


def h(wl, t, std, **kw):
    return hz.ocular_mpe(wl, t, standard=std, **kw).radiant_exposure_j_m2


# --- 1. 1200-1400 nm: the anterior-segment dual limit -----------------------------------
def test_iec_1200_1400_no_longer_five_orders_above_1400_nm():
    # issue 33: IEC mode gave the retinal limit alone, 7.9e6 W/m^2 at 1380 nm and 4.95e7 W/m^2
    # at 1399.9 nm for 10 s, against 1000 W/m^2 at 1400 nm.
    # ANSI Z136.1-2014 Table 5a, 1200-1400 nm corneal row, t >= 10 s: E = 0.03 K + 0.07 W/cm^2,
    # K = 10^(0.01 (1400 - l)); applied to IEC as the lower candidate [M].
    for wl in (1380.0, 1399.9):
        k = 10 ** (0.01 * (1400 - wl))
        assert hz.ocular_mpe(wl, 10.0, standard=IEC).irradiance_w_m2 == pytest.approx((0.03 * k + 0.07) * J_CM2, rel=REL)
    # the value the issue quotes for ANSI mode: 1001 W/m^2 at 1399.9 nm
    assert round(hz.ocular_mpe(1399.9, 10.0, standard=ANSI).irradiance_w_m2) == 1001
    assert round(hz.ocular_mpe(1399.9, 10.0, standard=IEC).irradiance_w_m2) == 1001


@pytest.mark.parametrize("std", [ANSI, IEC])
@pytest.mark.parametrize("t", [1e-12, 1e-10, 1e-8, 1e-6, 1e-4, 1e-3 * (1 + 1e-6), 0.1, 1.0, 5.0, 10.0, 100.0, 3e4])
def test_no_jump_at_1400_nm_beyond_the_standards_own(std, t):
    # Across 1400 nm the standards print one step: ANSI Z136.1-2014 Table 5a's corneal row
    # gives 0.3 K J/cm^2 (K -> 1) below 1e-3 s and 0.3 K + 0.56 t^0.25 - 0.1 to 4 s, where the
    # 1400-1500 nm row gives 0.1 and 0.56 t^0.25 J/cm^2: at most (0.2 + 0.56 * 1e-3^0.25) /
    # (0.56 * 1e-3^0.25) = 3.008x, at 1e-3 s.
    lo = h(1400 * (1 - 1e-7), t, std)
    hi = h(1400.0, t, std)
    assert lo / hi <= (0.2 + 0.56 * 1e-3**0.25) / (0.56 * 1e-3**0.25) * (1 + 1e-3) and hi / lo <= 1 + 1e-3


def test_iec_1200_1400_short_pulses_take_the_skin_candidate():
    # IEC 60825-1:2014 Table A.5 (skin), 400-1400 nm, 1e-9 - 1e-7 s: H = 200 C4 J/m^2, C4 = 5
    # (Table 9, 1050-1400 nm): 1000 J/m^2, below ANSI's corneal 0.3 K J/cm^2 >= 3000 J/m^2 [M].
    r = hz.ocular_mpe(1390.0, 1e-8, standard=IEC)
    assert r.radiant_exposure_j_m2 == pytest.approx(1000.0, rel=REL)
    assert r.governing_limit == "corneal: skin MPE" and r.unverified
    names = {n for n, _, _ in r.limits}
    assert names == {"retinal thermal", "corneal", "corneal: skin MPE"}
