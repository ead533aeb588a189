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
from functools import partial

from ssa_fusion.core.base.types import Cause, Measurement
from ssa_fusion.core.gaps import hankel_dmd
from ssa_fusion.core.gaps.estimator import EstimatorConfig, Lift, make_surrogate
from ssa_fusion.nodes import settings
from ssa_fusion.nodes.base import SsaNode
from ssa_fusion.nodes.defaults import SURROGATE
from ssa_fusion.nodes.diagnostics import Count
from ssa_fusion.nodes.parameters import (
    NON_NEGATIVE,
    POSITIVE,
    STATION_RULE_NAMES,
    Param,
    ParameterTable,
    ParamValue,
    Rule,
    Values,
    clock_lead,
    integer_in,
    measurement_stream,
    object_filter,
    one_of,
    sites_problem,
)
from ssa_fusion.ros import messages
from ssa_fusion.ros.interfaces import Measurement as MeasurementMsg
from ssa_fusion.ros.topics import DATA_QOS, DATA_WRITER_QOS, TOPIC_FORECAST, TOPIC_MEASUREMENT

MAX_DELAYS = 10_000
"""Most Hankel-DMD delays (a Hankel matrix of 10^4 x channels rows; with `cadence` 0 the
buffer's sample count is not known at start, so this bounds the fit's size)."""


def _fits(v: Values) -> str | None:
    """Return why the buffer cannot hold 2 x delays x cadence, or None."""
    delays, cadence, buffer = v["delays"], v["cadence"], v["buffer_length"]
    assert isinstance(delays, int | float) and isinstance(cadence, int | float)
    assert isinstance(buffer, int | float)
    if cadence > 0 and delays * cadence * 2 > buffer:
        return (f"needs a buffer of at least 2 x delays x cadence = {2 * delays * cadence} s, "
                f"but 'buffer_length' = {buffer} s")
    return None


PARAMETERS = ParameterTable("surrogate", (
    Param("buffer_length", SURROGATE.buffer_length,
          "real measurements kept for training (ten ISS orbits)", unit="s", check=POSITIVE,
          runtime=True),
    Param("retrain_period", SURROGATE.retrain_period,
          "refit at least this often while measurements arrive; 0 = never (every gap refits "
          "on the buffer up to the last real measurement anyway)", unit="sim s",
          check=NON_NEGATIVE, runtime=True),
    Param("delays", SURROGATE.delays, "Hankel-DMD time delays (two ISS orbits at 30 s)",
          unit="samples", check=integer_in(1, MAX_DELAYS), runtime=True),
    Param("rank", SURROGATE.rank, "Hankel-DMD rank; 0 = automatic (Gavish–Donoho)",
          check=NON_NEGATIVE, runtime=True),
    Param("max_horizon", SURROGATE.max_horizon,
          "nothing is forecast further than this after the last real measurement", unit="s",
          check=POSITIVE, runtime=True),
    Param("grace", SURROGATE.grace, "wait after a missed epoch before forecasting it "
          "(absorbs message latency)", unit="cadences", check=NON_NEGATIVE, runtime=True),
    Param("cadence", SURROGATE.cadence,
          "expected time between measurements; 0 = inferred from the buffered stamps",
          unit="s", check=NON_NEGATIVE, runtime=True),
    *measurement_stream(SURROGATE.kind, SURROGATE.station, SURROGATE.sites, "learns"),
    Param("lift", SURROGATE.lift,
          "what the DMD learns: `none` (the measurement itself) or `eci` (range/az/el "
          "lifted to the inertial (GCRF) position it implies, forecasts mapped back; needs "
          "`kind` `range_az_el`)", check=one_of(*map(str, Lift))),
    Param("check_period", SURROGATE.check_period, "period of the check for missed epochs",
          unit="wall s", check=POSITIVE),
    object_filter(SURROGATE.object_id, "learn"),
    clock_lead(SURROGATE.max_clock_lead),
), rules=(Rule(("delays", "cadence", "buffer_length"), _fits),
          Rule(STATION_RULE_NAMES, sites_problem),
          Rule(settings.SURROGATE_KEYS, partial(settings.estimator_problem, "surrogate"))))
"""The surrogate's parameters."""


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
        if m is None:
            return
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
