"""Where the solid Earth tides move a station: the displacement of degree 2 (IERS 2010, 7.1.1).

The Sun and the Moon deform the Earth: a station rises and falls by up to ~0.3 m twice a
day (LAGEOS's stations in February 2016: up to 0.15 m), far more than a normal point's
centimetre. The in-phase displacement of degree 2 with nominal Love and Shida numbers
(IERS Conventions 2010, eq. 7.5, step 1)::

    dr = sum_j GM_j R^4 / (GM r_j^3) (h2 rhat (3/2 (Rhat_j . rhat)^2 - 1/2)
                                      + 3 l2 (Rhat_j . rhat) (Rhat_j - (Rhat_j . rhat) rhat))

with ``h2 = 0.6078 - 0.0006 (3 sin^2 phi - 1) / 2`` and ``l2 = 0.0847 + 0.0002 (3 sin^2 phi
- 1) / 2`` (phi the station's latitude), R the Earth's equatorial radius, r_j and Rhat_j
the body's distance and direction, rhat the station's. The vectors may be in any frame
(GCRF here: the Sun and the Moon of DE421, `earth.ephemeris`). It includes the permanent
tide, as the ITRF's "conventional tide-free" coordinates of SINEX want. Left out (each
below ~1 cm): degree 3 (< 1.7 mm), the out-of-phase and latitude-band terms (< 2 mm), the
frequency-dependent corrections of step 2 (the K1 line: up to 13 mm radial).

Units: km, rad; epochs Unix s (UTC).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ssa_fusion.core.base.constants import MU_EARTH
from ssa_fusion.core.earth.ephemeris import sun_moon_positions, sun_moon_span

__all__ = ["EQUATORIAL_RADIUS_KM", "displacement", "solid_tide_displacement"]

Array = NDArray[np.float64]

EQUATORIAL_RADIUS_KM = 6378.1366
"""The Earth's equatorial radius of the IERS Conventions' formula, km."""


def displacement(site: ArrayLike, lat: ArrayLike, bodies: list[tuple[float, Array]]) -> Array:
    """Return the tidal displacement (n, 3) km of stations ``site`` (n, 3) km.

    ``lat`` (n,) their latitudes, rad; ``bodies`` (GM km^3/s^2, position (n, 3) km) of each
    tide-raising body, in the stations' frame (module docstring).
    """
    r = np.atleast_2d(np.asarray(site, dtype=float))
    rh = r / np.linalg.norm(r, axis=1)[:, None]
    p2 = (3.0 * np.sin(np.asarray(lat, dtype=float)) ** 2 - 1.0) / 2.0
    h2, l2 = 0.6078 - 0.0006 * p2, 0.0847 + 0.0002 * p2
    out = np.zeros_like(r)
    for gm, body in bodies:
        b = np.atleast_2d(body)
        bn = np.linalg.norm(b, axis=1)
        bh = b / bn[:, None]
        u = np.einsum("ij,ij->i", bh, rh)
        k = gm * EQUATORIAL_RADIUS_KM**4 / (MU_EARTH * bn**3)
        out += k[:, None] * (h2[:, None] * (1.5 * u * u - 0.5)[:, None] * rh
                             + 3.0 * (l2 * u)[:, None] * (bh - u[:, None] * rh))
    return out


def solid_tide_displacement(site_gcrs: ArrayLike, lat: ArrayLike, t_unix: ArrayLike) -> Array:
    """Return the tidal displacement (n, 3) km of GCRF stations ``site_gcrs`` at ``t_unix``."""
    t = np.atleast_1d(np.asarray(t_unix, dtype=float))
    if not t.size:
        return np.zeros((0, 3))
    sun, moon = sun_moon_positions(t)
    span = sun_moon_span(float(t[0]), 0.0, 0.0)
    return displacement(site_gcrs, lat, [(span.gm_sun, sun), (span.gm_moon, moon)])
