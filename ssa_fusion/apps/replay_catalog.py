"""`ssa-fusion replay` of a catalog's bag: its measurements through the catalog filter.

A bag is a catalog's (`catalog_reason`) when a catalog_filter recorded its settings with it
(``/ssa/config``, `params.settings.recorded_catalog`), when its measurements name more than
one object, or when it holds unlabelled detections (rows of ``/ssa/measurement_batch``
without an object id). One object's filter would put every object's measurements in one
track; this replay gives each object its own, as the catalog_filter node does, through the
same core policy (`core.catalog.fusion.CatalogFusion`: a `TrackBank`, one track per
``object_id``, and the association of unlabelled detections):

* the settings are those the catalog_filter recorded (every shard's); a bag without them is
  replayed with the catalog_filter's defaults and, as ``station``, the stations its
  measurements name (as ``ssa-fusion live --catalog`` sets it), and says so;
* offline, every recorded measurement message (a batch, or one Measurement) is one fusion,
  at its log
  time, in log-time order: what the filter's lockstep run fuses at once (each step's batch
  is fused before the next is published). The rows are checked as the node checks them
  (`core.catalog.fusion.row_causes`; a row stamped more than ``max_clock_lead`` after its
  log time is refused ``rejected_future``, its log time standing for the node's clock) and
  go to the shard whose key range holds their ``shard_key``;
* offline (``--offline``), the output bag has the live layout: the inputs as recorded, the
  new estimates on ``/ssa/estimate_batch`` (at most ``batch_rows`` rows a message, the
  shard's key range), the detections the association kept on
  ``/ssa/measurement_associated``, and the settings used on ``/ssa/config``. The catalog
  surrogates' gap forecasts (update source FORECAST on ``/ssa/estimate_batch``) are not
  recomputed and not copied (said so);
* over ROS, the inputs are played at ``--rate`` into fresh catalog_filter processes (one a
  shard, with the settings above) and recorded with them (`replay_live`); no catalog
  surrogate runs (its settings are not recorded).

Per object, the estimates do not depend on how the rows are cut into fusions as long as
each object's rows come in epoch order (`core.catalog.track_bank`), so a run whose batches the node
fused otherwise (open loop, two messages in one ``batch_period``) gives the same estimates.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
import time
from collections import Counter
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ssa_fusion.apps import runs
from ssa_fusion.apps.partial import removed_if_unfinished
from ssa_fusion.core.base import types
from ssa_fusion.core.base.rows import EstimateRows, MeasurementRows
from ssa_fusion.core.base.types import KIND_NAMES, Cause, Kind, UpdateSource
from ssa_fusion.core.catalog.association import DetectionFate
from ssa_fusion.core.catalog.fusion import CatalogFusion, Fused, in_epoch_order, row_causes
from ssa_fusion.core.catalog.unlabelled import elevation_masks, is_unlabelled
from ssa_fusion.core.earth.stations import network_stations
from ssa_fusion.formats.sites import load_sites, load_station_map
from ssa_fusion.params import settings
from ssa_fusion.params.defaults import CATALOG_FILTER
from ssa_fusion.ros import bagio, messages
from ssa_fusion.ros.topics import (
    TOPIC_ASSOCIATED,
    TOPIC_CONFIG,
    TOPIC_DETECTION_TRUTH,
    TOPIC_ESTIMATE_BATCH,
    TOPIC_MEASUREMENT,
    TOPIC_MEASUREMENT_BATCH,
    TOPIC_TRUTH,
    TOPIC_WITHHELD,
)

INPUTS = (TOPIC_MEASUREMENT_BATCH, TOPIC_MEASUREMENT, TOPIC_DETECTION_TRUTH, TOPIC_TRUTH,
          TOPIC_WITHHELD)
"""Topics copied from a catalog bag into its offline replay, as recorded."""
MEASURED = (TOPIC_MEASUREMENT_BATCH, TOPIC_MEASUREMENT)
"""Topics whose messages the catalog filter fuses."""
TELLING = (TOPIC_CONFIG, *MEASURED)
"""Topics that tell a catalog's bag from one object's (`catalog_reason`)."""
FILTER_SETTINGS = tuple(k for k in settings.CATALOG_KEYS if k != "shard")
"""The recorded parameters every shard of one graph shares."""


def config_texts(raw: list[bagio.BagMessage]) -> list[str]:
    """Return the ``/ssa/config`` JSON texts of a bag's messages, in log-time order."""
    return [str(m.msg.data) for m in raw if m.topic == TOPIC_CONFIG]


def measured(raw: list[bagio.BagMessage]) -> MeasurementRows | None:
    """Return every measurement of a bag's messages (batches and single ones) as rows.

    In log-time order, a batch's rows in its order; batches whose columns disagree left
    out (the replay counts them). None without a measurement.
    """
    parts = []
    for m in raw:
        if m.topic in MEASURED:
            try:
                parts.append(measurement_rows(m))
            except ValueError:
                continue
    return MeasurementRows.concat(parts) if parts else None


def catalog_reason(raw: list[bagio.BagMessage]) -> str | None:
    """Return why a bag is a catalog's, or None for one object's.

    `raw`: its messages of `TELLING` (`bagio.read_bag`: batches as they are). Measurements
    without an object id are unlabelled detections in batches or beside an object's; alone
    in single messages, they are one object's (a bag recorded before object ids).
    ValueError on a malformed ``/ssa/config``.
    """
    if settings.recorded_catalog(config_texts(raw)):
        return f"its catalog_filter settings are recorded ({TOPIC_CONFIG})"
    rows = measured(raw)
    ids = set(rows.object_id) if rows is not None else set()
    batched = any(m.topic == TOPIC_MEASUREMENT_BATCH for m in raw)
    labelled = sorted(ids - {""})
    if len(labelled) > 1:
        return f"its measurements are of {len(labelled)} objects ({shown_ids(labelled)})"
    if "" in ids and (batched or labelled):
        return "it holds unlabelled detections (measurements without object id" + (
            f" beside those of {labelled[0]})" if labelled else f" in {TOPIC_MEASUREMENT_BATCH})")
    return None


def shown_ids(ids: list[str], most: int = 5) -> str:
    """Return up to `most` of `ids`, comma-separated, with how many more."""
    more = f", ... ({len(ids) - most} more)" if len(ids) > most else ""
    return ", ".join(ids[:most]) + more


@dataclass
class CatalogSettings:
    """The catalog_filter parameters (SI, as declared) a replay runs each shard with."""

    shards: list[dict[str, Any]]
    """Per shard, in shard order."""
    origin: str
    """Where they came from (printed)."""


def catalog_settings(raw: list[bagio.BagMessage], sites: Path | None) -> CatalogSettings:
    """Return the catalog_filter settings to replay a catalog bag with (module docstring).

    `sites`: a sites file (``--sites``) for stations of one's own, replacing the recorded
    one. ValueError when the recorded shards disagree on a setting, or when the bag records
    none and its measurements name no station.
    """
    recorded = settings.recorded_catalog(config_texts(raw))
    own = {"sites": str(sites)} if sites is not None else {}
    if recorded:
        first = recorded[0]
        for p in recorded[1:]:
            differ = [k for k in FILTER_SETTINGS if p.get(k) != first.get(k)]
            if differ:
                raise ValueError(f"the recorded catalog_filter shards disagree on "
                                 f"{', '.join(differ)}; one graph's shards share them")
        shards = int(first["shards"])
        if len(recorded) != shards:
            # a shard that recorded nothing (e.g. on another host) runs as the others
            recorded = [{**first, "shard": k} for k in range(shards)]
        return CatalogSettings([{**p, **own} for p in recorded],
                               f"recorded with the bag ({TOPIC_CONFIG}; {shards} shard(s))")
    rows = measured(raw)
    sensor = rows.source == types.Source.SENSOR if rows is not None else np.zeros(0, bool)
    stations = sorted({rows.frame_id[i] for i in np.flatnonzero(sensor)} if rows else set())
    if not stations:
        raise ValueError("no sensor measurement names a station")
    d = dataclasses.asdict(CATALOG_FILTER)
    assumed = {**d, "station": ",".join(stations), **own}
    return CatalogSettings(
        [assumed], f"assumed (the bag records no catalog_filter settings on {TOPIC_CONFIG}): "
                   f"the catalog_filter's defaults (motion model {d['motion_model']}, q "
                   f"{d['q']:g} m^2/s^3, IOD from {d['iod_samples']} measurements within "
                   f"{d['iod_max_span']:g} s, reinit after {d['reinit_after']} gate misses), "
                   f"one shard, station {assumed['station']} (the stations its "
                   f"measurements name)")


class Shard:
    """One catalog_filter shard of a replay: its settings, key range and tracks."""

    def __init__(self, params: Mapping[str, Any]) -> None:
        self.params = dict(params)
        sites = str(params.get("sites", ""))
        self.stations = network_stations(str(params["station"]), load_station_map(sites))
        masks = elevation_masks(self.stations, load_sites(sites) if sites else {})
        self.fusion = CatalogFusion(settings.filter_options(params), self.stations, masks,
                                    max_objects=int(params["max_objects"]),
                                    evict_after_s=float(params["evict_after"]))
        self.key_range = messages.shard_range(int(params["shard"]), int(params["shards"]))


@dataclass
class CatalogResult:
    """What a catalog replay published, with the log time (ns) of the input that made it."""

    estimates: list[tuple[int, tuple[int, int], EstimateRows]] = field(default_factory=list)
    """(log time, shard key range, rows), in publication order."""
    associated: list[tuple[int, MeasurementRows]] = field(default_factory=list)
    """(log time, rows) on ``/ssa/measurement_associated``, in publication order: each
    fusion's associated detections, then those a deferred decision moved to another track
    (`core.catalog.unlabelled.RowsOutcome.relabelled`)."""
    causes: Counter[str] = field(default_factory=Counter)
    """Rows refused or pending, by cause (the node's /diagnostics counts)."""
    fates: Counter[DetectionFate] = field(default_factory=Counter)
    """The unlabelled detections' fates (`core.catalog.association.DetectionFate`)."""
    rows: int = 0
    """Measurement rows read."""

    def objects(self) -> set[str]:
        """Return the ids of the objects (or tracks) with an estimate."""
        return {o for _, _, e in self.estimates for o in e.object_id}


def measurement_rows(msg: bagio.BagMessage) -> MeasurementRows:
    """Return one recorded measurement message (a batch or a Measurement) as rows.

    ValueError for a batch whose columns disagree.
    """
    if msg.topic == TOPIC_MEASUREMENT_BATCH:
        return messages.measurement_batch_from_msg(msg.msg)
    m = messages.measurement_from_msg(msg.msg)
    z, R = np.zeros(3), np.zeros((3, 3))
    z[:m.z.size], R[:m.z.size, :m.z.size] = m.z, m.R
    return MeasurementRows(np.array([m.t]), [m.object_id], [m.frame_id], z[None], R[None],
                           np.array([m.kind], np.uint8), np.array([m.source], np.uint8),
                           np.array([m.horizon]),
                           np.array([msg.msg.shard_key], np.uint32))


def replay(raw: list[bagio.BagMessage], shards: list[Shard]) -> CatalogResult:
    """Fuse the measurement messages of `raw` (log-time order) in `shards` (module docstring)."""
    result = CatalogResult()
    for msg in raw:
        if msg.topic not in MEASURED:
            continue
        try:
            rows = measurement_rows(msg)
        except ValueError:
            n = len(msg.msg.object_id)
            result.rows += n
            result.causes[Cause.REJECTED_MALFORMED] += n
            continue
        result.rows += len(rows)
        for shard in shards:
            fused = fuse(shard, rows, msg.t_ns * 1e-9, len(shards), result.causes)
            if fused is None:
                continue
            if fused.unlabelled is not None:
                result.fates.update(fused.unlabelled.fates)
            for e in fused.estimates():
                result.estimates.append((msg.t_ns, shard.key_range, e))
            if fused.unlabelled is not None:  # the associated, then the relabelled
                result.associated += [(msg.t_ns, a) for a in (fused.unlabelled.associated,
                                                              fused.unlabelled.relabelled)
                                      if len(a)]
    return result


def fuse(shard: Shard, rows: MeasurementRows, clock: float, shards: int,
         causes: Counter[str]) -> Fused | None:
    """Fuse the rows of `rows` that `shard` takes (at `clock`, Unix s); count the others.

    With several `shards`, a row goes to the shard whose key range holds its ``shard_key``
    (a key that is not the CRC-32 of its id is refused ``rejected_shard_key``, an unlabelled
    row ``rejected_unlabelled_sharded``, by shard 0 only: once each).
    """
    lo, hi = shard.key_range
    mine = np.ones(len(rows), bool)
    if shards > 1:
        key = rows.shard_key.astype(np.int64)
        unlabelled = is_unlabelled(rows.object_id)
        wrong = (key != messages.shard_keys(rows.object_id)) & ~unlabelled
        if shard.key_range[0] == 0:
            causes["rejected_shard_key"] += int(wrong.sum())
            causes["rejected_unlabelled_sharded"] += int(unlabelled.sum())
        mine = (key >= lo) & (key <= hi) & ~wrong & ~unlabelled
    cause = row_causes(rows, shard.stations)
    lead = float(shard.params["max_clock_lead"])
    cause[(cause == "") & (rows.t > clock + lead)] = Cause.REJECTED_FUTURE
    for key, n in Counter(cause[mine & (cause != "")].tolist()).items():
        causes[str(key)] += n
    batch = in_epoch_order([rows.take(np.flatnonzero(mine & (cause == "")))])
    if batch is None or not len(batch):
        return None
    fused = shard.fusion.fuse(batch)
    if fused.bank is not None:
        causes.update(c for c in fused.bank.cause if c)
    return fused


def write(out: Path, raw: list[bagio.BagMessage], result: CatalogResult,
          used: Sequence[Mapping[str, Any]]) -> None:
    """Write the replay's bag `out` (module docstring): inputs, estimates, settings used."""
    writer = bagio.BagWriter(out)
    try:
        first_ns = min((m.t_ns for m in raw), default=0)
        writer.add_topic(TOPIC_CONFIG, "std_msgs/msg/String", [bagio.LATCHED_QOS])
        text = bagio.typestore().types["std_msgs/msg/String"]
        for p in used:
            writer.write_msg(TOPIC_CONFIG, first_ns,
                             text(data=settings.catalog_config_message(p)))
        rows: list[tuple[int, int, str, Any]] = []
        for m in raw:
            if m.topic in INPUTS:
                if not writer.has_topic(m.topic):
                    writer.add_topic(m.topic, m.msgtype)
                rows.append((m.t_ns, 0, m.topic, messages.recode(m.msg, m.msgtype,
                                                                  bagio.rosbags_classes())))
        classes = bagio.rosbags_classes()
        writer.add_topic(TOPIC_ESTIMATE_BATCH, f"{bagio.MSG_PACKAGE}/msg/EstimateBatch")
        most = int(used[0]["batch_rows"])
        for t_ns, key_range, e in result.estimates:
            e.shard_key = messages.shard_keys(e.object_id)
            for part in np.array_split(np.arange(len(e)), -(-len(e) // most)):
                rows.append((t_ns, 1, TOPIC_ESTIMATE_BATCH,
                             messages.estimate_batch_to_msg(e.take(part), key_range, classes)))
        if result.associated:
            writer.add_topic(TOPIC_ASSOCIATED, f"{bagio.MSG_PACKAGE}/msg/MeasurementBatch")
        for t_ns, a in result.associated:
            a.shard_key = messages.shard_keys(a.object_id)
            rows.append((t_ns, 1, TOPIC_ASSOCIATED,
                         messages.measurement_batch_to_msg(a, classes=classes)))
        for t_ns, _, topic, msg in sorted(rows, key=lambda r: (r[0], r[1])):
            writer.write_msg(topic, t_ns, msg)
    finally:
        writer.close()


def refusal(args: argparse.Namespace, reason: str) -> str | None:
    """Return why `args` cannot replay a catalog bag (`reason`: why it is one), or None."""
    bag = args.bag
    if args.smooth:
        return (f"{bag} is a catalog's bag ({reason}); --smooth smooths one object's track: "
                f"replay it without --smooth")
    if args.scenario or args.params_file is not None:
        return (f"{bag} is a catalog's bag ({reason}); --scenario and --params-file set one "
                f"object's filter, while a catalog replays with the catalog_filter settings "
                f"recorded with the bag (its defaults for a bag without them): drop them")
    return None


def unfusable(raw: list[bagio.BagMessage], reason: str) -> str | None:
    """Return why the catalog filter can fuse none of a catalog bag's measurements, or None.

    It fuses range/azimuth/elevation only; one object's filter would mix the objects.
    """
    rows = measured(raw)
    kinds = Counter(rows.kind[rows.source == types.Source.SENSOR].tolist()
                    if rows is not None else [])
    if kinds.get(Kind.RANGE_AZ_EL):
        return None
    names = ", ".join(KIND_NAMES.get(types.Kind(k), str(k)) if k in set(types.Kind) else str(k)
                      for k in sorted(kinds))
    return (f"the bag is a catalog's ({reason}), and its sensor measurements are "
            f"{names or 'none'}: the catalog filter fuses range/az/el only, and one object's "
            f"filter would put every object's measurements in one track. Replay one object's "
            f"measurements at a time (a bag of each object's), or record range/az/el")


def run(args: argparse.Namespace, telling: list[bagio.BagMessage], reason: str,
        out: Path) -> int:
    """Replay a catalog bag into `out`; return the exit code.

    `telling`: its `TELLING` messages; `reason`: `catalog_reason`'s. Offline
    (``--offline``), else over ROS into catalog_filter processes (`replay_live`).
    """
    why = refusal(args, reason) or unfusable(telling, reason)
    if why:
        print(f"error: {why}", file=sys.stderr)
        return 2
    if out.exists():
        print(f"error: {out} exists already; choose another "
              f"{'--out' if args.offline else '--record'}", file=sys.stderr)
        return 2
    try:
        chosen = catalog_settings(telling, args.sites)
        shards = [Shard(p) for p in chosen.shards]
        raw = list(bagio.read_bag(args.bag, topics=INPUTS))
    except (bagio.BagError, ValueError, OSError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    print(f"replay: {args.bag} is a catalog's bag ({reason}): each object its own track, "
          f"as the catalog filter gives it (core.catalog.fusion)")
    print(f"replay: catalog_filter settings: {chosen.origin}")
    forecasts = sum(len(m.msg.object_id) for m in bagio.read_bag(args.bag,
                                                                 topics=[TOPIC_ESTIMATE_BATCH])
                    if m.msg.update_source == UpdateSource.FORECAST)
    if forecasts:
        print(f"replay: the bag's {forecasts} catalog-surrogate gap forecasts are not "
              f"recomputed (no catalog surrogate runs in a replay); {out} will not hold them")
    if not args.offline:
        return replay_live(args, raw, chosen, out)
    result = replay(raw, shards)
    try:
        with removed_if_unfinished(out):
            write(out, raw, result, chosen.shards)
    except OSError as exc:
        print(f"error: cannot write {out}: {exc}", file=sys.stderr)
        return 2
    n = sum(len(e) for _, _, e in result.estimates)
    print(f"offline replay of {args.bag}: {n} estimates for {len(result.objects())} objects "
          f"from {result.rows} measurement rows -> {out}")
    print("replay: rejected / pending by cause: " + (", ".join(
        f"{k} {v}" for k, v in sorted(result.causes.items()) if v) or "none"))
    if result.fates:
        print(f"replay: {sum(result.fates.values())} unlabelled detections associated: "
              + ", ".join(f"{f.name.lower()} {n}" for f, n in sorted(result.fates.items()))
              + f"; {sum(len(a) for _, a in result.associated)} rows on {TOPIC_ASSOCIATED} "
              "(a detection a deferred decision moved again)")
    return 0


def node_params(p: Mapping[str, Any], sites: Path | None) -> dict[str, Any]:
    """Return the parameters of a catalog_filter process of shard settings `p` (SI).

    Its `settings.CATALOG_KEYS`, under sim time; `sites`: ``--sites``, as an absolute path
    (the node's working directory may differ).
    """
    own = {"sites": str(sites.resolve())} if sites is not None else {}
    return {"use_sim_time": True, **{k: p[k] for k in settings.CATALOG_KEYS}, **own}


def replay_live(args: argparse.Namespace, raw: list[bagio.BagMessage],
                chosen: CatalogSettings, record: Path) -> int:
    """Play a catalog bag into fresh catalog_filter processes (one a shard) and record them.

    The recorder and the shards of `chosen` start; the bag's measurement batches (and
    single measurements, truth, withheld and the detections' truth) are played with a
    ``/clock`` from their stamps at ``--rate`` (`ros.player.Player`) once every node has
    matched its publishers; the run ends when the estimates stop. Each shard fuses what
    arrived every ``batch_period`` wall s: per object the same estimates as the recorded
    run (module docstring), whatever the rate.
    """
    from ssa_fusion.ros import qos
    from ssa_fusion.ros.interfaces import EstimateBatch
    from ssa_fusion.ros.player import Player
    from ssa_fusion.ros.processes import ended_badly, recorded_short
    from ssa_fusion.ros.readiness import OUTPUT, ReadyNodes

    names = [f"catalog_filter_{int(p['shard'])}" for p in chosen.shards]
    opened = runs.replay_graph(args, record)
    if opened is None:
        return 2
    graph, logs = opened
    played = [m for m in raw if m.topic in INPUTS]
    print(f"replay: {args.bag} at rate {args.rate:g} into {len(names)} catalog_filter "
          f"process(es); ROS domain {graph.domain_id}, run {graph.run}; logs in {logs}",
          flush=True)
    t0 = time.monotonic()
    try:
        graph.start_node("recorder", params={"use_sim_time": True, "bag": str(record)})
        for n, p in zip(names, chosen.shards, strict=True):
            graph.start_node("catalog_filter", "-r", f"__node:={n}", name=n,
                             params=node_params(p, args.sites))
        player = Player(graph.probe, played, args.rate)
        rows: list[int] = []
        graph.subscribe(EstimateBatch, TOPIC_ESTIMATE_BATCH,
                        lambda m: rows.append(len(m.object_id)), qos.CATALOG_QOS)
        filters = {TOPIC_MEASUREMENT_BATCH, TOPIC_MEASUREMENT}
        graph.wait_for(player.subscribers_ready(
            {t: 1 + len(names) * (t in filters) for t in player.pubs}),
            30.0, "the catalog filter(s) and the recorder to subscribe")
        needs = [f"recorder:{TOPIC_ESTIMATE_BATCH}={len(names)}",
                 *(f"{n}:{OUTPUT}{TOPIC_ESTIMATE_BATCH}" for n in names),
                 *(f"{who}:{t}" for t in sorted(filters & set(player.pubs))
                   for who in ("recorder", *names))]
        readers = ReadyNodes(graph.probe, graph.subscribe)
        graph.play(player, lambda: readers.ready(needs),
                   "the catalog filter(s) and the recorder to match their publishers")
        graph.wait_quiet(lambda: sum(rows), quiet_s=1.0, limit_s=60.0)
    finally:
        problems = graph.close()  # each stopped in turn, newest first
    if ended_badly(problems) or recorded_short(
            record, {TOPIC_ESTIMATE_BATCH: sum(rows)}, lambda m: len(m.object_id)):
        return 1
    print(f"replayed {player.published} messages of {args.bag} at rate {args.rate:g} in "
          f"{time.monotonic() - t0:.1f} s: {sum(rows)} estimates; recorded to {record}")
    return 0
