"""Bags whose measurements and estimates are recorded as batches (MeasurementBatch,
EstimateBatch) read exactly as if recorded one message each: the same run written once as
single messages and once as batches gives `report` (its numbers and visual.mcap, the
Foxglove bridge's topics of the bag), `replay --offline`, `export oem` and `export tdm` the
same output, to the bit; a bag of both gives the union; rows no reader takes are refused by
cause and counted as single messages are."""

from __future__ import annotations

import copy
import json
import math
from collections import Counter
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

from ssa_fusion.apps import cli, evaluate, report, visual_mcap
from ssa_fusion.core.base import types
from ssa_fusion.core.base.rows import EstimateRows, MeasurementRows
from ssa_fusion.core.base.types import Cause
from ssa_fusion.core.earth.stations import network_stations
from ssa_fusion.formats.ccsds import oem as ccsds_oem
from ssa_fusion.formats.ccsds import tdm_out as ccsds_tdm_out
from ssa_fusion.ros import bagio, messages
from ssa_fusion.ros.topics import (
    TOPIC_ESTIMATE,
    TOPIC_ESTIMATE_BATCH,
    TOPIC_MEASUREMENT,
    TOPIC_MEASUREMENT_BATCH,
)

SAMPLE = Path(__file__).resolve().parents[2] / "bags" / "sample_iss_j2_rae"
C = bagio.rosbags_classes()
BATCHED = {TOPIC_MEASUREMENT: TOPIC_MEASUREMENT_BATCH, TOPIC_ESTIMATE: TOPIC_ESTIMATE_BATCH}
ROWS = 7
"""Rows a batch at most: the sample's measurements and estimates go out in groups of up to
ROWS consecutive messages (an estimate group: of one update source), each group at the log
time of its last message, as single messages or as one batch."""


def _groups(stream: list[bagio.BagMessage], batched: frozenset[str]
            ) -> Iterator[list[bagio.BagMessage]]:
    """The messages of `stream` in order, those of `batched` topics gathered into groups."""
    open_: dict[str, list[bagio.BagMessage]] = {}
    for m in stream:
        if m.topic not in batched:
            yield [m]
            continue
        group = open_.setdefault(m.topic, [])
        if group and (len(group) == ROWS or (
                m.topic == TOPIC_ESTIMATE
                and group[0].msg.update_source != m.msg.update_source)):
            yield group
            group = open_[m.topic] = []
        group.append(m)
    yield from (g for g in open_.values() if g)


def _batch(topic: str, group: list[bagio.BagMessage]):
    """The batch of `group`'s messages, made as the catalog nodes make theirs."""
    if topic == TOPIC_MEASUREMENT:
        ms = [messages.measurement_from_msg(m.msg) for m in group]
        ids = [m.object_id for m in ms]
        rows = MeasurementRows(
            np.array([m.t for m in ms]), ids, [m.frame_id for m in ms],
            np.array([m.z for m in ms]), np.array([m.R for m in ms]),
            np.array([m.kind for m in ms], np.uint8), np.array([m.source for m in ms], np.uint8),
            np.array([m.horizon for m in ms]), messages.shard_keys(ids))
        return messages.measurement_batch_to_msg(rows, classes=C)
    es = [messages.estimate_from_msg(m.msg) for m in group]
    ids = [e.object_id for e in es]
    rows = EstimateRows(np.array([e.t for e in es]), ids, np.array([e.x for e in es]),
                        np.array([e.P for e in es]), np.array([e.nis for e in es]),
                        types.UpdateSource(es[0].update_source), messages.shard_keys(ids))
    msg = messages.estimate_batch_to_msg(rows, classes=C)
    msg.header.frame_id = group[0].msg.header.frame_id  # "gcrf", or a legacy bag's "eci"
    return msg


def record(stream: list[bagio.BagMessage], bag: Path, batches: bool,
           batched: frozenset[str] = frozenset(BATCHED)) -> Path:
    """Write `stream` to `bag`, the messages of `batched` topics grouped (`ROWS`), each group
    one batch (`batches`) or its messages, at the group's last log time; the measurements
    and estimates (single or in batches) made by the nodes' conversions from core values."""
    writer = bagio.BagWriter(bag)
    for m in stream:
        if m.topic in batched and batches:
            writer.add_topic(BATCHED[m.topic], f"ssa_fusion_msgs/msg/{_batch_type(m.topic)}")
        else:
            writer.add_topic(m.topic, m.msgtype)
    for group in _groups(stream, batched):
        topic, t_ns = group[0].topic, group[-1].t_ns
        if topic not in batched:
            writer.write_msg(topic, t_ns, group[0].msg)
        elif batches:
            writer.write_msg(BATCHED[topic], t_ns, _batch(topic, group))
        else:
            for m in sorted(group, key=lambda m: messages.stamp_to_seconds(m.msg.header.stamp)):
                writer.write_msg(topic, t_ns, _single(m))
    writer.close()
    return bag


def _batch_type(topic: str) -> str:
    return "MeasurementBatch" if topic == TOPIC_MEASUREMENT else "EstimateBatch"


def _single(m: bagio.BagMessage):
    """`m` as the single-object nodes make it, from its core value."""
    if m.topic == TOPIC_MEASUREMENT:
        return messages.measurement_to_msg(messages.measurement_from_msg(m.msg), C)
    msg = messages.estimate_to_msg(messages.estimate_from_msg(m.msg), C)
    msg.header.frame_id = m.msg.header.frame_id
    return msg


SKIP_H = 13.5
"""Hours of the sample's start left out (it keeps the outage, 15.5 to 17 h, and the passes
before it): the tests' time."""


@pytest.fixture(scope="module")
def sample() -> list[bagio.BagMessage]:
    """The sample bag from `SKIP_H` h on (and its settings)."""
    stream = list(bagio.read_bag(SAMPLE))
    start = stream[0].t_ns + int(SKIP_H * 3600e9)
    return [m for m in stream if m.t_ns >= start or m.topic == "/ssa/config"]


@pytest.fixture(scope="module")
def bags(sample, tmp_path_factory) -> tuple[Path, Path]:
    d = tmp_path_factory.mktemp("batches")
    return record(sample, d / "single", False), record(sample, d / "batch", True)


def _same(a: object, b: object, what: str = "") -> None:
    """Equal to the bit: dataclasses field by field, arrays by their bytes."""
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        a, b = np.asarray(a), np.asarray(b)
        assert a.dtype == b.dtype and a.shape == b.shape and a.tobytes() == b.tobytes(), what
    elif isinstance(a, list | tuple):
        assert len(a) == len(b), what
        for i, (x, y) in enumerate(zip(a, b, strict=True)):
            _same(x, y, f"{what}[{i}]")
    elif hasattr(a, "__dataclass_fields__"):
        assert type(a) is type(b), what
        for name in a.__dataclass_fields__:
            _same(getattr(a, name), getattr(b, name), f"{what}.{name}")
    else:
        assert a == b, what


def test_a_batch_bag_holds_batches_and_reads_as_its_rows(bags):
    single, batch = bags
    raw = Counter(m.topic for m in bagio.read_bag(batch))
    assert raw[TOPIC_MEASUREMENT_BATCH] and raw[TOPIC_ESTIMATE_BATCH]
    assert not raw[TOPIC_MEASUREMENT] and not raw[TOPIC_ESTIMATE]
    a, b = list(bagio.read_records(single)), list(bagio.read_records(batch))
    assert [(m.topic, m.msgtype, m.t_ns) for m in a] == [(m.topic, m.msgtype, m.t_ns) for m in b]
    for x, y in zip(a, b, strict=True):  # the same message, to the byte of its CDR
        assert (bagio.typestore().serialize_cdr(x.msg, x.msgtype)
                == bagio.typestore().serialize_cdr(y.msg, y.msgtype))
    only = list(bagio.read_records(batch, topics=[TOPIC_MEASUREMENT]))
    assert {m.topic for m in only} == {TOPIC_MEASUREMENT}
    assert len(only) == sum(len(m.msg.object_id)
                            for m in bagio.read_bag(batch, [TOPIC_MEASUREMENT_BATCH]))


def test_report_and_its_foxglove_topics_are_the_same(sample, bags, tmp_path):
    data = [evaluate.load(bag) for bag in bags]
    _same(data[0], data[1], "BagData")
    # rows, under the message topic
    assert data[1].counts[TOPIC_MEASUREMENT] == sum(m.topic == TOPIC_MEASUREMENT for m in sample)
    evs = [evaluate.evaluate(d, "") for d in data]
    assert (json.dumps(report.summary(data[0], evs[0]))
            == json.dumps(report.summary(data[1], evs[1])))
    assert evaluate.table(evs[0]) == evaluate.table(evs[1])
    stations = network_stations("columbus")
    files = [tmp_path / f"{bag.name}.mcap" for bag in bags]
    counts = [visual_mcap.write(d, f, stations) for d, f in zip(data, files, strict=True)]
    assert counts[0] == counts[1] and counts[0]["/ssa/foxglove/metrics"] > 300
    assert files[0].read_bytes() == files[1].read_bytes()


def test_replay_offline_gives_the_same_bag(bags, tmp_path, capsys):
    outs = [tmp_path / f"{bag.name}_offline" for bag in bags]
    for bag, out in zip(bags, outs, strict=True):
        assert cli.main(["replay", str(bag), "--offline", "--out", str(out)]) == 0
    said = capsys.readouterr().out.replace(str(bags[1]), str(bags[0]))
    lines = said.replace(str(outs[1]), str(outs[0])).splitlines()
    assert lines[:len(lines) // 2] == lines[len(lines) // 2:]
    a, b = (list(bagio.read_bag(out)) for out in outs)
    assert sum(m.topic == TOPIC_ESTIMATE for m in a) > 300
    assert [(m.topic, m.t_ns) for m in a] == [(m.topic, m.t_ns) for m in b]
    store = bagio.typestore()
    assert all(store.serialize_cdr(x.msg, x.msgtype) == store.serialize_cdr(y.msg, y.msgtype)
               for x, y in zip(a, b, strict=True))


@pytest.mark.parametrize("what", ["oem", "tdm"])
def test_export_gives_the_same_file(bags, tmp_path, monkeypatch, capsys, what):
    for module in (ccsds_oem, ccsds_tdm_out):
        monkeypatch.setattr(module, "creation_date", lambda: "2026-01-01T00:00:00")
    files = [tmp_path / f"{bag.name}.{what}" for bag in bags]
    for bag, f in zip(bags, files, strict=True):
        assert cli.main(["export", what, str(bag), "--out", str(f)]) == 0
    assert files[0].read_text() == files[1].read_text()
    assert len(files[0].read_text()) > 30_000


def test_a_bag_of_singles_and_batches_gives_their_union(sample, bags, tmp_path):
    """Measurements one message each, estimates in batches: the same records."""
    mixed = record(sample, tmp_path / "mixed_a", True, batched=frozenset({TOPIC_ESTIMATE}))
    topics = Counter(m.topic for m in bagio.read_bag(mixed))
    assert topics[TOPIC_MEASUREMENT] and topics[TOPIC_ESTIMATE_BATCH]
    _same(evaluate.load(mixed), evaluate.load(bags[0]), "BagData")
    # one stream in both forms, in turns: the rows and messages come in stamp order
    half = [m for m in sample if m.topic == TOPIC_MEASUREMENT]
    turns = [half[i::2] for i in range(2)]
    writer = bagio.BagWriter(tmp_path / "mixed_b")
    writer.add_topic(TOPIC_MEASUREMENT, bagio.MEASUREMENT)
    writer.add_topic(TOPIC_MEASUREMENT_BATCH, bagio.MEASUREMENT_BATCH)
    for k in range(0, len(half) - 1, 2):
        writer.write_msg(TOPIC_MEASUREMENT, turns[0][k // 2].t_ns, _single(turns[0][k // 2]))
        writer.write_msg(TOPIC_MEASUREMENT_BATCH, turns[1][k // 2].t_ns,
                         _batch(TOPIC_MEASUREMENT, [turns[1][k // 2]]))
    writer.close()
    got = evaluate.load(tmp_path / "mixed_b").measurements
    t = [m.t for m in got]
    assert len(got) == 2 * (len(half) // 2) and t == sorted(t)
    _same(got, evaluate.load(bags[0]).measurements[:len(got)], "measurements")


def _bad_rows() -> tuple[list[types.Measurement], list[tuple[str, str]]]:
    """Good measurements with bad ones among them, and what each bad one is refused for
    where (at reading, or by the filter)."""
    good = [messages.measurement_from_msg(m.msg)
            for m in bagio.read_bag(SAMPLE, [TOPIC_MEASUREMENT])][:60]
    ms = copy.deepcopy(good)
    ms[20].z = np.array([ms[20].z[0], math.nan, ms[20].z[2]])
    ms[30].kind = 9
    ms[40].z = np.array([-5.0, *ms[40].z[1:]])
    return ms, [(Cause.REJECTED_NONFINITE, "filter"), (Cause.REJECTED_KIND, "read"),
                (Cause.REJECTED_NEGATIVE_RANGE, "filter")]


def _measurement_bag(path: Path, ms: list[types.Measurement], batches: bool,
                     malformed: bool = False) -> Path:
    """`ms` on /ssa/measurement, one a message at its stamp, or in batches of 10 each at
    its last stamp; `malformed`: one more batch whose columns disagree."""
    writer = bagio.BagWriter(path)
    if not batches:
        writer.add_topic(TOPIC_MEASUREMENT, bagio.MEASUREMENT)
        for m in ms:
            msg = messages.measurement_to_msg(m, C) if m.kind != 9 else _kind9(m)
            writer.write_msg(TOPIC_MEASUREMENT, round(m.t * 1e9), msg)
        writer.close()
        return path
    writer.add_topic(TOPIC_MEASUREMENT_BATCH, bagio.MEASUREMENT_BATCH)
    for i in range(0, len(ms), 10):
        part = ms[i:i + 10]
        ids = [m.object_id for m in part]
        rows = MeasurementRows(
            np.array([m.t for m in part]), ids, [m.frame_id for m in part],
            np.array([m.z for m in part]), np.array([m.R for m in part]),
            np.array([m.kind for m in part], np.uint8), shard_key=messages.shard_keys(ids))
        writer.write_msg(TOPIC_MEASUREMENT_BATCH, round(part[-1].t * 1e9),
                         messages.measurement_batch_to_msg(rows, classes=C))
    if malformed:
        msg = messages.measurement_batch_to_msg(rows, classes=C)
        msg.horizon = msg.horizon[:-1]
        writer.write_msg(TOPIC_MEASUREMENT_BATCH, round(ms[-1].t * 1e9) + 1, msg)
    writer.close()
    return path


def _kind9(m: types.Measurement):
    """A Measurement message of kind 9 (no kind the core knows), else as `m`."""
    msg = messages.measurement_to_msg(types.Measurement(
        m.t, m.z, m.R, types.Kind.RANGE_AZ_EL, m.source, m.object_id, m.frame_id), C)
    msg.kind = 9
    return msg


def test_bad_rows_are_refused_by_cause_and_counted_as_single_messages_are(tmp_path, capsys):
    ms, why = _bad_rows()
    single = _measurement_bag(tmp_path / "single", ms, False)
    batch = _measurement_bag(tmp_path / "batch", ms, True, malformed=True)
    refused: dict[Path, Counter] = {}
    for bag in (single, batch):
        refused[bag] = Counter()
        got = list(bagio.read_records(bag, refused=refused[bag]))
        assert len(got) == len(ms) - 1  # the measurement of kind 9 is refused at reading
    assert refused[single] == {(TOPIC_MEASUREMENT, Cause.REJECTED_KIND): 1}
    assert refused[batch] == {(TOPIC_MEASUREMENT_BATCH, Cause.REJECTED_KIND): 1,
                              (TOPIC_MEASUREMENT_BATCH, Cause.REJECTED_MALFORMED): 10}
    data = [evaluate.load(bag) for bag in (single, batch)]
    err = capsys.readouterr().err
    assert "1 message(s) on /ssa/measurement refused (rejected_kind" in err
    assert "1 row(s) of batches on /ssa/measurement_batch refused (rejected_kind" in err
    assert "10 row(s) of batches on /ssa/measurement_batch refused (rejected_malformed" in err
    assert data[0].counts["rejected_kind /ssa/measurement"] == 1
    assert data[1].counts["rejected_malformed /ssa/measurement_batch"] == 10
    _same(data[0].measurements, data[1].measurements, "measurements")
    # what the readers refuse of single messages, they refuse of rows: the filter's causes
    from ssa_fusion.apps import replay
    results = []
    for bag in (single, batch):
        stream = list(bagio.read_records(bag))
        results.append(replay.replay_offline(stream, replay.settings(stream).estimator))
    for cause, where in why:
        if where == "filter":
            assert results[0].rejected.get(cause) == results[1].rejected.get(cause) == 1
    _same([e for _, e in results[0].estimates], [e for _, e in results[1].estimates])
    assert cli.main(["export", "tdm", str(batch), "--out", str(tmp_path / "b.tdm")]) == 0
    assert "refused (rejected_kind" in capsys.readouterr().err


def test_rows_of_epochs_no_ros_time_carries_are_refused():
    rows = MeasurementRows(np.array([1e9, 2e9, 3e9]), ["a", "b", "c"], ["x", "y", "z"],
                           np.ones((3, 3)), np.tile(np.eye(3), (3, 1, 1)))
    msg = messages.measurement_batch_to_msg(rows.take(np.array([0, 1, 1])), classes=C)
    msg.stamp_ns = np.array([int(1e18), -5, int(2**31 * 1e9)], np.int64)  # 2001, 1969, 2038
    refused: Counter = Counter()
    got = bagio.batch_records(bagio.BagMessage("/b", bagio.MEASUREMENT_BATCH, 7, msg), refused)
    assert [m.msg.header.stamp.sec for m in got] == [10**9] and got[0].t_ns == 7
    assert refused == {("/b", Cause.REJECTED_MALFORMED): 2}


def test_legacy_frames_of_batches_are_said_as_of_single_messages(sample, tmp_path, capsys):
    """A bag whose estimates say frame "eci" (recorded before the GCRF): batches carry it
    in their header, and the readers that refuse or note it do so for batches too."""
    legacy = copy.deepcopy([m for m in sample if m.topic != "/ssa/truth"][:3000])
    for m in legacy:
        if m.topic == TOPIC_ESTIMATE:
            m.msg.header.frame_id = "eci"
    bag = record(legacy, tmp_path / "eci", True)
    assert {m.msg.header.frame_id for m in bagio.read_bag(bag, [TOPIC_ESTIMATE_BATCH])} == {"eci"}
    assert evaluate.load(bag).frames == {"eci"}
    assert cli.main(["export", "oem", str(bag), "--out", str(tmp_path / "x.oem")]) == 2
    assert "say frame 'eci'" in capsys.readouterr().err
    assert cli.main(["replay", str(bag), "--offline", "--out", str(tmp_path / "o")]) == 2
    assert "in frame 'eci'" in capsys.readouterr().err


def test_the_reading_layer_names_the_topics_of_ros_topics():
    """`bagio` (no rclpy) spells the topic names out; they are those of `ros.topics`."""
    assert bagio.BATCH_TOPICS == BATCHED
    assert {t for t, _ in bagio.ROW_TOPICS.values()} == set(BATCHED)
