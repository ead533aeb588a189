"""sensor_sim: simulate a tracked satellite and its sensors, and drive sim time.

Propagates the scenario's true orbit (two-body + J2, drag, or SGP4/SDP4), and publishes:

* ``/ssa/measurement`` (ssa_fusion_msgs/Measurement): what the sensors measured;
* ``/ssa/withheld``: what they would have measured during a scheduled outage (evaluation
  only);
* ``/ssa/truth`` (ssa_fusion_msgs/StateEstimate, zero covariance): the true state;
* ``/clock``: sim time, UTC (Unix seconds), advancing `time_scale` sim s per wall s.

A paper scenario (`sim.scenarios`) has one idealised sensor measuring at every epoch of
its cadence; a real-sky scenario (`sim.sky`) has stations that measure only above their
masks (optical ones only at night, of a sunlit object), at their own cadence during a pass,
and its truth keeps `cadence` through every gap. It exits 0 when the schedule is done. It is
the one node that uses the simulated world (`ssa_fusion.sim`): its scenarios and their
simulation are what it simulates.

    ros2 run ssa_fusion sensor_sim --ros-args -p scenario:=iss_j2_rae -p time_scale:=500.0
"""

from __future__ import annotations

import enum
import time
from typing import Any

import numpy as np
from builtin_interfaces.msg import Time as TimeMsg
from rclpy.duration import Duration
from rclpy.node import Node
from rosgraph_msgs.msg import Clock
from ssa_fusion_msgs.msg import Measurement as MeasurementMsg
from ssa_fusion_msgs.msg import StateEstimate as StateEstimateMsg

from ssa_fusion.core import catalog as catalog_io
from ssa_fusion.core import types
from ssa_fusion.core.frames import Frame
from ssa_fusion.nodes import start_process
from ssa_fusion.nodes.common import (
    Diagnostics,
    ParameterError,
    all_non_negative,
    declare,
    finish,
    non_negative,
    positive,
    run,
)
from ssa_fusion.nodes.defaults import SENSOR_SIM
from ssa_fusion.ros import messages
from ssa_fusion.ros.readiness import ReadyNodes, check_needs
from ssa_fusion.ros.topics import (
    CATALOG_QOS,
    DATA_QOS,
    TOPIC_CLOCK,
    TOPIC_MEASUREMENT,
    TOPIC_TRUTH,
    TOPIC_WITHHELD,
)
from ssa_fusion.sim import scenarios, sky, survey
from ssa_fusion.sim.simulate import simulate

ORBIT_SCENARIOS = [name for name, s in scenarios.SCENARIOS.items() if s.is_orbit]
SCENARIO_NAMES = [*ORBIT_SCENARIOS, *sky.SKY_SCENARIOS]
"""What the `scenario` parameter takes: the paper's orbit scenarios and the real-sky ones."""


class Event(enum.IntEnum):
    """What a scheduled publication is."""

    TRUTH = 0
    MEASUREMENT = 1
    WITHHELD = 2


Schedule = list[tuple[float, Event, types.Measurement | types.StateEstimate]]
"""Publications in epoch order: (epoch s, what, the message's content)."""


def paper_schedule(sim: Any, in_gap: np.ndarray, object_id: str) -> Schedule:
    """One measurement (or withheld one) and the truth at every epoch of a paper scenario."""
    s = sim.scenario
    out: Schedule = []
    for i, t in enumerate(sim.t.tolist()):
        m = types.Measurement(t=t, z=sim.z[i], R=sim.R, kind=s.kind, object_id=object_id,
                              frame_id=s.station or Frame.GCRF)
        out.append((t, Event.WITHHELD if in_gap[i] else Event.MEASUREMENT, m))
        out.append((t, Event.TRUTH, types.StateEstimate(t=t, x=sim.x[i], object_id=object_id)))
    return out


def sky_schedule(sim: sky.SkySimulation, object_id: str) -> Schedule:
    """The truth on its cadence and the stations' measurements, merged in epoch order."""
    out: Schedule = [(t, Event.TRUTH, types.StateEstimate(t=t, x=x, object_id=object_id))
                     for t, x in zip(sim.t.tolist(), sim.x, strict=True)]
    for m, w in zip(sim.measurements, sim.withheld, strict=True):
        m.object_id = object_id
        out.append((m.t, Event.WITHHELD if w else Event.MEASUREMENT, m))
    out.sort(key=lambda e: (e[0], -e[1]))  # at one epoch: measurements before the truth
    return out


def _or(default: Any, scenario_value: Any) -> Any:
    """A default of `defaults.SENSOR_SIM`, or the scenario's value where it is None."""
    return scenario_value if default is None else default


def _scenario_check(value: str) -> str | None:
    return None if value in SCENARIO_NAMES else f"unknown scenario; known: {SCENARIO_NAMES}"


def _gaps_check(value: list) -> str | None:
    if len(value) % 2:
        return "needs pairs [start_s, length_s, ...]"
    if not all_non_negative(value):
        return "starts and lengths must be finite numbers >= 0"
    return None


def _noise_check(value: list) -> str | None:
    if list(value) == [-1.0] or (len(value) == 3 and all_non_negative(value)):
        return None
    return "needs 3 values, each a finite number >= 0 (or [-1.0])"


def _count_check(value: Any) -> str | None:
    return None if isinstance(value, int) and value >= 0 else "must be an integer >= 0"


def _wait_check(value: list) -> str | None:
    for item in value:
        topic, _, count = item.partition("=")
        if not topic.startswith("/") or not count.isdigit():
            return f"{item!r} is not '/topic=count'"
    return None


class SensorSim(Node):
    def __init__(self) -> None:
        super().__init__("sensor_sim")
        name = declare(
            self,
            "scenario",
            SENSOR_SIM.scenario,
            "orbit scenario (truth model, orbit, measurement kind)",
            _scenario_check,
        )
        real_sky = sky.SKY_SCENARIOS.get(name)
        base = scenarios.get(name) if real_sky is None else scenarios.DEFAULT_LIVE
        d = SENSOR_SIM
        self.object_id = declare(self, "object_id", _or(d.object_id, name),
                                 "object id put in every message")
        cadence = declare(self, "cadence", _or(d.cadence, base.cadence_s if real_sky is None
                                               else real_sky.truth_cadence_s),
                          "s between measurements (real sky: between truth samples)", positive)
        duration = declare(self, "duration", d.duration,
                           "real-sky scenarios: s of sim time (0 = the scenario's)", non_negative)
        track = declare(
            self,
            "gap_start",
            _or(d.gap_start, base.track_s),
            "s of tracking before the gap (ignored when 'gaps' is set)",
            non_negative,
        )
        gap = declare(self, "gap_length", _or(d.gap_length, base.gap_s), "s of the sensor outage",
                      non_negative)
        gaps = declare(
            self,
            "gaps",
            list(d.gaps),
            "optional list [start_s, length_s, ...] of "
            "outages after the start; [0.0] = use gap_start/gap_length",
            lambda v: None if list(v) == [0.0] else _gaps_check(v),
        )
        after = declare(self, "after_gap", _or(d.after_gap, base.after_s),
                        "s of tracking after the (last) gap", non_negative)
        noise = declare(
            self,
            "noise_sigma",
            list(d.noise_sigma),
            "measurement noise std per channel (m, or m, rad, rad for "
            "range/az/el); [-1.0] = the scenario's noise",
            _noise_check,
        )
        self.time_scale = declare(
            self, "time_scale", d.time_scale, "sim seconds per wall second", positive
        )
        seed = declare(self, "seed", d.seed, "noise random seed")
        self.wait_for = declare(
            self,
            "wait_for",
            list(d.wait_for),
            "start only when each '/topic=count' has that many "
            "subscribers (e.g. /ssa/measurement=3)",
            lambda v: _wait_check([x for x in v if x]),
        )
        self.wait_for_readers = [x for x in declare(
            self,
            "wait_for_readers",
            list(d.wait_for_readers),
            "start only when each 'node:/topic' reports a matched publisher on /diagnostics "
            "(e.g. filter:/ssa/measurement): the readers' side of the match exists too",
            lambda v: check_needs([x for x in v if x]),
        ) if x]
        self.readers = ReadyNodes(self)
        tick = declare(self, "tick", d.tick, "wall s between publication ticks", positive)
        catalog = declare(self, "catalog", d.catalog,
                          "element sets (TLE, 3LE, OMM XML/CSV) of the objects to simulate; "
                          "'' = the scenario's one object")
        objects = declare(self, "objects", d.objects,
                          "catalog: simulate the first N objects (0 = all)", _count_check)
        synthetic = declare(self, "synthetic", d.synthetic,
                            "catalog: spread its first element set into N objects on orbits "
                            "of the same regime (0 = the catalog's own objects)", _count_check)

        self.catalog: survey.Observations | None = None
        if catalog:
            if real_sky is None:
                raise ParameterError(f"parameter 'catalog' = {catalog!r}: needs a real-sky "
                                     f"scenario (its radars observe the catalog); known: "
                                     f"{list(sky.SKY_SCENARIOS)}")
            self.catalog, summary = self._catalog(real_sky, catalog, objects, synthetic,
                                                  duration, seed)
            self.schedule = []
            self.times = self.catalog.t
        elif real_sky is None:
            self.schedule, summary = self._paper(base, cadence, track, gap, gaps, after, noise,
                                                 seed)
        else:
            self.schedule, summary = self._sky(real_sky, cadence, duration, gaps, seed)
        if self.catalog is None:
            self.times = np.array([e[0] for e in self.schedule])
        if not self.times.size:
            raise ParameterError(f"scenario {name!r}: nothing to publish (no measurement and "
                                 "no truth epoch)")

        self.pub_clock = self.create_publisher(Clock, TOPIC_CLOCK, DATA_QOS)
        self.pub_meas = self.create_publisher(
            MeasurementMsg, TOPIC_MEASUREMENT, DATA_QOS if self.catalog is None else CATALOG_QOS)
        self.pub_withheld = self.create_publisher(MeasurementMsg, TOPIC_WITHHELD, DATA_QOS)
        self.pub_truth = self.create_publisher(StateEstimateMsg, TOPIC_TRUTH, DATA_QOS)
        self.sim_stamp = TimeMsg()  # the sim time last published on /clock (0: none yet)
        self.diag = Diagnostics(self, stamp=lambda: self.sim_stamp)  # sim time, like the rest
        self.next = 0
        self.finished = False
        self._next_wait_log = time.monotonic() + 5.0  # quiet while discovery runs
        self.wall0: float | None = None
        self.create_timer(tick, self.step)
        self.get_logger().info(f"{name}: {summary}, time scale {self.time_scale}x")

    def _paper(self, base: scenarios.Scenario, cadence: float, track: float, gap: float,
               gaps: list, after: float, noise: list, seed: int) -> tuple[Schedule, str]:
        """The schedule of a paper scenario with the node's overrides, and a log line."""
        gap_list = list(gaps) if list(gaps) != [0.0] else [track, gap]
        windows = [(gap_list[i], gap_list[i] + gap_list[i + 1]) for i in range(0, len(gap_list), 2)]
        last_end = max(end for _, end in windows)
        scenario = base.with_(
            cadence_s=cadence,
            track_s=gap_list[0],
            gap_s=gap_list[1],
            after_s=max(0.0, last_end + after - gap_list[0] - gap_list[1]),
        )
        if len(noise) == 3:
            scenario = scenario.with_(
                noise_sigma=tuple(
                    v / s for v, s in zip(noise, messages.z_scale(scenario.kind), strict=True)
                ),
                noise_rel=0.0,
            )
        try:
            sim = simulate(scenario, seed=seed)
        except ValueError as exc:
            raise ParameterError(f"cannot simulate scenario {base.name!r}: {exc}") from exc
        rel = sim.t - scenario.t0
        in_gap = np.zeros(len(rel), dtype=bool)
        for start, end in windows:
            in_gap |= (rel >= start) & (rel < end)
        return (paper_schedule(sim, in_gap, self.object_id),
                f"{len(sim.t)} epochs every {cadence} s, gaps {windows} s")

    def _sky(self, s: sky.SkyScenario, cadence: float, duration: float, gaps: list,
             seed: int) -> tuple[Schedule, str]:
        """The schedule of a real-sky scenario (`gaps`, if set: whole-network outages)."""
        s = s.with_(truth_cadence_s=cadence, duration_s=duration or s.duration_s)
        if list(gaps) != [0.0]:
            s = s.with_(outages=tuple((sky.ALL_STATIONS, gaps[i], gaps[i + 1])
                                      for i in range(0, len(gaps), 2)))
        sim = sky.simulate_sky(s, seed=seed, object_id=self.object_id)
        return (sky_schedule(sim, self.object_id),
                f"{len(sim.measurements)} measurements ({int(sim.withheld.sum())} withheld) "
                f"from {', '.join(s.sensors)} over {s.duration_s / 3600:g} h, truth every "
                f"{cadence} s, outages {list(s.outages)}")

    def _catalog(self, s: sky.SkyScenario, path: str, objects: int, synthetic: int,
                 duration: float, seed: int) -> tuple[survey.Observations, str]:
        """The measurements of a catalog by the scenario's radars (no truth topic: the truth
        is SGP4 of the catalog, recomputed by whoever scores the run)."""
        try:
            entries = catalog_io.read_catalog(path)
        except ValueError as exc:
            raise ParameterError(f"parameter 'catalog' = {path!r}: {exc}") from exc
        if synthetic:
            entries = survey.synthetic_catalog(entries[0], synthetic, seed=seed)
        if objects:
            entries = entries[:objects]
        radars = s.radars
        if not radars:
            raise ParameterError(f"scenario {s.name!r} has no radar to observe a catalog")
        t0 = survey.catalog_start(entries)
        span = duration or s.duration_s
        obs = survey.observe_catalog(entries, radars, t0, span, seed=seed)
        self.catalog_ids = list(obs.object_ids)
        self.catalog_R = [r.R for r in radars]
        return obs, (f"catalog {path}: {len(entries)} objects, {len(obs)} measurements from "
                     f"{', '.join(r.station.name for r in radars)} over {span / 3600:g} h "
                     f"from t0={t0:.0f}")

    def waiting_for(self) -> list[str]:
        """What start-up still waits for: '/topic=count' entries whose subscriber count is
        short (matched by this node's own publishers where it publishes the topic), then
        'node:/topic' entries not reported as matched on /diagnostics."""
        own = {p.topic_name: p for p in (self.pub_clock, self.pub_meas, self.pub_withheld,
                                         self.pub_truth)}
        short = []
        for item in self.wait_for:
            if not item:
                continue
            topic, _, count = item.partition("=")
            have = (own[topic].get_subscription_count() if topic in own
                    else self.count_subscribers(topic))
            if have < int(count):
                short.append(f"{item} (has {have})")
        return short + self.readers.unmatched(self.wait_for_readers)

    def ready(self) -> bool:
        missing = self.waiting_for()
        if missing and time.monotonic() >= self._next_wait_log:
            self._next_wait_log = time.monotonic() + 5.0
            self.get_logger().info(f"waiting for: {', '.join(missing)}")
        return not missing

    def step(self) -> None:
        if self.finished:
            return
        if self.wall0 is None:
            if not self.ready():
                return
            self.wall0 = time.monotonic()
            waited = any(self.wait_for) or bool(self.wait_for_readers)
            self.get_logger().info("subscribers matched; starting" if waited
                                   else "starting (no subscribers awaited: wait_for is empty)")
        times = self.times
        now = times[0] + (time.monotonic() - self.wall0) * self.time_scale
        stop = int(np.searchsorted(times, now, side="right"))
        publish = self.publish_event
        if self.catalog is not None:  # one clock per tick, ahead of the tick's measurements
            self.publish_clock(min(now, times[-1]))
            publish = self.publish_catalog
        for i in range(self.next, stop):
            publish(i)
        self.next = max(self.next, stop)
        self.publish_clock(min(now, times[-1]))
        if self.next >= len(times):
            self.done()

    def publish_clock(self, t: float) -> None:
        msg = Clock()
        msg.clock = messages.seconds_to_stamp(t)
        self.pub_clock.publish(msg)
        self.sim_stamp = msg.clock

    def publish_event(self, i: int) -> None:
        t, what, content = self.schedule[i]
        self.publish_clock(t)
        if what == Event.TRUTH:
            assert isinstance(content, types.StateEstimate)
            self.pub_truth.publish(messages.estimate_to_msg(content))
            return
        assert isinstance(content, types.Measurement)
        if what == Event.WITHHELD:
            self.pub_withheld.publish(messages.measurement_to_msg(content))
            self.diag.counts["withheld"] += 1
        else:
            self.pub_meas.publish(messages.measurement_to_msg(content))
            self.diag.counts["published"] += 1

    def publish_catalog(self, i: int) -> None:
        """Publish catalog measurement `i` (its epoch is at or before the clock published)."""
        obs = self.catalog
        assert obs is not None
        k = int(obs.sensor[i])
        m = types.Measurement(float(obs.t[i]), obs.z[i], self.catalog_R[k],
                              kind=types.Kind.RANGE_AZ_EL,
                              object_id=self.catalog_ids[int(obs.obj[i])],
                              frame_id=obs.sensors[k].station.name)
        self.pub_meas.publish(messages.measurement_to_msg(m))
        self.diag.counts["published"] += 1

    def done(self) -> None:
        self.finished = True
        for pub in (self.pub_meas, self.pub_withheld, self.pub_truth, self.pub_clock):
            pub.wait_for_all_acked(Duration(seconds=5.0))
        self.diag.publish()
        self.get_logger().info(
            f"schedule done: {self.diag.counts['published']} measurements, "
            f"{self.diag.counts['withheld']} withheld"
        )
        finish()


def main(args: list[str] | None = None) -> int:
    start_process()
    return run(SensorSim, args)


if __name__ == "__main__":
    raise SystemExit(main())
