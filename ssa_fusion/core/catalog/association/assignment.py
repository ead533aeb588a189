"""Assignment: global nearest neighbour over the gated pairs of a scan.

`assign`: one detection per track and one track per detection, by
`scipy.optimize.linear_sum_assignment`: among the assignments of feasible pairs with the
most pairs, the one of least total cost (the assignment Stone Soup's
``GNNWith2DAssignment`` makes with a missed-detection distance beyond every feasible cost).
`associate` predicts, gates (`gating`) and assigns one scan. ``scipy.optimize`` is imported
by `assign` at its first call (package docstring).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ssa_fusion.core.catalog.association.config import AssociationConfig
from ssa_fusion.core.catalog.association.gating import (
    Gated,
    ScanPrediction,
    gate_scan,
    predict_scan,
)
from ssa_fusion.core.catalog.batch_ekf import BatchEKF

__all__ = ["UNASSIGNED", "ScanAssociation", "assign", "associate"]

IntArray = NDArray[np.int64]

UNASSIGNED = -1
"""The track index of a detection assigned to no track."""


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


def assign(cost: ArrayLike, feasible: ArrayLike) -> IntArray:
    """Global nearest neighbour: the track of each detection (module docstring).

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
    from scipy.optimize import linear_sum_assignment  # here: the package docstring, imports

    r, c = linear_sum_assignment(work)
    keep = fs[r, c]
    out[cols[c[keep]]] = rows[r[keep]]
    return out


def associate(ekf: BatchEKF, x: ArrayLike, P: ArrayLike, t_track: ArrayLike,
              t_scan: ArrayLike, z: ArrayLike, R: ArrayLike, station: int,
              config: AssociationConfig) -> ScanAssociation:
    """Predict, gate and assign one station's scan to N tracks (`gating`, `assign`).

    Parameters as `predict_scan` and `gate_scan`; the gate is ``config.gate``.
    """
    pred = predict_scan(ekf, x, P, t_track, t_scan, station)
    gated = gate_scan(pred, z, R, config.gate)
    return ScanAssociation(assign(gated.cost, gated.feasible), gated, pred)


