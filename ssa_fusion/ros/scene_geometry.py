"""The geometry of what the foxglove_bridge node shows, as pure functions (numpy only).

GCRF -> WGS-84 geodetic latitude/longitude (ground tracks), position covariance -> n σ
ellipsoid (its axes as a quaternion), a measurement -> the GCRF point it implies, and the
Earth's prime meridian in the GCRF. Positions in km, angles in rad, times Unix s (UTC).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ssa_fusion.core.base.constants import R_EARTH, WGS84_F
from ssa_fusion.core.base.types import Kind
from ssa_fusion.core.earth.frames import Station, gcrs_to_itrs, itrs_to_gcrs
from ssa_fusion.core.measure.iod import razel_to_gcrs

_E2 = WGS84_F * (2.0 - WGS84_F)


def itrs_to_geodetic(r_itrs_km: ArrayLike) -> tuple[float, float, float]:
    """Return the WGS-84 geodetic coordinates of an ITRF position (3,) km.

    Latitude rad, longitude rad in (-π, π], ellipsoidal height km; the inverse of
    `core.earth.frames.site_itrs` (fixed-point iteration on the latitude, converged to ~1e-12 rad).
    """
    x, y, z = (float(v) for v in np.asarray(r_itrs_km, dtype=float)[:3])
    lon = math.atan2(y, x)
    p = math.hypot(x, y)
    if p < 1e-9:  # on the polar axis
        lat = math.copysign(math.pi / 2, z)
        return lat, lon, abs(z) - R_EARTH * math.sqrt(1.0 - _E2)
    lat = math.atan2(z, p * (1.0 - _E2))
    for _ in range(20):
        n = R_EARTH / math.sqrt(1.0 - _E2 * math.sin(lat) ** 2)
        new = math.atan2(z + _E2 * n * math.sin(lat), p)
        done = abs(new - lat) < 1e-14
        lat = new
        if done:
            break
    n = R_EARTH / math.sqrt(1.0 - _E2 * math.sin(lat) ** 2)
    if abs(lat) < math.radians(80.0):
        alt = p / math.cos(lat) - n
    else:
        alt = z / math.sin(lat) - n * (1.0 - _E2)
    return lat, lon, alt


def gcrs_to_geodetic(r_gcrs_km: ArrayLike, t_unix: float) -> tuple[float, float, float]:
    """Return the geodetic coordinates of the point below a GCRF position (3,) km.

    At Unix time `t_unix` (s): latitude rad, longitude rad, height km of its sub-satellite
    point, via `core.earth.frames`.
    """
    r = np.asarray(r_gcrs_km, dtype=float)[:3]
    return itrs_to_geodetic(gcrs_to_itrs(r, t_unix))


@dataclass(frozen=True)
class Ellipsoid:
    """An n-σ ellipsoid of a 3x3 position covariance (km²).

    ``axes`` (3, 3): its principal directions, one unit vector per column (a proper
    rotation, det +1), in the covariance's frame; ``semi_axes`` (3,) km: n σ along each;
    ``quaternion`` (x, y, z, w): the same rotation, as `foxglove.Pose` takes it; ``size`` (3,)
    km: the diameters (2 × semi-axes), as `foxglove.SpherePrimitive` takes them.
    """

    axes: NDArray[np.float64]
    semi_axes: NDArray[np.float64]
    quaternion: tuple[float, float, float, float]

    @property
    def size(self) -> NDArray[np.float64]:
        """Return the diameters (3,) km."""
        return 2.0 * self.semi_axes


def rotation_to_quaternion(rot: ArrayLike) -> tuple[float, float, float, float]:
    """Return the unit quaternion (x, y, z, w), w >= 0, of a proper rotation matrix (3, 3).

    Shepperd's method: the largest of the four components is taken from the diagonal.
    """
    m = np.asarray(rot, dtype=float)
    tr = float(np.trace(m))
    cands = [tr, m[0, 0], m[1, 1], m[2, 2]]
    k = int(np.argmax(cands))
    if k == 0:
        w = 0.5 * math.sqrt(1.0 + tr)
        x, y, z = ((m[2, 1] - m[1, 2]) / (4 * w), (m[0, 2] - m[2, 0]) / (4 * w),
                   (m[1, 0] - m[0, 1]) / (4 * w))
    elif k == 1:
        x = 0.5 * math.sqrt(1.0 + m[0, 0] - m[1, 1] - m[2, 2])
        w, y, z = ((m[2, 1] - m[1, 2]) / (4 * x), (m[0, 1] + m[1, 0]) / (4 * x),
                   (m[0, 2] + m[2, 0]) / (4 * x))
    elif k == 2:
        y = 0.5 * math.sqrt(1.0 - m[0, 0] + m[1, 1] - m[2, 2])
        w, x, z = ((m[0, 2] - m[2, 0]) / (4 * y), (m[0, 1] + m[1, 0]) / (4 * y),
                   (m[1, 2] + m[2, 1]) / (4 * y))
    else:
        z = 0.5 * math.sqrt(1.0 - m[0, 0] - m[1, 1] + m[2, 2])
        w, x, y = ((m[1, 0] - m[0, 1]) / (4 * z), (m[0, 2] + m[2, 0]) / (4 * z),
                   (m[1, 2] + m[2, 1]) / (4 * z))
    q = np.array([x, y, z, w], dtype=float)
    q /= np.linalg.norm(q)
    if q[3] < 0:
        q = -q
    return (float(q[0]), float(q[1]), float(q[2]), float(q[3]))


def quaternion_to_rotation(q: ArrayLike) -> NDArray[np.float64]:
    """Return the rotation matrix (3, 3) of a unit quaternion (x, y, z, w)."""
    x, y, z, w = (float(v) for v in np.asarray(q, dtype=float))
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ])


def covariance_ellipsoid(p_pos_km2: ArrayLike, n_sigma: float = 3.0) -> Ellipsoid:
    """Return the `n_sigma` ellipsoid of position covariance `p_pos_km2` (3, 3), km².

    Eigenvectors as axes, n σ = n √λ (km) along each (negative eigenvalues of a numerically
    indefinite matrix count as 0). Its quadric is ``(x)ᵀ (n² P)⁻¹ x = 1``.
    """
    p = np.asarray(p_pos_km2, dtype=float)[:3, :3]
    p = 0.5 * (p + p.T)
    lam, vec = np.linalg.eigh(p)
    if np.linalg.det(vec) < 0:
        vec[:, 2] = -vec[:, 2]
    semi = n_sigma * np.sqrt(np.clip(lam, 0.0, None))
    return Ellipsoid(axes=vec, semi_axes=semi, quaternion=rotation_to_quaternion(vec))


def measurement_point(kind: int, z: ArrayLike, frame_id: str, t_unix: float,
                      stations: dict[str, Station]) -> NDArray[np.float64] | None:
    """Return the GCRF point (3,) km a measurement (core units: km, rad) implies, or None.

    A position measurement itself, range/az/el from its station (`frame_id` among
    `stations`); None for one without range (ra/dec) or from an unknown station.
    """
    if kind == Kind.POSITION:
        return np.asarray(z, dtype=float)[:3].copy()
    if kind == Kind.RANGE_AZ_EL and frame_id in stations:
        return razel_to_gcrs(np.asarray(z, dtype=float)[:3], t_unix, stations[frame_id])
    return None


def meridian_gcrs(t_unix: float, n: int = 37, lon_rad: float = 0.0) -> NDArray[np.float64]:
    """Return points (n, 3) km of the meridian at longitude `lon_rad` on the Earth's surface.

    Spherical, radius `R_EARTH` + 1 km, pole to pole, in the GCRF at Unix time `t_unix` (s):
    it shows the Earth's rotation in the inertial scene.
    """
    lat = np.linspace(-math.pi / 2, math.pi / 2, n)
    r = R_EARTH + 1.0
    itrs = np.stack([r * np.cos(lat) * math.cos(lon_rad), r * np.cos(lat) * math.sin(lon_rad),
                     r * np.sin(lat)], -1)
    return np.asarray(itrs_to_gcrs(itrs, t_unix), dtype=float)
