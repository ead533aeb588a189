"""foxglove_bridge: serve the graph live to Foxglove over its WebSocket protocol (foxglove-sdk).

Subscribes to ``/ssa/truth``, ``/ssa/estimate``, ``/ssa/measurement`` and ``/ssa/forecast``,
and to a catalog's ``/ssa/measurement_batch`` and ``/ssa/estimate_batch``, whose rows it takes
as the Measurement and StateEstimate messages they mean (`bagio.batch_records`), and serves,
on a WebSocket server bound to `host`:`port` (loopback by default):

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

from collections import Counter
from collections.abc import Callable
from functools import partial
from typing import Any

import numpy as np
from rclpy.publisher import Publisher

from ssa_fusion.core.base.types import Cause, Source
from ssa_fusion.core.earth.stations import network_stations
from ssa_fusion.nodes.kit.base import SsaNode
from ssa_fusion.nodes.kit.diagnostics import Count
from ssa_fusion.params.rows import ParameterError
from ssa_fusion.params.tables.foxglove_bridge import PARAMETERS
from ssa_fusion.ros import bagio, messages, topics, visual_msgs
from ssa_fusion.ros import foxglove_scene as scene
from ssa_fusion.ros.interfaces import (
    EstimateBatch,
    MarkerArray,
    MeasurementBatch,
    Message,
    NavSatFix,
)
from ssa_fusion.ros.interfaces import Measurement as MeasurementMsg
from ssa_fusion.ros.interfaces import StateEstimate as StateEstimateMsg
from ssa_fusion.ros.qos import CATALOG_QOS, DATA_QOS, DATA_WRITER_QOS
from ssa_fusion.ros.topics import (
    TOPIC_ESTIMATE,
    TOPIC_ESTIMATE_BATCH,
    TOPIC_FORECAST,
    TOPIC_MEASUREMENT,
    TOPIC_MEASUREMENT_BATCH,
    TOPIC_TRUTH,
)


class FoxgloveBridgeNode(SsaNode):
    """The Foxglove bridge node: graph topics in, `VisualTopics`, a WebSocket server out."""

    PARAMETERS = PARAMETERS

    def __init__(self) -> None:
        super().__init__()
        p = self.params
        host, port, station = p.text("host"), p.integer("port"), p.text("station")
        self.object_id = p.text("object_id")
        self.visual = scene.VisualTopics(network_stations(station) if station else {},
                                         trail=p.integer("trail_length"),
                                         points=p.integer("points"),
                                         marker_km=p.number("marker_size"))

        import foxglove  # the WebSocket server, only in this node
        from foxglove.channels import LocationFixChannel, SceneUpdateChannel

        try:
            self.server = foxglove.start_server(name="ssa_fusion", host=host, port=port)
        except Exception as exc:  # address in use, unknown host, ...
            raise ParameterError(f"parameter 'port' = {port!r} (host {host!r}): cannot serve "
                                 f"there: {exc}") from exc
        self.channels: dict[str, Any] = {  # foxglove channels of several message types
            scene.SCENE_TOPIC: SceneUpdateChannel(scene.SCENE_TOPIC),
            scene.TRACK_TOPIC: LocationFixChannel(scene.TRACK_TOPIC),
            scene.TRUTH_TRACK_TOPIC: LocationFixChannel(scene.TRUTH_TRACK_TOPIC),
            scene.METRICS_TOPIC: foxglove.Channel(scene.METRICS_TOPIC,
                                                  schema=scene.METRICS_SCHEMA),
        }
        self.port = int(self.server.port)
        self.diag.status["url"] = f"ws://{host}:{self.port}"
        self.get_logger().info(f"Foxglove WebSocket server on ws://{host}:{self.port}")

        self.ros_pubs: dict[str, Publisher[Message]] = {}
        if p.flag("ros_topics"):
            self.ros_pubs = {
                topics.MARKERS_TOPIC: self.create_publisher(
                    MarkerArray, topics.MARKERS_TOPIC, DATA_WRITER_QOS),
                **{topic: self.create_publisher(NavSatFix, topic, DATA_WRITER_QOS)
                   for topic in (topics.TRACK_TOPIC, topics.TRUTH_TRACK_TOPIC)},
            }

        subs: tuple[tuple[type[MeasurementMsg], str, Callable[[MeasurementMsg], None]], ...] = (
            (StateEstimateMsg, TOPIC_TRUTH, self.on_truth),
            (StateEstimateMsg, TOPIC_ESTIMATE, self.on_estimate),
            (MeasurementMsg, TOPIC_MEASUREMENT, self.on_measurement),
            (MeasurementMsg, TOPIC_FORECAST, self.on_measurement))
        for msg_type, topic, callback in subs:
            self.subscribe(msg_type, topic, callback, DATA_QOS)
        for batch_type, topic, msgtype in (
                (MeasurementBatch, TOPIC_MEASUREMENT_BATCH, bagio.MEASUREMENT_BATCH),
                (EstimateBatch, TOPIC_ESTIMATE_BATCH, bagio.ESTIMATE_BATCH)):
            self.subscribe(batch_type, topic, partial(self.on_batch, topic, msgtype),
                           CATALOG_QOS)
        self.wall_timer(p.number("scene_period"), self.publish_scene)

    def _ours(self, object_id: str) -> bool:
        """Return True when `object_id` is shown (else count it)."""
        if self.object_id and object_id != self.object_id:
            self.diag.count(Cause.IGNORED_OTHER_OBJECT, f"object_id {object_id!r}")
            return False
        return True

    def _log(self, logged: list[scene.Logged]) -> None:
        """Log `logged` on their Foxglove channels."""
        for item in logged:
            self.channels[item.topic].log(item.message, log_time=item.log_time)

    def _show(self, make: Callable[[], object], counter: Count) -> bool:
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
        """Show a true state (and its ground track)."""
        if not self._ours(msg.object_id):
            return
        e = messages.estimate_from_msg(msg)
        if self._show(lambda: self.visual.truth(e.t, e.x), Count.TRUTH):
            self._publish_fix(topics.TRUTH_TRACK_TOPIC, e.t, e.x, "truth")

    def on_estimate(self, msg: StateEstimateMsg) -> None:
        """Show an estimate (and its ground track)."""
        if not self._ours(msg.object_id):
            return
        e = messages.estimate_from_msg(msg)
        if self._show(lambda: self.visual.estimate(e.t, e.x, e.P, e.update_source, e.nis),
                      Count.ESTIMATES):  # the ground track only of what the scene shows
            self._publish_fix(topics.TRACK_TOPIC, e.t, e.x, "estimate")

    def _publish_fix(self, topic: str, t: float, x: np.ndarray, frame_id: str) -> None:
        """Publish the ground-track NavSatFix of a state the scene showed."""
        pub = self.ros_pubs.get(topic)
        if pub is not None:
            pub.publish(visual_msgs.nav_sat_fix(t, x, frame_id))

    def on_measurement(self, msg: MeasurementMsg) -> None:
        """Show the point a measurement or forecast implies."""
        if not self._ours(msg.object_id):
            return
        m = self.measurement_of(msg)
        if m is None:
            return
        forecast = m.source == Source.FORECAST
        self._show(lambda: self.visual.measurement(m.kind, m.z, m.frame_id, m.t, forecast),
                   Count.FORECASTS if forecast else Count.MEASUREMENTS)

    def on_batch(self, topic: str, msgtype: str, msg: Message) -> None:
        """Show the rows of a MeasurementBatch or EstimateBatch, each as its message would be.

        Rows no reader takes (`bagio.read_records`) are counted by cause.
        """
        refused: Counter[tuple[str, str]] = Counter()
        rows = bagio.batch_records(bagio.BagMessage(topic, msgtype, 0, msg), refused)
        for (_, cause), n in refused.items():
            self.diag.count(cause, f"{topic}: {bagio.REFUSED_WHY.get(cause, cause)}", n=n)
        show = self.on_measurement if msgtype == bagio.MEASUREMENT_BATCH else self.on_estimate
        for row in rows:
            show(row.msg)

    def publish_scene(self) -> None:
        """Log the scene, stamped with the newest epoch heard.

        When something changed since the last one and a truth or estimate was heard.
        """
        if not self.visual.scene_due:
            return
        logged = self.visual.scene()
        self._log([logged])
        pub = self.ros_pubs.get(topics.MARKERS_TOPIC)
        if pub is not None:
            pub.publish(visual_msgs.marker_array(self.visual.shapes, self.visual.state.t or 0.0))
        self.diag.counts[Count.SCENE_UPDATES] += 1

    def close(self) -> None:
        """Stop the WebSocket server."""
        server = getattr(self, "server", None)
        if server is not None:
            server.stop()


def main(args: list[str] | None = None) -> int:
    """Run the Foxglove bridge node (``ros2 run ssa_fusion foxglove_bridge``)."""
    return FoxgloveBridgeNode.main(args)


if __name__ == "__main__":
    raise SystemExit(main())
