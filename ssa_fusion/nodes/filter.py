"""filter: EKF of one satellite with the Keplerian two-body placeholder model.

Initialises from its first real measurements (Herrick–Gibbs for range/az/el, finite
differences for position), then fuses real measurements from ``/ssa/measurement`` and,
for epochs without one, forecasts from ``/ssa/forecast``. Publishes ``/ssa/estimate``
(state + full 6x6 covariance, stamped with the measurement epoch) for every fused epoch;
when nothing is fused for `predict_period` sim s it publishes a prediction (update_source
NONE) whose covariance grows. Rejected input is counted by cause on ``/diagnostics``.

    ros2 run ssa_fusion filter --ros-args -p use_sim_time:=true -p kind:=range_az_el
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

from rclpy.clock import JumpThreshold
from rclpy.duration import Duration
from rclpy.node import Node
from ssa_fusion_msgs.msg import Measurement as MeasurementMsg
from ssa_fusion_msgs.msg import StateEstimate as StateEstimateMsg

from ssa_fusion.core import kepler
from ssa_fusion.core.measurement import PositionModel, RazelModel
from ssa_fusion.core.stations import STATIONS, UNIX_EPOCH_JD
from ssa_fusion.core.tracker import Tracker, TrackerConfig
from ssa_fusion.core.types import Cause, Kind, StateEstimate
from ssa_fusion.core.validation import ahead_of_clock
from ssa_fusion.nodes import start_process
from ssa_fusion.nodes.common import (
    Diagnostics,
    all_non_negative,
    clock_lead,
    declare,
    measurement_stream,
    non_negative,
    run,
    wall_timer,
)
from ssa_fusion.nodes.defaults import FILTER
from ssa_fusion.ros import messages
from ssa_fusion.ros.topics import DATA_QOS, TOPIC_ESTIMATE, TOPIC_FORECAST, TOPIC_MEASUREMENT

SOURCE_NAMES = ("prediction", "sensor", "forecast")


def _p0_check(v: list) -> str | None:
    if len(v) == 6 and all_non_negative(v):
        return None
    return "needs 6 standard deviations, each a finite number >= 0"


def tracker_from(node: Node) -> Tracker:
    """Declare the filter's parameters on `node` (defaults: `defaults.FILTER`) and build its
    Tracker: the Keplerian placeholder, the measurement model of its `kind` (range/az/el
    from `station`, on the Unix-time clock), and a `TrackerConfig` in core units."""
    d = FILTER
    kind, frame = measurement_stream(node, d)
    config = TrackerConfig()

    def setter(field: str, convert: Callable[[Any], Any]) -> Callable[[Any], None]:
        def apply(value: Any) -> None:
            setattr(config, field, convert(value))

        return apply

    def p0_km(v: Any) -> tuple[float, ...]:
        return tuple(x / 1000.0 for x in v)

    p0 = declare(
        node,
        "p0_sigma",
        list(d.p0_sigma),
        "std floor added to the IOD covariance: 3 x m, 3 x m/s (applies at the next IOD)",
        _p0_check,
        apply=setter("p0_sigma", p0_km),
    )
    q = declare(
        node,
        "q",
        d.q,
        "process noise: white-noise acceleration spectral density, m^2/s^3",
        non_negative,
        apply=setter("q", lambda v: v * 1e-6),
    )
    gate = declare(
        node,
        "gate",
        d.gate,
        "NIS beyond which an update is rejected (0 = no gate)",
        non_negative,
        apply=setter("gate", lambda v: v or None),
    )
    object_id = declare(node, "object_id", d.object_id, "only track this object ('' = any)")
    iod_samples = declare(
        node,
        "iod_samples",
        d.iod_samples,
        "real measurements used by the initial orbit determination (>= 3)",
        lambda v: None if isinstance(v, int) and v >= 3 else "must be an integer >= 3",
        apply=setter("iod_samples", int),
    )
    model = (RazelModel(STATIONS[frame], UNIX_EPOCH_JD)
             if kind == Kind.RANGE_AZ_EL else PositionModel())
    config.p0_sigma, config.q, config.gate = p0_km(p0), q * 1e-6, gate or None
    config.frame_id, config.iod_samples = frame, iod_samples
    return Tracker(kepler.propagate, model, config, n=6, object_id=object_id)


class FilterNode(Node):
    def __init__(self) -> None:
        super().__init__("filter")
        self.tracker = tracker_from(self)
        self.predict_period = declare(
            self,
            "predict_period",
            FILTER.predict_period,
            "sim s without an update after which a prediction is published (0 = never)",
            non_negative,
            apply=lambda v: setattr(self, "predict_period", v),
        )
        self.max_lead = clock_lead(self, FILTER.max_clock_lead)
        self.diag = Diagnostics(self)
        self.pub = self.create_publisher(StateEstimateMsg, TOPIC_ESTIMATE, DATA_QOS)
        for topic in (TOPIC_MEASUREMENT, TOPIC_FORECAST):
            self.diag.subscribe(MeasurementMsg, topic, self.diag.guard(self.on_measurement),
                                DATA_QOS)
        wall_timer(self, 0.1, self.diag.guard(self.predict))
        self._jump = self.get_clock().create_jump_callback(
            JumpThreshold(
                min_forward=None, min_backward=Duration(nanoseconds=-1), on_clock_change=False
            ),
            post_callback=self.on_jump,
        )
        self.activity = 0
        self.last_object = ""
        self._predicted_at = -math.inf  # sim time of the last prediction published

    def on_jump(self, jump) -> None:
        self.tracker.reset()
        self._predicted_at = -math.inf
        self.diag.count(
            Cause.RESET_CLOCK_JUMP, "sim time jumped backwards: filter reset", warn=False
        )

    def on_measurement(self, msg: MeasurementMsg) -> None:
        self.activity += 1
        wanted = self.tracker.object_id
        if wanted and msg.object_id != wanted:
            self.diag.count(Cause.IGNORED_OTHER_OBJECT, f"object_id {msg.object_id!r}", warn=False)
            return
        try:
            m = messages.measurement_from_msg(msg)
        except ValueError as exc:
            self.diag.count(Cause.REJECTED_KIND, str(exc))
            return
        now = self.get_clock().now().nanoseconds * 1e-9
        cause, reason = ahead_of_clock(m.t, now, self.max_lead)
        if cause:
            self.diag.count(cause, reason)
            return
        out = self.tracker.process(m)
        if out.rejected == Cause.IOD_PENDING:
            self.diag.counts[Cause.IOD_PENDING] += 1
        elif out.rejected:
            self.diag.count(out.rejected, out.detail, warn=out.rejected.startswith("rej"))
        else:
            self.last_object = msg.object_id
        if out.rolled_back:
            self.diag.counts[Cause.FORECASTS_ROLLED_BACK] += out.rolled_back
        for e in (out.estimate, *out.fused_again):  # fused again even if m was rejected
            if e is not None:
                self.publish(e)

    def publish(self, e: StateEstimate) -> None:
        e.object_id = e.object_id or self.last_object
        self.pub.publish(messages.estimate_to_msg(e))
        self.diag.counts[f"published_{SOURCE_NAMES[e.update_source]}"] += 1

    def predict(self) -> None:
        if self.predict_period <= 0:
            return
        now = self.get_clock().now().nanoseconds * 1e-9
        if self.tracker.t >= now - self.predict_period or now <= self._predicted_at:
            return  # recently updated, or sim time has not moved since the last prediction
        e = self.tracker.predicted(now)
        if e is not None:
            self.publish(e)
            self._predicted_at = now


def main(args: list[str] | None = None) -> int:
    start_process()
    return run(FilterNode, args)


if __name__ == "__main__":
    raise SystemExit(main())
