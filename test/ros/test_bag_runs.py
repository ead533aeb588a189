"""A bag of one run only (`ros.bag_runs`): two runs named on /ssa/run, or two simulators'
/clock interleaved (what a recorder of an earlier version wrote when two `live` runs shared
a ROS domain), make `report` and `replay` refuse the bag in one line; one run's bag, the
sample bag, and a clock that goes back once (a looping playback) pass."""

import json
from pathlib import Path

import numpy as np
import pytest

from ssa_fusion.apps import cli
from ssa_fusion.core.base.types import StateEstimate
from ssa_fusion.ros import bagio, messages
from ssa_fusion.ros.bag_runs import CLOCK_BACKS, MixedBagError, check_one_run, runs_in
from ssa_fusion.ros.topics import TOPIC_CLOCK, TOPIC_RUN

SAMPLE = Path(__file__).resolve().parents[2] / "bags" / "sample_iss_j2_rae"
T0 = 1_735_689_600


def _bag(path: Path, runs: list[str], clocks: list[int]) -> Path:
    """Write a bag naming `runs` on /ssa/run, with /clock at `clocks` (s, in that order)."""
    store = bagio.typestore()
    text, clock = store.types["std_msgs/msg/String"], store.types["rosgraph_msgs/msg/Clock"]
    stamp = store.types["builtin_interfaces/msg/Time"]
    w = bagio.BagWriter(path)
    w.add_topic(TOPIC_RUN, "std_msgs/msg/String", [bagio.LATCHED_QOS])
    w.add_topic(TOPIC_CLOCK, "rosgraph_msgs/msg/Clock")
    for k, run in enumerate(runs):
        w.write_msg(TOPIC_RUN, (T0 + k) * 10**9, text(data=json.dumps({"run": run})))
    for k, t in enumerate(clocks):
        w.write_msg(TOPIC_CLOCK, (T0 + k) * 10**9, clock(clock=stamp(sec=t, nanosec=0)))
    w.close()
    return path


def test_one_runs_bag_passes(tmp_path):
    bag = _bag(tmp_path / "one", ["20250101_000000_000_aaaa"], [T0 + 30 * k for k in range(50)])
    assert runs_in(bag).runs == ("20250101_000000_000_aaaa",)
    check_one_run(bag)
    check_one_run(SAMPLE)  # recorded before runs were named: its clock tells
    # a looping playback's clock goes back once a loop
    check_one_run(_bag(tmp_path / "loop", [], [T0 + 30 * (k % 20) for k in range(60)]))


def test_two_runs_named_are_refused(tmp_path):
    bag = _bag(tmp_path / "two", ["20250101_000000_000_aaaa", "20250101_000000_001_bbbb"],
               [T0])
    with pytest.raises(MixedBagError, match="holds 2 runs"):
        check_one_run(bag)


def test_two_clocks_interleaved_are_refused(tmp_path):
    clocks = [T0 + 30 * (k // 2) - 7 * (k % 2) for k in range(2 * (CLOCK_BACKS + 5))]
    assert runs_in(_bag(tmp_path / "mixed", [], clocks)).clock_backs > CLOCK_BACKS
    with pytest.raises(MixedBagError, match="clocks of two runs interleaved"):
        check_one_run(tmp_path / "mixed")


@pytest.mark.parametrize("command", [["report"], ["replay", "--offline"]])
def test_report_and_replay_refuse_a_bag_of_two_runs_in_one_line(tmp_path, capsys, command):
    mixed = _bag(tmp_path / "runs", ["20250101_000000_000_aaaa", "20250101_000000_001_bbbb"],
                 [T0])
    out = tmp_path / "out"
    code = cli.main([command[0], str(mixed), *command[1:], "--out", str(out)])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and "holds 2 runs" in err[0], err
    assert not out.exists()


def _truth_bag(path: Path, epochs: list[int], logged: list[int] | None = None) -> Path:
    """Write a bag with one /ssa/truth of object "iss" at each of `epochs` (s), in order,
    logged at `logged` (s; default: its own epoch, as a run in lockstep records)."""
    w = bagio.BagWriter(path)
    w.add_topic("/ssa/truth", "ssa_fusion_msgs/msg/StateEstimate")
    for t, log in zip(epochs, logged or epochs, strict=True):
        e = StateEstimate(float(t), np.zeros(6), object_id="iss")
        w.write_msg("/ssa/truth", log * 10**9, messages.estimate_to_msg(e, bagio.rosbags_classes()))
    w.close()
    return path


def test_a_run_recorded_twice_into_one_bag_is_refused_a_loop_is_not(tmp_path):
    """Two recordings of a run in lockstep merged (the second 7 s later, log time = sim time):
    the clocks never go back, but the truth repeats its epochs while new ones come."""
    epochs = [T0 + 60 * k for k in range(40)]
    merged = sorted(epochs + epochs)  # each epoch twice, interleaved
    with pytest.raises(MixedBagError, match="repeats an object's epochs while 39 new ones"):
        check_one_run(_truth_bag(tmp_path / "merged", merged))
    looped = [T0 + 60 * k for k in range(2 * len(epochs))]  # a loop's log times go on
    check_one_run(_truth_bag(tmp_path / "loop", epochs + epochs, looped))
    check_one_run(_truth_bag(tmp_path / "one", epochs))
