"""Lockstep sim time: what each consumer has taken, and when the simulator may go on.

In lockstep (the default of simulated catalog runs) sensor_sim advances ``/clock`` by one
step only once every consumer it names has taken all it was sent: each catalog_filter shard
every measurement of its shard (fused, refused or dropped: nothing left waiting), the
recorder every measurement and every estimate the shards and surrogates published. All
count rows of the batches (MeasurementBatch, EstimateBatch), not messages. And it publishes
the next step's measurements only once every consumer has acted on that clock (`CLOCK`:
the filters and the recorder have it, a surrogate has stepped its bank at it), so that what
a node does at a clock never races the next step's data: the bag's log times, the fits and
the forecasts are the same on any machine. The time scale is then a ceiling, not a promise:
on a loaded machine the run is slower, never lossy, and gives the same bag as on an idle
one.

Each consumer publishes its counters on `TOPIC_PROGRESS` (`ProgressReporter`: a
``diagnostic_msgs/DiagnosticStatus`` named after the node, latched, sent within
`REPORT_PERIOD_S` of a change); the simulator keeps the latest of each (`ProgressWatch`) and
asks `waiting` what it still waits for. The topic is not under ``/ssa/``, so it is not in
the bag (whose content must not depend on the machine).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

from ssa_fusion.nodes.kit.diagnostics import RECORDED, Count
from ssa_fusion.nodes.kit.shards import shard_range
from ssa_fusion.ros.interfaces import DiagnosticStatus, KeyValue
from ssa_fusion.ros.topics import (
    TOPIC_ASSOCIATED,
    TOPIC_DETECTION_TRUTH,
    TOPIC_ESTIMATE_BATCH,
    TOPIC_MEASUREMENT_BATCH,
)

if TYPE_CHECKING:
    from ssa_fusion.nodes.kit.base import SsaNode

TOPIC_PROGRESS = "/lockstep"
"""Consumers' progress (``diagnostic_msgs/DiagnosticStatus``, name = node name)."""

PROGRESS_QOS = QoSProfile(
    history=HistoryPolicy.KEEP_LAST,
    depth=100,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.TRANSIENT_LOCAL,
)
"""Latched: the simulator sees each consumer's last report even if it joined later."""

REPORT_PERIOD_S = 0.005
"""Wall s between a counter's change and its report (at most)."""

TAKEN = "taken"
"""A filter shard's measurements with a final fate: fused, refused or dropped."""
TAKEN_ESTIMATES = "taken estimates"
"""A surrogate shard's filter estimates taken (used or refused)."""
TAKEN_ALL_ESTIMATES = "taken all estimates"
"""The conjunction node's estimates taken, of every filter shard (used or refused)."""
SHARD = "shard"
"""A filter or surrogate shard's place, ``k/K``."""
CLOCK = "clock ns"
"""The sim time (ns) a consumer has acted on: its clock, or what it last stepped at."""
RECORDED_MEASUREMENTS = RECORDED + TOPIC_MEASUREMENT_BATCH
"""The recorder's rows of measurement batches recorded."""
RECORDED_ESTIMATES = RECORDED + TOPIC_ESTIMATE_BATCH
"""The recorder's rows of estimate batches recorded."""
RECORDED_TRUTH = RECORDED + TOPIC_DETECTION_TRUTH
"""The recorder's rows of unlabelled detections' truth recorded (reported once it records
the topic: a run of unlabelled detections)."""
RECORDED_ASSOCIATED = RECORDED + TOPIC_ASSOCIATED
"""The recorder's rows of associated detections recorded (reported once it records the
topic)."""


class ProgressReporter:
    """Publish a node's progress counters (`counters()`: name -> value) when they change.

    With them `CLOCK`: `clock()` (ns), by default the node's clock (sim time). Checked every
    `REPORT_PERIOD_S` while the node has work, not while it waits (`SsaNode.wakeup`: its
    inputs, its clock and its other work wake the check up).
    """

    def __init__(self, node: SsaNode, counters: Callable[[], Mapping[str, str | int]],
                 clock: Callable[[], int] | None = None) -> None:
        self.node = node
        self.counters = counters
        self.clock = clock or (lambda: int(node.get_clock().now().nanoseconds))
        self.pub = node.create_publisher(DiagnosticStatus, TOPIC_PROGRESS, PROGRESS_QOS)
        self._sent: dict[str, str] = {}
        self.timer = node.wakeup(REPORT_PERIOD_S, self.report)

    def report(self) -> bool:
        """Publish the counters if any changed since the last report; return whether."""
        now = {k: str(v) for k, v in self.counters().items()}
        now[CLOCK] = str(self.clock())
        if now == self._sent:
            return False
        self._sent = now
        self.pub.publish(DiagnosticStatus(
            name=self.node.get_name(),
            values=[KeyValue(key=k, value=v) for k, v in now.items()]))
        return True


class ProgressWatch:
    """The latest progress report of each node (`reports`: node name -> counters)."""

    def __init__(self, node: Node) -> None:
        self.reports: dict[str, dict[str, str]] = {}
        self._sub = node.create_subscription(DiagnosticStatus, TOPIC_PROGRESS, self._on,
                                             PROGRESS_QOS)

    def _on(self, msg: DiagnosticStatus) -> None:
        self.reports[msg.name] = {kv.key: kv.value for kv in msg.values}


def _num(report: Mapping[str, str], key: str) -> int:
    v = report.get(key, "0")
    return int(v) if v.isdigit() else 0


def waiting(reports: Mapping[str, Mapping[str, str]], nodes: Sequence[str], sent: int,
            sent_by_shard: Callable[[int], NDArray[np.int64]], clock_ns: int = 0) -> list[str]:
    """Return what the named consumers have not taken yet ([] = the simulator may go on).

    Parameters
    ----------
    reports : mapping
        The latest progress of each node (`ProgressWatch.reports`).
    nodes : sequence of str
        The consumers to wait for: catalog_filter shards (they report `TAKEN`, `SHARD` and
        ``published_sensor``), catalog_surrogate shards (`TAKEN_ESTIMATES`, `SHARD`, the
        filter shard's estimates they wait for, and ``published_forecast``), the conjunction
        node (`TAKEN_ALL_ESTIMATES`: every filter shard's estimates) and the recorder
        (`RECORDED_MEASUREMENTS` and `RECORDED_ESTIMATES`, always both; `RECORDED_TRUTH`, as
        many as the measurements, and `RECORDED_ASSOCIATED`, the filters'
        ``published_associated``, where it reports them).
    sent : int
        Measurements published so far.
    sent_by_shard : callable
        K -> the measurements published so far to each of K shards (K,).
    clock_ns : int
        The sim time last published on /clock (ns): a consumer whose `CLOCK` is behind it
        has not acted on it yet.
    """
    out = []
    mine = [reports.get(n, {}) for n in nodes]
    published = sum(_num(r, Count.PUBLISHED_SENSOR) + _num(r, Count.PUBLISHED_FORECAST)
                    for r in mine)
    associated = sum(_num(r, Count.PUBLISHED_ASSOCIATED) for r in mine)
    estimates = {r[SHARD]: _num(r, Count.PUBLISHED_SENSOR) for r in mine if TAKEN in r}
    for name in nodes:
        r = reports.get(name)
        if r is None:
            out.append(f"{name} (no report yet)")
            continue
        if CLOCK in r and _num(r, CLOCK) < clock_ns:
            out.append(f"{name} (at sim time {_num(r, CLOCK)} ns of {clock_ns})")
        if TAKEN in r:
            k, _, shards = r[SHARD].partition("/")
            want = int(sent_by_shard(int(shards))[int(k)])
            if _num(r, TAKEN) < want:
                out.append(f"{name} (taken {_num(r, TAKEN)} of {want} measurements)")
        if TAKEN_ESTIMATES in r:
            want = estimates.get(r[SHARD], 0)
            if _num(r, TAKEN_ESTIMATES) < want:
                out.append(f"{name} (taken {_num(r, TAKEN_ESTIMATES)} of {want} estimates)")
        if TAKEN_ALL_ESTIMATES in r and _num(r, TAKEN_ALL_ESTIMATES) < sum(estimates.values()):
            out.append(f"{name} (taken {_num(r, TAKEN_ALL_ESTIMATES)} of "
                       f"{sum(estimates.values())} estimates)")
        if RECORDED_MEASUREMENTS in r or RECORDED_ESTIMATES in r:
            if _num(r, RECORDED_MEASUREMENTS) < sent:
                out.append(f"{name} (recorded {_num(r, RECORDED_MEASUREMENTS)} of {sent} "
                           "measurements)")
            if _num(r, RECORDED_ESTIMATES) < published:
                out.append(f"{name} (recorded {_num(r, RECORDED_ESTIMATES)} of {published} "
                           "estimates)")
            if RECORDED_TRUTH in r and _num(r, RECORDED_TRUTH) < sent:
                out.append(f"{name} (recorded {_num(r, RECORDED_TRUTH)} of {sent} "
                           "detections' truth)")
            if RECORDED_ASSOCIATED in r and _num(r, RECORDED_ASSOCIATED) < associated:
                out.append(f"{name} (recorded {_num(r, RECORDED_ASSOCIATED)} of {associated} "
                           "associated detections)")
    return out


class Lockstep:
    """The simulator's side of lockstep: whether it may publish the next step.

    Parameters
    ----------
    node : Node
        The simulator (it subscribes to `TOPIC_PROGRESS`).
    nodes : sequence of str
        The consumers to wait for (see `waiting`).
    keys : ndarray of int (N,)
        The ``shard_key`` of each object of the catalog (what its measurements carry);
        `published` counts the measurements of each as they go out.
    timeout_s : float
        Wall s the simulator waits for a step's consumers before it goes on without the
        late ones, for the rest of the run (a stopped or never started consumer must not
        stop the run; `go_on` reports them).
    """

    def __init__(self, node: Node, nodes: Sequence[str], keys: NDArray[np.int64],
                 timeout_s: float) -> None:
        self.watch = ProgressWatch(node)
        self.nodes = list(nodes)
        self.keys = keys
        self.timeout_s = timeout_s
        self.sent = 0
        """Measurements published so far (`published`)."""
        self.clock_ns = 0
        """The sim time last published on /clock, ns (the simulator sets it)."""
        self._per_object = np.zeros(len(keys), dtype=np.int64)
        self._by_shard: dict[int, tuple[int, NDArray[np.int64]]] = {}
        self._since: float | None = None

    def published(self, objects: NDArray[np.int64]) -> None:
        """Count measurements just published, of the objects `objects` (indices in `keys`)."""
        self._per_object += np.bincount(objects, minlength=len(self.keys))
        self.sent += len(objects)

    def sent_by_shard(self, shards: int) -> NDArray[np.int64]:
        """Return the measurements published so far to each of `shards` shards (shards,)."""
        n, counts = self._by_shard.get(shards, (-1, np.zeros(shards, dtype=np.int64)))
        if n != self.sent:
            his = np.array([shard_range(k, shards)[1] for k in range(shards)])
            shard = np.searchsorted(his, self.keys)  # the first range ending at/after the key
            counts = np.bincount(shard, weights=self._per_object,
                                 minlength=shards).astype(np.int64)
            self._by_shard[shards] = (self.sent, counts)
        return counts

    def go_on(self, now: float) -> tuple[bool, list[str]]:
        """Return (whether the next step may be published, what is still awaited).

        At wall time `now` (s, monotonic). True with a non-empty list: the consumers listed
        took longer than `timeout_s`; they are no longer waited for.
        """
        missing = waiting(self.watch.reports, self.nodes, self.sent, self.sent_by_shard,
                          self.clock_ns)
        if not missing:
            self._since = None
            return True, []
        if self._since is None:
            self._since = now
        if now - self._since > self.timeout_s:
            self._since = None
            self.nodes = [n for n in self.nodes if not any(m.startswith(f"{n} (")
                                                           for m in missing)]
            return True, missing
        return False, missing
