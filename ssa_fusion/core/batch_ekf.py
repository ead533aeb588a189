"""A bank of EKFs over N objects, vectorised over the object axis: `BatchEKF`.

One cycle of the per-object filter (`tracker.Tracker._step`: predict by the motion model,
``P = F P F^T + Q`` symmetrised, optional `ekf.bound_covariance`, then one range/azimuth/
elevation update from a ground station, Joseph form, azimuth and elevation residuals wrapped,
NIS gate) is done here for N objects at once with numpy, with no Python loop per object.
Every object has its own time step, station, measurement and noise; objects whose mask is
False in a batch are left exactly as they were.

State and frames: ``x`` (N, 6) ECI [r km, v km/s] (the project's ECI, `frames`), ``P``
(N, 6, 6) in km^2, km^2/s, km^2/s^2; measurements ``z`` (N, 3) [range km, azimuth rad in
[0, 2 pi), elevation rad] from the station ``stations[station[i]]`` at ``t`` s after the
configuration's ``jd0`` (UTC Julian date of t = 0; Unix time by default), noise ``R``
(N, 3, 3) or (3, 3) in km^2, rad^2.

Motion models (`BatchEKFConfig.motion_model`):

``"kepler"``
    Analytic two-body, as `kepler.propagate` (universal variable, Newton on Kepler's
    equation), with the same analytic state transition matrix (exact partials of the
    Lagrange coefficients, `kepler_stm`), evaluated elementwise over the object axis.
``"two_body"``, ``"j2"``, ``"drag"``
    The `dynamics` right-hand sides with their variational equations dPhi/dt = A(x) Phi
    (A by the complex step, as `dynamics.jacobian`), integrated for all objects at once
    with the 8th-order Dormand-Prince tableau (the one `dynamics.propagate_stm`'s DOP853
    uses) at a fixed step: each object takes ``ceil(|dt| / max_step_s)`` equal steps.
    The per-object filter integrates the same equations adaptively (DOP853, rtol 1e-10,
    atol 1e-9, `config.ORBIT_TOLERANCES`); with the default 60 s step the fixed-step
    result is the more accurate one and the two agree to ~5e-11 relative (LEO and Molniya,
    10 s to 1.5 h steps), so the batched and the per-object filter agree to 1e-9.

Not done here: light-time correction (`measurement` ``light_time``), ra/dec and position
measurements, and the per-message admission rules of `validation.measurement_problem`
beyond non-finite input, negative range and elevation outside [-pi/2, pi/2] (the node that
batches messages applies them to each message anyway).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any, NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from . import dynamics
from .constants import MU_EARTH
from .frames import ERA_RATE, Station, earth_rotation_angle, enu_matrix, site_ecef, wrap_angle
from .kepler import lagrange_partials
from .stations import UNIX_EPOCH_JD
from .tracker import DEFAULT_GATE
from .types import Cause

__all__ = [
    "REASONS",
    "BatchEKF",
    "BatchEKFConfig",
    "BatchUpdate",
    "Code",
    "Predicted",
    "integrate_stm",
    "kepler_state",
    "kepler_stm",
]

Array = NDArray[np.float64]
AnyArray = NDArray[Any]
"""An array of any dtype (per-object inputs as given)."""
BoolArray = NDArray[np.bool_]

_COMPLEX_STEP = 1e-30
"""Imaginary perturbation of the complex-step derivatives (as `dynamics.jacobian`)."""

_Z_SERIES = 0.5
"""|z| below which the Stumpff functions c2, c3 are evaluated by their power series."""

_MAX_NEWTON = 60

INTEGRATED_MODELS = ("two_body", "j2", "drag")
"""`dynamics` models integrated with their variational equations."""
MOTION_MODELS = ("kepler", *INTEGRATED_MODELS)
"""The motion models `BatchEKF` predicts with."""


class Code:
    """Per-object outcome codes of `BatchEKF.update` / `BatchEKF.step` (int8 values)."""

    FUSED = 0
    NOT_MEASURED = 1
    NONFINITE = 2
    NEGATIVE_RANGE = 3
    ELEVATION = 4
    NUMERIC = 5
    GATE = 6


REASONS: tuple[str, ...] = (
    "",
    "not_measured",
    Cause.REJECTED_NONFINITE,
    Cause.REJECTED_NEGATIVE_RANGE,
    Cause.REJECTED_ELEVATION,
    Cause.REJECTED_NUMERIC,
    Cause.REJECTED_GATE,
)
"""The reason of each `Code` (index = code): "" (fused), "not_measured" (masked out), or the
`types.Cause` key the per-object tracker uses for the same rejection."""


@dataclass(frozen=True)
class BatchEKFConfig:
    """Settings of a `BatchEKF` (shared by every object of the bank).

    Attributes
    ----------
    motion_model : str
        "kepler" (analytic), or an integrated `dynamics` model "two_body", "j2", "drag".
    motion_params : tuple of (str, float)
        Parameters of the motion model (`dynamics` names: ``mu`` km^3/s^2, ``j2``, ``re`` km,
        ``bc`` kg/m^2, ...); for "kepler" only ``mu`` (default `constants.MU_EARTH`).
    q : float
        White-noise acceleration spectral density of the process noise, km^2/s^3
        (`ekf.process_noise`).
    gate : float or None
        NIS threshold beyond which an update is rejected (None: no gate).
    sigma_bound : float
        After each prediction, position/velocity standard deviations are limited to
        ``sigma_bound`` times the position/velocity norm (`ekf.bound_covariance`); 0: none.
    jd0 : float
        UTC Julian date of t = 0 of the measurement clock (Unix time by default).
    max_step_s : float
        Longest fixed integration step of the integrated models, s (unused for "kepler").
    """

    motion_model: str = "kepler"
    motion_params: tuple[tuple[str, float], ...] = ()
    q: float = 1e-10
    gate: float | None = DEFAULT_GATE
    sigma_bound: float = 0.0
    jd0: float = UNIX_EPOCH_JD
    max_step_s: float = 60.0

    def __post_init__(self) -> None:
        """Check the motion model and the step (ValueError naming the field)."""
        if self.motion_model not in MOTION_MODELS:
            raise ValueError(f"motion_model {self.motion_model!r} unknown; known: "
                             f"{', '.join(MOTION_MODELS)}")
        if not (self.max_step_s > 0.0 and math.isfinite(self.max_step_s)):
            raise ValueError(f"max_step_s must be > 0 and finite, got {self.max_step_s}")

    @property
    def params(self) -> dict[str, float]:
        """`motion_params` as a dict."""
        return dict(self.motion_params)


class Predicted(NamedTuple):
    """Outcome of `BatchEKF.predict`.

    Attributes
    ----------
    x : ndarray (N, 6)
        Predicted states, km, km/s (unchanged where ``ok`` is False).
    P : ndarray (N, 6, 6)
        Predicted covariances (unchanged where ``ok`` is False).
    ok : ndarray (N,) of bool
        False where the prediction was not computable (non-finite input or result).
    """

    x: Array
    P: Array
    ok: BoolArray


class BatchUpdate(NamedTuple):
    """Outcome of `BatchEKF.update` and `BatchEKF.step`.

    Attributes
    ----------
    x : ndarray (N, 6)
        Posterior states (the input state where the object was not fused).
    P : ndarray (N, 6, 6)
        Posterior covariances (the input covariance where not fused).
    code : ndarray (N,) of int8
        `Code` per object; ``REASONS[code]`` is its reason.
    nis : ndarray (N,)
        Normalized innovation squared ``y^T S^-1 y`` (NaN where not computed).
    y : ndarray (N, 3)
        Innovations [km, rad, rad], angles wrapped to (-pi, pi] (NaN where not computed).
    """

    x: Array
    P: Array
    code: NDArray[np.int8]
    nis: Array
    y: Array

    @property
    def fused(self) -> BoolArray:
        """True for the objects whose measurement was fused."""
        out: BoolArray = self.code == Code.FUSED
        return out

    def reason(self, i: int) -> str:
        """Reason of object ``i`` ("" when fused)."""
        return REASONS[int(self.code[i])]


# --------------------------------------------------------------------------------------------
# Motion models
# --------------------------------------------------------------------------------------------
def _stumpff(z: Array, full: bool = False) -> tuple[Array, ...]:
    """Stumpff c2(z), c3(z) (and c4, c5 when ``full``) elementwise, as `kepler.stumpff`.

    Closed forms (trigonometric for z > 0.5, hyperbolic for z < -0.5), power series near 0
    (``c_k = sum_j (-z)^j / (k + 2j)!``, 8 terms: truncation < 0.5^8 / 20! ~ 2e-21).
    """
    big = np.abs(z) > _Z_SERIES
    anybig = bool(big.any())
    zm = np.where(big, 0.0, z) if anybig else z
    c4 = (1.0 / 24.0) * (1.0 - zm / 30.0 * (1.0 - zm / 56.0 * (1.0 - zm / 90.0 * (
        1.0 - zm / 132.0 * (1.0 - zm / 182.0 * (1.0 - zm / 240.0 * (1.0 - zm / 306.0)))))))
    c5 = (1.0 / 120.0) * (1.0 - zm / 42.0 * (1.0 - zm / 72.0 * (1.0 - zm / 110.0 * (
        1.0 - zm / 156.0 * (1.0 - zm / 210.0 * (1.0 - zm / 272.0 * (1.0 - zm / 342.0)))))))
    c2 = 0.5 - zm * c4
    c3 = 1.0 / 6.0 - zm * c5
    if anybig:
        for sel in (z > _Z_SERIES, z < -_Z_SERIES):
            if not sel.any():
                continue
            zs = z[sel]
            s = np.sqrt(np.abs(zs))
            if zs[0] > 0.0:
                h = np.sin(0.5 * s)
                a2, a3 = 2.0 * h * h / zs, (s - np.sin(s)) / (zs * s)
            else:
                a2, a3 = (np.cosh(s) - 1.0) / (-zs), (np.sinh(s) - s) / (-zs * s)
            c2[sel], c3[sel] = a2, a3
            if full:
                c4[sel], c5[sel] = (0.5 - a2) / zs, (1.0 / 6.0 - a3) / zs
    return (c2, c3, c4, c5) if full else (c2, c3)


def _kepler_terms(r0: Array, sig0: Array, alpha: Array,
                  chi: Array) -> tuple[Array, Array, Array, Array]:
    """Universal functions U1, U2, U3 at chi and the radius r (same shape as the inputs)."""
    chi2 = chi * chi
    c2, c3 = _stumpff(alpha * chi2)
    u2 = chi2 * c2
    u3 = chi2 * chi * c3
    u1 = chi - alpha * u3
    r = r0 * (1.0 - alpha * u2) + sig0 * u1 + u2
    return u1, u2, u3, r


def _solve_chi(r0: Array, sig0: Array, alpha: Array, tau: Array) -> tuple[Array, BoolArray]:
    """Solve ``r0 U1 + sig0 U2 + U3 = tau`` for chi, vectorised; return (chi, converged).

    Newton's method from a Taylor series (short steps) or the mean-anomaly guess (ellipses),
    safeguarded for ellipses by the bracket that follows from |dE - dM| <= 2 e.
    """
    bound = alpha > 1e-12 / r0
    sa = np.sqrt(np.where(bound, alpha, 1.0))
    ecc = np.hypot(1.0 - r0 * alpha, sig0 * sa)
    dm = tau * alpha * sa
    lo = np.where(bound, (dm - 2.0 * ecc - 1e-9) / sa, -np.inf)
    hi = np.where(bound, (dm + 2.0 * ecc + 1e-9) / sa, np.inf)
    ir0 = 1.0 / r0
    t = tau * ir0
    taylor = t * (1.0 - t * ir0 * (0.5 * sig0 - t * (0.5 * sig0 * sig0 * ir0
                                                      - (1.0 - alpha * r0) / 6.0)))
    short = np.abs(tau) < 0.2 * r0 * np.sqrt(r0)
    chi = np.where(short, taylor, np.where(bound, tau * alpha, t))
    done = (tau == 0.0) | ~np.isfinite(chi)
    chi[tau == 0.0] = 0.0
    for _ in range(_MAX_NEWTON):
        u1, u2, u3, r = _kepler_terms(r0, sig0, alpha, chi)
        err = r0 * u1 + sig0 * u2 + u3 - tau
        step = err / r
        # Newton's error after this step is ~ step^2 sigma / (2 r), sigma = dr/dchi
        sig = sig0 * (1.0 - alpha * u2) + (1.0 - alpha * r0) * u1
        conv = (step * step * np.abs(sig) <= 2e-16 * r * np.abs(chi)) | (err == 0.0)
        hi = np.where(err > 0.0, np.minimum(hi, chi), hi)
        lo = np.where(err < 0.0, np.maximum(lo, chi), lo)
        new = chi - step
        outside = ~((lo < new) & (new < hi))
        mid = 0.5 * (lo + hi)
        new = np.where(outside & np.isfinite(mid), mid, new)
        chi = np.where(done, chi, new)
        done = done | conv | ~np.isfinite(chi)
        if done.all():
            break
    return chi, done & np.isfinite(chi)


class _Orbit(NamedTuple):
    """N initial states split for the universal-variable solution, with chi solved."""

    r: Array  # (N, 3) km
    v: Array  # (N, 3) km/s
    r0: Array  # |r| km
    sig0: Array  # r.v / sqrt(mu)
    alpha: Array  # 1 / a, 1/km
    tau: Array  # sqrt(mu) dt
    chi: Array  # universal anomaly at t0 + dt
    ok: BoolArray


def _kepler_solve(x: ArrayLike, dt: ArrayLike, mu: float) -> _Orbit:
    """Split N states (N, 6) and solve Kepler's equation for their own dt (s)."""
    X = np.atleast_2d(np.asarray(x, dtype=float))
    dts = np.broadcast_to(np.asarray(dt, dtype=float), (X.shape[0],))
    smu = math.sqrt(mu)
    r, v = X[:, :3], X[:, 3:]
    r0 = np.sqrt(np.einsum("ij,ij->i", r, r))
    sig0 = np.einsum("ij,ij->i", r, v) / smu
    alpha = 2.0 / r0 - np.einsum("ij,ij->i", v, v) / mu
    chi, ok = _solve_chi(r0, sig0, alpha, smu * dts)
    return _Orbit(r, v, r0, sig0, alpha, smu * dts, chi, ok & (r0 > 0.0))


def _lagrange(r0: Array, sig0: Array, alpha: Array, chi: Array, smu: float) -> Array:
    """Lagrange coefficients (..., 4) [F, G, Fdot, Gdot] at chi."""
    u1, u2, _, rr = _kepler_terms(r0, sig0, alpha, chi)
    out: Array = np.stack([1.0 - u2 / r0, (r0 * u1 + sig0 * u2) / smu,
                              -smu * u1 / (rr * r0), 1.0 - u2 / rr], -1)
    return out


def _apply(fg: Array, r: Array, v: Array) -> Array:
    """States [F r + G v, Fdot r + Gdot v] (N, 6) from the coefficients fg (N, 4)."""
    return np.concatenate([fg[:, :1] * r + fg[:, 1:2] * v, fg[:, 2:3] * r + fg[:, 3:] * v], 1)


def kepler_stm(x: ArrayLike, dt: ArrayLike,
               mu: float = MU_EARTH) -> tuple[Array, Array, BoolArray]:
    """Propagate N two-body states by their own ``dt`` with their state transition matrices.

    The vectorised counterpart of `kepler.propagate`, with the same analytic STM: the
    Lagrange coefficients ``F, G, Fdot, Gdot`` (``x1 = [F r0 + G v0, Fdot r0 + Gdot v0]``)
    depend on the initial state only through p = (r0 km, sigma0 km^0.5, alpha 1/km); their
    exact partials (``dU_k/dalpha = (k U_{k+2} - chi U_{k+1}) / 2`` at fixed chi, and the
    implicit derivative of chi from Kepler's equation) give
    ``Phi = [[F I, G I], [Fdot I, Gdot I]] + W M W^T``, ``W = [[r0, v0, 0, 0], [0, 0, r0, v0]]``
    with a 4x4 matrix ``M`` per object. Every step is elementwise over the object axis.

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
    smu = math.sqrt(mu)
    with np.errstate(all="ignore"):
        o = _kepler_solve(x, dt, mu)
        r, v, r0, sig0, alpha, chi = o.r, o.v, o.r0, o.sig0, o.alpha, o.chi
        n = r.shape[0]
        c2, c3, c4, c5 = _stumpff(alpha * chi * chi, full=True)
        (f, g, fd, gd), ca, cb, cd = lagrange_partials(r0, sig0, alpha, chi,
                                                       (c2, c3, c4, c5), smu, mu)
        fs, a, b, dd = np.stack([f, g, fd, gd]), np.stack(ca), np.stack(cb), np.stack(cd)
        # structure of arrays (object axis last): long contiguous loops, no small inner axes
        rT, vT = np.ascontiguousarray(r.T), np.ascontiguousarray(v.T)  # (3, N)
        grad = np.empty((4, 6, n))  # rows d(coef i)/dx0
        grad[:, :3] = a[:, None, :] * rT + b[:, None, :] * vT
        grad[:, 3:] = b[:, None, :] * rT + dd[:, None, :] * vT
        phi = np.empty((6, 6, n))
        phi[:3] = rT[:, None, :] * grad[0] + vT[:, None, :] * grad[1]
        phi[3:] = rT[:, None, :] * grad[2] + vT[:, None, :] * grad[3]
        for i, (i0, j0) in enumerate(((0, 0), (0, 3), (3, 0), (3, 3))):
            for d in range(3):
                phi[i0 + d, j0 + d] += fs[i]
        ok = o.ok & np.isfinite(phi).all(axis=(0, 1))
        phi = np.ascontiguousarray(phi.transpose(2, 0, 1))
        x1 = np.empty((n, 6))
        x1[:, :3] = f[:, None] * r + g[:, None] * v
        x1[:, 3:] = fd[:, None] * r + gd[:, None] * v
        ok &= np.isfinite(x1).all(axis=1)
    return x1, phi, ok


def kepler_state(x: ArrayLike, dt: ArrayLike, mu: float = MU_EARTH) -> tuple[Array, BoolArray]:
    """Propagate N two-body states by their own ``dt`` (s), without the STM.

    As `kepler_stm` (same solution, about a third of its cost): returns (x1 (N, 6), ok (N,)).
    """
    with np.errstate(all="ignore"):
        o = _kepler_solve(x, dt, mu)
        x1 = _apply(_lagrange(o.r0, o.sig0, o.alpha, o.chi, math.sqrt(mu)), o.r, o.v)
        ok = o.ok & np.isfinite(x1).all(axis=1)
    return x1, ok


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


def _dop853() -> tuple[Array, Array, int]:
    """Return the Dormand-Prince 8(5,3) tableau of scipy's DOP853: (A, B, stages)."""
    from scipy.integrate._ivp import dop853_coefficients as dop

    return np.asarray(dop.A, float), np.asarray(dop.B, float), int(dop.N_STAGES)


def integrate_stm(model: str, x: ArrayLike, dt: ArrayLike, max_step_s: float = 60.0,
                  **params: float) -> tuple[Array, Array, BoolArray]:
    """Integrate N states of a `dynamics` model with their STMs, fixed-step DOP853.

    Object i takes ``ceil(|dt_i| / max_step_s)`` equal steps of the 8th-order Dormand-Prince
    method; all objects still stepping are advanced together (one right-hand-side call per
    stage for all of them).

    Parameters
    ----------
    model : str
        A 6-state `dynamics` model ("two_body", "j2", "drag").
    x : array_like (N, 6)
        Initial states, ECI km, km/s.
    dt : array_like (N,) or scalar
        Time steps, s (any sign).
    max_step_s : float
        Longest step, s.
    **params : float
        Model parameters (`dynamics` module docstring).

    Returns
    -------
    (x1 (N, 6), Phi (N, 6, 6), ok (N,)): ``ok`` False where input or result is not finite.
    """
    if model not in INTEGRATED_MODELS:
        raise ValueError(f"model {model!r} is not one of {', '.join(INTEGRATED_MODELS)}")
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


# --------------------------------------------------------------------------------------------
# The filter bank
# --------------------------------------------------------------------------------------------
def _process_noise_basis() -> Array:
    """(3, 6, 6) matrices B_k with ``process_noise(dt, q) = q sum_k dt^(3-k) B_k``."""
    out = np.zeros((3, 6, 6))
    i3 = np.eye(3)
    out[0, :3, :3] = i3 / 3.0
    out[1, :3, 3:] = out[1, 3:, :3] = i3 / 2.0
    out[2, 3:, 3:] = i3
    return out


def _inv3_sym_soa(S: Array) -> tuple[Array, BoolArray]:
    """Inverses of symmetric 3x3 matrices stored object axis last (3, 3, m), by cofactors.

    Returns (inverses (3, 3, m), ok (m,)); ok is False where det <= 0 or not finite.
    """
    a, b, c = S[0, 0], S[0, 1], S[0, 2]
    d, e, f = S[1, 1], S[1, 2], S[2, 2]
    c11 = d * f - e * e
    c12 = c * e - b * f
    c13 = b * e - c * d
    det = a * c11 + b * c12 + c * c13
    ok = np.isfinite(det) & (det > 0.0)
    i = 1.0 / np.where(ok, det, 1.0)
    inv = np.empty_like(S)
    inv[0, 0], inv[1, 1], inv[2, 2] = c11 * i, (a * f - c * c) * i, (a * d - b * b) * i
    inv[0, 1] = inv[1, 0] = c12 * i
    inv[0, 2] = inv[2, 0] = c13 * i
    inv[1, 2] = inv[2, 1] = (b * c - a * e) * i
    return inv, ok


def _sym(P: Array) -> Array:
    out: Array = 0.5 * (P + np.swapaxes(P, -1, -2))
    return out


class BatchEKF:
    """EKFs of N objects, one cycle for all at once (see the module docstring).

    The bank's arrays (``x`` (N, 6), ``P`` (N, 6, 6), and the epochs) belong to the caller;
    every method takes them and returns new arrays (or writes into them with
    ``inplace=True``).

    Parameters
    ----------
    config : BatchEKFConfig
        Motion model, process noise, gate, covariance bound, clock epoch.
    stations : sequence of frames.Station
        The stations measurements come from; a measurement names its station by index
        (`index` maps station names to indices).
    """

    def __init__(self, config: BatchEKFConfig, stations: Sequence[Station]) -> None:
        self.config = config
        self.stations = tuple(stations)
        self.index = {s.name: i for i, s in enumerate(self.stations)}
        self._era0 = float(earth_rotation_angle(config.jd0))
        self._enu = np.array([enu_matrix(s.lat_rad, s.lon_rad) for s in self.stations])
        self._site = np.array([m @ site_ecef(s.lat_rad, s.lon_rad, s.alt_km)
                               for m, s in zip(self._enu, self.stations, strict=True)])
        self._enu_soa = np.ascontiguousarray(self._enu.transpose(1, 2, 0))  # (3, 3, stations)
        self._site_soa = np.ascontiguousarray(self._site.T)  # (3, stations) km
        self._qbasis = config.q * _process_noise_basis().reshape(3, 36)
        self._params = config.params

    # ----------------------------------------------------------------------------------
    def propagate(self, x: ArrayLike, dt: ArrayLike) -> tuple[Array, Array, BoolArray]:
        """Motion model for N states: (x1 (N, 6), Phi (N, 6, 6), ok (N,)); dt in s."""
        if self.config.motion_model == "kepler":
            return kepler_stm(x, dt, self._params.get("mu", MU_EARTH))
        return integrate_stm(self.config.motion_model, x, dt, self.config.max_step_s,
                             **self._params)

    def _predict(self, x: Array, P: Array, dt: Array) -> tuple[Array, Array, BoolArray]:
        """x, P predicted by dt (dt == 0: unchanged, as the per-object filter skips it)."""
        move = dt != 0.0
        x1, F, ok = self.propagate(x, dt)
        adt = np.abs(dt)
        Q = (np.stack([adt**3, adt**2, adt], -1) @ self._qbasis).reshape(-1, 6, 6)
        P1 = _sym(np.matmul(np.matmul(F, P), np.swapaxes(F, 1, 2)) + Q)
        if self.config.sigma_bound:
            P1 = self._bound(x1, P1)
        ok &= np.isfinite(P1).all(axis=(1, 2))
        if not move.all():
            x1[~move] = x[~move]
            P1[~move] = P[~move]
            ok |= ~move
        return x1, P1, ok

    def _bound(self, x: Array, P: Array) -> Array:
        """`ekf.bound_covariance` for N objects."""
        factor = self.config.sigma_bound
        cap = np.repeat(factor * np.stack([np.linalg.norm(x[:, :3], axis=1),
                                           np.linalg.norm(x[:, 3:], axis=1)], -1), 3, axis=1)
        sig = np.sqrt(np.clip(np.diagonal(P, axis1=1, axis2=2), 0.0, None))
        over = (sig > cap) & (cap > 0.0)
        s = np.where(over, cap / np.where(over, sig, 1.0), 1.0)
        out: Array = P * s[:, :, None] * s[:, None, :]
        return out

    def predict(self, x: ArrayLike, P: ArrayLike, dt: ArrayLike) -> Predicted:
        """Predict N objects by their own ``dt`` (s): ``x <- f(x)``, ``P <- F P F^T + Q``.

        Then ``P`` is symmetrised and bounded (``sigma_bound``); ``dt == 0`` leaves an object
        unchanged. Objects whose prediction is not computable keep their input (``ok``).
        """
        X = np.asarray(x, dtype=float)
        PP = np.asarray(P, dtype=float)
        dts = np.broadcast_to(np.asarray(dt, dtype=float), (X.shape[0],))
        with np.errstate(all="ignore"):
            x1, P1, ok = self._predict(X, PP, dts)
        return Predicted(np.where(ok[:, None], x1, X), np.where(ok[:, None, None], P1, PP), ok)

    def measure(self, x: Array, t: Array, station: NDArray[np.intp]) -> tuple[Array, Array]:
        """Predicted [range km, az rad in [0, 2 pi), el rad] (m, 3) and Jacobian (m, 3, 6).

        ``x`` (m, 6) ECI states, ``t`` (m,) s after jd0, ``station`` (m,) station indices;
        the batched `measurement.RazelModel.h_and_H` (no light time).
        """
        th = self._era0 + ERA_RATE * t
        c, s = np.cos(th)[:, None], np.sin(th)[:, None]
        M = self._enu[station]
        T = np.empty_like(M)  # ECI -> ENU: M R3(th)
        T[:, :, 0] = M[:, :, 0] * c - M[:, :, 1] * s
        T[:, :, 1] = M[:, :, 0] * s + M[:, :, 1] * c
        T[:, :, 2] = M[:, :, 2]
        enu = np.einsum("mij,mj->mi", T, x[:, :3]) - self._site[station]
        e, n, u = enu[:, 0], enu[:, 1], enu[:, 2]
        h2 = e * e + n * n
        h = np.sqrt(h2)
        r2 = h2 + u * u
        r = np.sqrt(r2)
        zp = np.stack([r, np.mod(np.arctan2(e, n), 2.0 * math.pi), np.arctan2(u, h)], -1)
        k = -u / (h * r2)
        zero = np.zeros_like(e)
        D = np.stack([np.stack([e / r, n / r, u / r], -1),
                      np.stack([n / h2, -e / h2, zero], -1),
                      np.stack([k * e, k * n, h / r2], -1)], -2)
        H = np.zeros((x.shape[0], 3, 6))
        H[:, :, :3] = np.matmul(D, T)
        return zp, H

    def _update(self, x: Array, P: Array, z: Array, R: Array, t: Array,
                station: NDArray[np.intp]) -> tuple[Array, Array, Array, Array, BoolArray]:
        """Joseph-form update of m objects: (x, P, nis, y, computable).

        Elementwise over the object axis in a structure-of-arrays layout (object axis last),
        using the zero velocity columns of H. The Joseph form ``A P A^T + K R K^T``
        (``A = I - K H``) is evaluated expanded, ``P + (K S - 2 P H^T) K^T`` symmetrised
        (S = H P H^T + R): algebraically the same, and like it insensitive to first order
        to an error in the gain K (the first-order term is antisymmetric).
        """
        m = x.shape[0]
        th = self._era0 + ERA_RATE * t
        c, s = np.cos(th), np.sin(th)
        M = self._enu_soa[:, :, station]  # (3, 3, m)
        T = np.empty_like(M)  # ECI -> ENU: M R3(th)
        T[:, 0] = M[:, 0] * c - M[:, 1] * s
        T[:, 1] = M[:, 0] * s + M[:, 1] * c
        T[:, 2] = M[:, 2]
        xt = x.T
        enu = T[:, 0] * xt[0] + T[:, 1] * xt[1] + T[:, 2] * xt[2] - self._site_soa[:, station]
        e, n, u = enu
        h2 = e * e + n * n
        h = np.sqrt(h2)
        r2 = h2 + u * u
        rg = np.sqrt(r2)
        y = np.empty((3, m))
        y[0] = z[:, 0] - rg
        y[1] = wrap_angle(z[:, 1] - np.mod(np.arctan2(e, n), 2.0 * math.pi))
        y[2] = wrap_angle(z[:, 2] - np.arctan2(u, h))
        k = -u / (h * r2)
        D = np.empty((3, 3, m))  # d(range, az, el)/d(e, n, u)
        D[0, 0], D[0, 1], D[0, 2] = e / rg, n / rg, u / rg
        D[1, 0], D[1, 1], D[1, 2] = n / h2, -e / h2, 0.0
        D[2, 0], D[2, 1], D[2, 2] = k * e, k * n, h / r2
        Hr = D[:, 0, None] * T[0] + D[:, 1, None] * T[1] + D[:, 2, None] * T[2]  # (3, 3, m)
        Pt = np.ascontiguousarray(P.transpose(1, 2, 0))  # (6, 6, m)
        PHt = Pt[:, 0, None] * Hr[:, 0] + Pt[:, 1, None] * Hr[:, 1] + Pt[:, 2, None] * Hr[:, 2]
        S = (Hr[:, 0, None] * PHt[0] + Hr[:, 1, None] * PHt[1] + Hr[:, 2, None] * PHt[2]
             + R.transpose(1, 2, 0))
        Si, ok = _inv3_sym_soa(S)
        Siy = Si[:, 0] * y[0] + Si[:, 1] * y[1] + Si[:, 2] * y[2]
        nis = y[0] * Siy[0] + y[1] * Siy[1] + y[2] * Siy[2]
        K = PHt[:, 0, None] * Si[0] + PHt[:, 1, None] * Si[1] + PHt[:, 2, None] * Si[2]
        x1 = x + (K[:, 0] * y[0] + K[:, 1] * y[1] + K[:, 2] * y[2]).T
        E = K[:, 0, None] * S[0] + K[:, 1, None] * S[1] + K[:, 2, None] * S[2] - 2.0 * PHt
        P1 = Pt + E[:, 0, None] * K[:, 0] + E[:, 1, None] * K[:, 1] + E[:, 2, None] * K[:, 2]
        P1 += P1.transpose(1, 0, 2)
        P1 *= 0.5
        ok &= np.isfinite(nis) & np.isfinite(x1).all(axis=1) & np.isfinite(P1).all(axis=(0, 1))
        return x1, np.ascontiguousarray(P1.transpose(2, 0, 1)), nis, y.T, ok

    def update(self, x: ArrayLike, P: ArrayLike, z: ArrayLike, R: ArrayLike, t: ArrayLike,
               station: ArrayLike, mask: ArrayLike | None = None,
               inplace: bool = False) -> BatchUpdate:
        """Fuse one range/az/el measurement per object (no prediction; see `step`)."""
        return self.step(x, P, 0.0, z, R, t, station, mask, inplace)

    def step(self, x: ArrayLike, P: ArrayLike, dt: ArrayLike, z: ArrayLike, R: ArrayLike,
             t: ArrayLike, station: ArrayLike, mask: ArrayLike | None = None,
             inplace: bool = False) -> BatchUpdate:
        """One EKF cycle per object: predict by ``dt``, then fuse the measurement ``z``.

        Parameters
        ----------
        x : array_like (N, 6)
            States at the objects' epochs, ECI km, km/s.
        P : array_like (N, 6, 6)
            Their covariances.
        dt : array_like (N,) or scalar
            Measurement epoch minus the object's epoch, s (0: no prediction).
        z : array_like (N, 3)
            Measurements [range km, azimuth rad, elevation rad].
        R : array_like (N, 3, 3) or (3, 3)
            Measurement noise covariances, km^2 and rad^2.
        t : array_like (N,) or scalar
            Measurement epochs, s after ``config.jd0``.
        station : array_like (N,) or scalar of int
            Station index per measurement (``stations[station[i]]``).
        mask : array_like (N,) of bool, optional
            Objects measured in this batch (default: all); the others are left unchanged.
        inplace : bool
            Write the posterior into ``x`` and ``P`` (which must then be float64 arrays)
            instead of copies.

        Returns
        -------
        BatchUpdate
            Posteriors and per-object codes. As in the per-object tracker, an object whose
            measurement is rejected (non-finite input, negative range, elevation outside
            [-pi/2, pi/2], not computable, beyond the gate) keeps its state and epoch: its
            prediction is dropped too.
        """
        X = x if inplace and isinstance(x, np.ndarray) else np.asarray(x, dtype=float)
        PP = P if inplace and isinstance(P, np.ndarray) else np.asarray(P, dtype=float)
        n = X.shape[0]
        if mask is not None:
            mk = np.asarray(mask)
            if mk.dtype != np.bool_ or mk.shape != (n,):
                raise ValueError(f"mask must be a boolean array of shape ({n},), got "
                                 f"{mk.dtype} {mk.shape}")
        idx = np.arange(n) if mask is None else np.flatnonzero(np.asarray(mask, dtype=bool))
        code = np.full(n, Code.NOT_MEASURED, dtype=np.int8)
        nis = np.full(n, np.nan)
        yy = np.full((n, 3), np.nan)
        if idx.size == 0:
            return BatchUpdate(X if inplace else X.copy(), PP if inplace else PP.copy(),
                               code, nis, yy)
        every = idx.size == n

        def pick(a: AnyArray, ndim: int) -> AnyArray:
            """Rows idx of a per-object array (N, ...), or a broadcast one."""
            if a.ndim == ndim + 1 and a.shape[0] == n:
                return a if every else a[idx]
            return np.broadcast_to(a, (idx.size, *a.shape[a.ndim - ndim:]))

        zz = pick(np.asarray(z, dtype=float), 1)
        RR = pick(np.asarray(R, dtype=float), 2)
        tt = pick(np.asarray(t, dtype=float), 0)
        dts = pick(np.asarray(dt, dtype=float), 0)
        st = pick(np.asarray(station, dtype=np.intp), 0)
        xs, Ps = pick(X, 1), pick(PP, 2)
        with np.errstate(all="ignore"):
            finite = (np.isfinite(zz).all(axis=1) & np.isfinite(RR).all(axis=(1, 2))
                      & np.isfinite(tt) & np.isfinite(dts) & np.isfinite(xs).all(axis=1)
                      & np.isfinite(Ps).all(axis=(1, 2)) & (st >= 0) & (st < len(self.stations)))
            c = np.where(finite, Code.FUSED, Code.NONFINITE).astype(np.int8)
            c[finite & (zz[:, 0] < 0.0)] = Code.NEGATIVE_RANGE
            c[finite & ~(np.abs(zz[:, 2]) <= 0.5 * math.pi)] = Code.ELEVATION
            valid = c == Code.FUSED
            allv = bool(valid.all())
            go = np.flatnonzero(valid)

            def sub(a: AnyArray) -> AnyArray:
                return a if allv else a[go]

            xp, Pp, ok = self._predict(sub(xs), sub(Ps), sub(dts))
            x1, P1, g_nis, g_y, ok2 = self._update(xp, Pp, sub(zz), sub(RR), sub(tt), sub(st))
            ok &= ok2
            cg = np.where(ok, Code.FUSED, Code.NUMERIC).astype(np.int8)
            if self.config.gate is not None:
                cg[ok & (g_nis > self.config.gate)] = Code.GATE
            c[go] = cg
            where = idx[go]
            nis[where] = np.where(ok, g_nis, np.nan)
            yy[where] = g_y
        code[idx] = c
        take = cg == Code.FUSED
        if every and allv and bool(take.all()) and not inplace:
            X, PP = x1, P1
        else:
            if not inplace:
                X, PP = X.copy(), PP.copy()
            X[where[take]] = x1[take]
            PP[where[take]] = P1[take]
        return BatchUpdate(X, PP, code, nis, yy)
