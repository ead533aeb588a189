"""`core.gaps.calibration`: a gap forecast's covariance scaled by what the object's own last
passes say.

* `scale_estimate` against its closed form (equal eigenvalues: k = (mean q2 - 1) / lam),
  and against a simulation whose covariance is known to be k times too small;
* `batch_ls.whitened_predictions` against the whitened residual and covariance computed by
  hand for positions (h = r, H = [I 0]);
* `CovarianceScale`: the median of the last passes' estimates at one horizon, a power law
  of the horizon through estimates that follow one exactly; 1 before any;
* the gap fit publishes its covariances times the factor.
"""

import numpy as np
import pytest

from ssa_fusion.core.base.types import Kind, Measurement
from ssa_fusion.core.gaps import calibration
from ssa_fusion.core.gaps.calibration import CovarianceScale, ScaleRule, scale_estimate
from ssa_fusion.core.gaps.estimator import EstimatorConfig, measurement_model
from ssa_fusion.core.od.batch_ls import whitened_predictions

MODEL = measurement_model(EstimatorConfig(kind=Kind.POSITION))
SIGMA = 0.01  # km


def test_scale_estimate_closed_form_and_bounds():
    lam = np.full(30, 4.0)
    q2 = np.full(30, 9.0)  # mean q2 = 9: k = (9 - 1) / 4 = 2
    assert scale_estimate(lam, q2) == pytest.approx(2.0, rel=1e-9)
    assert scale_estimate(lam, np.full(30, 0.5)) == calibration.MIN_SCALE  # noise explains it
    assert scale_estimate(lam, np.full(30, 1e12)) == calibration.MAX_SCALE
    assert np.isnan(scale_estimate([], []))


def test_scale_estimate_finds_a_covariance_too_small_by_a_known_factor():
    rng = np.random.default_rng(5)
    lam = rng.uniform(0.5, 50.0, 3000)
    q2 = (rng.standard_normal(3000) * np.sqrt(6.0 * lam + 1.0)) ** 2
    assert scale_estimate(lam, q2) == pytest.approx(6.0, rel=0.1)


def _positions(x: np.ndarray, z: np.ndarray) -> list[Measurement]:
    return [Measurement(float(t), zi, SIGMA**2 * np.eye(3), kind=Kind.POSITION,
                        frame_id="gcrf") for t, zi in enumerate(z)]


def test_whitened_predictions_by_hand_for_positions():
    rng = np.random.default_rng(2)
    x = np.tile([7000.0, 0.0, 0.0, 0.0, 7.5, 0.0], (4, 1))
    z = x[:, :3] + rng.normal(0.0, 0.05, (4, 3))
    A = rng.normal(size=(4, 6, 6))
    P = A @ np.swapaxes(A, 1, 2) * 1e-3
    lam, q2 = whitened_predictions(_positions(x, z), MODEL, x, P)
    for i in range(4):
        S = P[i, :3, :3] / SIGMA**2
        r = (z[i] - x[i, :3]) / SIGMA
        e = np.linalg.eigvalsh(S)
        assert np.allclose(np.sort(lam[3 * i:3 * i + 3]), e, rtol=1e-9)
        nis = r @ np.linalg.solve(2.5 * S + np.eye(3), r)  # k = 2.5 by both routes
        assert np.sum(q2[3 * i:3 * i + 3] / (2.5 * lam[3 * i:3 * i + 3] + 1)) \
            == pytest.approx(nis, rel=1e-9)


X = np.tile([7000.0, 0.0, 0.0, 0.0, 7.5, 0.0], (10, 1))
P_UNIT = np.tile(np.diag([SIGMA**2] * 3 + [1e-9] * 3), (10, 1, 1))  # S = I


def _update(c: CovarianceScale, k: float, horizon_s: float) -> None:
    """A pass whose errors are sqrt(k + 1) sigma in every channel (estimate k)."""
    c.update(_positions(X, X[:, :3] + SIGMA * np.sqrt(k + 1.0)), MODEL, X, P_UNIT, horizon_s)


def test_covariance_scale_is_the_median_of_the_last_passes_at_one_horizon():
    c = CovarianceScale(passes=3)
    assert c.factor(3600.0)[0] == 1.0
    for k in (3.0, 8.0, 1.0, 15.0):
        _update(c, k, 3600.0)
    assert [k for _, k in c.estimates] == pytest.approx([8.0, 1.0, 15.0], rel=1e-6)
    beyond = 1.0 + 7.0 * 24.0**calibration.EXCESS_POWER  # 24 h: beyond every pass's 1 h
    assert c.factor([600.0, 3600.0, 86400.0]) == pytest.approx([8.0, 8.0, beyond], rel=1e-6)
    c.update(_positions(X, X[:, :3]), MODEL, np.full_like(X, np.nan), P_UNIT, 3600.0)
    assert len(c.estimates) == 3  # a forecast that failed estimates nothing


def test_covariance_scale_follows_a_power_of_the_horizon():
    """Estimates k = 2 (h / 1 h)^1.5 at 1.5, 3, 12 and 16 h: the factor is that law at any
    horizon (an error growing faster through a gap than the covariance)."""
    c = CovarianceScale(passes=6, rule=ScaleRule.POWER_LAW)
    for h in (1.5, 3.0, 12.0, 16.0):
        _update(c, 2.0 * h**1.5, 3600.0 * h)
    got = c.factor(3600.0 * np.array([1.0, 6.0, 24.0]))
    assert got == pytest.approx(2.0 * np.array([1.0, 6.0, 24.0]) ** 1.5, rel=1e-6)
    c.rule = ScaleRule.MEDIAN  # the median of the estimates at every horizon
    assert c.factor([3600.0, 86400.0]) == pytest.approx([2.0 * 6.0**1.5] * 2, rel=1e-6)  # 3, 12 h


def test_covariance_scale_at_a_horizon_counts_the_passes_that_saw_that_far():
    """One radar: short gaps (1.5 h, k 2) between the passes of a day, one long gap (12 h,
    k 50) a day. The median says 2 everywhere; the long horizons take the long gaps' 50, and
    beyond 12 h its excess grows (`calibration.EXCESS_POWER`)."""
    c = CovarianceScale(passes=6)
    assert c.rule is ScaleRule.HORIZON  # the default
    for h, k in ((1.5, 2.0), (1.5, 2.5), (12.0, 50.0), (1.5, 1.5), (1.5, 2.0), (12.0, 70.0)):
        _update(c, k, 3600.0 * h)
    got = c.factor(3600.0 * np.array([0.5, 4.0, 6.0, 20.0, 24.0, 30.0]))
    # medians of the log estimates: of an even count, the geometric mean of the middle two
    every, long_ones = np.sqrt(2.0 * 2.5), np.sqrt(50.0 * 70.0)
    # 20, 24 and 30 h: beyond every pass's horizon, the excess of the 12 h ones grown
    grown = (np.array([20.0, 24.0, 30.0]) / 12.0) ** calibration.EXCESS_POWER
    beyond = 1.0 + (long_ones - 1.0) * grown
    assert got == pytest.approx([every, long_ones, long_ones, *beyond], rel=1e-6)
    c.rule = ScaleRule.MEDIAN
    assert c.factor(3600.0 * 20.0) == pytest.approx([every], rel=1e-6)


def test_covariance_scale_grows_its_excess_beyond_the_horizons_seen(monkeypatch):
    """Beyond the longest horizon an estimate saw (3 h, k 5 and 7: their median sqrt(35)),
    the excess over one grows as (h / 3 h)^p; a factor of one stays one (no excess seen)."""
    monkeypatch.setattr(calibration, "EXCESS_POWER", 2.0)
    c = CovarianceScale(passes=6)
    for h, k in ((1.5, 2.0), (3.0, 5.0), (3.0, 7.0)):
        _update(c, k, 3600.0 * h)
    got = c.factor(3600.0 * np.array([2.0, 3.0, 6.0, 12.0]))
    k_l = np.sqrt(35.0)
    assert got == pytest.approx([k_l, k_l, 1.0 + (k_l - 1.0) * 4.0, 1.0 + (k_l - 1.0) * 16.0],
                                rel=1e-6)
    assert c.factor(1e12)[0] == pytest.approx(1.0 + calibration.MAX_SCALE)  # bounded
    flat = CovarianceScale(passes=6)
    for h in (1.5, 3.0):
        _update(flat, 0.0, 3600.0 * h)  # the noise explains the misfit: MIN_SCALE
    assert flat.factor(3600.0 * np.array([1.0, 24.0])) == pytest.approx([1.0, 1.0])
