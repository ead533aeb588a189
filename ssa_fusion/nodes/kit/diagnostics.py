"""What a node reports on ``/diagnostics``: counts by key, status values, matched endpoints.

The keys are enums: `core.base.types.Cause` for why the core refused or set aside an input,
`NodeCause` for causes only a node meets (shards, DDS), `Count` for what a node did. Their
values are the ``/diagnostics`` keys docs/NODES.md lists; they must not change.
"""

from __future__ import annotations

import enum
import inspect
import traceback
from collections import Counter
from collections.abc import Callable
from typing import TypeVar

from rclpy.clock import Clock, ClockType
from rclpy.duration import Duration
from rclpy.event_handler import PublisherEventCallbacks, SubscriptionEventCallbacks
from rclpy.node import Node
from rclpy.publisher import Publisher
from rclpy.qos import QoSProfile
from rclpy.serialization import deserialize_message
from rclpy.subscription import Subscription
from rclpy.subscription_content_filter_options import ContentFilterOptions
from rclpy.timer import Timer

from ssa_fusion.core.base.types import Cause
from ssa_fusion.ros.interfaces import DiagnosticArray, DiagnosticStatus, KeyValue, Message, Time
from ssa_fusion.ros.readiness import MATCHED_KEY, MATCHED_READERS_KEY
from ssa_fusion.ros.run_identity import RunGate, RunMembers
from ssa_fusion.ros.topics import TOPIC_CLOCK, TOPIC_DIAGNOSTICS

T = TypeVar("T")


class NodeCause(enum.StrEnum):
    """Why a node set an input aside, where the reason is the graph's and not the core's."""

    IGNORED_OTHER_SHARD = "ignored_other_shard"
    REJECTED_SHARD_KEY = "rejected_shard_key"
    REJECTED_OBJECT_ID = "rejected_object_id"
    IGNORED_NOT_SENSOR = "ignored_not_sensor"
    CONTENT_FILTER_UNAVAILABLE = "content_filter_unavailable"
    REJECTED_UNLABELLED_SHARDED = "rejected_unlabelled_sharded"
    FOREIGN_RUN = "foreign_run"
    """A message of another run or of a stranger: its writer is not in the node's run
    (`ros.run_identity`); never used, never recorded."""
    FOREIGN_CLOCK = "foreign_clock"
    """A /clock of another run or of a stranger: the node's sim time ignores it."""


GATE_PERIOD_S = 0.1
"""Wall s between two looks at messages held until the ROS graph names their writer."""
FINAL_REPORT_WAIT_S = 1.0
"""Wall s a stopping node waits for its last /diagnostics report to be acknowledged."""


class Count(enum.StrEnum):
    """What a node did: counters that are no cause."""

    RECEIVED = "received"
    REFUSED = "refused"
    CONSUMED = "consumed"
    DROPPED = "dropped"
    BUFFERED = "buffered"
    FORECASTS = "forecasts"
    PUBLISHED = "published"
    WITHHELD = "withheld"
    PUBLISHED_PREDICTION = "published_prediction"
    PUBLISHED_SENSOR = "published_sensor"
    PUBLISHED_FORECAST = "published_forecast"
    FITS_MADE = "fits_made"
    FITS_PHYSICS = "fits_physics"
    FITS_REFUSED = "fits_refused"
    FITS_SKIPPED = "fits_skipped"
    FITS_CUT = "fits_cut"
    FORECASTS_OVERTAKEN = "forecasts_overtaken"
    TRUTH = "truth"
    ESTIMATES = "estimates"
    MEASUREMENTS = "measurements"
    SCENE_UPDATES = "scene_updates"
    LOCKSTEP_GONE = "lockstep_gone"
    LOCKSTEP_DROPPED = "lockstep_dropped"
    ELEMENT_SETS_SKIPPED = "element_sets_skipped"
    EVICTED = "evicted"
    PUBLISHED_ASSOCIATED = "published_associated"
    PUBLISHED_RELABELLED = "published_relabelled"


PUBLISHED_BY_SOURCE = (Count.PUBLISHED_PREDICTION, Count.PUBLISHED_SENSOR,
                       Count.PUBLISHED_FORECAST)
"""The counter of an estimate published, by its `UpdateSource` (NONE, SENSOR, FORECAST)."""
RECORDED = "recorded "
"""Prefix of the recorder's per-topic counters (``recorded /ssa/estimate``)."""

Key = Cause | NodeCause | Count | str
"""A counter's key (a str: a key made of a prefix and a topic)."""

REJECTIONS = frozenset(k for k in (*Cause, *NodeCause)
                       if k.name.startswith(("REJECTED_", "FOREIGN_")))
"""The keys of refused input (a stranger's included): once any is counted, the report's
level is WARN."""
INFO = frozenset({Cause.IGNORED_OTHER_OBJECT, Cause.IGNORED_BEFORE_IOD, Cause.IOD_PENDING,
                  Cause.IOD_FAILED, Cause.FORECAST_SUPERSEDED, Cause.REINITIALISED,
                  Cause.RESET_CLOCK_JUMP, Cause.HELD_UNTIL_CLOCK, Cause.PREDICTIONS_SKIPPED,
                  NodeCause.IGNORED_OTHER_SHARD})
"""Causes whose first occurrence is logged as information; every other one as a warning."""


def wall_timer(node: Node, period_s: float, callback: Callable[[], None]) -> Timer:
    """Create a timer on the steady (wall) clock.

    Sim-time timers fire once per elapsed period and so, at a high time scale, back to
    back; checks that read sim time inside the callback run on this instead.
    """
    return node.create_timer(period_s, callback, clock=Clock(clock_type=ClockType.STEADY_TIME))


class Diagnostics:
    """Count events by key, log each key once, publish them on /diagnostics.

    Each report is published every `period_s` wall seconds (sim time may stand still) and
    stamped in the graph's time base: `stamp()` when given, else the node's clock (sim time
    under use_sim_time, 0 before the first /clock). The node that drives sim time
    (sensor_sim) gives the sim time it last published.
    """

    def __init__(self, node: Node, period_s: float = 1.0,
                 stamp: Callable[[], Time] | None = None) -> None:
        self.node = node
        self._stamp = stamp or (lambda: node.get_clock().now().to_msg())
        self.counts: Counter[str] = Counter()
        self.status: dict[str, str] = {}
        self.activity = 0
        """Messages of the run received on the inputs (`subscribe`); a node drains until it
        stands."""
        self.on_input: list[Callable[[], None]] = []
        """Called after each message of the run received on an input (`subscribe`)."""
        self._logged: set[str] = set()
        self._watched: list[Subscription[Message]] = []
        self._outputs: list[Publisher[Message]] = []
        self.members = RunMembers(node)
        """Which writers are of this node's run (`ros.run_identity`)."""
        self._gates: list[RunGate] = []
        self._pub = node.create_publisher(DiagnosticArray, TOPIC_DIAGNOSTICS, QoSProfile(depth=10))
        wall_timer(node, period_s, self.publish)  # sim time may stand still (no /clock)
        if self.members.has_run:
            wall_timer(node, GATE_PERIOD_S, self.guard(self.release_held))

    def count(self, key: Key, detail: str = "", warn: bool | None = None, n: int = 1) -> None:
        """Count `n` (one) `key`; its first occurrence is logged (with `detail`).

        As a warning, or as information for the keys of `INFO` (`warn` overrides).
        """
        if n <= 0:
            return
        self.counts[key] += n
        if key in self._logged:
            return
        self._logged.add(key)
        text = f"{key}: {detail} (logged once; counted on {TOPIC_DIAGNOSTICS})"
        loud = key not in INFO if warn is None else warn
        if loud:
            self.node.get_logger().warning(text)
        else:
            self.node.get_logger().info(text)

    def subscribe(self, msg_type: type[Message], topic: str, callback: Callable[[Message], None],
                  qos: QoSProfile, raw: bool = False,
                  content_filter: ContentFilterOptions | None = None) -> Subscription[Message]:
        """Create an input subscription, its callback guarded, its matches reported.

        The matched-publisher count is reported on /diagnostics (key ``MATCHED_KEY +
        topic``), at once when it changes: a sender can then wait until this reader has
        matched it, not only until its writer has matched the reader (DDS drops what a
        writer sends before the reader's side of the match exists). A payload that does not
        decode as `msg_type` is counted (`rejected_malformed`), not lost; with `raw` the
        callback gets the bytes. `content_filter`: DDS delivers only the samples it accepts.
        Only the run's messages reach `callback` (`ros.run_identity.RunGate`): another
        run's or a stranger's are counted (`foreign_run`; on /clock `foreign_clock`).
        """
        guarded = self.guard(callback)

        def take(data: bytes) -> None:
            self.activity += 1
            for hook in self.on_input:
                hook()
            if raw:
                guarded(data)
                return
            try:
                msg = deserialize_message(data, msg_type)
            except Exception as exc:  # rclpy raises several types for bad CDR
                name = f"{msg_type.__module__.split('.')[0]}/{msg_type.__name__}"
                self.count(Cause.REJECTED_MALFORMED,
                           f"{len(data)} bytes on {topic} do not decode as {name}: {exc}")
                return
            guarded(msg)

        cause = NodeCause.FOREIGN_CLOCK if topic == TOPIC_CLOCK else NodeCause.FOREIGN_RUN
        gate = RunGate(self.members, topic, take,
                       lambda why: self.count(cause, f"{why}: ignored"))
        self._gates.append(gate)

        def arrive(data: bytes, info: object) -> None:
            gate(data, info)

        sub = self.node.create_subscription(  # a node without a run takes every writer's
            msg_type, topic, arrive if self.members.has_run else take, qos, raw=True,
            event_callbacks=SubscriptionEventCallbacks(matched=lambda _info: self.publish()),
            content_filter_options=content_filter,
        )
        self._watched.append(sub)
        return sub

    def advertise(self, msg_type: type[Message], topic: str,
                  qos: QoSProfile) -> Publisher[Message]:
        """Create an output publisher whose matched-subscriber count is reported.

        On /diagnostics (key ``MATCHED_READERS_KEY + topic``), at once when it changes: a
        sender can then wait until this writer has matched its readers (its side of the
        match), as it waits for the readers' side (`subscribe`); what the writer sends
        before its side exists never reaches them.
        """
        pub = self.node.create_publisher(
            msg_type, topic, qos,
            event_callbacks=PublisherEventCallbacks(matched=lambda _info: self.publish()))
        self._outputs.append(pub)
        return pub

    def release_held(self) -> None:
        """Hand on the messages held until the ROS graph named their writers."""
        for gate in self._gates:
            gate.release()

    @property
    def has_inputs(self) -> bool:
        """Return True when the node subscribed to an input (`subscribe`)."""
        return bool(self._watched)

    def guard(self, callback: Callable[..., T]) -> Callable[..., T | None]:
        """Wrap a subscription or timer callback: an exception is counted, not fatal.

        An unexpected exception is counted as ``internal_error`` (traceback logged once)
        instead of killing the node (the wrapper then returns None; else what `callback`
        returned). Executors may pass extra arguments (TimerInfo): only those `callback`
        takes are passed on.
        """
        n_args = len(inspect.signature(callback).parameters)

        def guarded(*args: object) -> T | None:
            try:
                return callback(*args[:n_args])
            except Exception as exc:
                self.count(
                    Cause.INTERNAL_ERROR, f"{type(exc).__name__}: {exc}\n" + traceback.format_exc()
                )
                return None

        return guarded

    def publish(self) -> None:
        """Publish the counts, status and the inputs' and outputs' matched counts now."""
        msg = DiagnosticArray()
        msg.header.stamp = self._stamp()
        st = DiagnosticStatus()
        st.name = f"{self.node.get_name()}"
        st.hardware_id = "ssa_fusion"
        rejected = sum(v for k, v in self.counts.items() if k in REJECTIONS)
        st.level = DiagnosticStatus.WARN if rejected else DiagnosticStatus.OK
        st.message = "; ".join(f"{k}={v}" for k, v in self.status.items()) or "ok"
        st.values = [KeyValue(key=str(k), value=str(v)) for k, v in sorted(self.counts.items())]
        st.values += [KeyValue(key=k, value=v) for k, v in sorted(self.status.items())]
        st.values += [KeyValue(key=MATCHED_KEY + sub.topic_name,
                               value=str(sub.get_publisher_count())) for sub in self._watched]
        st.values += [KeyValue(key=MATCHED_READERS_KEY + pub.topic_name,
                               value=str(pub.get_subscription_count())) for pub in self._outputs]
        msg.status = [st]
        self._pub.publish(msg)

    def publish_last(self, timeout_s: float = FINAL_REPORT_WAIT_S) -> None:
        """Publish the final counts; wait until every reader acknowledged them.

        At most `timeout_s` wall s: a node's last word reaches whoever sums up the run.
        """
        self.publish()
        self._pub.wait_for_all_acked(Duration(nanoseconds=int(timeout_s * 1e9)))
