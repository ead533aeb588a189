r"""Analytic two-body (Keplerian) propagation with its state transition matrix.

The one Kepler solver of the package, compiled with numba (`jit.jit`): `kepler_stm` and
`kepler_state` propagate N states at once (the catalog filter's motion model), `propagate`
one state (the per-object filter's, the IOD's), with the same code.

The propagation uses the universal variable :math:`\chi` and the Stumpff functions
:math:`c_k(z)`, :math:`z = \alpha\chi^2`, with the universal functions
:math:`U_k(\chi, \alpha) = \chi^k c_k(z)` (Battin 1999, ch. 4).  With
:math:`r_0 = |\mathbf r_0|`, :math:`\sigma_0 = \mathbf r_0\cdot\mathbf v_0/\sqrt\mu` and
:math:`\alpha = 2/r_0 - v_0^2/\mu` (inverse semi-major axis) Kepler's equation reads

.. math:: \sqrt\mu\,\Delta t = r_0 U_1 + \sigma_0 U_2 + U_3,

solved by Newton's method, safeguarded for ellipses by the bracket that follows from
:math:`|\Delta E - \Delta M| \le 2e` (`_solve_chi`), and the state follows from the Lagrange
coefficients :math:`F = 1 - U_2/r_0`, :math:`G = (r_0 U_1 + \sigma_0 U_2)/\sqrt\mu`,
:math:`\dot F = -\sqrt\mu U_1/(r r_0)`, :math:`\dot G = 1 - U_2/r`.

The 6x6 state transition matrix is analytic: ``F, G, Fdot, Gdot`` depend on the initial
state only through the three scalars ``(r0, sigma0, alpha)``; their exact partials (using
:math:`\partial U_k/\partial\alpha = (k U_{k+2} - \chi U_{k+1})/2` and the implicit
derivative of :math:`\chi` from Kepler's equation, `lagrange_partials`) give the
Shepperd-type closed form

.. math:: \Phi = \begin{bmatrix} F I & G I \\ \dot F I & \dot G I \end{bmatrix}
          + W M W^T,\qquad W = \begin{bmatrix} \mathbf r_0 & \mathbf v_0 & 0 & 0\\
          0 & 0 & \mathbf r_0 & \mathbf v_0 \end{bmatrix},

with a 4x4 scalar matrix ``M`` per object.

Units: km, km/s, s; the frame is any inertial frame (GCRF).
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ssa_fusion.core.base.constants import MU_EARTH
from ssa_fusion.core.base.jit import f64, jit

__all__ = ["kepler_state", "kepler_stm", "lagrange_partials", "propagate", "stumpff"]

Array = NDArray[np.float64]
BoolArray = NDArray[np.bool_]
Quad = tuple[float, float, float, float]

_Z_SERIES = 0.5
"""|z| below which the Stumpff functions are evaluated by their power series."""

_MAX_NEWTON = 60


@jit
def _stumpff(z: float, full: bool) -> Quad:
    """Stumpff functions (c2, c3, c4, c5) at z; c4, c5 only when ``full`` (else 0).

    Closed forms (trigonometric for z > 0.5, hyperbolic for z < -0.5), power series near 0
    (``c_k = sum_j (-z)^j / (k + 2j)!``, 8 terms: truncation < 0.5^8 / 20! ~ 2e-21), nested,
    with ``z / m`` as ``z * (1 / m)`` (a multiplication is several times shorter than a
    division; the two differ by an ulp).
    """
    if -_Z_SERIES <= z <= _Z_SERIES:
        c4 = (1.0 / 24.0) * (1.0 - z * (1.0 / 30.0) * (1.0 - z * (1.0 / 56.0) * (
            1.0 - z * (1.0 / 90.0) * (1.0 - z * (1.0 / 132.0) * (1.0 - z * (1.0 / 182.0) * (
                1.0 - z * (1.0 / 240.0) * (1.0 - z * (1.0 / 306.0))))))))
        c5 = (1.0 / 120.0) * (1.0 - z * (1.0 / 42.0) * (1.0 - z * (1.0 / 72.0) * (
            1.0 - z * (1.0 / 110.0) * (1.0 - z * (1.0 / 156.0) * (1.0 - z * (1.0 / 210.0) * (
                1.0 - z * (1.0 / 272.0) * (1.0 - z * (1.0 / 342.0))))))))
        return 0.5 - z * c4, 1.0 / 6.0 - z * c5, c4, c5
    if z > 0.0:
        s = math.sqrt(z)
        h = math.sin(0.5 * s)
        c2, c3 = 2.0 * h * h / z, (s - math.sin(s)) / (z * s)
    else:
        s = math.sqrt(-z)
        c2, c3 = (math.cosh(s) - 1.0) / (-z), (math.sinh(s) - s) / (-z * s)
    if not full:
        return c2, c3, 0.0, 0.0
    return c2, c3, (0.5 - c2) / z, (1.0 / 6.0 - c3) / z


@jit
def _solve_chi(r0: float, sig0: float, alpha: float, tau: float) -> tuple[float, bool]:
    """Solve ``r0 U1 + sig0 U2 + U3 = tau`` for chi; return (chi, converged).

    ``tau = sqrt(mu) dt``. Newton's method from a third-order Taylor series of chi(tau)
    (short steps), the mean-anomaly guess (ellipses), Vallado's starter (hyperbolas, 2013,
    algorithm 8) or tau / r0 (near-parabolic), safeguarded for ellipses by the bracket that
    follows from |dE - dM| <= 2 e (chi = dE / sqrt(alpha)): it cannot diverge there.
    """
    if tau == 0.0:
        return 0.0, True
    lo, hi = -math.inf, math.inf
    bound = alpha > 1e-12 / r0
    if bound:
        sa = math.sqrt(alpha)
        ecc = math.hypot(1.0 - r0 * alpha, sig0 * sa)
        dm = tau * alpha * sa
        lo = (dm - 2.0 * ecc - 1e-9) / sa
        hi = (dm + 2.0 * ecc + 1e-9) / sa
    ir0 = 1.0 / r0
    t = tau * ir0
    if abs(tau) < 0.2 * r0 * math.sqrt(r0):
        chi = t * (1.0 - t * ir0 * (0.5 * sig0 - t * (0.5 * sig0 * sig0 * ir0
                                                      - (1.0 - alpha * r0) / 6.0)))
    elif bound:
        chi = tau * alpha
    elif alpha < 0.0:  # hyperbola
        sgn = 1.0 if tau > 0.0 else -1.0
        sa = math.sqrt(-1.0 / alpha)
        arg = (-2.0 * tau * alpha) / (sig0 + sgn * sa * (1.0 - r0 * alpha))
        chi = sgn * sa * math.log(arg) if arg > 0.0 else t
    else:  # near-parabolic
        chi = t
    if not math.isfinite(chi):
        return chi, False
    for _ in range(_MAX_NEWTON):
        chi2 = chi * chi
        c2, c3, _c4, _c5 = _stumpff(alpha * chi2, False)
        u2 = chi2 * c2
        u3 = chi2 * chi * c3
        u1 = chi - alpha * u3
        r = r0 * (1.0 - alpha * u2) + sig0 * u1 + u2
        err = r0 * u1 + sig0 * u2 + u3 - tau
        step = err / r
        # Newton's error after this step is ~ step^2 sigma / (2 r), sigma = dr/dchi; the last
        # step is taken as it is (below an ulp of chi it may not move chi off the bracket's
        # end, which is no reason to bisect)
        sig = sig0 * (1.0 - alpha * u2) + (1.0 - alpha * r0) * u1
        if step * step * abs(sig) <= 2e-16 * r * abs(chi) or err == 0.0:
            chi -= step
            return chi, math.isfinite(chi)
        if err > 0.0:
            hi = min(hi, chi)
        else:
            lo = max(lo, chi)
        new = chi - step
        if not (lo < new < hi):  # Newton left the bracket: bisect instead
            mid = 0.5 * (lo + hi)
            if math.isfinite(mid):
                new = mid
        chi = new
        if not math.isfinite(chi):
            return chi, False
    return chi, False


@jit
def lagrange_partials(r0: float, sig0: float, alpha: float, chi: float, c: Quad, smu: float,
                      mu: float) -> tuple[Quad, Quad, Quad, Quad]:
    """Return the Lagrange coefficients of a two-body arc and their exact gradients.

    For the arc from |r0| = `r0` km, sigma0 = r0.v0 / sqrt(mu), alpha = 2/r0 - v0^2/mu
    (1/km), with universal anomaly `chi` (sqrt(km)) and Stumpff values `c` = (c2, c3, c4,
    c5) at alpha chi^2: returns (f, g, fdot, gdot) and, per coefficient i, the factors
    (a_i, b_i, d_i) of its gradient with respect to the initial state,
    ``d coef_i / d x0 = [a_i r0_vec + b_i v0_vec, b_i r0_vec + d_i v0_vec]`` (the partials
    through r0, sigma0 and alpha, chi following Kepler's equation).
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


@jit
def _kepler_kernel(x: Array, dt: Array, mu: float, x1: Array, phi: Array, ok: BoolArray,
                   stm: bool) -> None:
    """Kepler propagation of x (n, 6) by dt (n,) into x1, phi (n, 6, 6) (if ``stm``), ok."""
    smu = math.sqrt(mu)
    grad = np.empty((4, 6))
    for i in range(x.shape[0]):
        rx, ry, rz, vx, vy, vz = x[i, 0], x[i, 1], x[i, 2], x[i, 3], x[i, 4], x[i, 5]
        r0 = math.sqrt(rx * rx + ry * ry + rz * rz)
        sig0 = (rx * vx + ry * vy + rz * vz) / smu
        alpha = 2.0 / r0 - (vx * vx + vy * vy + vz * vz) / mu
        chi, good = _solve_chi(r0, sig0, alpha, smu * dt[i])
        good = good and r0 > 0.0
        c = _stumpff(alpha * chi * chi, stm)
        (f, g, fd, gd), a, b, d = lagrange_partials(r0, sig0, alpha, chi, c, smu, mu)
        nf = 0.0  # stays 0.0 unless an element is inf or nan
        for k in range(3):
            w, wd = f * x[i, k] + g * x[i, k + 3], fd * x[i, k] + gd * x[i, k + 3]
            x1[i, k], x1[i, k + 3] = w, wd
            nf += (w - w) + (wd - wd)
        if stm:
            # Phi = [[F I, G I], [Fdot I, Gdot I]] + W M W^T (see kepler_stm)
            for m in range(4):
                for k in range(3):
                    grad[m, k] = a[m] * x[i, k] + b[m] * x[i, k + 3]
                    grad[m, k + 3] = b[m] * x[i, k] + d[m] * x[i, k + 3]
            for k in range(3):
                for j in range(6):
                    phi[i, k, j] = x[i, k] * grad[0, j] + x[i, k + 3] * grad[1, j]
                    phi[i, k + 3, j] = x[i, k] * grad[2, j] + x[i, k + 3] * grad[3, j]
                phi[i, k, k] += f
                phi[i, k, k + 3] += g
                phi[i, k + 3, k] += fd
                phi[i, k + 3, k + 3] += gd
            for k in range(6):
                for j in range(6):
                    nf += phi[i, k, j] - phi[i, k, j]
        ok[i] = good and nf == 0.0


def _kepler(x: ArrayLike, dt: ArrayLike, mu: float,
            stm: bool) -> tuple[Array, Array, BoolArray]:
    X = f64(np.atleast_2d(np.asarray(x, dtype=float)))
    n = X.shape[0]
    dts = f64(np.broadcast_to(np.asarray(dt, dtype=float), (n,)))
    x1 = np.empty((n, 6))
    phi = np.empty((n, 6, 6) if stm else (0, 6, 6))
    ok = np.empty(n, dtype=np.bool_)
    _kepler_kernel(X, dts, float(mu), x1, phi, ok, stm)
    return x1, phi, ok


def kepler_stm(x: ArrayLike, dt: ArrayLike,
               mu: float = MU_EARTH) -> tuple[Array, Array, BoolArray]:
    """Propagate N two-body states by their own ``dt`` with their state transition matrices.

    The analytic solution and STM of the module docstring (`propagate` is this for one
    object): the Lagrange coefficients ``F, G, Fdot, Gdot`` (``x1 = [F r0 + G v0,
    Fdot r0 + Gdot v0]``) and their exact partials (``dU_k/dalpha = (k U_{k+2} - chi
    U_{k+1}) / 2`` at fixed chi, and the implicit derivative of chi from Kepler's equation;
    `lagrange_partials`) give ``Phi = [[F I, G I], [Fdot I, Gdot I]] + W M W^T``. A compiled
    loop over the objects.

    Parameters
    ----------
    x : array_like (N, 6)
        Inertial states [km, km/s].
    dt : array_like (N,) or scalar
        Time steps, s (any sign).
    mu : float
        Gravitational parameter, km^3/s^2.

    Returns
    -------
    x1 : ndarray (N, 6)
        States at t0 + dt.
    Phi : ndarray (N, 6, 6)
        State transition matrices d x1 / d x0.
    ok : ndarray (N,) of bool
        False where the input is not finite, r0 = 0, or Kepler's equation did not converge.
    """
    return _kepler(x, dt, mu, True)


def kepler_state(x: ArrayLike, dt: ArrayLike, mu: float = MU_EARTH) -> tuple[Array, BoolArray]:
    """Propagate N two-body states by their own ``dt`` (s), without the STM.

    As `kepler_stm` (same solution, a fraction of its cost): returns (x1 (N, 6), ok (N,)).
    """
    x1, _, ok = _kepler(x, dt, mu, False)
    return x1, ok


def stumpff(z: float) -> Quad:
    """Stumpff functions ``(c2, c3, c4, c5)`` at ``z`` (dimensionless).

    ``c_k(z) = sum_j (-z)^j / (k + 2j)!``; closed forms (trigonometric for z > 0.5,
    hyperbolic for z < -0.5), power series near zero (the solver's, compiled).
    """
    return _stumpff(float(z), True)


def propagate(
    x0_km: ArrayLike, dt_s: float, mu: float = MU_EARTH
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Propagate an inertial two-body state by ``dt_s`` seconds, with its STM.

    `kepler_stm` for one object (the same compiled solver), with the input checked first.

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
    r0 = math.sqrt(x * x + y * y + z * z)
    rv = x * vx + y * vy + z * vz
    if not (r0 > 0.0 and math.isfinite(r0 + rv + dt + mu)) or not (
        math.isfinite(vx * vx + vy * vy + vz * vz)
    ):
        raise ValueError(f"kepler.propagate: need a finite state with r0 > 0 and finite dt, "
                         f"got x0={[x, y, z, vx, vy, vz]}, dt={dt}")
    x1, stm, _ = kepler_stm(np.array([[x, y, z, vx, vy, vz]]), dt, mu)
    return x1[0], stm[0]
