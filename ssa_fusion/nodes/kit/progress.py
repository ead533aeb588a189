"""Lockstep sim time: what each consumer has taken, and when the simulator may go on.

In lockstep (the default of simulated runs) sensor_sim advances ``/clock`` only once every
consumer it names has taken all it was sent, and its results are recorded; the time scale
is then a ceiling, not a promise: on a loaded machine the run is slower, never lossy, and
gives the same bag as on an idle one.

A catalog (`waiting`) steps by ``lockstep_step``: each catalog_filter shard takes every
measurement of its shard (fused, refused or dropped: nothing left waiting), the recorder
every measurement and every estimate the shards and surrogates published, counted in rows
of the batches (MeasurementBatch, EstimateBatch). It publishes the next step's measurements
only once every consumer has acted on the clock (`CLOCK`: the filters and the recorder have
it, a surrogate has stepped its bank at it), so that what a node does at a clock never races
the next step's data.

One object's graph (`object_waiting`, `ObjectSent`) steps from one scheduled epoch e to the
next, in four phases (`sim.schedule.Phase`): ``/clock`` e; then the surrogate's forecasts of
the epochs before e (`TOPIC_RELEASE_FORECASTS`: the surrogate forecasts what it missed up to
the time released), taken by the filter; then the filter's decisions of those epochs
(`TOPIC_RELEASE_DECISIONS`: its predictions or gap forecasts up to the time released), so
that a forecast for a gap epoch always reaches the filter before it decides what to publish
there; then the events at e (measurements, withheld ones, the truth). Each phase waits until
the filter, the surrogate and the recorder have taken and recorded all of the one before: a
message's log time in the bag is the clock of its phase, the same on any machine.

Each consumer publishes its counters on `TOPIC_PROGRESS` (`ProgressReporter`: a
``diagnostic_msgs/DiagnosticStatus`` named after the node, latched, sent within
`REPORT_PERIOD_S` of a change while the node has work (`SsaNode.wakeup`), or at once by
`ProgressReporter.nudge`), with its process
(`nodes.kit.liveness`); the simulator keeps the latest of each (`ProgressWatch`), of its
run only, and asks `Lockstep.go_on`. It waits as long as every consumer it waits for lives,
and gives up on one only when it is gone (`Lockstep.gone`) or when DDS dropped it, its
process silent beyond its participant lease (`Lockstep.dropped`: what was sent to it
meanwhile never reaches it; `ros.discovery.PARTICIPANT_LEASE_S` makes that lease long).
The topics are not under ``/ssa/``, so they are not in the bag (whose content must not
depend on the machine).
"""

from __future__ import annotations

import math
import time
from collections import Counter
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

from ssa_fusion.nodes.kit.diagnostics import RECORDED, Count
from ssa_fusion.nodes.kit.liveness import alive, process_keys
from ssa_fusion.nodes.kit.shards import shard_range
from ssa_fusion.ros.interfaces import DiagnosticStatus, KeyValue
from ssa_fusion.ros.qos import reliable_stream
from ssa_fusion.ros.topics import (
    TOPIC_ASSOCIATED,
    TOPIC_DETECTION_TRUTH,
    TOPIC_ESTIMATE,
    TOPIC_ESTIMATE_BATCH,
    TOPIC_FORECAST,
    TOPIC_MEASUREMENT,
    TOPIC_MEASUREMENT_BATCH,
    TOPIC_TRUTH,
    TOPIC_WITHHELD,
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
TOPIC_RELEASE_FORECASTS = "/lockstep/forecasts"
"""One object's lockstep: the surrogate may forecast the epochs it missed up to this time
(``rosgraph_msgs/Clock``)."""
TOPIC_RELEASE_DECISIONS = "/lockstep/decisions"
"""One object's lockstep: the filter may publish what it decides for the epochs up to this
time (``rosgraph_msgs/Clock``)."""
RELEASE_QOS = reliable_stream(10)
"""The releases: reliable, each one answered before the next is sent."""
LIVENESS_PERIOD_S = 1.0
"""Wall s between two looks at whether the consumers waited for still live."""
REPORT_EVERY_S = 5.0
"""Wall s between two lines saying what lockstep still waits for."""

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
TAKEN_FORECASTS = "taken forecasts"
"""One object's filter: the surrogate's forecasts it took (fused or refused)."""
PUBLISHED_ESTIMATES = "published estimates"
"""One object's filter: the estimates it published (updates, predictions, gap forecasts)."""
RELEASED = "released ns"
"""One object's surrogate: the time (ns) up to which it forecast what it missed."""
DECIDED = "decided ns"
"""One object's filter: the time (ns) up to which it decided what to publish."""
NEXT_DUE = "next due ns"
"""One object's surrogate: the first epoch (ns) it would forecast ('inf': none)."""
NEXT_DECISION = "next decision ns"
"""One object's filter: the first time (ns) it would publish a prediction at ('inf': none)."""


def time_ns(t: float) -> str:
    """Return epoch `t` (s) as a progress value: integer ns, or 'inf'."""
    return str(round(t * 1e9)) if math.isfinite(t) else "inf"


def wants(reports: Mapping[str, Mapping[str, str]], nodes: Sequence[str], key: str,
          t: float) -> bool:
    """Return True when a node of `nodes` reports `key` (`NEXT_DUE`, `NEXT_DECISION`) <= `t` s.

    A release up to `t` then gives it something to do (1 us of round-off allowed).
    """
    for name in nodes:
        value = reports.get(name, {}).get(key, "inf")
        if value.lstrip("-").isdigit() and int(value) * 1e-9 <= t + 1e-6:
            return True
    return False


OBJECT_TOPICS = (TOPIC_MEASUREMENT, TOPIC_WITHHELD, TOPIC_TRUTH)
"""What the simulator of one object publishes, besides /clock."""


class ProgressReporter:
    """Publish a node's progress counters (`counters()`: name -> value) when they change.

    With them `CLOCK`: `clock()` (ns), by default the node's clock (sim time), and the
    node's process (`nodes.kit.liveness`). Checked every `REPORT_PERIOD_S` while the node
    has work, not while it waits (`SsaNode.wakeup`: its inputs, its clock and its other work
    wake the check up); `nudge` reports at once what a message just handled changed.
    """

    def __init__(self, node: SsaNode, counters: Callable[[], Mapping[str, str | int]],
                 clock: Callable[[], int] | None = None) -> None:
        self.node = node
        self.counters = counters
        self.clock = clock or (lambda: int(node.get_clock().now().nanoseconds))
        self.pub = node.create_publisher(DiagnosticStatus, TOPIC_PROGRESS, PROGRESS_QOS)
        self._sent: dict[str, str] = {}
        self._sent_at = -math.inf
        self._process = process_keys()
        self.timer = node.wakeup(REPORT_PERIOD_S, self.report)

    def nudge(self) -> None:
        """Report now, unless a report went out within `REPORT_PERIOD_S` (then soon after).

        After each message a lockstep consumer handles: sparse progress (a lockstep phase)
        is reported at once, dense progress (a burst) at most every `REPORT_PERIOD_S`.
        """
        if time.monotonic() - self._sent_at >= REPORT_PERIOD_S:
            self.report()
        else:
            self.timer.arm()

    def report(self) -> bool:
        """Publish the counters if any changed since the last report; return whether.

        With them `CLOCK` and the process (`nodes.kit.liveness.process_keys`).
        """
        now = {k: str(v) for k, v in self.counters().items()}
        now[CLOCK] = str(self.clock())
        now.update(self._process)
        if now == self._sent:
            return False
        self._sent = now
        self._sent_at = time.monotonic()
        self.pub.publish(DiagnosticStatus(
            name=self.node.get_name(),
            values=[KeyValue(key=k, value=v) for k, v in now.items()]))
        return True


class ProgressWatch:
    """The latest progress report of each node (`reports`: node name -> counters).

    On an ssa_fusion node, of its run only (`Diagnostics.subscribe`: another run's
    consumers of the same names report too, in a shared ROS domain). `on_report` is called
    after each report taken.
    """

    def __init__(self, node: Node, on_report: Callable[[], None] | None = None) -> None:
        self.reports: dict[str, dict[str, str]] = {}
        self.on_report = on_report
        diag = getattr(node, "diag", None)
        if diag is not None:
            self._sub = diag.subscribe(DiagnosticStatus, TOPIC_PROGRESS, self._on, PROGRESS_QOS)
        else:
            self._sub = node.create_subscription(DiagnosticStatus, TOPIC_PROGRESS, self._on,
                                                 PROGRESS_QOS)

    def _on(self, msg: DiagnosticStatus) -> None:
        self.reports[msg.name] = {kv.key: kv.value for kv in msg.values}
        if self.on_report is not None:
            self.on_report()


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


@dataclass
class ObjectSent:
    """What the simulator of one object has sent: counts by topic, clock, releases (ns)."""

    published: Counter[str] = field(default_factory=Counter)
    released_forecasts_ns: int = 0
    released_decisions_ns: int = 0


def _short(report: Mapping[str, str], key: str, want: int, what: str) -> str | None:
    have = _num(report, key)
    return f"({what} {have} of {want})" if have < want else None


def object_waiting(reports: Mapping[str, Mapping[str, str]], nodes: Sequence[str],
                   sent: ObjectSent, clock_ns: int = 0) -> list[str]:
    """Return what one object's consumers have not taken yet ([] = the simulator may go on).

    The filter reports `TAKEN` (its measurements), `TAKEN_FORECASTS`, `PUBLISHED_ESTIMATES`
    and `DECIDED`; the surrogate `TAKEN`, its ``forecasts`` and `RELEASED`; the recorder
    ``recorded <topic>`` of each topic it records: every measurement, withheld one and truth
    sent, every forecast and estimate published. Each of them `CLOCK`.
    """
    mine = [reports.get(n, {}) for n in nodes]
    forecasts = sum(_num(r, Count.FORECASTS) for r in mine if RELEASED in r)
    estimates = sum(_num(r, PUBLISHED_ESTIMATES) for r in mine)
    out = []
    for name in nodes:
        r = reports.get(name)
        if r is None:
            out.append(f"{name} (no report yet)")
            continue
        shorts = [
            _short(r, CLOCK, clock_ns, "at sim time ns") if CLOCK in r else None,
            _short(r, TAKEN, sent.published[TOPIC_MEASUREMENT], "taken measurements")
            if TAKEN in r else None,
            _short(r, TAKEN_FORECASTS, forecasts, "taken forecasts")
            if TAKEN_FORECASTS in r else None,
            _short(r, RELEASED, sent.released_forecasts_ns, "forecast up to ns")
            if RELEASED in r else None,
            _short(r, DECIDED, sent.released_decisions_ns, "decided up to ns")
            if DECIDED in r else None,
            *(_short(r, RECORDED + topic, want, f"recorded {topic}")
              for topic, want in ((*((t, sent.published[t]) for t in OBJECT_TOPICS),
                                   (TOPIC_FORECAST, forecasts), (TOPIC_ESTIMATE, estimates)))
              if RECORDED + topic in r)]
        out += [f"{name} {x}" for x in shorts if x]
    return out


class Lockstep:
    """The simulator's side of lockstep: whether it may publish the next step.

    Parameters
    ----------
    node : Node
        The simulator (it subscribes to `TOPIC_PROGRESS`).
    nodes : sequence of str
        The consumers to wait for (see `waiting`, `object_waiting`), as long as they live
        (`go_on`).
    keys : ndarray of int (N,) or None
        A catalog: the ``shard_key`` of each object (what its measurements carry);
        `published` counts the measurements of each as they go out. None: one object
        (`object_waiting`, what was sent in `object`).
    on_report : callable, optional
        Called after each progress report taken (the simulator goes on at once).
    """

    def __init__(self, node: Node, nodes: Sequence[str], keys: NDArray[np.int64] | None,
                 on_report: Callable[[], None] | None = None) -> None:
        self.node = node
        self.watch = ProgressWatch(node, on_report)
        self.nodes = list(nodes)
        self.keys = keys
        self.sent = 0
        """A catalog's measurements published so far (`published`)."""
        self.object = ObjectSent()
        """What one object's simulator has sent (it sets it)."""
        self.clock_ns = 0
        """The sim time last published on /clock, ns (the simulator sets it)."""
        self.gone: list[str] = []
        """The consumers given up on: they are gone."""
        self.dropped: list[tuple[str, list[str]]] = []
        """The consumers given up on although their process lives: DDS dropped them (silent
        beyond their participant lease, `ros.discovery.PARTICIPANT_LEASE_S`), and what was
        sent to them meanwhile is lost to them; each with what it had not taken then."""
        self._listed: set[str] = set()  # the consumers the ROS graph has listed at a look
        self.since: float | None = None
        """Wall time (monotonic) the current wait began (None: not waiting)."""
        self._looked = -math.inf  # wall time (monotonic) liveness was last looked at
        self._per_object = np.zeros(0 if keys is None else len(keys), dtype=np.int64)
        self._by_shard: dict[int, tuple[int, NDArray[np.int64]]] = {}

    def published(self, objects: NDArray[np.int64]) -> None:
        """Count measurements just published, of the objects `objects` (indices in `keys`)."""
        assert self.keys is not None
        self._per_object += np.bincount(objects, minlength=len(self.keys))
        self.sent += len(objects)

    def sent_by_shard(self, shards: int) -> NDArray[np.int64]:
        """Return the measurements published so far to each of `shards` shards (shards,)."""
        n, counts = self._by_shard.get(shards, (-1, np.zeros(shards, dtype=np.int64)))
        if n != self.sent:
            assert self.keys is not None
            his = np.array([shard_range(k, shards)[1] for k in range(shards)])
            shard = np.searchsorted(his, self.keys)  # the first range ending at/after the key
            counts = np.bincount(shard, weights=self._per_object,
                                 minlength=shards).astype(np.int64)
            self._by_shard[shards] = (self.sent, counts)
        return counts

    def missing(self) -> list[str]:
        """Return what the consumers still waited for have not taken ([]: go on)."""
        if self.keys is None:
            return object_waiting(self.watch.reports, self.nodes, self.object, self.clock_ns)
        return waiting(self.watch.reports, self.nodes, self.sent, self.sent_by_shard,
                       self.clock_ns)

    def go_on(self, now: float) -> tuple[bool, list[str]]:
        """Return (whether the next step may be published, what is still awaited).

        At wall time `now` (s, monotonic). A consumer awaited that is gone (`alive`) is no
        longer waited for: it goes to `gone` (the caller says so); one that lives is waited
        for, however long, unless DDS dropped it: its process lives but the ROS graph that
        listed it no longer does (silent beyond its participant lease), and what it was sent
        meanwhile can never reach it (volatile writers); it goes to `dropped`, with what it
        had not taken (the caller names the loss).
        """
        missing = self.missing()
        if missing and now - self._looked >= LIVENESS_PERIOD_S:
            self._looked = now
            listed = {n for n, _ns in self.node.get_node_names_and_namespaces()
                      if _ns == self.node.get_namespace()}
            self._listed |= listed
            short = {n: [m for m in missing if m.startswith(f"{n} ")] for n in self.nodes}
            lost = [n for n in self.nodes if short[n]
                    and not alive(self.watch.reports.get(n), n in listed)]
            dropped = [n for n in self.nodes if short[n] and n not in lost
                       and n in self._listed and n not in listed]
            self.gone += lost
            self.dropped += [(n, short[n]) for n in dropped]
            if lost or dropped:
                self.nodes = [n for n in self.nodes if n not in lost and n not in dropped]
                missing = self.missing()
        if not missing:
            self.since = None
            return True, []
        if self.since is None:
            self.since = now
        return False, missing

    def waiting_line(self, missing: Sequence[str], now: float) -> str:
        """Return one line: since when (wall clock) and what lockstep waits for."""
        since = self.since if self.since is not None else now
        started = time.strftime("%H:%M:%S", time.localtime(time.time() - (now - since)))
        return (f"lockstep: waiting since {started} ({now - since:.0f} s) for "
                f"{', '.join(missing)}")
