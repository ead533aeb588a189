"""recorder: write every /ssa/* topic and /clock to a rosbag2 (MCAP, version 9) bag.

Raw subscriptions hand over the CDR bytes as they arrived; they are written unchanged with
`rosbags`, stamped with the node's ROS time at reception (sim time under use_sim_time), as
`ros2 bag record` does. Under sim time, what arrives before the first /clock (typically the
latched /ssa/config) is held and stamped with the clock's first time, so the bag does not
start at time 0, 55 years before its data (which `ros2 bag play` would wait through). Topics
are discovered as publishers appear (a scan every `discover_period` s, spaced out up to
`DISCOVER_BACKOFF` times that while scans find nothing new). The counts ``recorded <topic>``
on /diagnostics are messages, and rows for the batch types (MeasurementBatch, EstimateBatch:
what a catalog run's accounting counts). The pending MCAP chunk is flushed to disk every
`flush_period` s, which bounds what a SIGKILL can lose; SIGINT or SIGTERM close the bag with
everything received. A disk too full for the next message and the bag's closing records
(`bagio.BagWriter`) closes the bag whole, with every message before, and ends the node with
one line naming the bag and the reason, exit code 1; any other write error leaves what was
flushed before readable (`ssa-fusion bag repair`).

It records its run only (`ros.run_identity`): what another run or a stranger publishes on a
recorded topic is counted (`foreign_run`, `foreign_clock`) and never written, and the bag
names its run once, on ``/ssa/run``. Under sim time ``/clock`` is written from the node's own
clock subscription, after the clock is set: a clock's log time is its own time.

    ros2 run ssa_fusion recorder --ros-args -p bag:=bags/run1
"""

from __future__ import annotations

import importlib
import json
from collections.abc import Callable
from functools import partial

from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.serialization import deserialize_message, serialize_message

from ssa_fusion.core.base.types import Cause
from ssa_fusion.nodes.kit.base import SsaNode
from ssa_fusion.nodes.kit.diagnostics import RECORDED
from ssa_fusion.nodes.kit.process import EXIT_FAILED, finish
from ssa_fusion.nodes.kit.progress import (
    OBJECT_TOPICS,
    RECORDED_ASSOCIATED,
    RECORDED_ESTIMATES,
    RECORDED_MEASUREMENTS,
    RECORDED_TRUTH,
    ProgressReporter,
)
from ssa_fusion.params.rows import ParameterError
from ssa_fusion.params.tables.recorder import PARAMETERS
from ssa_fusion.ros.bagio import LATCHED_QOS, BagFullError, BagWriter, qos_from_rclpy
from ssa_fusion.ros.interfaces import Message, String
from ssa_fusion.ros.run_identity import run_of
from ssa_fusion.ros.topics import (
    DATA_DEPTH,
    TOPIC_CLOCK,
    TOPIC_ESTIMATE,
    TOPIC_FORECAST,
    TOPIC_RUN,
)

HOLD_LIMIT = 10_000
"""Most messages held until sim time starts (beyond, they are written stamped 0)."""
DISCOVER_BACKOFF = 8
"""The most `discover_period`s between two scans for new topics while none appears (a
publisher that appears is then seen within 0.8 s by default; a scan asks DDS for the whole
graph)."""


def _import_type(type_name: str) -> type[Message]:
    """Return the message class of a ROS type name (``pkg/msg/Name``)."""
    pkg, _, name = type_name.split("/")
    cls: type[Message] = getattr(importlib.import_module(f"{pkg}.msg"), name)
    return cls


BATCH_TYPES = ("ssa_fusion_msgs/msg/MeasurementBatch", "ssa_fusion_msgs/msg/EstimateBatch")
"""Types whose messages are counted in rows (one per ``object_id``)."""


def _one(_data: bytes) -> int:
    return 1


def row_counter(type_name: str, msg_class: type[Message]) -> Callable[[bytes], int]:
    """Return what one message of `type_name` (CDR bytes) counts: its rows for a batch, else 1.

    A batch whose bytes do not decode counts as no row (and is recorded as it came).
    """
    if type_name not in BATCH_TYPES:
        return _one

    def rows(data: bytes) -> int:
        try:
            return len(deserialize_message(data, msg_class).object_id)
        except Exception:  # rclpy raises several types on malformed bytes
            return 0

    return rows


class Recorder(SsaNode):
    """The recorder node: raw subscriptions to every topic wanted, into a `BagWriter`."""

    PARAMETERS = PARAMETERS

    def __init__(self) -> None:
        super().__init__()
        p = self.params
        bag = p.text("bag")
        self.topics = set(p.texts("topics"))
        self.prefix = p.text("prefix")
        try:
            self.writer = BagWriter(bag)
        except Exception as exc:  # rosbags raises several types for a path it cannot use
            raise ParameterError(f"parameter 'bag' = {bag!r}: cannot create the bag there: "
                                 f"{exc}") from exc
        self._subs: dict[str, object] = {}
        self._held: list[tuple[str, bytes]] = []  # received before sim time started
        self._rows: dict[str, Callable[[bytes], int]] = {}  # topic -> what a message counts
        self.failed: OSError | None = None  # why the bag cannot be written (then: exit 1)
        self._scan_every, self._since_scan = 1, 0  # discovery backs off while nothing is new
        self.wall_timer(p.number("discover_period"), self.discover_now_and_then)
        self.wall_timer(p.number("flush_period"), self.flush)
        self.progress = ProgressReporter(self, self.recorded)
        self.run_clock.listen(self.on_clock)
        self._name_run()
        self.get_logger().info(f"recording to {bag}")
        self.discover()

    def _name_run(self) -> None:
        """Hold the bag's ``/ssa/run`` message (written at the first clock), in a run."""
        run = run_of(self.get_namespace())
        if run is None:
            return
        self.writer.add_topic(TOPIC_RUN, "std_msgs/msg/String", [LATCHED_QOS])
        text = json.dumps({"run": run, "namespace": self.get_namespace()})
        self._held.append((TOPIC_RUN, serialize_message(String(data=text))))
        self.diag.counts[RECORDED + TOPIC_RUN] += 1

    def on_clock(self, data: bytes, _t_ns: int) -> None:
        """Write a /clock of the run (taken by the node's clock), once its topic is recorded."""
        if self._subs.get(TOPIC_CLOCK) is self.run_clock:
            self.on_message(TOPIC_CLOCK, data)
        else:
            self.progress.nudge()

    def recorded(self) -> dict[str, int]:
        """Return the lockstep progress: what it recorded (`nodes.kit.progress`).

        A catalog's batches' rows of measurements and estimates always; the unlabelled
        detections' truth and the associated detections once their topic is recorded; one
        object's messages of each of its topics recorded.
        """
        keys = [RECORDED_MEASUREMENTS, RECORDED_ESTIMATES,
                *(k for k in (RECORDED_TRUTH, RECORDED_ASSOCIATED)
                  if k.removeprefix(RECORDED) in self._subs),
                *(RECORDED + t for t in (*OBJECT_TOPICS, TOPIC_FORECAST, TOPIC_ESTIMATE)
                  if t in self._subs)]
        return {k: self.diag.counts[k] for k in keys}

    def wanted(self, topic: str) -> bool:
        """Return True when `topic` is to be recorded."""
        return topic in self.topics or topic.startswith(self.prefix)

    def discover_now_and_then(self) -> None:
        """Scan for new topics (`discover`), every tick at first, rarer while none is new.

        Every `_scan_every` ticks: doubled after a scan that found nothing (up to
        `DISCOVER_BACKOFF`), back to every tick after one that found a topic.
        """
        self._since_scan += 1
        if self._since_scan < self._scan_every:
            return
        self._since_scan = 0
        found = self.discover()
        self._scan_every = 1 if found else min(2 * self._scan_every, DISCOVER_BACKOFF)

    def discover(self) -> int:
        """Subscribe to wanted topics that gained a publisher since the last scan; how many."""
        before = len(self._subs)
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
            if topic == TOPIC_CLOCK and self.run_clock.active:  # the node's clock writes it
                self._subs[topic] = self.run_clock
                self._rows[topic] = _one
                self.get_logger().info(f"recording {topic} [{type_name}] (the run's clock)")
                continue
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
            self._rows[topic] = row_counter(type_name, msg_class)
            self._subs[topic] = self.subscribe(
                msg_class, topic, partial(self.on_message, topic), qos, raw=True)
            self.get_logger().info(f"recording {topic} [{type_name}]")
        return len(self._subs) - before

    def on_message(self, topic: str, data: bytes) -> None:
        """Write one message of `topic` (its CDR bytes), stamped with the node's clock.

        Once the bag cannot be written (`_cannot_write`), messages are counted as
        ``unrecorded_bag_failed``, never silently lost.
        """
        if self.failed is not None:
            self.diag.count(Cause.UNRECORDED_BAG_FAILED, f"the bag cannot be written: "
                                                         f"{self.failed}")
            return
        now = self.get_clock().now().nanoseconds
        n = self._rows.get(topic, _one)(data)
        if now == 0 and len(self._held) < HOLD_LIMIT:  # sim time has not started yet
            self._held.append((topic, data))
            self.diag.counts[RECORDED + topic] += n
            return
        try:
            self._release(now)
            self.writer.write(topic, now, data)
        except OSError as exc:
            self._cannot_write(exc)
            self.diag.count(Cause.UNRECORDED_BAG_FAILED, str(exc))
            return
        self.diag.counts[RECORDED + topic] += n
        self.progress.nudge()

    def _cannot_write(self, exc: OSError) -> None:
        """Say once why the bag cannot be written (a full disk), and end the node (exit 1).

        What was flushed before stays readable; ``ssa-fusion bag repair`` makes it a whole
        bag.
        """
        if self.failed is not None:
            return
        self.failed = exc
        if isinstance(exc, BagFullError):  # nothing of the message written: close the bag whole
            try:
                self.writer.close()
            except OSError as late:
                exc = late
            else:
                total = sum(self.writer.counts.values())
                self.get_logger().error(
                    f"cannot write the bag {self.writer.path}: {exc.strerror}; the bag is "
                    f"closed, whole, with the {total} messages before; stopping")
                finish(EXIT_FAILED)
                return
        self.get_logger().error(
            f"cannot write the bag {self.writer.path}: {exc.strerror or exc} "
            f"({exc.filename or self.writer.path}); it holds what was flushed before "
            f"(`ssa-fusion bag repair {self.writer.path}` makes it a whole bag); stopping")
        finish(EXIT_FAILED)

    def _release(self, now: int) -> None:
        """Write what was held until sim time started, stamped `now` (ns)."""
        for topic, data in self._held:
            self.writer.write(topic, now, data)
        self._held.clear()

    def flush(self) -> None:
        """Write what was held once sim time runs; push the pending chunk to disk."""
        if self.failed is not None:
            return
        now = self.get_clock().now().nanoseconds
        try:
            if now and self._held:
                self._release(now)
            self.writer.flush()
        except OSError as exc:
            self._cannot_write(exc)

    def close(self) -> None:
        """Close the bag with everything received (or say how to repair it)."""
        try:
            if self.failed is None:
                self._release(self.get_clock().now().nanoseconds)  # no clock ran: stamp 0
            self.writer.close()
        except OSError as exc:
            self.get_logger().error(
                f"bag {self.writer.path} not closed: {exc.strerror or exc}; `ssa-fusion bag "
                f"repair {self.writer.path}` recovers what was flushed")
            return
        total = sum(self.writer.counts.values())
        self.get_logger().info(f"bag closed: {self.writer.path} ({total} messages)")


def main(args: list[str] | None = None) -> int:
    """Run the recorder node (``ros2 run ssa_fusion recorder``)."""
    return Recorder.main(args)


if __name__ == "__main__":
    raise SystemExit(main())
