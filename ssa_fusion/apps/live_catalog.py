"""`ssa-fusion live --catalog FILE`: a catalog of objects through the live graph.

sensor_sim simulates the radars of the scenario (`--scenario` when it is a real-sky one,
else ``iss_network``'s radars) measuring every object of the catalog (SGP4/SDP4 truth,
`sim.survey`); `--shards` K ``catalog_filter`` processes each track the objects of their
shard (DDS content filter on ``Measurement.shard_key``), and as many ``catalog_surrogate``
processes forecast through the gaps between passes of the same shards' objects
(`core.catalog.gap_bank`, residual fits under a wall-time budget; ``--no-surrogate`` leaves them
out); the recorder records everything.

Measurements and estimates travel as batches (``/ssa/measurement_batch``,
``/ssa/estimate_batch``: many rows a message); every count below is in rows. At the end it
prints what happened to every measurement (published by the simulator,
recorded, received by the shards, fused, pending in an IOD batch, rejected by cause: none
may be missing), the real-time factor the run achieved, each shard's objects and memory, and
the estimates' position error against the SGP4 truth of the catalog; with the surrogates,
their fits (made, refused, skipped for want of time) and the forecasts' error against that
truth beside the filter's own coasting (its two-body + J2 model from the same pass end, the
physics-only baseline) at the same epochs (`catalog_summary`). ``catalog.json`` in the run
directory holds the same numbers.

With ``--unlabelled`` the radars report their detections without object ids (one filter
shard associates them: `core.catalog.unlabelled`); the truth labels travel apart, on
``/ssa/detection_truth``, and the summary adds the association's score from the bag
(`evaluation.association`: accuracy, coverage, confirmed tracks) and scores each confirmed
track's estimates against the SGP4 truth of its majority object.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import math
import shlex
import sys
import time
from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ssa_fusion import graphs
from ssa_fusion.apps import conjunction_table, run_costs, runs
from ssa_fusion.apps.args import discovery
from ssa_fusion.apps.catalog_summary import (
    conjunction_summary,
    count,
    statuses,
    summarise,
    table,
    unrecorded,
)
from ssa_fusion.apps.heartbeat import working
from ssa_fusion.apps.progress_lines import ProgressLines
from ssa_fusion.core.base.types import UpdateSource
from ssa_fusion.core.earth import timescales
from ssa_fusion.core.motion.element_sets import CatalogEntry
from ssa_fusion.formats import element_sets as catalog_io
from ssa_fusion.formats.skipped import Skipped
from ssa_fusion.nodes.kit.diagnostics import Count
from ssa_fusion.params.defaults import CATALOG_SURROGATE
from ssa_fusion.ros.bagio import BagError
from ssa_fusion.ros.discovery import Discovery
from ssa_fusion.ros.processes import Graph, ros_arguments
from ssa_fusion.ros.qos import CATALOG_QOS
from ssa_fusion.ros.topics import (
    TOPIC_DIAGNOSTICS,
    TOPIC_ESTIMATE_BATCH,
)
from ssa_fusion.sim import sky, survey

if TYPE_CHECKING:
    from ssa_fusion.ros.interfaces import Message


def add_arguments(p: argparse.ArgumentParser) -> None:
    """Add the catalog options of `ssa-fusion live` to `p`."""
    p.add_argument("--catalog", type=Path, default=None,
                   help="run a catalog instead of the scenario's one object: element sets "
                        "(TLE, 3LE, OMM XML/CSV), e.g. config/catalogs/sample.tle")
    p.add_argument("--objects", type=int, default=0,
                   help="catalog: only its first N objects (default all)")
    p.add_argument("--synthetic", type=int, default=0,
                   help="catalog: spread its first element set into N objects of the same "
                        "orbital regime (core.survey.synthetic_catalog)")
    p.add_argument("--shards", type=int, default=1,
                   help="catalog: filter (and surrogate) processes, each owning the objects "
                        "of its shard (default 1)")
    p.add_argument("--open-loop", dest="lockstep", action="store_false",
                   help="sim time follows the wall clock at --time-scale whatever the nodes "
                        "keep up with (default: lockstep, `nodes.kit.progress`: each step "
                        "waits until the filter(s), surrogate(s) and the recorder took the "
                        "last, as long as they live)")
    p.add_argument("--remote-shards", type=shard_list, default=(), metavar="K[,K...]",
                   help="catalog: shards (filter and surrogate) that run on other hosts: not "
                        "started here; the run prints their commands, waits for them and "
                        "accounts for them like its own (needs --discovery-range SUBNET or "
                        "--static-peers; docs/MULTIHOST.md)")
    p.add_argument("--no-surrogate", dest="surrogate", action="store_false",
                   help="catalog: no catalog_surrogate (gap forecasts)")
    p.add_argument("--unlabelled", action="store_true",
                   help="catalog: the radars report detections without object ids; the "
                        "filter associates them into tracks (needs --shards 1; "
                        "docs/ASSOCIATION.md)")
    p.add_argument("--conjunctions", action="store_true",
                   help="catalog: a conjunction node re-screens the estimates for close "
                        "approaches (/ssa/conjunctions; CDMs in the run's conjunctions/; "
                        "docs/CONJUNCTIONS.md)")
    p.add_argument("--surrogate-param", action="append", default=[], metavar="NAME=VALUE",
                   help="catalog: a catalog_surrogate parameter (e.g. min_span=21600), "
                        "repeatable")


def shard_list(text: str) -> tuple[int, ...]:
    """Parse `--remote-shards` (an argparse type): comma-separated shard indices >= 0."""
    try:
        shards = tuple(sorted({int(x) for x in text.split(",") if x.strip()}))
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not comma-separated integers") from None
    if not shards or shards[0] < 0:
        raise argparse.ArgumentTypeError(f"{text!r}: shard indices 0..shards-1")
    return shards


def args_problem(args: argparse.Namespace) -> str | None:
    """Return why the catalog options cannot run, or None.

    The catalog is read by `run` (`entries_of`), which then checks the run's window.
    """
    if args.objects < 0 or args.synthetic < 0 or not args.duration >= 0:
        return "--objects, --synthetic and --duration must be >= 0"
    if getattr(args, "sites", ""):
        try:
            if not catalog_scenario(args).radars:
                return f"--sites {args.sites}: no radar in it to observe a catalog"
        except ValueError as exc:
            return str(exc)
    if getattr(args, "elements", ""):
        return "--elements is one object; a catalog's element sets are --catalog FILE"
    if args.start:
        try:
            timescales.parse_utc(args.start)
        except ValueError as exc:
            return f"--start: {exc}"
    if not 1 <= args.shards <= 64:
        return "--shards must be in 1..64"
    if getattr(args, "unlabelled", False) and args.shards != 1:
        return ("--unlabelled: detections without object ids cannot be routed to shards by "
                "object; one filter shard associates them all (--shards 1)")
    remote = getattr(args, "remote_shards", ())
    if remote and remote[-1] >= args.shards:
        return f"--remote-shards {remote[-1]}: there are shards 0..{args.shards - 1}"
    if remote and not discovery(args).reaches_other_hosts:
        return ("--remote-shards: nodes on other hosts cannot discover this host's on loopback; "
                "add --discovery-range SUBNET or --static-peers ADDR (docs/MULTIHOST.md)")
    try:
        catalog_surrogate_params(args)
    except ValueError as exc:
        return str(exc)
    return None


def pace(args: argparse.Namespace) -> str:
    """Return how sim time runs: "in lockstep (at most 100x)", "at 100x (open loop)"."""
    if not args.lockstep:
        return f"at {args.time_scale:g}x (open loop)"
    return ("in lockstep (as fast as the nodes go)" if math.isinf(args.time_scale)
            else f"in lockstep (at most {args.time_scale:g}x)")


def catalog_scenario(args: argparse.Namespace) -> sky.SkyScenario:
    """Return the real-sky scenario whose radars observe the catalog.

    ``--scenario`` (a paper one: `graphs.DEFAULT_SCENARIO`), observed by the radars of
    ``--sites`` instead when given (SiteFileError, a ValueError, when the file is wrong).
    """
    s = sky.SKY_SCENARIOS.get(args.scenario) or sky.SKY_SCENARIOS[graphs.DEFAULT_SCENARIO]
    sites = getattr(args, "sites", "")
    return s.with_sites(sites) if sites else s


def entries_of(args: argparse.Namespace, progress: catalog_io.Progress | None = None,
               skip: Skipped | None = None) -> list[CatalogEntry]:
    """Return the objects the run simulates (as sensor_sim builds them from the options).

    ValueError (one line naming the file and line) for a catalog that cannot be read;
    `progress`: `catalog_io.read_catalog`'s; `skip`: its bad element sets are left out and
    counted there (as sensor_sim leaves them out), else the first refuses the file.
    """
    entries = catalog_io.read_catalog(args.catalog, progress, skip)
    if args.synthetic:
        entries = survey.synthetic_catalog(entries[0], args.synthetic, seed=args.seed)
    return entries[: args.objects] if args.objects else entries


def catalog_surrogate_params(args: argparse.Namespace) -> dict[str, Any]:
    """Return the ``--surrogate-param NAME=VALUE`` options as parameters.

    The values are YAML (numbers, booleans, strings); ValueError naming an option that is
    not NAME=VALUE or names no parameter of catalog_surrogate.
    """
    import yaml

    known = {f.name: getattr(CATALOG_SURROGATE, f.name) for f in fields(CATALOG_SURROGATE)}
    out: dict[str, Any] = {}
    for item in getattr(args, "surrogate_param", []):
        name, eq, text = (x.strip() for x in item.partition("="))
        if not eq or not name:
            raise ValueError(f"--surrogate-param {item!r}: expected NAME=VALUE")
        if name not in known or name in ("shards", "shard"):
            raise ValueError(f"--surrogate-param {item!r}: catalog_surrogate has no parameter "
                             f"{name!r} to set (it has {', '.join(sorted(known))}; shards "
                             "come from --shards)")
        value = yaml.safe_load(text)
        if isinstance(known[name], float) and type(value) is int:
            value = float(value)  # 10800 for a parameter of seconds: a float parameter
        out[name] = value
    return out


def _pass_break(args: argparse.Namespace) -> float:
    """Return the surrogates' ``pass_break`` (s): ``--surrogate-param``'s, or the default."""
    return float(catalog_surrogate_params(args).get("pass_break", CATALOG_SURROGATE.pass_break))


def _rss_kib(pid: int) -> int:
    """Return the resident set size of process `pid`, KiB (0 when unknown)."""
    try:
        for line in Path(f"/proc/{pid}/status").read_text().splitlines():
            if line.startswith("VmRSS:"):
                return int(line.split()[1])
    except OSError:
        pass
    return 0


SHARD_EXECUTABLES = ("catalog_filter", "catalog_surrogate")
"""The executables of a catalog graph that own a shard (`graphs.catalog_graph`)."""


def is_remote(spec: graphs.NodeSpec, remote: Sequence[int]) -> bool:
    """Return True when `spec` is a shard process of one of the `remote` shards."""
    return spec.executable in SHARD_EXECUTABLES and spec.params["shard"] in remote


def remote_commands(specs: Sequence[graphs.NodeSpec], remote: Sequence[int], domain_id: int,
                    reach: Discovery, namespace: str = "/") -> list[tuple[int, str]]:
    """Return (shard, shell command) of each process of the `remote` shards, in start order.

    What another host runs to be shard k of this graph: ``ros2 run`` of its executable with
    its node name and parameters, in ROS domain `domain_id` with the discovery range of
    `reach` (its static peers name other hosts: they are this host's to announce to, and one
    side naming the other is enough), in the run's `namespace` (its identity).
    """
    env = [f"ROS_DOMAIN_ID={domain_id}", *Discovery(reach.range).exports()]
    ns = ["-r", f"__ns:={namespace}"] if namespace != "/" else []
    return [(s.params["shard"],
             shlex.join([*env, "ros2", "run", "ssa_fusion", s.executable,
                         *ros_arguments(s.params), *ns, "-r", f"__node:={s.name}"]))
            for s in specs if is_remote(s, remote)]


def run(args: argparse.Namespace) -> int:
    """Run `ssa-fusion live --catalog`; return the exit code (1 when measurements were lost)."""
    problem = args_problem(args)
    if problem:
        print(f"error: {problem}", file=sys.stderr)
        return 2
    skipped = None if getattr(args, "strict", False) else Skipped()
    try:
        entries = entries_of(args, ProgressLines(f"live: catalog {args.catalog}",
                                                 "objects").reading, skipped)
        t0 = timescales.parse_utc(args.start) if args.start else survey.catalog_start(entries)
        timescales.check_window(t0, args.duration * 3600.0)
    except ValueError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    s = catalog_scenario(args)
    unlabelled = bool(getattr(args, "unlabelled", False))
    dirs = runs.run_dirs(args, f"catalog_{s.name}")
    if dirs is None:
        return 2
    out, bag = dirs
    sim_s = args.duration * 3600.0 or s.duration_s
    conj = out / "conjunctions" if getattr(args, "conjunctions", False) else None
    specs = graphs.catalog_graph(s, args.catalog, args.objects, args.synthetic, sim_s,
                          args.time_scale, args.seed, args.shards, args.surrogate,
                          catalog_surrogate_params(args), bag, args.start, args.lockstep,
                          unlabelled, conj)
    remote = getattr(args, "remote_shards", ())
    graph = runs.run_graph(args, out / "logs", "live")
    if graph is None:
        return 2
    _announce(args, s, len(entries), specs, graph, remote, sim_s, unlabelled, out, skipped)
    t_start, command_start = time.monotonic(), time.time()
    outcome = _Outcome(sim_s=sim_s)
    try:
        _run_graph(graph, specs, remote, args.lockstep, sim_s / args.time_scale, unlabelled,
                   outcome)
    except TimeoutError as exc:  # its message holds every log's tail: the first line says what
        timed_out = str(exc).splitlines()[0]
    else:
        timed_out = ""
    finally:
        problems = graph.close()
    ended_badly = runs.ended_badly(problems)  # the summary still says what was done
    if timed_out:
        elsewhere = (f"; shard(s) {','.join(map(str, remote))} run on other hosts: were they "
                     "started there with the commands above, and can the hosts reach each "
                     "other? (docs/MULTIHOST.md)") if remote else ""
        print(f"error: {timed_out}{elsewhere}; logs in {out}/logs", file=sys.stderr)
        return 1
    wall = time.monotonic() - t_start
    sim_wall = runs.sensor_wall_times(out / "logs" / "sensor_sim.err")
    ran = None if sim_wall is None else (sim_wall[0], max(sim_wall[1], outcome.last_output))
    names, gaps = _shard_names(specs)
    status = statuses(outcome.diagnostics)
    try:
        summary = summarise(bag, entries, status, names, outcome.rss, ran, sim_s, gaps,
                            unlabelled, t0, _pass_break(args))
    except (OSError, ValueError, BagError) as exc:  # no bag, or a recorder killed mid-write
        print(f"error: no summary: cannot read {bag}: {exc} (`ssa-fusion bag repair`)",
              file=sys.stderr)
        return 1
    summary.update(costs(out / "logs" / "sensor_sim.err", outcome.cpu, command_start, ran,
                         summary["published"]))
    summary.update({"catalog": str(args.catalog), "objects": len(entries), "scenario": s.name,
                    "time_scale": args.time_scale if math.isfinite(args.time_scale) else "max",
                    "lockstep": args.lockstep,
                    "shards": args.shards, "wall_s": wall, "unlabelled": unlabelled,
                    "remote_nodes": [n.name for n in specs if is_remote(n, remote)],
                    "element_sets_skipped": skipped.count if skipped else 0,
                    "element_sets_skipped_lines": skipped.lines if skipped else [],
                    "processes_ended_badly": [p.splitlines()[0] for p in problems],
                    "summary_s": None if ran is None else time.time() - ran[1]})
    if conj is not None:
        summary["conjunctions"] = conjunction_summary(bag, status, conj)
    (out / "catalog.json").write_text(json.dumps(summary, indent=2))
    print(table(summary))
    if conj is not None:
        print(conjunction_table.table(conjunction_table.latest(bag)))
    return 0 if summary["lost_measurements"] == 0 and not ended_badly else 1


def costs(sensor_log: Path, cpu: dict[str, float], command_start: float,
          ran: tuple[float, float] | None, published: int) -> dict[str, Any]:
    """Return the run's phases (start-up, running) and each node's CPU time (`run_costs`).

    `cpu`: CPU s of each node process still running at the end (the simulator's from its
    log); per measurement published, in microseconds.
    """
    cpu = dict(cpu)
    sim = run_costs.sensor_costs(sensor_log)
    if sim is not None:
        cpu["sensor_sim"] = sim[0]
    per = {n: round(1e6 * v / published, 2) if published else None for n, v in cpu.items()}
    return {**run_costs.phases(command_start, run_costs.first_measurement(sensor_log), ran),
            "cpu_s": cpu, "cpu_us_per_measurement": per,
            "simulator_peak_rss_mib": None if sim is None else sim[1]}


def _shard_names(specs: Sequence[graphs.NodeSpec]) -> tuple[list[str], list[str]]:
    """Return the node names of the catalog_filter shards and of the catalog_surrogates."""
    return ([n.name for n in specs if n.executable == "catalog_filter"],
            [n.name for n in specs if n.executable == "catalog_surrogate"])


def _announce(args: argparse.Namespace, s: sky.SkyScenario, objects: int,
              specs: Sequence[graphs.NodeSpec], graph: Graph, remote: Sequence[int],
              sim_s: float, unlabelled: bool, out: Path, skipped: Skipped | None) -> None:
    """Print what runs (and what the other hosts are to run, `remote_commands`).

    The element sets `skipped` left out are named on stderr first.
    """
    gaps = _shard_names(specs)[1]
    radars = (f"radars of {s.sites_file} ({', '.join(r.station.name for r in s.radars)})"
              if s.sites_file else f"radars of {s.name}")
    if skipped is not None and skipped.count:
        print(skipped.summary(), file=sys.stderr)
    left_out = f", {skipped.count} bad element sets left out" if skipped and skipped.count else ""
    print(f"live: catalog {args.catalog} ({objects} objects{left_out}"
          f"{', unlabelled detections' if unlabelled else ''}), {radars}, "
          f"{sim_s / 3600:g} h of sim time {pace(args)}, {args.shards} filter "
          f"shard(s){' with a surrogate each' if gaps else ''}; ROS domain {graph.domain_id}, "
          f"run {graph.run}; logs in {out}/logs", flush=True)
    for k, command in remote_commands(specs, remote, graph.domain_id, graph.discovery,
                                      graph.namespace):
        print(f"  on shard {k}'s host: {command}", flush=True)


@dataclass
class _Outcome:
    """What `_run_graph` heard.

    The /diagnostics messages, the shards' resident memory (KiB), the CPU time (s) of
    each node process of this host and the wall time (Unix s) the last estimate arrived.
    """

    diagnostics: Sequence[Message] = ()
    rss: dict[str, int] = field(default_factory=dict)
    cpu: dict[str, float] = field(default_factory=dict)
    last_output: float = field(default_factory=time.time)
    sim_s: float = 0.0
    """The run's sim time, s."""
    seen: Counter[int] = field(default_factory=Counter)
    """Estimate rows heard, by update source."""
    stamps: list[float] = field(default_factory=list)
    """The first and the newest estimate batch's sim time heard (Unix s)."""

    def hear(self, msg: Message) -> None:
        """Count an EstimateBatch's rows; keep its sim time."""
        self.seen.update({msg.update_source: len(msg.object_id)})
        t = msg.header.stamp.sec + 1e-9 * msg.header.stamp.nanosec
        if self.stamps:
            self.stamps[1:] = [max(t, self.stamps[-1])]
        else:
            self.stamps.append(t)

    def how_far(self) -> str:
        """Say how far the run is (for `heartbeat.working`): sim time and estimates heard."""
        if not self.stamps:
            return "the nodes starting, no estimate yet"
        done = self.stamps[-1] - self.stamps[0]
        return (f"sim time {done / 3600:.1f} of {self.sim_s / 3600:.1f} h, "
                f"{self.seen[UpdateSource.SENSOR]} estimates")


def _run_graph(graph: Graph, specs: Sequence[graphs.NodeSpec], remote: Sequence[int],
               lockstep: bool, wall_s: float, unlabelled: bool, outcome: _Outcome) -> None:
    """Start the nodes of this host, wait for the run to end and everything to be recorded.

    `wall_s`: the simulation's wall time at its pace, s. TimeoutError when the simulator, a
    shard or the recorder does not get there.
    """
    with working("live", "running the catalog graph", outcome.how_far):
        from ssa_fusion.ros.interfaces import DiagnosticArray, EstimateBatch

        names, gaps = _shard_names(specs)
        diagnostics = graph.collect(DiagnosticArray, TOPIC_DIAGNOSTICS)
        outcome.diagnostics = diagnostics
        seen = outcome.seen
        graph.subscribe(EstimateBatch, TOPIC_ESTIMATE_BATCH, outcome.hear, CATALOG_QOS)
        started = {n.name: graph.start_node(n.executable, "-r", f"__node:={n.name}",
                                            name=n.name, params=n.params)
                   for n in specs if not is_remote(n, remote)}
        sim = started["sensor_sim"]
        # else a node ended early (the recorder too): graph.close says which
        # in lockstep sim time waits for its nodes as long as they live: no limit
        limit = math.inf if lockstep else 300.0 + 3.0 * wall_s
        if not graph.wait_done_or_broken(sim, limit):
            return
        # the filters are done when their estimates stop (surrogates may still be fitting)
        graph.wait_quiet(lambda: seen[UpdateSource.SENSOR], quiet_s=1.0, limit_s=600.0)
        outcome.last_output = time.time() - 1.0  # wall time (Unix s) the last estimate arrived
        # then one more report of every shard, counting all it did (a shard still busy gives
        # its last when it is stopped: the summary comes either way)
        since = len(diagnostics)
        with contextlib.suppress(TimeoutError):
            graph.wait_for(lambda: set(names + gaps) <= {st.name for d in diagnostics[since:]
                                                         for st in d.status}, 10.0,
                           "a last /diagnostics report of every shard")
        # and the recorder (last stopped, but stopped) has written all they published; briefly
        # when lockstep named a consumer DDS dropped: what it lost never comes
        dropped = count(statuses(diagnostics), "sensor_sim", Count.LOCKSTEP_DROPPED)
        with contextlib.suppress(TimeoutError):  # the summary counts what it lacks
            graph.wait_for(lambda: unrecorded(statuses(diagnostics), names, gaps,
                                              unlabelled) == 0,
                           5.0 if dropped else 60.0,
                           "the recorder to write every measurement and estimate")
        outcome.rss = {n: _rss_kib(started[n].popen.pid) for n in names + gaps if n in started}
        outcome.cpu = {n: run_costs.cpu_s(p.popen.pid) for n, p in started.items()}
