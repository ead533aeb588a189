"""Initial orbit determination: Gibbs, Herrick-Gibbs, finite differences, RAE -> ECI.

Units km, km/s, s, rad; position vectors are inertial (ECI).
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .constants import MU_EARTH
from .frames import Station, ecef_to_eci, enu_matrix, site_ecef

Array = NDArray[np.float64]


def gibbs(r1: ArrayLike, r2: ArrayLike, r3: ArrayLike, mu: float = MU_EARTH) -> Array:
    """Gibbs method: velocity (3,) km/s at ``r2`` from three coplanar ECI positions (km).

    Best for widely separated vectors (angles > ~5 deg); see :func:`herrick_gibbs` otherwise.
    (Curtis, Orbital Mechanics for Engineering Students, Algorithm 5.1.)
    """
    r1, r2, r3 = (np.asarray(r, float) for r in (r1, r2, r3))
    n1, n2, n3 = (float(np.linalg.norm(r)) for r in (r1, r2, r3))
    c12, c23, c31 = np.cross(r1, r2), np.cross(r2, r3), np.cross(r3, r1)
    n = n1 * c23 + n2 * c31 + n3 * c12
    d = c12 + c23 + c31
    s = r1 * (n2 - n3) + r2 * (n3 - n1) + r3 * (n1 - n2)
    nn, dn = float(np.linalg.norm(n)), float(np.linalg.norm(d))
    return math.sqrt(mu / (nn * dn)) * (np.cross(d, r2) / n2 + s)


def herrick_gibbs(
    r1: ArrayLike,
    r2: ArrayLike,
    r3: ArrayLike,
    t1: float,
    t2: float,
    t3: float,
    mu: float = MU_EARTH,
) -> Array:
    """Herrick-Gibbs: velocity (3,) km/s at ``r2`` from three closely spaced ECI positions.

    Times in s. Taylor-series method for small separations (Vallado, Algorithm 55).
    """
    r1, r2, r3 = (np.asarray(r, float) for r in (r1, r2, r3))
    n1, n2, n3 = (float(np.linalg.norm(r)) for r in (r1, r2, r3))
    d21, d31, d32 = t2 - t1, t3 - t1, t3 - t2
    return (
        -d32 * (1.0 / (d21 * d31) + mu / (12.0 * n1**3)) * r1
        + (d32 - d21) * (1.0 / (d21 * d32) + mu / (12.0 * n2**3)) * r2
        + d21 * (1.0 / (d32 * d31) + mu / (12.0 * n3**3)) * r3
    )


def lagrange_derivative_weights(t_s: ArrayLike) -> Array:
    """Return weights w (k,) with ``f'(t_s[-1]) ~= sum_j w_j f(t_s[j])`` (1/s for t_s in s).

    The derivative of the Lagrange interpolating polynomial through all k >= 2 samples,
    evaluated at the last node.
    """
    t = np.asarray(t_s, float)
    k = t.size
    if k < 2:
        raise ValueError("need at least two samples")
    d = t[:, None] - t[None, :]  # d[j, m] = t_j - t_m
    np.fill_diagonal(d, 1.0)
    w = np.empty(k)
    tk = t[-1]
    dk = tk - t[:-1]
    w[-1] = float(np.sum(1.0 / dk))
    for j in range(k - 1):  # k is a handful of IOD samples, not a trajectory
        others = [m for m in range(k - 1) if m != j]
        w[j] = float(np.prod(dk[others])) / float(np.prod(d[j]))
    return w


def finite_difference_state(t_s: ArrayLike, r: ArrayLike) -> Array:
    """State [r, v] (2m,) at the last epoch ``t_s[-1]`` from samples ``r`` (k, m) at ``t_s`` (k,).

    Velocity is the derivative of the Lagrange polynomial through the k >= 2 samples at the last
    node (one-sided: k=2 is a backward difference, k=3 second order, ...). Works for any m, e.g.
    m=3 (ECI position, km -> km/s) or m=1 (pendulum angle).
    """
    rr = np.asarray(r, float)
    if rr.ndim == 1:
        rr = rr[:, None]
    w = lagrange_derivative_weights(t_s)
    return np.concatenate([rr[-1], w @ rr])


def razel_to_eci(z: ArrayLike, jd_utc: ArrayLike, station: Station) -> Array:
    """[range km, az rad, el rad] (..., 3) seen from ``station`` -> ECI position (..., 3) km.

    Inverse of :func:`ssa_fusion.core.frames.razel_eci` (same frame conventions).
    """
    zz = np.asarray(z, float)
    rng, az, el = zz[..., 0], zz[..., 1], zz[..., 2]
    ce = np.cos(el)
    enu = np.stack([rng * ce * np.sin(az), rng * ce * np.cos(az), rng * np.sin(el)], -1)
    m = enu_matrix(station.lat_rad, station.lon_rad)
    r_ecef = enu @ m + site_ecef(station.lat_rad, station.lon_rad, station.alt_km)
    return ecef_to_eci(r_ecef, jd_utc)
