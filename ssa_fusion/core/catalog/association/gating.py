"""Gating: tracks predicted to a scan, every (track, detection) pair scored against the gate.

One *scan* of one station (M detections ``z`` (M, 3) [range km, azimuth rad, elevation
rad] with noise ``R`` (M, 3, 3) km^2, rad^2, at one epoch or at one epoch per detection,
Unix s UTC) against N tracks (GCRF states ``x`` (N, 6) km, km/s, covariances ``P``
(N, 6, 6), epochs ``t`` (N,) Unix s; a `track_bank.TrackBank`'s arrays):

1. *prediction* (`predict_scan`): every track is predicted to every distinct epoch of the
   scan by the bank's motion model (`batch_ekf.BatchEKF.predict`) and measured by the
   batched range/az/el model (`batch_ekf.BatchEKF.measure`): predicted measurement
   ``h(x)`` and ``H P H^T`` per track and epoch;
2. *gating* (`gate_scan`): for every (track, detection) pair the innovation
   ``y = z - h(x)`` (angles wrapped to (-pi, pi]), its covariance ``S = H P H^T + R``, the
   squared Mahalanobis distance ``d^2 = y^T S^-1 y`` and the cost ``d^2 + ln det S`` (the
   negative log-likelihood of the pair up to a constant); a pair is feasible when ``d^2``
   is within the chi-square gate (`config.AssociationConfig.gate`: probability
   ``gate_probability`` of a chi-square law with 3 degrees of freedom).

Costs need no Python loop over tracks or detections: the (N, M) arrays are computed at once
(O(N M) memory: a scan of 50 detections against 10,000 tracks is 5e5 pairs, ~40 MB).
`gate_long_arc` rescores the gated pairs by the long-arc predictor (`manager.Associator`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ssa_fusion.core.catalog.batch_ekf import BatchEKF

__all__ = ["Gated", "ScanPrediction", "gate_long_arc", "gate_scan", "predict_scan", "whitened"]

Array = NDArray[np.float64]
BoolArray = NDArray[np.bool_]
IntArray = NDArray[np.int64]


@dataclass(frozen=True)
class ScanPrediction:
    """Tracks predicted to the epochs of a scan (`predict_scan`).

    Attributes
    ----------
    epochs : ndarray (K,)
        The scan's distinct epochs, Unix s.
    epoch_index : ndarray (M,) of int
        Index in `epochs` of each detection's epoch.
    zp : ndarray (K, N, 3)
        Predicted measurement of every track at every epoch [km, rad in [0, 2 pi), rad].
    HPHt : ndarray (K, N, 3, 3)
        ``H P H^T`` at those predictions (km^2, km rad, rad^2).
    ok : ndarray (K, N) of bool
        False where the prediction was not computable.
    sigma_pos : ndarray (K, N)
        Largest standard deviation of each predicted position, km (the square root of the
        largest eigenvalue of its 3 x 3 covariance).
    zp_rate : ndarray (K, N, 3) or None
        Rate of each predicted measurement with a shift of its track along its orbit,
        [km/s, rad/s, rad/s] per s of shift (the track a time ``s`` ahead of its
        prediction, measured at the same epoch: ``zp + zp_rate s`` to first order;
        ``H v``, v the predicted GCRF velocity); None when not computed.
    speed : ndarray (K, N) or None
        Predicted speed of each track, km/s (GCRF); None when not computed.
    """

    epochs: Array
    epoch_index: IntArray
    zp: Array
    HPHt: Array
    ok: BoolArray
    sigma_pos: Array
    zp_rate: Array | None = None
    speed: Array | None = None


@dataclass(frozen=True)
class Gated:
    """Every (track, detection) pair of a scan scored (`gate_scan`).

    Attributes
    ----------
    d2 : ndarray (N, M)
        Squared Mahalanobis distance of each pair (inf where not computable).
    cost : ndarray (N, M)
        ``d^2 + ln det S`` (S in km^2, rad^2; inf where not computable).
    feasible : ndarray (N, M) of bool
        ``d^2`` within the gate.
    """

    d2: Array
    cost: Array
    feasible: BoolArray



def predict_scan(ekf: BatchEKF, x: ArrayLike, P: ArrayLike, t_track: ArrayLike,
                 t_scan: ArrayLike, station: int) -> ScanPrediction:
    """Predict N tracks to the epochs of one station's scan and measure them there.

    Parameters
    ----------
    ekf : BatchEKF
        The tracks' filter (its motion model and stations; a `track_bank.TrackBank`'s
        ``ekf``).
    x, P : array_like (N, 6), (N, 6, 6)
        GCRF states km, km/s at `t_track` and their covariances.
    t_track : array_like (N,)
        Epochs of the states, s after the filter's jd0 (Unix s by default).
    t_scan : array_like (M,) or scalar
        Epoch of each detection (or of the whole scan), same clock.
    station : int
        Index of the scanning station in ``ekf.stations``.
    """
    X = np.asarray(x, dtype=float).reshape(-1, 6)
    PP = np.asarray(P, dtype=float).reshape(-1, 6, 6)
    t0 = np.asarray(t_track, dtype=float).reshape(-1)
    ts = np.atleast_1d(np.asarray(t_scan, dtype=float))
    epochs, index = np.unique(ts, return_inverse=True)
    n, k = X.shape[0], epochs.size
    dt = (epochs[:, None] - t0[None, :]).reshape(-1)
    pred = ekf.predict(np.tile(X, (k, 1)), np.tile(PP, (k, 1, 1)), dt, np.tile(t0, k))
    tt = np.repeat(epochs, n)
    zp, H = ekf.measure(pred.x, tt, np.full(k * n, station, dtype=np.intp))
    HPHt = np.matmul(np.matmul(H, pred.P), np.swapaxes(H, -1, -2))
    ok = pred.ok & np.isfinite(zp).all(-1) & np.isfinite(HPHt).all((-1, -2))
    Pr = np.where(ok[:, None, None], pred.P[:, :3, :3], 0.0)
    sigma = np.sqrt(np.clip(np.linalg.eigvalsh(Pr)[:, -1], 0.0, None))
    v = pred.x[:, 3:]
    rate = np.einsum("mij,mj->mi", H[:, :, :3], v)
    return ScanPrediction(epochs, index.reshape(-1).astype(np.int64),
                          zp.reshape(k, n, 3), HPHt.reshape(k, n, 3, 3), ok.reshape(k, n),
                          np.where(ok, sigma, np.inf).reshape(k, n), rate.reshape(k, n, 3),
                          np.linalg.norm(v, axis=-1).reshape(k, n))


def gate_scan(prediction: ScanPrediction, z: ArrayLike, R: ArrayLike, gate: float) -> Gated:
    """Score every (track, detection) pair of a scan (module docstring, step 2).

    Parameters
    ----------
    prediction : ScanPrediction
        The N tracks predicted to the scan (`predict_scan`).
    z : array_like (M, 3)
        Detections [range km, azimuth rad, elevation rad].
    R : array_like (M, 3, 3) or (3, 3)
        Their noise covariances, km^2, rad^2.
    gate : float
        Threshold on ``d^2`` (`AssociationConfig.gate`).
    """
    w, _, ok, logdet = whitened(prediction, z, R)
    d2 = np.full(ok.shape, np.inf)
    cost = np.full(ok.shape, np.inf)
    d2[ok] = np.einsum("ij,ij->i", w, w)
    cost[ok] = d2[ok] + logdet
    return Gated(d2, cost, d2 <= gate)


def whitened(prediction: ScanPrediction, z: ArrayLike,
              R: ArrayLike) -> tuple[Array, Array | None, BoolArray, Array]:
    """Whitened innovations of every computable (track, detection) pair.

    Returns ``w = L^-1 y`` (P, 3) and ``u = L^-1 zp_rate`` (P, 3) (None without
    ``zp_rate``) for the P pairs where ``ok`` (N, M) holds (``L L^T = S``, angles of ``y``
    wrapped to (-pi, pi]), and ``ln det S`` (P,).
    """
    zz = np.asarray(z, dtype=float).reshape(-1, 3)
    m = zz.shape[0]
    RR = np.broadcast_to(np.asarray(R, dtype=float), (m, 3, 3))
    e = prediction.epoch_index
    zp = np.swapaxes(prediction.zp[e], 0, 1)  # (N, M, 3): track i at detection j's epoch
    y = zz[None, :, :] - zp
    y[..., 1:] = math.pi - np.mod(math.pi - y[..., 1:], 2.0 * math.pi)  # (-pi, pi]
    S = np.swapaxes(prediction.HPHt[e], 0, 1) + RR[None]  # (N, M, 3, 3)
    ok = np.swapaxes(prediction.ok[e], 0, 1) & np.isfinite(y).all(-1) & np.isfinite(S).all(
        (-1, -2))
    S = np.where(ok[..., None, None], 0.5 * (S + np.swapaxes(S, -1, -2)), np.eye(3))
    if not ok.any():
        return np.zeros((0, 3)), np.zeros((0, 3)), ok, np.zeros(0)
    L = np.linalg.cholesky(S[ok])  # LinAlgError only for a non-positive S: below
    w = np.linalg.solve(L, y[ok][..., None])[..., 0]
    u = None
    if prediction.zp_rate is not None:
        rate = np.swapaxes(prediction.zp_rate[e], 0, 1)  # (N, M, 3)
        u = np.linalg.solve(L, rate[ok][..., None])[..., 0]
    return w, u, ok, 2.0 * np.log(np.diagonal(L, axis1=-2, axis2=-1)).sum(-1)


def gate_long_arc(wide: Gated, fine: Gated, which: IntArray) -> Gated:
    """Rescore gated pairs by a long-arc predictor (`Associator`'s, `AssociationConfig`).

    Parameters
    ----------
    wide : Gated
        The N tracks' pairs scored by the tracks' own filter (`gate_scan`): its gate
        decides which pairs are feasible (its process noise covers what its motion model
        leaves out, so a detection it expects is never left out).
    fine : Gated
        The tracks ``which`` (rows of ``wide``) scored by the long-arc predictor (a filter
        of the same tracks with small process noise: a sharp along-track prediction across
        long gaps).
    which : ndarray (K,) of int
        The rows of ``wide`` that ``fine`` scores.

    Returns
    -------
    Gated
        ``wide``'s feasibility; ``d2`` and ``cost`` the long-arc predictor's where it
        computed them, the tracks' filter's elsewhere.
    """
    d2, cost = wide.d2.copy(), wide.cost.copy()
    sharp = np.isfinite(fine.cost)
    d2[which] = np.where(sharp, fine.d2, wide.d2[which])
    cost[which] = np.where(sharp, fine.cost, wide.cost[which])
    return Gated(d2, cost, wide.feasible)


