"""Light time between an object and a ground station.

A station receiving at epoch t sees the object where it was at ``t - tau``, with
``tau = |r(t - tau) - r_site(t)| / c`` (one way, down leg; both positions in the GCRF, so the
Earth's rotation during the light's travel is in: the station is taken where it is at
reception). `retarded_states` solves that by fixed-point iteration on a trajectory function
(each iteration shrinks the error by ``|v| / c ~ 3e-5``: three are exact to round-off). A
radar's range is modelled as this one-way down leg; the round trip differs from it by less
than a metre for a low orbit. Units km, km/s, s; epochs Unix s (UTC).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ssa_fusion.core.base.constants import C_KM_S
from ssa_fusion.core.earth.frames import Station, site_gcrs

Trajectory = Callable[[NDArray[np.float64]], NDArray[np.float64]]
"""states(t) -> (len(t), 6) GCRF states at Unix epochs t."""


def light_time_delay(r_gcrs_km: ArrayLike, station: Station,
                     t_unix: ArrayLike) -> NDArray[np.float64]:
    """Return the one-way light time (s) from objects at `r_gcrs_km` (..., 3) to `station`.

    At reception epochs `t_unix`; no iteration (the object's position is taken at emission).
    """
    r = np.asarray(r_gcrs_km, dtype=float)[..., :3]
    out: NDArray[np.float64] = np.linalg.norm(r - site_gcrs(station, t_unix), axis=-1) / C_KM_S
    return out


def retarded_states(states: Trajectory, t_receive: ArrayLike, station: Station,
                    iterations: int = 3) -> NDArray[np.float64]:
    """Return the GCRF states (len(t), 6) of the object when the light left it.

    The light is received by `station` at `t_receive` (Unix s).
    """
    t = np.atleast_1d(np.asarray(t_receive, dtype=float))
    site = site_gcrs(station, t)
    x = states(t)
    for _ in range(iterations):
        x = states(t - np.linalg.norm(x[:, :3] - site, axis=-1) / C_KM_S)
    return x
