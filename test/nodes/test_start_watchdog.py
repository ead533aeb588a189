"""A node whose DDS start hangs exits 1 with every thread's stack instead of hanging.

Fast DDS can deadlock while a participant is made as others leave (eProsima/Fast-DDS#6502):
the main thread blocks inside rcl holding the GIL, deaf to SIGINT and SIGTERM. Here the
hang is rclpy's `Node.__init__` made to block in C (`time.sleep`), as the deadlock does;
the node's own work at start (a slow ``__init__`` after its participant exists) is not
cut short. Each test is a process of its own, loopback only, its own domain."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
import time

import pytest

from ssa_fusion.nodes.kit.process import START_TIMEOUT_ENV
from ssa_fusion.ros.processes import fresh_domain_id

SCRIPT = textwrap.dedent("""
    import sys
    import time

    from rclpy.node import Node

    from ssa_fusion.nodes.kit.base import SsaNode
    from ssa_fusion.params.rows import ParameterTable

    where = sys.argv[1]
    rclpy_init = Node.__init__

    def hanging_init(self, *args, **kwargs):
        time.sleep(60)  # blocked in C, as rcl_service_init on Fast DDS's mutex

    if where == "dds":
        Node.__init__ = hanging_init

    class Slow(SsaNode):
        PARAMETERS = ParameterTable("slow_start", ())

        def __init__(self) -> None:
            super().__init__()
            if where == "own":
                time.sleep(3)  # the node's own work at start: not the watchdog's
                print("constructed", flush=True)
                raise SystemExit(0)

    raise SystemExit(Slow.main([]))
""")


def run_node(where: str, timeout_s: str) -> tuple[subprocess.CompletedProcess[str], float]:
    env = {**os.environ, "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST",
           "ROS_DOMAIN_ID": str(fresh_domain_id()), START_TIMEOUT_ENV: timeout_s}
    start = time.monotonic()
    r = subprocess.run([sys.executable, "-c", SCRIPT, where], capture_output=True, text=True,
                       timeout=120, env=env)
    return r, time.monotonic() - start


def test_a_start_hung_in_dds_exits_1_with_the_stacks_after_the_timeout():
    r, wall = run_node("dds", "2")
    assert r.returncode == 1, r
    assert "Timeout (0:00:02)!" in r.stderr, r.stderr
    assert "hanging_init" in r.stderr, r.stderr  # where it hung
    assert wall < 50, wall  # the sleep would last 60 s


def test_the_nodes_own_work_at_start_is_not_cut_short():
    r, _ = run_node("own", "1")
    assert r.returncode == 0, r
    assert "constructed" in r.stdout and "Timeout" not in r.stderr, r.stderr


@pytest.mark.parametrize("value", ["-1", "soon", "nan"])
def test_an_invalid_timeout_is_refused_with_exit_2_and_its_name(value):
    r, _ = run_node("own", value)
    assert r.returncode == 2, r
    ours = [line for line in r.stderr.splitlines() if line.startswith("error:")]
    assert len(ours) == 1 and START_TIMEOUT_ENV in ours[0] and value in ours[0], r.stderr
