"""The two-way laser range model (core.measure.laser_range), its troposphere and stations.

References: the IERS routines' own test cases (FCUL_A, FCUL_ZD_HPA prologs), a light-time
solution by root finding with the station rotated exactly (frames) and the satellite on an
exact Kepler orbit, finite differences; the real-data check against the CPF is in
test_laser_cpf.py.
"""

import math

import numpy as np
import pytest
from scipy.optimize import brentq

from ssa_fusion.core.base.constants import C_KM_S
from ssa_fusion.core.earth.frames import enu_matrix, itrs_to_gcrs
from ssa_fusion.core.measure import laser_range as lr
from ssa_fusion.core.measure import troposphere as tr
from ssa_fusion.core.measure.laser_station import LaserStation, velocity_per_year
from ssa_fusion.core.motion.kepler import propagate

T0 = 1455370982.4005626  # 2016-02-13 13:43 UTC, Yarragadee's first normal point
YARL = LaserStation("7090", np.array([-2389.00753398029, 5043.32944749889, -3078.52422322662]),
                    velocity_per_year([-0.0468389138240797, 0.00839461295243685,
                                       0.0509471988578335]),
                    1262304000.0, np.array([3.1827e-3, -0.0064e-3, 0.0194e-3]), 0.532, "YARL")


def _lageos_over(station: LaserStation, t: float) -> np.ndarray:
    """A LAGEOS-like GCRF state (12,270 km, circular) about 60 deg above `station` at `t`."""
    site = itrs_to_gcrs(station.itrs(t), t)
    up = site / np.linalg.norm(site)
    side = np.cross(up, [0.0, 0.0, 1.0])
    side /= np.linalg.norm(side)
    r = 12270.0 * (math.cos(0.25) * up + math.sin(0.25) * side)
    v_dir = np.cross(r, np.cross(up, side))
    v = math.sqrt(398600.4418 / 12270.0) * v_dir / np.linalg.norm(v_dir)
    return np.concatenate([r, v])


def test_fcula_and_zenith_delay_reproduce_the_iers_routines_test_cases():
    # FCUL_A prolog: McDonald, 30.67166667 deg, 2075 m, 300.15 K, 15 deg -> 3.800243667312344087
    m = tr.mapping(math.radians(15.0), 300.15, math.radians(30.67166667), 2.075)
    assert float(m) == pytest.approx(3.800243667312344087, abs=1e-14)
    # FCUL_ZD_HPA prolog: 798.4188 hPa, e 14.322 hPa, 0.532 um -> ZTD 1.935225924846803114 m;
    # the printed outputs are those of 2003.344 m (its header says 2010.344)
    d = tr.zenith_delay_km(798.4188, 14.322, 0.532, math.radians(30.67166667), 2.003344)
    assert float(d) * 1000.0 == pytest.approx(1.935225924846803114, abs=2e-10)
    # at sea level, 45 deg: the ~2.4 m every SLR text quotes; 1/sin(el) far from the horizon
    p, t, rh = tr.standard_atmosphere(0.0)
    z = tr.zenith_delay_km(p, tr.water_vapour_hpa(t, rh), 0.532, math.radians(45.0), 0.0)
    assert 2.40e-3 < float(z) < 2.46e-3
    assert float(tr.mapping(math.radians(60.0), 288.0, 0.5, 0.1)) == pytest.approx(
        1.0 / math.sin(math.radians(60.0)), rel=2e-3)


def test_water_vapour_and_standard_atmosphere():
    # 6.11 hPa at 0 C saturated (Marini-Murray); 23.4 hPa at 20 C (the tables' 23.39)
    assert float(tr.water_vapour_hpa(273.15, 100.0)) == pytest.approx(6.11)
    assert float(tr.water_vapour_hpa(293.15, 100.0)) == pytest.approx(23.39, abs=0.06)
    p, t, rh = tr.standard_atmosphere(np.array([0.0, 3.0]))
    np.testing.assert_allclose(p, [1013.25, 701.1], atol=0.2)  # US standard atmosphere 1976
    np.testing.assert_allclose(t, [288.15, 268.65])
    assert (rh == 50.0).all()


def test_meteo_series_interpolates_holds_and_gives_up():
    s = tr.MeteoSeries.of([200.0, 100.0, 100.0], [990.0, 980.0, 1.0], [290.0, 280.0, 1.0],
                          [60.0, 40.0, 1.0])  # unsorted, a tie (the first kept)
    p, t, h, found = s.at([100.0, 150.0, 200.0, 1000.0, -1800.0, 1900.0, 2100.0])
    np.testing.assert_allclose(p[:4], [980.0, 985.0, 990.0, 990.0])
    np.testing.assert_allclose(h[:3], [40.0, 50.0, 60.0])
    assert found.tolist() == [True, True, True, True, False, True, False]
    assert np.isnan(p[4]) and np.isnan(t[6])
    empty = tr.MeteoSeries.of([], [], [], [])
    assert not empty.at([1.0])[3].any()


def test_station_moves_with_its_plate_and_eccentricity():
    lat, lon, h = YARL.geodetic
    assert math.degrees(lat) == pytest.approx(-29.0465, abs=1e-3)  # SINEX SITE/ID: -29 2 47.3
    assert math.degrees(lon) % 360 == pytest.approx(115.3467, abs=1e-3)  # 115 20 48.2
    assert h * 1000 == pytest.approx(242.0, abs=2.0)  # its approximate height
    moved = YARL.itrs(T0) - YARL.itrs(YARL.t_ref)
    years = (T0 - YARL.t_ref) / (365.25 * 86400)
    np.testing.assert_allclose(moved, YARL.velocity_km_s * (T0 - YARL.t_ref))
    assert np.linalg.norm(moved) * 1e5 == pytest.approx(6.971 * years, abs=0.01)  # 6.971 cm/yr
    ecc = YARL.eccentricity_itrs_km
    up = enu_matrix(lat, lon)[2]
    assert float(ecc @ up) == pytest.approx(3.1827e-3, abs=1e-9)  # 3.18 m up


def _direct_range(station: LaserStation, x: np.ndarray, t: float) -> tuple[float, float]:
    """The two legs' light times by root finding, the station rotated exactly at each epoch."""

    def site(dt: float) -> np.ndarray:
        return itrs_to_gcrs(station.itrs(t + dt), t + dt)

    def sat(dt: float) -> np.ndarray:
        return propagate(x, dt)[0][:3]

    s0 = site(0.0)
    up = brentq(lambda tau: C_KM_S * tau - np.linalg.norm(sat(tau) - s0), 0.0, 0.1,
                xtol=1e-16)
    rb = sat(up)
    dn = brentq(lambda tau: C_KM_S * tau - np.linalg.norm(rb - site(up + tau)), 0.0, 0.1,
                xtol=1e-16)
    return up, dn


def test_light_time_matches_a_direct_solution_and_the_moving_station_matters():
    ts = T0 + np.array([0.0, 600.0])
    x = np.array([_lageos_over(YARL, t) for t in ts])
    g = lr.geometry([YARL], [0, 0], ts, tides=False)  # the direct solution's station
    model = lr.two_way_range(g, None, x, com_km=0.0, shapiro=False)
    for i, t in enumerate(ts):
        up, dn = _direct_range(YARL, x[i], t)
        assert model.tau_up[i] == pytest.approx(up, abs=2e-12)  # 0.6 mm of light
        assert model.range_km[i] == pytest.approx(0.5 * C_KM_S * (up + dn), abs=1e-6)
    # the station standing still during the flight would be metres off (the ~27 m of SOURCE)
    still = lr.LaserGeometry(g.t, g.site * np.array([1, 1, 1, 0, 0, 0]), 0 * g.site_acceleration,
                             g.gcrs_to_itrs, g.site_itrs, g.lat, g.height_km)
    off = lr.two_way_range(still, None, x, com_km=0.0, shapiro=False).range_km - model.range_km
    assert np.all(np.abs(off) > 1e-3)


def test_jacobian_matches_finite_differences():
    ts = T0 + np.array([0.0, 300.0, 900.0])
    x = np.array([_lageos_over(YARL, t) for t in ts])
    x[1, 3:] *= 1.1  # not circular
    g = lr.geometry([YARL] * 3, [0, 1, 2], ts)
    air = lr.atmosphere(980.0, 295.0, 40.0, 0.532)
    # the troposphere's partials are left out (2e-5); the velocity columns' differences
    # carry the range's round-off (1e-12 km / 2e-3 km/s)
    for air_, tols in ((None, (1e-8, 2e-9)), (air, (2e-5, 1e-6))):
        m = lr.two_way_range(g, air_, x, bias_km=0.001)
        for j, step in enumerate([1e-3] * 3 + [1e-3] * 3):
            dx = np.zeros(6)
            dx[j] = step
            fd = (lr.two_way_range(g, air_, x + dx, bias_km=0.001).range_km
                  - lr.two_way_range(g, air_, x - dx, bias_km=0.001).range_km) / (2 * step)
            np.testing.assert_allclose(m.H[:, j], fd, atol=tols[j // 3], rtol=0)
        # the bias enters with 1
        fb = (lr.two_way_range(g, air_, x, bias_km=0.002).range_km - m.range_km) / 0.001
        np.testing.assert_allclose(m.H_bias, fb, atol=1e-8)
        assert np.abs(m.H[:, 3:]).max() > 1e-3  # the light time's velocity partials are there


def test_the_solid_tide_moves_the_station_by_centimetres_to_decimetres():
    ts = T0 + np.arange(0.0, 86400.0, 3600.0)
    moved = lr.geometry([YARL] * len(ts), np.arange(len(ts)), ts)
    fixed = lr.geometry([YARL] * len(ts), np.arange(len(ts)), ts, tides=False)
    d = np.linalg.norm(moved.site[:, :3] - fixed.site[:, :3], axis=1) * 1e3
    print(f"\nYarragadee's tidal displacement over a day: {d.min():.3f}..{d.max():.3f} m")
    assert 0.05 < d.max() < 0.4 and d.min() < d.max() / 2  # twice a day up and down
    assert np.array_equal(moved.site[:, 3:], fixed.site[:, 3:])


def test_terms_have_their_sizes():
    ts = T0 + np.array([0.0])
    x = np.array([_lageos_over(YARL, ts[0])])
    g = lr.geometry([YARL], [0], ts)
    air = lr.atmosphere(*tr.standard_atmosphere(0.242), 0.532)
    full = lr.two_way_range(g, air, x)
    bare = lr.two_way_range(g, None, x, com_km=0.0, shapiro=False)
    assert 4e-6 < full.shapiro_km[0] < 9e-6  # ~6 mm: SOURCE's "about 7 mm"
    assert 2.4e-3 < full.troposphere_km[0] < 3.5e-3  # 60 deg elevation: ~2.7 m
    assert math.degrees(full.elevation[0]) == pytest.approx(61.0, abs=3.0)
    expected = full.troposphere_km + full.shapiro_km - lr.LAGEOS_COM_KM
    np.testing.assert_allclose(full.range_km - bare.range_km, expected, atol=1e-12)
