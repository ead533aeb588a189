"""Graph test of unlabelled detections: `ssa-fusion live --catalog --unlabelled` starts
sensor_sim (catalog mode, detections without object ids), the recorder and one
catalog_filter as separate processes over DDS (private domain, loopback). A few
well-separated objects: each gets exactly one confirmed track, every detection in a
confirmed track is of the track's object, every detection is accounted for on /diagnostics,
nothing is lost between simulator, bag and filter, and the bag holds what the evaluation
needs (the detections without ids, their truth apart, the associated detections, the
tracks' estimates), readable. The estimates equal those of the recorded detections
associated in this process (`core.catalog.unlabelled.RowAssociator`): the live graph gives what an
offline run of its bag gives.

Also: a catalog_filter of a graph of two shards refuses unlabelled detections with a reason
(they have no object key to be routed by)."""

import json
from collections import Counter
from dataclasses import asdict

import numpy as np
import pytest
from ssa_fusion_msgs.msg import MeasurementBatch
from test_catalog_graph import _rows, catalog_args
from test_faults import Diag, publisher

from ssa_fusion.apps import live_catalog
from ssa_fusion.core.base.rows import MeasurementRows
from ssa_fusion.core.catalog.unlabelled import RowAssociator, elevation_masks, without_labels
from ssa_fusion.core.earth.stations import network_stations
from ssa_fusion.params import settings
from ssa_fusion.params.defaults import CATALOG_FILTER
from ssa_fusion.ros import messages

OBJECTS = 4
STATIONS = "millstone,tira,altair"  # the radars of iss_network


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    out = tmp_path_factory.mktemp("unlabelled")
    args = catalog_args(out, synthetic=OBJECTS, unlabelled=True)
    rc = live_catalog.run(args)
    return rc, out, json.loads((out / "catalog.json").read_text())


def test_nothing_is_lost_and_every_detection_is_accounted_for(run):
    rc, _, s = run
    assert rc == 0
    assert s["published"] > 300
    assert s["lost_measurements"] == 0 and s["lost_estimates"] == 0
    assert s["published"] == s["recorded_measurements"] == s["received_by_shards"] \
        == s["consumed_by_banks"]
    (shard,) = s["per_shard"].values()
    c = shard["association_counts"]
    fates = {k: v for k, v in c.items() if k.startswith("detection_")}
    assert sum(fates.values()) == s["published"] == c["association_detections"]
    assert c["detection_track"] == c["association_assigned"] > 0
    assert c["published_associated"] == s["published"] - c.get("detection_refused", 0)
    assert c["association_track_confirmed"] == OBJECTS == shard["confirmed_tracks"]
    a = s["association"]
    assert a["associated_published"] == a["associated_recorded"] == c["published_associated"]
    assert a["truth_recorded"] == s["published"] and a["detections_without_fate"] == 0


def test_each_object_has_exactly_one_confirmed_track_and_accuracy_is_one(run):
    _, _, s = run
    a = s["association"]
    assert a["objects"] == a["confirmed_tracks"] == a["objects_with_track"] == OBJECTS
    assert a["duplicate_tracks"] == 0
    assert a["accuracy"] == 1.0
    assert a["coverage"] > 0.9
    assert sorted(a["owner"].values()) == [str(70000 + i) for i in range(OBJECTS)]
    assert s["objects_with_estimates"] == OBJECTS
    assert s["position_error_km"]["median"] < 0.5


def test_the_bag_keeps_the_truth_apart_from_the_measurements(run):
    _, out, s = run
    bag = out / "bag"
    sent = MeasurementRows.concat(_rows(bag, "/ssa/measurement_batch"))
    truth = MeasurementRows.concat(_rows(bag, "/ssa/detection_truth"))
    assert set(sent.object_id) == {""} and not sent.shard_key.any()
    np.testing.assert_array_equal(sent.z, truth.z)
    np.testing.assert_array_equal(sent.t, truth.t)
    assert set(truth.object_id) == set(s["association"]["owner"].values())
    np.testing.assert_array_equal(truth.shard_key, messages.shard_keys(truth.object_id))
    associated = MeasurementRows.concat(_rows(bag, "/ssa/measurement_associated"))
    assert all(o.startswith("track-") for o in associated.object_id)
    np.testing.assert_array_equal(associated.shard_key,
                                  messages.shard_keys(associated.object_id))
    estimates = _rows(bag, "/ssa/estimate_batch")
    tracks = Counter(o for e in estimates for o in e.object_id)
    assert set(tracks) == set(s["association"]["owner"]) and len(tracks) == OBJECTS


def test_the_estimates_equal_the_recorded_detections_associated_in_process(run):
    _, out, _ = run
    bag = out / "bag"
    sent = MeasurementRows.concat(_rows(bag, "/ssa/measurement_batch"))
    stations = network_stations(STATIONS, {})
    assoc = RowAssociator(settings.filter_options({**asdict(CATALOG_FILTER),
                                                   "station": STATIONS}),
                          stations, elevation_masks(stations))
    want = assoc.process(sent.take(np.argsort(sent.t, kind="stable")))
    got = _rows(bag, "/ssa/estimate_batch")
    ids = [o for e in got for o in e.object_id]
    assert ids == want.estimates.object_id
    x = np.concatenate([e.x for e in got])
    P = np.concatenate([e.P for e in got])
    np.testing.assert_allclose(x, want.estimates.x, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(P, want.estimates.P, rtol=1e-9, atol=1e-15)


def test_a_sharded_filter_refuses_unlabelled_detections_with_a_reason(ros_graph):
    g = ros_graph
    node = g.start_node("catalog_filter", params={"use_sim_time": True, "shards": 2,
                                                  "shard": 0, "station": STATIONS})
    diag = Diag(g)
    pub = publisher(g, MeasurementBatch, "/ssa/measurement_batch", ("catalog_filter",))
    rows = MeasurementRows(np.array([1.75e9, 1.75e9]), ["x", "y"], ["tira", "tira"],
                           np.array([[1000.0, 1.0, 0.5], [1100.0, 1.1, 0.6]]),
                           np.tile(np.diag([4e-4, 1e-7, 1e-7]), (2, 1, 1)))
    pub.publish(messages.measurement_batch_to_msg(without_labels(rows)))
    c = diag.wait(g, "catalog_filter", {"rejected_unlabelled_sharded": 2, "refused": 2,
                                        "received": 2}, 30.0)
    assert "consumed" not in c or c["consumed"] == "0"
    assert node.popen.poll() is None
    g.wait_for(lambda: "no object key to route it by"
               in (g.workdir / "catalog_filter.err").read_text(), 10.0, "the reason logged")
