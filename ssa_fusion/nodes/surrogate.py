"""surrogate: learn the measurement stream with Hankel-DMD and forecast it through gaps.

Keeps a sliding buffer of real measurements from ``/ssa/measurement``, retrains on it, and
publishes on ``/ssa/forecast`` one forecast measurement (source FORECAST) for each epoch
the sensor missed, with a covariance that grows with the horizon; never past
`max_horizon`. A backwards jump of sim time (a looping bag) empties the buffer. If it
cannot fit, it publishes nothing and says why on ``/diagnostics``. It learns only
measurements of its `kind` from its `station` (frame_id), and of `object_id` if set; others,
bad values and stamps more than `max_clock_lead` ahead of its clock are counted by cause and
never trained on.

    ros2 run ssa_fusion surrogate --ros-args -p use_sim_time:=true -p kind:=range_az_el
"""

from __future__ import annotations

from dataclasses import replace
from typing import Any

from rclpy.clock import JumpThreshold
from rclpy.duration import Duration
from rclpy.node import Node
from ssa_fusion_msgs.msg import Measurement as MeasurementMsg
from std_msgs.msg import String

from ssa_fusion.core.config import EstimatorConfig, Lift, make_surrogate
from ssa_fusion.core.types import Cause
from ssa_fusion.core.validation import ahead_of_clock
from ssa_fusion.nodes import settings, start_process
from ssa_fusion.nodes.common import (
    ClockHold,
    Diagnostics,
    ParameterError,
    clock_lead,
    cross_check,
    declare,
    measurement_stream,
    non_negative,
    one_of,
    positive,
    run,
    wall_timer,
)
from ssa_fusion.nodes.defaults import SURROGATE
from ssa_fusion.ros import messages
from ssa_fusion.ros.topics import (
    CONFIG_QOS,
    DATA_QOS,
    TOPIC_CONFIG,
    TOPIC_FORECAST,
    TOPIC_MEASUREMENT,
)

MAX_DELAYS = 10_000
"""Most Hankel-DMD delays (a Hankel matrix of 10^4 x channels rows; with `cadence` 0 the
buffer's sample count is not known at start, so this bounds the fit's size)."""

def estimator_from(node: Node) -> EstimatorConfig:
    """Declare the surrogate's estimator parameters on `node` (defaults:
    `defaults.SURROGATE`) and return its `EstimatorConfig` (core units, via
    `settings.estimator_from`). Model settings can be changed at run time (`ros2 param
    set`): the new value goes through the same translation into ``node.core.config``
    (published on /ssa/config) and takes effect at the next fit."""
    d = SURROGATE
    values: dict[str, Any] = {}

    def fits(v: dict[str, Any]) -> str | None:
        """The buffer must hold 2 x delays x cadence (checked at start and on every set)."""
        if v["cadence"] > 0 and v["delays"] * v["cadence"] * 2 > v["buffer_length"]:
            return (f"needs a buffer of at least 2 x delays x cadence = "
                    f"{2 * v['delays'] * v['cadence']} s, but 'buffer_length' = "
                    f"{v['buffer_length']} s")
        return None

    def setting(name: str, description: str, check: Any) -> Any:
        def apply(value: Any) -> None:
            values[name] = value
            node.estimator = settings.estimator_from({}, values)
            current = node.core.config
            node.core.config = replace(node.estimator.surrogate, kind=current.kind,
                                       frame_id=current.frame_id, lift=current.lift)
            node.publish_config()

        values[name] = declare(node, name, getattr(d, name), description, check, apply=apply)
        return values[name]

    setting("buffer_length", "s of real measurements kept for training", positive)
    setting("retrain_period",
            "sim s between refits while measurements arrive; 0 = none (every gap refits on "
            "the buffer up to the last real measurement anyway)", non_negative)
    setting("delays", f"Hankel-DMD time delays (1..{MAX_DELAYS})",
            lambda v: None if isinstance(v, int) and 1 <= v <= MAX_DELAYS
            else f"must be an integer in 1..{MAX_DELAYS}")
    setting("rank", "Hankel-DMD rank (0 = automatic)", non_negative)
    setting("max_horizon", "s after the last real measurement beyond which nothing is "
            "forecast", positive)
    setting("grace", "cadences after a missed epoch before it is forecast (absorbs message "
            "latency)", non_negative)
    setting("cadence", "expected s between measurements (0 = infer from the buffer)",
            non_negative)
    cross_check(node, ("delays", "cadence", "buffer_length"), fits)
    measurement_stream(node, d)
    values["kind"] = node.get_parameter("kind").value
    values["station"] = node.get_parameter("station").value
    values["lift"] = declare(
        node,
        "lift",
        d.lift,
        "observable the DMD learns: none (the measurement itself) or eci (range/az/el "
        "lifted to the inertial (GCRF) position it implies, forecasts mapped back)",
        one_of(*map(str, Lift)),
    )
    try:
        return settings.estimator_from({}, values)
    except ValueError as exc:
        raise ParameterError(str(exc)) from exc


class SurrogateNode(Node):
    def __init__(self) -> None:
        super().__init__("surrogate")
        self.config_pub = self.create_publisher(String, TOPIC_CONFIG, CONFIG_QOS)
        self.estimator = estimator_from(self)
        self.core = make_surrogate(self.estimator)
        self.publish_config()
        check = declare(
            self, "check_period", SURROGATE.check_period, "wall s between checks for missed epochs",
            positive,
        )
        self.object_id = declare(self, "object_id", SURROGATE.object_id,
                                 "only learn this object ('' = any)")
        self.max_lead = clock_lead(self, SURROGATE.max_clock_lead)
        self.diag = Diagnostics(self)
        self.clock_hold = ClockHold(self)
        self.pub = self.create_publisher(MeasurementMsg, TOPIC_FORECAST, DATA_QOS)
        self.diag.subscribe(
            MeasurementMsg, TOPIC_MEASUREMENT, self.diag.guard(self.on_measurement), DATA_QOS
        )
        wall_timer(self, check, self.diag.guard(self.check))
        self._jump = self.get_clock().create_jump_callback(
            JumpThreshold(
                min_forward=None, min_backward=Duration(nanoseconds=-1), on_clock_change=False
            ),
            post_callback=self.on_jump,
        )
        self.activity = 0

    def publish_config(self) -> None:
        """Publish the estimator settings in effect on /ssa/config (latched)."""
        if hasattr(self, "core"):
            surrogate = replace(self.core.config, lift=None)
            self.config_pub.publish(String(data=settings.config_message(
                "surrogate", self.estimator.with_(surrogate=surrogate))))

    def on_jump(self, jump) -> None:
        self.core.reset()
        self.diag.count(
            Cause.RESET_CLOCK_JUMP, "sim time jumped backwards: buffer emptied", warn=False
        )

    def on_measurement(self, msg: MeasurementMsg) -> None:
        self.activity += 1
        if self.clock_hold.hold(msg):
            return
        if self.object_id and msg.object_id != self.object_id:
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
        forecasts = self.core.add(m)
        if self.core.rejected[0]:  # never trained on: it would stop every fit or empty the buffer
            self.diag.count(*self.core.rejected)
            return
        self.publish(forecasts)
        self.diag.counts["buffered"] += 1

    def check(self) -> None:
        for held in self.clock_hold.release():
            self.on_measurement(*held)
        now = self.get_clock().now().nanoseconds * 1e-9
        self.publish(self.core.due(now))
        if self.core.invalid > self.diag.counts[Cause.FORECAST_INVALID]:
            self.diag.count(Cause.FORECAST_INVALID, self.core.status)
            self.diag.counts[Cause.FORECAST_INVALID] = self.core.invalid
        self.diag.status["model"] = self.core.status

    def publish(self, forecasts: list) -> None:
        for f in forecasts:
            self.pub.publish(messages.measurement_to_msg(f))
            self.diag.counts["forecasts"] += 1


def main(args: list[str] | None = None) -> int:
    start_process()
    return run(SurrogateNode, args)


if __name__ == "__main__":
    raise SystemExit(main())
