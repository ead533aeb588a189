"""Tests for ssa_fusion.core.filter.ekf.

References: filterpy's KalmanFilter / ExtendedKalmanFilter (both Joseph-form updates),
filterpy's Q_continuous_white_noise, and the chi-square distribution of the NIS of a
consistent filter (Bar-Shalom, Li & Kirubarajan 2001, sec. 5.4).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from filterpy.common import Q_continuous_white_noise
from filterpy.kalman import ExtendedKalmanFilter as FpEKF
from filterpy.kalman import KalmanFilter
from scipy.stats import chi2

from ssa_fusion.core.earth.frames import wrap_angle
from ssa_fusion.core.filter.ekf import ExtendedKalmanFilter, UpdateResult, process_noise
from ssa_fusion.core.motion.kepler import propagate

DT = 0.5
F_CV = np.block([[np.eye(2), DT * np.eye(2)], [np.zeros((2, 2)), np.eye(2)]])  # [px py vx vy]
H_POS = np.hstack([np.eye(2), np.zeros((2, 2))])


def _linear_f(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    return F_CV @ x, F_CV


def _linear_h(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    return H_POS @ x, H_POS


def test_matches_filterpy_kalman_filter_linear_cv() -> None:
    rng = np.random.default_rng(1)
    x0 = np.array([0.0, 1.0, 0.3, -0.2])
    P0 = np.diag([4.0, 4.0, 1.0, 1.0])
    Q = process_noise(DT, 0.05, dim=2)
    R = np.array([[0.3, 0.05], [0.05, 0.2]])
    ref = KalmanFilter(dim_x=4, dim_z=2)
    ref.x, ref.P, ref.F, ref.H, ref.Q, ref.R = x0.copy(), P0.copy(), F_CV, H_POS, Q, R
    kf = ExtendedKalmanFilter(x0, P0)
    truth = x0.copy()
    for k in range(200):
        truth = F_CV @ truth
        z = H_POS @ truth + rng.multivariate_normal(np.zeros(2), R)
        ref.predict()
        kf.predict(_linear_f, Q)
        np.testing.assert_allclose(kf.x_prior, ref.x_prior, rtol=1e-10, atol=1e-12)
        np.testing.assert_allclose(kf.P_prior, ref.P_prior, rtol=1e-10, atol=1e-12)
        if k % 7 == 3:  # some predict-only steps
            continue
        ref.update(z)
        res = kf.update(z, _linear_h, R)
        assert res.accepted
        np.testing.assert_allclose(kf.x, ref.x, rtol=1e-10, atol=1e-12)
        np.testing.assert_allclose(kf.P, ref.P, rtol=1e-10, atol=1e-12)
        np.testing.assert_allclose(kf.K, ref.K, rtol=1e-10, atol=1e-12)
        np.testing.assert_allclose(kf.S, ref.S, rtol=1e-10, atol=1e-12)
        np.testing.assert_allclose(res.y, ref.y, rtol=1e-10, atol=1e-12)
        assert res.nis == pytest.approx(float(ref.y @ np.linalg.solve(ref.S, ref.y)), rel=1e-10)


def _range_bearing_h(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Range [km] and azimuth [rad, [0, 2pi)] of the first 3 state channels; H (3, 6)."""
    r = float(np.linalg.norm(x[:3]))
    rho2 = x[0] ** 2 + x[1] ** 2
    rho = math.sqrt(rho2)
    az = math.atan2(x[1], x[0]) % (2 * math.pi)
    el = math.atan2(x[2], rho)
    H = np.zeros((3, 6))
    H[0, :3] = x[:3] / r
    H[1, :2] = [-x[1] / rho2, x[0] / rho2]
    H[2, :3] = [-x[0] * x[2] / (rho * r * r), -x[1] * x[2] / (rho * r * r), rho / (r * r)]
    return np.array([r, az, el]), H


_START = np.array([6800.0, -200.0, 300.0, 0.2, 7.4, 1.1])


def test_matches_filterpy_ekf_on_orbit_with_angles() -> None:
    rng = np.random.default_rng(7)
    truth = _START.copy()
    x0 = truth + np.array([50.0, -30.0, 20.0, 1e-2, -2e-2, 1e-2])
    P0 = np.diag([2500.0, 2500.0, 2500.0, 1e-3, 1e-3, 1e-3])
    R = np.diag([0.5, 1e-4, 1e-4])
    dt = 20.0
    Q = process_noise(dt, 1e-9)

    class KeplerEKF(FpEKF):
        def predict_x(self, u: object = 0) -> None:
            self.x, self.F = propagate(self.x, dt)

    def residual(a: np.ndarray, b: np.ndarray) -> np.ndarray:
        y = a - b
        y[1:] = wrap_angle(y[1]), wrap_angle(y[2])
        return y

    ref = KeplerEKF(dim_x=6, dim_z=3)
    ref.x, ref.P, ref.Q, ref.R = x0.copy(), P0.copy(), Q, R
    kf = ExtendedKalmanFilter(x0, P0)
    f = lambda x: propagate(x, dt)  # noqa: E731
    mask = (False, True, True)
    for _ in range(150):
        truth, _ = propagate(truth, dt)
        z = _range_bearing_h(truth)[0] + rng.normal(0.0, np.sqrt(np.diag(R)))
        z[1] %= 2 * math.pi
        ref.predict()
        kf.predict(f, Q)
        ref.update(z, lambda x: _range_bearing_h(x)[1], lambda x: _range_bearing_h(x)[0], R=R,
                   residual=residual)
        kf.update(z, _range_bearing_h, R, angle_mask=mask)
        np.testing.assert_allclose(kf.x, ref.x, rtol=1e-10, atol=1e-9)
        np.testing.assert_allclose(kf.P, ref.P, rtol=1e-8, atol=1e-13)
    err = kf.x[:3] - truth[:3]
    assert err @ np.linalg.solve(kf.P[:3, :3], err) < chi2.ppf(0.9999, 3)  # consistent
    assert np.linalg.norm(err) < 0.2 * np.linalg.norm(x0[:3] - _START[:3])  # and converged


def test_angle_residual_wraps_near_two_pi() -> None:
    # state = [angle, rate]; observe the angle in [0, 2pi)
    x0 = np.array([0.01, 0.0])
    kf = ExtendedKalmanFilter(x0, np.diag([1e-2, 1e-2]))
    H = np.array([[1.0, 0.0]])
    res = kf.update([2 * math.pi - 0.01], lambda x: (H @ x, H), [[1e-2]], angle_mask=(True,))
    assert res.accepted
    assert res.y[0] == pytest.approx(-0.02, abs=1e-12)
    assert res.nis == pytest.approx(0.02**2 / 2e-2, rel=1e-9)
    assert kf.x[0] == pytest.approx(0.0, abs=1e-12)  # halfway between, across the wrap
    # without the mask the residual is ~2 pi and the estimate is dragged across the circle
    kf2 = ExtendedKalmanFilter(x0, np.diag([1e-2, 1e-2]))
    res2 = kf2.update([2 * math.pi - 0.01], lambda x: (H @ x, H), [[1e-2]])
    assert res2.y[0] == pytest.approx(2 * math.pi - 0.02)


def test_wrap_angle_interval() -> None:
    assert wrap_angle(math.pi) == pytest.approx(math.pi)
    assert wrap_angle(-math.pi) == pytest.approx(math.pi)
    assert wrap_angle(3 * math.pi) == pytest.approx(math.pi)
    assert wrap_angle(2 * math.pi - 0.1) == pytest.approx(-0.1)
    assert wrap_angle(-2 * math.pi + 0.1) == pytest.approx(0.1)
    a = np.linspace(-20, 20, 1001)
    w = np.array([wrap_angle(v) for v in a])
    assert np.all(w > -math.pi) and np.all(w <= math.pi)
    np.testing.assert_allclose(np.cos(w), np.cos(a), atol=1e-12)
    np.testing.assert_allclose(np.sin(w), np.sin(a), atol=1e-12)


def test_gate_rejects_outlier_and_leaves_state_unchanged() -> None:
    x0 = np.array([1.0, 2.0, 0.1, 0.0])
    P0 = np.eye(4)
    R = 0.1 * np.eye(2)
    kf = ExtendedKalmanFilter(x0, P0)
    gate = float(chi2.ppf(0.999, 2))
    res = kf.update([1.0 + 30.0, 2.0], _linear_h, R, gate=gate)
    assert isinstance(res, UpdateResult)
    assert not res.accepted
    assert res.nis == pytest.approx(30.0**2 / 1.1)
    assert res.nis > gate
    np.testing.assert_array_equal(kf.x, x0)
    np.testing.assert_array_equal(kf.P, P0)
    np.testing.assert_array_equal(kf.x_post, x0)
    assert kf.nis == res.nis
    # an inlier passes the same gate
    res = kf.update([1.5, 2.2], _linear_h, R, gate=gate)
    assert res.accepted
    assert not np.array_equal(kf.x, x0)


@pytest.mark.parametrize("bad", ["z_nan", "z_inf", "R_nan", "R_inf_diag", "R_inf_off"])
def test_non_finite_input_raises_and_state_unchanged(bad: str) -> None:
    x0 = np.array([1.0, 2.0, 0.0, 0.0, 0.0, 0.0])
    kf = ExtendedKalmanFilter(x0, np.eye(6))
    H = np.hstack([np.eye(3), np.zeros((3, 3))])
    z = np.array([1.0, 2.0, 0.5])
    R = np.eye(3)
    if bad == "z_nan":
        z[1] = np.nan
    elif bad == "z_inf":
        z[2] = np.inf
    elif bad == "R_nan":
        R[0, 0] = np.nan
    elif bad == "R_inf_diag":
        R[1, 1] = np.inf
    else:
        R[0, 2] = R[2, 0] = -np.inf
    with pytest.raises(ValueError, match=r"z contains|R contains"):
        kf.update(z, lambda x: (H @ x, H), R)
    np.testing.assert_array_equal(kf.x, x0)
    np.testing.assert_array_equal(kf.P, np.eye(6))


@pytest.mark.parametrize("m", [1, 2])
def test_non_finite_input_raises_small_m(m: int) -> None:
    kf = ExtendedKalmanFilter(np.zeros(4), np.eye(4))
    H = H_POS[:m]
    with pytest.raises(ValueError, match="R contains"):
        kf.update(np.zeros(m), lambda x: (H @ x, H), np.diag([np.inf] * m))
    with pytest.raises(ValueError, match="z contains"):
        kf.update(np.full(m, np.nan), lambda x: (H @ x, H), np.eye(m))


def test_covariance_stays_exactly_symmetric() -> None:
    rng = np.random.default_rng(3)
    A = rng.normal(size=(6, 6))
    kf = ExtendedKalmanFilter(np.zeros(6), A @ A.T + np.eye(6))
    F = np.eye(6) + 0.1 * rng.normal(size=(6, 6))
    H = rng.normal(size=(3, 6))
    for _ in range(50):
        kf.predict(lambda x: (F @ x, F), 0.01 * np.eye(6))
        assert np.array_equal(kf.P, kf.P.T)
        kf.update(rng.normal(size=3), lambda x: (H @ x, H), np.diag([0.1, 0.2, 0.3]))
        assert np.array_equal(kf.P, kf.P.T)
        assert np.all(np.linalg.eigvalsh(kf.P) > 0)


def test_nis_is_chi_square_distributed() -> None:
    """A consistent filter on a correctly modelled system: mean NIS = dim z."""
    rng = np.random.default_rng(2025)
    q, n_runs, n_steps = 0.02, 50, 60
    Q = process_noise(DT, q, dim=2)
    R = np.array([[0.2, 0.03], [0.03, 0.1]])
    Lq, Lr = np.linalg.cholesky(Q), np.linalg.cholesky(R)
    P0 = np.diag([1.0, 1.0, 0.25, 0.25])
    nis = []
    for _ in range(n_runs):
        truth = np.array([0.0, 0.0, 1.0, -0.5])
        kf = ExtendedKalmanFilter(truth + np.linalg.cholesky(P0) @ rng.normal(size=4), P0)
        for _ in range(n_steps):
            truth = F_CV @ truth + Lq @ rng.normal(size=4)
            z = H_POS @ truth + Lr @ rng.normal(size=2)
            kf.predict(_linear_f, Q)
            nis.append(kf.update(z, _linear_h, R).nis)
    total = float(np.sum(nis))
    dof = 2 * len(nis)
    lo, hi = chi2.ppf([0.005, 0.995], dof)
    assert lo < total < hi, (total / len(nis), lo / len(nis), hi / len(nis))


def test_process_noise_matches_filterpy() -> None:
    for dim in (1, 2, 3):
        for dt, q in ((0.5, 2.0), (10.0, 1e-9), (60.0, 3e-12)):
            ref = Q_continuous_white_noise(
                dim=2, dt=dt, spectral_density=q, block_size=dim, order_by_dim=False
            )
            np.testing.assert_allclose(process_noise(dt, q, dim=dim), ref, rtol=1e-14, atol=0)
    np.testing.assert_allclose(process_noise(-3.0, 1.0), process_noise(3.0, 1.0))


def test_constructor_validates() -> None:
    with pytest.raises(ValueError):
        ExtendedKalmanFilter(np.zeros(3), np.eye(2))
    with pytest.raises(ValueError):
        ExtendedKalmanFilter([0.0, np.nan], np.eye(2))
    kf = ExtendedKalmanFilter([1.0, 2.0], [[1.0, 0.0], [0.0, 1.0]])
    assert math.isnan(kf.nis)
    assert kf.x.dtype == np.float64


def test_bound_covariance_limits_sigmas_and_keeps_correlations():
    from ssa_fusion.core.filter.ekf import bound_covariance

    x = np.array([7000.0, 0.0, 0.0, 0.0, 7.5, 0.0])  # km, km/s
    A = np.random.default_rng(1).standard_normal((6, 6))
    d = np.repeat([3e4, 1.0], 3)
    P = A @ A.T * np.outer(d, d)  # position sigma ~3e4 km: beyond 2|r|
    B = bound_covariance(x, P, 2.0)
    sig, sig_b = np.sqrt(np.diag(P)), np.sqrt(np.diag(B))
    cap = np.repeat([14000.0, 15.0], 3)
    np.testing.assert_allclose(sig_b, np.minimum(sig, cap), rtol=1e-12)
    corr = P / np.outer(sig, sig)
    np.testing.assert_allclose(B / np.outer(sig_b, sig_b), corr, atol=1e-12)
    assert np.linalg.eigvalsh(B).min() > -1e-9 * np.abs(B).max()
    assert np.array_equal(bound_covariance(x, P, 0.0), P)
    small = np.diag([1.0, 1.0, 1.0, 1e-6, 1e-6, 1e-6])
    assert np.array_equal(bound_covariance(x, small, 2.0), small)  # within the bound: unchanged
