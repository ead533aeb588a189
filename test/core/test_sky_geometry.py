"""The Sun, the Earth's shadow, station visibility and light time, against independent
references: astropy (the Sun), skyfield (rise and set times of a real ISS element set)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from ssa_fusion.core.base.constants import R_EARTH
from ssa_fusion.core.earth import frames, lighttime, sun, visibility
from ssa_fusion.core.earth.stations import STATIONS
from ssa_fusion.core.earth.timescales import UNIX_EPOCH_JD

# ISS (ZARYA), NORAD 25544, epoch 2019-12-31 19:42 UTC (the sgp4 package's test suite)
ISS_TLE = ("1 25544U 98067A   20001.82137887  .00016717  00000-0  10270-3 0  9127",
           "2 25544  51.6392  96.6358 0005156  88.7140 271.4601 15.49497216  6061")


def test_sun_direction_matches_astropy():
    """Within 25" of astropy's apparent Sun in the GCRS over dates 2000-2026 (astropy's
    bundled IERS data, offline): ours is geometric, astropy's carries the annual aberration
    (20.5") and 8 min of light time; the distance within 1e-4."""
    astropy_time = pytest.importorskip("astropy.time")
    coords = pytest.importorskip("astropy.coordinates")
    from astropy.utils import iers

    iers.conf.auto_download = False
    iers.conf.auto_max_age = None
    jd = np.array([2451545.0, 2453371.75, 2455197.5, 2458849.5, 2460676.5, 2461192.25])
    t = astropy_time.Time(jd, format="jd", scale="utc")
    ref = coords.get_sun(t).cartesian.xyz.value.T
    ours = sun.sun_position_gcrs((jd - UNIX_EPOCH_JD) * 86400.0)
    cos = np.sum(ours * ref, axis=1) / np.linalg.norm(ours, axis=1) / np.linalg.norm(ref, axis=1)
    worst = np.degrees(np.arccos(np.clip(cos, -1, 1))).max() * 3600.0
    assert 15.0 < worst < 25.0, worst
    dist = np.linalg.norm(ref, axis=1) * 149597870.7  # au -> km
    assert np.allclose(np.linalg.norm(ours, axis=1), dist, rtol=1e-4)


def test_earth_shadow():
    s = np.array([1.5e8, 0.0, 0.0])
    assert sun.in_earth_shadow([-7000.0, 0.0, 0.0], s)  # behind the Earth
    assert not sun.in_earth_shadow([-7000.0, 0.0, R_EARTH + 10.0], s)  # beside the shadow
    assert not sun.in_earth_shadow([7000.0, 0.0, 0.0], s)  # on the day side


def _iss_states(t_unix: np.ndarray) -> np.ndarray:
    """GCRF states of the ISS element set at Unix epochs (SGP4's TEME turned to the GCRF)."""
    from sgp4.api import Satrec

    sat = Satrec.twoline2rv(*ISS_TLE)
    jd = UNIX_EPOCH_JD + t_unix / 86400.0
    jd_int = np.floor(jd)
    err, r, v = sat.sgp4_array(jd_int, jd - jd_int)
    assert not err.any()
    return frames.teme_to_gcrs(np.concatenate([r, v], axis=1), t_unix)


def test_iss_spends_a_third_of_its_orbit_in_shadow():
    t = 1577836800.0 + np.arange(0.0, 86400.0, 10.0)  # 2020-01-01
    x = _iss_states(t)
    frac = 1.0 - sun.sunlit(x[:, :3], t).mean()
    assert 0.30 < frac < 0.42, frac  # ~35 min of a 92 min orbit at low beta angle


def test_rise_and_set_times_match_skyfield():
    """Passes of the ISS over Columbus above 10 deg on 2020-01-01 from our frames against
    skyfield's find_events: within 1.5 s (the grid is 1 s; skyfield's own UT1 and
    its root finding)."""
    api = pytest.importorskip("skyfield.api")
    ts = api.load.timescale(builtin=True)
    sat = api.EarthSatellite(*ISS_TLE, "ISS", ts)
    st = STATIONS["columbus"]
    topos = api.wgs84.latlon(math.degrees(st.lat_rad), math.degrees(st.lon_rad),
                             elevation_m=st.alt_km * 1000.0)
    t0 = ts.utc(2020, 1, 1)
    t1 = ts.utc(2020, 1, 2)
    times, events = sat.find_events(topos, t0, t1, altitude_degrees=10.0)
    ref = [(float(tt.utc_datetime().timestamp()), int(e)) for tt, e in zip(times, events,
                                                                            strict=True)]
    rises = [t for t, e in ref if e == 0]
    sets = [t for t, e in ref if e == 2]
    assert len(rises) >= 3
    grid = 1577836800.0 + np.arange(0.0, 86400.0, 1.0)
    x = _iss_states(grid)
    up = visibility.above_mask(x, grid, st, math.radians(10.0))
    edges = np.diff(up.astype(int))
    ours_rise = grid[1:][edges == 1]
    ours_set = grid[1:][edges == -1]
    assert len(ours_rise) == len(rises) and len(ours_set) == len(sets)
    assert np.abs(ours_rise - rises).max() < 1.5, np.abs(ours_rise - rises)
    assert np.abs(ours_set - sets).max() < 1.5, np.abs(ours_set - sets)


def test_optical_rules():
    """An optical site sees only at night (sun below -12 deg) an object in sunlight."""
    st = STATIONS["socorro"]
    t = 1735689600.0 + np.arange(0.0, 86400.0, 600.0)
    dark = visibility.station_dark(t, st)
    el = sun.sun_elevation(t, st)
    assert np.array_equal(dark, el < math.radians(-12.0))
    assert 0.3 < dark.mean() < 0.7  # January in New Mexico: long nights
    # a point straight above the site at 1000 km: visible iff dark and sunlit
    site = frames.site_gcrs(st, t)
    above = site * (1 + 1000.0 / np.linalg.norm(site, axis=1))[:, None]
    seen = visibility.optical_visible(above, t, st, math.radians(20.0))
    assert np.array_equal(seen, dark & sun.sunlit(above, t))
    assert seen.any() and not seen.all()


def test_light_time_of_the_iss_in_view():
    """1.4-5 ms from the ISS to Columbus while above 10 deg (range / c), and the exact
    retarded positions move 11-39 m (7.7 km/s for 1.4-5 ms)."""
    t = 1577836800.0 + np.arange(0.0, 86400.0, 10.0)
    x = _iss_states(t)
    st = STATIONS["columbus"]
    up = visibility.above_mask(x, t, st, math.radians(10.0))
    tau = lighttime.light_time_delay(x[up, :3], st, t[up])
    assert tau.min() > 1.4e-3 and tau.max() < 5.0e-3
    ret = lighttime.retarded_states(_iss_states, t[up], st)
    moved = np.linalg.norm(ret[:, :3] - x[up, :3], axis=1) * 1000.0
    assert moved.min() > 11.0 and moved.max() < 39.0
    # the delay from the retarded position differs from range / c by v_r tau / c (~1e-5)
    again = lighttime.light_time_delay(ret[:, :3], st, t[up])
    assert np.allclose(again, tau, rtol=1e-4)


def test_the_diffuse_sphere_phase_function_and_the_apparent_magnitude():
    """F(0) = 1, F(90 deg) = 1/pi, F(180 deg) = 0; the magnitude against the same formula
    evaluated with astropy's site and Sun (GCRS), within 0.01 mag."""
    assert visibility.diffuse_sphere_phase([0.0, math.pi / 2, math.pi]) == pytest.approx(
        [1.0, 1.0 / math.pi, 0.0], abs=1e-15)
    astropy_time = pytest.importorskip("astropy.time")
    coords = pytest.importorskip("astropy.coordinates")
    from astropy import units as u
    from astropy.utils import iers

    iers.conf.auto_download = False
    iers.conf.auto_max_age = None
    st = STATIONS["socorro"]
    t = 1.7e9 + np.array([0.0, 3600.0, 7200.0])
    x = np.array([[7000.0, 0.0, 0.0], [0.0, 7000.0, 1000.0], [-3000.0, -4000.0, 5000.0]])
    ours = visibility.apparent_magnitude(x, t, st, -1.3)
    when = astropy_time.Time(t, format="unix", scale="utc")
    site = coords.EarthLocation.from_geodetic(math.degrees(st.lon_rad) * u.deg,
                                              math.degrees(st.lat_rad) * u.deg,
                                              st.alt_km * u.km)
    r_site = site.get_gcrs(when).cartesian.xyz.to_value(u.km).T
    r_sun = coords.get_sun(when).cartesian.xyz.to_value(u.km).T
    to_site, to_sun = r_site - x, r_sun - x
    rng = np.linalg.norm(to_site, axis=1)
    phase = np.arccos(np.sum(to_site * to_sun, axis=1) / rng / np.linalg.norm(to_sun, axis=1))
    f = (np.sin(phase) + (math.pi - phase) * np.cos(phase)) / math.pi
    ref = -1.3 + 5 * np.log10(rng / 1000.0) - 2.5 * np.log10(f * math.pi)
    np.testing.assert_allclose(ours, ref, atol=0.01)
