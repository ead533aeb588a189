"""Unlabelled detections as batch rows: a catalog node's rows through the `Associator`.

A radar does not know what it detected. A measurement row (`rows.MeasurementRows`, a
``MeasurementBatch`` row) whose ``object_id`` is `UNLABELLED` (the empty string) is such a
detection; its ``shard_key`` is 0 (the CRC-32 of the empty string). `RowAssociator` takes
any number of such rows (of any stations and epochs), cuts them into *scans* (one station,
one epoch), hands the scans in epoch order to an `association.Associator` (gating, global
nearest neighbour, tracklets, IOD, M-of-N confirmation, deletion), and returns per call:

* the estimates of *confirmed* tracks: one row per detection fused into a track that is
  confirmed after its scan (state, covariance and NIS of the update, at the detection's
  epoch), named by the track's id (`track_name`: ``track-000001``, ...). A tentative track
  (maybe a false one) publishes nothing until the M-of-N rule confirms it;
* the detections the association kept, relabelled with the id of the track or tracklet
  they went to (a tracklet's id is that of the track its IOD starts): rows a labelled
  consumer can read;
* the detections of earlier scans whose track a deferred decision changed
  (`association.AssociationConfig.defer_passes`, `deferral.Relabel`), again, with the id
  of the track they now belong to: a detection given out twice belongs to the track of
  its last publication (`evaluation.association.detection_labels` reads them so). The
  rows of a scan are kept while an open deferred decision may relabel them;
* what became of every detection (`association.DetectionFate` counts: to a track, to a
  tracklet, a new tracklet, refused) and the association's events (`TrackEvent` counts),
  for ``/diagnostics``.

A scan is what one call holds of one station at one epoch: a caller that cuts a scan in
two calls makes two scans of it. Units: the core's (km, rad, Unix s); tracks in the GCRF.
"""

from __future__ import annotations

import math
import re
from collections import Counter
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ssa_fusion.core.base.rows import EstimateRows, MeasurementRows
from ssa_fusion.core.base.types import UpdateSource
from ssa_fusion.core.catalog.association import (
    AssociationConfig,
    Associator,
    DetectionFate,
    Relabel,
    TrackEvent,
    TrackStatus,
)
from ssa_fusion.core.catalog.track_bank import BankResult, TrackBank
from ssa_fusion.core.earth.frames import Station
from ssa_fusion.core.earth.stations import SENSORS, Sensor
from ssa_fusion.core.filter.options import FilterOptions

UNLABELLED = ""
"""The ``object_id`` of an unlabelled detection (its ``shard_key``: 0, the CRC-32 of "")."""

TRACK_PREFIX = "track-"
"""Start of the id under which a track of unlabelled detections is published."""

_CORE_ID = re.compile(r"T(\d+)")


def track_name(core_id: str) -> str:
    """Return the published id of the associator's track or tracklet `core_id`.

    ``T1`` -> ``track-000001`` (six digits at least); another form keeps its text after
    `TRACK_PREFIX`. Stable: a track keeps its id for its life.
    """
    m = _CORE_ID.fullmatch(core_id)
    return f"{TRACK_PREFIX}{int(m.group(1)):06d}" if m else TRACK_PREFIX + core_id


def is_unlabelled(object_ids: Sequence[str]) -> NDArray[np.bool_]:
    """Return which of `object_ids` (M,) are `UNLABELLED`."""
    return np.fromiter((o == UNLABELLED for o in object_ids), bool, len(object_ids))


def without_labels(rows: MeasurementRows) -> MeasurementRows:
    """Return `rows` as a radar reports them: object ids `UNLABELLED`, shard keys 0."""
    m = len(rows)
    return MeasurementRows(rows.t, [UNLABELLED] * m, list(rows.frame_id), rows.z, rows.R,
                           rows.kind, rows.source, rows.horizon, np.zeros(m, np.uint32))


def elevation_masks(stations: Mapping[str, Station],
                    sensors: Mapping[str, Sensor] | None = None) -> dict[str, float]:
    """Return each station's elevation mask, rad: where the association expects a track.

    From `sensors` (a sites file's, `site_file.load_sites`) when it has the station, else
    from the built-in sensor of that id (`stations.SENSORS`), else 0 (the horizon).
    """
    own = sensors or {}
    out = {}
    for name in stations:
        sensor = own.get(name) or SENSORS.get(name)
        out[name] = math.radians(sensor.min_elevation_deg) if sensor else 0.0
    return out


class _FusionLog(TrackBank):
    """A `TrackBank` that keeps, per `process` call, the ids and epochs it fused."""

    def __init__(self, bank: TrackBank, stations: dict[str, Station]) -> None:
        super().__init__(bank.config, stations, max_objects=bank.max_objects,
                         evict_after_s=bank.evict_after_s)
        self.log: list[tuple[list[str], NDArray[np.float64], BankResult]] = []

    def process(self, t: ArrayLike, object_ids: Sequence[str], frame_ids: Sequence[str],
                z: ArrayLike, R: ArrayLike) -> BankResult:
        """`TrackBank.process`, then keep (ids, epochs, result) of what it fused."""
        res = super().process(t, object_ids, frame_ids, z, R)
        tt = np.asarray(t, dtype=float).reshape(-1)
        self.log.append(([object_ids[i] for i in res.fused.tolist()], tt[res.fused], res))
        return res


@dataclass
class RowsOutcome:
    """What `RowAssociator.process` did with M unlabelled rows.

    Attributes
    ----------
    estimates : EstimateRows
        Confirmed tracks' estimates (update source SENSOR), in processing order.
    associated : MeasurementRows
        The detections placed in a track or a tracklet, ``object_id`` = its `track_name`
        (``shard_key`` its CRC-32 is the caller's to set), in processing order.
    relabelled : MeasurementRows
        Detections of earlier calls or this one that a deferred decision moved to another
        track, ``object_id`` = that track's `track_name` (after `associated` in time: they
        supersede what was given out for them before), in decision order.
    fates : Counter of DetectionFate
        Every detection's fate: they sum to M.
    events : Counter of TrackEvent
        The association's events during the call.
    refusals : list of str
        A line per refused detection: its track or tracklet, epoch and station.
    """

    estimates: EstimateRows
    associated: MeasurementRows
    relabelled: MeasurementRows
    fates: Counter[DetectionFate] = field(default_factory=Counter)
    events: Counter[TrackEvent] = field(default_factory=Counter)
    refusals: list[str] = field(default_factory=list)


def _empty_estimates() -> EstimateRows:
    return EstimateRows(np.zeros(0), [], np.zeros((0, 6)), np.zeros((0, 6, 6)), np.zeros(0))


class RowAssociator:
    """Unlabelled rows in, confirmed tracks' estimates out (module docstring).

    Parameters
    ----------
    options : FilterOptions
        The tracks' filter (as a labelled catalog's bank: `track_bank.TrackBank`).
    stations : dict of str to Station
        The network: a row's ``frame_id`` names its station.
    masks_rad : mapping of str to float
        Each station's elevation mask, rad (`elevation_masks`).
    config : AssociationConfig, optional
        Gate and track-management rules (default `AssociationConfig()`).
    """

    def __init__(self, options: FilterOptions, stations: dict[str, Station],
                 masks_rad: Mapping[str, float], config: AssociationConfig | None = None) -> None:
        self.associator = Associator(options, stations, config)
        self._log = _FusionLog(self.associator.bank, dict(stations))
        self.associator.bank = self._log  # the same bank, which keeps what it fused
        self.masks = {name: float(masks_rad.get(name, 0.0)) for name in stations}
        self._names = list(stations)
        self._index = {name: i for i, name in enumerate(self._names)}
        self._held: dict[int, MeasurementRows] = {}
        """The rows of each scan (by serial number) that a deferred decision may relabel."""

    def tracks(self, status: TrackStatus) -> int:
        """Return how many tracks have `status`."""
        return int((self.associator.status == status).sum())

    def process(self, rows: MeasurementRows) -> RowsOutcome:
        """Associate `rows` (every one unlabelled, of a station of the network), scan by scan.

        Scans go in epoch order, at one epoch in the network's order of stations: the
        same scans in any cut of the rows into calls give the same tracks. KeyError for a
        station not of the network.
        """
        assoc, log = self.associator, self._log
        before = Counter(assoc.counts)
        none = rows.take(np.zeros(0, np.int64))
        out = RowsOutcome(_empty_estimates(), none, none)
        if not len(rows):
            return out
        station = np.array([self._index[f] for f in rows.frame_id], dtype=np.int64)
        order = np.lexsort((station, rows.t))
        cut = np.flatnonzero((np.diff(rows.t[order]) != 0)
                             | (np.diff(station[order]) != 0)) + 1
        estimates, kept, ids, moved = [], [], [], [none]
        for scan in np.split(order, cut):
            name = self._names[station[scan[0]]]
            log.log.clear()
            res = assoc.process_scan(name, rows.t[scan], rows.z[scan], rows.R[scan],
                                     self.masks[name])
            fate = np.asarray(res.fate)
            out.fates.update(DetectionFate(int(f)) for f in fate.tolist())
            keep = fate != DetectionFate.REFUSED
            kept.append(scan[keep])
            ids += [track_name(i) for i, k in zip(res.ids, keep.tolist(), strict=True) if k]
            out.refusals += [f"{track_name(i)} at t={rows.t[j]} from {name!r}"
                             for i, j, k in zip(res.ids, scan.tolist(), keep.tolist(),
                                                strict=True) if not k]
            estimates += self._confirmed(log.log)
            moved += self._relabelled(rows.take(scan), res.relabelled)
        idx = np.concatenate(kept)
        out.associated = rows.take(idx)
        out.associated.object_id = ids
        out.relabelled = MeasurementRows.concat(moved)
        if estimates:
            out.estimates = EstimateRows(
                np.concatenate([e.t for e in estimates]),
                [o for e in estimates for o in e.object_id],
                np.concatenate([e.x for e in estimates]),
                np.concatenate([e.P for e in estimates]),
                np.concatenate([e.nis for e in estimates]), UpdateSource.SENSOR)
        out.events = Counter({k: v - before[k] for k, v in assoc.counts.items()
                              if v != before[k]})
        return out

    def _relabelled(self, scan: MeasurementRows, relabels: Sequence[Relabel]
                    ) -> list[MeasurementRows]:
        """Hold the rows of the scan just associated; return those `relabels` moved.

        Each moved detection (`Relabel`: scan serial and index in it) comes back as its row
        of the scan it was in, ``object_id`` its new track's `track_name`. Only the scans
        an open deferred decision may relabel stay held.
        """
        assoc = self.associator
        if assoc.deferral is None:
            return []
        self._held[assoc.scan_serial] = scan
        out = []
        for r in relabels:
            row = self._held[r.scan].take(np.array([r.detection], dtype=np.int64))
            row.object_id = [track_name(r.track)]
            out.append(row)
        held = assoc.deferral.scans_held()
        self._held = {k: v for k, v in self._held.items() if k in held}
        return out

    def _confirmed(self, log: list[tuple[list[str], NDArray[np.float64], BankResult]]
                   ) -> list[EstimateRows]:
        """Return the estimates of a scan's fusions whose track is confirmed after it."""
        assoc = self.associator
        out = []
        for ids, t, res in log:
            rows = np.array([assoc.bank.rows[i] for i in ids], dtype=np.int64)
            ok = (np.flatnonzero(assoc.status[rows] == TrackStatus.CONFIRMED)
                  if rows.size else rows)
            if ok.size:
                out.append(EstimateRows(t[ok], [track_name(ids[k]) for k in ok.tolist()],
                                        res.x[ok], res.P[ok], res.nis[ok]))
        return out
