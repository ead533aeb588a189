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
physics-only baseline) at the same epochs. ``catalog.json`` in the run directory holds the
same numbers.

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
from collections import Counter, defaultdict
from collections.abc import Sequence
from dataclasses import fields
from pathlib import Path
from typing import TYPE_CHECKING, Any, TypedDict

import numpy as np

from ssa_fusion import graphs
from ssa_fusion.apps import runs
from ssa_fusion.apps.args import discovery
from ssa_fusion.apps.progress_lines import ProgressLines
from ssa_fusion.core.base.rows import MeasurementRows
from ssa_fusion.core.base.types import UpdateSource
from ssa_fusion.core.earth import timescales
from ssa_fusion.core.motion.element_sets import CatalogEntry, catalog_states
from ssa_fusion.evaluation.association import detection_labels, score_association
from ssa_fusion.evaluation.object_states import ObjectStates, States, StatesByObject, merge
from ssa_fusion.formats import element_sets as catalog_io
from ssa_fusion.nodes.kit.diagnostics import RECORDED, Count
from ssa_fusion.nodes.kit.progress import RECORDED_ESTIMATES, RECORDED_MEASUREMENTS
from ssa_fusion.nodes.kit.unlabelled import EVENT_PREFIX, FATE_PREFIX
from ssa_fusion.params.defaults import CATALOG_FILTER, CATALOG_SURROGATE
from ssa_fusion.ros import bagio, messages
from ssa_fusion.ros.discovery import Discovery
from ssa_fusion.ros.processes import ros_arguments
from ssa_fusion.ros.qos import CATALOG_QOS
from ssa_fusion.ros.topics import (
    TOPIC_ASSOCIATED,
    TOPIC_DETECTION_TRUTH,
    TOPIC_DIAGNOSTICS,
    TOPIC_ESTIMATE_BATCH,
    TOPIC_MEASUREMENT_BATCH,
)
from ssa_fusion.sim import sky, survey
from ssa_fusion.studies.catalog_gaps import gap_coverage, gap_errors

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


def entries_of(args: argparse.Namespace,
               progress: catalog_io.Progress | None = None) -> list[CatalogEntry]:
    """Return the objects the run simulates (as sensor_sim builds them from the options).

    ValueError (one line naming the file and line) for a catalog that cannot be read;
    `progress`: `catalog_io.read_catalog`'s.
    """
    entries = catalog_io.read_catalog(args.catalog, progress)
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


def _statuses(diagnostics: Sequence[Message]) -> dict[str, dict[str, str]]:
    """Return the last /diagnostics key/values of each node (by node name)."""
    out: dict[str, dict[str, str]] = {}
    for msg in diagnostics:
        for status in msg.status:
            out[status.name] = {kv.key: kv.value for kv in status.values}
    return out


def _count(status: dict[str, dict[str, str]], node: str, key: str) -> int:
    """Return the count `key` of `node` in `status` (`_statuses`), 0 when absent."""
    v = status.get(node, {}).get(key, "0")
    return int(v) if v.isdigit() else 0


def unrecorded(status: dict[str, dict[str, str]], names: list[str], gaps: list[str],
               unlabelled: bool = False) -> int:
    """Return how many measurements and estimates are published but not yet recorded.

    As the nodes and the recorder report them (`status`: `_statuses`; `names`: the filter
    shards, `gaps`: the surrogate shards); with `unlabelled`, the detections' truth and
    the associated detections too.
    """

    def num(node: str, key: str) -> int:
        return _count(status, node, key)

    published = (num("sensor_sim", Count.PUBLISHED)
                 + sum(num(n, Count.PUBLISHED_SENSOR) for n in names)
                 + sum(num(g, Count.PUBLISHED_FORECAST) for g in gaps))
    recorded = num("recorder", RECORDED_MEASUREMENTS) + num("recorder", RECORDED_ESTIMATES)
    if unlabelled:
        published += num("sensor_sim", Count.PUBLISHED) \
            + sum(num(n, Count.PUBLISHED_ASSOCIATED) for n in names)
        recorded += num("recorder", RECORDED + TOPIC_DETECTION_TRUTH) \
            + num("recorder", RECORDED + TOPIC_ASSOCIATED)
    return published - recorded


def _rss_kib(pid: int) -> int:
    """Return the resident set size of process `pid`, KiB (0 when unknown)."""
    try:
        for line in Path(f"/proc/{pid}/status").read_text().splitlines():
            if line.startswith("VmRSS:"):
                return int(line.split()[1])
    except OSError:
        pass
    return 0


def position_errors(entries: list[CatalogEntry], estimates: States) -> np.ndarray:
    """|r_estimate - r_SGP4| (km) of every estimate of an object of `entries`."""
    by_id = {e.object_id: e for e in entries}
    errs = []
    for oid, est in estimates.items():
        entry = by_id.get(oid)
        if entry is None or not est.t.size:
            continue
        x = catalog_states([entry], est.t).x[0]
        errs.append(np.linalg.norm(est.x[:, :3] - x[:, :3], axis=1))
    return np.concatenate(errs) if errs else np.zeros(0)


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
    try:
        entries = entries_of(args, ProgressLines(f"live: catalog {args.catalog}",
                                                 "objects").reading)
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
    specs = graphs.catalog_graph(s, args.catalog, args.objects, args.synthetic, sim_s,
                          args.time_scale, args.seed, args.shards, args.surrogate,
                          catalog_surrogate_params(args), bag, args.start, args.lockstep,
                          unlabelled)
    names = [n.name for n in specs if n.executable == "catalog_filter"]
    gaps = [n.name for n in specs if n.executable == "catalog_surrogate"]
    remote = getattr(args, "remote_shards", ())
    graph = runs.run_graph(args, out / "logs", "live")
    if graph is None:
        return 2
    radars = (f"radars of {s.sites_file} ({', '.join(r.station.name for r in s.radars)})"
              if s.sites_file else f"radars of {s.name}")
    print(f"live: catalog {args.catalog} ({len(entries)} objects"
          f"{', unlabelled detections' if unlabelled else ''}), {radars}, "
          f"{sim_s / 3600:g} h of sim time {pace(args)}, {args.shards} filter "
          f"shard(s){' with a surrogate each' if gaps else ''}; ROS domain {graph.domain_id}; "
          f"logs in {out}/logs", flush=True)
    for k, command in remote_commands(specs, remote, graph.domain_id, graph.discovery,
                                      graph.namespace):
        print(f"  on shard {k}'s host: {command}", flush=True)
    t_start = time.monotonic()
    rss: dict[str, int] = {}
    last_output = time.time()
    try:
        from ssa_fusion.ros.interfaces import DiagnosticArray, EstimateBatch

        diagnostics = graph.collect(DiagnosticArray, TOPIC_DIAGNOSTICS)
        seen: Counter[int] = Counter()  # estimates (rows) heard, by update source
        graph.subscribe(EstimateBatch, TOPIC_ESTIMATE_BATCH,
                        lambda m: seen.update({m.update_source: len(m.object_id)}), CATALOG_QOS)
        started = {n.name: graph.start_node(n.executable, "-r", f"__node:={n.name}",
                                            name=n.name, params=n.params)
                   for n in specs if not is_remote(n, remote)}
        sim = started["sensor_sim"]
        # else a node ended early (the recorder too): graph.close says which
        # in lockstep sim time waits for its nodes as long as they live: no limit
        limit = math.inf if args.lockstep else 300.0 + 3.0 * sim_s / args.time_scale
        if graph.wait_done_or_broken(sim, limit):
            # the filters are done when their estimates stop (surrogates may still be fitting)
            graph.wait_quiet(lambda: seen[UpdateSource.SENSOR], quiet_s=1.0, limit_s=600.0)
            last_output = time.time() - 1.0  # wall time (Unix s) the last estimate arrived
            # then one more report of every shard, counting all it did
            since = len(diagnostics)
            graph.wait_for(lambda: set(names + gaps) <= {st.name for d in diagnostics[since:]
                                                         for st in d.status}, 10.0,
                           "a last /diagnostics report of every shard")
            # and the recorder (last stopped, but stopped) has written all they published
            with contextlib.suppress(TimeoutError):  # the summary counts what it lacks
                graph.wait_for(lambda: unrecorded(_statuses(diagnostics), names, gaps,
                                                  unlabelled) == 0,
                               60.0, "the recorder to write every measurement and estimate")
            rss = {n: _rss_kib(started[n].popen.pid) for n in names + gaps if n in started}
    except TimeoutError as exc:  # its message holds every log's tail: the first line says what
        timed_out = str(exc).splitlines()[0]
    else:
        timed_out = ""
    finally:
        problems = graph.close()
    if runs.ended_badly(problems):
        return 1
    if timed_out:
        elsewhere = (f"; shard(s) {','.join(map(str, remote))} run on other hosts: were they "
                     "started there with the commands above, and can the hosts reach each "
                     "other? (docs/MULTIHOST.md)") if remote else ""
        print(f"error: {timed_out}{elsewhere}; logs in {out}/logs", file=sys.stderr)
        return 1
    wall = time.monotonic() - t_start
    sim_wall = runs.sensor_wall_times(out / "logs" / "sensor_sim.err")
    ran = None if sim_wall is None else (sim_wall[0], max(sim_wall[1], last_output))
    summary = summarise(bag, entries, _statuses(diagnostics), names, rss, ran, sim_s, gaps,
                        unlabelled, t0, _pass_break(args))
    summary.update({"catalog": str(args.catalog), "objects": len(entries), "scenario": s.name,
                    "time_scale": args.time_scale if math.isfinite(args.time_scale) else "max",
                    "lockstep": args.lockstep,
                    "shards": args.shards, "wall_s": wall, "unlabelled": unlabelled,
                    "remote_nodes": [n.name for n in specs if is_remote(n, remote)]})
    (out / "catalog.json").write_text(json.dumps(summary, indent=2))
    print(table(summary))
    return 0 if summary["lost_measurements"] == 0 else 1


class ShardSummary(TypedDict):
    """One catalog_filter shard in the summary (``per_shard`` of ``catalog.json``)."""

    received: int
    ignored_other_shard: int
    refused: int
    dropped: int
    consumed: int
    estimates: int
    objects: int
    rss_mib: float
    bank_bytes_per_object: str
    object_ids: list[str]
    association_counts: dict[str, int]
    confirmed_tracks: int
    """Unlabelled detections: ``detection_*``, ``association_*`` and
    ``published_associated`` (`nodes.kit.unlabelled`)."""


def summarise(bag: Path, entries: list[CatalogEntry],
              status: dict[str, dict[str, str]], names: list[str], rss: dict[str, int],
              sim_wall: tuple[float, float] | None, sim_s: float,
              gap_nodes: list[str] | None = None, unlabelled: bool = False,
              t0: float | None = None,
              pass_break_s: float = CATALOG_SURROGATE.pass_break) -> dict[str, Any]:
    """Return the run's accounting (every measurement), speed, memory and accuracy.

    `sim_wall`: wall times (Unix s) of the first measurement published and of the last
    estimate heard; `gap_nodes`: the catalog_surrogate processes; `unlabelled`: the
    detections went without object ids (``association``: their score, `association`).
    `t0`: the sim epoch the run started at (Unix s; None: its first estimate's); with
    `gap_nodes`, ``gap_coverage`` counts the gaps (`pass_break_s`, s) after its first day
    and those the surrogates forecast (`studies.catalog_gaps.gap_coverage`).
    """
    recorded: Counter[str] = Counter()  # rows
    sensor, forecast = StatesByObject(), StatesByObject()  # the estimates, the forecasts
    labelled: dict[str, list[MeasurementRows]] = defaultdict(list)  # unlabelled runs
    topics = [TOPIC_MEASUREMENT_BATCH, TOPIC_ESTIMATE_BATCH]
    for m in bagio.read_bag(bag, topics=topics + ([TOPIC_DETECTION_TRUTH, TOPIC_ASSOCIATED]
                                                  if unlabelled else [])):
        recorded[m.topic] += len(m.msg.object_id)
        if m.topic in (TOPIC_DETECTION_TRUTH, TOPIC_ASSOCIATED):
            labelled[m.topic].append(messages.measurement_batch_from_msg(m.msg))
        elif m.topic == TOPIC_ESTIMATE_BATCH:
            e = messages.estimate_batch_from_msg(m.msg)
            into = forecast if e.update_source == UpdateSource.FORECAST else sensor
            into.add(e.object_id, e.t, e.x)
    n_forecasts = forecast.rows
    estimates, forecasts = sensor.done(), forecast.done()

    def num(node: str, key: str) -> int:
        return _count(status, node, key)

    published = num("sensor_sim", Count.PUBLISHED)
    per_shard: dict[str, ShardSummary] = {}
    causes: Counter[str] = Counter()
    for shard in names:
        st = status.get(shard, {})
        counts = {k: int(v) for k, v in st.items() if v.isdigit()}
        per_shard[shard] = {"received": counts.get("received", 0),
                            "ignored_other_shard": counts.get("ignored_other_shard", 0),
                            "refused": counts.get("refused", 0),
                            "dropped": counts.get("dropped", 0),
                            "consumed": counts.get("consumed", 0),
                            "estimates": counts.get("published_sensor", 0),
                            "objects": int(st.get("objects", "0") or 0),
                            "rss_mib": rss.get(shard, 0) / 1024.0,
                            "bank_bytes_per_object": st.get("bank_bytes_per_object", ""),
                            "object_ids": [x for x in st.get("object_ids", "").split(",") if x],
                            "association_counts": {
                                k: v for k, v in counts.items()
                                if k.startswith((FATE_PREFIX, EVENT_PREFIX))
                                or k == Count.PUBLISHED_ASSOCIATED},
                            "confirmed_tracks": int(st.get("confirmed_tracks", "0") or 0)}
        for k, v in counts.items():
            if k.startswith(("rejected_", "iod_", "reinitialised", "internal_error")):
                causes[k] += v
    received = sum(p["received"] for p in per_shard.values())
    door = sum(p["refused"] for p in per_shard.values())
    consumed = sum(p["consumed"] for p in per_shard.values())
    # every received measurement ends refused at the door, consumed by the bank, or dropped
    unaccounted = sum(p["received"] - p["refused"] - p["consumed"] for p in per_shard.values())
    fused = sum(p["estimates"] for p in per_shard.values())
    score, lost_association = None, 0
    if unlabelled:
        score = association(labelled[TOPIC_DETECTION_TRUTH], labelled[TOPIC_ASSOCIATED],
                            set(estimates))
        associated = sum(num(n, Count.PUBLISHED_ASSOCIATED) for n in names)
        # every unlabelled row the banks took has a fate (`nodes.kit.unlabelled`)
        no_fate = consumed - sum(v for p in per_shard.values()
                                 for k, v in p["association_counts"].items()
                                 if k.startswith(FATE_PREFIX))
        lost_association = abs(published - recorded[TOPIC_DETECTION_TRUTH]) \
            + abs(associated - recorded[TOPIC_ASSOCIATED]) + abs(no_fate)
        score.update({"detections_without_fate": no_fate,
                      "associated_published": associated,
                      "associated_recorded": recorded[TOPIC_ASSOCIATED],
                      "truth_recorded": recorded[TOPIC_DETECTION_TRUTH]})
        estimates = by_owner(estimates, score["owner"])
        forecasts = by_owner(forecasts, score["owner"])
    err = position_errors(entries, estimates)
    ran = None if sim_wall is None else sim_wall[1] - sim_wall[0]
    n = max(len(entries), 1)
    surrogates: dict[str, dict[str, float | list[str]]] = {}
    for g in gap_nodes or []:
        st = status.get(g, {})
        surrogates[g] = {k: num(g, k) for k in (
            "received", "fits_made", "fits_physics", "fits_refused", "fits_skipped",
            "published_forecast", "forecasts_overtaken", "waiting_for_fit", "objects")}
        surrogates[g]["fit_seconds"] = float(st.get("fit_seconds", "0") or 0)
        surrogates[g]["object_ids"] = [x for x in st.get("object_ids", "").split(",") if x]
        surrogates[g]["rss_mib"] = rss.get(g, 0) / 1024.0
    start = t0 if t0 is not None else min((float(r.t[0]) for r in estimates.values()),
                                         default=0.0)
    return {
        "published": published, "recorded_measurements": recorded[TOPIC_MEASUREMENT_BATCH],
        "received_by_shards": received, "consumed_by_banks": consumed,
        "estimates_published": fused,
        "estimates_recorded": recorded[TOPIC_ESTIMATE_BATCH] - n_forecasts,
        "surrogates": surrogates, "forecasts_recorded": n_forecasts,
        "gap_errors": gap_errors(entries, estimates, forecasts, CATALOG_FILTER.motion_model)
        if surrogates else None,
        "gap_coverage": gap_coverage(estimates, forecasts, start, start + sim_s, pass_break_s)
        if surrogates else None,
        "rejected_and_pending": dict(causes), "refused_at_door": door,
        "dropped": sum(p["dropped"] for p in per_shard.values()),
        "unaccounted": unaccounted,
        "lost_measurements": abs(published - recorded[TOPIC_MEASUREMENT_BATCH])
        + abs(published - received) + abs(unaccounted) + lost_association,
        "association": score,
        "lost_estimates": max(fused - recorded[TOPIC_ESTIMATE_BATCH], 0),
        "objects_with_estimates": len(estimates),
        "sim_s": sim_s, "sim_wall_s": ran,
        "live_real_time_factor": None if not ran else sim_s / ran,
        "throughput_per_s": None if not ran else consumed / ran,
        "per_shard": per_shard,
        "rss_mib_per_object": sum(p["rss_mib"] for p in per_shard.values()) / n,
        "position_error_km": {"median": float(np.median(err)) if err.size else None,
                              "p95": float(np.percentile(err, 95)) if err.size else None,
                              "estimates": int(err.size)},
    }


def association(truth: list[MeasurementRows], associated: list[MeasurementRows],
                confirmed: set[str]) -> dict[str, Any]:
    """Return the association's score (`evaluation.association`) of a bag's rows.

    `truth`: the detections with their objects (``/ssa/detection_truth``); `associated`:
    with their track ids (``/ssa/measurement_associated``); `confirmed`: the ids of the
    tracks with estimates. ValueError for an associated detection the truth lacks.
    """
    if not truth:
        return score_association([], [], confirmed).as_dict()
    rows = MeasurementRows.concat(truth)
    labels = detection_labels(rows, MeasurementRows.concat(associated)) if associated \
        else [""] * len(rows)
    return score_association(rows.object_id, labels, confirmed).as_dict()


def by_owner(rows: States, owner: dict[str, str]) -> States:
    """Return each track's states as its object's (every track of one object merged).

    Tracks of no object (`owner` lacks them) are left out.
    """
    parts: dict[str, list[ObjectStates]] = defaultdict(list)
    for track, states in rows.items():
        if track in owner:
            parts[owner[track]].append(states)
    return {oid: merge(p) for oid, p in parts.items()}


def table(s: dict[str, Any]) -> str:
    """Return the summary as lines of text."""
    rows = [
        f"\nmeasurements: published {s['published']}, recorded {s['recorded_measurements']}, "
        f"received by the shards {s['received_by_shards']} (refused at the door "
        f"{s['refused_at_door']}, taken by the banks {s['consumed_by_banks']}, dropped "
        f"{s['dropped']}); lost: {s['lost_measurements']}",
        f"estimates: published {s['estimates_published']}, recorded "
        f"{s['estimates_recorded']}, for {s['objects_with_estimates']} objects",
        "rejected / pending by cause: " + (", ".join(
            f"{k} {v}" for k, v in sorted(s["rejected_and_pending"].items())) or "none"),
    ]
    if s["live_real_time_factor"]:
        rows.append(f"speed: {s['sim_s'] / 3600:g} h of sim time estimated in "
                    f"{s['sim_wall_s']:.1f} s of wall time (first measurement to last "
                    f"estimate) = {s['live_real_time_factor']:.0f}x real time, "
                    f"{s['throughput_per_s']:.0f} measurements/s")
    remote = s.get("remote_nodes", [])

    def rss(node: str, mib: float) -> str:
        return "RSS on its own host" if node in remote else f"RSS {mib:.0f} MiB"

    for n, p in s["per_shard"].items():
        tracks = (f", {p['confirmed_tracks']} confirmed tracks of unlabelled detections"
                  if p["association_counts"] else "")
        bank = (f", bank {p['bank_bytes_per_object']} B/object"
                if p["bank_bytes_per_object"] else "")
        rows.append(f"{n}: {p['objects']} objects{tracks}, {p['received']} received, "
                    f"{p['estimates']} estimates, {rss(n, p['rss_mib'])}{bank}")
    a = s.get("association")
    if a:
        rows.append(
            f"association of {a['detections']} unlabelled detections: accuracy "
            f"{a['accuracy']:.4f} (of the {a['in_confirmed']} in confirmed tracks, those of "
            f"the track's majority object), coverage {a['coverage']:.4f}; "
            f"{a['confirmed_tracks']} confirmed tracks for {a['objects_with_track']} of "
            f"{a['objects']} objects, {a['duplicate_tracks']} duplicates; detections "
            f"without a fate {a['detections_without_fate']}; associated "
            f"detections published {a['associated_published']}, recorded "
            f"{a['associated_recorded']}; truth recorded {a['truth_recorded']}")
    pe = s["position_error_km"]
    if pe["median"] is not None:
        rows.append(f"position error against the SGP4 truth: median {pe['median']:.3f} km, "
                    f"95 % {pe['p95']:.3f} km over {pe['estimates']} estimates")
    for n, g in s.get("surrogates", {}).items():
        rows.append(f"{n}: {g['objects']} objects; fits made {g['fits_made']} "
                    f"({g.get('fits_physics', 0)} physics-only), refused "
                    f"{g['fits_refused']}, skipped (gap over before its turn) "
                    f"{g['fits_skipped']}, waiting {g['waiting_for_fit']}; "
                    f"{g['fit_seconds']:.0f} s of fitting; {g['published_forecast']} "
                    f"forecasts ({g['forecasts_overtaken']} overtaken by a measurement); "
                    f"{rss(n, g['rss_mib'])}")
    gc = s.get("gap_coverage")
    if gc:
        made = sum(int(g["fits_made"]) for g in s.get("surrogates", {}).values())
        rows.append(f"gaps after the first {gc['after_s'] / 3600:g} h: {gc['gaps']}, "
                    f"{gc['with_forecast']} with a forecast; fits made {made}; "
                    f"{gc['object_gaps']} gaps as long after the object's first gap, "
                    f"{gc['object_with_forecast']} with a forecast")
    ge = s.get("gap_errors")
    if ge and ge.get("gaps_scored"):
        rows.append(
            f"gaps: {ge['forecasts']} forecasts recorded in {ge['gaps']} gaps; scored "
            f"{ge['forecasts_scored']} in {ge['gaps_scored']} gaps against the SGP4 truth: "
            f"surrogate median {ge['forecast_error_km']['median']:.3f} km (95 % "
            f"{ge['forecast_error_km']['p95']:.3f}), the filter coasting on its model "
            f"median {ge['coast_error_km']['median']:.3f} km (95 % "
            f"{ge['coast_error_km']['p95']:.3f}): coast / surrogate "
            f"{ge['coast_over_forecast']:.2f}; surrogate better in "
            f"{100 * ge['gaps_forecast_better']:.0f} % of the gaps")
    elif ge is not None:
        rows.append("gaps: no forecasts recorded (fits need pass ends over "
                    "min_span; see the surrogates' counts)")
    return "\n".join(rows)
