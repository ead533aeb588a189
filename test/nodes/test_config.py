"""The nodes' defaults in three places that must agree:

* `ssa_fusion.params.defaults` (what the nodes declare: checked by constructing each node),
* config/default.yaml (launch file, --params-file): every parameter, at its default, except
  the few the default *run* sets otherwise (`RUN_SETTINGS`, each with its reason),
* `ssa-fusion live` on the default scenario: every parameter it sets, the yaml sets to the
  same value (so the estimator defaults are the default scenario's).
"""

import dataclasses
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

from ssa_fusion.core.filter.options import DEFAULT_GATE
from ssa_fusion.core.gaps.surrogate import LIVE_SURROGATE
from ssa_fusion.core.measure.validation import MAX_CLOCK_LEAD_S
from ssa_fusion.graphs import node_parameters
from ssa_fusion.params import defaults
from ssa_fusion.ros.processes import fresh_domain_id
from ssa_fusion.sim import scenarios

CONFIG = Path(__file__).resolve().parents[2] / "config" / "default.yaml"
WORKER = Path(__file__).with_name("declared_parameters.py")

RUN_SETTINGS = {
    # the demo's pace, start only once every reader has matched (nothing is lost), and
    # lockstep (the default of `ssa-fusion live`)
    "sensor_sim": {"time_scale", "wait_for", "wait_for_readers", "lockstep"},
    # the default scenario's cadence, and its gap (+ one cadence) as the forecast horizon,
    # as `ssa-fusion live` and the offline replay set them; lockstep
    "surrogate": {"cadence", "max_horizon", "lockstep"},
    "filter": {"lockstep"},
}
"""Parameters the yaml sets to other values than the nodes' defaults, on purpose."""

NOT_IN_YAML = {"recorder": {"bag"}}
"""Defaults the yaml cannot hold: a bag directory must be new for every run."""

SCENARIO_FIELDS = {"object_id": "name", "cadence": "cadence_s", "gap_start": "track_s",
                   "gap_length": "gap_s", "after_gap": "after_s"}
"""sensor_sim defaults that are the scenario's (None in `defaults`): the Scenario field."""


def _yaml() -> dict:
    return yaml.safe_load(CONFIG.read_text())


def _expected(node: str) -> dict:
    """The node's defaults from `defaults`, with computed ones (None) filled in for the
    default scenario; the recorder's bag is left out (it depends on the time)."""
    values = dataclasses.asdict(defaults.NODES[node])
    scenario = scenarios.get(defaults.SENSOR_SIM.scenario)
    for key, value in list(values.items()):
        if isinstance(value, tuple):
            values[key] = list(value)
        if value is None and node == "sensor_sim":
            values[key] = getattr(scenario, SCENARIO_FIELDS[key])
    if node == "recorder":
        del values["bag"]
    return values


def test_default_yaml_matches_the_live_default_scenario():
    config = _yaml()
    live = node_parameters(scenarios.DEFAULT_LIVE, time_scale=1000.0, seed=0, bag=Path("x"))
    for node in ("sensor_sim", "surrogate", "filter"):
        params = config[node]["ros__parameters"]
        for key, value in live[node].items():
            assert key in params, (node, key)
            assert params[key] == pytest.approx(value, rel=1e-12), (node, key)


def test_defaults_that_are_core_defaults_equal_them():
    assert defaults.SURROGATE.grace == LIVE_SURROGATE.grace
    assert defaults.FILTER.gate == DEFAULT_GATE
    assert defaults.SURROGATE.max_clock_lead == defaults.FILTER.max_clock_lead == MAX_CLOCK_LEAD_S


def test_sensor_sim_defaults_are_the_default_scenario():
    assert defaults.SENSOR_SIM.scenario == scenarios.DEFAULT_LIVE.name
    assert set(SCENARIO_FIELDS) == {f.name for f in dataclasses.fields(defaults.SENSOR_SIM)
                                     if getattr(defaults.SENSOR_SIM, f.name) is None}


@pytest.mark.parametrize("node", list(defaults.NODES))
def test_default_yaml_holds_every_default(node):
    params = dict(_yaml()[node]["ros__parameters"])
    assert params.pop("use_sim_time", True) is True
    expected = _expected(node)
    missing = set(expected) - set(params) - NOT_IN_YAML.get(node, set())
    unknown = set(params) - set(expected) - NOT_IN_YAML.get(node, set())
    assert not missing, f"{node}: default(s) missing from config/default.yaml: {missing}"
    assert not unknown, f"{node}: config/default.yaml sets unknown parameter(s) {unknown}"
    run = RUN_SETTINGS.get(node, set())
    assert run <= set(params)
    for key in set(params) - run:
        assert params[key] == pytest.approx(expected[key], rel=1e-12), (node, key)
        assert type(params[key]) is type(expected[key]), (node, key)  # ROS types are strict


def _declared(cwd: Path, *ros_args: str) -> dict:
    """{node: {parameter: value}} the nodes declare, constructed in a process of their own
    (private domain, loopback) with `ros_args`."""
    env = {k: v for k, v in os.environ.items() if k != "ROS_DOMAIN_ID"}
    env.update(ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST", ROS_DOMAIN_ID=str(fresh_domain_id()))
    done = subprocess.run([sys.executable, str(WORKER), *ros_args], cwd=cwd, env=env,
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    declared = json.loads(done.stdout)
    assert set(declared) == set(defaults.NODES)
    return declared


def test_nodes_declare_exactly_the_defaults(tmp_path):
    """Each node, constructed with no parameters given, declares exactly the parameters of
    its `defaults` dataclass, at those values."""
    declared = _declared(tmp_path)
    for node, values in declared.items():
        expected = _expected(node)
        if node == "recorder":
            assert values.pop("bag").startswith("out/bags/ssa_")
        assert set(values) == set(expected), node
        for key, value in values.items():
            assert value == expected[key], (node, key)
            assert type(value) is type(expected[key]), (node, key)


def test_nodes_take_every_value_of_the_default_yaml(tmp_path):
    """ROS reads config/default.yaml into the nodes as written (types included)."""
    declared = _declared(tmp_path, "--ros-args", "--params-file", str(CONFIG))
    config = _yaml()
    for node, values in declared.items():
        for key, value in config[node]["ros__parameters"].items():
            if key != "use_sim_time":
                assert values[key] == value, (node, key)


def test_filter_and_surrogate_take_a_station_of_a_sites_file(tmp_path):
    """`station` names a site of the `sites` file: the nodes start with it; without the
    file they refuse it, naming the parameter and the station."""
    example = str(CONFIG.parent / "sites" / "example.yaml")
    params = tmp_path / "params.yaml"
    for sites in (example, ""):
        params.write_text(yaml.safe_dump({node: {"ros__parameters": {
            "station": "nordlys", "sites": sites}} for node in ("filter", "surrogate")}))
        env = {k: v for k, v in os.environ.items() if k != "ROS_DOMAIN_ID"}
        env.update(ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST",
                   ROS_DOMAIN_ID=str(fresh_domain_id()))
        done = subprocess.run([sys.executable, str(WORKER), "--ros-args", "--params-file",
                               str(params)], cwd=tmp_path, env=env, capture_output=True,
                              text=True, timeout=120)
        if sites:
            assert done.returncode == 0, done.stderr
            declared = json.loads(done.stdout)
            for node in ("filter", "surrogate"):
                assert (declared[node]["station"], declared[node]["sites"]) == ("nordlys",
                                                                               example)
        else:
            assert done.returncode != 0
            assert "parameter 'station' = 'nordlys': station 'nordlys' unknown" in done.stderr
