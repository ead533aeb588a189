"""Measurement models h(x) and their Jacobians H for the EKF (hot path: keep them cheap).

Every model exposes ``kind``, ``angle_mask``, ``h(x, t_s)``, ``H(x, t_s)`` and
``h_and_H(x, t_s) -> (z, H)``. States are GCRF [km, km/s] for orbits (or any state vector for
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

from ssa_fusion.core.base.constants import C_KM_S
from ssa_fusion.core.base.types import Kind
from ssa_fusion.core.earth.eop import EarthOrientation
from ssa_fusion.core.earth.eop import default as eop_default
from ssa_fusion.core.earth.frames import Station, enu_matrix, gcrs_to_itrs_floats, wrap_2pi
from ssa_fusion.core.earth.refraction import refraction, refraction_rate
from ssa_fusion.core.earth.timescales import DAY_S, UNIX_EPOCH_JD, install_leap_seconds
from ssa_fusion.core.measure.laser_model import LaserModels


class PositionModel:
    """Observe selected state channels: ``z = x[observed]``, ``H`` a constant selection matrix.

    Parameters
    ----------
    observed
        Observed state indices, default (0, 1, 2) (GCRF position, km). Use (0,) for a pendulum's
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
    """What the two station models share: the station, the reference epoch, light time.

    The GCRF -> ITRF rotation G at each epoch is `frames.gcrs_to_itrs_floats` (IERS 2010,
    the EOP read at construction); with ``T = M G`` (M: ITRF -> ENU of the station) the
    topocentric vector of a GCRF position p is ``T p - M r_site``. The arithmetic is in
    Python floats (the EKF's hot path: ~8 us a measurement; numpy's small-array overhead
    would triple it).
    """

    def __init__(self, station: Station, jd0_utc: float, light_time: bool = False,
                 refraction: bool = False, eop: EarthOrientation | None = None) -> None:
        self.station = station
        self.jd0_utc = float(jd0_utc)
        self.light_time = bool(light_time)
        self.refraction = bool(refraction)
        # the tables read now (EOP, leap seconds), not at the first measurement
        self.eop = eop_default() if eop is None else eop
        install_leap_seconds()
        self.unix0 = (self.jd0_utc - UNIX_EPOCH_JD) * DAY_S
        """Unix time (s) of ``t_s = 0``."""
        m = enu_matrix(station.lat_rad, station.lon_rad)
        self._m = [[float(v) for v in row] for row in m]
        self._site_itrs = [float(v) for v in station.itrs]
        self._site_enu = [float(v) for v in m @ station.itrs]

    def _enu_rows(self, t_s: float) -> list[list[float]]:
        """Rows of ``T = M G`` (GCRF -> ENU) at ``t_s`` s after jd0."""
        g = gcrs_to_itrs_floats(self.unix0 + float(t_s), self.eop)
        return [[row[0] * g[j] + row[1] * g[3 + j] + row[2] * g[6 + j] for j in range(3)]
                for row in self._m]

    def gcrs_to_itrs(self, t_s: float) -> NDArray[np.float64]:
        """Return the GCRF -> ITRF rotation (3, 3) at ``t_s`` s after jd0."""
        return np.array(gcrs_to_itrs_floats(self.unix0 + float(t_s), self.eop)).reshape(3, 3)

    def _site_gcrs(self, t_s: float) -> tuple[float, float, float]:
        g = gcrs_to_itrs_floats(self.unix0 + float(t_s), self.eop)
        a, b, c = self._site_itrs
        return (g[0] * a + g[3] * b + g[6] * c, g[1] * a + g[4] * b + g[7] * c,
                g[2] * a + g[5] * b + g[8] * c)

    def site_gcrs(self, t_s: float) -> NDArray[np.float64]:
        """Return the station's GCRF position (3,) km at ``t_s`` s after jd0."""
        return np.array(self._site_gcrs(t_s))

    def _retarded(self, x: NDArray[np.float64], rho: float
                  ) -> tuple[float, float, float, float]:
        """Return (x, y, z) of the object when the light left it (km, GCRF), and tau (s).

        ``rho`` is the range (km) the delay is computed from; tau = 0 without light time or
        without a velocity in the state.
        """
        x0, x1, x2 = float(x[0]), float(x[1]), float(x[2])
        if not self.light_time or len(x) < 6:
            return x0, x1, x2, 0.0
        tau = rho / C_KM_S
        return x0 - tau * float(x[3]), x1 - tau * float(x[4]), x2 - tau * float(x[5]), tau

    @staticmethod
    def _jacobian(rows: list[list[float]], los: list[float] | tuple[float, ...],
                  x: NDArray[np.float64], tau: float) -> NDArray[np.float64]:
        """Return the (m, 6) Jacobian from d z / d r at the retarded position (`rows`).

        With light time (tau > 0) the retarded position is ``r - tau v`` with
        ``tau = |rho| / c``: d/dr = I - v los^T / c (`los`: GCRF unit line of sight),
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

    def H(self, x: NDArray[np.float64], t_s: float) -> NDArray[np.float64]:
        """Analytic Jacobian d z / d x (m, 6)."""
        return self.h_and_H(x, t_s)[1]

    def h(self, x: NDArray[np.float64], t_s: float) -> NDArray[np.float64]:
        """Predicted measurement of GCRF state ``x`` at ``t_s`` s after jd0."""
        return self.h_and_H(x, t_s)[0]

    def h_and_H(
        self, x: NDArray[np.float64], t_s: float
    ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        raise NotImplementedError


class RazelModel(_StationModel):
    """Range/azimuth/elevation of a GCRF state seen from a ground station.

    Parameters
    ----------
    station
        Observer (WGS-84 geodetic, ITRF).
    jd0_utc
        Reference epoch (UTC Julian date); ``t_s`` arguments are seconds since it.
    light_time
        See the object where it was ``range / c`` earlier (module docstring).
    refraction
        Add the atmosphere's refraction to the elevation (`refraction.refraction`): the
        elevation a sensor sees, not the geometric one (default).
    eop
        Earth-orientation parameters (default `eop.default()`).

    ``h`` returns [range km, az rad in [0, 2 pi), el rad]; ``H`` is the analytic (3, 6)
    Jacobian w.r.t. the GCRF state (velocity columns zero without light time). Frames as
    :mod:`ssa_fusion.core.earth.frames`.
    """

    kind = Kind.RANGE_AZ_EL
    angle_mask = (False, True, True)

    def _enu(self, t: list[list[float]], p: tuple[float, float, float]
             ) -> tuple[float, float, float]:
        s = self._site_enu
        return (t[0][0] * p[0] + t[0][1] * p[1] + t[0][2] * p[2] - s[0],
                t[1][0] * p[0] + t[1][1] * p[1] + t[1][2] * p[2] - s[1],
                t[2][0] * p[0] + t[2][1] * p[1] + t[2][2] * p[2] - s[2])

    def h_and_H(
        self, x: NDArray[np.float64], t_s: float
    ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """``(h(x, t_s), H(x, t_s))`` in one call (EKF hot path)."""
        T = self._enu_rows(t_s)  # GCRF -> ENU
        p0, p1, p2, tau = self._retarded(x, 0.0)
        e, n, u = self._enu(T, (p0, p1, p2))
        if self.light_time:
            p0, p1, p2, tau = self._retarded(x, math.sqrt(e * e + n * n + u * u))
            e, n, u = self._enu(T, (p0, p1, p2))
        h2 = e * e + n * n
        h = math.sqrt(h2)
        r2 = h2 + u * u
        r = math.sqrt(r2)
        k = -u / (h * r2)
        D = ((e / r, n / r, u / r), (n / h2, -e / h2, 0.0), (k * e, k * n, h / r2))
        rows = [[d[0] * T[0][j] + d[1] * T[1][j] + d[2] * T[2][j] for j in range(3)]
                for d in D]
        el = math.atan2(u, h)
        los = list(rows[0])  # the range row: the unit line of sight in the GCRF
        if self.refraction:
            scale = 1.0 + float(refraction_rate(el))
            rows[2] = [v * scale for v in rows[2]]
            el += float(refraction(el))
        z = np.array([r, float(wrap_2pi(math.atan2(e, n))), el])
        return z, self._jacobian(rows, los, x, tau)


class RadecModel(_StationModel):
    """Astrometric right ascension / declination of a GCRF state seen from a ground station.

    The optical sensor's measurement: the direction of ``rho = r - r_site`` in the GCRF (no
    aberration; `frames`), ``ra = atan2(rho_y, rho_x)`` in [0, 2 pi),
    ``dec = atan2(rho_z, hypot(rho_x, rho_y))``. Same parameters as `RazelModel` (no
    refraction: a plate reduced against catalogue stars carries none); ``H`` is the analytic
    (2, 6) Jacobian (velocity columns zero without light time). Singular at the celestial
    poles (ra undefined).
    """

    kind = Kind.RA_DEC
    angle_mask = (True, True)

    def h_and_H(
        self, x: NDArray[np.float64], t_s: float
    ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """``(h(x, t_s), H(x, t_s))`` in one call (EKF hot path)."""
        s0, s1, s2 = self._site_gcrs(t_s)
        p0, p1, p2, tau = self._retarded(x, 0.0)
        if self.light_time:
            p0, p1, p2, tau = self._retarded(x, math.dist((p0, p1, p2), (s0, s1, s2)))
        dx, dy, dz = p0 - s0, p1 - s1, p2 - s2
        h2 = dx * dx + dy * dy
        h = math.sqrt(h2)
        r2 = h2 + dz * dz
        r = math.sqrt(r2)
        rows = [[-dy / h2, dx / h2, 0.0], [-dz * dx / (h * r2), -dz * dy / (h * r2), h / r2]]
        z = np.array([float(wrap_2pi(math.atan2(dy, dx))), math.atan2(dz, h)])
        return z, self._jacobian(rows, (dx / r, dy / r, dz / r), x, tau)


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
    refraction
        Refracted elevations in the radar models (`RazelModel`).
    """

    kind = STATION_KINDS

    def __init__(self, stations: dict[str, Station], jd0_utc: float,
                 light_time: bool = False, refraction: bool = False) -> None:
        self.stations = dict(stations)
        self.jd0_utc = float(jd0_utc)
        self.light_time = bool(light_time)
        self.refraction = bool(refraction)
        self._models: dict[tuple[int, str], StationModel] = {}

    def get(self, kind: int, frame_id: str) -> StationModel | None:
        """Return the model of `kind` at station `frame_id`, or None (unknown station or kind)."""
        key = (int(kind), frame_id)
        model = self._models.get(key)
        if model is None:
            station = self.stations.get(frame_id)
            if station is None or kind not in STATION_KINDS:
                return None
            if kind == Kind.RANGE_AZ_EL:
                model = RazelModel(station, self.jd0_utc, self.light_time, self.refraction)
            else:
                model = RadecModel(station, self.jd0_utc, self.light_time)
            self._models[key] = model
        return model


MeasurementModel = PositionModel | RazelModel | RadecModel | StationModels | LaserModels
"""What a tracker observes with: one model, a station network's models, or a laser network's
(`laser_model.LaserModels`)."""
