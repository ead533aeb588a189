"""Truth dynamics: numerically integrated models, Keplerian elements, and an SGP4/SDP4 ephemeris.

Models for :func:`propagate` (state layout, units, parameters), by their `types.MotionModel`
name:

``"two_body"``  inertial [r km, v km/s] (GCRF); ``mu`` (km^3/s^2, default MU_EARTH).
``"j2"``        two-body + J2 zonal about the z axis of the frame the state is in; ``mu``,
                ``j2`` (default J2), ``re`` (km, default R_EARTH). In the GCRF the Earth's
                pole is not that axis (precession and nutation have moved it by ~0.14 deg
                since J2000): give `propagate` the ``pole_frame`` of the start epoch
                (`frames.pole_frame`), which turns the state to axes whose z is the pole.
``"drag"``      two-body + drag in an exponential atmosphere co-rotating with the Earth (about
                the z axis, as J2: the same ``pole_frame`` applies):
                ``a = -0.5 rho |v_rel| v_rel / bc``; ``bc`` = ballistic coefficient m/(Cd A)
                in kg/m^2 (default 100, ISS-like, giving ~0.1 km/day decay of a at 420 km);
                ``rho0`` kg/m^3 at ``h0`` km with scale height ``scale_height`` km (defaults:
                Vallado's exponential model row for 400-450 km: 3.725e-12, 400, 58.515).
``"cr3bp"``     Earth-Moon circular restricted three-body problem, rotating frame, nondimensional
                (Earth at (-mu, 0, 0), Moon at (1 - mu, 0, 0)); ``mu`` (default MU_EARTH_MOON).
``"pendulum"``  [theta rad, theta_dot rad/s]; ``theta_dd = -(c/m) theta_dot - (g/L) sin(theta)``
                (the paper's state-space form); ``m`` kg (0.5), ``c`` (2e-3), ``L`` m (1.0, our
                choice: the paper gives none; small-angle period 2.006 s), ``g`` m/s^2 (G0).
``"vdp"``       Van der Pol [x, x_dot]; ``x_dd = mu (1 - x^2) x_dot - x``; ``mu`` (default 2).

All right-hand sides are vectorised: ``x0`` may be one state (n,) or a batch (p, n) (e.g. a
Monte Carlo ensemble), integrated as one system.

``scipy.integrate`` and ``scipy.optimize`` are imported by the functions that use them, not
here: a process that only uses the Kepler or J2 models never pays for ``scipy.integrate``
(~0.6 s to import).
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
from numpy.typing import ArrayLike, NDArray
from sgp4.api import WGS72, Satrec

from ssa_fusion.core.base.constants import G0, J2, MU_EARTH, MU_EARTH_MOON, OMEGA_EARTH, R_EARTH
from ssa_fusion.core.base.types import MotionModel
from ssa_fusion.core.earth import frames
from ssa_fusion.core.earth.frames import wrap_2pi
from ssa_fusion.core.earth.timescales import UNIX_EPOCH_JD

Array = NDArray[np.float64]

# --------------------------------------------------------------------------------------------
# Right-hand sides; y has shape (n, ...) (state along axis 0)
# --------------------------------------------------------------------------------------------
def _rhs_two_body(y: Array, mu: float = MU_EARTH) -> Array:
    r = y[:3]
    rn = np.sqrt(np.sum(r * r, axis=0))
    return np.concatenate([y[3:6], -mu * r / rn**3])


def _rhs_j2(y: Array, mu: float = MU_EARTH, j2: float = J2, re: float = R_EARTH) -> Array:
    x, yy, z = y[0], y[1], y[2]
    r2 = x * x + yy * yy + z * z
    r = np.sqrt(r2)
    k = -mu / (r2 * r)
    f = 1.5 * j2 * re * re / r2
    z2r = 5.0 * z * z / r2
    ax = k * x * (1.0 + f * (1.0 - z2r))
    ay = k * yy * (1.0 + f * (1.0 - z2r))
    az = k * z * (1.0 + f * (3.0 - z2r))
    return np.concatenate([y[3:6], np.stack([ax, ay, az])])


def _rhs_drag(
    y: Array,
    mu: float = MU_EARTH,
    bc: float = 100.0,
    rho0: float = 3.725e-12,
    h0: float = 400.0,
    scale_height: float = 58.515,
    re: float = R_EARTH,
    omega: float = OMEGA_EARTH,
) -> Array:
    out = _rhs_two_body(y, mu)
    r = y[:3]
    rn = np.sqrt(np.sum(r * r, axis=0))
    rho = rho0 * np.exp(-(rn - re - h0) / scale_height)  # kg/m^3
    vrel = y[3:6] - omega * np.stack([-r[1], r[0], np.zeros_like(r[0])])  # km/s
    vn = np.sqrt(np.sum(vrel * vrel, axis=0))
    # 0.5 rho v^2 / bc in m/s^2 (v in m/s) -> km/s^2: rho * (vn*1e3)^2 / bc * 1e-3
    out[3:6] -= 0.5 * rho * 1e3 * vn * vrel / bc
    return out


def _rhs_cr3bp(y: Array, mu: float = MU_EARTH_MOON) -> Array:
    x, yy, z, vx, vy, vz = y[0], y[1], y[2], y[3], y[4], y[5]
    r1 = np.sqrt((x + mu) ** 2 + yy * yy + z * z)
    r2 = np.sqrt((x - 1.0 + mu) ** 2 + yy * yy + z * z)
    a = (1.0 - mu) / r1**3
    b = mu / r2**3
    ax = 2.0 * vy + x - a * (x + mu) - b * (x - 1.0 + mu)
    ay = -2.0 * vx + yy - (a + b) * yy
    az = -(a + b) * z
    return np.stack([vx, vy, vz, ax, ay, az])


def _rhs_pendulum(
    y: Array, m: float = 0.5, c: float = 2e-3, L: float = 1.0, g: float = G0
) -> Array:
    return np.stack([y[1], -(c / m) * y[1] - (g / L) * np.sin(y[0])])


def _rhs_vdp(y: Array, mu: float = 2.0) -> Array:
    return np.stack([y[1], mu * (1.0 - y[0] ** 2) * y[1] - y[0]])


_MODELS: dict[str, tuple[Callable[..., Array], int]] = {
    MotionModel.TWO_BODY: (_rhs_two_body, 6),
    MotionModel.J2: (_rhs_j2, 6),
    MotionModel.DRAG: (_rhs_drag, 6),
    MotionModel.CR3BP: (_rhs_cr3bp, 6),
    MotionModel.PENDULUM: (_rhs_pendulum, 2),
    MotionModel.VDP: (_rhs_vdp, 2),
}
"""Right-hand side and state size of each integrated `types.MotionModel` (looked up by the
model or its name)."""


def rhs(model: str, x: ArrayLike, **params: float) -> Array:
    """Time derivative dx/dt of state(s) ``x`` ((n,) or (n, p), state along axis 0)."""
    return _MODELS[model][0](np.asarray(x, float), **params)


def rotate_states(x: Array, rotation: Array | None) -> Array:
    """States (..., 6) (or positions (..., 3)) with every 3-vector turned by ``rotation``.

    ``rotation`` (3, 3) or (..., 3, 3) broadcasting against the leading axes; None: ``x``.
    """
    if rotation is None:
        return x
    parts = [np.einsum("...ij,...j->...i", rotation, x[..., k:k + 3])
             for k in range(0, x.shape[-1], 3)]
    out: Array = np.concatenate(parts, -1)
    return out


def propagate(model: str, x0: ArrayLike, t_s: ArrayLike, rtol: float = 1e-12,
              atol: float = 1e-12, pole_frame: Array | None = None, **params: float) -> Array:
    """Integrate ``model`` from ``x0`` (at ``t_s[0]``) and sample it at ``t_s``.

    Parameters
    ----------
    model
        One of "two_body", "j2", "drag", "cr3bp", "pendulum", "vdp" (see module docstring).
    x0
        Initial state (n,) or a batch (p, n), in the model's units (orbits: GCRF km, km/s).
    t_s
        Monotonic sample times (s; nondimensional time for "cr3bp"); ``t_s[0]`` is x0's epoch.
    rtol, atol
        DOP853 tolerances.
    pole_frame
        Rotation (3, 3) from the states' frame to axes whose z is the Earth's pole
        (`frames.pole_frame` of the start epoch), for the orbit models; None: the frame's
        own z axis is the pole.
    **params
        Model parameters (module docstring).

    Returns
    -------
    ndarray (len(t_s), n) or (len(t_s), p, n) for a batch.
    """
    if pole_frame is not None:
        r = np.asarray(pole_frame, dtype=float)
        x_pole = rotate_states(np.asarray(x0, dtype=float), r)
        out_pole = propagate(model, x_pole, t_s, rtol, atol, None, **params)
        return rotate_states(out_pole, r.T)
    from scipy.integrate import solve_ivp

    fun, n = _MODELS[model]
    x0 = np.asarray(x0, dtype=float)
    t = np.atleast_1d(np.asarray(t_s, dtype=float))
    if x0.shape[-1] != n:
        raise ValueError(f"model {model!r} needs states of size {n}, got {x0.shape}")
    batch = x0.shape[:-1]
    y0 = np.moveaxis(x0, -1, 0).reshape(n, -1)  # (n, p)
    p = y0.shape[1]

    def f(_t: float, y: Array) -> Array:
        return fun(y.reshape(n, p), **params).reshape(-1)

    if t.size == 1 or t[-1] == t[0]:
        out = np.repeat(y0.reshape(1, n, p), t.size, axis=0)
    else:
        sol = solve_ivp(
            f, (t[0], t[-1]), y0.reshape(-1), method="DOP853", t_eval=t, rtol=rtol, atol=atol
        )
        if not sol.success:
            raise RuntimeError(f"propagation failed: {sol.message}")
        out = sol.y.T.reshape(t.size, n, p)
    out = np.moveaxis(out, 1, -1)  # (k, p, n)
    return out.reshape((t.size, *batch, n))


def _jac_two_body(x: Array, mu: float = MU_EARTH) -> Array:
    r = x[:3]
    rn = math.sqrt(float(r @ r))
    A = np.zeros((6, 6))
    A[:3, 3:] = np.eye(3)
    A[3:, :3] = mu / rn**3 * (3.0 * np.outer(r, r) / rn**2 - np.eye(3))
    return A


def _jac_cr3bp(x: Array, mu: float = MU_EARTH_MOON) -> Array:
    px, py, pz = float(x[0]), float(x[1]), float(x[2])
    d1 = np.array([px + mu, py, pz])
    d2 = np.array([px - 1.0 + mu, py, pz])
    r1, r2 = math.sqrt(float(d1 @ d1)), math.sqrt(float(d2 @ d2))
    g = (
        (1.0 - mu) * (3.0 * np.outer(d1, d1) / r1**5 - np.eye(3) / r1**3)
        + mu * (3.0 * np.outer(d2, d2) / r2**5 - np.eye(3) / r2**3)
    )
    g[0, 0] += 1.0
    g[1, 1] += 1.0
    A = np.zeros((6, 6))
    A[:3, 3:] = np.eye(3)
    A[3:, :3] = g
    A[3, 4], A[4, 3] = 2.0, -2.0
    return A


def _jac_pendulum(
    x: Array, m: float = 0.5, c: float = 2e-3, L: float = 1.0, g: float = G0
) -> Array:
    return np.array([[0.0, 1.0], [-(g / L) * math.cos(float(x[0])), -c / m]])


def _jac_vdp(x: Array, mu: float = 2.0) -> Array:
    p, v = float(x[0]), float(x[1])
    return np.array([[0.0, 1.0], [-2.0 * mu * p * v - 1.0, mu * (1.0 - p * p)]])


_JACOBIANS: dict[str, Callable[..., Array]] = {
    MotionModel.TWO_BODY: _jac_two_body,
    MotionModel.CR3BP: _jac_cr3bp,
    MotionModel.PENDULUM: _jac_pendulum,
    MotionModel.VDP: _jac_vdp,
}


def jacobian(model: str, x: ArrayLike, **params: float) -> Array:
    """State Jacobian A = d(dx/dt)/dx (n, n) at one state ``x`` (n,).

    Analytic for "two_body", "cr3bp", "pendulum", "vdp"; for "j2" and "drag" by the complex
    step (one vectorised call of the right-hand side on x + i h e_j, A[:, j] = Im f / h), which
    is exact to round-off: a finite-difference Jacobian's truncation noise makes an adaptive
    integrator of the variational equations take ~40 steps where 3 do.
    """
    xx = np.asarray(x, float)
    if model in _JACOBIANS:
        return _JACOBIANS[model](xx, **params)
    fun, n = _MODELS[model]
    h = 1e-30
    cols = xx[:, None] + 1j * h * np.eye(n)
    jac: Array = fun(cols, **params).imag / h
    return jac


def propagate_stm(model: str, x0: ArrayLike, dt_s: float, rtol: float = 1e-11,
                  atol: float = 1e-12, **params: float) -> tuple[Array, Array]:
    """Propagate one state ``x0`` (n,) by ``dt_s`` with its state transition matrix.

    Integrates the variational equations dPhi/dt = A(x) Phi (DOP853) alongside the state;
    for EKF placeholders that are not Keplerian (pendulum, Van der Pol, CR3BP).

    Returns
    -------
    (x1 (n,), Phi (n, n)) with Phi = dx1/dx0.
    """
    from scipy.integrate import solve_ivp

    fun, n = _MODELS[model]
    x = np.asarray(x0, float)
    if x.shape != (n,):
        raise ValueError(f"model {model!r} needs a state of shape ({n},), got {x.shape}")
    if dt_s == 0.0:
        return x.copy(), np.eye(n)

    def f(_t: float, y: Array) -> Array:
        xs = y[:n]
        phi = y[n:].reshape(n, n)
        return np.concatenate([fun(xs, **params), (jacobian(model, xs, **params) @ phi).ravel()])

    y0 = np.concatenate([x, np.eye(n).ravel()])
    sol = solve_ivp(f, (0.0, dt_s), y0, method="DOP853", rtol=rtol, atol=atol)
    if not sol.success:
        raise RuntimeError(f"propagation failed: {sol.message}")
    y1 = sol.y[:, -1]
    return y1[:n].copy(), y1[n:].reshape(n, n).copy()


# --------------------------------------------------------------------------------------------
# Keplerian elements
# --------------------------------------------------------------------------------------------
def elements_to_state(
    a_km: float,
    e: float,
    i_rad: float,
    raan_rad: float,
    argp_rad: float,
    nu_rad: float,
    mu: float = MU_EARTH,
) -> Array:
    """Classical elements -> inertial state [r km, v km/s] (6,).

    Semi-major axis ``a_km`` (negative for hyperbolas), eccentricity, inclination, RAAN,
    argument of periapsis and true anomaly in rad.
    """
    p = a_km * (1.0 - e * e)
    cn, sn = math.cos(nu_rad), math.sin(nu_rad)
    rm = p / (1.0 + e * cn)
    r_pf = np.array([rm * cn, rm * sn, 0.0])
    sq = math.sqrt(mu / p)
    v_pf = np.array([-sq * sn, sq * (e + cn), 0.0])
    co, so = math.cos(raan_rad), math.sin(raan_rad)
    cw, sw = math.cos(argp_rad), math.sin(argp_rad)
    ci, si = math.cos(i_rad), math.sin(i_rad)
    q = np.array(
        [
            [co * cw - so * sw * ci, -co * sw - so * cw * ci, so * si],
            [so * cw + co * sw * ci, -so * sw + co * cw * ci, -co * si],
            [sw * si, cw * si, ci],
        ]
    )
    return np.concatenate([q @ r_pf, q @ v_pf])


def state_to_elements(
    x: ArrayLike, mu: float = MU_EARTH
) -> tuple[float, float, float, float, float, float]:
    """Inertial state [km, km/s] -> (a km, e, i, raan, argp, nu) with angles in rad.

    Angles in [0, 2 pi) (i in [0, pi]). For circular orbits argp is 0 and nu is the argument of
    latitude; for equatorial orbits raan is 0 and argp is measured from +x.
    """
    x = np.asarray(x, float)
    r, v = x[:3], x[3:6]
    rn, vn2 = float(np.linalg.norm(r)), float(v @ v)
    h = np.cross(r, v)
    hn = float(np.linalg.norm(h))
    nvec = np.array([-h[1], h[0], 0.0])
    nn = float(np.linalg.norm(nvec))
    evec = ((vn2 - mu / rn) * r - float(r @ v) * v) / mu
    e = float(np.linalg.norm(evec))
    energy = vn2 / 2.0 - mu / rn
    a = -mu / (2.0 * energy)
    inc = math.acos(max(-1.0, min(1.0, h[2] / hn)))
    tol = 1e-11
    two_pi = 2.0 * math.pi
    raan = math.atan2(nvec[1], nvec[0]) % two_pi if nn > tol * hn else 0.0
    node = nvec / nn if nn > tol * hn else np.array([1.0, 0.0, 0.0])
    what = h / hn
    if e > tol:
        argp = math.atan2(float(what @ np.cross(node, evec)), float(node @ evec)) % two_pi
        nu = math.atan2(float(what @ np.cross(evec, r)), float(evec @ r)) % two_pi
    else:
        argp = 0.0
        nu = math.atan2(float(what @ np.cross(node, r)), float(node @ r)) % two_pi
    return a, e, inc, raan, argp, nu


def _true_to_mean(nu: float, e: float) -> float:
    """Convert true anomaly ``nu`` to mean anomaly (rad) on an elliptic orbit (e < 1)."""
    ea = 2.0 * math.atan2(
        math.sqrt(1.0 - e) * math.sin(nu / 2), math.sqrt(1.0 + e) * math.cos(nu / 2)
    )
    return ea - e * math.sin(ea)


# --------------------------------------------------------------------------------------------
# SGP4 / SDP4
# --------------------------------------------------------------------------------------------
SGP4_EPOCH0_JD = 2433281.5
"""sgp4init epoch origin: 1949 December 31 00:00 UT as a Julian date."""


def _satrec(params: Array, epoch_days: float, bstar: float, gravity: int) -> Satrec:
    n_radmin, ex, ey, inc, raan, lam = (float(v) for v in params)
    e = math.hypot(ex, ey)
    argp = math.atan2(ey, ex)
    sat = Satrec()
    sat.sgp4init(gravity, "i", 1, epoch_days, bstar, 0.0, 0.0, e, wrap_2pi(argp), inc,
                 wrap_2pi(lam - argp), n_radmin, wrap_2pi(raan))
    return sat


def fit_sgp4_mean_elements(
    x0_osc_km: ArrayLike, jd0_utc: float, bstar: float = 0.0, gravity: int = WGS72
) -> Satrec:
    """Satrec whose SGP4/SDP4 TEME state at its epoch reproduces ``x0_osc_km`` (< 1 m).

    The osculating elements of ``x0_osc_km`` are only the starting guess; the mean elements
    (n, e cos w, e sin w, i, raan, w + M) are then fitted by ``scipy.optimize.least_squares``
    so that the SGP4 state at epoch matches (velocity weighted by 1000 s).
    """
    from scipy.optimize import least_squares

    x0 = np.asarray(x0_osc_km, float)
    epoch_days = jd0_utc - SGP4_EPOCH0_JD
    mu = 398600.8 if gravity == WGS72 else MU_EARTH
    a, e, inc, raan, argp, nu = state_to_elements(x0, mu)
    m = _true_to_mean(nu, e)
    p0 = np.array(
        [math.sqrt(mu / a**3) * 60.0, e * math.cos(argp), e * math.sin(argp), inc, raan, argp + m]
    )
    w = np.array([1.0, 1.0, 1.0, 1e3, 1e3, 1e3])

    def resid(p: Array) -> Array:
        sat = _satrec(p, epoch_days, bstar, gravity)
        err, r, v = sat.sgp4_tsince(0.0)
        if err != 0:
            return np.full(6, 1e6)
        res: Array = (np.concatenate([r, v]) - x0) * w
        return res

    sol = least_squares(resid, p0, x_scale=np.array([1e-3, 1e-3, 1e-3, 1e-2, 1e-2, 1e-2]),
                        xtol=1e-15, ftol=1e-15, gtol=1e-15, method="lm")
    return _satrec(sol.x, epoch_days, bstar, gravity)


def sgp4_ephemeris_teme(
    x0_osc_km: ArrayLike, jd0_utc: float, t_s: ArrayLike, bstar: float = 0.0
) -> Array:
    """SGP4/SDP4 ephemeris (len(t_s), 6) [km, km/s] in TEME, SGP4's own frame.

    Mean elements are fitted (:func:`fit_sgp4_mean_elements`, WGS-72 constants as in the
    standard SGP4) so the TEME state at ``jd0_utc`` equals ``x0_osc_km``; SDP4 is selected
    automatically for periods >= 225 min. ``t_s``: seconds since ``jd0_utc``.
    """
    sat = fit_sgp4_mean_elements(x0_osc_km, jd0_utc, bstar)
    t = np.atleast_1d(np.asarray(t_s, float))
    jd = np.full(t.shape, sat.jdsatepoch)
    fr = sat.jdsatepochF + t / 86400.0
    err, r, v = sat.sgp4_array(jd, fr)
    if np.any(err):
        raise RuntimeError(f"SGP4 error codes {set(err[err != 0].tolist())}")
    state: Array = np.concatenate([r, v], axis=1)
    return state


def sgp4_ephemeris(
    x0_gcrs_km: ArrayLike, t0_unix: float, t_s: ArrayLike, bstar: float = 0.0
) -> Array:
    """SGP4/SDP4 ephemeris (len(t_s), 6) [km, km/s] in the GCRF, from a GCRF state.

    ``x0_gcrs_km`` at Unix epoch ``t0_unix`` (UTC) is turned to TEME (`frames.gcrs_to_teme`),
    mean elements are fitted to it (`sgp4_ephemeris_teme`), and SGP4's TEME states at
    ``t0_unix + t_s`` are turned back to the GCRF (`frames.teme_to_gcrs`).
    """
    t = np.atleast_1d(np.asarray(t_s, float))
    x0_teme = frames.gcrs_to_teme(np.asarray(x0_gcrs_km, float), t0_unix)
    eph = sgp4_ephemeris_teme(x0_teme, UNIX_EPOCH_JD + t0_unix / 86400.0, t, bstar)
    return frames.teme_to_gcrs(eph, t0_unix + t)
