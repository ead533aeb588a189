"""Every node's parameter table, one module per node, each with its ``PARAMETERS``.

`table_of` imports a node's module only when asked: a node process imports its own table
and no other (the catalog filter's imports stay light: test/test_imports.py).
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from ssa_fusion.params.rows import ParameterTable

NODES = ("sensor_sim", "surrogate", "filter", "recorder", "foxglove_bridge", "catalog_filter",
         "catalog_surrogate", "conjunction")
"""The nodes, in docs/NODES.md's order: each has an executable and a table here."""


def table_of(node: str) -> ParameterTable:
    """Return the parameter table of node `node` (its module's ``PARAMETERS``).

    ValueError names an unknown node.
    """
    if node not in NODES:
        raise ValueError(f"unknown node {node!r}; known: {', '.join(NODES)}")
    table: ParameterTable = importlib.import_module(f"ssa_fusion.params.tables.{node}").PARAMETERS
    return table
