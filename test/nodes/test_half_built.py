"""A node whose ``__init__`` refuses a parameter after it made publishers is destroyed by
`nodes.kit.process.run` (its publishers first, as `Node.destroy_node` does), not left to the
garbage collector while DDS still runs. Left so, the half-built node is kept alive by a
reference cycle until a collection frees it in no set order (a sensor_sim refusing its
scenario once died of a segmentation fault, exit -11, instead of exiting 2); here a
collection is made to happen just before rclpy shuts down."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap

SCRIPT = textwrap.dedent("""
    import gc

    import rclpy
    from std_msgs.msg import String

    from ssa_fusion.nodes.kit import process
    from ssa_fusion.nodes.kit.base import SsaNode
    from ssa_fusion.params.rows import ParameterError, ParameterTable

    def collecting_shutdown(*args, **kwargs):
        # garbage collected just before rclpy shuts down, as Python may do at any time
        gc.collect()
        return shutdown(*args, **kwargs)

    shutdown, rclpy.try_shutdown = rclpy.try_shutdown, collecting_shutdown

    class Refusing(SsaNode):
        PARAMETERS = ParameterTable("refusing", ())

        def __init__(self) -> None:
            super().__init__()
            self.pub = self.create_publisher(String, "/refusing/out", 10)
            raise ParameterError("parameter 'x' = 1: refused after a publisher was made")

        def destroy_node(self) -> None:
            print("destroy_node with", len(list(self.publishers)), "publishers", flush=True)
            super().destroy_node()
            print("destroyed with", len(list(self.publishers)), "publishers", flush=True)

    print("code", process.run(Refusing, []))
""")


def test_a_node_refused_while_starting_is_destroyed_publishers_first():
    env = {**os.environ, "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST", "ROS_DOMAIN_ID": "98"}
    r = subprocess.run([sys.executable, "-c", SCRIPT], capture_output=True, text=True,
                       timeout=120, env=env)
    assert r.returncode == 0, r.stderr
    assert "error: parameter 'x' = 1: refused after a publisher was made" in r.stderr
    # the node is destroyed by `run`, its publishers (its own and rclpy's) first, then exit 2
    lines = r.stdout.splitlines()
    assert lines[0].startswith("destroy_node with") and lines[0] != "destroy_node with 0 publishers"
    assert lines[1:] == ["destroyed with 0 publishers", "code 2"], r.stdout
