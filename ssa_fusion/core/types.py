"""Plain data types shared by the core, the nodes and the offline tools.

Everything here is in the core's units: km, km/s, rad, s. Times are seconds on the
simulation clock (the ROS time of the message stamps).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

POSITION = 0
"""Measurement kind: ECI position [x, y, z], km."""
RANGE_AZ_EL = 1
"""Measurement kind: [range km, azimuth rad (north, clockwise, [0, 2pi)), elevation rad]."""

SENSOR = 0
"""Measurement source: a real sensor."""
FORECAST = 1
"""Measurement source: a surrogate forecast."""

UPDATE_NONE = 0
UPDATE_SENSOR = 1
UPDATE_FORECAST = 2

KIND_NAMES = {POSITION: "position", RANGE_AZ_EL: "range_az_el"}


@dataclass
class Measurement:
    """One measurement (real or forecast) of an object.

    Attributes
    ----------
    t : float
        Epoch, s (simulation clock).
    z : ndarray (3,)
        Position in km (POSITION, ECI) or [range km, az rad, el rad] (RANGE_AZ_EL).
    R : ndarray (3, 3)
        Noise covariance of z in the units of z squared.
    kind, source : int
        See the module constants.
    frame_id : str
        "eci" for POSITION, the station id for RANGE_AZ_EL.
    horizon : float
        s since the last real measurement the forecast came from (0 for SENSOR).
    """

    t: float
    z: np.ndarray
    R: np.ndarray
    kind: int = POSITION
    source: int = SENSOR
    object_id: str = ""
    frame_id: str = "eci"
    horizon: float = 0.0


@dataclass
class StateEstimate:
    """An ECI state estimate: x (6,) in km, km/s; P (6, 6) in km^2, km^2/s, km^2/s^2."""

    t: float
    x: np.ndarray
    P: np.ndarray = field(default_factory=lambda: np.zeros((6, 6)))
    object_id: str = ""
    update_source: int = UPDATE_NONE
    nis: float = 0.0
