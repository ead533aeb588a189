"""config/default.yaml (launch file, --params-file) runs the same default scenario as
`ssa-fusion live`: every parameter `live` sets, the yaml sets to the same value."""

from pathlib import Path

import pytest
import yaml

from ssa_fusion.apps.live import node_parameters
from ssa_fusion.paper import scenarios

CONFIG = Path(__file__).resolve().parents[2] / "config" / "default.yaml"


def test_default_yaml_matches_the_live_default_scenario():
    config = yaml.safe_load(CONFIG.read_text())
    live = node_parameters(scenarios.DEFAULT_LIVE, time_scale=1000.0, seed=0, bag=Path("x"))
    for node in ("sensor_sim", "surrogate", "filter"):
        params = config[node]["ros__parameters"]
        for key, value in live[node].items():
            assert key in params, (node, key)
            assert params[key] == pytest.approx(value, rel=1e-12), (node, key)
