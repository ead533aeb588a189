"""The batches read off their CDR bytes (`cdr_rows`) against rosbags' generic decoder."""

from __future__ import annotations

from collections import Counter
from pathlib import Path

import numpy as np
import pytest

from ssa_fusion.core.base.rows import EstimateRows, MeasurementRows
from ssa_fusion.core.base.types import Kind, UpdateSource
from ssa_fusion.ros import bagio, messages
from ssa_fusion.ros.cdr_rows import estimate_batch_columns, measurement_batch_rows
from ssa_fusion.ros.topics import TOPIC_ESTIMATE_BATCH, TOPIC_MEASUREMENT_BATCH

# ids of every padding (lengths 0..7 with the NUL), multi-byte UTF-8 among them
IDS = ["", "a", "25544", "1234567", "LAGEOS-2", "ISS (ZARYA)", "Łódź-1", "x" * 33]


def _serialized(msg: object, msgtype: str, little_endian: bool = True) -> bytes:
    return bytes(bagio.typestore().serialize_cdr(msg, msgtype, little_endian=little_endian))


def _estimates(ids: list[str], frame: str = "gcrf") -> object:
    m = len(ids)
    rng = np.random.default_rng(m)
    rows = EstimateRows(t=1.7e9 + np.arange(m, dtype=float), object_id=ids,
                        x=rng.normal(size=(m, 6)) * 7000.0, P=rng.normal(size=(m, 6, 6)),
                        nis=rng.random(m), update_source=UpdateSource.FORECAST,
                        shard_key=messages.shard_keys(ids))
    msg = messages.estimate_batch_to_msg(rows, (7, 99), bagio.rosbags_classes())
    msg.header.frame_id = frame
    return msg


def _measurements(ids: list[str], frames: list[str]) -> object:
    m = len(ids)
    rows = MeasurementRows(t=1.7e9 + np.arange(m, dtype=float), object_id=ids,
                           frame_id=frames, z=np.ones((m, 3)), R=np.ones((m, 3, 3)),
                           kind=np.full(m, int(Kind.RANGE_AZ_EL), np.uint8),
                           source=np.zeros(m, np.uint8), horizon=np.zeros(m),
                           shard_key=messages.shard_keys(ids))
    return messages.measurement_batch_to_msg(rows, classes=bagio.rosbags_classes())


@pytest.mark.parametrize("little_endian", [True, False])
@pytest.mark.parametrize("ids", [IDS, [], IDS[2:3] * 5], ids=["mixed", "empty", "same"])
@pytest.mark.parametrize("frame", ["", "gcrf", "abcdefg"])
def test_estimate_columns_equal_the_generic_decoding(ids: list[str], frame: str,
                                                     little_endian: bool) -> None:
    msg = _estimates(ids, frame)
    data = _serialized(msg, bagio.ESTIMATE_BATCH, little_endian)
    ref = bagio.typestore().deserialize_cdr(data, bagio.ESTIMATE_BATCH)
    got = estimate_batch_columns(data)
    assert got.object_id == list(ref.object_id) == ids
    assert (got.frame_id, got.update_source, got.key_lo, got.key_hi) == (
        ref.header.frame_id, ref.update_source, ref.key_lo, ref.key_hi)
    assert (got.stamp_sec, got.stamp_nanosec) == (ref.header.stamp.sec, ref.header.stamp.nanosec)
    for name in ("shard_key", "stamp_ns", "state", "covariance", "nis"):
        np.testing.assert_array_equal(getattr(got, name), getattr(ref, name), err_msg=name)
    rows, ref_rows = messages.estimate_batch_from_msg(got), messages.estimate_batch_from_msg(ref)
    np.testing.assert_array_equal(rows.x, ref_rows.x)
    np.testing.assert_array_equal(rows.t, ref_rows.t)


@pytest.mark.parametrize("little_endian", [True, False])
@pytest.mark.parametrize("m", [0, 1, 7])
def test_measurement_rows_count_the_batch(m: int, little_endian: bool) -> None:
    ids = (IDS * 2)[:m]
    msg = _measurements(ids, [f"site{i}" * (i % 3) for i in range(m)])
    for frame in ("", "gcrf", "abc"):  # every alignment of the key words after the header
        msg.header.frame_id = frame
        assert measurement_batch_rows(_serialized(msg, bagio.MEASUREMENT_BATCH,
                                                  little_endian)) == m


def test_bytes_that_are_no_batch_are_refused_as_the_generic_decoder_refuses_them() -> None:
    est = _serialized(_estimates(IDS), bagio.ESTIMATE_BATCH)
    meas = _serialized(_measurements(IDS, IDS), bagio.MEASUREMENT_BATCH)
    for cut in (3, 10, 40, len(est) // 2, len(est) - 1):
        with pytest.raises(ValueError):
            estimate_batch_columns(est[:cut])
        with pytest.raises(Exception):  # noqa: B017 (rosbags raises several types)
            bagio.typestore().deserialize_cdr(est[:cut], bagio.ESTIMATE_BATCH)
    for cut in (3, 10, 30, len(meas) // 2):
        with pytest.raises(ValueError):
            measurement_batch_rows(meas[:cut])
    with pytest.raises(ValueError, match="not plain CDR"):
        measurement_batch_rows(b"\x00\x03\x00\x00" + meas[4:])


def test_a_bag_read_with_the_fast_decoders_gives_the_same_rows(tmp_path: Path) -> None:
    w = bagio.BagWriter(tmp_path / "bag")
    w.add_topic(TOPIC_ESTIMATE_BATCH, bagio.ESTIMATE_BATCH)
    w.add_topic(TOPIC_MEASUREMENT_BATCH, bagio.MEASUREMENT_BATCH)
    w.write_msg(TOPIC_ESTIMATE_BATCH, 1, _estimates(IDS))
    w.write_msg(TOPIC_MEASUREMENT_BATCH, 2, _measurements(IDS, IDS))
    w.write(TOPIC_ESTIMATE_BATCH, 3, b"\x00\x01\x00\x00\x01")  # cut short: undecodable
    w.close()
    undecodable: Counter[str] = Counter()
    got = list(bagio.read_bag(tmp_path / "bag", undecodable=undecodable, decoders={
        TOPIC_MEASUREMENT_BATCH: measurement_batch_rows,
        TOPIC_ESTIMATE_BATCH: estimate_batch_columns}))
    assert [m.topic for m in got] == [TOPIC_ESTIMATE_BATCH, TOPIC_MEASUREMENT_BATCH]
    assert got[0].msg.object_id == IDS and got[1].msg == len(IDS)
    assert undecodable == Counter({TOPIC_ESTIMATE_BATCH: 1})
