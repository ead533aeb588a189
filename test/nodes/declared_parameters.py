"""Test process: construct each ssa_fusion node (never spun) with the ROS arguments given
on the command line, if any (e.g. --ros-args --params-file FILE), and print, as JSON, every
parameter it declared with its value: {node: {name: value}}.

Run with a private ROS_DOMAIN_ID, loopback discovery, and a scratch working directory (the
recorder creates its default bag directory under bags/)."""

import json
import sys

import rclpy

from ssa_fusion.nodes.filter import FilterNode
from ssa_fusion.nodes.recorder import Recorder
from ssa_fusion.nodes.sensor_sim import SensorSim
from ssa_fusion.nodes.surrogate import SurrogateNode

BUILT_IN = {"use_sim_time", "start_type_description_service"}
"""Parameters rclpy declares on every node."""


def _plain(value):
    """A parameter value as JSON can hold it (arrays may come as array.array)."""
    return value if isinstance(value, (str, int, float, bool, type(None))) else list(value)


def main() -> None:
    rclpy.init(args=sys.argv)
    declared = {}
    try:
        for name, cls in (("sensor_sim", SensorSim), ("surrogate", SurrogateNode),
                          ("filter", FilterNode), ("recorder", Recorder)):
            node = cls()
            declared[name] = {p: _plain(node.get_parameter(p).value) for p in node._parameters
                              if p not in BUILT_IN}
            close = getattr(node, "close", None)
            if close is not None:
                close()
            node.destroy_node()
    finally:
        rclpy.try_shutdown()
    print(json.dumps(declared))


if __name__ == "__main__":
    main()
