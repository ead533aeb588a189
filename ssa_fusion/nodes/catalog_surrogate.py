r"""catalog_surrogate: residual forecasts through the gaps of every object of a catalog.

Subscribes to ``/ssa/estimate_batch`` (ssa_fusion_msgs/EstimateBatch) for the estimates the
catalog_filter made from real measurements (update source SENSOR; a DDS content filter
keeps the others away), learns per object what the filter's motion model gets wrong from
its pass-end estimates (`core.gaps.residual`; until they span a day, `min_span`, the physics-only
forecast from the pass end, `physics_fit`), and publishes on ``/ssa/estimate_batch`` the
object's forecast through each gap between passes (update source FORECAST, ``object_id``
set; one batch per round) on the grid of multiples of `predict_period`, once `pass_break`
sim s have passed without an estimate. A stop (SIGINT, SIGTERM) cuts the fits still queued
(counted ``fits_cut``): the node ends within a fit's time, with its last report. The fits
(`core.catalog.gap_bank.GapBank`) take at most `fit_budget` of the wall time on average: a gap that
ends before its turn is left to the filter's coasting and counted as ``skipped`` on
``/diagnostics``.

With `gap_forecast` ``batch_fit`` the forecast of each gap is instead the batch
least-squares fit of the object's measurements of its last passes (the single-object
filter's `core.gaps.batch_gap`, with the radars of `station`): the node also subscribes to
``/ssa/measurement_batch`` (its shard's rows, as the catalog_filter) for them, and schedules
and publishes these fits as the residual's.

Sharding as catalog_filter: with ``shards`` = K > 1 the node takes the objects whose
``shard_key`` lies in the ``shard``-th of K ranges (content filter on the batches' key
range; rows of other shards in a batch that covers more are ignored).

    ros2 run ssa_fusion catalog_surrogate --ros-args -p use_sim_time:=true \
        -p shards:=2 -p shard:=0 -r __node:=catalog_surrogate_0
"""

from __future__ import annotations

from collections import Counter
from dataclasses import replace
from functools import partial

import numpy as np

from ssa_fusion.core.base.rows import EstimateRows
from ssa_fusion.core.base.types import Cause, Kind, MotionModel, UpdateSource
from ssa_fusion.core.catalog.gap_bank import (
    CATALOG_RESIDUAL,
    GapBank,
    GapBankConfig,
    GapForecast,
)
from ssa_fusion.core.earth.stations import network_stations
from ssa_fusion.core.earth.timescales import UNIX_EPOCH_JD
from ssa_fusion.core.gaps.publisher import GapFill
from ssa_fusion.core.gaps.residual import PHYSICS_RESIDUAL
from ssa_fusion.core.measure.measurement import StationModels
from ssa_fusion.core.measure.validation import (
    MAX_ID_CHARS,
    ahead_of_clock,
    id_problem,
    rows_problems,
    state_problem,
    states_problems,
)
from ssa_fusion.formats.sites import load_station_map
from ssa_fusion.nodes import STOP
from ssa_fusion.nodes.kit.base import SsaNode
from ssa_fusion.nodes.kit.diagnostics import Count, NodeCause
from ssa_fusion.nodes.kit.progress import SHARD, TAKEN_ESTIMATES, ProgressReporter
from ssa_fusion.nodes.kit.shards import (
    LIST_OBJECTS,
    content_filter,
    rows_shard_problems,
    sensor_estimates,
    shard_problem,
    shard_range,
)
from ssa_fusion.params.tables.catalog_surrogate import PARAMETERS
from ssa_fusion.ros import messages
from ssa_fusion.ros.interfaces import EstimateBatch, MeasurementBatch, Message
from ssa_fusion.ros.qos import CATALOG_QOS, CATALOG_WRITER_QOS
from ssa_fusion.ros.topics import TOPIC_ESTIMATE_BATCH, TOPIC_MEASUREMENT_BATCH

TICK_S = 0.01
"""Wall s between two rounds of fits and releases (in lockstep the simulator's next step
waits for the round at its clock: `nodes.kit.progress.CLOCK`)."""

COUNTERS = {"fitted": Count.FITS_MADE, "fitted_physics": Count.FITS_PHYSICS,
            "refused": Count.FITS_REFUSED, "skipped": Count.FITS_SKIPPED,
            "cut": Count.FITS_CUT, "overtaken": Count.FORECASTS_OVERTAKEN}
"""/diagnostics counters of the bank's counts (`GapBank.counts`)."""


class CatalogSurrogateNode(SsaNode):
    """The catalog surrogate node: SENSOR estimates in, a `GapBank`, forecasts out."""

    PARAMETERS = PARAMETERS

    def __init__(self) -> None:
        super().__init__()
        p = self.params
        self.shard, self.shards = p.integer("shard"), p.integer("shards")
        residual = replace(CATALOG_RESIDUAL, min_anchors=p.integer("min_anchors"),
                           min_span_s=p.number("min_span"))
        self.config = GapBankConfig(motion_model=MotionModel(p.text("motion_model")),
                                    period_s=p.number("predict_period"),
                                    pass_break_s=p.number("pass_break"),
                                    hold_s=p.number("hold"), fit_budget=p.number("fit_budget"),
                                    residual=residual,
                                    physics=PHYSICS_RESIDUAL if p.flag("physics_fit") else None,
                                    gap_forecast=GapFill(p.text("gap_forecast")))
        batch = self.config.gap_forecast == GapFill.BATCH_FIT
        self.model = StationModels(network_stations(
            p.text("station"), load_station_map(p.text("sites"))), UNIX_EPOCH_JD) if batch else None
        self.bank = self.new_bank()
        self.diag.status["shard"] = f"{self.shard}/{self.shards}"
        self.key_range = shard_range(self.shard, self.shards)
        self.pub = self.advertise(EstimateBatch, TOPIC_ESTIMATE_BATCH, CATALOG_WRITER_QOS)
        cft = content_filter(self.shard, self.shards, "update_source = %0",
                             (str(UpdateSource.SENSOR.value),), batches=True)
        self.sub = self.subscribe(EstimateBatch, TOPIC_ESTIMATE_BATCH, self.on_message,
                                  CATALOG_QOS, content_filter=cft)
        self.taken = 0  # SENSOR estimates arrived (used or refused): lockstep progress
        self.sub_batch = self.subscribe(
            MeasurementBatch, TOPIC_MEASUREMENT_BATCH, self.on_measurement_batch, CATALOG_QOS,
            content_filter=content_filter(self.shard, self.shards, batches=True)
        ) if batch else None
        if not self.sub.is_cft_enabled:
            self.diag.count(NodeCause.CONTENT_FILTER_UNAVAILABLE,
                            "the DDS implementation does not filter by content: every "
                            "estimate arrives and those not taken are ignored here")
        self.wakeup(TICK_S, self.tick)
        self.stepped_ns = 0  # the sim time (ns) the bank was last stepped at: lockstep
        self.progress = ProgressReporter(self, lambda: {
            SHARD: f"{self.shard}/{self.shards}", TAKEN_ESTIMATES: self.taken,
            Count.PUBLISHED_FORECAST: self.diag.counts[Count.PUBLISHED_FORECAST]},
            clock=lambda: self.stepped_ns)
        self.reset_on_backward_jump(self.reset, "every object forgotten")

    def new_bank(self) -> GapBank:
        """Return an empty bank of this node's settings."""
        return GapBank(self.config, max_objects=self.params.integer("max_objects"),
                       model=self.model)

    def reset(self) -> None:
        """Forget every object."""
        self.bank = self.new_bank()

    def on_measurement_batch(self, msg: Message) -> None:
        """Take one MeasurementBatch for the batch fits: its rows of this shard's objects.

        Rows of other shards, of another network's stations, forecasts and rows the
        catalog_filter refuses (`validation.rows_problems`: it counts them) are ignored; a
        malformed batch is refused whole.
        """
        try:
            rows = messages.measurement_batch_from_msg(msg)
        except ValueError as exc:
            self.diag.count(Cause.REJECTED_MALFORMED, f"{TOPIC_MEASUREMENT_BATCH}: {exc}",
                            n=len(msg.object_id))
            return
        bad_key, other = rows_shard_problems(rows.shard_key, rows.object_id, self.shard,
                                             self.shards)
        assert self.model is not None
        known = np.isin(np.asarray(rows.frame_id, dtype=object), list(self.model.stations))
        sound = rows_problems(rows, Kind.RANGE_AZ_EL) == ""
        self.bank.on_measurements(rows.take(np.flatnonzero(~bad_key & ~other & known & sound)))

    def on_message(self, msg: Message) -> None:
        """Take one EstimateBatch: a filter's rows each are an object's newest estimate.

        Its SENSOR rows are counted for lockstep (taken), forecasts (ours included) are
        ignored; a batch whose columns disagree is refused whole (``rejected_malformed``).
        """
        taken, rows = sensor_estimates(self.diag, msg)
        self.taken += taken
        if rows is None:
            return
        rows = self._admit_rows(rows)
        if len(rows) and not self.clock_hold.hold_ahead(
                partial(self._take_rows, rows), float(rows.t.max()), self.max_clock_lead()):
            self._take_rows(rows)

    def _admit_rows(self, rows: EstimateRows) -> EstimateRows:
        """Return the rows with an id and of this shard; count the others by cause."""
        too_long = np.fromiter(map(len, rows.object_id), np.int64, len(rows)) > MAX_ID_CHARS
        bad_key, other = rows_shard_problems(rows.shard_key, rows.object_id, self.shard,
                                             self.shards)
        cause = np.select([too_long, bad_key, other], [Cause.REJECTED_ID,
                          NodeCause.REJECTED_SHARD_KEY, NodeCause.IGNORED_OTHER_SHARD], "")
        for key, n in Counter(cause[cause != ""].tolist()).items():
            i = int(np.argmax(cause == key))
            oid = rows.object_id[i]
            why = (id_problem(oid, "")[1] if key == Cause.REJECTED_ID else
                   (shard_problem(int(rows.shard_key[i]), oid, self.shard, self.shards)
                    or ("", ""))[1])
            self.diag.count(key, why, n=n)
        return rows.take(np.flatnonzero(cause == ""))

    def _take_rows(self, rows: EstimateRows) -> None:
        """Give the rows to the bank, in order, and publish the forecasts they release.

        Checked for the whole batch at once, in this order, each refusal counted by cause:
        stamped beyond ``max_clock_lead`` of the clock, without an object id, a state or
        covariance the filter would refuse (`validation.states_problems`), an object beyond
        ``max_objects``. The rest go to `GapBank.on_estimates`.
        """
        ids = np.asarray(rows.object_id, dtype=object)
        now, lead = self.now_s(), self.max_clock_lead()
        ahead = (rows.t > now + lead) if now > 0.0 else np.zeros(len(rows), dtype=bool)
        if ahead.any():
            i = int(np.argmax(ahead))
            self.diag.count(Cause.REJECTED_FUTURE,
                            ahead_of_clock(float(rows.t[i]), now, lead)[1], n=int(ahead.sum()))
        no_id = ~ahead & (ids == "")
        self.diag.count(NodeCause.REJECTED_OBJECT_ID,
                        "an estimate without object_id: whose it is cannot be known",
                        n=int(no_id.sum()))
        problems = states_problems(rows.x, rows.P)
        unsound = ~ahead & ~no_id & (problems != "")
        for cause in np.unique(problems[unsound]).tolist():
            i = int(np.argmax(unsound & (problems == cause)))
            self.diag.count(Cause(cause), f"object {ids[i]!r} at t={float(rows.t[i])}: "
                            f"{state_problem(rows.x[i], rows.P[i])[1]}",
                            n=int((unsound & (problems == cause)).sum()))
        sound = np.flatnonzero(~ahead & ~no_id & ~unsound)
        admitted = self.bank.admitted(ids[sound].tolist())
        if not admitted.all():
            oid = ids[sound[int(np.argmin(admitted))]]
            self.diag.count(Cause.REJECTED_BANK_FULL,
                            f"object {oid!r}: the bank holds max_objects "
                            f"({self.bank.max_objects}) objects already",
                            n=int((~admitted).sum()))
        take = sound[admitted]
        self.diag.counts[Count.RECEIVED] += take.size
        self.publish(self.bank.on_estimates(ids[take].tolist(), rows.t[take], rows.x[take],
                                            rows.P[take]))

    def tick(self) -> bool:
        """Take what waited for the clock; fit what the budget allows; publish what is due.

        Return whether there was anything to do (`SsaNode.wakeup`): a new clock, forecasts
        published, or fits still waiting for the budget.
        """
        self.replay_held()
        now_ns = int(self.get_clock().now().nanoseconds)
        out = self.bank.step(now_ns * 1e-9, stop=STOP.is_set)  # a stop cuts the fits left
        self.publish(out)
        moved = now_ns != self.stepped_ns
        self.stepped_ns = now_ns
        b, status = self.bank, self.diag.status
        for key, name in COUNTERS.items():
            self.diag.counts[name] = b.counts[key]
        status["objects"] = str(len(b))
        if len(b) <= LIST_OBJECTS:
            status["object_ids"] = ",".join(b.object_ids)
        status["waiting_for_fit"] = str(b.waiting)
        status["fit_seconds"] = f"{b.fit_seconds:.1f}"
        return moved or bool(out) or b.waiting > 0

    def publish(self, forecasts: list[GapForecast]) -> None:
        """Publish `forecasts` as one EstimateBatch (update source FORECAST), if any."""
        if forecasts:
            ids = [f.object_id for f in forecasts]
            self.pub.publish(messages.estimate_batch_to_msg(EstimateRows(
                np.array([f.t for f in forecasts]), ids, np.array([f.x for f in forecasts]),
                np.array([f.P for f in forecasts]), np.zeros(len(forecasts)),
                UpdateSource.FORECAST, messages.shard_keys(ids)), self.key_range))
        self.diag.counts[Count.PUBLISHED_FORECAST] += len(forecasts)


def main(args: list[str] | None = None) -> int:
    """Run the catalog surrogate node (``ros2 run ssa_fusion catalog_surrogate``)."""
    return CatalogSurrogateNode.main(args)


if __name__ == "__main__":
    raise SystemExit(main())
