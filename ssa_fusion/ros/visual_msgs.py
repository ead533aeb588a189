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

import numpy as np
from numpy.typing import ArrayLike

from ssa_fusion.ros.foxglove_scene import (
    SCENE_FRAME,
    Rgba,
    Shape,
    gcrs_to_geodetic,
    log_time_ns,
)
from ssa_fusion.ros.interfaces import (
    ColorRGBA,
    Marker,
    MarkerArray,
    NavSatFix,
    NavSatStatus,
    Point,
    Time,
)

LINE_WIDTH_KM = 25.0
"""Width of trails in the scene, km (ROS markers have no screen-space widths)."""
LABEL_HEIGHT_KM = 400.0
"""Height of text labels in the scene, km."""


def stamp(t_unix: float) -> Time:
    """Return Unix s (sim time) as a builtin_interfaces/Time (clamped at 0, as log times)."""
    ns = log_time_ns(t_unix)
    return Time(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)


def _color(rgba: Rgba) -> ColorRGBA:
    """Return `rgba` as a std_msgs/ColorRGBA."""
    return ColorRGBA(r=float(rgba[0]), g=float(rgba[1]), b=float(rgba[2]), a=float(rgba[3]))


def _point(p: ArrayLike) -> Point:
    """Return a 3-vector (km) as a geometry_msgs/Point."""
    x, y, z = (float(v) for v in np.ravel(p))
    return Point(x=x, y=y, z=z)


def _marker(t: Time, ns: str, mid: int, kind: int, rgba: Rgba) -> Marker:
    """Return an ADD marker of `kind` in the scene's frame, stamped `t`."""
    m = Marker(ns=ns, id=mid, type=kind, action=Marker.ADD, color=_color(rgba))
    m.header.stamp = t
    m.header.frame_id = SCENE_FRAME
    m.pose.orientation.w = 1.0
    return m


def marker_array(shapes: list[Shape], t_unix: float) -> MarkerArray:
    """Return the MarkerArray of `shapes` (GCRF, km) stamped `t_unix` (Unix s).

    It replaces the scene: its first marker deletes all earlier ones.
    """
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
    """Return the NavSatFix of the point below GCRF position `r_gcrs_km` (km) at `t_unix`.

    At Unix s `t_unix` (sim time): WGS-84 latitude and longitude (deg), height (m), status
    FIX, covariance unknown; the same values as the Foxglove ground track
    (`foxglove_scene.location_fix`).
    """
    lat, lon, alt = gcrs_to_geodetic(r_gcrs_km, t_unix)
    msg = NavSatFix(latitude=math.degrees(lat), longitude=math.degrees(lon),
                    altitude=alt * 1000.0,
                    position_covariance_type=NavSatFix.COVARIANCE_TYPE_UNKNOWN)
    msg.status.status = NavSatStatus.STATUS_FIX
    msg.header.stamp = stamp(t_unix)
    msg.header.frame_id = frame_id
    return msg
