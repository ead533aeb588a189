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

from ssa_fusion.ros.processes import Graph as RosGraph
from ssa_fusion.ros.processes import Proc as NodeProcess


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

__all__ = ["TIMEOUT_FACTOR", "NodeProcess", "RosGraph"]
