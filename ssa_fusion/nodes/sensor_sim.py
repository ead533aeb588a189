"""sensor_sim: simulate a tracked satellite and its sensors, and drive sim time.

Propagates the scenario's true orbit (two-body + J2, drag, or SGP4/SDP4), and publishes:

* ``/ssa/measurement`` (ssa_fusion_msgs/Measurement): what the sensors measured; for a
  catalog ``/ssa/measurement_batch`` (ssa_fusion_msgs/MeasurementBatch) instead: per step
  (lockstep) or tick (open loop) one batch per shard key range of `shards`;
* ``/ssa/withheld``: what they would have measured during a scheduled outage (evaluation
  only);
* ``/ssa/detection_truth``: a catalog run with `unlabelled`: the detections with their true
  object ids (evaluation only; the measurement batches carry none: `core.catalog.unlabelled`);
* ``/ssa/truth`` (ssa_fusion_msgs/StateEstimate, zero covariance): the true state;
* ``/clock``: sim time, UTC (Unix seconds), advancing `time_scale` sim s per wall s; with
  ``lockstep`` consumers (the default of ``ssa-fusion live``), only once they have taken
  all of the last step, `time_scale` being a ceiling (`nodes.kit.progress`): a catalog by
  ``lockstep_step``, one object from one scheduled epoch to the next, with the releases of
  the surrogate's forecasts and of the filter's decisions between (``/lockstep/forecasts``,
  ``/lockstep/decisions``). Lockstep waits for a consumer as long as it lives, saying every
  5 s what it waits for and since when; one that is gone is named and no longer waited for
  (``lockstep_gone``), and so is one whose process lives but that DDS dropped (silent beyond
  its participant lease), with the rows it lost (``lockstep_dropped``).

What it publishes when is the simulated world's (`sim.schedule`: a paper scenario's one
idealised sensor at every epoch of its cadence, a real-sky scenario's stations above their
masks, a catalog's radars; the epochs due in the open loop or in lockstep); this node
publishes it over ROS. It exits 0 when the schedule is done. It is the one node that uses
the simulated world (`ssa_fusion.sim`).

    ros2 run ssa_fusion sensor_sim --ros-args -p scenario:=iss_j2_rae -p time_scale:=500.0
"""

from __future__ import annotations

import math
import resource
import time

import numpy as np
from rclpy.duration import Duration

from ssa_fusion.core.base import types
from ssa_fusion.core.catalog.unlabelled import without_labels
from ssa_fusion.core.earth import timescales
from ssa_fusion.nodes.kit.base import SsaNode
from ssa_fusion.nodes.kit.diagnostics import Count
from ssa_fusion.nodes.kit.node_parameters import NodeParameters
from ssa_fusion.nodes.kit.process import finish
from ssa_fusion.nodes.kit.progress import (
    NEXT_DECISION,
    NEXT_DUE,
    RELEASE_QOS,
    REPORT_EVERY_S,
    TOPIC_RELEASE_DECISIONS,
    TOPIC_RELEASE_FORECASTS,
    Lockstep,
    wants,
)
from ssa_fusion.nodes.kit.shards import shard_range
from ssa_fusion.params.rows import ParameterError
from ssa_fusion.params.tables.sensor_sim import PARAMETERS
from ssa_fusion.ros import messages
from ssa_fusion.ros.interfaces import Clock, MeasurementBatch, Time
from ssa_fusion.ros.interfaces import Measurement as MeasurementMsg
from ssa_fusion.ros.interfaces import StateEstimate as StateEstimateMsg
from ssa_fusion.ros.qos import CATALOG_WRITER_QOS, DATA_QOS, DATA_WRITER_QOS
from ssa_fusion.ros.readiness import ReadyNodes
from ssa_fusion.ros.topics import (
    TOPIC_CLOCK,
    TOPIC_DETECTION_TRUTH,
    TOPIC_MEASUREMENT,
    TOPIC_MEASUREMENT_BATCH,
    TOPIC_TRUTH,
    TOPIC_WITHHELD,
)
from ssa_fusion.sim.schedule import (
    CatalogPace,
    Event,
    ObjectStep,
    Pace,
    Phase,
    Plan,
    ScheduleError,
    SimSettings,
    plan,
    resolve,
)
from ssa_fusion.sim.survey import Observations


def plan_of(p: NodeParameters) -> Plan:
    """Return the run sensor_sim's parameters in effect `p` give (`sim.schedule.plan`).

    The noise is converted to the core's units of the scenario's measurements here (the
    messages' scale); a setting that gives no run is a `ParameterError`.
    """
    name = p.text("scenario")
    base, real_sky = resolve(name, p.text("sites"), p.text("elements"))  # valid: their checks
    noise = p.numbers("noise_sigma")
    settings = SimSettings(
        object_id=p.text("object_id"), cadence=p.number("cadence"),
        duration=p.number("duration"),
        start=timescales.parse_utc(p.text("start")) if p.text("start") else None,
        gap_start=p.number("gap_start"), gap_length=p.number("gap_length"),
        gaps=tuple(p.numbers("gaps")), after_gap=p.number("after_gap"),
        noise_sigma=tuple(v / s for v, s in zip(noise, messages.z_scale(base.kind), strict=True))
        if len(noise) == 3 else None,
        seed=p.integer("seed"), truth=p.text("truth"), geometry_seed=p.integer("geometry_seed"),
        catalog=p.text("catalog"), objects=p.integer("objects"),
        synthetic=p.integer("synthetic"))
    try:
        return plan(name, base, real_sky, settings)
    except ScheduleError as exc:
        raise ParameterError(str(exc)) from exc


class SensorSim(SsaNode):
    """The simulator node: a schedule of what the sensors measure, published in sim time."""

    PARAMETERS = PARAMETERS

    def __init__(self) -> None:
        super().__init__()
        self.sim_stamp = Time()  # the sim time last published on /clock (0: none yet)
        p = self.params
        run = plan_of(p)
        self.schedule, self.catalog, self.times = run.schedule, run.catalog, run.times
        self.lockstep_on = self.catalog is not None and any(p.texts("lockstep"))
        step = p.number("lockstep_step")
        self.pace: Pace | CatalogPace = Pace(self.times, step) if self.catalog is None else \
            CatalogPace(self.catalog, step if self.lockstep_on else math.inf)
        self.catalog_keys = (messages.shard_keys(list(self.catalog.object_ids))
                             if self.catalog is not None else None)
        self.time_scale = p.number("time_scale")
        self.wait_for = p.texts("wait_for")
        self.wait_for_readers = [x for x in p.texts("wait_for_readers") if x]
        self.readers = ReadyNodes(self)
        self.shards = p.integer("shards")
        self.unlabelled = p.flag("unlabelled")
        self._advertise()
        self.finished = False
        self._next_wait_log = time.monotonic() + 5.0  # quiet while discovery runs
        self.wall0: float | None = None
        self.lockstep = self._lockstep()
        self.create_timer(p.number("tick"), self.step)
        self.get_logger().info(f"{p.text('scenario')}: {run.summary}, "
                               f"time scale {self.time_scale}x")
        if self.catalog is not None and self.catalog.skipped.count:
            skipped = self.catalog.skipped
            self.diag.count(Count.ELEMENT_SETS_SKIPPED, skipped.lines[0], n=skipped.count)
            for line in skipped.lines[1:]:
                self.get_logger().warning(line)

    def _advertise(self) -> None:
        """Create the publishers (the detections' truth only for unlabelled detections)."""
        self.pub_clock = self.create_publisher(Clock, TOPIC_CLOCK, DATA_QOS)
        self.pub_meas = self.create_publisher(MeasurementMsg, TOPIC_MEASUREMENT, DATA_WRITER_QOS)
        self.pub_batch = self.create_publisher(MeasurementBatch, TOPIC_MEASUREMENT_BATCH,
                                               CATALOG_WRITER_QOS)
        self.pub_withheld = self.create_publisher(MeasurementMsg, TOPIC_WITHHELD, DATA_WRITER_QOS)
        self.pub_truth = self.create_publisher(StateEstimateMsg, TOPIC_TRUTH, DATA_WRITER_QOS)
        self.pub_detection_truth = self.create_publisher(
            MeasurementBatch, TOPIC_DETECTION_TRUTH, CATALOG_WRITER_QOS
        ) if self.unlabelled else None
        self.pub_release = {
            Phase.FORECASTS: self.create_publisher(Clock, TOPIC_RELEASE_FORECASTS, RELEASE_QOS),
            Phase.DECISIONS: self.create_publisher(Clock, TOPIC_RELEASE_DECISIONS, RELEASE_QOS)}

    def _lockstep(self) -> Lockstep | None:
        """Return the lockstep of the ``lockstep`` consumers, or None: open loop."""
        p = self.params
        names = [n for n in p.texts("lockstep") if n]
        if not names:
            return None
        if self.catalog_keys is None:
            return Lockstep(self, names, None, self.diag.guard(self.step))
        keys = self.catalog_keys.astype(np.int64)
        if self.unlabelled:  # what the batches carry: key 0
            keys = np.zeros_like(keys)
        return Lockstep(self, names, keys, self.diag.guard(self.step))

    def diagnostics_stamp(self) -> Time:
        """Return the sim time last published on /clock: sim time, like the other nodes'."""
        return self.sim_stamp

    def waiting_for(self) -> list[str]:
        """Return what start-up still waits for.

        '/topic=count' entries whose subscriber count is short (matched by this node's own
        publishers where it publishes the topic), then 'node:[>]/topic' entries not reported
        as matched on /diagnostics.
        """
        own = {p.topic_name: p for p in (self.pub_clock, self.pub_meas, self.pub_withheld,
                                         self.pub_truth, self.pub_batch,
                                         self.pub_detection_truth) if p is not None}
        short = []
        for item in self.wait_for:
            if not item:
                continue
            topic, _, count = item.partition("=")
            have = (own[topic].get_subscription_count() if topic in own
                    else self.count_subscribers(topic))
            if have < int(count):
                short.append(f"{item} (has {have})")
        return short + self.readers.unmatched(self.wait_for_readers)

    def ready(self) -> bool:
        """Return True once nothing is awaited (log what is, every 5 s)."""
        missing = self.waiting_for()
        if missing and time.monotonic() >= self._next_wait_log:
            self._next_wait_log = time.monotonic() + 5.0
            self.get_logger().info(f"waiting for: {', '.join(missing)}")
        return not missing

    def step(self) -> None:
        """Publish what is due by the wall clock since the start (once ready)."""
        if self.finished:
            return
        if self.wall0 is None:
            if not self.ready():
                return
            self.wall0 = time.monotonic()
            waited = any(self.wait_for) or bool(self.wait_for_readers)
            self.get_logger().info("subscribers matched; starting" if waited
                                   else "starting (no subscribers awaited: wait_for is empty)")
        times = self.times
        now = times[0] + (time.monotonic() - self.wall0) * self.time_scale
        if self.lockstep is not None:
            if self.awaited(self.lockstep):
                return
            if self.catalog is not None:
                self.step_lockstep(now)
            else:
                self.step_object(now)
            return
        if isinstance(self.pace, CatalogPace):  # one clock per tick, ahead of its measurements
            self.publish_clock(min(now, times[-1]))
            self.publish_catalog(self.pace.due(now))
        else:
            for i in self.pace.due(now):
                self.publish_event(i)
        self.publish_clock(min(now, times[-1]))
        if self.pace.done:
            self.done()

    def awaited(self, lockstep: Lockstep) -> bool:
        """Return True while the consumers have not taken all of the last step.

        Says every `REPORT_EVERY_S` wall s what is awaited and since when; names a consumer
        that is gone (counted ``lockstep_gone``), which is no longer waited for, and one that
        DDS dropped with what it lost (``lockstep_dropped``: one line each).
        """
        now = time.monotonic()
        go, missing = lockstep.go_on(now)
        while lockstep.gone:
            name = lockstep.gone.pop()
            self.diag.count(Count.LOCKSTEP_GONE, f"lockstep: {name} is gone (its process ended "
                            "or it left the ROS graph); sim time goes on without it")
            self.get_logger().error(f"lockstep: {name} is gone; no longer waited for")
        while lockstep.dropped:
            name, short = lockstep.dropped.pop()
            self.diag.counts[Count.LOCKSTEP_DROPPED] += 1
            self.get_logger().error(
                f"lockstep: {name} lost what was sent to it while DDS had dropped it (its "
                f"process silent beyond its participant lease: stopped?): "
                f"{'; '.join(m.removeprefix(f'{name} ').strip('()') for m in short)}; "
                f"no longer waited for ({Count.LOCKSTEP_DROPPED})")
        if not go and now >= self._next_wait_log:
            self._next_wait_log = now + REPORT_EVERY_S
            self.get_logger().info(lockstep.waiting_line(missing, now))
        elif go:
            self._next_wait_log = now + REPORT_EVERY_S
        return not go

    def step_object(self, ceiling: float) -> None:
        """Publish one object's next lockstep phase (time scale: `ceiling`), or end the run.

        Called once the consumers took all of the phase before (`sim.schedule.Phase`): a
        release only a consumer has something for (its `NEXT_DUE`, `NEXT_DECISION`), the
        epoch's clock, its events.
        """
        lockstep, pace = self.lockstep, self.pace
        assert lockstep is not None and isinstance(pace, Pace)
        reports, nodes = lockstep.watch.reports, lockstep.nodes
        step = pace.object_step(ceiling, lambda phase, t: wants(
            reports, nodes, NEXT_DUE if phase == Phase.FORECASTS else NEXT_DECISION, t))
        if step is None:
            if pace.object_done:
                self.done()
            return
        if step.phase == Phase.CLOCK:
            self.publish_clock(step.t)
            lockstep.clock_ns = self.sim_stamp.sec * 1_000_000_000 + self.sim_stamp.nanosec
        elif step.phase == Phase.EVENTS:
            for i in step.events:
                lockstep.object.published[self.publish_content(i)] += 1
        else:
            self.release(step)

    def release(self, step: ObjectStep) -> None:
        """Publish the release of `step` (forecasts or decisions up to its time)."""
        assert self.lockstep is not None
        stamp = messages.seconds_to_stamp(step.t)
        ns = stamp.sec * 1_000_000_000 + stamp.nanosec
        if step.phase == Phase.FORECASTS:
            self.lockstep.object.released_forecasts_ns = ns
        else:
            self.lockstep.object.released_decisions_ns = ns
        self.pub_release[step.phase].publish(Clock(clock=stamp))

    def step_lockstep(self, ceiling: float) -> None:
        """Publish the next step once the consumers took the last (time scale: `ceiling`).

        A step's measurements (epochs in (T - lockstep_step, T]) go first, ahead of the
        clock; once every consumer took them (and the estimates they gave), `/clock` moves
        to T: whatever a consumer does at T (a surrogate releasing a gap's forecasts) sees
        everything before T. The next step's measurements wait until every consumer has
        acted on T (`progress.CLOCK`), so nothing after T is seen at T.
        """
        lockstep, pace = self.lockstep, self.pace
        assert lockstep is not None and isinstance(pace, CatalogPace)
        if self.sim_stamp.sec == 0 or pace.clock_behind:
            # the last step's measurements are all taken: now its clock (the first: t0);
            # the next step's go once every consumer has acted on it
            self.publish_clock(min(pace.sim_now, float(self.times[-1])))
            pace.clock_behind = False
            lockstep.clock_ns = self.sim_stamp.sec * 1_000_000_000 + self.sim_stamp.nanosec
            return
        if pace.done:
            self.done()
            return
        due = pace.step(ceiling)
        if due is None:
            return
        self.publish_catalog(due)

    def publish_clock(self, t: float) -> None:
        """Publish sim time `t` (s) on /clock."""
        msg = Clock()
        msg.clock = messages.seconds_to_stamp(t)
        self.pub_clock.publish(msg)
        self.sim_stamp = msg.clock

    def publish_event(self, i: int) -> None:
        """Publish scheduled event `i` (after the clock of its epoch)."""
        self.publish_clock(self.schedule[i][0])
        self.publish_content(i)

    def publish_content(self, i: int) -> str:
        """Publish scheduled event `i`'s message; return its topic."""
        _t, what, content = self.schedule[i]
        if what == Event.TRUTH:
            assert isinstance(content, types.StateEstimate)
            self.pub_truth.publish(messages.estimate_to_msg(content))
            return TOPIC_TRUTH
        assert isinstance(content, types.Measurement)
        if what == Event.WITHHELD:
            self.pub_withheld.publish(messages.measurement_to_msg(content))
            self.diag.counts[Count.WITHHELD] += 1
            return TOPIC_WITHHELD
        self.pub_meas.publish(messages.measurement_to_msg(content))
        self.diag.counts[Count.PUBLISHED] += 1
        return TOPIC_MEASUREMENT

    def publish_catalog(self, due: Observations) -> None:
        """Publish catalog measurements `due` (a window of the stream) in batches per shard.

        Their epochs are at or before the clock published (open loop), or at most one
        `lockstep_step` after it (lockstep). A range with no measurement gets no batch; one
        with more than ``batch_rows`` gets several, in epoch order. With `unlabelled`, each
        batch goes without its object ids, and with them on ``/ssa/detection_truth``.
        """
        if self.catalog is None or self.catalog_keys is None or not len(due):
            return
        rows = self.catalog.rows(due, self.catalog_keys)
        ranges = [shard_range(k, self.shards) for k in range(self.shards)]
        shard = np.searchsorted(np.array([hi for _, hi in ranges]), rows.shard_key)
        most = self.params.integer("batch_rows")
        for k in np.unique(shard).tolist():  # per shard, rows in epoch order, in batches
            mine = np.flatnonzero(shard == k)
            for part in np.array_split(mine, -(-mine.size // most)):
                batch = rows.take(part)
                if self.pub_detection_truth is not None:
                    self.pub_detection_truth.publish(
                        messages.measurement_batch_to_msg(batch, ranges[k]))
                    batch = without_labels(batch)
                self.pub_batch.publish(messages.measurement_batch_to_msg(batch, ranges[k]))
        if not self.diag.counts[Count.PUBLISHED]:
            self.get_logger().info("first measurements published")
        self.diag.counts[Count.PUBLISHED] += len(due)
        if self.lockstep is not None:
            self.lockstep.published(due.obj)

    def close(self) -> None:
        """Stop the catalog's window thread (a node stopped before its schedule is done)."""
        if isinstance(self.pace, CatalogPace):
            self.pace.close()
        super().close()

    def done(self) -> None:
        """End the run: wait for the readers' acknowledgements, report, exit 0."""
        self.finished = True
        if isinstance(self.pace, CatalogPace):
            self.pace.close()
        for pub in (self.pub_meas, self.pub_batch, self.pub_withheld, self.pub_truth,
                    self.pub_clock, self.pub_detection_truth):
            if pub is not None:
                pub.wait_for_all_acked(Duration(seconds=5.0))
        self.diag.publish_last()
        use = resource.getrusage(resource.RUSAGE_SELF)
        self.get_logger().info(
            f"schedule done: {self.diag.counts[Count.PUBLISHED]} measurements, "
            f"{self.diag.counts[Count.WITHHELD]} withheld; CPU "
            f"{use.ru_utime + use.ru_stime:.1f} s, peak RSS {use.ru_maxrss / 1024:.0f} MiB"
        )
        finish()


def main(args: list[str] | None = None) -> int:
    """Run the simulator node (``ros2 run ssa_fusion sensor_sim``)."""
    return SensorSim.main(args)


if __name__ == "__main__":
    raise SystemExit(main())
