"""The catalog_filter's parameters (docs/NODES.md, "catalog_filter", says more of each)."""

from __future__ import annotations

from ssa_fusion.params.checks import POSITIVE, STATION_IDS, at_least
from ssa_fusion.params.defaults import CATALOG_FILTER
from ssa_fusion.params.rows import Param, ParameterTable
from ssa_fusion.params.shared import (
    SHARD_RULE,
    STATION_RULE,
    clock_lead,
    filter_rows,
    max_objects_row,
    shard_rows,
    sites_row,
)

PARAMETERS = ParameterTable("catalog_filter", (
    Param("station", CATALOG_FILTER.station,
          "radar stations of the measurements: a network id, or station ids (built in, or "
          "sites of `sites`) separated by commas", check=STATION_IDS),
    sites_row(CATALOG_FILTER.sites),
    *filter_rows(CATALOG_FILTER, runtime=False, unlimited_span=False),
    *shard_rows(CATALOG_FILTER.shards, CATALOG_FILTER.shard),
    Param("batch_period", CATALOG_FILTER.batch_period,
          "time between batches: what arrived meanwhile is fused at once", unit="wall s",
          check=POSITIVE),
    Param("evict_after", CATALOG_FILTER.evict_after,
          "when the shard holds max_objects, the object measured longest ago gives its row "
          "to a new one if silent this long (counted `evicted`)", unit="s", check=POSITIVE),
    Param("batch_rows", CATALOG_FILTER.batch_rows,
          "a fusion's estimates go in EstimateBatch messages of at most this many rows "
          "(~0.4 kB each; DDS keeps buffers as large as the largest message)",
          check=at_least(1)),
    Param("max_unacked_rows", CATALOG_FILTER.max_unacked_rows,
          "estimate rows published before the node waits (at most 5 wall s) for its readers' "
          "acknowledgements; 0 = never wait", check=at_least(0)),
    clock_lead(CATALOG_FILTER.max_clock_lead),
    max_objects_row(CATALOG_FILTER.max_objects, "tracks (~2 kB each: 180 MiB for 100,000)",
                    "a measurement"),
), rules=(SHARD_RULE, STATION_RULE))
"""The catalog_filter's parameters."""
