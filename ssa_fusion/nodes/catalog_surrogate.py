"""catalog_surrogate: residual forecasts through the gaps of every object of a catalog.

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

    ros2 run ssa_fusion catalog_surrogate --ros-args -p use_sim_time:=true \\
        -p shards:=2 -p shard:=0 -r __node:=catalog_surrogate_0
"""

from __future__ import annotations

from dataclasses import replace
from typing import Any

import numpy as np
from rclpy.clock import JumpThreshold
from rclpy.duration import Duration
from rclpy.node import Node
from ssa_fusion_msgs.msg import StateEstimate as StateEstimateMsg

from ssa_fusion.core.gap_bank import CATALOG_RESIDUAL, GapBank, GapBankConfig, GapForecast
from ssa_fusion.core.types import Cause, StateEstimate, UpdateSource
from ssa_fusion.core.validation import ahead_of_clock
from ssa_fusion.nodes import start_process
from ssa_fusion.nodes.common import (
    Diagnostics,
    at_least,
    clock_lead,
    declare,
    non_negative,
    one_of,
    positive,
    run,
    wall_timer,
)
from ssa_fusion.nodes.defaults import CATALOG_SURROGATE
from ssa_fusion.nodes.shards import LIST_OBJECTS, content_filter, declare_shard, shard_problem
from ssa_fusion.ros import messages
from ssa_fusion.ros.topics import CATALOG_QOS, TOPIC_ESTIMATE

TICK_S = 0.1
"""Wall s between two rounds of fits and releases."""

COUNTERS = {"fitted": "fits_made", "refused": "fits_refused", "skipped": "fits_skipped",
            "overtaken": "forecasts_overtaken"}
"""/diagnostics counters of the bank's counts (`GapBank.counts`)."""


def _budget(v: Any) -> str | None:
    return None if isinstance(v, float) and 0.0 < v <= 1.0 else "must be in (0, 1]"


class CatalogSurrogateNode(Node):
    def __init__(self) -> None:
        super().__init__("catalog_surrogate")
        d = CATALOG_SURROGATE
        model = declare(self, "motion_model", d.motion_model, "the catalog_filter's motion "
                        "model, which the residual is learned against: kepler | j2",
                        one_of("kepler", "j2"))
        period = declare(self, "predict_period", d.predict_period,
                         "sim s: forecasts at its multiples in a gap", positive)
        pass_break = declare(self, "pass_break", d.pass_break,
                             "sim s without an estimate after which a pass has ended",
                             positive)
        hold = declare(self, "hold", d.hold, "sim s: forecasts only for epochs this long "
                       "before the clock (the filter's estimates arrive after the clock)",
                       non_negative)
        budget = declare(self, "fit_budget", d.fit_budget,
                         "fraction of wall time the fits may take on average", _budget)
        anchors = declare(self, "min_anchors", d.min_anchors,
                          "pass ends a fit needs (>= 2)", at_least(2))
        span = declare(self, "min_span", d.min_span,
                       "sim s the pass ends of a fit must span at least", non_negative)
        self.shard, self.shards = declare_shard(self, d.shards, d.shard)
        self.max_lead = clock_lead(self, d.max_clock_lead)
        residual = replace(CATALOG_RESIDUAL, min_anchors=anchors, min_span_s=span)
        self.config = GapBankConfig(motion_model=model, period_s=period,
                                    pass_break_s=pass_break, hold_s=hold,
                                    fit_budget=budget, residual=residual)
        self.bank = GapBank(self.config)
        self.diag = Diagnostics(self)
        self.diag.status["shard"] = f"{self.shard}/{self.shards}"
        self.pub = self.create_publisher(StateEstimateMsg, TOPIC_ESTIMATE, CATALOG_QOS)
        cft = content_filter(self.shard, self.shards, "update_source = %0",
                             (str(UpdateSource.SENSOR.value),))
        self.sub = self.diag.subscribe(StateEstimateMsg, TOPIC_ESTIMATE,
                                       self.diag.guard(self.on_estimate), CATALOG_QOS,
                                       content_filter=cft)
        if not self.sub.is_cft_enabled:
            self.diag.count("content_filter_unavailable",
                            "the DDS implementation does not filter by content: every "
                            "estimate arrives and those not taken are ignored here")
        wall_timer(self, TICK_S, self.diag.guard(self.tick))
        self._jump = self.get_clock().create_jump_callback(
            JumpThreshold(min_forward=None, min_backward=Duration(nanoseconds=-1),
                          on_clock_change=False),
            post_callback=self.on_jump)
        self.activity = 0

    def on_jump(self, _jump: Any) -> None:
        self.bank = GapBank(self.config)
        self.diag.count(Cause.RESET_CLOCK_JUMP, "sim time jumped backwards: every object "
                        "forgotten", warn=False)

    def on_estimate(self, msg: StateEstimateMsg) -> None:
        """Take one estimate of the filter: a real measurement's is an object's newest."""
        self.activity += 1
        if msg.update_source != UpdateSource.SENSOR:
            self.diag.counts["ignored_not_sensor"] += 1  # forecasts, ours included
            return
        why = shard_problem(msg.shard_key, msg.object_id, self.shard, self.shards)
        if why:
            self.diag.count(why[0], why[1], warn=why[0] != "ignored_other_shard")
            return
        e = messages.estimate_from_msg(msg)
        cause, reason = ahead_of_clock(e.t, self.get_clock().now().nanoseconds * 1e-9,
                                       self.max_lead)
        if cause:
            self.diag.count(cause, reason)
            return
        if not e.object_id:
            self.diag.count("rejected_object_id",
                            "an estimate without object_id: whose it is cannot be known")
            return
        if not (np.isfinite(e.x).all() and np.isfinite(e.P).all()):
            self.diag.count(Cause.REJECTED_NONFINITE, f"object {e.object_id!r} at t={e.t}: "
                            "state or covariance not finite")
            return
        self.diag.counts["received"] += 1
        self.publish(self.bank.on_estimate(e.object_id, e.t, e.x, e.P))

    def tick(self) -> None:
        """Fit what the budget allows and publish the forecasts due."""
        self.publish(self.bank.step(self.get_clock().now().nanoseconds * 1e-9))
        b = self.bank
        for key, name in COUNTERS.items():
            self.diag.counts[name] = b.counts[key]
        self.diag.status["objects"] = str(len(b))
        if len(b) <= LIST_OBJECTS:
            self.diag.status["object_ids"] = ",".join(b.object_ids)
        self.diag.status["waiting_for_fit"] = str(b.waiting)
        self.diag.status["fit_seconds"] = f"{b.fit_seconds:.1f}"

    def publish(self, forecasts: list[GapForecast]) -> None:
        for f in forecasts:
            self.pub.publish(messages.estimate_to_msg(StateEstimate(
                t=f.t, x=f.x, P=f.P, object_id=f.object_id,
                update_source=UpdateSource.FORECAST)))
        self.diag.counts["published_forecast"] += len(forecasts)


def main(args: list[str] | None = None) -> int:
    start_process()
    return run(CatalogSurrogateNode, args)


if __name__ == "__main__":
    raise SystemExit(main())
