"""The filter node's laser ranging: its network, its forces, its a-priori orbit.

A filter node with ``kind`` laser_range is the laser filter of `core.gaps.estimator`
(`laser_filter`: the object's high-fidelity forces, the stations' range biases and k_R as
states), whatever its tuning parameters say:

* the stations and the object come in its ``laser`` parameter, the ``/ssa/config``
  message `ssa-fusion import crd` records with a bag (`ros.laser_config`); the object's
  forces are those of its kind (`formats.force_choice.sphere_params`);
* it starts from its ``apriori`` parameter (epoch, GCRF state in m and m/s), not from an
  IOD batch (`core.filter.tracker.Tracker.set_prior`);
* the stations' meteorological records come on ``/ssa/meteo`` (`on_meteo` hands them to the
  model).

`laser_estimator` and `start` do it; ValueError names what is missing or wrong.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from ssa_fusion.core.base.types import StateEstimate
from ssa_fusion.core.filter.tracker import Tracker
from ssa_fusion.core.gaps import estimator as est
from ssa_fusion.core.gaps.estimator import EstimatorConfig
from ssa_fusion.core.measure.laser_model import LaserModels, LaserNetwork
from ssa_fusion.formats import force_choice
from ssa_fusion.ros import messages
from ssa_fusion.ros.interfaces import Message
from ssa_fusion.ros.laser_config import recorded_laser

__all__ = ["apriori", "laser_estimator", "on_meteo", "start"]

M = 1000.0
"""m per km."""


def laser_estimator(values: Mapping[str, Any]) -> EstimatorConfig:
    """Return the laser filter of the node's parameters ``values`` (module docstring)."""
    text = str(values.get("laser", ""))
    config = recorded_laser([text]) if text else None
    if config is None:
        raise ValueError("kind laser_range needs the 'laser' parameter: the /ssa/config "
                         "message of `ssa-fusion import crd` (its stations and object)")
    objects = sorted(config.com_km)
    wanted = str(values.get("object_id", ""))
    oid = wanted or (objects[0] if len(objects) == 1 else "")
    if oid not in config.com_km:
        raise ValueError(f"'laser' describes object(s) {', '.join(objects)}: set object_id "
                         f"to one of them")
    network = LaserNetwork(config.stations, config.com_km[oid], config.bias_km,
                           config.bias_sigma_km)
    ilrs = config.meta.get("objects", {}).get(oid, {}).get("ilrs_id")
    params = force_choice.sphere_params(int(ilrs) if ilrs is not None else None)
    return est.laser_filter(network, force_choice.force_spec(params), params)


def apriori(values: Mapping[str, Any]) -> StateEstimate:
    """Return the ``apriori`` parameter as an estimate (km, km/s); ValueError if unset."""
    v = np.asarray(values.get("apriori", ()), dtype=float)
    if v.shape != (7,) or not np.any(v[1:]):
        raise ValueError("kind laser_range needs the 'apriori' parameter: the epoch and "
                         "GCRF state (m, m/s) of an a-priori orbit (ranges alone give none)")
    return StateEstimate(float(v[0]), v[1:] / M)


def start(tracker: Tracker, c: EstimatorConfig, values: Mapping[str, Any]) -> None:
    """Set the laser filter ``tracker`` of ``c`` to start from the ``apriori`` parameter."""
    tracker.set_prior(est.laser_prior(c, apriori(values)))


def on_meteo(tracker: Tracker, msg: Message) -> None:
    """Hand a Meteo message to the laser filter's model."""
    if isinstance(tracker.model, LaserModels):
        tracker.model.add_meteo([messages.meteo_from_msg(msg)])
