"""Light time between an object and a ground station.

A station receiving at epoch t sees the object where it was at ``t - tau``, with
``tau = |r(t - tau) - r_site(t)| / c`` (one way, down leg). `retarded_states` solves that by
fixed-point iteration on a trajectory function (each iteration shrinks the error by
``|v| / c ~ 3e-5``: three are exact to round-off). Units km, km/s, s; epochs Unix s.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .constants import C_KM_S
from .frames import Station, ecef_to_eci, site_ecef
from .stations import UNIX_EPOCH_JD

Trajectory = Callable[[NDArray[np.float64]], NDArray[np.float64]]
"""states(t) -> (len(t), 6) ECI states at Unix epochs t."""


def site_eci(station: Station, t_unix: ArrayLike) -> NDArray[np.float64]:
    """ECI position (..., 3), km, of `station` at Unix epochs `t_unix`."""
    t = np.asarray(t_unix, dtype=float)
    e = site_ecef(station.lat_rad, station.lon_rad, station.alt_km)
    return ecef_to_eci(np.broadcast_to(e, (*t.shape, 3)), UNIX_EPOCH_JD + t / 86400.0)


def light_time_delay(r_eci_km: ArrayLike, station: Station,
                     t_unix: ArrayLike) -> NDArray[np.float64]:
    """Return the one-way light time (s) from objects at `r_eci_km` (..., 3) to `station`.

    At reception epochs `t_unix`; no iteration (the object's position is taken at emission).
    """
    r = np.asarray(r_eci_km, dtype=float)[..., :3]
    out: NDArray[np.float64] = np.linalg.norm(r - site_eci(station, t_unix), axis=-1) / C_KM_S
    return out


def retarded_states(states: Trajectory, t_receive: ArrayLike, station: Station,
                    iterations: int = 3) -> NDArray[np.float64]:
    """Return the ECI states (len(t), 6) of the object when the light left it.

    The light is received by `station` at `t_receive` (Unix s).
    """
    t = np.atleast_1d(np.asarray(t_receive, dtype=float))
    site = site_eci(station, t)
    x = states(t)
    for _ in range(iterations):
        x = states(t - np.linalg.norm(x[:, :3] - site, axis=-1) / C_KM_S)
    return x
