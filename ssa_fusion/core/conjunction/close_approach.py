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

from collections.abc import Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ssa_fusion.core.conjunction.encounter import relative_state_rtn
from ssa_fusion.core.conjunction.probability import pc2d_batch

__all__ = ["CloseApproaches"]

Array = NDArray[np.float64]
IntArray = NDArray[np.int64]
BoolArray = NDArray[np.bool_]


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

    def log10_pc(self, hbr_km: float) -> Array:
        """Return each approach's 2D Pc (Foster) as its log10 (M,), NaN without covariances.

        ``hbr_km``: the combined hard-body radius, km (`probability.pc2d_batch`).
        """
        if self.p1 is None or self.p2 is None or not len(self):
            return np.full(len(self), np.nan)
        _, integral = pc2d_batch(self.x1, self.p1, self.x2, self.p2, hbr_km)
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

    @classmethod
    def concat(cls, parts: Sequence[CloseApproaches]) -> CloseApproaches:
        """Return the rows of ``parts`` (same catalog) one after the other."""
        if not parts:
            raise ValueError("nothing to concatenate")
        first = parts[0]
        covs = all(p.p1 is not None and p.p2 is not None for p in parts)

        def cat(name: str) -> NDArray[Any]:
            return np.concatenate([getattr(p, name) for p in parts])

        return cls(first.object_ids, cat("primary"), cat("secondary"), cat("tca"),
                   cat("miss_km"), cat("x1"), cat("x2"), cat("p1") if covs else None,
                   cat("p2") if covs else None)

    def sorted(self) -> CloseApproaches:
        """Return the approaches by TCA (ties: by primary, then secondary)."""
        return self.take(np.lexsort((self.secondary, self.primary, self.tca)))
