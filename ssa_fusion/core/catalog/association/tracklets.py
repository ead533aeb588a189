"""Tracklets: detections no track took, of one station in one pass, not yet an orbit.

The detections no track took (`manager.Associator`) extend *tracklets* by the same gate and
assignment (`assignment.assign`) on a tracklet's prediction: from its last two detections
(their GCRF positions, `detection_positions`: `iod.razel_to_gcrs`, with the range/az/el
noise pushed through the inverse Jacobian of `batch_ekf.BatchEKF.measure`) by two-body
gravity; a tracklet of one detection has no velocity yet, and a detection extends it when
the speed the pair implies is near the circular speed at its radius
(``tracklet_speed_sigma_km_s``: a prior of near-circular orbits, gated at the same
probability with 1 degree of freedom). The rest start new tracklets, named by the id of the
track their IOD will start ("T1", "T2", ...). A tracklet without a detection for
``tracklet_max_gap_s`` is dropped (`config.AssociationConfig`). Units: km, km/s, rad, s
(Unix s UTC), GCRF.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ssa_fusion.core.base.constants import MU_EARTH
from ssa_fusion.core.catalog.association.assignment import UNASSIGNED, assign
from ssa_fusion.core.catalog.association.config import AssociationConfig, chi2_quantile
from ssa_fusion.core.catalog.batch_ekf import BatchEKF
from ssa_fusion.core.measure.iod import razel_to_gcrs

__all__ = ["Extension", "Tracklets", "detection_positions", "gravity"]

Array = NDArray[np.float64]
BoolArray = NDArray[np.bool_]
IntArray = NDArray[np.int64]

Detection = tuple[float, Array, Array]
"""A raw detection kept for the IOD: (epoch Unix s, [range km, az rad, el rad], noise)."""


def detection_positions(ekf: BatchEKF, st: int, t: Array, z: Array,
                        R: Array) -> tuple[Array, Array]:
    """GCRF positions (M, 3) km of detections and their covariances (M, 3, 3) km^2.

    ``z`` (M, 3) [range km, az rad, el rad] with noise ``R`` (M, 3, 3) at ``t`` (M,) Unix s
    from station ``ekf.stations[st]``.
    """
    r = razel_to_gcrs(z, t, ekf.stations[st])
    x = np.concatenate([r, np.zeros_like(r)], -1)
    _, H = ekf.measure(x, t, np.full(t.size, st, dtype=np.intp))
    Hi = np.linalg.inv(H[:, :, :3])
    return r, Hi @ R @ np.swapaxes(Hi, -1, -2)


def gravity(r: Array) -> Array:
    """Two-body acceleration (..., 3) km/s^2 at GCRF positions r (..., 3) km."""
    n = np.linalg.norm(r, axis=-1, keepdims=True)
    out: Array = -MU_EARTH * r / n**3
    return out


@dataclass(frozen=True)
class Extension:
    """What `Tracklets.extend` did with a scan's free detections.

    Attributes
    ----------
    names : list of str
        Per free detection, the id of the tracklet it went to.
    extended : ndarray of int
        The free detections (indices among them) that extended a tracklet.
    started : int
        How many started a tracklet.
    """

    names: list[str]
    extended: IntArray
    started: int


class Tracklets:
    """The open tracklets of an associator, one row each (module docstring).

    Parameters
    ----------
    config : AssociationConfig
        The gate and the tracklets' rules.
    """

    def __init__(self, config: AssociationConfig) -> None:
        self.config = config
        self._gate = config.gate
        self._gate1 = chi2_quantile(config.gate_probability, 1)
        self._next_id = 1
        self.ids: list[str] = []
        self.station = np.zeros(0, dtype=np.int64)
        self.length = np.zeros(0, dtype=np.int64)
        self.t = np.zeros((0, 2))
        """Epochs of each tracklet's last two detections, Unix s."""
        self.r = np.zeros((0, 2, 3))
        """Their GCRF positions, km."""
        self.C = np.zeros((0, 2, 3, 3))
        """Their position covariances, km^2."""
        self.raw: dict[str, list[Detection]] = {}
        """Each tracklet's detections, by id (for its IOD)."""

    def expire(self, t_scan: float) -> int:
        """Drop the tracklets too old to extend at `t_scan` (Unix s); return how many."""
        old = t_scan - self.t[:, 1] > self.config.tracklet_max_gap_s
        self.keep(~old)
        return int(old.sum())

    def keep(self, keep: BoolArray) -> None:
        """Keep the tracklets where ``keep`` holds, drop the others."""
        for i in np.flatnonzero(~keep).tolist():
            self.raw.pop(self.ids[i], None)
        self.ids = [s for s, k in zip(self.ids, keep.tolist(), strict=True) if k]
        self.station = self.station[keep]
        self.length = self.length[keep]
        self.t = self.t[keep]
        self.r = self.r[keep]
        self.C = self.C[keep]

    def extend(self, st: int, r: Array, C: Array, t: Array,
               raw: list[Detection]) -> Extension:
        """Extend the tracklets of station ``st`` with free detections; start new ones.

        ``r``, ``C`` (M, 3), (M, 3, 3): the detections' GCRF positions and covariances
        (`detection_positions`), ``t`` (M,) their epochs, ``raw`` the detections as kept for
        the IOD.
        """
        take = self._match(st, r, C, t)
        ext = np.flatnonzero(take >= 0)
        k = take[ext]
        self.t[k, 0], self.r[k, 0], self.C[k, 0] = self.t[k, 1], self.r[k, 1], self.C[k, 1]
        self.t[k, 1], self.r[k, 1], self.C[k, 1] = t[ext], r[ext], C[ext]
        self.length[k] += 1
        new = np.flatnonzero(take == UNASSIGNED)
        self.ids += [f"T{self._next_id + i}" for i in range(new.size)]
        self._next_id += new.size
        self.station = np.r_[self.station, np.full(new.size, st, np.int64)]
        self.length = np.r_[self.length, np.ones(new.size, np.int64)]
        self.t = np.concatenate([self.t, np.repeat(t[new, None], 2, 1)])
        self.r = np.concatenate([self.r, np.repeat(r[new, None], 2, 1)])
        self.C = np.concatenate([self.C, np.repeat(C[new, None], 2, 1)])
        owner = np.empty(t.size, dtype=np.int64)
        owner[ext], owner[new] = k, self.station.size - new.size + np.arange(new.size)
        names = [self.ids[o] for o in owner.tolist()]
        for name, detection in zip(names, raw, strict=True):
            self.raw.setdefault(name, []).append(detection)
        return Extension(names, ext, int(new.size))

    def _match(self, st: int, r: Array, C: Array, t: Array) -> IntArray:
        """Per detection the tracklet it extends, or `UNASSIGNED`: the moving ones first."""
        take = np.full(t.size, UNASSIGNED, dtype=np.int64)
        mine = self.station == st
        for cost_of, which in ((self._cost_moving, mine & (self.length >= 2)),
                               (self._cost_first, mine & (self.length == 1))):
            cand = np.flatnonzero(which)
            left = np.flatnonzero(take == UNASSIGNED)
            if not cand.size or not left.size:
                continue
            cost, feasible = cost_of(cand, r[left], C[left], t[left])
            got = assign(cost, feasible)
            take[left[got >= 0]] = cand[got[got >= 0]]
        return take

    def complete(self, samples: int) -> IntArray:
        """Return the rows of the tracklets of at least ``samples`` detections."""
        return np.flatnonzero(self.length >= samples)

    def _cost_moving(self, cand: IntArray, r: Array, C: Array,
                     t: Array) -> tuple[Array, BoolArray]:
        """Cost (T, M) of adding each detection to each tracklet of two or more detections.

        The tracklet's next position from its last two by two-body gravity (module
        docstring); the gate and cost as `gating.gate_scan`'s, in GCRF position.
        """
        t1, t2 = self.t[cand, 0], self.t[cand, 1]
        r1, r2 = self.r[cand, 0], self.r[cand, 1]
        h = (t2 - t1)[:, None]
        a = gravity(r2)
        v2 = (r2 - r1) / h + 0.5 * a * h
        tau = t[None, :] - t2[:, None]  # (T, M)
        pred = r2[:, None] + v2[:, None] * tau[..., None] + 0.5 * a[:, None] * tau[..., None] ** 2
        c = (tau / h)[..., None, None]
        q = (self.config.tracklet_accel_sigma_km_s2 * 0.5 * tau * (tau + h)) ** 2
        S = ((1 + c) ** 2 * self.C[cand, 1][:, None] + c**2 * self.C[cand, 0][:, None]
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
        t1, r1, C1 = self.t[cand, 1], self.r[cand, 1], self.C[cand, 1]
        tau = t[None, :] - t1[:, None]
        with np.errstate(divide="ignore", invalid="ignore"):
            d = (r[None] - r1[:, None]
                 - 0.5 * gravity(r1)[:, None] * tau[..., None] ** 2)  # (T, M, 3)
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
