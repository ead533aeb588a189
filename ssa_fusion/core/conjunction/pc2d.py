"""The 2D collision probability of Foster: a Gaussian integrated over a circle, in logs.

``Pc = ∫∫_{|u| < R} N(u; m, C) du`` over the hard-body circle of radius R centred on object 1
in the encounter plane, the combined covariance C's Gaussian centred on the miss vector m
(Foster & Estes 1992; Alfano 2005 for the one-dimensional form). In C's principal axes the
inner integral, across the narrower axis, is a difference of normal CDFs; the outer one,
along the wider axis, is done with Gauss-Legendre quadrature in ``x = R sin θ`` (smooth at the
circle's edge). Everything is in logarithms (``scipy.special.log_ndtr``, log-sum-exp), so a
Pc of 1e-300 or 1e-3000 comes out as its log10, never as an underflowed 0.

`log10_pc_circle` does n conjunctions at once (numpy, fixed 64-node rule, checked against
32 nodes); a conjunction whose two rules disagree (a covariance small beside the circle)
is redone alone with an adaptive rule (`scipy.integrate.quad` on the integrand scaled by
its maximum). Covariances are remediated as CARA does: eigenvalues below
``(CLIP_FRACTION * R)**2`` are clipped up to it and the conjunction flagged.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass
from functools import cache

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy import integrate, special

from ssa_fusion.core.conjunction.result import CLIP_FRACTION

Array = NDArray[np.float64]
BoolArray = NDArray[np.bool_]

__all__ = ["CircleIntegral", "eig2x2", "log10_pc_circle"]

NODES = 64
"""Gauss-Legendre nodes of the vectorised rule (its check uses half as many)."""
REL_TOL = 1e-9
"""Relative agreement of the two rules below which the 64-node answer is kept."""
_LOG_SQRT_2PI = 0.5 * math.log(2 * math.pi)
_LN10 = math.log(10.0)


@dataclass(frozen=True)
class CircleIntegral:
    """The 2D Pc of n conjunctions (`log10_pc_circle`).

    Attributes
    ----------
    log10_pc : ndarray (n,)
        log10 of the Pc (-inf for a zero radius).
    sigma_major, sigma_minor : ndarray (n,)
        Standard deviations along the principal axes, after clipping, same unit as the input.
    remediated : ndarray (n,) of bool
        Where an eigenvalue was below the clip level (or negative) and was clipped.
    adaptive : ndarray (n,) of bool
        Where the adaptive rule was used.
    unrefined : ndarray (n,) of bool
        Where the two Gauss-Legendre rules disagreed but the Pc was below the refinement
        floor (``refine_below_log10`` of `log10_pc_circle`): the fine rule's value, its
        relative error not bounded.
    """

    log10_pc: Array
    sigma_major: Array
    sigma_minor: Array
    remediated: BoolArray
    adaptive: BoolArray
    unrefined: BoolArray


@cache
def _rule(n: int) -> tuple[Array, Array]:
    """Gauss-Legendre nodes θ in (-π/2, π/2) and log weights (incl. dx/dθ's cos θ) of n."""
    t, w = np.polynomial.legendre.leggauss(n)
    theta = 0.5 * np.pi * t
    return theta, np.log(0.5 * np.pi * w) + np.log(np.cos(theta))


def eig2x2(c: ArrayLike) -> tuple[Array, Array, Array]:
    """Eigen-decomposition of symmetric 2x2 matrices (n, 2, 2), closed form.

    Returns
    -------
    l_major, l_minor : ndarray (n,)
        Larger and smaller eigenvalue.
    v_major : ndarray (n, 2)
        Unit eigenvector of the larger (the other is its perpendicular).
    """
    m = np.asarray(c, dtype=float).reshape(-1, 2, 2)
    a, b, d = m[:, 0, 0], 0.5 * (m[:, 0, 1] + m[:, 1, 0]), m[:, 1, 1]
    mean, disc = 0.5 * (a + d), np.hypot(0.5 * (a - d), b)
    l1, l2 = mean + disc, mean - disc
    # the better conditioned of the two forms of the eigenvector
    v = np.where((a >= d)[:, None], np.stack([l1 - d, b], axis=1), np.stack([b, l1 - a], axis=1))
    norm = np.linalg.norm(v, axis=1, keepdims=True)
    v = np.where(norm > 0, v / np.where(norm > 0, norm, 1.0), np.array([1.0, 0.0]))
    return l1, l2, v


def _log_ndtr_diff(a: Array, b: Array) -> Array:
    """log(Φ(b) - Φ(a)) for a <= b, accurate in both tails and near a = b."""
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        upper = a > 0  # both in the upper tail: Φ(b) - Φ(a) = Φ(-a) - Φ(-b)
        lo = np.where(upper, -b, a)
        hi = np.where(upper, -a, b)
        lhi, llo = special.log_ndtr(hi), special.log_ndtr(lo)
        tail = lhi + np.log(-np.expm1(llo - lhi))
        middle = np.log(0.5 * (special.erf(b / math.sqrt(2)) - special.erf(a / math.sqrt(2))))
        out: Array = np.where(upper | (b <= 0), tail, middle)
    return out


def _log_integrand(theta: Array, r: Array, mu: Array, s_major: Array, s_minor: Array
                   ) -> Array:
    """Return the log of the outer integrand at θ (n, k) without the rule's weights.

    ``mu`` (n, 2): the miss in the principal axes (major, minor); the circle is centred at 0.
    """
    x = r[:, None] * np.sin(theta)
    h = r[:, None] * np.cos(theta)
    z = (x - mu[:, :1]) / s_major[:, None]
    outer = -0.5 * z * z - np.log(s_major)[:, None] - _LOG_SQRT_2PI
    inner = _log_ndtr_diff((-h - mu[:, 1:]) / s_minor[:, None], (h - mu[:, 1:]) / s_minor[:, None])
    out: Array = outer + inner + np.log(r)[:, None]
    return out


def _log_gl(n: int, r: Array, mu: Array, s1: Array, s2: Array) -> Array:
    """Return ln Pc (n_conj,) with the n-node Gauss-Legendre rule."""
    theta, logw = _rule(n)
    f = _log_integrand(np.broadcast_to(theta, (len(r), n)), r, mu, s1, s2) + logw
    top = np.max(f, axis=1)
    safe = np.where(np.isfinite(top), top, 0.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        out: Array = np.where(np.isfinite(top), safe + np.log(np.sum(np.exp(f - safe[:, None]),
                                                                     axis=1)), top)
    return out


def _log_adaptive(r: float, mu: Array, s1: float, s2: float) -> float:
    """Return ln Pc of one conjunction: an adaptive rule on the integrand scaled by its peak."""
    args = (np.array([r]), mu[None, :], np.array([s1]), np.array([s2]))
    grid = np.linspace(-0.5 * np.pi, 0.5 * np.pi, 4001)[1:-1]
    logs = _log_integrand(grid[None, :], *args)[0] + np.log(np.cos(grid))
    peak = int(np.argmax(logs))
    top = float(logs[peak])
    if not math.isfinite(top):
        return -math.inf

    def scaled(t: float) -> float:
        v = _log_integrand(np.array([[t]]), *args)[0, 0] + math.log(max(math.cos(t), 0.0)
                                                                     or 1e-300)
        return math.exp(v - top)

    pts = [float(grid[max(peak - 1, 0)]), float(grid[peak]), float(grid[min(peak + 1,
                                                                           len(grid) - 1)])]
    with warnings.catch_warnings():  # round-off at 1e-11 is below what is asked of it
        warnings.simplefilter("ignore", integrate.IntegrationWarning)
        val, _ = integrate.quad(scaled, -0.5 * np.pi, 0.5 * np.pi, points=pts, limit=500,
                                epsabs=0.0, epsrel=1e-11)
    return top + math.log(val) if val > 0 else -math.inf


def log10_pc_circle(miss: ArrayLike, cov: ArrayLike, hbr: ArrayLike,
                    clip_fraction: float = CLIP_FRACTION,
                    refine_below_log10: float = -math.inf) -> CircleIntegral:
    """2D Pc of n conjunctions in their encounter planes (module docstring).

    Parameters
    ----------
    miss : array_like (2,) or (n, 2)
        Miss vectors in the plane, any length unit (km in the core).
    cov : array_like (2, 2) or (n, 2, 2)
        Combined position covariances in the same axes, that unit squared.
    hbr : float or array_like (n,)
        Combined hard-body radii, the same unit.
    clip_fraction : float
        Eigenvalues below ``(clip_fraction * hbr)**2`` are clipped up to it.
    refine_below_log10 : float
        Where the rules disagree, the adaptive rule (~10 ms a conjunction) is used only
        when the fine rule's log10 Pc is at least this; below it the fine rule's value
        stays (``unrefined``). -inf (the default): always refined.

    Returns
    -------
    CircleIntegral
    """
    m = np.asarray(miss, dtype=float).reshape(-1, 2)
    c = np.broadcast_to(np.asarray(cov, dtype=float).reshape(-1, 2, 2), (len(m), 2, 2))
    r = np.broadcast_to(np.asarray(hbr, dtype=float).reshape(-1), (len(m),)).copy()
    l1, l2, v1 = eig2x2(c)
    floor = (clip_fraction * r) ** 2
    remediated = l2 < floor
    s1, s2 = np.sqrt(np.maximum(l1, floor)), np.sqrt(np.maximum(l2, floor))
    v2 = np.stack([-v1[:, 1], v1[:, 0]], axis=1)
    mu = np.stack([np.einsum("ni,ni->n", m, v1), np.einsum("ni,ni->n", m, v2)], axis=1)
    ok = r > 0
    rr = np.where(ok, r, 1.0)
    fine, coarse = _log_gl(NODES, rr, mu, s1, s2), _log_gl(NODES // 2, rr, mu, s1, s2)
    with np.errstate(invalid="ignore"):
        agree = np.abs(np.expm1(coarse - fine)) <= REL_TOL
    with np.errstate(invalid="ignore"):
        worth = fine >= refine_below_log10 * _LN10
    redo = ok & ~agree & worth
    for i in np.flatnonzero(redo):
        fine[i] = _log_adaptive(float(rr[i]), mu[i], float(s1[i]), float(s2[i]))
    ln_pc = np.where(ok, np.minimum(fine, 0.0), -np.inf)
    return CircleIntegral(ln_pc / _LN10, s1, s2, remediated, redo, ok & ~agree & ~worth)
