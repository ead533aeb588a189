"""The Sun's position and the Earth's shadow (what an optical sensor needs).

The Sun's geocentric position comes from the Astronomical Almanac's low-precision formulae
(Vallado, "Fundamentals of Astrodynamics and Applications", 4th ed., Algorithm 29): about
0.01 deg in direction between 1950 and 2050, referred to the mean equator and equinox of
date, which is this project's ECI to well within that (TEME differs from it by the
equation of the equinoxes, < 0.005 deg). Units: km, rad; epochs are UTC Julian dates.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .constants import R_EARTH
from .frames import J2000_JD, Station, razel_eci

AU_KM = 149597870.7
"""Astronomical unit, km (IAU 2012)."""


def sun_position_eci(jd_utc: ArrayLike) -> NDArray[np.float64]:
    """Return the Sun's geocentric position (..., 3), km, ECI, at UTC Julian dates."""
    t = (np.asarray(jd_utc, dtype=float) - J2000_JD) / 36525.0
    mean_lon = np.radians(280.460 + 36000.771 * t)
    m = np.radians(357.5291092 + 35999.05034 * t)
    lon = mean_lon + np.radians(1.914666471 * np.sin(m) + 0.019994643 * np.sin(2 * m))
    r = AU_KM * (1.000140612 - 0.016708617 * np.cos(m) - 0.000139589 * np.cos(2 * m))
    eps = np.radians(23.439291 - 0.0130042 * t)
    out: NDArray[np.float64] = np.stack(
        [r * np.cos(lon), r * np.cos(eps) * np.sin(lon), r * np.sin(eps) * np.sin(lon)], -1)
    return out


def in_earth_shadow(r_eci_km: ArrayLike, r_sun_km: ArrayLike) -> NDArray[np.bool_]:
    """Return whether objects at `r_eci_km` (..., 3) are in the Earth's shadow.

    Cylindrical shadow model (Vallado Algorithm 34, without the penumbra): behind the Earth
    as seen from the Sun `r_sun_km` (..., 3) and within one Earth radius of the Earth-Sun
    line. For low orbits the conical umbra differs by a few seconds of shadow entry.
    """
    r = np.asarray(r_eci_km, dtype=float)
    s = np.asarray(r_sun_km, dtype=float)
    s_hat = s / np.linalg.norm(s, axis=-1, keepdims=True)
    along = np.sum(r * s_hat, axis=-1)
    perp = np.linalg.norm(r - along[..., None] * s_hat, axis=-1)
    out: NDArray[np.bool_] = (along < 0.0) & (perp < R_EARTH)
    return out


def sunlit(r_eci_km: ArrayLike, jd_utc: ArrayLike) -> NDArray[np.bool_]:
    """Return whether objects at `r_eci_km` (..., 3) are sunlit at `jd_utc` (broadcast)."""
    out: NDArray[np.bool_] = ~in_earth_shadow(r_eci_km, sun_position_eci(jd_utc))
    return out


def sun_elevation(jd_utc: ArrayLike, station: Station) -> NDArray[np.float64]:
    """Return the elevation of the Sun above the horizon of `station`, rad, at `jd_utc`."""
    jd = np.asarray(jd_utc, dtype=float)
    out: NDArray[np.float64] = razel_eci(sun_position_eci(jd), jd, station)[..., 2]
    return out
