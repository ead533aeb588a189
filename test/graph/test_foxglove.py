"""Graph test of foxglove_bridge: the node process serves the graph to Foxglove over its
WebSocket protocol on loopback. The test publishes estimates (one message each and as
one-row EstimateBatch messages, in turns) and truth over DDS (its own ROS domain), connects
a minimal WebSocket client (RFC 6455, Foxglove subprotocol) to the port the node reports,
and checks the advertised channels and a scene message."""

from __future__ import annotations

import base64
import json
import os
import re
import select
import socket
import struct
import time
from collections import Counter

import numpy as np
from sensor_msgs.msg import NavSatFix
from ssa_fusion_msgs.msg import EstimateBatch, StateEstimate
from visualization_msgs.msg import Marker, MarkerArray

from ssa_fusion.core.base import types
from ssa_fusion.core.base.rows import EstimateRows
from ssa_fusion.ros import bagio, messages, topics
from ssa_fusion.ros import foxglove_scene as scene
from ssa_fusion.ros.qos import CATALOG_QOS, DATA_QOS
from ssa_fusion.ros.topics import TOPIC_ESTIMATE_BATCH

SUBPROTOCOLS = ("foxglove.sdk.v1", "foxglove.websocket.v1")
T0 = 1_718_000_000.0  # Unix s


class WsClient:
    """Just enough of a WebSocket client for the Foxglove protocol: handshake, masked text
    frames out, text/binary frames in (non-blocking `poll`)."""

    def __init__(self, host: str, port: int, timeout: float) -> None:
        self.sock = socket.create_connection((host, port), timeout=timeout)
        key = base64.b64encode(os.urandom(16)).decode()
        self.sock.sendall((
            f"GET / HTTP/1.1\r\nHost: {host}:{port}\r\nUpgrade: websocket\r\n"
            f"Connection: Upgrade\r\nSec-WebSocket-Key: {key}\r\n"
            f"Sec-WebSocket-Version: 13\r\nSec-WebSocket-Protocol: {', '.join(SUBPROTOCOLS)}"
            "\r\n\r\n").encode())
        buf = b""
        while b"\r\n\r\n" not in buf:
            chunk = self.sock.recv(4096)
            assert chunk, f"connection closed during the handshake: {buf!r}"
            buf += chunk
        head, _, self.buf = buf.partition(b"\r\n\r\n")
        self.head = head.decode(errors="replace")
        assert " 101 " in self.head.splitlines()[0], self.head
        self.sock.setblocking(False)
        self.texts: list[dict] = []
        self.binaries: list[bytes] = []

    def send_text(self, obj: dict) -> None:
        data = json.dumps(obj).encode()
        mask = os.urandom(4)
        n = len(data)
        head = bytes([0x81]) + (bytes([0x80 | n]) if n < 126 else
                                bytes([0x80 | 126]) + struct.pack(">H", n))
        masked = bytes(b ^ mask[i % 4] for i, b in enumerate(data))
        self.sock.setblocking(True)
        self.sock.sendall(head + mask + masked)
        self.sock.setblocking(False)

    def poll(self) -> None:
        """Read what arrived (no wait) and parse every complete frame."""
        while select.select([self.sock], [], [], 0)[0]:
            chunk = self.sock.recv(65536)
            if not chunk:
                break
            self.buf += chunk
        while True:
            frame = self._frame()
            if frame is None:
                return
            opcode, payload = frame
            if opcode == 1:
                self.texts.append(json.loads(payload))
            elif opcode == 2:
                self.binaries.append(payload)

    def _frame(self) -> tuple[int, bytes] | None:
        b = self.buf
        if len(b) < 2:
            return None
        opcode, n, i = b[0] & 0x0F, b[1] & 0x7F, 2
        if n == 126:
            if len(b) < 4:
                return None
            n, i = struct.unpack(">H", b[2:4])[0], 4
        elif n == 127:
            if len(b) < 10:
                return None
            n, i = struct.unpack(">Q", b[2:10])[0], 10
        if len(b) < i + n:
            return None
        self.buf = b[i + n:]
        return opcode, b[i:i + n]

    def close(self) -> None:
        self.sock.close()


def _batch(msg: StateEstimate) -> EstimateBatch:
    """The one-row EstimateBatch of `msg`."""
    e = messages.estimate_from_msg(msg)
    return messages.estimate_batch_to_msg(EstimateRows(
        np.array([e.t]), [e.object_id], e.x[None], e.P[None], np.array([e.nis]),
        types.UpdateSource(e.update_source), messages.shard_keys([e.object_id])))


def _estimate(k: int, truth: bool = False) -> StateEstimate:
    r = np.array([6778.0, 0.0, 0.0]) if truth else np.array([6779.0, 1.0, 0.5])
    x = np.concatenate([r, [0.0, 7.67, 0.0]])
    p = np.zeros((6, 6)) if truth else np.diag([1.0, 4.0, 9.0, 1e-6, 1e-6, 1e-6])
    return messages.estimate_to_msg(types.StateEstimate(
        t=T0 + 30.0 * k, x=x, P=p, object_id="iss", update_source=0 if truth else 1))


def test_bridge_serves_scene_track_and_metrics_and_records_them_in_the_bag(ros_graph,
                                                                           tmp_path):
    """Over the WebSocket: the scene, the ground track and the metrics; over DDS, recorded by
    the recorder into the bag: the same scene as a MarkerArray and the ground tracks as
    NavSatFix. The fixture tears the processes down (SIGTERM, SIGKILL after a timeout)
    whatever happens, and fails the test if one did not exit 0."""
    g = ros_graph
    t_start = time.monotonic()
    client = None
    bag = tmp_path / "bag"
    markers: list[MarkerArray] = []
    fixes: list[NavSatFix] = []
    g.probe.create_subscription(MarkerArray, topics.MARKERS_TOPIC, markers.append,
                                DATA_QOS)
    g.probe.create_subscription(NavSatFix, topics.TRACK_TOPIC, fixes.append, DATA_QOS)
    try:
        rec = g.start_node("recorder", params={"bag": str(bag), "discover_period": 0.2})
        proc = g.start_node("foxglove_bridge", params={"port": 0, "station": "network",
                                                       "scene_period": 0.05})
        g.wait_for_subscriber(topics.MARKERS_TOPIC, 2)  # the probe and the recorder
        g.wait_for_subscriber(topics.TRACK_TOPIC, 2)
        g.wait_for_subscriber(topics.TRUTH_TRACK_TOPIC, 1)  # the recorder
        url = re.compile(r"ws://127\.0\.0\.1:(\d+)")
        g.wait_for(lambda: url.search(proc.stderr()) is not None or proc.returncode is not None,
                   20, "the bridge to report its WebSocket address")
        match = url.search(proc.stderr())
        assert match, g.report()
        port = int(match.group(1))
        est_pub = g.probe.create_publisher(StateEstimate, "/ssa/estimate", DATA_QOS)
        truth_pub = g.probe.create_publisher(StateEstimate, "/ssa/truth", DATA_QOS)
        batch_pub = g.probe.create_publisher(EstimateBatch, TOPIC_ESTIMATE_BATCH, CATALOG_QOS)

        client = WsClient("127.0.0.1", port, timeout=g.scaled(10))
        assert any(p in client.head for p in SUBPROTOCOLS), client.head
        wanted = set(scene.TOPICS)
        channels: dict[str, dict] = {}

        def advertised() -> bool:
            client.poll()
            for msg in client.texts:
                if msg.get("op") == "advertise":
                    channels.update({c["topic"]: c for c in msg["channels"]})
            return wanted <= set(channels)

        g.wait_for(advertised, 10, f"the server to advertise {sorted(wanted)}")
        assert channels[scene.SCENE_TOPIC]["schemaName"] == "foxglove.SceneUpdate"
        assert channels[scene.TRACK_TOPIC]["schemaName"] == "foxglove.LocationFix"
        assert channels[scene.METRICS_TOPIC]["encoding"] == "json"
        subs = {1: scene.SCENE_TOPIC, 2: scene.TRACK_TOPIC, 3: scene.METRICS_TOPIC}
        client.send_text({"op": "subscribe", "subscriptions": [
            {"id": sid, "channelId": channels[topic]["id"]} for sid, topic in subs.items()]})

        received: dict[str, list[bytes]] = {topic: [] for topic in subs.values()}
        metric_times: list[int] = []
        k = 0

        def got_all() -> bool:
            nonlocal k
            # keep publishing (new epochs) until the bridge has matched us and answered
            truth_pub.publish(_estimate(k, truth=True))
            if k % 2:  # odd epochs as a batch's row
                batch_pub.publish(_batch(_estimate(k)))
            else:
                est_pub.publish(_estimate(k))
            k += 1
            client.poll()
            for data in client.binaries:
                if data[0] == 0x01:  # message data: op, subscription id, log time, payload
                    sid, log_time = struct.unpack("<IQ", data[1:13])
                    received[subs[sid]].append(data[13:])
                    if subs[sid] == scene.METRICS_TOPIC:
                        metric_times.append(log_time)
            client.binaries.clear()
            # truth and estimate travel on two topics: an estimate can arrive before the
            # truth of its epoch (its error is then unknown, None); wait for one that did not
            errors = [json.loads(m)["position_error_km"] for m in received[scene.METRICS_TOPIC]]
            odd = {round((t * 1e-9 - T0) / 30.0) % 2 for t in metric_times}
            return (all(received.values()) and any(e is not None for e in errors)
                    and odd == {0, 1})  # estimates of both kinds of message shown

        drawn = {"earth", "truth", "estimate", "covariance", "stations"}

        def complete() -> list[MarkerArray]:
            # the scenes that draw everything: the first ones can come before any truth
            return [a for a in markers if {m.ns for m in a.markers} >= drawn]

        g.wait_for(lambda: got_all() and bool(complete()) and bool(fixes), 15,
                   "messages on the scene, ground-track and metrics channels and their ROS "
                   "topics")
        metric = json.loads(received[scene.METRICS_TOPIC][-1])
        assert metric["sigma_km"] == np.sqrt(14.0)
        assert metric["three_sigma_max_km"] == 9.0
        errors = [json.loads(m)["position_error_km"] for m in received[scene.METRICS_TOPIC]]
        assert any(e is not None and abs(e - np.sqrt(1.0 + 1.0 + 0.25)) < 1e-9
                   for e in errors), errors
        assert len(received[scene.SCENE_TOPIC][0]) > 100  # a protobuf SceneUpdate
        assert g.stop(proc) == 0, g.report()
        assert g.stop(rec) == 0, g.report()

        # the ROS topics: the estimate's marker where the estimate is, its sub-satellite point
        shown = complete()[-1]
        est = [m for m in shown.markers if m.ns == "estimate" and m.type == Marker.SPHERE]
        p = est[0].pose.position
        assert (p.x, p.y, p.z) == (6779.0, 1.0, 0.5)
        assert shown.markers[0].action == Marker.DELETEALL
        fix = fixes[-1]
        lat, lon, _ = scene.gcrs_to_geodetic([6779.0, 1.0, 0.5],
                                            fix.header.stamp.sec + fix.header.stamp.nanosec * 1e-9)
        assert abs(fix.latitude - np.degrees(lat)) < 1e-9
        assert abs(fix.longitude - np.degrees(lon)) < 1e-9
        # ... and the recorder put them in the bag, readable with their ROS types
        in_bag = Counter((m.topic, m.msgtype) for m in bagio.read_bag(bag))
        assert in_bag[(topics.MARKERS_TOPIC, "visualization_msgs/msg/MarkerArray")] > 0
        assert in_bag[(topics.TRACK_TOPIC, "sensor_msgs/msg/NavSatFix")] > 0
        assert in_bag[(topics.TRUTH_TRACK_TOPIC, "sensor_msgs/msg/NavSatFix")] > 0
    finally:
        if client is not None:
            client.close()
    assert time.monotonic() - t_start < 25 * g.timeout_factor


def test_live_foxglove_starts_the_bridge_and_says_where(ros_graph):
    """`ssa-fusion live --foxglove` starts the bridge (sim time, loopback, the filter's
    stations) before the graph and prints its ws:// address once it listens."""
    from ssa_fusion.apps import live

    said: list[str] = []
    params = {"filter": {"station": "radar_network"}}
    assert live.foxglove_parameters(params, 8765) == {
        "use_sim_time": True, "host": "127.0.0.1", "port": 8765, "station": "radar_network"}
    address = live.start_foxglove(ros_graph, params, 0, said.append)
    assert re.fullmatch(r"ws://127\.0\.0\.1:\d+", address), address
    assert address in said[0] and "config/foxglove_layout.json" in said[0]
    port = int(address.rsplit(":", 1)[1])
    client = WsClient("127.0.0.1", port, timeout=ros_graph.scaled(10))
    client.close()
