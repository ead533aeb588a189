"""The accounting of a catalog run (`ssa-fusion live --catalog`) from its bag and diagnostics.

Every measurement (published by the simulator, recorded, received by the shards, fused,
pending in an IOD batch, rejected by cause: none may be missing), the real-time factor the
run achieved, each shard's objects and memory, the estimates' position error against the
SGP4 truth of the catalog; with the surrogates, their fits and the forecasts' error against
that truth beside the filter's own coasting; with unlabelled detections, the association's
score (`evaluation.association`). `summarise` makes the numbers (``catalog.json``), `table`
the lines printed. Units: km, s (wall times Unix s), MiB.
"""

from __future__ import annotations

from collections import Counter, defaultdict
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any, TypedDict

import numpy as np

from ssa_fusion.apps import conjunction_table
from ssa_fusion.core.base.rows import MeasurementRows
from ssa_fusion.core.base.types import UpdateSource
from ssa_fusion.core.motion.element_sets import CatalogEntry, catalog_states
from ssa_fusion.evaluation.association import detection_labels, score_association
from ssa_fusion.evaluation.object_states import ObjectStates, States, StatesByObject, merge
from ssa_fusion.nodes.kit.diagnostics import RECORDED, Count
from ssa_fusion.nodes.kit.progress import RECORDED_ESTIMATES, RECORDED_MEASUREMENTS
from ssa_fusion.nodes.kit.unlabelled import EVENT_PREFIX, FATE_PREFIX
from ssa_fusion.params.defaults import CATALOG_FILTER, CATALOG_SURROGATE
from ssa_fusion.ros import bagio, messages
from ssa_fusion.ros.cdr_rows import estimate_batch_columns, measurement_batch_rows
from ssa_fusion.ros.topics import (
    TOPIC_ASSOCIATED,
    TOPIC_DETECTION_TRUTH,
    TOPIC_ESTIMATE_BATCH,
    TOPIC_MEASUREMENT_BATCH,
)
from ssa_fusion.studies.catalog_gaps import gap_coverage, gap_errors

if TYPE_CHECKING:
    from ssa_fusion.ros.interfaces import Message

__all__ = ["ShardSummary", "association", "by_owner", "conjunction_summary", "count",
           "position_errors", "statuses", "summarise", "table", "unrecorded"]


def statuses(diagnostics: Sequence[Message]) -> dict[str, dict[str, str]]:
    """Return the last /diagnostics key/values of each node (by node name)."""
    out: dict[str, dict[str, str]] = {}
    for msg in diagnostics:
        for status in msg.status:
            out[status.name] = {kv.key: kv.value for kv in status.values}
    return out


def count(status: dict[str, dict[str, str]], node: str, key: str) -> int:
    """Return the count `key` of `node` in `status` (`statuses`), 0 when absent."""
    v = status.get(node, {}).get(key, "0")
    return int(v) if v.isdigit() else 0


def unrecorded(status: dict[str, dict[str, str]], names: list[str], gaps: list[str],
               unlabelled: bool = False) -> int:
    """Return how many measurements and estimates are published but not yet recorded.

    As the nodes and the recorder report them (`status`: `statuses`; `names`: the filter
    shards, `gaps`: the surrogate shards); with `unlabelled`, the detections' truth and
    the associated detections too.
    """

    def num(node: str, key: str) -> int:
        return count(status, node, key)

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
    rec = _Recorded.read(bag, unlabelled)
    estimates, forecasts = rec.sensor.done(), rec.forecast.done()
    recorded = rec.rows
    published = count(status, "sensor_sim", Count.PUBLISHED)
    per_shard, causes = _shards(status, names, rss)
    received = sum(p["received"] for p in per_shard.values())
    consumed = sum(p["consumed"] for p in per_shard.values())
    # every received measurement ends refused at the door, consumed by the bank, or dropped
    unaccounted = sum(p["received"] - p["refused"] - p["consumed"] for p in per_shard.values())
    fused = sum(p["estimates"] for p in per_shard.values())
    score, lost_association = None, 0
    if unlabelled:
        score, lost_association = _association_score(rec, status, names, per_shard,
                                                     set(estimates), published, consumed)
        estimates = by_owner(estimates, score["owner"])
        forecasts = by_owner(forecasts, score["owner"])
    err = position_errors(entries, estimates)
    ran = None if sim_wall is None else sim_wall[1] - sim_wall[0]
    surrogates = _surrogates(status, gap_nodes or [], rss)
    start = t0 if t0 is not None else min((float(r.t[0]) for r in estimates.values()),
                                         default=0.0)
    return {
        "published": published, "recorded_measurements": recorded[TOPIC_MEASUREMENT_BATCH],
        "received_by_shards": received, "consumed_by_banks": consumed,
        "estimates_published": fused,
        "estimates_recorded": recorded[TOPIC_ESTIMATE_BATCH] - rec.n_forecasts,
        "surrogates": surrogates, "forecasts_recorded": rec.n_forecasts,
        "gap_errors": gap_errors(entries, estimates, forecasts, CATALOG_FILTER.motion_model)
        if surrogates else None,
        "gap_coverage": gap_coverage(estimates, forecasts, start, start + sim_s, pass_break_s)
        if surrogates else None,
        "rejected_and_pending": dict(causes),
        "refused_at_door": sum(p["refused"] for p in per_shard.values()),
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
        "rss_mib_per_object": sum(p["rss_mib"] for p in per_shard.values())
        / max(len(entries), 1),
        "position_error_km": {"median": float(np.median(err)) if err.size else None,
                              "p95": float(np.percentile(err, 95)) if err.size else None,
                              "estimates": int(err.size)},
    }


class _Recorded:
    """What a catalog run's bag holds.

    Rows per topic, the estimates, the forecasts and (for unlabelled detections) the truth
    and associated rows.
    """

    def __init__(self) -> None:
        self.rows: Counter[str] = Counter()
        self.sensor, self.forecast = StatesByObject(), StatesByObject()
        self.labelled: dict[str, list[MeasurementRows]] = defaultdict(list)
        self.n_forecasts = 0

    @classmethod
    def read(cls, bag: Path, unlabelled: bool) -> _Recorded:
        """Read the bag's batches (with `unlabelled`, the truth and associated rows too)."""
        out = cls()
        topics = [TOPIC_MEASUREMENT_BATCH, TOPIC_ESTIMATE_BATCH]
        # the measurements counted and the estimates read off their bytes (`cdr_rows`): their
        # generic decoding took most of a day-long catalog run's summary
        for m in bagio.read_bag(bag, topics=topics + ([TOPIC_DETECTION_TRUTH, TOPIC_ASSOCIATED]
                                                      if unlabelled else []),
                                decoders={TOPIC_MEASUREMENT_BATCH: measurement_batch_rows,
                                          TOPIC_ESTIMATE_BATCH: estimate_batch_columns}):
            if m.topic == TOPIC_MEASUREMENT_BATCH:
                out.rows[m.topic] += m.msg
                continue
            out.rows[m.topic] += len(m.msg.object_id)
            if m.topic in (TOPIC_DETECTION_TRUTH, TOPIC_ASSOCIATED):
                out.labelled[m.topic].append(messages.measurement_batch_from_msg(m.msg))
            elif m.topic == TOPIC_ESTIMATE_BATCH:
                e = messages.estimate_batch_from_msg(m.msg)
                into = out.forecast if e.update_source == UpdateSource.FORECAST else out.sensor
                into.add(e.object_id, e.t, e.x)
        out.n_forecasts = out.forecast.rows
        return out


def _shards(status: dict[str, dict[str, str]], names: list[str],
            rss: dict[str, int]) -> tuple[dict[str, ShardSummary], Counter[str]]:
    """Return each filter shard's summary and the rejections and pending rows by cause."""
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
    return per_shard, causes


def _association_score(rec: _Recorded, status: dict[str, dict[str, str]], names: list[str],
                       per_shard: dict[str, ShardSummary], confirmed: set[str],
                       published: int, consumed: int) -> tuple[dict[str, Any], int]:
    """Return the unlabelled detections' score and how many of them are unaccounted for."""
    score = association(rec.labelled[TOPIC_DETECTION_TRUTH], rec.labelled[TOPIC_ASSOCIATED],
                        confirmed)
    associated = sum(count(status, n, Count.PUBLISHED_ASSOCIATED) for n in names)
    # every unlabelled row the banks took has a fate (`nodes.kit.unlabelled`)
    no_fate = consumed - sum(v for p in per_shard.values()
                             for k, v in p["association_counts"].items()
                             if k.startswith(FATE_PREFIX))
    lost = abs(published - rec.rows[TOPIC_DETECTION_TRUTH]) \
        + abs(associated - rec.rows[TOPIC_ASSOCIATED]) + abs(no_fate)
    score.update({"detections_without_fate": no_fate,
                  "associated_published": associated,
                  "associated_recorded": rec.rows[TOPIC_ASSOCIATED],
                  "truth_recorded": rec.rows[TOPIC_DETECTION_TRUTH]})
    return score, lost


def _surrogates(status: dict[str, dict[str, str]], gap_nodes: list[str],
                rss: dict[str, int]) -> dict[str, dict[str, float | list[str]]]:
    """Return each catalog_surrogate's counts, fitting time, objects and memory."""
    surrogates: dict[str, dict[str, float | list[str]]] = {}
    for g in gap_nodes:
        st = status.get(g, {})
        surrogates[g] = {k: count(status, g, k) for k in (
            "received", "fits_made", "fits_physics", "fits_refused", "fits_skipped", "fits_cut",
            "published_forecast", "forecasts_overtaken", "waiting_for_fit", "objects")}
        surrogates[g]["fit_seconds"] = float(st.get("fit_seconds", "0") or 0)
        surrogates[g]["object_ids"] = [x for x in st.get("object_ids", "").split(",") if x]
        surrogates[g]["rss_mib"] = rss.get(g, 0) / 1024.0
    return surrogates


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
    return "\n".join(rows + run_rows(s))


def run_rows(s: dict[str, Any]) -> list[str]:
    """Return the lines of what the run cost and what it left out or cut (`live_catalog.costs`)."""
    rows = []
    if s.get("element_sets_skipped"):
        rows.append(f"element sets left out of the catalog: {s['element_sets_skipped']} "
                    "(each named on stderr at the start)")
    if s.get("startup_s") is not None or s.get("running_s") is not None:
        def sec(v: float | None) -> str:
            return "?" if v is None else f"{v:.1f} s"
        rows.append(f"wall time: start-up (command to the first measurement) "
                    f"{sec(s.get('startup_s'))}, running {sec(s.get('running_s'))}, summary "
                    f"{sec(s.get('summary_s'))}")
    if s.get("cpu_s"):
        each = ", ".join(f"{n} {v:.1f} s ({s['cpu_us_per_measurement'][n]} us)"
                         for n, v in s["cpu_s"].items())
        rows.append(f"CPU per node (per measurement published): {each}")
    if s.get("simulator_peak_rss_mib") is not None:
        rows.append(f"sensor_sim peak RSS {s['simulator_peak_rss_mib']:.0f} MiB")
    cut = {n: g.get("fits_cut", 0) for n, g in s.get("surrogates", {}).items()}
    if any(cut.values()):
        rows.append("fits cut by the stop (their gaps left to the filter's coasting): "
                    + ", ".join(f"{n} {v}" for n, v in cut.items()))
    for line in s.get("processes_ended_badly", []):
        rows.append(f"ended badly: {line}")
    return rows


def conjunction_summary(bag: Path, status: dict[str, dict[str, str]],
                        cdm_dir: Path) -> dict[str, Any]:
    """Return the conjunction node's accounting: its counters, the bag's batches, the CDMs."""
    mine = status.get("conjunction", {})
    standing = conjunction_table.latest(bag)
    return {"received": int(mine.get("received", 0)),
            "rescreenings": int(mine.get("rescreenings", 0)),
            "approaches_published": int(mine.get("approaches", 0)),
            "batches_recorded": standing.batches, "approaches_standing": len(standing.rows),
            "cdms": len(list(cdm_dir.glob("*.cdm"))), "cdm_dir": str(cdm_dir)}
