"""`ssa-fusion report BAG` for a catalog's bag: every object scored on its own rows.

A bag is a catalog's as `replay` tells it (`replay_catalog.catalog_reason`): a live
``--catalog`` run (labelled, or unlabelled detections with ``/ssa/detection_truth``), any
number of shards, or its offline replay. One object's report would put every object's
measurements against one track; this one never mixes objects
(`evaluation.catalog_scores`):

* per object (per track for unlabelled detections: its rows on
  ``/ssa/measurement_associated``): measurements and estimates; the position error of its
  estimates against the truth recorded on ``/ssa/truth`` (median, 95 %) and their NEES
  against the 95 % χ² band (6 dof), where the bag holds a truth (a live catalog run records
  none: its truth is SGP4 of the catalog); the NIS the filter published with each fused
  measurement against its 95 % χ² band (3 dof); the post-fit residuals of the object's own
  range/az/el measurements against its own fused estimates at their epochs, in units of the
  measurement σ;
* the catalog's summary (objects, estimates, pooled error and bands, residual RMS) and the
  worst `WORST` objects; for unlabelled detections the association's accuracy and coverage
  against ``/ssa/detection_truth`` (`evaluation.association`); a track is scored against
  the truth of the object most of its detections are of;
* the settings: the catalog_filter's recorded on ``/ssa/config`` (every shard's), or the
  defaults a replay would assume (`replay_catalog.catalog_settings`).

Written: ``report.json`` (summary, settings, association, the worst objects),
``objects.csv`` (every object, one line each) and ``report.html`` (the summary and the worst
objects as tables: bounded whatever the catalog's size). The catalog surrogates' gap
forecasts (update source FORECAST) are counted, not scored. A run with the conjunction node
also gets its table of close approaches (`conjunction_table`: the most likely printed,
every one in ``conjunctions.csv``).
"""

from __future__ import annotations

import argparse
import csv
import html
import json
import sys
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ssa_fusion.apps import conjunction_table, replay_catalog
from ssa_fusion.core.base.rows import EstimateRows, MeasurementRows
from ssa_fusion.core.base.types import Kind, Source, StateEstimate, UpdateSource
from ssa_fusion.core.catalog.batch_ekf import BatchEKF
from ssa_fusion.core.earth.stations import network_stations
from ssa_fusion.evaluation import catalog_scores as cs
from ssa_fusion.evaluation.association import detection_labels, score_association
from ssa_fusion.formats.sites import load_station_map
from ssa_fusion.params import settings
from ssa_fusion.ros import bagio, messages
from ssa_fusion.ros.topics import (
    TOPIC_ASSOCIATED,
    TOPIC_CONFIG,
    TOPIC_DETECTION_TRUTH,
    TOPIC_ESTIMATE_BATCH,
    TOPIC_TRUTH,
)

WORST = 20
"""Objects listed by name in the printed table, report.json and report.html."""
SHOWN = ("station", "motion_model", "q", "gate", "iod_samples", "iod_max_span", "reinit_after",
         "shards")
"""The catalog_filter settings the summary names (all of them in report.json)."""
TRUTH_TYPES = (bagio.STATE_ESTIMATE, bagio.ESTIMATE_BATCH)
"""What ``/ssa/truth`` may hold: one state a message, or a batch of them."""


@dataclass
class _Rows:
    """Columns gathered from a bag's batches (concatenated at the end)."""

    parts: dict[str, list[np.ndarray]] = field(default_factory=dict)

    def add(self, **cols: np.ndarray) -> None:
        """Append one batch's columns (each of the batch's rows)."""
        for k, v in cols.items():
            self.parts.setdefault(k, []).append(v)

    def get(self, name: str, shape: tuple[int, ...] = (0,)) -> np.ndarray:
        """Return column `name` of every batch, or an empty array of `shape`."""
        p = self.parts.get(name)
        return np.concatenate(p) if p else np.zeros(shape)


@dataclass
class CatalogReport:
    """What the report of a catalog bag shows (module docstring)."""

    scores: cs.ObjectScores
    summary: dict[str, Any]
    worst: np.ndarray
    ranked_by: str
    origin: str
    parameters: list[dict[str, Any]]
    association: dict[str, Any] | None
    unlabelled: int
    """Measurement rows without object id (detections)."""
    forecasts: int
    notes: list[str]
    counts: dict[str, int]
    """Messages read, by topic."""


def measurement_model(params: dict[str, Any]) -> BatchEKF:
    """Return the measurement model of a shard's settings (its stations: `BatchEKF`)."""
    sites = str(params.get("sites", ""))
    stations = network_stations(str(params["station"]), load_station_map(sites))
    return BatchEKF(settings.filter_options(params), list(stations.values()))


def _add_measurements(rows: MeasurementRows, codes: cs.Codes, ekf: BatchEKF,
                      into: _Rows) -> None:
    """Add the labelled sensor range/az/el rows of `rows` to `into` (object codes)."""
    keep = ((rows.source == Source.SENSOR) & (rows.kind == Kind.RANGE_AZ_EL)
            & (np.asarray(rows.object_id, dtype=str) != ""))
    k = np.flatnonzero(keep)
    if not len(k):
        return
    r = rows.take(k)
    frame = np.asarray(r.frame_id, dtype=str)
    station = np.full(len(r), -1, np.int64)
    for name, i in ekf.index.items():
        station[frame == name] = i
    into.add(code=codes.encode(r.object_id), t=r.t, station=station, z=r.z,
             sigma=np.sqrt(np.diagonal(r.R, axis1=1, axis2=2)))


def build(bag: Path, telling: list[bagio.BagMessage], sites: Path | None) -> CatalogReport:
    """Read the catalog bag `bag` and score every object (module docstring).

    `telling`: the messages that told it a catalog's (`replay_catalog.catalog_reason`): its
    ``/ssa/config`` and, when those record no catalog_filter settings, its measurements.
    The bag is read twice, message by message (measurements, truth and associations, then
    estimates), keeping per row only what the scores need. ValueError for settings it
    cannot use.
    """
    chosen = replay_catalog.catalog_settings(telling, sites)
    ekf = measurement_model(chosen.shards[0])
    got = _Measured.read(bag, telling, ekf)
    codes, meas, truth = got.codes, got.meas, got.truth
    labels = _Labels(got.detections, got.associated)
    has_truth = bool(truth.parts)
    est, fused, forecasts = _read_estimates(bag, got, labels, has_truth)
    est_code = est.get("code").astype(np.int64)
    score = labels.score({codes.ids[c] for c in np.unique(est_code).tolist()})
    truth_object = [labels.truth_object(i) for i in codes.ids]
    nan = np.full(len(est_code), np.nan)
    err = cs.TruthErrors(est.get("err") if has_truth else nan,
                         est.get("nees") if has_truth else nan)
    f_code = fused.get("code").astype(np.int64)
    f_t, f_nis = fused.get("t"), fused.get("nis")
    m_code = meas.get("code").astype(np.int64)
    res = cs.postfit_residuals(ekf, cs.Matcher(f_code, f_t), fused.get("r", (0, 3)), m_code,
                               meas.get("t"), meas.get("station").astype(np.int64),
                               meas.get("z", (0, 3)), meas.get("sigma", (0, 3)))
    has_nis = f_nis > 0.0
    scores = cs.object_scores(codes.ids, m_code, est_code, err, f_code[has_nis],
                              f_nis[has_nis], res, truth_object)
    summary = cs.summary(scores, err, f_nis[has_nis], res)
    worst, ranked_by = cs.worst(scores, WORST)
    notes = _notes(has_truth, got.unlabelled, bool(got.associated), forecasts)
    return CatalogReport(scores, summary, worst, ranked_by, chosen.origin, chosen.shards,
                         score, got.unlabelled, forecasts, notes, dict(got.counts))


@dataclass
class _Measured:
    """The first read of a catalog bag: measurements, truth and associations.

    ``codes`` numbers the measured objects (and tracks), ``meas`` their measurements,
    ``truth_codes`` and ``truth`` the truth's objects and states; ``detections`` and
    ``associated`` the unlabelled detections with their objects and with their tracks;
    ``unlabelled`` the measurements without object id; ``counts`` the messages read by topic.
    """

    codes: cs.Codes = field(default_factory=cs.Codes)
    meas: _Rows = field(default_factory=lambda: _Rows())
    truth_codes: cs.Codes = field(default_factory=cs.Codes)
    truth: _Rows = field(default_factory=lambda: _Rows())
    detections: list[MeasurementRows] = field(default_factory=list)
    associated: list[MeasurementRows] = field(default_factory=list)
    unlabelled: int = 0
    counts: Counter[str] = field(default_factory=Counter)

    @classmethod
    def read(cls, bag: Path, telling: list[bagio.BagMessage], ekf: BatchEKF) -> _Measured:
        """Read the bag's measurements, truth and associations, message by message."""
        out = cls()
        out.counts.update(m.topic for m in telling if m.topic == TOPIC_CONFIG)
        for m in bagio.read_bag(bag, topics=[*replay_catalog.MEASURED, TOPIC_TRUTH,
                                             TOPIC_DETECTION_TRUTH, TOPIC_ASSOCIATED]):
            out.counts[m.topic] += 1
            if m.topic in replay_catalog.MEASURED:
                try:
                    rows = replay_catalog.measurement_rows(m)
                except ValueError:
                    continue
                out.unlabelled += int(np.count_nonzero(np.asarray(rows.object_id,
                                                                  dtype=str) == ""))
                _add_measurements(rows, out.codes, ekf, out.meas)
            elif m.topic == TOPIC_TRUTH and m.msgtype in TRUTH_TYPES:
                e = (messages.estimate_batch_from_msg(m.msg)
                     if m.msgtype == bagio.ESTIMATE_BATCH
                     else _one(messages.estimate_from_msg(m.msg)))
                out.truth.add(code=out.truth_codes.encode(e.object_id), t=e.t, x=e.x)
            elif m.topic == TOPIC_DETECTION_TRUTH:
                out.detections.append(messages.measurement_batch_from_msg(m.msg))
            elif m.topic == TOPIC_ASSOCIATED:
                a = messages.measurement_batch_from_msg(m.msg)
                out.associated.append(a)
                _add_measurements(a, out.codes, ekf, out.meas)
        return out


def _read_estimates(bag: Path, got: _Measured, labels: _Labels,
                    has_truth: bool) -> tuple[_Rows, _Rows, int]:
    """Read the estimates (the second read): errors against the truth, the fused ones' NIS.

    Returns the estimates' rows (code, and with truth the position error km and NEES), the
    fused ones' (code, epoch, position km, NIS) and the number of gap forecasts (counted,
    not scored).
    """
    codes, truth_codes = got.codes, got.truth_codes
    matcher = cs.Matcher(got.truth.get("code").astype(np.int64), got.truth.get("t"))
    truth_x = got.truth.get("x", (0, 6))
    truth_of: list[int] = []
    est, fused = _Rows(), _Rows()
    forecasts = 0
    for m in bagio.read_bag(bag, topics=[TOPIC_ESTIMATE_BATCH]):
        got.counts[m.topic] += 1
        e = messages.estimate_batch_from_msg(m.msg)
        if e.update_source == UpdateSource.FORECAST:
            forecasts += len(e)
            continue
        c = codes.encode(e.object_id)
        truth_of += [truth_codes.find(labels.truth_object(i)) for i in codes.ids[len(truth_of):]]
        err = (cs.truth_errors(matcher, truth_x, np.asarray(truth_of, np.int64)[c], e.t, e.x,
                               e.P) if has_truth else None)
        est.add(code=c, **({"err": err.position_km, "nees": err.nees} if err else {}))
        if e.update_source == UpdateSource.SENSOR:
            fused.add(code=c, t=e.t, r=e.x[:, :3], nis=e.nis)
    return est, fused, forecasts


def _notes(has_truth: bool, unlabelled: int, associated: bool, forecasts: int) -> list[str]:
    """Return what the report cannot score, in words."""
    notes = []
    if not has_truth:
        notes.append(f"no {TOPIC_TRUTH} in the bag: no position error or NEES (a live "
                     "catalog run records no truth: it is SGP4 of its catalog)")
    if unlabelled and not associated:
        notes.append(f"{unlabelled} detections without object id and nothing on "
                     f"{TOPIC_ASSOCIATED}: they are in no object's numbers")
    if forecasts:
        notes.append(f"{forecasts} catalog-surrogate gap forecasts on {TOPIC_ESTIMATE_BATCH}: "
                     "counted, not scored")
    return notes


class _Labels:
    """The unlabelled detections' truth and the tracks they were placed in."""

    def __init__(self, detections: list[MeasurementRows],
                 associated: list[MeasurementRows]) -> None:
        self.tracks: set[str] = set()
        self.objects: list[str] = []
        self.labels: list[str] = []
        self.owner: dict[str, str] = {}
        if not (detections or associated):
            return
        self.tracks = {o for a in associated for o in a.object_id}
        if detections:
            rows = MeasurementRows.concat(detections)
            self.objects = rows.object_id
            self.labels = (detection_labels(rows, MeasurementRows.concat(associated))
                           if associated else [""] * len(rows))
        # a track's object: the majority of its detections, whichever tracks are confirmed
        self.owner = score_association(self.objects, self.labels, self.tracks).owner

    def truth_object(self, object_id: str) -> str:
        """Return whose truth scores `object_id`: its own, a track's object ('' for none)."""
        return self.owner.get(object_id, "") if object_id in self.tracks else object_id

    def score(self, confirmed: set[str]) -> dict[str, Any] | None:
        """Return the association's score for the `confirmed` tracks (None: no detections)."""
        if not self.tracks and not self.objects:
            return None
        return score_association(self.objects, self.labels, confirmed & self.tracks).as_dict()


def _one(e: StateEstimate) -> EstimateRows:
    """Return one core StateEstimate as `EstimateRows` of one row."""
    return EstimateRows(np.array([e.t]), [e.object_id], e.x[None], e.P[None],
                        np.array([e.nis]), UpdateSource(e.update_source))


COLUMNS = ("object", "measurements", "estimates", "error median [km]", "error 95 % [km]",
           "NEES in 95 % band", "NIS in 95 % band", "post-fit residual RMS [σ]")


def _f(v: float, fmt: str) -> str:
    return "–" if not np.isfinite(v) else format(v, fmt)


def worst_cells(rep: CatalogReport) -> list[list[str]]:
    """Return the worst objects' table cells (`COLUMNS`)."""
    s = rep.scores
    out = []
    for i in rep.worst.tolist():
        name = s.ids[i] + (f" ({s.truth_object[i]})" if s.truth_object[i] not in ("", s.ids[i])
                           else "")
        out.append([name, str(s.measurements[i]), str(s.estimates[i]),
                    _f(s.error_median_km[i], ".3f"), _f(s.error_p95_km[i], ".3f"),
                    _f(100 * s.nees_inside[i], ".0f") + (" %" if s.nees_count[i] else ""),
                    _f(100 * s.nis_inside[i], ".0f") + (" %" if s.nis_count[i] else ""),
                    _f(s.residual_rms_all[i], ".2f")])
    return out


def lines(rep: CatalogReport) -> list[str]:
    """Return the summary's lines (printed, and under the tables of report.html)."""
    s = rep.summary
    e = s["position_error_km"]
    out = [f"catalog: {s['objects']} {'tracks' if rep.association else 'objects'} "
           f"({s['objects_with_estimates']} with estimates), {s['measurements']} measurements "
           f"of them, {s['estimates']} estimates"]
    if e["rows"]:
        out.append(f"position error against {TOPIC_TRUTH} over {e['rows']} estimates of "
                   f"{s['objects_with_truth']} objects: median {e['median']:.3f} km, 95 % "
                   f"{e['p95']:.3f} km (median of the objects' medians "
                   f"{s['median_of_object_medians_km']:.3f} km)")
    if s["nees"]["rows"]:
        lo, hi = s["nees"]["band_95"]
        out.append(f"NEES inside the 95 % χ² band [{lo:.2f}, {hi:.2f}] (6 dof): "
                   f"{100 * s['nees']['inside']:.1f} % of {s['nees']['rows']} estimates "
                   f"(mean {s['nees']['mean']:.2f}; a consistent filter: about 95 %, mean 6)")
    if s["nis"]["rows"]:
        lo, hi = s["nis"]["band_95"]
        out.append(f"published NIS inside the 95 % χ² band [{lo:.2f}, {hi:.2f}] (3 dof): "
                   f"{100 * s['nis']['inside']:.1f} % of {s['nis']['rows']} fused measurements")
    if s["residual_rows"]:
        out.append(f"post-fit residuals of each object's measurements against its own fused "
                   f"estimates: RMS {s['postfit_residual_rms_sigma']:.2f} σ over "
                   f"{s['residual_rows']} measurements (σ: the measurement's; post-fit, so "
                   f"below 1 for a consistent filter)")
    a = rep.association
    if a is not None:
        out.append(f"association of {a['detections']} detections: accuracy "
                   f"{100 * a['accuracy']:.1f} %, coverage {100 * a['coverage']:.1f} %, "
                   f"{a['confirmed_tracks']} confirmed tracks of {a['objects']} objects "
                   f"({a['objects_with_track']} with a track, {a['duplicate_tracks']} "
                   f"duplicates)")
    out += rep.notes
    p = rep.parameters[0]
    out.append(f"catalog_filter settings: {rep.origin}: " + ", ".join(
        f"{k} {p[k]}" for k in SHOWN if k in p))
    return out


def table(rep: CatalogReport) -> str:
    """Markdown: the summary lines, then the worst objects."""
    head = ["| " + " | ".join(COLUMNS) + " |", "|" + "---|" * len(COLUMNS)]
    body = ["| " + " | ".join(c) + " |" for c in worst_cells(rep)]
    return ("\n".join(lines(rep)) + f"\n\nworst {len(rep.worst)} by {rep.ranked_by}:\n"
            + "\n".join(head + body))


def summary_json(rep: CatalogReport) -> dict[str, Any]:
    """Return what report.json holds."""
    return {"catalog": True, "truth": rep.summary["objects_with_truth"] > 0,
            "summary": rep.summary,
            "association": ({k: v for k, v in rep.association.items() if k != "owner"}
                            if rep.association is not None else None),
            "unlabelled_detections": rep.unlabelled, "forecasts_not_scored": rep.forecasts,
            "worst_ranked_by": rep.ranked_by,
            "worst": [cs.object_row(rep.scores, i) for i in rep.worst.tolist()],
            "settings": rep.origin, "catalog_filter": rep.parameters, "notes": rep.notes,
            "message_counts": rep.counts}


def write(rep: CatalogReport, out: Path, title: str) -> None:
    """Write report.json, objects.csv (every object) and report.html into `out`."""
    out.mkdir(parents=True, exist_ok=True)
    (out / "report.json").write_text(json.dumps(summary_json(rep), indent=2))
    with (out / "objects.csv").open("w", newline="") as f:
        rows = [cs.object_row(rep.scores, i) for i in range(len(rep.scores.ids))]
        if rows:
            keys = [k for k in rows[0] if k != "postfit_residual_rms_sigma_range_az_el"]
            w = csv.writer(f)
            w.writerow(keys)
            w.writerows([["" if r[k] is None else r[k] for k in keys] for r in rows])
    from ssa_fusion.apps.report_html import STYLE, _table

    parts = [f"<h1>{html.escape(title)}</h1>",
             "<p class=\"note\">A catalog's bag: every object scored on its own measurements "
             "and estimates only.</p>", "<h2>Catalog</h2>",
             *(f'<p class="note">{html.escape(x)}</p>' for x in lines(rep)),
             f"<h2>Worst {len(rep.worst)} by {html.escape(rep.ranked_by)}</h2>",
             _table(list(COLUMNS), worst_cells(rep)),
             "<p class=\"note\">Every object: objects.csv beside this page.</p>"]
    (out / "report.html").write_text(
        "<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">"
        f"<title>{html.escape(title)}</title>{STYLE}</head>\n<body>\n" + "\n".join(parts)
        + "\n</body></html>\n", encoding="utf-8")


def run(args: argparse.Namespace, telling: list[bagio.BagMessage], reason: str,
        out: Path) -> int:
    """Report on a catalog bag into `out`; return the exit code (2 when it cannot)."""
    if args.scenario or args.params_file is not None:
        print(f"error: {args.bag} is a catalog's bag ({reason}); --scenario and --params-file "
              f"set one object's filter: drop them", file=sys.stderr)
        return 2
    try:
        rep = build(args.bag, telling, args.sites)
        write(rep, out, f"ssa_fusion catalog report: {out.name}")
    except (bagio.BagError, ValueError, OSError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    print(f"{args.bag} is a catalog's bag ({reason}): each object scored on its own rows\n")
    print(table(rep))
    print(f"\nwrote {out}/report.json, {out}/objects.csv (every object) and {out}/report.html")
    conj = conjunction_table.latest(args.bag)
    if conj.batches:  # a run with the conjunction node
        conjunction_table.write_csv(conj, out / "conjunctions.csv")
        print("\n" + conjunction_table.table(conj)
              + f"\nwrote {out}/conjunctions.csv (every approach)")
    return 0
