"""A laser-ranging bag in the core's terms: its ranges, stations, air and reference orbit.

`ssa-fusion import crd` writes LASER_RANGE measurements on ``/ssa/measurement``, the
stations' meteorological records on ``/ssa/meteo``, its set-up on ``/ssa/config``
(`laser_config`) and, with ``--reference``, an independent orbit on ``/ssa/reference``.
`laser_bag` gathers them from a bag's messages (a replayed bag holds them too) as a
`LaserBag`: the sensor's ranges (`types.Measurement`, km), the `laser_model.LaserNetwork`
of the object ranged, the `troposphere.MeteoSample` records and the reference states
(GCRF km, km/s). `is_laser` tells a laser bag from any other. No rclpy here.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from ssa_fusion.core.base import types
from ssa_fusion.core.measure.laser_model import LaserNetwork
from ssa_fusion.core.measure.troposphere import MeteoSample
from ssa_fusion.ros import messages
from ssa_fusion.ros.bagio import BagMessage
from ssa_fusion.ros.laser_config import LaserConfig, recorded_laser
from ssa_fusion.ros.topics import TOPIC_CONFIG, TOPIC_MEASUREMENT, TOPIC_METEO, TOPIC_REFERENCE

__all__ = ["LaserBag", "is_laser", "laser_bag"]

Array = NDArray[np.float64]


@dataclass
class LaserBag:
    """The laser ranging of one object in a bag (module docstring).

    Attributes
    ----------
    measurements : list of Measurement
        The sensor's LASER_RANGE measurements, in log-time order (km).
    config : LaserConfig
        The set-up `import crd` recorded (stations, objects, bias priors, sources).
    object_id : str
        The object ranged.
    meteo : list of MeteoSample
        The stations' meteorological records.
    reference_t, reference_x : ndarray (K,), (K, 6)
        The reference orbit's epochs (Unix s) and GCRF states (km, km/s); empty without.
    """

    measurements: list[types.Measurement]
    config: LaserConfig
    object_id: str
    meteo: list[MeteoSample] = field(default_factory=list)
    reference_t: Array = field(default_factory=lambda: np.zeros(0))
    reference_x: Array = field(default_factory=lambda: np.zeros((0, 6)))

    @property
    def network(self) -> LaserNetwork:
        """The stations that ranged the object (in the order first seen) and its offset."""
        seen = list(dict.fromkeys(m.frame_id for m in self.measurements))
        c = self.config
        return LaserNetwork({s: c.stations[s] for s in seen}, c.com_km[self.object_id],
                            {s: c.bias_km[s] for s in seen},
                            {s: c.bias_sigma_km[s] for s in seen})

    @property
    def ilrs_id(self) -> int | None:
        """The object's ILRS id as recorded (None if not)."""
        got = self.config.meta.get("objects", {}).get(self.object_id, {}).get("ilrs_id")
        return int(got) if got is not None else None


def is_laser(stream: Sequence[BagMessage]) -> bool:
    """Return True when the bag's measurements include laser ranges."""
    return any(m.topic == TOPIC_MEASUREMENT and int(m.msg.kind) == types.Kind.LASER_RANGE
               for m in stream)


def laser_bag(stream: Sequence[BagMessage]) -> LaserBag:
    """Return the `LaserBag` of a bag's messages (ValueError saying what is missing).

    One object's ranges (a bag of several is refused: replay or report each apart), the
    ``import_crd`` set-up naming every station that ranged it.
    """
    config = recorded_laser(m.msg.data for m in stream if m.topic == TOPIC_CONFIG)
    if config is None:
        raise ValueError("laser ranges without their stations: the bag has no /ssa/config "
                         "of `ssa-fusion import crd`")
    ms = [messages.measurement_from_msg(m.msg) for m in stream
          if m.topic == TOPIC_MEASUREMENT and int(m.msg.kind) == types.Kind.LASER_RANGE
          and int(m.msg.source) == types.Source.SENSOR]
    objects = sorted({m.object_id for m in ms})
    if len(objects) != 1:
        raise ValueError(f"laser ranges of {len(objects)} objects ({', '.join(objects)}): "
                         f"one object's at a time")
    unknown = sorted({m.frame_id for m in ms} - set(config.stations))
    if unknown:
        raise ValueError(f"laser ranges from station(s) {', '.join(unknown)} that "
                         f"/ssa/config does not describe")
    if objects[0] not in config.com_km:
        raise ValueError(f"object {objects[0]}: no centre-of-mass offset in /ssa/config")
    ref = [messages.estimate_from_msg(m.msg) for m in stream if m.topic == TOPIC_REFERENCE]
    meteo = [messages.meteo_from_msg(m.msg) for m in stream if m.topic == TOPIC_METEO]
    return LaserBag(ms, config, objects[0], meteo,
                    np.array([e.t for e in ref], dtype=float),
                    np.array([e.x for e in ref], dtype=float).reshape(-1, 6))
