"""The foxglove_bridge's parameters (docs/NODES.md, "foxglove_bridge")."""

from __future__ import annotations

from ssa_fusion.params.checks import POSITIVE, STATIONS, Check, ParamValue, at_least
from ssa_fusion.params.defaults import FOXGLOVE_BRIDGE as D
from ssa_fusion.params.rows import Param, ParameterTable
from ssa_fusion.params.shared import object_filter


def _port(value: ParamValue) -> str | None:
    ok = isinstance(value, int) and 0 <= value <= 65535
    return None if ok else "must be an integer in 0..65535 (0 = any free port)"


def _host(value: ParamValue) -> str | None:
    return None if isinstance(value, str) and value.strip() else "must be a host name or address"


def _stations(value: ParamValue) -> str | None:
    return None if value == "" else STATIONS(value)


PARAMETERS = ParameterTable("foxglove_bridge", (
    Param("host", D.host, "address the WebSocket server binds to (loopback by default)",
          check=Check("a host name or address", _host)),
    Param("port", D.port, "TCP port of the WebSocket server (0 = any free port; the log "
          "says which)", check=Check("0..65535", _port)),
    Param("station", D.station, "stations drawn in the scene ('' = none); range/az/el from "
          "them are drawn as points", check=Check(STATIONS.text + ", or ''", _stations)),
    Param("scene_period", D.scene_period, "time between scene updates", unit="wall s",
          check=POSITIVE),
    Param("trail_length", D.trail_length, "positions kept per trail", check=at_least(1)),
    Param("points", D.points, "forecast and measurement points kept in the scene",
          check=at_least(1)),
    Param("marker_size", D.marker_size, "diameter of the position markers in the scene",
          unit="km", check=POSITIVE),
    object_filter(D.object_id, "show"),
    Param("ros_topics", D.ros_topics, "also publish the scene and ground tracks as ROS "
          "messages (`/ssa/visual/*`: MarkerArray, NavSatFix), so that the recorder puts the "
          "picture in the bag"),
))
"""The foxglove_bridge's parameters."""
