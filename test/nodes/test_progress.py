"""Lockstep bookkeeping (`nodes.kit.progress`): what the simulator still waits for, from the
consumers' latest reports, and the measurements sent to each shard."""

import numpy as np

from ssa_fusion.nodes.kit.progress import (
    CLOCK,
    RECORDED_ASSOCIATED,
    RECORDED_ESTIMATES,
    RECORDED_MEASUREMENTS,
    RECORDED_TRUTH,
    SHARD,
    TAKEN,
    TAKEN_ALL_ESTIMATES,
    TAKEN_ESTIMATES,
    Lockstep,
    waiting,
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
    def create_subscription(self, *args, **kwargs):
        return None


def test_measurements_sent_per_shard_follow_the_shard_keys():
    """Each object's measurements count for the shard of its key, as they are published."""
    ids = [f"{k:05d}" for k in range(300)]
    keys = np.array([messages.shard_key(o) for o in ids], dtype=np.int64)
    lock = Lockstep(_Node(), NODES, keys, 30.0)
    objects = np.random.default_rng(3).integers(0, 300, 900)  # a measurement's object
    for sent in (0, 17, 900):  # grows as the simulator publishes
        lock.published(objects[lock.sent:sent])
        assert lock.sent == sent
        for shards in (1, 2, 3):
            want = [sum(shard_range(k, shards)[0] <= keys[o] <= shard_range(k, shards)[1]
                        for o in objects[:sent]) for k in range(shards)]
            assert lock.sent_by_shard(shards).tolist() == want


def test_a_consumer_that_does_not_answer_is_left_after_the_timeout():
    """For the rest of the run: a shard on a host that never started does not cost every
    step the timeout."""
    lock = Lockstep(_Node(), ["recorder", "catalog_filter_1"], np.zeros(1, dtype=np.int64),
                    30.0)
    lock.watch.reports["recorder"] = {RECORDED_MEASUREMENTS: "0", RECORDED_ESTIMATES: "0"}
    assert lock.go_on(100.0) == (False, ["catalog_filter_1 (no report yet)"])
    assert lock.go_on(129.0)[0] is False
    assert lock.go_on(131.0) == (True, ["catalog_filter_1 (no report yet)"])
    assert lock.nodes == ["recorder"]
    assert lock.go_on(132.0) == (True, [])
    lock.published(np.zeros(5, dtype=np.int64))  # the recorder is still waited for
    assert lock.go_on(133.0) == (False, ["recorder (recorded 0 of 5 measurements)"])
