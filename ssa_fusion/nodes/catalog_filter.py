r"""catalog_filter: IOD + EKF of every object of a catalog in one process, batched.

Subscribes to ``/ssa/measurement_batch`` (ssa_fusion_msgs/MeasurementBatch: many rows a
message, range/az/el of any object from the stations of `station`) and to
``/ssa/measurement`` (one Measurement a message, for publishers that send them so),
checks what arrives (a batch's rows at once, vectorised: `validation.rows_problems`),
and every `batch_period` wall s fuses it all at once in a `core.catalog.track_bank.TrackBank` (one
track per ``object_id``, vectorised over objects). Publishes ``/ssa/estimate_batch``
(ssa_fusion_msgs/EstimateBatch, update source SENSOR): one batch per fusion, a row for
every fused measurement and for every track an IOD starts. Refused input is counted by
cause on ``/diagnostics``, a batch's refused rows each (the good rows of the same batch are
fused); ``consumed`` counts every measurement the bank took (fused, pending in an IOD batch,
or rejected by it), so that published = consumed + refused at the door (in rows).
Once a second it gives the C heap the fusions freed back to the system
(`memory.release_free_heap`), so that its resident memory follows what it holds rather than
its largest batch. With ``max_unacked_rows`` it waits for its estimate readers'
acknowledgements whenever that many rows are out (`memory.AckedPublisher`), so that the
publisher's history keeps a few message slots, not as many as its largest burst left
unacknowledged (at the cost of the waits; with rmw_fastrtps's default history memory: the
graphs ssa_fusion starts free a slot's buffer with its message, `ros.discovery`).

Sharding: with ``shards`` = K > 1 the node owns the objects whose ``shard_key`` (CRC-32 of
``object_id``) lies in the ``shard``-th of K equal ranges, and subscribes with a DDS content
filter: to the batches whose key range (``key_lo``, ``key_hi``) meets its own, and to the
Measurements whose ``shard_key`` lies in it. The other shards' measurements never reach it
(a batch that covers more than its range: their rows are counted ``ignored_other_shard``).
K processes with shard 0..K-1 cover every object exactly once, on one host or several in
one ROS domain.

Unlabelled detections (rows whose ``object_id`` is empty, a radar's scans) are associated
with tracks (`nodes.kit.unlabelled`, `core.catalog.unlabelled`): the confirmed tracks'
estimates go out on ``/ssa/estimate_batch`` under their track ids, the associated detections on
``/ssa/measurement_associated``. They need one shard (``shards`` 1): with several, they are
refused (``rejected_unlabelled_sharded``).

    ros2 run ssa_fusion catalog_filter --ros-args -p use_sim_time:=true \
        -p station:=radar_network -p shards:=2 -p shard:=0 -r __node:=catalog_filter_0
"""

from __future__ import annotations

import math
from collections import Counter
from functools import partial

import numpy as np

from ssa_fusion.core.base.rows import EstimateRows, MeasurementRows
from ssa_fusion.core.base.types import Cause, Kind, Measurement, Source
from ssa_fusion.core.catalog.fusion import (
    CatalogFusion,
    fused_estimates,
    in_epoch_order,
    row_causes,
)
from ssa_fusion.core.catalog.track_bank import BankResult, TrackBank
from ssa_fusion.core.catalog.unlabelled import elevation_masks, is_unlabelled
from ssa_fusion.core.earth.stations import network_stations
from ssa_fusion.core.measure import validation
from ssa_fusion.core.measure.validation import id_problem, measurement_problem
from ssa_fusion.formats.sites import load_sites, load_station_map
from ssa_fusion.nodes.kit.base import SsaNode
from ssa_fusion.nodes.kit.diagnostics import Count, NodeCause
from ssa_fusion.nodes.kit.memory import AckedPublisher, release_free_heap
from ssa_fusion.nodes.kit.progress import SHARD, TAKEN, ProgressReporter
from ssa_fusion.nodes.kit.shards import (
    LIST_OBJECTS,
    content_filter,
    rows_shard_problems,
    shard_problem,
    shard_range,
)
from ssa_fusion.nodes.kit.unlabelled import UnlabelledRows, sharded_problem
from ssa_fusion.params import settings
from ssa_fusion.params.tables.catalog_filter import PARAMETERS
from ssa_fusion.ros import messages
from ssa_fusion.ros.interfaces import EstimateBatch, MeasurementBatch, Message
from ssa_fusion.ros.interfaces import Measurement as MeasurementMsg
from ssa_fusion.ros.qos import CATALOG_QOS, CATALOG_WRITER_QOS
from ssa_fusion.ros.topics import (
    CATALOG_DEPTH,
    TOPIC_ESTIMATE_BATCH,
    TOPIC_MEASUREMENT,
    TOPIC_MEASUREMENT_BATCH,
)

RELEASE_HEAP_PERIOD_S = 1.0
"""Wall s between two returns of the freed C heap to the system (`memory.release_free_heap`):
the batches' arrays and messages are freed, their pages stay resident until then."""

ACK_WAIT_S = 5.0
"""Longest wait for the acknowledgements (wall s; Fast DDS's readers acknowledge at the latest
when its writer's heartbeat, every 3 s, asks them to); then the estimates go out anyway."""


class CatalogFilterNode(SsaNode):
    """The catalog filter node: measurements in, batches into a `TrackBank`, estimates out."""

    PARAMETERS = PARAMETERS

    def __init__(self) -> None:
        super().__init__()
        p = self.params
        # first: its discovery is over long before the estimates' publisher exists
        self.publish_settings(settings.catalog_config_message(p.values))
        self.shard, self.shards = p.integer("shard"), p.integer("shards")
        self.options = settings.filter_options(p.values)
        self.stations = network_stations(p.text("station"),
                                         load_station_map(p.text("sites")))  # valid: `SITES`
        sites = p.text("sites")
        self.masks = elevation_masks(self.stations, load_sites(sites) if sites else {})
        self.fusion = self.new_fusion()
        self.lo, self.hi = shard_range(self.shard, self.shards)
        self.diag.status["shard"] = f"{self.shard}/{self.shards} keys [{self.lo}, {self.hi}]"
        self.pub = self.advertise(EstimateBatch, TOPIC_ESTIMATE_BATCH, CATALOG_WRITER_QOS)
        unacked = p.integer("max_unacked_rows")
        self.acked = AckedPublisher(self.pub, unacked if unacked > 0 else math.inf, ACK_WAIT_S)
        self.unlabelled = UnlabelledRows(self.diag)
        cft = content_filter(self.shard, self.shards)
        self.sub = self.subscribe(MeasurementMsg, TOPIC_MEASUREMENT, self.on_measurement,
                                  CATALOG_QOS, content_filter=cft)
        self.sub_batch = self.subscribe(
            MeasurementBatch, TOPIC_MEASUREMENT_BATCH, self.on_batch, CATALOG_QOS,
            content_filter=content_filter(self.shard, self.shards, batches=True))
        if cft is not None and not (self.sub.is_cft_enabled and self.sub_batch.is_cft_enabled):
            self.diag.count(NodeCause.CONTENT_FILTER_UNAVAILABLE,
                            "the DDS implementation does not filter by content: every "
                            "measurement arrives and those of other shards are ignored here")
        self._pending_rows: list[MeasurementRows] = []  # batches' rows admitted
        self._pending: list[Measurement] = []
        self.clock_hold.limit = CATALOG_DEPTH  # a stalled catalog's burst is held whole
        self.wakeup(p.number("batch_period"), self.fuse)
        self._released_at = -1  # diag.activity at the last release of the heap
        self.wall_timer(RELEASE_HEAP_PERIOD_S, self.release_heap)
        self.reset_on_backward_jump(self.reset, "every track forgotten")
        self.progress = ProgressReporter(self, self.taken)

    def release_heap(self) -> None:
        """Return the pages the fusions freed to the system (`memory.release_free_heap`).

        Not while nothing arrived since the last time: nothing was freed.
        """
        if self.diag.activity != self._released_at:
            self._released_at = self.diag.activity
            release_free_heap()

    def taken(self) -> dict[str, str | int]:
        """Return the lockstep progress: measurements with a final fate, estimates published.

        And the measurements received (admitted or refused, not yet all fused).
        """
        c = self.diag.counts
        return {SHARD: f"{self.shard}/{self.shards}",
                TAKEN: c[Count.REFUSED] + c[Count.CONSUMED] + c[Count.DROPPED],
                Count.RECEIVED: c[Count.RECEIVED],
                Count.PUBLISHED_SENSOR: c[Count.PUBLISHED_SENSOR],
                Count.PUBLISHED_ASSOCIATED: c[Count.PUBLISHED_ASSOCIATED]}

    @property
    def bank(self) -> TrackBank:
        """The labelled objects' tracks."""
        return self.fusion.bank

    def new_fusion(self) -> CatalogFusion:
        """Return the empty tracks of this shard's settings (`core.catalog.fusion`)."""
        p = self.params
        fusion = CatalogFusion(self.options, self.stations, self.masks,
                               max_objects=p.integer("max_objects"),
                               evict_after_s=p.number("evict_after"))
        fusion.bank.warm_up()  # its compiled code loaded before the first batch, not in it
        return fusion

    def reset(self) -> None:
        """Forget every track and what waits for the next batch."""
        self.fusion = self.new_fusion()
        self.diag.counts[Count.DROPPED] += len(self._pending) + sum(map(len, self._pending_rows))
        self._pending.clear()
        self._pending_rows.clear()

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
        if not why and not msg.object_id and self.shards > 1:
            why = (NodeCause.REJECTED_UNLABELLED_SHARDED, sharded_problem(self.shards))
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

    def on_batch(self, msg: Message) -> None:
        """Check the rows of one MeasurementBatch; keep the good ones for the next fusion.

        Every row ends counted once, as a Measurement would (`on_measurement`): a batch
        whose columns disagree is refused whole (``rejected_malformed``, each row).
        """
        try:
            rows = messages.measurement_batch_from_msg(msg)
        except ValueError as exc:
            m = len(msg.object_id)
            self.diag.counts[Count.RECEIVED] += m
            self.diag.counts[Count.REFUSED] += m
            self.diag.count(Cause.REJECTED_MALFORMED, f"{TOPIC_MEASUREMENT_BATCH}: {exc}", n=m)
            return
        keep = self._admit_rows(rows)
        if not len(keep):
            return
        if self.clock_hold.hold_ahead(partial(self._take_rows, keep), float(keep.t.max()),
                                      self.max_clock_lead()):
            return  # taken or refused once the clock catches up
        self._take_rows(keep)

    def _admit_rows(self, rows: MeasurementRows) -> MeasurementRows:
        """Return the rows of `rows` to keep; count the others by cause.

        The checks and causes of `_admit`, in its order, vectorised: source, id length,
        shard key, the measurement (`validation.rows_problems`), station. Rows of another
        shard are counted ``ignored_other_shard`` only, not received.
        """
        m = len(rows)
        own = row_causes(rows, self.stations)  # the filter's, before and after the shard's
        first = (own == Cause.REJECTED_SOURCE) | (own == Cause.REJECTED_ID)
        cause = np.where(first, own, "").astype(object)
        bad_key, other = rows_shard_problems(rows.shard_key, rows.object_id, self.shard,
                                             self.shards)
        unrouted = is_unlabelled(rows.object_id) & (self.shards > 1)
        for bad, why in ((bad_key, NodeCause.REJECTED_SHARD_KEY),
                         (other, NodeCause.IGNORED_OTHER_SHARD),
                         (unrouted, NodeCause.REJECTED_UNLABELLED_SHARDED),
                         (own != "", own)):
            free = bad & (cause == "")
            cause[free] = why[free] if isinstance(why, np.ndarray) else why
        n_other = int((cause == NodeCause.IGNORED_OTHER_SHARD).sum())
        self.diag.counts[Count.RECEIVED] += m - n_other
        self.diag.counts[Count.REFUSED] += int((cause != "").sum()) - n_other
        for key, n in Counter(cause[cause != ""].tolist()).items():
            self.diag.count(key, self._reason(key, rows, int(np.argmax(cause == key))), n=n)
        keep = np.flatnonzero(cause == "")
        return rows if keep.size == m else rows.take(keep)  # no copy when all are kept

    def _reason(self, cause: str, rows: MeasurementRows, i: int) -> str:
        """Return the line logged for the first row of `rows` refused for `cause`: row `i`."""
        oid, key = rows.object_id[i], int(rows.shard_key[i])
        if cause == Cause.REJECTED_SOURCE:
            return (f"source {rows.source[i]} on {TOPIC_MEASUREMENT_BATCH}, which carries only "
                    "sensor data")
        if cause == NodeCause.REJECTED_UNLABELLED_SHARDED:
            return sharded_problem(self.shards)
        if cause in (NodeCause.REJECTED_SHARD_KEY, NodeCause.IGNORED_OTHER_SHARD):
            why = shard_problem(key, oid, self.shard, self.shards)
            return why[1] if why else ""
        if cause == Cause.REJECTED_FRAME:  # the station check (rows_problems checks none)
            return (f"station {rows.frame_id[i]!r} is not in the network "
                    f"({', '.join(self.stations)})")
        m = validation.row_measurement(rows, i)
        if m.kind == Kind.RA_DEC:
            m.z, m.R = m.z[:2], m.R[:2, :2]
        return measurement_problem(m, Kind.RANGE_AZ_EL)[1]

    def _take_rows(self, rows: MeasurementRows) -> None:
        """Keep `rows` for the next fusion, but those still ahead of the clock (refused)."""
        now, lead = self.now_s(), self.max_clock_lead()
        ahead = (rows.t > now + lead) if now > 0.0 else np.zeros(len(rows), bool)
        n = int(ahead.sum())
        if n:
            first = float(rows.t[np.argmax(ahead)])
            self.diag.count(Cause.REJECTED_FUTURE,
                            validation.ahead_of_clock(first, now, lead)[1], n=n)
            self.diag.counts[Count.REFUSED] += n
            rows = rows.take(np.flatnonzero(~ahead))
        if len(rows):
            self._pending_rows.append(rows)

    def _pending_batch(self) -> MeasurementRows | None:
        """Return what waits for the fusion as rows in epoch order, and forget it (None: none).

        Stable: arrival order at a tie (a batch's rows, then the Measurements;
        `core.catalog.fusion.in_epoch_order`).
        """
        parts = list(self._pending_rows)
        if self._pending:
            ms = self._pending
            parts.append(MeasurementRows(
                np.array([m.t for m in ms]), [m.object_id for m in ms],
                [m.frame_id for m in ms], np.array([m.z for m in ms]),
                np.array([m.R for m in ms])))
        self._pending, self._pending_rows = [], []
        return in_epoch_order(parts)

    def fuse(self) -> bool:
        """Fuse what arrived since the last batch (in epoch order) and publish the estimates.

        With what waited for the clock to catch up, once it has. The unlabelled rows
        first, then the labelled ones (`core.catalog.fusion.CatalogFusion`). Return whether
        there was anything to fuse (`SsaNode.wakeup`).
        """
        self.replay_held()
        batch = self._pending_batch()
        if batch is None:
            return False
        batch = self.unlabelled.take(self.fusion, batch, self.publish_estimates)
        if batch is None:
            return True
        try:
            res = self.fusion.track(batch)
        except Exception:  # counted, then the guard logs the traceback as internal_error
            self.diag.counts[Count.DROPPED] += len(batch)
            raise
        self.diag.counts[Count.CONSUMED] += len(batch)
        self._count_causes(res, batch)
        self.diag.counts[Count.EVICTED] = self.bank.evicted
        if res.fused.size:
            self.publish_estimates(fused_estimates(batch, res))
        self.diag.counts[Count.PUBLISHED_SENSOR] += int(res.fused.size)
        self._report(len(batch))
        return True

    def publish_estimates(self, rows: EstimateRows) -> None:
        """Publish `rows` (their keys set from their ids) in batches of ``batch_rows``."""
        rows.shard_key = messages.shard_keys(rows.object_id)
        most = self.params.integer("batch_rows")
        for part in np.array_split(np.arange(len(rows)), -(-len(rows) // most)):
            self.acked.publish(messages.estimate_batch_to_msg(rows.take(part), (self.lo, self.hi)),
                               part.size)

    def _count_causes(self, res: BankResult, batch: MeasurementRows) -> None:
        """Count the bank's causes (``iod_pending`` silently), logging the first of each."""
        cause = np.asarray(res.cause, dtype=object)
        for key, n in Counter(res.cause).items():
            if key == Cause.IOD_PENDING:
                self.diag.counts[key] += n
            elif key:
                i = int(np.argmax(cause == key))
                self.diag.count(Cause(key), f"object {batch.object_id[i]!r} at "
                                f"t={batch.t[i]} from {batch.frame_id[i]!r}", n=n)

    def _report(self, batch: int) -> None:
        """Put the bank's size on /diagnostics (status)."""
        bank, status = self.bank, self.diag.status
        status["objects"] = str(len(bank))
        if len(bank) <= LIST_OBJECTS:
            status["object_ids"] = ",".join(bank.object_ids)
        status["tracks"] = str(int(bank.tracking.sum()))
        n = max(len(bank), 1)
        status["bank_bytes_per_object"] = f"{bank.nbytes / n:.0f}"
        status["measurements_in_iod_batches"] = str(bank.pending_iod)
        status["estimate_ack_waits"] = f"{self.acked.waits} ({self.acked.waited_s:.1f} s)"
        status["estimate_ack_timeouts"] = str(self.acked.timeouts)
        status["max_batch"] = str(max(int(status.get("max_batch", 0)), batch))


def main(args: list[str] | None = None) -> int:
    """Run the catalog filter node (``ros2 run ssa_fusion catalog_filter``)."""
    return CatalogFilterNode.main(args)


if __name__ == "__main__":
    raise SystemExit(main())
