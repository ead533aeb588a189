"""recorder: write every /ssa/* topic and /clock to a rosbag2 (MCAP, version 9) bag.

Raw subscriptions hand over the CDR bytes as they arrived; they are written unchanged with
`rosbags`, stamped with the node's ROS time at reception (sim time under use_sim_time), as
`ros2 bag record` does. Under sim time, what arrives before the first /clock (typically the
latched /ssa/config) is held and stamped with the clock's first time, so the bag does not
start at time 0, 55 years before its data (which `ros2 bag play` would wait through).
Topics are discovered as publishers appear. The pending MCAP chunk is flushed to disk every
`flush_period` s, which bounds what a SIGKILL can lose; SIGINT or SIGTERM close the bag with
everything received.

    ros2 run ssa_fusion recorder --ros-args -p bag:=bags/run1
"""

from __future__ import annotations

import importlib
import time
from pathlib import Path

from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

from ssa_fusion.core.types import Cause
from ssa_fusion.nodes import start_process
from ssa_fusion.nodes.common import (
    Diagnostics,
    ParameterError,
    declare,
    positive,
    run,
    wall_timer,
)
from ssa_fusion.nodes.defaults import BAG_PATTERN, RECORDER
from ssa_fusion.ros.bagio import BagWriter, qos_from_rclpy
from ssa_fusion.ros.topics import DATA_DEPTH

HOLD_LIMIT = 10_000
"""Most messages held until sim time starts (beyond, they are written stamped 0)."""


def _import_type(type_name: str):
    pkg, _, name = type_name.split("/")
    return getattr(importlib.import_module(f"{pkg}.msg"), name)


class Recorder(Node):
    def __init__(self) -> None:
        super().__init__("recorder")
        default_bag = RECORDER.bag or time.strftime(BAG_PATTERN)
        bag = declare(
            self,
            "bag",
            default_bag,
            "output bag directory (must not exist)",
            lambda v: None if v else "must be a directory path",
        )
        self.topics = set(
            declare(
                self,
                "topics",
                list(RECORDER.topics),
                "topics recorded besides every topic under prefix",
            )
        )
        self.prefix = declare(
            self, "prefix", RECORDER.prefix, "record every topic whose name starts with this"
        )
        flush = declare(
            self,
            "flush_period",
            RECORDER.flush_period,
            "s of wall time between flushes of the bag to disk",
            positive,
        )
        discover = declare(
            self,
            "discover_period",
            RECORDER.discover_period,
            "s between topic discovery scans",
            positive,
        )
        if Path(bag).exists():
            raise ParameterError(f"parameter 'bag' = {bag!r}: exists already, not overwriting")
        try:
            self.writer = BagWriter(bag)
        except Exception as exc:  # rosbags raises several types for a path it cannot use
            raise ParameterError(f"parameter 'bag' = {bag!r}: cannot create the bag there: "
                                 f"{exc}") from exc
        self.diag = Diagnostics(self)
        self._subs = {}
        self.activity = 0
        wall_timer(self, discover, self.diag.guard(self.discover))
        self._held: list[tuple[str, bytes]] = []  # received before sim time started
        wall_timer(self, flush, self.flush)
        self.get_logger().info(f"recording to {bag}")
        self.discover()

    def wanted(self, topic: str) -> bool:
        return topic in self.topics or topic.startswith(self.prefix)

    def discover(self) -> None:
        """Subscribe to wanted topics that gained a publisher since the last scan."""
        for topic, types in self.get_topic_names_and_types():
            if topic in self._subs or not self.wanted(topic):
                continue
            pubs = self.get_publishers_info_by_topic(topic)
            if not pubs:
                continue
            type_name = types[0]
            try:
                msg_class = _import_type(type_name)
                self.writer.add_topic(
                    topic, type_name, [qos_from_rclpy(p.qos_profile) for p in pubs]
                )
            except Exception as exc:  # an unknown type must not stop the others
                self.diag.count(Cause.UNRECORDABLE_TOPIC, f"{topic} ({type_name}): {exc}")
                self._subs[topic] = None
                continue
            # as rosbag2 adapts: reliable / transient local only if every publisher offers it
            # (a latched topic, /ssa/config, is then received although published before)
            reliable = all(p.qos_profile.reliability == ReliabilityPolicy.RELIABLE for p in pubs)
            latched = all(p.qos_profile.durability == DurabilityPolicy.TRANSIENT_LOCAL
                          for p in pubs)
            qos = QoSProfile(
                history=HistoryPolicy.KEEP_LAST,
                depth=DATA_DEPTH,
                reliability=ReliabilityPolicy.RELIABLE
                if reliable
                else ReliabilityPolicy.BEST_EFFORT,
                durability=DurabilityPolicy.TRANSIENT_LOCAL
                if latched
                else DurabilityPolicy.VOLATILE,
            )
            self._subs[topic] = self.diag.subscribe(
                msg_class, topic, lambda data, t=topic: self.on_message(t, data), qos, raw=True
            )
            self.get_logger().info(f"recording {topic} [{type_name}]")

    def on_message(self, topic: str, data: bytes) -> None:
        now = self.get_clock().now().nanoseconds
        self.activity += 1
        self.diag.counts[f"recorded {topic}"] += 1
        if now == 0 and len(self._held) < HOLD_LIMIT:  # sim time has not started yet
            self._held.append((topic, data))
            return
        self._release(now)
        self.writer.write(topic, now, data)

    def _release(self, now: int) -> None:
        """Write what was held until sim time started, stamped `now` (ns)."""
        for topic, data in self._held:
            self.writer.write(topic, now, data)
        self._held.clear()

    def flush(self) -> None:
        now = self.get_clock().now().nanoseconds
        if now and self._held:
            self._release(now)
        self.writer.flush()

    def close(self) -> None:
        self._release(self.get_clock().now().nanoseconds)  # a graph whose clock never ran: 0
        self.writer.close()
        total = sum(self.writer.counts.values())
        self.get_logger().info(f"bag closed: {self.writer.path} ({total} messages)")


def main(args: list[str] | None = None) -> int:
    start_process()
    return run(Recorder, args)


if __name__ == "__main__":
    raise SystemExit(main())
