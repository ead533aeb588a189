"""Registration: groups of tracks shifted along track by a common time before the assignment.

Objects launched together (a train) share the error their motion model leaves out (drag,
the model's own error): after a long gap every member's prediction is off along track by
nearly the same time, which can exceed the members' spacing, and the assignment of the
shifted train (each track on its neighbour's detection) then costs about as little as the
true one. `register` gives each *group* of tracks (linked by detections they both gate,
or, by `linked_tracks`, predicted on one orbit close together) one shift along track: the
common time, with a Gaussian prior, that best aligns the group with the scan
(`config.AssociationConfig.register_groups`, ``group_link_km``). ``scipy.sparse`` is
imported by `register` at its first call (package docstring). Units: km, km/s, rad, s.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ssa_fusion.core.catalog.association.assignment import assign
from ssa_fusion.core.catalog.association.gating import ScanPrediction, whitened

__all__ = ["linked_tracks", "register"]

Array = NDArray[np.float64]
BoolArray = NDArray[np.bool_]
IntArray = NDArray[np.int64]


def register(prediction: ScanPrediction, z: ArrayLike, R: ArrayLike, feasible: ArrayLike,
             gate: float, sigma_shift_s: ArrayLike, candidates: int = 4,
             linked: ArrayLike | None = None) -> Array:
    """Return the common along-track shift of each group of tracks sharing detections (s).

    A *group* is a connected set of two or more tracks linked by feasible pairs (two tracks
    sharing a detection they both gate); every group gets one shift ``s`` (its tracks moved
    along their orbits by ``s`` seconds: ``zp + zp_rate s``, first order), with a Gaussian
    prior N(0, sigma^2) (sigma: the median of its tracks' ``sigma_shift_s``), that
    maximises the likelihood of its best assignment (`group_shift`). Irregular spacings
    make the true alignment unique.

    Parameters
    ----------
    prediction : ScanPrediction
        The N tracks predicted to the scan, with ``zp_rate`` (`gating.predict_scan`).
    z, R : array_like (M, 3), (M, 3, 3)
        Detections and their noise (as `gating.gate_scan`).
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
        More links between tracks (e.g. `linked_tracks`): a group then spans them too, so
        that the end of a train with a single detection is not registered alone (one
        detection aligns with any of its tracks).

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
    from scipy.sparse.csgraph import connected_components  # here: the package docstring

    ngroups, group = connected_components(share, directed=False)
    if ngroups == n:  # no group of two or more: nothing to register
        return shift
    quad = _pair_quadratics(prediction, z, R, F)
    if quad is None:
        return shift
    F, a, b, c, ld = quad
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
        shift[rows] = group_shift(A, B, C, LD, fs, sigma, gate, candidates)
    return shift


def _pair_quadratics(prediction: ScanPrediction, z: ArrayLike, R: ArrayLike,
                     F: BoolArray) -> tuple[BoolArray, Array, Array, Array, Array] | None:
    """Return each pair's ``d^2(s) = a - 2 b s + c s^2`` and ``ln det S`` (N, M).

    nan where not computable, with the feasible pairs ``F`` restricted to the computable
    ones; None without ``zp_rate``.
    """
    w, u, ok, logdet = whitened(prediction, z, R)
    if u is None:
        return None
    a, b, c, ld = (np.full(ok.shape, np.nan) for _ in range(4))
    a[ok], b[ok], c[ok] = (np.einsum("ij,ij->i", w, w), np.einsum("ij,ij->i", u, w),
                           np.einsum("ij,ij->i", u, u))
    ld[ok] = logdet
    return F & ok, a, b, c, ld


def group_shift(A: Array, B: Array, C: Array, LD: Array, fs: BoolArray, sigma: float,
                gate: float, candidates: int) -> float:
    """Return the along-track shift of one group, s (`register`).

    The search: every feasible pair's own best shift (``s_ij``, where the pair's ``d^2(s)
    = A - 2 B s + C s^2`` is least) and 0 are candidates, ranked by the sum over the
    group's detections of their least ``d^2(s)`` (clipped at ``gate``) plus the prior's
    ``s^2 / sigma^2``; the best ``candidates`` distinct ones are solved by `assign` and
    refined in closed form on their assignment (``s = sum B / (sum C + 1 / sigma^2)``);
    the least total cost (``d^2 + ln det S`` of the pairs plus the prior) wins.

    Parameters
    ----------
    A, B, C, LD : ndarray (K, L)
        The group's K tracks against the L detections they gate: the coefficients of each
        pair's ``d^2(s)`` and its ``ln det S``.
    fs : ndarray (K, L) of bool
        The feasible pairs.
    sigma : float
        The prior's standard deviation of the shift, s (> 0).
    gate, candidates
        As `register`.
    """
    cand, order = _ranked_candidates(A, B, C, fs, sigma, gate)
    picked: list[float] = []
    best = (math.inf, 0.0)
    for k in order.tolist():
        s0 = float(cand[k])
        if any(abs(s0 - p) < 1e-3 * sigma for p in picked):
            continue
        picked.append(s0)
        total, s0 = _solve_at(A, B, C, LD, fs, sigma, s0)
        if total < best[0]:
            best = (total, s0)
        if len(picked) >= candidates:
            break
    return best[1]


def _ranked_candidates(A: Array, B: Array, C: Array, fs: BoolArray, sigma: float,
                       gate: float) -> tuple[Array, IntArray]:
    """Return the candidate shifts (0 and each feasible pair's own), s, and their ranking."""
    with np.errstate(divide="ignore", invalid="ignore"):
        own = np.where(fs & (C > 0), B / C, np.nan)
    cand = np.unique(np.r_[0.0, own[np.isfinite(own)]])
    d2 = A[None] - 2.0 * B[None] * cand[:, None, None] + C[None] * cand[:, None, None] ** 2
    d2 = np.where(fs[None], d2, np.inf)
    rank = np.minimum(d2.min(1), gate).sum(-1) + (cand / sigma) ** 2
    order: IntArray = np.argsort(rank, kind="stable")
    return cand, order


def _solve_at(A: Array, B: Array, C: Array, LD: Array, fs: BoolArray, sigma: float,
              s0: float) -> tuple[float, float]:
    """Assign at the shift ``s0``, refine it on the assignment (twice): (total cost, shift)."""
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
    return total, s0


def linked_tracks(pred: ScanPrediction, fine: ScanPrediction, which: IntArray,
                  link_km: float, speed_fraction: float) -> BoolArray:
    """Pairs of the tracks ``which`` on one orbit, close together (K, K) of bool.

    At the scan's first epoch, from the long-arc prediction ``fine`` (positions and
    velocities in the station's range/azimuth/elevation frame, km and km/s: ``[r,
    r cos(el) az, r el]`` and the same of ``zp_rate``): two tracks are linked when their
    predicted positions differ by at most ``link_km`` and their velocities by at most
    ``speed_fraction`` of the speed (objects launched together; crossing planes differ in
    velocity by a large fraction of it; `AssociationConfig.group_link_km`,
    ``group_link_speed_fraction``). ``pred`` (the tracks' filter's) marks the predictions
    that are computable.
    """
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
    out: BoolArray = ((dp <= link_km) & (dv <= speed_fraction * speed[:, None])
                      & ok[:, None] & ok[None, :])
    return out
