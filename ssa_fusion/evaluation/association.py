"""Scoring the association of unlabelled detections against their truth labels.

A run of unlabelled detections (`core.catalog.unlabelled`) leaves two sets of rows: every
detection with its true object (the simulator's ``/ssa/detection_truth``) and the
detections the association placed in a track or tracklet, labelled with its id (the
filter's ``/ssa/measurement_associated``). `detection_labels` pairs them (the same
station, epoch and measurement); `score_association` scores the labels against the truth
for the *confirmed* tracks (those with published estimates):

* accuracy: of the detections in confirmed tracks, the fraction whose object is the
  track's object (the object of the majority of its detections);
* coverage: the fraction of all detections in confirmed tracks;
* confirmed tracks, objects detected, objects with a confirmed track (one whose majority
  object they are), and duplicate tracks (a second confirmed track of one object);
* `pass_swaps`: confirmed tracks whose object (the majority of each pass) differs from
  their first pass's, in more than one pass and in any pass.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Collection, Sequence
from dataclasses import asdict, dataclass
from typing import Any, TypeVar

import numpy as np
from numpy.typing import ArrayLike

from ssa_fusion.core.base.rows import MeasurementRows

_T = TypeVar("_T")


def detection_labels(truth: MeasurementRows, associated: MeasurementRows) -> list[str]:
    """Return per row of `truth` the ``object_id`` its detection has in `associated` ('').

    A row of `associated` is the row of `truth` of its station and epoch nearest to it in
    measurement (a detection sent on and back again may differ in its last bit: km to m
    and back). ValueError when an associated row has no truth row of its station and epoch.
    """
    groups: dict[tuple[float, str], list[int]] = {}
    for i, key in enumerate(zip(truth.t.tolist(), truth.frame_id, strict=True)):
        groups.setdefault(key, []).append(i)
    labels = [""] * len(truth)
    scale = np.abs(truth.z) + 1e-9
    for j, key in enumerate(zip(associated.t.tolist(), associated.frame_id, strict=True)):
        rows = groups.get(key)
        if not rows:
            raise ValueError(f"associated detection at t={key[0]} from {key[1]!r} is no "
                             "detection of the truth")
        d = (np.abs(truth.z[rows] - associated.z[j]) / scale[rows]).max(axis=1)
        labels[rows[int(np.argmin(d))]] = associated.object_id[j]
    return labels


@dataclass(frozen=True)
class AssociationScore:
    """The association of a run scored against the truth (module docstring).

    Attributes
    ----------
    detections : int
        Detections with a truth label.
    in_confirmed : int
        Of them, in a confirmed track.
    accuracy, coverage : float
        As the module docstring says (nan without detections in confirmed tracks).
    confirmed_tracks, objects, objects_with_track, duplicate_tracks : int
        As the module docstring says.
    owner : dict of str to str
        Each confirmed track's majority object.
    """

    detections: int
    in_confirmed: int
    accuracy: float
    coverage: float
    confirmed_tracks: int
    objects: int
    objects_with_track: int
    duplicate_tracks: int
    owner: dict[str, str]

    def as_dict(self) -> dict[str, Any]:
        """Return the score as JSON-ready values."""
        return asdict(self)


def score_association(objects: Sequence[str], labels: Sequence[str],
                      confirmed: Collection[str],
                      counted: ArrayLike | None = None) -> AssociationScore:
    """Score per-detection `labels` (track ids, '' = none) against their true `objects`.

    `confirmed`: the ids of the confirmed tracks (labels of other tracks or tracklets are
    not in a confirmed track). `counted` (bool per detection, optional): the accuracy is
    that of the detections in confirmed tracks that it marks (e.g. those fused into their
    track, not those of the tracklet that started it); the tracks' objects are still the
    majority of all their detections.
    """
    truth = np.asarray(objects, dtype=object)
    label = np.asarray(labels, dtype=object)
    if truth.shape != label.shape:
        raise ValueError(f"{truth.size} true objects for {label.size} labels")
    keep = np.isin(label, np.asarray(list(confirmed), dtype=object)) if confirmed else \
        np.zeros(truth.size, bool)
    by_track: dict[str, list[str]] = {}
    for track, obj in zip(label[keep].tolist(), truth[keep].tolist(), strict=True):
        by_track.setdefault(track, []).append(obj)
    owner = {track: _majority(objs) for track, objs in sorted(by_track.items())}
    n_in = int(keep.sum())
    scored = keep if counted is None else keep & np.asarray(counted, dtype=bool)
    right = sum(owner[lab] == obj for lab, obj in zip(label[scored].tolist(),
                                                        truth[scored].tolist(), strict=True))
    n_scored = int(scored.sum())
    tracks_of = Counter(owner.values())
    return AssociationScore(
        detections=int(truth.size), in_confirmed=n_in,
        accuracy=right / n_scored if n_scored else float("nan"),
        coverage=n_in / truth.size if truth.size else float("nan"),
        confirmed_tracks=len(set(confirmed)), objects=len(set(truth.tolist())),
        objects_with_track=len(tracks_of),
        duplicate_tracks=sum(n - 1 for n in tracks_of.values()), owner=owner)


def _majority(objects: Sequence[_T]) -> _T:
    """Return the most frequent of `objects` (on a tie, the first seen)."""
    return Counter(objects).most_common(1)[0][0]


def pass_swaps(objects: Sequence[object], labels: Sequence[str], t: ArrayLike,
               tracks: Collection[str], pass_gap_s: float) -> tuple[int, int]:
    """Count the tracks whose object changed from one pass to another.

    A track's detections (`labels` == its id, in epoch order) are cut into passes where two
    in a row are more than `pass_gap_s` apart (epochs `t`, s); each pass's object is the
    majority of its detections' true `objects`.

    Returns
    -------
    (int, int)
        Of `tracks`, those whose object differs from their first pass's in more than one
        pass, and in at least one.
    """
    truth = np.asarray(objects, dtype=object)
    label = np.asarray(labels, dtype=object)
    tt = np.asarray(t, dtype=float)
    gt1 = any_pass = 0
    for track in tracks:
        idx = np.flatnonzero(label == track)
        if not idx.size:
            continue
        idx = idx[np.argsort(tt[idx], kind="stable")]
        cut = np.flatnonzero(np.diff(tt[idx]) > pass_gap_s) + 1
        per_pass = [_majority(truth[p].tolist()) for p in np.split(idx, cut)]
        other = sum(o != per_pass[0] for o in per_pass)
        gt1 += other > 1
        any_pass += other > 0
    return gt1, any_pass
