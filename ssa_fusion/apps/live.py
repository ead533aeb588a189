"""`ssa-fusion live`: run the node graph on a scenario, record it, and evaluate the bag.

Starts the four executables as separate processes (the same files `ros2 run` starts) in a
private ROS domain on loopback, waits until the recorder listens to every topic, lets the
simulation run at `--time-scale`, stops everything cleanly, then prints the table of the
paper's three arms for the gap and writes plots.

The summary warns when the machine did not keep up: when the simulation and the estimation
behind it took more than `SLOW_FACTOR` times the wall time `--time-scale` asks for, and when
the surrogate's forecasts for gap epochs never went into the filter (late or dropped; those
epochs are scored from the filter's prediction). With `--strict` the latter fails the run.

With `--foxglove` it also starts `foxglove_bridge`, which serves the graph to Foxglove over
WebSocket on loopback (``ws://127.0.0.1:PORT``, printed once it listens; the layout
``config/foxglove_layout.json`` shows its topics), and the simulation waits until the bridge
has matched the sensor's topics.
"""

from __future__ import annotations

import argparse
import json
import math
import re
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ssa_fusion import graphs
from ssa_fusion.apps import evaluate, report, runs
from ssa_fusion.apps.args import add_discovery, add_domain_id, time_scale
from ssa_fusion.apps.heartbeat import working
from ssa_fusion.apps.progress_lines import ProgressLines
from ssa_fusion.core.base.types import UpdateSource
from ssa_fusion.core.earth import timescales
from ssa_fusion.core.gaps.publisher import GapFill
from ssa_fusion.ros.processes import Graph
from ssa_fusion.ros.topics import TOPIC_DIAGNOSTICS, VISUAL_TOPICS
from ssa_fusion.sim import scenarios, sky
from ssa_fusion.sim.world import TruthModel

if TYPE_CHECKING:
    from ssa_fusion.ros.interfaces import Message

LIVE_ROOT = Path("out/live")
"""Where runs go by default, one directory each."""
SLOW_FACTOR = 1.2
"""Warn when the run took more than this times the wall time the time scale asks for."""
SLOW_SLACK_S = 0.5
"""... and more than this many wall seconds over it (start-up and teardown jitter), s."""
FILTER_COUNTERS = ("forecast_superseded", "forecasts_rolled_back", "rejected_gate",
                   "rejected_stale")
"""The filter's /diagnostics counters the late-forecast warning quotes (when received)."""


def add_arguments(p: argparse.ArgumentParser) -> None:
    """Add the options of `ssa-fusion live` (with the catalog ones) to `p`."""
    p.add_argument("--scenario", default=scenarios.DEFAULT_LIVE.name, choices=graphs.LIVE_SCENARIOS)
    p.add_argument("--time-scale", type=time_scale, default=1000.0,
                   help="sim seconds per wall second (default 1000); a catalog in lockstep: "
                        "the ceiling, `max` for none (as fast as its slowest node)")
    p.add_argument("--bag", type=Path, default=None,
                   help="bag directory to record (default: OUT/bag)")
    p.add_argument("--out", type=Path, default=None,
                   help=f"output directory (default: {LIVE_ROOT}/<scenario>_<date-time>, "
                        f"also linked as {LIVE_ROOT}/latest)")
    p.add_argument("--seed", type=int, default=0,
                   help="noise seed; a real-sky scenario's object also starts later and on an "
                        "orbit of its own for each seed (plane, phase, start epoch, as the "
                        "benchmarks' cases: `sky.seeded_case`) unless --same-geometry, and a "
                        "high-fidelity truth's space weather is drawn from it")
    p.add_argument("--same-geometry", action="store_true",
                   help="a real-sky scenario keeps its own orbit and start whatever --seed")
    p.add_argument("--truth", choices=[str(t) for t in TruthModel],
                   default=str(TruthModel.SGP4),
                   help="a real-sky object's truth: sgp4 (default) or high_fidelity "
                        "(sim/world.py: EGM96 20x20, Sun, Moon, SRP, NRLMSISE-00 drag)")
    p.add_argument("--start", default="", metavar="UTC",
                   help="first epoch, ISO 8601 UTC (e.g. 2025-06-01T00:00:00Z) of a real-sky "
                        "scenario (its object starts from the scenario's initial GCRF state "
                        "then) or a catalog (default: the scenario's epoch; a catalog's: its "
                        "first element set's)")
    p.add_argument("--sites", default="", metavar="FILE",
                   help="a sites file (YAML, docs/SITES.md) whose sites observe a real-sky "
                        "scenario's object (with --catalog: whose radars observe the "
                        "catalog) instead of the scenario's sensors "
                        "(e.g. config/sites/example.yaml)")
    p.add_argument("--elements", "--tle", "--omm", default="", metavar="FILE",
                   help="an element set file (TLE, 3LE, OMM XML/CSV) whose first object a "
                        "real-sky scenario's sensors observe instead of its own (truth: its "
                        "SGP4/SDP4, from its epoch unless --start)")
    p.add_argument("--duration", type=float, default=0.0, metavar="HOURS",
                   help="hours of sim time (default: the scenario's; a paper scenario keeps "
                        "its tracking and gap and tracks after the gap for the rest)")
    p.add_argument("--gap-forecast", default="", choices=["", *(str(f) for f in GapFill)],
                   help="what a real-sky scenario's filter publishes through its gaps (its "
                        "`gap_forecast`: none, residual, batch_fit, batch_init, "
                        "fit_residual; default: the scenario's)")
    p.add_argument("--strict", action="store_true",
                   help="exit 1 when forecasts for gap epochs never went into the filter "
                        "(they arrived late or were dropped, e.g. at too high a time scale); "
                        "with --catalog: refuse the file at its first bad element set "
                        "(default: each is left out, named on stderr with its file, line, "
                        "object and reason, and counted in the summary)")
    p.add_argument("--foxglove", action="store_true",
                   help="also serve the graph live to Foxglove (foxglove_bridge node, "
                        "WebSocket on 127.0.0.1; layout: config/foxglove_layout.json)")
    p.add_argument("--foxglove-port", type=_port, default=FOXGLOVE_PORT,
                   help=f"port of that WebSocket server (default {FOXGLOVE_PORT}; 0 = any free)")
    add_domain_id(p)
    add_discovery(p)
    from ssa_fusion.apps import live_catalog

    live_catalog.add_arguments(p)


FOXGLOVE_PORT = 8765
"""Default port of `--foxglove`'s WebSocket server (Foxglove's usual one)."""
FOXGLOVE_READERS = [*(f"foxglove_bridge:{t}" for t in ("/ssa/measurement", "/ssa/truth")),
                    *(f"recorder:{t}" for t in VISUAL_TOPICS)]
"""What the bridge must have matched before measurements flow (with `--foxglove`), and the
recorder of the bridge's ROS visual topics (so the bag holds the picture from the start)."""
_FOXGLOVE_URL = re.compile(r"Foxglove WebSocket server on (ws://\S+)")


def _port(text: str) -> int:
    """Parse a TCP port 0..65535 (an argparse type)."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not an integer") from None
    if not 0 <= value <= 65535:
        raise argparse.ArgumentTypeError(f"must be in 0..65535, got {value}")
    return value


def foxglove_parameters(params: dict[str, dict[str, Any]], port: int) -> dict[str, Any]:
    """Parameters of the foxglove_bridge node beside the graph `params` (`node_parameters`).

    Sim time, `port` on loopback, and the filter's stations (drawn in the scene).
    """
    out: dict[str, Any] = {"use_sim_time": True, "host": "127.0.0.1", "port": port}
    station = params.get("filter", {}).get("station")
    if station:
        out["station"] = station
    return out


def start_foxglove(graph: Graph, params: dict[str, dict[str, Any]], port: int,
                   say: Callable[[str], None] = print) -> str:
    """Start foxglove_bridge in `graph`; say and return its address once its server listens.

    The address is ``ws://127.0.0.1:PORT``.
    """
    proc = graph.start_node("foxglove_bridge", params=foxglove_parameters(params, port))

    def url() -> str | None:
        found = _FOXGLOVE_URL.search(proc.stderr())
        return found.group(1) if found else None

    graph.wait_for(lambda: url() is not None or proc.returncode is not None, 20.0,
                   "foxglove_bridge to listen")
    address = url()
    if address is None:
        raise RuntimeError("foxglove_bridge did not start:\n" + proc.describe())
    say(f"foxglove: open {address} in Foxglove (Open connection -> Foxglove WebSocket); "
        "layout: config/foxglove_layout.json")
    return address


def slow_warning(ran_s: float, sim_s: float, time_scale: float) -> str | None:
    """Return one warning line when the run was too slow for `time_scale`; else None.

    Too slow: `ran_s` wall seconds exceed `SLOW_FACTOR` times (and `SLOW_SLACK_S` over) the
    `sim_s / time_scale` asked for.
    """
    asked = sim_s / time_scale
    if ran_s <= SLOW_FACTOR * asked or ran_s - asked <= SLOW_SLACK_S:
        return None
    return (f"warning: --time-scale {time_scale:g} is more than this machine sustains: "
            f"{sim_s:.0f} sim s took {ran_s:.1f} s of wall time, not {asked:.1f} s "
            f"({sim_s / ran_s:.0f}x, {100 * (ran_s / asked - 1):.0f} % slower); "
            "a lower --time-scale gives the nodes time to keep up")


def filter_counters(diagnostics: Sequence[Message]) -> dict[str, int]:
    """Return `FILTER_COUNTERS` of the filter's last /diagnostics message in `diagnostics`.

    `diagnostics`: DiagnosticArray messages. The result is empty when none came from the
    filter.
    """
    for msg in reversed(diagnostics):
        for status in msg.status:
            if status.name == "filter":
                values = {kv.key: kv.value for kv in status.values}
                return {k: int(values[k]) for k in FILTER_COUNTERS
                        if values.get(k, "").isdigit()}
    return {}


def late_warning(late: evaluate.LateForecasts, counters: dict[str, int]) -> str | None:
    """Return a warning line when forecasts for gap epochs never reached the filter, or None."""
    if not late.epochs:
        return None
    seen = ", ".join(f"{k}={v}" for k, v in counters.items() if v)
    return (f"warning: forecasts for {late.epochs} of {late.forecast_epochs} gap epochs never "
            f"went into the filter (arrived late or were dropped; first t={late.first_t:.3f} s"
            + (f"; filter /diagnostics: {seen}" if seen else "")
            + "): those epochs are scored from its prediction; a lower --time-scale gives "
            "the surrogate time")


def catalog_options_given(args: argparse.Namespace) -> list[str]:
    """Return the catalog-only options of `args` set away from their defaults."""
    given = {"--objects": args.objects != 0, "--synthetic": args.synthetic != 0,
             "--shards": args.shards != 1, "--no-surrogate": not args.surrogate,
             "--surrogate-param": bool(args.surrogate_param),
             "--remote-shards": bool(args.remote_shards),
             "--unlabelled": bool(getattr(args, "unlabelled", False))}
    return [name for name, set_ in given.items() if set_]


def how_far(graph: Graph, sim_s: float) -> Callable[[], str]:
    """Return what `working` says of a single-object run: its sim time and estimates so far.

    From the estimates the probe hears (their stamps: sim time since the first).
    """
    from ssa_fusion.ros.interfaces import StateEstimate

    heard = graph.collect(StateEstimate, "/ssa/estimate")

    def say() -> str:
        if not heard:
            return "the nodes starting, no estimate yet"
        first, last = (h.header.stamp for h in (heard[0], heard[-1]))
        done = (last.sec - first.sec) + 1e-9 * (last.nanosec - first.nanosec)
        return (f"sim time {done / 3600:.1f} of {sim_s / 3600:.1f} h, {len(heard)} "
                "estimates")

    return say


def _drain(graph: Graph) -> float:
    """Let surrogate, filter and recorder finish what is in flight (until 1 s of quiet).

    Return the wall time (Unix s) the probe last saw an estimate or forecast arrive (0: none).
    """
    from ssa_fusion.ros.interfaces import Measurement, StateEstimate

    seen = [graph.collect(StateEstimate, "/ssa/estimate"),
            graph.collect(Measurement, "/ssa/forecast")]
    before: tuple[int, ...] = (0, 0)
    last_output = 0.0

    def counts() -> tuple[int, ...]:
        nonlocal before, last_output
        now = tuple(len(x) for x in seen)
        if now != before:
            before, last_output = now, time.time()
        return now

    graph.wait_quiet(counts, quiet_s=1.0, limit_s=30.0)
    return last_output


def _case(s: scenarios.Scenario | sky.SkyScenario, args: argparse.Namespace
          ) -> tuple[scenarios.Scenario | sky.SkyScenario, int]:
    """Return the run's scenario and its geometry seed (-1: its own orbit).

    A real-sky scenario gets the truth of ``--truth``, and, unless ``--same-geometry`` or
    an element set's object (whose orbit is its own), the orbit of case ``--seed``
    (`sky.case_geometry`) from the case's start (`sky.case_start_offset_s` after the
    scenario's, unless ``--start``).
    """
    if not isinstance(s, sky.SkyScenario):
        return s, -1
    s = s.with_(truth=TruthModel(args.truth))
    if args.same_geometry or s.element_set is not None:
        return s, -1
    if not args.start:
        s = s.with_window(s.t0 + sky.case_start_offset_s(args.seed), s.duration_s)
    return s, args.seed


def run(args: argparse.Namespace) -> int:
    """Run `ssa-fusion live` (or, with ``--catalog``, `live_catalog.run`); return the exit code."""
    if getattr(args, "catalog", None) is not None:
        return _run_catalog(args)
    catalog_only = catalog_options_given(args)
    if catalog_only:
        print(f"error: {', '.join(catalog_only)} apply to a catalog run (--catalog FILE)",
              file=sys.stderr)
        return 2
    if math.isinf(args.time_scale) and not args.lockstep:
        print("error: --time-scale max needs lockstep (without --open-loop): in the open "
              "loop sim time follows the wall clock", file=sys.stderr)
        return 2
    chosen = _scenario(args)
    if chosen is None:
        return 2
    s, geometry_seed = _case(chosen, args)
    dirs = runs.run_dirs(args, s.name)
    if dirs is None:
        return 2
    out, bag = dirs
    scale = min(args.time_scale, graphs.MAX_TIME_SCALE)
    params = graphs.node_parameters(s, scale, args.seed, bag, geometry_seed,
                                    lockstep=args.lockstep)
    sim_s = graphs.sim_seconds(s)
    graph = runs.run_graph(args, out / "logs", "live")
    if graph is None:
        return 2
    print(f"live: {s.name}, {sim_s / 3600:.1f} h of sim time {_pace(args, sim_s)}; ROS "
          f"domain {graph.domain_id}, run {graph.run}; logs in {out}/logs", flush=True)
    if isinstance(s, sky.SkyScenario):
        orbit = (f"object {graphs.object_name(s)} of {s.elements_file}" if s.element_set
                 else "the scenario's own orbit" if geometry_seed < 0 else
                 f"the orbit of case {geometry_seed} (--same-geometry: the scenario's own)")
        print(f"live: {s.truth} truth from {timescales.iso(s.t0)}, {orbit}", flush=True)
    t_start = time.monotonic()
    heard = _Heard()
    try:
        _run_graph(graph, params, args, sim_s, heard)
    finally:
        with working("live", "stopping the nodes"):
            problems = graph.close()
    if runs.ended_badly(problems):
        return 1
    return _report(args, s.name, out, bag, time.monotonic() - t_start, sim_s, heard)


def _pace(args: argparse.Namespace, sim_s: float) -> str:
    """Say how sim time goes: in lockstep as fast as the nodes go, or at a time scale."""
    if math.isinf(args.time_scale):
        return "in lockstep as fast as the nodes go"
    return (f"at {args.time_scale:g}x (~{sim_s / args.time_scale:.0f} s of simulation after "
            f"start-up{', in lockstep' if args.lockstep else ', open loop'})")


def _run_catalog(args: argparse.Namespace) -> int:
    """Run `live_catalog.run` (a ``--gap-forecast`` is a real-sky scenario's: exit code 2)."""
    from ssa_fusion.apps import live_catalog

    if getattr(args, "gap_forecast", ""):
        print("error: --gap-forecast applies to a real-sky scenario; a catalog's gaps: "
              "--surrogate-param gap_forecast=residual|batch_fit", file=sys.stderr)
        return 2
    return live_catalog.run(args)


def _scenario(args: argparse.Namespace) -> scenarios.Scenario | sky.SkyScenario | None:
    """Return the scenario the arguments name (None: said why on stderr)."""
    try:
        s = graphs.live_scenario(args.scenario, args.start, args.duration, args.sites,
                                 args.elements, ProgressLines(f"live: elements {args.elements}",
                                                              "objects").reading)
    except ValueError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return None
    if args.gap_forecast:
        if not isinstance(s, sky.SkyScenario):
            print(f"error: --gap-forecast applies to the real-sky scenarios "
                  f"({', '.join(sky.SKY_SCENARIOS)})", file=sys.stderr)
            return None
        s = s.with_(gap_fill=GapFill(args.gap_forecast))
    return s


@dataclass
class _Heard:
    """What the probe heard during a run.

    The /diagnostics messages and the wall time (Unix s) it last saw an estimate or forecast
    arrive (0: none).
    """

    diagnostics: Sequence[Message] = ()
    last_output: float = 0.0


def _run_graph(graph: Graph, params: dict[str, dict[str, Any]], args: argparse.Namespace,
               sim_s: float, heard: _Heard) -> None:
    """Start the graph's nodes (and Foxglove's bridge), wait for the simulator to end."""
    from ssa_fusion.ros.interfaces import DiagnosticArray

    heard.diagnostics = graph.collect(DiagnosticArray, TOPIC_DIAGNOSTICS)
    if getattr(args, "foxglove", False):
        start_foxglove(graph, params, args.foxglove_port, lambda text: print(text, flush=True))
        params["sensor_sim"]["wait_for_readers"] = [
            *params["sensor_sim"]["wait_for_readers"], *FOXGLOVE_READERS]
    with working("live", "running the graph", how_far(graph, sim_s)):
        for name in ("recorder", "surrogate", "filter"):
            graph.start_node(name, params=params[name])
        sensor = graph.start_node("sensor_sim", params=params["sensor_sim"])
        # a node that ends early (a recorder that cannot write its bag) ends the run at
        # once: graph.close says which and why; in lockstep sim time waits for its nodes
        # as long as they live: no limit
        limit = math.inf if args.lockstep else 60.0 + 3.0 * sim_s / args.time_scale
        if graph.wait_done_or_broken(sensor, timeout=limit):
            heard.last_output = _drain(graph)


def _report(args: argparse.Namespace, name: str, out: Path, bag: Path, wall: float,
            sim_s: float, heard: _Heard) -> int:
    """Evaluate the recorded run, write its report and live.json, print its table."""
    with working("live", "reading the bag"):
        data = evaluate.load(bag)
    try:
        evaluate.require_outage(data)
        with working("live", "scoring the arms over the outage"):
            ev = evaluate.evaluate(data, seed=args.seed)  # with the settings the bag recorded
    except ValueError as exc:  # e.g. a real-sky seed whose outage fell where no pass was
        fused = any(e.update_source != UpdateSource.NONE for e in data.estimates)
        if isinstance(exc, evaluate.NoTruthError) and fused:
            # no outage to score the arms over: the filter judged as your own data is
            print(f"recorded {sum(data.counts.values())} messages to {bag} in {wall:.1f} s; "
                  f"no arms to score (no pass fell in the run's outage)")
            own = argparse.Namespace(bag=bag, sites=args.sites or None, scenario="",
                                     params_file=None, setup=None, command="live")
            return report.run_own(own, data, out, str(exc))
        reason = str(exc)
        if isinstance(exc, evaluate.NoOutageError) and not data.measurements:  # no pass
            reason = (f"no station saw the object in the run's {sim_s / 3600.0:g} h (0 "
                      "measurements): a longer --duration, another --seed (each seed's case "
                      "has its own start and orbit plane; --same-geometry: the scenario's "
                      "own), or other --sites")
        print(f"recorded {sum(data.counts.values())} messages to {bag} in {wall:.1f} s\n"
              f"error: the run cannot be evaluated: {reason}", file=sys.stderr)
        return 1
    report.write(data, ev, out, "live")
    late = evaluate.unfused_forecasts(data, ev.gap.t)
    counters = filter_counters(heard.diagnostics)
    sim_wall = runs.sensor_wall_times(out / "logs" / "sensor_sim.err")
    # the simulation, and the estimation behind it until its last output reached the probe
    ran = None if sim_wall is None else max(sim_wall[1], heard.last_output) - sim_wall[0]
    summary = {"scenario": name, "time_scale": args.time_scale, "wall_s": wall,
               "sim_wall_s": ran, "bag": str(bag), **report.summary(data, ev),
               "late_forecast_epochs": late.epochs, "forecast_epochs": late.forecast_epochs,
               "filter_counters": counters}
    (out / "live.json").write_text(json.dumps(summary, indent=2))
    slow = None if ran is None or args.lockstep else slow_warning(ran, sim_s, args.time_scale)
    if slow:
        print(slow, file=sys.stderr)
    print(f"\nrecorded {sum(data.counts.values())} messages to {bag} in {wall:.1f} s")
    print(evaluate.table(ev))
    print(f"\nplots and report.json in {out}/; open {out / 'report.html'} in a browser")
    warning = late_warning(late, counters)
    if warning:
        print(warning, file=sys.stderr)
    if warning and args.strict:
        print(f"error: --strict: forecasts for {late.epochs} gap epochs never went into the "
              "filter", file=sys.stderr)
        return 1
    return 0
