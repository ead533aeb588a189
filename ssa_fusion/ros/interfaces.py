"""The ROS interface (message) classes ssa_fusion uses, imported in this one place.

The generated interface packages ship no type information (no ``py.typed``), so a type
checker sees these classes as `typing.Any`; the one ``type: ignore`` per package is here.
`Message` names a message instance where it is not of one class (rclpy's classes or the
rosbags dataclasses of the same message).
"""

from __future__ import annotations

from typing import Any, TypeAlias

from builtin_interfaces.msg import Time  # type: ignore[import-untyped]
from diagnostic_msgs.msg import (  # type: ignore[import-untyped]
    DiagnosticArray,
    DiagnosticStatus,
    KeyValue,
)
from geometry_msgs.msg import Point  # type: ignore[import-untyped]
from rcl_interfaces.msg import (  # type: ignore[import-untyped]
    ParameterDescriptor,
    SetParametersResult,
)
from rosgraph_msgs.msg import Clock  # type: ignore[import-untyped]
from sensor_msgs.msg import NavSatFix, NavSatStatus  # type: ignore[import-untyped]
from ssa_fusion_msgs.msg import (  # type: ignore[import-untyped]
    ConjunctionBatch,
    EstimateBatch,
    Measurement,
    MeasurementBatch,
    Meteo,
    StateEstimate,
)
from std_msgs.msg import ColorRGBA, Header, String  # type: ignore[import-untyped]
from visualization_msgs.msg import Marker, MarkerArray  # type: ignore[import-untyped]

Message: TypeAlias = Any
"""A ROS message instance (of an rclpy class or a rosbags dataclass): untyped."""

__all__ = ["Clock", "ColorRGBA", "ConjunctionBatch", "DiagnosticArray", "DiagnosticStatus",
           "EstimateBatch",
           "Header", "KeyValue", "Marker", "MarkerArray", "Measurement", "MeasurementBatch",
           "Message", "Meteo", "NavSatFix", "NavSatStatus",
           "ParameterDescriptor", "Point", "SetParametersResult", "StateEstimate", "String",
           "Time"]
