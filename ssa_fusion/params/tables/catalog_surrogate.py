"""The catalog_surrogate's parameters (docs/NODES.md, "catalog_surrogate", says more)."""

from __future__ import annotations

from ssa_fusion.core.catalog.gap_bank import GAP_FORECASTS
from ssa_fusion.params.checks import (
    NON_NEGATIVE,
    POSITIVE,
    STATION_IDS,
    Check,
    ParamValue,
    at_least,
    one_of,
)
from ssa_fusion.params.defaults import CATALOG_SURROGATE
from ssa_fusion.params.rows import Param, ParameterTable
from ssa_fusion.params.shared import (
    MOTION_MODELS,
    SHARD_RULE,
    STATION_RULE,
    clock_lead,
    max_objects_row,
    shard_rows,
    sites_row,
)


def _fraction(v: ParamValue) -> str | None:
    return None if isinstance(v, float) and 0.0 <= v <= 1.0 else "must be in [0, 1]"


PARAMETERS = ParameterTable("catalog_surrogate", (
    Param("motion_model", CATALOG_SURROGATE.motion_model,
          "the catalog_filter's motion model, which the residual is learned against",
          check=MOTION_MODELS),
    Param("predict_period", CATALOG_SURROGATE.predict_period,
          "forecasts at its multiples in a gap", unit="s", check=POSITIVE),
    Param("pass_break", CATALOG_SURROGATE.pass_break,
          "sim time without an estimate after which a pass has ended", unit="s",
          check=POSITIVE),
    Param("hold", CATALOG_SURROGATE.hold,
          "forecasts only for epochs at least this long before the clock (the filter's "
          "estimates arrive after the clock)", unit="s", check=NON_NEGATIVE),
    Param("fit_budget", CATALOG_SURROGATE.fit_budget,
          "fraction of wall time the fits may take on average; 0 = no budget: every pass "
          "end is fitted when found", check=Check("in [0, 1]", _fraction)),
    Param("min_anchors", CATALOG_SURROGATE.min_anchors, "pass ends a fit needs",
          check=at_least(2)),
    Param("min_span", CATALOG_SURROGATE.min_span,
          "the pass ends of a fit must span at least this", unit="s", check=NON_NEGATIVE),
    Param("physics_fit", CATALOG_SURROGATE.physics_fit,
          "residual: a gap the learned residual has no fit for yet, or refuses, gets the "
          "physics-only forecast from the object's pass end"),
    Param("gap_forecast", CATALOG_SURROGATE.gap_forecast,
          "each gap's forecast: `residual` (the motion model plus its residual learned from "
          "pass ends) or `batch_fit` (a batch least-squares fit of the object's last passes)",
          check=one_of(*(str(f) for f in GAP_FORECASTS))),
    Param("station", CATALOG_SURROGATE.station,
          "batch_fit: radar stations of the measurements, as the catalog_filter's "
          "`station`", check=STATION_IDS),
    sites_row(CATALOG_SURROGATE.sites),
    *shard_rows(CATALOG_SURROGATE.shards, CATALOG_SURROGATE.shard),
    clock_lead(CATALOG_SURROGATE.max_clock_lead),
    max_objects_row(CATALOG_SURROGATE.max_objects, "holds", "an estimate"),
), rules=(SHARD_RULE, STATION_RULE))
"""The catalog_surrogate's parameters."""
