"""Graph test: a catalog_surrogate stopped (SIGTERM) in the middle of its fits ends within a
bounded time, exit 0, and its last /diagnostics report says what was done and what was cut.

The test process gives the node one pass of many objects (one EstimateBatch), then moves
/clock past the pass break: every object's gap is queued at once and, with ``fit_budget``
0 (lockstep's setting), all are fitted in that one step, seconds of work. Once the node is
seen busy (its CPU time grows), SIGTERM: the fits still queued are cut (``fits_cut``), the
node drains and says its last report; made and cut add up to the gaps queued.
"""

from __future__ import annotations

import signal
import time

import numpy as np
from rosgraph_msgs.msg import Clock
from ssa_fusion_msgs.msg import EstimateBatch
from test_faults import Diag, publisher

from ssa_fusion.apps.run_costs import cpu_s
from ssa_fusion.core.base import types
from ssa_fusion.core.base.rows import EstimateRows
from ssa_fusion.core.motion import dynamics
from ssa_fusion.ros import messages
from ssa_fusion.sim.scenarios import ISS_ELEMENTS

T0 = 1.7e9  # Unix s
OBJECTS = 3000
"""Objects whose gaps are queued at once: a few seconds of fits on any machine."""
STOP_WITHIN_S = 8.0
"""Wall s a stopped surrogate may take to exit: its drain (at most 3 s) and its last report."""


def _pass_batch() -> EstimateBatch:
    """Every object's pass: 3 estimates 60 s apart of a J2 orbit, the node turned per object."""
    x0 = np.array(dynamics.elements_to_state(**ISS_ELEMENTS))
    x = dynamics.propagate("j2", x0, np.array([0.0, 60.0, 120.0]))
    turn = np.linspace(0.0, 2.0 * np.pi, OBJECTS, endpoint=False)
    c, s = np.cos(turn)[:, None, None], np.sin(turn)[:, None, None]
    rot = np.concatenate([np.concatenate([c, -s, 0 * c], 2), np.concatenate([s, c, 0 * c], 2),
                          np.tile(np.array([[[0.0, 0.0, 1.0]]]), (OBJECTS, 1, 1))], 1)
    xs = np.concatenate([np.einsum("kij,tj->kti", rot, x[:, :3]),
                         np.einsum("kij,tj->kti", rot, x[:, 3:])], 2).reshape(-1, 6)
    ids = [f"{70000 + k}" for k in range(OBJECTS) for _ in range(3)]
    rows = EstimateRows(T0 + np.tile([0.0, 60.0, 120.0], OBJECTS), ids, xs,
                        np.tile(np.diag([1e-4] * 3 + [1e-10] * 3), (len(ids), 1, 1)),
                        np.zeros(len(ids)), types.UpdateSource.SENSOR, messages.shard_keys(ids))
    return messages.estimate_batch_to_msg(rows)


def test_a_stop_in_the_middle_of_the_fits_cuts_them_and_reports(ros_graph):
    g = ros_graph
    node = g.start_node("catalog_surrogate", params={
        "use_sim_time": True, "shards": 1, "shard": 0, "hold": 0.0, "fit_budget": 0.0,
        "pass_break": 600.0})
    diag = Diag(g)
    clock = publisher(g, Clock, "/clock", ("catalog_surrogate",))
    est = publisher(g, EstimateBatch, "/ssa/estimate_batch", ("catalog_surrogate",))
    clock.publish(Clock(clock=messages.seconds_to_stamp(T0)))
    est.publish(_pass_batch())
    diag.wait(g, "catalog_surrogate", {"received": 3 * OBJECTS}, 60.0)
    busy_from = cpu_s(node.popen.pid)
    clock.publish(Clock(clock=messages.seconds_to_stamp(T0 + 120.0 + 601.0)))
    g.wait_for(lambda: cpu_s(node.popen.pid) - busy_from > 0.5, 60.0,
               "the surrogate to be fitting")
    stopped = time.monotonic()
    code = g.stop(node, signal.SIGTERM, timeout=30.0)
    took = time.monotonic() - stopped
    last = diag.counts("catalog_surrogate")
    made, cut = int(last.get("fits_made", "0")), int(last.get("fits_cut", "0"))
    print(f"stopped in {took:.2f} s: fits made {made}, cut {cut}")
    assert code == 0
    assert took < g.scaled(STOP_WITHIN_S), took
    assert cut > 0 and made + cut == OBJECTS, last
