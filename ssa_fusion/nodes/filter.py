"""filter: EKF of one satellite with a Keplerian (default) or two-body + J2 motion model.

Initialises from its first real measurements (Herrick–Gibbs for range/az/el, finite
differences for position), then fuses real measurements from ``/ssa/measurement`` and,
for epochs without one, forecasts from ``/ssa/forecast``. Publishes ``/ssa/estimate``
(state + full 6x6 covariance, stamped with the measurement epoch) for every fused epoch,
and through a gap predictions or residual forecasts on the grid of multiples of
`predict_period`: what it publishes is `core.gaps.publisher.GapPublisher`'s policy, which
the offline replay (`ssa-fusion replay --offline`) follows too. Rejected input is counted by
cause on ``/diagnostics``. The settings in effect are published (latched) on
``/ssa/config``, so every bag records them. With ``lockstep`` it publishes its predictions
and gap forecasts only up to the time sensor_sim releases on ``/lockstep/decisions`` (after
the surrogate's forecasts of those epochs reached it), and reports its progress
(`nodes.kit.progress`). ``station`` names built-in stations
(`core.earth.stations`) or those of the ``sites`` file (`formats.sites`).

With ``kind`` laser_range it is the laser filter (`nodes.kit.laser`): the stations and the
object of its ``laser`` parameter, the object's high-fidelity forces, the stations' range
biases and Cr as states, started from its ``apriori`` orbit; it takes the stations'
meteorological records on ``/ssa/meteo``.

    ros2 run ssa_fusion filter --ros-args -p use_sim_time:=true -p kind:=range_az_el
"""

from __future__ import annotations

from functools import partial

from ssa_fusion.core.base.types import Cause, Kind, Source
from ssa_fusion.core.gaps.batch_gap import BatchGapForecaster
from ssa_fusion.core.gaps.estimator import EstimatorConfig, make_tracker
from ssa_fusion.core.gaps.fit_residual import FitResidualForecaster
from ssa_fusion.core.gaps.publisher import GapFill, GapPublisher, Published
from ssa_fusion.nodes.kit import laser
from ssa_fusion.nodes.kit.base import SsaNode
from ssa_fusion.nodes.kit.diagnostics import PUBLISHED_BY_SOURCE
from ssa_fusion.nodes.kit.progress import (
    DECIDED,
    NEXT_DECISION,
    PUBLISHED_ESTIMATES,
    RELEASE_QOS,
    TAKEN,
    TAKEN_FORECASTS,
    TOPIC_RELEASE_DECISIONS,
    ProgressReporter,
    time_ns,
)
from ssa_fusion.params import settings
from ssa_fusion.params.checks import ParamValue
from ssa_fusion.params.tables.filter import PARAMETERS
from ssa_fusion.ros import messages
from ssa_fusion.ros.interfaces import Clock
from ssa_fusion.ros.interfaces import Measurement as MeasurementMsg
from ssa_fusion.ros.interfaces import Meteo as MeteoMsg
from ssa_fusion.ros.interfaces import StateEstimate as StateEstimateMsg
from ssa_fusion.ros.qos import DATA_QOS, DATA_WRITER_QOS
from ssa_fusion.ros.topics import TOPIC_ESTIMATE, TOPIC_FORECAST, TOPIC_MEASUREMENT, TOPIC_METEO

TICK_S = 0.1
"""Wall s between two publications of the predictions due (at most 100 each)."""


class FilterNode(SsaNode):
    """The filter node: messages in, `GapPublisher` (tracker + gap policy), estimates out."""

    PARAMETERS = PARAMETERS

    def __init__(self) -> None:
        super().__init__()
        self.estimator = self._estimator()
        self.tracker = make_tracker(self.estimator, self.params.text("object_id"))
        if self.estimator.kind == Kind.LASER_RANGE:
            laser.start(self.tracker, self.estimator, self.params.values)
            self.subscribe(MeteoMsg, TOPIC_METEO, partial(laser.on_meteo, self.tracker),
                           DATA_QOS)
        self.gaps = GapPublisher.of(self.tracker, self.params.number("predict_period"),
                                    GapFill(self.params.text("gap_forecast")), self.estimator)
        self.publish_config()
        self.pub = self.advertise(StateEstimateMsg, TOPIC_ESTIMATE, DATA_WRITER_QOS)
        for topic, source in ((TOPIC_MEASUREMENT, Source.SENSOR),
                              (TOPIC_FORECAST, Source.FORECAST)):
            self.subscribe(MeasurementMsg, topic,
                           partial(self.on_measurement, topic=topic, source=source), DATA_QOS)
        self.wall_timer(TICK_S, self.predict)
        self.reset_on_backward_jump(self.gaps.reset, "filter reset")
        self.decided_ns = 0
        self.progress: ProgressReporter | None = None
        if self.params.flag("lockstep"):
            self.subscribe(Clock, TOPIC_RELEASE_DECISIONS, self.on_release, RELEASE_QOS)
            self.run_clock.listen(lambda _data, _t: self.report())
            self.progress = ProgressReporter(self, self.counters)

    def counters(self) -> dict[str, int | str]:
        """Return the lockstep progress: what it took, published and decided, and will."""
        return {TAKEN: self.handled[TOPIC_MEASUREMENT],
                TAKEN_FORECASTS: self.handled[TOPIC_FORECAST],
                PUBLISHED_ESTIMATES: sum(self.diag.counts[k] for k in PUBLISHED_BY_SOURCE),
                DECIDED: self.decided_ns, NEXT_DECISION: time_ns(self.gaps.next_decision())}

    def on_release(self, msg: Clock) -> None:
        """Publish what is decided up to the time released (lockstep), and say so."""
        self.replay_held()
        self.publish(self.gaps.advance(messages.stamp_to_seconds(msg.clock)))
        self.decided_ns = msg.clock.sec * 1_000_000_000 + msg.clock.nanosec
        self.report()

    def report(self) -> None:
        """Report the lockstep progress now (lockstep only)."""
        if self.progress is not None:
            self.progress.nudge()

    def _estimator(self) -> EstimatorConfig:
        """Return the estimator settings of the parameters in effect (core units)."""
        c = settings.node_estimator("filter", self.params.values)
        return laser.laser_estimator(self.params.values) if c.kind == Kind.LASER_RANGE else c

    def on_parameters_set(self, changed: dict[str, ParamValue]) -> None:
        """Put new tuning values or a new `predict_period` into effect (and record them)."""
        estimator = bool(changed.keys() & set(settings.FILTER_KEYS))
        if estimator:
            self.estimator = self._estimator()
            self.tracker.config = self.estimator.filter
        if "predict_period" in changed:
            self.gaps.set_period(self.params.number("predict_period"))
        if estimator or "predict_period" in changed:
            self.publish_config()

    def publish_config(self) -> None:
        """Publish the settings in effect on /ssa/config (latched)."""
        self.publish_settings(settings.config_message(
            "filter", self.estimator, settings.gap_params(self.params.values)))

    def on_measurement(self, msg: MeasurementMsg, topic: str, source: Source) -> None:
        """Fuse one message of `topic`, which carries only `source`.

        Sensor data on /ssa/measurement, forecasts on /ssa/forecast; anything else is
        ``rejected_source``.
        """
        if msg.source != source:
            self.diag.count(Cause.REJECTED_SOURCE,
                            f"source {msg.source} on {topic}, which carries only source "
                            f"{int(source)} ({Source(source).name})")
            self.handled[topic] += 1
            self.report()
            return
        again = partial(self.on_measurement, msg, topic, source)
        m = self.measurement_in(msg, again, self.tracker.object_id, topic)
        if m is not None:
            self.publish(self.gaps.measurement(m))
        self.report()

    def predict(self) -> None:
        """Take what waited for the clock; publish the predictions due by the clock.

        In lockstep the predictions wait for their release (`on_release`).
        """
        self.replay_held()
        if self.progress is None:
            self.publish(self.gaps.advance(self.now_s()))

    def publish(self, out: Published) -> None:
        """Publish `out`'s estimates; count what the tracker refused and what was skipped."""
        if out.skipped:
            self.diag.count(Cause.PREDICTIONS_SKIPPED,
                            f"{out.skipped} prediction epochs skipped: sim time ran "
                            f"{out.ran_ahead_s:.0f} s ahead")
            self.diag.counts[Cause.PREDICTIONS_SKIPPED] += out.skipped - 1
        if out.outcome is not None:
            rejected = Cause(out.outcome.rejected) if out.outcome.rejected else None
            if rejected == Cause.IOD_PENDING:
                self.diag.counts[rejected] += 1
            elif rejected is not None:
                self.diag.count(rejected, out.outcome.detail)
            if out.outcome.rolled_back:
                self.diag.counts[Cause.FORECASTS_ROLLED_BACK] += out.outcome.rolled_back
        for e in out.estimates:
            self.pub.publish(messages.estimate_to_msg(e))
            self.diag.counts[PUBLISHED_BY_SOURCE[e.update_source]] += 1
        f = self.gaps.forecaster
        if isinstance(f, BatchGapForecaster):
            self.diag.status["gap_covariance_factor"] = f"{f.scale.factor(0.0)[0]:.3g}"
        if isinstance(f, FitResidualForecaster):
            for choice, n in f.choices.items():
                self.diag.status[f"gap_{choice}"] = str(n)


def main(args: list[str] | None = None) -> int:
    """Run the filter node (``ros2 run ssa_fusion filter``)."""
    return FilterNode.main(args)


if __name__ == "__main__":
    raise SystemExit(main())
