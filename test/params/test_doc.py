"""docs/NODES.md's parameter tables are the nodes' own tables (`params.tables`), rendered by
`ssa_fusion.params.doc`: a parameter added, renamed, given another default, unit, range,
run-time flag or description in a table and not in the doc fails here (fix:
``python -m ssa_fusion.params.doc docs/NODES.md``). A row's description is a sentence or
two; the rest is docs/NODES.md's prose."""

from pathlib import Path

import pytest

from ssa_fusion.params import defaults, doc
from ssa_fusion.params.rows import Computed
from ssa_fusion.params.tables import NODES, table_of

ROOT = Path(__file__).resolve().parents[2]
DOC = ROOT / "docs" / "NODES.md"
CONFIG = ROOT / "config" / "default.yaml"
DEFAULTS = {"sensor_sim": defaults.SENSOR_SIM, "surrogate": defaults.SURROGATE,
            "filter": defaults.FILTER, "recorder": defaults.RECORDER,
            "foxglove_bridge": defaults.FOXGLOVE_BRIDGE,
            "catalog_filter": defaults.CATALOG_FILTER,
            "catalog_surrogate": defaults.CATALOG_SURROGATE,
            "conjunction": defaults.CONJUNCTION}
"""Every node's defaults (`params.defaults`)."""
MAX_DESCRIPTION = 200
"""Most characters of a row's description (``ros2 param describe`` prints it)."""


def test_nodes_md_tables_are_the_nodes_tables():
    text = DOC.read_text()
    assert doc.documented(text) == list(NODES), "a node's table markers are missing"
    assert doc.render(text, CONFIG) == text, (
        "docs/NODES.md's parameter tables differ from the nodes' tables: run "
        "python -m ssa_fusion.params.doc docs/NODES.md")


def test_the_check_mode_fails_on_a_stale_doc(tmp_path):
    stale = tmp_path / "NODES.md"
    stale.write_text(DOC.read_text().replace("| `q` |", "| `qq` |", 1))
    args = [str(stale), "--config", str(CONFIG), "--check"]
    assert doc.main(args) == 1
    assert doc.main([str(stale), "--config", str(CONFIG)]) == 0  # rewritten
    assert doc.main(args) == 0
    assert stale.read_text() == DOC.read_text()


def test_every_node_has_a_table_and_defaults():
    assert set(DEFAULTS) == set(NODES)
    with pytest.raises(ValueError, match="unknown node 'sensor'"):
        table_of("sensor")


@pytest.mark.parametrize("node", NODES)
def test_each_table_declares_exactly_the_nodes_defaults(node):
    """The table and `params.defaults` name the same parameters, with the same values (a
    default computed at start-up is None there)."""
    table = table_of(node)
    assert table.node == node
    values = {p.name: None if isinstance(p.default, Computed) else p.default for p in table}
    assert values == dict(vars(DEFAULTS[node]))


@pytest.mark.parametrize("node", NODES)
def test_every_row_has_a_unit_and_a_short_description(node):
    for p in table_of(node):
        assert p.description and p.unit, (node, p.name)
        assert len(p.description) <= MAX_DESCRIPTION, (node, p.name, len(p.description))
