"""Reference frames of the real Earth: GCRF, ITRF, TEME, topocentric; vectorised (pyerfa).

Frames
------
* **GCRF** (Geocentric Celestial Reference Frame; ERFA's GCRS axes) is the inertial frame of
  everything ssa_fusion estimates and publishes: states, covariances, forecasts, the
  optical sensors' right ascension and declination. It agrees with EME2000/J2000 to 23 mas
  (the frame bias), so an OEM in GCRF is read correctly by software that takes EME2000.
* **ITRF** (International Terrestrial Reference Frame, ERFA's ITRS) is the Earth-fixed frame of
  the stations (WGS-84 geodetic coordinates -> ITRF; WGS-84 and ITRF agree to centimetres).
* **TEME** (True Equator, Mean Equinox) is only where SGP4/SDP4 speak it: element sets and
  their propagation are converted on the way in (`teme_to_gcrs`).

Transformations (IERS Conventions 2010, CIO based, IAU 2006/2000A)::

    r_ITRS = W(x_p, y_p, s') R3(ERA(UT1)) Q(TT) r_GCRS

with ``Q`` the GCRS -> CIRS matrix of the CIP coordinates X, Y and the CIO locator s
(`erfa.xys06a`, `erfa.c2ixys`), ``ERA`` the Earth rotation angle of UT1 (`erfa.era00`) and
``W`` polar motion (`erfa.pom00`, s' from `erfa.sp00`). ``Q`` and ``W`` change slowly (the
fastest nutation term has a period of 5.6 days), so they are computed on a grid of whole
UTC hours and interpolated linearly, element by element: the error of that is below
1e-5 arcsec. The Earth rotation angle is computed at every epoch. Velocities carry the
``omega x r`` of the Earth's rotation (``omega`` = `ERA_RATE` about the CIP); the slow
rotation of ``Q`` and ``W`` (~1.1e-11 rad/s) is neglected in velocities: < 0.5 mm/s below
the geostationary orbit, 2 mm/s at 200,000 km.

TEME -> GCRS follows Vallado (2006) as astropy does: ``r_PEF = R3(GMST82(UT1)) r_TEME`` (PEF
is the terrestrial intermediate frame, up to the TIO locator s' < 0.1 mas), then as above
without polar motion, so ``r_GCRS = Q^T R3(GMST82 - ERA) r_TEME`` (the same for velocities).

Time: stamps are Unix seconds, UTC (`timescales`); TT for ``Q`` and s', UT1 for ERA and
GMST from the EOP (`eop`; the no-EOP mode and its size of error are described there).
Every function takes ``eop`` (default `eop.default()`).

Topocentric: East-North-Up (ENU) at the station's geodetic latitude/longitude. Azimuth from
north, clockwise (towards east), in [0, 2 pi); elevation in [-pi/2, pi/2] above the local
ellipsoid-normal horizon, geometric (no refraction; see `refraction`). Right ascension and
declination are *astrometric*: the direction from the station to the object, in the GCRF,
with no aberration applied (what a plate reduction against a star catalogue gives).

Units: km, km/s, rad, s.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import cast

import erfa
import numpy as np
from numpy.typing import ArrayLike, NDArray

from ssa_fusion.core.base.constants import R_EARTH, WGS84_F
from ssa_fusion.core.earth import eop as eop_
from ssa_fusion.core.earth.timescales import jd_tt, jd_ut1

Array = NDArray[np.float64]

TWO_PI = 2.0 * math.pi
J2000_JD = 2451545.0
ERA_RATE = TWO_PI * 1.00273781191135448 / 86400.0
"""Rate of the Earth rotation angle, rad/s of UT1 (IERS 2003; equals OMEGA_EARTH)."""

NODE_S = 3600.0
"""Spacing of the grid on which Q and W are computed and then interpolated, s."""

_E2 = WGS84_F * (2.0 - WGS84_F)


class Frame:
    """Names of the frames as messages (``header.frame_id``) and CCSDS files write them."""

    GCRF = "gcrf"
    """The inertial frame of every state, covariance and RA/Dec (module docstring)."""
    ITRF = "itrf"
    """The Earth-fixed frame (stations; ground tracks)."""
    TEME = "teme"
    """SGP4's frame (element sets only)."""
    LEGACY_ECI = "eci"
    """What states say in bags recorded before ssa_fusion used the GCRF: SGP4's TEME axes
    turned to Earth-fixed by the Earth rotation angle alone, consistent with itself but not
    with the Earth (0.3-0.4 deg off in the 2020s)."""


@dataclass(frozen=True)
class Station:
    """Ground station: geodetic latitude/longitude (rad, east positive) and WGS-84 height (km)."""

    name: str
    lat_rad: float
    lon_rad: float
    alt_km: float

    @property
    def itrs(self) -> Array:
        """Position in the ITRF (3,), km."""
        return site_itrs(self.lat_rad, self.lon_rad, self.alt_km)


COLUMBUS = Station("columbus", math.radians(39.9612), math.radians(-82.9988), 0.275)
"""Columbus, Ohio (the paper's observer)."""


# --------------------------------------------------------------------------------------------
# Q (GCRS -> CIRS) and W (polar motion) on the hourly grid
# --------------------------------------------------------------------------------------------
_NODES: dict[tuple[int, int], tuple[Array, Array]] = {}
_NODES_MAX = 200_000
"""Entries of the node cache before it is emptied (a node is two 3x3 matrices: ~150 B)."""


def _compute_nodes(keys: NDArray[np.int64], eop: eop_.EarthOrientation) -> None:
    """Compute and cache Q and W at the grid nodes ``keys`` (whole hours since 1970)."""
    t = keys.astype(float) * NODE_S
    tt1, tt2 = jd_tt(t)
    x, y, s = erfa.xys06a(tt1, tt2)
    q = erfa.c2ixys(x, y, s)
    v = eop.at(t)
    w = erfa.pom00(v.xp, v.yp, erfa.sp00(tt1, tt2))
    if len(_NODES) + len(keys) > _NODES_MAX:
        _NODES.clear()
    for k, qi, wi in zip(keys.tolist(), q, w, strict=True):
        _NODES[(eop._key, k)] = (qi, wi)


def _nodes(keys: NDArray[np.int64], eop: eop_.EarthOrientation) -> tuple[Array, Array]:
    """Q and W at the grid nodes ``keys`` (n,): two (n, 3, 3) arrays."""
    uniq, inverse = np.unique(keys, return_inverse=True)
    missing = np.array([k for k in uniq.tolist() if (eop._key, k) not in _NODES],
                       dtype=np.int64)
    if len(missing):
        _compute_nodes(missing, eop)
    got = [_NODES[(eop._key, k)] for k in uniq.tolist()]
    q = np.array([g[0] for g in got]).reshape(-1, 3, 3)
    w = np.array([g[1] for g in got]).reshape(-1, 3, 3)
    return q[inverse], w[inverse]


def _slow_matrices(t: Array, eop: eop_.EarthOrientation) -> tuple[Array, Array]:
    """Q (GCRS -> CIRS) and W (TIRS -> ITRS) at epochs ``t`` (n,): (n, 3, 3) each."""
    h = t / NODE_S
    k0 = np.floor(h)
    f = (h - k0)[:, None, None]
    keys = k0.astype(np.int64)
    n = len(t)
    if n and np.all(np.isfinite(h)):
        lo, hi = int(keys.min()), int(keys.max())
        if hi - lo < 4 * n + 64:  # a span of epochs: the hours in it, no sort of the epochs
            qs, ws = _nodes(np.arange(lo, hi + 2, dtype=np.int64), eop)
            i = keys - lo
            q0, w0 = qs[i], ws[i]
            return q0 + f * (qs[i + 1] - q0), w0 + f * (ws[i + 1] - w0)
    q, w = _nodes(np.concatenate([keys, keys + 1]), eop)
    return q[:n] + f * (q[n:] - q[:n]), w[:n] + f * (w[n:] - w[:n])


def _epochs(t_unix: ArrayLike) -> tuple[Array, tuple[int, ...]]:
    t = np.asarray(t_unix, dtype=float)
    return t.ravel(), t.shape


def _eop(eop: eop_.EarthOrientation | None) -> eop_.EarthOrientation:
    return eop_.default() if eop is None else eop


def earth_rotation_angle(t_unix: ArrayLike,
                         eop: eop_.EarthOrientation | None = None) -> Array:
    """Earth rotation angle (IERS 2003, `erfa.era00`) of UT1 at Unix (UTC) stamps, rad."""
    t, shape = _epochs(t_unix)
    e = _eop(eop)
    out: Array = erfa.era00(*jd_ut1(t, e.at(t).dut1)).reshape(shape)
    return out


def gmst82(t_unix: ArrayLike, eop: eop_.EarthOrientation | None = None) -> Array:
    """Greenwich mean sidereal time, IAU 1982 (`erfa.gmst82`), of UT1 at Unix stamps, rad."""
    t, shape = _epochs(t_unix)
    e = _eop(eop)
    out: Array = erfa.gmst82(*jd_ut1(t, e.at(t).dut1)).reshape(shape)
    return out


def rot_z(theta: ArrayLike) -> Array:
    """Return frame rotations R3(theta), shape (..., 3, 3).

    A vector's coordinates in a frame turned by +theta about z.
    """
    th = np.asarray(theta, dtype=float)
    c, s = np.cos(th), np.sin(th)
    z, o = np.zeros_like(th), np.ones_like(th)
    out: Array = np.stack(
        [np.stack([c, s, z], -1), np.stack([-s, c, z], -1), np.stack([z, z, o], -1)], -2)
    return out


def gcrs_to_cirs_matrix(t_unix: ArrayLike,
                        eop: eop_.EarthOrientation | None = None) -> Array:
    """Q(t): GCRS -> CIRS rotation (precession-nutation, frame bias), (..., 3, 3)."""
    t, shape = _epochs(t_unix)
    q, _ = _slow_matrices(t, _eop(eop))
    return q.reshape(*shape, 3, 3)


def cip_gcrs(t_unix: ArrayLike, eop: eop_.EarthOrientation | None = None) -> Array:
    """Return the Celestial Intermediate Pole (the Earth's axis), GCRF unit vectors (..., 3).

    The axis of the Earth's rotation and, to 0.5" (polar motion), of its figure: the axis
    about which J2 acts.
    """
    q = gcrs_to_cirs_matrix(t_unix, eop)
    p = q[..., 2, :]
    out: Array = p / np.linalg.norm(p, axis=-1, keepdims=True)
    return out


def pole_frame(t_unix: ArrayLike, eop: eop_.EarthOrientation | None = None) -> Array:
    """Rotation (..., 3, 3) from the GCRF to axes whose z is the Earth's pole, near ``t_unix``.

    The GCRS -> CIRS matrix Q at the whole UTC hour at or before each epoch (the pole moves
    < 0.01" in an hour): the axes in which J2 and the co-rotating atmosphere of `dynamics`
    act about z. Epochs in the same hour share one matrix (cheap for a batch).
    """
    e = _eop(eop)
    if np.ndim(t_unix) == 0:  # one epoch (the per-object filter): the cached node itself
        key = math.floor(float(np.asarray(t_unix)) / NODE_S)
        node = _NODES.get((e._key, key))
        if node is None:
            _compute_nodes(np.array([key], dtype=np.int64), e)
            node = _NODES[(e._key, key)]
        return node[0]
    t, shape = _epochs(t_unix)
    q, _ = _nodes(np.floor(t / NODE_S).astype(np.int64), e)
    return q.reshape(*shape, 3, 3)


def gcrs_to_itrs_matrix(t_unix: ArrayLike,
                        eop: eop_.EarthOrientation | None = None) -> Array:
    """GCRS -> ITRS rotation ``W R3(ERA) Q`` at Unix (UTC) stamps, (..., 3, 3)."""
    t, shape = _epochs(t_unix)
    e = _eop(eop)
    q, w = _slow_matrices(t, e)
    r = rot_z(erfa.era00(*jd_ut1(t, e.at(t).dut1)))
    out: Array = np.matmul(w, np.matmul(r, q)).reshape(*shape, 3, 3)
    return out


Matrix3 = tuple[float, float, float, float, float, float, float, float, float]
"""A 3x3 matrix as nine Python floats, row by row (the scalar path's arithmetic)."""


@dataclass(frozen=True)
class _Segment:
    """One hour of the grid, for the scalar path: Q, W and UT1 - UTC linear in it (floats)."""

    t0: float
    q0: Matrix3
    dq: Matrix3
    w0: Matrix3
    dw: Matrix3
    dut1: float
    dut1_rate: float


_SEGMENTS: dict[tuple[int, int], _Segment] = {}


def _floats(m: Array) -> Matrix3:
    v = [float(a) for a in m.ravel()]
    return (v[0], v[1], v[2], v[3], v[4], v[5], v[6], v[7], v[8])


def _segment(key: int, eop: eop_.EarthOrientation) -> _Segment:
    seg = _SEGMENTS.get((eop._key, key))
    if seg is None:
        keys = np.array([key, key + 1], dtype=np.int64)
        q, w = _nodes(keys, eop)
        t = keys.astype(float) * NODE_S
        d = eop.at(t).dut1
        if abs(d[1] - d[0]) > 0.5:  # a leap second at the hour's end: UT1 itself is smooth
            d[1] += math.copysign(1.0, d[0] - d[1])
        if len(_SEGMENTS) > _NODES_MAX:
            _SEGMENTS.clear()
        seg = _SEGMENTS[(eop._key, key)] = _Segment(
            float(t[0]), _floats(q[0]), _floats(q[1] - q[0]), _floats(w[0]),
            _floats(w[1] - w[0]), float(d[0]), float(d[1] - d[0]) / NODE_S)
    return seg


def _era_scalar(t_unix: float, dut1: float) -> float:
    """`erfa.era00` of UT1 = the UTC stamp `t_unix` (s) + `dut1` (s), rad.

    The seconds of the day are taken before `dut1` is added: a Unix stamp resolves only
    0.24 us, 1.7e-11 rad of Earth rotation.
    """
    days = math.floor(t_unix / 86400.0)
    frac = ((t_unix - days * 86400.0) + dut1) / 86400.0
    du = (2440587.5 - J2000_JD + days) + frac
    return TWO_PI * ((frac + 0.5 + 0.7790572732640 + 0.00273781191135448 * du) % 1.0)


def gcrs_to_itrs_floats(t_unix: float, eop: eop_.EarthOrientation | None = None) -> Matrix3:
    """`gcrs_to_itrs_matrix` of one epoch as nine floats, row by row.

    The fast path of the measurement models (~3 us): Q and W of the epoch's hour
    interpolated, ERA of its UT1, ``W R3(ERA) Q`` in Python floats; equal to the vectorised
    matrix to ~1e-13.
    """
    e = _eop(eop)
    seg = _segment(math.floor(t_unix / NODE_S), e)
    f = (t_unix - seg.t0) / NODE_S
    q0, dq, w0, dw = seg.q0, seg.dq, seg.w0, seg.dw
    q = [q0[i] + f * dq[i] for i in range(9)]
    w = [w0[i] + f * dw[i] for i in range(9)]
    th = _era_scalar(t_unix, seg.dut1 + seg.dut1_rate * (t_unix - seg.t0))
    c, s = math.cos(th), math.sin(th)
    r = (c * q[0] + s * q[3], c * q[1] + s * q[4], c * q[2] + s * q[5],
         c * q[3] - s * q[0], c * q[4] - s * q[1], c * q[5] - s * q[2],
         q[6], q[7], q[8])  # R3(ERA) Q
    return (w[0] * r[0] + w[1] * r[3] + w[2] * r[6], w[0] * r[1] + w[1] * r[4] + w[2] * r[7],
            w[0] * r[2] + w[1] * r[5] + w[2] * r[8], w[3] * r[0] + w[4] * r[3] + w[5] * r[6],
            w[3] * r[1] + w[4] * r[4] + w[5] * r[7], w[3] * r[2] + w[4] * r[5] + w[5] * r[8],
            w[6] * r[0] + w[7] * r[3] + w[8] * r[6], w[6] * r[1] + w[7] * r[4] + w[8] * r[7],
            w[6] * r[2] + w[7] * r[5] + w[8] * r[8])


def gcrs_to_itrs_matrix1(t_unix: float, eop: eop_.EarthOrientation | None = None
                         ) -> Array:
    """`gcrs_to_itrs_matrix` of one epoch (3, 3), by the scalar path `gcrs_to_itrs_floats`."""
    return np.array(gcrs_to_itrs_floats(t_unix, eop)).reshape(3, 3)


def _apply(m: Array, v: Array) -> Array:
    out: Array = np.einsum("...ij,...j->...i", m, v)
    return out


def _parts(x: ArrayLike, t_unix: ArrayLike) -> tuple[Array, Array, tuple[int, ...]]:
    """``x`` (..., 3|6) broadcast against the epochs, and the epochs as given (as an array)."""
    xa = np.asarray(x, dtype=float)
    if xa.shape[-1] not in (3, 6):
        raise ValueError("last axis must be 3 (position) or 6 (position+velocity)")
    t = np.asarray(t_unix, dtype=float)
    lead = np.broadcast_shapes(xa.shape[:-1], t.shape)
    return np.broadcast_to(xa, (*lead, xa.shape[-1])), t, lead


def _omega_cross(r: Array) -> Array:
    """ERA_RATE z x r for positions (..., 3)."""
    return ERA_RATE * np.stack([-r[..., 1], r[..., 0], np.zeros(r.shape[:-1])], -1)


def _rq_w(t: Array, eop: eop_.EarthOrientation | None) -> tuple[Array, Array]:
    """R3(ERA) Q and W at epochs ``t`` (any shape): two (*t.shape, 3, 3) arrays."""
    e = _eop(eop)
    flat = t.ravel()
    q, w = _slow_matrices(flat, e)
    rq = np.matmul(rot_z(erfa.era00(*jd_ut1(flat, e.at(flat).dut1))), q)
    return rq.reshape(*t.shape, 3, 3), w.reshape(*t.shape, 3, 3)


def gcrs_to_itrs(x: ArrayLike, t_unix: ArrayLike,
                 eop: eop_.EarthOrientation | None = None) -> Array:
    """GCRF -> ITRF of positions (..., 3) km or states (..., 6) km, km/s at Unix stamps.

    ``t_unix`` broadcasts against the leading axes of ``x`` (the rotations are computed once
    per epoch given). Velocities: ``v_ITRS = W (R Q v - omega x (R Q r))``.
    """
    xs, t, _ = _parts(x, t_unix)
    rq, w = _rq_w(t, eop)
    r_tirs = _apply(rq, xs[..., :3])
    out = _apply(w, r_tirs)
    if xs.shape[-1] == 6:
        v_tirs = _apply(rq, xs[..., 3:]) - _omega_cross(r_tirs)
        out = np.concatenate([out, _apply(w, v_tirs)], -1)
    return out


def itrs_to_gcrs(x: ArrayLike, t_unix: ArrayLike,
                 eop: eop_.EarthOrientation | None = None) -> Array:
    """ITRF -> GCRF, the inverse of `gcrs_to_itrs` (positions (..., 3) or states (..., 6))."""
    xs, t, _ = _parts(x, t_unix)
    rq, w = _rq_w(t, eop)
    wt, rq_t = np.swapaxes(w, -1, -2), np.swapaxes(rq, -1, -2)
    r_tirs = _apply(wt, xs[..., :3])
    out = _apply(rq_t, r_tirs)
    if xs.shape[-1] == 6:
        v_tirs = _apply(wt, xs[..., 3:]) + _omega_cross(r_tirs)
        out = np.concatenate([out, _apply(rq_t, v_tirs)], -1)
    return out


def teme_to_gcrs_matrix(t_unix: ArrayLike,
                        eop: eop_.EarthOrientation | None = None) -> Array:
    """TEME -> GCRS rotation ``Q^T R3(GMST82 - ERA)`` at Unix stamps, (..., 3, 3).

    Positions and velocities alike (module docstring).
    """
    t, shape = _epochs(t_unix)
    e = _eop(eop)
    q, _ = _slow_matrices(t, e)
    ut1 = jd_ut1(t, e.at(t).dut1)
    r3 = rot_z(erfa.gmst82(*ut1) - erfa.era00(*ut1))
    out: Array = np.matmul(np.swapaxes(q, -1, -2), r3).reshape(*shape, 3, 3)
    return out


def _rotate_parts(m: Array, xs: Array) -> Array:
    out: Array = np.concatenate(
        [_apply(m, xs[..., k:k + 3]) for k in range(0, xs.shape[-1], 3)], -1)
    return out


def teme_to_gcrs(x: ArrayLike, t_unix: ArrayLike,
                 eop: eop_.EarthOrientation | None = None) -> Array:
    """TEME (SGP4's output) -> GCRF, positions (..., 3) or states (..., 6), km, km/s."""
    xs, t, _ = _parts(x, t_unix)
    return _rotate_parts(teme_to_gcrs_matrix(t, eop), xs)


def gcrs_to_teme(x: ArrayLike, t_unix: ArrayLike,
                 eop: eop_.EarthOrientation | None = None) -> Array:
    """GCRF -> TEME, the inverse of `teme_to_gcrs` (an OEM in TEME, an SGP4 fit)."""
    xs, t, _ = _parts(x, t_unix)
    return _rotate_parts(np.swapaxes(teme_to_gcrs_matrix(t, eop), -1, -2), xs)


# --------------------------------------------------------------------------------------------
# Stations and topocentric measurements
# --------------------------------------------------------------------------------------------
def site_itrs(lat_rad: float, lon_rad: float, alt_km: float) -> Array:
    """WGS-84 geodetic (lat, lon [rad], ellipsoidal height [km]) -> ITRF position (3,) km."""
    sl, cl = math.sin(lat_rad), math.cos(lat_rad)
    n = R_EARTH / math.sqrt(1.0 - _E2 * sl * sl)
    return np.array(
        [
            (n + alt_km) * cl * math.cos(lon_rad),
            (n + alt_km) * cl * math.sin(lon_rad),
            (n * (1.0 - _E2) + alt_km) * sl,
        ]
    )


def site_gcrs(station: Station, t_unix: ArrayLike,
              eop: eop_.EarthOrientation | None = None) -> Array:
    """Return the station's GCRF position (..., 3), km, at Unix stamps (shape of ``t_unix``)."""
    t = np.asarray(t_unix, dtype=float)
    return itrs_to_gcrs(np.broadcast_to(station.itrs, (*t.shape, 3)), t, eop)


def enu_matrix(lat_rad: float, lon_rad: float) -> Array:
    """Rotation ITRF -> local East-North-Up (3, 3); rows are the E, N, U unit vectors."""
    sl, cl = math.sin(lat_rad), math.cos(lat_rad)
    so, co = math.sin(lon_rad), math.cos(lon_rad)
    return np.array([[-so, co, 0.0], [-sl * co, -sl * so, cl], [cl * co, cl * so, sl]])


def _enu_to_razel(enu: Array) -> tuple[Array, Array, Array]:
    """Range km, azimuth rad in [0, 2 pi) and elevation rad of ENU vectors (..., 3) km."""
    e, n, u = enu[..., 0], enu[..., 1], enu[..., 2]
    horiz = np.hypot(e, n)
    rng = np.hypot(horiz, u)
    az = cast(Array, wrap_2pi(np.arctan2(e, n)))
    el = np.arctan2(u, horiz)
    return rng, az, el


def razel_itrs(r_itrs_km: ArrayLike, station: Station) -> Array:
    """[range km, azimuth rad in [0, 2 pi), elevation rad] (..., 3) of ITRF positions."""
    rho = np.asarray(r_itrs_km, float)[..., :3] - station.itrs
    enu = rho @ enu_matrix(station.lat_rad, station.lon_rad).T
    return np.stack(_enu_to_razel(enu), -1)


def razel_gcrs(x_gcrs: ArrayLike, t_unix: ArrayLike, station: Station,
               eop: eop_.EarthOrientation | None = None) -> Array:
    """[range km, az rad, el rad] (..., 3) of GCRF target(s) (..., 3 or 6) seen from `station`.

    Geometric (the target where it is at ``t_unix``; see `lighttime` for where it was when
    the light left it). ``t_unix`` is a scalar or broadcasts against the leading axes.
    """
    r = gcrs_to_itrs(np.asarray(x_gcrs, float)[..., :3], t_unix, eop)
    return razel_itrs(r, station)


def radec_gcrs(x_gcrs: ArrayLike, t_unix: ArrayLike, station: Station,
               eop: eop_.EarthOrientation | None = None) -> Array:
    """Astrometric [ra rad in [0, 2 pi), dec rad] (..., 2) of GCRF target(s) from `station`.

    The direction of ``r - r_site(t)`` in the GCRF, no aberration (module docstring).
    """
    x = np.asarray(x_gcrs, float)[..., :3]
    t = np.broadcast_to(np.asarray(t_unix, dtype=float), x.shape[:-1])
    rho = x - site_gcrs(station, t, eop)
    ra = cast(Array, wrap_2pi(np.arctan2(rho[..., 1], rho[..., 0])))
    dec = np.arctan2(rho[..., 2], np.hypot(rho[..., 0], rho[..., 1]))
    return np.stack([ra, dec], -1)


def razel_partials_enu(enu: Array) -> Array:
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


def razel_jacobian_gcrs(x_gcrs6: ArrayLike, t_unix: float, station: Station,
                        eop: eop_.EarthOrientation | None = None) -> Array:
    """Analytic Jacobian d[range, az, el]/d[x_gcrs] (3, 6) (velocity columns are zero).

    Singular at the station's zenith (azimuth undefined), as for any RAE sensor.
    """
    x = np.asarray(x_gcrs6, float)
    m = enu_matrix(station.lat_rad, station.lon_rad)
    t = m @ gcrs_to_itrs_matrix(float(t_unix), eop)
    enu = t @ x[:3] - m @ station.itrs
    jac = np.zeros((3, 6))
    jac[:, :3] = razel_partials_enu(enu) @ t
    return jac


# --------------------------------------------------------------------------------------------
# Angles
# --------------------------------------------------------------------------------------------
def wrap_angle(a: float | ArrayLike) -> NDArray[np.float64] | float:
    """Wrap angle(s) into (-pi, pi] (residuals: the EKF innovation).

    ``pi - (pi - a) mod 2 pi`` of `a` (rad, float or array_like): a float for a Python float
    or a 0-d input, else an array.
    """
    if isinstance(a, float):  # the EKF's per-channel hot path
        return math.pi - (math.pi - a) % TWO_PI
    return _float_if_scalar(math.pi - np.mod(math.pi - np.asarray(a, dtype=float), TWO_PI))


def wrap_2pi(a: float | ArrayLike) -> NDArray[np.float64] | float:
    """Wrap angle(s) into [0, 2 pi) (azimuths, orbital angles).

    ``a mod 2 pi`` (floor convention); a float or an array as `wrap_angle`.
    """
    if isinstance(a, float):
        return a % TWO_PI
    return _float_if_scalar(np.mod(np.asarray(a, dtype=float), TWO_PI))


def wrap_pi(a: float | ArrayLike) -> NDArray[np.float64] | float:
    """Wrap angle(s) into [-pi, pi) (errors of forecasts against truth).

    ``(a + pi) mod 2 pi - pi``; a float or an array as `wrap_angle`.
    """
    if isinstance(a, float):
        return (a + math.pi) % TWO_PI - math.pi
    return _float_if_scalar(np.mod(np.asarray(a, dtype=float) + math.pi, TWO_PI) - math.pi)


def _float_if_scalar(w: NDArray[np.float64]) -> NDArray[np.float64] | float:
    """Return a 0-d array as a float, any other as it is."""
    return float(w) if np.ndim(w) == 0 else w


def cross3(a: Array, b: Array) -> Array:
    """Return the cross products of the 3-vectors (..., 3) `a` and `b` (broadcast).

    The arithmetic of `numpy.cross` (the same numbers), without its axis handling, which
    costs ~50 us a call: what small arrays spend most of their time in.
    """
    a0, a1, a2 = a[..., 0], a[..., 1], a[..., 2]
    b0, b1, b2 = b[..., 0], b[..., 1], b[..., 2]
    out = np.empty(np.broadcast_shapes(a.shape, b.shape))
    out[..., 0] = a1 * b2 - a2 * b1
    out[..., 1] = a2 * b0 - a0 * b2
    out[..., 2] = a0 * b1 - a1 * b0
    return out


def rtn_axes(x_ref: ArrayLike) -> Array:
    """Return the radial, along-track and cross-track (RTN) axes of GCRF states.

    Unit axes (k, 3, 3) of states (k, 6): row 0
    r/|r|, row 2 the orbit normal h/|h|, row 1 = row 2 x row 0.
    """
    x = np.atleast_2d(np.asarray(x_ref, float))
    r, v = x[:, :3], x[:, 3:]
    rh = r / np.sqrt((r * r).sum(axis=1, keepdims=True))  # as np.linalg.norm, cheaper
    h = cross3(r, v)
    nh = h / np.sqrt((h * h).sum(axis=1, keepdims=True))
    return np.stack([rh, cross3(nh, rh), nh], axis=1)
