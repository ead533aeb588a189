"""Association of unlabelled radar detections with tracks: gating and global nearest neighbour.

A radar does not label its detections with an object id. One *scan* of one station (M
detections ``z`` (M, 3) [range km, azimuth rad, elevation rad] with noise ``R`` (M, 3, 3)
km^2, rad^2, at one epoch or at one epoch per detection, Unix s UTC) is associated with N
tracks (GCRF states ``x`` (N, 6) km, km/s, covariances ``P`` (N, 6, 6), epochs ``t`` (N,)
Unix s; a `track_bank.TrackBank`'s arrays) in three vectorised steps:

1. *prediction* (`predict_scan`): every track is predicted to every distinct epoch of the
   scan by the bank's motion model (`batch_ekf.BatchEKF.predict`) and measured by the
   batched range/az/el model (`batch_ekf.BatchEKF.measure`): predicted measurement
   ``h(x)`` and ``H P H^T`` per track and epoch;
2. *gating* (`gate_scan`): for every (track, detection) pair the innovation
   ``y = z - h(x)`` (angles wrapped to (-pi, pi]), its covariance ``S = H P H^T + R``, the
   squared Mahalanobis distance ``d^2 = y^T S^-1 y`` and the cost ``d^2 + ln det S`` (the
   negative log-likelihood of the pair up to a constant); a pair is feasible when ``d^2``
   is within the chi-square gate (`AssociationConfig.gate`: probability
   ``gate_probability`` of a chi-square law with 3 degrees of freedom);
3. *assignment* (`assign`): global nearest neighbour, one detection per track and one
   track per detection, by `scipy.optimize.linear_sum_assignment`: among the assignments of
   feasible pairs with the most pairs, the one of least total cost (the assignment Stone
   Soup's ``GNNWith2DAssignment`` makes with a missed-detection distance beyond every
   feasible cost).

`associate` runs the three. Costs need no Python loop over tracks or detections: the
(N, M) arrays are computed at once (O(N M) memory: a scan of 50 detections against 10,000
tracks is 5e5 pairs, ~40 MB).

The tracks' management around it (tentative tracks from unassigned detections, their
initial orbit determination, confirmation and deletion) is `Associator`'s.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.optimize import linear_sum_assignment
from scipy.stats import chi2

from .batch_ekf import BatchEKF

__all__ = [
    "UNASSIGNED",
    "AssociationConfig",
    "Gated",
    "ScanAssociation",
    "ScanPrediction",
    "assign",
    "associate",
    "gate_scan",
    "predict_scan",
]

Array = NDArray[np.float64]
BoolArray = NDArray[np.bool_]
IntArray = NDArray[np.int64]

UNASSIGNED = -1
"""The track index of a detection assigned to no track."""

MEASUREMENT_DOF = 3
"""Degrees of freedom of a range/az/el innovation (the chi-square gate's)."""


@dataclass(frozen=True)
class AssociationConfig:
    """Gate and track-management rules of the association (module docstring, `Associator`).

    Attributes
    ----------
    gate_probability : float
        Probability that a detection of a track falls inside the track's gate: the gate on
        ``d^2`` is the chi-square quantile of this probability with 3 degrees of freedom
        (0.9999: d^2 <= 21.1).
    confirm_hits, confirm_window : int
        M-of-N confirmation: a tentative track is confirmed once ``confirm_hits``
        detections were assigned to it in the last ``confirm_window`` scans in which it was
        expected (predicted above the scanning sensor's mask).
    delete_after_missed_passes : int
        A track is deleted after this many passes in a row in which it was expected and got
        no detection.
    pass_gap_s : float
        Two scans of one track further apart than this, s, belong to different passes.
    max_position_sigma_km : float
        A track whose predicted position standard deviation (the largest axis of its
        position covariance) exceeds this, km, is deleted: it can no longer be told from
        its neighbours.
    tracklet_max_gap_s : float
        A tracklet (unassigned detections not yet an orbit) that got no detection for this
        long, s, is dropped.
    tracklet_speed_sigma_km_s : float
        Standard deviation, km/s, of an object's speed about the circular speed at its
        radius, the prior that pairs a tracklet's first detection with its second (a
        near-circular orbit: 0.3 km/s is an eccentricity of ~0.04 in low orbit).
    tracklet_accel_sigma_km_s2 : float
        Standard deviation, km/s^2, of the acceleration left out of a tracklet's
        prediction (two-body gravity is in it), per axis.
    """

    gate_probability: float = 0.9999
    confirm_hits: int = 6
    confirm_window: int = 8
    delete_after_missed_passes: int = 3
    pass_gap_s: float = 600.0
    max_position_sigma_km: float = 100.0
    tracklet_max_gap_s: float = 60.0
    tracklet_speed_sigma_km_s: float = 0.3
    tracklet_accel_sigma_km_s2: float = 1e-4

    def __post_init__(self) -> None:
        """Check the settings (ValueError naming the field)."""
        if not 0.0 < self.gate_probability < 1.0:
            raise ValueError(f"gate_probability must be in (0, 1), got {self.gate_probability}")
        if not 1 <= self.confirm_hits <= self.confirm_window <= 62:
            raise ValueError("need 1 <= confirm_hits <= confirm_window <= 62, got "
                             f"{self.confirm_hits} of {self.confirm_window}")
        if self.delete_after_missed_passes < 1:
            raise ValueError("delete_after_missed_passes must be >= 1, got "
                             f"{self.delete_after_missed_passes}")
        for name in ("pass_gap_s", "max_position_sigma_km", "tracklet_max_gap_s",
                     "tracklet_speed_sigma_km_s", "tracklet_accel_sigma_km_s2"):
            if not getattr(self, name) > 0.0:
                raise ValueError(f"{name} must be > 0, got {getattr(self, name)}")

    @property
    def gate(self) -> float:
        """Threshold on the squared Mahalanobis distance (chi-square quantile, 3 dof)."""
        return float(chi2.ppf(self.gate_probability, MEASUREMENT_DOF))


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
    """

    epochs: Array
    epoch_index: IntArray
    zp: Array
    HPHt: Array
    ok: BoolArray


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


@dataclass(frozen=True)
class ScanAssociation:
    """The outcome of `associate` for one scan.

    Attributes
    ----------
    track : ndarray (M,) of int
        Per detection, the index of its track among the N, or `UNASSIGNED`.
    gated : Gated
        The pairs' distances, costs and gate.
    prediction : ScanPrediction
        The tracks' predicted measurements.
    """

    track: IntArray
    gated: Gated
    prediction: ScanPrediction


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
    return ScanPrediction(epochs, index.reshape(-1).astype(np.int64),
                          zp.reshape(k, n, 3), HPHt.reshape(k, n, 3, 3), ok.reshape(k, n))


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
    d2 = np.full(ok.shape, np.inf)
    cost = np.full(ok.shape, np.inf)
    if ok.any():
        L = np.linalg.cholesky(S[ok])  # LinAlgError only for a non-positive S: below
        w = np.linalg.solve(L, y[ok][..., None])[..., 0]
        d2[ok] = np.einsum("ij,ij->i", w, w)
        cost[ok] = d2[ok] + 2.0 * np.log(np.diagonal(L, axis1=-2, axis2=-1)).sum(-1)
    return Gated(d2, cost, d2 <= gate)


def assign(cost: ArrayLike, feasible: ArrayLike) -> IntArray:
    """Global nearest neighbour: the track of each detection (module docstring, step 3).

    Parameters
    ----------
    cost : array_like (N, M)
        Cost of assigning detection j to track i (only feasible pairs are read).
    feasible : array_like (N, M) of bool
        The pairs that may be assigned.

    Returns
    -------
    ndarray (M,) of int
        Per detection its track index, or `UNASSIGNED`: the assignment of feasible pairs
        with the most pairs, of least total cost among those.
    """
    C = np.asarray(cost, dtype=float)
    F = np.asarray(feasible, dtype=bool) & np.isfinite(C)
    out = np.full(C.shape[1], UNASSIGNED, dtype=np.int64)
    rows, cols = np.flatnonzero(F.any(1)), np.flatnonzero(F.any(0))
    if not rows.size:
        return out
    sub, fs = C[np.ix_(rows, cols)], F[np.ix_(rows, cols)]
    low = sub[fs].min()
    # an infeasible pair costs more than any assignment of feasible pairs: the most
    # feasible pairs first, then the least cost
    big = (float((sub[fs] - low).max()) + 1.0) * (min(fs.shape) + 1)
    work = np.where(fs, sub - low, big)
    r, c = linear_sum_assignment(work)
    keep = fs[r, c]
    out[cols[c[keep]]] = rows[r[keep]]
    return out


def associate(ekf: BatchEKF, x: ArrayLike, P: ArrayLike, t_track: ArrayLike,
              t_scan: ArrayLike, z: ArrayLike, R: ArrayLike, station: int,
              config: AssociationConfig) -> ScanAssociation:
    """Predict, gate and assign one station's scan to N tracks (module docstring).

    Parameters as `predict_scan` and `gate_scan`; the gate is ``config.gate``.
    """
    pred = predict_scan(ekf, x, P, t_track, t_scan, station)
    gated = gate_scan(pred, z, R, config.gate)
    return ScanAssociation(assign(gated.cost, gated.feasible), gated, pred)
