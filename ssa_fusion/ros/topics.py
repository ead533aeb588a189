"""Topic names and QoS profiles of the ssa_fusion topics, shared by every node.

Measurements, forecasts, estimates and truth are *reliable* with a deep keep-last history so
that a burst at a high simulation time scale is queued rather than dropped; they are
*volatile* because late joiners should start from live data (replay covers the past).
"""

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
``object_id`` the track's id (MeasurementBatch; `core.unlabelled`)."""
TOPIC_FORECAST = "/ssa/forecast"
TOPIC_ESTIMATE = "/ssa/estimate"
TOPIC_SMOOTHED = "/ssa/estimate_smoothed"
"""Smoothed estimates (`replay --offline --smooth`): the definitive orbit at the fused epochs."""
TOPIC_TRUTH = "/ssa/truth"
TOPIC_WITHHELD = "/ssa/withheld"
TOPIC_CLOCK = "/clock"
TOPIC_DIAGNOSTICS = "/diagnostics"
TOPIC_CONFIG = "/ssa/config"
"""The estimator settings in effect (std_msgs/String, JSON of `nodes.settings.config_message`),
one latched message per filter/surrogate node, re-sent when a parameter changes."""

CONFIG_QOS = QoSProfile(
    history=HistoryPolicy.KEEP_LAST,
    depth=1,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.TRANSIENT_LOCAL,
)
"""Latched: a reader that joins later (the recorder) still gets each node's last settings."""
