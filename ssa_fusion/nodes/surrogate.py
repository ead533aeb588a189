"""surrogate: learn the measurement stream with Hankel-DMD and forecast it through gaps.

Keeps a sliding buffer of real measurements from ``/ssa/measurement``, retrains on it, and
publishes on ``/ssa/forecast`` one forecast measurement (source FORECAST) for each epoch
the sensor missed, with a covariance that grows with the horizon; never past
`max_horizon`. A backwards jump of sim time (a looping bag) empties the buffer. If it
cannot fit, it publishes nothing and says why on ``/diagnostics``. It learns only
measurements of its `kind` from its `station` (frame_id), and of `object_id` if set; others,
bad values and stamps more than `max_clock_lead` ahead of its clock are counted by cause and
never trained on. With ``lockstep`` it forecasts the epochs it missed only up to the time
sensor_sim releases on ``/lockstep/forecasts`` (without `grace`: every real measurement up
to then has reached it), and reports its progress (`nodes.kit.progress`).

    ros2 run ssa_fusion surrogate --ros-args -p use_sim_time:=true -p kind:=range_az_el
"""

from __future__ import annotations

from dataclasses import replace
from functools import partial

from ssa_fusion.core.base.types import Cause, Measurement
from ssa_fusion.core.gaps import hankel_dmd
from ssa_fusion.core.gaps.estimator import EstimatorConfig, make_surrogate
from ssa_fusion.nodes.kit.base import SsaNode
from ssa_fusion.nodes.kit.diagnostics import Count
from ssa_fusion.nodes.kit.progress import (
    NEXT_DUE,
    RELEASE_QOS,
    RELEASED,
    TAKEN,
    TOPIC_RELEASE_FORECASTS,
    ProgressReporter,
    time_ns,
)
from ssa_fusion.params import settings
from ssa_fusion.params.checks import ParamValue
from ssa_fusion.params.tables.surrogate import PARAMETERS
from ssa_fusion.ros import messages
from ssa_fusion.ros.interfaces import Clock
from ssa_fusion.ros.interfaces import Measurement as MeasurementMsg
from ssa_fusion.ros.qos import DATA_QOS, DATA_WRITER_QOS
from ssa_fusion.ros.topics import TOPIC_FORECAST, TOPIC_MEASUREMENT


class SurrogateNode(SsaNode):
    """The surrogate node: measurements in, `core.gaps.surrogate.Surrogate`, forecasts out."""

    PARAMETERS = PARAMETERS

    def __init__(self) -> None:
        super().__init__()
        self.estimator = self._estimator()
        self.core = make_surrogate(self.estimator)
        hankel_dmd.warm_up()  # the first fit, in the first gap, not late by an import
        self.publish_config()
        self.pub = self.advertise(MeasurementMsg, TOPIC_FORECAST, DATA_WRITER_QOS)
        self.subscribe(MeasurementMsg, TOPIC_MEASUREMENT, self.on_measurement, DATA_QOS)
        self.wall_timer(self.params.number("check_period"), self.publish_missed)
        self.reset_on_backward_jump(self.core.reset, "buffer emptied")
        self.released_ns = 0
        self.progress: ProgressReporter | None = None
        if self.params.flag("lockstep"):
            self.subscribe(Clock, TOPIC_RELEASE_FORECASTS, self.on_release, RELEASE_QOS)
            self.run_clock.listen(lambda _data, _t: self.report())
            self.progress = ProgressReporter(self, lambda: {
                TAKEN: self.handled[TOPIC_MEASUREMENT],
                Count.FORECASTS: self.diag.counts[Count.FORECASTS],
                RELEASED: self.released_ns, NEXT_DUE: time_ns(self.core.next_due())})

    def on_release(self, msg: Clock) -> None:
        """Forecast the epochs missed up to the time released (lockstep), and say so."""
        self.replay_held()
        self.publish(self.core.due_through(messages.stamp_to_seconds(msg.clock)))
        self.released_ns = msg.clock.sec * 1_000_000_000 + msg.clock.nanosec
        self.report()

    def report(self) -> None:
        """Report the lockstep progress now (lockstep only)."""
        if self.progress is not None:
            self.progress.nudge()

    def _estimator(self) -> EstimatorConfig:
        """Return the estimator settings of the parameters in effect (core units)."""
        return settings.node_estimator("surrogate", self.params.values)

    def on_parameters_set(self, changed: dict[str, ParamValue]) -> None:
        """Put new model settings into effect at the next fit (and record them)."""
        if changed.keys() & set(settings.SURROGATE_KEYS):
            self.estimator = self._estimator()
            current = self.core.config
            self.core.config = replace(self.estimator.surrogate, kind=current.kind,
                                       frame_id=current.frame_id, lift=current.lift)
            self.publish_config()

    def publish_config(self) -> None:
        """Publish the estimator settings in effect on /ssa/config (latched)."""
        surrogate = replace(self.core.config, lift=None)
        self.publish_settings(settings.config_message(
            "surrogate", self.estimator.with_(surrogate=surrogate)))

    def on_measurement(self, msg: MeasurementMsg) -> None:
        """Learn one real measurement (and publish the forecasts it releases)."""
        again = partial(self.on_measurement, msg)
        m = self.measurement_in(msg, again, self.params.text("object_id"))
        if m is not None:
            self.learn(m)
        self.report()

    def learn(self, m: Measurement) -> None:
        """Buffer real measurement `m` (publish the forecasts it releases), or count why not."""
        forecasts = self.core.add(m)
        cause, reason = self.core.rejected
        if cause:  # never trained on: it would stop every fit or empty the buffer
            self.diag.count(Cause(cause), reason)
            return
        self.publish(forecasts)
        self.diag.counts[Count.BUFFERED] += 1

    def publish_missed(self) -> None:
        """Take what waited for the clock; publish the forecasts of the epochs missed."""
        self.replay_held()
        if self.progress is None:  # in lockstep: at the releases
            self.publish(self.core.due(self.now_s()))
        if self.core.invalid > self.diag.counts[Cause.FORECAST_INVALID]:
            self.diag.count(Cause.FORECAST_INVALID, self.core.status)
            self.diag.counts[Cause.FORECAST_INVALID] = self.core.invalid
        self.diag.status["model"] = self.core.status

    def publish(self, forecasts: list[Measurement]) -> None:
        """Publish `forecasts` on /ssa/forecast."""
        for f in forecasts:
            self.pub.publish(messages.measurement_to_msg(f))
            self.diag.counts[Count.FORECASTS] += 1


def main(args: list[str] | None = None) -> int:
    """Run the surrogate node (``ros2 run ssa_fusion surrogate``)."""
    return SurrogateNode.main(args)


if __name__ == "__main__":
    raise SystemExit(main())
