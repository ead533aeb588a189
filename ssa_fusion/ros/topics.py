"""Topic names and QoS profiles of the ssa_fusion topics, shared by every node.

Measurements, forecasts, estimates and truth are *reliable* with a deep keep-last history so
that a burst at a high simulation time scale is queued rather than dropped; they are
*volatile* because late joiners should start from live data (replay covers the past).
"""

from copy import copy

from rclpy.duration import Duration
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

DATA_DEPTH = 10000
"""Keep-last depth of data topics: ~3 h of 1 Hz measurements queued before any loss."""

DATA_QOS = QoSProfile(
    history=HistoryPolicy.KEEP_LAST,
    depth=DATA_DEPTH,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.VOLATILE,
)

CATALOG_DEPTH = 1_000_000
"""Keep-last depth of a catalog's measurement and estimate streams: a shard or the recorder
that falls minutes behind a catalog's thousands of measurements per second queues them (the
history grows only as far as the backlog) rather than losing the oldest."""

CATALOG_QOS = QoSProfile(
    history=HistoryPolicy.KEEP_LAST,
    depth=CATALOG_DEPTH,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.VOLATILE,
)

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

TOPIC_MEASUREMENT = "/ssa/measurement"
TOPIC_MEASUREMENT_BATCH = "/ssa/measurement_batch"
"""A catalog's measurements as ssa_fusion_msgs/MeasurementBatch (many rows a message)."""
TOPIC_ESTIMATE_BATCH = "/ssa/estimate_batch"
"""A catalog's estimates and forecasts as ssa_fusion_msgs/EstimateBatch."""
TOPIC_DETECTION_TRUTH = "/ssa/detection_truth"
"""For evaluation only, never fused: the simulator's unlabelled detections with their true
object ids (MeasurementBatch; each batch the rows of one on `TOPIC_MEASUREMENT_BATCH`, in
the same order)."""
TOPIC_ASSOCIATED = "/ssa/measurement_associated"
"""The unlabelled detections the catalog_filter placed in a track or tracklet, each row's
``object_id`` the track's id (MeasurementBatch; `core.catalog.unlabelled`)."""
TOPIC_FORECAST = "/ssa/forecast"
TOPIC_ESTIMATE = "/ssa/estimate"
TOPIC_SMOOTHED = "/ssa/estimate_smoothed"
"""Smoothed estimates (`replay --offline --smooth`): the definitive orbit at the fused epochs."""
TOPIC_TRUTH = "/ssa/truth"
TOPIC_WITHHELD = "/ssa/withheld"
TOPIC_CLOCK = "/clock"
TOPIC_METEO = "/ssa/meteo"
"""Surface meteorological data of the stations (ssa_fusion_msgs/Meteo): the troposphere of
their laser ranges (`ssa-fusion import crd`)."""
TOPIC_REFERENCE = "/ssa/reference"
"""For evaluation only, never fused: an independent orbit of the object (StateEstimate,
GCRF, zero covariance), e.g. a CPF prediction (`ssa-fusion import crd --reference`)."""
TOPIC_DIAGNOSTICS = "/diagnostics"
TOPIC_CONFIG = "/ssa/config"
"""The estimator settings in effect (std_msgs/String, JSON of `params.settings.config_message`),
one latched message per filter/surrogate node, re-sent when a parameter changes."""

CONFIG_QOS = QoSProfile(
    history=HistoryPolicy.KEEP_LAST,
    depth=1,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.TRANSIENT_LOCAL,
)
"""Latched: a reader that joins later (the recorder) still gets each node's last settings."""
