"""The conjunction node's parameters (docs/NODES.md, "conjunction", says more)."""

from __future__ import annotations

from ssa_fusion.params.checks import POSITIVE, Check, ParamValue
from ssa_fusion.params.defaults import CONJUNCTION
from ssa_fusion.params.rows import Param, ParameterTable
from ssa_fusion.params.shared import MOTION_MODELS, clock_lead


def _probability(v: ParamValue) -> str | None:
    return None if isinstance(v, float) and 0.0 <= v <= 1.0 else "must be in [0, 1]"


PARAMETERS = ParameterTable("conjunction", (
    Param("distance", CONJUNCTION.distance,
          "screening distance: approaches closer than this are published", unit="m",
          check=POSITIVE, scale=1000.0),
    Param("horizon", CONJUNCTION.horizon,
          "the window screened runs from the clock this far ahead", unit="s", check=POSITIVE),
    Param("rescreen_period", CONJUNCTION.rescreen_period,
          "sim time between two re-screenings of the objects whose estimates changed",
          unit="s", check=POSITIVE),
    Param("hard_body_radius", CONJUNCTION.hard_body_radius,
          "combined hard-body radius of the collision probability", unit="m", check=POSITIVE,
          scale=1000.0),
    Param("motion_model", CONJUNCTION.motion_model,
          "the catalog_filter's motion model, which the estimates are flown with",
          check=MOTION_MODELS),
    Param("cdm_dir", CONJUNCTION.cdm_dir,
          "directory the CDMs are written to (one KVN file per approach and re-screening); "
          "'' = none"),
    Param("cdm_min_pc", CONJUNCTION.cdm_min_pc,
          "CDMs only for approaches of at least this collision probability",
          check=Check("in [0, 1]", _probability)),
    clock_lead(CONJUNCTION.max_clock_lead),
))
"""The conjunction node's parameters."""
