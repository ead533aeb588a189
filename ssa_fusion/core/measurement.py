"""Measurement models h(x) and their Jacobians H for the EKF (hot path: keep them cheap).

Every model exposes ``kind``, ``angle_mask``, ``h(x, t_s)``, ``H(x, t_s)`` and
``h_and_H(x, t_s) -> (z, H)``. States are ECI [km, km/s] for orbits (or any state vector for
:class:`PositionModel`); ``t_s`` is seconds since the model's reference epoch (the
measurement's reception epoch at the station).

Light time: with ``light_time=True`` the station models see the object where it was when the
light left it, ``tau = range / c`` earlier, to first order ``r(t - tau) ~= r(t) - tau v(t)``
(the ISS moves 11-39 m in the 1.4-5 ms it takes, more than a good radar's range noise; the
second-order term ``tau^2 |a| / 2`` is below a micrometre). The Jacobian is that of this
first-order model: position columns ``H_r (I - v los^T / c)``, velocity columns
``-tau H_r``.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from .constants import C_KM_S
from .frames import ERA_RATE, Station, earth_rotation_angle, enu_matrix, site_ecef, wrap_2pi
from .types import Kind


class PositionModel:
    """Observe selected state channels: ``z = x[observed]``, ``H`` a constant selection matrix.

    Parameters
    ----------
    observed
        Observed state indices, default (0, 1, 2) (ECI position, km). Use (0,) for a pendulum's
        theta or a Van der Pol oscillator's x.
    """

    kind = Kind.POSITION

    def __init__(self, observed: tuple[int, ...] = (0, 1, 2)) -> None:
        self.observed = tuple(int(i) for i in observed)
        self.angle_mask: tuple[bool, ...] = (False,) * len(self.observed)
        m = len(self.observed)
        contiguous = self.observed == tuple(range(self.observed[0], self.observed[0] + m))
        self._slice = slice(self.observed[0], self.observed[0] + m) if contiguous else None
        self._idx = np.array(self.observed, dtype=np.intp)
        self._H_cache: dict[int, NDArray[np.float64]] = {}

    def _H(self, n: int) -> NDArray[np.float64]:
        H = self._H_cache.get(n)
        if H is None:
            H = np.zeros((len(self.observed), n))
            H[np.arange(len(self.observed)), self._idx] = 1.0
            H.setflags(write=False)  # shared between calls: never mutate
            self._H_cache[n] = H
        return H

    def h(self, x: NDArray[np.float64], t_s: float = 0.0) -> NDArray[np.float64]:
        """Predicted measurement ``x[observed]`` (a copy), shape (len(observed),)."""
        if self._slice is not None:
            return x[self._slice].copy()
        return x[self._idx]

    def H(self, x: NDArray[np.float64], t_s: float = 0.0) -> NDArray[np.float64]:
        """Return the selection Jacobian (len(observed), len(x)) (read-only, cached per size)."""
        return self._H(len(x))

    def h_and_H(
        self, x: NDArray[np.float64], t_s: float = 0.0
    ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """``(h(x), H(x))`` in one call."""
        return self.h(x, t_s), self._H(len(x))


class _StationModel:
    """What the two station models share: the station, the reference epoch, light time."""

    def __init__(self, station: Station, jd0_utc: float, light_time: bool = False) -> None:
        self.station = station
        self.jd0_utc = float(jd0_utc)
        self.light_time = bool(light_time)
        self._era0 = float(earth_rotation_angle(self.jd0_utc))
        m = enu_matrix(station.lat_rad, station.lon_rad)
        self._site_ecef = site_ecef(station.lat_rad, station.lon_rad, station.alt_km)
        s = m @ self._site_ecef
        self._m = [[float(v) for v in row] for row in m]
        self._s = [float(v) for v in s]

    def _position(self, x: NDArray[np.float64], rho: float) -> tuple[float, float, float, float]:
        """Return (x, y, z) of the object when the light left it (km), and tau (s).

        ``rho`` is the range (km) the delay is computed from; tau = 0 without light time or
        without a velocity in the state.
        """
        x0, x1, x2 = float(x[0]), float(x[1]), float(x[2])
        if not self.light_time or len(x) < 6:
            return x0, x1, x2, 0.0
        tau = rho / C_KM_S
        return x0 - tau * float(x[3]), x1 - tau * float(x[4]), x2 - tau * float(x[5]), tau

    @staticmethod
    def _jacobian(rows: tuple[tuple[float, float, float], ...], los: tuple[float, ...],
                  x: NDArray[np.float64], tau: float) -> NDArray[np.float64]:
        """Return the (m, 6) Jacobian from d z / d r at the retarded position (`rows`).

        With light time (tau > 0) the retarded position is ``r - tau v`` with
        ``tau = |rho| / c``: d/dr = I - v los^T / c (`los`: ECI unit line of sight),
        d/dv = -tau I.
        """
        if tau == 0.0:
            return np.array([[*row, 0.0, 0.0, 0.0] for row in rows])
        v0, v1, v2 = float(x[3]), float(x[4]), float(x[5])
        l0, l1, l2 = (float(v) / C_KM_S for v in los)
        out = []
        for a, b, c in rows:
            hv = a * v0 + b * v1 + c * v2
            out.append([a - hv * l0, b - hv * l1, c - hv * l2, -tau * a, -tau * b, -tau * c])
        return np.array(out)

    def site_eci(self, t_s: float) -> NDArray[np.float64]:
        """Return the station's ECI position (3,) km at ``t_s``."""
        th = self._era0 + ERA_RATE * float(t_s)
        c, s = math.cos(th), math.sin(th)
        e = self._site_ecef
        return np.array([c * e[0] - s * e[1], s * e[0] + c * e[1], e[2]])

    def H(self, x: NDArray[np.float64], t_s: float) -> NDArray[np.float64]:
        """Analytic Jacobian d z / d x (m, 6)."""
        return self.h_and_H(x, t_s)[1]

    def h(self, x: NDArray[np.float64], t_s: float) -> NDArray[np.float64]:
        """Predicted measurement of ECI state ``x`` at ``t_s`` s after jd0."""
        return self.h_and_H(x, t_s)[0]

    def h_and_H(
        self, x: NDArray[np.float64], t_s: float
    ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        raise NotImplementedError


class RazelModel(_StationModel):
    """Range/azimuth/elevation of an ECI state seen from a ground station.

    Parameters
    ----------
    station
        Observer (WGS-84 geodetic).
    jd0_utc
        Reference epoch (UTC Julian date); ``t_s`` arguments are seconds since it.
    light_time
        See the object where it was ``range / c`` earlier (module docstring).

    ``h`` returns [range km, az rad in [0, 2 pi), el rad]; ``H`` is the analytic (3, 6)
    Jacobian w.r.t. the ECI state (velocity columns zero without light time). Same frame
    conventions as :mod:`ssa_fusion.core.frames` (ECEF = ECI rotated by the Earth rotation
    angle).
    """

    kind = Kind.RANGE_AZ_EL
    angle_mask = (False, True, True)

    def _enu(self, p: tuple[float, float, float], t_s: float) -> tuple[float, ...]:
        th = self._era0 + ERA_RATE * float(t_s)
        c, s = math.cos(th), math.sin(th)
        x0, x1, x2 = p
        (m00, m01, m02), (m10, m11, m12), (m20, m21, m22) = self._m
        # T = M R3(th): ECI -> ENU rotation (m02 == 0 for ENU)
        t00, t01 = m00 * c - m01 * s, m00 * s + m01 * c
        t10, t11 = m10 * c - m11 * s, m10 * s + m11 * c
        t20, t21 = m20 * c - m21 * s, m20 * s + m21 * c
        e = t00 * x0 + t01 * x1 + m02 * x2 - self._s[0]
        n = t10 * x0 + t11 * x1 + m12 * x2 - self._s[1]
        u = t20 * x0 + t21 * x1 + m22 * x2 - self._s[2]
        return e, n, u, t00, t01, m02, t10, t11, m12, t20, t21, m22

    @staticmethod
    def _z(e: float, n: float, u: float) -> tuple[float, float, float, float, float]:
        h2 = e * e + n * n
        h = math.sqrt(h2)
        r2 = h2 + u * u
        az = float(wrap_2pi(math.atan2(e, n)))
        return math.sqrt(r2), az, math.atan2(u, h), h2, r2

    def h_and_H(
        self, x: NDArray[np.float64], t_s: float
    ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """``(h(x, t_s), H(x, t_s))`` in one call (EKF hot path)."""
        p0, p1, p2, tau = self._position(x, 0.0)
        if self.light_time:
            e, n, u = self._enu((p0, p1, p2), t_s)[:3]
            p0, p1, p2, tau = self._position(x, math.sqrt(e * e + n * n + u * u))
        e, n, u, t00, t01, t02, t10, t11, t12, t20, t21, t22 = self._enu((p0, p1, p2), t_s)
        r, az, el, h2, r2 = self._z(e, n, u)
        h = math.sqrt(h2)
        # d[r, az, el]/d[e, n, u]
        a0, a1, a2 = e / r, n / r, u / r
        b0, b1 = n / h2, -e / h2
        k = -u / (h * r2)
        c0, c1, c2 = k * e, k * n, h / r2
        rows = (
            (a0 * t00 + a1 * t10 + a2 * t20, a0 * t01 + a1 * t11 + a2 * t21,
             a0 * t02 + a1 * t12 + a2 * t22),
            (b0 * t00 + b1 * t10, b0 * t01 + b1 * t11, b0 * t02 + b1 * t12),
            (c0 * t00 + c1 * t10 + c2 * t20, c0 * t01 + c1 * t11 + c2 * t21,
             c0 * t02 + c1 * t12 + c2 * t22),
        )
        return np.array([r, az, el]), self._jacobian(rows, rows[0], x, tau)


class RadecModel(_StationModel):
    """Topocentric right ascension / declination of an ECI state seen from a ground station.

    The optical sensor's measurement: the direction of ``rho = r - r_site`` in the ECI frame,
    ``ra = atan2(rho_y, rho_x)`` in [0, 2 pi), ``dec = atan2(rho_z, hypot(rho_x, rho_y))``.
    Same parameters as `RazelModel`; ``H`` is the analytic (2, 6) Jacobian (velocity
    columns zero without light time). Singular at the celestial poles (ra undefined).
    """

    kind = Kind.RA_DEC
    angle_mask = (True, True)

    def h_and_H(
        self, x: NDArray[np.float64], t_s: float
    ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """``(h(x, t_s), H(x, t_s))`` in one call (EKF hot path)."""
        site = self.site_eci(t_s)
        p0, p1, p2, tau = self._position(x, 0.0)
        if self.light_time:
            rho = math.dist((p0, p1, p2), (float(site[0]), float(site[1]), float(site[2])))
            p0, p1, p2, tau = self._position(x, rho)
        dx, dy, dz = p0 - float(site[0]), p1 - float(site[1]), p2 - float(site[2])
        h2 = dx * dx + dy * dy
        h = math.sqrt(h2)
        r2 = h2 + dz * dz
        ra = float(wrap_2pi(math.atan2(dy, dx)))
        dec = math.atan2(dz, h)
        rows = ((-dy / h2, dx / h2, 0.0), (-dz * dx / (h * r2), -dz * dy / (h * r2), h / r2))
        r = math.sqrt(r2)
        return np.array([ra, dec]), self._jacobian(rows, (dx / r, dy / r, dz / r), x, tau)


StationModel = RazelModel | RadecModel
"""A measurement model of one ground station (radar or optical)."""

STATION_KINDS = (Kind.RANGE_AZ_EL, Kind.RA_DEC)
"""The measurement kinds a station network produces."""


class StationModels:
    """The measurement models of a station network, picked per measurement.

    A radar's measurements (kind RANGE_AZ_EL) and an optical site's (RA_DEC) name their
    station in ``frame_id``; `get` returns that station's model of that kind (built once,
    cached), or None for a station outside the network.

    Parameters
    ----------
    stations
        The network: station id -> `Station`.
    jd0_utc
        Reference epoch of every model (UTC Julian date of t = 0).
    light_time
        Light-time correction in every model (module docstring).
    """

    kind = STATION_KINDS

    def __init__(self, stations: dict[str, Station], jd0_utc: float,
                 light_time: bool = False) -> None:
        self.stations = dict(stations)
        self.jd0_utc = float(jd0_utc)
        self.light_time = bool(light_time)
        self._models: dict[tuple[int, str], StationModel] = {}

    def get(self, kind: int, frame_id: str) -> StationModel | None:
        """Return the model of `kind` at station `frame_id`, or None (unknown station or kind)."""
        key = (int(kind), frame_id)
        model = self._models.get(key)
        if model is None:
            station = self.stations.get(frame_id)
            if station is None or kind not in STATION_KINDS:
                return None
            cls = RazelModel if kind == Kind.RANGE_AZ_EL else RadecModel
            model = self._models[key] = cls(station, self.jd0_utc, self.light_time)
        return model


MeasurementModel = PositionModel | RazelModel | RadecModel | StationModels
"""What a tracker observes with: one model, or a station network's models."""
