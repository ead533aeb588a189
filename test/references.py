"""Independent references for the frame and real-Earth tests and the frame bench.

astropy (its own IERS 2010 CIO-based chain) and skyfield (equinox based, IAU 2006/2000A, its
own WGS-84 and polar motion), both on the IERS finals2000A table the project uses
(astropy-iers-data, `core.earth.eop.bundled`), offline; Vallado's SGP4 verification set; and the
comparisons of topocentric geometry against them. Imported by test/core/test_frames.py,
test/core/test_real_earth.py (the test directory is on pytest's path) and
bench/bench_frames.py (which puts it on its own). Units km, km/s, rad; epochs Unix seconds
(UTC).
"""

from __future__ import annotations

import calendar
import math
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import astropy.units as u
import astropy_iers_data
import erfa
import numpy as np
import sgp4
from astropy.coordinates import (
    ITRS,
    AltAz,
    CartesianDifferential,
    CartesianRepresentation,
    EarthLocation,
)
from astropy.time import Time
from astropy.utils import iers
from numpy.typing import NDArray
from scipy.integrate import solve_ivp
from sgp4.api import Satrec
from skyfield.api import wgs84
from skyfield.constants import AU_KM
from skyfield.data import iers as skyfield_iers
from skyfield.positionlib import ICRF
from skyfield.timelib import Time as SkyTime
from skyfield.timelib import Timescale
from skyfield.toposlib import GeographicPosition

from ssa_fusion.core.base.constants import ARCSEC
from ssa_fusion.core.earth import eop, timescales
from ssa_fusion.core.earth.frames import Station, wrap_pi

Array = NDArray[np.float64]

CATALOGS = Path(__file__).resolve().parents[1] / "config" / "catalogs"
SAMPLE = CATALOGS / "sample.tle"
"""The six-object sample catalog (LEO, high-drag LEO, GPS, GEO, Molniya)."""
ACTIVE = CATALOGS / "celestrak_active_2025-07.tle"
"""306 objects of CelesTrak's active catalog, July 2025 (its header cites its source)."""
SGP4_VER = Path(sgp4.__file__).with_name("SGP4-VER.TLE")
"""Vallado's SGP4 verification set, shipped with `sgp4`."""


def unix(year: int, month: int, day: int, hour: int = 0, minute: int = 0,
         second: float = 0.0) -> float:
    """Unix seconds of a UTC calendar date."""
    whole = int(second)
    return calendar.timegm((year, month, day, hour, minute, whole, 0, 0, 0)) + (second - whole)


def leap_second_day(t_unix: Array) -> NDArray[np.bool_]:
    """True for stamps on a UTC day that ends with a leap second (e.g. 2016-12-31).

    `core.earth.timescales` smears TAI - UTC over such a day (test_frames.test_leap_second_day_*),
    so comparisons leave those stamps out.
    """
    day = np.floor(np.asarray(t_unix, dtype=float) / 86400.0) * 86400.0
    out: NDArray[np.bool_] = timescales.tai_minus_utc(day + 86400.0) != \
        timescales.tai_minus_utc(day)
    return out


def sgp4_ver_cases() -> Iterator[tuple[Satrec, Array, Array, Array, Array]]:
    """Each element set of `SGP4_VER` at its own test times: (satrec, t, err, r, v).

    SGP4-VER.TLE gives each element set's start, stop and step (minutes) after column 69
    of line 2; `t` are the epochs, Unix s (UTC), `err` SGP4's error codes (the set's decay
    cases fail), `r`, `v` TEME km, km/s.
    """
    lines = [ln.rstrip() for ln in SGP4_VER.read_text().splitlines() if ln[:2] in ("1 ", "2 ")]
    for l1, l2 in zip(lines[::2], lines[1::2], strict=True):
        satrec = Satrec.twoline2rv(l1[:69], l2[:69])
        start, stop, step = (float(v) for v in l2[69:].split())
        minutes = np.arange(start, stop + 0.5 * step, step)
        jd = np.full(minutes.shape, satrec.jdsatepoch)
        fr = satrec.jdsatepochF + minutes / 1440.0
        err, r, v = satrec.sgp4_array(jd, fr)
        yield satrec, ((jd - timescales.UNIX_EPOCH_JD) + fr) * 86400.0, err, r, v


# --------------------------------------------------------------------------------------------
# astropy
# --------------------------------------------------------------------------------------------
@contextmanager
def astropy_offline_eop() -> Iterator[None]:
    """astropy on the bundled finals2000A (the same table as `eop.bundled`), offline."""
    with iers.conf.set_temp("auto_download", False), iers.conf.set_temp("auto_max_age", None), \
            iers.earth_orientation_table.set(iers.IERS_A.open(iers.IERS_A_FILE)):
        yield


def astropy_time(t_unix: Array) -> Time:
    """astropy Time of Unix (POSIX) stamps, through their calendar strings (sub-microsecond).

    Not ``format="unix"``: astropy's unix time runs 86400 s per UTC day also on a day with a
    leap second, so it differs from POSIX by up to 1 s on such days (its documentation).
    """
    ns = np.round(np.asarray(t_unix, dtype=float) * 1e9).astype(np.int64)
    return Time(np.datetime_as_string(ns.astype("datetime64[ns]")), format="isot", scale="utc")


def astropy_state(x: Array, t: Time, frame: type) -> Any:
    """astropy coordinates of states `x` (n, 6) km, km/s in `frame` at `t`."""
    rep = CartesianRepresentation(
        x[:, :3].T * u.km, differentials=CartesianDifferential(x[:, 3:].T * u.km / u.s))
    return frame(rep, obstime=t)


def states(coord: Any) -> Array:
    """States (n, 6) km, km/s of astropy coordinates with velocities."""
    c = coord.cartesian
    return np.concatenate([c.xyz.to_value(u.km).T,
                           c.differentials["s"].d_xyz.to_value(u.km / u.s).T], axis=1)


def location(station: Station) -> EarthLocation:
    """astropy's EarthLocation of a station (WGS-84 geodetic)."""
    return EarthLocation.from_geodetic(math.degrees(station.lon_rad) * u.deg,
                                       math.degrees(station.lat_rad) * u.deg,
                                       station.alt_km * u.km)


def astropy_razel(itrs: Any, t: Time, loc: EarthLocation) -> Array:
    """astropy's [range km, az, el] (n, 3) of ITRS positions `itrs` from `loc`, geometric.

    Topocentric ITRS -> AltAz with pressure 0 (no refraction).
    """
    topo = ITRS(itrs.cartesian - loc.get_itrs(t).cartesian, obstime=t, location=loc)
    aa = topo.transform_to(AltAz(obstime=t, location=loc, pressure=0 * u.hPa))
    return np.stack([aa.distance.to_value(u.km), aa.az.rad, aa.alt.rad], axis=-1)


# --------------------------------------------------------------------------------------------
# skyfield
# --------------------------------------------------------------------------------------------
def skyfield_timescale() -> Timescale:
    """Skyfield's timescale and polar motion from finals2000A.all (astropy-iers-data), offline.

    Skyfield's reader (`skyfield.data.iers.parse_x_y_dut1_from_finals_all`) takes the
    Bulletin A columns; ours and astropy's take Bulletin B where a row has it (they differ
    by up to 3 ms of UT1 in 1980, 1 m of topocentric range), so the rows' Bulletin B values
    (bytes 135-165 of the IERS ReadMe) replace A where given before skyfield builds its
    tables (`build_timescale_arrays`, `install_polar_motion_table`).
    """
    path = Path(astropy_iers_data.IERS_A_FILE)
    with path.open("rb") as f:
        rows = skyfield_iers.parse_x_y_dut1_from_finals_all(f)
    bulletin_b = {}
    for line in path.read_text().splitlines():
        fields = line[134:144].strip(), line[144:154].strip(), line[154:165].strip()
        if all(fields):
            bulletin_b[float(line[7:15])] = tuple(float(v) for v in fields)
    for row in rows:
        b = bulletin_b.get(float(row["utc_mjd"]))
        if b is not None:
            row["x_arcseconds"], row["y_arcseconds"], row["dut1"] = b
    daily_tt, daily_delta_t, leap_dates, leap_offsets = skyfield_iers.build_timescale_arrays(
        rows["utc_mjd"], rows["dut1"])
    ts = Timescale((daily_tt, daily_delta_t), leap_dates, leap_offsets)
    skyfield_iers.install_polar_motion_table(ts, rows)
    return ts


def checked_skyfield_timescale() -> Timescale:
    """`skyfield_timescale`, its UT1 checked against `eop.bundled` (1975-2027, to 1 us)."""
    ts = skyfield_timescale()
    t = np.linspace(unix(1975, 1, 1), unix(2027, 10, 1), 2000)
    t = t[~leap_second_day(t)]
    np.testing.assert_allclose(sky_time(ts, t).dut1, eop.bundled().at(t).dut1, rtol=0,
                               atol=1e-6)
    return ts


def sky_time(ts: Timescale, t_unix: Array) -> SkyTime:
    """Skyfield Time of Unix (UTC) stamps (whole days added to the date, leap seconds right)."""
    days = np.floor(t_unix / 86400.0)
    return ts.utc(1970, 1, 1 + days, 0, 0, t_unix - days * 86400.0)


def topos(station: Station) -> GeographicPosition:
    """Skyfield's WGS-84 position of a station."""
    return wgs84.latlon(math.degrees(station.lat_rad), math.degrees(station.lon_rad),
                        elevation_m=station.alt_km * 1e3)


def topocentric(r_gcrs: Array, t: SkyTime, site: GeographicPosition) -> ICRF:
    """Skyfield's position of GCRS positions `r_gcrs` (3, n) km at `t` seen from `site`.

    `r_gcrs` is where the object is at `t` (or where it was, light time); the site's own
    position at `t` is subtracted here.
    """
    here = site.at(t).position.km
    here = here[:, None] if here.ndim == 1 else here
    return ICRF((r_gcrs - here) / AU_KM, t=t, center=site)


def sky_razel(pos: Any) -> Array:
    """[range km, az, el] (n, 3) of a skyfield position seen from a site (`altaz`)."""
    alt, az, dist = pos.altaz()
    return np.stack([dist.km, az.radians, alt.radians], axis=-1)


def sky_radec(pos: Any) -> Array:
    """[ra, dec] (n, 2) of a skyfield position seen from a site (`radec`, astrometric)."""
    ra, dec, _ = pos.radec()
    return np.stack([ra.radians, dec.radians], axis=-1)


# --------------------------------------------------------------------------------------------
# comparisons
# --------------------------------------------------------------------------------------------
def assert_razel(z: Array, ref: Array, range_tol: float, angle_tol: float) -> None:
    """Range within `range_tol` km; azimuth (times cos el), elevation within `angle_tol`."""
    dr = np.abs(z[:, 0] - ref[:, 0])
    daz = np.abs(wrap_pi(z[:, 1] - ref[:, 1])) * np.cos(ref[:, 2])
    de = np.abs(z[:, 2] - ref[:, 2])
    assert dr.max() <= range_tol, f"range differs by {dr.max() * 1e3:.6f} m"
    assert daz.max() <= angle_tol, f"azimuth differs by {daz.max() / ARCSEC:.6f} arcsec"
    assert de.max() <= angle_tol, f"elevation differs by {de.max() / ARCSEC:.6f} arcsec"


def assert_radec(z: Array, ref: Array, angle_tol: float) -> None:
    """Right ascension (times cos dec) and declination within `angle_tol`."""
    dra = np.abs(wrap_pi(z[:, 0] - ref[:, 0])) * np.cos(ref[:, 1])
    dd = np.abs(z[:, 1] - ref[:, 1])
    assert dra.max() <= angle_tol, f"right ascension differs by {dra.max() / ARCSEC:.6f}\""
    assert dd.max() <= angle_tol, f"declination differs by {dd.max() / ARCSEC:.6f}\""


MU_J2 = (398600.4418, 6378.137, 1.08262668e-3)
"""GM (km^3/s^2), equatorial radius (km) and J2 of the reference orbits (EGM96/WGS-84)."""


def cip_pole(t_unix: float) -> Array:
    """The CIP in the GCRS at `t_unix`: (X, Y, sqrt(1 - X^2 - Y^2)) of `erfa.xys06a` (TT)."""
    x, y, _ = erfa.xys06a(2440587.5, t_unix / 86400.0 + 69.184 / 86400.0)
    return np.array([x, y, np.sqrt(1.0 - x * x - y * y)])


J3_J4 = (-2.5324105e-6, -1.6198976e-6)
"""EGM2008's J3 and J4 (unnormalised)."""


def scipy_orbit(x0: Array, t: Array, j2: bool = True, j3_j4: bool = False,
                rtn_accel: tuple[float, float, float] = (0.0, 0.0, 0.0)) -> Array:
    """Two-body (+ J2, + J3 and J4, about the pole at t[0]) by scipy, independently of
    core.motion.dynamics.

    `x0` (6,) km, km/s at t[0]; `t` (K,) increasing Unix s; returns (K, 6). J3 and J4 by
    the textbook component formulas (Vallado 8-31) in a frame whose z axis is the pole.
    `rtn_accel`: a constant acceleration (km/s^2) along the radial, along-track (h x r)
    and orbit-normal directions of the current state, beside gravity.
    """
    mu, re, j2_ = MU_J2
    p = cip_pole(float(t[0]))
    e1 = np.cross(p, [1.0, 0.0, 0.0])
    e1 /= np.linalg.norm(e1)
    rot = np.array([e1, np.cross(p, e1), p])  # GCRF -> pole frame
    j3, j4 = J3_J4

    def f(_t: float, y: Array) -> Array:
        r = np.linalg.norm(y[:3])
        a = -mu * y[:3] / r**3
        if j2:
            z = float(y[:3] @ p)
            k = 1.5 * j2_ * mu * re**2 / r**5
            a = a - k * ((1 - 5 * z * z / r**2) * y[:3] + 2 * z * p)
        if j3_j4:
            x_, y_, z_ = rot @ y[:3]
            u = z_ / r
            c3 = -2.5 * j3 * mu * re**3 / r**7
            a3 = np.array([c3 * x_ * (3 * z_ - 7 * z_**3 / r**2),
                           c3 * y_ * (3 * z_ - 7 * z_**3 / r**2),
                           c3 * (6 * z_**2 - 7 * z_**4 / r**2 - 0.6 * r**2)])
            c4 = 0.625 * j4 * mu * re**4 / r**7
            a4 = np.array([c4 * x_ * (3 - 42 * u**2 + 63 * u**4),
                           c4 * y_ * (3 - 42 * u**2 + 63 * u**4),
                           c4 * z_ * (15 - 70 * u**2 + 63 * u**4)])
            a = a + rot.T @ (a3 + a4)
        if any(rtn_accel):
            rh = y[:3] / r
            hn = np.cross(y[:3], y[3:])
            hn /= np.linalg.norm(hn)
            a = a + np.array([rh, np.cross(hn, rh), hn]).T @ np.asarray(rtn_accel, float)
        return np.concatenate([y[3:], a])

    sol = solve_ivp(f, (t[0], t[-1]), x0, t_eval=t, rtol=1e-12, atol=1e-12, method="DOP853")
    out: Array = sol.y.T
    return out
