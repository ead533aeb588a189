"""Measurement models h(x) and their Jacobians H for the EKF (hot path: keep them cheap).

Both models expose ``kind``, ``angle_mask``, ``h(x, t_s)``, ``H(x, t_s)`` and
``h_and_H(x, t_s) -> (z, H)``. States are ECI [km, km/s] for orbits (or any state vector for
:class:`PositionModel`); ``t_s`` is seconds since the model's reference epoch.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

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


class RazelModel:
    """Range/azimuth/elevation of an ECI state seen from a ground station.

    Parameters
    ----------
    station
        Observer (WGS-84 geodetic).
    jd0_utc
        Reference epoch (UTC Julian date); ``t_s`` arguments are seconds since it.

    ``h`` returns [range km, az rad in [0, 2 pi), el rad]; ``H`` is the analytic (3, 6)
    Jacobian w.r.t. the ECI state (velocity columns zero). Same frame conventions as
    :mod:`ssa_fusion.core.frames` (ECEF = ECI rotated by the Earth rotation angle).
    """

    kind = Kind.RANGE_AZ_EL
    angle_mask = (False, True, True)

    def __init__(self, station: Station, jd0_utc: float) -> None:
        self.station = station
        self.jd0_utc = float(jd0_utc)
        self._era0 = float(earth_rotation_angle(self.jd0_utc))
        m = enu_matrix(station.lat_rad, station.lon_rad)
        s = m @ site_ecef(station.lat_rad, station.lon_rad, station.alt_km)
        self._m = [[float(v) for v in row] for row in m]
        self._s = [float(v) for v in s]

    def _enu(self, x: NDArray[np.float64], t_s: float) -> tuple[float, ...]:
        th = self._era0 + ERA_RATE * float(t_s)
        c, s = math.cos(th), math.sin(th)
        x0, x1, x2 = float(x[0]), float(x[1]), float(x[2])
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

    def h(self, x: NDArray[np.float64], t_s: float) -> NDArray[np.float64]:
        """Predicted [range km, az rad, el rad] of ECI state ``x`` at ``t_s`` s after jd0."""
        e, n, u = self._enu(x, t_s)[:3]
        r, az, el, _, _ = self._z(e, n, u)
        return np.array([r, az, el])

    def H(self, x: NDArray[np.float64], t_s: float) -> NDArray[np.float64]:
        """Analytic Jacobian d[range, az, el]/d[x] (3, 6)."""
        return self.h_and_H(x, t_s)[1]

    def h_and_H(
        self, x: NDArray[np.float64], t_s: float
    ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """``(h(x, t_s), H(x, t_s))`` in one call (EKF hot path)."""
        e, n, u, t00, t01, t02, t10, t11, t12, t20, t21, t22 = self._enu(x, t_s)
        r, az, el, h2, r2 = self._z(e, n, u)
        h = math.sqrt(h2)
        # d[r, az, el]/d[e, n, u]
        a0, a1, a2 = e / r, n / r, u / r
        b0, b1 = n / h2, -e / h2
        k = -u / (h * r2)
        c0, c1, c2 = k * e, k * n, h / r2
        jac = np.array(
            [
                [a0 * t00 + a1 * t10 + a2 * t20, a0 * t01 + a1 * t11 + a2 * t21,
                 a0 * t02 + a1 * t12 + a2 * t22, 0.0, 0.0, 0.0],
                [b0 * t00 + b1 * t10, b0 * t01 + b1 * t11, b0 * t02 + b1 * t12, 0.0, 0.0, 0.0],
                [c0 * t00 + c1 * t10 + c2 * t20, c0 * t01 + c1 * t11 + c2 * t21,
                 c0 * t02 + c1 * t12 + c2 * t22, 0.0, 0.0, 0.0],
            ]
        )
        return np.array([r, az, el]), jac
