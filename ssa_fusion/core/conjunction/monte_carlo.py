"""3D collision probability by Monte Carlo: both objects' states drawn and flown past each other.

For slow encounters, where the 2D Pc's straight-line relative motion fails
(`usage.usage_warnings`). Each sample draws object 1's and object 2's states at TCA from
their 6x6 inertial covariances (position and velocity), propagates both on two-body orbits
(`core.motion.kepler.kepler_state`, compiled) and finds the pair's closest approach in the
time window by Newton's method on the relative range rate ``f(t) = r·v`` (``f' = v·v + r·a``),
the window's ends included; a hit is a closest approach under the hard-body radius. The Pc
is the fraction of hits, with its binomial standard error. It is the 3D Pc of CARA's
two-body Monte Carlo (``Pc_MC_Kep2body``) in method, written here from its description.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ssa_fusion.core.base.constants import MU_EARTH
from ssa_fusion.core.motion.kepler import kepler_state

Array = NDArray[np.float64]

__all__ = ["MonteCarloPc", "pc_monte_carlo", "sample_states"]

NEWTON_STEPS = 8
"""Newton iterations on the range rate per sample pair."""
GRID = 33
"""Times of the coarse search over the window that starts each pair's Newton iterations."""
BATCH = 20_000
"""Sample pairs propagated at once (memory: a few MB per batch)."""


@dataclass(frozen=True)
class MonteCarloPc:
    """A Monte Carlo Pc.

    Attributes
    ----------
    pc : float
        Fraction of sample pairs that collide.
    std_error : float
        Its binomial standard error ``sqrt(pc (1 - pc) / samples)``.
    hits, samples : int
        Colliding pairs, pairs drawn.
    """

    pc: float
    std_error: float
    hits: int
    samples: int


def sample_states(x: ArrayLike, p: ArrayLike, n: int, rng: np.random.Generator) -> Array:
    """Draw n states (n, 6) from N(x, p), km, km/s; p (6, 6) inertial.

    Negative eigenvalues (a not quite positive semi-definite covariance) are taken as 0.
    """
    lam, vec = np.linalg.eigh(0.5 * (np.asarray(p, float) + np.asarray(p, float).T))
    half = vec * np.sqrt(np.maximum(lam, 0.0))
    out: Array = np.asarray(x, float) + rng.standard_normal((n, 6)) @ half.T
    return out


def _accel(r: Array) -> Array:
    """Two-body acceleration (n, 3) at positions r (n, 3), km/s²."""
    out: Array = -MU_EARTH * r / np.linalg.norm(r, axis=1, keepdims=True) ** 3
    return out


def _relative(a: Array, b: Array, t: Array) -> tuple[Array, Array, Array]:
    """Relative position, velocity and acceleration of b to a after t (n,) s."""
    sa, _ = kepler_state(a, t)
    sb, _ = kepler_state(b, t)
    return sb[:, :3] - sa[:, :3], sb[:, 3:] - sa[:, 3:], _accel(sb[:, :3]) - _accel(sa[:, :3])


def closest_approach(a: Array, b: Array, window: tuple[float, float]) -> Array:
    """Smallest distance (n,) between states a and b (n, 6) over the window (t0, t1) s, km.

    A coarse search over `GRID` times of the window, then Newton on the range rate from the
    closest of them, kept inside the window; the grid's times stay candidates.
    """
    lo, hi = window
    grid = np.linspace(lo, hi, GRID)
    best = np.full(len(a), np.inf)
    t = np.full(len(a), 0.5 * (lo + hi))
    for g in grid:
        d = np.linalg.norm(_relative(a, b, np.full(len(a), g))[0], axis=1)
        t = np.where(d < best, g, t)
        best = np.minimum(best, d)
    for _ in range(NEWTON_STEPS):
        r, v, acc = _relative(a, b, t)
        f = np.einsum("ni,ni->n", r, v)
        fp = np.einsum("ni,ni->n", v, v) + np.einsum("ni,ni->n", r, acc)
        vv = np.einsum("ni,ni->n", v, v)
        step = -f / np.where(fp > 0, fp, np.where(vv > 0, vv, 1.0))
        t = np.clip(t + step, lo, hi)
    out: Array = np.minimum(best, np.linalg.norm(_relative(a, b, t)[0], axis=1))
    return out


def pc_monte_carlo(x1: ArrayLike, p1: ArrayLike, x2: ArrayLike, p2: ArrayLike, hbr_km: float,
                   window_s: tuple[float, float], samples: int = 100_000, seed: int = 0
                   ) -> MonteCarloPc:
    """3D Pc by Monte Carlo (module docstring).

    Parameters
    ----------
    x1, x2 : array_like (6,)
        Inertial states at TCA, km, km/s.
    p1, p2 : array_like (6, 6)
        Their inertial covariances, km², km²/s, km²/s².
    hbr_km : float
        Combined hard-body radius, km.
    window_s : (float, float)
        Times around TCA searched for each pair's closest approach, s.
    samples : int
        Sample pairs to draw.
    seed : int
        Seed of the random generator (the same seed gives the same Pc).

    Returns
    -------
    MonteCarloPc
    """
    rng = np.random.default_rng(seed)
    hits, done = 0, 0
    while done < samples:
        n = min(BATCH, samples - done)
        a = sample_states(x1, p1, n, rng)
        b = sample_states(x2, p2, n, rng)
        hits += int(np.count_nonzero(closest_approach(a, b, window_s) < hbr_km))
        done += n
    pc = hits / samples
    return MonteCarloPc(pc, math.sqrt(pc * (1.0 - pc) / samples), hits, samples)
