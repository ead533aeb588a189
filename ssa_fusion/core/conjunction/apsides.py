"""The apogee/perigee filter: `osculating_apsides`, `radial_bands`, `bands_meet`.

Two objects can come within a distance d of each other only if the shells their radii sweep
come within d: an object of radii in ``[lo_1, hi_1]`` and one in ``[lo_2, hi_2]`` cannot
meet when ``lo_2 > hi_1 + d`` or ``lo_1 > hi_2 + d``. The radius of an object at an epoch
lies between the perigee and apogee radii of its osculating conic at that epoch (exactly,
for any state: the position is on that conic), so the shell an object sweeps over a span
of time is bounded by the smallest osculating perigee and the largest osculating apogee of
its states over that span, less and plus a pad for what the sampling of those states misses
(J2's short-periodic terms move the osculating perigee of a LEO orbit by ~10 km over half a
revolution: sampled every 5 min, the smallest is missed by < 0.2 km).

Units: km, km/s; states GCRF (any inertial frame).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ssa_fusion.core.base.constants import MU_EARTH
from ssa_fusion.core.base.jit import jit

__all__ = ["RadialBands", "bands_meet", "meet", "meets_any", "osculating_apsides",
           "radial_bands"]

Array = NDArray[np.float64]
BoolArray = NDArray[np.bool_]


def osculating_apsides(x: ArrayLike, mu: float = MU_EARTH) -> tuple[Array, Array, Array]:
    """Return the osculating perigee and apogee radii and perigee speed of states ``x``.

    Parameters
    ----------
    x : array_like (..., 6)
        Inertial states, km and km/s.
    mu : float
        Gravitational parameter, km³/s².

    Returns
    -------
    (rp, ra, vp) : ndarrays (...)
        Perigee radius km, apogee radius km (inf for an open orbit, e >= 1) and the speed
        at perigee km/s (the largest speed on the conic): ``rp = h² / (mu (1 + e))``,
        ``ra = h² / (mu (1 - e))``, ``vp = mu (1 + e) / h``. NaN where ``x`` is not finite.
    """
    s = np.asarray(x, dtype=float)
    r, v = s[..., :3], s[..., 3:]
    rn = np.linalg.norm(r, axis=-1)
    h2 = np.sum(np.cross(r, v) ** 2, axis=-1)
    energy = 0.5 * np.sum(v * v, axis=-1) - mu / rn
    e = np.sqrt(np.maximum(1.0 + 2.0 * energy * h2 / (mu * mu), 0.0))
    with np.errstate(divide="ignore", invalid="ignore"):
        rp = h2 / (mu * (1.0 + e))
        ra = np.where(e < 1.0, h2 / (mu * (1.0 - e)), np.inf)
        vp = mu * (1.0 + e) / np.sqrt(h2)
    ra = np.where(np.isfinite(rp), ra, np.nan)
    return rp, ra, vp


@dataclass(frozen=True)
class RadialBands:
    """The shells objects sweep over a span of time, and their largest speeds.

    Attributes
    ----------
    lo, hi : ndarray (N,)
        Smallest and largest radius, km (``lo = inf``, ``hi = -inf`` for an object with no
        state in the span: it meets nothing).
    vmax : ndarray (N,)
        Largest speed, km/s (0 for an object with no state).
    """

    lo: Array
    hi: Array
    vmax: Array


def radial_bands(x: ArrayLike, pad_km: float, speed_margin: float = 0.01,
                 mu: float = MU_EARTH) -> RadialBands:
    """Return the radial bands of objects from their states sampled over a span of time.

    Parameters
    ----------
    x : array_like (N, K, 6)
        Each object's GCRF states at K epochs spanning the time, km and km/s; NaN rows are
        skipped.
    pad_km : float
        Taken off the smallest osculating perigee and added to the largest apogee, km.
    speed_margin : float
        Relative margin on the largest osculating perigee speed.
    mu : float
        Gravitational parameter, km³/s².
    """
    rp, ra, vp = osculating_apsides(x, mu)
    with np.errstate(invalid="ignore"):
        lo = np.min(np.where(np.isfinite(rp), rp, np.inf), axis=1) - pad_km
        hi = np.max(np.where(np.isnan(ra), -np.inf, ra), axis=1) + pad_km
        vmax = np.max(np.where(np.isfinite(vp), vp, 0.0), axis=1) * (1.0 + speed_margin)
    return RadialBands(lo, hi, vmax)


@jit
def meet(lo1: float, hi1: float, lo2: float, hi2: float, distance: float) -> bool:
    """Return whether radial bands ``[lo1, hi1]`` and ``[lo2, hi2]`` (km) come within d km."""
    return lo2 <= hi1 + distance and lo1 <= hi2 + distance


def bands_meet(b1: tuple[ArrayLike, ArrayLike], b2: tuple[ArrayLike, ArrayLike],
               distance_km: float) -> BoolArray:
    """Return where bands ``b1 = (lo, hi)`` and ``b2`` (km, broadcast) come within d km."""
    lo1, hi1 = (np.asarray(a, dtype=float) for a in b1)
    lo2, hi2 = (np.asarray(a, dtype=float) for a in b2)
    out: BoolArray = (lo2 <= hi1 + distance_km) & (lo1 <= hi2 + distance_km)
    return out


def meets_any(lo: ArrayLike, hi: ArrayLike, of: ArrayLike, distance_km: float) -> BoolArray:
    """Return which bands ``[lo, hi]`` (N,) come within d km of one of the bands ``of`` (mask).

    Sorted by their lower ends, the bands ``of`` that start low enough for a band are a
    prefix: the band meets one of them when the highest upper end of that prefix reaches
    it. O(N log N). NaN bands meet nothing.
    """
    lo_, hi_ = np.asarray(lo, dtype=float), np.asarray(hi, dtype=float)
    sel = np.asarray(of, dtype=np.bool_) & np.isfinite(lo_) & np.isfinite(hi_)
    order = np.argsort(lo_[sel])
    starts = lo_[sel][order]
    top = np.maximum.accumulate(hi_[sel][order]) if starts.size else np.zeros(0)
    with np.errstate(invalid="ignore"):
        k = np.searchsorted(starts, hi_ + distance_km, side="right")
        reach = np.where(k > 0, top[np.maximum(k - 1, 0)] if top.size else -np.inf, -np.inf)
        out: BoolArray = reach >= lo_ - distance_km
    return out
