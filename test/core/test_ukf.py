"""Tests for ssa_fusion.core.filter.ukf: the unscented filter option.

References: FilterPy's ``UnscentedKalmanFilter`` with ``MerweScaledSigmaPoints`` (same
alpha, beta, kappa; the same angle-aware measurement mean and residual given to it) on an
orbit tracked by the Columbus radar (equal to 1e-9), and the linear Kalman filter (the
unscented transform is exact for linear models).
"""

from __future__ import annotations

import numpy as np
import pytest
from filterpy.kalman import MerweScaledSigmaPoints
from filterpy.kalman import UnscentedKalmanFilter as FpUKF

from ssa_fusion.core.base.types import Measurement
from ssa_fusion.core.earth.frames import wrap_angle
from ssa_fusion.core.filter.ekf import ExtendedKalmanFilter, process_noise
from ssa_fusion.core.filter.ukf import UnscentedKalmanFilter, merwe_weights, sigma_points
from ssa_fusion.core.gaps import estimator as config
from ssa_fusion.sim import sky

ANGLES = np.array([False, True, True])


def _z_mean(sigmas: np.ndarray, wm: np.ndarray) -> np.ndarray:
    d = sigmas - sigmas[0]
    d[:, ANGLES] = wrap_angle(d[:, ANGLES])
    return sigmas[0] + wm @ d


def _residual_z(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    d = np.asarray(a - b, dtype=float)
    d[ANGLES] = wrap_angle(d[ANGLES])
    return d


@pytest.mark.parametrize(("alpha", "beta", "kappa"), [(1.0, 2.0, 0.0), (0.5, 2.0, 1.0)])
def test_weights_and_points_are_filterpys(alpha: float, beta: float, kappa: float) -> None:
    pts = MerweScaledSigmaPoints(4, alpha, beta, kappa)
    wm, wc, lam = merwe_weights(4, alpha, beta, kappa)
    np.testing.assert_allclose(wm, pts.Wm, rtol=1e-15)
    np.testing.assert_allclose(wc, pts.Wc, rtol=1e-15)
    x = np.array([1.0, -2.0, 0.5, 3.0])
    P = np.array([[2.0, 0.3, 0, 0], [0.3, 1.0, 0.1, 0], [0, 0.1, 0.5, 0], [0, 0, 0, 4.0]])
    np.testing.assert_allclose(sigma_points(x, P, lam), pts.sigma_points(x, P), rtol=1e-14)


def test_equals_filterpy_on_an_orbit() -> None:
    s = sky.SKY_SCENARIOS["iss_radar_columbus"].with_(duration_s=0.42 * 86400.0)
    sim = sky.simulate_sky(s, seed=2)
    meas: list[Measurement] = sim.real[:60]  # two passes and the gap between them
    c = s.estimator()
    f = config.motion(c)
    models = config.measurement_model(c)
    t = meas[0].t - 10.0  # FilterPy's update needs a predict before it (its sigmas_f)
    x0 = sky.truth(s, np.array([t]))[0] + np.array([0.5, -0.3, 0.2, 3e-4, 2e-4, -1e-4])
    P0 = np.diag([1.0, 1.0, 1.0, 1e-6, 1e-6, 1e-6])
    ours = UnscentedKalmanFilter(x0, P0)
    fp = FpUKF(6, 3, 1.0, None, None, MerweScaledSigmaPoints(6, 1.0, 2.0, 0.0),
               z_mean_fn=_z_mean, residual_z=_residual_z)
    fp.x, fp.P = x0.copy(), P0.copy()
    for m in meas:
        model = models.get(m.kind, m.frame_id)
        assert model is not None
        dt, t0 = m.t - t, t
        if dt:
            Q = process_noise(dt, 1e-12)
            ours.predict(lambda x, dt=dt, t0=t0: f(x, dt, t0), Q)  # the EKF's f(x) -> (x, F)
            fp.Q = Q
            fp.predict(dt=dt, fx=lambda x, dt, t0=t0: f(x, dt, t0)[0])
        res = ours.update(m.z, lambda x, tm=m.t, h=model: h.h_and_H(x, tm), m.R,
                          model.angle_mask)
        fp.update(m.z, R=m.R, hx=lambda x, tm=m.t, h=model: h.h(x, tm))
        assert res.accepted
        np.testing.assert_allclose(ours.x, fp.x, rtol=1e-9, atol=1e-12)
        np.testing.assert_allclose(ours.P, fp.P, rtol=0, atol=1e-9 * np.abs(fp.P).max())
        np.testing.assert_allclose(ours.y, fp.y, rtol=0, atol=1e-9 * np.abs(m.z).max())
        t = m.t
    err = np.linalg.norm(ours.x[:3] - sky.truth(s, np.array([t]))[0, :3])
    assert err < 0.2  # it tracked



def test_linear_problem_equals_kalman_filter() -> None:
    F = np.eye(4)
    F[0, 2] = F[1, 3] = 0.5
    H = np.hstack([np.eye(2), np.zeros((2, 2))])
    Q, R = process_noise(0.5, 0.1, dim=2), np.diag([0.2, 0.4])
    rng = np.random.default_rng(3)
    ukf = UnscentedKalmanFilter(np.zeros(4), np.eye(4), alpha=0.7, kappa=1.0)
    kf = ExtendedKalmanFilter(np.zeros(4), np.eye(4))
    for _ in range(30):
        z = rng.standard_normal(2)
        ukf.predict_batch(lambda X: X @ F.T, Q)
        kf.predict(lambda x: (F @ x, F), Q)
        np.testing.assert_allclose(ukf.P_prior, kf.P_prior, rtol=1e-12, atol=1e-14)
        r1 = ukf.update(z, lambda x: H @ x, R)
        r2 = kf.update(z, lambda x: (H @ x, H), R)
        assert r1.nis == pytest.approx(r2.nis, rel=1e-10)
        np.testing.assert_allclose(ukf.x, kf.x, rtol=1e-10, atol=1e-12)
        np.testing.assert_allclose(ukf.P, kf.P, rtol=1e-10, atol=1e-13)


def test_gate_and_bad_input() -> None:
    H = np.hstack([np.eye(2), np.zeros((2, 2))])
    ukf = UnscentedKalmanFilter(np.zeros(4), np.eye(4))
    x, P = ukf.snapshot()
    res = ukf.update(np.array([100.0, 0.0]), lambda x: H @ x, np.eye(2), gate=20.0)
    assert not res.accepted and res.nis > 20.0 and ukf.K is None
    np.testing.assert_array_equal(ukf.x, x)
    np.testing.assert_array_equal(ukf.P, P)
    with pytest.raises(ValueError, match="non-finite"):
        ukf.update(np.array([np.nan, 0.0]), lambda x: H @ x, np.eye(2))
    with pytest.raises(ValueError, match="shape"):
        ukf.update(np.zeros(2), lambda x: H @ x, np.eye(3))


def test_azimuth_wraps_in_the_unscented_transform() -> None:
    """Points whose azimuths straddle 0/2 pi average near 0, not near pi."""
    ukf = UnscentedKalmanFilter(np.array([0.0, 0.0]), np.diag([1e-4, 1e-4]))

    def h(x: np.ndarray) -> np.ndarray:
        return np.array([1.0, np.mod(x[0], 2 * np.pi), 0.1 + x[1]])

    ukf.update(np.array([1.0, 2 * np.pi - 0.001, 0.1]), h, np.diag([1.0, 1e-4, 1e-4]),
               [False, True, True])
    assert ukf.y is not None and abs(ukf.y[1] + 0.001) < 1e-12
    assert abs(ukf.x[0] + 0.0005) < 1e-4


def test_the_tracker_runs_with_it() -> None:
    """Same interface: a `Tracker` whose EKF is swapped for the UKF after its IOD fuses the
    passes (predict, gate, update, snapshot/restore) and tracks as the EKF does."""
    s = sky.SKY_SCENARIOS["iss_radar_columbus"].with_(duration_s=0.55 * 86400.0)
    real = sky.simulate_sky(s, seed=4).real
    truth = sky.truth(s, np.array([m.t for m in real]))
    medians = []
    for swap in (False, True):
        tracker = config.make_tracker(s.estimator())
        for m in real[:7]:  # the IOD batch
            tracker.process(m)
        assert tracker.ekf is not None
        if swap:
            tracker.ekf = UnscentedKalmanFilter(tracker.ekf.x, tracker.ekf.P)  # type: ignore[assignment]
        errors = []
        for m, xt in zip(real[7:], truth[7:], strict=True):
            out = tracker.process(m)
            assert out.estimate is not None, out.detail
            errors.append(np.linalg.norm(out.estimate.x[:3] - xt[:3]))
        medians.append(float(np.median(errors)))
    assert isinstance(tracker.ekf, UnscentedKalmanFilter)
    assert medians[1] < 0.15 and abs(medians[1] - medians[0]) < 0.1 * medians[0]
