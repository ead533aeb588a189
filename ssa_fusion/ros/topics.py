"""QoS profiles of the ssa_fusion topics, chosen on purpose and shared by every node.

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

TOPIC_MEASUREMENT = "/ssa/measurement"
TOPIC_FORECAST = "/ssa/forecast"
TOPIC_ESTIMATE = "/ssa/estimate"
TOPIC_TRUTH = "/ssa/truth"
TOPIC_WITHHELD = "/ssa/withheld"
TOPIC_CLOCK = "/clock"
TOPIC_DIAGNOSTICS = "/diagnostics"
