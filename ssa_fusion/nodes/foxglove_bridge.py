"""foxglove_bridge: serve the graph live to Foxglove over its WebSocket protocol (foxglove-sdk).

Subscribes to ``/ssa/truth``, ``/ssa/estimate``, ``/ssa/measurement`` and ``/ssa/forecast``
and serves, on a WebSocket server bound to `host`:`port` (loopback by default):

* ``/ssa/foxglove/scene`` (`foxglove.SceneUpdate`, every `scene_period` wall s): the Earth,
  true and estimated positions with their recent trails, the 3σ ellipsoid of the estimate's
  position covariance, the stations of `station`, the points forecasts and range/az/el (or
  position) measurements imply; frame ``eci``, one scene unit = 1 km
  (`ssa_fusion.ros.foxglove_scene`);
* ``/ssa/foxglove/ground_track`` and ``/ssa/foxglove/ground_track_truth``
  (`foxglove.LocationFix`, per estimate / truth): geodetic latitude/longitude (deg);
* ``/ssa/foxglove/metrics`` (JSON, per estimate): position error against the truth of the
  same epoch (km), σ (km), largest 3σ semi-axis (km), NIS, update source.

The messages come from `foxglove_scene.VisualTopics`, which `ssa-fusion report` also uses to
write the same topics of a bag to ``visual.mcap`` (`ssa_fusion.apps.visual_mcap`).

With ``ros_topics`` (default true) it also publishes the scene and the ground tracks as ROS
messages that the recorder puts in the bag (`ssa_fusion.ros.visual_msgs`):
``/ssa/visual/markers`` (`visualization_msgs/MarkerArray`), ``/ssa/visual/ground_track`` and
``/ssa/visual/ground_track_truth`` (`sensor_msgs/NavSatFix`).

Message log times are the messages' sim-time stamps. ``config/foxglove_layout.json`` is a
Foxglove layout of these topics (3D, Map, Plot).

    ros2 run ssa_fusion foxglove_bridge --ros-args -p use_sim_time:=true -p port:=8765
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from rclpy.node import Node
from ssa_fusion_msgs.msg import Measurement as MeasurementMsg
from ssa_fusion_msgs.msg import StateEstimate as StateEstimateMsg

from ssa_fusion.core.types import Source
from ssa_fusion.nodes import start_process
from ssa_fusion.nodes.common import (
    Diagnostics,
    ParameterError,
    declare,
    positive,
    run,
    wall_timer,
)
from ssa_fusion.nodes.defaults import STATION
from ssa_fusion.ros import foxglove_scene as scene
from ssa_fusion.ros import messages, visual_msgs
from ssa_fusion.ros.topics import (
    DATA_QOS,
    TOPIC_ESTIMATE,
    TOPIC_FORECAST,
    TOPIC_MEASUREMENT,
    TOPIC_TRUTH,
)

DEFAULT_HOST = "127.0.0.1"
"""Loopback: nothing is served beyond this machine unless `host` says so."""
DEFAULT_PORT = 8765
"""Foxglove's usual WebSocket port."""


def _port(value: Any) -> str | None:
    ok = isinstance(value, int) and 0 <= value <= 65535
    return None if ok else "must be an integer in 0..65535 (0 = any free port)"


def _host(value: Any) -> str | None:
    return None if isinstance(value, str) and value.strip() else "must be a host name or address"


def _count(value: Any) -> str | None:
    return None if isinstance(value, int) and value >= 1 else "must be an integer >= 1"


def _station(value: Any) -> str | None:
    if value == "":
        return None
    from ssa_fusion.core.stations import network_stations

    try:
        network_stations(value)
    except ValueError as exc:
        return str(exc)
    return None


class FoxgloveBridgeNode(Node):
    def __init__(self) -> None:
        super().__init__("foxglove_bridge")
        from ssa_fusion.core.stations import network_stations

        host = declare(self, "host", DEFAULT_HOST,
                       "address the Foxglove WebSocket server binds to (loopback by default)",
                       _host)
        port = declare(self, "port", DEFAULT_PORT,
                       "TCP port of the Foxglove WebSocket server (0 = any free port)", _port)
        station = declare(self, "station", STATION,
                          "stations drawn in the scene: a station id, a network id, or ids "
                          "separated by commas ('' = none); range/az/el from them are drawn "
                          "as points", _station)
        period = declare(self, "scene_period", 0.2,
                         "wall s between scene updates", positive)
        trail = declare(self, "trail_length", 600,
                        "positions kept in the truth and estimate trails", _count)
        points = declare(self, "points", 300,
                         "forecast and measurement points kept in the scene", _count)
        marker_km = float(declare(self, "marker_size", 150.0,
                                  "diameter of the position markers in the scene, km",
                                  positive))
        self.object_id = declare(self, "object_id", "", "only show this object ('' = any)")
        ros_topics = declare(self, "ros_topics", True,
                             "also publish the scene and ground tracks as ROS messages "
                             "(/ssa/visual/*: MarkerArray, NavSatFix), so the recorder puts "
                             "them in the bag")
        self.visual = scene.VisualTopics(network_stations(station) if station else {},
                                         trail=int(trail), points=int(points),
                                         marker_km=marker_km)
        self.diag = Diagnostics(self)
        self.activity = 0

        import foxglove
        from foxglove.channels import LocationFixChannel, SceneUpdateChannel

        try:
            self.server = foxglove.start_server(name="ssa_fusion", host=host, port=int(port))
        except Exception as exc:  # address in use, unknown host, ...
            raise ParameterError(f"parameter 'port' = {port!r} (host {host!r}): cannot serve "
                                 f"there: {exc}") from exc
        self.channels: dict[str, Any] = {
            scene.SCENE_TOPIC: SceneUpdateChannel(scene.SCENE_TOPIC),
            scene.TRACK_TOPIC: LocationFixChannel(scene.TRACK_TOPIC),
            scene.TRUTH_TRACK_TOPIC: LocationFixChannel(scene.TRUTH_TRACK_TOPIC),
            scene.METRICS_TOPIC: foxglove.Channel(scene.METRICS_TOPIC,
                                                  schema=scene.METRICS_SCHEMA),
        }
        self.port = int(self.server.port)
        self.diag.status["url"] = f"ws://{host}:{self.port}"
        self.get_logger().info(f"Foxglove WebSocket server on ws://{host}:{self.port}")

        self.ros_pubs: dict[str, Any] = {}
        if ros_topics:
            from sensor_msgs.msg import NavSatFix
            from visualization_msgs.msg import MarkerArray

            self.ros_pubs = {
                visual_msgs.MARKERS_TOPIC: self.create_publisher(
                    MarkerArray, visual_msgs.MARKERS_TOPIC, DATA_QOS),
                **{topic: self.create_publisher(NavSatFix, topic, DATA_QOS)
                   for topic in (visual_msgs.TRACK_TOPIC, visual_msgs.TRUTH_TRACK_TOPIC)},
            }

        subs = ((StateEstimateMsg, TOPIC_TRUTH, self.on_truth),
                (StateEstimateMsg, TOPIC_ESTIMATE, self.on_estimate),
                (MeasurementMsg, TOPIC_MEASUREMENT, self.on_measurement),
                (MeasurementMsg, TOPIC_FORECAST, self.on_measurement))
        for msg_type, topic, callback in subs:
            self.diag.subscribe(msg_type, topic, self.diag.guard(callback), DATA_QOS)
        wall_timer(self, float(period), self.diag.guard(self.publish_scene))

    def _ours(self, object_id: str) -> bool:
        if self.object_id and object_id != self.object_id:
            self.diag.count("ignored_other_object", f"object_id {object_id!r}", warn=False)
            return False
        return True

    def _log(self, logged: list[scene.Logged]) -> None:
        for item in logged:
            self.channels[item.topic].log(item.message, log_time=item.log_time)

    def _show(self, make: Callable[[], object], counter: str) -> bool:
        """Run `make` (a `VisualTopics` call); count `counter`, or why it was not shown."""
        try:
            made = make()
        except scene.NotShownError as exc:
            self.diag.count(exc.key, exc.detail, warn=exc.warn)
            return False
        if isinstance(made, list):
            self._log(made)
        self.diag.counts[counter] += 1
        return True

    def on_truth(self, msg: StateEstimateMsg) -> None:
        self.activity += 1
        if not self._ours(msg.object_id):
            return
        e = messages.estimate_from_msg(msg)
        if self._show(lambda: self.visual.truth(e.t, e.x), "truth"):
            self._publish_fix(visual_msgs.TRUTH_TRACK_TOPIC, e.t, e.x, "truth")

    def on_estimate(self, msg: StateEstimateMsg) -> None:
        self.activity += 1
        if not self._ours(msg.object_id):
            return
        e = messages.estimate_from_msg(msg)
        if self._show(lambda: self.visual.estimate(e.t, e.x, e.P, e.update_source, e.nis),
                      "estimates"):  # the ground track only of what the scene shows
            self._publish_fix(visual_msgs.TRACK_TOPIC, e.t, e.x, "estimate")

    def _publish_fix(self, topic: str, t: float, x: Any, frame_id: str) -> None:
        """Publish the ground-track NavSatFix of a state the scene showed."""
        pub = self.ros_pubs.get(topic)
        if pub is not None:
            pub.publish(visual_msgs.nav_sat_fix(t, x, frame_id))

    def on_measurement(self, msg: MeasurementMsg) -> None:
        self.activity += 1
        if not self._ours(msg.object_id):
            return
        try:
            m = messages.measurement_from_msg(msg)
        except ValueError as exc:
            self.diag.count("rejected_kind", str(exc))
            return
        forecast = m.source == Source.FORECAST
        self._show(lambda: self.visual.measurement(m.kind, m.z, m.frame_id, m.t, forecast),
                   "forecasts" if forecast else "measurements")

    def publish_scene(self) -> None:
        """Log the scene (when something changed since the last one and a truth or estimate
        was heard), stamped with the newest epoch heard."""
        if not self.visual.scene_due:
            return
        logged = self.visual.scene()
        self._log([logged])
        pub = self.ros_pubs.get(visual_msgs.MARKERS_TOPIC)
        if pub is not None:
            pub.publish(visual_msgs.marker_array(self.visual.shapes, self.visual.state.t or 0.0))
        self.diag.counts["scene_updates"] += 1

    def close(self) -> None:
        server = getattr(self, "server", None)
        if server is not None:
            server.stop()


def main(args: list[str] | None = None) -> int:
    start_process()
    return run(FoxgloveBridgeNode, args)


if __name__ == "__main__":
    raise SystemExit(main())
