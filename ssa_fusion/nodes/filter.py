"""filter: EKF of one satellite with a Keplerian (default) or two-body + J2 motion model.

Initialises from its first real measurements (Herrick–Gibbs for range/az/el, finite
differences for position), then fuses real measurements from ``/ssa/measurement`` and,
for epochs without one, forecasts from ``/ssa/forecast``. Publishes ``/ssa/estimate``
(state + full 6x6 covariance, stamped with the measurement epoch) for every fused epoch;
when nothing is fused for `predict_period` sim s it publishes predictions (update_source
NONE) whose covariance grows, at every multiple of `predict_period` of sim time through the
gap (so on the truth's grid when the two cadences agree; each predicted on from the
previous, so a gap of hours costs one short propagation per prediction). Rejected
input is counted by cause on ``/diagnostics``. The
estimator settings in effect are published (latched) on ``/ssa/config``, so every bag
records them.

    ros2 run ssa_fusion filter --ros-args -p use_sim_time:=true -p kind:=range_az_el
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import replace
from typing import Any

from rclpy.clock import JumpThreshold
from rclpy.duration import Duration
from rclpy.node import Node
from ssa_fusion_msgs.msg import Measurement as MeasurementMsg
from ssa_fusion_msgs.msg import StateEstimate as StateEstimateMsg
from std_msgs.msg import String

from ssa_fusion.core.config import EstimatorConfig, make_tracker
from ssa_fusion.core.residual import GapForecaster
from ssa_fusion.core.tracker import prediction_epochs
from ssa_fusion.core.types import Cause, Source, StateEstimate, UpdateSource
from ssa_fusion.core.validation import ahead_of_clock
from ssa_fusion.nodes import settings, start_process
from ssa_fusion.nodes.common import (
    ClockHold,
    Diagnostics,
    all_non_negative,
    clock_lead,
    cross_check,
    declare,
    measurement_stream,
    non_negative,
    one_of,
    run,
    wall_timer,
)
from ssa_fusion.nodes.defaults import FILTER
from ssa_fusion.ros import messages
from ssa_fusion.ros.topics import (
    CONFIG_QOS,
    DATA_QOS,
    TOPIC_CONFIG,
    TOPIC_ESTIMATE,
    TOPIC_FORECAST,
    TOPIC_MEASUREMENT,
)

SOURCE_NAMES = ("prediction", "sensor", "forecast")
MAX_IOD_SAMPLES = 1000
"""Most measurements one IOD batch may take (a pass of 10 s samples has at most ~100)."""
PREDICTIONS_PER_TICK = 100
"""Most predictions published per 0.1 s wall tick (a backlog is worked off over ticks)."""


def _p0_check(v: list) -> str | None:
    if len(v) == 6 and all_non_negative(v):
        return None
    return "needs 6 standard deviations, each a finite number >= 0"


def estimator_from(node: Node) -> EstimatorConfig:
    """Declare the filter's estimator parameters on `node` (defaults: `defaults.FILTER`) and
    return its `EstimatorConfig` (core units, via `settings.estimator_from`). The tuning
    parameters can be set at run time: the new value goes through the same translation into
    ``node.tracker.config`` (and is published on /ssa/config)."""
    d = FILTER
    values: dict[str, Any] = {}

    def runtime(name: str) -> Callable[[Any], None]:
        def apply(value: Any) -> None:
            values[name] = value
            node.estimator = settings.estimator_from(values, {})
            node.tracker.config = replace(node.estimator.tracker,
                                          frame_id=node.tracker.config.frame_id)
            node.publish_config()

        return apply

    measurement_stream(node, d)
    values["kind"] = node.get_parameter("kind").value
    values["station"] = node.get_parameter("station").value
    values["motion_model"] = declare(
        node, "motion_model", d.motion_model,
        "the EKF's motion model: kepler (analytic two-body) | j2 (two-body + J2, integrated)",
        one_of(*map(str, settings.NODE_MOTION_MODELS)))
    values["p0_sigma"] = declare(
        node, "p0_sigma", list(d.p0_sigma),
        "std floor added to the IOD covariance: 3 x m, 3 x m/s (applies at the next IOD)",
        _p0_check, apply=runtime("p0_sigma"))
    values["q"] = declare(
        node, "q", d.q, "process noise: white-noise acceleration spectral density, m^2/s^3",
        non_negative, apply=runtime("q"))
    values["gate"] = declare(
        node, "gate", d.gate, "NIS beyond which an update is rejected (0 = no gate)",
        non_negative, apply=runtime("gate"))
    values["iod_samples"] = declare(
        node, "iod_samples", d.iod_samples,
        f"real measurements used by the initial orbit determination (3..{MAX_IOD_SAMPLES})",
        lambda v: None if isinstance(v, int) and 3 <= v <= MAX_IOD_SAMPLES
        else f"must be an integer in 3..{MAX_IOD_SAMPLES}",
        apply=runtime("iod_samples"))
    values["iod_max_span"] = declare(
        node, "iod_max_span", d.iod_max_span,
        "s one IOD batch may span (one pass of one station); later, another station's or "
        "another kind's measurement starts a new batch (0 = no limit)",
        non_negative, apply=runtime("iod_max_span"))
    values["reinit_after"] = declare(
        node, "reinit_after", d.reinit_after,
        "real measurements in a row beyond the gate after which the filter forgets its state "
        "and initialises again (0 = never)",
        lambda v: None if isinstance(v, int) and v >= 0 else "must be an integer >= 0",
        apply=runtime("reinit_after"))
    values["sigma_bound"] = declare(
        node, "sigma_bound", d.sigma_bound,
        "after each prediction, position sigmas are limited to sigma_bound x |position| and "
        "velocity sigmas to sigma_bound x |velocity| (2: the orbit's diameter; 0 = no limit)",
        non_negative, apply=runtime("sigma_bound"))
    values["light_time"] = declare(
        node, "light_time", d.light_time,
        "correct the station measurement models for light time (range / c)")
    values["refraction"] = declare(
        node, "refraction", d.refraction,
        "radar elevations as the atmosphere refracts them (Saemundsson's standard-atmosphere "
        "formula, core.refraction); off: geometric elevations")
    def consistent(v: dict[str, Any]) -> str | None:
        try:
            settings.estimator_from(v, {})
        except ValueError as exc:
            return str(exc)
        return None

    # every cross-parameter rule of the estimator, at start and on every run-time set
    cross_check(node, tuple(values), lambda v: consistent({**values, **v}))
    return settings.estimator_from(values, {})


class FilterNode(Node):
    def __init__(self) -> None:
        super().__init__("filter")
        self.config_pub = self.create_publisher(String, TOPIC_CONFIG, CONFIG_QOS)
        self.estimator = estimator_from(self)
        object_id = declare(self, "object_id", FILTER.object_id,
                            "only track this object ('' = any)")
        self.tracker = make_tracker(self.estimator, object_id)
        self.publish_config()
        self.predict_period = declare(
            self,
            "predict_period",
            FILTER.predict_period,
            "sim s: without an update for this long, predictions are published at every "
            "multiple of it (0 = never)",
            non_negative,
            apply=self._set_predict_period,
        )
        self.gap_forecast = declare(
            self, "gap_forecast", FILTER.gap_forecast,
            "what the predictions in a gap between passes are: none (the EKF coasting) | "
            "residual (the motion model plus its residual learned from past pass ends, "
            "core.residual; tagged update_source FORECAST; the EKF itself coasts on)",
            one_of("none", "residual"))
        self.gaps = self._gap_forecaster()
        self.max_lead = clock_lead(self, FILTER.max_clock_lead)
        self.diag = Diagnostics(self)
        self.clock_hold = ClockHold(self)
        self.pub = self.create_publisher(StateEstimateMsg, TOPIC_ESTIMATE, DATA_QOS)
        for topic, source in ((TOPIC_MEASUREMENT, Source.SENSOR),
                              (TOPIC_FORECAST, Source.FORECAST)):
            self.diag.subscribe(
                MeasurementMsg, topic,
                self.diag.guard(lambda msg, t=topic, s=source: self.on_measurement(msg, t, s)),
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
        self._prediction: StateEstimate | None = None  # and that prediction

    def _gap_forecaster(self) -> GapForecaster | None:
        if self.gap_forecast != "residual" or self.predict_period <= 0:
            return None
        return GapForecaster.for_model(str(self.estimator.motion_model), self.predict_period)

    def _set_predict_period(self, value: float) -> None:
        self.predict_period = value
        if self.gaps is not None and value > 0:  # keep the anchors; tabulate anew
            self.gaps.period_s = float(value)
            self.gaps.fitted_t = -math.inf
        else:
            self.gaps = self._gap_forecaster()

    def publish_config(self) -> None:
        """Publish the estimator settings in effect on /ssa/config (latched)."""
        if hasattr(self, "tracker"):
            self.config_pub.publish(String(data=settings.config_message(
                "filter", self.estimator.with_(tracker=self.tracker.config))))

    def on_jump(self, jump) -> None:
        self.tracker.reset()
        self.gaps = self._gap_forecaster()
        self._predicted_at = -math.inf
        self._prediction = None
        self.diag.count(
            Cause.RESET_CLOCK_JUMP, "sim time jumped backwards: filter reset", warn=False
        )

    def on_measurement(self, msg: MeasurementMsg, topic: str = TOPIC_MEASUREMENT,
                       source: int = Source.SENSOR) -> None:
        """Fuse one message of `topic`, which carries only `source` (sensor data on
        /ssa/measurement, forecasts on /ssa/forecast; anything else is rejected_source)."""
        self.activity += 1
        if msg.source != source:
            self.diag.count(Cause.REJECTED_SOURCE,
                            f"source {msg.source} on {topic}, which carries only source "
                            f"{int(source)} ({Source(source).name})")
            return
        if self.clock_hold.hold(msg, topic, source):
            return
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
        if m.source == Source.SENSOR:  # the gap's predictions before the measurement ending it
            self.predict_until(math.nextafter(m.t, -math.inf), 10 * PREDICTIONS_PER_TICK)
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
        if self.gaps is not None and e.update_source == UpdateSource.SENSOR:
            self.gaps.on_estimate(e.t, e.x, e.P)
        self.pub.publish(messages.estimate_to_msg(e))
        self.diag.counts[f"published_{SOURCE_NAMES[e.update_source]}"] += 1

    def predict(self) -> None:
        for held in self.clock_hold.release():
            self.on_measurement(*held)
        self.predict_until(self.get_clock().now().nanoseconds * 1e-9)

    def predict_until(self, now: float, limit: int = PREDICTIONS_PER_TICK) -> None:
        """Publish the predictions due on the `predict_period` grid up to sim time `now` (s).

        Called by the timer with the clock's time (at most `limit` predictions), and before a
        real measurement is fused with the epoch just before it (all that are due), so the
        grid through a gap is complete however fast sim time runs."""
        if self.predict_period <= 0:
            return
        if not self.tracker.initialised or self.tracker.t >= now - self.predict_period:
            return  # nothing to predict from, or recently updated
        epochs, skipped = prediction_epochs(max(self.tracker.t, self._predicted_at), now,
                                            self.predict_period, limit)
        if skipped:
            self.diag.count(Cause.PREDICTIONS_SKIPPED,
                            f"{skipped} prediction epochs skipped: sim time ran "
                            f"{now - self._predicted_at:.0f} s ahead", warn=False)
            self.diag.counts[Cause.PREDICTIONS_SKIPPED] += skipped - 1
        for t in epochs:  # on the grid of multiples of predict_period, chained
            last = self._prediction
            if last is not None and last.t >= self.tracker.t:
                e: StateEstimate | None = self.tracker.predict_from(last, t)
            else:
                e = self.tracker.predicted(t)
            if e is None:
                return
            f = self.gaps.forecast(t) if self.gaps is not None else None
            self.publish(e if f is None else StateEstimate(
                t=t, x=f[0], P=f[1], object_id=e.object_id,
                update_source=UpdateSource.FORECAST))
            self._predicted_at = t
            self._prediction = e  # the EKF's own prediction chain goes on


def main(args: list[str] | None = None) -> int:
    start_process()
    return run(FilterNode, args)


if __name__ == "__main__":
    raise SystemExit(main())
