"""Deterministic sample messages for the message round-trip graph test (shared by the
publisher script and the test)."""

from __future__ import annotations

import math

from ssa_fusion_msgs.msg import Measurement, StateEstimate

N_SAMPLES = 5


def sample_measurement(i: int) -> Measurement:
    m = Measurement()
    m.header.stamp.sec = 1_700_000_000 + i
    m.header.stamp.nanosec = 123_456_789 + i
    m.header.frame_id = "columbus" if i % 2 else "gcrf"
    m.object_id = f"ISS (ZARYA) #{i}"
    m.kind = Measurement.RANGE_AZ_EL if i % 2 else Measurement.POSITION
    m.source = Measurement.FORECAST if i % 3 == 0 else Measurement.SENSOR
    m.z = [6.7969e6 + i, -0.0, math.pi * 2 - 1e-12]
    m.covariance = [1e-300 * (k + 1) + k * 1.5 - i for k in range(9)]
    m.horizon = 30.0 * i + 1e-9
    return m


def sample_estimate(i: int) -> StateEstimate:
    e = StateEstimate()
    e.header.stamp.sec = 1_700_000_000 + i
    e.header.stamp.nanosec = 999_999_999 - i
    e.header.frame_id = "gcrf"
    e.object_id = f"obj-{i}"
    e.state = [-6.7e6 + i, 1.0e-3, 3.3e6, 7.6e3, -0.5, float(i)]
    e.covariance = [(-1) ** k * 10.0 ** (k - 18) + i for k in range(36)]
    e.update_source = i % 3
    e.nis = 1.0 / (i + 3)
    return e


def as_dict(msg) -> dict:
    """Every field of a Measurement or StateEstimate as plain Python values."""
    out = {
        "stamp": (msg.header.stamp.sec, msg.header.stamp.nanosec),
        "frame_id": msg.header.frame_id,
        "object_id": msg.object_id,
    }
    for name in msg.get_fields_and_field_types():
        if name in ("header", "object_id"):
            continue
        value = getattr(msg, name)
        out[name] = [float(v) for v in value] if hasattr(value, "__len__") else value
    return out
