"""One object's graph in lockstep, as a run (its own namespace): the same seed gives the same
bag whatever happens beside it. Against a lone run on an idle machine, a run beside 3 CPU
burners whose recorder is stopped (SIGSTOP) for 6 s, and a run into which a stranger
publishes 20 /clock dated 2037 and a burst of measurements (stamped 1972, of an unknown
station), record the same /ssa/* messages at the same log times: nothing lost, no estimate
changed, the strangers counted by every node (`foreign_clock`, `foreign_run`) and kept out of
the bag. A consumer killed mid-run is named and no longer waited for."""

import os
import signal
import time
from pathlib import Path

import pytest
import rclpy
from diagnostic_msgs.msg import DiagnosticArray
from rclpy.duration import Duration
from rclpy.qos import QoSProfile
from ros_graph import RosGraph, cpu_burners
from rosgraph_msgs.msg import Clock
from ssa_fusion_msgs.msg import Measurement

from ssa_fusion.graphs import node_parameters
from ssa_fusion.ros import bagio
from ssa_fusion.ros.bag_runs import runs_in, same_messages
from ssa_fusion.ros.interfaces import Time
from ssa_fusion.ros.qos import DATA_QOS
from ssa_fusion.ros.run_identity import new_run_id
from ssa_fusion.sim import scenarios

SHORT = scenarios.DEFAULT_LIVE.with_(track_s=3000.0, gap_s=900.0, after_s=600.0, delays=40)
EPOCHS = round((SHORT.track_s + SHORT.gap_s + SHORT.after_s) / SHORT.cadence_s) + 1
NODES = ("recorder", "surrogate", "filter")
STRANGER_CLOCKS = 20
STRANGER_MEASUREMENTS = 300
TIME_SCALE = 450.0
"""The ceiling: a run of about 10 s, so that what happens a third through is mid-run."""


def run_graph(tmp: Path, name: str, during=None, before=None) -> dict:
    """Run SHORT in lockstep; `before(g)` before it starts, `during(g, nodes, clocks)` while.

    Returns the bag, sensor_sim's log and the last /diagnostics counters of each node.
    """
    g = RosGraph(tmp / name / "logs", run=new_run_id())
    params = node_parameters(SHORT, TIME_SCALE, seed=3, bag=tmp / name / "bag")
    try:
        clocks = g.collect(Clock, "/clock")
        diagnostics = g.collect(DiagnosticArray, "/diagnostics", QoSProfile(depth=1000))
        nodes = {n: g.start_node(n, params=params[n]) for n in NODES}
        if before is not None:
            before(g)
        nodes["sensor_sim"] = g.start_node("sensor_sim", params=params["sensor_sim"])
        if during is not None:
            during(g, nodes, clocks)
        code = g.wait_exit(nodes["sensor_sim"], timeout=120.0)
        for p in (nodes[n] for n in NODES if nodes[n].returncode is None):
            p.popen.send_signal(signal.SIGTERM)
        for n in NODES:
            g.wait_exit(nodes[n], timeout=10.0)
        log = nodes["sensor_sim"].stderr()
    finally:
        problems = g.close(together=True)
    last: dict[str, dict[str, str]] = {}
    for arr in diagnostics:
        for st in arr.status:
            last[st.name] = {kv.key: kv.value for kv in st.values}
    return {"bag": tmp / name / "bag", "code": code, "log": log, "diag": last,
            "problems": problems, "foreign_at_probe": dict(g.foreign)}


@pytest.fixture(scope="module")
def lone(tmp_path_factory):
    """The reference: a lone run, nothing beside it."""
    return run_graph(tmp_path_factory.mktemp("lockstep"), "lone")


def _third_through(g: RosGraph, clocks: list) -> None:
    g.wait_for(lambda: len(clocks) > EPOCHS // 3, 60.0, "a third of the run")


def test_a_lone_run_records_every_epoch(lone):
    assert lone["code"] == 0 and not lone["problems"], lone["log"]
    counts = {t: sum(1 for _ in bagio.read_bag(lone["bag"], [t]))
              for t in ("/clock", "/ssa/truth", "/ssa/measurement", "/ssa/withheld")}
    assert counts["/clock"] == counts["/ssa/truth"] == EPOCHS
    assert counts["/ssa/measurement"] + counts["/ssa/withheld"] == EPOCHS
    assert len(runs_in(lone["bag"]).runs) == 1


def test_a_paused_recorder_beside_cpu_burners_loses_nothing_and_changes_nothing(
        lone, tmp_path):
    """SIGSTOP for 6 s (a closed lid, a swap storm): sim time waits, says so, and the bag is
    the lone run's."""

    def pause(g, nodes, clocks):
        _third_through(g, clocks)
        os.kill(nodes["recorder"].popen.pid, signal.SIGSTOP)
        try:
            time.sleep(6.0)  # the pause itself (its length is the test's, not a wait)
        finally:
            os.kill(nodes["recorder"].popen.pid, signal.SIGCONT)

    with cpu_burners(3):
        paused = run_graph(tmp_path, "paused", pause)
    assert paused["code"] == 0 and not paused["problems"], paused["log"]
    assert "lockstep: waiting since" in paused["log"] and "for recorder" in paused["log"]
    assert "lockstep_gone" not in paused["log"]
    assert same_messages(lone["bag"], paused["bag"])


def test_a_strangers_clock_and_measurements_change_nothing_and_are_counted(lone, tmp_path):
    """A participant outside the run (its own namespace) publishes 20 /clock dated 2037 and
    300 measurements stamped 1972 of a station no one knows, mid-run."""

    pubs = {}

    def meet(g):  # the stranger joins before the run starts: it has matched every node
        node = rclpy.create_node("stranger", namespace="/elsewhere", context=g.context)
        g.executor.add_node(node)
        pubs["clock"] = node.create_publisher(Clock, "/clock", DATA_QOS)
        pubs["meas"] = node.create_publisher(Measurement, "/ssa/measurement", DATA_QOS)
        g.wait_for(lambda: pubs["clock"].get_subscription_count() >= 4
                   and pubs["meas"].get_subscription_count() >= 3, 30.0,
                   "the stranger's matches")

    def stranger(g, nodes, clocks):
        _third_through(g, clocks)
        for k in range(STRANGER_CLOCKS):
            pubs["clock"].publish(Clock(clock=Time(sec=2_130_000_000 + k)))
        for k in range(STRANGER_MEASUREMENTS):
            m = Measurement(object_id="iss", kind=1, z=[7e6, 1.0, 0.5],
                            covariance=[1e6, 0, 0, 0, 1e-4, 0, 0, 0, 1e-4])
            m.header.stamp = Time(sec=70_000_000 + k)  # 1972
            m.header.frame_id = "nowhere"
            pubs["meas"].publish(m)
        for pub in pubs.values():
            pub.wait_for_all_acked(Duration(seconds=10))
        assert len(clocks) < EPOCHS, "the run ended before the stranger spoke"

    strange = run_graph(tmp_path, "stranger", stranger, meet)
    assert strange["code"] == 0 and not strange["problems"], strange["log"]
    assert same_messages(lone["bag"], strange["bag"])  # no estimate changed, nothing of theirs
    for node in ("filter", "surrogate", "recorder"):
        counts = strange["diag"][node]
        assert counts.get("foreign_clock") == str(STRANGER_CLOCKS), (node, counts)
    for node in ("filter", "surrogate", "recorder"):
        assert strange["diag"][node].get("foreign_run") == str(STRANGER_MEASUREMENTS), node
    assert strange["foreign_at_probe"].get("/clock") == STRANGER_CLOCKS
    stamps = [m.t_ns for m in bagio.read_bag(strange["bag"], ["/ssa/measurement"])]
    assert min(stamps) >= SHORT.t0 * 1e9  # nothing of 1972 in the bag


def test_a_consumer_that_is_gone_is_named_and_the_run_ends(tmp_path):
    """The surrogate killed (SIGKILL) mid-run: lockstep says it is gone and goes on."""

    def kill(g, nodes, clocks):
        _third_through(g, clocks)
        nodes["surrogate"].popen.kill()
        nodes["surrogate"].expect_returncode = None

    gone = run_graph(tmp_path, "gone", kill)
    assert gone["code"] == 0, gone["log"]
    assert "lockstep: surrogate is gone" in gone["log"]
