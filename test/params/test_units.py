"""`params.units.convert`: SI <-> the core's units by each row's scale, for any table."""

import pytest

from ssa_fusion.params import settings
from ssa_fusion.params.rows import Param
from ssa_fusion.params.tables import NODES, table_of
from ssa_fusion.params.tables.catalog_filter import PARAMETERS as CATALOG_FILTER
from ssa_fusion.params.units import Units, convert

ROWS = (Param("p0_sigma", (1.0,), "", scale=1000.0), Param("q", 0.1, "", scale=1e6),
        Param("gate", 10.0, ""))


def test_si_to_core_divides_by_the_scale_and_back_multiplies():
    si = {"p0_sigma": [1000.0, 2500, 0.5], "q": 0.1, "gate": 16.0, "kind": "position"}
    core = convert(ROWS, si, Units.CORE)
    assert core == {"p0_sigma": [1.0, 2.5, 0.0005], "q": pytest.approx(1e-7, rel=1e-15),
                    "gate": 16.0, "kind": "position"}
    assert all(isinstance(v, float) for v in core["p0_sigma"])
    assert convert(ROWS, core, Units.SI) == pytest.approx(
        {"p0_sigma": [1000.0, 2500.0, 0.5], "q": 0.1, "gate": 16.0, "kind": "position"})


def test_only_the_lengths_of_the_filters_are_scaled():
    """m against km: p0_sigma (m, m/s) by 1e3, q (m²/s³) by 1e6, the conjunction node's
    distances (m) by 1e3; nothing else of any table."""
    scaled = {(node, p.name): p.scale for node in NODES for p in table_of(node)
              if p.scale != 1.0}
    assert scaled == {**{(node, name): scale for node in ("filter", "catalog_filter")
                         for name, scale in (("p0_sigma", 1e3), ("q", 1e6))},
                      ("conjunction", "distance"): 1e3,
                      ("conjunction", "hard_body_radius"): 1e3}
    assert all(CATALOG_FILTER[p.name].scale == p.scale for p in settings.FILTER_ROWS)
