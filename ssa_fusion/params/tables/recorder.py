"""The recorder's parameters (docs/NODES.md, "recorder")."""

from __future__ import annotations

import time
from pathlib import Path

from ssa_fusion.params.checks import POSITIVE, Check, ParamValue
from ssa_fusion.params.defaults import BAG_PATTERN, RECORDER
from ssa_fusion.params.rows import Computed, Param, ParameterTable


def _new_bag(value: ParamValue) -> str | None:
    if not value:
        return "must be a directory path"
    return "exists already, not overwriting" if Path(str(value)).exists() else None


PARAMETERS = ParameterTable("recorder", (
    Param("bag", Computed(lambda _: time.strftime(BAG_PATTERN),
                          "`out/bags/ssa_<YYYYmmdd_HHMMSS>` (start time; not in the yaml: the "
                          "launch file's `bag:=`)", "out/bags/ssa_20260101_120000"),
          "output bag directory", check=Check("must not exist", _new_bag)),
    Param("topics", RECORDER.topics, "topics recorded besides every topic under `prefix`"),
    Param("prefix", RECORDER.prefix, "record every topic whose name starts with this"),
    Param("flush_period", RECORDER.flush_period, "time between flushes of the bag to disk",
          unit="wall s", check=POSITIVE),
    Param("discover_period", RECORDER.discover_period, "time between topic discovery scans",
          unit="wall s", check=POSITIVE),
))
"""The recorder's parameters."""
