"""`bagio.read_bag`'s topic selection on a rosbag2 directory (the sample bag)."""

from pathlib import Path

from ssa_fusion.ros import bagio

SAMPLE = Path(__file__).resolve().parents[2] / "bags" / "sample_iss_j2_rae"


def test_topics_select_and_a_topic_the_bag_lacks_gives_nothing():
    every = {m.topic for m in bagio.read_bag(SAMPLE)}
    assert {"/clock", "/ssa/estimate"} <= every
    assert {m.topic for m in bagio.read_bag(SAMPLE, topics=["/ssa/estimate"])} == \
        {"/ssa/estimate"}
    # rosbags reads every connection when given none: asking for a topic the bag lacks
    # must not return the others
    assert list(bagio.read_bag(SAMPLE, topics=["/ssa/estimate_batch"])) == []
