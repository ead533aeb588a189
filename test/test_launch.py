"""The launch file (launch_scripts/ssa_fusion.launch.py), without the launch library.

`launch` and `launch_ros` are not installable here (no PyPI wheels), so the launch file is
imported with stand-ins for them put into sys.modules: each stand-in class only records the
arguments it was constructed with. The tests check the declared arguments, then call the
file's OpaqueFunction as `ros2 launch` would, with the arguments' values, and check the four
nodes (executables, parameters) and the two OnProcessExit -> Shutdown handlers (sensor_sim
done, recorder gone). `ament_index_python` is the real one, over the venv prefix.

Checked by hand with the real thing: upstream launch, launch_ros and ros2cli (their 2024
rolling sources) built with colcon over the venv; `ros2 launch ssa_fusion
ssa_fusion.launch.py time_scale:=3000` ran the default scenario and ended by itself 2 s after
sensor_sim (every node exit 0, bag closed), a second launch with the first one's bag ended
at once (recorder exit 2), `scenario:=iss_j2_pos` ran the position scenario, and SIGINT
mid-run stopped every node cleanly.
"""

from __future__ import annotations

import importlib.util
import re
import sys
import time
import types
from pathlib import Path
from typing import Any

import pytest

from ssa_fusion.graphs import WAIT_FOR, node_parameters
from ssa_fusion.params.defaults import BAG_PATTERN
from ssa_fusion.ros.readiness import LOCKSTEP_READERS, READERS
from ssa_fusion.sim import scenarios

ROOT = Path(__file__).resolve().parents[1]
LAUNCH_FILE = ROOT / "launch_scripts" / "ssa_fusion.launch.py"
NODES = ("recorder", "surrogate", "filter", "sensor_sim")
ARGUMENTS = ("params_file", "scenario", "time_scale", "start", "duration", "sites", "elements",
             "bag")


class Recorded:
    """A stand-in launch entity: keeps what it was constructed with."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        self.args = args
        self.kwargs = kwargs

    def __repr__(self) -> str:
        return f"{type(self).__name__}({self.args}, {self.kwargs})"


STAND_INS = {
    "launch": ("LaunchDescription",),
    "launch.actions": ("DeclareLaunchArgument", "LogInfo", "OpaqueFunction",
                       "RegisterEventHandler", "Shutdown", "TimerAction"),
    "launch.event_handlers": ("OnProcessExit",),
    "launch_ros": (),
    "launch_ros.actions": ("Node",),
}
"""Stand-in modules and the classes the launch file may take from them."""


@pytest.fixture
def launch(monkeypatch) -> types.ModuleType:
    """The launch file imported over the stand-ins (and AMENT_PREFIX_PATH = the venv)."""
    return load_launch_file(monkeypatch, LAUNCH_FILE)


def load_launch_file(monkeypatch, path: Path) -> types.ModuleType:
    """Import the launch file `path` over the stand-ins (AMENT_PREFIX_PATH = the venv)."""
    modules = {}
    for name, classes in STAND_INS.items():
        module = types.ModuleType(name)
        for cls in classes:
            setattr(module, cls, type(cls, (Recorded,), {}))
        modules[name] = module
        monkeypatch.setitem(sys.modules, name, module)
    for name, module in modules.items():
        if "." in name:
            parent, _, child = name.rpartition(".")
            setattr(modules[parent], child, module)
    monkeypatch.setenv("AMENT_PREFIX_PATH", sys.prefix)
    spec = importlib.util.spec_from_file_location(path.name.replace(".", "_"), path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def kind(entity: Any) -> str:
    return type(entity).__name__


def declared(description: Any) -> dict[str, Recorded]:
    (entities,) = description.args
    return {a.args[0]: a for a in entities if kind(a) == "DeclareLaunchArgument"}


def run_graph(launch: types.ModuleType, **given: str) -> tuple[dict, list]:
    """Evaluate the launch description as `ros2 launch ... name:=value` would: (nodes by
    name, event handlers) of the OpaqueFunction, called with the arguments' values."""
    description = launch.generate_launch_description()
    values = {name: a.kwargs["default_value"] for name, a in declared(description).items()}
    values.update(given)
    (entities,) = description.args
    (opaque,) = [e for e in entities if kind(e) == "OpaqueFunction"]
    context = types.SimpleNamespace(launch_configurations=values)
    actions = opaque.kwargs["function"](context)
    nodes = {a.kwargs["name"]: a for a in actions if kind(a) == "Node"}
    handlers = [a.args[0] for a in actions if kind(a) == "RegisterEventHandler"]
    assert len(actions) == len(nodes) + len(handlers), actions
    return nodes, handlers


def shutdowns(actions: list) -> list[Recorded]:
    """The Shutdown actions in `actions`, also those a TimerAction runs."""
    out = []
    for a in actions:
        if kind(a) == "Shutdown":
            out.append(a)
        elif kind(a) == "TimerAction":
            out += shutdowns(a.kwargs["actions"])
    return out


def test_declares_its_arguments_with_descriptions_and_defaults(launch):
    args = declared(launch.generate_launch_description())
    assert tuple(args) == ARGUMENTS
    for a in args.values():
        assert a.kwargs["description"], a
    default_yaml = Path(sys.prefix) / "share" / "ssa_fusion" / "config" / "default.yaml"
    assert args["params_file"].kwargs["default_value"] == str(default_yaml)
    assert default_yaml.is_file()
    assert args["scenario"].kwargs["default_value"] == ""
    assert args["time_scale"].kwargs["default_value"] == ""


def test_the_default_bag_is_named_by_the_launch_time(launch):
    """Like `ros2 bag record`'s default: a second launch does not meet the first one's bag."""
    before = time.strftime(BAG_PATTERN)
    bag = declared(launch.generate_launch_description())["bag"].kwargs["default_value"]
    assert before <= bag <= time.strftime(BAG_PATTERN)
    assert re.fullmatch(r"out/bags/ssa_\d{8}_\d{6}", bag), bag
    nodes, _ = run_graph(launch)
    assert nodes["recorder"].kwargs["parameters"][1]["bag"] == bag


def test_starts_the_four_nodes_over_the_params_file(launch):
    nodes, _ = run_graph(launch, params_file="/my/params.yaml", bag="/tmp/run1")
    assert tuple(nodes) == NODES  # sensor_sim last: it waits for the others anyway
    for name, node in nodes.items():
        assert node.kwargs["package"] == "ssa_fusion"
        assert node.kwargs["executable"] == name
        params_file, extra = node.kwargs["parameters"]
        assert params_file == "/my/params.yaml"  # read first, the launch's values over it
        assert extra.get("use_sim_time") is (True if name != "sensor_sim" else None)
        exe = Path(sys.prefix) / "lib" / "ssa_fusion" / name  # what ros2 launch runs
        assert exe.is_file(), exe
    sensor = nodes["sensor_sim"].kwargs["parameters"][1]
    assert sensor == {"wait_for": WAIT_FOR, "wait_for_readers": READERS + LOCKSTEP_READERS}
    assert nodes["recorder"].kwargs["parameters"][1] == {"bag": "/tmp/run1", "use_sim_time": True}


def test_sensor_sim_done_or_recorder_gone_shut_the_graph_down(launch):
    nodes, handlers = run_graph(launch)
    assert [kind(h) for h in handlers] == ["OnProcessExit", "OnProcessExit"]
    by_target = {next(n for n, a in nodes.items() if a is h.kwargs["target_action"]): h
                 for h in handlers}
    assert set(by_target) == {"sensor_sim", "recorder"}
    for handler in by_target.values():
        assert len(shutdowns(handler.kwargs["on_exit"])) == 1, handler
    # sensor_sim done: the others get DRAIN_S to take what is in flight, then shut down
    (timer,) = [a for a in by_target["sensor_sim"].kwargs["on_exit"] if kind(a) == "TimerAction"]
    assert timer.kwargs["period"] == launch.DRAIN_S > 0
    # recorder gone (died, or its bag exists): at once, nothing would be recorded
    assert [kind(a) for a in by_target["recorder"].kwargs["on_exit"]] == ["Shutdown"]


def test_scenario_and_time_scale_set_every_node(launch):
    """scenario:= gives every node the scenario's settings, as `ssa-fusion live`;
    time_scale:= the sensor's pace (a float, as sensor_sim declares it)."""
    nodes, _ = run_graph(launch, scenario="iss_j2_pos", time_scale="500", bag="/tmp/b")
    want = node_parameters(scenarios.get("iss_j2_pos"), time_scale=500.0, seed=0,
                           bag=Path("/tmp/b"))
    for name, node in nodes.items():
        extra = node.kwargs["parameters"][1]
        expected = {k: v for k, v in want[name].items() if k != "seed"}
        assert extra == expected, name
    assert nodes["filter"].kwargs["parameters"][1]["kind"] == "position"
    assert type(nodes["sensor_sim"].kwargs["parameters"][1]["time_scale"]) is float


def test_start_and_duration_set_the_scenarios_window(launch):
    """start:= and duration:= as `ssa-fusion live --start/--duration`: the real-sky
    simulator's first epoch and length; a paper scenario tracks after its gap for the rest."""
    nodes, _ = run_graph(launch, scenario="iss_radar_columbus", start="2025-06-01T06:00:00Z",
                         duration="6")
    sensor = nodes["sensor_sim"].kwargs["parameters"][1]
    assert sensor["start"] == "2025-06-01T06:00:00.000Z" and sensor["duration"] == 21600.0
    sites = str(ROOT / "config" / "sites" / "example.yaml")
    nodes, _ = run_graph(launch, scenario="iss_radar_columbus", sites=sites)
    for name in ("sensor_sim", "filter", "surrogate"):
        assert nodes[name].kwargs["parameters"][1]["sites"] == sites
    assert nodes["filter"].kwargs["parameters"][1]["station"] == "nordlys,kestrel,pampa-obs,"
    tle = str(ROOT / "config" / "catalogs" / "sample.tle")
    nodes, _ = run_graph(launch, scenario="iss_network", elements=tle, duration="6")
    sensor = nodes["sensor_sim"].kwargs["parameters"][1]
    assert sensor["elements"] == tle and sensor["duration"] == 21600.0
    assert sensor["start"].startswith("2006-06-26T")  # the first element set's epoch
    nodes, _ = run_graph(launch, scenario="iss_j2_rae", duration="20")
    paper = scenarios.get("iss_j2_rae")
    sensor = nodes["sensor_sim"].kwargs["parameters"][1]
    assert sensor["gap_start"] + sensor["gap_length"] + sensor["after_gap"] == 72000.0
    assert (sensor["gap_start"], sensor["gap_length"]) == (paper.track_s, paper.gap_s)


def test_without_scenario_or_time_scale_the_params_file_decides(launch):
    nodes, _ = run_graph(launch)
    for node in nodes.values():
        extra = node.kwargs["parameters"][1]
        assert not {"scenario", "time_scale", "kind", "delays"} & set(extra)


@pytest.mark.parametrize(("given", "message"), [
    ({"scenario": "mars_base"}, "scenario 'mars_base' unknown; known: "),
    ({"time_scale": "fast"}, "time_scale:='fast' is not a number"),
    ({"start": "2025-06-01"}, "start:=, duration:=, sites:= and elements:= need scenario:="),
    ({"scenario": "iss_j2_rae", "sites": str(ROOT / "config" / "sites" / "example.yaml")},
     "iss_j2_rae keeps the paper's station"),
    ({"scenario": "iss_j2_rae", "start": "2025-06-01"}, "iss_j2_rae keeps the paper's epoch"),
    ({"scenario": "iss_network", "start": "June"}, "'June' is not an ISO 8601 epoch"),
    ({"scenario": "iss_network", "duration": "six"}, "duration:='six' is not a number"),
])
def test_bad_arguments_are_named(launch, given, message):
    with pytest.raises(ValueError, match=re.escape(message)):
        run_graph(launch, **given)
