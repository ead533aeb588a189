"""The simulated world's air: NRLMSISE-00's total mass density along an orbit.

NRLMSISE-00 (Picone, Hedin, Drob & Aikin 2002, J. Geophys. Res. 107(A12), 1468), as the
``pymsis`` package wraps NRL's Fortran (version 0; MIT licence, compiled wheels, no network:
the activity is always given, `space_weather.SpaceWeather`). Its density varies with
altitude, latitude, local solar time (the diurnal bulge), season, F10.7 and ap: what the
filters' exponential atmosphere (`core.motion.force_model`) leaves out.

`msis_density` evaluates it at GCRF positions (turned to the ITRF, then to WGS84 geodetic
longitude, latitude and height); `density_factor` divides it by the exponential
atmosphere's density at the same radius, the factor `core.motion.high_fidelity.DensityTable`
tabulates for the propagator. Units: km, kg/m^3, Unix s UTC.
"""

from __future__ import annotations

import erfa
import numpy as np
from numpy.typing import ArrayLike, NDArray

from ssa_fusion.core.base.constants import R_EARTH
from ssa_fusion.core.earth import frames
from ssa_fusion.core.motion.force_spec import DragSpec
from ssa_fusion.sim.space_weather import SpaceWeather

__all__ = ["MSIS_VERSION", "density_factor", "exponential_density", "msis_density"]

Array = NDArray[np.float64]

MSIS_VERSION = 0
"""pymsis's model version: 0 is NRLMSISE-00 (2.0 and 2.1 are NRLMSIS 2.x)."""
STORM_TIME_AP = -1
"""pymsis's ``geomagnetic_activity`` switch: -1 reads the 3-hourly ap history (storm time)."""


def msis_density(t_unix: ArrayLike, r_gcrs_km: ArrayLike, weather: SpaceWeather) -> Array:
    """Return NRLMSISE-00's total mass density (n,) kg/m^3 at GCRF positions (n, 3) km."""
    import pymsis

    t = np.atleast_1d(np.asarray(t_unix, dtype=float))
    r = np.asarray(r_gcrs_km, dtype=float).reshape(-1, 3)
    itrs = frames.gcrs_to_itrs(r, t)
    lon, lat, h = erfa.gc2gd(1, itrs * 1000.0)
    f107, f107a, ap = weather.msis_inputs(t)
    dates = (np.round(t * 1e6).astype(np.int64)).astype("datetime64[us]")
    out = pymsis.calculate(dates, np.degrees(lon), np.degrees(lat), np.asarray(h) / 1000.0,
                           f107, f107a, ap, version=MSIS_VERSION,
                           geomagnetic_activity=STORM_TIME_AP)
    rho: Array = np.asarray(out, dtype=float)[..., pymsis.Variable.MASS_DENSITY].reshape(-1)
    return rho


def exponential_density(r_km: ArrayLike, drag: DragSpec) -> Array:
    """Return the exponential atmosphere's density kg/m^3 at radii ``r_km`` (`force_model`)."""
    r = np.asarray(r_km, dtype=float)
    out: Array = drag.rho0 * np.exp(-(r - R_EARTH - drag.h0) / drag.scale_height)
    return out


def density_factor(t_unix: ArrayLike, r_gcrs_km: ArrayLike, weather: SpaceWeather,
                   drag: DragSpec) -> Array:
    """Return NRLMSISE-00's density over the exponential atmosphere's at each position (n,)."""
    r = np.asarray(r_gcrs_km, dtype=float).reshape(-1, 3)
    out: Array = msis_density(t_unix, r, weather) / exponential_density(
        np.linalg.norm(r, axis=1), drag)
    return out
