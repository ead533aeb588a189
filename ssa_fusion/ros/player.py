"""Play bag messages into a ROS graph with a `/clock` derived from their stamps.

As `ros2 bag play --clock` does: `rate` sim seconds per wall second, reliable publishers,
start only when the caller says the subscribers are there. Measurements, estimates and
meteorological records one a message, and a catalog's MeasurementBatch (stamped with its
last row's epoch, published with the catalog QoS and its recorded key range).
"""

from __future__ import annotations

import time
from collections.abc import Callable

from rclpy.clock import Clock, ClockType
from rclpy.duration import Duration
from rclpy.node import Node
from rclpy.publisher import Publisher
from rclpy.timer import Timer

from ssa_fusion.ros import bagio, messages
from ssa_fusion.ros.interfaces import Clock as ClockMsg
from ssa_fusion.ros.interfaces import Message
from ssa_fusion.ros.qos import CATALOG_WRITER_QOS, DATA_QOS, DATA_WRITER_QOS
from ssa_fusion.ros.topics import TOPIC_CLOCK


class Player:
    """Publish `stream` (bag messages with a header stamp) from `node` in stamp order."""

    def __init__(self, node: Node, stream: list[bagio.BagMessage], rate: float,
                 tick_s: float = 0.005) -> None:
        if rate <= 0:
            raise ValueError(f"rate must be > 0, got {rate}")
        self.node = node
        self.rate = rate
        self.tick_s = tick_s
        self.items = sorted(((messages.stamp_to_seconds(m.msg.header.stamp), i, m)
                             for i, m in enumerate(stream)), key=lambda r: (r[0], r[1]))
        self.classes = messages.rclpy_classes()
        self.pubs: dict[str, Publisher[Message]] = {}
        for topic in sorted({m.topic for m in stream}):
            msgtype = next(m.msgtype for m in stream if m.topic == topic)
            cls = {bagio.MEASUREMENT: self.classes.measurement,
                   bagio.STATE_ESTIMATE: self.classes.estimate,
                   bagio.MEASUREMENT_BATCH: self.classes.measurement_batch,
                   bagio.METEO: self.classes.meteo}[msgtype]
            assert cls is not None  # Meteo: rclpy's classes have it
            qos = (CATALOG_WRITER_QOS if msgtype == bagio.MEASUREMENT_BATCH
                   else DATA_WRITER_QOS)
            self.pubs[topic] = node.create_publisher(cls, topic, qos)
        self.clock_pub = node.create_publisher(ClockMsg, TOPIC_CLOCK, DATA_QOS)
        self.next = 0
        self.published = 0
        self.wall0: float | None = None
        self.timer: Timer | None = None

    @property
    def duration_s(self) -> float:
        """Return the wall s the playback takes."""
        return (self.items[-1][0] - self.items[0][0]) / self.rate if self.items else 0.0

    def subscribers_ready(self, needs: dict[str, int]) -> Callable[[], bool]:
        """Return a test: has each topic of `needs` (that is played) that many subscribers."""
        return lambda: all(self.pubs[t].get_subscription_count() >= n
                           for t, n in needs.items() if t in self.pubs)

    def start(self) -> None:
        """Start playing (a wall timer publishes what is due)."""
        self.wall0 = time.monotonic()
        self.timer = self.node.create_timer(
            self.tick_s, self.step, clock=Clock(clock_type=ClockType.STEADY_TIME))

    def step(self) -> None:
        """Publish what is due by the wall clock since the start, then the clock."""
        assert self.wall0 is not None
        t0 = self.items[0][0]
        now = t0 + (time.monotonic() - self.wall0) * self.rate
        while self.next < len(self.items) and self.items[self.next][0] <= now:
            t, _, m = self.items[self.next]
            self._clock(t)
            self.pubs[m.topic].publish(self._convert(m))
            self.next += 1
            self.published += 1
        self._clock(min(now, self.items[-1][0]))

    def _clock(self, t: float) -> None:
        """Publish sim time `t` (s) on /clock."""
        self.clock_pub.publish(ClockMsg(clock=messages.seconds_to_stamp(t, self.classes)))

    def _convert(self, m: bagio.BagMessage) -> Message:
        """Return the rclpy message of bag message `m`."""
        if m.msgtype == bagio.MEASUREMENT_BATCH:
            return messages.measurement_batch_copy(m.msg, self.classes)
        return messages.recode(m.msg, m.msgtype, self.classes)

    def done(self) -> bool:
        """Return True once everything was published."""
        return self.next >= len(self.items)

    def finish(self, ack_timeout_s: float = 5.0) -> None:
        """Stop playing; wait until the subscribers acknowledged everything published.

        Up to `ack_timeout_s` per publisher.
        """
        if self.timer is not None:
            self.node.destroy_timer(self.timer)
        for pub in (*self.pubs.values(), self.clock_pub):
            pub.wait_for_all_acked(Duration(seconds=ack_timeout_s))
