"""MeasurementBatch and EstimateBatch: columns (core units) to messages (SI) and back.

Property-tested: any rows survive the round trip through an rclpy message, its CDR bytes
and a bag's (rosbags) decoding to the bit; each row is what the per-message conversion
gives for the same measurement or estimate; what rosbags writes rclpy reads, and the
reverse."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from ssa_fusion.core.base import types
from ssa_fusion.core.base.rows import EstimateRows, MeasurementRows
from ssa_fusion.ros import bagio, messages

EPOCH = st.floats(0.0, 2.1e9)
FINITE = st.floats(-1e7, 1e7, allow_nan=False)
IDS = st.text(st.characters(exclude_characters="\x00", exclude_categories=("Cs",)), max_size=12)
"""Ids a ROS string carries: UTF-8 text without NUL."""


@st.composite
def measurement_rows(draw: st.DrawFn) -> MeasurementRows:
    m = draw(st.integers(1, 12))  # a publisher sends no empty batch (the messages say why)
    ids = draw(st.lists(IDS, min_size=m, max_size=m))
    return MeasurementRows(
        t=np.array(draw(st.lists(EPOCH, min_size=m, max_size=m)), dtype=float),
        object_id=ids, frame_id=draw(st.lists(IDS, min_size=m, max_size=m)),
        z=draw(hnp.arrays(float, (m, 3), elements=FINITE)),
        R=draw(hnp.arrays(float, (m, 3, 3), elements=FINITE)),
        kind=np.array(draw(st.lists(st.integers(0, 255), min_size=m, max_size=m)), np.uint8),
        source=np.array(draw(st.lists(st.integers(0, 1), min_size=m, max_size=m)), np.uint8),
        horizon=draw(hnp.arrays(float, (m,), elements=FINITE)),
        shard_key=messages.shard_keys(ids))


@st.composite
def estimate_rows(draw: st.DrawFn) -> EstimateRows:
    m = draw(st.integers(1, 8))
    ids = draw(st.lists(IDS, min_size=m, max_size=m))
    return EstimateRows(
        t=np.array(draw(st.lists(EPOCH, min_size=m, max_size=m)), dtype=float), object_id=ids,
        x=draw(hnp.arrays(float, (m, 6), elements=FINITE)),
        P=draw(hnp.arrays(float, (m, 6, 6), elements=FINITE)),
        nis=draw(hnp.arrays(float, (m,), elements=FINITE)),
        update_source=draw(st.sampled_from(types.UpdateSource)),
        shard_key=messages.shard_keys(ids))


def _via_ns(t: np.ndarray) -> np.ndarray:
    """Epochs as they come back: rounded to the ns, as a builtin_interfaces/Time holds them."""
    return messages.ns_to_seconds(messages.stamps_ns(t))


def _same(a: MeasurementRows | EstimateRows, b: MeasurementRows | EstimateRows) -> None:
    for name, va in vars(a).items():
        vb = getattr(b, name)
        if isinstance(va, np.ndarray):
            assert va.shape == vb.shape and va.tobytes() == vb.tobytes(), name  # to the bit
        else:
            assert va == vb, name


def _scaled_back(rows: MeasurementRows) -> MeasurementRows:
    """`rows` after SI and back: z and R multiplied by the kind's scale and divided again."""
    s = np.ones((len(rows), 3))
    for k in types.Kind:
        s[rows.kind == k, :len(messages.z_scale(k))] = messages.z_scale(k)
    ss = s[:, :, None] * s[:, None, :]
    return MeasurementRows(_via_ns(rows.t), rows.object_id, rows.frame_id, rows.z * s / s,
                           rows.R * ss / ss, rows.kind, rows.source, rows.horizon,
                           rows.shard_key)


@settings(max_examples=60, deadline=None)
@given(measurement_rows())
def test_measurement_rows_round_trip_through_rclpy_cdr_and_a_bag(rows):
    from rclpy.serialization import deserialize_message, serialize_message

    from ssa_fusion.ros.interfaces import MeasurementBatch

    msg = messages.measurement_batch_to_msg(rows, (7, 99))
    assert (msg.key_lo, msg.key_hi) == (7, 99) and len(msg.z) == 3 * len(rows)
    cdr = serialize_message(msg)
    back = messages.measurement_batch_from_msg(deserialize_message(cdr, MeasurementBatch))
    _same(back, _scaled_back(rows))
    name = "ssa_fusion_msgs/msg/MeasurementBatch"
    store = bagio.typestore()
    _same(messages.measurement_batch_from_msg(store.deserialize_cdr(cdr, name)), back)
    # and what rosbags writes (a bag written without ROS) rclpy reads as the same rows
    ours = messages.measurement_batch_to_msg(rows, (7, 99), bagio.rosbags_classes())
    _same(messages.measurement_batch_from_msg(
        deserialize_message(bytes(store.serialize_cdr(ours, name)), MeasurementBatch)), back)


@settings(max_examples=40, deadline=None)
@given(estimate_rows())
def test_estimate_rows_round_trip_through_rclpy_cdr_and_a_bag(rows):
    from rclpy.serialization import deserialize_message, serialize_message

    from ssa_fusion.ros.interfaces import EstimateBatch

    cdr = serialize_message(messages.estimate_batch_to_msg(rows))
    back = messages.estimate_batch_from_msg(deserialize_message(cdr, EstimateBatch))
    km2 = messages.KM * messages.KM
    want = EstimateRows(_via_ns(rows.t), rows.object_id, rows.x * messages.KM / messages.KM,
                        rows.P * messages.KM * messages.KM / km2, rows.nis,
                        rows.update_source, rows.shard_key)
    _same(back, want)
    name = "ssa_fusion_msgs/msg/EstimateBatch"
    store = bagio.typestore()
    _same(messages.estimate_batch_from_msg(store.deserialize_cdr(cdr, name)), back)
    ours = messages.estimate_batch_to_msg(rows, classes=bagio.rosbags_classes())
    _same(messages.estimate_batch_from_msg(
        deserialize_message(bytes(store.serialize_cdr(ours, name)), EstimateBatch)), back)


@settings(max_examples=40, deadline=None)
@given(measurement_rows())
def test_each_row_is_what_the_per_message_conversion_gives(rows):
    """Row i of a batch = `measurement_from_msg` of the same measurement as a Measurement."""
    msg = messages.measurement_batch_to_msg(rows)
    back = messages.measurement_batch_from_msg(msg)
    for i in np.flatnonzero(np.isin(rows.kind, list(types.Kind))).tolist():
        k = len(messages.z_scale(rows.kind[i]))
        one = types.Measurement(float(rows.t[i]), rows.z[i, :k], rows.R[i, :k, :k],
                                kind=int(rows.kind[i]), source=int(rows.source[i]),
                                object_id=rows.object_id[i], frame_id=rows.frame_id[i],
                                horizon=float(rows.horizon[i]))
        want = messages.measurement_from_msg(messages.measurement_to_msg(one))
        assert back.t[i] == want.t and back.object_id[i] == want.object_id
        assert back.frame_id[i] == want.frame_id and back.horizon[i] == want.horizon
        assert back.z[i, :k].tobytes() == want.z.tobytes()
        assert back.R[i, :k, :k].tobytes() == want.R.tobytes()
        assert back.shard_key[i] == messages.shard_key(want.object_id)


def test_estimate_rows_are_what_the_per_message_conversion_gives():
    rng = np.random.default_rng(1)
    rows = EstimateRows(np.array([1.75e9, 1.75e9 + 0.123456789]), ["a", "25544"],
                        rng.normal(size=(2, 6)) * 7000.0, rng.normal(size=(2, 6, 6)),
                        np.array([0.5, 3.0]), types.UpdateSource.FORECAST,
                        messages.shard_keys(["a", "25544"]))
    back = messages.estimate_batch_from_msg(messages.estimate_batch_to_msg(rows))
    for i in range(2):
        one = types.StateEstimate(t=float(rows.t[i]), x=rows.x[i], P=rows.P[i],
                                  object_id=rows.object_id[i], nis=float(rows.nis[i]),
                                  update_source=types.UpdateSource.FORECAST)
        want = messages.estimate_from_msg(messages.estimate_to_msg(one))
        assert back.t[i] == want.t and back.object_id[i] == want.object_id
        assert back.x[i].tobytes() == want.x.tobytes() and back.P[i].tobytes() == want.P.tobytes()
        assert back.update_source == want.update_source and back.nis[i] == want.nis


def test_a_batch_whose_columns_disagree_is_one_line_not_a_traceback():
    rows = MeasurementRows(np.array([1.75e9]), ["a"], ["millstone"], np.ones((1, 3)),
                           np.eye(3)[None])
    msg = messages.measurement_batch_to_msg(rows)
    msg.z = msg.z[:2]
    with pytest.raises(ValueError, match="has 2 values in z, expected 3"):
        messages.measurement_batch_from_msg(msg)


def test_an_epoch_a_ros_time_cannot_carry_is_refused_by_name():
    rows = MeasurementRows(np.array([1.75e9, -1.0]), ["a", "b"], ["m", "m"], np.ones((2, 3)),
                           np.zeros((2, 3, 3)))
    with pytest.raises(ValueError, match="cannot be a ROS 2 time"):
        messages.measurement_batch_to_msg(rows)
