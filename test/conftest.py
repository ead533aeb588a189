"""Shared fixtures. Graph tests get a `ros_graph` in a private ROS domain, loopback only."""

import os

from ssa_fusion import limit_blas_threads

# Before numpy is imported: tests compare in-process results with the nodes' (one BLAS
# thread each) to 1e-9, and a different thread count changes the round-off of the fits.
limit_blas_threads()

import pytest  # noqa: E402

os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
# Every graph a test starts picks a domain of its own; a ROS_DOMAIN_ID exported in the
# developer's shell (which `ssa-fusion live/replay` would honour) must not pull them together.
os.environ.pop("ROS_DOMAIN_ID", None)
# Test processes side by side on one loopback (`pytest -n N`, tools/run_tests.sh) each pick
# domains from their own part of 1..100, they and every run they start (the environment is
# inherited): no worker's graph lands in a domain another worker's graph is in.
_WORKER = os.environ.get("PYTEST_XDIST_WORKER")
_WORKERS = os.environ.get("PYTEST_XDIST_WORKER_COUNT")
if _WORKER and _WORKERS:
    _span = 100 // int(_WORKERS)
    _first = 1 + int(_WORKER.removeprefix("gw")) * _span
    os.environ["SSA_FUSION_DOMAINS"] = f"{_first}-{_first + _span - 1}"

# Imported here, before any test: sets the timeout factor (SSA_TEST_TIMEOUT_FACTOR) of every
# Graph the tests create, also those `ssa-fusion replay` creates inside a test.
from ros_graph import RosGraph  # noqa: E402


@pytest.fixture
def ros_graph(tmp_path):
    """A RosGraph (see test/ros_graph.py) torn down after the test, whatever happens."""
    graph = RosGraph(tmp_path)
    try:
        yield graph
    finally:
        problems = graph.close(together=True)  # assertions are done: stop them at once
    if problems:
        pytest.fail("node process(es) ended badly:\n" + "\n\n".join(problems))
