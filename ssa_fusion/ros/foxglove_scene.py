"""What the foxglove_bridge node shows, as pure functions.

The 3D scene's entities (the Earth, truth, estimate, trails, 3σ ellipsoid, stations,
forecasts, measurements), ground tracks and metrics, from the geometry of `scene_geometry`.
No rclpy here (testable with numpy alone); `foxglove` (foxglove-sdk) is imported only by the
functions that build its messages. Units and frames: positions in km in the GCRF
(`core.earth.frames`); the 3D scene is drawn in frame ``gcrf`` with one scene unit = 1 km; ground
tracks are WGS-84 geodetic of the ITRF position; times are Unix seconds (UTC, sim time);
angles rad, except the ground track's latitude/longitude, which `foxglove.LocationFix` takes
in degrees.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Iterable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ssa_fusion.core.base.constants import R_EARTH, WGS84_F
from ssa_fusion.core.base.types import Cause
from ssa_fusion.core.earth.frames import Frame, Station, site_gcrs
from ssa_fusion.ros.scene_geometry import (
    covariance_ellipsoid,
    gcrs_to_geodetic,
    measurement_point,
    meridian_gcrs,
)

if TYPE_CHECKING:  # foxglove-sdk is imported when a message is built
    from foxglove.messages import (
        Color,
        LinePrimitive,
        LocationFix,
        Pose,
        SceneEntity,
        SceneUpdate,
        SpherePrimitive,
        TextPrimitive,
        Timestamp,
    )

SCENE_FRAME = Frame.GCRF
"""frame_id of every scene entity (the GCRF, km)."""
SCENE_TOPIC = "/ssa/foxglove/scene"
"""foxglove.SceneUpdate: Earth, truth, estimate, trails, 3σ ellipsoid, stations, forecasts."""
TRACK_TOPIC = "/ssa/foxglove/ground_track"
"""foxglove.LocationFix: the estimate's geodetic latitude/longitude (deg), height (m)."""
TRUTH_TRACK_TOPIC = "/ssa/foxglove/ground_track_truth"
"""foxglove.LocationFix: the truth's geodetic latitude/longitude (deg), height (m)."""
METRICS_TOPIC = "/ssa/foxglove/metrics"
"""JSON: per estimate, its position error against the truth (km) and its σ (km)."""
TOPICS = (SCENE_TOPIC, TRACK_TOPIC, TRUTH_TRACK_TOPIC, METRICS_TOPIC)

Rgba = tuple[float, float, float, float]
EARTH_RGBA: Rgba = (0.15, 0.35, 0.8, 0.55)
TRUTH_RGBA: Rgba = (0.1, 0.85, 0.2, 1.0)
ESTIMATE_RGBA: Rgba = (0.95, 0.2, 0.15, 1.0)
ELLIPSOID_RGBA: Rgba = (1.0, 0.6, 0.1, 0.45)
STATION_RGBA: Rgba = (1.0, 1.0, 0.2, 1.0)
FORECAST_RGBA: Rgba = (0.85, 0.2, 0.9, 0.9)
MEASUREMENT_RGBA: Rgba = (0.75, 0.75, 0.75, 0.8)


@dataclass
class SceneState:
    """What the scene shows, as the bridge last heard it (km, GCRF, Unix s).

    ``truth``/``estimate``: (t, state (6,) km km/s) of the newest; ``covariance`` (6, 6) km²
    of the newest estimate; trails and point lists keep the newest `trail` / `points` items.
    """

    trail: int = 600
    points: int = 300
    truth: tuple[float, NDArray[np.float64]] | None = None
    estimate: tuple[float, NDArray[np.float64]] | None = None
    covariance: NDArray[np.float64] | None = None
    truth_trail: deque[NDArray[np.float64]] = field(default_factory=deque)
    estimate_trail: deque[NDArray[np.float64]] = field(default_factory=deque)
    forecasts: deque[NDArray[np.float64]] = field(default_factory=deque)
    measurements: deque[NDArray[np.float64]] = field(default_factory=deque)

    def add_truth(self, t: float, x: ArrayLike) -> None:
        """Take the true state `x` at `t`."""
        self.truth = (t, np.asarray(x, dtype=float))
        _push(self.truth_trail, self.truth[1][:3], self.trail)

    def add_estimate(self, t: float, x: ArrayLike, p: ArrayLike) -> None:
        """Take the estimate `x`, `p` at `t`."""
        self.estimate = (t, np.asarray(x, dtype=float))
        self.covariance = np.asarray(p, dtype=float).reshape(6, 6)
        _push(self.estimate_trail, self.estimate[1][:3], self.trail)

    def add_forecast(self, r_gcrs_km: ArrayLike) -> None:
        """Take the point a forecast implies."""
        _push(self.forecasts, np.asarray(r_gcrs_km, dtype=float), self.points)

    def add_measurement(self, r_gcrs_km: ArrayLike) -> None:
        """Take the point a measurement implies."""
        _push(self.measurements, np.asarray(r_gcrs_km, dtype=float), self.points)

    @property
    def t(self) -> float | None:
        """Return the newest epoch heard (Unix s), None before any."""
        ts = [s[0] for s in (self.truth, self.estimate) if s is not None]
        return max(ts) if ts else None


def _push(buf: deque[NDArray[np.float64]], item: NDArray[np.float64], limit: int) -> None:
    """Append `item`, keeping the newest `limit`."""
    buf.append(item)
    while len(buf) > limit:
        buf.popleft()


def position_error_km(estimate: ArrayLike, truth: ArrayLike) -> float:
    """Return ‖r̂ − r‖ (km) of two states (km)."""
    return float(np.linalg.norm(np.asarray(estimate, float)[:3] - np.asarray(truth, float)[:3]))


def metrics(t: float, x: ArrayLike, p: ArrayLike, truth: ArrayLike | None,
            update_source: int, nis: float) -> dict[str, Any]:
    """Return the JSON message of `METRICS_TOPIC` for an estimate at `t` (Unix s).

    State `x` km, covariance `p` (6, 6) km²; `truth` the true state at the same epoch, or
    None. Keys: ``t`` (s), ``position_error_km`` (None without truth), ``sigma_km``
    (√trace of the position block, km), ``three_sigma_max_km`` (the largest semi-axis of the
    3σ ellipsoid, km), ``velocity_sigma_km_s``, ``nis``, ``update_source`` (0 none, 1 sensor,
    2 forecast).
    """
    pm = np.asarray(p, dtype=float).reshape(6, 6)
    ell = covariance_ellipsoid(pm[:3, :3])
    return {
        "t": float(t),
        "position_error_km": None if truth is None else position_error_km(x, truth),
        "sigma_km": float(math.sqrt(max(np.trace(pm[:3, :3]), 0.0))),
        "three_sigma_max_km": float(ell.semi_axes.max()),
        "velocity_sigma_km_s": float(math.sqrt(max(np.trace(pm[3:, 3:]), 0.0))),
        "nis": float(nis),
        "update_source": int(update_source),
    }


METRICS_SCHEMA: dict[str, Any] = {
    "type": "object",
    "properties": {
        "t": {"type": "number", "description": "epoch, Unix s (sim time)"},
        "position_error_km": {"type": ["number", "null"],
                              "description": "|estimate - truth| position, km"},
        "sigma_km": {"type": "number", "description": "sqrt(trace P_pos), km"},
        "three_sigma_max_km": {"type": "number",
                               "description": "largest semi-axis of the 3-sigma ellipsoid, km"},
        "velocity_sigma_km_s": {"type": "number", "description": "sqrt(trace P_vel), km/s"},
        "nis": {"type": "number"},
        "update_source": {"type": "integer", "description": "0 none, 1 sensor, 2 forecast"},
    },
}
"""JSON schema of `METRICS_TOPIC`'s messages."""


# foxglove messages ------------------------------------------------------------------------

def _stamp(t_unix: float) -> Timestamp:
    """Return Unix s as a foxglove timestamp (clamped at 0)."""
    from foxglove.messages import Timestamp

    ns = max(round(t_unix * 1e9), 0)
    return Timestamp(sec=ns // 1_000_000_000, nsec=ns % 1_000_000_000)


def _color(rgba: Rgba) -> Color:
    """Return `rgba` as a foxglove colour."""
    from foxglove.messages import Color

    return Color(r=rgba[0], g=rgba[1], b=rgba[2], a=rgba[3])


def _pose(position: ArrayLike, quaternion: tuple[float, float, float, float] = (0, 0, 0, 1)
          ) -> Pose:
    """Return a foxglove pose at `position` (km), rotated by `quaternion`."""
    from foxglove.messages import Pose, Quaternion, Vector3

    x, y, z = (float(v) for v in np.asarray(position, dtype=float)[:3])
    qx, qy, qz, qw = quaternion
    return Pose(position=Vector3(x=x, y=y, z=z),
                orientation=Quaternion(x=qx, y=qy, z=qz, w=qw))


def _sphere(position: ArrayLike, size: ArrayLike, rgba: Rgba,
            quaternion: tuple[float, float, float, float] = (0, 0, 0, 1)) -> SpherePrimitive:
    """Return a foxglove sphere (an ellipsoid of diameters `size` km)."""
    from foxglove.messages import SpherePrimitive, Vector3

    sx, sy, sz = (float(v) for v in np.broadcast_to(np.asarray(size, dtype=float), (3,)))
    return SpherePrimitive(pose=_pose(position, quaternion), size=Vector3(x=sx, y=sy, z=sz),
                           color=_color(rgba))


def _line(points: ArrayLike, rgba: Rgba, thickness: float = 2.0) -> LinePrimitive:
    """Return a foxglove line strip through `points` (n, 3) km."""
    from foxglove.messages import LinePrimitive, LinePrimitiveLineType, Point3

    pts = [Point3(x=float(p[0]), y=float(p[1]), z=float(p[2]))
           for p in np.asarray(points, dtype=float).reshape(-1, 3)]
    return LinePrimitive(type=LinePrimitiveLineType.LineStrip, pose=_pose((0, 0, 0)),
                         thickness=thickness, scale_invariant=True, points=pts,
                         color=_color(rgba))


def _text(position: ArrayLike, text: str, rgba: Rgba) -> TextPrimitive:
    """Return a foxglove text label at `position` (km), facing the viewer."""
    from foxglove.messages import TextPrimitive

    return TextPrimitive(pose=_pose(position), billboard=True, font_size=14.0,
                         scale_invariant=True, color=_color(rgba), text=text)


@dataclass(frozen=True)
class Sphere:
    """A sphere (ellipsoid) of the scene.

    Centre ``position`` (3,) km GCRF, diameters ``size`` (3,) km along its axes, rotated by
    ``quaternion`` (x, y, z, w).
    """

    position: NDArray[np.float64]
    size: NDArray[np.float64]
    rgba: Rgba
    quaternion: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 1.0)


@dataclass(frozen=True)
class Line:
    """A polyline through ``points`` (n, 3) km GCRF, ``thickness`` in screen pixels."""

    points: NDArray[np.float64]
    rgba: Rgba
    thickness: float = 2.0


@dataclass(frozen=True)
class Label:
    """A text label at ``position`` (3,) km GCRF, facing the viewer."""

    position: NDArray[np.float64]
    text: str
    rgba: Rgba


@dataclass(frozen=True)
class Shape:
    """One entity of the scene as plain geometry.

    ``id``: earth, truth, estimate, covariance, stations, forecasts, measurements; drawn by
    `scene_entities` in Foxglove's schema and by `ssa_fusion.ros.visual_msgs` as ROS markers.
    """

    id: str
    spheres: tuple[Sphere, ...] = ()
    lines: tuple[Line, ...] = ()
    labels: tuple[Label, ...] = ()


def _ball(position: ArrayLike, size: ArrayLike, rgba: Rgba,
          quaternion: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 1.0)) -> Sphere:
    """Return a `Sphere` (its arrays copied)."""
    return Sphere(np.asarray(position, dtype=float)[:3].copy(),
                  np.broadcast_to(np.asarray(size, dtype=float), (3,)).copy(), rgba, quaternion)


def _polyline(points: Iterable[ArrayLike], rgba: Rgba, thickness: float = 2.0) -> Line:
    """Return a `Line` through `points` (3-vectors, km)."""
    pts = np.asarray([np.asarray(p, dtype=float)[:3] for p in points], dtype=float)
    return Line(pts.reshape(-1, 3), rgba, thickness)


def scene_shapes(state: SceneState, stations: dict[str, Station],
                 marker_km: float = 150.0) -> list[Shape]:
    """Return the scene of `state` as `Shape` s (GCRF, km).

    ``earth`` (WGS-84-sized sphere, its prime meridian), ``truth`` and ``estimate`` (a
    `marker_km`-wide sphere and the recent trail each), ``covariance`` (the 3σ ellipsoid of
    the estimate's position block, true size), ``stations`` (one marker and label per
    station of `stations`), ``forecasts`` and ``measurements`` (the recent points they
    imply). Entities without data are left out.
    """
    t = state.t if state.t is not None else 0.0
    earth_d = 2.0 * R_EARTH
    out = [Shape("earth",
                 spheres=(_ball((0, 0, 0), (earth_d, earth_d, earth_d * (1 - WGS84_F)),
                                EARTH_RGBA),),
                 lines=(_polyline(meridian_gcrs(t), (1.0, 1.0, 1.0, 0.8), 1.5),))]
    if state.truth is not None:
        out.append(Shape("truth", spheres=(_ball(state.truth[1], marker_km, TRUTH_RGBA),),
                         lines=(_polyline(state.truth_trail, TRUTH_RGBA),)))
    if state.estimate is not None:
        out.append(Shape("estimate",
                         spheres=(_ball(state.estimate[1], marker_km, ESTIMATE_RGBA),),
                         lines=(_polyline(state.estimate_trail, ESTIMATE_RGBA),)))
        if state.covariance is not None:
            ell = covariance_ellipsoid(state.covariance[:3, :3])
            out.append(Shape("covariance",
                             spheres=(_ball(state.estimate[1], ell.size, ELLIPSOID_RGBA,
                                            ell.quaternion),),
                             labels=(Label(np.asarray(state.estimate[1][:3], dtype=float),
                                           f"3σ {ell.semi_axes.max():.3g} km",
                                           (*ELLIPSOID_RGBA[:3], 1.0)),)))
    if stations:
        pos = {name: site_gcrs(s, t) for name, s in stations.items()}
        out.append(Shape("stations",
                         spheres=tuple(_ball(p, marker_km * 0.6, STATION_RGBA)
                                       for p in pos.values()),
                         labels=tuple(Label(p, name, STATION_RGBA) for name, p in pos.items())))
    if state.forecasts:
        out.append(Shape("forecasts", spheres=tuple(_ball(p, marker_km * 0.4, FORECAST_RGBA)
                                                    for p in state.forecasts)))
    if state.measurements:
        out.append(Shape("measurements",
                         spheres=tuple(_ball(p, marker_km * 0.3, MEASUREMENT_RGBA)
                                       for p in state.measurements)))
    return out


def scene_entities(state: SceneState, stations: dict[str, Station],
                   marker_km: float = 150.0) -> list[SceneEntity]:
    """Return `scene_shapes` as `foxglove.SceneEntity` s (frame ``gcrf``, km).

    Stamped with the state's newest epoch.
    """
    return _entities(scene_shapes(state, stations, marker_km), state.t or 0.0)


def _entities(shapes: list[Shape], t: float) -> list[SceneEntity]:
    """Return `shapes` as foxglove scene entities stamped `t` (Unix s)."""
    from foxglove.messages import SceneEntity

    stamp = _stamp(t)
    return [SceneEntity(timestamp=stamp, frame_id=SCENE_FRAME, id=sh.id,
                        spheres=[_sphere(b.position, b.size, b.rgba, b.quaternion)
                                 for b in sh.spheres],
                        lines=[_line(ln.points, ln.rgba, ln.thickness) for ln in sh.lines],
                        texts=[_text(lb.position, lb.text, lb.rgba) for lb in sh.labels])
            for sh in shapes]


def scene_update(state: SceneState, stations: dict[str, Station],
                 marker_km: float = 150.0) -> SceneUpdate:
    """Return the `foxglove.SceneUpdate` of `scene_entities`.

    Each replaces its entity of the same id.
    """
    from foxglove.messages import SceneUpdate

    return SceneUpdate(entities=scene_entities(state, stations, marker_km))


def location_fix(t_unix: float, r_gcrs_km: ArrayLike,
                 frame_id: str = "estimate") -> LocationFix:
    """Return the `foxglove.LocationFix` of the point below GCRF position `r_gcrs_km` (km).

    At `t_unix` (Unix s): latitude and longitude in degrees (WGS-84), altitude in m.
    """
    from foxglove.messages import LocationFix

    lat, lon, alt = gcrs_to_geodetic(r_gcrs_km, t_unix)
    return LocationFix(timestamp=_stamp(t_unix), frame_id=frame_id,
                       latitude=math.degrees(lat), longitude=math.degrees(lon),
                       altitude=alt * 1000.0)


# what one truth / estimate / measurement adds to the visual topics ------------------------

NOT_DRAWN = "not_drawn"
"""Diagnostics key of a measurement that implies no point to draw (ra/dec, other station)."""
TRUTH_KEEP = 5000
"""Truth states kept by epoch, to score estimates that arrive after their truth."""


def log_time_ns(t_unix: float) -> int:
    """Return the foxglove log time (int ns >= 0) of a message stamped `t_unix` (Unix s)."""
    return max(round(t_unix * 1e9), 0) if math.isfinite(t_unix) else 0


@dataclass(frozen=True)
class Logged:
    """One message for a visual topic.

    ``topic`` (one of `TOPICS`), ``message`` (a foxglove message, or the JSON dict of
    `METRICS_TOPIC`), ``log_time`` (int ns, the sim-time stamp).
    """

    topic: str
    message: Any
    log_time: int


class NotShownError(Exception):
    """A message the visual topics leave out.

    ``key`` is the diagnostics key (`Cause.REJECTED_NONFINITE`, `NOT_DRAWN`), ``warn``
    whether it is worth a warning.
    """

    def __init__(self, key: str, detail: str, warn: bool = True) -> None:
        super().__init__(detail)
        self.key = key
        self.detail = detail
        self.warn = warn


class VisualTopics:
    """The visual topics of a stream of truth states, estimates and measurements.

    In the order they arrive: one object shared by the live `foxglove_bridge` and the
    `visual.mcap` writer of `ssa-fusion report`, so both serve the same messages.

    Inputs are in core units (km, km/s, rad; GCRF; Unix s, sim time). `truth` and `estimate`
    return the `Logged` messages they produce at once (ground tracks, metrics, log time = their
    stamp); `measurement` only updates the scene; `scene` is the current `foxglove.SceneUpdate`
    (the caller decides how often). Each raises `NotShownError` for what it leaves out.
    """

    def __init__(self, stations: dict[str, Station], trail: int = 600, points: int = 300,
                 marker_km: float = 150.0) -> None:
        self.stations = stations
        self.marker_km = float(marker_km)
        self.state = SceneState(trail=int(trail), points=int(points))
        self.truths: dict[float, NDArray[np.float64]] = {}
        self.dirty = False
        """True when something changed since the last `scene`."""
        self.shapes: list[Shape] = []
        """The geometry of the last `scene` (GCRF, km)."""

    def truth(self, t: float, x: ArrayLike) -> list[Logged]:
        """Take a true state `x` (6,) km, km/s at `t` (Unix s); return its track's fix."""
        xs = np.asarray(x, dtype=float)
        if not np.all(np.isfinite(xs)):
            raise NotShownError(Cause.REJECTED_NONFINITE, "a truth state with NaN/inf")
        self.state.add_truth(t, xs)
        self.truths[t] = xs
        while len(self.truths) > TRUTH_KEEP:
            del self.truths[next(iter(self.truths))]
        self.dirty = True
        return [Logged(TRUTH_TRACK_TOPIC, location_fix(t, xs, "truth"), log_time_ns(t))]

    def estimate(self, t: float, x: ArrayLike, p: ArrayLike, update_source: int,
                 nis: float) -> list[Logged]:
        """Take an estimate; return its `TRACK_TOPIC` fix and `METRICS_TOPIC` JSON.

        State `x` km, km/s, covariance `p` (6, 6) km² at `t` Unix s; scored against the
        truth of the same epoch, when it came first.
        """
        xs, ps = np.asarray(x, dtype=float), np.asarray(p, dtype=float)
        if not (np.all(np.isfinite(xs)) and np.all(np.isfinite(ps))):
            raise NotShownError(Cause.REJECTED_NONFINITE, "an estimate with NaN/inf")
        self.state.add_estimate(t, xs, ps)
        self.dirty = True
        ns = log_time_ns(t)
        return [Logged(TRACK_TOPIC, location_fix(t, xs, "estimate"), ns),
                Logged(METRICS_TOPIC, metrics(t, xs, ps, self.truths.get(t), update_source,
                                              nis), ns)]

    def measurement(self, kind: int, z: ArrayLike, frame_id: str, t: float,
                    forecast: bool) -> None:
        """Put the point a measurement or (`forecast`) a forecast implies in the scene.

        In core units.
        """
        zs = np.asarray(z, dtype=float)
        if not np.all(np.isfinite(zs)):
            raise NotShownError(Cause.REJECTED_NONFINITE, "a measurement with NaN/inf")
        point = measurement_point(kind, zs, frame_id, t, self.stations)
        if point is None:
            raise NotShownError(NOT_DRAWN, f"kind {kind} from {frame_id!r}: no point to draw "
                           "(ra/dec, or a station not in 'station')", warn=False)
        if forecast:
            self.state.add_forecast(point)
        else:
            self.state.add_measurement(point)
        self.dirty = True

    @property
    def scene_due(self) -> bool:
        """Return True when the scene changed since the last `scene` and can be stamped.

        It can be once a truth or an estimate was heard.
        """
        return self.dirty and self.state.t is not None

    def scene(self) -> Logged:
        """Return the `SCENE_TOPIC` update of the current state, logged at its newest epoch."""
        from foxglove.messages import SceneUpdate

        self.dirty = False
        t = self.state.t or 0.0
        self.shapes = scene_shapes(self.state, self.stations, self.marker_km)
        return Logged(SCENE_TOPIC, SceneUpdate(entities=_entities(self.shapes, t)),
                      log_time_ns(t))
