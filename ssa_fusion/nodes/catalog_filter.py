r"""catalog_filter: IOD + EKF of every object of a catalog in one process, batched.

Subscribes to ``/ssa/measurement`` (range/az/el of any object from the stations of
`station`), collects what arrives, and every `batch_period` wall s fuses it all at once in a
`core.track_bank.TrackBank` (one track per ``object_id``, vectorised over objects). Publishes
``/ssa/estimate`` (``object_id`` set, update source SENSOR) for every fused measurement and
for every track an IOD starts. Rejected input is counted by cause on ``/diagnostics``;
``consumed`` counts every measurement the bank took (fused, pending in an IOD batch, or
rejected by it), so that published = consumed + refused at the door.

Sharding: with ``shards`` = K > 1 the node owns the objects whose
``Measurement.shard_key`` (CRC-32 of ``object_id``) lies in the ``shard``-th of K equal
ranges, and subscribes with a DDS content filter (``shard_key BETWEEN lo AND hi``): the
other shards' measurements never reach it. K processes with shard 0..K-1 cover every object
exactly once, on one host or several in one ROS domain.

    ros2 run ssa_fusion catalog_filter --ros-args -p use_sim_time:=true \
        -p station:=radar_network -p shards:=2 -p shard:=0 -r __node:=catalog_filter_0
"""

from __future__ import annotations

from functools import partial

import numpy as np

from ssa_fusion.core.site_file import load_station_map
from ssa_fusion.core.stations import network_stations
from ssa_fusion.core.track_bank import TrackBank
from ssa_fusion.core.types import Cause, Kind, Measurement, Source, StateEstimate, UpdateSource
from ssa_fusion.core.validation import id_problem, measurement_problem
from ssa_fusion.nodes import settings
from ssa_fusion.nodes.base import SsaNode
from ssa_fusion.nodes.defaults import CATALOG_FILTER
from ssa_fusion.nodes.diagnostics import Count, NodeCause
from ssa_fusion.nodes.parameters import (
    POSITIVE,
    STATION_IDS,
    STATION_RULE_NAMES,
    Param,
    ParameterTable,
    Rule,
    clock_lead,
    filter_rows,
    sites_problem,
    sites_row,
)
from ssa_fusion.nodes.progress import SHARD, TAKEN, ProgressReporter
from ssa_fusion.nodes.shards import (
    LIST_OBJECTS,
    SHARD_RULE,
    content_filter,
    max_objects_row,
    shard_problem,
    shard_range,
    shard_rows,
)
from ssa_fusion.ros import messages
from ssa_fusion.ros.interfaces import Measurement as MeasurementMsg
from ssa_fusion.ros.interfaces import StateEstimate as StateEstimateMsg
from ssa_fusion.ros.topics import (
    CATALOG_DEPTH,
    CATALOG_QOS,
    TOPIC_ESTIMATE,
    TOPIC_MEASUREMENT,
)

PARAMETERS = ParameterTable("catalog_filter", (
    Param("station", CATALOG_FILTER.station,
          "radar stations of the measurements: a network id, or station ids (built in, or "
          "sites of `sites`) separated by commas", check=STATION_IDS),
    sites_row(CATALOG_FILTER.sites),
    *filter_rows(CATALOG_FILTER, runtime=False, unlimited_span=False),
    *shard_rows(CATALOG_FILTER.shards, CATALOG_FILTER.shard),
    Param("batch_period", CATALOG_FILTER.batch_period,
          "time between batches: what arrived meanwhile is fused at once", unit="wall s",
          check=POSITIVE),
    clock_lead(CATALOG_FILTER.max_clock_lead),
    max_objects_row(CATALOG_FILTER.max_objects, "tracks (~0.5 kB each)", "a measurement"),
), rules=(SHARD_RULE, Rule(STATION_RULE_NAMES, sites_problem)))
"""The catalog_filter's parameters."""


class CatalogFilterNode(SsaNode):
    """The catalog filter node: measurements in, batches into a `TrackBank`, estimates out."""

    PARAMETERS = PARAMETERS

    def __init__(self) -> None:
        super().__init__()
        p = self.params
        self.shard, self.shards = p.integer("shard"), p.integer("shards")
        self.options = settings.filter_options(p.values)
        self.stations = network_stations(p.text("station"),
                                         load_station_map(p.text("sites")))  # valid: `SITES`
        self.bank = TrackBank(self.options, self.stations,
                              max_objects=p.integer("max_objects"))
        self.lo, self.hi = shard_range(self.shard, self.shards)
        self.diag.status["shard"] = f"{self.shard}/{self.shards} keys [{self.lo}, {self.hi}]"
        self.pub = self.create_publisher(StateEstimateMsg, TOPIC_ESTIMATE, CATALOG_QOS)
        cft = content_filter(self.shard, self.shards)
        self.sub = self.subscribe(MeasurementMsg, TOPIC_MEASUREMENT, self.on_measurement,
                                  CATALOG_QOS, content_filter=cft)
        if cft is not None and not self.sub.is_cft_enabled:
            self.diag.count(NodeCause.CONTENT_FILTER_UNAVAILABLE,
                            "the DDS implementation does not filter by content: every "
                            "measurement arrives and those of other shards are ignored here")
        self._pending: list[Measurement] = []
        self.clock_hold.limit = CATALOG_DEPTH  # a stalled catalog's burst is held whole
        self.wall_timer(p.number("batch_period"), self.fuse)
        self.reset_on_backward_jump(self.reset, "every track forgotten")
        self.progress = ProgressReporter(self, self.taken)

    def taken(self) -> dict[str, str | int]:
        """Return the lockstep progress: measurements with a final fate, estimates published."""
        c = self.diag.counts
        return {SHARD: f"{self.shard}/{self.shards}",
                TAKEN: c[Count.REFUSED] + c[Count.CONSUMED] + c[Count.DROPPED],
                Count.PUBLISHED_SENSOR: c[Count.PUBLISHED_SENSOR]}

    def reset(self) -> None:
        """Forget every track and what waits for the next batch."""
        self.bank = TrackBank(self.options, self.stations,
                              max_objects=self.params.integer("max_objects"))
        self.diag.counts[Count.DROPPED] += len(self._pending)
        self._pending.clear()

    def on_measurement(self, msg: MeasurementMsg) -> None:
        """Check one message and keep it for the next batch.

        Every received message ends counted once: ``ignored_other_shard``, ``refused``
        (with its cause), ``consumed`` by the bank, or ``dropped`` (by a clock jump or a
        failed batch).
        """
        self.diag.counts[Count.RECEIVED] += 1
        if not self._admit(msg):
            self.diag.counts[Count.REFUSED] += 1

    def _admit(self, msg: MeasurementMsg) -> bool:
        """Keep `msg` for the next batch and return True, or count why not and return False.

        A measurement of another shard is counted as ``ignored_other_shard`` only, not as
        received (True).
        """
        if msg.source != Source.SENSOR:
            self.diag.count(Cause.REJECTED_SOURCE, f"source {msg.source} on "
                            f"{TOPIC_MEASUREMENT}, which carries only sensor data")
            return False
        cause, reason = id_problem(msg.object_id, msg.header.frame_id)
        if cause:
            self.diag.count(Cause(cause), reason)
            return False
        why = shard_problem(msg.shard_key, msg.object_id, self.shard, self.shards)
        if why:
            other = why[0] == NodeCause.IGNORED_OTHER_SHARD
            self.diag.count(*why)
            if other:
                self.diag.counts[Count.RECEIVED] -= 1  # never this shard's: not received here
            return other
        m = self.measurement_of(msg)
        if m is None:
            return False
        cause, reason = measurement_problem(m, Kind.RANGE_AZ_EL)
        if not cause and m.frame_id not in self.stations:
            cause, reason = (Cause.REJECTED_FRAME, f"station {m.frame_id!r} is not in the "
                             f"network ({', '.join(self.stations)})")
        if cause:
            self.diag.count(Cause(cause), reason)
            return False
        if self.clock_hold.hold_ahead(partial(self._take_late, m), m.t, self.max_clock_lead()):
            return True  # received; taken or refused once the clock catches up
        return self._take(m)

    def _take(self, m: Measurement) -> bool:
        """Keep `m` for the next batch and return True, or count it ahead of the clock."""
        if self.ahead_of_clock(m.t):
            return False
        self._pending.append(m)
        return True

    def _take_late(self, m: Measurement) -> None:
        """`_take` a measurement held ahead of the clock (counted refused if still ahead)."""
        if not self._take(m):
            self.diag.counts[Count.REFUSED] += 1

    def fuse(self) -> None:
        """Fuse what arrived since the last batch (in epoch order) and publish the estimates.

        With what waited for the clock to catch up, once it has.
        """
        self.replay_held()
        if not self._pending:
            return
        batch = sorted(self._pending, key=lambda m: m.t)  # stable: arrival order at a tie
        self._pending = []
        t = np.array([m.t for m in batch])
        try:
            res = self.bank.process(t, [m.object_id for m in batch], [m.frame_id for m in batch],
                                    np.array([m.z for m in batch]), np.array([m.R for m in batch]))
        except Exception:  # counted, then the guard logs the traceback as internal_error
            self.diag.counts[Count.DROPPED] += len(batch)
            raise
        self.diag.counts[Count.CONSUMED] += len(batch)
        for i, cause in enumerate(res.cause):
            if cause == Cause.IOD_PENDING:
                self.diag.counts[cause] += 1
            elif cause:
                m = batch[i]
                self.diag.count(Cause(cause),
                                f"object {m.object_id!r} at t={m.t} from {m.frame_id!r}")
        for j, i in enumerate(res.fused.tolist()):
            e = StateEstimate(t=float(t[i]), x=res.x[j], P=res.P[j], object_id=batch[i].object_id,
                              update_source=UpdateSource.SENSOR, nis=float(res.nis[j]))
            self.pub.publish(messages.estimate_to_msg(e))
        self.diag.counts[Count.PUBLISHED_SENSOR] += int(res.fused.size)
        self._report(len(batch))

    def _report(self, batch: int) -> None:
        """Put the bank's size on /diagnostics (status)."""
        bank, status = self.bank, self.diag.status
        status["objects"] = str(len(bank))
        if len(bank) <= LIST_OBJECTS:
            status["object_ids"] = ",".join(bank.object_ids)
        status["tracks"] = str(int(bank.tracking.sum()))
        n = max(len(bank), 1)
        arrays = bank.x.nbytes + bank.P.nbytes + bank.t.nbytes + bank.tracking.nbytes
        status["bank_bytes_per_object"] = f"{arrays / n:.0f}"
        status["max_batch"] = str(max(int(status.get("max_batch", 0)), batch))


def main(args: list[str] | None = None) -> int:
    """Run the catalog filter node (``ros2 run ssa_fusion catalog_filter``)."""
    return CatalogFilterNode.main(args)


if __name__ == "__main__":
    raise SystemExit(main())
