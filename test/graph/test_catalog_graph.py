"""Graph test of a sharded catalog run: `ssa-fusion live --catalog` starts
sensor_sim (catalog mode), the recorder, two catalog_filter shards and two catalog_surrogate
shards as separate processes over DDS (private domain, loopback). Every object's estimates
come from exactly one shard, the one its shard key belongs to, and its gap forecasts from
that shard's surrogate; no measurement is lost between simulator, bag and shards; the
estimates follow the SGP4 truth, and the forecasts lie in the gaps between passes.

The run is in lockstep (the default) beside two CPU burners the test starts, at a time scale
the loaded machine does not sustain: nothing is lost all the same, and the estimates equal
those of the same measurements fused in this process (`TrackBank`), bit for bit or to
round-off: what a run gives does not depend on the machine's load."""

import argparse
import json
import subprocess
import sys
from collections import Counter, defaultdict
from dataclasses import asdict
from pathlib import Path

import numpy as np
import pytest

from ssa_fusion.apps import live_catalog
from ssa_fusion.core.stations import network_stations
from ssa_fusion.core.track_bank import TrackBank
from ssa_fusion.nodes import settings
from ssa_fusion.nodes.defaults import CATALOG_FILTER
from ssa_fusion.nodes.shards import shard_range
from ssa_fusion.ros import bagio, messages

SAMPLE = Path(__file__).resolve().parents[2] / "config" / "catalogs" / "sample.tle"
OBJECTS = 12


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    out = tmp_path_factory.mktemp("catalog")
    args = argparse.Namespace(
        catalog=SAMPLE, objects=0, synthetic=OBJECTS, duration=6.0, start="", shards=2,
        scenario="iss_network", time_scale=20000.0, seed=4, out=out, bag=None, domain_id=None,
        surrogate=True, surrogate_param=["min_span=7200", "min_anchors=3"], lockstep=True)
    burners = [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(2)]
    try:
        rc = live_catalog.run(args)
    finally:
        for b in burners:
            b.kill()
            b.wait()
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
                                                          topics=["/ssa/estimate"])
                  if m.msg.update_source == 1)  # the filters' (not the surrogates' forecasts)
    for p, mine in zip(shards.values(), ids, strict=True):
        assert sum(est[o] for o in mine) == p["estimates"]


def test_estimates_follow_the_sgp4_truth(run):
    _, _, s = run
    assert s["objects_with_estimates"] == OBJECTS
    assert s["position_error_km"]["median"] < 0.5


def test_each_shards_surrogate_forecasts_its_objects_gaps_only(run):
    _, out, s = run
    filters, gaps = list(s["per_shard"].values()), list(s["surrogates"].values())
    assert len(gaps) == 2
    for f, g in zip(filters, gaps, strict=True):
        assert set(g["object_ids"]) == set(f["object_ids"])  # the shard's objects, all
        assert g["received"] == f["estimates"]  # every estimate of its shard, nothing else
    made = sum(g["fits_made"] for g in gaps)
    published = sum(g["published_forecast"] for g in gaps)
    assert made >= 4 and published > 20
    assert s["forecasts_recorded"] == published
    sensor, forecast = {}, {}
    for m in bagio.read_bag(out / "bag", topics=["/ssa/estimate"]):
        e = messages.estimate_from_msg(m.msg)
        (forecast if e.update_source == 2 else sensor).setdefault(e.object_id, []).append(e.t)
    mine = {o: k for k, g in enumerate(gaps) for o in g["object_ids"]}
    for oid, ts in forecast.items():
        assert oid in mine
        est = sorted(sensor[oid])
        for t in ts:  # at least pass_break (600 s) after the object's last estimate
            before = [x for x in est if x < t]
            assert before and t - before[-1] >= 600.0
            assert t % 600.0 == 0.0  # on the predict_period grid
    # scored against the SGP4 truth beside the filter coasting on its J2 model
    ge = s["gap_errors"]
    assert ge["forecasts"] == published and ge["gaps_scored"] >= 4
    assert ge["forecast_error_km"]["median"] < 5.0


def test_the_estimates_equal_the_same_measurements_fused_in_process(run):
    """Lockstep under load: each shard's estimates are what a `TrackBank` with the node's
    default settings gives for the recorded measurements of its objects, in order."""
    _, out, _ = run
    bag = list(bagio.read_bag(out / "bag", topics=["/ssa/measurement", "/ssa/estimate"]))
    ms = [messages.measurement_from_msg(m.msg) for m in bag if m.topic == "/ssa/measurement"]
    got: dict[str, list[np.ndarray]] = defaultdict(list)
    for m in bag:
        if m.topic == "/ssa/estimate" and m.msg.update_source == 1:
            e = messages.estimate_from_msg(m.msg)
            got[e.object_id].append(np.r_[e.t, e.x, e.P.ravel()])
    station = ",".join(r.station.name for r in live_catalog.catalog_scenario(
        argparse.Namespace(scenario="iss_network", sites="")).radars)
    want: dict[str, list[np.ndarray]] = defaultdict(list)
    for k in range(2):
        lo, hi = shard_range(k, 2)
        mine = sorted((m for m in ms if lo <= messages.shard_key(m.object_id) <= hi),
                      key=lambda m: m.t)
        bank = TrackBank(settings.filter_options({**asdict(CATALOG_FILTER), "station": station}),
                         network_stations(station, {}))
        res = bank.process([m.t for m in mine], [m.object_id for m in mine],
                           [m.frame_id for m in mine], np.array([m.z for m in mine]),
                           np.array([m.R for m in mine]))
        for j, i in enumerate(res.fused.tolist()):
            want[mine[i].object_id].append(np.r_[mine[i].t, res.x[j], res.P[j].ravel()])
    assert set(got) == set(want) and len(got) == OBJECTS
    worst = 0.0
    for oid, rows in want.items():
        assert len(got[oid]) == len(rows), oid
        a, b = np.array(got[oid]), np.array(rows)
        worst = max(worst, float((np.abs(a - b) / np.maximum(np.abs(b), 1e-300)).max()))
    assert worst <= 1e-12, worst
