"""Lockstep bookkeeping (`nodes.kit.progress`): what the simulator still waits for, from the
consumers' latest reports, and the measurements sent to each shard."""

import subprocess
import sys

import numpy as np

from ssa_fusion.nodes.kit.liveness import PID, process_keys
from ssa_fusion.nodes.kit.progress import (
    CLOCK,
    DECIDED,
    NEXT_DECISION,
    NEXT_DUE,
    PUBLISHED_ESTIMATES,
    RECORDED_ASSOCIATED,
    RECORDED_ESTIMATES,
    RECORDED_MEASUREMENTS,
    RECORDED_TRUTH,
    RELEASED,
    SHARD,
    TAKEN,
    TAKEN_ALL_ESTIMATES,
    TAKEN_ESTIMATES,
    TAKEN_FORECASTS,
    Lockstep,
    ObjectSent,
    object_waiting,
    time_ns,
    waiting,
    wants,
)
from ssa_fusion.nodes.kit.shards import shard_range
from ssa_fusion.ros import messages

NODES = ["catalog_filter_0", "catalog_filter_1", "catalog_surrogate_0", "recorder"]


def _sent(counts):
    return lambda shards: np.array(counts[:shards])


def _reports(taken=(5, 7), published=(4, 6), gap_taken=4, forecasts=2, recorded=(12, 12)):
    return {
        **{f"catalog_filter_{k}": {SHARD: f"{k}/2", TAKEN: str(taken[k]),
                                   "published_sensor": str(published[k])} for k in range(2)},
        "catalog_surrogate_0": {SHARD: "0/2", TAKEN_ESTIMATES: str(gap_taken),
                                "published_forecast": str(forecasts)},
        "recorder": {RECORDED_MEASUREMENTS: str(recorded[0]), RECORDED_ESTIMATES: str(recorded[1])},
    }


def test_all_taken_and_recorded_lets_the_simulator_go_on():
    assert waiting(_reports(), NODES, 12, _sent([5, 7])) == []


def test_each_shortfall_is_named():
    assert waiting({}, NODES, 0, _sent([0, 0])) == [f"{n} (no report yet)" for n in NODES]
    got = waiting(_reports(taken=(5, 6)), NODES, 12, _sent([5, 7]))
    assert got == ["catalog_filter_1 (taken 6 of 7 measurements)"]
    # the surrogate waits for its own filter shard's estimates (4), not the other's
    got = waiting(_reports(gap_taken=3), NODES, 12, _sent([5, 7]))
    assert got == ["catalog_surrogate_0 (taken 3 of 4 estimates)"]
    # the recorder: every measurement sent, every estimate and forecast published (4+6+2)
    got = waiting(_reports(recorded=(11, 11)), NODES, 12, _sent([5, 7]))
    assert got == ["recorder (recorded 11 of 12 measurements)",
                   "recorder (recorded 11 of 12 estimates)"]


def test_the_conjunction_node_waits_for_every_shards_estimates():
    reports = {**_reports(), "conjunction": {TAKEN_ALL_ESTIMATES: "9"}}
    nodes = [*NODES, "conjunction"]
    assert waiting(reports, nodes, 12, _sent([5, 7])) == [
        "conjunction (taken 9 of 10 estimates)"]  # shard 0 published 4, shard 1 6
    reports["conjunction"][TAKEN_ALL_ESTIMATES] = "10"
    assert waiting(reports, nodes, 12, _sent([5, 7])) == []


def test_unlabelled_detections_wait_for_their_truth_and_associations_to_be_recorded():
    reports = _reports()
    reports["catalog_filter_0"]["published_associated"] = "3"
    assert waiting(reports, NODES, 12, _sent([5, 7])) == []  # the recorder reports neither
    reports["recorder"].update({RECORDED_TRUTH: "11", RECORDED_ASSOCIATED: "2"})
    assert waiting(reports, NODES, 12, _sent([5, 7])) == [
        "recorder (recorded 11 of 12 detections' truth)",
        "recorder (recorded 2 of 3 associated detections)"]
    reports["recorder"].update({RECORDED_TRUTH: "12", RECORDED_ASSOCIATED: "3"})
    assert waiting(reports, NODES, 12, _sent([5, 7])) == []


def test_the_next_step_waits_until_every_consumer_acted_on_the_clock():
    """A consumer that has taken everything but whose clock (a surrogate: the sim time it
    last stepped its bank at) is behind the clock last published is waited for: the next
    step's data must not reach it before it acted on that clock."""
    reports = _reports()
    for r in reports.values():
        r[CLOCK] = "2000000000000"
    assert waiting(reports, NODES, 12, _sent([5, 7]), clock_ns=2_000_000_000_000) == []
    reports["catalog_surrogate_0"][CLOCK] = "1999700000000"
    assert waiting(reports, NODES, 12, _sent([5, 7]), clock_ns=2_000_000_000_000) == [
        "catalog_surrogate_0 (at sim time 1999700000000 ns of 2000000000000)"]


class _Node:
    """What Lockstep asks of its node: the ROS graph's nodes (`listed`), its namespace."""

    def __init__(self, listed=()):
        self.listed = list(listed)

    def create_subscription(self, *args, **kwargs):
        return None

    def get_node_names_and_namespaces(self):
        return [(n, "/") for n in self.listed]

    def get_namespace(self):
        return "/"


def test_measurements_sent_per_shard_follow_the_shard_keys():
    """Each object's measurements count for the shard of its key, as they are published."""
    ids = [f"{k:05d}" for k in range(300)]
    keys = np.array([messages.shard_key(o) for o in ids], dtype=np.int64)
    lock = Lockstep(_Node(), NODES, keys)
    objects = np.random.default_rng(3).integers(0, 300, 900)  # a measurement's object
    for sent in (0, 17, 900):  # grows as the simulator publishes
        lock.published(objects[lock.sent:sent])
        assert lock.sent == sent
        for shards in (1, 2, 3):
            want = [sum(shard_range(k, shards)[0] <= keys[o] <= shard_range(k, shards)[1]
                        for o in objects[:sent]) for k in range(shards)]
            assert lock.sent_by_shard(shards).tolist() == want


def test_a_consumer_that_lives_is_waited_for_however_long():
    """A stopped process (SIGSTOP: a closed lid, a swap storm) is alive: sim time waits."""
    node = _Node(listed=["recorder"])
    lock = Lockstep(node, ["recorder"], np.zeros(1, dtype=np.int64))
    lock.watch.reports["recorder"] = {RECORDED_MEASUREMENTS: "0", RECORDED_ESTIMATES: "0",
                                      **process_keys()}  # this process: alive
    lock.published(np.zeros(5, dtype=np.int64))
    for now in (100.0, 160.0, 10_000.0):
        assert lock.go_on(now) == (False, ["recorder (recorded 0 of 5 measurements)"])
    assert lock.gone == [] and lock.since == 100.0
    assert "waiting since" in lock.waiting_line(["recorder (x)"], 160.0)
    assert "(60 s) for recorder (x)" in lock.waiting_line(["recorder (x)"], 160.0)


def test_a_consumer_that_is_gone_is_named_and_no_longer_waited_for():
    """Its process ended (same host): at once; elsewhere: once the graph no longer lists it."""
    node = _Node(listed=["catalog_filter_1"])
    lock = Lockstep(node, ["recorder", "catalog_filter_1"], np.zeros(1, dtype=np.int64))
    ended = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"],
                           capture_output=True, text=True, check=True)
    lock.watch.reports["recorder"] = {RECORDED_MEASUREMENTS: "0", RECORDED_ESTIMATES: "0",
                                      **process_keys(), PID: ended.stdout.strip()}
    lock.published(np.zeros(5, dtype=np.int64))
    go, missing = lock.go_on(100.0)  # the filter shard has not reported: listed, so alive
    assert (lock.gone, lock.nodes) == (["recorder"], ["catalog_filter_1"])
    assert (go, missing) == (False, ["catalog_filter_1 (no report yet)"])
    node.listed = []  # it left the graph (another host's process)
    assert lock.go_on(100.5) == (False, ["catalog_filter_1 (no report yet)"])  # 1 s between
    assert lock.go_on(101.5) == (True, [])
    assert lock.gone == ["recorder", "catalog_filter_1"]


def test_a_live_consumer_that_dds_dropped_is_named_with_its_loss_and_not_waited_for():
    """Its process lives (stopped) but the graph that listed it no longer does: DDS dropped
    it after its lease, and what it was sent meanwhile never reaches it: waiting would be
    forever. Not listed before (starting up, or another host's): not dropped."""
    node = _Node(listed=["recorder"])
    lock = Lockstep(node, ["recorder", "catalog_filter_1"], np.zeros(1, dtype=np.int64))
    alive_here = {**process_keys()}  # this process: alive
    lock.watch.reports["recorder"] = {RECORDED_MEASUREMENTS: "3", RECORDED_ESTIMATES: "0",
                                      **alive_here}
    lock.watch.reports["catalog_filter_1"] = {TAKEN: "0", SHARD: "0/1", **alive_here}
    lock.published(np.zeros(5, dtype=np.int64))
    assert lock.go_on(100.0)[0] is False and lock.dropped == []  # listed: waited for
    node.listed = []
    go, missing = lock.go_on(101.0)
    assert lock.dropped == [("recorder", ["recorder (recorded 3 of 5 measurements)"])]
    assert (go, missing, lock.nodes) == (
        False, ["catalog_filter_1 (taken 0 of 5 measurements)"], ["catalog_filter_1"])
    assert lock.gone == []  # never listed: not dropped, and its process lives: not gone


def test_one_object_waits_for_every_message_forecast_and_estimate():
    sent = ObjectSent(released_forecasts_ns=7, released_decisions_ns=5)
    sent.published.update({"/ssa/measurement": 3, "/ssa/withheld": 1, "/ssa/truth": 4})
    recorded = {f"recorded {t}": str(n) for t, n in (
        ("/ssa/measurement", 3), ("/ssa/withheld", 1), ("/ssa/truth", 4),
        ("/ssa/forecast", 2), ("/ssa/estimate", 6))}
    reports = {
        "filter": {TAKEN: "3", TAKEN_FORECASTS: "2", PUBLISHED_ESTIMATES: "6", DECIDED: "5",
                   CLOCK: "9"},
        "surrogate": {TAKEN: "3", "forecasts": "2", RELEASED: "7", CLOCK: "9"},
        "recorder": {**recorded, CLOCK: "9"}}
    nodes = ["filter", "surrogate", "recorder"]
    assert object_waiting(reports, nodes, sent, clock_ns=9) == []
    reports["surrogate"]["forecasts"] = "3"  # one more forecast: the filter and recorder lag
    assert object_waiting(reports, nodes, sent, clock_ns=9) == [
        "filter (taken forecasts 2 of 3)", "recorder (recorded /ssa/forecast 2 of 3)"]
    reports["surrogate"]["forecasts"] = "2"
    sent.released_decisions_ns = 8  # released, not decided yet
    assert object_waiting(reports, nodes, sent, clock_ns=10) == [
        "filter (at sim time ns 9 of 10)", "filter (decided up to ns 5 of 8)",
        "surrogate (at sim time ns 9 of 10)", "recorder (at sim time ns 9 of 10)"]


def test_a_release_is_wanted_only_by_a_consumer_with_something_due():
    reports = {"surrogate": {NEXT_DUE: time_ns(100.0)}, "filter": {NEXT_DECISION: "inf"}}
    assert wants(reports, ["surrogate", "filter"], NEXT_DUE, 100.0)
    assert not wants(reports, ["surrogate", "filter"], NEXT_DUE, 99.9)
    assert not wants(reports, ["surrogate", "filter"], NEXT_DECISION, 1e12)
    assert not wants({}, ["filter"], NEXT_DECISION, 1e12)  # no report: nothing due
