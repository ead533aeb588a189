"""Graph test of one catalog_filter shard fed a MeasurementBatch with bad rows among good
ones: every bad row is refused by its cause on /diagnostics (a row of the other shard
ignored, not received), the good rows of the same batch are fused, and the estimates it
publishes (one EstimateBatch) equal an in-process `TrackBank` fed the good rows alone."""

from __future__ import annotations

from dataclasses import asdict
from pathlib import Path

import numpy as np
from ssa_fusion_msgs.msg import EstimateBatch, MeasurementBatch
from test_faults import Diag, publisher

from ssa_fusion.core.base.rows import MeasurementRows
from ssa_fusion.core.catalog.track_bank import TrackBank
from ssa_fusion.core.earth.stations import network_stations
from ssa_fusion.formats import element_sets as catalog_io
from ssa_fusion.nodes.kit.shards import shard_range
from ssa_fusion.params import settings
from ssa_fusion.params.defaults import CATALOG_FILTER
from ssa_fusion.ros import messages
from ssa_fusion.ros.qos import CATALOG_QOS
from ssa_fusion.sim import sky, survey

SAMPLE = Path(__file__).resolve().parents[2] / "config" / "catalogs" / "sample.tle"
STATIONS = "millstone,tira,altair"


def _pass_of_shard_0() -> MeasurementRows:
    """Twelve measurements of one pass of an object of shard 0 (of 2) by the radars of
    iss_network, and one of an object of shard 1 (the last row)."""
    radars = sky.SKY_SCENARIOS["iss_network"].radars
    entries = survey.synthetic_catalog(catalog_io.read_catalog(SAMPLE)[0], 8, seed=2)
    obs = survey.observe_catalog(entries, radars, survey.catalog_start(entries), 6 * 3600.0,
                                 seed=2)
    ids = np.asarray(obs.object_ids, dtype=object)[obs.obj].tolist()
    rows = MeasurementRows(obs.t, ids, np.asarray([r.station.name for r in radars],
                                                  dtype=object)[obs.sensor].tolist(),
                           obs.z, np.array([r.R for r in radars])[obs.sensor],
                           shard_key=messages.shard_keys(ids))
    hi0 = shard_range(0, 2)[1]
    mine = np.flatnonzero(rows.shard_key <= hi0)
    first = rows.object_id[mine[0]]
    take = [i for i in mine.tolist() if rows.object_id[i] == first][:12]
    other = int(np.flatnonzero(rows.shard_key > hi0)[0])
    return rows.take(np.array([*take, other]))


def test_bad_rows_are_refused_by_cause_and_the_good_rows_of_the_batch_fused(ros_graph):
    g = ros_graph
    node = g.start_node("catalog_filter", params={"use_sim_time": True, "shards": 2, "shard": 0,
                                                  "station": STATIONS})
    diag = Diag(g)
    got: list = []
    g.probe.create_subscription(EstimateBatch, "/ssa/estimate_batch",
                                lambda m: got.append(messages.estimate_batch_from_msg(m)),
                                CATALOG_QOS)
    pub = publisher(g, MeasurementBatch, "/ssa/measurement_batch", ("catalog_filter",))
    rows = _pass_of_shard_0()
    good, other = rows.take(np.arange(12)), rows.take(np.array([12]))
    # one bad copy of the pass's first row per cause
    bad = [good.take(np.array([0])) for _ in range(8)]
    bad[0].z[0, 1] = np.nan
    bad[1].z[0, 0] = -1.0
    bad[2].kind[0] = 2  # RA_DEC: a kind the filter does not take
    bad[3].frame_id = ["nowhere"]
    bad[4].shard_key[0] += 1  # in range, not the CRC-32 of its id
    bad[5].source[0] = 1  # a forecast on the measurement topic
    bad[6].R[0, 0, 1] = 1.0  # asymmetric covariance
    bad[7].object_id = ["x" * 200]  # too long (checked before its shard key)
    batch = MeasurementRows.concat([*bad[:4], good.take(np.arange(6)), *bad[4:], other,
                                    good.take(np.arange(6, 12))])
    pub.publish(messages.measurement_batch_to_msg(batch))  # of every key: both shards'
    c = diag.wait(g, "catalog_filter", {
        "rejected_nonfinite": 1, "rejected_negative_range": 1, "rejected_kind": 1,
        "rejected_frame": 1, "rejected_shard_key": 1, "rejected_source": 1,
        "rejected_covariance": 1, "rejected_id": 1, "ignored_other_shard": 1,
        "refused": 8, "received": 20, "consumed": 12}, 30.0)
    assert c["published_sensor"] != "0"
    g.wait_for(lambda: sum(map(len, got)) == int(c["published_sensor"]), 20.0,
               "the estimates of the good rows")
    bank = TrackBank(settings.filter_options({**asdict(CATALOG_FILTER), "station": STATIONS}),
                     network_stations(STATIONS, {}))
    want = bank.process(good.t, good.object_id, good.frame_id, good.z, good.R)
    assert want.fused.size == sum(map(len, got)) >= 2
    x = np.concatenate([e.x for e in got])
    np.testing.assert_allclose(x, want.x, rtol=1e-12)
    assert all(o == good.object_id[0] for e in got for o in e.object_id)
    assert node.popen.poll() is None
