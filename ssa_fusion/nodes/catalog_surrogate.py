r"""catalog_surrogate: residual forecasts through the gaps of every object of a catalog.

Subscribes to ``/ssa/estimate`` for the estimates the catalog_filter made from real
measurements (update source SENSOR; a DDS content filter keeps the others away), learns per
object what the filter's motion model gets wrong from its pass-end estimates
(`core.residual`), and publishes on ``/ssa/estimate`` the object's forecast through each gap
between passes (update source FORECAST, ``object_id`` set) on the grid of multiples of
`predict_period`, once `pass_break` sim s have passed without an estimate. The fits
(`core.gap_bank.GapBank`) take at most `fit_budget` of the wall time on average: a gap that
ends before its turn is left to the filter's coasting and counted as ``skipped`` on
``/diagnostics``.

Sharding as catalog_filter: with ``shards`` = K > 1 the node takes the objects whose
``StateEstimate.shard_key`` lies in the ``shard``-th of K ranges (content filter).

    ros2 run ssa_fusion catalog_surrogate --ros-args -p use_sim_time:=true \
        -p shards:=2 -p shard:=0 -r __node:=catalog_surrogate_0
"""

from __future__ import annotations

from dataclasses import replace
from functools import partial

from ssa_fusion.core.gap_bank import CATALOG_RESIDUAL, GapBank, GapBankConfig, GapForecast
from ssa_fusion.core.types import Cause, MotionModel, StateEstimate, UpdateSource
from ssa_fusion.core.validation import id_problem, state_problem
from ssa_fusion.nodes.base import SsaNode
from ssa_fusion.nodes.defaults import CATALOG_SURROGATE
from ssa_fusion.nodes.diagnostics import Count, NodeCause
from ssa_fusion.nodes.parameters import (
    MOTION_MODELS,
    NON_NEGATIVE,
    POSITIVE,
    Check,
    Param,
    ParameterTable,
    ParamValue,
    at_least,
    clock_lead,
)
from ssa_fusion.nodes.progress import SHARD, TAKEN_ESTIMATES, ProgressReporter
from ssa_fusion.nodes.shards import (
    LIST_OBJECTS,
    SHARD_RULE,
    content_filter,
    max_objects_row,
    shard_problem,
    shard_rows,
)
from ssa_fusion.ros import messages
from ssa_fusion.ros.interfaces import StateEstimate as StateEstimateMsg
from ssa_fusion.ros.topics import CATALOG_QOS, TOPIC_ESTIMATE

TICK_S = 0.1
"""Wall s between two rounds of fits and releases."""

COUNTERS = {"fitted": Count.FITS_MADE, "refused": Count.FITS_REFUSED,
            "skipped": Count.FITS_SKIPPED, "overtaken": Count.FORECASTS_OVERTAKEN}
"""/diagnostics counters of the bank's counts (`GapBank.counts`)."""


def _fraction(v: ParamValue) -> str | None:
    return None if isinstance(v, float) and 0.0 < v <= 1.0 else "must be in (0, 1]"


PARAMETERS = ParameterTable("catalog_surrogate", (
    Param("motion_model", CATALOG_SURROGATE.motion_model,
          "the catalog_filter's motion model, which the residual is learned against",
          check=MOTION_MODELS),
    Param("predict_period", CATALOG_SURROGATE.predict_period,
          "forecasts at its multiples in a gap", unit="s", check=POSITIVE),
    Param("pass_break", CATALOG_SURROGATE.pass_break,
          "sim time without an estimate after which a pass has ended", unit="s",
          check=POSITIVE),
    Param("hold", CATALOG_SURROGATE.hold,
          "forecasts only for epochs at least this long before the clock (the filter's "
          "estimates arrive after the clock)", unit="s", check=NON_NEGATIVE),
    Param("fit_budget", CATALOG_SURROGATE.fit_budget,
          "fraction of wall time the fits may take on average",
          check=Check("in (0, 1]", _fraction)),
    Param("min_anchors", CATALOG_SURROGATE.min_anchors, "pass ends a fit needs",
          check=at_least(2)),
    Param("min_span", CATALOG_SURROGATE.min_span,
          "the pass ends of a fit must span at least this", unit="s", check=NON_NEGATIVE),
    *shard_rows(CATALOG_SURROGATE.shards, CATALOG_SURROGATE.shard),
    clock_lead(CATALOG_SURROGATE.max_clock_lead),
    max_objects_row(CATALOG_SURROGATE.max_objects, "holds", "an estimate"),
), rules=(SHARD_RULE,))
"""The catalog_surrogate's parameters."""


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
                                    residual=residual)
        self.bank = GapBank(self.config, max_objects=p.integer("max_objects"))
        self.diag.status["shard"] = f"{self.shard}/{self.shards}"
        self.pub = self.create_publisher(StateEstimateMsg, TOPIC_ESTIMATE, CATALOG_QOS)
        cft = content_filter(self.shard, self.shards, "update_source = %0",
                             (str(UpdateSource.SENSOR.value),))
        self.sub = self.subscribe(StateEstimateMsg, TOPIC_ESTIMATE, self.on_message,
                                  CATALOG_QOS, content_filter=cft)
        self.taken = 0  # SENSOR estimates arrived (used or refused): lockstep progress
        if not self.sub.is_cft_enabled:
            self.diag.count(NodeCause.CONTENT_FILTER_UNAVAILABLE,
                            "the DDS implementation does not filter by content: every "
                            "estimate arrives and those not taken are ignored here")
        self.wall_timer(TICK_S, self.tick)
        self.progress = ProgressReporter(self, lambda: {
            SHARD: f"{self.shard}/{self.shards}", TAKEN_ESTIMATES: self.taken,
            Count.PUBLISHED_FORECAST: self.diag.counts[Count.PUBLISHED_FORECAST]})
        self.reset_on_backward_jump(self.reset, "every object forgotten")

    def reset(self) -> None:
        """Forget every object."""
        self.bank = GapBank(self.config, max_objects=self.params.integer("max_objects"))

    def on_message(self, msg: StateEstimateMsg) -> None:
        """Take one message of /ssa/estimate (counted for lockstep when a filter's)."""
        self.taken += msg.update_source == UpdateSource.SENSOR
        self.on_estimate(msg)

    def on_estimate(self, msg: StateEstimateMsg) -> None:
        """Take one estimate of the filter: a real measurement's is an object's newest."""
        if msg.update_source != UpdateSource.SENSOR:
            self.diag.counts[NodeCause.IGNORED_NOT_SENSOR] += 1  # forecasts, ours included
            return
        cause, reason = id_problem(msg.object_id, "")
        if cause:
            self.diag.count(Cause(cause), reason)
            return
        why = shard_problem(msg.shard_key, msg.object_id, self.shard, self.shards)
        if why:
            self.diag.count(*why)
            return
        e = messages.estimate_from_msg(msg)
        if self.clock_hold.hold_ahead(partial(self.on_estimate, msg), e.t,
                                      self.max_clock_lead()) or self.ahead_of_clock(e.t):
            return
        if not e.object_id:
            self.diag.count(NodeCause.REJECTED_OBJECT_ID,
                            "an estimate without object_id: whose it is cannot be known")
            return
        cause, reason = state_problem(e.x, e.P)
        if cause:
            self.diag.count(Cause(cause), f"object {e.object_id!r} at t={e.t}: {reason}")
            return
        if not self.bank.admits(e.object_id):
            self.diag.count(Cause.REJECTED_BANK_FULL,
                            f"object {e.object_id!r}: the bank holds max_objects "
                            f"({self.bank.max_objects}) objects already")
            return
        self.diag.counts[Count.RECEIVED] += 1
        self.publish(self.bank.on_estimate(e.object_id, e.t, e.x, e.P))

    def tick(self) -> None:
        """Take what waited for the clock; fit what the budget allows; publish what is due."""
        self.replay_held()
        self.publish(self.bank.step(self.now_s()))
        b, status = self.bank, self.diag.status
        for key, name in COUNTERS.items():
            self.diag.counts[name] = b.counts[key]
        status["objects"] = str(len(b))
        if len(b) <= LIST_OBJECTS:
            status["object_ids"] = ",".join(b.object_ids)
        status["waiting_for_fit"] = str(b.waiting)
        status["fit_seconds"] = f"{b.fit_seconds:.1f}"

    def publish(self, forecasts: list[GapForecast]) -> None:
        """Publish `forecasts` on /ssa/estimate (update source FORECAST)."""
        for f in forecasts:
            self.pub.publish(messages.estimate_to_msg(StateEstimate(
                t=f.t, x=f.x, P=f.P, object_id=f.object_id,
                update_source=UpdateSource.FORECAST)))
        self.diag.counts[Count.PUBLISHED_FORECAST] += len(forecasts)


def main(args: list[str] | None = None) -> int:
    """Run the catalog surrogate node (``ros2 run ssa_fusion catalog_surrogate``)."""
    return CatalogSurrogateNode.main(args)


if __name__ == "__main__":
    raise SystemExit(main())
