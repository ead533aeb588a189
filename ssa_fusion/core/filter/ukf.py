"""Unscented Kalman filter with the EKF's interface: `UnscentedKalmanFilter`.

Where the EKF's linearisation is the limit (long gaps, angles-only tracking) the unscented
transform carries the mean and covariance through the motion and measurement models by
``2n + 1`` sigma points instead of Jacobians (Julier and Uhlmann; the scaled points of
Van der Merwe, as FilterPy's ``MerweScaledSigmaPoints``)::

    lambda = alpha^2 (n + kappa) - n,   X_0 = x,   X_i, X_{n+i} = x +- L[:, i],
    L L^T = (n + lambda) P   (Cholesky),
    Wm_0 = lambda / (n + lambda),   Wc_0 = Wm_0 + 1 - alpha^2 + beta,
    Wm_i = Wc_i = 1 / (2 (n + lambda))

Defaults ``alpha = 1``, ``beta = 2``, ``kappa = 0`` (``lambda = 0``: no negative weight, the
points at ``sqrt(n)`` sigma; the often quoted ``alpha = 1e-3`` gives a central weight of
-1e6 for n = 6, which turns round-off of km-sized states into covariance).

The interface is `ekf.ExtendedKalmanFilter`'s, so `tracker.Tracker` could hold either:
``predict(f, Q)`` with ``f(x) -> (x_new, F)`` (F unused; ``f`` may also return x_new alone)
and ``update(z, h, R, angle_mask, gate) -> ekf.UpdateResult`` with ``h(x) -> (z, H)`` (H
unused, or z alone); the attributes ``x, P, x_prior, P_prior, x_post, P_post, y, S, K, nis``,
`snapshot` and `restore` are the EKF's. `predict_batch` takes a motion model vectorised over
the points (one `propagation.integrate_stm` call for all of them).

Angles: measurement channels flagged in ``angle_mask`` are averaged about the central
point's prediction, ``z_mean = Z_0 + sum_i Wm_i wrap(Z_i - Z_0)``, and every difference
(``Z_i - z_mean``, the innovation) is wrapped to (-pi, pi], so an azimuth crossing 0/2 pi is
handled as the EKF handles it. Each update draws its points from the current (x, P) (as
FilterPy's does after a predict); the covariance update is ``P - K S K^T``, symmetrised.

Units are the caller's (orbits: GCRF km, km/s; rad; s).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ssa_fusion.core.earth.frames import wrap_angle
from ssa_fusion.core.filter.ekf import GaussianFilter, UpdateResult, _inv_sym

__all__ = ["UnscentedKalmanFilter", "merwe_weights", "sigma_points"]

Array = NDArray[np.float64]
ModelFn = Callable[[Array], tuple[Array, Array] | Array]


def merwe_weights(n: int, alpha: float = 1.0, beta: float = 2.0,
                  kappa: float = 0.0) -> tuple[Array, Array, float]:
    """Return Van der Merwe's scaled weights (Wm, Wc) (2n+1,) and lambda (module docstring).

    Parameters
    ----------
    n : int
        State dimension.
    alpha, beta, kappa : float
        Spread, prior-distribution and secondary scaling parameters.

    Returns
    -------
    (Wm (2n+1,), Wc (2n+1,), lambda)
    """
    lam = alpha * alpha * (n + kappa) - n
    c = 0.5 / (n + lam)
    wm = np.full(2 * n + 1, c)
    wc = wm.copy()
    wm[0] = lam / (n + lam)
    wc[0] = lam / (n + lam) + (1.0 - alpha * alpha + beta)
    return wm, wc, lam


def sigma_points(x: ArrayLike, P: ArrayLike, lam: float) -> Array:
    """Return the 2n+1 scaled sigma points (2n+1, n) of mean ``x`` and covariance ``P``.

    Row 0 is ``x``, rows 1..n ``x + L[:, i]``, rows n+1..2n ``x - L[:, i]``, with
    ``L L^T = (n + lam) P`` (lower Cholesky factor; LinAlgError if P is not positive
    definite).
    """
    xx = np.asarray(x, dtype=float).reshape(-1)
    n = xx.size
    L = np.linalg.cholesky((n + lam) * np.asarray(P, dtype=float))
    pts = np.empty((2 * n + 1, n))
    pts[0] = xx
    pts[1:n + 1] = xx + L.T
    pts[n + 1:] = xx - L.T
    return pts


def _value(out: tuple[Array, Array] | Array) -> Array:
    """Return the model's value: the first of an (x, Jacobian) pair, or the array itself."""
    v = out[0] if isinstance(out, tuple) else out
    return np.asarray(v, dtype=float).reshape(-1)


class UnscentedKalmanFilter(GaussianFilter):
    """Unscented Kalman filter (the EKF's attributes and methods; module docstring).

    Parameters
    ----------
    x0 : array_like (n,)
        Initial state estimate.
    P0 : array_like (n, n)
        Initial covariance (symmetric positive definite).
    alpha, beta, kappa : float
        Sigma-point parameters (`merwe_weights`).
    """

    def __init__(self, x0: ArrayLike, P0: ArrayLike, alpha: float = 1.0, beta: float = 2.0,
                 kappa: float = 0.0) -> None:
        super().__init__(x0, P0)
        self.Wm, self.Wc, self.lam = merwe_weights(self.dim_x, alpha, beta, kappa)

    def sigma_points(self) -> Array:
        """Return the sigma points (2n+1, n) of the current estimate."""
        return sigma_points(self.x, self.P, self.lam)

    def _predicted(self, pts: Array, Q: ArrayLike) -> None:
        """Set the prior from the propagated points (2n+1, n) and the process noise."""
        x = self.Wm @ pts
        d = pts - x
        P = (d.T * self.Wc) @ d + np.asarray(Q, dtype=float)
        self.x = x
        self.P = 0.5 * (P + P.T)
        self.x_prior = self.x.copy()
        self.P_prior = self.P.copy()

    def predict(self, f: ModelFn, Q: ArrayLike) -> None:
        """Propagate the estimate through ``f`` point by point, adding ``Q``.

        Parameters
        ----------
        f : callable
            ``f(x) -> (x_new, F)`` (the EKF's; F unused) or ``f(x) -> x_new``.
        Q : array_like (n, n)
            Process noise covariance accumulated over the step.
        """
        pts = self.sigma_points()
        self._predicted(np.array([_value(f(p)) for p in pts]), Q)

    def predict_batch(self, f: Callable[[Array], Array], Q: ArrayLike) -> None:
        """`predict` with a motion model vectorised over the points: (2n+1, n) -> (2n+1, n)."""
        self._predicted(np.asarray(f(self.sigma_points()), dtype=float), Q)

    def update(self, z: ArrayLike, h: ModelFn, R: ArrayLike,
               angle_mask: Sequence[bool] | None = None,
               gate: float | None = None) -> UpdateResult:
        """Fuse one measurement by the unscented transform (module docstring).

        Parameters
        ----------
        z : array_like (m,)
            Measurement.
        h : callable
            ``h(x) -> (z_pred, H)`` (H unused) or ``h(x) -> z_pred``.
        R : array_like (m, m)
            Measurement noise covariance.
        angle_mask : sequence of bool, optional
            True for angle channels (rad): averaged and differenced with wrapping.
        gate : float, optional
            NIS threshold beyond which the measurement is rejected (x, P unchanged).

        Returns
        -------
        ekf.UpdateResult
            ``(accepted, nis, y)``.

        Raises
        ------
        ValueError
            Non-finite z, R or predicted measurement, or inconsistent shapes.
        """
        zz = np.asarray(z, dtype=float).reshape(-1)
        RR = np.asarray(R, dtype=float)
        m = zz.size
        if RR.shape != (m, m):
            raise ValueError(f"R must have shape ({m}, {m}) for a {m}-vector z, got {RR.shape}")
        pts = self.sigma_points()
        Z = np.array([_value(h(p)) for p in pts])
        if not (np.isfinite(zz).all() and np.isfinite(RR).all() and np.isfinite(Z).all()):
            raise ValueError(f"non-finite measurement, covariance or prediction (z = {zz}, "
                             f"R = {RR.tolist()})")
        mask = np.zeros(m, dtype=bool) if angle_mask is None else np.array(angle_mask, bool)
        dz0 = Z - Z[0]
        if mask.any():
            dz0[:, mask] = wrap_angle(dz0[:, mask])
        zp = Z[0] + self.Wm @ dz0
        dz = Z - zp
        y = zz - zp
        if mask.any():
            dz[:, mask] = wrap_angle(dz[:, mask])
            y[mask] = wrap_angle(y[mask])
        S = (dz.T * self.Wc) @ dz + RR
        S = 0.5 * (S + S.T)
        Si = _inv_sym(S)
        nis = float(y @ Si @ y)
        if not math.isfinite(nis):
            raise ValueError(f"non-finite or singular innovation covariance (S = {S.tolist()})")
        self.y, self.S, self.nis = y, S, nis
        if gate is not None and nis > gate:
            self.K = None
            self.x_post = self.x.copy()
            self.P_post = self.P.copy()
            return UpdateResult(False, nis, y)
        dx = pts - self.x
        Pxz = (dx.T * self.Wc) @ dz
        K = Pxz @ Si
        self.K = K
        self.x = self.x + K @ y
        P = self.P - K @ S @ K.T
        self.P = 0.5 * (P + P.T)
        self.x_post = self.x.copy()
        self.P_post = self.P.copy()
        return UpdateResult(True, nis, y)
