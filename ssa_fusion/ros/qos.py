"""QoS profiles of the ssa_fusion topics, shared by every node (rclpy).

Measurements, forecasts, estimates and truth are *reliable* with a deep keep-last history so
that a burst at a high simulation time scale is queued rather than dropped; they are
*volatile* because late joiners should start from live data (replay covers the past). The
topic names are `ros.topics`'.
"""

from copy import copy

from rclpy.duration import Duration
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

from ssa_fusion.ros.topics import CATALOG_DEPTH, DATA_DEPTH


def reliable_stream(depth: int) -> QoSProfile:
    """Return the QoS of a data stream: reliable, volatile, the last `depth` messages kept."""
    return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=depth,
                      reliability=ReliabilityPolicy.RELIABLE,
                      durability=DurabilityPolicy.VOLATILE)


DATA_QOS = reliable_stream(DATA_DEPTH)

CATALOG_QOS = reliable_stream(CATALOG_DEPTH)

WRITER_LIVELINESS_LEASE_S = 86_400.0
"""Liveliness lease (wall s) every data writer offers (`writer_qos`); readers keep the default
(infinite), which accepts any writer's."""


def writer_qos(qos: QoSProfile) -> QoSProfile:
    """Return `qos` for a writer of data topics: a finite liveliness lease.

    Fast DDS evaluates a reader's content filter in the writer when the writer's lease is
    infinite (rmw's default), and a sample that fails it stays in the writer's history: a
    reliable volatile writer never removes it, and with `CATALOG_DEPTH` a shard's batches
    for the other shard's readers piled up for the rest of the run (a publisher of 1,500
    batches of 1,000 rows grew from 71 to 445 MiB with one reader filtering every batch
    out, 70 to 72 MiB with this lease). With a finite lease the readers filter what arrives
    and every sample leaves the history once acknowledged. (Liveliness is asserted by
    Fast DDS's own threads every 2/3 of the lease, as rmw_fastrtps sets it.)
    """
    out = copy(qos)
    out.liveliness_lease_duration = Duration(seconds=WRITER_LIVELINESS_LEASE_S)
    return out


DATA_WRITER_QOS = writer_qos(DATA_QOS)
"""`DATA_QOS` for the writers of data topics (`writer_qos`)."""
CATALOG_WRITER_QOS = writer_qos(CATALOG_QOS)
"""`CATALOG_QOS` for the writers of a catalog's batches (`writer_qos`)."""

CONFIG_QOS = QoSProfile(
    history=HistoryPolicy.KEEP_LAST,
    depth=1,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.TRANSIENT_LOCAL,
)
"""Latched: a reader that joins later (the recorder) still gets each node's last settings."""
