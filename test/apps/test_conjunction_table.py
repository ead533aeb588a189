"""The conjunctions of a bag (`apps.conjunction_table`): ConjunctionBatch messages written
with the rosbags classes, read back (m <-> km to the bit), each batch replacing the
approaches of the objects it screened; the table and the CSV list what stands at the end.
"""

from __future__ import annotations

import csv

import numpy as np
import pytest

from ssa_fusion.apps import conjunction_table
from ssa_fusion.core.conjunction.close_approach import CloseApproaches
from ssa_fusion.core.conjunction.watch import WatchUpdate
from ssa_fusion.ros import bagio, messages
from ssa_fusion.ros.topics import TOPIC_CONJUNCTIONS

C = bagio.rosbags_classes()
T0 = 1.7536e9


def _update(ids, pairs, tca, miss, log10_pc, screened) -> WatchUpdate:
    n = len(pairs)
    x1 = np.tile([7000.0, 0, 0, 0, 7.5, 0], (n, 1))
    x2 = x1 + np.c_[np.zeros((n, 1)), np.asarray(miss)[:, None], np.zeros((n, 1)),
                    np.tile([0.0, -7.5, 7.5], (n, 1))]
    p = np.broadcast_to(np.eye(6) * 1e-2, (n, 6, 6)).copy()
    a = CloseApproaches(tuple(ids), np.array([i for i, _ in pairs], dtype=np.int64),
                        np.array([j for _, j in pairs], dtype=np.int64), np.asarray(tca),
                        np.asarray(miss, dtype=float), x1, x2, p, p)
    return WatchUpdate(screened, a, np.asarray(log10_pc, dtype=float), (T0, T0 + 86400.0),
                       5.0, 0.02)


def test_the_last_batches_stand_and_round_trip(tmp_path):
    ids = ["1", "2", "3", "4"]
    first = _update(ids, [(0, 1), (2, 3)], [T0 + 100.0, T0 + 200.0], [1.0, 2.0],
                    [-3.0, -5.0], ["1", "2", "3", "4"])
    second = _update(ids, [(2, 0)], [T0 + 300.0], [0.5], [-2.0], ["3"])  # 3 re-screened
    bag = tmp_path / "bag"
    w = bagio.BagWriter(bag)
    w.add_topic(TOPIC_CONJUNCTIONS, bagio.CONJUNCTION_BATCH)
    for k, up in enumerate((first, second)):
        w.write_msg(TOPIC_CONJUNCTIONS, int((T0 + k) * 1e9),
                    messages.conjunction_batch_to_msg(up, T0 + k, classes=C))
    w.close()
    back = [messages.conjunction_batch_from_msg(m.msg)
            for m in bagio.read_bag(bag, topics=[TOPIC_CONJUNCTIONS])]
    assert back[0].approaches.miss_km.tolist() == [1.0, 2.0]
    np.testing.assert_array_equal(back[0].approaches.x2, first.approaches.x2)
    assert back[1].screened == ["3"] and back[1].hbr_km == 0.02
    c = conjunction_table.latest(bag)
    assert (c.batches, c.screened) == (2, 5)
    # (1, 2) stands; (3, 4) was replaced by the re-screening of 3: (3, 1), most likely first
    assert [(r["primary"], r["secondary"]) for r in c.rows] == [("3", "1"), ("1", "2")]
    assert c.rows[0]["pc"] == pytest.approx(1e-2) and c.rows[0]["miss_m"] == 500.0
    assert c.rows[0]["rtn_m"] == pytest.approx([0.0, 500.0, 0.0])
    text = conjunction_table.table(c)
    assert "2 approaches standing (within 5000 m" in text and "| 3 | 1 |" in text
    conjunction_table.write_csv(c, tmp_path / "c.csv")
    rows = list(csv.DictReader((tmp_path / "c.csv").open()))
    assert [r["primary"] for r in rows] == ["3", "1"] and float(rows[1]["miss_m"]) == 1000.0
