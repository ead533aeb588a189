"""The surrogate's parameters (docs/NODES.md, "surrogate", says more of each)."""

from __future__ import annotations

from functools import partial

from ssa_fusion.core.gaps.estimator import Lift
from ssa_fusion.params import settings
from ssa_fusion.params.checks import NON_NEGATIVE, POSITIVE, Values, integer_in, one_of
from ssa_fusion.params.defaults import SURROGATE
from ssa_fusion.params.rows import Param, ParameterTable, Rule
from ssa_fusion.params.shared import (
    KINDS,
    STATION_RULE,
    clock_lead,
    lockstep_row,
    measurement_stream,
    object_filter,
)

MAX_DELAYS = 10_000
"""Most Hankel-DMD delays (a Hankel matrix of 10^4 x channels rows; with `cadence` 0 the
buffer's sample count is not known at start, so this bounds the fit's size)."""


def _fits(v: Values) -> str | None:
    """Return why the buffer cannot hold 2 x delays x cadence, or None."""
    delays, cadence, buffer = v["delays"], v["cadence"], v["buffer_length"]
    assert isinstance(delays, int | float) and isinstance(cadence, int | float)
    assert isinstance(buffer, int | float)
    if cadence > 0 and delays * cadence * 2 > buffer:
        return (f"needs a buffer of at least 2 x delays x cadence = {2 * delays * cadence} s, "
                f"but 'buffer_length' = {buffer} s")
    return None


PARAMETERS = ParameterTable("surrogate", (
    Param("buffer_length", SURROGATE.buffer_length,
          "real measurements kept for training (ten ISS orbits)", unit="s", check=POSITIVE,
          runtime=True),
    Param("retrain_period", SURROGATE.retrain_period,
          "refit at least this often while measurements arrive; 0 = never (every gap refits "
          "on the buffer up to the last real measurement anyway)", unit="sim s",
          check=NON_NEGATIVE, runtime=True),
    Param("delays", SURROGATE.delays, "Hankel-DMD time delays (two ISS orbits at 30 s)",
          unit="samples", check=integer_in(1, MAX_DELAYS), runtime=True),
    Param("rank", SURROGATE.rank, "Hankel-DMD rank; 0 = automatic (Gavish–Donoho)",
          check=NON_NEGATIVE, runtime=True),
    Param("max_horizon", SURROGATE.max_horizon,
          "nothing is forecast further than this after the last real measurement", unit="s",
          check=POSITIVE, runtime=True),
    Param("grace", SURROGATE.grace, "wait after a missed epoch before forecasting it "
          "(absorbs message latency)", unit="cadences", check=NON_NEGATIVE, runtime=True),
    Param("cadence", SURROGATE.cadence,
          "expected time between measurements; 0 = inferred from the buffered stamps",
          unit="s", check=NON_NEGATIVE, runtime=True),
    *measurement_stream(SURROGATE.kind, SURROGATE.station, SURROGATE.sites, "learns",
                        tuple(k for k in KINDS if k != "laser_range")),
    Param("lift", SURROGATE.lift,
          "what the DMD learns: `none` (the measurement itself) or `eci` (range/az/el lifted "
          "to the GCRF position it implies; needs `kind` `range_az_el`)",
          check=one_of(*map(str, Lift))),
    Param("check_period", SURROGATE.check_period, "period of the check for missed epochs",
          unit="wall s", check=POSITIVE),
    object_filter(SURROGATE.object_id, "learn"),
    clock_lead(SURROGATE.max_clock_lead),
    lockstep_row(SURROGATE.lockstep,
                 "forecasts the epochs it missed (without `grace`)"),
), rules=(Rule(("delays", "cadence", "buffer_length"), _fits),
          STATION_RULE,
          Rule(settings.SURROGATE_KEYS, partial(settings.estimator_problem, "surrogate"))))
"""The surrogate's parameters."""
