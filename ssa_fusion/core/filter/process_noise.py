"""Process noise with physical meaning: state-noise and dynamic-model compensation in RTN.

Both model the accelerations the motion model leaves out (drag errors, higher harmonics,
third bodies) as random accelerations along the orbit's own axes, radial R = r/|r|,
cross-track N = (r x v)/|r x v| and along-track T = N x R (`frames.rtn_axes`), which is
where they act: drag along-track, gravity-field errors radially and along-track. The
matrices are mapped to the GCRF with those axes at the state given (``M = [R T N]``, GCRF
from RTN), so they are rotation-covariant: the Q of a rotated state is the rotated Q.

State-noise compensation (SNC, `snc`)
    White-noise accelerations with power spectral densities ``psd = (q_R, q_T, q_N)``,
    km^2/s^3 (so that ``q dt`` is a velocity variance, km^2/s^2). Over a step ``dt`` short
    against the orbit (the kinematic approximation of `ekf.process_noise`, with the axes of
    the state)::

        Q = [[dt^3/3 Qa, s dt^2/2 Qa], [s dt^2/2 Qa, |dt| Qa]],   Qa = M diag(psd) M^T

    ``s`` the sign of dt (a step backwards in time correlates position and velocity
    negatively). Equal PSDs give exactly `ekf.process_noise` (isotropic white noise).
    For a long step, integrate along the trajectory: sum the short steps' Q mapped by the
    state transition matrices (as `batch_ls` does through a gap).

Dynamic-model compensation (DMC, `dmc`, `gauss_markov`)
    First-order Gauss-Markov accelerations ``w`` (RTN components), per axis
    ``dw/dt = -w / tau + u`` with time constant ``tau`` s and steady-state standard
    deviation ``sigma`` km/s^2: ``u`` is white with PSD ``q_u = 2 sigma^2 / tau``. With the
    acceleration in the state ([r, v, w], 9 states) the discrete transition and noise per
    axis are, with ``b = 1/tau``, ``E = exp(-b dt)``::

        Phi = [[1, dt, (b dt - 1 + E)/b^2], [0, 1, (1 - E)/b], [0, 0, E]]
        Q   = q_u int_0^dt g(s) g(s)^T ds,   g(s) = [(b s - 1 + e^-bs)/b^2, (1 - e^-bs)/b, e^-bs]

    (Tapley, Schutz & Born, Statistical Orbit Determination, 4.9; closed form for
    ``b dt > 1``, the power series in ``b dt`` below, where the closed form cancels).
    For a 6-state filter that does not carry ``w``, `dmc_equivalent_q` is the covariance
    of the position and velocity a *stationary* Gauss-Markov acceleration adds over the
    step (``w`` correlated in time, its start drawn from the steady state)::

        Q_vv = 2 sigma^2 dt^2 [1/u - (1 - E)/u^2],  Q_rv = dt Q_vv / 2,
        Q_rr = 2 sigma^2 dt^4 [1/(3u) - 1/(2u^2) + (1 - E (1 + u))/u^4],   u = dt / tau

    Limits (the tests check them): ``tau -> 0`` with ``q = 2 sigma^2 tau`` fixed, both tend
    to the white-noise Q of PSD q (SNC); ``tau -> inf`` (``u -> 0``), the equivalent Q tends
    to a random constant acceleration over the step, ``sigma^2 [[dt^4/4, dt^3/2],
    [dt^3/2, dt^2]]``.

Units: km, km/s, km/s^2, s; PSDs km^2/s^3; GCRF states.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ssa_fusion.core.earth.frames import rtn_axes

__all__ = ["dmc", "dmc_equivalent_q", "gauss_markov", "rtn_matrix", "snc", "snc_batch",
           "white_psd"]

Array = NDArray[np.float64]

_SERIES_BELOW = 1.0
"""``dt / tau`` below which the Gauss-Markov integrals are summed as power series."""

_TERMS = 30
"""Terms of those series (the remainder is below 1e-30 relative for dt / tau <= 1)."""


def rtn_matrix(x: ArrayLike) -> Array:
    """Return ``M`` (3, 3), GCRF from RTN: columns the unit R, T, N axes of GCRF state ``x``.

    Parameters
    ----------
    x : array_like (6,)
        GCRF state, km, km/s.

    Returns
    -------
    ndarray (3, 3)
    """
    m: Array = rtn_axes(np.asarray(x, dtype=float).reshape(1, 6))[0].T
    return m


def _triple(v: float | Sequence[float] | ArrayLike) -> Array:
    """``v`` as three per-axis values (a scalar repeated)."""
    a = np.asarray(v, dtype=float).reshape(-1)
    out: Array = np.broadcast_to(a, (3,)).astype(float) if a.size in (1, 3) else a
    if out.shape != (3,):
        raise ValueError(f"expected a scalar or three values (R, T, N), got {a.size}")
    return out


def snc(x: ArrayLike, dt_s: float, psd_rtn: float | Sequence[float] | ArrayLike) -> Array:
    """State-noise compensation Q (6, 6) over a step (module docstring).

    Parameters
    ----------
    x : array_like (6,)
        GCRF state (km, km/s) whose RTN axes the accelerations follow (the step's start or
        middle).
    dt_s : float
        Step, s (negative: a step backwards in time).
    psd_rtn : float or (3,)
        White-noise acceleration PSDs along R, T, N, km^2/s^3 (one value: isotropic).

    Returns
    -------
    ndarray (6, 6)
        GCRF [r, v] covariance, km^2, km^2/s, km^2/s^2.
    """
    out: Array = snc_batch(np.asarray(x, dtype=float).reshape(1, 6), np.array([dt_s]),
                           psd_rtn)[0]
    return out


def snc_batch(x: ArrayLike, dt_s: ArrayLike,
              psd_rtn: float | Sequence[float] | ArrayLike) -> Array:
    """`snc` of K steps at once: states (K, 6), steps (K,) s -> Q (K, 6, 6).

    Parameters
    ----------
    x : array_like (K, 6)
        GCRF states (km, km/s) whose RTN axes the accelerations follow.
    dt_s : array_like (K,)
        Steps, s (negative: backwards in time).
    psd_rtn : float or (3,)
        White-noise acceleration PSDs along R, T, N, km^2/s^3.

    Returns
    -------
    ndarray (K, 6, 6)
        GCRF [r, v] covariances, km^2, km^2/s, km^2/s^2.
    """
    q = _triple(psd_rtn)
    xx = np.atleast_2d(np.asarray(x, dtype=float))
    dt = np.asarray(dt_s, dtype=float).reshape(-1)
    if q[0] == q[1] == q[2]:  # isotropic: exactly `ekf.process_noise`, whatever the axes
        qa = np.broadcast_to(q[0] * np.eye(3), (xx.shape[0], 3, 3))
    else:
        m = np.swapaxes(rtn_axes(xx), 1, 2)  # columns R, T, N
        qa = (m * q) @ np.swapaxes(m, 1, 2)
        qa = 0.5 * (qa + np.swapaxes(qa, 1, 2))
    a = np.abs(dt)[:, None, None]
    out = np.empty((xx.shape[0], 6, 6))
    out[:, :3, :3] = qa * (a**3 / 3.0)
    out[:, :3, 3:] = out[:, 3:, :3] = qa * (dt[:, None, None] * a / 2.0)
    out[:, 3:, 3:] = qa * a
    return out


def white_psd(tau_s: float, sigma: float) -> float:
    """Return ``2 sigma^2 tau``, the white-noise PSD (km^2/s^3) of a Gauss-Markov acceleration.

    The PSD of the white noise whose integral equals that of a Gauss-Markov acceleration of
    steady-state ``sigma`` km/s^2 and time constant ``tau`` s (the tau -> 0 limit).
    """
    return 2.0 * sigma * sigma * tau_s


def _series(u: float) -> tuple[Array, Array, Array]:
    """Polynomial coefficients in s/dt of g_r / dt^2, g_v / dt, g_w (module docstring)."""
    k = np.arange(_TERMS)
    fact = np.cumprod(np.concatenate([[1.0], np.arange(1.0, _TERMS + 3)]))  # 0! .. (T+2)!
    pw = (-u) ** k
    cw, cv, cr = np.zeros(_TERMS + 2), np.zeros(_TERMS + 2), np.zeros(_TERMS + 2)
    cw[:_TERMS] = pw / fact[k]
    cv[1:_TERMS + 1] = pw / fact[k + 1]
    cr[2:_TERMS + 2] = pw / fact[k + 2]
    return cr, cv, cw


def _int01(a: Array, b: Array) -> float:
    """Integral over [0, 1] of the product of two polynomials (coefficients, low first)."""
    c = np.convolve(a, b)
    return float(np.sum(c / np.arange(1.0, c.size + 1)))


def gauss_markov(dt_s: float, tau_s: float, sigma: float) -> tuple[Array, Array]:
    """Transition and process noise (3, 3) of one axis of [r, v, w] with a GM acceleration.

    Parameters
    ----------
    dt_s : float
        Step, s (>= 0).
    tau_s : float
        Time constant of the acceleration, s (> 0).
    sigma : float
        Its steady-state standard deviation, km/s^2.

    Returns
    -------
    (Phi (3, 3), Q (3, 3)) in km, km/s, km/s^2 (module docstring).
    """
    T = abs(float(dt_s))
    b = 1.0 / float(tau_s)
    u = b * T
    E = math.exp(-u)
    qu = 2.0 * sigma * sigma * b
    Q = np.empty((3, 3))
    if u > _SERIES_BELOW:
        em = -math.expm1(-u)
        e2 = em * (2.0 - em)  # 1 - E^2
        phi_rw = T * T * (u - em) / (u * u)
        phi_vw = T * em / u
        Q[2, 2] = qu * e2 / (2.0 * b)
        Q[1, 2] = qu / b**2 * (em - e2 / 2.0)
        Q[1, 1] = qu / b**3 * (u - 2.0 * em + e2 / 2.0)
        Q[0, 2] = qu / b**3 * (e2 / 2.0 - u * E)
        Q[0, 1] = qu / b**4 * (u * u / 2.0 - (1.0 - E * (1.0 + u)) - u + 2.0 * em - e2 / 2.0)
        Q[0, 0] = qu / b**5 * (((u - 1.0) ** 3 + 1.0) / 3.0 - 2.0 * u * E + e2 / 2.0)
    else:
        cr, cv, cw = _series(u)
        phi_rw = T * T * float(np.sum(cr))
        phi_vw = T * float(np.sum(cv))
        g = (cr, cv, cw)
        p = (2, 1, 0)
        for i in range(3):
            for j in range(i, 3):
                Q[i, j] = qu * T ** (1 + p[i] + p[j]) * _int01(g[i], g[j])
    Q[1, 0], Q[2, 0], Q[2, 1] = Q[0, 1], Q[0, 2], Q[1, 2]
    phi = np.array([[1.0, T, phi_rw], [0.0, 1.0, phi_vw], [0.0, 0.0, E]])
    return phi, Q


def dmc(x: ArrayLike, dt_s: float, tau_s: float | Sequence[float] | ArrayLike,
        sigma_rtn: float | Sequence[float] | ArrayLike,
        phi6: ArrayLike | None = None) -> tuple[Array, Array]:
    """Transition and process noise (9, 9) of [r, v, w]: DMC, w in RTN (module docstring).

    The accelerations' axes are those of ``x`` (the step's start), held over the step; the
    coupling of ``w`` into r and v is the kinematic one, valid for steps short against the
    orbit's period (a filter's prediction steps of <= 60 s).

    Parameters
    ----------
    x : array_like (6,)
        GCRF state at the step's start, km, km/s.
    dt_s : float
        Step, s (>= 0).
    tau_s : float or (3,)
        Time constants along R, T, N, s.
    sigma_rtn : float or (3,)
        Steady-state standard deviations along R, T, N, km/s^2.
    phi6 : array_like (6, 6), optional
        The motion model's state transition matrix over the step (the [r, v] block of the
        result); None: the kinematic ``[[I, dt I], [0, I]]``.

    Returns
    -------
    (Phi (9, 9), Q (9, 9)): the states [r (GCRF km), v (GCRF km/s), w (RTN km/s^2)].
    """
    taus, sigmas = _triple(tau_s), _triple(sigma_rtn)
    m = rtn_matrix(x)
    T = abs(float(dt_s))
    parts = [gauss_markov(T, float(taus[a]), float(sigmas[a])) for a in range(3)]
    phi = np.eye(9)
    if phi6 is None:
        phi[:3, 3:6] = T * np.eye(3)
    else:
        phi[:6, :6] = np.asarray(phi6, dtype=float)
    phi[:3, 6:] = m * np.array([p[0][0, 2] for p in parts])
    phi[3:6, 6:] = m * np.array([p[0][1, 2] for p in parts])
    phi[6:, 6:] = np.diag([p[0][2, 2] for p in parts])
    Q = np.zeros((9, 9))

    def axis(i: int, j: int) -> Array:
        return np.array([p[1][i, j] for p in parts])

    Q[:3, :3] = (m * axis(0, 0)) @ m.T
    Q[:3, 3:6] = (m * axis(0, 1)) @ m.T
    Q[3:6, 3:6] = (m * axis(1, 1)) @ m.T
    Q[:3, 6:] = m * axis(0, 2)
    Q[3:6, 6:] = m * axis(1, 2)
    Q[6:, 6:] = np.diag(axis(2, 2))
    Q = np.triu(Q) + np.triu(Q, 1).T
    return phi, 0.5 * (Q + Q.T)


def _equivalent_axis(T: float, tau: float, sigma: float) -> tuple[float, float, float]:
    """(Q_rr, Q_rv, Q_vv) of one axis of `dmc_equivalent_q`."""
    u = T / tau
    s2 = sigma * sigma
    if u > _SERIES_BELOW:
        em = -math.expm1(-u)
        vv = 2.0 * s2 * T * T * (1.0 / u - em / (u * u))
        rr = 2.0 * s2 * T**4 * (1.0 / (3.0 * u) - 1.0 / (2.0 * u * u)
                                + (1.0 - math.exp(-u) * (1.0 + u)) / u**4)
    else:
        k = np.arange(2, _TERMS + 4, dtype=float)
        fact = np.array([math.factorial(int(i)) for i in k])
        sv = float(np.sum((-1.0) ** k * u ** (k - 2) / fact))
        kk, fk = k[2:], fact[2:]  # k >= 4
        sr = float(np.sum((-1.0) ** kk * (kk - 1.0) / fk * u ** (kk - 4)))
        vv = 2.0 * s2 * T * T * sv
        rr = 2.0 * s2 * T**4 * sr
    return rr, T * vv / 2.0, vv


def dmc_equivalent_q(x: ArrayLike, dt_s: float, tau_s: float | Sequence[float] | ArrayLike,
                     sigma_rtn: float | Sequence[float] | ArrayLike) -> Array:
    """Return a 6-state filter's Q (6, 6) of stationary Gauss-Markov RTN accelerations.

    Parameters
    ----------
    x : array_like (6,)
        GCRF state whose RTN axes the accelerations follow, km, km/s.
    dt_s : float
        Step, s (its sign is ignored, as `ekf.process_noise` does).
    tau_s : float or (3,)
        Time constants along R, T, N, s.
    sigma_rtn : float or (3,)
        Steady-state standard deviations along R, T, N, km/s^2.

    Returns
    -------
    ndarray (6, 6)
        GCRF [r, v] covariance, km^2, km^2/s, km^2/s^2.
    """
    taus, sigmas = _triple(tau_s), _triple(sigma_rtn)
    m = rtn_matrix(x)
    T = abs(float(dt_s))
    d = np.array([_equivalent_axis(T, float(taus[a]), float(sigmas[a])) for a in range(3)])
    out = np.empty((6, 6))
    out[:3, :3] = (m * d[:, 0]) @ m.T
    out[:3, 3:] = out[3:, :3] = (m * d[:, 1]) @ m.T
    out[3:, 3:] = (m * d[:, 2]) @ m.T
    return 0.5 * (out + out.T)
