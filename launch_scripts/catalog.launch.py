"""Launch a catalog graph: sensor_sim measuring a catalog, K filter and K surrogate shards.

    ros2 launch ssa_fusion catalog.launch.py [catalog:=FILE] [objects:=N] [synthetic:=N]
        [duration:=HOURS] [shards:=K] [surrogate:=true|false] [scenario:=NAME]
        [time_scale:=X] [lockstep:=true|false] [seed:=N] [bag:=DIR]
        [unlabelled:=true|false]

The same processes and parameters as ``ssa-fusion live --catalog`` (`apps.live_catalog.
catalog_graph`): the recorder, ``shards`` catalog_filter processes each owning the objects of
its key range (DDS content filter), as many catalog_surrogate processes forecasting their
gaps, and sensor_sim simulating the scenario's radars measuring every object (SGP4 truth).
Arguments (``--show-args``): `ARGUMENTS`. The graph shuts itself down like
ssa_fusion.launch.py: `DRAIN_S` s after sensor_sim exits, and at once if the recorder exits.
Without ``ssa-fusion live``'s accounting at the end: read the bag (``ssa-fusion export``,
rosbags) or /diagnostics.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch_ros.actions import Node

from ssa_fusion.graphs import DEFAULT_SCENARIO, catalog_graph, catalog_scenario, default_bag
from ssa_fusion.ros.launch_events import launch_description, shutdown_handlers

DRAIN_S = 2.0
"""Wall s between sensor_sim's exit and the shutdown of the rest."""
ARGUMENTS = {
    "catalog": "element sets (TLE, 3LE, OMM XML/CSV); default: the installed sample catalog",
    "objects": "only the catalog's first N objects (0 = all)",
    "synthetic": "spread the catalog's first element set into N objects (0 = the catalog's)",
    "duration": "hours of sim time (0 = the scenario's)",
    "start": "first epoch, ISO 8601 UTC ('' = the catalog's first element set's)",
    "shards": "filter (and surrogate) processes, each owning the objects of its key range",
    "surrogate": "true: a catalog_surrogate per shard (gap forecasts); false: none",
    "scenario": "real-sky scenario whose radars observe the catalog",
    "sites": "sites file (docs/SITES.md) whose radars observe the catalog instead ('' = none)",
    "time_scale": "sim seconds per wall second (in lockstep: at most)",
    "lockstep": "true: sim time waits for the shards and the recorder at each step (nothing "
                "lost on a loaded machine); false: open loop at time_scale",
    "seed": "measurement noise (and synthetic catalog) seed",
    "bag": "recorder output directory, must not exist (default: out/bags/ssa_<date>_<time>)",
    "unlabelled": "true: the radars report detections without object ids and the filter "
                  "associates them into tracks (needs shards:=1); false: labelled",
}
"""The launch arguments and their descriptions."""


def _number(args: dict[str, str], name: str, kind: type, low: float) -> Any:
    try:
        value = kind(args[name])
    except ValueError:
        what = "an integer" if kind is int else "a number"
        raise ValueError(f"{name}:={args[name]!r} is not {what}") from None
    if not value >= low:
        raise ValueError(f"{name}:={args[name]!r} must be >= {low}")
    return value


def graph(context: Any) -> list[Any]:
    """The catalog graph's nodes and the two shutdown handlers, for the arguments given."""
    args = context.launch_configurations
    scenario = catalog_scenario(args["scenario"])
    if args["sites"]:
        scenario = scenario.with_sites(args["sites"])  # SiteFileError: one line
    for flag in ("surrogate", "lockstep", "unlabelled"):
        if args[flag] not in ("true", "false"):
            raise ValueError(f"{flag}:={args[flag]!r}: true or false")
    hours = _number(args, "duration", float, 0.0)
    specs = catalog_graph(
        scenario, Path(args["catalog"]), _number(args, "objects", int, 0),
        _number(args, "synthetic", int, 0), hours * 3600.0 or scenario.duration_s,
        _number(args, "time_scale", float, 1e-9), _number(args, "seed", int, 0),
        _number(args, "shards", int, 1), args["surrogate"] == "true", {}, Path(args["bag"]),
        args["start"], args["lockstep"] == "true", args["unlabelled"] == "true")
    nodes = {s.name: Node(package="ssa_fusion", executable=s.executable, name=s.name,
                          output="screen", parameters=[s.params]) for s in specs}
    return [*nodes.values(),
            *shutdown_handlers(nodes["sensor_sim"], nodes["recorder"], DRAIN_S)]


def generate_launch_description() -> LaunchDescription:
    """The launch arguments, then the graph built from their values (`graph`)."""
    share = get_package_share_directory("ssa_fusion")
    defaults = {
        "catalog": os.path.join(share, "config", "catalogs", "sample.tle"),
        "objects": "0",
        "synthetic": "0",
        "duration": "0",
        "start": "",
        "shards": "1",
        "surrogate": "true",
        "scenario": DEFAULT_SCENARIO,
        "sites": "",
        "time_scale": "100",
        "lockstep": "true",
        "seed": "0",
        "bag": default_bag(),
        "unlabelled": "false",
    }
    return launch_description(ARGUMENTS, defaults, graph)
