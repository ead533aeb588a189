"""catalog_filter's unlabelled detections: rows without ``object_id`` into tracks.

A row whose ``object_id`` is empty (`core.unlabelled.UNLABELLED`) is a radar's detection of
an unknown object. `UnlabelledRows.take` sets those rows of a fusion's batch aside, hands
them to a `core.unlabelled.RowAssociator` (gating and global nearest neighbour per scan,
tracklets, IOD, M-of-N confirmation: `core.association`), and publishes:

* on ``/ssa/estimate_batch`` (the labelled objects' EstimateBatch, update source SENSOR)
  the estimates of confirmed tracks, each named by its track id (``track-000001``, ...);
* on ``/ssa/measurement_associated`` (MeasurementBatch) the detections placed in a track or
  tracklet, each row's ``object_id`` the track's id (``shard_key`` its CRC-32).

Every detection is counted on ``/diagnostics`` by its fate (``detection_track``,
``detection_tracklet``, ``detection_new_tracklet``, ``detection_refused``: they sum to the
unlabelled rows consumed) and the association's events as ``association_<event>``
(`core.association.TrackEvent`: scans, assigned, track_confirmed, ...); the status gives
``confirmed_tracks`` and ``tentative_tracks``.

Unlabelled detections cannot be routed by object key: they need a single shard
(`sharded_problem`).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping

import numpy as np
from rclpy.node import Node

from ssa_fusion.core.association import DetectionFate, TrackStatus
from ssa_fusion.core.filter_options import FilterOptions
from ssa_fusion.core.frames import Station
from ssa_fusion.core.rows import EstimateRows, MeasurementRows
from ssa_fusion.core.stations import Sensor
from ssa_fusion.core.unlabelled import RowAssociator, elevation_masks, is_unlabelled
from ssa_fusion.nodes.diagnostics import Count, Diagnostics
from ssa_fusion.ros import messages
from ssa_fusion.ros.interfaces import MeasurementBatch
from ssa_fusion.ros.topics import CATALOG_QOS, TOPIC_ASSOCIATED

FATE_PREFIX = "detection_"
"""/diagnostics key of an unlabelled detection's fate: this + the `DetectionFate` name."""
EVENT_PREFIX = "association_"
"""/diagnostics key of an association event: this + the `TrackEvent` value."""


def fate_key(fate: DetectionFate) -> str:
    """Return the /diagnostics key counting detections of `fate` (``detection_track``...)."""
    return FATE_PREFIX + fate.name.lower()


def sharded_problem(shards: int) -> str:
    """Return why a shard of `shards` refuses an unlabelled row ("" for one shard).

    Shards own objects by the key of their id; a detection without an id has no owner.
    """
    if shards <= 1:
        return ""
    return (f"an unlabelled detection (object_id '') in a graph of {shards} shards: it has "
            "no object key to route it by; unlabelled detections need one catalog_filter "
            "(shards 1)")


class UnlabelledRows:
    """The unlabelled rows of a catalog_filter: association, publication, counts.

    Parameters
    ----------
    node : rclpy Node
        The catalog_filter (publishers are created on it).
    diag : Diagnostics
        Its diagnostics (counts and status).
    options, stations : FilterOptions, dict of str to Station
        The filter's settings and network (as its labelled bank's).
    sensors : mapping of str to Sensor
        Sensors of a sites file by id (their masks; built-in stations use their presets').
    key_range : tuple of int
        The shard's key range, put on the estimate batches.
    """

    def __init__(self, node: Node, diag: Diagnostics, options: FilterOptions,
                 stations: dict[str, Station], sensors: Mapping[str, Sensor],
                 key_range: tuple[int, int]) -> None:
        self.diag = diag
        self.options, self.stations = options, stations
        self.masks = elevation_masks(stations, sensors)
        self.key_range = key_range
        self.associator = RowAssociator(options, stations, self.masks)
        self.pub = node.create_publisher(MeasurementBatch, TOPIC_ASSOCIATED, CATALOG_QOS)

    def reset(self) -> None:
        """Forget every track and tracklet (a backward clock jump)."""
        self.associator = RowAssociator(self.options, self.stations, self.masks)

    def take(self, batch: MeasurementRows,
             publish_estimates: Callable[[EstimateRows], None]) -> MeasurementRows | None:
        """Associate the unlabelled rows of `batch`; return the others (None: none left).

        `publish_estimates` publishes the confirmed tracks' estimates as the labelled
        ones are.
        """
        mask = is_unlabelled(batch.object_id)
        if not mask.any():
            return batch
        rows = batch.take(np.flatnonzero(mask))
        try:
            out = self.associator.process(rows)
        except Exception:  # counted, then the guard logs the traceback as internal_error
            self.diag.counts[Count.DROPPED] += len(rows)
            raise
        c = self.diag.counts
        c[Count.CONSUMED] += len(rows)
        for fate, n in out.fates.items():
            if fate == DetectionFate.REFUSED:
                self.diag.count(fate_key(fate), f"refused by its track's filter or IOD: "
                                f"{out.refusals[0]}", n=n)
            else:
                c[fate_key(fate)] += n
        for event, n in out.events.items():
            c[EVENT_PREFIX + event.value] += n
        if len(out.estimates):
            publish_estimates(out.estimates)
        c[Count.PUBLISHED_SENSOR] += len(out.estimates)
        self._publish_associated(out.associated)
        status = self.diag.status
        status["confirmed_tracks"] = str(self.associator.tracks(TrackStatus.CONFIRMED))
        status["tentative_tracks"] = str(self.associator.tracks(TrackStatus.TENTATIVE))
        rest = np.flatnonzero(~mask)
        return batch.take(rest) if rest.size else None

    def _publish_associated(self, rows: MeasurementRows) -> None:
        """Publish the associated detections (their keys set from their track ids)."""
        if not len(rows):
            return
        rows.shard_key = messages.shard_keys(rows.object_id)
        self.pub.publish(messages.measurement_batch_to_msg(rows))
        self.diag.counts[Count.PUBLISHED_ASSOCIATED] += len(rows)


