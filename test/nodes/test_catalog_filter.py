"""catalog_filter's shard rules: which shard takes which measurement."""

import itertools

from ssa_fusion.nodes.kit.shards import shard_problem, shard_range
from ssa_fusion.ros.messages import KEY_SPACE, shard_key


def test_the_shards_ranges_cover_every_key_once():
    for k in (1, 2, 3, 7):
        ranges = [shard_range(i, k) for i in range(k)]
        assert ranges[0][0] == 0 and ranges[-1][1] == KEY_SPACE - 1
        assert all(a[1] + 1 == b[0] for a, b in itertools.pairwise(ranges))


def test_each_object_goes_to_exactly_one_shard():
    for oid in ("25544", "70001", "iss_j2_rae", ""):
        takers = [i for i in range(3) if shard_problem(shard_key(oid), oid, i, 3) is None]
        assert len(takers) == 1, oid


def test_one_shard_takes_a_message_without_a_key_several_refuse_it_with_a_reason():
    assert shard_problem(0, "25544", 0, 1) is None  # a sensor that does not set shard_key
    why = shard_problem(0, "25544", 0, 2)
    assert why is not None and why[0] == "rejected_shard_key" and "must set" in why[1]
    other = next(i for i in range(2) if shard_problem(shard_key("25544"), "25544", i, 2))
    assert shard_problem(shard_key("25544"), "25544", other, 2)[0] == "ignored_other_shard"
