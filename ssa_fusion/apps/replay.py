"""`ssa-fusion replay BAG`: re-run estimation on a recorded pass.

Over ROS 2 (default): plays the bag's measurements, truth and withheld measurements with a
`/clock` derived from their stamps into fresh surrogate + filter processes, as
`ros2 bag play --clock` would (waiting for subscribers first, honouring ``--rate``), and
records the new run with the recorder.

``--offline``: the same estimation through the core, without ROS, deterministically,
written as a bag of the same layout. Live and offline runs can differ only in the order in
which the filter sees a forecast and a real measurement (two topics, no ordering between
them). The design removes that difference: forecast *values* depend only on the
measurements (see `core.gaps.surrogate`), the filter's rules are order-independent for real
measurements, and the offline replay fuses forecasts at the positions the recorder saw them
in the bag's log-time order. A bag without recorded forecasts gets them when the clock
(the measurement stamps) passes each missed epoch by the live grace, and those still owed
when the measurement ending a gap arrives with it, as the surrogate node publishes them.
What the filter publishes besides its updates, the predictions through a gap, follows the
filter node's own policy (`core.gaps.publisher.GapPublisher`, with the ``predict_period`` and
``gap_forecast`` the bag records), driven by the bag's /clock.

``--offline --smooth`` adds the definitive orbit: the filter's fused estimates smoothed
backwards (Rauch-Tung-Striebel, `core.filter.smoother`; never across a re-initialisation), written
on ``/ssa/estimate_smoothed`` after the bag's last message; with truth in the bag, the
smoothed and the filtered position errors at the fused epochs the truth has are printed.

The estimator settings are those recorded with the bag (``/ssa/config``) unless
``--params-file`` or ``--scenario`` says otherwise (`settings`). With ``--sites`` (a sites
file, `formats.sites`), or for a bag without recorded settings, the filter takes the
stations the bag's measurements name (`core.gaps.estimator.for_stations`; the real-sky filter,
`core.gaps.estimator.station_estimator`, for a bag without settings whose stations are not the
default's). An offline replay that produces no estimate says why
(`replay_outcome.why_no_estimate`).

A bag whose measurements are recorded as batches (``/ssa/measurement_batch``) is replayed, in
both modes, as if recorded one message each: every row is the Measurement it means, at its
batch's log time (`bagio.read_records`), and is played and written as one. A catalog's bag
(measurements of several objects, unlabelled detections, or recorded catalog_filter
settings: `replay_catalog.catalog_reason`) never goes into one object's filter: it is
replayed through the catalog filter, one track per object (`replay_catalog`).

A bag at another cadence than its settings' is replayed at its own: the surrogate infers the
cadence from the stamps, as the node does with ``cadence`` 0.
"""

from __future__ import annotations

import argparse
import itertools
import math
import statistics
import sys
import time
from collections import Counter
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

from ssa_fusion.apps import evaluate, replay_catalog, replay_outcome, runs
from ssa_fusion.apps.args import add_domain_id, add_settings, add_sites, positive_float
from ssa_fusion.apps.filter_setup import DataMix, FilterSetup
from ssa_fusion.apps.heartbeat import working
from ssa_fusion.apps.partial import removed_if_unfinished
from ssa_fusion.core.base import types
from ssa_fusion.core.base.types import Cause
from ssa_fusion.core.earth.frames import Frame, Station
from ssa_fusion.core.filter.smoother import TrackerRecorder
from ssa_fusion.core.filter.tracker import Tracker
from ssa_fusion.core.gaps.estimator import (
    EstimatorConfig,
    make_surrogate,
    make_tracker,
)
from ssa_fusion.core.gaps.publisher import GapFill, GapPublisher, Published
from ssa_fusion.core.gaps.surrogate import Surrogate
from ssa_fusion.core.measure.laser_model import LaserModels
from ssa_fusion.core.measure.validation import MAX_CLOCK_LEAD_S, ahead_of_clock
from ssa_fusion.formats import sites as site_file
from ssa_fusion.params import settings as node_settings
from ssa_fusion.ros import bag_runs, bagio, messages
from ssa_fusion.ros.laser_bag import is_laser
from ssa_fusion.ros.topics import (
    TOPIC_CLOCK,
    TOPIC_CONFIG,
    TOPIC_ESTIMATE,
    TOPIC_FORECAST,
    TOPIC_MEASUREMENT,
    TOPIC_METEO,
    TOPIC_REFERENCE,
    TOPIC_RUN,
    TOPIC_SMOOTHED,
    TOPIC_TRUTH,
    TOPIC_WITHHELD,
)

PLAYED = (TOPIC_MEASUREMENT, TOPIC_TRUTH, TOPIC_WITHHELD)
"""Topics a replay plays back (estimates and forecasts are what it recomputes)."""
KEPT = (TOPIC_METEO, TOPIC_REFERENCE)
"""Topics an offline replay writes as recorded besides those it plays (a laser bag's)."""
KNOWN = (*PLAYED, TOPIC_ESTIMATE, TOPIC_SMOOTHED, TOPIC_FORECAST, TOPIC_CLOCK, TOPIC_CONFIG,
         TOPIC_METEO, TOPIC_REFERENCE, TOPIC_RUN, "/diagnostics", "/rosout",
         "/parameter_events")


def add_arguments(p: argparse.ArgumentParser) -> None:
    """Add the options of `ssa-fusion replay` to `p`."""
    p.add_argument("bag", type=Path, help="rosbag2 directory or .mcap file")
    p.add_argument("--rate", type=positive_float, default=1.0,
                   help="playback rate (sim seconds per wall second / bag timing), default 1")
    p.add_argument("--record", type=Path, default=None,
                   help="bag to record the new run to (default: BAG_replay)")
    p.add_argument("--offline", action="store_true", help="estimate through the core, no ROS")
    p.add_argument("--out", type=Path, default=None,
                   help="with --offline: output bag (default: BAG_offline)")
    p.add_argument("--smooth", action="store_true",
                   help="with --offline: also the RTS-smoothed estimates (the definitive orbit) "
                        "on /ssa/estimate_smoothed, and their error against the bag's truth")
    add_settings(p, "replay", "those recorded with the bag, else the measurement kind's "
                              "default")
    add_sites(p, "stations of your own that the bag's measurements name; the filter takes "
                 "the stations its measurements name")
    add_domain_id(p)


def run(args: argparse.Namespace) -> int:
    """Run `ssa-fusion replay` (live over ROS 2, or ``--offline``); return the exit code."""
    try:
        bag_runs.check_one_run(args.bag)  # a bag of two runs is no run to replay
        undecodable: Counter[str] = Counter()
        refused: Counter[tuple[str, str]] = Counter()
        # a catalog's bag is never read row by row as messages (millions of rows)
        telling = list(bagio.read_bag(args.bag, topics=replay_catalog.TELLING,
                                      undecodable=undecodable))
        catalog = replay_catalog.catalog_reason(telling)
        if catalog is None:
            undecodable.clear()
            stream = list(bagio.read_records(args.bag, undecodable=undecodable,
                                             refused=refused))
        for line in bagio.left_out(undecodable, refused):
            print(f"replay: {line}")
        if catalog is None:
            check_topics(args.bag, stream)
            if is_laser(stream):
                from ssa_fusion.apps import replay_laser  # it builds on this module

                return replay_laser.run(args, stream)
            sites = site_file.load_stations(args.sites) if args.sites else ()
            chosen = settings(stream, args.scenario, args.params_file, sites, args.setup)
    except (bagio.BagError, ValueError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    if catalog is not None:
        out = (args.out or sibling(args.bag, "_offline") if args.offline
               else args.record or sibling(args.bag, "_replay"))
        return replay_catalog.run(args, telling, catalog, out)
    s = chosen.estimator
    print(f"replay: estimator settings: {chosen.origin}")
    if s.surrogate.cadence_s == 0:
        print(f"replay: measurements every {bag_cadence(stream):g} s, not the settings' "
              f"cadence: the surrogate infers the cadence from the stamps")
    stream, ahead = drop_ahead_of_clock(stream)
    if ahead:
        print(f"replay: {ahead} measurement(s) stamped more than {MAX_CLOCK_LEAD_S:g} s after "
              f"the recorder's clock (log time) not played: the nodes refuse them live "
              f"(rejected_future)")
    if args.smooth and not args.offline:
        print("error: --smooth needs --offline (the smoother runs in the core)", file=sys.stderr)
        return 2
    if args.offline:
        out = args.out or sibling(args.bag, "_offline")
        if out.exists():
            print(f"error: {out} exists already; choose another --out", file=sys.stderr)
            return 2
        result = replay_offline(stream, s, smooth=args.smooth)
        settings_used = [node_settings.config_message("filter", s, recorded_gaps(stream)),
                         node_settings.config_message("surrogate", s)]
        try:
            with removed_if_unfinished(out):
                write_offline(out, stream, result, settings_used)
        except OSError as exc:
            print(f"error: cannot write {out}: {exc}", file=sys.stderr)
            return 2
        print(f"offline replay of {args.bag}: {len(result.estimates)} estimates, "
              f"{len(result.forecasts)} forecasts"
              + (f", {len(result.smoothed)} smoothed" if args.smooth else "") + f" -> {out}")
        if not result.estimates:
            why = replay_outcome.why_no_estimate(stream, result, s)
            print(f"error: no estimate: {why}", file=sys.stderr)
            return 1
        print(replay_outcome.judged(stream, result, s, out))
        if args.smooth:
            print(replay_outcome.smoothing_summary(stream, result))
        return 0
    return replay_live(args, stream, s)


def sibling(bag: Path, suffix: str) -> Path:
    """Return the path beside `bag` named after it plus `suffix` (``.mcap`` dropped)."""
    base = bag.with_suffix("") if bag.suffix == ".mcap" else bag
    return base.with_name(base.name + suffix)


def check_topics(path: Path, stream: list[bagio.BagMessage]) -> None:
    """Check that the bag at `path` can be replayed; ValueError saying why not.

    A bag to replay needs measurements, and states in the GCRF; a topic this tool does not
    know is an error (naming it) rather than silently dropped.
    """
    unknown = sorted({m.topic for m in stream if m.topic not in KNOWN})
    if unknown:
        raise ValueError(f"{path}: unknown topic(s) {', '.join(unknown)}; this replay plays "
                         f"{', '.join(PLAYED)}")
    if not any(m.topic == TOPIC_MEASUREMENT for m in stream):
        raise ValueError(f"{path}: no {TOPIC_MEASUREMENT} messages to replay")
    legacy = sorted({m.msg.header.frame_id for m in stream
                     if m.topic in (TOPIC_TRUTH, TOPIC_ESTIMATE)} - {Frame.GCRF})
    if legacy:
        raise ValueError(f"{path}: its states are in frame {', '.join(legacy)!r}, recorded "
                         f"before ssa_fusion used the GCRF; a replay would put them beside "
                         f"GCRF estimates. `ssa-fusion report` still reads it; re-record it "
                         f"to replay it")


def drop_ahead_of_clock(stream: list[bagio.BagMessage]) -> tuple[list[bagio.BagMessage], int]:
    """Drop the measurements stamped ahead of the recorder's clock; return the rest and how many.

    Ahead: more than `MAX_CLOCK_LEAD_S` after their log time (the recorder's clock when they
    arrived). Live, the nodes refuse them against their clock; a replay's clock follows the
    stamps, so they are taken out before either replay (a year-ahead stamp would also
    stretch the playback).
    """
    kept = [m for m in stream if m.topic != TOPIC_MEASUREMENT or not ahead_of_clock(
        messages.stamp_to_seconds(m.msg.header.stamp), m.t_ns * 1e-9, MAX_CLOCK_LEAD_S)[0]]
    return kept, len(stream) - len(kept)


def settings(stream: list[bagio.BagMessage], scenario: str = "",
             params_file: Path | None = None, sites: tuple[Station, ...] = (),
             setup: FilterSetup | None = None) -> evaluate.Settings:
    """Return the estimator settings to replay `stream` with.

    As `evaluate.settings_for_bag` chooses them: params file, scenario, filter set-up
    (`setup`), those recorded with the bag, else the set-up its measurements call for
    (`filter_setup`); with `sites` (stations of one's own) the filter takes the stations
    the measurements name.

    The bag's own cadence wins: if its measurements come at another interval than the
    settings' cadence (beyond the surrogate's jitter tolerance), the cadence is set to 0 and
    the surrogate infers it from the stamps, as the surrogate node does with `cadence` 0 (a
    fixed 30 s cadence against 10 s data would find every interval off its grid and never
    fit). Data at the settings' cadence keep it, so a replay reproduces the live run.
    """
    recorded = [m.msg.data for m in stream if m.topic == TOPIC_CONFIG]
    mix = DataMix.of(messages.measurement_from_msg(m.msg) for m in stream
                     if m.topic == TOPIC_MEASUREMENT)
    chosen = evaluate.settings_for_bag(recorded, mix, scenario, params_file, sites, setup)
    c = chosen.estimator
    dt, cadence = bag_cadence(stream), c.surrogate.cadence_s
    if not math.isnan(dt) and cadence > 0 and abs(dt - cadence) > c.surrogate.jitter * cadence:
        chosen.estimator = c.with_(surrogate=replace(c.surrogate, cadence_s=0.0))
    return chosen


def bag_cadence(stream: list[bagio.BagMessage]) -> float:
    """Return the median interval (s) between successive stamps of the sensor measurements.

    The cadence of the data, gaps and all; NaN with fewer than two measurements.
    """
    t = sorted({messages.stamp_to_seconds(m.msg.header.stamp) for m in stream
                if m.topic == TOPIC_MEASUREMENT and m.msg.source == types.Source.SENSOR})
    if len(t) < 2:
        return math.nan
    return statistics.median(b - a for a, b in itertools.pairwise(t))


@dataclass
class OfflineResult:
    """Estimates and forecasts with the log time (ns) of the input that produced them."""

    estimates: list[tuple[int, types.StateEstimate]] = field(default_factory=list)
    forecasts: list[tuple[int, types.Measurement]] = field(default_factory=list)
    rejected: dict[str, int] = field(default_factory=dict)
    smoothed: list[types.StateEstimate] = field(default_factory=list)
    """With ``smooth``: the smoothed estimates, epoch order (segment after segment)."""
    end_ns: int = 0
    """Log time (ns) of the bag's last message."""


class _NoForecasts:
    """The surrogate of a stream it does not forecast (laser ranges): nothing, ever."""

    def due(self, _t: float) -> list[types.Measurement]:
        return []

    def add(self, _m: types.Measurement) -> list[types.Measurement]:
        return []

    def reset(self) -> None:
        """Nothing to forget."""


def _offline_parts(stream: list[bagio.BagMessage], c: EstimatorConfig,
                   gaps: Mapping[str, Any] | None, smooth: bool, tracker: Tracker | None
                   ) -> tuple[GapPublisher, TrackerRecorder | None, Surrogate | _NoForecasts]:
    """Return `replay_offline`'s publisher (its tracker inside), recorder and surrogate."""
    g = gaps if gaps is not None else recorded_gaps(stream)
    publisher = GapPublisher.of(tracker or make_tracker(c), float(g["predict_period"]),
                                GapFill(g["gap_forecast"]), c)
    recorder = TrackerRecorder(publisher.tracker) if smooth else None
    # Forecasts always come from a fit on the buffer up to the last real measurement, so the
    # live node's optional periodic refits (retrain_period) would change nothing here.
    surrogate = _NoForecasts() if c.kind == types.Kind.LASER_RANGE else make_surrogate(
        c.with_(surrogate=replace(c.surrogate, retrain_period_s=math.inf)))
    return publisher, recorder, surrogate


def replay_offline(stream: list[bagio.BagMessage], c: EstimatorConfig,
                   gaps: Mapping[str, Any] | None = None, smooth: bool = False,
                   tracker: Tracker | None = None) -> OfflineResult:
    """Run surrogate + filter of estimator `c` through the core over the bag's messages.

    The messages are taken in log-time order. The filter publishes what the filter node
    publishes (`core.gaps.publisher.GapPublisher`): the estimate of every fused measurement
    and, through a gap, predictions (or residual forecasts) on the grid of the filter's
    `gaps` parameters (``predict_period``, ``gap_forecast``; default: those recorded with
    the bag), as the bag's /clock passes them, the rest once the bag ends; with `smooth`
    also smoothed (`TrackerRecorder`). `tracker` (default `make_tracker(c)`): a laser
    filter takes the bag's meteorological records as they come; nothing forecasts ranges.
    """
    publisher, recorder, surrogate = _offline_parts(stream, c, gaps, smooth, tracker)
    model, result = publisher.tracker.model, OfflineResult()
    recorded = {messages.stamp_to_seconds(m.msg.header.stamp)
                for m in stream if m.topic == TOPIC_FORECAST}
    pool: dict[float, types.Measurement] = {}
    last_clock, last_ns = -float("inf"), 0

    def publish(out: Published, t_ns: int) -> bool:
        causes = [out.outcome.rejected] if out.outcome and out.outcome.rejected else []
        causes += [Cause.PREDICTIONS_SKIPPED] * out.skipped
        for cause in causes:
            result.rejected[cause] = result.rejected.get(cause, 0) + 1
        result.estimates += [(t_ns, e) for e in out.estimates]
        return bool(out.estimates)

    def fuse(m: types.Measurement, t_ns: int) -> None:
        out = publisher.measurement(m)
        if recorder is not None and out.outcome is not None:
            recorder.observe(m, out.outcome)
        publish(out, t_ns)

    def forecast(f: types.Measurement, t_ns: int) -> None:
        result.forecasts.append((t_ns, f))
        fuse(f, t_ns)

    for msg in stream:
        if msg.topic == TOPIC_CLOCK:
            now = messages.stamp_to_seconds(msg.msg.clock)
            if now < last_clock:  # a looping bag: both start over, as the nodes do
                publisher.reset()
                if recorder is not None:
                    recorder.reset()
                surrogate.reset()
                pool.clear()
            last_clock, last_ns = now, msg.t_ns
            publish(publisher.advance(now), msg.t_ns)
        elif msg.topic == TOPIC_MEASUREMENT:
            m = messages.measurement_from_msg(msg.msg)
            if m.source != types.Source.SENSOR:
                continue
            if not recorded:  # no recorded forecast timing: release them by the clock
                for f in surrogate.due(m.t):
                    forecast(f, msg.t_ns)
            owed = surrogate.add(m)  # forecasts of the epochs before m not yet released
            for f in owed:
                if recorded:
                    pool[f.t] = f
                else:  # released with m, as the node publishes them
                    forecast(f, msg.t_ns)
            fuse(m, msg.t_ns)
        elif msg.topic == TOPIC_METEO and isinstance(model, LaserModels):
            model.add_meteo([messages.meteo_from_msg(msg.msg)])
        elif msg.topic == TOPIC_FORECAST and isinstance(surrogate, Surrogate):
            t = messages.stamp_to_seconds(msg.msg.header.stamp)
            if t not in pool:
                for f in surrogate.due(t + surrogate.config.grace * surrogate.cadence()):
                    pool[f.t] = f
            due = pool.pop(t, None)
            if due is not None:
                forecast(due, msg.t_ns)
    while publish(publisher.advance(last_clock), last_ns):  # the node's timer works it off
        pass
    result.end_ns = max((m.t_ns for m in stream), default=0)
    if recorder is not None:
        object_id = publisher.last_object
        result.smoothed = [e for seg in recorder.smooth() for e in seg.estimates(object_id)]
    return result


def recorded_gaps(stream: list[bagio.BagMessage]) -> dict[str, Any]:
    """Return the filter's gap parameters recorded with the bag (else its defaults)."""
    return node_settings.recorded_gaps([m.msg.data for m in stream if m.topic == TOPIC_CONFIG])


def write_offline(out: Path, stream: list[bagio.BagMessage], result: OfflineResult,
                  settings_used: list[str] | None = None) -> None:
    """Write the bag `out` of the live layout with the new estimates and forecasts.

    The played topics as recorded, plus the new estimates and forecasts at the log times of
    the inputs that produced them, and the smoothed estimates (if any) after the last; the
    estimator settings the replay used (`settings_used`: ``/ssa/config`` JSON of the filter
    and the surrogate, latched, at the first log time), as the live nodes record theirs, so
    that the bag alone says how it was made (frame, stations and sites, filter). A laser
    bag's meteorological records and reference orbit (`KEPT`) are kept as recorded.
    """
    classes = bagio.rosbags_classes()
    writer = bagio.BagWriter(out)
    try:
        if settings_used:
            writer.add_topic(TOPIC_CONFIG, "std_msgs/msg/String",
                             [bagio.LATCHED_QOS])
            first_ns = min((m.t_ns for m in stream), default=0)
            text = bagio.typestore().types["std_msgs/msg/String"]
            for data in settings_used:
                writer.write_msg(TOPIC_CONFIG, first_ns, text(data=data))
        for topic, msgtype in ((TOPIC_MEASUREMENT, "Measurement"), (TOPIC_TRUTH, "StateEstimate"),
                               (TOPIC_WITHHELD, "Measurement"), (TOPIC_FORECAST, "Measurement"),
                               (TOPIC_ESTIMATE, "StateEstimate")):
            writer.add_topic(topic, f"{bagio.MSG_PACKAGE}/msg/{msgtype}")
        kept = {m.topic: m.msgtype for m in stream if m.topic in KEPT}
        for topic, msgtype in kept.items():
            writer.add_topic(topic, msgtype)
        rows = [(m.t_ns, 0, m.topic, messages.recode(m.msg, m.msgtype, classes))
                for m in stream if m.topic in PLAYED or m.topic in kept]
        rows += [(t, 1, TOPIC_FORECAST, messages.measurement_to_msg(f, classes))
                 for t, f in result.forecasts]
        rows += [(t, 2, TOPIC_ESTIMATE, messages.estimate_to_msg(e, classes))
                 for t, e in result.estimates]
        if result.smoothed:
            writer.add_topic(TOPIC_SMOOTHED, f"{bagio.MSG_PACKAGE}/msg/StateEstimate")
            rows += [(result.end_ns + 1, 3, TOPIC_SMOOTHED, messages.estimate_to_msg(e, classes))
                     for e in result.smoothed]
        for t_ns, _, topic, msg in sorted(rows, key=lambda r: (r[0], r[1])):
            writer.write_msg(topic, t_ns, msg)
    finally:
        writer.close()


def replay_live(args: argparse.Namespace, stream: list[bagio.BagMessage],
                c: EstimatorConfig) -> int:
    """Play the bag into surrogate + filter processes (estimator `c`) and record the run."""
    from ssa_fusion.ros.player import Player
    from ssa_fusion.ros.processes import ended_badly, recorded_short
    from ssa_fusion.ros.readiness import OUTPUT, ReadyNodes, readers_of

    record = args.record or sibling(args.bag, "_replay")
    if record.exists():
        print(f"error: {record} exists already; choose another --record", file=sys.stderr)
        return 2
    if c.sites and args.sites is None:
        print(f"error: the settings name stations of your own ("
              f"{', '.join(s.name for s in c.sites)}): give their sites file with --sites "
              f"for a replay over ROS (or replay --offline)", file=sys.stderr)
        return 2
    own = {"sites": str(args.sites.resolve())} if args.sites else {}
    params = {"recorder": {"use_sim_time": True, "bag": str(record)},
              "surrogate": {"use_sim_time": True, **node_settings.surrogate_params(c), **own},
              "filter": {"use_sim_time": True, **node_settings.filter_params(c),
                         **recorded_gaps(stream), **own}}
    opened = runs.replay_graph(args, record)
    if opened is None:
        return 2
    graph, logs = opened
    played = [m for m in stream if m.topic in PLAYED]
    print(f"replay: {args.bag} at rate {args.rate:g} into surrogate + filter: "
          f"{replay_outcome.live_duration(played, args.rate)}; ROS domain {graph.domain_id}, "
          f"run {graph.run}; logs in {logs}", flush=True)
    t0 = time.monotonic()
    try:
        for n in ("recorder", "surrogate", "filter"):  # the recorder first: it hears all
            graph.start_node(n, params=params[n])
        player = Player(graph.probe, played, args.rate)
        from ssa_fusion.ros.interfaces import Measurement, StateEstimate

        # what the graph publishes, heard from the first to check the recording against
        seen = [graph.collect(StateEstimate, TOPIC_ESTIMATE),
                graph.collect(Measurement, TOPIC_FORECAST)]
        # recorder + surrogate + filter on measurements; recorder on the evaluation topics;
        # filter + recorder (+ this probe) on forecasts, recorder (+ probe) on estimates
        graph.wait_for(player.subscribers_ready({TOPIC_MEASUREMENT: 3, TOPIC_TRUTH: 1,
                                                 TOPIC_WITHHELD: 1}),
                       30.0, "surrogate, filter and recorder to subscribe")
        graph.wait_for_subscriber(TOPIC_FORECAST, 3, timeout=30.0)
        graph.wait_for_subscriber(TOPIC_ESTIMATE, 2, timeout=30.0)
        # only topics with a publisher here: a bag need not hold /ssa/truth or /ssa/withheld
        published = {*player.pubs, TOPIC_CLOCK, TOPIC_FORECAST, TOPIC_ESTIMATE}
        needs = [*readers_of(published),
                 f"filter:{OUTPUT}{TOPIC_ESTIMATE}=2", f"surrogate:{OUTPUT}{TOPIC_FORECAST}=3"]
        readers = ReadyNodes(graph.probe, graph.subscribe)

        def how_far() -> str:
            return (f"played {player.published} of {len(played)} messages, "
                    f"{len(seen[0])} estimates")

        with working("replay", "playing the bag", how_far):
            graph.play(player, lambda: readers.ready(needs),
                       "surrogate, filter and recorder to match their publishers")
        graph.wait_quiet(lambda: tuple(len(x) for x in seen), quiet_s=1.0, limit_s=30.0)
    finally:
        problems = graph.close()  # each stopped in turn, newest first
    if ended_badly(problems) or recorded_short(
            record, {TOPIC_ESTIMATE: len(seen[0]), TOPIC_FORECAST: len(seen[1])}):
        return 1
    print(f"replayed {player.published} messages of {args.bag} at rate {args.rate:g} in "
          f"{time.monotonic() - t0:.1f} s; recorded to {record}")
    return 0
