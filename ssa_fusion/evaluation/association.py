"""Scoring the association of unlabelled detections against their truth labels.

A run of unlabelled detections (`core.unlabelled`) leaves two sets of rows: every
detection with its true object (the simulator's ``/ssa/detection_truth``) and the
detections the association placed in a track or tracklet, labelled with its id (the
filter's ``/ssa/measurement_associated``). `detection_labels` pairs them (the same
station, epoch and measurement); `score_association` scores the labels against the truth
for the *confirmed* tracks (those with published estimates):

* accuracy: of the detections in confirmed tracks, the fraction whose object is the
  track's object (the object of the majority of its detections);
* coverage: the fraction of all detections in confirmed tracks;
* confirmed tracks, objects detected, objects with a confirmed track (one whose majority
  object they are), and duplicate tracks (a second confirmed track of one object).
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Collection, Sequence
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

from ssa_fusion.core.rows import MeasurementRows


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
                      confirmed: Collection[str]) -> AssociationScore:
    """Score per-detection `labels` (track ids, '' = none) against their true `objects`.

    `confirmed`: the ids of the confirmed tracks (labels of other tracks or tracklets are
    not in a confirmed track).
    """
    truth = np.asarray(objects, dtype=object)
    label = np.asarray(labels, dtype=object)
    if truth.shape != label.shape:
        raise ValueError(f"{truth.size} true objects for {label.size} labels")
    keep = np.isin(label, np.asarray(list(confirmed), dtype=object)) if confirmed else \
        np.zeros(truth.size, bool)
    pairs = Counter(zip(label[keep].tolist(), truth[keep].tolist(), strict=True))
    owner: dict[str, str] = {}
    best: dict[str, int] = {}
    for (track, obj), n in sorted(pairs.items()):
        if n > best.get(track, 0):
            owner[track], best[track] = obj, n
    right = sum(best.values())
    n_in = int(keep.sum())
    tracks_of = Counter(owner.values())
    return AssociationScore(
        detections=int(truth.size), in_confirmed=n_in,
        accuracy=right / n_in if n_in else float("nan"),
        coverage=n_in / truth.size if truth.size else float("nan"),
        confirmed_tracks=len(set(confirmed)), objects=len(set(truth.tolist())),
        objects_with_track=len(tracks_of),
        duplicate_tracks=sum(n - 1 for n in tracks_of.values()), owner=owner)
