"""When a ground sensor can measure an object: elevation masks, night, sunlight.

A radar measures above its elevation mask, day and night; an optical sensor only above its
mask, while its station is dark (the Sun below `ASTRONOMICAL_DARK`, nautical twilight's end)
and the object is sunlit. Vectorised over epochs; units km, rad; states GCRF; epochs Unix
seconds (UTC).
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .frames import Station, razel_gcrs
from .sun import sun_elevation, sunlit

ASTRONOMICAL_DARK = math.radians(-12.0)
"""Sun elevation below which an optical site observes, rad (-12 deg, nautical twilight)."""

__all__ = ["ASTRONOMICAL_DARK", "above_mask", "optical_visible", "station_dark", "sunlit"]


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
