"""Graph tests use ssa_fusion.ros.processes.Graph (real processes, private domain, loopback).

Timeouts: one factor for every test that starts processes
---------------------------------------------------------
Each wait in those tests (a node matching a topic, a message arriving, a process exiting,
`ssa-fusion replay`'s own waits when a test runs it) is a condition wait: it polls until its
condition holds and fails only after a timeout. Every such timeout is the nominal number
written in the test times ``TIMEOUT_FACTOR``, read here, once, from the environment variable
``SSA_TEST_TIMEOUT_FACTOR`` (default 3: the 20 s a node gets to match becomes 60 s, enough
for a 2-core machine busy with other work). The factor reaches every wait through
`Graph.timeout_factor`, set below for every Graph the test process creates (conftest.py imports
this module first); a test's own deadline loop uses ``graph.scaled(seconds)``. Since waits end
as soon as their condition holds, a larger factor never slows a passing test; raise it
(``SSA_TEST_TIMEOUT_FACTOR=10``) on a slower or busier machine, never the numbers in tests.
"""

import math
import os
import signal
import subprocess
import sys
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import Any

from rclpy.qos import QoSProfile
from rclpy.subscription import Subscription

from ssa_fusion.ros.interfaces import DiagnosticArray, DiagnosticStatus, KeyValue
from ssa_fusion.ros.processes import Graph as RosGraph
from ssa_fusion.ros.processes import Proc as NodeProcess
from ssa_fusion.ros.readiness import MATCHED_KEY
from ssa_fusion.ros.topics import TOPIC_DIAGNOSTICS


def _timeout_factor() -> float:
    raw = os.environ.get("SSA_TEST_TIMEOUT_FACTOR", "").strip() or "3"
    try:
        value = float(raw)
    except ValueError:
        value = math.nan
    if not (math.isfinite(value) and value > 0):
        raise ValueError(f"SSA_TEST_TIMEOUT_FACTOR must be a finite number > 0, got {raw!r}")
    return value


TIMEOUT_FACTOR = _timeout_factor()
"""Multiplies every timeout of the tests that start processes (see the module docstring)."""

RosGraph.timeout_factor = TIMEOUT_FACTOR

OBJECT_NODES = ("recorder", "surrogate", "filter")
"""The nodes of the one-object graph that sensor_sim feeds."""


def run_object_graph(g: RosGraph, params: dict[str, dict[str, Any]], sensor_timeout: float,
                     settled: Callable[[], object],
                     before_sensor: Callable[[], object] | None = None) -> dict[str, Any]:
    """Run the one-object graph once on `g` and stop it; what the tests of a run check.

    Starts `OBJECT_NODES`, then (after `before_sensor()`) sensor_sim, with their `params`
    by node (`graphs.node_parameters`); waits for sensor_sim to exit (`sensor_timeout` s)
    and for `settled()` to stop changing (1 s, at most 20 s), then SIGTERMs the three at
    once (their shutdowns overlap). Returns ``sensor_code``, ``codes`` (by node), ``report``.
    """
    nodes = {n: g.start_node(n, params=params[n]) for n in OBJECT_NODES}
    if before_sensor is not None:
        before_sensor()
    sensor = g.start_node("sensor_sim", params=params["sensor_sim"])
    sensor_code = g.wait_exit(sensor, timeout=sensor_timeout)
    g.wait_quiet(settled, quiet_s=1.0, limit_s=20)
    for p in nodes.values():
        p.popen.send_signal(signal.SIGTERM)
    codes = {n: g.wait_exit(p, timeout=10.0) for n, p in nodes.items()}
    return {"sensor_code": sensor_code, "codes": codes, "report": g.report()}


def report_probe_matches(g: RosGraph, subs: list[Subscription[Any]],
                         name: str = "test_probe") -> list[str]:
    """Have `g`'s probe report its subscriptions' matches on /diagnostics, as a node does.

    Every 0.2 s while the probe spins (each wait of `g` spins it): ``MATCHED_KEY + topic``
    = the publishers each of `subs` has matched. Returns the 'name:/topic' entries that make
    sensor_sim (``wait_for_readers``) wait for the probe's side of its matches as well, so
    that the probe hears the run from its first message.
    """
    pub = g.probe.create_publisher(DiagnosticArray, TOPIC_DIAGNOSTICS, QoSProfile(depth=10))

    def report() -> None:
        st = DiagnosticStatus(name=name, values=[
            KeyValue(key=MATCHED_KEY + sub.topic_name, value=str(sub.get_publisher_count()))
            for sub in subs])
        pub.publish(DiagnosticArray(status=[st]))

    g.probe.create_timer(0.2, report)
    return [f"{name}:{sub.topic_name}" for sub in subs]


@contextmanager
def cpu_burners(n: int) -> Iterator[None]:
    """Run `n` busy-loop processes (a loaded machine) for the duration of the block."""
    procs = [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(n)]
    try:
        yield
    finally:
        for p in procs:
            p.kill()
            p.wait()


__all__ = [
    "OBJECT_NODES",
    "TIMEOUT_FACTOR",
    "NodeProcess",
    "RosGraph",
    "cpu_burners",
    "report_probe_matches",
    "run_object_graph",
]
