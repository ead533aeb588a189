"""A conjunction's collision probability, with the checks its method needs: the entry points.

`collision_probability` takes the two objects' inertial states and covariances at TCA and
the combined hard-body radius and returns a `PcResult`: the 2D Pc of Foster (default), or
a 3D Monte Carlo Pc (`PcMethod.MONTE_CARLO_3D`) for slow encounters, or, when a covariance
is missing, the largest Pc it allows (Frisbee with one missing, Alfano's bound with both).
Every result carries the short-encounter usage warnings (`usage`), the non-positive-definite
covariances found and remediated, and a Pc below the float range as its log10.

`pc2d_batch` is the vectorised 2D Pc of n conjunctions (states and covariances stacked),
for screening many pairs: the encounter planes and the integrals, without the per-pair
checks.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ssa_fusion.core.conjunction import max_pc, monte_carlo, usage
from ssa_fusion.core.conjunction.encounter import Encounter, encounter_plane, orbital_period
from ssa_fusion.core.conjunction.pc2d import CircleIntegral, log10_pc_circle
from ssa_fusion.core.conjunction.result import PcMethod, PcResult, PcWarning, pc_from_log10

Array = NDArray[np.float64]

__all__ = ["collision_probability", "pc2d_batch"]

_NPD_TOL = 1e-12
"""An eigenvalue below -_NPD_TOL * the largest makes a covariance non-positive-definite."""


def pc2d_batch(x1: ArrayLike, p1: ArrayLike, x2: ArrayLike, p2: ArrayLike, hbr_km: ArrayLike,
               refine_below_log10: float = -math.inf) -> tuple[Encounter, CircleIntegral]:
    """2D Pc of n conjunctions at once (module docstring).

    Parameters
    ----------
    x1, x2 : array_like (n, 6)
        Inertial states at (or within a second or so of) TCA, km, km/s.
    p1, p2 : array_like (n, k, k), k = 3 or 6
        Inertial covariances, km² (only the position blocks are used).
    hbr_km : float or array_like (n,)
        Combined hard-body radii, km.
    refine_below_log10 : float
        `pc2d.log10_pc_circle`'s refinement floor (-inf: every Pc refined).

    Returns
    -------
    (Encounter, CircleIntegral)
        The encounter planes and the Pc (``log10_pc``) of each conjunction.
    """
    enc = encounter_plane(x1, p1, x2, p2)
    return enc, log10_pc_circle(enc.miss, enc.cov, hbr_km,
                                refine_below_log10=refine_below_log10)


def _npd(p: Array | None, flag: PcWarning) -> set[PcWarning]:
    """{flag} when the position block of p is not positive semi-definite."""
    if p is None:
        return set()
    lam = np.linalg.eigvalsh(0.5 * (p[:3, :3] + p[:3, :3].T))
    return {flag} if lam[0] < -_NPD_TOL * max(abs(lam[-1]), 1e-300) else set()


def _full(p: Array | None) -> Array:
    """Return a 6x6 covariance of p (3x3 or 6x6; zeros for a missing one), km², km²/s, km²/s²."""
    out = np.zeros((6, 6))
    if p is not None:
        k = p.shape[0]
        out[:k, :k] = p
    return out


def _plane_pc(enc: Encounter, hbr_km: float, p1: Array | None, p2: Array | None
              ) -> tuple[float, PcMethod, float, float, set[PcWarning]]:
    """log10 Pc, method, sigmas and warnings of the 2D methods (one conjunction)."""
    if p1 is not None and p2 is not None:
        res = log10_pc_circle(enc.miss[0], enc.cov[0], hbr_km)
        method = PcMethod.FOSTER_2D
        warn: set[PcWarning] = set()
    elif p1 is None and p2 is None:
        lp = max_pc.log10_max_pc_no_covariance(float(enc.miss_km[0]), hbr_km)
        return lp, PcMethod.ALFANO_MAX, math.nan, math.nan, {PcWarning.MISSING_COVARIANCE}
    else:
        res = max_pc.log10_max_pc_frisbee(enc.miss[0], enc.cov[0], hbr_km)
        method, warn = PcMethod.FRISBEE_MAX, {PcWarning.MISSING_COVARIANCE}
    if res.remediated[0]:
        warn.add(PcWarning.REMEDIATED_COVARIANCE)
    return (float(res.log10_pc[0]), method, float(res.sigma_major[0]),
            float(res.sigma_minor[0]), warn)


def _bounds(enc: Encounter, hbr_km: float, known: bool) -> tuple[float, float]:
    """Coppola bounds around the linear TCA (NaN when no covariance is known)."""
    if not known:
        return math.nan, math.nan
    t0, t1 = usage.encounter_bounds(enc.rel_position, enc.rel_velocity, enc.cov_3d, hbr_km)
    return float(t0[0]), float(t1[0])


def collision_probability(x1: ArrayLike, p1: ArrayLike | None, x2: ArrayLike,
                          p2: ArrayLike | None, hbr_km: float,
                          method: PcMethod = PcMethod.FOSTER_2D, *,
                          samples: int = 100_000, seed: int = 0) -> PcResult:
    """Collision probability of one conjunction (module docstring).

    Parameters
    ----------
    x1, x2 : array_like (6,)
        Inertial (GCRF or EME2000, the same for both) states at TCA, km, km/s.
    p1, p2 : array_like (3, 3) or (6, 6), or None
        Their inertial covariances, km², km²/s, km²/s²; None when missing (the Pc is then
        the maximum over the missing one: `PcMethod.FRISBEE_MAX` or `ALFANO_MAX`).
    hbr_km : float
        Combined hard-body radius, km (> 0).
    method : PcMethod
        `FOSTER_2D` (default) or `MONTE_CARLO_3D` (needs both covariances, 6x6 for the
        velocity uncertainty); the maximum methods follow from missing covariances.
    samples, seed : int
        Monte Carlo sample pairs and seed.

    Returns
    -------
    PcResult
    """
    a, b = np.asarray(x1, dtype=float).reshape(6), np.asarray(x2, dtype=float).reshape(6)
    c1 = None if p1 is None else np.asarray(p1, dtype=float)
    c2 = None if p2 is None else np.asarray(p2, dtype=float)
    if not hbr_km > 0:
        raise ValueError(f"the hard-body radius must be > 0 km, got {hbr_km}")
    if method is PcMethod.MONTE_CARLO_3D and (c1 is None or c2 is None):
        raise ValueError("a Monte Carlo Pc needs both covariances")
    enc = encounter_plane(a, _full(c1), b, _full(c2))
    warn = _npd(c1, PcWarning.NPD_PRIMARY) | _npd(c2, PcWarning.NPD_SECONDARY)
    period = float(np.min(orbital_period(np.stack([a, b]))))
    base = PcResult(math.nan, math.nan, method, frozenset(warn), float(enc.miss_km[0]),
                    float(enc.speed_km_s[0]), float(hbr_km), float(enc.tca_offset_s[0]),
                    math.nan, math.nan, period_s=period)
    if not enc.moving[0]:
        return dataclasses.replace(base, warnings=frozenset(
            warn | {PcWarning.ZERO_RELATIVE_VELOCITY}))
    tau0, tau1 = _bounds(enc, hbr_km, c1 is not None or c2 is not None)
    if math.isfinite(tau1 - tau0):
        warn |= usage.usage_warnings(tau0, tau1, period)
    if method is PcMethod.MONTE_CARLO_3D:
        return _monte_carlo(a, _full(c1), b, _full(c2), hbr_km, (tau0, tau1), warn, base,
                            samples, seed)
    lp, used, s1, s2, more = _plane_pc(enc, hbr_km, c1, c2)
    pc, below = pc_from_log10(lp)
    if below:
        more.add(PcWarning.BELOW_FLOAT_RANGE)
    return dataclasses.replace(base, pc=pc, log10_pc=lp, method=used,
                               warnings=frozenset(warn | more), sigma_major_km=s1,
                               sigma_minor_km=s2, duration_s=tau1 - tau0)


def _monte_carlo(a: Array, p1: Array, b: Array, p2: Array, hbr_km: float,
                 bounds: tuple[float, float], warn: set[PcWarning], base: PcResult,
                 samples: int, seed: int) -> PcResult:
    """Return the Monte Carlo branch of `collision_probability`.

    The window is the Coppola bounds around the linear TCA for a short encounter, half the
    shorter period each way for a long one (whose relative motion curves).
    """
    half = 0.5 * base.period_s
    t_ca = base.tca_offset_s
    short = not warn & {PcWarning.EXTENDED_ENCOUNTER, PcWarning.OFFSET_ENCOUNTER}
    window = ((t_ca + max(bounds[0], -half), t_ca + min(bounds[1], half)) if short
              else (t_ca - half, t_ca + half))
    mc = monte_carlo.pc_monte_carlo(a, p1, b, p2, hbr_km, window, samples, seed)
    more = {PcWarning.MONTE_CARLO_NOISE} if mc.hits < 10 else set()
    lp = math.log10(mc.pc) if mc.pc > 0 else -math.inf
    return dataclasses.replace(base, pc=mc.pc, log10_pc=lp, method=PcMethod.MONTE_CARLO_3D,
                               warnings=frozenset(warn | more),
                               duration_s=bounds[1] - bounds[0], std_error=mc.std_error,
                               samples=mc.samples)
