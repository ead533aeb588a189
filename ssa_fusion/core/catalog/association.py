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

Crowded skies (objects launched together, a few km apart) need two more steps, both in
`Associator` (docs/ASSOCIATION.md measures them):

* a *long-arc predictor* (`AssociationConfig.predictor_q`): a second filter of every track,
  of much smaller process noise, fed the same detections. The tracks' filter's process
  noise (tuned for a consistent covariance under model error) makes it forget the mean
  motion that earlier passes pinned: after a gap of half a day its along-track prediction
  errs by independent km per track, more than the spacing of a train. The long-arc
  predictor keeps it; its predictions rescore the pairs the tracks' filter gates
  (`gate_long_arc`: the gate stays the tracks' filter's, so a detection it expects is
  never left out because the long-arc predictor is too sure);
* a *registration* (`register`, `AssociationConfig.register_groups`): what the long-arc
  predictor still misses (drag, the motion model's own error) is nearly the same along-
  track time for every member of a group. Tracks linked by detections they both gate, or
  predicted on one orbit close together (`AssociationConfig.group_link_km`), form a group;
  each group is shifted along track by the common time (Gaussian prior from the
  tracks' filter's predicted position standard deviation) that best aligns it with the
  scan, before the assignment.

Young tracks need one more (`AssociationConfig.defer_passes`, `deferral.PairDeferral`): in
its second pass a track's orbit comes from one pass, and two neighbours' predictions can
be in each other's place. A pair of confirmed tracks whose swapped assignment in a scan
costs little more than the chosen one (``defer_margin``) keeps both hypotheses: the chosen
one in the tracks, the pair's detections exchanged for the rest of the pass in shadow
copies. At the next pass that sees the pair, the hypothesis of least total cost (the
deferred pass's and that scan's) wins: the tracks take the shadows' states when the swap
wins, and the deferred pass's detections change track (`Associator.relabels`,
`ScanOutcome.relabelled`).

Track management (`Associator`): a catalog of unlabelled objects, scan by scan.

* Every scan is first associated with the tracks (tentative and confirmed, the rows of a
  `track_bank.TrackBank` named by track ids "T1", "T2", ...) as above; each assigned
  detection is fused by the bank under its track's id.
* The detections no track took extend *tracklets* (detections of one station in one pass
  not yet an orbit), by the same gate and assignment on a tracklet's prediction: from its
  last two detections (their GCRF positions, `iod.razel_to_gcrs`, with the range/az/el
  noise pushed through the inverse Jacobian of `batch_ekf.BatchEKF.measure`) by two-body
  gravity; a tracklet of one detection has no velocity yet, and a detection extends it
  when the speed the pair implies is near the circular speed at its radius
  (``tracklet_speed_sigma_km_s``: a prior of near-circular orbits, gated at the same
  probability with 1 degree of freedom). The rest start new tracklets. A tracklet of
  ``iod_samples`` detections (the bank's `filter_options.IodOptions`) is handed to the
  bank under a new track id: its initial orbit determination (Herrick-Gibbs over the
  pass, `initiation.OrbitInitiator`) starts a *tentative* track. A tracklet without a
  detection for ``tracklet_max_gap_s`` is dropped.
* A tentative track is *confirmed* after ``confirm_hits`` detections in its last
  ``confirm_window`` expected scans (M of N; expected: predicted above the scanning
  sensor's mask), and deleted once it can no longer be (``confirm_window`` expected scans
  with fewer hits). Any track is deleted after ``delete_after_missed_passes`` passes in a
  row in which it was expected and got nothing, or when its predicted position standard
  deviation exceeds ``max_position_sigma_km``.
* `TrackEvent` counts each outcome; `Associator.counts` holds the counters.

Deleted tracks keep their bank rows (never reused): a bank holds at most
``max_objects`` rows (`validation.MAX_OBJECTS`) over its life.

Imports: every catalog_filter process imports this module (`catalog_fusion`), and most never
see an unlabelled detection. So of scipy it imports only ``scipy.special`` (the chi-square
quantile, `chi2_quantile`, ~9 MiB); ``scipy.optimize`` (`assign`) and ``scipy.sparse``
(`register`) are imported by the functions that use them, at their first call:
``scipy.stats`` and ``scipy.optimize`` would add ~45 MiB to every process's resident memory.
"""

from __future__ import annotations

import enum
import math
from collections import Counter
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.special import gammaincinv

from ssa_fusion.core.base.constants import MU_EARTH
from ssa_fusion.core.catalog.batch_ekf import BatchEKF
from ssa_fusion.core.catalog.deferral import (
    ForkState,
    PairDeferral,
    Relabel,
    ambiguous_pairs,
    copy_track,
    shadows_in,
)
from ssa_fusion.core.catalog.track_bank import TrackBank
from ssa_fusion.core.earth.frames import Station
from ssa_fusion.core.filter.options import FilterOptions
from ssa_fusion.core.measure.iod import razel_to_gcrs

__all__ = [
    "UNASSIGNED",
    "AssociationConfig",
    "Associator",
    "DetectionFate",
    "Gated",
    "ScanAssociation",
    "ScanOutcome",
    "ScanPrediction",
    "TrackEvent",
    "TrackStatus",
    "assign",
    "associate",
    "gate_long_arc",
    "gate_scan",
    "pair_cost",
    "predict_scan",
    "register",
]

Array = NDArray[np.float64]
BoolArray = NDArray[np.bool_]
IntArray = NDArray[np.int64]

UNASSIGNED = -1
"""The track index of a detection assigned to no track."""

MEASUREMENT_DOF = 3
"""Degrees of freedom of a range/az/el innovation (the chi-square gate's)."""


def chi2_quantile(p: float, dof: int) -> float:
    """Return the `p` quantile of a chi-square law of `dof` degrees of freedom.

    ``2 gammaincinv(dof / 2, p)``, the expression ``scipy.stats.chi2.ppf(p, dof)`` evaluates
    (the same float, bit for bit), without importing ``scipy.stats`` (module docstring).
    """
    return float(2 * gammaincinv(dof / 2, p))


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
    predictor_q : float or None
        Process-noise spectral density, km^2/s^3, of the association's own *long-arc
        predictor* (module docstring): a second filter of every track, fed the same
        detections, whose predictions rescore the pairs the tracks' filter gates
        (`gate_long_arc`); None: the tracks' filter scores them. Chosen on the crowded
        cases' tuning seeds 1-3 (`bench/bench_association.py`, docs/ASSOCIATION.md): the
        largest of 1e-16, 1e-17, 1e-18 with which every tuning run kept 99.95 % of the
        detections on the right track and no track swapped.
    register_groups : bool
        Before the assignment, shift each group of tracks that
        share detections along track by the common time that best aligns it with the scan
        (`register`; its prior from the tracks' filter's predicted position standard
        deviation).
    group_link_km, group_link_speed_fraction : float
        A group also spans tracks predicted within ``group_link_km`` km of each other whose
        predicted velocities differ by at most this fraction of their speed (one orbit:
        objects launched together), chained: twice the widest spacing (5 km) of the
        crowded cases' trains, so that a whole train, not pieces of it, is registered.
    defer_passes : int
        Decisions deferred over passes (`deferral.PairDeferral`): two confirmed tracks with
        at least one and at most this many passes behind them (an orbit of one pass, for
        1), ambiguous in a scan, keep both hypotheses until the next pass; 0: never.
    defer_margin : float
        The most the swapped assignment of two tracks may cost above the chosen one
        (``d^2 + ln det S`` units: twice a log-likelihood ratio) for them to be ambiguous.
        2 ln 1000 (a swap at least 1/1000 as likely as the chosen assignment): chosen on the
        crowded cases' tuning seeds 1-3 (24 h, `bench/bench_association.py`) as the largest
        of 2 ln 10, 2 ln 100, 2 ln 1000 with which every tuning run kept 99.95 % of the
        detections on the right track and no track swapped.
    defer_max_wait_s : float
        A deferred decision whose pair is not seen again within this long after its pass,
        s, is dropped (the scan-wise assignment stays). Each hypothesis is scored on the
        whole scan as the association makes it (the long-arc predictor and the groups'
        registration, `Associator._scan_cost`), so a decision across the half-day gap of a
        station's passes is as sharp as one at the next pass; 1 day: a low orbit comes
        back into a mid-latitude station's view within a day (not fitted).
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
    predictor_q: float | None = 1e-17
    register_groups: bool = True
    group_link_km: float = 10.0
    group_link_speed_fraction: float = 0.01
    defer_passes: int = 1
    defer_margin: float = 2.0 * math.log(1000.0)
    defer_max_wait_s: float = 86400.0

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
                     "tracklet_speed_sigma_km_s", "tracklet_accel_sigma_km_s2",
                     "group_link_km", "group_link_speed_fraction"):
            if not getattr(self, name) > 0.0:
                raise ValueError(f"{name} must be > 0, got {getattr(self, name)}")
        if self.defer_passes < 0:
            raise ValueError(f"defer_passes must be >= 0, got {self.defer_passes}")
        if not self.defer_margin >= 0.0:
            raise ValueError(f"defer_margin must be >= 0, got {self.defer_margin}")
        if not self.defer_max_wait_s > 0.0:
            raise ValueError(f"defer_max_wait_s must be > 0, got {self.defer_max_wait_s}")
        if self.predictor_q is not None and not self.predictor_q >= 0.0:
            raise ValueError(f"predictor_q must be >= 0 or None, got {self.predictor_q}")

    @property
    def gate(self) -> float:
        """Threshold on the squared Mahalanobis distance (chi-square quantile, 3 dof)."""
        return chi2_quantile(self.gate_probability, MEASUREMENT_DOF)


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
    w, _, ok, logdet = _whitened(prediction, z, R)
    d2 = np.full(ok.shape, np.inf)
    cost = np.full(ok.shape, np.inf)
    d2[ok] = np.einsum("ij,ij->i", w, w)
    cost[ok] = d2[ok] + logdet
    return Gated(d2, cost, d2 <= gate)


def _whitened(prediction: ScanPrediction, z: ArrayLike,
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
    from scipy.optimize import linear_sum_assignment  # here: module docstring, imports

    r, c = linear_sum_assignment(work)
    keep = fs[r, c]
    out[cols[c[keep]]] = rows[r[keep]]
    return out


def register(prediction: ScanPrediction, z: ArrayLike, R: ArrayLike, feasible: ArrayLike,
             gate: float, sigma_shift_s: ArrayLike, candidates: int = 4,
             linked: ArrayLike | None = None) -> Array:
    """Return the common along-track shift of each group of tracks sharing detections (s).

    Objects launched together (a train) share the error their motion model leaves out (drag,
    the model's own error): after a long gap every member's prediction is off along track by
    nearly the same time, which can exceed the members' spacing, and the assignment of the
    shifted train (each track on its neighbour's detection) then costs about as little as
    the true one. A *group* is a connected set of two or more tracks linked by feasible pairs
    (two tracks sharing a detection they both gate); every group gets one shift ``s`` (its
    tracks moved along their orbits by ``s`` seconds: ``zp + zp_rate s``, first order),
    with a Gaussian prior N(0, sigma^2) (sigma: the median of its tracks'
    ``sigma_shift_s``), that maximises the likelihood of its best assignment. Irregular
    spacings make the true alignment unique.

    The search: every feasible pair's own best shift (``s_ij``, where the pair's ``d^2(s)
    = a - 2 b s + c s^2`` is least) and 0 are candidates, ranked by the sum over the
    group's detections of their least ``d^2(s)`` (clipped at the gate) plus the prior's
    ``s^2 / sigma^2``; the best ``candidates`` distinct ones are solved by `assign` and
    refined in closed form on their assignment (``s = sum b / (sum c + 1 / sigma^2)``);
    the least total cost (``d^2 + ln det S`` of the pairs plus the prior) wins.

    Parameters
    ----------
    prediction : ScanPrediction
        The N tracks predicted to the scan, with ``zp_rate`` (`predict_scan`).
    z, R : array_like (M, 3), (M, 3, 3)
        Detections and their noise (as `gate_scan`).
    feasible : array_like (N, M) of bool
        The pairs that may be assigned (the gate); the shift leaves them as they are.
    gate : float
        Threshold on ``d^2`` (`AssociationConfig.gate`): the most a detection adds to a
        candidate's rank.
    sigma_shift_s : array_like (N,)
        Prior standard deviation of each track's along-track shift, s (its filter's
        predicted position standard deviation over its speed).
    candidates : int
        How many of the ranked candidate shifts are solved by assignment.
    linked : array_like (N, N) of bool, optional
        More links between tracks (e.g. each track's prediction inside another's gate,
        `Associator`): a group then spans them too, so that the end of a train with a single
        detection is not registered alone (one detection aligns with any of its tracks).

    Returns
    -------
    ndarray (N,)
        Per track the shift of its group, s; 0 for a track in no group.
    """
    if prediction.zp_rate is None:
        raise ValueError("register needs a prediction with zp_rate (predict_scan)")
    F = np.asarray(feasible, dtype=bool)
    n = F.shape[0]
    shift = np.zeros(n)
    if n < 2:
        return shift
    share = (F.astype(np.int64) @ F.T.astype(np.int64)) > 0  # tracks sharing a detection
    if linked is not None:
        share = share | np.asarray(linked, dtype=bool)
    from scipy.sparse.csgraph import connected_components  # here: module docstring, imports

    ngroups, group = connected_components(share, directed=False)
    if ngroups == n:  # no group of two or more: nothing to register
        return shift
    w, u, ok, logdet = _whitened(prediction, z, R)
    if u is None:
        return shift
    F = F & ok
    a, b, c, ld = (np.full(ok.shape, np.nan) for _ in range(4))
    a[ok], b[ok], c[ok] = (np.einsum("ij,ij->i", w, w), np.einsum("ij,ij->i", u, w),
                           np.einsum("ij,ij->i", u, u))
    ld[ok] = logdet
    sig = np.asarray(sigma_shift_s, dtype=float).reshape(-1)
    sizes = np.bincount(group, minlength=ngroups)
    for g in np.flatnonzero(sizes >= 2).tolist():  # over the groups, not the tracks
        rows = np.flatnonzero(group == g)
        cols = np.flatnonzero(F[rows].any(0))
        sigma = float(np.median(sig[rows]))
        if not (math.isfinite(sigma) and sigma > 0.0):
            continue
        fs = F[np.ix_(rows, cols)]
        A, B, C, LD = (x[np.ix_(rows, cols)] for x in (a, b, c, ld))
        with np.errstate(divide="ignore", invalid="ignore"):
            own = np.where(fs & (C > 0), B / C, np.nan)
        cand = np.unique(np.r_[0.0, own[np.isfinite(own)]])
        d2 = A[None] - 2.0 * B[None] * cand[:, None, None] + C[None] * cand[:, None, None] ** 2
        d2 = np.where(fs[None], d2, np.inf)
        rank = np.minimum(d2.min(1), gate).sum(-1) + (cand / sigma) ** 2
        order = np.argsort(rank, kind="stable")
        picked: list[float] = []
        best = (math.inf, 0.0)
        for k in order.tolist():
            s0 = float(cand[k])
            if any(abs(s0 - p) < 1e-3 * sigma for p in picked):
                continue
            picked.append(s0)
            for _ in range(2):  # solve at s0, refine on its assignment, solve again
                cost = np.where(fs, A - 2.0 * B * s0 + C * s0**2 + LD, np.inf)
                det_track = assign(cost, fs)
                got = det_track >= 0
                i, j = det_track[got], np.flatnonzero(got)
                s0 = float(B[i, j].sum() / (C[i, j].sum() + sigma**-2))
            cost = np.where(fs, A - 2.0 * B * s0 + C * s0**2 + LD, np.inf)
            det_track = assign(cost, fs)
            got = det_track >= 0
            total = float(cost[det_track[got], np.flatnonzero(got)].sum()) + (s0 / sigma) ** 2
            if total < best[0]:
                best = (total, s0)
            if len(picked) >= candidates:
                break
        shift[rows] = best[1]
    return shift


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


def pair_cost(bank: TrackBank, rows: ArrayLike, station: int, t: Array, z: Array, R: Array,
              gate: float, dets: ArrayLike | None = None) -> tuple[float, bool]:
    """Cost of K tracks of a bank on a scan's detections (a deferred decision's score).

    Each track costs ``min(d^2, gate) + ln det S`` on its detection (the cost of
    `gate_scan` with ``d^2`` clipped at the gate), or ``gate + ln det S`` (S at the scan's
    first epoch) without one: a detection outside the gate counts as a miss.

    Parameters
    ----------
    bank : TrackBank
        Holds the tracks.
    rows : array_like (K,) of int
        Their rows in ``bank``.
    station : int
        Index of the scanning station in ``bank.ekf.stations``.
    t, z, R : ndarray (M,), (M, 3), (M, 3, 3)
        The scan's epochs (Unix s), detections and their noise (as `gate_scan`).
    gate : float
        Threshold on ``d^2`` (`AssociationConfig.gate`).
    dets : array_like (K,) of int, optional
        Each track's detection (-1: none); default: the tracks' own best assignment of the
        scan (`assign` on their K x M costs).

    Returns
    -------
    (float, bool)
        The total cost, and whether any (track, detection) pair is inside the gate.
    """
    r = np.asarray(rows, dtype=np.int64)
    pred = predict_scan(bank.ekf, bank.x[r], bank.P[r], bank.t[r], t, station)
    g = gate_scan(pred, z, R, gate)
    if dets is None:
        det_track = assign(g.cost, g.feasible)
        d = np.full(r.size, UNASSIGNED, dtype=np.int64)
        got = np.flatnonzero(det_track >= 0)
        d[det_track[got]] = got
    else:
        d = np.asarray(dets, dtype=np.int64)
    S0 = pred.HPHt[0] + np.asarray(R, dtype=float).reshape(-1, 3, 3)[0]
    sign, miss_logdet = np.linalg.slogdet(S0)
    total = 0.0
    for i, j in enumerate(d.tolist()):
        if j >= 0 and math.isfinite(g.d2[i, j]):
            total += min(float(g.d2[i, j]), gate) + float(g.cost[i, j] - g.d2[i, j])
        else:
            total += gate + (float(miss_logdet[i]) if sign[i] > 0 else 0.0)
    return total, bool(g.feasible.any())


def associate(ekf: BatchEKF, x: ArrayLike, P: ArrayLike, t_track: ArrayLike,
              t_scan: ArrayLike, z: ArrayLike, R: ArrayLike, station: int,
              config: AssociationConfig) -> ScanAssociation:
    """Predict, gate and assign one station's scan to N tracks (module docstring).

    Parameters as `predict_scan` and `gate_scan`; the gate is ``config.gate``.
    """
    pred = predict_scan(ekf, x, P, t_track, t_scan, station)
    gated = gate_scan(pred, z, R, config.gate)
    return ScanAssociation(assign(gated.cost, gated.feasible), gated, pred)


# ------------------------------------------------------------------------------------------
# Track management
# ------------------------------------------------------------------------------------------
class TrackStatus(enum.IntEnum):
    """Where a track stands (`Associator.status`)."""

    TENTATIVE = 0
    """Started by an initial orbit determination, not yet confirmed."""
    CONFIRMED = 1
    """Passed the M-of-N rule."""
    DELETED = 2
    """Dropped: no longer predicted, associated or fused."""


class DetectionFate(enum.IntEnum):
    """What `Associator.process_scan` did with a detection."""

    TRACK = 0
    """Assigned to a track and fused."""
    TRACKLET = 1
    """Added to an existing tracklet (it may have started a track by its IOD)."""
    NEW_TRACKLET = 2
    """Started a tracklet."""
    REFUSED = 3
    """Assigned to a track, whose filter refused it (its own NIS gate or a numeric
    failure), or ended a tracklet whose initial orbit determination failed."""


class TrackEvent(enum.StrEnum):
    """The counted outcomes of the association (`Associator.counts` keys)."""

    SCANS = "scans"
    DETECTIONS = "detections"
    ASSIGNED = "assigned"
    """Detections assigned to a track and fused."""
    REFUSED = "refused"
    """Detections assigned to a track that its filter refused."""
    TRACKLET_EXTENDED = "tracklet_extended"
    TRACKLET_STARTED = "tracklet_started"
    TRACKLET_EXPIRED = "tracklet_expired"
    TRACK_INITIATED = "track_initiated"
    """Tracklets whose initial orbit determination started a tentative track."""
    IOD_FAILED = "iod_failed"
    TRACK_CONFIRMED = "track_confirmed"
    TENTATIVE_DROPPED = "tentative_dropped"
    """Tentative tracks deleted because they can no longer pass the M-of-N rule."""
    DELETED_MISSED_PASSES = "deleted_missed_passes"
    DELETED_COVARIANCE = "deleted_covariance"
    GROUP_REGISTERED = "group_registered"
    """Groups of tracks sharing detections shifted along track before an assignment
    (`register`; one per group and scan)."""
    DEFER_OPENED = "defer_opened"
    """Ambiguous pairs of tracks whose decision was deferred (`deferral.PairDeferral`)."""
    DEFER_SWAPPED = "defer_swapped"
    """Deferred decisions that exchanged the pair's detections of the deferred pass."""
    DEFER_KEPT = "defer_kept"
    """Deferred decisions that kept the scan-wise assignment."""
    DEFER_DROPPED = "defer_dropped"
    """Deferred decisions dropped undecided (a track of the pair was deleted, or the pair
    was not seen within `AssociationConfig.defer_max_wait_s` of its pass)."""


@dataclass(frozen=True)
class ScanOutcome:
    """What `Associator.process_scan` did with a scan of M detections.

    Attributes
    ----------
    ids : list of str
        Per detection, the id of the track or tracklet it went to (a tracklet's id is the
        id of the track its IOD starts).
    fate : ndarray (M,) of int8
        Per detection, its `DetectionFate`.
    relabelled : tuple of Relabel
        Detections of earlier scans (this one's included) whose track a deferred decision
        taken in this scan changed (`deferral.Relabel`: the scan's serial number, from 0 for
        the first `Associator.process_scan` call, and the detection's index in it).
    """

    ids: list[str]
    fate: NDArray[np.int8]
    relabelled: tuple[Relabel, ...] = ()


def _popcount(bits: IntArray, width: int) -> IntArray:
    """Return the number of set bits among the low `width` bits of each element."""
    out = np.zeros(bits.shape, dtype=np.int64)
    for k in range(width):  # over the bits, not the tracks
        out += (bits >> k) & 1
    return out


class Associator:
    """Tracks of unlabelled objects from scans of detections (module docstring).

    Parameters
    ----------
    filter_options : FilterOptions
        The tracks' filter (`track_bank.TrackBank`; its ``reinit_after`` is set to 0: a
        track that loses its object is deleted here, not initialised again from a detection
        that may be another object's).
    stations : dict of str to Station
        The network: a scan names its station by id.
    config : AssociationConfig
        Gate and track-management rules.
    """

    def __init__(self, filter_options: FilterOptions, stations: dict[str, Station],
                 config: AssociationConfig | None = None) -> None:
        self.config = AssociationConfig() if config is None else config
        options = filter_options.with_(reinit_after=0)
        self.bank = TrackBank(options, stations)
        q = self.config.predictor_q
        self.predictor = None if q is None else TrackBank(options.with_(q=q), stations)
        """The long-arc predictor (`AssociationConfig.predictor_q`): the same tracks, fed the
        same detections, whose predictions score the pairs; None without one."""
        self.stations = dict(stations)
        self.deferral = None if not self.config.defer_passes else PairDeferral(
            options, None if q is None else options.with_(q=q), self.stations,
            self.config.gate, self.config.pass_gap_s)
        """The deferred decisions (`AssociationConfig.defer_passes`); None without them."""
        self.relabels: list[Relabel] = []
        """Every detection whose track a deferred decision changed (`ScanOutcome`)."""
        self.iod_samples = int(options.iod.iod_samples)
        self.counts: Counter[TrackEvent] = Counter()
        self._gate = self.config.gate
        self._gate1 = chi2_quantile(self.config.gate_probability, 1)
        self._next_id = 1
        # per bank row (grown with the bank)
        self.status = np.zeros(0, dtype=np.int8)
        self._bits = np.zeros(0, dtype=np.int64)
        self._expected = np.zeros(0, dtype=np.int64)
        self._last_expected = np.zeros(0)
        self._pass_open = np.zeros(0, dtype=bool)
        self._pass_hits = np.zeros(0, dtype=np.int64)
        self._missed = np.zeros(0, dtype=np.int64)
        self._passes = np.zeros(0, dtype=np.int64)  # passes ended with a detection
        self._prow = np.zeros(0, dtype=np.int64)  # the row in `predictor`, -1: none
        self._scan = -1  # serial number of the scan being processed
        # tracklets: one row each; their raw detections by id (for the IOD)
        self._tl_ids: list[str] = []
        self._tl_station = np.zeros(0, dtype=np.int64)
        self._tl_len = np.zeros(0, dtype=np.int64)
        self._tl_t = np.zeros((0, 2))
        self._tl_r = np.zeros((0, 2, 3))
        self._tl_C = np.zeros((0, 2, 3, 3))
        self._tl_raw: dict[str, list[tuple[float, Array, Array]]] = {}

    # --------------------------------------------------------------------------------------
    @property
    def scan_serial(self) -> int:
        """Serial number of the last scan processed (0 for the first; -1 before it)."""
        return self._scan

    def track_ids(self, status: TrackStatus) -> list[str]:
        """Return the ids of the tracks of a status."""
        return [self.bank.object_ids[r] for r in np.flatnonzero(self.status == status)]

    def _grow(self) -> None:
        """Per-track arrays as long as the bank."""
        extra = len(self.bank) - self.status.size
        if extra <= 0:
            return
        self.status = np.r_[self.status, np.full(extra, TrackStatus.TENTATIVE, np.int8)]
        self._bits = np.r_[self._bits, np.zeros(extra, np.int64)]
        self._expected = np.r_[self._expected, np.zeros(extra, np.int64)]
        self._last_expected = np.r_[self._last_expected, np.full(extra, -math.inf)]
        self._pass_open = np.r_[self._pass_open, np.zeros(extra, bool)]
        self._pass_hits = np.r_[self._pass_hits, np.zeros(extra, np.int64)]
        self._missed = np.r_[self._missed, np.zeros(extra, np.int64)]
        self._passes = np.r_[self._passes, np.zeros(extra, np.int64)]
        self._prow = np.r_[self._prow, np.full(extra, -1, np.int64)]

    def _delete(self, rows: IntArray, event: TrackEvent) -> None:
        self.status[rows] = TrackStatus.DELETED
        self.bank.tracking[rows] = False
        self.counts[event] += int(rows.size)

    # --------------------------------------------------------------------------------------
    def process_scan(self, station: str, t: ArrayLike, z: ArrayLike, R: ArrayLike,
                     min_elevation_rad: float) -> ScanOutcome:
        """Associate one station's scan, fuse it, and manage the tracks (module docstring).

        Parameters
        ----------
        station : str
            Id of the scanning station (a key of the network).
        t : array_like (M,) or scalar
            Epoch of each detection (or of the scan: a scalar, needed when M = 0), Unix s;
            scans come in epoch order.
        z : array_like (M, 3)
            Detections [range km, azimuth rad, elevation rad].
        R : array_like (M, 3, 3) or (3, 3)
            Their noise covariances, km^2, rad^2.
        min_elevation_rad : float
            The sensor's elevation mask, rad: a track predicted above it is expected in the
            scan (the sensor sees its whole sky above the mask).
        """
        zz = np.asarray(z, dtype=float).reshape(-1, 3)
        m = zz.shape[0]
        t_scan = float(np.min(t))
        tt = np.broadcast_to(np.asarray(t, dtype=float), (m,)).copy()
        RR = np.broadcast_to(np.asarray(R, dtype=float), (m, 3, 3)).copy()
        st = self.bank.ekf.index[station]
        self.counts[TrackEvent.SCANS] += 1
        self.counts[TrackEvent.DETECTIONS] += m
        self._scan += 1
        ids = [""] * m
        fate = np.full(m, DetectionFate.NEW_TRACKLET, dtype=np.int8)
        self._grow()
        self._expire(t_scan)
        done = len(self.relabels)
        if self.deferral is not None and m:
            self._decide(station, st, t_scan, tt, zz, RR)
        free = self._tracks(station, st, t_scan, tt, zz, RR, min_elevation_rad, ids, fate)
        self._tracklets(station, st, free, tt, zz, RR, ids, fate)
        self._grow()
        return ScanOutcome(ids, fate, tuple(self.relabels[done:]))

    def _tracks(self, station: str, st: int, t_scan: float, tt: Array, zz: Array,
                RR: Array, min_el: float, ids: list[str],
                fate: NDArray[np.int8]) -> IntArray:
        """Associate with the tracks, fuse, keep the counters: the free detections.

        A scan without detections (M = 0, at `t_scan`) still counts the tracks it
        expected as missed.
        """
        m = zz.shape[0]
        rows = self._active_rows()
        if not rows.size:
            return np.arange(m)
        cfg = self.config
        bank = self.bank
        pred = predict_scan(bank.ekf, bank.x[rows], bank.P[rows], bank.t[rows],
                            tt if m else t_scan, st)
        track = np.zeros(0, dtype=np.int64)
        if m:
            gated = self._gate_scan(rows, pred, st, tt, zz, RR)
            track = assign(gated.cost, gated.feasible)
        sigma = pred.sigma_pos.max(0)
        lost = rows[sigma > cfg.max_position_sigma_km]
        got = track >= 0
        hit = np.zeros(rows.size, dtype=bool)
        hit[track[got]] = True
        expected = (pred.ok & (pred.zp[..., 2] >= min_el)).any(0) | hit
        # fuse what was assigned, in epoch order
        if self.deferral is not None and m:
            self._defer(rows, track, gated, station, st, t_scan, tt, zz, RR)
        det = np.flatnonzero(got)
        det = det[np.argsort(tt[det], kind="stable")]
        names = [bank.object_ids[r] for r in rows[track[det]]]
        res = bank.process(tt[det], names, [station] * det.size, zz[det], RR[det])
        if self.predictor is not None and det.size:
            self.predictor.process(tt[det], names, [station] * det.size, zz[det], RR[det])
        refused = np.array([c != "" for c in res.cause], dtype=bool)
        for j, name in zip(det.tolist(), names, strict=True):
            ids[j] = name
        fate[det] = np.where(refused, DetectionFate.REFUSED, DetectionFate.TRACK)
        self.counts[TrackEvent.ASSIGNED] += int((~refused).sum())
        self.counts[TrackEvent.REFUSED] += int(refused.sum())
        # passes and M of N
        r_exp, h_exp = rows[expected], hit[expected]
        new_pass = t_scan - self._last_expected[r_exp] > cfg.pass_gap_s
        self._pass_hits[r_exp[new_pass]] = 0
        self._pass_open[r_exp] = True
        self._last_expected[r_exp] = t_scan
        self._pass_hits[r_exp] += h_exp
        width = cfg.confirm_window
        self._bits[r_exp] = ((self._bits[r_exp] << 1) | h_exp) & ((1 << width) - 1)
        self._expected[r_exp] += 1
        hits = _popcount(self._bits[r_exp], width)
        tentative = self.status[r_exp] == TrackStatus.TENTATIVE
        confirm = r_exp[tentative & (hits >= cfg.confirm_hits)]
        self.status[confirm] = TrackStatus.CONFIRMED
        self.counts[TrackEvent.TRACK_CONFIRMED] += int(confirm.size)
        hopeless = tentative & (hits < cfg.confirm_hits) & (self._expected[r_exp] >= width)
        self._delete(r_exp[hopeless], TrackEvent.TENTATIVE_DROPPED)
        self._delete(lost[self.status[lost] != TrackStatus.DELETED],
                     TrackEvent.DELETED_COVARIANCE)
        return np.flatnonzero(~got)

    # --------------------------------------------------------------------------------------
    def _scoring(self) -> tuple[TrackBank, IntArray]:
        """Return the scoring filter of deferred decisions and each track's row in it.

        The long-arc predictor if any, else the tracks' filter; per row of the tracks'
        bank its row there (-1: none).
        """
        if self.predictor is None:
            return self.bank, np.arange(len(self.bank), dtype=np.int64)
        return self.predictor, self._prow

    def _filters(self, a: int, b: int) -> list[tuple[TrackBank, int, int]]:
        """Per filter (the tracks', the long-arc predictor's), its bank and rows of a, b."""
        out = [(self.bank, a, b)]
        if self.predictor is not None:
            out.append((self.predictor, int(self._prow[a]), int(self._prow[b])))
        return out

    def _defer(self, rows: IntArray, track: IntArray, gated: Gated, station: str, st: int,
               t_scan: float, tt: Array, zz: Array, RR: Array) -> None:
        """Open forks on the scan's ambiguous pairs; fuse and score the open forks' H1.

        Called after the assignment (``track``: per detection its index in ``rows``), before
        the fusion: a new fork's shadows are the tracks' states before this scan.
        """
        deferral = self.deferral
        assert deferral is not None
        cfg = self.config
        src, srow = self._scoring()
        eligible = ((self.status[rows] == TrackStatus.CONFIRMED)
                    & (self._passes[rows] >= 1) & (self._passes[rows] <= cfg.defer_passes)
                    & (srow[rows] >= 0) & ~np.isin(rows, list(deferral.busy())))
        for i, k in ambiguous_pairs(track, gated.cost, gated.feasible, cfg.defer_margin,
                                    eligible):
            a, b = int(rows[i]), int(rows[k])
            deferral.open(a, b, t_scan, self._filters(a, b))
            self.counts[TrackEvent.DEFER_OPENED] += 1
        local = {int(r): i for i, r in enumerate(rows.tolist())}
        shadow = deferral.scoring_shadow()
        for fork in deferral.forks:
            if fork.state != ForkState.OPEN or fork.a not in local or fork.b not in local:
                continue
            da, db = (int(np.flatnonzero(track == local[r])[0]) if (track == local[r]).any()
                      else UNASSIGNED for r in (fork.a, fork.b))
            if da == UNASSIGNED and db == UNASSIGNED:
                continue
            h0, _ = pair_cost(src, srow[[fork.a, fork.b]], st, tt, zz, RR, self._gate, [da, db])
            h1, _ = pair_cost(shadow, [shadow.rows[n] for n in fork.shadow], st, tt, zz, RR,
                              self._gate, [db, da])
            fork.cost += (h0, h1)
            names = self.bank.object_ids
            fork.labels += [(self._scan, j, names[r]) for j, r in ((da, fork.b), (db, fork.a))
                            if j != UNASSIGNED]
            fork.t_last = t_scan
            deferral.fuse_shadows(fork, tt, station, zz, RR, (da, db))

    def _decide(self, station: str, st: int, t_scan: float, tt: Array, zz: Array,
                RR: Array) -> None:
        """Decide the forks whose pass ended, on this scan (`deferral` module docstring).

        Each hypothesis is scored on the whole scan as `_tracks` would associate it
        (`_scan_cost`: every track's prediction, the long-arc rescoring, the groups'
        registration and the assignment), with the pair's tracks in H0's states (the
        tracks') or H1's (the shadows'): after a long gap the pair's own predictions share
        an along-track error of km with their group, which the registration takes out.
        """
        deferral = self.deferral
        assert deferral is not None
        keep, ready = [], []
        for fork in deferral.forks:
            if TrackStatus.DELETED in (self.status[fork.a], self.status[fork.b]):
                self.counts[TrackEvent.DEFER_DROPPED] += 1
                continue
            if fork.state == ForkState.OPEN and t_scan - fork.t_last > deferral.pass_gap_s:
                fork.state = ForkState.PENDING
            if fork.state != ForkState.PENDING:
                keep.append(fork)
                continue
            if t_scan - fork.t_last > self.config.defer_max_wait_s:
                self.counts[TrackEvent.DEFER_DROPPED] += 1
                continue
            ready.append(fork)
        rows = self._active_rows()
        local = {int(r): i for i, r in enumerate(rows.tolist())}
        h0: tuple[float, IntArray, Array] | None = None
        for fork in ready:
            if fork.a not in local or fork.b not in local:
                self.counts[TrackEvent.DEFER_DROPPED] += 1
                continue
            shadow = deferral.shadow
            if not (pair_cost(self.bank, [fork.a, fork.b], st, tt, zz, RR, self._gate)[1]
                    or pair_cost(shadow, [shadow.rows[n] for n in fork.shadow], st, tt, zz,
                                 RR, self._gate)[1]):
                keep.append(fork)  # the pair is not in this scan's gates
                continue
            if h0 is None:  # H0 of every fork: the tracks as they are
                h0 = self._scan_cost(rows, st, tt, zz, RR)
            filters = self._filters(fork.a, fork.b)
            with shadows_in(fork, filters, deferral.banks()):
                h1 = self._scan_cost(rows, st, tt, zz, RR)
            pair = [local[fork.a], local[fork.b]]
            if not any((h[2][pair] <= self._gate).all() for h in (h0, h1)):
                keep.append(fork)  # no hypothesis has both tracks in the scan yet
                continue
            if fork.cost[1] + h1[0] < fork.cost[0] + h0[0]:
                for (bank, ra, rb), dst in zip(filters, deferral.banks(), strict=True):
                    copy_track(dst, dst.rows[fork.shadow[0]], bank, ra)
                    copy_track(dst, dst.rows[fork.shadow[1]], bank, rb)
                self.relabels += [Relabel(*lab) for lab in fork.labels]
                self.counts[TrackEvent.DEFER_SWAPPED] += 1
                h0 = None  # the tracks changed
            else:
                self.counts[TrackEvent.DEFER_KEPT] += 1
        deferral.forks = keep

    def _active_rows(self) -> IntArray:
        """Return the bank rows of the tracks associated with a scan (tracked, not deleted)."""
        n = len(self.bank)
        return np.flatnonzero(self.bank.tracking[:n] & (self.status[:n] != TrackStatus.DELETED))

    def _scan_cost(self, rows: IntArray, st: int, tt: Array, zz: Array,
                   RR: Array) -> tuple[float, IntArray, Array]:
        """Associate the scan with the tracks ``rows`` as `_tracks` does; return its cost.

        Returns the total over the tracks of ``min(d^2, gate) + ln det S`` on the detection
        the assignment gave each (the scores of `_gate_scan`: the long-arc predictor's,
        registered), ``gate + ln det S`` (S at the scan's first detection) for a track
        without one (as `pair_cost`), per detection its index in ``rows`` or
        `UNASSIGNED`, and per track the ``d^2`` of its detection (inf without one). Nothing
        is fused or counted.
        """
        bank = self.bank
        pred = predict_scan(bank.ekf, bank.x[rows], bank.P[rows], bank.t[rows], tt, st)
        gated = self._gate_scan(rows, pred, st, tt, zz, RR, count=False)
        track = assign(gated.cost, gated.feasible)
        with np.errstate(invalid="ignore"):
            logdet = gated.cost - gated.d2  # ln det S where computable, else nan
        miss = np.where(np.isfinite(logdet[:, 0]), logdet[:, 0], 0.0) + self._gate
        got = np.flatnonzero(track >= 0)
        i = track[got]
        d2 = np.full(rows.size, np.inf)
        d2[i] = gated.d2[i, got]
        hit = np.minimum(d2[i], self._gate) + logdet[i, got]
        return float(miss.sum() + (hit - miss[i]).sum()), track, d2

    def _gate_scan(self, rows: IntArray, pred: ScanPrediction, st: int, tt: Array,
                   zz: Array, RR: Array, count: bool = True) -> Gated:
        """Score the scan's pairs: `gate_scan`, rescored by the long-arc predictor.

        ``pred`` is the tracks' filter's prediction of the bank rows ``rows``; only the
        tracks with a feasible pair are predicted again, by the long-arc predictor
        (`gate_long_arc`; a track it does not hold, its IOD failed there, keeps the tracks'
        filter's score) and, with ``register_groups``, shifted along track by their
        group's `register` shift (the tracks' filter's prediction when there is no
        long-arc predictor). ``count``: add the groups registered to `counts`.
        """
        wide = gate_scan(pred, zz, RR, self._gate)
        which = np.flatnonzero(wide.feasible.any(1))
        register_groups = self.config.register_groups and which.size > 1
        src = self.bank if self.predictor is None else self.predictor
        if self.predictor is None:
            if not register_groups:
                return wide
            pr = rows[which]
        else:
            pr = self._prow[rows[which]]
            which, pr = which[pr >= 0], pr[pr >= 0]
            keep = src.tracking[pr]
            which, pr = which[keep], pr[keep]
            if not which.size:
                return wide
        t0 = src.t[pr]
        fine = predict_scan(src.ekf, src.x[pr], src.P[pr], t0, tt, st)
        if register_groups and which.size > 1:
            assert fine.speed is not None
            sigma_s = pred.sigma_pos[:, which].max(0) / fine.speed.min(0)
            shift = register(fine, zz, RR, wide.feasible[which], self._gate, sigma_s,
                             linked=self._close_tracks(pred, fine, which))
            if count:
                self.counts[TrackEvent.GROUP_REGISTERED] += int(
                    np.unique(shift[shift != 0.0]).size)
            if np.any(shift != 0.0):  # the shifted tracks predicted again, exactly
                fine = predict_scan(src.ekf, src.x[pr], src.P[pr], t0 - shift, tt, st)
        return gate_long_arc(wide, gate_scan(fine, zz, RR, self._gate), which)

    def _close_tracks(self, pred: ScanPrediction, fine: ScanPrediction,
                      which: IntArray) -> BoolArray:
        """Pairs of the tracks ``which`` on one orbit, close together (K, K) of bool.

        At the scan's first epoch, from the long-arc prediction ``fine`` (positions and
        velocities in the station's range/azimuth/elevation frame, km and km/s: ``[r,
        r cos(el) az, r el]`` and the same of ``zp_rate``): two tracks are linked when
        their predicted positions differ by at most ``group_link_km`` and their velocities
        by at most ``group_link_speed_fraction`` of the speed (objects launched together;
        crossing planes differ in velocity by a large fraction of it). ``pred`` (the
        tracks' filter's) marks the predictions that are computable.
        """
        cfg = self.config
        zp = fine.zp[0]
        rate = fine.zp_rate[0] if fine.zp_rate is not None else np.zeros_like(zp)
        r, el = zp[:, 0], zp[:, 2]
        scale = np.stack([np.ones_like(r), r * np.cos(el), r], -1)  # km per unit
        dz = zp[:, None, :] - zp[None, :, :]
        dz[..., 1] = math.pi - np.mod(math.pi - dz[..., 1], 2.0 * math.pi)
        dp = np.linalg.norm(dz * scale[:, None, :], axis=-1)
        dv = np.linalg.norm((rate[:, None, :] - rate[None, :, :]) * scale[:, None, :], axis=-1)
        speed = fine.speed[0] if fine.speed is not None else np.full(which.size, np.inf)
        ok = pred.ok[0, which] & fine.ok[0]
        out: BoolArray = ((dp <= cfg.group_link_km)
                          & (dv <= cfg.group_link_speed_fraction * speed[:, None])
                          & ok[:, None] & ok[None, :])
        return out

    def _close_passes(self, t_scan: float) -> None:
        """Count the passes that ended before `t_scan` without a detection."""
        ended = self._pass_open & (t_scan - self._last_expected > self.config.pass_gap_s)
        self._pass_open[ended] = False
        miss = ended & (self._pass_hits == 0)
        self._missed[ended & ~miss] = 0
        self._passes[ended & ~miss] += 1
        self._missed[miss] += 1
        gone = np.flatnonzero((self._missed >= self.config.delete_after_missed_passes)
                              & (self.status != TrackStatus.DELETED))
        self._delete(gone, TrackEvent.DELETED_MISSED_PASSES)

    def _expire(self, t_scan: float) -> None:
        """Drop the tracklets too old to extend; close the ended passes."""
        self._close_passes(t_scan)
        old = t_scan - self._tl_t[:, 1] > self.config.tracklet_max_gap_s
        self.counts[TrackEvent.TRACKLET_EXPIRED] += int(old.sum())
        self._keep_tracklets(~old)

    # --------------------------------------------------------------------------------------
    def _keep_tracklets(self, keep: BoolArray) -> None:
        for i in np.flatnonzero(~keep).tolist():
            self._tl_raw.pop(self._tl_ids[i], None)
        self._tl_ids = [s for s, k in zip(self._tl_ids, keep.tolist(), strict=True) if k]
        self._tl_station = self._tl_station[keep]
        self._tl_len = self._tl_len[keep]
        self._tl_t = self._tl_t[keep]
        self._tl_r = self._tl_r[keep]
        self._tl_C = self._tl_C[keep]

    def _positions(self, st: int, tt: Array, zz: Array, RR: Array) -> tuple[Array, Array]:
        """GCRF positions (M, 3) km of detections and their covariances (M, 3, 3)."""
        r = razel_to_gcrs(zz, tt, self.bank.ekf.stations[st])
        x = np.concatenate([r, np.zeros_like(r)], -1)
        _, H = self.bank.ekf.measure(x, tt, np.full(tt.size, st, dtype=np.intp))
        Hi = np.linalg.inv(H[:, :, :3])
        return r, Hi @ RR @ np.swapaxes(Hi, -1, -2)

    def _tracklets(self, station: str, st: int, free: IntArray, tt: Array, zz: Array,
                   RR: Array, ids: list[str], fate: NDArray[np.int8]) -> None:
        """Extend tracklets with the free detections, start new ones, start tracks."""
        if not free.size:
            return
        r, C = self._positions(st, tt[free], zz[free], RR[free])
        tf = tt[free]
        take = np.full(free.size, UNASSIGNED, dtype=np.int64)
        mine = self._tl_station == st
        for cost_of, which in ((self._cost_moving, mine & (self._tl_len >= 2)),
                               (self._cost_first, mine & (self._tl_len == 1))):
            cand = np.flatnonzero(which)
            left = np.flatnonzero(take == UNASSIGNED)
            if not cand.size or not left.size:
                continue
            cost, feasible = cost_of(cand, r[left], C[left], tf[left])
            got = assign(cost, feasible)
            take[left[got >= 0]] = cand[got[got >= 0]]
        ext = np.flatnonzero(take >= 0)
        k = take[ext]
        self._tl_t[k, 0], self._tl_r[k, 0], self._tl_C[k, 0] = (
            self._tl_t[k, 1], self._tl_r[k, 1], self._tl_C[k, 1])
        self._tl_t[k, 1], self._tl_r[k, 1], self._tl_C[k, 1] = tf[ext], r[ext], C[ext]
        self._tl_len[k] += 1
        self.counts[TrackEvent.TRACKLET_EXTENDED] += int(ext.size)
        new = np.flatnonzero(take == UNASSIGNED)
        new_ids = [f"T{self._next_id + i}" for i in range(new.size)]
        self._next_id += new.size
        self.counts[TrackEvent.TRACKLET_STARTED] += int(new.size)
        self._tl_ids += new_ids
        self._tl_station = np.r_[self._tl_station, np.full(new.size, st, np.int64)]
        self._tl_len = np.r_[self._tl_len, np.ones(new.size, np.int64)]
        self._tl_t = np.concatenate([self._tl_t, np.repeat(tf[new, None], 2, 1)])
        self._tl_r = np.concatenate([self._tl_r, np.repeat(r[new, None], 2, 1)])
        self._tl_C = np.concatenate([self._tl_C, np.repeat(C[new, None], 2, 1)])
        owner = np.empty(free.size, dtype=np.int64)
        owner[ext], owner[new] = k, self._tl_station.size - new.size + np.arange(new.size)
        for j, o in zip(free.tolist(), owner.tolist(), strict=True):
            name = self._tl_ids[o]
            ids[j] = name
            self._tl_raw.setdefault(name, []).append((float(tt[j]), zz[j], RR[j]))
        fate[free[ext]] = DetectionFate.TRACKLET
        done = np.flatnonzero(self._tl_len >= self.iod_samples)
        for i in done.tolist():
            if not self._initiate(station, self._tl_ids[i]):
                fate[[j for j in free.tolist() if ids[j] == self._tl_ids[i]]] = (
                    DetectionFate.REFUSED)
        keep = np.ones(self._tl_len.size, dtype=bool)
        keep[done] = False
        self._keep_tracklets(keep)

    def _initiate(self, station: str, name: str) -> bool:
        """Hand a complete tracklet to the bank: whether its IOD started a track."""
        raw = self._tl_raw[name]
        res = self.bank.process([d[0] for d in raw], [name] * len(raw), [station] * len(raw),
                                [d[1] for d in raw], [d[2] for d in raw])
        ok = res.cause[-1] == "" and bool(self.bank.tracking[self.bank.rows[name]])
        if ok and self.predictor is not None:
            self.predictor.process([d[0] for d in raw], [name] * len(raw),
                                   [station] * len(raw), [d[1] for d in raw],
                                   [d[2] for d in raw])
            self._grow()
            self._prow[self.bank.rows[name]] = self.predictor.rows[name]
        self.counts[TrackEvent.TRACK_INITIATED if ok else TrackEvent.IOD_FAILED] += 1
        if not ok:
            self.bank.tracking[self.bank.rows[name]] = False
        return ok

    @staticmethod
    def _gravity(r: Array) -> Array:
        """Two-body acceleration (..., 3) km/s^2 at GCRF positions r (..., 3) km."""
        n = np.linalg.norm(r, axis=-1, keepdims=True)
        out: Array = -MU_EARTH * r / n**3
        return out

    def _cost_moving(self, cand: IntArray, r: Array, C: Array,
                     t: Array) -> tuple[Array, BoolArray]:
        """Cost (T, M) of adding each detection to each tracklet of two or more detections.

        The tracklet's next position from its last two by two-body gravity (module
        docstring); the gate and cost as `gate_scan`'s, in GCRF position.
        """
        t1, t2 = self._tl_t[cand, 0], self._tl_t[cand, 1]
        r1, r2 = self._tl_r[cand, 0], self._tl_r[cand, 1]
        h = (t2 - t1)[:, None]
        a = self._gravity(r2)
        v2 = (r2 - r1) / h + 0.5 * a * h
        tau = t[None, :] - t2[:, None]  # (T, M)
        pred = r2[:, None] + v2[:, None] * tau[..., None] + 0.5 * a[:, None] * tau[..., None] ** 2
        c = (tau / h)[..., None, None]
        q = (self.config.tracklet_accel_sigma_km_s2 * 0.5 * tau * (tau + h)) ** 2
        S = ((1 + c) ** 2 * self._tl_C[cand, 1][:, None] + c**2 * self._tl_C[cand, 0][:, None]
             + C[None] + q[..., None, None] * np.eye(3))
        y = r[None] - pred
        L = np.linalg.cholesky(S)
        w = np.linalg.solve(L, y[..., None])[..., 0]
        d2 = np.einsum("...i,...i->...", w, w)
        cost = d2 + 2.0 * np.log(np.diagonal(L, axis1=-2, axis2=-1)).sum(-1)
        return cost, (d2 <= self._gate) & (tau > 0)

    def _cost_first(self, cand: IntArray, r: Array, C: Array,
                    t: Array) -> tuple[Array, BoolArray]:
        """Cost (T, M) of pairing each one-detection tracklet with each detection.

        The speed the pair implies (two-body gravity taken out) against the circular speed
        at the tracklet's radius, with ``tracklet_speed_sigma_km_s`` and the detections'
        noise along the displacement; gate at the same probability, 1 degree of freedom.
        """
        t1, r1, C1 = self._tl_t[cand, 1], self._tl_r[cand, 1], self._tl_C[cand, 1]
        tau = t[None, :] - t1[:, None]
        with np.errstate(divide="ignore", invalid="ignore"):
            d = (r[None] - r1[:, None]
                 - 0.5 * self._gravity(r1)[:, None] * tau[..., None] ** 2)  # (T, M, 3)
            dist = np.linalg.norm(d, axis=-1)
            u = d / dist[..., None]
            var_pos = (np.einsum("tmi,tij,tmj->tm", u, C1, u)
                       + np.einsum("tmi,mij,tmj->tm", u, C, u))
            v_circ = np.sqrt(MU_EARTH / np.linalg.norm(r1, axis=-1))[:, None]
            var = self.config.tracklet_speed_sigma_km_s ** 2 + var_pos / tau**2
            d2 = (dist / tau - v_circ) ** 2 / var
            cost = d2 + np.log(var)
        feasible = (tau > 0) & (d2 <= self._gate1)
        return np.where(feasible, cost, np.inf), feasible
