"""A ROS params file (the YAML of ``--ros-args --params-file``) read without ROS.

`load_params_file` gives the estimator settings the file gives the filter and the surrogate
(``ssa-fusion replay``/``report --params-file``), after judging every value of theirs as the
nodes would at start-up (`section_problem`, by their tables): no rclpy, no node started.
Importing it imports no table (a node process checks a params file's size with
`PARAMS_FILE_MAX_BYTES` before it starts).
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

import yaml

from ssa_fusion.core.base.quoting import one_line, quote, shown
from ssa_fusion.core.gaps.estimator import EstimatorConfig
from ssa_fusion.params.rows import ParameterTable
from ssa_fusion.params.settings import FILTER_KEYS, SURROGATE_KEYS, estimator_from
from ssa_fusion.params.tables import table_of


def node_section(params_file: Mapping[str, Any], node: str) -> dict[str, Any]:
    """Return the ``ros__parameters`` of `node` in a loaded ROS params file.

    Wildcard sections (``/**``, ``**``, ``/*``, ``*``) first, then the node's own
    (``node`` or ``/node``), as rcl applies them.
    """
    out: dict[str, Any] = {}
    for key in ("/**", "**", "/*", "*", node, f"/{node}"):
        section = params_file.get(key)
        if isinstance(section, Mapping):
            out.update(section.get("ros__parameters") or {})
    return out


PARAMS_FILE_MAX_BYTES = 1_000_000
"""Largest params file read offline (a node's own settings are a few hundred bytes)."""

ROS_OWN_PARAMETERS = ("use_sim_time", "qos_overrides", "start_type_description_service")
"""Parameters rclpy declares on every node itself (not in the nodes' tables)."""


def section_problem(section: Mapping[str, Any], table: ParameterTable) -> str | None:
    """Return why a node's ``ros__parameters`` `section` would not start the node, or None.

    As the node judges them at start-up: a name it does not declare, a value its row refuses
    (`Param.reason`) or of another type. (Rules across parameters are the node's own.)
    """
    for key, value in section.items():
        if key in ROS_OWN_PARAMETERS:
            continue
        if key not in table.names:
            return f"{quote(key)} is not a parameter of {table.node} (docs/NODES.md)"
        try:
            reason = table[key].reason(value)
        except (TypeError, ValueError, AttributeError, ArithmeticError):
            reason = f"of the wrong type ({type(value).__name__})"
        if reason:
            return f"parameter '{key}' = {quote(value)}: {one_line(reason, 200)}"
    return None


def load_params_file(path: Path | str) -> EstimatorConfig:
    """Return the estimator a ROS params YAML gives the filter and the surrogate.

    The YAML of ``--ros-args --params-file``. ValueError (naming the file) if it cannot be
    read or holds a bad value; parameters that are not estimator settings are ignored.
    """
    try:
        with Path(path).open("rb") as f:
            raw = f.read(PARAMS_FILE_MAX_BYTES + 1)
        if len(raw) > PARAMS_FILE_MAX_BYTES:
            raise ValueError(f"params file {path}: larger than {PARAMS_FILE_MAX_BYTES} bytes; "
                             "a params file holds a few settings per node")
        loaded = yaml.safe_load(raw.decode("utf-8"))
    except (OSError, yaml.YAMLError, UnicodeDecodeError) as exc:
        raise ValueError(f"cannot read params file {shown(str(path), 200)}: "
                         f"{one_line(exc, 240)}") from None
    except (RecursionError, MemoryError):
        raise ValueError(f"params file {path}: nested too deeply or too large to read") from None
    except Exception as exc:  # PyYAML's own on odd input: ValueError (an int of over 4300
        # digits), IndexError ('!!float' of nothing), ...
        raise ValueError(f"params file {path}: not YAML PyYAML can load: "
                         f"{type(exc).__name__}: {one_line(exc, 120)}") from None
    if not isinstance(loaded, Mapping):
        raise ValueError(f"params file {path}: not a mapping of node names to ros__parameters")
    for node in ("filter", "surrogate"):
        problem = section_problem(node_section(loaded, node), table_of(node))
        if problem:
            raise ValueError(f"params file {path}: {node}: {problem}")
    filt = {k: v for k, v in node_section(loaded, "filter").items() if k in FILTER_KEYS}
    surr = {k: v for k, v in node_section(loaded, "surrogate").items() if k in SURROGATE_KEYS}
    try:
        return estimator_from(filt, surr)
    except (ValueError, TypeError, KeyError, ArithmeticError) as exc:
        raise ValueError(f"params file {path}: {one_line(exc, 300)}") from None
