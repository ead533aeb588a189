"""Tests of ssa_fusion.core.earth.frames, timescales and eop against independent references.

References: astropy (its own IERS 2010 CIO-based chain and TEME per Vallado 2006, given the
same IERS finals2000A table as ours), skyfield (equinox-based IAU 2006/2000A, its own WGS-84
and polar motion, reading the same table), Vallado's published worked examples, the SOFA/ERFA
test values, the IERS definitions, and finite differences. Units km, km/s, rad; epochs Unix
seconds (UTC).

One module of ~650 lines: the astropy and skyfield references (test/references.py) are set
up once per module (module-scoped fixtures) for every comparison here.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from pathlib import Path

import astropy.units as u
import erfa
import numpy as np
import pytest
from astropy.coordinates import (
    GCRS,
    ITRS,
    TEME,
    CartesianRepresentation,
    EarthLocation,
)
from astropy.table import QTable
from astropy.utils import iers
from references import (
    SAMPLE,
    Array,
    assert_radec,
    assert_razel,
    astropy_offline_eop,
    astropy_razel,
    astropy_state,
    astropy_time,
    checked_skyfield_timescale,
    leap_second_day,
    location,
    sgp4_ver_cases,
    sky_radec,
    sky_razel,
    sky_time,
    states,
    topos,
    unix,
)
from skyfield.api import EarthSatellite
from skyfield.timelib import Timescale

from ssa_fusion.core.base.constants import ARCSEC, R_EARTH
from ssa_fusion.core.earth import eop, frames, timescales
from ssa_fusion.core.earth.frames import (
    COLUMBUS,
    ERA_RATE,
    Station,
    earth_rotation_angle,
    gcrs_to_itrs,
    gcrs_to_itrs_matrix,
    gcrs_to_itrs_matrix1,
    gcrs_to_teme,
    gmst82,
    itrs_to_gcrs,
    razel_gcrs,
    razel_itrs,
    razel_jacobian_gcrs,
    site_itrs,
    teme_to_gcrs,
    wrap_2pi,
    wrap_angle,
    wrap_pi,
)
from ssa_fusion.core.earth.stations import SENSORS
from ssa_fusion.core.motion.element_sets import catalog_states
from ssa_fusion.formats import element_sets as catalog

POS_TOL_KM = 0.05e-3
"""Position agreement with astropy, km (5 cm). Measured <= 1.6 cm, growing with distance and
epoch (217,000 km, 2035): astropy's TEME -> ITRS leaves out the TIO locator s' (16 uas by
2035); <= 0.4 cm below GEO."""
VEL_TOL_KM_S = 1e-6
"""Velocity agreement with astropy, km/s (1 mm/s; measured <= 0.43 mm/s up to GEO)."""
SLOW_RATE = 1.2e-11
"""Bound of the rotation rate of Q, W and GMST82 - ERA, rad/s, which `frames` neglects in
velocities (its docstring says < 1e-11 rad/s; measured up to 1.08e-11 rad/s for TEME ->
GCRS): beyond GEO the velocity tolerance is ``SLOW_RATE |r|`` (measured 2.0 mm/s at
217,000 km, the verification set's farthest state)."""
TOPO_RANGE_TOL_KM = 1e-5
"""Topocentric range agreement with skyfield and astropy, km (1 cm; measured 3e-7 m against
skyfield, 0.12 mm against astropy)."""
TOPO_ANGLE_TOL = 1e-3 * ARCSEC
"""Topocentric angle agreement, rad (1 mas; measured 4e-5" against astropy, 4e-6" against
skyfield (right ascension and declination: the hourly interpolation of Q)): 100 times
tighter than the 1 m and 0.1" asked of the frames, 10-100 times looser than measured."""

DUBIOUS_YEAR = pytest.mark.filterwarnings("ignore:ERFA function.*dubious year:erfa.ErfaWarning")
"""ERFA calls a UTC year beyond its leap-second table's horizon "dubious" (2029 on, with the
table of astropy-iers-data): astropy's own time conversions warn for every such epoch (ours
do not); these tests use them on purpose."""

SITES = {s.station.name: s.station for s in SENSORS.values()}
"""The project's real sensor sites (columbus, millstone, altair, tira, socorro, maui, ...)."""


def _sgp4_ver_states() -> tuple[Array, Array]:
    """TEME states (n, 6) of Vallado's SGP4 verification set at its own test times, and epochs.

    States SGP4 flags as errors (decay cases of the set) are left out. Epochs are Unix s
    (UTC).
    """
    xs, ts = [], []
    for _, t, err, r, v in sgp4_ver_cases():
        ok = (err == 0) & np.all(np.isfinite(r), axis=1)
        xs.append(np.concatenate([r, v], axis=1)[ok])
        ts.append(t[ok])
    return np.concatenate(xs), np.concatenate(ts)


# --------------------------------------------------------------------------------------------
# astropy and skyfield, on the same IERS table as ours (test/references.py)
# --------------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def astropy_eop() -> Iterator[None]:
    """astropy on the bundled finals2000A (the same table as `eop.bundled`), offline."""
    with astropy_offline_eop():
        yield


@pytest.fixture(scope="module")
def skyfield_ts() -> Timescale:
    """Skyfield on the same EOP as ours (checked against `eop.bundled`)."""
    return checked_skyfield_timescale()


def _assert_states_close(ours: Array, ref: Array, pos_tol: float, vel_tol: float,
                         rate: float = 0.0) -> None:
    """Positions within `pos_tol` km, velocities within max(`vel_tol`, `rate` |r|) km/s."""
    dr = np.linalg.norm(ours[:, :3] - ref[:, :3], axis=1)
    dv = np.linalg.norm(ours[:, 3:] - ref[:, 3:], axis=1)
    tol_v = np.maximum(vel_tol, rate * np.linalg.norm(ref[:, :3], axis=1))
    assert dr.max() <= pos_tol, f"position differs by {dr.max() * 1e3:.4f} m"
    k = int(np.argmax(dv / tol_v))
    assert dv[k] <= tol_v[k], f"velocity differs by {dv[k] * 1e6:.4f} mm/s at |r| " \
        f"{np.linalg.norm(ref[k, :3]):.0f} km"


def _compare_chain_with_astropy(x_teme: Array, t_unix: Array,
                                e: eop.EarthOrientation) -> None:
    """TEME -> GCRS, TEME -> ITRS, GCRS -> ITRS, ITRS -> GCRS, GCRS -> TEME vs astropy."""
    t = astropy_time(t_unix)
    teme = astropy_state(x_teme, t, TEME)
    g_ref = states(teme.transform_to(GCRS(obstime=t)))
    i_ref = states(teme.transform_to(ITRS(obstime=t)))
    # Each leg on its own too: astropy's GCRS -> ITRS of our GCRS, ITRS -> GCRS of its ITRS.
    g = teme_to_gcrs(x_teme, t_unix, e)
    i_of_g = states(astropy_state(g, t, GCRS).transform_to(
        ITRS(obstime=t)))
    g_of_i = states(astropy_state(i_ref, t, ITRS).transform_to(
        GCRS(obstime=t)))
    pairs = [(g, g_ref), (gcrs_to_itrs(g, t_unix, e), i_ref),
             (gcrs_to_itrs(g, t_unix, e), i_of_g), (itrs_to_gcrs(i_ref, t_unix, e), g_of_i),
             (gcrs_to_teme(g_ref, t_unix, e), x_teme)]
    for ours, ref in pairs:
        _assert_states_close(ours, ref, POS_TOL_KM, VEL_TOL_KM_S, SLOW_RATE)


def test_teme_gcrs_itrs_of_real_element_sets_match_astropy_at_their_epochs(
        astropy_eop: None) -> None:
    # Vallado's verification set (LEO, HEO, Molniya, GEO, deep space; epochs 1980-2009) at its
    # own test times and the sample catalog hours after its epochs: the bundled EOP both sides.
    x, t = _sgp4_ver_states()
    entries = catalog.read_catalog(SAMPLE)
    t_sample = np.array([e.epoch_unix for e in entries]) + 3600.0 * np.arange(1, 7)
    jd, fr = timescales.jd_utc(t_sample)
    for k, ent in enumerate(entries):
        err, r, v = ent.satrec.sgp4(jd[k], fr[k])
        assert err == 0
        x = np.vstack([x, np.concatenate([r, v])])
    t = np.concatenate([t, t_sample])
    keep = ~leap_second_day(t)  # 2005-12-31: see test_leap_second_day_* below
    assert len(t) > 500 and np.ptp(t) > 20 * 365 * 86400.0 and keep.sum() > len(t) - 20
    _compare_chain_with_astropy(x[keep], t[keep], eop.bundled())


def _synthetic_eop(t0: float, t1: float) -> tuple[eop.EarthOrientation, iers.IERS]:
    """One realistic made-up daily EOP table, ours and astropy's, over Unix t0..t1.

    UT1 - UTC wanders in +-0.5 s and the pole circles 0.25" (Chandler-like) around a 0.35"
    mean; no leap seconds fall in the span used (none are announced after 2017).
    """
    mjd = np.arange(math.floor(t0 / 86400.0) + 40587.0, math.ceil(t1 / 86400.0) + 40588.0)
    t_rows = (mjd - 40587.0) * 86400.0
    days = mjd - mjd[0]
    dut1 = 0.1 + 0.4 * np.sin(2 * np.pi * days / 2000.0) + 0.02 * np.sin(2 * np.pi * days / 365.25)
    xp = 0.05 + 0.25 * np.cos(2 * np.pi * days / 433.0)
    yp = 0.35 + 0.25 * np.sin(2 * np.pi * days / 433.0)
    ours = eop.EarthOrientation(t_rows, dut1 - timescales.tai_minus_utc(t_rows), xp * ARCSEC,
                                yp * ARCSEC, "synthetic")
    theirs = iers.IERS(QTable({"MJD": mjd * u.d, "UT1_UTC": dut1 * u.s, "PM_x": xp * u.arcsec,
                               "PM_y": yp * u.arcsec}))
    return ours, theirs


@DUBIOUS_YEAR
@pytest.mark.parametrize("span", ["bundled 2000-2027", "synthetic 2027-2035"])
def test_teme_gcrs_itrs_at_epochs_spread_over_2000_2035_match_astropy(
        astropy_eop: None, span: str) -> None:
    # Real SGP4 states (the verification set, LEO to deep space) evaluated at frame epochs
    # spread uniformly over 2000-2035: the bundled table where it holds values (to
    # 2027-10-29), a made-up table given to both libraries beyond it.
    x, _ = _sgp4_ver_states()
    rng = np.random.default_rng(2035)
    x = x[rng.choice(len(x), 300, replace=False)]
    if span.startswith("bundled"):
        lo, hi = unix(2000, 1, 1), eop.bundled().span[1] - 86400.0
        e, table = eop.bundled(), iers.earth_orientation_table.get()
    else:
        lo, hi = eop.bundled().span[1] + 86400.0, unix(2035, 12, 31)
        e, table = _synthetic_eop(lo - 5 * 86400.0, hi + 5 * 86400.0)
    t = np.sort(rng.uniform(lo, hi, len(x)))
    t = np.where(leap_second_day(t), t - 86400.0, t)  # see test_leap_second_day_* below
    with iers.earth_orientation_table.set(table):
        assert np.all(e.covers(t))
        np.testing.assert_allclose(astropy_time(t).delta_ut1_utc,
                                   e.at(t).dut1, rtol=0, atol=1e-9)
        _compare_chain_with_astropy(x, t, e)


def test_topocentric_razel_and_radec_match_skyfield_and_astropy(
        astropy_eop: None, skyfield_ts: Timescale) -> None:
    # The sample catalog over a day from its epochs, seen from every sensor site of the
    # project: ours (catalog_states -> razel_gcrs / radec_gcrs, geometric) against skyfield's
    # (sat - topos).at(t) (geometric) and astropy's TEME -> ITRS -> topocentric AltAz
    # (pressure 0: no refraction). Every epoch counts, above the horizon or not.
    entries = catalog.read_catalog(SAMPLE)
    n_up = 0
    for station in SITES.values():
        site, loc = topos(station), location(station)
        for ent in entries:
            t = ent.epoch_unix + np.arange(0.0, 86400.0, 900.0)
            x = catalog_states([ent], t).x[0]
            z = razel_gcrs(x, t, station)
            geo = (EarthSatellite.from_satrec(ent.satrec, skyfield_ts) - site).at(
                sky_time(skyfield_ts, t))
            ref = sky_razel(geo)
            assert_razel(z, ref, TOPO_RANGE_TOL_KM, TOPO_ANGLE_TOL)
            assert_radec(frames.radec_gcrs(x, t, station), sky_radec(geo), TOPO_ANGLE_TOL)
            n_up += int(np.sum(ref[:, 2] > 0.0))
            # astropy
            tt = astropy_time(t)
            jd, fr = timescales.jd_utc(t)
            _, r, _ = ent.satrec.sgp4_array(jd, fr)
            itrs = TEME(CartesianRepresentation(r.T * u.km), obstime=tt).transform_to(
                ITRS(obstime=tt))
            assert_razel(z, astropy_razel(itrs, tt, loc), TOPO_RANGE_TOL_KM, TOPO_ANGLE_TOL)
    assert n_up > 500  # the comparison includes plenty of real passes


# --------------------------------------------------------------------------------------------
# Vallado's worked example
# --------------------------------------------------------------------------------------------
VALLADO_T = unix(2004, 4, 6, 7, 51, 28.386009)
"""2004-04-06 07:51:28.386009 UTC (Vallado, Fundamentals of Astrodynamics and Applications,
4th ed., Example 3-15; AIAA 2006-6753 Appendix C)."""
VALLADO_ITRF = np.array([-1033.4793830, 7901.2952754, 6380.3565958,
                         -3.225636520, -2.872451450, 5.531924446])
VALLADO_GCRF = np.array([5102.50895790, 6123.01140070, 6378.13692820,
                         -4.7432201570, 0.7905364970, 5.5337557270])
"""GCRF of the FK5 reduction with the EOP corrections ddpsi, ddeps (Table 3-6; the book prints
5102.508958, 6123.011401, 6378.136928 km), as SatelliteToolbox.jl's tests quote it
(JuliaSpace/SatelliteToolbox.jl, test/transformations/eci_to_eci.jl)."""
VALLADO_TEME = np.array([5094.18016210, 6127.64465950, 6380.34453270,
                         -4.7461314870, 0.7858180410, 5.5319312880])
"""TEME of the same example (Table 3-6; astropy's test_teme_itrf quotes it too)."""
VALLADO_EOP = eop.EarthOrientation(
    np.array([unix(2004, 4, 5), unix(2004, 4, 8)]), np.full(2, -0.4399619 - 32.0),
    np.full(2, -0.140682 * ARCSEC), np.full(2, 0.333309 * ARCSEC), "Vallado example 3-15")
"""The example's EOP: UT1 - UTC = -0.4399619 s (TAI - UTC = 32 s), x_p = -0.140682",
y_p = 0.333309" (held constant over the days around it)."""
VALLADO_POS_TOL_KM = 0.03e-3
"""3 cm: measured 9 mm (ITRF <-> GCRF) and 4 mm (TEME <-> GCRF). Vallado's FK5 reduction
with ddpsi/ddeps tracks the IAU 2006/2000A CIO chain to a few mas (here < 0.3 mas); the
example's dX/dY (< 0.3 mas), which we do not apply, move it 1 mm."""
VALLADO_VEL_TOL_KM_S = 0.05e-6
"""0.05 mm/s (measured 0.014 mm/s; the example's LOD changes omega x r by < 1e-6 mm/s)."""


def test_vallado_example_3_15_itrf_gcrf_teme() -> None:
    e, t = VALLADO_EOP, VALLADO_T
    assert float(e.at(t).dut1) == pytest.approx(-0.4399619, abs=1e-12)
    cases = [
        (itrs_to_gcrs(VALLADO_ITRF, t, e), VALLADO_GCRF),
        (gcrs_to_itrs(VALLADO_GCRF, t, e), VALLADO_ITRF),
        (teme_to_gcrs(VALLADO_TEME, t, e), VALLADO_GCRF),
        (gcrs_to_teme(VALLADO_GCRF, t, e), VALLADO_TEME),
        (gcrs_to_itrs(teme_to_gcrs(VALLADO_TEME, t, e), t, e), VALLADO_ITRF),
    ]
    for ours, ref in cases:
        _assert_states_close(ours[None], ref[None], VALLADO_POS_TOL_KM, VALLADO_VEL_TOL_KM_S)
    # The example does exercise the EOP: without them ITRF -> GCRF is off by 0.26 km, and
    # the bundled table's UT1 (-0.44044 s, a later analysis) moves it 0.29 m.
    no = itrs_to_gcrs(VALLADO_ITRF, t, eop.NO_EOP)
    assert np.linalg.norm(no[:3] - VALLADO_GCRF[:3]) > 0.1
    bundled = itrs_to_gcrs(VALLADO_ITRF, t, eop.bundled())
    assert 0.1e-3 < np.linalg.norm(bundled[:3] - VALLADO_GCRF[:3]) < 1e-3


# --------------------------------------------------------------------------------------------
# Sidereal time, Earth rotation angle, time scales
# --------------------------------------------------------------------------------------------
def test_gmst82_against_vallado_and_sofa() -> None:
    # Vallado Example 3-5: 1992-08-20 12:14:00 UT1 -> GMST = 152.578787810 deg, from
    # JD 2448855.009722 (1.9e-5 s early: 8e-8 deg; ERFA gives 152.5787878517 deg).
    g = gmst82(unix(1992, 8, 20, 12, 14, 0), eop.NO_EOP)
    assert math.degrees(float(g)) == pytest.approx(152.578787810, abs=1e-7)
    # Vallado Example 3-15 (UT1 = UTC - 0.4399619 s): GMST = 312.8098943 deg.
    g = gmst82(VALLADO_T, VALLADO_EOP)
    assert math.degrees(float(g)) == pytest.approx(312.8098943, abs=1e-6)
    # SOFA/ERFA test value: eraGmst82(2400000.5, 53736.0) = 1.754174981860675096 rad.
    g = gmst82((53736.0 - 40587.0) * 86400.0, eop.NO_EOP)
    assert float(g) == pytest.approx(1.754174981860675096, abs=1e-11)


def test_earth_rotation_angle_definition_sofa_and_rate() -> None:
    # IERS 2003: ERA(J2000.0 UT1) = 2 pi 0.7790572732640 (UT1 = UTC without EOP).
    era0 = earth_rotation_angle(unix(2000, 1, 1, 12), eop.NO_EOP)
    assert float(era0) == pytest.approx(2 * math.pi * 0.7790572732640, abs=1e-11)
    # SOFA/ERFA test value: eraEra00(2400000.5, 54388.0) = 0.4022837240028158102 rad.
    era = earth_rotation_angle((54388.0 - 40587.0) * 86400.0, eop.NO_EOP)
    assert float(era) == pytest.approx(0.4022837240028158102, abs=1e-11)
    # With the EOP, ERA is that of UT1 = UTC + dut1.
    t = np.array([unix(2020, 3, 1, 6), unix(2024, 11, 5, 18, 30)])
    d = eop.bundled().at(t).dut1
    np.testing.assert_allclose(earth_rotation_angle(t), earth_rotation_angle(t + d, eop.NO_EOP),
                               rtol=0, atol=1e-9)
    era = earth_rotation_angle(np.array([2.0e9, 2.0e9 + 8640.0]), eop.NO_EOP)
    assert np.all((era >= 0) & (era < 2 * math.pi))
    assert (era[1] - era[0]) % (2 * math.pi) == pytest.approx(ERA_RATE * 8640.0, abs=1e-9)


def test_leap_seconds_tai_minus_utc() -> None:
    t = np.array([unix(1972, 1, 1), unix(1972, 7, 1), unix(2016, 7, 1), unix(2017, 1, 1),
                  unix(2026, 5, 1)])
    np.testing.assert_array_equal(timescales.tai_minus_utc(t), [10, 11, 36, 37, 37])
    np.testing.assert_array_equal(timescales.tt_minus_utc(t[-1:]), [37 + 32.184])
    # Elapsed TT over a year without a leap second is the difference of the stamps; over
    # the year that ends with the leap second 2016-12-31T23:59:60, one second more.
    assert float(timescales.tt_elapsed(unix(2017, 6, 1), unix(2018, 6, 1))) == 365 * 86400
    assert float(timescales.tt_elapsed(unix(2016, 6, 1), unix(2017, 6, 1))) == 365 * 86400 + 1


def test_leap_second_day_tai_minus_utc() -> None:
    # POSIX stamps of a day that ends with a leap second: the second is inserted after
    # 23:59:59, so TAI - UTC is the day's old value until then (36 s on 2016-12-31).
    t = np.array([unix(1972, 6, 30, 12), unix(1972, 6, 30, 23, 59, 59),
                  unix(2016, 12, 31, 12), unix(2016, 12, 31, 23, 59, 59)])
    np.testing.assert_array_equal(timescales.tai_minus_utc(t), [10, 10, 36, 36])
    assert float(timescales.tt_elapsed(unix(2016, 12, 31, 23, 59, 59), unix(2017, 1, 1))) == 2


def test_leap_second_day_earth_rotation_matches_astropy(astropy_eop: None) -> None:
    # The same as the astropy comparisons above, on 2016-12-31 (UT1 - UTC = -0.408 s all
    # day): the leap second must not smear into the Earth rotation angle.
    t = np.array([unix(2016, 12, 31, 6), unix(2016, 12, 31, 12), unix(2016, 12, 31, 23)])
    np.testing.assert_allclose(eop.bundled().at(t).dut1, astropy_time(t).delta_ut1_utc,
                               rtol=0, atol=1e-6)
    x = np.tile([6778.0, 0.0, 0.0, 0.0, 7.5, 0.0], (len(t), 1))
    ref = states(astropy_state(x, astropy_time(t), GCRS).transform_to(
        ITRS(obstime=astropy_time(t))))
    _assert_states_close(gcrs_to_itrs(x, t), ref, POS_TOL_KM, VEL_TOL_KM_S)


# --------------------------------------------------------------------------------------------
# EOP tables
# --------------------------------------------------------------------------------------------
def _finals_row(yy: int, mm: int, dd: int, mjd: float, a: tuple[float, float, float] | None,
                b: tuple[float, float, float] | None = None) -> str:
    """One finals2000A line, fields at the bytes of the IERS ReadMe.finals2000A.

    `a` and `b`: Bulletin A and B (x_p ", y_p ", UT1 - UTC s); None leaves them blank.
    """
    row = [" "] * 187

    def put(first: int, last: int, text: str) -> None:
        assert len(text) <= last - first + 1
        row[first - 1:last] = list(text.rjust(last - first + 1))

    put(1, 2, f"{yy:2d}")
    put(3, 4, f"{mm:2d}")
    put(5, 6, f"{dd:2d}")
    put(8, 15, f"{mjd:8.2f}")
    if a is not None:
        put(17, 17, "I")
        put(19, 27, f"{a[0]:9.6f}")
        put(38, 46, f"{a[1]:9.6f}")
        put(58, 58, "I")
        put(59, 68, f"{a[2]:10.7f}")
    if b is not None:
        put(135, 144, f"{b[0]:10.6f}")
        put(145, 154, f"{b[1]:10.6f}")
        put(155, 165, f"{b[2]:11.7f}")
    return "".join(row).rstrip()


FINALS_ROWS = [
    # The rows of 2016-12-31 and 2017-01-01 of finals2000A.all (a leap second between them),
    # a row with Bulletin A only (B blank: A serves), and a prediction row without values.
    _finals_row(16, 12, 31, 57753.0, (0.081400, 0.263094, -0.4077601),
                (0.081318, 0.262990, -0.4077600)),
    _finals_row(17, 1, 1, 57754.0, (0.080504, 0.263145, 0.5912821),
                (0.080450, 0.263074, 0.5912975)),
    _finals_row(17, 1, 2, 57755.0, (0.080285, 0.263605, 0.5901752)),
    _finals_row(17, 1, 3, 57756.0, None),
]


def test_read_finals_parses_a_hand_written_table_and_interpolates_linearly(
        tmp_path: Path) -> None:
    rows = FINALS_ROWS
    path = tmp_path / "finals2000A.snippet"
    path.write_text("\n".join(rows) + "\n")
    table = eop.read_finals(path)
    assert table.span == (unix(2016, 12, 31), unix(2017, 1, 2))
    # At the rows: Bulletin B where given, else A.
    v = table.at(np.array([unix(2016, 12, 31), unix(2017, 1, 1), unix(2017, 1, 2)]))
    np.testing.assert_allclose(v.dut1, [-0.4077600, 0.5912975, 0.5901752], atol=1e-12)
    np.testing.assert_allclose(v.xp / ARCSEC, [0.081318, 0.080450, 0.080285], atol=1e-12)
    np.testing.assert_allclose(v.yp / ARCSEC, [0.262990, 0.263074, 0.263605], atol=1e-12)
    # UT1 - UTC is tabulated as UT1 - TAI, which has no jump at the leap second.
    np.testing.assert_allclose(table.ut1_tai, [-0.4077600 - 36, 0.5912975 - 37,
                                               0.5901752 - 37], rtol=0, atol=1e-12)
    # In between: linear (on 2016-12-31, the leap-second day, UT1 - UTC is checked by
    # test_read_finals_interpolates_across_a_leap_second).
    v = table.at(np.array([unix(2016, 12, 31, 12), unix(2017, 1, 1, 6)]))
    assert float(v.dut1[1]) == pytest.approx(0.5912975 + (0.5901752 - 0.5912975) / 4, abs=1e-12)
    np.testing.assert_allclose(v.xp / ARCSEC, [(0.081318 + 0.080450) / 2,
                                               0.080450 + (0.080285 - 0.080450) / 4], atol=1e-12)
    np.testing.assert_allclose(v.yp / ARCSEC, [(0.262990 + 0.263074) / 2,
                                               0.263074 + (0.263605 - 0.263074) / 4], atol=1e-12)
    # Outside the table: the no-EOP values, and `covers` says so.
    out = table.at(np.array([unix(2016, 12, 30), unix(2017, 1, 3)]))
    assert not out.covered.any() and not out.dut1.any() and not out.xp.any()
    # A file that is not a finals table: a ValueError naming it.
    bad = tmp_path / "not_finals.txt"
    bad.write_text("hello\nworld\n")
    with pytest.raises(ValueError, match=r"not_finals\.txt"):
        eop.read_finals(bad)


def test_read_finals_interpolates_across_a_leap_second(tmp_path: Path) -> None:
    path = tmp_path / "finals2000A.snippet"
    path.write_text("\n".join(FINALS_ROWS) + "\n")
    v = eop.read_finals(path).at(np.array([unix(2016, 12, 31, 12)]))
    # Halfway between the rows in UT1 - TAI, then UT1 - UTC with the day's 36 s.
    assert float(v.dut1[0]) == pytest.approx((-0.4077600 + 0.5912975 - 1.0) / 2, abs=1e-9)


def test_bundled_table_matches_astropy_reading_of_the_same_file(astropy_eop: None) -> None:
    t = np.linspace(unix(1980, 1, 1), eop.bundled().span[1] - 86400.0, 3000)
    t = t[~leap_second_day(t)]  # see test_leap_second_day_* below
    v = eop.bundled().at(t)
    tt = astropy_time(t)
    np.testing.assert_allclose(v.dut1, tt.delta_ut1_utc, rtol=0, atol=1e-9)
    xp, yp = iers.earth_orientation_table.get().pm_xy(tt)
    np.testing.assert_allclose(v.xp, xp.to_value(u.rad), rtol=0, atol=1e-14)
    np.testing.assert_allclose(v.yp, yp.to_value(u.rad), rtol=0, atol=1e-14)


def test_no_eop_gives_zeros_and_the_default_follows_the_environment(
        monkeypatch: pytest.MonkeyPatch) -> None:
    t = np.array([unix(1990, 1, 1), unix(2025, 1, 1), unix(2090, 1, 1)])
    v = eop.NO_EOP.at(t)
    assert not v.dut1.any() and not v.xp.any() and not v.yp.any() and not v.covered.any()
    assert eop.NO_EOP.span == (math.inf, -math.inf)
    monkeypatch.setenv(eop.EOP_ENV, "none")
    assert eop.default() is eop.NO_EOP
    np.testing.assert_array_equal(earth_rotation_angle(t), earth_rotation_angle(t, eop.NO_EOP))
    monkeypatch.delenv(eop.EOP_ENV)
    assert eop.default() is eop.bundled()


def test_no_eop_error_is_within_the_size_eop_documents() -> None:
    # eop's docstring: |UT1 - UTC| < 0.9 s turns the Earth by up to 13.5" (~0.42 km along
    # the equator, ~0.45 km for a LEO object); polar motion adds < 0.6" (~20 m at the surface).
    b = eop.bundled()
    t = np.linspace(b.span[0] + 86400.0, b.span[1] - 86400.0, 4000)
    v = b.at(t)
    assert np.abs(v.dut1).max() > 0.75  # the table spans most of the +-0.9 s allowed
    equator = Station("equator", 0.0, 0.0, 0.0)
    d_site = np.linalg.norm(frames.site_gcrs(equator, t) - frames.site_gcrs(equator, t,
                                                                            eop.NO_EOP), axis=1)
    pm = np.hypot(v.xp, v.yp)
    assert np.all(d_site <= (np.abs(v.dut1) * ERA_RATE + pm) * R_EARTH + 1e-6)
    assert 0.35 < d_site.max() <= 0.42 + 0.02
    leo = np.array([6778.0, 0.0, 0.0])  # an ISS-like object over the equator, GCRF
    d_leo = np.linalg.norm(gcrs_to_itrs(leo, t) - gcrs_to_itrs(leo, t, eop.NO_EOP), axis=1)
    assert np.all(d_leo <= (0.9 * ERA_RATE + 0.6 * ARCSEC) * 6778.0)
    assert d_leo.max() <= 0.45 + 0.02


# --------------------------------------------------------------------------------------------
# Internal consistency
# --------------------------------------------------------------------------------------------
@DUBIOUS_YEAR
def test_scalar_matrix_equals_vectorised_one() -> None:
    rng = np.random.default_rng(16)
    leap = unix(2017, 1, 1)
    t = np.concatenate([rng.uniform(unix(1990, 1, 1), unix(2035, 1, 1), 300),
                        leap + rng.uniform(-3600.0, 3600.0, 60),  # the leap second's hours
                        [leap - 1.0, leap, leap - 3600.0, unix(2025, 1, 1, 0, 59, 59.999)]])
    m = gcrs_to_itrs_matrix(t)
    m1 = np.array([gcrs_to_itrs_matrix1(float(ti)) for ti in t])
    assert np.abs(m - m1).max() <= 1e-10
    np.testing.assert_allclose(np.einsum("nij,nkj->nik", m, m), np.broadcast_to(np.eye(3),
                               m.shape), atol=1e-12)


def test_round_trips() -> None:
    rng = np.random.default_rng(1)
    x = np.concatenate([rng.normal(0, 20000, (50, 3)), rng.normal(0, 5, (50, 3))], axis=1)
    t = rng.uniform(unix(1995, 1, 1), unix(2027, 1, 1), 50)
    np.testing.assert_allclose(itrs_to_gcrs(gcrs_to_itrs(x, t), t), x, rtol=0, atol=1e-9)
    np.testing.assert_allclose(gcrs_to_teme(teme_to_gcrs(x, t), t), x, rtol=0, atol=1e-9)
    # One epoch for many states, and positions alone, broadcast the same way.
    one = gcrs_to_itrs(x, t[0])
    np.testing.assert_allclose(one, gcrs_to_itrs(x, np.full(50, t[0])), rtol=0, atol=1e-12)
    np.testing.assert_allclose(gcrs_to_itrs(x[:, :3], t), gcrs_to_itrs(x, t)[:, :3], atol=0)


def test_velocity_transform_matches_finite_differences_of_positions() -> None:
    # An inertially moving point seen from the ITRS: d/dt of its ITRS position is the ITRS
    # velocity gcrs_to_itrs gives, up to the neglected slow rotation of Q and W (the frames
    # docstring: < 1e-11 rad/s, i.e. < 1e-11 |r| km/s; measured 0.26 mm/s at GEO).
    entries = catalog.read_catalog(SAMPLE)
    x = catalog_states(entries, entries[0].epoch_unix + 3600.0).x[:, 0]
    t = np.random.default_rng(7).uniform(unix(2001, 1, 1), unix(2027, 1, 1), 40)
    h = 1.0  # s
    for xi in x:
        v = gcrs_to_itrs(np.broadcast_to(xi, (len(t), 6)), t)[:, 3:]
        fwd = gcrs_to_itrs(xi[:3] + h * xi[3:], t + h)
        bwd = gcrs_to_itrs(xi[:3] - h * xi[3:], t - h)
        err = np.linalg.norm((fwd - bwd) / (2 * h) - v, axis=1)
        assert err.max() <= 1e-11 * np.linalg.norm(xi[:3]) + 1e-9
    # And back: a point at rest in the ITRS moves at omega x r in the GCRF, which is the
    # derivative of its GCRF positions.
    site = frames.site_itrs(0.3, 1.0, 0.2)
    g = itrs_to_gcrs(np.concatenate([site, np.zeros(3)]), t)
    fd = (itrs_to_gcrs(site, t + h) - itrs_to_gcrs(site, t - h)) / (2 * h)
    assert np.linalg.norm(fd - g[:, 3:], axis=1).max() <= 1e-11 * np.linalg.norm(site) + 1e-9
    np.testing.assert_allclose(np.linalg.norm(g[:, 3:], axis=1),
                               ERA_RATE * np.hypot(site[0], site[1]), rtol=1e-6)


def test_site_itrs_vallado_example_3_1_and_astropy() -> None:
    # Vallado, Example 3-1 (Ascension Island): lat -7 54' 23.886", lon 345 35' 51.000",
    # h = 56 m -> r_ITRF = (6119.40026, -1571.47955, -871.56118) km.
    lat = -math.radians(7 + 54 / 60 + 23.886 / 3600)
    lon = math.radians(345 + 35 / 60 + 51.0 / 3600)
    np.testing.assert_allclose(site_itrs(lat, lon, 0.056),
                               [6119.40026, -1571.47955, -871.56118], rtol=0, atol=2e-5)
    for station in SITES.values():
        loc = EarthLocation.from_geodetic(math.degrees(station.lon_rad) * u.deg,
                                          math.degrees(station.lat_rad) * u.deg,
                                          station.alt_km * u.km, ellipsoid="WGS84")
        ref = np.array([loc.x.to_value(u.km), loc.y.to_value(u.km), loc.z.to_value(u.km)])
        np.testing.assert_allclose(station.itrs, ref, rtol=0, atol=1e-9)


@DUBIOUS_YEAR
def test_cip_matches_erfa_xys06a_of_astropy_tt() -> None:
    t = np.random.default_rng(3).uniform(unix(1975, 1, 1), unix(2095, 1, 1), 300)
    tt = astropy_time(t).tt
    x, y, _ = erfa.xys06a(tt.jd1, tt.jd2)
    ref = np.stack([x, y, np.sqrt(1.0 - x * x - y * y)], axis=-1)
    cip = frames.cip_gcrs(t)
    assert np.linalg.norm(cip - ref, axis=1).max() <= 1e-10  # rad (2e-5"; measured 7e-6")
    # The pole has moved 0.1-0.5 deg from the GCRF z axis over these epochs.
    assert np.degrees(np.arccos(cip[:, 2])).max() > 0.3


def test_razel_jacobian_matches_central_differences() -> None:
    entries = catalog.read_catalog(SAMPLE)
    t = entries[0].epoch_unix + np.arange(0.0, 86400.0, 60.0)
    x = catalog_states(entries[:1], t).x[0]
    station = SITES["millstone"]
    z = razel_gcrs(x, t, station)
    k = int(np.argmax(np.where(z[:, 2] < math.radians(80.0), z[:, 2], -1.0)))
    assert z[k, 2] > math.radians(10.0)  # a real pass, away from the zenith
    xk, tk = x[k], float(t[k])
    jac = razel_jacobian_gcrs(xk, tk, station)
    assert jac.shape == (3, 6)
    num = np.zeros((3, 3))
    h = 1e-3  # km
    for j in range(3):
        dp, dm = xk.copy(), xk.copy()
        dp[j] += h
        dm[j] -= h
        diff = razel_gcrs(dp, tk, station) - razel_gcrs(dm, tk, station)
        diff[1:] = wrap_angle(diff[1:])
        num[:, j] = diff / (2 * h)
    np.testing.assert_allclose(jac[:, :3], num, rtol=1e-6, atol=1e-12)
    np.testing.assert_array_equal(jac[:, 3:], 0.0)


def test_azimuth_convention_north_clockwise() -> None:
    st = Station("equator", 0.0, 0.0, 0.0)
    site = site_itrs(0.0, 0.0, 0.0)
    targets = site + np.array([[0, 0, 100.0], [0, 100.0, 0], [0, 0, -100.0], [0, -100.0, 0]])
    z = razel_itrs(targets, st)
    np.testing.assert_allclose(z[:, 1], [0, math.pi / 2, math.pi, 3 * math.pi / 2], atol=1e-12)
    np.testing.assert_allclose(z[:, 2], 0, atol=1e-12)
    np.testing.assert_allclose(z[:, 0], 100, atol=1e-9)
    assert razel_itrs(site + np.array([500.0, 0, 0]), st)[2] == pytest.approx(math.pi / 2)
    assert COLUMBUS.itrs[2] > 0 and COLUMBUS.itrs[1] < 0  # north, west


# --------------------------------------------------------------------------------------------
# Angles
# --------------------------------------------------------------------------------------------
def test_wrap_angle_range() -> None:
    a = np.array([math.pi, -math.pi, 0.0, 3 * math.pi / 2, 7.0, -7.0])
    w = np.asarray(wrap_angle(a))
    assert np.all((w > -math.pi) & (w <= math.pi))
    np.testing.assert_allclose(np.cos(w), np.cos(a), atol=1e-12)
    np.testing.assert_allclose(np.sin(w), np.sin(a), atol=1e-12)
    assert w[0] == pytest.approx(math.pi) and w[1] == pytest.approx(math.pi)


def test_wrap_helpers_equal_the_formulas_they_replace() -> None:
    """wrap_2pi / wrap_pi / wrap_angle give bit-identical results to the expressions the
    code used before (Python float % and np.mod share the floor convention)."""
    rng = np.random.default_rng(16)
    a = np.concatenate((rng.uniform(-50.0, 50.0, 2000), rng.normal(0.0, 1e-9, 200),
                        [0.0, -0.0, math.pi, -math.pi, 2 * math.pi, -2 * math.pi, 1e-300]))
    two_pi = 2 * math.pi
    np.testing.assert_array_equal(wrap_2pi(a), np.mod(a, two_pi))
    np.testing.assert_array_equal(wrap_pi(a), (a + math.pi) % two_pi - math.pi)
    np.testing.assert_array_equal(wrap_angle(a), math.pi - np.mod(math.pi - a, two_pi))
    for v in a:
        f = float(v)
        assert wrap_2pi(f) == f % two_pi
        assert wrap_pi(f) == (f + math.pi) % two_pi - math.pi
        assert wrap_angle(f) == math.pi - (math.pi - f) % two_pi
        assert wrap_2pi(f) == float(wrap_2pi(np.array(f)))  # scalar and array paths agree
        assert wrap_pi(f) == float(wrap_pi(np.array(f)))
        assert wrap_angle(f) == float(wrap_angle(np.array(f)))
    w = np.asarray(wrap_2pi(a))
    assert np.all((w >= 0.0) & (w <= two_pi))  # == 2 pi only by rounding of tiny negatives
    w = np.asarray(wrap_pi(a))
    assert np.all((w >= -math.pi) & (w <= math.pi))

