"""Atmospheric refraction of the elevation a ground sensor measures (an option, off by default).

Air bends a ray towards the zenith, so a sensor sees an object higher than it geometrically
is: ``el_observed = el + R(el)``. `refraction` is Saemundsson's formula (Sky & Telescope 72,
70, 1986; the inverse of Bennett's), for the standard atmosphere of 101.0 kPa and 10 deg C,
from the geometric (true) elevation ``h`` in degrees::

    R = 1.02 / tan(h + 10.3 / (h + 5.11)) + 0.0019279  arc minutes

(the constant makes R vanish at the zenith, as Meeus does for Bennett's formula). It is 29'
at a geometric elevation of 0 (34' at an apparent one), 5.4' at 10 deg, 1' at 45 deg, and
agrees with Bennett's to 0.1'. A radar's radio refraction depends on
the air's humidity and is ~15 % larger near the ground (surface refractivity N ~ 313 against
~ 273 for light); the optical formula is a first correction, not a tropospheric model (no
weather is known here). Below -1 deg the value at -1 deg is used (the formula's pole lies near
-5 deg). Right ascension and declination from a plate reduced against catalogue stars carry
no refraction (the stars around the object are refracted alike), so the optical model takes
none.

Units: rad in, rad out.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

_ARCMIN = math.pi / (180.0 * 60.0)
_FLOOR_DEG = -1.0


def _terms(el_rad: ArrayLike) -> tuple[NDArray[np.float64], NDArray[np.float64],
                                       NDArray[np.bool_]]:
    h = np.degrees(np.asarray(el_rad, dtype=float))
    low = h < _FLOOR_DEG
    h = np.where(low, _FLOOR_DEG, h)
    return h, np.radians(h + 10.3 / (h + 5.11)), low


def refraction(el_rad: ArrayLike) -> NDArray[np.float64]:
    """Return the refraction R (rad) at geometric elevations ``el_rad`` (rad): add it."""
    _, a, _ = _terms(el_rad)
    out: NDArray[np.float64] = (1.02 / np.tan(a) + 0.0019279) * _ARCMIN
    return out


def refraction_rate(el_rad: ArrayLike) -> NDArray[np.float64]:
    """Return dR/d(el) (dimensionless) of `refraction` at ``el_rad`` (0 below -1 deg)."""
    h, a, low = _terms(el_rad)
    # dR/dh_deg = -1.02' / sin^2(a) * d(a)/dh_deg, a in rad of (h + 10.3 / (h + 5.11)) deg
    da_dh = math.radians(1.0) * (1.0 - 10.3 / (h + 5.11) ** 2)
    out: NDArray[np.float64] = np.where(
        low, 0.0, -1.02 * _ARCMIN / np.sin(a) ** 2 * da_dh / math.radians(1.0))
    return out
