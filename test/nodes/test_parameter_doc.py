"""docs/NODES.md's parameter tables are the nodes' own tables (`PARAMETERS` of each node
module), rendered by `ssa_fusion.nodes.parameter_doc`: a parameter added, renamed, given
another default, unit, range, run-time flag or description in a node and not in the doc
fails here (fix: ``python -m ssa_fusion.nodes.parameter_doc docs/NODES.md``)."""

from pathlib import Path

import pytest

from ssa_fusion.nodes import defaults, parameter_doc
from ssa_fusion.nodes.entry import NODES
from ssa_fusion.nodes.parameters import Computed

ROOT = Path(__file__).resolve().parents[2]
DOC = ROOT / "docs" / "NODES.md"
CONFIG = ROOT / "config" / "default.yaml"
DEFAULTS = {"sensor_sim": defaults.SENSOR_SIM, "surrogate": defaults.SURROGATE,
            "filter": defaults.FILTER, "recorder": defaults.RECORDER,
            "catalog_filter": defaults.CATALOG_FILTER,
            "catalog_surrogate": defaults.CATALOG_SURROGATE}
"""The nodes whose defaults live in `nodes.defaults` (foxglove_bridge's are its own)."""


def test_nodes_md_tables_are_the_nodes_tables():
    text = DOC.read_text()
    assert parameter_doc.documented(text) == list(NODES), "a node's table markers are missing"
    assert parameter_doc.render(text, CONFIG) == text, (
        "docs/NODES.md's parameter tables differ from the nodes' PARAMETERS: run "
        "python -m ssa_fusion.nodes.parameter_doc docs/NODES.md")


def test_the_check_mode_fails_on_a_stale_doc(tmp_path):
    stale = tmp_path / "NODES.md"
    stale.write_text(DOC.read_text().replace("| `q` |", "| `qq` |", 1))
    args = [str(stale), "--config", str(CONFIG), "--check"]
    assert parameter_doc.main(args) == 1
    assert parameter_doc.main([str(stale), "--config", str(CONFIG)]) == 0  # rewritten
    assert parameter_doc.main(args) == 0
    assert stale.read_text() == DOC.read_text()


@pytest.mark.parametrize("node", list(DEFAULTS))
def test_each_table_declares_exactly_the_nodes_defaults(node):
    """The table and `nodes.defaults` name the same parameters, with the same values (a
    default computed at start-up is None there)."""
    table = parameter_doc.table_of(node)
    values = {p.name: None if isinstance(p.default, Computed) else p.default for p in table}
    assert values == {k: v for k, v in vars(DEFAULTS[node]).items()}


def test_every_row_is_documented_with_a_unit_and_a_description():
    for node in NODES:
        for p in parameter_doc.table_of(node):
            assert p.description and p.unit, (node, p.name)
