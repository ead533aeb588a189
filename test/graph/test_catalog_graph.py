"""Graph test of a sharded catalog run (issue 20): `ssa-fusion live --catalog` starts
sensor_sim (catalog mode), the recorder and two catalog_filter shards as separate processes
over DDS (private domain, loopback). Every object's estimates come from exactly one shard,
the one its shard key belongs to; no measurement is lost between simulator, bag and shards;
the estimates follow the SGP4 truth."""

import argparse
import json
from collections import Counter
from pathlib import Path

import pytest

from ssa_fusion.apps import live_catalog
from ssa_fusion.nodes.shards import shard_range
from ssa_fusion.ros import bagio, messages

SAMPLE = Path(__file__).resolve().parents[2] / "config" / "catalogs" / "sample.tle"
OBJECTS = 12


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    out = tmp_path_factory.mktemp("catalog")
    args = argparse.Namespace(
        catalog=SAMPLE, objects=0, synthetic=OBJECTS, duration=3.0, shards=2,
        scenario="iss_network", time_scale=2000.0, seed=4, out=out, bag=None, domain_id=None)
    rc = live_catalog.run(args)
    return rc, out, json.loads((out / "catalog.json").read_text())


def test_the_run_ends_with_nothing_lost(run):
    rc, _, s = run
    assert rc == 0
    assert s["published"] > 500
    assert s["lost_measurements"] == 0 and s["lost_estimates"] == 0
    assert s["published"] == s["recorded_measurements"] == s["received_by_shards"] \
        == s["consumed_by_banks"]
    pending = s["rejected_and_pending"]
    assert s["estimates_published"] + sum(pending.values()) == s["consumed_by_banks"]


def test_every_object_is_tracked_by_exactly_the_shard_of_its_key(run):
    _, out, s = run
    shards = s["per_shard"]
    ids = [set(p["object_ids"]) for p in shards.values()]
    assert ids[0].isdisjoint(ids[1])
    assert len(ids[0] | ids[1]) == OBJECTS and all(ids)
    for k, p in enumerate(shards.values()):
        lo, hi = shard_range(k, 2)
        assert all(lo <= messages.shard_key(o) <= hi for o in p["object_ids"])
        assert p["received"] > 0
    # and the recorded estimates are those objects' (counted per shard as they published)
    est = Counter(m.msg.object_id for m in bagio.read_bag(out / "bag",
                                                          topics=["/ssa/estimate"]))
    for p, mine in zip(shards.values(), ids, strict=True):
        assert sum(est[o] for o in mine) == p["estimates"]


def test_estimates_follow_the_sgp4_truth(run):
    _, _, s = run
    assert s["objects_with_estimates"] == OBJECTS
    assert s["position_error_km"]["median"] < 0.5
