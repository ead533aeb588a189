"""sensor_sim: simulate a tracked satellite and its sensors, and drive sim time.

Propagates the scenario's true orbit (two-body + J2, drag, or SGP4/SDP4), and publishes:

* ``/ssa/measurement`` (ssa_fusion_msgs/Measurement): what the sensors measured; for a
  catalog ``/ssa/measurement_batch`` (ssa_fusion_msgs/MeasurementBatch) instead: per step
  (lockstep) or tick (open loop) one batch per shard key range of `shards`;
* ``/ssa/withheld``: what they would have measured during a scheduled outage (evaluation
  only);
* ``/ssa/detection_truth``: a catalog run with `unlabelled`: the detections with their true
  object ids (evaluation only; the measurement batches carry none: `core.catalog.unlabelled`);
* ``/ssa/truth`` (ssa_fusion_msgs/StateEstimate, zero covariance): the true state;
* ``/clock``: sim time, UTC (Unix seconds), advancing `time_scale` sim s per wall s; for
  a catalog with ``lockstep`` consumers, by ``lockstep_step`` once they have taken the last
  step's measurements, `time_scale` being a ceiling (`nodes.progress`).

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

import numpy as np
from rclpy.duration import Duration

from ssa_fusion.core.base import types
from ssa_fusion.core.base.rows import MeasurementRows
from ssa_fusion.core.catalog.unlabelled import without_labels
from ssa_fusion.core.earth import timescales
from ssa_fusion.core.earth.frames import Frame
from ssa_fusion.core.measure.validation import MAX_CLOCK_LEAD_S
from ssa_fusion.formats import element_sets as catalog_io
from ssa_fusion.nodes import parameters
from ssa_fusion.nodes.base import SsaNode
from ssa_fusion.nodes.defaults import SENSOR_SIM
from ssa_fusion.nodes.diagnostics import Count
from ssa_fusion.nodes.parameters import (
    NON_NEGATIVE,
    POSITIVE,
    SITES,
    Check,
    Computed,
    Param,
    ParameterTable,
    ParamValue,
    Rule,
    Values,
    all_non_negative,
    at_least,
    one_of,
    read_by,
)
from ssa_fusion.nodes.process import finish
from ssa_fusion.nodes.progress import Lockstep
from ssa_fusion.nodes.shards import shard_range
from ssa_fusion.ros import messages
from ssa_fusion.ros.interfaces import Clock, MeasurementBatch, Time
from ssa_fusion.ros.interfaces import Measurement as MeasurementMsg
from ssa_fusion.ros.interfaces import StateEstimate as StateEstimateMsg
from ssa_fusion.ros.readiness import ReadyNodes, check_needs
from ssa_fusion.ros.topics import (
    CATALOG_WRITER_QOS,
    DATA_QOS,
    DATA_WRITER_QOS,
    TOPIC_CLOCK,
    TOPIC_DETECTION_TRUTH,
    TOPIC_MEASUREMENT,
    TOPIC_MEASUREMENT_BATCH,
    TOPIC_TRUTH,
    TOPIC_WITHHELD,
)
from ssa_fusion.sim import scenarios, sky, survey
from ssa_fusion.sim.simulate import Simulation, simulate

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


def paper_schedule(sim: Simulation, in_gap: np.ndarray, object_id: str) -> Schedule:
    """Return a measurement (or a withheld one) and the truth per epoch of a paper scenario."""
    s = sim.scenario
    out: Schedule = []
    for i, t in enumerate(sim.t.tolist()):
        m = types.Measurement(t=t, z=sim.z[i], R=sim.R, kind=s.kind, object_id=object_id,
                              frame_id=s.station or Frame.GCRF)
        out.append((t, Event.WITHHELD if in_gap[i] else Event.MEASUREMENT, m))
        out.append((t, Event.TRUTH, types.StateEstimate(t=t, x=sim.x[i], object_id=object_id)))
    return out


def sky_schedule(sim: sky.SkySimulation, object_id: str) -> Schedule:
    """Return the truth on its cadence and the stations' measurements in epoch order."""
    out: Schedule = [(t, Event.TRUTH, types.StateEstimate(t=t, x=x, object_id=object_id))
                     for t, x in zip(sim.t.tolist(), sim.x, strict=True)]
    for m, w in zip(sim.measurements, sim.withheld, strict=True):
        m.object_id = object_id
        out.append((m.t, Event.WITHHELD if w else Event.MEASUREMENT, m))
    out.sort(key=lambda e: (e[0], -e[1]))  # at one epoch: measurements before the truth
    return out


def _scenario(values: Values) -> tuple[scenarios.Scenario, sky.SkyScenario | None]:
    """Return the paper scenario of the chosen ``scenario``, and the real-sky one or None.

    For a real-sky scenario, the paper scenario is the default live one.
    """
    name = str(values["scenario"])
    real_sky = sky.SKY_SCENARIOS.get(name)
    return (scenarios.get(name) if real_sky is None else scenarios.DEFAULT_LIVE), real_sky


def _cadence(values: Values) -> float:
    """Return the chosen scenario's cadence (real sky: of its truth samples), s."""
    base, real_sky = _scenario(values)
    return base.cadence_s if real_sky is None else real_sky.truth_cadence_s


def _from_scenario(field: str) -> Computed:
    """Return the default of a paper scenario's `field` (s)."""
    def compute(values: Values) -> float:
        return float(getattr(_scenario(values)[0], field))

    default = float(getattr(scenarios.get(SENSOR_SIM.scenario), field))
    return Computed(compute, f"the scenario's ({default:g})", default)


def _gaps(value: ParamValue) -> str | None:
    if not isinstance(value, list) or value == [0.0]:
        return None
    if len(value) % 2:
        return "needs pairs [start_s, length_s, ...]"
    if not all_non_negative(value):
        return "starts and lengths must be finite numbers >= 0"
    return None


def _noise(value: ParamValue) -> str | None:
    if value == [-1.0] or (isinstance(value, list) and len(value) == 3
                           and all_non_negative(value)):
        return None
    return "needs 3 values, each a finite number >= 0 (or [-1.0])"


def _wait(value: ParamValue) -> str | None:
    assert isinstance(value, list)
    for item in value:
        topic, _, count = str(item).partition("=")
        if item and (not topic.startswith("/") or not count.isdigit()):
            return f"{item!r} is not '/topic=count'"
    return None


def _readers(value: ParamValue) -> str | None:
    assert isinstance(value, list)
    return check_needs([str(x) for x in value if x])


def _needs_sky(name: str, why: str) -> Rule:
    """Return the rule that parameter `name`, when set, needs a real-sky `scenario` (`why`)."""
    def test(values: Values) -> str | None:
        if values[name] and values["scenario"] not in sky.SKY_SCENARIOS:
            return f"needs a real-sky scenario ({why}); known: {list(sky.SKY_SCENARIOS)}"
        return None

    return Rule((name, "scenario"), test)


def _one_object_or_a_catalog(values: Values) -> str | None:
    if values["elements"] and values["catalog"]:
        return "one object or a catalog: not both (`catalog` simulates every object)"
    return None


def _step(value: ParamValue) -> str | None:
    ok = isinstance(value, float) and 0.0 < value <= MAX_CLOCK_LEAD_S / 2
    return None if ok else f"must be in (0, {MAX_CLOCK_LEAD_S / 2:g}]"


def _unlabelled_needs_a_catalog_of_one_shard(values: Values) -> str | None:
    if not values["unlabelled"]:
        return None
    if not values["catalog"]:
        return "unlabelled detections are a catalog's (`catalog`)"
    if values["shards"] != 1:
        return ("unlabelled detections carry no object id to route them by: one filter "
                "shard takes them all (`shards` 1)")
    return None


def _lockstep_needs_a_catalog(values: Values) -> str | None:
    names = values["lockstep"]
    assert isinstance(names, list)
    if any(names) and not values["catalog"]:
        return "lockstep is for catalog runs (`catalog`): their consumers report progress"
    return None


DEFAULT_CADENCE = _cadence({"scenario": SENSOR_SIM.scenario})
"""The default scenario's cadence, s."""

PARAMETERS = ParameterTable("sensor_sim", (
    Param("scenario", SENSOR_SIM.scenario,
          "orbit scenario (truth model, orbit, measurement kind, noise): a paper one (see "
          "`sim/scenarios.py`) or a real-sky one (`sim/sky.py`)", check=one_of(*SCENARIO_NAMES)),
    Param("object_id", Computed(lambda v: str(v["scenario"]),
                                f"the scenario's name (`{SENSOR_SIM.scenario}`)",
                                SENSOR_SIM.scenario),
          "object id put in every message"),
    Param("cadence", Computed(_cadence, f"the scenario's ({DEFAULT_CADENCE:g}; real sky: its "
                                        "truth cadence)", DEFAULT_CADENCE),
          "time between measurements (real sky: between truth samples)", unit="s",
          check=POSITIVE),
    Param("duration", SENSOR_SIM.duration,
          "real-sky scenarios and catalogs: sim time to run (a scenario's outages keep "
          "their place in the run: `sky.SkyScenario.with_window`); 0 = the scenario's (3 days)",
          unit="s", check=NON_NEGATIVE),
    Param("start", SENSOR_SIM.start,
          "real-sky scenarios and catalogs: the first epoch, ISO 8601 UTC (e.g. "
          "`2025-06-01T00:00:00Z`); the object starts from the scenario's initial GCRF state "
          "at it, so its orbit plane meets the Sun and the sites elsewhere; '' = the "
          "scenario's epoch (a catalog: its first element set's)",
          check=Check("ISO 8601 UTC, 1972..2038", read_by(timescales.parse_utc, empty_ok=True))),
    Param("sites", SENSOR_SIM.sites,
          "real-sky scenarios: a sites file (YAML, docs/SITES.md) whose sites observe the "
          "object instead of the scenario's sensors (their masks, maximum range, noise and "
          "cadence); '' = the scenario's", check=SITES),
    Param("elements", SENSOR_SIM.elements,
          "real-sky scenarios: an element set file (TLE, 3LE, OMM XML/CSV) whose first object "
          "the scenario's sensors observe instead of the scenario's (truth: its SGP4/SDP4, "
          "from the first whole minute after its epoch unless `start`); '' = the scenario's",
          check=Check("'' or a readable element set file",
                      read_by(catalog_io.read_catalog, empty_ok=True))),
    Param("gap_start", _from_scenario("track_s"),
          "tracking before the gap, from the first epoch; ignored when `gaps` is set",
          unit="s", check=NON_NEGATIVE),
    Param("gap_length", _from_scenario("gap_s"), "length of the sensor outage", unit="s",
          check=NON_NEGATIVE),
    Param("gaps", SENSOR_SIM.gaps, "outages as pairs `[start, length, start, length, …]` "
          "after the first epoch; `[0.0]` = one gap from `gap_start`/`gap_length`", unit="s",
          check=Check("pairs, each ≥ 0", _gaps)),
    Param("after_gap", _from_scenario("after_s"), "tracking after the (last) gap", unit="s",
          check=NON_NEGATIVE),
    Param("noise_sigma", SENSOR_SIM.noise_sigma,
          "measurement noise standard deviation per channel; `[-1.0]` = the scenario's noise "
          "(iss_j2_rae: 1000 m, 0.01 rad, 0.01 rad)",
          unit="m (position); m, rad, rad (range/az/el)",
          check=Check("3 values, each ≥ 0", _noise)),
    Param("time_scale", SENSOR_SIM.time_scale, "simulation speed", unit="sim s per wall s",
          check=POSITIVE),
    Param("seed", SENSOR_SIM.seed, "noise random seed"),
    Param("wait_for", SENSOR_SIM.wait_for, "start only when each `/topic=count` has that "
          "many subscribers (e.g. `/ssa/measurement=3`); `[\"\"]` = none",
          check=Check("`/topic=count` entries", _wait)),
    Param("wait_for_readers", SENSOR_SIM.wait_for_readers,
          "start only when each `node:/topic` reports a matched publisher on `/diagnostics` "
          "(e.g. `filter:/ssa/measurement`), or `node:/topic=count` that many: the readers' "
          "side of the match exists too; `node:>/topic[=count]`: that node's output on the "
          "topic has matched that many subscribers (its writer's side); `[\"\"]` = none",
          check=Check("`node:[>]/topic[=count]` entries", _readers)),
    Param("tick", SENSOR_SIM.tick, "period of the publication timer", unit="wall s",
          check=POSITIVE),
    Param("catalog", SENSOR_SIM.catalog,
          "element sets (TLE, 3LE, OMM XML/CSV) of the objects to simulate instead of the "
          "scenario's one object; needs a real-sky `scenario`, whose radars observe every "
          "object (`sim.survey`: SGP4/SDP4 truth, masks, noise); no `/ssa/truth` (the truth "
          "is SGP4 of the catalog); measurements on `/ssa/measurement_batch` "
          "(MeasurementBatch, keep-last depth 1e6: `CATALOG_WRITER_QOS`); one `/clock` per tick; "
          "'' = off"),
    Param("objects", SENSOR_SIM.objects, "catalog: only the first N objects (0 = all)",
          check=at_least(0)),
    Param("synthetic", SENSOR_SIM.synthetic,
          "catalog: spread its first element set into N objects of the same regime "
          "(`survey.synthetic_catalog`, seeded by `seed`; 0 = the catalog's own)",
          check=at_least(0)),
    Param("shards", SENSOR_SIM.shards,
          "catalog: the measurements of a step (or tick) go out as this many batches, one "
          "per shard key range (`nodes.shards.shard_range`), so that each of as many filter "
          "shards receives its own batch only (content filter on the batch's key range)",
          check=at_least(1)),
    Param("lockstep", SENSOR_SIM.lockstep,
          "catalog: the consumers (node names: catalog_filter and catalog_surrogate shards, "
          "the recorder) sim time waits for: `/clock` advances by `lockstep_step` only once "
          "each has taken all it was sent (`nodes.progress`), `time_scale` being a ceiling; "
          "`[\"\"]` = open loop (sim time follows the wall clock, whatever is missed)"),
    Param("lockstep_step", SENSOR_SIM.lockstep_step,
          "lockstep: sim time per step (its measurements run ahead of the clock by up to "
          "this: keep it below the consumers' `max_clock_lead`)", unit="s",
          check=Check(f"in (0, {MAX_CLOCK_LEAD_S / 2:g}]", _step)),
    Param("batch_rows", SENSOR_SIM.batch_rows,
          "a catalog's measurements go in batches of at most this many rows (a shard's step "
          "is split: DDS keeps buffers as large as the largest message)",
          check=at_least(1)),
    Param("lockstep_timeout", SENSOR_SIM.lockstep_timeout,
          "lockstep: wall time a step waits for its consumers before it goes on without "
          "them (counted `lockstep_timeouts`, and logged)", unit="wall s", check=POSITIVE),
    Param("unlabelled", SENSOR_SIM.unlabelled,
          "catalog: publish each scan's detections as a radar reports them, without object "
          "ids (`object_id` '', `shard_key` 0: `core.catalog.unlabelled`); their true ids go to "
          "`/ssa/detection_truth` (evaluation only); needs `shards` 1"),
), rules=(Rule(("unlabelled", "catalog", "shards"), _unlabelled_needs_a_catalog_of_one_shard),
          _needs_sky("catalog", "its radars observe the catalog"),
          Rule(("lockstep", "catalog"), _lockstep_needs_a_catalog),
          _needs_sky("start", "a paper scenario keeps the paper's epoch"),
          _needs_sky("sites", "its object is what the sites observe"),
          _needs_sky("elements", "its sensors observe the object"),
          Rule(("elements", "catalog"), _one_object_or_a_catalog)))
"""The sensor_sim's parameters."""


def window_problem(t0: float, span: float) -> None:
    """Refuse a run whose start `t0` or end `t0` + `span` (Unix s) ssa_fusion cannot represent.

    `ParameterError` (one line, exit 2) from `timescales.check_window`'s ValueError.
    """
    try:
        timescales.check_window(t0, span)
    except ValueError as exc:
        raise parameters.ParameterError(f"parameters 'start', 'duration': {exc}") from exc


class SensorSim(SsaNode):
    """The simulator node: a schedule of what the sensors measure, published in sim time."""

    PARAMETERS = PARAMETERS

    def __init__(self) -> None:
        super().__init__()
        self.sim_stamp = Time()  # the sim time last published on /clock (0: none yet)
        p = self.params
        name = p.text("scenario")
        base, real_sky = _scenario(p.values)
        if real_sky is not None and p.text("sites"):
            real_sky = real_sky.with_sites(p.text("sites"))  # valid: the check `SITES`
        if real_sky is not None and p.text("elements"):
            real_sky = real_sky.with_elements(p.text("elements"))  # valid: `_elements`
        self.object_id = p.text("object_id")
        cadence, duration, gaps = p.number("cadence"), p.number("duration"), p.numbers("gaps")
        start = timescales.parse_utc(p.text("start")) if p.text("start") else None
        seed = p.integer("seed")
        self.time_scale = p.number("time_scale")
        self.wait_for = p.texts("wait_for")
        self.wait_for_readers = [x for x in p.texts("wait_for_readers") if x]
        self.readers = ReadyNodes(self)
        catalog = p.text("catalog")
        self.catalog: survey.Observations | None = None
        self.schedule: Schedule = []
        if catalog:
            assert real_sky is not None  # the rule `_needs_sky("catalog", ...)`
            self.catalog, summary = self._catalog(real_sky, catalog, p.integer("objects"),
                                                  p.integer("synthetic"), duration, start,
                                                  seed)
            self.times = self.catalog.t
        elif real_sky is None:
            self.schedule, summary = self._paper(
                base, cadence, p.number("gap_start"), p.number("gap_length"), gaps,
                p.number("after_gap"), p.numbers("noise_sigma"), seed)
        else:
            self.schedule, summary = self._sky(real_sky, cadence, duration, start, gaps, seed)
        if self.catalog is None:
            self.times = np.array([e[0] for e in self.schedule])
        if not self.times.size:
            raise parameters.ParameterError(
                f"scenario {name!r}: nothing to publish (no measurement and no truth epoch)")

        self.pub_clock = self.create_publisher(Clock, TOPIC_CLOCK, DATA_QOS)
        self.pub_meas = self.create_publisher(MeasurementMsg, TOPIC_MEASUREMENT, DATA_WRITER_QOS)
        self.pub_batch = self.create_publisher(MeasurementBatch, TOPIC_MEASUREMENT_BATCH,
                                               CATALOG_WRITER_QOS)
        self.shards = p.integer("shards")
        self.pub_withheld = self.create_publisher(MeasurementMsg, TOPIC_WITHHELD, DATA_WRITER_QOS)
        self.pub_truth = self.create_publisher(StateEstimateMsg, TOPIC_TRUTH, DATA_WRITER_QOS)
        self.next = 0
        self.finished = False
        self._next_wait_log = time.monotonic() + 5.0  # quiet while discovery runs
        self.wall0: float | None = None
        self.lockstep: Lockstep | None = None
        self.unlabelled = p.flag("unlabelled")
        self.pub_detection_truth = self.create_publisher(
            MeasurementBatch, TOPIC_DETECTION_TRUTH, CATALOG_WRITER_QOS
        ) if self.unlabelled else None
        if self.catalog is not None and any(p.texts("lockstep")):
            keys = self.catalog_keys.astype(np.int64)[self.catalog.obj]
            if self.unlabelled:  # what the batches carry: key 0
                keys = np.zeros_like(keys)
            self.lockstep = Lockstep(self, [n for n in p.texts("lockstep") if n], keys,
                                     p.number("lockstep_timeout"))
        self.lockstep_step = p.number("lockstep_step")
        self.sim_now = float(self.times[0])  # lockstep: the end of the last step published
        self.clock_behind = False  # lockstep: its clock waits until its measurements are taken
        self.create_timer(p.number("tick"), self.step)
        self.get_logger().info(f"{name}: {summary}, time scale {self.time_scale}x")

    def diagnostics_stamp(self) -> Time:
        """Return the sim time last published on /clock: sim time, like the other nodes'."""
        return self.sim_stamp

    def _paper(self, base: scenarios.Scenario, cadence: float, track: float, gap: float,
               gaps: list[float], after: float, noise: list[float],
               seed: int) -> tuple[Schedule, str]:
        """Return the schedule of a paper scenario with the node's overrides, and a log line."""
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
            raise parameters.ParameterError(
                f"cannot simulate scenario {base.name!r}: {exc}") from exc
        rel = sim.t - scenario.t0
        in_gap = np.zeros(len(rel), dtype=bool)
        for start, end in windows:
            in_gap |= (rel >= start) & (rel < end)
        return (paper_schedule(sim, in_gap, self.object_id),
                f"{len(sim.t)} epochs every {cadence} s, gaps {windows} s")

    def _sky(self, s: sky.SkyScenario, cadence: float, duration: float, start: float | None,
             gaps: list[float], seed: int) -> tuple[Schedule, str]:
        """Return the schedule of a real-sky scenario (`gaps`, if set: network outages).

        `duration` (s; 0: the scenario's) from `start` (Unix s; None: the scenario's t0).
        """
        t0, span = s.t0 if start is None else start, duration or s.duration_s
        window_problem(t0, span)  # what with_window would refuse, as a parameter error
        s = s.with_window(t0, span).with_(truth_cadence_s=cadence)
        if list(gaps) != [0.0]:
            s = s.with_(outages=tuple((sky.ALL_STATIONS, gaps[i], gaps[i + 1])
                                      for i in range(0, len(gaps), 2)))
        sim = sky.simulate_sky(s, seed=seed, object_id=self.object_id)
        return (sky_schedule(sim, self.object_id),
                f"{len(sim.measurements)} measurements ({int(sim.withheld.sum())} withheld) "
                f"from {', '.join(s.sensors)} from {timescales.iso(s.t0)} over "
                f"{s.duration_s / 3600:g} h, truth every "
                f"{cadence} s, outages {list(s.outages)}")

    def _catalog(self, s: sky.SkyScenario, path: str, objects: int, synthetic: int,
                 duration: float, start: float | None,
                 seed: int) -> tuple[survey.Observations, str]:
        """Return the measurements of a catalog by the scenario's radars.

        Over `duration` (s; 0: the scenario's) from `start` (Unix s; None: the catalog's
        first element set epoch).

        No truth topic: the truth is SGP4 of the catalog, recomputed by whoever scores the
        run.
        """
        try:
            entries = catalog_io.read_catalog(path)
        except ValueError as exc:
            raise parameters.ParameterError(f"parameter 'catalog' = {path!r}: {exc}") from exc
        if synthetic:
            entries = survey.synthetic_catalog(entries[0], synthetic, seed=seed)
        if objects:
            entries = entries[:objects]
        radars = s.radars
        if not radars:
            raise parameters.ParameterError(
                f"scenario {s.name!r} has no radar to observe a catalog")
        t0 = survey.catalog_start(entries) if start is None else start
        span = duration or s.duration_s
        window_problem(t0, span)
        obs = survey.observe_catalog(entries, radars, t0, span, seed=seed)
        self.catalog_ids = list(obs.object_ids)
        # per object and per sensor, indexed by a measurement's obj and sensor
        self.catalog_ids_array = np.asarray(self.catalog_ids, dtype=object)
        self.catalog_keys = messages.shard_keys(self.catalog_ids)
        self.catalog_frames = np.asarray([x.station.name for x in obs.sensors], dtype=object)
        self.catalog_R_array = np.array([r.R for r in radars], dtype=float)  # km^2, rad^2
        return obs, (f"catalog {path}: {len(entries)} objects, {len(obs)} measurements from "
                     f"{', '.join(r.station.name for r in radars)} over {span / 3600:g} h "
                     f"from {timescales.iso(t0)}")

    def waiting_for(self) -> list[str]:
        """Return what start-up still waits for.

        '/topic=count' entries whose subscriber count is short (matched by this node's own
        publishers where it publishes the topic), then 'node:[>]/topic' entries not reported
        as matched on /diagnostics.
        """
        own = {p.topic_name: p for p in (self.pub_clock, self.pub_meas, self.pub_withheld,
                                         self.pub_truth, self.pub_batch,
                                         self.pub_detection_truth) if p is not None}
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
        """Return True once nothing is awaited (log what is, every 5 s)."""
        missing = self.waiting_for()
        if missing and time.monotonic() >= self._next_wait_log:
            self._next_wait_log = time.monotonic() + 5.0
            self.get_logger().info(f"waiting for: {', '.join(missing)}")
        return not missing

    def step(self) -> None:
        """Publish what is due by the wall clock since the start (once ready)."""
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
        if self.lockstep is not None:
            self.step_lockstep(now)
            return
        stop = int(np.searchsorted(times, now, side="right"))
        if self.catalog is not None:  # one clock per tick, ahead of the tick's measurements
            self.publish_clock(min(now, times[-1]))
            self.publish_catalog(self.next, stop)
        else:
            for i in range(self.next, stop):
                self.publish_event(i)
        self.next = max(self.next, stop)
        self.publish_clock(min(now, times[-1]))
        if self.next >= len(times):
            self.done()

    def step_lockstep(self, ceiling: float) -> None:
        """Publish the next step once the consumers took the last (time scale: `ceiling`).

        A step's measurements (epochs in (T - lockstep_step, T]) go first, ahead of the
        clock; once every consumer took them (and the estimates they gave), `/clock` moves
        to T: whatever a consumer does at T (a surrogate releasing a gap's forecasts) sees
        everything before T. The next step's measurements wait until every consumer has
        acted on T (`progress.CLOCK`), so nothing after T is seen at T.
        """
        lockstep = self.lockstep
        assert lockstep is not None and self.catalog is not None
        go, missing = lockstep.go_on(time.monotonic())
        if not go:
            if time.monotonic() >= self._next_wait_log:
                self._next_wait_log = time.monotonic() + 5.0
                self.get_logger().info(f"lockstep: waiting for {', '.join(missing)}")
            return
        if missing:
            self.diag.count(Count.LOCKSTEP_TIMEOUTS,
                            f"lockstep: went on after {lockstep.timeout_s:g} s without "
                            f"{', '.join(missing)}")
        times = self.times
        if self.sim_stamp.sec == 0 or self.clock_behind:
            # the last step's measurements are all taken: now its clock (the first: t0);
            # the next step's go once every consumer has acted on it
            self.publish_clock(min(self.sim_now, float(times[-1])))
            self.clock_behind = False
            lockstep.clock_ns = self.sim_stamp.sec * 1_000_000_000 + self.sim_stamp.nanosec
            return
        if self.next >= len(times):
            self.done()
            return
        target = self.sim_now + self.lockstep_step
        if target > ceiling:
            return
        self.sim_now = target
        stop = int(np.searchsorted(times, target, side="right"))
        self.publish_catalog(self.next, stop)
        self.next = max(self.next, stop)
        lockstep.sent = self.next
        self.clock_behind = True

    def publish_clock(self, t: float) -> None:
        """Publish sim time `t` (s) on /clock."""
        msg = Clock()
        msg.clock = messages.seconds_to_stamp(t)
        self.pub_clock.publish(msg)
        self.sim_stamp = msg.clock

    def publish_event(self, i: int) -> None:
        """Publish scheduled event `i` (after the clock of its epoch)."""
        t, what, content = self.schedule[i]
        self.publish_clock(t)
        if what == Event.TRUTH:
            assert isinstance(content, types.StateEstimate)
            self.pub_truth.publish(messages.estimate_to_msg(content))
            return
        assert isinstance(content, types.Measurement)
        if what == Event.WITHHELD:
            self.pub_withheld.publish(messages.measurement_to_msg(content))
            self.diag.counts[Count.WITHHELD] += 1
        else:
            self.pub_meas.publish(messages.measurement_to_msg(content))
            self.diag.counts[Count.PUBLISHED] += 1

    def publish_catalog(self, start: int, stop: int) -> None:
        """Publish catalog measurements `start`..`stop`-1 in batches per shard key range.

        Their epochs are at or before the clock published (open loop), or at most one
        `lockstep_step` after it (lockstep). A range with no measurement gets no batch; one
        with more than ``batch_rows`` gets several, in epoch order. With `unlabelled`, each
        batch goes without its object ids, and with them on ``/ssa/detection_truth``.
        """
        obs = self.catalog
        if obs is None or stop <= start:
            return
        sl = slice(start, stop)
        keys = self.catalog_keys[obs.obj[sl]]
        rows = MeasurementRows(
            t=obs.t[sl], object_id=self.catalog_ids_array[obs.obj[sl]].tolist(),
            frame_id=self.catalog_frames[obs.sensor[sl]].tolist(), z=obs.z[sl],
            R=self.catalog_R_array[obs.sensor[sl]], shard_key=keys)
        ranges = [shard_range(k, self.shards) for k in range(self.shards)]
        shard = np.searchsorted(np.array([hi for _, hi in ranges]), keys)
        most = self.params.integer("batch_rows")
        for k in np.unique(shard).tolist():  # per shard, rows in epoch order, in batches
            mine = np.flatnonzero(shard == k)
            for part in np.array_split(mine, -(-mine.size // most)):
                batch = rows.take(part)
                if self.pub_detection_truth is not None:
                    self.pub_detection_truth.publish(
                        messages.measurement_batch_to_msg(batch, ranges[k]))
                    batch = without_labels(batch)
                self.pub_batch.publish(messages.measurement_batch_to_msg(batch, ranges[k]))
        self.diag.counts[Count.PUBLISHED] += stop - start

    def done(self) -> None:
        """End the run: wait for the readers' acknowledgements, report, exit 0."""
        self.finished = True
        for pub in (self.pub_meas, self.pub_batch, self.pub_withheld, self.pub_truth,
                    self.pub_clock, self.pub_detection_truth):
            if pub is not None:
                pub.wait_for_all_acked(Duration(seconds=5.0))
        self.diag.publish_last()
        self.get_logger().info(
            f"schedule done: {self.diag.counts[Count.PUBLISHED]} measurements, "
            f"{self.diag.counts[Count.WITHHELD]} withheld"
        )
        finish()


def main(args: list[str] | None = None) -> int:
    """Run the simulator node (``ros2 run ssa_fusion sensor_sim``)."""
    return SensorSim.main(args)


if __name__ == "__main__":
    raise SystemExit(main())
