"""Initial orbit determination: Gibbs, Herrick-Gibbs, finite differences, RAE -> GCRF.

Units km, km/s, s, rad; position vectors are inertial (GCRF).
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ssa_fusion.core.base.constants import MU_EARTH
from ssa_fusion.core.earth.frames import Station, enu_matrix, gcrs_to_itrs_matrix, itrs_to_gcrs
from ssa_fusion.core.motion.kepler import propagate

Array = NDArray[np.float64]


def gibbs(r1: ArrayLike, r2: ArrayLike, r3: ArrayLike, mu: float = MU_EARTH) -> Array:
    """Gibbs method: velocity (3,) km/s at ``r2`` from three coplanar GCRF positions (km).

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
    t1: float | Array,
    t2: float | Array,
    t3: float | Array,
    mu: float = MU_EARTH,
) -> Array:
    """Herrick-Gibbs: velocity (..., 3) km/s at ``r2`` from three closely spaced GCRF positions.

    Positions (..., 3) km (many triples at the same three epochs at once), times in s (or
    arrays of them broadcasting against the positions' leading axes, with a trailing axis
    of 1: triples at epochs of their own).
    Taylor-series method for small separations (Vallado, Algorithm 55).
    """
    r1, r2, r3 = (np.asarray(r, float) for r in (r1, r2, r3))
    n1, n2, n3 = (np.linalg.norm(r, axis=-1)[..., None] for r in (r1, r2, r3))
    d21, d31, d32 = t2 - t1, t3 - t1, t3 - t2
    out: Array = (
        -d32 * (1.0 / (d21 * d31) + mu / (12.0 * n1**3)) * r1
        + (d32 - d21) * (1.0 / (d21 * d32) + mu / (12.0 * n2**3)) * r2
        + d21 * (1.0 / (d32 * d31) + mu / (12.0 * n3**3)) * r3
    )
    return out


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
    m=3 (GCRF position, km -> km/s) or m=1 (pendulum angle).
    """
    rr = np.asarray(r, float)
    if rr.ndim == 1:
        rr = rr[:, None]
    w = lagrange_derivative_weights(t_s)
    return np.concatenate([rr[-1], w @ rr])


def razel_to_gcrs(z: ArrayLike, t_unix: ArrayLike, station: Station,
                  to_gcrs: Array | None = None) -> Array:
    """[range km, az rad, el rad] (..., 3) seen from ``station`` -> GCRF position (..., 3) km.

    At Unix (UTC) epochs ``t_unix``; the inverse of :func:`ssa_fusion.core.earth.frames.razel_gcrs`.
    `to_gcrs`: the ITRS -> GCRS rotations at those epochs (..., 3, 3), `itrs_to_gcrs_at`,
    when the same epochs are converted many times (the Earth's orientation is then computed
    once); equal to the direct conversion to rounding (1e-16 relative).
    """
    zz = np.asarray(z, float)
    rng, az, el = zz[..., 0], zz[..., 1], zz[..., 2]
    ce = np.cos(el)
    enu = np.stack([rng * ce * np.sin(az), rng * ce * np.cos(az), rng * np.sin(el)], -1)
    m = enu_matrix(station.lat_rad, station.lon_rad)
    if to_gcrs is not None:
        out: Array = np.einsum("...ij,...j->...i", to_gcrs, enu @ m + station.itrs)
        return out
    return itrs_to_gcrs(enu @ m + station.itrs, t_unix)


def itrs_to_gcrs_at(t_unix: ArrayLike) -> Array:
    """Return the ITRS -> GCRS rotations (..., 3, 3) at Unix (UTC) epochs (`razel_to_gcrs`)."""
    out: Array = np.swapaxes(gcrs_to_itrs_matrix(t_unix), -1, -2)
    return out


def radec_los(ra_rad: ArrayLike, dec_rad: ArrayLike) -> Array:
    """Line-of-sight unit vectors (..., 3) of topocentric right ascension/declination (rad)."""
    ra, dec = np.asarray(ra_rad, float), np.asarray(dec_rad, float)
    out: Array = np.stack([np.cos(dec) * np.cos(ra), np.cos(dec) * np.sin(ra), np.sin(dec)], -1)
    return out


def _gauss_initial(t: Array, los: Array, site: Array, mu: float) -> tuple[Array, Array]:
    """Return (r2, v2) at the middle epoch by Gauss's method without improvement.

    Curtis, "Orbital Mechanics for Engineering Students", 3rd ed., Algorithm 5.5.
    """
    tau1, tau3 = t[0] - t[1], t[2] - t[1]
    tau = tau3 - tau1
    p = [np.cross(los[1], los[2]), np.cross(los[0], los[2]), np.cross(los[0], los[1])]
    d0 = float(los[0] @ p[0])
    if abs(d0) < 1e-14:
        raise ValueError("angles-only IOD: the three lines of sight are coplanar")
    d = np.array([[float(site[i] @ p[j]) for j in range(3)] for i in range(3)])
    a = (-d[0, 1] * tau3 / tau + d[1, 1] + d[2, 1] * tau1 / tau) / d0
    b = (d[0, 1] * (tau3**2 - tau**2) * tau3 / tau
         + d[2, 1] * (tau**2 - tau1**2) * tau1 / tau) / (6.0 * d0)
    e = float(site[1] @ los[1])
    r2_site = float(site[1] @ site[1])
    coeffs = [1.0, 0.0, -(a * a + 2 * a * e + r2_site), 0.0, 0.0, -2 * mu * b * (a + e), 0.0,
              0.0, -(mu * b) ** 2]
    roots = np.roots(coeffs)
    real = roots[(np.abs(roots.imag) < 1e-9 * np.abs(roots)) & (roots.real > 0.0)].real
    real = real[real > float(np.linalg.norm(site[1]))]  # above the observer's radius
    if not len(real):
        raise ValueError("angles-only IOD: no positive real root of Gauss's polynomial")
    r2 = float(real.min())  # the lowest orbit consistent with the angles (Vallado's rule)
    r3 = r2**3
    rho2 = a + mu * b / r3
    rho1 = ((6 * (d[2, 0] * tau1 / tau3 + d[1, 0] * tau / tau3) * r3
             + mu * d[2, 0] * (tau**2 - tau1**2) * tau1 / tau3)
            / (6 * r3 + mu * (tau**2 - tau3**2)) - d[0, 0]) / d0
    rho3 = ((6 * (d[0, 2] * tau3 / tau1 - d[1, 2] * tau / tau1) * r3
             + mu * d[0, 2] * (tau**2 - tau3**2) * tau3 / tau1)
            / (6 * r3 + mu * (tau**2 - tau1**2)) - d[2, 2]) / d0
    r = site + np.array([rho1, rho2, rho3])[:, None] * los
    f1, f3 = 1 - mu * tau1**2 / (2 * r3), 1 - mu * tau3**2 / (2 * r3)
    g1, g3 = tau1 - mu * tau1**3 / (6 * r3), tau3 - mu * tau3**3 / (6 * r3)
    v2 = (-f3 * r[0] + f1 * r[2]) / (f1 * g3 - f3 * g1)
    return r[1], v2


def gauss_angles_only(t_s: ArrayLike, ra_rad: ArrayLike, dec_rad: ArrayLike,
                      site_eci_km: ArrayLike, mu: float = MU_EARTH,
                      iterations: int = 8) -> tuple[Array, Array]:
    """Angles-only initial orbit determination from three topocentric ra/dec observations.

    Gauss's method (Curtis Algorithm 5.5) followed by differential correction of the
    two-body state at the middle epoch until it reproduces the three lines of sight (the
    role of Curtis's Algorithm 5.6 iterative improvement, with exact two-body propagation,
    `kepler.propagate`, and its state transition matrix).

    Parameters
    ----------
    t_s : (3,) epochs, s (increasing).
    ra_rad, dec_rad : (3,) topocentric right ascension and declination in the GCRF frame, rad.
    site_eci_km : (3, 3) the observer's GCRF position at each epoch, km.
    mu : gravitational parameter, km^3/s^2.
    iterations : differential-correction steps at most (0: Gauss's first estimate).

    Returns
    -------
    r2, v2 : (3,), (3,) GCRF position (km) and velocity (km/s) at the middle epoch.

    Raises ValueError when the geometry has no solution (coplanar lines of sight, no
    positive root, a correction that does not converge).
    """
    t = np.asarray(t_s, float)
    los = radec_los(ra_rad, dec_rad)
    site = np.asarray(site_eci_km, float)
    r2, v2 = _gauss_initial(t, los, site, mu)
    x = np.concatenate([r2, v2])
    # residual: the component of each observed line of sight off the predicted one
    for _ in range(iterations):
        res, jac = [], []
        for k in (0, 2):
            xk, phi = propagate(x, float(t[k] - t[1]), mu)
            rho = xk[:3] - site[k]
            n = float(np.linalg.norm(rho))
            u = rho / n
            dudr = (np.eye(3) - np.outer(u, u)) / n
            res.append(u - los[k])
            jac.append(dudr @ phi[:3, :])
        rho2 = x[:3] - site[1]
        n2 = float(np.linalg.norm(rho2))
        u2 = rho2 / n2
        res.append(u2 - los[1])
        jac.append(np.hstack([(np.eye(3) - np.outer(u2, u2)) / n2, np.zeros((3, 3))]))
        dx = np.linalg.lstsq(np.vstack(jac), -np.concatenate(res), rcond=None)[0]
        x = x + dx
        if float(np.linalg.norm(dx[:3])) < 1e-9 * float(np.linalg.norm(x[:3])):
            break
    if not np.isfinite(x).all():
        raise ValueError("angles-only IOD: the correction diverged")
    return x[:3], x[3:]
