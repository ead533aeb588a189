"""What the association reports: track status, detection fates, event counts, relabels.

`TrackStatus` (where a track stands), `DetectionFate` (what became of a detection),
`TrackEvent` (the counted outcomes, `manager.Associator.counts`), `Relabel` (a detection
whose track a deferred decision changed) and `ScanOutcome` (one scan's result). Imports
nothing of the package.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

__all__ = ["DetectionFate", "Relabel", "ScanOutcome", "TrackEvent", "TrackStatus"]


class TrackStatus(enum.IntEnum):
    """Where a track stands (`Associator.status`)."""

    TENTATIVE = 0
    """Started by an initial orbit determination, not yet confirmed."""
    CONFIRMED = 1
    """Passed the M-of-N rule."""
    DELETED = 2
    """Dropped: no longer predicted, associated or fused."""


class DetectionFate(enum.IntEnum):
    """What `Associator.process_scan` did with a detection."""

    TRACK = 0
    """Assigned to a track and fused."""
    TRACKLET = 1
    """Added to an existing tracklet (it may have started a track by its IOD)."""
    NEW_TRACKLET = 2
    """Started a tracklet."""
    REFUSED = 3
    """Assigned to a track, whose filter refused it (its own NIS gate or a numeric
    failure), or ended a tracklet whose initial orbit determination failed."""


class TrackEvent(enum.StrEnum):
    """The counted outcomes of the association (`Associator.counts` keys)."""

    SCANS = "scans"
    DETECTIONS = "detections"
    ASSIGNED = "assigned"
    """Detections assigned to a track and fused."""
    REFUSED = "refused"
    """Detections assigned to a track that its filter refused."""
    TRACKLET_EXTENDED = "tracklet_extended"
    TRACKLET_STARTED = "tracklet_started"
    TRACKLET_EXPIRED = "tracklet_expired"
    TRACK_INITIATED = "track_initiated"
    """Tracklets whose initial orbit determination started a tentative track."""
    IOD_FAILED = "iod_failed"
    TRACK_CONFIRMED = "track_confirmed"
    TENTATIVE_DROPPED = "tentative_dropped"
    """Tentative tracks deleted because they can no longer pass the M-of-N rule."""
    DELETED_MISSED_PASSES = "deleted_missed_passes"
    DELETED_COVARIANCE = "deleted_covariance"
    GROUP_REGISTERED = "group_registered"
    """Groups of tracks sharing detections shifted along track before an assignment
    (`register`; one per group and scan)."""
    DEFER_OPENED = "defer_opened"
    """Ambiguous pairs of tracks whose decision was deferred (`deferral.PairDeferral`)."""
    DEFER_SWAPPED = "defer_swapped"
    """Deferred decisions that exchanged the pair's detections of the deferred pass."""
    DEFER_KEPT = "defer_kept"
    """Deferred decisions that kept the scan-wise assignment."""
    DEFER_DROPPED = "defer_dropped"
    """Deferred decisions dropped undecided (a track of the pair was deleted, or the pair
    was not seen within `AssociationConfig.defer_max_wait_s` of its pass)."""


@dataclass(frozen=True)
class Relabel:
    """A detection whose track changed after its scan (a deferred decision's outcome).

    Attributes
    ----------
    scan : int
        Serial number of its scan (0 for the associator's first `process_scan` call).
    detection : int
        Its index in that scan.
    track : str
        The id of the track it now belongs to.
    """

    scan: int
    detection: int
    track: str


@dataclass(frozen=True)
class ScanOutcome:
    """What `Associator.process_scan` did with a scan of M detections.

    Attributes
    ----------
    ids : list of str
        Per detection, the id of the track or tracklet it went to (a tracklet's id is the
        id of the track its IOD starts).
    fate : ndarray (M,) of int8
        Per detection, its `DetectionFate`.
    relabelled : tuple of Relabel
        Detections of earlier scans (this one's included) whose track a deferred decision
        taken in this scan changed (`deferral.Relabel`: the scan's serial number, from 0 for
        the first `Associator.process_scan` call, and the detection's index in it).
    """

    ids: list[str]
    fate: NDArray[np.int8]
    relabelled: tuple[Relabel, ...] = ()

