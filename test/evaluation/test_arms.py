"""`evaluation.arms` against independent computations: scipy-integrated two-body and J2 orbits
from the arm's own start (J2 about the Earth's pole of date, from ERFA's X, Y of the CIP),
hand-computed scores."""

import numpy as np
import pytest
from references import scipy_orbit as orbit

from ssa_fusion.core.base.types import Kind, Measurement, MotionModel, StateEstimate, UpdateSource
from ssa_fusion.core.filter.options import FilterOptions
from ssa_fusion.core.gaps import batch_gap
from ssa_fusion.core.gaps.estimator import EstimatorConfig
from ssa_fusion.core.motion import kepler
from ssa_fusion.evaluation import arms

X0 = np.array([6778.0, 0.0, 0.0, 0.0, 4.8, 5.9])
T0 = 1.7e9  # Unix s (2023-11-14)


CONFIG = EstimatorConfig(kind=Kind.POSITION, lift="none",
                         filter=FilterOptions().with_(p0_sigma=(1.0,) * 3 + (1e-2,) * 3,
                                                      q=1e-12))


def test_coast_is_the_motion_model_from_the_start_estimate():
    start = StateEstimate(100.0, X0, 1e-10 * np.eye(6), update_source=UpdateSource.SENSOR)
    t_gap = 100.0 + 60.0 * np.arange(1, 31)
    got = arms.coast(CONFIG, start, t_gap)
    ref = orbit(X0, np.concatenate([[100.0], t_gap]), j2=False)[1:]
    np.testing.assert_allclose(got.x, ref, atol=1e-6)
    assert np.all(np.diff(np.trace(got.P, axis1=1, axis2=2)) > 0)
    assert set(got.source) == {UpdateSource.NONE}
    # the Monte Carlo placeholder from the same start agrees with it
    mc = arms.placeholder(CONFIG, start, t_gap, seed=4)
    np.testing.assert_allclose(mc.x[:, :3], ref[:, :3], atol=5e-3)  # ~3 x sigma/sqrt(200)
    F = kepler.propagate(X0, t_gap[-1] - 100.0)[1]  # no process noise in the Monte Carlo
    np.testing.assert_allclose(np.sqrt(np.diag(mc.P[-1])), np.sqrt(np.diag(F @ start.P @ F.T)),
                               rtol=0.3)


def test_j2_coast_tracks_with_j2_then_follows_an_independent_j2_orbit():
    t = T0 + 60.0 * np.arange(200)
    truth = orbit(X0, t)
    real = [Measurement(float(ti), xi[:3], 1e-6 * np.eye(3), kind=Kind.POSITION,
                        frame_id="gcrf") for ti, xi in zip(t[:150], truth[:150], strict=True)]
    t_gap = t[150:]
    got = arms.j2_coast(CONFIG, real, t_gap)
    j2 = CONFIG.with_(filter=CONFIG.filter.with_(motion_model=MotionModel.J2))
    start = arms.start_estimate(arms.run_filter(j2, real), float(t_gap[0]))
    assert start.t == t[149]
    ref = orbit(start.x, np.concatenate([[start.t], t_gap]))[1:]
    np.testing.assert_allclose(got.x, ref, atol=1e-5)
    # and tracking with J2 found the true orbit: 50 min later still within 100 m
    assert np.linalg.norm(got.x[-1, :3] - truth[-1, :3]) < 0.1
    assert arms.j2_coast(EstimatorConfig(kind=Kind.POSITION, n=2, observed=(0,), lift="none",
                                         filter=FilterOptions().with_(motion_model="pendulum")),
                          real, t_gap) is None


def test_score_by_hand():
    x_true = np.tile([7000.0, 0, 0, 0, 7.5, 0], (2, 1))
    x = x_true.copy()
    x[0, 0] += 3.0
    x[1, 1] += 4.0
    arm = arms.ArmTrajectory(np.array([0.0, 1.0]), x, np.stack([np.eye(6)] * 2),
                             np.zeros(2, dtype=int))
    sc = arms.score(arm, x_true)
    assert sc.pos_err_mean_km == pytest.approx(3.5) and sc.pos_err_final_km == pytest.approx(4.0)
    assert sc.nees_mean == pytest.approx((9.0 + 16.0) / 2)


def test_dmd_ekf_matches_epochs_up_to_round_off():
    """Forecast epochs computed as last + k * cadence differ from the gap epochs in the last
    bits; they still count as the same epoch (a bug once scored 38 % of them as missing)."""
    est = {0.0: StateEstimate(0.0, X0, np.eye(6), update_source=UpdateSource.SENSOR)}
    t_gap = np.array([0.1 * k for k in range(1, 4)])
    for k in range(1, 4):
        t = 0.0 + k * 0.1 + 4e-17 * k
        est[t] = StateEstimate(t, X0 + k, np.eye(6), update_source=UpdateSource.FORECAST)
    got = arms.dmd_ekf(CONFIG, est, t_gap)
    np.testing.assert_array_equal(got.x[:, 0], X0[0] + np.arange(1, 4))


@pytest.mark.parametrize(("x0", "bound_km"), [
    (np.array([7378.0, 0.0, 0.0, 0.0, 4.7, 5.67]), 0.03),  # 1,000 km: no air
    (X0, 1.0),  # 400 km: the fit solves for a drag factor the 1.3 h window hardly observes
])
def test_batch_fit_spans_the_last_passes_and_follows_an_independent_zonal_orbit(
        x0, bound_km, monkeypatch):
    """Four 'passes' of noisy positions (10 m) of a drag-free J2-J4 orbit, 30 min apart; the
    first is 50 km off (a different object): with a window of three passes and no span
    (`batch_gap.GAP_FIT_SPAN_H` 0) the arm fits the last three only (the state and a drag
    factor), from a first guess 1 km and 1 m/s off, and predicts the next hour
    within 30 m of scipy's orbit at 1,000 km; at 400 km the drag factor the short window
    leaves uncertain (0.32 here, truly 0) costs up to a kilometre in that hour, and the
    covariance says so: at both, NEES below chi2(6)'s 99.9 % point at every epoch."""
    monkeypatch.setattr(batch_gap, "GAP_FIT_SPAN_H", 0.0)
    rng = np.random.default_rng(3)
    t = T0 + np.concatenate([k * 2400.0 + 60.0 * np.arange(10) for k in range(4)])
    t_gap = t[-1] + 60.0 * np.arange(1, 61)
    truth = orbit(x0, np.concatenate([t, t_gap]), j3_j4=True)
    z = truth[: t.size, :3] + 0.01 * rng.standard_normal((t.size, 3))
    z[:10] += 50.0
    real = [Measurement(float(ti), zi, 1e-4 * np.eye(3), kind=Kind.POSITION, frame_id="gcrf")
            for ti, zi in zip(t, z, strict=True)]
    x_guess = truth[t.size - 1] + np.array([1.0, -1.0, 0.5, 1e-3, -1e-3, 5e-4])
    start = StateEstimate(float(t[-1]), x_guess, np.eye(6), update_source=UpdateSource.SENSOR)
    got = arms.batch_fit(CONFIG, real, start, t_gap)
    assert got is not None
    err = got.x - truth[t.size:]
    assert np.max(np.linalg.norm(err[:, :3], axis=1)) < bound_km
    n = np.einsum("ki,kij,kj->k", err, np.linalg.inv(got.P), err)
    assert np.all(n < 22.46)  # chi2(6) 99.9 %
    assert set(got.source) == {UpdateSource.NONE}
    # not an Earth orbit: no batch fit
    pendulum = EstimatorConfig(kind=Kind.POSITION, n=2, observed=(0,), lift="none",
                               filter=FilterOptions().with_(motion_model="pendulum"))
    assert arms.batch_fit(pendulum, real, start, t_gap) is None
