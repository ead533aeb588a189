"""When a ground sensor can measure an object: elevation masks, night, sunlight, brightness.

A radar measures above its elevation mask, day and night; an optical sensor only above its
mask, while its station is dark (the Sun below `ASTRONOMICAL_DARK`, nautical twilight's end)
and the object is sunlit, and (with a limiting magnitude) bright enough: `apparent_magnitude`
of a diffuse sphere of a given standard magnitude. Vectorised over epochs; units km, rad;
states GCRF; epochs Unix seconds (UTC).
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ssa_fusion.core.earth.frames import Station, razel_gcrs, site_gcrs
from ssa_fusion.core.earth.sun import sun_elevation, sun_position_gcrs, sunlit

ASTRONOMICAL_DARK = math.radians(-12.0)
"""Sun elevation below which an optical site observes, rad (-12 deg, nautical twilight)."""

STANDARD_RANGE_KM = 1000.0
"""Range at which a standard magnitude is given (with a 90 deg phase angle), km."""

__all__ = ["ASTRONOMICAL_DARK", "STANDARD_RANGE_KM", "above_mask", "apparent_magnitude",
           "diffuse_sphere_phase", "optical_visible", "station_dark", "sunlit"]


def above_mask(x_gcrs: ArrayLike, t_unix: ArrayLike, station: Station,
               min_elevation: float | NDArray[np.float64] = 0.0) -> NDArray[np.bool_]:
    """Return whether objects at GCRF `x_gcrs` (..., 3 or 6) are above the mask of `station`.

    `min_elevation` (rad) is a scalar or an array of the epochs' shape (a mask by azimuth).
    """
    el = razel_gcrs(x_gcrs, t_unix, station)[..., 2]
    out: NDArray[np.bool_] = el >= min_elevation
    return out


def station_dark(t_unix: ArrayLike, station: Station,
                 sun_limit_rad: float = ASTRONOMICAL_DARK) -> NDArray[np.bool_]:
    """Return whether the Sun is below `sun_limit_rad` at `station`."""
    out: NDArray[np.bool_] = sun_elevation(t_unix, station) < sun_limit_rad
    return out


def optical_visible(x_gcrs: ArrayLike, t_unix: ArrayLike, station: Station,
                    min_elevation: float = 0.0) -> NDArray[np.bool_]:
    """Return whether an optical sensor sees: above the mask, station dark, object sunlit."""
    x = np.asarray(x_gcrs, dtype=float)
    out: NDArray[np.bool_] = (above_mask(x, t_unix, station, min_elevation)
                              & station_dark(t_unix, station) & sunlit(x[..., :3], t_unix))
    return out


def diffuse_sphere_phase(phase_rad: ArrayLike) -> NDArray[np.float64]:
    """Return the diffuse (Lambertian) sphere's phase function at phase angles `phase_rad`.

    ``(sin p + (pi - p) cos p) / pi``: 1 fully lit (p = 0), 1/pi at 90 deg, 0 at 180 deg.
    """
    p = np.asarray(phase_rad, dtype=float)
    out: NDArray[np.float64] = (np.sin(p) + (math.pi - p) * np.cos(p)) / math.pi
    return out


def apparent_magnitude(x_gcrs: ArrayLike, t_unix: ArrayLike, station: Station,
                       standard_magnitude: float) -> NDArray[np.float64]:
    """Return the visual magnitude of objects at GCRF `x_gcrs` (..., 3 or 6) from `station`.

    A diffuse sphere whose magnitude is `standard_magnitude` at `STANDARD_RANGE_KM` and a
    90 deg phase angle (the usual catalogue convention; the ISS is about -1.3):
    ``m = m_std + 5 log10(range / 1000 km) - 2.5 log10(F(phase) / F(90 deg))``, phase being
    the Sun-object-station angle. Infinite where the object is unlit from the station's side
    (phase 180 deg).
    """
    x = np.asarray(x_gcrs, dtype=float)[..., :3]
    t = np.asarray(t_unix, dtype=float)
    to_site = site_gcrs(station, t)[..., :3] - x
    to_sun = sun_position_gcrs(t) - x
    rng = np.linalg.norm(to_site, axis=-1)
    cos_p = np.einsum("...i,...i->...", to_site, to_sun) / (
        rng * np.linalg.norm(to_sun, axis=-1))
    f = diffuse_sphere_phase(np.arccos(np.clip(cos_p, -1.0, 1.0)))
    with np.errstate(divide="ignore"):
        out: NDArray[np.float64] = (standard_magnitude
                                    + 5.0 * np.log10(rng / STANDARD_RANGE_KM)
                                    - 2.5 * np.log10(f * math.pi))
    return out
