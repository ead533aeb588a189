"""The one place where messages (SI: m, m/s, rad) meet core types (km, km/s, rad).

Every node and every bag tool converts through these functions, so a unit or layout change
happens here and nowhere else. Conversions *from* messages accept any object with the
message's fields (rclpy messages, rosbags-deserialized ones); conversions *to* messages
build rclpy messages by default, or the classes of another implementation (`MsgClasses`,
e.g. `bagio.ROSBAGS_CLASSES` for writing bags without ROS).
"""

from __future__ import annotations

import zlib
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from ssa_fusion.core import types
from ssa_fusion.core.frames import Frame
from ssa_fusion.core.timescales import EPOCH_MAX, iso

if TYPE_CHECKING:  # the message packages are imported when first needed (`rclpy_classes`)
    from ssa_fusion.ros.interfaces import Message

KM = 1000.0
"""m per km."""

# Per-component scale from core units to SI for each measurement kind.
_Z_SCALE = {
    types.Kind.POSITION: np.array([KM, KM, KM]),
    types.Kind.RANGE_AZ_EL: np.array([KM, 1.0, 1.0]),
    types.Kind.RA_DEC: np.array([1.0, 1.0]),
}
_X_SCALE = np.full(6, KM)


@dataclass(frozen=True)
class MsgClasses:
    """Constructors of builtin_interfaces/Time, std_msgs/Header and the two messages."""

    time: type[Message]
    header: type[Message]
    measurement: type[Message]
    estimate: type[Message]


def rclpy_classes() -> MsgClasses:
    """Return the rclpy message classes (imported on the first call)."""
    from ssa_fusion.ros.interfaces import Header, Measurement, StateEstimate, Time

    return MsgClasses(Time, Header, Measurement, StateEstimate)


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
    """Return a builtin_interfaces/Time in float seconds."""
    return float(stamp.sec) + float(stamp.nanosec) * 1e-9


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
    are returned as they are.
    """
    if not msgtype.startswith("ssa_fusion_msgs/"):
        return msg
    if msgtype.endswith("Measurement"):
        return measurement_to_msg(measurement_from_msg(msg), classes)
    return estimate_to_msg(estimate_from_msg(msg), classes)


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


def estimate_to_msg(e: types.StateEstimate, classes: MsgClasses | None = None) -> Message:
    """Return core StateEstimate `e` (km, km/s) as an ssa_fusion_msgs/StateEstimate (m, m/s)."""
    c = _default(classes)
    return c.estimate(
        header=c.header(stamp=seconds_to_stamp(e.t, c), frame_id=Frame.GCRF),
        object_id=e.object_id,
        state=np.asarray(e.x, dtype=float) * _X_SCALE,
        covariance=(np.asarray(e.P, dtype=float) * KM * KM).ravel(),
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
