"""The solid-tide displacement of a station (core.measure.station_tides) against the IERS
Conventions' own routine: the test cases printed in the prolog of DEHANTTIDEINEL.F (IERS
2010 software), which computes the full model (degree 3, out-of-phase, latitude-band terms,
the frequency-dependent corrections of step 2). What is modelled here is the in-phase
degree-2 term of step 1: it must agree to the neglected terms' size (~1 cm), and a sign
slip (tens of centimetres) must not."""

from __future__ import annotations

import math

import numpy as np
import pytest

from ssa_fusion.core.earth.ephemeris import sun_moon_span
from ssa_fusion.core.earth.timescales import parse_utc
from ssa_fusion.core.measure.station_tides import displacement

# station, Sun, Moon (ITRF, m) and the printed displacement (m)
CASES = {
    "2009-04-13": ((4075578.385, 931852.890, 4801570.154),
                   (137859926952.015, 54228127881.4350, 23509422341.6960),
                   (-179996231.920342, -312468450.131567, -169288918.592160),
                   (0.7700420357108125891e-01, 0.6304056321824967613e-01,
                    0.5516568152597246810e-01)),
    "2012-07-13": ((1112189.660, -4842955.026, 3985352.284),
                   (-54537460436.2357, 130244288385.279, 56463429031.5996),
                   (300396716.912, 243238281.451, 120548075.939),
                   (-0.2036831479592075833e-01, 0.5658254776225972449e-01,
                    -0.7597679676871742227e-01)),
    "2015-07-15": ((1112200.5696, -4842957.8511, 3985345.9122),
                   (100210282451.6279, 103055630398.3160, 56855096480.4475),
                   (369817604.4348, 1897917.5258, 120804980.8284),
                   (0.00509570869172363845, 0.0828663025983528700, -0.0636634925404189617)),
}
NEGLECTED_M = 0.015
"""Step 2's K1 correction (up to 13 mm radial) and the rest (a few mm)."""


@pytest.mark.parametrize("date", sorted(CASES))
def test_the_iers_routine_test_cases(date: str) -> None:
    station, sun, moon, printed = (np.array(v) / 1000.0 for v in CASES[date])
    span = sun_moon_span(parse_utc(date + "T00:00:00"), 0.0, 0.0)
    lat = math.asin(station[2] / np.linalg.norm(station))
    got = displacement(station[None], [lat], [(span.gm_sun, sun[None]),
                                               (span.gm_moon, moon[None])])[0]
    diff = np.linalg.norm(got - printed) * 1e3
    print(f"\n{date}: {np.round(got * 1e6, 1)} mm against the routine's "
          f"{np.round(printed * 1e6, 1)} mm: {diff * 1e3:.1f} mm apart")
    assert diff <= NEGLECTED_M
    assert np.linalg.norm(-got - printed) * 1e3 > 3 * NEGLECTED_M
