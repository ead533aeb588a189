"""ssa_fusion.ros.foxglove_scene against analytic results and core.earth.frames: covariance
ellipsoids (diagonal, rotated, degenerate), quaternions, GCRF -> geodetic (against astropy),
range/az/el -> GCRF, and the foxglove messages it builds."""

from __future__ import annotations

import json
import math
import re
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation
from ssa_fusion_msgs.msg import StateEstimate as StateEstimateMsg
from visualization_msgs.msg import Marker

from ssa_fusion.core.base.constants import R_EARTH, WGS84_F
from ssa_fusion.core.base.types import Kind
from ssa_fusion.core.earth.frames import (
    COLUMBUS,
    ERA_RATE,
    Frame,
    gcrs_to_itrs,
    itrs_to_gcrs,
    razel_gcrs,
    site_gcrs,
    site_itrs,
    wrap_pi,
)
from ssa_fusion.core.earth.stations import network_stations
from ssa_fusion.ros import foxglove_scene as fs
from ssa_fusion.ros import scene_geometry as geo
from ssa_fusion.ros import topics
from ssa_fusion.ros import visual_msgs as vm

T = 1_718_000_000.0  # 2024-06-10, Unix s


def test_ellipsoid_of_a_diagonal_covariance():
    ell = geo.covariance_ellipsoid(np.diag([4.0, 9.0, 16.0]))  # σ = 2, 3, 4 km
    assert ell.semi_axes == pytest.approx([6.0, 9.0, 12.0])
    assert ell.size == pytest.approx([12.0, 18.0, 24.0])
    # each axis is a coordinate axis (up to sign), a proper rotation
    assert np.abs(ell.axes) == pytest.approx(np.eye(3))
    assert np.linalg.det(ell.axes) == pytest.approx(1.0)


def test_ellipsoid_of_a_rotated_covariance():
    rot = Rotation.from_euler("ZX", [30.0, 50.0], degrees=True).as_matrix()  # Rz(30) Rx(50)
    p = rot @ np.diag([1.0, 25.0, 100.0]) @ rot.T  # km²
    ell = geo.covariance_ellipsoid(p)
    assert ell.semi_axes == pytest.approx([3.0, 15.0, 30.0])
    for i in range(3):  # principal directions are the rotated axes (up to sign)
        assert abs(ell.axes[:, i] @ rot[:, i]) == pytest.approx(1.0)
    # the pose foxglove gets (quaternion, diameters) rebuilds 9 P
    r = geo.quaternion_to_rotation(ell.quaternion)
    assert r @ np.diag((ell.size / 2) ** 2) @ r.T == pytest.approx(9.0 * p)
    assert np.linalg.norm(ell.quaternion) == pytest.approx(1.0)


def test_ellipsoid_of_a_singular_covariance_is_flat_not_nan():
    p = np.diag([0.0, 1.0, 4.0])
    p[0, 0] = -1e-18  # round-off makes it indefinite
    ell = geo.covariance_ellipsoid(p, n_sigma=1.0)
    assert ell.semi_axes == pytest.approx([0.0, 1.0, 2.0])
    assert np.all(np.isfinite(ell.quaternion))


@pytest.mark.parametrize("angle", [0.0, 0.3, 2.0, math.pi - 1e-3, math.pi])
@pytest.mark.parametrize("axis", [(1, 0, 0), (0, 1, 0), (0, 0, 1), (1, 2, -3)])
def test_quaternion_round_trip(angle, axis):
    u = np.asarray(axis, float) / np.linalg.norm(axis)
    k = np.array([[0, -u[2], u[1]], [u[2], 0, -u[0]], [-u[1], u[0], 0]])
    rot = np.eye(3) + math.sin(angle) * k + (1 - math.cos(angle)) * k @ k  # Rodrigues
    q = geo.rotation_to_quaternion(rot)
    assert geo.quaternion_to_rotation(q) == pytest.approx(rot, abs=1e-12)
    assert q[3] == pytest.approx(math.cos(angle / 2), abs=1e-12)


def test_sub_satellite_point_matches_astropy():
    """GCRF points -> geodetic latitude, longitude, height against astropy's GCRS -> ITRS ->
    WGS-84 (same IERS table): 1e-9 rad, 1 mm."""
    astropy_time = pytest.importorskip("astropy.time")
    coords = pytest.importorskip("astropy.coordinates")
    from astropy import units
    from astropy.utils import iers

    iers.conf.auto_download = False
    iers.conf.auto_max_age = None
    iers.earth_orientation_table.set(iers.IERS_A.open(iers.IERS_A_FILE))
    r = np.array([[7000.0, 0.0, 0.0], [4000.0, -3000.0, 4500.0], [-100.0, 200.0, 6800.0]])
    t = astropy_time.Time(T, format="unix", scale="utc")
    gcrs = coords.GCRS(coords.CartesianRepresentation(r.T * units.km), obstime=t)
    itrs = gcrs.transform_to(coords.ITRS(obstime=t))
    ref = itrs.earth_location.to_geodetic("WGS84")
    for i in range(len(r)):
        lat, lon, alt = geo.gcrs_to_geodetic(r[i], T)
        assert lat == pytest.approx(ref.lat.rad[i], abs=1e-9)
        assert float(wrap_pi(lon - ref.lon.rad[i])) == pytest.approx(0.0, abs=1e-9)
        assert alt == pytest.approx(ref.height.to_value(units.km)[i], abs=1e-6)


def test_geodetic_of_the_pole():
    b = R_EARTH * (1 - WGS84_F)
    lat, _lon, alt = geo.itrs_to_geodetic([0.0, 0.0, b + 500.0])
    assert lat == pytest.approx(math.pi / 2)
    assert alt == pytest.approx(500.0, abs=1e-9)


@pytest.mark.parametrize(("lat_deg", "lon_deg", "alt_km"),
                         [(39.9612, -82.9988, 0.275), (-33.9, 151.2, 420.0), (0.0, 180.0, 0.0),
                          (85.0, 10.0, 35786.0), (-89.9, -45.0, 1.0), (51.6, 0.0, 400.0)])
def test_geodetic_inverts_core_frames(lat_deg, lon_deg, alt_km):
    """core.earth.frames builds the GCRF point of a geodetic site (site_itrs, itrs_to_gcrs);
    gcrs_to_geodetic gets the site back at the same epoch."""
    lat, lon = math.radians(lat_deg), math.radians(lon_deg)
    r_gcrs = itrs_to_gcrs(site_itrs(lat, lon, alt_km), T)
    got = geo.gcrs_to_geodetic(r_gcrs, T)
    assert got[0] == pytest.approx(lat, abs=1e-11)
    assert float(wrap_pi(got[1] - lon)) == pytest.approx(0.0, abs=1e-11)
    assert got[2] == pytest.approx(alt_km, abs=1e-7)


def test_measurement_point_inverts_core_razel():
    r_eci = np.array([4000.0, -3000.0, 4500.0])
    z = razel_gcrs(r_eci, T, COLUMBUS)
    stations = {"columbus": COLUMBUS}
    assert geo.measurement_point(Kind.RANGE_AZ_EL, z, "columbus", T, stations) == \
        pytest.approx(r_eci, abs=1e-8)
    assert geo.measurement_point(Kind.POSITION, r_eci, Frame.GCRF, T, {}) == \
        pytest.approx(r_eci)
    assert geo.measurement_point(Kind.RA_DEC, z[1:], "columbus", T, stations) is None
    assert geo.measurement_point(Kind.RANGE_AZ_EL, z, "elsewhere", T, stations) is None


def test_meridian_and_station_turn_with_the_earth():
    m0, m1 = geo.meridian_gcrs(T), geo.meridian_gcrs(T + 6 * 3600.0)
    assert np.linalg.norm(m0, axis=1) == pytest.approx(R_EARTH + 1.0)
    mid0, mid1 = m0[len(m0) // 2], m1[len(m1) // 2]  # on the equator
    turned = math.acos(mid0 @ mid1 / (np.linalg.norm(mid0) * np.linalg.norm(mid1)))
    assert turned == pytest.approx(6 * 3600.0 * ERA_RATE, rel=1e-4)  # + precession
    assert gcrs_to_itrs(m1, T + 6 * 3600.0) == pytest.approx(gcrs_to_itrs(m0, T), abs=1e-9)
    s = site_gcrs(COLUMBUS, T)
    assert np.linalg.norm(s) == pytest.approx(np.linalg.norm(COLUMBUS.itrs))


def test_metrics():
    x = np.array([7001.0, 2.0, 2.0, 0.0, 7.5, 0.0])
    truth = np.array([7000.0, 0.0, 0.0, 0.0, 7.5, 0.0])
    p = np.diag([1.0, 4.0, 9.0, 1e-6, 4e-6, 4e-6])
    m = fs.metrics(T, x, p, truth, update_source=2, nis=1.5)
    assert m["position_error_km"] == pytest.approx(3.0)
    assert m["sigma_km"] == pytest.approx(math.sqrt(14.0))
    assert m["three_sigma_max_km"] == pytest.approx(9.0)
    assert m["velocity_sigma_km_s"] == pytest.approx(3e-3)
    assert (m["t"], m["nis"], m["update_source"]) == (T, 1.5, 2)
    assert fs.metrics(T, x, p, None, 1, 0.0)["position_error_km"] is None


def test_scene_state_keeps_the_newest():
    s = fs.SceneState(trail=3, points=2)
    assert s.t is None
    for k in range(5):
        s.add_truth(T + k, [7000.0 + k, 0, 0, 0, 7.5, 0])
        s.add_forecast([k, 0, 0])
    s.add_estimate(T + 2, np.zeros(6), np.eye(6))
    assert [p[0] for p in s.truth_trail] == [7002.0, 7003.0, 7004.0]
    assert [p[0] for p in s.forecasts] == [3.0, 4.0]
    assert s.t == T + 4


def test_scene_messages_encode():
    """The foxglove messages build and encode (protobuf); entities without data are left
    out."""
    from foxglove.messages import SceneUpdate

    def ids(entities: list) -> list[str]:  # the messages have no getters; their repr says
        return [re.search(r'\bid="([^"]*)"', repr(e)).group(1) for e in entities]

    s = fs.SceneState()
    assert ids(fs.scene_entities(s, {})) == ["earth"]
    s.add_truth(T, [7000.0, 0, 0, 0, 7.5, 0])
    s.add_estimate(T, [7001.0, 0, 0, 0, 7.5, 0], np.diag([1.0, 4, 9, 1e-6, 1e-6, 1e-6]))
    s.add_forecast([7000.0, 10.0, 0.0])
    s.add_measurement([7000.0, 20.0, 0.0])
    stations = network_stations("network")
    got = ids(fs.scene_entities(s, stations))
    assert got == ["earth", "truth", "estimate", "covariance", "stations", "forecasts",
                   "measurements"]
    update = fs.scene_update(s, stations)
    assert isinstance(update, SceneUpdate)
    assert len(update.encode()) > 500
    fix = repr(fs.location_fix(T, [7000.0, 0.0, 0.0]))
    lat, lon, alt = geo.gcrs_to_geodetic([7000.0, 0.0, 0.0], T)
    values = {k: float(v) for k, v in re.findall(r"\b(latitude|longitude|altitude)=([-\d.e]+)",
                                                 fix)}
    assert values == pytest.approx({"latitude": math.degrees(lat),
                                    "longitude": math.degrees(lon), "altitude": alt * 1000.0})


LAYOUT = Path(__file__).resolve().parents[2] / "config" / "foxglove_layout.json"


def _panels(tree: object) -> list[str]:
    if isinstance(tree, str):
        return [tree]
    assert isinstance(tree, dict)
    return _panels(tree["first"]) + _panels(tree["second"])


def test_the_layout_shows_the_bridge_topics():
    """config/foxglove_layout.json (Foxglove's layout JSON: configById + layout tree): a 3D
    panel on the scene in frame gcrf, a Map panel on the ground tracks, a Plot of the metrics'
    fields; every panel of the tree is configured."""
    layout = json.loads(LAYOUT.read_text())
    panels = _panels(layout["layout"])
    assert sorted(panels) == sorted(layout["configById"])
    kinds = {p.split("!")[0]: layout["configById"][p] for p in panels}
    assert set(kinds) == {"3D", "map", "Plot"}
    assert kinds["3D"]["followTf"] == fs.SCENE_FRAME
    # the same picture live (foxglove schemas) and from a recorded bag (ROS messages)
    assert set(kinds["3D"]["topics"]) == {fs.SCENE_TOPIC, topics.MARKERS_TOPIC}
    assert set(kinds["map"]["topicColors"]) == {fs.TRACK_TOPIC, fs.TRUTH_TRACK_TOPIC,
                                                topics.TRACK_TOPIC, topics.TRUTH_TRACK_TOPIC}
    fields = [p["value"].split(".", 1) for p in kinds["Plot"]["paths"]]
    metric_fields = {f for topic, f in fields if topic == fs.METRICS_TOPIC}
    assert metric_fields and metric_fields <= set(fs.METRICS_SCHEMA["properties"])
    estimate_fields = {f for topic, f in fields if topic == "/ssa/estimate"}
    assert estimate_fields == {"nis"}
    assert "nis" in StateEstimateMsg.get_fields_and_field_types()


def test_ros_markers_draw_the_same_shapes_as_the_foxglove_scene():
    """The bag's MarkerArray: a DELETEALL first, then per entity its spheres (one SPHERE with
    the 3σ ellipsoid's size and rotation; a SPHERE_LIST for a cloud of points), trails and
    labels, in frame gcrf, stamped with the scene's epoch."""
    v = fs.VisualTopics(network_stations("network"))
    p = np.diag([1.0, 4.0, 9.0, 1e-6, 1e-6, 1e-6])
    v.truth(T, [7000.0, 0.0, 0.0, 0.0, 7.5, 0.0])
    v.truth(T + 60.0, [6990.0, 450.0, 0.0, -0.5, 7.5, 0.0])
    v.estimate(T + 60.0, [6991.0, 451.0, 1.0, -0.5, 7.5, 0.0], p, 1, 2.0)
    for k in range(3):
        v.measurement(Kind.POSITION, [7000.0, 10.0 * k, 0.0], "x", T + 60.0, forecast=True)
    v.scene()
    ma = vm.marker_array(v.shapes, T + 60.0)
    assert ma.markers[0].action == Marker.DELETEALL
    by = {(m.ns, m.type): m for m in ma.markers[1:]}
    assert all(m.header.frame_id == fs.SCENE_FRAME and m.header.stamp.sec == int(T + 60.0)
               for m in ma.markers)
    cov = by[("covariance", Marker.SPHERE)]
    ell = geo.covariance_ellipsoid(p[:3, :3])
    assert [cov.scale.x, cov.scale.y, cov.scale.z] == pytest.approx(list(ell.size))
    o = cov.pose.orientation
    assert (o.x, o.y, o.z, o.w) == pytest.approx(ell.quaternion)
    cloud = by[("forecasts", Marker.SPHERE_LIST)]
    assert [(q.x, q.y, q.z) for q in cloud.points] == [(7000.0, 10.0 * k, 0.0) for k in range(3)]
    trail = by[("truth", Marker.LINE_STRIP)]
    assert len(trail.points) == 2 and trail.points[1].y == 450.0
    assert by[("stations", Marker.SPHERE_LIST)].points
    ids = [(m.ns, m.id) for m in ma.markers[1:]]
    assert len(ids) == len(set(ids))  # each marker its own (namespace, id)


def test_nav_sat_fix_is_the_sub_satellite_point():
    r = [4000.0, 3000.0, 4500.0]
    fix = vm.nav_sat_fix(T, r, "estimate")
    lat, lon, alt = geo.gcrs_to_geodetic(r, T)
    assert (fix.latitude, fix.longitude, fix.altitude) == (math.degrees(lat),
                                                           math.degrees(lon), alt * 1000.0)
    assert fix.header.frame_id == "estimate" and fix.header.stamp.sec == int(T)
