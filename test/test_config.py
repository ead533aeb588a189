"""config/default.yaml (launch file, --params-file) runs the same default scenario as
`ssa-fusion live` and the nodes' own defaults."""

from pathlib import Path

import yaml

from ssa_fusion.core import scenarios
from ssa_fusion.live import node_parameters

CONFIG = Path(__file__).resolve().parents[1] / "config" / "default.yaml"
SHARED = {
    "sensor_sim": ("scenario", "cadence", "gap_start", "gap_length", "after_gap", "time_scale"),
    "surrogate": ("buffer_length", "delays", "rank", "cadence"),
    "filter": ("kind", "station"),
}


def test_default_yaml_matches_the_live_default_scenario():
    config = yaml.safe_load(CONFIG.read_text())
    live = node_parameters(scenarios.DEFAULT_LIVE, time_scale=1000.0, seed=0, bag=Path("x"))
    for node, keys in SHARED.items():
        params = config[node]["ros__parameters"]
        for key in keys:
            assert params[key] == live[node][key], (node, key)
