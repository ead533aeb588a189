"""Tests for ssa_fusion.core.filter.process_noise: SNC and DMC in the orbit's RTN axes.

References: `ekf.process_noise` (isotropic white noise, filterpy's Q_continuous_white_noise),
Van Loan's matrix exponential for the discrete Gauss-Markov transition and noise (scipy's
expm), the double integral of the Gauss-Markov autocorrelation (scipy's dblquad), and the
limits derived in the module docstring.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.integrate import dblquad
from scipy.linalg import expm
from scipy.spatial.transform import Rotation

from ssa_fusion.core.filter import process_noise as pn
from ssa_fusion.core.filter.ekf import process_noise

X = np.array([6000.0, 2500.0, 1200.0, -2.5, 6.0, 3.5])


def _van_loan(T: float, tau: float, sigma: float) -> tuple[np.ndarray, np.ndarray]:
    b = 1.0 / tau
    A = np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [0.0, 0.0, -b]])
    M = np.zeros((6, 6))
    M[:3, :3] = -A
    M[2, 5] = 2.0 * sigma**2 * b
    M[3:, 3:] = A.T
    E = expm(M * T)
    phi = E[3:, 3:].T
    return phi, phi @ E[:3, 3:]


@pytest.mark.parametrize("dt", [1.0, 60.0, 3600.0])
def test_snc_equal_psds_is_white_noise(dt: float) -> None:
    np.testing.assert_allclose(pn.snc(X, dt, 1e-12), process_noise(dt, 1e-12),
                               rtol=1e-13, atol=0)
    np.testing.assert_allclose(pn.snc(X, dt, (3e-12, 3e-12, 3e-12)),
                               process_noise(dt, 3e-12), rtol=1e-13, atol=0)


def test_snc_is_rotation_covariant() -> None:
    psd = (1e-12, 5e-11, 2e-13)
    R = Rotation.from_rotvec([0.3, -1.1, 0.7]).as_matrix()
    B = np.kron(np.eye(2), R)
    q = pn.snc(X, 60.0, psd)
    np.testing.assert_allclose(pn.snc(B @ X, 60.0, psd), B @ q @ B.T, rtol=0,
                               atol=1e-12 * np.abs(q).max())


def test_snc_acts_along_its_axes() -> None:
    q = pn.snc(X, 60.0, (0.0, 1e-12, 0.0))  # along-track only
    m = pn.rtn_matrix(X)
    t_hat = m[:, 1]
    np.testing.assert_allclose(q[3:, 3:], 60.0 * 1e-12 * np.outer(t_hat, t_hat), atol=1e-25)
    assert abs(t_hat @ X[3:] / np.linalg.norm(X[3:])) > 0.99  # nearly the velocity


def test_snc_backwards_step_correlates_negatively() -> None:
    q_fwd, q_back = pn.snc(X, 60.0, 1e-12), pn.snc(X, -60.0, 1e-12)
    np.testing.assert_allclose(q_back[:3, :3], q_fwd[:3, :3])
    np.testing.assert_allclose(q_back[:3, 3:], -q_fwd[:3, 3:])


@pytest.mark.parametrize(("T", "tau"), [(60.0, 600.0), (60.0, 30.0), (60.0, 59.9),
                                        (60.0, 60.1), (10.0, 1e5), (600.0, 100.0)])
def test_gauss_markov_is_van_loan(T: float, tau: float) -> None:
    phi, Q = pn.gauss_markov(T, tau, 1e-8)
    phi_ref, Q_ref = _van_loan(T, tau, 1e-8)
    np.testing.assert_allclose(phi, phi_ref, rtol=1e-12, atol=1e-15)
    scale = np.sqrt(np.outer(np.diag(Q_ref), np.diag(Q_ref)))
    np.testing.assert_allclose(Q / scale, Q_ref / scale, rtol=0, atol=1e-11)


@pytest.mark.filterwarnings("ignore::scipy.integrate.IntegrationWarning")
@pytest.mark.parametrize(("T", "tau"), [(60.0, 600.0), (60.0, 20.0), (60.0, 60.0)])
def test_equivalent_q_is_the_autocorrelation_integral(T: float, tau: float) -> None:
    def k(a: float, b: float) -> float:
        return float(np.exp(-abs(a - b) / tau))

    vv = dblquad(k, 0, T, 0, T, epsrel=1e-10)[0]
    rv = dblquad(lambda a, b: (T - a) * k(a, b), 0, T, 0, T, epsrel=1e-10)[0]
    rr = dblquad(lambda a, b: (T - a) * (T - b) * k(a, b), 0, T, 0, T, epsrel=1e-10)[0]
    q = pn.dmc_equivalent_q(X, T, tau, 1.0)
    m = pn.rtn_matrix(X)
    qa = m.T @ q[:3, :3] @ m, m.T @ q[:3, 3:] @ m, m.T @ q[3:, 3:] @ m
    np.testing.assert_allclose([qa[0][0, 0], qa[1][0, 0], qa[2][0, 0]], [rr, rv, vv], rtol=1e-7)


@pytest.mark.parametrize("tau", [1e-1, 1e-3])
def test_dmc_tends_to_white_noise_for_short_tau(tau: float) -> None:
    """tau -> 0 with q = 2 sigma^2 tau fixed: both the 9-state and the equivalent 6-state Q
    tend to white noise of PSD q; the largest relative deviation is Q_rr's, 3 tau / dt to
    first order (Q_rr = q dt^3 / 3 (1 - 3 tau / dt + ...))."""
    q, T = 1e-12, 60.0
    sigma = np.sqrt(q / (2.0 * tau))
    assert pn.white_psd(tau, sigma) == pytest.approx(q)
    white = process_noise(T, q)
    _, q9 = pn.dmc(X, T, tau, sigma)
    q6 = pn.dmc_equivalent_q(X, T, tau, sigma)
    for got in (q9[:6, :6], q6):
        err = np.abs(got - white).max() / np.abs(white).max()
        assert 0.0 < err < 3.2 * tau / T


def test_equivalent_q_tends_to_random_constant_for_long_tau() -> None:
    T, s = 60.0, 1e-9
    q6 = pn.dmc_equivalent_q(X, T, 1e9, s)
    m = pn.rtn_matrix(X)
    const = s * s * np.array([[T**4 / 4, T**3 / 2], [T**3 / 2, T**2]])
    np.testing.assert_allclose((m.T @ q6[:3, :3] @ m)[1, 1], const[0, 0], rtol=1e-6)
    np.testing.assert_allclose((m.T @ q6[:3, 3:] @ m)[1, 1], const[0, 1], rtol=1e-6)
    np.testing.assert_allclose((m.T @ q6[3:, 3:] @ m)[1, 1], const[1, 1], rtol=1e-6)


def test_dmc_in_rtn() -> None:
    """The 9-state model: w along R, T, N with per-axis tau and sigma, mapped by the axes."""
    taus, sig = (100.0, 600.0, 2000.0), (1e-9, 3e-9, 5e-10)
    phi, q = pn.dmc(X, 30.0, taus, sig)
    m = pn.rtn_matrix(X)
    for a in range(3):
        p_ax, q_ax = pn.gauss_markov(30.0, taus[a], sig[a])
        np.testing.assert_allclose(phi[:3, 6 + a], m[:, a] * p_ax[0, 2])
        np.testing.assert_allclose(phi[3:6, 6 + a], m[:, a] * p_ax[1, 2])
        assert phi[6 + a, 6 + a] == pytest.approx(p_ax[2, 2])
        np.testing.assert_allclose(q[:3, 6 + a], m[:, a] * q_ax[0, 2])
        assert q[6 + a, 6 + a] == pytest.approx(q_ax[2, 2])
    np.testing.assert_allclose(q, q.T)
    assert np.linalg.eigvalsh(q).min() > -1e-12 * np.abs(q).max()
    phi6 = np.arange(36.0).reshape(6, 6)
    np.testing.assert_array_equal(pn.dmc(X, 30.0, taus, sig, phi6)[0][:6, :6], phi6)


def test_snc_batch_is_snc_step_by_step() -> None:
    xs = np.array([X, X * np.array([1, -1, 1, 1, -1, 1]), np.roll(X, 3)[[3, 4, 5, 0, 1, 2]]])
    dts = np.array([60.0, -30.0, 10.0])
    psd = (1e-12, 5e-11, 2e-13)
    q = pn.snc_batch(xs, dts, psd)
    for k in range(3):
        np.testing.assert_array_equal(q[k], pn.snc(xs[k], dts[k], psd))
