"""Graph test of floods (hostile conditions, finding 7): a publisher anywhere in the domain
sends 100,000 distinct object ids, and one object id of 1 MB, to a catalog_filter shard.

Before, each new id grew the shard without bound and uncounted (100,000 ids: +167 MiB) and a
1 MB id made every status report 2 MB. Now the shard holds at most `max_objects` objects,
refuses the others as ``rejected_bank_full`` (counted, the node lives on), refuses an id over
`validation.MAX_ID_CHARS` as ``rejected_id`` with a bounded line, and its memory grows by the
objects it holds only. The test prints one ``FLOOD {json}`` line with what it measured
(`bench/probe_hostile.py` class 7 runs it)."""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np
from ssa_fusion_msgs.msg import MeasurementBatch
from test_catalog_filter_batch_graph import STATIONS, _pass_of_shard_0
from test_faults import Diag, publisher

from ssa_fusion.core.base.rows import MeasurementRows
from ssa_fusion.core.measure.validation import MAX_ID_CHARS
from ssa_fusion.ros import messages

FLOOD = 100_000
"""Distinct object ids sent (the finding's flood)."""
HOLD = 2_000
"""The shard's `max_objects` in this test."""
PER_BATCH = 5_000
MAX_GROWTH_MIB = 64.0
"""Bound on the shard's RSS growth over the flood: what HOLD objects may take (each a few
kB: its measurements waiting for initial orbit determination and its row) plus the DDS
receive buffers of the batches; 100,000 objects held took 167 MiB before."""


def _rss_kib(pid: int) -> int:
    """Resident set size of process `pid` (kB), from /proc."""
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1])
    raise AssertionError(f"no VmRSS for {pid}")


def _flood_rows(template: MeasurementRows, first: int, n: int) -> MeasurementRows:
    """`n` copies of `template`'s first row, each under a new object id (shard 0 of 1)."""
    rows = template.take(np.zeros(n, dtype=np.int64))
    rows.object_id = [f"FLOOD{k:07d}" for k in range(first, first + n)]
    rows.shard_key = messages.shard_keys(rows.object_id)
    return rows


def test_a_flood_of_object_ids_is_capped_counted_and_bounded_in_memory(ros_graph):
    g = ros_graph
    node = g.start_node("catalog_filter", params={
        "use_sim_time": True, "shards": 1, "shard": 0, "station": STATIONS,
        "max_objects": HOLD})
    diag = Diag(g)
    pub = publisher(g, MeasurementBatch, "/ssa/measurement_batch", ("catalog_filter",))
    template = _pass_of_shard_0().take(np.array([0]))
    pub.publish(messages.measurement_batch_to_msg(_flood_rows(template, 0, 10)))
    diag.wait(g, "catalog_filter", {"received": 10}, 30.0)
    before = _rss_kib(node.popen.pid)
    for first in range(10, FLOOD, PER_BATCH):
        pub.publish(messages.measurement_batch_to_msg(
            _flood_rows(template, first, min(PER_BATCH, FLOOD - first))))
        g.spin_once(0.01)
    long_id = template.take(np.array([0]))
    long_id.object_id = ["L" * 1_000_000]
    long_id.shard_key = messages.shard_keys(long_id.object_id)
    pub.publish(messages.measurement_batch_to_msg(long_id))
    c = diag.wait(g, "catalog_filter", {"received": FLOOD + 1, "rejected_id": 1,
                                        "rejected_bank_full": FLOOD - HOLD}, 120.0)
    after = _rss_kib(node.popen.pid)
    growth_mib = (after - before) / 1024.0
    sizes = [len(str(kv.value)) + len(kv.key) for arr in diag.msgs for st in arr.status
             if st.name == "catalog_filter" for kv in st.values]
    print("FLOOD " + json.dumps({"ids": FLOOD, "held": HOLD, "rss_before_kib": before,
                                 "rss_after_kib": after, "growth_mib": round(growth_mib, 1),
                                 "rejected_bank_full": int(c["rejected_bank_full"]),
                                 "rejected_id": int(c["rejected_id"]),
                                 "longest_status_value": max(sizes)}))
    assert growth_mib < MAX_GROWTH_MIB, growth_mib
    assert max(sizes) < 100 * MAX_ID_CHARS  # the 1 MB id is never echoed whole
    assert node.popen.poll() is None
    assert os.path.exists(f"/proc/{node.popen.pid}")
