"""Tests for ssa_fusion.core.base.metrics against hand computations and scipy."""

import numpy as np
import pytest
from scipy.stats import chi2

from ssa_fusion.core.base.metrics import chi2_bounds, epsilon, nees, nis


def test_epsilon_hand_computation():
    x_true = np.array([[3.0, 4.0, 0.0, 0.0, 1.0, 0.0], [6.0, 8.0, 0.0, 0.0, 2.0, 0.0]])
    x_hat = x_true.copy()
    x_hat[0, 0] += 1.0  # pos error 1 / max|pos| 10
    x_hat[1, 3:] += [0.0, 0.0, 0.5]  # vel error 0.5 / max|vel| 2
    assert epsilon(x_hat, x_true) == pytest.approx((0.1 + 0.25) / 2)
    assert epsilon(x_true, x_true) == 0.0


def test_epsilon_two_state_system():
    x_true = np.array([[1.0, -2.0], [-0.5, 4.0]])
    x_hat = np.array([[1.5, -2.0], [-0.5, 3.0]])
    assert epsilon(x_hat, x_true) == pytest.approx((0.5 / 1.0 + 1.0 / 4.0) / 2)
    with pytest.raises(ValueError):
        epsilon(x_hat[:, :1], x_true[:, :1])


def test_nees_nis_against_direct_formula():
    rng = np.random.default_rng(0)
    k, n = 7, 6
    A = rng.normal(size=(k, n, n))
    P = A @ np.transpose(A, (0, 2, 1)) + n * np.eye(n)
    e = rng.normal(size=(k, n))
    ref = [ei @ np.linalg.inv(Pi) @ ei for ei, Pi in zip(e, P, strict=True)]
    np.testing.assert_allclose(nees(e, P), ref, rtol=1e-10)
    np.testing.assert_allclose(nis(e[:, :3], P[:, :3, :3]),
                               [ei[:3] @ np.linalg.inv(Pi[:3, :3]) @ ei[:3]
                                for ei, Pi in zip(e, P, strict=True)], rtol=1e-10)
    assert nees(e[0], P[0]).shape == (1,)


def test_nees_of_consistent_samples_lies_in_chi2_bounds():
    rng = np.random.default_rng(42)
    n, runs = 6, 2000
    L = np.tril(rng.normal(size=(n, n))) + 3 * np.eye(n)
    P = L @ L.T
    e = rng.normal(size=(runs, n)) @ L.T
    lo, hi = chi2_bounds(n, n_runs=runs, alpha=0.01)
    assert lo < np.mean(nees(e, np.broadcast_to(P, (runs, n, n)))) < hi


def test_chi2_bounds_values():
    lo, hi = chi2_bounds(3)
    assert lo == pytest.approx(0.2158, abs=1e-4) and hi == pytest.approx(9.3484, abs=1e-4)
    lo, hi = chi2_bounds(6, n_runs=50, alpha=0.05)
    assert lo == pytest.approx(chi2.ppf(0.025, 300) / 50)
    assert hi == pytest.approx(chi2.ppf(0.975, 300) / 50)
    assert lo < 6 < hi
