"""`ssa-fusion replay` of a catalog's bag (the measurements of several objects, as batches).

Offline, each object gets its own track: its estimates are those of its measurements alone
in a `TrackBank` of the catalog_filter's settings (the reference never sees another
object), whatever the other objects in the bag; unlabelled detections are associated as
`core.catalog.unlabelled.RowAssociator` associates all of them at once. A bag of several objects
the catalog filter cannot fuse, and the single-object replay's options (``--smooth``,
``--scenario``) for a catalog bag, are refused (exit 2) with what to do instead. The
replayed bag reads in `report` and `export`. (Over ROS: test/graph/test_catalog_replay_graph.py.)
"""

from __future__ import annotations

import dataclasses
import json
from collections import defaultdict
from pathlib import Path

import numpy as np
import pytest

from ssa_fusion.apps import cli, replay_catalog
from ssa_fusion.core.base import types
from ssa_fusion.core.base.rows import MeasurementRows
from ssa_fusion.core.catalog.track_bank import TrackBank
from ssa_fusion.core.catalog.unlabelled import RowAssociator, elevation_masks, without_labels
from ssa_fusion.core.earth.stations import NETWORKS, SENSORS, network_stations
from ssa_fusion.formats import element_sets as catalog
from ssa_fusion.params import settings
from ssa_fusion.params.defaults import CATALOG_FILTER
from ssa_fusion.ros import bagio, messages
from ssa_fusion.ros.topics import (
    TOPIC_ASSOCIATED,
    TOPIC_CONFIG,
    TOPIC_ESTIMATE_BATCH,
    TOPIC_MEASUREMENT,
    TOPIC_MEASUREMENT_BATCH,
)
from ssa_fusion.sim import survey

SAMPLE = Path(__file__).resolve().parents[2] / "config" / "catalogs" / "sample.tle"
RADARS = [SENSORS[s] for s in NETWORKS["radar_network"]]
OBJECTS, HOURS, STEP_S = 4, 4.0, 60.0
C = bagio.rosbags_classes()


@pytest.fixture(scope="module")
def rows() -> MeasurementRows:
    """4 synthetic LEO objects measured by the radar network for 4 h (epoch order)."""
    base = catalog.read_catalog(SAMPLE)[0]
    cat = survey.synthetic_catalog(base, OBJECTS, seed=4)
    obs = survey.observe_catalog(cat, RADARS, base.epoch_unix, HOURS * 3600.0, seed=2)
    ids = [obs.object_ids[k] for k in obs.obj]
    out = MeasurementRows(obs.t, ids, [obs.sensors[j].station.name for j in obs.sensor],
                          obs.z, np.stack([obs.sensors[j].R for j in obs.sensor]),
                          shard_key=messages.shard_keys(ids))
    return out.take(np.argsort(out.t, kind="stable"))


def write_bag(bag: Path, rows: MeasurementRows, config: list[str] = ()) -> Path:
    """`rows` as a catalog run records them: one MeasurementBatch per `STEP_S` of sim time,
    at the step's end (log time), and `config` on /ssa/config."""
    writer = bagio.BagWriter(bag)
    writer.add_topic(TOPIC_MEASUREMENT_BATCH, bagio.MEASUREMENT_BATCH)
    if config:
        writer.add_topic(TOPIC_CONFIG, "std_msgs/msg/String")
        text = bagio.typestore().types["std_msgs/msg/String"]
        for c in config:
            writer.write_msg(TOPIC_CONFIG, int(rows.t[0] * 1e9), text(data=c))
    step = np.floor((rows.t - rows.t[0]) / STEP_S).astype(int)
    for k in np.unique(step).tolist():
        part = rows.take(np.flatnonzero(step == k))
        t_ns = int((rows.t[0] + (k + 1) * STEP_S) * 1e9)
        writer.write_msg(TOPIC_MEASUREMENT_BATCH, t_ns,
                         messages.measurement_batch_to_msg(part, classes=C))
    writer.close()
    return bag


def estimates(bag: Path) -> dict[str, list[tuple[float, np.ndarray, np.ndarray]]]:
    """Per object, its (t, x, P) on /ssa/estimate_batch, in bag order."""
    out: dict[str, list] = defaultdict(list)
    for m in bagio.read_bag(bag, topics=[TOPIC_ESTIMATE_BATCH]):
        e = messages.estimate_batch_from_msg(m.msg)
        for o, t, x, P in zip(e.object_id, e.t.tolist(), e.x, e.P, strict=True):
            out[o].append((t, x, P))
    return out


def alone(rows: MeasurementRows, oid: str, params: dict) -> list[tuple[float, np.ndarray,
                                                                         np.ndarray]]:
    """Object `oid`'s measurements alone, all at once, in a bank of the settings `params`."""
    mine = rows.take(np.flatnonzero(np.array(rows.object_id) == oid))
    bank = TrackBank(settings.filter_options(params), network_stations(params["station"]))
    res = bank.process(mine.t, mine.object_id, mine.frame_id, mine.z, mine.R)
    return [(float(mine.t[i]), x, P) for i, x, P in zip(res.fused.tolist(), res.x, res.P,
                                                         strict=True)]


def assert_equal_tracks(got, want) -> None:
    """The same epochs; states to 1e-12 relative, covariances to 1e-9 (their largest term:
    fused with other objects, the vectorised kernels may round the small terms of an
    update's cancellation otherwise than for one object alone)."""
    assert [t for t, _, _ in got] == [t for t, _, _ in want]
    for (_, x, P), (_, wx, wP) in zip(got, want, strict=True):
        assert np.abs(x - wx).max() <= 1e-12 * np.abs(wx).max()
        assert np.abs(P - wP).max() <= 1e-9 * np.abs(wP).max()


def test_each_object_is_tracked_alone_with_the_assumed_settings(rows, tmp_path, capsys):
    """A bag without recorded settings: the catalog_filter's defaults on the stations its
    measurements name, said so."""
    bag = write_bag(tmp_path / "bag", rows)
    out = tmp_path / "off"
    assert cli.main(["replay", str(bag), "--offline", "--out", str(out)]) == 0
    said = capsys.readouterr().out
    assert f"measurements are of {OBJECTS} objects" in said
    assert "assumed" in said and "station altair,millstone,tira" in said
    got = estimates(out)
    assert set(got) == set(rows.object_id) and len(got) == OBJECTS
    params = {**dataclasses.asdict(CATALOG_FILTER), "station": "altair,millstone,tira"}
    for oid in got:
        want = alone(rows, oid, params)
        assert len(want) > 20
        assert_equal_tracks(got[oid], want)
    # the inputs copied, the settings used recorded
    raw = list(bagio.read_bag(out, topics=[TOPIC_MEASUREMENT_BATCH, TOPIC_CONFIG]))
    assert sum(len(m.msg.object_id) for m in raw if m.topic == TOPIC_MEASUREMENT_BATCH) \
        == len(rows)
    used = settings.recorded_catalog(m.msg.data for m in raw if m.topic == TOPIC_CONFIG)
    assert [p["station"] for p in used] == ["altair,millstone,tira"]


def test_recorded_settings_are_used_shard_by_shard(rows, tmp_path, capsys):
    """Two shards of recorded settings other than the defaults (Kepler, 5 IOD samples):
    each object's estimates are those of a bank of those settings, under its shard's key
    range."""
    values = {**dataclasses.asdict(CATALOG_FILTER), "station": "radar_network",
              "motion_model": "kepler", "iod_samples": 5, "shards": 2, "batch_rows": 7}
    config = [settings.catalog_config_message({**values, "shard": k}) for k in (0, 1)]
    bag = write_bag(tmp_path / "bag", rows, config)
    out = tmp_path / "off"
    assert cli.main(["replay", str(bag), "--offline", "--out", str(out)]) == 0
    assert "recorded with the bag (/ssa/config; 2 shard(s))" in capsys.readouterr().out
    got = estimates(out)
    assert len(got) == OBJECTS
    for oid in got:
        assert_equal_tracks(got[oid], alone(rows, oid, values))
    ranges = {messages.shard_range(k, 2) for k in (0, 1)}
    for m in bagio.read_bag(out, topics=[TOPIC_ESTIMATE_BATCH]):
        assert len(m.msg.object_id) <= 7
        lo, hi = m.msg.key_lo, m.msg.key_hi
        assert (lo, hi) in ranges
        assert all(lo <= k <= hi for k in messages.shard_keys(list(m.msg.object_id)))


def test_unlabelled_detections_are_associated_as_the_core_associates_them(rows, tmp_path,
                                                                           capsys):
    bag = write_bag(tmp_path / "bag", without_labels(rows))
    out = tmp_path / "off"
    assert cli.main(["replay", str(bag), "--offline", "--out", str(out)]) == 0
    assert "unlabelled detections" in capsys.readouterr().out
    stations = network_stations("altair,millstone,tira")
    options = settings.filter_options(dataclasses.asdict(CATALOG_FILTER))
    want = RowAssociator(options, stations, elevation_masks(stations)).process(
        without_labels(rows))
    got = [messages.estimate_batch_from_msg(m.msg)
           for m in bagio.read_bag(out, topics=[TOPIC_ESTIMATE_BATCH])]
    assert [o for e in got for o in e.object_id] == want.estimates.object_id
    assert len(want.estimates) > 50
    np.testing.assert_allclose(np.concatenate([e.x for e in got]), want.estimates.x,
                               rtol=1e-12, atol=1e-12)
    kept = sum(len(m.msg.object_id) for m in bagio.read_bag(out, topics=[TOPIC_ASSOCIATED]))
    assert kept == len(want.associated)


def test_report_and_export_read_the_replayed_bag(rows, tmp_path):
    bag = write_bag(tmp_path / "bag", rows)
    out = tmp_path / "off"
    assert cli.main(["replay", str(bag), "--offline", "--out", str(out)]) == 0
    assert cli.main(["report", str(out), "--out", str(tmp_path / "report")]) == 0
    rep = json.loads((tmp_path / "report" / "report.json").read_text())
    assert rep["catalog"] and rep["summary"]["objects_with_estimates"] == OBJECTS
    assert rep["settings"].startswith("recorded with the bag")
    # the bag replayed: its objects' measurements, with the settings a replay assumes
    assert cli.main(["report", str(bag), "--out", str(tmp_path / "report_in")]) == 0
    rep = json.loads((tmp_path / "report_in" / "report.json").read_text())
    assert rep["summary"]["objects"] == OBJECTS and rep["summary"]["estimates"] == 0
    assert rep["settings"].startswith("assumed")
    oem = tmp_path / "x.oem"
    assert cli.main(["export", "oem", str(out), "--out", str(oem)]) == 0
    assert oem.read_text().count("OBJECT_ID") == OBJECTS


def test_single_object_options_are_refused_for_a_catalog_bag(rows, tmp_path, capsys):
    bag = write_bag(tmp_path / "bag", rows)
    for extra in (["--smooth"], ["--scenario", "iss_network"]):
        assert cli.main(["replay", str(bag), "--offline", *extra]) == 2
        err = capsys.readouterr().err
        assert "catalog's bag" in err and extra[0] in err
    assert not (tmp_path / "bag_offline").exists()


def test_objects_the_catalog_filter_cannot_fuse_are_refused_not_mixed(tmp_path, capsys):
    """Right ascension/declination of two objects, one message each: no catalog path, and
    one object's filter would mix them."""
    writer = bagio.BagWriter(tmp_path / "bag")
    writer.add_topic(TOPIC_MEASUREMENT, bagio.MEASUREMENT)
    for i in range(20):
        m = types.Measurement(1.7e9 + 30.0 * i, np.array([0.1 * i, 0.2]), np.eye(2) * 1e-10,
                              types.Kind.RA_DEC, object_id=f"obj{i % 2}", frame_id="columbus")
        writer.write_msg(TOPIC_MEASUREMENT, int(m.t * 1e9), messages.measurement_to_msg(m, C))
    writer.close()
    out = tmp_path / "off"
    assert cli.main(["replay", str(tmp_path / "bag"), "--offline", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "of 2 objects (obj0, obj1)" in err and "ra_dec" in err and "one track" in err
    assert not out.exists()


def test_the_catalog_filter_settings_round_trip_and_stay_apart():
    values = {**dataclasses.asdict(CATALOG_FILTER), "q": 2e-7, "batch_period": 0.5}
    text = settings.catalog_config_message(values)
    assert json.loads(text)["node"] == "catalog_filter"
    back = settings.recorded_catalog([text])
    assert back[0]["q"] == 2e-7 and back[0]["p0_sigma"] == list(CATALOG_FILTER.p0_sigma)
    assert "batch_period" not in json.loads(text)["parameters"]
    # the single-object filter's recorded settings do not take the catalog's
    assert settings.recorded_estimator([text]) is None


def _records(ids: list[str], batched: bool = False) -> list[bagio.BagMessage]:
    """Measurements of `ids`, one a message, or all in one batch (`batched`)."""
    ms = [types.Measurement(1.7e9 + i, np.array([1000.0, 1.0, 0.5]), np.eye(3) * 1e-6,
                            types.Kind.RANGE_AZ_EL, object_id=oid, frame_id="millstone")
          for i, oid in enumerate(ids)]
    if batched:
        rows = MeasurementRows(np.array([m.t for m in ms]), ids, ["millstone"] * len(ms),
                               np.array([m.z for m in ms]), np.array([m.R for m in ms]))
        return [bagio.BagMessage(TOPIC_MEASUREMENT_BATCH, bagio.MEASUREMENT_BATCH, 0,
                                 messages.measurement_batch_to_msg(rows, classes=C))]
    return [bagio.BagMessage(TOPIC_MEASUREMENT, bagio.MEASUREMENT, i,
                             messages.measurement_to_msg(m, C)) for i, m in enumerate(ms)]


def test_what_makes_a_catalog_bag():
    reason = replay_catalog.catalog_reason
    assert reason(_records(["a", "a"])) is None
    assert reason(_records(["a", "a"], batched=True)) is None
    assert reason(_records(["", ""])) is None  # one object, before ids
    assert "2 objects (a, b)" in reason(_records(["a", "b"]))
    assert "unlabelled" in reason(_records(["", ""], batched=True))
    assert "beside those of a" in reason(_records(["a", ""]))
    text = settings.catalog_config_message(dataclasses.asdict(CATALOG_FILTER))
    config = [bagio.BagMessage(TOPIC_CONFIG, "std_msgs/msg/String", 0,
                               bagio.typestore().types["std_msgs/msg/String"](data=text))]
    assert "settings are recorded" in reason(config + _records(["a"]))
