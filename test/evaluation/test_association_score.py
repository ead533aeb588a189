"""evaluation.association: detections paired with their truth, the association scored."""

import math

import numpy as np
import pytest

from ssa_fusion.core.base.rows import MeasurementRows
from ssa_fusion.evaluation.association import detection_labels, pass_swaps, score_association


def _rows(t, frames, z, ids) -> MeasurementRows:
    z = np.asarray(z, dtype=float)
    return MeasurementRows(np.asarray(t, dtype=float), list(ids), list(frames), z,
                           np.tile(np.eye(3), (len(z), 1, 1)))


def test_associated_detections_find_their_truth_row_to_the_last_bit():
    z = [[1000.0, 1.0, 0.5], [1000.5, 1.0, 0.5], [1000.0, 1.0, 0.5], [2000.0, 3.0, 0.1]]
    truth = _rows([5, 5, 5, 6], ["a", "a", "b", "a"], z, ["o1", "o2", "o3", "o1"])
    # sent on in km, back in m and again: the last bit may differ; any order
    back = np.asarray(z)[[3, 1, 0]] / 1000.0 * 1000.0 * (1 + 2e-16)
    assoc = _rows([6, 5, 5], ["a", "a", "a"], back, ["track-1", "track-2", "track-1"])
    assert detection_labels(truth, assoc) == ["track-1", "track-2", "", "track-1"]
    stray = _rows([7], ["a"], [[1.0, 1.0, 1.0]], ["track-9"])
    with pytest.raises(ValueError, match="no detection of the truth"):
        detection_labels(truth, stray)


def test_accuracy_coverage_and_duplicates():
    objects = ["a"] * 4 + ["b"] * 4 + ["c"] * 2
    labels = ["T1", "T1", "T1", "T3",  # a: T1 (3 of its 4), one in T3
              "T2", "T2", "T1", "",  # b: T2, one swapped into T1, one never associated
              "T4", "T5"]  # c: T4 confirmed, T5 a tracklet never confirmed
    s = score_association(objects, labels, {"T1", "T2", "T3", "T4"})
    assert s.detections == 10 and s.in_confirmed == 8
    # T1: a a a b -> a (3 right); T2: b b (2); T3: a (1); T4: c (1): 7 of 8
    assert s.accuracy == pytest.approx(7 / 8) and s.coverage == pytest.approx(0.8)
    assert s.owner == {"T1": "a", "T2": "b", "T3": "a", "T4": "c"}
    assert s.confirmed_tracks == 4 and s.objects == 3 and s.objects_with_track == 3
    assert s.duplicate_tracks == 1  # T3: a second track of a


def test_no_confirmed_track_scores_nothing():
    s = score_association(["a", "b"], ["T1", ""], set())
    assert s.in_confirmed == 0 and math.isnan(s.accuracy) and s.coverage == 0.0
    with pytest.raises(ValueError, match="2 true objects for 1 labels"):
        score_association(["a", "b"], ["T1"], {"T1"})


def test_pass_swaps_count_tracks_whose_object_changes_between_passes():
    # T1: a, then b for one pass, then a again (swapped in one pass); T2: b, a, a (two);
    # T3: c throughout; passes 1000 s apart, detections 10 s apart within a pass
    t = [0, 10, 1000, 1010, 2000, 2010] * 3
    objects = ["a", "a", "b", "b", "a", "a",
               "b", "b", "a", "a", "a", "a",
               "c", "c", "c", "c", "c", "c"]
    labels = ["T1"] * 6 + ["T2"] * 6 + ["T3"] * 6
    assert pass_swaps(objects, labels, t, {"T1", "T2", "T3"}, 600.0) == (1, 2)
    assert pass_swaps(objects, labels, t, {"T1", "T3"}, 600.0) == (0, 1)
    # one pass when the gap is longer than the passes' spacing: no swap to see
    assert pass_swaps(objects, labels, t, {"T1", "T2", "T3"}, 5000.0) == (0, 0)


def test_accuracy_of_the_counted_detections_with_the_owner_of_all():
    objects = ["a", "a", "a", "b", "b"]
    labels = ["T1"] * 5  # owner a (3 of 5)
    s = score_association(objects, labels, {"T1"}, counted=[False, False, True, True, True])
    assert s.owner == {"T1": "a"} and s.accuracy == pytest.approx(1 / 3)
    assert score_association(objects, labels, {"T1"}).accuracy == pytest.approx(3 / 5)
