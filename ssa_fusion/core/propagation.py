r"""Propagation with state transition matrices, compiled: Kepler's equation and the integrator.

Two jobs, each a loop over N objects compiled with numba (`jit`: IEEE arithmetic in the
order written; compiled once per process, or loaded from the user's cache):

Analytic two-body (`kepler_stm`, `kepler_state`)
    The one Kepler solver of the package (`kepler.propagate` calls it for one object).
    Universal variable :math:`\chi`, Stumpff functions :math:`c_k(z)`, :math:`z = \alpha
    \chi^2`, universal functions :math:`U_k = \chi^k c_k(z)` (Battin 1999, ch. 4); with
    :math:`r_0 = |\mathbf r_0|`, :math:`\sigma_0 = \mathbf r_0\cdot\mathbf v_0/\sqrt\mu`
    and :math:`\alpha = 2/r_0 - v_0^2/\mu` Kepler's equation reads :math:`\sqrt\mu\,
    \Delta t = r_0 U_1 + \sigma_0 U_2 + U_3` (`_solve_chi`: Newton, safeguarded for
    ellipses by the bracket that follows from :math:`|\Delta E - \Delta M| \le 2e`), and
    the state follows from the Lagrange coefficients :math:`F = 1 - U_2/r_0`,
    :math:`G = (r_0 U_1 + \sigma_0 U_2)/\sqrt\mu`, :math:`\dot F = -\sqrt\mu U_1/(r
    r_0)`, :math:`\dot G = 1 - U_2/r`. The STM is analytic: F, G, Fdot, Gdot depend on the
    initial state only through (r0, sigma0, alpha); their exact partials
    (`lagrange_partials`) give :math:`\Phi = [[F I, G I], [\dot F I, \dot G I]] + W M W^T`,
    :math:`W = [[\mathbf r_0, \mathbf v_0, 0, 0], [0, 0, \mathbf r_0, \mathbf v_0]]`,
    with a 4x4 matrix M per object.

Integrated models (`integrate_stm`: "two_body", "j2", "drag")
    The `dynamics` right-hand sides with their variational equations dPhi/dt = A(x) Phi,
    integrated with the 8th-order Dormand-Prince tableau (scipy's DOP853) at a fixed step:
    each object takes ``ceil(|dt| / max_step_s)`` equal steps. "two_body" and "j2": a
    compiled loop with the analytic Jacobian (`_gravity_stm_kernel`, J2 about the Earth's
    pole); "drag": numpy, all objects at once, A by the complex step
    (`_integrate_stm_numpy`). The two paths agree to ~1e-15 relative per step (~1e-12 over
    a day of steps). The per-object filter's adaptive DOP853 (rtol 1e-10, atol 1e-9) and
    this fixed-step scheme at 60 s agree to ~5e-11 relative (LEO and Molniya, 10 s to
    1.5 h steps).

Units: km, km/s, s; states in an inertial frame (GCRF). The arrays the kernels take are
C-contiguous float64 (`f64`), one type per argument, so that each is compiled once.
"""

from __future__ import annotations

import functools
import inspect
import math
from collections.abc import Callable
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from . import dynamics
from .constants import MU_EARTH
from .jit import jit
from .types import MotionModel

__all__ = ["INTEGRATED_MODELS", "f64", "integrate_stm", "kepler_state", "kepler_stm",
           "lagrange_partials"]

Array = NDArray[np.float64]
AnyArray = NDArray[Any]
"""An array of any dtype (per-object inputs as given)."""
BoolArray = NDArray[np.bool_]
Quad = tuple[float, float, float, float]

_COMPLEX_STEP = 1e-30
"""Imaginary perturbation of the complex-step derivatives (as `dynamics.jacobian`)."""

_Z_SERIES = 0.5
"""|z| below which the Stumpff functions are evaluated by their power series."""

_MAX_NEWTON = 60
_Z_AXIS = np.array([0.0, 0.0, 1.0])
"""The pole of an integration without one (the states' own z axis)."""

INTEGRATED_MODELS = (MotionModel.TWO_BODY, MotionModel.J2, MotionModel.DRAG)
"""`dynamics` models integrated with their variational equations (`integrate_stm`)."""


def f64(a: AnyArray) -> Array:
    """Return ``a`` as a C-contiguous writable float64 array (the kernels' argument type).

    ``a`` itself when it is one (the usual case, checked faster than ``np.require``), else a
    copy: one array type per argument, so each kernel is compiled once.
    """
    if a.dtype == np.float64 and a.flags.c_contiguous and a.flags.writeable:
        return a
    out: Array = np.array(a, dtype=np.float64, order="C")
    return out


# --------------------------------------------------------------------------------------------
# Kepler's equation and the two-body STM
# --------------------------------------------------------------------------------------------
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
        # Newton's error after this step is ~ step^2 sigma / (2 r), sigma = dr/dchi
        sig = sig0 * (1.0 - alpha * u2) + (1.0 - alpha * r0) * u1
        conv = step * step * abs(sig) <= 2e-16 * r * abs(chi) or err == 0.0
        if err > 0.0:
            hi = min(hi, chi)
        elif err < 0.0:
            lo = max(lo, chi)
        new = chi - step
        if not (lo < new < hi):
            mid = 0.5 * (lo + hi)
            if math.isfinite(mid):
                new = mid
        chi = new
        if conv or not math.isfinite(chi):
            return chi, math.isfinite(chi)
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

    The analytic solution and STM of the module docstring (`kepler.propagate` is this for
    one object): the Lagrange coefficients ``F, G, Fdot, Gdot`` (``x1 = [F r0 + G v0,
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


# --------------------------------------------------------------------------------------------
# Integration with the variational equations
# --------------------------------------------------------------------------------------------
@jit
def _gravity_rhs(y: Array, mu: float, j2: float, re: float, px: float, py: float, pz: float,
                 out: Array, s: int) -> None:
    """``out[s] = dy/dt`` of the state + STM ``y`` (42,) under two-body + J2 gravity.

    J2 acts about the unit vector ``p = (px, py, pz)`` (the Earth's pole in the states'
    frame; (0, 0, 1): the frame's z axis, `dynamics._rhs_j2`). With ``r2 = |r|^2``,
    ``k = -mu / r^3``, ``f = 1.5 J2 Re^2 / r2``, ``z = p . r``, ``w = 5 z^2 / r2`` and
    ``g = 1 + f (1 - w)``::

        a = k (g r + 2 f z p)

    (J2 = 0: two-body). ``dPhi/dt = A Phi`` with ``A = [[0, I], [G, 0]]``: the velocity rows
    of Phi become the position rows of dPhi/dt, and ``G = da/dr``, analytic (the numpy path
    takes A by the complex step, exact to round-off as well)::

        G = k (g I + (4 f w - 2 f - 3 g) r r^T / r2 - 10 f z (r p^T + p r^T) / r2
               + 2 f p p^T)

    (symmetric, as the Hessian of the potential is; two-body: ``k (I - 3 r r^T / r2)``).
    """
    x, yy, zz = y[0], y[1], y[2]
    r2 = x * x + yy * yy + zz * zz
    r = math.sqrt(r2)
    k = -mu / (r2 * r)
    f = 1.5 * j2 * re * re / r2
    z = px * x + py * yy + pz * zz
    w = 5.0 * z * z / r2
    g = 1.0 + f * (1.0 - w)
    c = 2.0 * f * z
    out[s, 0], out[s, 1], out[s, 2] = y[3], y[4], y[5]
    out[s, 3] = k * (g * x + c * px)
    out[s, 4] = k * (g * yy + c * py)
    out[s, 5] = k * (g * zz + c * pz)
    ir2 = 1.0 / r2
    e = k * ir2 * (4.0 * f * w - 2.0 * f - 3.0 * g)  # the r r^T term
    d = -10.0 * k * f * z * ir2  # the (r p^T + p r^T) term
    h = 2.0 * k * f  # the p p^T term
    kg = k * g
    g00 = kg + e * x * x + 2.0 * d * x * px + h * px * px
    g11 = kg + e * yy * yy + 2.0 * d * yy * py + h * py * py
    g22 = kg + e * zz * zz + 2.0 * d * zz * pz + h * pz * pz
    g01 = e * x * yy + d * (x * py + px * yy) + h * px * py
    g02 = e * x * zz + d * (x * pz + px * zz) + h * px * pz
    g12 = e * yy * zz + d * (yy * pz + py * zz) + h * py * pz
    for j in range(6):  # dPhi/dt: rows 0-2 = Phi rows 3-5, rows 3-5 = G Phi rows 0-2
        p0, p1, p2 = y[6 + j], y[12 + j], y[18 + j]
        out[s, 6 + j] = y[24 + j]
        out[s, 12 + j] = y[30 + j]
        out[s, 18 + j] = y[36 + j]
        out[s, 24 + j] = g00 * p0 + g01 * p1 + g02 * p2
        out[s, 30 + j] = g01 * p0 + g11 * p1 + g12 * p2
        out[s, 36 + j] = g02 * p0 + g12 * p1 + g22 * p2


@jit
def _gravity_stm_kernel(x: Array, dt: Array, max_step: float, mu: float, j2: float, re: float,
                        pole: Array, A: Array, B: Array, x1: Array, phi: Array,
                        ok: BoolArray) -> None:
    """Fixed-step DOP853 of two-body + J2 with the STM for n objects (see `integrate_stm`).

    Object i takes ``ceil(|dt_i| / max_step)`` steps of ``h = dt_i / steps`` with the
    explicit Runge-Kutta tableau ``A`` (stages, stages), ``B`` (stages,) (scipy's DOP853) on
    ``y = [x, Phi]`` (42,), ``Phi(0) = I``, right-hand side `_gravity_rhs` with J2 about
    ``pole[i]`` (unit vectors (n, 3)); as
    `_integrate_stm_numpy` (the stage sums ``sum_j A[s, j] K[j]`` and ``sum_j B[j] K[j]``
    taken in the order of j, as BLAS may not: ~1e-16 apart per step). A non-finite input
    (state or dt) takes no step: x1 = x, Phi = I, ok False; ok is False where x1 or Phi is
    not finite.
    """
    ns = B.shape[0]
    y = np.empty(42)
    ys = np.empty(42)
    K = np.empty((ns, 42))
    for i in range(x.shape[0]):
        nf = dt[i] - dt[i]  # stays 0.0 unless an input is inf or nan
        for c in range(6):
            nf += x[i, c] - x[i, c]
            y[c] = x[i, c]
        for c in range(6, 42):
            y[c] = 0.0
        for c in range(6):
            y[6 + 7 * c] = 1.0
        steps = math.ceil(abs(dt[i]) / max_step) if nf == 0.0 else 0
        h = dt[i] / max(steps, 1)
        px, py, pz = pole[i, 0], pole[i, 1], pole[i, 2]
        for _ in range(steps):
            for s in range(ns):
                if s == 0:
                    _gravity_rhs(y, mu, j2, re, px, py, pz, K, 0)
                    continue
                a0 = A[s, 0]
                for c in range(42):
                    ys[c] = a0 * K[0, c]
                for j in range(1, s):
                    a = A[s, j]
                    for c in range(42):
                        ys[c] += a * K[j, c]
                for c in range(42):
                    ys[c] = y[c] + h * ys[c]
                _gravity_rhs(ys, mu, j2, re, px, py, pz, K, s)
            b0 = B[0]
            for c in range(42):
                ys[c] = b0 * K[0, c]
            for j in range(1, ns):
                b = B[j]
                for c in range(42):
                    ys[c] += b * K[j, c]
            for c in range(42):
                y[c] = y[c] + h * ys[c]
        for c in range(6):
            x1[i, c] = y[c]
            nf += y[c] - y[c]
        for c in range(36):
            w = y[6 + c]
            phi[i, c // 6, c % 6] = w
            nf += w - w
        ok[i] = nf == 0.0


def _variational(fun: Callable[..., Array], params: dict[str, float]) -> Callable[[Array], Array]:
    """Right-hand side of the stacked state + STM system, y (m, 42) -> dy/dt (m, 42)."""
    eye_h = 1j * _COMPLEX_STEP * np.eye(6)

    def f(y: Array) -> Array:
        m = y.shape[0]
        xs = y[:, :6]
        phi = y[:, 6:].reshape(m, 6, 6)
        xdot = fun(xs.T, **params).T
        # A[:, i, j] = d xdot_i / d x_j by the complex step, all objects and columns at once
        cols = xs[:, :, None] + eye_h  # (m, 6 components, 6 columns)
        A = fun(cols.transpose(1, 0, 2), **params).imag.transpose(1, 0, 2) / _COMPLEX_STEP
        return np.concatenate([xdot, np.matmul(A, phi).reshape(m, 36)], axis=1)

    return f


@functools.cache
def _dop853() -> tuple[Array, Array, int]:
    """Return the Dormand-Prince 8(5,3) tableau of scipy's DOP853: (A, B, stages).

    Read once (the arrays are shared: not to be written to).
    """
    from scipy.integrate._ivp import dop853_coefficients as dop

    return np.asarray(dop.A, float), np.asarray(dop.B, float), int(dop.N_STAGES)


@functools.cache
def _tableau() -> tuple[Array, Array]:
    """`_dop853`'s (A[:stages, :stages], B) as C-contiguous float64 (the kernel's)."""
    A, B, stages = _dop853()
    return np.ascontiguousarray(A[:stages, :stages]), np.ascontiguousarray(B)


def _defaults(fun: Callable[..., Array]) -> dict[str, float]:
    """Return the keyword parameters of a `dynamics` right-hand side with their defaults."""
    return {k: float(p.default) for k, p in inspect.signature(fun).parameters.items()
            if p.default is not inspect.Parameter.empty}


_GRAVITY_DEFAULTS = {m: _defaults(dynamics._MODELS[m][0])
                     for m in (MotionModel.TWO_BODY, MotionModel.J2)}
"""The models `_gravity_stm_kernel` integrates, with their parameters' defaults (`dynamics`'
own: ``mu``; ``mu``, ``j2``, ``re``)."""


def _gravity_params(model: MotionModel,
                    params: dict[str, float]) -> tuple[float, float, float] | None:
    """(mu, j2, re) of the compiled path for ``model`` and ``params``, or None (numpy path).

    None for a model the kernel does not integrate ("drag"), or parameters the model does not
    take or that are not real scalars (the numpy path then does what it always did with
    them: a TypeError for an unknown name, numpy broadcasting for arrays).
    """
    defaults = _GRAVITY_DEFAULTS.get(model)
    if defaults is None:
        return None
    p = dict(defaults)
    for k, v in params.items():
        if k not in defaults or not isinstance(v, (int, float, np.integer, np.floating)):
            return None
        p[k] = float(v)
    return p["mu"], p.get("j2", 0.0), p.get("re", 1.0)


def _integrated(model: MotionModel | str) -> MotionModel:
    """Return ``model`` as one of `INTEGRATED_MODELS` (ValueError naming them otherwise)."""
    if model not in INTEGRATED_MODELS:
        raise ValueError(f"model {model!r} is not one of {', '.join(INTEGRATED_MODELS)}")
    return MotionModel(model)


def integrate_stm(model: MotionModel | str, x: ArrayLike, dt: ArrayLike,
                  max_step_s: float = 60.0, pole_frame: ArrayLike | None = None,
                  **params: float) -> tuple[Array, Array, BoolArray]:
    """Integrate N states of a `dynamics` model with their STMs, fixed-step DOP853.

    Object i takes ``ceil(|dt_i| / max_step_s)`` equal steps of the 8th-order Dormand-Prince
    method. "two_body" and "j2": a compiled loop over the objects (`_gravity_stm_kernel`,
    analytic Jacobian; equal to `_integrate_stm_numpy` to ~1e-15 relative per step, 1e-12
    over days); "drag": `_integrate_stm_numpy`.

    Parameters
    ----------
    model : MotionModel or str
        One of `INTEGRATED_MODELS` ("two_body", "j2", "drag").
    x : array_like (N, 6)
        Initial states, GCRF km, km/s.
    dt : array_like (N,) or scalar
        Time steps, s (any sign).
    max_step_s : float
        Longest step, s.
    pole_frame : array_like (3, 3) or (N, 3, 3), optional
        Rotation from the states' frame (GCRF) to axes whose z is the Earth's pole at the
        start epoch (`frames.pole_frame`): J2 acts about its third row (the pole), in the
        compiled loop; on the numpy path ("drag") the states are turned to it, integrated
        (J2 and the atmosphere act about its z) and turned back, Phi with them. None: the
        states' own z axis is the pole.
    **params : float
        Model parameters (`dynamics` module docstring).

    Returns
    -------
    (x1 (N, 6), Phi (N, 6, 6), ok (N,)): ``ok`` False where input or result is not finite.
    """
    model = _integrated(model)
    gp = _gravity_params(model, params)
    X = np.atleast_2d(np.asarray(x, dtype=float))
    if gp is not None and X.ndim == 2 and X.shape[1] == 6 and (
            max_step_s > 0.0 and math.isfinite(max_step_s)):
        X = f64(X)
        n = X.shape[0]
        dts = f64(np.broadcast_to(np.asarray(dt, dtype=float), (n,)))
        # J2 about the pole: the third row of the rotation to the pole's axes
        pole = (np.broadcast_to(_Z_AXIS, (n, 3)) if pole_frame is None else
                np.broadcast_to(np.asarray(pole_frame, dtype=float)[..., 2, :], (n, 3)))
        A, B = _tableau()
        x1, phi = np.empty((n, 6)), np.empty((n, 6, 6))
        ok = np.empty(n, dtype=np.bool_)
        _gravity_stm_kernel(X, dts, float(max_step_s), *gp, f64(pole), A, B, x1, phi, ok)
        return x1, phi, ok
    if pole_frame is not None and model != MotionModel.TWO_BODY:  # numpy path: turn the states
        r = np.asarray(pole_frame, dtype=float)
        B = np.zeros((*r.shape[:-2], 6, 6))  # diag(R, R): states into the pole's axes
        B[..., :3, :3] = B[..., 3:, 3:] = r
        Bt = np.swapaxes(B, -1, -2)
        X = np.atleast_2d(np.asarray(x, dtype=float))
        x1p, phip, okp = integrate_stm(model, np.einsum("...ij,...j->...i", B, X), dt,
                                       max_step_s, None, **params)
        x1 = f64(np.einsum("...ij,...j->...i", Bt, x1p))
        return x1, np.matmul(np.matmul(Bt, phip), B), okp
    return _integrate_stm_numpy(model, X, dt, max_step_s, **params)


def _integrate_stm_numpy(model: MotionModel | str, x: ArrayLike, dt: ArrayLike,
                         max_step_s: float = 60.0,
                         **params: float) -> tuple[Array, Array, BoolArray]:
    """`integrate_stm` in numpy, vectorised over the objects (any `INTEGRATED_MODELS` model).

    All objects still stepping are advanced together (one right-hand-side call per stage for
    all of them; A by the complex step, `_variational`). `integrate_stm` uses it for "drag"
    (and unusual arguments); the tests compare the compiled path with it.
    """
    model = _integrated(model)
    A, B, stages = _dop853()
    f = _variational(dynamics._MODELS[model][0], params)
    X = np.atleast_2d(np.asarray(x, dtype=float))
    n = X.shape[0]
    dts = np.broadcast_to(np.asarray(dt, dtype=float), (n,))
    with np.errstate(all="ignore"):
        ok = np.isfinite(X).all(axis=1) & np.isfinite(dts)
        steps = np.where(ok, np.ceil(np.abs(dts) / max_step_s), 0).astype(np.int64)
        order = np.argsort(-steps, kind="stable")  # most steps first: the active ones lead
        y = np.concatenate([X, np.tile(np.eye(6).ravel(), (n, 1))], axis=1)[order]
        h = (dts / np.maximum(steps, 1))[order][:, None]
        ks = steps[order]
        K = np.empty((stages, n, 42))
        for k in range(int(ks[0]) if n else 0):
            m = int(np.count_nonzero(ks > k))
            ym, hm = y[:m], h[:m]
            for s in range(stages):
                inc = np.tensordot(A[s, :s], K[:s, :m], axes=1) if s else 0.0
                K[s, :m] = f(ym + hm * inc)
            y[:m] = ym + hm * np.tensordot(B, K[:, :m], axes=1)
        out = np.empty_like(y)
        out[order] = y
        x1 = np.ascontiguousarray(out[:, :6])
        phi = out[:, 6:].reshape(n, 6, 6).copy()
        ok &= np.isfinite(x1).all(axis=1) & np.isfinite(phi).all(axis=(1, 2))
    return x1, phi, ok
