"""Unlabelled detections need one shard: the simulator's parameters, `live --catalog
--unlabelled` and the catalog_filter's reason say so (the node's refusal over DDS:
test/graph/test_unlabelled_graph.py)."""

import argparse
from pathlib import Path

from ssa_fusion.apps import live_catalog
from ssa_fusion.core.catalog.association import DetectionFate
from ssa_fusion.nodes.kit.unlabelled import fate_key, sharded_problem
from ssa_fusion.params.tables.sensor_sim import PARAMETERS as SENSOR_SIM

SAMPLE = Path(__file__).resolve().parents[2] / "config" / "catalogs" / "sample.tle"


def _rule(names: tuple[str, ...]):
    (rule,) = [r for r in SENSOR_SIM.rules if r.names == names]
    return rule.test


def test_sensor_sim_refuses_unlabelled_without_a_catalog_or_with_shards():
    test = _rule(("unlabelled", "catalog", "shards"))
    assert test({"unlabelled": False, "catalog": "", "shards": 4}) is None
    assert test({"unlabelled": True, "catalog": "x.tle", "shards": 1}) is None
    assert "catalog" in test({"unlabelled": True, "catalog": "", "shards": 1})
    assert "one filter shard" in test({"unlabelled": True, "catalog": "x.tle", "shards": 2})


def test_live_refuses_unlabelled_with_several_shards():
    args = argparse.Namespace(catalog=SAMPLE, objects=0, synthetic=4, duration=1.0, start="",
                              shards=2, scenario="iss_network", surrogate_param=[],
                              unlabelled=True)
    assert "--shards 1" in live_catalog.args_problem(args)
    args.shards = 1
    assert live_catalog.args_problem(args) is None


def test_the_filter_s_reason_and_keys():
    assert sharded_problem(1) == ""
    assert "no object key to route it by" in sharded_problem(3)
    assert "(shards 1)" in sharded_problem(3)
    assert [fate_key(f) for f in DetectionFate] == [
        "detection_track", "detection_tracklet", "detection_new_tracklet", "detection_refused"]
