"""The Sun's position and the Earth's shadow (what an optical sensor needs).

The Sun's geocentric position in the GCRF is minus the Earth's heliocentric position from
ERFA's `epv00` (Bretagnon & Francou's VSOP2000-based series, a few km over 1900-2100), of TT,
in km. No aberration or light time: at the Sun's distance they displace it by ~20", which
moves a shadow boundary by ~0.7 km at a low orbit and a twilight limit by a second of time.
Units: km, rad; epochs are Unix seconds (UTC), converted to TT (`timescales`).
"""

from __future__ import annotations

import erfa
import numpy as np
from numpy.typing import ArrayLike, NDArray

from .constants import R_EARTH
from .frames import Station, razel_gcrs
from .timescales import jd_tt

AU_KM = 149597870.7
"""Astronomical unit, km (IAU 2012)."""


def sun_position_gcrs(t_unix: ArrayLike) -> NDArray[np.float64]:
    """Return the Sun's geocentric position (..., 3), km, GCRF, at Unix (UTC) epochs."""
    t = np.asarray(t_unix, dtype=float)
    pvh, _ = erfa.epv00(*jd_tt(t))
    out: NDArray[np.float64] = -AU_KM * np.asarray(pvh['p'], dtype=float)
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
