"""Association of unlabelled radar detections with tracks, and the tracks' management.

A radar does not label its detections with an object id. Its scans (one station's
detections at one epoch) are associated with a catalog of tracks, and the tracks are
started, confirmed and deleted from them (docs/ASSOCIATION.md measures it). Split the way
Stone Soup splits a tracker, one module per job; each imports only the modules before it
in this list (and the core's rooms up to `catalog`):

* `config`: the rules (`AssociationConfig`) and the chi-square gate;
* `outcomes`: what the association reports (`TrackStatus`, `DetectionFate`, `TrackEvent`,
  `Relabel`, `ScanOutcome`);
* `gating`: tracks predicted to a scan, every (track, detection) pair scored against the
  gate (`predict_scan`, `gate_scan`), and rescored by a long-arc predictor
  (`gate_long_arc`);
* `assignment`: global nearest neighbour (`assign`, `associate`);
* `registration`: groups of tracks shifted along track by a common time before the
  assignment, for objects launched together (`register`);
* `tracklets`: the detections no track took, until an initial orbit starts a track;
* `deferral`: decisions deferred over passes for ambiguous pairs of young tracks
  (`PairDeferral`);
* `manager`: the track management that runs them scan by scan (`Associator`).

This package's namespace holds the public names of all of them.

Imports: every catalog_filter process imports this package (`catalog.fusion`), and most
never see an unlabelled detection. So of scipy it imports only ``scipy.special`` (the
chi-square quantile, `config.chi2_quantile`, ~9 MiB); ``scipy.optimize``
(`assignment.assign`) and ``scipy.sparse`` (`registration.register`) are imported by the
functions that use them, at their first call: ``scipy.stats`` and ``scipy.optimize`` would
add ~45 MiB to every process's resident memory.
"""

from ssa_fusion.core.catalog.association.assignment import (
    UNASSIGNED,
    ScanAssociation,
    assign,
    associate,
)
from ssa_fusion.core.catalog.association.config import (
    MEASUREMENT_DOF,
    AssociationConfig,
    chi2_quantile,
)
from ssa_fusion.core.catalog.association.deferral import (
    Fork,
    ForkState,
    PairDeferral,
    ambiguous_pairs,
    pair_cost,
    shadows_in,
)
from ssa_fusion.core.catalog.association.gating import (
    Gated,
    ScanPrediction,
    gate_long_arc,
    gate_scan,
    predict_scan,
)
from ssa_fusion.core.catalog.association.manager import Associator
from ssa_fusion.core.catalog.association.outcomes import (
    DetectionFate,
    Relabel,
    ScanOutcome,
    TrackEvent,
    TrackStatus,
)
from ssa_fusion.core.catalog.association.registration import linked_tracks, register

__all__ = [
    "MEASUREMENT_DOF",
    "UNASSIGNED",
    "AssociationConfig",
    "Associator",
    "DetectionFate",
    "Fork",
    "ForkState",
    "Gated",
    "PairDeferral",
    "Relabel",
    "ScanAssociation",
    "ScanOutcome",
    "ScanPrediction",
    "TrackEvent",
    "TrackStatus",
    "ambiguous_pairs",
    "assign",
    "associate",
    "chi2_quantile",
    "gate_long_arc",
    "gate_scan",
    "linked_tracks",
    "pair_cost",
    "predict_scan",
    "register",
    "shadows_in",
]
