"""Which pairs of a catalog may come close, epoch by epoch: a spatial grid, compiled.

At each epoch ``t_s`` of a fine grid (spacing h) every object's state is interpolated
(`hermite`) and binned in a grid of cubic cells; a pair is tested only when one object lies
in one of the 8 cells nearest the other (the cells are twice the largest distance a pair can
be apart at ``t_s`` and still pass the test below: then the other object is in one of
those 8). The test, per pair (i, j) at ``t_s``, with ``dr``, ``dv`` the interpolated
relative position and velocity::

    min over |tau| <= h/2 of |dr + dv tau|  <=  D + e_i + e_j + (ev_i + ev_j) h/2
                                                 + (h²/8) (a_i + a_j)

where D is the screening distance, ``e``, ``ev`` bound the interpolation errors of position
and velocity (`hermite.interpolation_pad`) and ``a`` the size of each object's acceleration.
It cannot miss: if the pair's true distance falls to D or less at some epoch ``t*``, the
fine epoch nearest ``t*`` is within h/2 of it, the relative motion departs from the straight
line through the true state at ``t_s`` by at most ``tau² (a_i + a_j) / 2``, and the
interpolated state differs from the true one by at most the error bounds. Pairs whose
radial bands cannot meet (`apsides`) are skipped, and so are pairs of which neither object
is a primary (a re-screening of a few objects against the catalog).

Every pair that passes is a *hit* ``(i, j, s)``: its closest approaches (`tca`) are looked
for within h/2 of ``t_s``. Units: km, km/s, km/s², s.
"""

from __future__ import annotations

import math
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ssa_fusion.core.base.jit import f64, jit, jit_nogil
from ssa_fusion.core.conjunction.apsides import meet
from ssa_fusion.core.conjunction.hermite import (
    NodeTable,
    Weights,
    hermite_weights,
    position,
    velocity,
)

__all__ = ["Hits", "PairLimits", "near_primaries", "sieve"]

Array = NDArray[np.float64]
IntArray = NDArray[np.int64]
BoolArray = NDArray[np.bool_]

@dataclass(frozen=True)
class PairLimits:
    """What bounds each object's part of the pair test over a span of time (N,) each.

    Attributes
    ----------
    lo, hi : ndarray
        Radial band, km (`apsides.radial_bands`).
    vmax : ndarray
        Largest speed, km/s.
    amax : ndarray
        Largest acceleration, km/s².
    eps, eps_v : ndarray
        Interpolation error bounds, km and km/s (`hermite.interpolation_pad`).
    primary : ndarray of bool
        Pairs with at least one primary object are tested.
    """

    lo: Array
    hi: Array
    vmax: Array
    amax: Array
    eps: Array
    eps_v: Array
    primary: BoolArray

    def reach(self, distance_km: float, h: float) -> float:
        """Return the largest separation (km) at a fine epoch a tested pair can have."""
        live = np.isfinite(self.lo) & (self.hi >= self.lo)
        if not live.any():
            return distance_km
        v = float(np.max((self.vmax + self.eps_v)[live]))
        e = float(np.max((self.eps + self.eps_v * h / 2 + h * h / 8 * self.amax)[live]))
        return distance_km + 2.0 * e + h * v


@dataclass(frozen=True)
class Hits:
    """Pairs that passed the test, and at which fine epoch (`sieve`).

    Attributes
    ----------
    i, j : ndarray (M,) of int
        The pair's objects: ``i`` a primary, and ``i < j`` when both are.
    s : ndarray (M,) of int
        The fine epoch's index (epoch ``t_first_sample + s h``).
    """

    i: IntArray
    j: IntArray
    s: IntArray


@jit
def _cell_key(cx: int, cy: int, cz: int, mask: int) -> int:
    """Return the hash bucket of cell (cx, cy, cz) (``mask`` = buckets - 1).

    The multipliers are primes (the spatial hash of Teschner et al. 2003).
    """
    return ((cx * 73856093) ^ (cy * 19349663) ^ (cz * 83492791)) & mask


@jit
def _bin(nodes: Array, k: int, w: Weights, live: BoolArray, cell: float, pos: Array,
         cells: IntArray, counts: IntArray, order: IntArray, mask: int) -> None:
    """Interpolate every live object's position in node interval k; sort them by bucket.

    ``pos[i]`` the position (weights ``w``), ``cells[i]`` its cell (``cells[i, 3]`` = 0 when
    the object is absent: not live or NaN); ``order`` the objects by bucket, ``counts[b]``
    the start of bucket b in it (``counts[b + 1]`` its end).
    """
    counts[:] = 0
    for i in range(pos.shape[0]):
        cells[i, 3] = 0
        if not live[i]:
            continue
        position(nodes, k, i, w, pos[i])
        x, y, z = pos[i, 0], pos[i, 1], pos[i, 2]
        if not (math.isfinite(x) and math.isfinite(y) and math.isfinite(z)):
            continue
        cx, cy, cz = math.floor(x / cell), math.floor(y / cell), math.floor(z / cell)
        cells[i, 0], cells[i, 1], cells[i, 2], cells[i, 3] = cx, cy, cz, 1
        counts[_cell_key(cx, cy, cz, mask) + 1] += 1
    for b in range(1, counts.size):
        counts[b] += counts[b - 1]
    for i in range(pos.shape[0]):
        if cells[i, 3]:
            key = _cell_key(cells[i, 0], cells[i, 1], cells[i, 2], mask)
            order[counts[key]] = i
            counts[key] += 1
    for b in range(counts.size - 1, 0, -1):  # filling moved each start to the next one's
        counts[b] = counts[b - 1]
    counts[0] = 0


@jit
def _passes(pos: Array, nodes: Array, k: int, w: Weights, i: int, j: int, h: float,
            distance: float, limits: Array, vel: Array) -> bool:
    """Return whether pair (i, j) passes the test of the module docstring at this epoch.

    ``limits`` (N, 6): lo, hi, vmax, amax, eps, eps_v of each object (`PairLimits`); the
    velocities are interpolated (into ``vel`` (2, 6)) only for a pair near enough.
    """
    li, lj = limits[i], limits[j]
    d0 = pos[j, 0] - pos[i, 0]
    d1 = pos[j, 1] - pos[i, 1]
    d2 = pos[j, 2] - pos[i, 2]
    limit = (distance + li[4] + lj[4] + (li[5] + lj[5]) * 0.5 * h
             + 0.125 * h * h * (li[3] + lj[3]))
    reach = limit + 0.5 * h * (li[2] + lj[2] + li[5] + lj[5])
    if d0 * d0 + d1 * d1 + d2 * d2 > reach * reach:
        return False
    if not meet(li[0], li[1], lj[0], lj[1], limit):
        return False
    velocity(nodes, k, i, w, vel[0])
    velocity(nodes, k, j, w, vel[1])
    w0 = vel[1, 3] - vel[0, 3]
    w1 = vel[1, 4] - vel[0, 4]
    w2 = vel[1, 5] - vel[0, 5]
    ww = w0 * w0 + w1 * w1 + w2 * w2
    tau = 0.0
    if ww > 0.0:
        tau = min(max(-(d0 * w0 + d1 * w1 + d2 * w2) / ww, -0.5 * h), 0.5 * h)
    e0, e1, e2 = d0 + w0 * tau, d1 + w1 * tau, d2 + w2 * tau
    return bool(e0 * e0 + e1 * e1 + e2 * e2 <= limit * limit)


@jit
def _query(pos: Array, cells: IntArray, counts: IntArray, order: IntArray, mask: int,
           cell: float, primary: BoolArray, nodes: Array, k: int, w: Weights, s: int,
           h: float, distance: float, limits: Array, out: IntArray, n_out: int) -> int:
    """Test each primary's pairs in its 8 nearest cells; append hits to ``out``.

    ``out`` (capacity, 3) rows (i, j, s); returns the new number of hits (beyond the
    capacity they are counted, not written).
    """
    vel = np.empty((2, 6))
    for i in range(pos.shape[0]):
        if not (cells[i, 3] and primary[i]):
            continue
        cx, cy, cz = cells[i, 0], cells[i, 1], cells[i, 2]
        ox = 1 if pos[i, 0] / cell - cx >= 0.5 else -1
        oy = 1 if pos[i, 1] / cell - cy >= 0.5 else -1
        oz = 1 if pos[i, 2] / cell - cz >= 0.5 else -1
        for q in range(8):
            qx = cx + (ox if q & 1 else 0)
            qy = cy + (oy if q & 2 else 0)
            qz = cz + (oz if q & 4 else 0)
            key = _cell_key(qx, qy, qz, mask)
            for b in range(counts[key], counts[key + 1]):
                j = order[b]
                if j == i or (primary[j] and j < i):
                    continue
                if cells[j, 0] != qx or cells[j, 1] != qy or cells[j, 2] != qz:
                    continue
                if _passes(pos, nodes, k, w, i, j, h, distance, limits, vel):
                    if n_out < out.shape[0]:
                        out[n_out, 0], out[n_out, 1], out[n_out, 2] = i, j, s
                    n_out += 1
    return n_out


@jit_nogil
def _sieve_kernel(nodes: Array, q0: int, m: int, s0: int, s1: int, h: float, cell: float,
                  distance: float, live: BoolArray, primary: BoolArray, limits: Array,
                  out: IntArray) -> int:
    """Run `_bin` and `_query` at fine epochs ``q0 + s`` (h apart from node 0), s0 <= s < s1.

    ``m`` fine steps per node interval. Returns the number of hits (`_query`).
    """
    n = nodes.shape[1]
    buckets = 1
    while buckets < 2 * n:
        buckets *= 2
    mask = buckets - 1
    pos = np.empty((n, 3))
    cells = np.zeros((n, 4), dtype=np.int64)
    counts = np.zeros(buckets + 1, dtype=np.int64)
    order = np.zeros(n, dtype=np.int64)
    n_out = 0
    last = nodes.shape[0] - 2
    for s in range(s0, s1):
        q = q0 + s
        k, r = q // m, q % m
        if k > last:
            k, r = last, m
        w = hermite_weights(r / m, h * m)
        _bin(nodes, k, w, live, cell, pos, cells, counts, order, mask)
        n_out = _query(pos, cells, counts, order, mask, cell, primary, nodes, k, w, s, h,
                       distance, limits, out, n_out)
    return n_out


def near_primaries(limits: PairLimits, distance_km: float) -> BoolArray:
    """Return which objects have a state and a radial band meeting some primary's (N,).

    Within ``distance_km``: the objects a re-screening of the primaries must bin (the
    others cannot pass the test with any of them).
    """
    live: BoolArray = np.isfinite(limits.lo) & (limits.hi >= limits.lo)
    p = live & limits.primary
    if p.all() or not p.any():
        return live & p.any()
    order = np.argsort(limits.lo[p])
    plo, phi = limits.lo[p][order], np.maximum.accumulate(limits.hi[p][order])
    k = np.searchsorted(plo, limits.hi + distance_km, side="right")  # primaries low enough
    reach = np.where(k > 0, phi[np.maximum(k - 1, 0)], -np.inf)
    out: BoolArray = live & (reach >= limits.lo - distance_km)
    return out


def sieve(table: NodeTable, q0: int, m: int, n_steps: int, distance_km: float,
          limits: PairLimits, workers: int = 1, capacity: int = 1 << 16) -> Hits:
    """Return the pairs that may come within ``distance_km`` near fine epochs (`Hits`).

    Parameters
    ----------
    table : NodeTable
        States and accelerations at the nodes (spacing H = ``table.step_s``).
    q0 : int
        Index of the first fine epoch, in fine steps h = H / m after node 0.
    m : int
        Fine steps per node interval.
    n_steps : int
        Fine epochs to test: hit ``s`` is at ``table.t_first + (q0 + s) h``, within the
        table (``q0 + n_steps - 1 <= m (K - 1)``).
    distance_km : float
        Screening distance, km.
    limits : PairLimits
        Each object's bounds over the span.
    workers : int
        Threads, each testing a share of the fine epochs (the kernel releases the GIL).
    capacity : int
        Hits held at first per thread (the kernel runs again with room for all when more
        pass).
    """
    h = table.step_s / m
    if q0 < 0 or q0 + n_steps - 1 > m * (table.nodes.shape[0] - 1):
        raise ValueError("the fine epochs run outside the node table")
    live = near_primaries(limits, distance_km)
    cell = 2.0 * limits.reach(distance_km, h)
    nodes = f64(table.nodes)
    primary = np.ascontiguousarray(limits.primary, dtype=np.bool_)
    table6 = f64(np.stack([limits.lo, limits.hi, limits.vmax, limits.amax, limits.eps,
                           limits.eps_v], axis=1))

    def block(s0: int, s1: int) -> IntArray:
        out = np.empty((capacity, 3), dtype=np.int64)
        for _ in range(2):  # again with room for every hit when they overflowed
            n = _sieve_kernel(nodes, int(q0), int(m), s0, s1, float(h), float(cell),
                              float(distance_km), live, primary, table6, out)
            if n <= out.shape[0]:
                break
            out = np.empty((n, 3), dtype=np.int64)
        return out[:n]

    cuts = np.linspace(0, n_steps, max(1, min(workers, n_steps)) + 1).astype(int).tolist()
    if len(cuts) == 2:
        hits = block(0, n_steps)
    else:
        with ThreadPoolExecutor(len(cuts) - 1) as pool:
            hits = np.concatenate(list(pool.map(block, cuts[:-1], cuts[1:])))
    return Hits(hits[:, 0].copy(), hits[:, 1].copy(), hits[:, 2].copy())
