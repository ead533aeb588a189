"""Reference frames: ECI <-> ECEF by Earth rotation angle, WGS-84 sites, range/azimuth/elevation.

Conventions
-----------
* Units: km, km/s, rad. Epochs are UTC Julian dates ``jd_utc`` (UT1 ~= UTC is assumed).
* ECI is the project's inertial frame: ECEF rotated about +z by the IERS 2003 Earth rotation
  angle (ERA) only -- no precession, nutation or polar motion. SGP4's TEME output is used as
  this ECI directly (TEME is rotated to ECEF by GMST; GMST - ERA is ~0 at J2000 and grows by
  ~0.0128 deg per year, i.e. ~0.3 deg in 2024; inside this project the frame is consistent).
* Topocentric frame: East-North-Up (ENU) at the station's geodetic latitude/longitude.
  Azimuth is measured from north, clockwise (towards east), in [0, 2 pi); elevation in
  [-pi/2, pi/2] above the local (ellipsoid-normal) horizon.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import cast

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .constants import R_EARTH, WGS84_F

TWO_PI = 2.0 * math.pi
J2000_JD = 2451545.0
ERA_RATE = TWO_PI * 1.00273781191135448 / 86400.0
"""Rate of the Earth rotation angle, rad/s (IERS 2003; equals OMEGA_EARTH)."""

_E2 = WGS84_F * (2.0 - WGS84_F)


@dataclass(frozen=True)
class Station:
    """Ground station: geodetic latitude/longitude (rad, east positive) and WGS-84 height (km)."""

    name: str
    lat_rad: float
    lon_rad: float
    alt_km: float


COLUMBUS = Station("columbus", math.radians(39.9612), math.radians(-82.9988), 0.275)
"""Columbus, Ohio (the paper's observer)."""


def earth_rotation_angle(jd_utc: ArrayLike) -> NDArray[np.float64] | float:
    """Earth rotation angle (IERS 2003), rad in [0, 2 pi).

    ``ERA = 2 pi (0.7790572732640 + 1.00273781191135448 Du)``, ``Du = jd - 2451545.0``, evaluated
    as ``frac(jd) + 0.779... + 0.00273781191135448 Du`` to keep precision. Vectorised.
    """
    jd = np.asarray(jd_utc, dtype=float)
    du = jd - J2000_JD
    frac = np.mod(jd, 1.0)
    era = TWO_PI * np.mod(frac + 0.7790572732640 + 0.00273781191135448 * du, 1.0)
    return wrap_2pi(era)


def _rot_z(theta: ArrayLike) -> NDArray[np.float64]:
    """Frame rotations R3(theta), shape (..., 3, 3); ECI -> ECEF for theta = ERA."""
    th = np.asarray(theta, dtype=float)
    c, s = np.cos(th), np.sin(th)
    z, o = np.zeros_like(th), np.ones_like(th)
    return np.stack(
        [np.stack([c, s, z], -1), np.stack([-s, c, z], -1), np.stack([z, z, o], -1)], -2
    )


def _rotate(x: NDArray[np.float64], theta: ArrayLike, sign: float) -> NDArray[np.float64]:
    """Rotate positions (..., 3) or states (..., 6) by R3(sign * theta), km, km/s.

    ``sign = +1``: ECI -> ECEF (theta = ERA), with the ``omega x r`` term of the rotating
    frame subtracted from the velocity; ``sign = -1``: ECEF -> ECI (it is added back).
    """
    x = np.asarray(x, dtype=float)
    rot = _rot_z(sign * np.asarray(theta, dtype=float))
    r: NDArray[np.float64] = np.einsum("...ij,...j->...i", rot, x[..., :3])
    if x.shape[-1] == 3:
        return r
    if x.shape[-1] != 6:
        raise ValueError("last axis must be 3 (position) or 6 (position+velocity)")
    v = np.einsum("...ij,...j->...i", rot, x[..., 3:6])
    # v_ecef = R v_eci - w x r_ecef ;  v_eci = R^T (v_ecef + w x r_ecef)
    if sign > 0:
        wxr = ERA_RATE * np.stack([-r[..., 1], r[..., 0], np.zeros_like(r[..., 0])], -1)
        v = v - wxr
    else:
        xe = x[..., :3]
        wxr = ERA_RATE * np.stack([-xe[..., 1], xe[..., 0], np.zeros_like(xe[..., 0])], -1)
        v = np.einsum("...ij,...j->...i", rot, x[..., 3:6] + wxr)
    return np.concatenate([r, v], -1)


def eci_to_ecef(x_eci: ArrayLike, jd_utc: ArrayLike) -> NDArray[np.float64]:
    """ECI -> ECEF. ``x_eci`` (..., 3) positions [km] or (..., 6) states [km, km/s].

    ``jd_utc`` broadcasts against the leading axes (scalar or (...)).
    """
    return _rotate(np.asarray(x_eci, float), earth_rotation_angle(jd_utc), 1.0)


def ecef_to_eci(x_ecef: ArrayLike, jd_utc: ArrayLike) -> NDArray[np.float64]:
    """ECEF -> ECI, inverse of :func:`eci_to_ecef` (positions (..., 3) or states (..., 6))."""
    return _rotate(np.asarray(x_ecef, float), earth_rotation_angle(jd_utc), -1.0)


def site_ecef(lat_rad: float, lon_rad: float, alt_km: float) -> NDArray[np.float64]:
    """WGS-84 geodetic (lat, lon [rad], ellipsoidal height [km]) -> ECEF position (3,) km."""
    sl, cl = math.sin(lat_rad), math.cos(lat_rad)
    n = R_EARTH / math.sqrt(1.0 - _E2 * sl * sl)
    return np.array(
        [
            (n + alt_km) * cl * math.cos(lon_rad),
            (n + alt_km) * cl * math.sin(lon_rad),
            (n * (1.0 - _E2) + alt_km) * sl,
        ]
    )


def enu_matrix(lat_rad: float, lon_rad: float) -> NDArray[np.float64]:
    """Rotation ECEF -> local East-North-Up (3, 3); rows are the E, N, U unit vectors in ECEF."""
    sl, cl = math.sin(lat_rad), math.cos(lat_rad)
    so, co = math.sin(lon_rad), math.cos(lon_rad)
    return np.array([[-so, co, 0.0], [-sl * co, -sl * so, cl], [cl * co, cl * so, sl]])


def _enu_to_razel(
    enu: NDArray[np.float64],
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """Range km, azimuth rad in [0, 2 pi) and elevation rad of ENU vectors (..., 3) km."""
    e, n, u = enu[..., 0], enu[..., 1], enu[..., 2]
    horiz = np.hypot(e, n)
    rng = np.hypot(horiz, u)
    az = cast(NDArray[np.float64], wrap_2pi(np.arctan2(e, n)))  # np.float64 for one vector
    el = np.arctan2(u, horiz)
    return rng, az, el


def razel(
    r_ecef_km: ArrayLike, lat_rad: float, lon_rad: float, alt_km: float
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """Range [km], azimuth [rad, from north clockwise, in [0, 2 pi)], elevation [rad].

    ``r_ecef_km``: target ECEF position(s), shape (..., 3). Returns three arrays of shape (...).
    """
    rho = np.asarray(r_ecef_km, float)[..., :3] - site_ecef(lat_rad, lon_rad, alt_km)
    enu = rho @ enu_matrix(lat_rad, lon_rad).T
    return _enu_to_razel(enu)


def razel_eci(x_eci: ArrayLike, jd_utc: ArrayLike, station: Station) -> NDArray[np.float64]:
    """[range km, az rad, el rad] (..., 3) of ECI target(s) ``x_eci`` ((..., 3) or (..., 6)).

    ``jd_utc`` (UTC Julian date) is a scalar or broadcasts against the leading axes of ``x_eci``.
    """
    r_ecef = eci_to_ecef(np.asarray(x_eci, float)[..., :3], jd_utc)
    rng, az, el = razel(r_ecef, station.lat_rad, station.lon_rad, station.alt_km)
    return np.stack([rng, az, el], -1)


def razel_partials_enu(enu: NDArray[np.float64]) -> NDArray[np.float64]:
    """Analytic d[range, az, el]/d[e, n, u] (3, 3) at the topocentric ENU vector ``enu`` (3,)."""
    e, n, u = float(enu[0]), float(enu[1]), float(enu[2])
    h2 = e * e + n * n
    h = math.sqrt(h2)
    r2 = h2 + u * u
    r = math.sqrt(r2)
    return np.array(
        [
            [e / r, n / r, u / r],
            [n / h2, -e / h2, 0.0],
            [-u * e / (h * r2), -u * n / (h * r2), h / r2],
        ]
    )


def razel_jacobian_eci(x_eci6: ArrayLike, jd_utc: float, station: Station) -> NDArray[np.float64]:
    """Analytic Jacobian d[range, az, el]/d[x_eci] (3, 6) (velocity columns are zero).

    ``x_eci6``: ECI state (6,) [km, km/s] (or position (3,), still giving (3, 6)).
    Singular at the station's zenith (azimuth undefined), as for any RAE sensor.
    """
    x = np.asarray(x_eci6, float)
    m = enu_matrix(station.lat_rad, station.lon_rad)
    t = m @ _rot_z(earth_rotation_angle(jd_utc))
    enu = t @ x[:3] - m @ site_ecef(station.lat_rad, station.lon_rad, station.alt_km)
    jac = np.zeros((3, 6))
    jac[:, :3] = razel_partials_enu(enu) @ t
    return jac


def wrap_angle(a: float | ArrayLike) -> NDArray[np.float64] | float:
    """Wrap angle(s) into (-pi, pi] (residuals: the EKF innovation).

    Parameters
    ----------
    a : float or array_like
        Angle(s), rad.

    Returns
    -------
    float or ndarray
        ``pi - (pi - a) mod 2 pi``; a float for a Python float or 0-d input.
    """
    if isinstance(a, float):  # the EKF's per-channel hot path
        return math.pi - (math.pi - a) % TWO_PI
    w = math.pi - np.mod(math.pi - np.asarray(a, dtype=float), TWO_PI)
    return float(w) if np.ndim(w) == 0 else w


def wrap_2pi(a: float | ArrayLike) -> NDArray[np.float64] | float:
    """Wrap angle(s) into [0, 2 pi) (azimuths, orbital angles).

    Parameters
    ----------
    a : float or array_like
        Angle(s), rad.

    Returns
    -------
    float or ndarray
        ``a mod 2 pi`` (floor convention); a float for a Python float or 0-d input.
    """
    if isinstance(a, float):
        return a % TWO_PI
    w = np.mod(np.asarray(a, dtype=float), TWO_PI)
    return float(w) if np.ndim(w) == 0 else w


def wrap_pi(a: float | ArrayLike) -> NDArray[np.float64] | float:
    """Wrap angle(s) into [-pi, pi) (errors of forecasts against truth).

    Parameters
    ----------
    a : float or array_like
        Angle(s), rad.

    Returns
    -------
    float or ndarray
        ``(a + pi) mod 2 pi - pi``; a float for a Python float or 0-d input.
    """
    if isinstance(a, float):
        return (a + math.pi) % TWO_PI - math.pi
    w = np.mod(np.asarray(a, dtype=float) + math.pi, TWO_PI) - math.pi
    return float(w) if np.ndim(w) == 0 else w
