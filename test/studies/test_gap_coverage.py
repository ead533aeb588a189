"""Tests for ssa_fusion.studies.catalog_gaps.gap_coverage: gaps after the first day counted
by hand on a small hand-made stream, from the run's start and from each object's first gap."""

import numpy as np

from ssa_fusion.evaluation.object_states import states_of
from ssa_fusion.studies.catalog_gaps import gap_coverage

DAY = 86400.0
X = np.zeros(6)


def test_gaps_after_the_first_day_and_those_forecast():
    # object a: passes (estimates 60 s apart) ending at 1000, 0.9 d, 1.2 d, 1.5 d; gaps
    # after each. b: first pass ends at 0.5 d, then 1.1 d, 1.6 d. Forecasts: a in its
    # 1.2 d gap, b in its 1.6 d gap and one in b's 1.1 d gap at its very end (counted: in
    # (t_e, next estimate]); a 1.5 d gap runs to the end (t_end 2 d) without a forecast.
    def passes(ends):
        return [(t - dt, X) for t in ends for dt in (120.0, 60.0, 0.0)]

    a_ends = [1000.0, 0.9 * DAY, 1.2 * DAY, 1.5 * DAY]
    b_ends = [0.5 * DAY, 1.1 * DAY, 1.6 * DAY]
    est = {"a": passes(a_ends), "b": passes(b_ends)}
    b_next_after_1_1 = 1.6 * DAY - 120.0  # the first estimate of b's next pass
    fc = {"a": [(1.2 * DAY + 1200.0, X)],
          "b": [(1.6 * DAY + 600.0, X), (b_next_after_1_1, X)]}
    got = gap_coverage(states_of(est), states_of(fc), t_start=0.0, t_end=2 * DAY,
                       pass_break_s=600.0)
    # from the start: a's 1.2 d and 1.5 d gaps, b's 1.1 d and 1.6 d gaps
    assert (got["gaps"], got["with_forecast"]) == (4, 3)
    # from each object's first gap: a's from 1000 s + 1 d (1.2 d, 1.5 d), b's from 1.5 d
    # (1.6 d only)
    assert (got["object_gaps"], got["object_with_forecast"]) == (3, 2)
    # estimates 60 s apart are no gap; a forecast before the gap's pass end counts for none
    one, early = states_of({"c": passes([1.5 * DAY])}), states_of({"c": [(1.5 * DAY - 30.0, X)]})
    got = gap_coverage(one, early, 0.0, 1.5 * DAY + 599.0, 600.0)
    assert got["gaps"] == 0
    got = gap_coverage(one, early, 0.0, 2 * DAY, 600.0)
    assert (got["gaps"], got["with_forecast"]) == (1, 0)
