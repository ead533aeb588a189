"""The live catalog graph and the offline replay of its bag publish the same estimates.

`ssa-fusion live --catalog` (sensor_sim, recorder, one catalog_filter: separate processes
over DDS, in lockstep) records 3 h of sim time of 3 synthetic objects, labelled and as
unlabelled detections; the catalog_filter records its settings on /ssa/config.
`ssa-fusion replay --offline` of the bag takes the catalog path with those settings and
must publish the same estimate rows in the same order (objects or tracks, epochs, states
and covariances), and for the unlabelled run the same associated detections. `ssa-fusion
replay` over ROS (the bag played at a rate into a fresh catalog_filter process, recorded)
gives every object the same estimates too (the fusions may group the objects otherwise).
"""

import math

import numpy as np
import pytest
from test_catalog_graph import _rows, catalog_args

from ssa_fusion.apps import cli, live_catalog
from ssa_fusion.core.base.rows import EstimateRows, MeasurementRows
from ssa_fusion.params import settings
from ssa_fusion.ros import bagio

OBJECTS = 3
pytestmark = pytest.mark.graph


@pytest.fixture(scope="module", params=[False, True], ids=["labelled", "unlabelled"])
def run(request, tmp_path_factory):
    out = tmp_path_factory.mktemp("catalog_replay")
    args = catalog_args(out, synthetic=OBJECTS, duration=3.0, time_scale=math.inf,
                        unlabelled=request.param)
    assert live_catalog.run(args) == 0
    return out, request.param


def test_the_bag_records_the_catalog_filter_settings(run):
    out, _ = run
    texts = [m.msg.data for m in bagio.read_bag(out / "bag", topics=["/ssa/config"])]
    recorded = settings.recorded_catalog(texts)
    assert len(recorded) == 1
    assert recorded[0]["station"] == "millstone,tira,altair"  # the run's, not the default


def test_the_offline_replay_publishes_what_the_live_filter_published(run, capsys):
    out, unlabelled = run
    bag, offline = out / "bag", out / "offline"
    assert cli.main(["replay", str(bag), "--offline", "--out", str(offline)]) == 0
    assert "recorded with the bag (/ssa/config; 1 shard(s))" in capsys.readouterr().out
    live, again = (_estimates(b) for b in (bag, offline))
    assert len(live.t) > 150 and len(set(live.object_id)) == OBJECTS
    assert live.object_id == again.object_id
    assert np.array_equal(live.t, again.t)
    np.testing.assert_allclose(again.x, live.x, rtol=1e-12, atol=0)
    np.testing.assert_allclose(again.P, live.P, rtol=1e-12, atol=1e-300)
    if unlabelled:
        a, b = (MeasurementRows.concat(_rows(x, "/ssa/measurement_associated"))
                for x in (bag, offline))
        assert a.object_id == b.object_id and np.array_equal(a.t, b.t)
        assert len(a) > 150


def _estimates(bag):
    """Every estimate row of `bag` (/ssa/estimate_batch) in bag order, as one EstimateRows."""
    rows = _rows(bag, "/ssa/estimate_batch")
    return EstimateRows(np.concatenate([r.t for r in rows]),
                        [o for r in rows for o in r.object_id],
                        np.concatenate([r.x for r in rows]), np.concatenate([r.P for r in rows]),
                        np.concatenate([r.nis for r in rows]))


def test_the_replay_over_ros_gives_each_object_its_live_estimates(run):
    out, _ = run
    bag, again = out / "bag", out / "over_ros"
    assert cli.main(["replay", str(bag), "--rate", "2000", "--record", str(again)]) == 0
    live, played = (_by_object(_estimates(b)) for b in (bag, again))
    assert sorted(live) == sorted(played) and len(live) == OBJECTS
    for oid, (t, x, P) in live.items():
        t2, x2, P2 = played[oid]
        assert np.array_equal(t, t2), oid
        np.testing.assert_allclose(x2, x, rtol=1e-12, atol=0)
        np.testing.assert_allclose(P2, P, rtol=1e-12, atol=1e-300)
    # the replayed bag records the settings it ran with
    texts = [m.msg.data for m in bagio.read_bag(again, topics=["/ssa/config"])]
    assert settings.recorded_catalog(texts)[0]["station"] == "millstone,tira,altair"


def _by_object(e: EstimateRows) -> dict[str, tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """Per object (or track): its estimates' epochs, states and covariances, in epoch order."""
    ids = np.array(e.object_id)
    out = {}
    for oid in sorted(set(e.object_id)):
        i = np.flatnonzero(ids == oid)
        i = i[np.argsort(e.t[i], kind="stable")]
        out[oid] = (e.t[i], e.x[i], e.P[i])
    return out
