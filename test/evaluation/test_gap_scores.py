"""`evaluation.gap_scores`: gap epochs, errors and the NEES coverage by hand."""

import numpy as np
import pytest
from scipy.stats import chi2

from ssa_fusion.core.base.types import Kind, Measurement, StateEstimate, UpdateSource
from ssa_fusion.evaluation.gap_scores import LONG_GAP_S, NEES3_95, score_gaps

T = 60.0 * np.arange(0, 1500)  # 25 h of truth on a 60 s grid
X = np.column_stack([7000.0 + T, np.zeros((T.size, 5))])


def meas(t):
    return Measurement(float(t), X[int(t // 60), :3], np.eye(3), kind=Kind.POSITION)


def test_gap_epochs_errors_and_coverage_by_hand():
    """Passes at 0-300 s, 3600-3900 s and 60,000-60,300 s (a gap > 12 h); every estimate
    between passes is 0.1 km off in x with sigma 0.1 km, except that every 10th is 1 km off
    (NEES 100): median error 0.1 km, coverage 90 %, median NEES 1."""
    real = [meas(t) for t in (*range(0, 301, 60), *range(3600, 3901, 60),
                              *range(60000, 60301, 60))]
    est = {}
    for k, t in enumerate(T):
        x = X[k].copy()
        x[0] += 1.0 if k % 10 == 0 else 0.1
        est[float(t)] = StateEstimate(float(t), x, 0.01 * np.eye(6),
                                      update_source=UpdateSource.NONE)
    got = score_gaps(est, real, T, X)
    inside = ((T > 300) & (T < 3600)) | ((T > 3900) & (T < 60000))
    assert got.gap_epochs == inside.sum()
    assert LONG_GAP_S < 60000 - 3900
    assert got.long_gap_epochs == ((T > 3900) & (T < 60000)).sum()
    assert got.err_median_km == pytest.approx(0.1)
    assert got.long_err_median_km == pytest.approx(0.1)
    share_far = np.mean([int(t // 60) % 10 == 0 for t in T[inside]])
    assert got.nees_in_95 == pytest.approx(1.0 - share_far)
    assert got.nees_median == pytest.approx(1.0)
    assert got.after_pass_median_km == pytest.approx(0.1)  # 360 s and 3960 s: not a 10th
    assert chi2.cdf(NEES3_95, 3) == pytest.approx(0.95)


def test_no_gap_scores_nan():
    real = [meas(t) for t in range(0, 301, 60)]
    got = score_gaps({float(t): StateEstimate(float(t), X[0], np.eye(6)) for t in T[:6]},
                     real, T, X)
    assert got.gap_epochs == 0 and np.isnan(got.err_median_km) and np.isnan(got.nees_in_95)
