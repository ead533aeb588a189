"""What a laser-ranging bag records on ``/ssa/config``: its stations, objects and biases.

`ssa-fusion import crd` writes one latched ``std_msgs/String`` on ``/ssa/config`` whose
JSON says everything its LASER_RANGE measurements need besides their own messages and the
meteorological data (``/ssa/meteo``): ``{"node": "import_crd", "laser_ranging": ...}`` with

* ``stations``: by station id (the measurements' frame_id), the marker's ITRF position
  (``position_m``) at ``reference_epoch`` (Unix s, UTC), its velocity (``velocity_m_s``),
  the eccentricity (``eccentricity_une_m``: up, north, east), the laser's wavelength
  (``wavelength_m``), the prior of its range bias (``range_bias_m``, ``range_bias_sigma_m``:
  a parameter to estimate), its name, and where each came from; ``frame`` says ``itrf``;
* ``objects``: by object id, the centre-of-mass offset (``com_offset_m``), name, ILRS id;
* what the ranges are and how the model treats them (``range``, ``troposphere``,
  ``meteo_fallback``), and the reference orbit's file, if any.

SI units, as every message (`messages`); `LaserConfig` holds the same in the core's (km,
km/s, `laser_station.LaserStation`). `laser_config_message` writes it; `recorded_laser`
reads it back from a bag's ``/ssa/config`` texts. No rclpy here.
"""

from __future__ import annotations

import json
from collections.abc import Iterable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ssa_fusion.core.earth.frames import Frame
from ssa_fusion.core.measure.laser_station import LaserStation

NODE = "import_crd"
"""The ``node`` of the message (not a node's: no estimator settings in it)."""
KM = 1000.0
"""m per km."""
RANGE = "c x two-way time of flight / 2, at the transmit epoch (the message stamp)"
TROPOSPHERE = "mendes_pavlis"
METEO_FALLBACK = "standard_atmosphere"


@dataclass
class LaserConfig:
    """The laser-ranging set-up of a bag, in the core's units (module docstring).

    `stations` by id; `com_km` the centre-of-mass offset by object id (km); `bias_km` and
    `bias_sigma_km` each station's range-bias prior (km); `meta` the rest as recorded (names,
    sources, the reference orbit's file), SI.
    """

    stations: dict[str, LaserStation] = field(default_factory=dict)
    com_km: dict[str, float] = field(default_factory=dict)
    bias_km: dict[str, float] = field(default_factory=dict)
    bias_sigma_km: dict[str, float] = field(default_factory=dict)
    meta: dict[str, Any] = field(default_factory=dict)


def _vector(v: Iterable[float]) -> list[float]:
    return [float(x) for x in v]


def laser_config_message(c: LaserConfig) -> str:
    """Return the JSON of `c` for ``/ssa/config`` (SI; module docstring)."""
    stations = {}
    for sid, s in c.stations.items():
        stations[sid] = {
            "name": s.name, "frame": Frame.ITRF,
            "position_m": _vector(np.asarray(s.position_km) * KM),
            "velocity_m_s": _vector(np.asarray(s.velocity_km_s) * KM),
            "reference_epoch": float(s.t_ref),
            "eccentricity_une_m": _vector(np.asarray(s.eccentricity_une_km) * KM),
            "wavelength_m": float(s.wavelength_um) * 1e-6,
            "range_bias_m": c.bias_km.get(sid, 0.0) * KM,
            "range_bias_sigma_m": c.bias_sigma_km.get(sid, 0.0) * KM,
            **c.meta.get("stations", {}).get(sid, {})}
    objects = {oid: {"com_offset_m": com * KM, **c.meta.get("objects", {}).get(oid, {})}
               for oid, com in c.com_km.items()}
    body = {"stations": stations, "objects": objects, "range": RANGE,
            "troposphere": TROPOSPHERE, "meteo_fallback": METEO_FALLBACK,
            **{k: v for k, v in c.meta.items() if k not in ("stations", "objects")}}
    return json.dumps({"node": NODE, "laser_ranging": body}, sort_keys=True)


def recorded_laser(texts: Iterable[str]) -> LaserConfig | None:
    """Return the `LaserConfig` of a bag's ``/ssa/config`` texts (the last one), or None.

    ValueError on a malformed message of this node.
    """
    found = None
    for text in texts:
        try:
            msg = json.loads(text)
        except ValueError as exc:
            raise ValueError(f"malformed /ssa/config message {text[:80]!r}: {exc}") from exc
        if isinstance(msg, dict) and msg.get("node") == NODE:
            found = msg
    if found is None:
        return None
    try:
        return _from_json(found["laser_ranging"])
    except (KeyError, TypeError, ValueError) as exc:
        raise ValueError(f"malformed {NODE} /ssa/config message: {exc!r}") from exc


def _from_json(body: dict[str, Any]) -> LaserConfig:
    """Return the `LaserConfig` of a message's ``laser_ranging`` part."""
    c = LaserConfig()
    for sid, s in body["stations"].items():
        if s["frame"] != Frame.ITRF:
            raise ValueError(f"station {sid}: frame {s['frame']!r}, not {Frame.ITRF!r}")
        c.stations[sid] = LaserStation(
            sid, np.asarray(s["position_m"], float) / KM,
            np.asarray(s["velocity_m_s"], float) / KM, float(s["reference_epoch"]),
            np.asarray(s["eccentricity_une_m"], float) / KM,
            float(s["wavelength_m"]) * 1e6, str(s["name"]))
        c.bias_km[sid] = float(s["range_bias_m"]) / KM
        c.bias_sigma_km[sid] = float(s["range_bias_sigma_m"]) / KM
    c.meta = {k: v for k, v in body.items() if k not in ("stations", "objects")}
    for oid, o in body["objects"].items():
        c.com_km[oid] = float(o["com_offset_m"]) / KM
        c.meta.setdefault("objects", {})[oid] = {k: v for k, v in o.items()
                                                 if k != "com_offset_m"}
    return c
