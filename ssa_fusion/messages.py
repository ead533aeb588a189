"""The one place where ROS messages (SI: m, m/s, rad) meet core types (km, km/s, rad).

Every node and every bag tool converts through these functions, so a unit or layout change
happens here and nowhere else.
"""

from __future__ import annotations

import numpy as np
from builtin_interfaces.msg import Time
from ssa_fusion_msgs.msg import Measurement as MeasurementMsg
from ssa_fusion_msgs.msg import StateEstimate as StateEstimateMsg

from ssa_fusion.core import types

KM = 1000.0
"""m per km."""

# Per-component scale from core units to SI for each measurement kind.
_Z_SCALE = {
    types.POSITION: np.array([KM, KM, KM]),
    types.RANGE_AZ_EL: np.array([KM, 1.0, 1.0]),
}
_X_SCALE = np.full(6, KM)


def stamp_to_seconds(stamp: Time) -> float:
    """builtin_interfaces/Time -> float seconds."""
    return stamp.sec + stamp.nanosec * 1e-9


def seconds_to_stamp(t: float) -> Time:
    """float seconds (>= 0) -> builtin_interfaces/Time, rounded to the nanosecond."""
    ns = round(float(t) * 1e9)
    return Time(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)


def z_scale(kind: int) -> np.ndarray:
    """Scale from core units to SI for measurement `kind`; ValueError for an unknown kind."""
    try:
        return _Z_SCALE[kind]
    except KeyError:
        raise ValueError(
            f"unknown measurement kind {kind} (expected {types.POSITION}=POSITION "
            f"or {types.RANGE_AZ_EL}=RANGE_AZ_EL)"
        ) from None


def measurement_to_msg(m: types.Measurement) -> MeasurementMsg:
    """Core Measurement (km) -> ssa_fusion_msgs/Measurement (m)."""
    s = z_scale(m.kind)
    msg = MeasurementMsg()
    msg.header.stamp = seconds_to_stamp(m.t)
    msg.header.frame_id = m.frame_id
    msg.object_id = m.object_id
    msg.kind = m.kind
    msg.source = m.source
    msg.z = (np.asarray(m.z, dtype=float) * s).tolist()
    msg.covariance = (np.asarray(m.R, dtype=float) * np.outer(s, s)).ravel().tolist()
    msg.horizon = float(m.horizon)
    return msg


def measurement_from_msg(msg: MeasurementMsg) -> types.Measurement:
    """Measurement message (m) -> core Measurement (km); ValueError for an unknown kind.

    Works for rclpy messages and for rosbags-deserialized ones (same field names).
    """
    s = z_scale(msg.kind)
    return types.Measurement(
        t=stamp_to_seconds(msg.header.stamp),
        z=np.asarray(msg.z, dtype=float) / s,
        R=np.asarray(msg.covariance, dtype=float).reshape(3, 3) / np.outer(s, s),
        kind=int(msg.kind),
        source=int(msg.source),
        object_id=msg.object_id,
        frame_id=msg.header.frame_id,
        horizon=float(msg.horizon),
    )


def estimate_to_msg(e: types.StateEstimate) -> StateEstimateMsg:
    """Core StateEstimate (km, km/s) -> ssa_fusion_msgs/StateEstimate (m, m/s)."""
    msg = StateEstimateMsg()
    msg.header.stamp = seconds_to_stamp(e.t)
    msg.header.frame_id = "eci"
    msg.object_id = e.object_id
    msg.state = (np.asarray(e.x, dtype=float) * _X_SCALE).tolist()
    msg.covariance = (np.asarray(e.P, dtype=float) * KM * KM).ravel().tolist()
    msg.update_source = e.update_source
    msg.nis = float(e.nis)
    return msg


def estimate_from_msg(msg: StateEstimateMsg) -> types.StateEstimate:
    """ssa_fusion_msgs/StateEstimate (m, m/s) -> core StateEstimate (km, km/s)."""
    return types.StateEstimate(
        t=stamp_to_seconds(msg.header.stamp),
        x=np.asarray(msg.state, dtype=float) / _X_SCALE,
        P=np.asarray(msg.covariance, dtype=float).reshape(6, 6) / (KM * KM),
        object_id=msg.object_id,
        update_source=int(msg.update_source),
        nis=float(msg.nis),
    )

