"""What a screening finds: `CloseApproaches`, one row per pair and time of closest approach.

Each row: the primary and the secondary object, the time of closest approach (TCA), the
miss distance, both objects' states at TCA and, when the screened trajectories carry them,
both covariances at TCA (what a collision probability needs). Relative quantities are the
secondary minus the primary, in the primary's RTN frame at TCA (radial, along-track,
cross-track; the frame's axes at TCA, not rotating: a CDM's ``RELATIVE_POSITION_R`` ..
``RELATIVE_VELOCITY_N``).

Units: epochs Unix s (UTC), GCRF km, km/s, covariances km², km²/s, km²/s².
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ssa_fusion.core.conjunction.encounter import relative_state_rtn
from ssa_fusion.core.conjunction.probability import pc2d_batch

__all__ = ["SAME_APPROACH_S", "ApproachBuffer", "CloseApproaches", "once"]

Array = NDArray[np.float64]
IntArray = NDArray[np.int64]
BoolArray = NDArray[np.bool_]

SAME_APPROACH_S = 1e-3
"""Two approaches of one pair closer than this in time are one, s."""


@dataclass(frozen=True)
class CloseApproaches:
    """Close approaches of a catalog's pairs (module docstring), M rows.

    Attributes
    ----------
    object_ids : tuple of str
        The screened catalog's ids: ``primary`` and ``secondary`` index it.
    primary, secondary : ndarray (M,) of int
        The two objects of each approach.
    tca : ndarray (M,)
        Time of closest approach, Unix s (UTC).
    miss_km : ndarray (M,)
        Distance at TCA, km.
    x1, x2 : ndarray (M, 6)
        Primary's and secondary's GCRF states at TCA, km, km/s.
    p1, p2 : ndarray (M, 6, 6) or None
        Their GCRF covariances at TCA, km², km²/s, km²/s² (None when the screened
        trajectories carry none, e.g. element sets).
    """

    object_ids: tuple[str, ...]
    primary: IntArray
    secondary: IntArray
    tca: Array
    miss_km: Array
    x1: Array
    x2: Array
    p1: Array | None = None
    p2: Array | None = None

    def __len__(self) -> int:
        """Return the number of close approaches."""
        return int(self.tca.size)

    @property
    def primary_ids(self) -> list[str]:
        """The primaries' object ids (M)."""
        return [self.object_ids[k] for k in self.primary.tolist()]

    @property
    def secondary_ids(self) -> list[str]:
        """The secondaries' object ids (M)."""
        return [self.object_ids[k] for k in self.secondary.tolist()]

    @property
    def relative_speed(self) -> Array:
        """Relative speed at TCA (M,), km/s."""
        out: Array = np.linalg.norm(self.x2[:, 3:] - self.x1[:, 3:], axis=1)
        return out

    def relative_rtn(self) -> Array:
        """Return the secondary's state relative to the primary in the primary's RTN (M, 6).

        Position km, velocity km/s, both rotated by the primary's RTN axes at TCA
        (`encounter.relative_state_rtn`).
        """
        if not len(self):
            return np.zeros((0, 6))
        return relative_state_rtn(self.x1, self.x2)

    def log10_pc(self, hbr_km: float, refine_below_log10: float = -math.inf) -> Array:
        """Return each approach's 2D Pc (Foster) as its log10 (M,), NaN without covariances.

        ``hbr_km``: the combined hard-body radius, km; ``refine_below_log10``: the
        refinement floor (`probability.pc2d_batch`).
        """
        if self.p1 is None or self.p2 is None or not len(self):
            return np.full(len(self), np.nan)
        _, integral = pc2d_batch(self.x1, self.p1, self.x2, self.p2, hbr_km,
                                 refine_below_log10)
        out: Array = np.asarray(integral.log10_pc, dtype=float)
        return out

    def take(self, rows: ArrayLike) -> CloseApproaches:
        """Return the approaches ``rows`` (indices or a boolean mask)."""
        k = np.asarray(rows)
        return replace(self, primary=self.primary[k], secondary=self.secondary[k],
                       tca=self.tca[k], miss_km=self.miss_km[k], x1=self.x1[k], x2=self.x2[k],
                       p1=None if self.p1 is None else self.p1[k],
                       p2=None if self.p2 is None else self.p2[k])

    @classmethod
    def empty(cls, object_ids: Sequence[str], covariances: bool = False) -> CloseApproaches:
        """Return no close approach of a catalog ``object_ids``."""
        cov = np.zeros((0, 6, 6)) if covariances else None
        return cls(tuple(object_ids), np.zeros(0, np.int64), np.zeros(0, np.int64),
                   np.zeros(0), np.zeros(0), np.zeros((0, 6)), np.zeros((0, 6)), cov, cov)


def once(i: IntArray, j: IntArray, t: Array) -> IntArray:
    """Return the rows of pairs' epochs without repeats (one pair within `SAME_APPROACH_S`).

    By pair, then epoch.
    """
    order = np.lexsort((t, j, i))
    i, j, t = i[order], j[order], t[order]
    keep = np.ones(order.size, dtype=np.bool_)
    keep[1:] = (i[1:] != i[:-1]) | (j[1:] != j[:-1]) | (np.diff(t) > SAME_APPROACH_S)
    out: IntArray = order[keep]
    return out


class ApproachBuffer:
    """Approaches gathered batch by batch with one copy of them in memory.

    The rows are appended to arrays reserved ahead (`reserve`) or doubled when full;
    `result` removes repeats (`once`) and sorts by TCA field by field (one field's
    temporary at a time): ~144 B a row, 1.5 times that while a doubling copies.
    """

    _FIELDS = ("primary", "secondary", "tca", "miss_km", "x1", "x2")

    def __init__(self, object_ids: Sequence[str]) -> None:
        """Gather approaches of the catalog ``object_ids``."""
        self.object_ids = tuple(object_ids)
        self.n = 0
        self._a: dict[str, NDArray[Any]] = {
            "primary": np.zeros(0, np.int64), "secondary": np.zeros(0, np.int64),
            "tca": np.zeros(0), "miss_km": np.zeros(0), "x1": np.zeros((0, 6)),
            "x2": np.zeros((0, 6))}

    def reserve(self, rows: int) -> None:
        """Make room for ``rows`` rows in all (no copy when there is room already)."""
        if rows > self._a["tca"].shape[0]:
            for name, a in self._a.items():
                grown = np.empty((rows, *a.shape[1:]), dtype=a.dtype)
                grown[:self.n] = a[:self.n]
                self._a[name] = grown

    def add(self, i: IntArray, j: IntArray, tca: Array, miss_km: Array, x1: Array,
            x2: Array) -> None:
        """Append rows (M,) each (states (M, 6))."""
        m = int(tca.size)
        if self.n + m > self._a["tca"].shape[0]:
            self.reserve(max(self.n + m, 2 * self._a["tca"].shape[0]))
        for name, v in zip(self._FIELDS, (i, j, tca, miss_km, x1, x2), strict=True):
            self._a[name][self.n:self.n + m] = v
        self.n += m

    def result(self) -> CloseApproaches:
        """Return the approaches once each, by TCA (ties: primary, secondary).

        The buffer is emptied.
        """
        a = {k: v[:self.n] for k, v in self._a.items()}
        rows = once(a["primary"], a["secondary"], a["tca"])
        order = rows[np.lexsort((a["secondary"][rows], a["primary"][rows], a["tca"][rows]))]
        if order.size != self.n or np.any(np.diff(order) < 0):
            for name in self._FIELDS:  # one field's temporary at a time
                a[name] = a[name][order]
                self._a[name] = np.zeros((0, *a[name].shape[1:]), a[name].dtype)
        self.n = 0
        out = CloseApproaches(self.object_ids, a["primary"], a["secondary"], a["tca"],
                              a["miss_km"], a["x1"], a["x2"])
        self._a = {k: np.zeros((0, *v.shape[1:]), v.dtype) for k, v in self._a.items()}
        return out
