r"""Analytic two-body (Keplerian) propagation with its state transition matrix.

The propagation uses the universal variable :math:`\chi` and the Stumpff functions
:math:`c_k(z)`, :math:`z = \alpha\chi^2`, with the universal functions
:math:`U_k(\chi, \alpha) = \chi^k c_k(z)` (Battin 1999, ch. 4).  With
:math:`r_0 = |\mathbf r_0|`, :math:`\sigma_0 = \mathbf r_0\cdot\mathbf v_0/\sqrt\mu` and
:math:`\alpha = 2/r_0 - v_0^2/\mu` (inverse semi-major axis) Kepler's equation reads

.. math:: \sqrt\mu\,\Delta t = r_0 U_1 + \sigma_0 U_2 + U_3,

and the state follows from the Lagrange coefficients
:math:`F = 1 - U_2/r_0`, :math:`G = (r_0 U_1 + \sigma_0 U_2)/\sqrt\mu`,
:math:`\dot F = -\sqrt\mu U_1/(r r_0)`, :math:`\dot G = 1 - U_2/r`.

The 6x6 state transition matrix is analytic: ``F, G, Fdot, Gdot`` depend on the initial
state only through the three scalars ``(r0, sigma0, alpha)``; their exact partials (using
:math:`\partial U_k/\partial\alpha = (k U_{k+2} - \chi U_{k+1})/2` and the implicit
derivative of :math:`\chi` from Kepler's equation) give the Shepperd-type closed form

.. math:: \Phi = \begin{bmatrix} F I & G I \\ \dot F I & \dot G I \end{bmatrix}
          + W M W^T,\qquad W = \begin{bmatrix} \mathbf r_0 & \mathbf v_0 & 0 & 0\\
          0 & 0 & \mathbf r_0 & \mathbf v_0 \end{bmatrix},

with a 4x4 scalar matrix ``M``.  All scalar work is done with :mod:`math` (this sits in the
EKF hot path); numpy is only used to assemble the 6x6 result.

Units: km, km/s, s; the frame is any inertial frame (GCRF).
"""

from __future__ import annotations

import math
from typing import TypeVar

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ssa_fusion.core.constants import MU_EARTH

__all__ = ["propagate", "stumpff"]

_Z_SERIES = 0.5
"""|z| below which the Stumpff functions c4, c5 are evaluated by their power series."""

_MAX_ITER = 60

# D = F*E_rr + G*E_rv + Fdot*E_vr + Gdot*E_vv as one (4,) @ (4, 36) product.
_D_BASIS: NDArray[np.float64] = np.zeros((4, 6, 6))
for _k, (_i0, _j0) in enumerate(((0, 0), (0, 3), (3, 0), (3, 3))):
    for _d in range(3):
        _D_BASIS[_k, _i0 + _d, _j0 + _d] = 1.0
_D_BASIS = _D_BASIS.reshape(4, 36)
del _k, _i0, _j0, _d


def _c45_series(z: float) -> tuple[float, float]:
    """Stumpff c4(z), c5(z) by their power series (accurate for |z| <= 0.5)."""
    # c_k(z) = sum_j (-z)^j / (k + 2j)!, 8 terms: truncation < 0.5^8 / 20! ~ 2e-21.
    c4 = (1.0 / 24.0) * (1.0 - z / 30.0 * (1.0 - z / 56.0 * (1.0 - z / 90.0 * (
        1.0 - z / 132.0 * (1.0 - z / 182.0 * (1.0 - z / 240.0 * (1.0 - z / 306.0)))))))
    c5 = (1.0 / 120.0) * (1.0 - z / 42.0 * (1.0 - z / 72.0 * (1.0 - z / 110.0 * (
        1.0 - z / 156.0 * (1.0 - z / 210.0 * (1.0 - z / 272.0 * (1.0 - z / 342.0)))))))
    return c4, c5


def _c23(z: float) -> tuple[float, float]:
    """Stumpff c2(z) = (1 - cos sqrt z)/z and c3(z) = (sqrt z - sin sqrt z)/z^1.5."""
    if z > _Z_SERIES:
        s = math.sqrt(z)
        h = math.sin(0.5 * s)
        return 2.0 * h * h / z, (s - math.sin(s)) / (z * s)
    if z < -_Z_SERIES:
        s = math.sqrt(-z)
        return (math.cosh(s) - 1.0) / (-z), (math.sinh(s) - s) / (-z * s)
    c4, c5 = _c45_series(z)
    return 0.5 - z * c4, 1.0 / 6.0 - z * c5


def stumpff(z: float) -> tuple[float, float, float, float]:
    """Stumpff functions ``(c2, c3, c4, c5)`` at ``z`` (dimensionless).

    ``c_k(z) = sum_j (-z)^j / (k + 2j)!``; closed forms (trigonometric for z > 0,
    hyperbolic for z < 0) away from zero, power series near zero.
    """
    if -_Z_SERIES <= z <= _Z_SERIES:
        c4, c5 = _c45_series(z)
        return 0.5 - z * c4, 1.0 / 6.0 - z * c5, c4, c5
    c2, c3 = _c23(z)
    return c2, c3, (0.5 - c2) / z, (1.0 / 6.0 - c3) / z


def _solve_chi(r0: float, sig0: float, alpha: float, tau: float) -> float:
    """Solve Kepler's equation ``r0 U1 + sig0 U2 + U3 = tau`` (tau = sqrt(mu) dt) for chi.

    Newton's method; for bound orbits it is safeguarded by the bracket that follows from
    ``|dE - dM| <= 2 e`` (chi = dE / sqrt(alpha)), so it cannot diverge.
    """
    if tau == 0.0:
        return 0.0
    lo = -math.inf
    hi = math.inf
    bound = alpha > 1e-12 / r0
    if bound:  # ellipse: chi = delta eccentric anomaly * sqrt(a), |dE - dM| <= 2 e
        sa = math.sqrt(alpha)
        e = math.hypot(1.0 - r0 * alpha, sig0 * sa)
        dm = tau * alpha * sa  # mean motion * dt
        lo = (dm - 2.0 * e - 1e-9) / sa
        hi = (dm + 2.0 * e + 1e-9) / sa
    if abs(tau) < 0.2 * r0 * math.sqrt(r0):
        # short step: third-order Taylor series of chi(tau) (dchi/dtau = 1/r,
        # d2chi/dtau2 = -sigma/r^3, d3chi/dtau3 = 3 sigma^2/r^5 - (1 - alpha r)/r^4)
        ir0 = 1.0 / r0
        t = tau * ir0
        chi = t * (1.0 - t * ir0 * (0.5 * sig0 - t * (
            0.5 * sig0 * sig0 * ir0 - (1.0 - alpha * r0) / 6.0)))
    elif bound:
        chi = tau * alpha
    elif alpha < 0.0:  # hyperbola (Vallado 2013, algorithm 8 starter)
        sgn = 1.0 if tau > 0.0 else -1.0
        sa = math.sqrt(-1.0 / alpha)
        arg = (-2.0 * tau * alpha) / (sig0 + sgn * sa * (1.0 - r0 * alpha))
        chi = sgn * sa * math.log(arg) if arg > 0.0 else tau / r0
    else:  # near-parabolic
        chi = tau / r0
    for _ in range(_MAX_ITER):
        z = alpha * chi * chi
        c2, c3 = _c23(z)
        chi2 = chi * chi
        u2 = chi2 * c2
        u1 = chi * (1.0 - z * c3)
        u0 = 1.0 - z * c2
        err = r0 * u1 + sig0 * u2 + chi2 * chi * c3 - tau
        r = r0 * u0 + sig0 * u1 + u2
        step = err / r
        # Newton's error after this step is ~ step^2 * sigma / (2 r), sigma = dr/dchi
        sig = sig0 * u0 + (1.0 - alpha * r0) * u1
        if step * step * abs(sig) <= 2e-16 * r * abs(chi) or err == 0.0:
            return chi - step
        if err > 0.0:
            hi = min(hi, chi)
        else:
            lo = max(lo, chi)
        new = chi - step
        if not lo < new < hi:  # Newton left the bracket: bisect instead
            new = 0.5 * (lo + hi)
            if not math.isfinite(new):
                new = chi - step
        chi = new
    return chi


Num = TypeVar("Num", float, NDArray[np.float64])


def lagrange_partials(r0: Num, sig0: Num, alpha: Num, chi: Num,
                      c: tuple[Num, Num, Num, Num], smu: float, mu: float
                      ) -> tuple[tuple[Num, Num, Num, Num], tuple[Num, Num, Num, Num],
                                 tuple[Num, Num, Num, Num], tuple[Num, Num, Num, Num]]:
    """Return the Lagrange coefficients of a two-body arc and their exact gradients.

    For the arc from |r0| = `r0` km, sigma0 = r0.v0 / sqrt(mu), alpha = 2/r0 - v0^2/mu
    (1/km), with universal anomaly `chi` (sqrt(km)) and Stumpff values `c` = (c2, c3, c4,
    c5) at alpha chi^2: returns (f, g, fdot, gdot) and, per coefficient i, the factors
    (a_i, b_i, d_i) of its gradient with respect to the initial state,
    ``d coef_i / d x0 = [a_i r0_vec + b_i v0_vec, b_i r0_vec + d_i v0_vec]`` (the partials
    through r0, sigma0 and alpha, chi following Kepler's equation). Elementwise: Python
    floats (`propagate`) or arrays of objects (`batch_ekf.kepler_stm`).
    """
    c2, c3, c4, c5 = c
    chi2 = chi * chi
    u2 = chi2 * c2
    u3 = chi2 * chi * c3
    u4 = chi2 * chi2 * c4
    u5 = chi2 * chi2 * chi * c5
    u1 = chi - alpha * u3
    u0 = 1.0 - alpha * u2
    r = r0 * u0 + sig0 * u1 + u2
    ir0 = 1.0 / r0
    ir = 1.0 / r
    f = 1.0 - u2 * ir0
    g = (r0 * u1 + sig0 * u2) / smu
    fd = -smu * u1 * ir * ir0
    gd = 1.0 - u2 * ir
    # --- partials w.r.t. p = (r0, sigma0, alpha) --------------------------------
    # dU_k/dalpha at fixed chi = (k U_{k+2} - chi U_{k+1}) / 2
    u0a = -0.5 * chi * u1
    u1a = 0.5 * (u3 - chi * u2)
    u2a = 0.5 * (2.0 * u4 - chi * u3)
    u3a = 0.5 * (3.0 * u5 - chi * u4)
    # chi from Kepler's equation K(chi, p) = tau:  dchi/dp = -dK/dp / r
    xa_r, xa_s, xa_a = -u1 * ir, -u2 * ir, -(r0 * u1a + sig0 * u2a + u3a) * ir
    # total derivatives of U0, U1, U2 (dU_k/dchi = U_{k-1}, dU0/dchi = -alpha U1)
    au1 = -alpha * u1
    d0r, d0s, d0a = au1 * xa_r, au1 * xa_s, au1 * xa_a + u0a
    d1r, d1s, d1a = u0 * xa_r, u0 * xa_s, u0 * xa_a + u1a
    d2r, d2s, d2a = u1 * xa_r, u1 * xa_s, u1 * xa_a + u2a
    # r = r0 U0 + sig0 U1 + U2
    rr = u0 + r0 * d0r + sig0 * d1r + d2r
    rs = u1 + r0 * d0s + sig0 * d1s + d2s
    ra = r0 * d0a + sig0 * d1a + d2a
    f_r, f_s, f_a = -d2r * ir0 + u2 * ir0 * ir0, -d2s * ir0, -d2a * ir0
    g_r = (u1 + r0 * d1r + sig0 * d2r) / smu
    g_s = (u2 + r0 * d1s + sig0 * d2s) / smu
    g_a = (r0 * d1a + sig0 * d2a) / smu
    k = -smu * ir * ir0
    fd_r = k * d1r - fd * (rr * ir + ir0)
    fd_s = k * d1s - fd * rs * ir
    fd_a = k * d1a - fd * ra * ir
    q = u2 * ir * ir
    gd_r, gd_s, gd_a = -d2r * ir + q * rr, -d2s * ir + q * rs, -d2a * ir + q * ra
    # grad r0 = [r0_vec/r0, 0], grad sigma0 = [v0_vec, r0_vec]/sqrt(mu),
    # grad alpha = [-2 r0_vec/r0^3, -2 v0_vec/mu]
    ir03 = 2.0 * ir0 * ir0 * ir0
    ism = 1.0 / smu
    imu = 2.0 / mu
    return ((f, g, fd, gd),
            (f_r * ir0 - f_a * ir03, g_r * ir0 - g_a * ir03, fd_r * ir0 - fd_a * ir03,
             gd_r * ir0 - gd_a * ir03),
            (f_s * ism, g_s * ism, fd_s * ism, gd_s * ism),
            (-f_a * imu, -g_a * imu, -fd_a * imu, -gd_a * imu))


def propagate(
    x0_km: ArrayLike, dt_s: float, mu: float = MU_EARTH
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Propagate an inertial two-body state by ``dt_s`` seconds, with its STM.

    Parameters
    ----------
    x0_km : array_like, shape (6,)
        Initial state ``[x, y, z, vx, vy, vz]`` in an inertial frame, km and km/s.
    dt_s : float
        Time step, s.  Any sign and size (multiple revolutions are fine).
    mu : float, optional
        Gravitational parameter, km^3/s^2 (default Earth).

    Returns
    -------
    x1 : ndarray, shape (6,)
        State at ``t0 + dt_s``, same frame and units.
    stm : ndarray, shape (6, 6)
        State transition matrix ``d x1 / d x0`` (analytic, exact to round-off).

    Notes
    -----
    Works for ellipses (circular to highly eccentric), hyperbolas and near-parabolic
    orbits; the rectilinear/degenerate ``r0 = 0`` case is not supported.

    Raises
    ------
    ValueError
        If the state or ``dt_s`` is not finite or ``r0 = 0``.
    """
    if isinstance(x0_km, np.ndarray):
        x, y, z, vx, vy, vz = x0_km.tolist()
    else:
        x, y, z, vx, vy, vz = np.asarray(x0_km, dtype=float).tolist()
    dt = float(dt_s)
    smu = math.sqrt(mu)
    r0 = math.sqrt(x * x + y * y + z * z)
    rv = x * vx + y * vy + z * vz
    sig0 = rv / smu
    if not (r0 > 0.0 and math.isfinite(r0 + rv + dt + mu)) or not (
        math.isfinite(vx * vx + vy * vy + vz * vz)
    ):
        raise ValueError(f"kepler.propagate: need a finite state with r0 > 0 and finite dt, "
                         f"got x0={[x, y, z, vx, vy, vz]}, dt={dt}")
    alpha = 2.0 / r0 - (vx * vx + vy * vy + vz * vz) / mu

    chi = _solve_chi(r0, sig0, alpha, smu * dt)
    (f, g, fd, gd), a, b, d = lagrange_partials(r0, sig0, alpha, chi,
                                                stumpff(alpha * chi * chi), smu, mu)
    m = np.array([(a[i], b[i], b[i], d[i]) for i in range(4)])
    w = np.array((
        (x, vx, 0.0, 0.0), (y, vy, 0.0, 0.0), (z, vz, 0.0, 0.0),
        (0.0, 0.0, x, vx), (0.0, 0.0, y, vy), (0.0, 0.0, z, vz),
    ))
    stm = w.dot(m).dot(w.T)
    stm += np.array((f, g, fd, gd)).dot(_D_BASIS).reshape(6, 6)
    x1 = np.array((
        f * x + g * vx, f * y + g * vy, f * z + g * vz,
        fd * x + gd * vx, fd * y + gd * vy, fd * z + gd * vz,
    ))
    return x1, stm
