"""A brute-force screening to score `core.conjunction.screening` against: every pair, every step.

`brute_force_approaches` samples every object of an `Ephemeris` on a uniform grid (1 s by
default: the states themselves, never an interpolant), finds at every step all pairs within
``D + 2 vmax step / 2`` of each other (``vmax`` the largest speed seen: a pair whose distance
falls to D between two steps is that close at the nearer one) with a k-d tree
(`scipy.spatial.cKDTree`, exact for a radius query), keeps the steps where a pair's sampled
distance is a local minimum, and refines each by bounded Brent minimisation of the exact
distance (`scipy.optimize.minimize_scalar`) between the steps either side. It shares nothing
with the screening but the trajectories: no grid of cells, no interpolation, no bounds.

`match` pairs a screening's approaches with the reference's (same pair, TCAs within a
tolerance): recall, and the TCA and miss differences.

Units: epochs Unix s (UTC), km.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import minimize_scalar
from scipy.spatial import cKDTree

from ssa_fusion.core.conjunction.close_approach import CloseApproaches
from ssa_fusion.core.conjunction.ephemeris import Ephemeris

__all__ = ["Match", "ReferenceApproaches", "brute_force_approaches", "match"]

Array = NDArray[np.float64]
IntArray = NDArray[np.int64]

CURVATURE_KM = 0.05
"""Added to the k-d tree radius for the bend of the relative motion over half a step (1 s
steps: < 3 m in LEO)."""


@dataclass(frozen=True)
class ReferenceApproaches:
    """The reference's close approaches: objects i < j, TCA (Unix s) and miss (km), (M,) each."""

    i: IntArray
    j: IntArray
    tca: Array
    miss_km: Array

    def __len__(self) -> int:
        """Return the number of approaches."""
        return int(self.tca.size)


def _local_minima(x: Array, radius: float) -> list[tuple[int, int, int]]:
    """Return (i, j, k) where pair (i, j)'s distance at step k (1..T-2) is a local minimum.

    ``x`` (N, T, 3) positions; only pairs within ``radius`` at step k (k-d tree).
    """
    out: list[tuple[int, int, int]] = []
    for k in range(1, x.shape[1] - 1):
        p = x[:, k]
        ok = np.flatnonzero(np.isfinite(p).all(axis=1))
        pairs = cKDTree(p[ok]).query_pairs(radius, output_type="ndarray")
        if not pairs.size:
            continue
        i, j = ok[pairs[:, 0]], ok[pairs[:, 1]]
        d = [np.linalg.norm(x[j, k + s] - x[i, k + s], axis=1) for s in (-1, 0, 1)]
        with np.errstate(invalid="ignore"):
            low = ~(d[0] < d[1]) & ~(d[2] < d[1])  # NaN neighbours count as farther
        out += [(int(a), int(b), k) for a, b in zip(i[low], j[low], strict=True)]
    return out


def _refine(eph: Ephemeris, i: int, j: int, lo: float, hi: float) -> tuple[float, float]:
    """Return (epoch, distance) of the smallest exact distance of pair (i, j) in [lo, hi].

    Minimised over the offset from ``lo`` (the method's relative tolerance, sqrt(eps) |x|,
    would be 26 s on a Unix epoch).
    """

    def dist(tau: float) -> float:
        x = eph.exact(np.array([i, j]), np.array([lo + tau, lo + tau]))
        return float(np.linalg.norm(x[1, :3] - x[0, :3]))

    res = minimize_scalar(dist, bounds=(0.0, hi - lo), method="bounded",
                          options={"xatol": 1e-6})
    return lo + float(res.x), float(res.fun)


def brute_force_approaches(eph: Ephemeris, t_start: float, t_end: float, distance_km: float,
                           step_s: float = 1.0, chunk_steps: int = 1200) -> ReferenceApproaches:
    """Every close approach within ``distance_km`` with TCA in [t_start, t_end] (module doc).

    The grid runs from one step before ``t_start`` to one after ``t_end``, ``chunk_steps``
    epochs sampled at a time (memory ~48 B per object and epoch).
    """
    n_grid = int(np.ceil((t_end - t_start) / step_s)) + 3
    t_all = t_start + step_s * (np.arange(n_grid) - 1.0)
    found: list[tuple[int, int, float, float]] = []
    for a in range(0, n_grid - 2, chunk_steps):
        t = t_all[a:min(a + chunk_steps + 2, n_grid)]
        x = eph.sample(t)
        vmax = float(np.nanmax(np.linalg.norm(x[..., 3:], axis=-1)))
        radius = distance_km + vmax * step_s + CURVATURE_KM
        for i, j, k in _local_minima(np.ascontiguousarray(x[..., :3]), radius):
            tk, dk = _refine(eph, i, j, float(t[k - 1]), float(t[k + 1]))
            if dk <= distance_km and t_start <= tk <= t_end:
                found.append((i, j, tk, dk))
    if not found:
        return ReferenceApproaches(np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0),
                                   np.zeros(0))
    f = np.array(found)
    order = np.lexsort((f[:, 2], f[:, 1], f[:, 0]))
    f = f[order]
    keep = np.ones(len(f), dtype=bool)  # a minimum on two steps (equal distances) once
    keep[1:] = (np.diff(f[:, 0]) != 0) | (np.diff(f[:, 1]) != 0) | (np.diff(f[:, 2]) > 0.01)
    f = f[keep]
    return ReferenceApproaches(f[:, 0].astype(np.int64), f[:, 1].astype(np.int64), f[:, 2],
                               f[:, 3])


@dataclass(frozen=True)
class Match:
    """A screening's approaches against the reference's (`match`).

    Attributes
    ----------
    found : ndarray (R,) of bool
        Per reference approach: the screening found it.
    extra : int
        Screening approaches not in the reference.
    dt_s, dmiss_km : ndarray (F,)
        TCA and miss differences (screening - reference) of the matched ones.
    """

    found: NDArray[np.bool_]
    extra: int
    dt_s: Array
    dmiss_km: Array

    @property
    def recall(self) -> float:
        """Fraction of the reference's approaches the screening found (1 when it has none)."""
        return float(self.found.mean()) if self.found.size else 1.0


def match(screened: CloseApproaches, ref: ReferenceApproaches, tol_s: float = 1.0) -> Match:
    """Match approaches by pair (either order) and TCA within ``tol_s``."""
    a = np.minimum(screened.primary, screened.secondary)
    b = np.maximum(screened.primary, screened.secondary)
    by_pair: dict[tuple[int, int], list[int]] = {}
    for k, key in enumerate(zip(a.tolist(), b.tolist(), strict=True)):
        by_pair.setdefault(key, []).append(k)
    used = np.zeros(len(screened), dtype=bool)
    found = np.zeros(len(ref), dtype=bool)
    dt, dm = [], []
    for r, key in enumerate(zip(ref.i.tolist(), ref.j.tolist(), strict=True)):
        for k in by_pair.get(key, []):
            if not used[k] and abs(screened.tca[k] - ref.tca[r]) <= tol_s:
                used[k] = found[r] = True
                dt.append(screened.tca[k] - ref.tca[r])
                dm.append(screened.miss_km[k] - ref.miss_km[r])
                break
    return Match(found, int((~used).sum()), np.array(dt), np.array(dm))
