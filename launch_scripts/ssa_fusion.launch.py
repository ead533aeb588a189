"""Launch the ssa_fusion graph (sensor_sim, surrogate, filter, recorder) with sim time.

    ros2 launch ssa_fusion ssa_fusion.launch.py [scenario:=NAME] [time_scale:=X]
                                                [start:=UTC] [duration:=HOURS]
                                                [sites:=FILE] [elements:=FILE]
                                                [bag:=DIR] [params_file:=FILE]

Arguments (``ros2 launch ssa_fusion ssa_fusion.launch.py --show-args``):

* ``params_file``: ROS params YAML every node reads first (default: the installed
  ``config/default.yaml``, the default scenario);
* ``scenario``: a scenario name (as ``ssa-fusion live --scenario``); every node then gets
  that scenario's settings, over the params file's ('' = the params file's scenario);
* ``time_scale``: sim seconds per wall second, over both ('' = theirs: 1000 in default.yaml);
* ``start``, ``duration``: the scenario's first epoch (ISO 8601 UTC) and hours of sim time,
  as ``ssa-fusion live --start/--duration`` (need ``scenario``; '' = the scenario's);
* ``sites``: a sites file whose sites observe a real-sky scenario's object, as ``ssa-fusion
  live --sites`` (needs ``scenario``; '' = the scenario's sensors);
* ``elements``: an element set file whose first object a real-sky scenario observes, as
  ``ssa-fusion live --elements`` (needs ``scenario``; '' = the scenario's object);
* ``bag``: the recorder's output directory, which must not exist (default, like ``ros2 bag
  record``'s: ``out/bags/ssa_<date>_<time>`` at launch, `graphs.default_bag`).

The graph shuts itself down: when sensor_sim exits (its schedule is done), after
`DRAIN_S` s in which filter, surrogate and recorder take what is still in flight; and at once
when the recorder exits (it died, or refused its parameters: a bag that exists already), as
nothing would be recorded and sensor_sim would wait for it forever.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch_ros.actions import Node

from ssa_fusion.graphs import (
    LOCKSTEP_READERS,
    READERS,
    WAIT_FOR,
    default_bag,
    live_scenario,
    node_parameters,
)
from ssa_fusion.ros.launch_events import launch_description, shutdown_handlers

NODES = ("recorder", "surrogate", "filter", "sensor_sim")
"""Started in this order; sensor_sim waits until the others have matched its topics."""
DRAIN_S = 2.0
"""Wall s between sensor_sim's exit and the shutdown of the rest. sensor_sim exits once every
reader acknowledged its last message; the filter and the surrogate then publish their last
estimates and forecasts, and the recorder writes them."""
ARGUMENTS = {
    "params_file": "ROS params YAML every node reads (default: the installed default.yaml)",
    "scenario": "scenario name (as `ssa-fusion live --scenario`): every node gets its "
                "settings, over the params file ('' = the params file's)",
    "time_scale": "sim seconds per wall second, over params file and scenario ('' = theirs)",
    "start": "first epoch of a real-sky scenario, ISO 8601 UTC (needs scenario; '' = its own)",
    "duration": "hours of sim time (needs scenario; '' = the scenario's)",
    "sites": "sites file (docs/SITES.md) observing a real-sky scenario (needs scenario)",
    "elements": "element set file (TLE/3LE/OMM) of the object observed (needs scenario)",
    "bag": "recorder output directory, must not exist (default: out/bags/ssa_<date>_<time>)",
}
"""The launch arguments and their descriptions."""


def scenario_parameters(name: str, bag: str, start: str = "", duration: str = "",
                        sites: str = "", elements: str = "") -> dict[str, dict[str, Any]]:
    """Per-node parameters that run scenario `name`, as `ssa-fusion live --scenario` sets
    them (its time scale and seed left to the params file); `start` (ISO 8601 UTC),
    `duration` (hours), `sites` and `elements` (files) as its ``--start``, ``--duration``,
    ``--sites`` and ``--elements`` ('' = the scenario's)."""
    try:
        hours = float(duration or 0.0)
    except ValueError:
        raise ValueError(f"duration:={duration!r} is not a number") from None
    s = live_scenario(name, start, hours, sites, elements)
    params = node_parameters(s, time_scale=1.0, seed=0, bag=Path(bag))
    for key in ("time_scale", "seed"):
        params["sensor_sim"].pop(key)
    return params


def graph(context: Any) -> list[Any]:
    """The four nodes and the two shutdown handlers, for the arguments given."""
    args = context.launch_configurations
    bag = args["bag"]
    extra: dict[str, dict[str, Any]] = {name: {} for name in NODES}
    if args["scenario"]:
        extra = scenario_parameters(args["scenario"], bag, args["start"], args["duration"],
                                    args["sites"], args["elements"])
    elif any(args[k] for k in ("start", "duration", "sites", "elements")):
        raise ValueError("start:=, duration:=, sites:= and elements:= need scenario:= (the "
                         "scenario they change)")
    extra["recorder"].update(bag=bag)
    for name in ("recorder", "surrogate", "filter"):
        extra[name].update(use_sim_time=True)
    # start once every node has matched its inputs (both sides of each DDS match), the
    # lockstep topics too (the params file runs the graph in lockstep, as `live` does)
    extra["sensor_sim"].update(wait_for=WAIT_FOR, wait_for_readers=READERS + LOCKSTEP_READERS)
    if args["time_scale"]:
        try:
            extra["sensor_sim"].update(time_scale=float(args["time_scale"]))
        except ValueError:
            raise ValueError(f"time_scale:={args['time_scale']!r} is not a number") from None
    nodes = {name: Node(package="ssa_fusion", executable=name, name=name, output="screen",
                        parameters=[args["params_file"], extra[name]])
             for name in NODES}
    return [*nodes.values(),
            *shutdown_handlers(nodes["sensor_sim"], nodes["recorder"], DRAIN_S)]


def generate_launch_description() -> LaunchDescription:
    """The launch arguments, then the graph built from their values (`graph`)."""
    defaults = {
        "params_file": os.path.join(get_package_share_directory("ssa_fusion"), "config",
                                    "default.yaml"),
        "scenario": "",
        "time_scale": "",
        "start": "",
        "duration": "",
        "sites": "",
        "elements": "",
        "bag": default_bag(),
    }
    return launch_description(ARGUMENTS, defaults, graph)
