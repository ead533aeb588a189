"""Benchmark: association of unlabelled radar detections on crowded cases (not a test).

Cases (`sim.survey`), each over ``--hours`` of radar scans of every object:

* ``train``: 20 satellites launched together, one plane (550 km, 53 deg), 1-5 km apart
  along track (`survey.satellite_train`), the first over Columbus at the start + 10 min;
* ``crossing``: two trains of 10 whose planes cross over Columbus at that epoch, 4 s apart
  (`survey.crossing_trains`).

Each is seen by one radar (Columbus, 10 deg mask) and by two (Columbus and Millstone, 5 deg,
its scans 5 s after Columbus's), with the tracking-radar noise of the scenarios
(`stations.RADAR_SIGMA`: 20 m, 0.02 deg; 10 s cadence), truth by SGP4
(`survey.observe_catalog`). The scans come without object ids (`survey.Observations.scans`,
shuffled within each scan) into `core.catalog.association.Associator` (the real-sky filter
`filter_options.SKY_FILTER`: two-body + J2, IOD from 7 detections of a pass), one scan at
a time. Scored by the truth labels kept aside:

* accuracy: of the detections fused into confirmed tracks, the fraction whose object is the
  track's object (the object of the majority of the track's detections);
* coverage: the fraction of all detections that went into a confirmed track (tracklets
  that made it included);
* swapped: confirmed tracks whose object (majority per pass) differs from their first
  pass's in more than one pass; any_swap: in at least one;
* these scores (`evaluation.association`: `score_association`, `pass_swaps`) are of the
  labels as decided: a deferred decision (`AssociationConfig.defer_passes`) that changes
  the track of detections of an earlier pass (`ScanOutcome.relabelled`) changes their
  labels; ``*_as_emitted``: the same scores of the labels as each scan returned them (the
  node graph publishes the moved detections again, `core.catalog.unlabelled.RowsOutcome.relabelled`,
  so a live run scores the labels as decided);
* confirmed tracks, objects with a confirmed track, duplicate tracks (a second confirmed
  track of an object), tracklets and tentative tracks dropped;
* cost per scan: wall time of `Associator.process_scan` (association, fusion, tentative
  tracks), median and p95 in us, over the scans with detections.

Each case runs once per variant (``--variants``, `VARIANTS`): GNN on the tracks' filter alone
(``baseline``), with the groups' registration (``register``), with the long-arc predictor
(``long-arc``), with both (``long-arc+register``), with both and the decisions deferred
over passes (``long-arc+register+defer``, the defaults of `AssociationConfig`), in the same
conditions, one after the other.

Usage::

    nice -n 10 python bench/bench_association.py [--hours 24] [--cases train,crossing]
        [--radars 1,2] [--seed 1] [--variants baseline,...,long-arc+register+defer]
        [--defer-margin 9.21]

Prints ``key: value`` lines per run; the last line is one JSON object.
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import argparse
import json
import math
import sys
import time
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # run from a source checkout

from ssa_fusion.core.catalog.association import (
    AssociationConfig,
    Associator,
    DetectionFate,
    Relabel,
    TrackEvent,
    TrackStatus,
)
from ssa_fusion.core.earth.stations import SENSORS
from ssa_fusion.core.filter.options import SKY_FILTER
from ssa_fusion.evaluation.association import pass_swaps, score_association
from ssa_fusion.sim import survey

T0 = 1_735_732_800.0
"""Start of every run: 2025-01-01T12:00:00Z."""
RADARS = {1: ("columbus",), 2: ("columbus", "millstone")}
VARIANTS: dict[str, dict[str, Any]] = {
    "baseline": {"predictor_q": None, "register_groups": False, "defer_passes": 0},
    "register": {"predictor_q": None, "defer_passes": 0},
    "long-arc": {"register_groups": False, "defer_passes": 0},
    "long-arc+register": {"defer_passes": 0},
    "long-arc+register+defer": {},
}
"""The association compared: GNN on the tracks' filter alone; with the groups' registration
(`AssociationConfig.register_groups`) on it; with the long-arc predictor
(`AssociationConfig.predictor_q`); with both; with both and the decisions deferred over
passes (`AssociationConfig.defer_passes`: the defaults)."""


def _catalog(case: str, seed: int) -> list:
    station = SENSORS["columbus"].station
    if case == "train":
        return survey.satellite_train(station, T0 + 600.0, 20, seed=seed)
    if case == "crossing":
        return survey.crossing_trains(station, T0 + 600.0, 10, seed=seed)
    raise ValueError(f"case {case!r}: train or crossing")


def _observe(entries: list, sensors: list, hours: float, seed: int) -> survey.Observations:
    """Every sensor's measurements, the k-th sensor's scans 5k s after the first's.

    (A bank that fuses one measurement per object and epoch would refuse the second radar's
    detections at the first's epochs as duplicates.)
    """
    parts = [survey.observe_catalog(entries, [s], T0 + 5.0 * k, hours * 3600.0, seed=seed + k)
             for k, s in enumerate(sensors)]
    t = np.concatenate([p.t for p in parts])
    obj = np.concatenate([p.obj for p in parts])
    sensor = np.concatenate([np.full(len(p), k, np.int64) for k, p in enumerate(parts)])
    z = np.concatenate([p.z for p in parts])
    order = np.lexsort((obj, sensor, t))
    return survey.Observations(t[order], obj[order], sensor[order], z[order],
                               parts[0].object_ids, tuple(sensors))


def _score(obs: survey.Observations, label: np.ndarray, fate: np.ndarray,
           confirmed: set[str], pass_gap_s: float) -> dict[str, float | int]:
    """Accuracy, coverage, objects with a track, duplicates and swaps of the labels.

    By `evaluation.association` (`score_association`, `pass_swaps`): a refused detection
    is in no track; the accuracy is that of the detections fused into confirmed tracks.
    """
    labels = np.where(fate == DetectionFate.REFUSED, "", label).tolist()
    objects = obs.obj.tolist()
    s = score_association(objects, labels, confirmed, counted=fate == DetectionFate.TRACK)
    everything = score_association(objects, labels, confirmed)
    gt1, any_pass = pass_swaps(objects, labels, obs.t, set(s.owner), pass_gap_s)
    return {"accuracy": s.accuracy, "accuracy_all_in_tracks": everything.accuracy,
            "coverage": s.coverage, "objects_with_track": s.objects_with_track,
            "duplicate_tracks": s.duplicate_tracks,
            "swapped_gt1_pass": gt1, "swapped_any_pass": any_pass}


def run(case: str, radars: int, hours: float, seed: int,
        config: AssociationConfig) -> dict[str, float | int | str]:
    """One case seen by 1 or 2 radars: the scores of the module docstring."""
    sensors = [SENSORS[s] for s in RADARS[radars]]
    entries = _catalog(case, seed)
    obs = _observe(entries, sensors, hours, seed)
    scans = obs.scans(seed)
    assoc = Associator(SKY_FILTER, {s.station.name: s.station for s in sensors}, config)
    m = len(obs)
    label = np.full(m, "", dtype=object)
    fate = np.zeros(m, dtype=np.int8)
    ever_confirmed: set[str] = set()
    cost_us = []
    relabels: list[Relabel] = []
    for scan in scans:
        s = sensors[scan.sensor]
        R = np.broadcast_to(s.R, (scan.z.shape[0], 3, 3))
        t1 = time.perf_counter()
        out = assoc.process_scan(s.station.name, scan.t, scan.z, R,
                                 math.radians(s.min_elevation_deg))
        cost_us.append((time.perf_counter() - t1) * 1e6)
        label[scan.index] = out.ids
        fate[scan.index] = out.fate
        relabels += out.relabelled
        ever_confirmed.update(assoc.track_ids(TrackStatus.CONFIRMED))
    emitted = _score(obs, label, fate, ever_confirmed, config.pass_gap_s)
    for r in relabels:  # the deferred decisions' outcome: the labels as decided
        label[scans[r.scan].index[r.detection]] = r.track
    score = _score(obs, label, fate, ever_confirmed, config.pass_gap_s)
    truth = obs.obj
    seen = np.unique(truth).size
    assert len(scans) > 0 and m > 0, "no scan, no detection"
    assert seen == len(entries), f"only {seen} of {len(entries)} objects were seen"
    assert (assoc.predictor is not None) == (config.predictor_q is not None)
    registered = assoc.counts[TrackEvent.GROUP_REGISTERED]
    assert registered > 0 if config.register_groups else registered == 0, (
        f"register_groups {config.register_groups}, {registered} groups registered")
    assert (assoc.deferral is not None) == (config.defer_passes > 0)
    assert len(relabels) == len(assoc.relabels)
    costs = np.array(cost_us)
    counts = assoc.counts
    return {
        "case": case, "radars": radars, "hours": hours, "seed": seed,
        "objects": len(entries), "objects_seen": int(seen),
        "scans": len(scans), "detections": m,
        **score,
        "accuracy_as_emitted": emitted["accuracy"],
        "swapped_gt1_pass_as_emitted": emitted["swapped_gt1_pass"],
        "swapped_any_pass_as_emitted": emitted["swapped_any_pass"],
        "confirmed_tracks": len(ever_confirmed),
        "tentative_dropped": counts[TrackEvent.TENTATIVE_DROPPED],
        "tracklets_started": counts[TrackEvent.TRACKLET_STARTED],
        "tracklets_expired": counts[TrackEvent.TRACKLET_EXPIRED],
        "tracks_initiated": counts[TrackEvent.TRACK_INITIATED],
        "iod_failed": counts[TrackEvent.IOD_FAILED],
        "refused": counts[TrackEvent.REFUSED],
        "deleted_missed_passes": counts[TrackEvent.DELETED_MISSED_PASSES],
        "deleted_covariance": counts[TrackEvent.DELETED_COVARIANCE],
        "groups_registered": counts[TrackEvent.GROUP_REGISTERED],
        "defer_opened": counts[TrackEvent.DEFER_OPENED],
        "defer_swapped": counts[TrackEvent.DEFER_SWAPPED],
        "defer_kept": counts[TrackEvent.DEFER_KEPT],
        "defer_dropped": counts[TrackEvent.DEFER_DROPPED],
        "relabelled": len(relabels),
        "cost_us_median": float(np.median(costs)),
        "cost_us_p95": float(np.percentile(costs, 95)),
        "cost_us_max": float(costs.max()),
        "detections_per_scan_max": int(max(s.z.shape[0] for s in scans)),
    }


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--hours", type=float, default=24.0)
    ap.add_argument("--cases", default="train,crossing")
    ap.add_argument("--radars", default="1,2", help="1, 2 or 1,2")
    ap.add_argument("--seed", type=int, default=1)
    default = AssociationConfig()
    ap.add_argument("--predictor-q", type=float, default=default.predictor_q,
                    help="the long-arc predictor's q, km^2/s^3 (AssociationConfig.predictor_q)")
    ap.add_argument("--defer-margin", type=float, default=default.defer_margin,
                    help="the largest extra cost of a swap for a deferred decision "
                         "(AssociationConfig.defer_margin)")
    ap.add_argument("--variants", default=",".join(VARIANTS),
                    help=f"comma-separated, of {', '.join(VARIANTS)}")
    args = ap.parse_args(argv)
    names = args.variants.split(",")
    configs = [replace(default, **VARIANTS[v]) for v in names]
    configs = [replace(c, predictor_q=args.predictor_q) if c.predictor_q is not None else c
               for c in configs]
    configs = [replace(c, defer_margin=args.defer_margin) if c.defer_passes else c
               for c in configs]
    results = []
    for case in args.cases.split(","):
        for radars in (int(r) for r in args.radars.split(",")):
            for name, config in zip(names, configs, strict=True):
                t1 = time.perf_counter()
                res = run(case, radars, args.hours, args.seed, config)
                res["variant"] = name
                res["predictor_q"] = str(config.predictor_q)
                res["register_groups"] = config.register_groups
                res["wall_s"] = round(time.perf_counter() - t1, 1)
                results.append(res)
                print(f"\n{case}, {radars} radar(s), {args.hours:g} h, {name}:")
                for k, v in res.items():
                    print(f"  {k}: {v:.5g}" if isinstance(v, float) else f"  {k}: {v}")
    print(json.dumps({"configs": {n: {k: getattr(c, k) for k in c.__dataclass_fields__}
                                  for n, c in zip(names, configs, strict=True)},
                      "runs": results}))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
