"""GCRF -> ITRF rotation over a span, for compiled code: `rotation_grid`, `gcrs_to_itrs_at`.

The same rotation as `frames.gcrs_to_itrs_matrix` (IAU 2006/2000A, CIO based, with the EOP
of `eop`), ``M(t) = W(t) R3(ERA(t)) Q(t)``, evaluated inside a compiled force model with no
Python call: `rotation_grid` computes, once per span, ``Q`` and ``W`` at the whole UTC hours
that cover it (the nodes `frames` itself interpolates between, so the two agree to
round-off) and UT1 - UTC there; `gcrs_to_itrs_at` interpolates ``Q``, ``W`` and UT1 - UTC
linearly at an epoch (as `frames` does: < 1e-5" from the exact matrices) and computes the
Earth rotation angle from UT1, ``ERA = ERA(t0) + ERA_RATE (t - t0 + dUT1(t) - dUT1(t0))``
(ERA is linear in UT1; ~1e-15 relative over days).

Times are seconds from the grid's origin ``t0_unix`` (Unix s UTC). A span that crosses a
leap second is taken as if none were there (its epochs after it are read 1 s off).

Units: s, rad; the matrix turns GCRF coordinates into ITRF ones.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ssa_fusion.core.base.jit import f64, jit
from ssa_fusion.core.earth import eop as eop_
from ssa_fusion.core.earth import frames

__all__ = ["RotationGrid", "gcrs_to_itrs_at", "rotation_grid"]

Array = NDArray[np.float64]

_ERA_RATE = frames.ERA_RATE
"""Rate of the Earth rotation angle, rad/s of UT1."""


@dataclass(frozen=True)
class RotationGrid:
    """Q, W and UT1 - UTC at whole UTC hours over a span (module docstring).

    Attributes
    ----------
    t0_unix : float
        The origin, Unix s UTC.
    first_s : float
        The first node, s from the origin.
    node_s : float
        Node spacing, s (`frames.NODE_S`).
    q, w : ndarray (K, 9)
        GCRS -> CIRS and TIRS -> ITRS matrices at the nodes, row by row.
    dut1 : ndarray (K,)
        UT1 - UTC at the nodes, s (a leap second inside the span removed).
    era0 : float
        The Earth rotation angle at the origin, rad.
    """

    t0_unix: float
    first_s: float
    node_s: float
    q: Array
    w: Array
    dut1: Array
    era0: float

    def packed(self) -> Array:
        """Return the grid as one array for the kernel: [first, step, era0, dut1(0), nodes...].

        Each node: 9 of Q, 9 of W, dUT1 (19 numbers).
        """
        head = np.array([self.first_s, self.node_s, self.era0, self._dut1_origin()])
        body = np.concatenate([self.q, self.w, self.dut1[:, None]], axis=1).ravel()
        return f64(np.concatenate([head, body]))

    def _dut1_origin(self) -> float:
        f = (0.0 - self.first_s) / self.node_s
        k = min(max(math.floor(f), 0), len(self.dut1) - 2)
        return float(self.dut1[k] + (f - k) * (self.dut1[k + 1] - self.dut1[k]))


def rotation_grid(t0_unix: float, t_min_s: float, t_max_s: float,
                  eop: eop_.EarthOrientation | None = None) -> RotationGrid:
    """Return the rotation's nodes over ``t0_unix + [t_min_s, t_max_s]`` (module docstring)."""
    e = eop_.default() if eop is None else eop
    step = frames.NODE_S
    k0 = math.floor((t0_unix + t_min_s) / step) - 1
    k1 = math.floor((t0_unix + t_max_s) / step) + 2
    nodes = np.arange(k0, k1 + 1, dtype=float) * step
    q = frames.gcrs_to_cirs_matrix(nodes, e)
    era = frames.earth_rotation_angle(nodes, e)
    m = frames.gcrs_to_itrs_matrix(nodes, e)
    w = np.matmul(np.matmul(m, np.swapaxes(q, 1, 2)), np.swapaxes(frames.rot_z(era), 1, 2))
    dut1 = e.at(nodes).dut1.copy()
    jumps = np.round(np.diff(dut1))  # a leap second: UT1 - UTC jumps by 1 s
    dut1[1:] -= np.cumsum(jumps)
    era0 = float(frames.earth_rotation_angle(np.array([t0_unix]), e)[0])
    return RotationGrid(float(t0_unix), float(nodes[0] - t0_unix), step,
                        q.reshape(-1, 9), w.reshape(-1, 9), dut1, era0)


@jit
def gcrs_to_itrs_at(grid: Array, t: float, out: Array) -> None:
    """``out[0:9]`` = the GCRF -> ITRF matrix (row by row) at ``t`` s from the grid's origin.

    ``grid``: `RotationGrid.packed`. Times outside the grid use its end nodes' hour
    (extrapolated linearly).
    """
    first, step, era0, d0 = grid[0], grid[1], grid[2], grid[3]
    nk = (grid.shape[0] - 4) // 19
    f = (t - first) / step
    k = min(max(math.floor(f), 0), nk - 2)
    f -= k
    a = 4 + 19 * k
    b = a + 19
    q = np.empty(9)
    w = np.empty(9)
    for i in range(9):
        q[i] = grid[a + i] + f * (grid[b + i] - grid[a + i])
        w[i] = grid[a + 9 + i] + f * (grid[b + 9 + i] - grid[a + 9 + i])
    dut1 = grid[a + 18] + f * (grid[b + 18] - grid[a + 18])
    th = era0 + _ERA_RATE * (t + (dut1 - d0))
    c, s = math.cos(th), math.sin(th)
    r = (c * q[0] + s * q[3], c * q[1] + s * q[4], c * q[2] + s * q[5],
         c * q[3] - s * q[0], c * q[4] - s * q[1], c * q[5] - s * q[2],
         q[6], q[7], q[8])  # R3(ERA) Q
    for i in range(3):
        for j in range(3):
            out[3 * i + j] = (w[3 * i] * r[j] + w[3 * i + 1] * r[3 + j]
                              + w[3 * i + 2] * r[6 + j])
