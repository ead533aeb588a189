"""The honesty of the collision probability in simulation (`studies.conjunction_honesty`).

The truth of each simulated close approach is a draw from the covariance its estimate
reports: the normalised miss errors must be chi-square(2) (95 % coverage), and the Pc must
come true at its own rate; a covariance reported four times too small must fail both.
"""

from __future__ import annotations

import math

import numpy as np

from ssa_fusion.studies.conjunction_honesty import (
    CHI2_2_95,
    HonestyConfig,
    reliability,
    run_honesty,
)


def test_honest_covariances_cover_95_percent_and_the_pc_comes_true():
    r = run_honesty(HonestyConfig(pairs=400, seed=11))
    assert r.epsilon.size == 400  # every planted approach found by the screening
    # binomial 99.9 % band of the coverage of 400 draws around 0.95
    assert abs(r.coverage95 - 0.95) < 3.3 * math.sqrt(0.95 * 0.05 / 400)
    assert abs(r.epsilon.mean() - 2.0) < 3.3 * 2.0 / math.sqrt(400)  # chi2_2: mean 2, sd 2
    expected = r.pc.sum()
    assert abs(r.collided.sum() - expected) < 3.3 * math.sqrt(expected) + 1
    assert np.all(r.true_miss_km[r.collided] < 0.03)


def test_an_overconfident_covariance_fails_the_coverage():
    r = run_honesty(HonestyConfig(pairs=200, seed=12, cov_scale=0.25))
    assert r.coverage95 < 0.75
    assert np.mean(r.epsilon > CHI2_2_95) > 0.25


def test_reliability_rows_count_and_bound_the_rates():
    pc = np.array([0.0005, 0.002, 0.004, 0.02, 0.5, 0.9])
    hit = np.array([False, False, True, False, True, True])
    rows = reliability(pc, hit, (0.0, 0.001, 0.01, 0.1, 1.0))
    assert [r.n for r in rows] == [1, 2, 1, 2]
    assert [r.collisions for r in rows] == [0, 1, 0, 2]
    assert rows[3].mean_pc == 0.7 and rows[3].rate_hi == 1.0
    lo, hi = rows[1].rate_lo, rows[1].rate_hi  # Wilson interval of 1 in 2
    assert 0.09 < lo < 0.1 and 0.9 < hi < 0.91
