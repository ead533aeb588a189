"""catalog_filter's unlabelled rows published: the associated detections, then those a
deferred decision moved, again under their new track (`nodes.kit.unlabelled.UnlabelledRows`,
on stand-ins for the node, its diagnostics and the fusion; the messages decoded back)."""

from collections import Counter
from types import SimpleNamespace

import numpy as np

from ssa_fusion.core.base.rows import EstimateRows, MeasurementRows
from ssa_fusion.core.catalog.association import DetectionFate
from ssa_fusion.core.catalog.unlabelled import RowsOutcome
from ssa_fusion.evaluation.association import detection_labels
from ssa_fusion.nodes.kit.diagnostics import Count
from ssa_fusion.nodes.kit.unlabelled import UnlabelledRows
from ssa_fusion.ros import messages
from ssa_fusion.ros.topics import TOPIC_ASSOCIATED


class _Diagnostics:
    """Stands in for `nodes.kit.diagnostics.Diagnostics`: counts, and the output it advertises."""

    def __init__(self) -> None:
        self.sent: list = []
        self.counts: Counter = Counter()
        self.status: dict = {}
        self.count = None

    def advertise(self, _type, topic, _qos):
        assert topic == TOPIC_ASSOCIATED
        return SimpleNamespace(publish=self.sent.append)


def _rows(ids: list[str], t0: float = 1.7e9) -> MeasurementRows:
    m = len(ids)
    z = np.column_stack([1000.0 + np.arange(m), np.full(m, 1.0), np.full(m, 0.5)])
    return MeasurementRows(t0 + np.arange(m) * 10.0, ids, ["columbus"] * m, z,
                           np.broadcast_to(np.eye(3) * 1e-6, (m, 3, 3)).copy())


def test_the_moved_detections_go_out_after_the_associated_and_their_last_label_holds():
    truth = _rows(["obj-a", "obj-b", "obj-a", "obj-b"])
    associated = _rows(["track-000001", "track-000002", "track-000002", "track-000001"])
    moved = associated.take(np.array([2, 3]))  # the deferred pass, put back
    moved.object_id = ["track-000001", "track-000002"]
    out = RowsOutcome(EstimateRows(np.zeros(0), [], np.zeros((0, 6)), np.zeros((0, 6, 6)),
                                   np.zeros(0)), associated, moved,
                      fates=Counter({DetectionFate.TRACK: 4}))
    fusion = SimpleNamespace(associate=lambda batch: (out, None),
                             associator=SimpleNamespace(tracks=lambda status: 2))
    diag = _Diagnostics()
    assert UnlabelledRows(diag).take(fusion, truth, lambda e: None) is None
    got = [messages.measurement_batch_from_msg(m) for m in diag.sent]
    assert [r.object_id for r in got] == [associated.object_id, moved.object_id]
    assert diag.counts[Count.PUBLISHED_ASSOCIATED] == 6
    assert diag.counts[Count.PUBLISHED_RELABELLED] == 2
    # as a bag's reader scores them: the last publication of a detection holds
    labels = detection_labels(truth, MeasurementRows.concat(got))
    assert labels == ["track-000001", "track-000002", "track-000001", "track-000002"]
    assert detection_labels(truth, got[0]) == associated.object_id
