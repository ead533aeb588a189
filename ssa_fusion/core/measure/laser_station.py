"""A laser ranging station where it is: ITRF position moving with its plate, eccentricity.

A station's coordinates come as a solution of a terrestrial reference frame (SLRF2014, the
ILRS's realisation of ITRF2014, in SINEX): the position of its marker at a reference epoch
and its velocity (plate tectonics, a few cm/yr), and its eccentricity, the vector from
the marker to the system reference point the ranges are measured from, as Up, North, East.
At an epoch t the reference point is

    r(t) = r_ref + v (t - t_ref) + E^T [east, north, up]

with E the ITRF -> East-North-Up rotation at the marker's geodetic latitude and longitude
(`frames.enu_matrix`). Post-seismic deformations (which SLRF2014 leaves to the user for a
few stations) are not modelled.

Units: km, km/s, Unix s (UTC); the geodetic latitude and longitude in rad, height in km
above the WGS-84 ellipsoid.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import erfa
import numpy as np
from numpy.typing import ArrayLike, NDArray

from ssa_fusion.core.earth.frames import enu_matrix

Array = NDArray[np.float64]

JULIAN_YEAR_S = 365.25 * 86400.0
"""A Julian year, s (the year of velocities in m/yr: SINEX's)."""
WAVELENGTH_UM = 0.532
"""The usual transmit wavelength, um (frequency-doubled Nd:YAG)."""


@dataclass(frozen=True)
class LaserStation:
    """A laser ranging station (module docstring).

    Attributes
    ----------
    station_id
        Its id (what its measurements' frame_id says).
    position_km, velocity_km_s
        The marker's ITRF position (km) at `t_ref` and its velocity (km/s), (3,).
    t_ref
        The reference epoch of `position_km`, Unix s (UTC).
    eccentricity_une_km
        Marker -> system reference point, (up, north, east) km.
    wavelength_um
        The laser's transmit wavelength, um (the troposphere's delay depends on it).
    name
        A readable name (e.g. the CRD's four characters "YARL").
    """

    station_id: str
    position_km: Array
    velocity_km_s: Array
    t_ref: float
    eccentricity_une_km: Array = field(default_factory=lambda: np.zeros(3))
    wavelength_um: float = WAVELENGTH_UM
    name: str = ""

    @property
    def geodetic(self) -> tuple[float, float, float]:
        """(latitude rad, longitude rad, height km) of the marker at `t_ref` (WGS-84)."""
        lon, lat, h = erfa.gc2gd(1, np.asarray(self.position_km, dtype=float) * 1000.0)
        return float(lat), float(lon), float(h) / 1000.0

    @property
    def eccentricity_itrs_km(self) -> Array:
        """The eccentricity as an ITRF vector (3,), km."""
        lat, lon, _ = self.geodetic
        up, north, east = np.asarray(self.eccentricity_une_km, dtype=float)
        out: Array = enu_matrix(lat, lon).T @ np.array([east, north, up])
        return out

    def itrs(self, t_unix: ArrayLike) -> Array:
        """Return the system reference point's ITRF position (..., 3), km, at Unix epochs."""
        dt = np.asarray(t_unix, dtype=float)[..., None] - self.t_ref
        out: Array = (np.asarray(self.position_km, dtype=float) + dt * np.asarray(
            self.velocity_km_s, dtype=float) + self.eccentricity_itrs_km)
        return out


def velocity_per_year(velocity_m_yr: ArrayLike) -> Array:
    """Return a velocity in m/yr (Julian years) in km/s."""
    out: Array = np.asarray(velocity_m_yr, dtype=float) / 1000.0 / JULIAN_YEAR_S
    return out


def geodetic_of(position_km: ArrayLike) -> tuple[Array, Array, Array]:
    """Return (latitude rad, longitude rad, height km) of ITRF positions (..., 3) km."""
    lon, lat, h = erfa.gc2gd(1, np.asarray(position_km, dtype=float) * 1000.0)
    return np.asarray(lat, float), np.asarray(lon, float), np.asarray(h, float) / 1000.0
