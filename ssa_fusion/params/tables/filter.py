"""The filter's parameters (docs/NODES.md, "filter", says more of each)."""

from __future__ import annotations

import json
from functools import partial

from ssa_fusion.core.gaps.publisher import GapFill
from ssa_fusion.params import settings
from ssa_fusion.params.checks import NON_NEGATIVE, Check, finite_numbers, one_of, read_by
from ssa_fusion.params.defaults import FILTER
from ssa_fusion.params.rows import Param, ParameterTable, Rule
from ssa_fusion.params.shared import (
    STATION_RULE,
    clock_lead,
    filter_rows,
    lockstep_row,
    measurement_stream,
    object_filter,
)


def _json_object(text: str) -> None:
    """Read ``text`` as a JSON object (ValueError otherwise)."""
    if not isinstance(json.loads(text), dict):
        raise ValueError("must be a JSON object")


PARAMETERS = ParameterTable("filter", (
    *measurement_stream(FILTER.kind, FILTER.station, FILTER.sites, "fuses"),
    *filter_rows(FILTER, runtime=True, unlimited_span=True),
    Param("light_time", FILTER.light_time,
          "station models see the object where it was range / c earlier (the ISS moves "
          "11–39 m meanwhile)"),
    Param("refraction", FILTER.refraction,
          "radar elevations as the standard atmosphere refracts them (Saemundsson's "
          "formula, `core.earth.refraction`; 5.4′ at 10°); off: geometric"),
    object_filter(FILTER.object_id, "track"),
    Param("predict_period", FILTER.predict_period,
          "without an update for this long, predictions are published at every multiple of "
          "`predict_period` of sim time; 0 = never", unit="sim s", check=NON_NEGATIVE,
          runtime=True),
    Param("gap_forecast", FILTER.gap_forecast,
          "what the predictions in a gap between passes are: the EKF coasting (`none`), or "
          "a forecast of the residual, of a batch fit, or of both", check=one_of(*GapFill)),
    clock_lead(FILTER.max_clock_lead),
    lockstep_row(FILTER.lockstep, "publishes its predictions and gap forecasts"),
    Param("laser", FILTER.laser,
          "with `kind` laser_range: the stations and the object, `import crd`'s /ssa/config "
          "message (JSON); the filter is then the laser filter; `\"\"` = none",
          check=Check("'' or a JSON object", read_by(_json_object, empty_ok=True))),
    Param("apriori", FILTER.apriori,
          "with `kind` laser_range: the a-priori orbit it starts from, epoch (Unix s) and GCRF "
          "state (m, m/s)", unit="s, m, m/s",
          check=finite_numbers(7, "needs 7 finite numbers: epoch, x, y, z, vx, vy, vz")),
), rules=(STATION_RULE,
          Rule(settings.FILTER_KEYS, partial(settings.estimator_problem, "filter"))))
"""The filter's parameters."""
