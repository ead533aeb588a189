"""The visual topics as ROS messages, so a rosbag2 bag carries its own picture.

Foxglove (and RViz) draw `visualization_msgs/MarkerArray` in the 3D panel and
`sensor_msgs/NavSatFix` on the Map panel straight from a ROS bag, so the `foxglove_bridge`
node also publishes, and the recorder records:

* `MARKERS_TOPIC` (`visualization_msgs/MarkerArray`): the scene of
  `foxglove_scene.scene_shapes` — one DELETEALL marker, then per entity (namespace = entity
  id: earth, truth, estimate, covariance, stations, forecasts, measurements) a SPHERE per
  single sphere, a SPHERE_LIST for a cloud of equal points, a LINE_STRIP per trail and a
  TEXT_VIEW_FACING per label; frame ``gcrf``, one unit = 1 km, stamped with the scene's sim
  time;
* `TRACK_TOPIC` / `TRUTH_TRACK_TOPIC` (`sensor_msgs/NavSatFix`): the point below the estimate
  / the truth, WGS-84 latitude and longitude in deg, height in m, covariance unknown.

Pure conversions (no rclpy): shapes and states in, ROS messages out.
"""

from __future__ import annotations

import math
from typing import Any

from builtin_interfaces.msg import Time
from geometry_msgs.msg import Point
from numpy.typing import ArrayLike
from sensor_msgs.msg import NavSatFix, NavSatStatus
from std_msgs.msg import ColorRGBA
from visualization_msgs.msg import Marker, MarkerArray

from ssa_fusion.ros.foxglove_scene import (
    SCENE_FRAME,
    Rgba,
    Shape,
    gcrs_to_geodetic,
    log_time_ns,
)

MARKERS_TOPIC = "/ssa/visual/markers"
"""visualization_msgs/MarkerArray: the 3D scene (GCRF, km)."""
TRACK_TOPIC = "/ssa/visual/ground_track"
"""sensor_msgs/NavSatFix: the estimate's sub-satellite point."""
TRUTH_TRACK_TOPIC = "/ssa/visual/ground_track_truth"
"""sensor_msgs/NavSatFix: the truth's sub-satellite point."""
TOPICS = (MARKERS_TOPIC, TRACK_TOPIC, TRUTH_TRACK_TOPIC)

LINE_WIDTH_KM = 25.0
"""Width of trails in the scene, km (ROS markers have no screen-space widths)."""
LABEL_HEIGHT_KM = 400.0
"""Height of text labels in the scene, km."""


def stamp(t_unix: float) -> Time:
    """Unix s (sim time) -> builtin_interfaces/Time (clamped at 0, like the log times)."""
    ns = log_time_ns(t_unix)
    return Time(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)


def _color(rgba: Rgba) -> ColorRGBA:
    return ColorRGBA(r=float(rgba[0]), g=float(rgba[1]), b=float(rgba[2]), a=float(rgba[3]))


def _point(p: Any) -> Point:
    return Point(x=float(p[0]), y=float(p[1]), z=float(p[2]))


def _marker(t: Time, ns: str, mid: int, kind: int, rgba: Rgba) -> Marker:
    m = Marker(ns=ns, id=mid, type=kind, action=Marker.ADD, color=_color(rgba))
    m.header.stamp = t
    m.header.frame_id = SCENE_FRAME
    m.pose.orientation.w = 1.0
    return m


def marker_array(shapes: list[Shape], t_unix: float) -> MarkerArray:
    """`shapes` (GCRF, km) stamped `t_unix` (Unix s) -> MarkerArray that replaces the scene
    (its first marker deletes all earlier ones)."""
    t = stamp(t_unix)
    clear = Marker(action=Marker.DELETEALL)
    clear.header.stamp = t
    clear.header.frame_id = SCENE_FRAME
    out = [clear]
    for shape in shapes:
        first_id = len(out)

        def add(kind: int, rgba: Rgba, ns: str = shape.id, first: int = first_id) -> Marker:
            m = _marker(t, ns, len(out) - first, kind, rgba)  # ids 0, 1, ... per entity
            out.append(m)
            return m

        if len(shape.spheres) > 1:  # a cloud of equal points: one SPHERE_LIST
            first = shape.spheres[0]
            m = add(Marker.SPHERE_LIST, first.rgba)
            m.scale.x, m.scale.y, m.scale.z = (float(v) for v in first.size)
            m.points = [_point(b.position) for b in shape.spheres]
        elif shape.spheres:
            b = shape.spheres[0]
            m = add(Marker.SPHERE, b.rgba)
            m.pose.position = _point(b.position)
            qx, qy, qz, qw = b.quaternion
            m.pose.orientation.x, m.pose.orientation.y = float(qx), float(qy)
            m.pose.orientation.z, m.pose.orientation.w = float(qz), float(qw)
            m.scale.x, m.scale.y, m.scale.z = (float(v) for v in b.size)
        for line in shape.lines:
            if len(line.points) < 2:
                continue
            m = add(Marker.LINE_STRIP, line.rgba)
            m.scale.x = LINE_WIDTH_KM
            m.points = [_point(p) for p in line.points]
        for label in shape.labels:
            m = add(Marker.TEXT_VIEW_FACING, label.rgba)
            m.pose.position = _point(label.position)
            m.scale.z = LABEL_HEIGHT_KM
            m.text = label.text
    return MarkerArray(markers=out)


def nav_sat_fix(t_unix: float, r_gcrs_km: ArrayLike, frame_id: str) -> NavSatFix:
    """The point below GCRF position `r_gcrs_km` (km) at `t_unix` (Unix s, sim time) ->
    NavSatFix: WGS-84 latitude and longitude (deg), height (m), status FIX, covariance
    unknown; the same values as the Foxglove ground track (`foxglove_scene.location_fix`)."""
    lat, lon, alt = gcrs_to_geodetic(r_gcrs_km, t_unix)
    msg = NavSatFix(latitude=math.degrees(lat), longitude=math.degrees(lon),
                    altitude=alt * 1000.0,
                    position_covariance_type=NavSatFix.COVARIANCE_TYPE_UNKNOWN)
    msg.status.status = NavSatStatus.STATUS_FIX
    msg.header.stamp = stamp(t_unix)
    msg.header.frame_id = frame_id
    return msg
