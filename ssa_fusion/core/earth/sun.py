"""The Sun's position and the Earth's shadow (what an optical sensor needs).

The Sun's geocentric position in the GCRF is minus the Earth's heliocentric position from
ERFA's `epv00` (Bretagnon & Francou's VSOP2000-based series, a few km over 1900-2100), of TT,
in km, computed at whole UTC hours and interpolated linearly between them (the series costs
~20 us an epoch; the interpolation's error is ~10 km at the Sun's distance, 0.01"). No
aberration or light time: at the Sun's distance they displace it by ~20", which
moves a shadow boundary by ~0.7 km at a low orbit and a twilight limit by a second of time.
Units: km, rad; epochs are Unix seconds (UTC), converted to TT (`timescales`).
"""

from __future__ import annotations

import erfa
import numpy as np
from numpy.typing import ArrayLike, NDArray

from ssa_fusion.core.base.constants import R_EARTH
from ssa_fusion.core.earth.frames import Station, razel_gcrs
from ssa_fusion.core.earth.timescales import jd_tt

AU_KM = 149597870.7
"""Astronomical unit, km (IAU 2012)."""


NODE_S = 3600.0
"""Spacing of the Sun's computed positions, s (whole UTC hours)."""

_NODES: dict[int, NDArray[np.float64]] = {}
_NODES_MAX = 100_000


def _at_nodes(keys: NDArray[np.int64]) -> NDArray[np.float64]:
    """Return the Sun (n, 3) km at the whole hours ``keys`` (since 1970), `erfa.epv00`, cached."""
    missing = np.array([k for k in np.unique(keys).tolist() if k not in _NODES], dtype=np.int64)
    if len(missing):
        pvh, _ = erfa.epv00(*jd_tt(missing.astype(float) * NODE_S))
        if len(_NODES) + len(missing) > _NODES_MAX:
            _NODES.clear()
        for k, p in zip(missing.tolist(), np.asarray(pvh["p"], dtype=float), strict=True):
            _NODES[k] = -AU_KM * p
    return np.array([_NODES[k] for k in keys.tolist()]).reshape(-1, 3)


def sun_position_gcrs(t_unix: ArrayLike) -> NDArray[np.float64]:
    """Return the Sun's geocentric position (..., 3), km, GCRF, at Unix (UTC) epochs."""
    t = np.asarray(t_unix, dtype=float)
    h = t.ravel() / NODE_S
    k0 = np.floor(h)
    keys = k0.astype(np.int64)
    uniq, inv = np.unique(np.concatenate([keys, keys + 1]), return_inverse=True)
    nodes = _at_nodes(uniq)[inv]
    n = len(keys)
    f = (h - k0)[:, None]
    out: NDArray[np.float64] = (nodes[:n] + f * (nodes[n:] - nodes[:n])).reshape(*t.shape, 3)
    return out


def in_earth_shadow(r_gcrs_km: ArrayLike, r_sun_km: ArrayLike) -> NDArray[np.bool_]:
    """Return whether objects at `r_gcrs_km` (..., 3) are in the Earth's shadow.

    Cylindrical shadow model (Vallado Algorithm 34, without the penumbra): behind the Earth
    as seen from the Sun `r_sun_km` (..., 3) and within one Earth radius of the Earth-Sun
    line. For low orbits the conical umbra differs by a few seconds of shadow entry.
    """
    r = np.asarray(r_gcrs_km, dtype=float)
    s = np.asarray(r_sun_km, dtype=float)
    s_hat = s / np.linalg.norm(s, axis=-1, keepdims=True)
    along = np.sum(r * s_hat, axis=-1)
    perp = np.linalg.norm(r - along[..., None] * s_hat, axis=-1)
    out: NDArray[np.bool_] = (along < 0.0) & (perp < R_EARTH)
    return out


def sunlit(r_gcrs_km: ArrayLike, t_unix: ArrayLike) -> NDArray[np.bool_]:
    """Return whether objects at `r_gcrs_km` (..., 3) are sunlit at `t_unix` (broadcast)."""
    out: NDArray[np.bool_] = ~in_earth_shadow(r_gcrs_km, sun_position_gcrs(t_unix))
    return out


def sun_elevation(t_unix: ArrayLike, station: Station) -> NDArray[np.float64]:
    """Return the geometric elevation of the Sun above the horizon of `station`, rad."""
    t = np.asarray(t_unix, dtype=float)
    out: NDArray[np.float64] = razel_gcrs(sun_position_gcrs(t), t, station)[..., 2]
    return out
