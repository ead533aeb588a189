"""Extended Kalman filter with Joseph-form update, angle-aware residuals and NIS gating.

Naming follows FilterPy (``x, P, x_prior, P_prior, x_post, P_post, y, S, K``) so that the
filter can be checked against :class:`filterpy.kalman.ExtendedKalmanFilter`.  The model
functions are passed per call, so one filter serves any dynamics / sensor:

* ``predict(f, Q)`` with ``f(x) -> (x_new, F)`` (``F = d x_new / d x``),
* ``update(z, h, R, angle_mask, gate)`` with ``h(x) -> (z_pred, H)`` (``H = dh/dx``).

Units are whatever the caller uses consistently (the orbit filters use km, km/s, rad, s in
an inertial frame).  The hot path is tuned for small state/measurement sizes (n = 6,
m = 1..3): scalar work in :mod:`math`, closed-form 1x1 / 3x3 innovation inverses.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import NamedTuple, cast

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ssa_fusion.core.earth.frames import wrap_angle

__all__ = ["ExtendedKalmanFilter", "UpdateResult", "process_noise"]


Array = NDArray[np.float64]
PredictFn = Callable[[Array], tuple[Array, Array]]
MeasureFn = Callable[[Array], tuple[Array, Array]]


class UpdateResult(NamedTuple):
    """Outcome of :meth:`ExtendedKalmanFilter.update`.

    Attributes
    ----------
    accepted : bool
        True if the measurement was fused (passed the gate).
    nis : float
        Normalized innovation squared ``y^T S^-1 y`` (reported also when rejected).
    y : ndarray, shape (m,)
        Innovation ``z - h(x_prior)``, angle channels wrapped to (-pi, pi].
    """

    accepted: bool
    nis: float
    y: Array


def _inv_sym(s: Array) -> Array:
    """Inverse of a small symmetric positive-definite innovation covariance."""
    m = s.shape[0]
    if m == 1:
        v = float(s[0, 0])
        if math.isfinite(v) and v != 0.0:
            return np.array(((1.0 / v,),))
        return np.full((1, 1), math.nan)
    if m == 3:
        (a, b, c), (_, d, e), (_, _, f) = s.tolist()
        c11 = d * f - e * e
        c12 = c * e - b * f
        c13 = b * e - c * d
        det = a * c11 + b * c12 + c * c13
        if not math.isfinite(det):
            return np.full((3, 3), math.nan)
        if det > 0.0:
            i = 1.0 / det
            c12 *= i
            c13 *= i
            c23 = (b * c - a * e) * i
            return np.array((
                (c11 * i, c12, c13),
                (c12, (a * f - c * c) * i, c23),
                (c13, c23, (a * d - b * b) * i),
            ))
    if not np.isfinite(s).all():
        return np.full((m, m), math.nan)
    return cast(Array, np.linalg.inv(s))


class GaussianFilter:
    """What the Kalman filters share: a Gaussian estimate, its checks, snapshots.

    Parameters
    ----------
    x0 : array_like, shape (n,)
        Initial state estimate.
    P0 : array_like, shape (n, n)
        Initial covariance (symmetric positive definite; it is symmetrised).

    Attributes
    ----------
    x, P, x_prior, P_prior, x_post, P_post, y, S, K, nis
        As `ExtendedKalmanFilter` describes them.
    """

    def __init__(self, x0: ArrayLike, P0: ArrayLike) -> None:
        x = np.array(x0, dtype=float).reshape(-1)
        P = np.array(P0, dtype=float)
        n = x.shape[0]
        if P.shape != (n, n):
            raise ValueError(f"P0 must have shape ({n}, {n}), got {P.shape}")
        if not (np.isfinite(x).all() and np.isfinite(P).all()):
            raise ValueError("x0 and P0 must be finite")
        self.dim_x = n
        self.x: Array = x
        self.P: Array = 0.5 * (P + P.T)
        self.x_prior: Array = self.x.copy()
        self.P_prior: Array = self.P.copy()
        self.x_post: Array = self.x.copy()
        self.P_post: Array = self.P.copy()
        self.y: Array | None = None
        self.S: Array | None = None
        self.K: Array | None = None
        self.nis: float = math.nan

    def snapshot(self) -> tuple[Array, Array]:
        """Return copies of the current estimate, for :meth:`restore`.

        Returns
        -------
        x : ndarray, shape (n,)
            Copy of ``x``.
        P : ndarray, shape (n, n)
            Copy of ``P``.
        """
        return self.x.copy(), self.P.copy()

    def restore(self, x: ArrayLike, P: ArrayLike) -> None:
        """Set the current estimate back to (copies of) a :meth:`snapshot`.

        Only ``x`` and ``P`` are set; the diagnostics of the last step (``x_prior``,
        ``x_post``, ``y``, ``S``, ``K``, ``nis``, ...) are left as they are.

        Parameters
        ----------
        x : array_like, shape (n,)
            Estimate to restore.
        P : array_like, shape (n, n)
            Its covariance.
        """
        self.x = np.array(x, dtype=float)
        self.P = np.array(P, dtype=float)


class ExtendedKalmanFilter(GaussianFilter):
    """Extended Kalman filter (FilterPy-like attributes).

    Parameters
    ----------
    x0 : array_like, shape (n,)
        Initial state estimate.
    P0 : array_like, shape (n, n)
        Initial state covariance (symmetric positive definite).

    Attributes
    ----------
    x, P : ndarray
        Current estimate and covariance (posterior after ``update``, prior after
        ``predict``).  Replaced (never modified in place) by each step.
    x_prior, P_prior : ndarray
        Copies of the estimate after the last ``predict``.
    x_post, P_post : ndarray
        Copies of the estimate after the last ``update`` (unchanged if it was rejected).
    y, S, K : ndarray or None
        Innovation, innovation covariance and gain of the last ``update`` (``K`` is None
        when the update was rejected by the gate).
    nis : float
        Normalized innovation squared of the last ``update`` (NaN before any).
    """

    def __init__(self, x0: ArrayLike, P0: ArrayLike) -> None:
        super().__init__(x0, P0)
        self._eye = np.eye(self.dim_x)

    def predict(self, f: PredictFn, Q: ArrayLike) -> None:
        """Propagate the estimate: ``x <- f(x)``, ``P <- F P F^T + Q``.

        Parameters
        ----------
        f : callable
            ``f(x) -> (x_new, F)`` with ``F`` the (n, n) Jacobian of ``x_new``.
        Q : array_like, shape (n, n)
            Process noise covariance accumulated over the step.
        """
        x, F = f(self.x)
        P = F.dot(self.P).dot(F.T) + Q
        P = P + P.T
        P *= 0.5
        self.x = x = np.asarray(x, dtype=float)
        self.P = P
        self.x_prior = x.copy()
        self.P_prior = P.copy()

    def update(
        self,
        z: ArrayLike,
        h: MeasureFn,
        R: ArrayLike,
        angle_mask: Sequence[bool] | None = None,
        gate: float | None = None,
    ) -> UpdateResult:
        """Fuse one measurement (Joseph-form covariance update).

        Parameters
        ----------
        z : array_like, shape (m,)
            Measurement.
        h : callable
            ``h(x) -> (z_pred, H)``: predicted measurement (m,) and its Jacobian (m, n).
        R : array_like, shape (m, m)
            Measurement noise covariance.
        angle_mask : sequence of bool, optional
            True for channels that are angles (rad): their residual is wrapped to
            (-pi, pi].
        gate : float, optional
            Chi-square threshold on the NIS ``y^T S^-1 y``; if exceeded the measurement
            is rejected and ``x``/``P`` are left unchanged.

        Returns
        -------
        UpdateResult
            ``(accepted, nis, y)``.

        Raises
        ------
        ValueError
            If ``z`` or ``R`` (or the predicted measurement) contain NaN/inf, or the
            shapes are inconsistent.
        """
        z = np.asarray(z, dtype=float).reshape(-1)
        R = np.asarray(R, dtype=float)
        m = z.shape[0]
        if R.shape != (m, m):
            raise ValueError(f"R must have shape ({m}, {m}) for a {m}-vector z, got {R.shape}")

        x = self.x
        P = self.P
        zp, H = h(x)
        y = z - zp
        if angle_mask is not None:
            for i, is_angle in enumerate(angle_mask):
                if is_angle:
                    y[i] = wrap_angle(float(y[i]))
        PHt = P.dot(H.T)
        S = H.dot(PHt) + R
        Si = _inv_sym(S)
        nis = float(y.dot(Si.dot(y)))
        if not math.isfinite(nis):  # NaN/inf anywhere in z, R, h(x) or P ends up here
            _raise_non_finite(z, R, zp, S)
        self.y = y
        self.S = S
        self.nis = nis
        if gate is not None and nis > gate:
            self.K = None
            self.x_post = x.copy()
            self.P_post = P.copy()
            return UpdateResult(False, nis, y)

        K = PHt.dot(Si)
        self.K = K
        self.x = x = x + K.dot(y)
        A = self._eye - K.dot(H)
        P = A.dot(P).dot(A.T) + K.dot(R).dot(K.T)
        P = P + P.T
        P *= 0.5
        self.P = P
        self.x_post = x.copy()
        self.P_post = P.copy()
        return UpdateResult(True, nis, y)


def _raise_non_finite(z: Array, R: Array, zp: Array, S: Array) -> None:
    """Raise a ValueError naming the first non-finite input of an update."""
    if not np.isfinite(z).all():
        raise ValueError(f"measurement z contains NaN/inf: {z}")
    if not np.isfinite(R).all():
        raise ValueError(f"measurement covariance R contains NaN/inf: {R.tolist()}")
    if not np.isfinite(zp).all():
        raise ValueError(f"predicted measurement h(x) contains NaN/inf: {zp}")
    raise ValueError(f"non-finite or singular innovation covariance (S = {S.tolist()})")


def process_noise(dt_s: float, q: float, dim: int = 3) -> Array:
    """Continuous white-noise-acceleration process noise for a ``[pos, vel]`` state.

    Parameters
    ----------
    dt_s : float
        Step length, s (its sign is ignored).
    q : float
        Acceleration power spectral density, km^2/s^3 (so ``Q`` is in km^2, km^2/s, km^2/s^2).
    dim : int, optional
        Number of position axes (3 for orbits, 1 for a pendulum angle).

    Returns
    -------
    ndarray, shape (2*dim, 2*dim)
        ``q * [[dt^3/3 I, dt^2/2 I], [dt^2/2 I, dt I]]`` with states ordered
        ``[p_1..p_dim, v_1..v_dim]``.
    """
    dt = abs(float(dt_s))
    Q = np.zeros((2 * dim, 2 * dim))  # the Kronecker product by hand (np.kron: ~50 us)
    i = np.arange(dim)
    Q[i, i] = q * dt**3 / 3.0
    Q[i, i + dim] = Q[i + dim, i] = q * dt**2 / 2.0
    Q[i + dim, i + dim] = q * dt
    return Q


def bound_covariance(x: ArrayLike, P: ArrayLike, factor: float) -> Array:
    """Limit the standard deviations of a ``[pos, vel]`` state's covariance.

    Each position standard deviation is limited to ``factor * |pos|`` and each velocity one
    to ``factor * |vel|`` (for an orbit, ``factor`` 2: the orbit's diameter and twice its
    speed, beyond which the object could be anywhere on its orbit and a linear covariance
    means nothing). Rows and columns over the limit are scaled, ``P <- D P D``, so the
    correlations are kept and P stays positive semi-definite.

    Parameters
    ----------
    x : array_like, shape (2*dim,)
        State ``[p_1..p_dim, v_1..v_dim]`` (any units; the limit is relative).
    P : array_like, shape (2*dim, 2*dim)
        Its covariance.
    factor : float
        The limit relative to the norms; 0 or inf: no limit (P is returned unchanged).

    Returns
    -------
    ndarray, shape (2*dim, 2*dim)
    """
    P = np.asarray(P, dtype=float)
    if not factor or not math.isfinite(factor):
        return P
    x = np.asarray(x, dtype=float)
    h = len(x) // 2
    cap = np.repeat([factor * np.linalg.norm(x[:h]), factor * np.linalg.norm(x[h:])],
                    [h, len(x) - h])
    sig = np.sqrt(np.clip(np.diag(P), 0.0, None))
    over = (sig > cap) & (cap > 0.0)
    if not over.any():
        return P
    s = np.where(over, cap / np.where(over, sig, 1.0), 1.0)
    return cast(Array, P * s[:, None] * s[None, :])
