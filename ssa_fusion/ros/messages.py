"""The one place where messages (SI: m, m/s, rad) meet core types (km, km/s, rad).

Every node and every bag tool converts through these functions, so a unit or layout change
happens here and nowhere else. Conversions *from* messages accept any object with the
message's fields (rclpy messages, rosbags-deserialized ones); conversions *to* messages
build rclpy messages by default, or the classes of another implementation (`MsgClasses`,
e.g. `bagio.ROSBAGS_CLASSES` for writing bags without ROS).
"""

from __future__ import annotations

import array
import zlib
from collections.abc import Sized
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from ssa_fusion.core.base import types
from ssa_fusion.core.base.rows import EstimateRows, MeasurementRows
from ssa_fusion.core.earth import timescales
from ssa_fusion.core.earth.frames import Frame
from ssa_fusion.core.earth.timescales import EPOCH_MAX, iso
from ssa_fusion.core.measure.troposphere import MeteoSample

if TYPE_CHECKING:  # the message packages are imported when first needed (`rclpy_classes`)
    from ssa_fusion.core.conjunction.watch import WatchUpdate
    from ssa_fusion.ros.interfaces import Message

KM = 1000.0
"""m per km."""
HPA = 100.0
"""Pa per hPa (mbar)."""

# Per-component scale from core units to SI for each measurement kind.
_Z_SCALE = {
    types.Kind.POSITION: np.array([KM, KM, KM]),
    types.Kind.RANGE_AZ_EL: np.array([KM, 1.0, 1.0]),
    types.Kind.RA_DEC: np.array([1.0, 1.0]),
    types.Kind.LASER_RANGE: np.array([KM]),
}
_X_SCALE = np.full(6, KM)
# The same per row of a batch: row k is the scale of kind k (a kind unknown to the core
# keeps scale 1: the consumer refuses it by kind).
_Z_SCALE_ROWS = np.ones((256, 3))
for _kind, _scale in _Z_SCALE.items():
    _Z_SCALE_ROWS[_kind, :len(_scale)] = _scale

KEY_SPACE = 2**32
"""Values of ``shard_key`` (uint32)."""
ALL_KEYS = (0, KEY_SPACE - 1)
"""The key range of a batch that may hold any object's rows."""
NS = 1_000_000_000
"""ns per s."""


@dataclass(frozen=True)
class MsgClasses:
    """Constructors of builtin_interfaces/Time, std_msgs/Header and the messages.

    `numpy_arrays`: whether the classes take numeric sequences as numpy arrays (rosbags)
    rather than as ``array.array`` (rclpy).
    """

    time: type[Message]
    header: type[Message]
    measurement: type[Message]
    estimate: type[Message]
    measurement_batch: type[Message]
    estimate_batch: type[Message]
    numpy_arrays: bool = False
    meteo: type[Message] | None = None
    conjunction_batch: type[Message] | None = None


def rclpy_classes() -> MsgClasses:
    """Return the rclpy message classes (imported on the first call)."""
    from ssa_fusion.ros.interfaces import (
        ConjunctionBatch,
        EstimateBatch,
        Header,
        Measurement,
        MeasurementBatch,
        Meteo,
        StateEstimate,
        Time,
    )

    return MsgClasses(Time, Header, Measurement, StateEstimate, MeasurementBatch,
                      EstimateBatch, meteo=Meteo, conjunction_batch=ConjunctionBatch)


_RCLPY: MsgClasses | None = None


def _default(classes: MsgClasses | None) -> MsgClasses:
    """Return `classes`, or the rclpy classes when None."""
    global _RCLPY
    if classes is not None:
        return classes
    if _RCLPY is None:
        _RCLPY = rclpy_classes()
    return _RCLPY


def stamp_to_seconds(stamp: Message) -> float:
    """Return a builtin_interfaces/Time in float seconds (`timescales.stamp_seconds`)."""
    return timescales.stamp_seconds(stamp.sec, stamp.nanosec)


def seconds_to_stamp(t: float, classes: MsgClasses | None = None) -> Message:
    """Return float seconds (>= 0) as a builtin_interfaces/Time, rounded to the nanosecond.

    ValueError for a stamp a ROS 2 Time cannot carry (negative, not finite, or beyond its
    int32 seconds, 2038-01-19): never a wrapped stamp.
    """
    if not 0.0 <= t <= EPOCH_MAX:
        raise ValueError(f"stamp {iso(t)} cannot be a ROS 2 time (0 .. {iso(EPOCH_MAX)})")
    ns = round(float(t) * 1e9)
    return _default(classes).time(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)


def z_scale(kind: int) -> np.ndarray:
    """Return the scale from core units to SI of measurement `kind` (ValueError: unknown)."""
    try:
        return _Z_SCALE[types.Kind(kind)]
    except (KeyError, ValueError):
        raise ValueError(
            f"unknown measurement kind {kind} (expected "
            + ", ".join(f"{k.value}={k.name}" for k in types.Kind) + ")"
        ) from None


def measurement_to_msg(m: types.Measurement, classes: MsgClasses | None = None) -> Message:
    """Return core Measurement `m` (km) as an ssa_fusion_msgs/Measurement (m).

    A two-channel kind (RA_DEC) fills z[:2] and the covariance's upper-left 2x2; the rest is 0.
    """
    c = _default(classes)
    s = z_scale(m.kind)
    k = len(s)
    z = np.zeros(3)
    z[:k] = np.asarray(m.z, dtype=float) * s
    cov = np.zeros((3, 3))
    cov[:k, :k] = np.asarray(m.R, dtype=float) * np.outer(s, s)
    return c.measurement(
        header=c.header(stamp=seconds_to_stamp(m.t, c), frame_id=m.frame_id),
        object_id=m.object_id,
        kind=int(m.kind),
        source=int(m.source),
        z=z,
        covariance=cov.ravel(),
        horizon=float(m.horizon),
        shard_key=shard_key(m.object_id),
    )


def recode(msg: Message, msgtype: str, classes: MsgClasses | None = None) -> Message:
    """Return a message read from a bag as the current version of its type.

    A Measurement or StateEstimate of any version of the types goes through the core types:
    fields newer than the bag (e.g. ``shard_key``) are filled in. Messages of other types
    (the batches included: they are of their first version) are returned as they are.
    """
    if msgtype == "ssa_fusion_msgs/msg/Measurement":
        return measurement_to_msg(measurement_from_msg(msg), classes)
    if msgtype == "ssa_fusion_msgs/msg/StateEstimate":
        return estimate_to_msg(estimate_from_msg(msg), classes)
    if msgtype == "ssa_fusion_msgs/msg/Meteo":
        return meteo_to_msg(meteo_from_msg(msg), classes)
    return msg


class _KeyCache(dict[str, int]):
    """object_id -> shard_key, computed on the first lookup of an id."""

    def __missing__(self, object_id: str) -> int:
        key = shard_key(object_id)
        if len(self) < _KEY_CACHE_MAX:
            self[object_id] = key
        return key


_KEY_CACHE_MAX = 1_000_000
_KEYS = _KeyCache()


def shard_range(shard: int, shards: int) -> tuple[int, int]:
    """Return the closed range [lo, hi] of shard keys shard `shard` of `shards` owns."""
    lo = shard * KEY_SPACE // shards
    return lo, (shard + 1) * KEY_SPACE // shards - 1


def shard_keys(object_ids: list[str]) -> NDArray[np.uint32]:
    """Return the `shard_key` of every id of `object_ids` (M,), each id's computed once.

    A catalog's ids repeat from batch to batch: a cache of up to a million ids makes this a
    dictionary lookup per row, in C (no Python loop).
    """
    return np.fromiter(map(_KEYS.__getitem__, object_ids), np.uint32, len(object_ids))


def shard_key(object_id: str) -> int:
    """Return the ``shard_key`` of `object_id` (Measurement and StateEstimate messages).

    The CRC-32 of its UTF-8 bytes (0 .. 2**32 - 1), the same on every machine and in every
    process (unlike `hash`).
    """
    return zlib.crc32(object_id.encode("utf-8"))


def measurement_from_msg(msg: Message) -> types.Measurement:
    """Return a Measurement message (m) as a core Measurement (km); ValueError: unknown kind.

    A two-channel kind (RA_DEC) takes z[:2] and the covariance's upper-left 2x2.
    """
    s = z_scale(msg.kind)
    k = len(s)
    return types.Measurement(
        t=stamp_to_seconds(msg.header.stamp),
        z=np.asarray(msg.z, dtype=float)[:k] / s,
        R=np.asarray(msg.covariance, dtype=float).reshape(3, 3)[:k, :k] / np.outer(s, s),
        kind=int(msg.kind),
        source=int(msg.source),
        object_id=msg.object_id,
        frame_id=msg.header.frame_id,
        horizon=float(msg.horizon),
    )


def meteo_to_msg(m: MeteoSample, classes: MsgClasses | None = None) -> Message:
    """Return core `MeteoSample` `m` (hPa, K, %) as an ssa_fusion_msgs/Meteo (Pa, K, 0..1)."""
    c = _default(classes)
    if c.meteo is None:
        raise ValueError("these message classes have no ssa_fusion_msgs/Meteo")
    return c.meteo(header=c.header(stamp=seconds_to_stamp(m.t, c), frame_id=m.station),
                   pressure=float(m.pressure_hpa) * HPA,
                   temperature=float(m.temperature_k),
                   relative_humidity=float(m.humidity_pct) / 100.0)


def meteo_from_msg(msg: Message) -> MeteoSample:
    """Return a Meteo message (Pa, K, 0..1) as a core `MeteoSample` (hPa, K, %)."""
    return MeteoSample(t=stamp_to_seconds(msg.header.stamp), station=str(msg.header.frame_id),
                       pressure_hpa=float(msg.pressure) / HPA,
                       temperature_k=float(msg.temperature),
                       humidity_pct=float(msg.relative_humidity) * 100.0)


def estimate_to_msg(e: types.StateEstimate, classes: MsgClasses | None = None) -> Message:
    """Return core StateEstimate `e` (km, km/s) as an ssa_fusion_msgs/StateEstimate (m, m/s).

    The message holds the orbit: a filter's further states (a laser filter's range biases
    and k_R after ``[r, v]``) stay out of it.
    """
    c = _default(classes)
    return c.estimate(
        header=c.header(stamp=seconds_to_stamp(e.t, c), frame_id=Frame.GCRF),
        object_id=e.object_id,
        state=np.asarray(e.x, dtype=float)[:6] * _X_SCALE,
        covariance=(np.asarray(e.P, dtype=float)[:6, :6] * KM * KM).ravel(),
        update_source=int(e.update_source),
        nis=float(e.nis),
        shard_key=shard_key(e.object_id),
    )


def estimate_from_msg(msg: Message) -> types.StateEstimate:
    """Return a StateEstimate message (m, m/s) as a core StateEstimate (km, km/s)."""
    return types.StateEstimate(
        t=stamp_to_seconds(msg.header.stamp),
        x=np.asarray(msg.state, dtype=float) / _X_SCALE,
        P=np.asarray(msg.covariance, dtype=float).reshape(6, 6) / (KM * KM),
        object_id=msg.object_id,
        update_source=int(msg.update_source),
        nis=float(msg.nis),
    )


def _column(values: NDArray[Any], code: str, classes: MsgClasses) -> object:
    """Return a numeric column as the message classes take it.

    An ``array.array`` of type `code` (rclpy: no check or copy per element) or a numpy
    array (rosbags).
    """
    flat = np.ascontiguousarray(values).ravel()
    return flat if classes.numpy_arrays else array.array(code, flat.tobytes())


def stamps_ns(t: NDArray[np.float64]) -> NDArray[np.int64]:
    """Return epochs `t` (s) as int64 ns, rounded as `seconds_to_stamp` rounds.

    ValueError naming the first epoch a ROS 2 Time cannot carry (negative, not finite, or
    beyond 2038-01-19), as `seconds_to_stamp`.
    """
    t = np.asarray(t, dtype=float)
    bad = ~((t >= 0.0) & (t <= EPOCH_MAX))
    if bad.any():
        seconds_to_stamp(float(t[np.argmax(bad)]))  # raises, naming it
    return np.rint(t * 1e9).astype(np.int64)


def ns_to_seconds(ns: NDArray[np.int64]) -> NDArray[np.float64]:
    """Return int64 ns since the Unix epoch as float s, as `stamp_to_seconds` computes them."""
    ns = np.asarray(ns, dtype=np.int64)
    sec = ns // NS
    out: NDArray[np.float64] = sec.astype(float) + (ns - sec * NS).astype(float) * 1e-9
    return out


def _header(classes: MsgClasses, t: NDArray[np.float64], frame_id: str) -> Message:
    """Return the header of a batch: stamp its last epoch (0 when empty), `frame_id`."""
    last = float(t.max()) if len(t) else 0.0
    return classes.header(stamp=seconds_to_stamp(last, classes), frame_id=frame_id)


def measurement_batch_to_msg(rows: MeasurementRows, key_range: tuple[int, int] = ALL_KEYS,
                             classes: MsgClasses | None = None) -> Message:
    """Return `rows` (core units) as an ssa_fusion_msgs/MeasurementBatch (SI).

    `key_range`: the closed range of shard keys of the rows (``key_lo``, ``key_hi``). The
    rows' shard_key is what `rows` holds: `shard_keys` computes it. ValueError for an epoch
    a ROS 2 Time cannot carry.
    """
    c = _default(classes)
    s = _Z_SCALE_ROWS[rows.kind]
    return c.measurement_batch(
        header=_header(c, rows.t, ""), key_lo=int(key_range[0]), key_hi=int(key_range[1]),
        object_id=list(rows.object_id),
        shard_key=_column(rows.shard_key.astype(np.uint32), "I", c),
        kind=_column(rows.kind.astype(np.uint8), "B", c),
        source=_column(rows.source.astype(np.uint8), "B", c),
        frame_id=list(rows.frame_id),
        stamp_ns=_column(stamps_ns(rows.t), "q", c),
        z=_column(rows.z * s, "d", c),
        covariance=_column(rows.R * (s[:, :, None] * s[:, None, :]), "d", c),
        horizon=_column(rows.horizon.astype(float), "d", c))


def measurement_batch_copy(msg: Message, classes: MsgClasses | None = None) -> Message:
    """Return a MeasurementBatch (of any message classes) as one of `classes`, column by column.

    The values as they are (SI, no conversion): a recorded batch played again is the batch
    that was published, to the bit.
    """
    c = _default(classes)
    h = msg.header
    return c.measurement_batch(
        header=c.header(stamp=c.time(sec=int(h.stamp.sec), nanosec=int(h.stamp.nanosec)),
                        frame_id=str(h.frame_id)),
        key_lo=int(msg.key_lo), key_hi=int(msg.key_hi), object_id=list(msg.object_id),
        shard_key=_column(np.asarray(msg.shard_key, np.uint32), "I", c),
        kind=_column(np.asarray(msg.kind, np.uint8), "B", c),
        source=_column(np.asarray(msg.source, np.uint8), "B", c),
        frame_id=list(msg.frame_id),
        stamp_ns=_column(np.asarray(msg.stamp_ns, np.int64), "q", c),
        z=_column(np.asarray(msg.z, np.float64), "d", c),
        covariance=_column(np.asarray(msg.covariance, np.float64), "d", c),
        horizon=_column(np.asarray(msg.horizon, np.float64), "d", c))


def measurement_batch_from_msg(msg: Message) -> MeasurementRows:
    """Return an ssa_fusion_msgs/MeasurementBatch (SI) as `MeasurementRows` (core units).

    ValueError (one line) when its columns do not all have the same number of rows. Each
    row is what `measurement_from_msg` gives for the same Measurement, to the bit (RA_DEC:
    z and R keep 3 channels, the third 0).
    """
    m = len(msg.object_id)
    kind = np.asarray(msg.kind, dtype=np.uint8)
    source = np.asarray(msg.source, dtype=np.uint8)
    key = np.asarray(msg.shard_key, dtype=np.uint32)
    ns = np.asarray(msg.stamp_ns, dtype=np.int64)
    z = np.asarray(msg.z, dtype=float)
    cov = np.asarray(msg.covariance, dtype=float)
    horizon = np.asarray(msg.horizon, dtype=float)
    _check_rows(m, {"shard_key": key, "kind": kind, "source": source, "frame_id": msg.frame_id,
                    "stamp_ns": ns, "z": z, "covariance": cov, "horizon": horizon},
                {"z": 3, "covariance": 9})
    s = _Z_SCALE_ROWS[kind]
    return MeasurementRows(
        t=ns_to_seconds(ns), object_id=list(msg.object_id), frame_id=list(msg.frame_id),
        z=z.reshape(m, 3) / s, R=cov.reshape(m, 3, 3) / (s[:, :, None] * s[:, None, :]),
        kind=kind, source=source, horizon=horizon, shard_key=key)


def _check_rows(m: int, columns: dict[str, Sized], per_row: dict[str, int]) -> None:
    """Raise ValueError unless every column has `m` rows (`per_row` values per row)."""
    for name, col in columns.items():
        want = m * per_row.get(name, 1)
        if len(col) != want:
            raise ValueError(f"batch of {m} rows (object_id) has {len(col)} values in "
                             f"{name}, expected {want}")


def estimate_batch_to_msg(rows: EstimateRows, key_range: tuple[int, int] = ALL_KEYS,
                          classes: MsgClasses | None = None) -> Message:
    """Return `rows` (km, km/s) as an ssa_fusion_msgs/EstimateBatch (m, m/s), frame GCRF.

    `key_range` as `measurement_batch_to_msg`; ValueError for an epoch a ROS 2 Time cannot
    carry.
    """
    c = _default(classes)
    return c.estimate_batch(
        header=_header(c, rows.t, Frame.GCRF), update_source=int(rows.update_source),
        key_lo=int(key_range[0]), key_hi=int(key_range[1]), object_id=list(rows.object_id),
        shard_key=_column(rows.shard_key.astype(np.uint32), "I", c),
        stamp_ns=_column(stamps_ns(rows.t), "q", c),
        state=_column(rows.x * _X_SCALE, "d", c),
        covariance=_column(rows.P * KM * KM, "d", c),  # as estimate_to_msg: to the bit
        nis=_column(rows.nis.astype(float), "d", c))


def estimate_batch_from_msg(msg: Message) -> EstimateRows:
    """Return an ssa_fusion_msgs/EstimateBatch (m, m/s) as `EstimateRows` (km, km/s).

    ValueError (one line) when its columns do not all have the same number of rows, or for
    an update source that is none of `types.UpdateSource`.
    """
    m = len(msg.object_id)
    key = np.asarray(msg.shard_key, dtype=np.uint32)
    ns = np.asarray(msg.stamp_ns, dtype=np.int64)
    x = np.asarray(msg.state, dtype=float)
    cov = np.asarray(msg.covariance, dtype=float)
    nis = np.asarray(msg.nis, dtype=float)
    _check_rows(m, {"shard_key": key, "stamp_ns": ns, "state": x, "covariance": cov,
                    "nis": nis}, {"state": 6, "covariance": 36})
    try:
        source = types.UpdateSource(msg.update_source)
    except ValueError:
        raise ValueError(f"unknown update_source {msg.update_source}") from None
    return EstimateRows(t=ns_to_seconds(ns), object_id=list(msg.object_id),
                        x=x.reshape(m, 6) / _X_SCALE, P=cov.reshape(m, 6, 6) / (KM * KM),
                        nis=nis, update_source=source, shard_key=key)


def conjunction_batch_to_msg(update: WatchUpdate, stamp: float,
                             classes: MsgClasses | None = None) -> Message:
    """Return a re-screening (km, km/s) as an ssa_fusion_msgs/ConjunctionBatch (m, m/s).

    ``stamp``: the header's epoch (Unix s), the newest estimate screened. The approaches
    must carry both covariances (ValueError otherwise, or for an epoch a ROS 2 Time cannot
    carry).
    """
    c = _default(classes)
    if c.conjunction_batch is None:
        raise ValueError("these message classes have no ssa_fusion_msgs/ConjunctionBatch")
    a = update.approaches
    if a.p1 is None or a.p2 is None:
        raise ValueError("a ConjunctionBatch carries both covariances: these have none")
    pc = np.where(update.log10_pc > -300.0, 10.0 ** np.maximum(update.log10_pc, -300.0), 0.0)
    return c.conjunction_batch(
        header=c.header(stamp=seconds_to_stamp(stamp, c), frame_id=Frame.GCRF),
        screened_id=list(update.screened),
        window_start_ns=int(stamps_ns(np.array([update.window[0]]))[0]),
        window_end_ns=int(stamps_ns(np.array([update.window[1]]))[0]),
        screening_distance=float(update.distance_km) * KM,
        hard_body_radius=float(update.hbr_km) * KM,
        primary_id=a.primary_ids, secondary_id=a.secondary_ids,
        tca_ns=_column(stamps_ns(a.tca), "q", c),
        miss_distance=_column(a.miss_km * KM, "d", c),
        relative_state_rtn=_column(a.relative_rtn() * KM, "d", c),
        primary_state=_column(a.x1 * KM, "d", c), secondary_state=_column(a.x2 * KM, "d", c),
        primary_covariance=_column(a.p1 * KM * KM, "d", c),
        secondary_covariance=_column(a.p2 * KM * KM, "d", c),
        pc=_column(np.minimum(pc, 1.0), "d", c), log10_pc=_column(update.log10_pc, "d", c))


def conjunction_batch_from_msg(msg: Message) -> WatchUpdate:
    """Return an ssa_fusion_msgs/ConjunctionBatch (m, m/s) as a `WatchUpdate` (km, km/s).

    The approaches' ``object_ids`` are the batch's objects (screened first, then the
    others in order of appearance). ValueError (one line) when its columns disagree.
    """
    from ssa_fusion.core.conjunction.close_approach import CloseApproaches  # the screening's
    from ssa_fusion.core.conjunction.watch import WatchUpdate  # imports: only where used

    m = len(msg.primary_id)
    cols = {"secondary_id": msg.secondary_id, "tca_ns": msg.tca_ns,
            "miss_distance": msg.miss_distance, "primary_state": msg.primary_state,
            "secondary_state": msg.secondary_state,
            "primary_covariance": msg.primary_covariance,
            "secondary_covariance": msg.secondary_covariance, "log10_pc": msg.log10_pc}
    _check_rows(m, cols, {"primary_state": 6, "secondary_state": 6,
                          "primary_covariance": 36, "secondary_covariance": 36})
    ids = list(dict.fromkeys([*msg.screened_id, *msg.primary_id, *msg.secondary_id]))
    index = {o: k for k, o in enumerate(ids)}
    x1 = np.asarray(msg.primary_state, dtype=float).reshape(m, 6) / KM
    x2 = np.asarray(msg.secondary_state, dtype=float).reshape(m, 6) / KM
    a = CloseApproaches(
        tuple(ids), np.array([index[o] for o in msg.primary_id], dtype=np.int64),
        np.array([index[o] for o in msg.secondary_id], dtype=np.int64),
        ns_to_seconds(np.asarray(msg.tca_ns, dtype=np.int64)),
        np.asarray(msg.miss_distance, dtype=float) / KM, x1, x2,
        np.asarray(msg.primary_covariance, dtype=float).reshape(m, 6, 6) / (KM * KM),
        np.asarray(msg.secondary_covariance, dtype=float).reshape(m, 6, 6) / (KM * KM))
    window = ns_to_seconds(np.array([msg.window_start_ns, msg.window_end_ns], dtype=np.int64))
    return WatchUpdate(list(msg.screened_id), a, np.asarray(msg.log10_pc, dtype=float),
                       (float(window[0]), float(window[1])),
                       float(msg.screening_distance) / KM, float(msg.hard_body_radius) / KM)
