"""Topic names of the ssa_fusion topics and their queue depths, shared by every node.

Names only (no ROS import: offline replay and reports read them); the QoS profiles the nodes
use are `ros.qos`'s.
"""

DATA_DEPTH = 10000
"""Keep-last depth of data topics: ~3 h of 1 Hz measurements queued before any loss."""

CATALOG_DEPTH = 1_000_000
"""Keep-last depth of a catalog's measurement and estimate streams: a shard or the recorder
that falls minutes behind a catalog's thousands of measurements per second queues them (the
history grows only as far as the backlog) rather than losing the oldest."""

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
TOPIC_RUN = "/ssa/run"
"""The run a bag holds (std_msgs/String, JSON ``{"run": id, "namespace": ns}``): written by
the recorder itself, once, at the first /clock; never published (`ros.run_identity`)."""
TOPIC_CONJUNCTIONS = "/ssa/conjunctions"
"""Close approaches of a catalog (ssa_fusion_msgs/ConjunctionBatch): each re-screening of
the objects whose estimates changed (the conjunction node)."""
TOPIC_DIAGNOSTICS = "/diagnostics"
TOPIC_CONFIG = "/ssa/config"
"""The estimator settings in effect (std_msgs/String, JSON of `params.settings.config_message`),
one latched message per filter/surrogate node, re-sent when a parameter changes."""
MARKERS_TOPIC = "/ssa/visual/markers"
"""visualization_msgs/MarkerArray: the 3D scene (GCRF, km)."""
TRACK_TOPIC = "/ssa/visual/ground_track"
"""sensor_msgs/NavSatFix: the estimate's sub-satellite point."""
TRUTH_TRACK_TOPIC = "/ssa/visual/ground_track_truth"
"""sensor_msgs/NavSatFix: the truth's sub-satellite point."""
VISUAL_TOPICS = (MARKERS_TOPIC, TRACK_TOPIC, TRUTH_TRACK_TOPIC)
"""The topics of the scene and ground tracks the foxglove_bridge publishes and the recorder
keeps (`ros.visual_msgs` builds their messages)."""
