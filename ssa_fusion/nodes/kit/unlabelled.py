"""catalog_filter's unlabelled detections: rows without ``object_id`` into tracks.

A row whose ``object_id`` is empty (`core.catalog.unlabelled.UNLABELLED`) is a radar's detection of
an unknown object. `UnlabelledRows.take` hands a fusion's batch to the filter's
`core.catalog.fusion.CatalogFusion`, which sets those rows aside for its
`core.catalog.unlabelled.RowAssociator` (gating and global nearest neighbour per scan, tracklets,
IOD, M-of-N confirmation: `core.catalog.association`), and publishes:

* on ``/ssa/estimate_batch`` (the labelled objects' EstimateBatch, update source SENSOR)
  the estimates of confirmed tracks, each named by its track id (``track-000001``, ...);
* on ``/ssa/measurement_associated`` (MeasurementBatch) the detections placed in a track or
  tracklet, each row's ``object_id`` the track's id (``shard_key`` its CRC-32); after them
  the detections of earlier scans that a deferred decision moved to another track
  (`core.catalog.unlabelled.RowsOutcome.relabelled`), again, under that track's id: a detection
  published twice belongs to the track of its last publication.

Every detection is counted on ``/diagnostics`` by its fate (``detection_track``,
``detection_tracklet``, ``detection_new_tracklet``, ``detection_refused``: they sum to the
unlabelled rows consumed) and the association's events as ``association_<event>``
(`core.catalog.association.TrackEvent`: scans, assigned, track_confirmed, ...); the status gives
``confirmed_tracks`` and ``tentative_tracks``.

Unlabelled detections cannot be routed by object key: they need a single shard
(`sharded_problem`).
"""

from __future__ import annotations

from collections.abc import Callable

from ssa_fusion.core.base.rows import EstimateRows, MeasurementRows
from ssa_fusion.core.catalog.association import DetectionFate, TrackStatus
from ssa_fusion.core.catalog.fusion import CatalogFusion
from ssa_fusion.core.catalog.unlabelled import is_unlabelled
from ssa_fusion.nodes.kit.diagnostics import Count, Diagnostics
from ssa_fusion.ros import messages
from ssa_fusion.ros.interfaces import MeasurementBatch
from ssa_fusion.ros.qos import CATALOG_WRITER_QOS
from ssa_fusion.ros.topics import TOPIC_ASSOCIATED

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
    diag : Diagnostics
        The catalog_filter's diagnostics (counts and status; its output publisher is
        created through them, its matches reported: `Diagnostics.advertise`).
    """

    def __init__(self, diag: Diagnostics) -> None:
        self.diag = diag
        self.pub = diag.advertise(MeasurementBatch, TOPIC_ASSOCIATED, CATALOG_WRITER_QOS)

    def take(self, fusion: CatalogFusion, batch: MeasurementRows,
             publish_estimates: Callable[[EstimateRows], None]) -> MeasurementRows | None:
        """Associate the unlabelled rows of `batch` in `fusion`; return the others.

        None: no labelled row left. `publish_estimates` publishes the confirmed tracks'
        estimates as the labelled ones are.
        """
        try:
            out, rest = fusion.associate(batch)
        except Exception:  # counted, then the guard logs the traceback as internal_error
            self.diag.counts[Count.DROPPED] += int(is_unlabelled(batch.object_id).sum())
            raise
        if out is None:
            return rest
        c = self.diag.counts
        c[Count.CONSUMED] += sum(out.fates.values())
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
        self._publish_associated(out.relabelled)
        c[Count.PUBLISHED_RELABELLED] += len(out.relabelled)
        status = self.diag.status
        status["confirmed_tracks"] = str(fusion.associator.tracks(TrackStatus.CONFIRMED))
        status["tentative_tracks"] = str(fusion.associator.tracks(TrackStatus.TENTATIVE))
        return rest

    def _publish_associated(self, rows: MeasurementRows) -> None:
        """Publish associated detections (their keys set from their track ids), counted."""
        if not len(rows):
            return
        rows.shard_key = messages.shard_keys(rows.object_id)
        self.pub.publish(messages.measurement_batch_to_msg(rows))
        self.diag.counts[Count.PUBLISHED_ASSOCIATED] += len(rows)


