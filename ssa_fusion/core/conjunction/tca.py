"""Times of closest approach: roots of the relative range rate, then the trajectory's own.

A pair's distance has a local minimum where its range rate ``f(t) = dr . dv`` (relative
position and velocity, object j minus object i) crosses zero from below. Near each
`sieve` hit ``(i, j, s)`` (within h/2 of the fine epoch ``t_s``) `hit_roots` looks for such
crossings on the interpolated trajectories (`hermite`): f at both ends and the middle of
the half-width, Brent's method in each bracket that changes sign upward (compiled, one loop
over the hits, no Python per pair). `newton_tca` then moves each root to the trajectories'
own (`ephemeris.Ephemeris.exact`, SGP4 or the integrated model) by Newton steps on f, with
``f' = |dv|² + dr . da`` (two-body accelerations): the TCA and the miss distance reported
are the propagation's, not the interpolant's.

Units: epochs Unix s (UTC), km, km/s.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ssa_fusion.core.base.constants import MU_EARTH
from ssa_fusion.core.base.jit import f64, jit
from ssa_fusion.core.conjunction.ephemeris import Ephemeris
from ssa_fusion.core.conjunction.hermite import NodeTable, state_at
from ssa_fusion.core.conjunction.sieve import Hits

__all__ = ["Roots", "hit_roots", "newton_tca"]

Array = NDArray[np.float64]
IntArray = NDArray[np.int64]

ROOT_TOL_S = 1e-6
"""Brent's tolerance on the interpolated root, s."""


@dataclass(frozen=True)
class Roots:
    """Local minima of pairs' distances: objects ``i``, ``j`` (M,) and epochs ``t`` (M,) Unix s."""

    i: IntArray
    j: IntArray
    t: Array

    def take(self, rows: slice | IntArray) -> Roots:
        """Return the roots ``rows``."""
        return Roots(self.i[rows], self.j[rows], self.t[rows])

    @classmethod
    def concat(cls, parts: list[Roots]) -> Roots:
        """Return the roots of ``parts`` one after the other."""
        return cls(np.concatenate([np.zeros(0, np.int64)] + [p.i for p in parts]),
                   np.concatenate([np.zeros(0, np.int64)] + [p.j for p in parts]),
                   np.concatenate([np.zeros(0)] + [p.t for p in parts]))


@jit
def _range_rate(nodes: Array, t_first: float, big_h: float, i: int, j: int, t: float,
                a: Array, b: Array) -> tuple[float, float]:
    """Return (dr . dv km²/s, |dr|² km²) of pair (i, j) at epoch t on the interpolants."""
    state_at(nodes, t_first, big_h, i, t, a)
    state_at(nodes, t_first, big_h, j, t, b)
    f, d2 = 0.0, 0.0
    for c in range(3):
        dr = b[c] - a[c]
        f += dr * (b[3 + c] - a[3 + c])
        d2 += dr * dr
    return f, d2


@jit
def _brent(nodes: Array, t_first: float, big_h: float, i: int, j: int, lo: float,
           hi: float, f_lo: float, f_hi: float, tol: float, a: Array, b: Array) -> float:
    """Return the root of the range rate in [lo, hi] (f_lo <= 0 < f_hi), Brent's method.

    Brent (1973), "zeroin": inverse quadratic interpolation or the secant, bisection when
    they do not shrink the bracket fast enough; to ``tol`` s (plus the epoch's round-off).
    """
    xa, xb, fa, fb = lo, hi, f_lo, f_hi
    xc, fc = xb, fb
    d = e = xb - xa
    for _ in range(200):
        if (fb > 0.0 and fc > 0.0) or (fb < 0.0 and fc < 0.0):
            xc, fc = xa, fa
            d = e = xb - xa
        if abs(fc) < abs(fb):
            xa, xb, xc = xb, xc, xb
            fa, fb, fc = fb, fc, fb
        tol1 = 4.4e-16 * abs(xb) + 0.5 * tol
        m = 0.5 * (xc - xb)
        if abs(m) <= tol1 or fb == 0.0:
            return xb
        if abs(e) >= tol1 and abs(fa) > abs(fb):
            s = fb / fa
            if xa == xc:
                p, q = 2.0 * m * s, 1.0 - s
            else:
                q, r = fa / fc, fb / fc
                p = s * (2.0 * m * q * (q - r) - (xb - xa) * (r - 1.0))
                q = (q - 1.0) * (r - 1.0) * (s - 1.0)
            if p > 0.0:
                q = -q
            p = abs(p)
            if 2.0 * p < min(3.0 * m * q - abs(tol1 * q), abs(e * q)):
                e, d = d, p / q
            else:
                d = e = m
        else:
            d = e = m
        xa, fa = xb, fb
        xb += d if abs(d) > tol1 else (tol1 if m > 0.0 else -tol1)
        fb, _ = _range_rate(nodes, t_first, big_h, i, j, xb, a, b)
    return xb


@jit
def _roots_kernel(nodes: Array, t_first: float, big_h: float, t_s0: float, h: float,
                  t_lo: float, t_hi: float, hit_i: IntArray, hit_j: IntArray,
                  hit_s: IntArray, limit: Array, out_i: IntArray, out_j: IntArray,
                  out_t: Array) -> int:
    """Find the upward zero crossings of the range rate within h/2 of each hit (see module).

    Epoch of hit k: ``t_s0 + hit_s[k] h``, searched within [t_lo, t_hi]; a root is kept
    when the interpolated distance there is at most ``limit[k]`` km. Returns the number of
    roots written to ``out_*`` (each of size 2 M).
    """
    a = np.empty(6)
    b = np.empty(6)
    n = 0
    for k in range(hit_i.size):
        i, j = hit_i[k], hit_j[k]
        ts = t_s0 + hit_s[k] * h
        lo, hi = max(ts - 0.5 * h, t_lo), min(ts + 0.5 * h, t_hi)
        if not lo < hi:
            continue
        mid = 0.5 * (lo + hi)
        f0, _ = _range_rate(nodes, t_first, big_h, i, j, lo, a, b)
        f1, _ = _range_rate(nodes, t_first, big_h, i, j, mid, a, b)
        f2, _ = _range_rate(nodes, t_first, big_h, i, j, hi, a, b)
        for x0, x1, g0, g1 in ((lo, mid, f0, f1), (mid, hi, f1, f2)):
            if not (g0 <= 0.0 < g1):
                continue
            t = _brent(nodes, t_first, big_h, i, j, x0, x1, g0, g1, ROOT_TOL_S, a, b)
            _, d2 = _range_rate(nodes, t_first, big_h, i, j, t, a, b)
            if d2 <= limit[k] * limit[k]:
                out_i[n], out_j[n], out_t[n] = i, j, t
                n += 1
    return n


def hit_roots(table: NodeTable, hits: Hits, t_s0: float, h: float, window: tuple[float, float],
              limit_km: Array) -> Roots:
    """Return the local minima of the hits' interpolated distances within h/2 of each hit.

    Parameters
    ----------
    table : NodeTable
        The interpolation nodes.
    hits : Hits
        Pairs and fine epochs ``t_s0 + s h`` (`sieve.sieve`).
    t_s0, h : float
        Epoch of fine step 0 (Unix s) and the fine spacing (s).
    window : (float, float)
        Only minima within it (Unix s) are kept.
    limit_km : ndarray (M,)
        Largest interpolated distance kept per hit, km (the screening distance plus the
        pair's interpolation error bounds).
    """
    m = hits.i.size
    out_i, out_j = np.empty(2 * m, np.int64), np.empty(2 * m, np.int64)
    out_t = np.empty(2 * m)
    n = _roots_kernel(f64(table.nodes), table.t_first, table.step_s, float(t_s0), float(h),
                      float(window[0]), float(window[1]), hits.i, hits.j, hits.s,
                      f64(np.asarray(limit_km, dtype=float)), out_i, out_j, out_t)
    return Roots(out_i[:n].copy(), out_j[:n].copy(), out_t[:n].copy())


def _two_body_accel(r: Array) -> Array:
    """Two-body accelerations (M, 3) km/s² at positions ``r`` (M, 3) km."""
    n = np.linalg.norm(r, axis=1, keepdims=True)
    out: Array = -MU_EARTH * r / n**3
    return out


def newton_tca(eph: Ephemeris, roots: Roots, max_shift_s: float,
               iterations: int = 2) -> tuple[Array, Array, Array]:
    """Move roots to the zeros of the range rate of the ephemeris's own trajectories.

    Newton steps on ``f = dr . dv`` with ``f' = |dv|² + dr . da`` (two-body da), each
    limited to ``max_shift_s``; a root whose f' is not positive stays where it is.

    Returns
    -------
    (t (M,), x_i (M, 6), x_j (M, 6))
        The epochs (Unix s) and both objects' states there (GCRF km, km/s; NaN where the
        ephemeris has none).
    """
    t = roots.t.copy()
    for _ in range(iterations):
        xi, xj = eph.exact(roots.i, t), eph.exact(roots.j, t)
        dr, dv = xj[:, :3] - xi[:, :3], xj[:, 3:] - xi[:, 3:]
        da = _two_body_accel(xj[:, :3]) - _two_body_accel(xi[:, :3])
        f = np.einsum("ij,ij->i", dr, dv)
        fp = np.einsum("ij,ij->i", dv, dv) + np.einsum("ij,ij->i", dr, da)
        with np.errstate(divide="ignore", invalid="ignore"):
            step = np.where(fp > 0.0, -f / fp, 0.0)
        t += np.clip(np.nan_to_num(step), -max_shift_s, max_shift_s)
    return t, eph.exact(roots.i, t), eph.exact(roots.j, t)
