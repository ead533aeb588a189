"""Graph test of a sharded catalog run: `ssa-fusion live --catalog` starts
sensor_sim (catalog mode), the recorder, two catalog_filter shards and two catalog_surrogate
shards as separate processes over DDS (private domain, loopback). Every object's estimates
come from exactly one shard, the one its shard key belongs to, and its gap forecasts from
that shard's surrogate; no measurement is lost between simulator, bag and shards; the
estimates follow the SGP4 truth, and the forecasts lie in the gaps between passes.

The run is in lockstep (the default) beside two CPU burners the test starts, at a time scale
the loaded machine does not sustain: nothing is lost all the same, and the estimates equal
those of the same measurements fused in this process (`TrackBank`), bit for bit or to
round-off: what a run gives does not depend on the machine's load. Measurements and
estimates travel as batches (MeasurementBatch, EstimateBatch); every count is in rows."""

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
from ssa_fusion.core.base.rows import EstimateRows, MeasurementRows
from ssa_fusion.core.catalog.track_bank import TrackBank
from ssa_fusion.core.earth.stations import network_stations
from ssa_fusion.nodes.kit.shards import shard_range
from ssa_fusion.params import settings
from ssa_fusion.params.defaults import CATALOG_FILTER
from ssa_fusion.ros import bagio, messages


def _rows(bag: Path, topic: str) -> list:
    """The rows of every batch of `topic` in `bag` (EstimateRows of /ssa/estimate_batch,
    MeasurementRows of the measurement batch topics)."""
    convert = (messages.estimate_batch_from_msg if topic == "/ssa/estimate_batch"
               else messages.measurement_batch_from_msg)
    return [convert(m.msg) for m in bagio.read_bag(bag, topics=[topic])]


def _estimates(bag: Path) -> list[tuple[int, str, float, np.ndarray, np.ndarray]]:
    """(update source, object id, t, x, P) of every estimate row in `bag`, in bag order."""
    out = []
    for r in _rows(bag, "/ssa/estimate_batch"):
        assert isinstance(r, EstimateRows)
        out += [(int(r.update_source), o, float(t), x, P)
                for o, t, x, P in zip(r.object_id, r.t, r.x, r.P, strict=True)]
    return out


SAMPLE = Path(__file__).resolve().parents[2] / "config" / "catalogs" / "sample.tle"
OBJECTS = 12


def catalog_args(out: Path, **changes: object) -> argparse.Namespace:
    """`live --catalog`'s arguments for the sample catalog's first `OBJECTS` synthetic
    objects, 6 h on iss_network's radars in lockstep, seed 4, written to `out`; `changes`
    replace any of them."""
    args = dict(catalog=SAMPLE, objects=0, synthetic=OBJECTS, duration=6.0, start="", shards=1,
                scenario="iss_network", time_scale=20000.0, seed=4, out=out, bag=None,
                domain_id=None, surrogate=False, surrogate_param=[], lockstep=True,
                unlabelled=False)
    return argparse.Namespace(**{**args, **changes})


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    out = tmp_path_factory.mktemp("catalog")
    args = catalog_args(out, shards=2, surrogate=True,
                        surrogate_param=["min_span=7200", "min_anchors=3"])
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
    est = Counter(e[1] for e in _estimates(out / "bag")
                  if e[0] == 1)  # the filters' (not the surrogates' forecasts)
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
    # the gaps before an object's pass ends span min_span: the physics-only forecast
    assert 0 < sum(g["fits_physics"] for g in gaps) < made
    assert s["forecasts_recorded"] == published
    sensor, forecast = {}, {}
    for source, oid, t, _, _ in _estimates(out / "bag"):
        (forecast if source == 2 else sensor).setdefault(oid, []).append(t)
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
    ms = MeasurementRows.concat(_rows(out / "bag", "/ssa/measurement_batch"))
    got: dict[str, list[np.ndarray]] = defaultdict(list)
    for source, oid, t, x, P in _estimates(out / "bag"):
        if source == 1:
            got[oid].append(np.r_[t, x, P.ravel()])
    station = ",".join(r.station.name for r in live_catalog.catalog_scenario(
        argparse.Namespace(scenario="iss_network", sites="")).radars)
    want: dict[str, list[np.ndarray]] = defaultdict(list)
    for k in range(2):
        lo, hi = shard_range(k, 2)
        keys = messages.shard_keys(ms.object_id)
        mine = ms.take(np.flatnonzero((keys >= lo) & (keys <= hi)))
        mine = mine.take(np.argsort(mine.t, kind="stable"))
        bank = TrackBank(settings.filter_options({**asdict(CATALOG_FILTER), "station": station}),
                         network_stations(station, {}))
        res = bank.process(mine.t, mine.object_id, mine.frame_id, mine.z, mine.R)
        for j, i in enumerate(res.fused.tolist()):
            want[mine.object_id[i]].append(np.r_[mine.t[i], res.x[j], res.P[j].ravel()])
    assert set(got) == set(want) and len(got) == OBJECTS
    worst = 0.0
    for oid, rows in want.items():
        assert len(got[oid]) == len(rows), oid
        a, b = np.array(got[oid]), np.array(rows)
        worst = max(worst, float((np.abs(a - b) / np.maximum(np.abs(b), 1e-300)).max()))
    assert worst <= 1e-12, worst
