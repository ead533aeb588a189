"""Which pairs of a catalog may come close, epoch by epoch: a spatial grid, compiled.

At each epoch ``t_s`` of a fine grid (spacing h) every object's state is interpolated
(`hermite`) and binned in a grid of cubic cells as large as the farthest two objects can be
apart at ``t_s`` and still pass the test below, so that a pair that may pass lies in one
cell or two neighbouring ones: each object looks at its own cell and its 13 "forward"
neighbours (all 27 when only some objects are primaries). Cells are hashed into buckets
(each index modulo a power of 2, packed: neighbours land in nearby buckets), the objects
sorted by bucket with their states in float32 for the first checks, a bitmap of used
buckets looked at first. The test, per pair (i, j) at ``t_s``, with ``dr``, ``dv`` the
interpolated relative position and velocity::

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
from ssa_fusion.core.conjunction.apsides import meet, meets_any
from ssa_fusion.core.conjunction.hermite import (
    NodeTable,
    Weights,
    hermite_weights,
    interpolate,
)

__all__ = ["Hits", "PairLimits", "near_primaries", "sieve"]

Array = NDArray[np.float64]
IntArray = NDArray[np.int64]
BoolArray = NDArray[np.bool_]
Array32 = NDArray[np.float32]
UIntArray = NDArray[np.uint64]

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

    def radius(self, h: float) -> Array:
        """Return each object's part of a pair's reach (N,), km.

        A pair (i, j) that passes the test at a fine epoch (spacing h) is within
        ``D + radius_i + radius_j`` there. ``eps + eps_v h + (h²/8) amax + (h/2) vmax``:
        its interpolation error, its part of the bend of the relative motion and of the
        distance covered in h/2.
        """
        out: Array = (self.eps + self.eps_v * h + 0.125 * h * h * self.amax
                      + 0.5 * h * self.vmax)
        return out

    def reach(self, distance_km: float, h: float) -> float:
        """Return the largest separation (km) at a fine epoch a tested pair can have."""
        live = np.isfinite(self.lo) & (self.hi >= self.lo)
        if not live.any():
            return distance_km
        return distance_km + 2.0 * float(np.max(self.radius(h)[live]))


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


_STENCIL = np.array([(dx, dy, dz) for dx in (-1, 0, 1) for dy in (-1, 0, 1)
                     for dz in (-1, 0, 1)], dtype=np.int64)
"""The 27 cells around a cell (the cell itself at row 13); rows 14.. are the 13 "forward" ones:
of two different neighbouring cells, exactly one is forward of the other."""

_CODE_BITS = 21
"""Bits of each cell index in a cell's code (cells of > 10 m within 10⁴ Earth radii)."""

_POS32_KM = 0.01
"""Slack of the first checks for the float32 states they read, km (their round-off is
< 6e-8 relative: 5 m at 10⁵ km, and 0.6 mm/s at 10 km/s)."""


@jit
def _code(cx: int, cy: int, cz: int) -> int:
    """Return a cell's code: its three indices packed (`_CODE_BITS` each, offset to >= 0)."""
    off = 1 << (_CODE_BITS - 1)
    return ((cx + off) << (2 * _CODE_BITS)) | ((cy + off) << _CODE_BITS) | (cz + off)


@jit
def _cell_key(cx: int, cy: int, cz: int, bits: int) -> int:
    """Return the bucket of cell (cx, cy, cz): each index modulo ``2**bits``, packed.

    Neighbouring cells fall in nearby buckets (z in the low bits): the lookups of objects
    processed in bucket order stay in a few cache lines.
    """
    m = (1 << bits) - 1
    return (cz & m) | ((cy & m) << bits) | ((cx & m) << (2 * bits))


@jit
def _bin(nodes: Array, k: int, w: Weights, live: BoolArray, parts: Array, cell: float,
         bits: int, st: Array, cells: IntArray, counts: IntArray, used: UIntArray,
         order: IntArray, sst: Array32, sparts: Array, scode: IntArray) -> int:
    """Interpolate every live object in node interval k; sort them by bucket.

    Writes ``order[:n]`` (the n binned objects by bucket: live, with a finite position)
    with their states ``sst[:n]`` (float32), `PairLimits.radius` and pads ``sparts[:n]``
    (of ``parts``) and cell codes ``scode[:n]`` in that order; ``counts[b]`` the start of
    bucket b in it (``counts[b + 1]`` its end); bit b of ``used`` (64 buckets a word) set
    where bucket b holds an object (small enough to stay in the first-level cache, looked
    at before ``counts``). ``st`` and ``cells`` (N, 4: the cell and whether binned) are
    scratch. Returns n.
    """
    counts[:] = 0
    used[:] = 0
    for i in range(st.shape[0]):
        cells[i, 3] = 0
        if not live[i]:
            continue
        interpolate(nodes, k, i, w, st[i])
        x, y, z = st[i, 0], st[i, 1], st[i, 2]
        if not (math.isfinite(x) and math.isfinite(y) and math.isfinite(z)):
            continue
        cx, cy, cz = math.floor(x / cell), math.floor(y / cell), math.floor(z / cell)
        cells[i, 0], cells[i, 1], cells[i, 2], cells[i, 3] = cx, cy, cz, 1
        key = _cell_key(cx, cy, cz, bits)
        counts[key + 1] += 1
        used[key >> 6] |= np.uint64(1) << np.uint64(key & 63)
    for b in range(1, counts.size):
        counts[b] += counts[b - 1]
    for i in range(st.shape[0]):
        if cells[i, 3]:
            cx, cy, cz = cells[i, 0], cells[i, 1], cells[i, 2]
            key = _cell_key(cx, cy, cz, bits)
            a = counts[key]
            order[a] = i
            scode[a] = _code(cx, cy, cz)
            sparts[a, 0], sparts[a, 1] = parts[i, 0], parts[i, 1]
            for c in range(6):
                sst[a, c] = st[i, c]
            counts[key] = a + 1
    for b in range(counts.size - 1, 0, -1):  # filling moved each start to the next one's
        counts[b] = counts[b - 1]
    counts[0] = 0
    return int(counts[counts.size - 1])


@jit
def _passes(i: int, j: int, nodes: Array, k: int, w: Weights, h: float, distance: float,
            limits: Array, st: Array) -> bool:
    """Return whether pair (i, j) passes the test of the module docstring at this epoch.

    ``limits`` (N, 6): lo, hi, vmax, amax, eps, eps_v of each object (`PairLimits`); both
    states interpolated into ``st`` (2, 6).
    """
    li, lj = limits[i], limits[j]
    limit = (distance + li[4] + lj[4] + (li[5] + lj[5]) * 0.5 * h
             + 0.125 * h * h * (li[3] + lj[3]))
    if not meet(li[0], li[1], lj[0], lj[1], limit):
        return False
    interpolate(nodes, k, i, w, st[0])
    interpolate(nodes, k, j, w, st[1])
    return _linear_min(st[1, 0] - st[0, 0], st[1, 1] - st[0, 1], st[1, 2] - st[0, 2],
                       st[1, 3] - st[0, 3], st[1, 4] - st[0, 4], st[1, 5] - st[0, 5],
                       0.5 * h, limit)


@jit
def _linear_min(d0: float, d1: float, d2: float, w0: float, w1: float, w2: float,
                half: float, limit: float) -> bool:
    """Return whether min over |tau| <= half of |d + w tau| is at most ``limit``."""
    ww = w0 * w0 + w1 * w1 + w2 * w2
    tau = 0.0
    if ww > 0.0:
        tau = min(max(-(d0 * w0 + d1 * w1 + d2 * w2) / ww, -half), half)
    e0, e1, e2 = d0 + w0 * tau, d1 + w1 * tau, d2 + w2 * tau
    return bool(e0 * e0 + e1 * e1 + e2 * e2 <= limit * limit)


@jit
def _near(sst: Array32, sparts: Array, a: int, b: int, h: float, distance: float) -> bool:
    """Return whether sorted slots a and b may pass the test (float32 states, with slack).

    Their distance within their reach (`PairLimits.radius`), then their least distance
    on the straight line within h/2 within the test's limit.
    """
    d0 = float(sst[b, 0]) - float(sst[a, 0])
    d1 = float(sst[b, 1]) - float(sst[a, 1])
    d2 = float(sst[b, 2]) - float(sst[a, 2])
    reach = distance + _POS32_KM + sparts[a, 0] + sparts[b, 0]
    if d0 * d0 + d1 * d1 + d2 * d2 > reach * reach:
        return False
    return _linear_min(d0, d1, d2, float(sst[b, 3]) - float(sst[a, 3]),
                       float(sst[b, 4]) - float(sst[a, 4]), float(sst[b, 5]) - float(sst[a, 5]),
                       0.5 * h, distance + _POS32_KM + sparts[a, 1] + sparts[b, 1])


@jit
def _query(n: int, sst: Array32, sparts: Array, scode: IntArray, counts: IntArray,
           used: UIntArray, order: IntArray, bits: int, primary: BoolArray, half: bool,
           nodes: Array, k: int, w: Weights, s: int, h: float, distance: float,
           limits: Array, out: IntArray, n_out: int) -> int:
    """Test the pairs of each primary with the objects of the cells around it; append hits.

    ``half`` (every object a primary): each object looks at its own cell's later slots and
    the 13 forward cells, so each pair is seen once; otherwise each primary looks at all
    27 cells (a pair of two primaries from the lower index). The n binned objects in bucket
    order (`_bin`). ``out`` (capacity, 3) rows (i, j, s); returns the new number of hits
    (beyond the capacity they are counted, not written).
    """
    st = np.empty((2, 6))
    first = 13 if half else 0
    off = 1 << (_CODE_BITS - 1)
    cmask = (1 << _CODE_BITS) - 1
    for a in range(n):
        i = order[a]
        if not primary[i]:
            continue
        code = scode[a]
        cx = ((code >> (2 * _CODE_BITS)) & cmask) - off
        cy = ((code >> _CODE_BITS) & cmask) - off
        cz = (code & cmask) - off
        for q in range(first, 27):
            qx, qy, qz = cx + _STENCIL[q, 0], cy + _STENCIL[q, 1], cz + _STENCIL[q, 2]
            key = _cell_key(qx, qy, qz, bits)
            if not (used[key >> 6] >> np.uint64(key & 63)) & np.uint64(1):
                continue
            target = _code(qx, qy, qz)
            for b in range(a + 1 if half and q == 13 else counts[key], counts[key + 1]):
                if scode[b] != target or b == a or not _near(sst, sparts, a, b, h, distance):
                    continue
                j = order[b]
                if primary[j] and j < i and not half:
                    continue
                p, r = (i, j) if primary[i] and (i < j or not primary[j]) else (j, i)
                if _passes(p, r, nodes, k, w, h, distance, limits, st):
                    if n_out < out.shape[0]:
                        out[n_out, 0], out[n_out, 1], out[n_out, 2] = p, r, s
                    n_out += 1
    return n_out


@jit_nogil
def _sieve_kernel(nodes: Array, q0: int, m: int, s0: int, s1: int, h: float, cell: float,
                  distance: float, live: BoolArray, primary: BoolArray, limits: Array,
                  parts: Array, out: IntArray) -> int:
    """Run `_bin` and `_query` at fine epochs ``q0 + s`` (h apart from node 0), s0 <= s < s1.

    ``m`` fine steps per node interval; ``parts`` (N, 2) each object's `PairLimits.radius`
    and its pad (``eps + eps_v h / 2 + h² amax / 8``). Returns the number of hits.
    """
    n = nodes.shape[1]
    bits = 1
    while 1 << (3 * bits) < 4 * n:  # four buckets per object or more
        bits += 1
    half = True
    for i in range(n):
        half = half and bool(primary[i])
    st = np.empty((n, 6))
    cells = np.zeros((n, 4), dtype=np.int64)
    counts = np.zeros((1 << (3 * bits)) + 1, dtype=np.int64)
    used = np.zeros(max(1, (1 << (3 * bits)) // 64), dtype=np.uint64)
    order = np.zeros(n, dtype=np.int64)
    sst = np.empty((n, 6), dtype=np.float32)
    sparts = np.empty((n, 2))
    scode = np.zeros(n, dtype=np.int64)
    n_out = 0
    last = nodes.shape[0] - 2
    for s in range(s0, s1):
        q = q0 + s
        k, r = q // m, q % m
        if k > last:
            k, r = last, m
        w = hermite_weights(r / m, h * m)
        n_in = _bin(nodes, k, w, live, parts, cell, bits, st, cells, counts, used, order,
                    sst, sparts, scode)
        n_out = _query(n_in, sst, sparts, scode, counts, used, order, bits, primary, half,
                       nodes, k, w, s, h, distance, limits, out, n_out)
    return n_out


def near_primaries(limits: PairLimits, distance_km: float) -> BoolArray:
    """Return which objects have a state and a radial band meeting some primary's (N,).

    Within ``distance_km`` (`apsides.meets_any`): the objects a re-screening of the
    primaries must bin (the others cannot pass the test with any of them).
    """
    live: BoolArray = np.isfinite(limits.lo) & (limits.hi >= limits.lo)
    p = live & limits.primary
    if p.all():
        return live
    out: BoolArray = live & meets_any(limits.lo, limits.hi, p, distance_km)
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
    cell = limits.reach(distance_km, h) + _POS32_KM
    nodes = f64(table.nodes)
    primary = np.ascontiguousarray(limits.primary, dtype=np.bool_)
    parts = f64(np.nan_to_num(np.stack([
        limits.radius(h),
        limits.eps + 0.5 * h * limits.eps_v + 0.125 * h * h * limits.amax], axis=1)))
    table6 = f64(np.stack([limits.lo, limits.hi, limits.vmax, limits.amax, limits.eps,
                           limits.eps_v], axis=1))

    def block(s0: int, s1: int) -> IntArray:
        out = np.empty((capacity, 3), dtype=np.int64)
        for _ in range(2):  # again with room for every hit when they overflowed
            n = _sieve_kernel(nodes, int(q0), int(m), s0, s1, float(h), float(cell),
                              float(distance_km), live, primary, table6, parts, out)
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
