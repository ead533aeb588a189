"""Launch the ssa_fusion graph (sensor_sim, surrogate, filter, recorder) on the default
scenario with sim time:  ros2 launch ssa_fusion ssa_fusion.launch.py [params:=FILE] [bag:=DIR]
"""

import os

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node

from ssa_fusion.ros.readiness import READERS


def generate_launch_description() -> LaunchDescription:
    default_params = os.path.join(
        get_package_share_directory("ssa_fusion"), "config", "default.yaml"
    )
    params = LaunchConfiguration("params")
    bag = LaunchConfiguration("bag")
    nodes = [
        Node(package="ssa_fusion", executable=name, name=name, output="screen",
             parameters=[params, *extra])
        for name, extra in [
            ("recorder", [{"bag": bag, "use_sim_time": True}]),
            ("surrogate", [{"use_sim_time": True}]),
            ("filter", [{"use_sim_time": True}]),
            # start once every node has matched its inputs (both sides of each DDS match)
            ("sensor_sim", [{"wait_for": ["/ssa/measurement=3", "/ssa/estimate=1"],
                             "wait_for_readers": READERS}]),
        ]
    ]
    return LaunchDescription([
        DeclareLaunchArgument("params", default_value=default_params,
                              description="parameter YAML"),
        DeclareLaunchArgument("bag", default_value="ssa_fusion_bag",
                              description="output bag directory"),
        *nodes,
    ])
