"""Accuracy and consistency metrics: the paper's normalised error, NEES, NIS, chi-square bounds."""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.stats import chi2

Array = NDArray[np.float64]


def epsilon(x_hat: ArrayLike, x_true: ArrayLike) -> float:
    """Paper's normalised 2-norm error (section 3) over k samples.

    ``eps = mean_i ||xh_pos(i) - x_pos(i)|| / max_j ||x_pos(j)||
                + ||xh_vel(i) - x_vel(i)|| / max_j ||x_vel(j)||``

    ``x_hat``, ``x_true``: (k, 2d); the first d columns are "position", the last d "velocity"
    (d = 3 for orbits, d = 1 for the pendulum [theta, theta_dot] and Van der Pol [x, x_dot]).
    The maxima are over the true trajectory's norms. Dimensionless.
    """
    xh = np.atleast_2d(np.asarray(x_hat, float))
    xt = np.atleast_2d(np.asarray(x_true, float))
    if xh.shape != xt.shape or xh.shape[1] % 2:
        raise ValueError(f"need equal (k, 2d) shapes, got {xh.shape} and {xt.shape}")
    d = xh.shape[1] // 2
    err = xh - xt
    pos_scale = np.max(np.linalg.norm(xt[:, :d], axis=1))
    vel_scale = np.max(np.linalg.norm(xt[:, d:], axis=1))
    e_pos = np.linalg.norm(err[:, :d], axis=1) / pos_scale
    e_vel = np.linalg.norm(err[:, d:], axis=1) / vel_scale
    return float(np.mean(e_pos + e_vel))


def _mahalanobis_sq(v: ArrayLike, C: ArrayLike) -> Array:
    """``v^T C^-1 v`` per sample: v (k, n) or (n,), C (k, n, n) or (n, n) -> (k,)."""
    vv = np.asarray(v, float)
    cc = np.asarray(C, float)
    if vv.ndim == 1:
        vv, cc = vv[None], cc[None]
    sol = np.linalg.solve(cc, vv[..., None])[..., 0]
    out: Array = np.einsum("ki,ki->k", vv, sol)
    return out


def nees(err: ArrayLike, P: ArrayLike) -> Array:
    """Normalised estimation error squared ``e^T P^-1 e``: err (k, n), P (k, n, n) -> (k,)."""
    return _mahalanobis_sq(err, P)


def nis(y: ArrayLike, S: ArrayLike) -> Array:
    """Normalised innovation squared ``y^T S^-1 y`` per sample: y (k, m), S (k, m, m) -> (k,)."""
    return _mahalanobis_sq(y, S)


def chi2_bounds(dof: int, n_runs: int = 1, alpha: float = 0.05) -> tuple[float, float]:
    """Two-sided (1 - alpha) acceptance interval for the mean of ``n_runs`` chi-square(dof) values.

    ``N * mean ~ chi2(N * dof)`` so the bounds are ``chi2.ppf([alpha/2, 1 - alpha/2], N dof) / N``
    (Bar-Shalom's NEES/NIS consistency test).
    """
    k = int(dof) * int(n_runs)
    lo = float(chi2.ppf(alpha / 2.0, k)) / n_runs
    hi = float(chi2.ppf(1.0 - alpha / 2.0, k)) / n_runs
    return lo, hi
