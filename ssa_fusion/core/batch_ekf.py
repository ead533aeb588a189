"""A bank of EKFs over N objects, one compiled loop over the objects: `BatchEKF`.

One cycle of the per-object filter (`tracker.Tracker._step`: predict by the motion model,
``P = F P F^T + Q`` symmetrised, optional `ekf.bound_covariance`, then one range/azimuth/
elevation update from a ground station, Joseph form, azimuth and elevation residuals wrapped,
NIS gate) is done here for N objects in one call, with no Python loop per object.
Every object has its own time step, station, measurement and noise; objects whose mask is
False in a batch are left exactly as they were.

Compiled with numba: the admission checks, the Kepler propagation with its STM, the
two-body and J2 integration with its STM, the covariance prediction and the update are
loops over the objects compiled by `numba.njit` (no fastmath: IEEE arithmetic in the
order written; the results equal the former numpy formulation to ~1e-15 relative, ~2e-12
over multi-day arcs where Kepler's equation is that ill-conditioned, and the per-object
filter to 1e-9). The numba kernels are compiled at their first call in a process (4 to
6 s here; the two-body/J2 integration kernel ~1 s more) unless numba's on-disk cache holds
them (``__pycache__`` next to this file, else ``NUMBA_CACHE_DIR`` or ``~/.cache/numba``;
about 0.2 s to load), see `_jit`. The "drag" model's integration stays numpy, vectorised
over the objects.

State and frames: ``x`` (N, 6) GCRF [r km, v km/s] (`frames`), ``P`` (N, 6, 6) in km^2,
km^2/s, km^2/s^2; measurements ``z`` (N, 3) [range km, azimuth rad in [0, 2 pi), elevation
rad] from the station ``stations[station[i]]`` (ITRF) at ``t`` s after the configuration's
``jd0`` (UTC Julian date of t = 0; Unix time by default), noise ``R`` (N, 3, 3) or (3, 3)
in km^2, rad^2. The GCRF -> ITRF rotation is computed once per distinct measurement epoch
(`frames.gcrs_to_itrs_matrix`, vectorised) and handed to the compiled update; J2 acts about
the Earth's pole at each object's start epoch (`frames.pole_frame`).

Motion models (`BatchEKFConfig.motion_model`):

``"kepler"``
    Analytic two-body, as `kepler.propagate` (universal variable, Newton on Kepler's
    equation), with the same analytic state transition matrix (exact partials of the
    Lagrange coefficients, `kepler_stm`; `kepler.lagrange_partials` itself, compiled).
``"two_body"``, ``"j2"``, ``"drag"``
    The `dynamics` right-hand sides with their variational equations dPhi/dt = A(x) Phi,
    integrated with the 8th-order Dormand-Prince tableau (the one `dynamics.propagate_stm`'s
    DOP853 uses) at a fixed step: each object takes ``ceil(|dt| / max_step_s)`` equal steps.
    "two_body" and "j2": a compiled loop over the objects with the analytic Jacobian
    (`_gravity_stm_kernel`); "drag": numpy, all objects at once, A by the complex step (as
    `dynamics.jacobian`; `_integrate_stm_numpy`). The two paths agree to ~1e-15 relative
    per step (~1e-12 over a day of steps).
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

import functools
import hashlib
import inspect
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any, NamedTuple, TypeVar, cast

import numba
import numpy as np
from numpy.typing import ArrayLike, NDArray

from . import dynamics, frames, kepler
from .constants import MU_EARTH
from .eop import default as eop_default
from .frames import Station, enu_matrix
from .timescales import DAY_S, UNIX_EPOCH_JD, install_leap_seconds
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
_Z_AXIS = np.array([0.0, 0.0, 1.0])
"""The pole of an integration without one (the states' own z axis)."""
_TWO_PI = 2.0 * math.pi

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


_FUSED, _NONFINITE, _NEGATIVE_RANGE, _ELEVATION = (Code.FUSED, Code.NONFINITE,
                                                  Code.NEGATIVE_RANGE, Code.ELEVATION)

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
# Compiled kernels (numba)
# --------------------------------------------------------------------------------------------
_Fn = TypeVar("_Fn", bound=Callable[..., Any])


_KEPLER_PARTIALS_SHA256 = "1f232bc5f2f87ac7"
"""First 16 hex digits of the SHA-256 of the source of `kepler.lagrange_partials` that the
cached kernels were written against (see `_cacheable`; test_batch_ekf checks it)."""


def _lagrange_partials_digest() -> str:
    """First 16 hex digits of the SHA-256 of the source of `kepler.lagrange_partials`."""
    src = inspect.getsource(kepler.lagrange_partials)
    return hashlib.sha256(src.encode()).hexdigest()[:16]


def _cacheable() -> bool:
    """Whether the compiled kernels may be cached on disk.

    numba checks a cached kernel against its own source file only (this one), not against
    the functions it calls from other files: `kepler.lagrange_partials` is compiled into
    `_kepler_kernel`, and a cached kernel would keep an older version of it. So the cache is
    used only while that function's source is the one `_KEPLER_PARTIALS_SHA256` names; after
    an edit of it the kernels are compiled in every process (correct, a few seconds slower)
    until the digest here is updated, which, by changing this file, invalidates every
    cached kernel.
    """
    try:
        return _lagrange_partials_digest() == _KEPLER_PARTIALS_SHA256
    except (OSError, TypeError):  # no source (a frozen install): compile every time
        return False


_CACHE = _cacheable()


def _jit(fn: _Fn) -> _Fn:
    """Compile ``fn`` with ``numba.njit``: no fastmath, numpy's error model.

    No fastmath: IEEE arithmetic, nothing reassociated or contracted; numpy's error model:
    x / 0 is inf or nan as in numpy, not an exception. The machine code is cached on disk
    (``cache=True``, see `_cacheable`) in the ``__pycache__`` directory next to this file,
    or where numba falls back to when that is not writable (``NUMBA_CACHE_DIR``, else the
    user's cache directory, ``~/.cache/numba``); without a writable place, or without the
    cache, the kernels are compiled in each process at their first call (a few seconds).
    """
    return _compile(fn, _CACHE)


def _compile(fn: _Fn, cache: bool) -> _Fn:
    """`_jit` with or without the cache."""
    if cache:
        try:
            return cast(_Fn, numba.njit(cache=True, error_model="numpy")(fn))
        except RuntimeError:  # numba: "cannot cache function ...: no locator available"
            pass
    return cast(_Fn, numba.njit(error_model="numpy")(fn))


# kepler.propagate's Lagrange coefficients and partials, the same code compiled into the
# kernels that call it (not cached itself: numba's cache key ignores the compile options)
_lagrange_partials = _compile(kepler.lagrange_partials, False)


@_jit
def _stumpff(z: float, full: bool) -> tuple[float, float, float, float]:
    """Stumpff (c2, c3, c4, c5) at z (c4, c5 only when ``full``, else 0), as `kepler.stumpff`.

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


@_jit
def _solve_chi(r0: float, sig0: float, alpha: float, tau: float) -> tuple[float, bool]:
    """Solve ``r0 U1 + sig0 U2 + U3 = tau`` for chi; return (chi, converged).

    Newton's method from a Taylor series (short steps) or the mean-anomaly guess (ellipses),
    safeguarded for ellipses by the bracket that follows from |dE - dM| <= 2 e.
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
    else:
        chi = tau * alpha if bound else t
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


@_jit
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
        (f, g, fd, gd), a, b, d = _lagrange_partials(r0, sig0, alpha, chi, c, smu, mu)
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


@_jit
def _predict_kernel(x: Array, P: Array, dt: Array, x1: Array, F: Array, ok: BoolArray,
                    q: float, sigma_bound: float, P1: Array) -> None:
    """``P1 = sym(F P F^T + Q)``, bounded; dt == 0: x1, P1 = x, P (ok).

    ``Q = q [[dt^3/3 I, dt^2/2 I], [dt^2/2 I, dt I]]`` (`ekf.process_noise`), ``sym(M) =
    (M + M^T) / 2`` as the per-object `ekf.ExtendedKalmanFilter.predict` (computing one
    triangle of F sym(P) F^T instead, as cheap, lets the batched and the per-object filter
    drift apart by ~5e-12 over a day of updates instead of ~2e-13). ``ok`` is and-ed with
    the finiteness of P1.
    """
    FP = np.empty((6, 6))
    s = np.empty(6)
    for i in range(x.shape[0]):
        if dt[i] == 0.0:  # no prediction (as the per-object filter)
            x1[i] = x[i]
            P1[i] = P[i]
            ok[i] = True
            continue
        for k in range(6):  # FP = F P, row by row (the inner loop over j vectorises)
            for j in range(6):
                FP[k, j] = F[i, k, 0] * P[i, 0, j]
            for m in range(1, 6):
                f = F[i, k, m]
                for j in range(6):
                    FP[k, j] += f * P[i, m, j]
        for k in range(6):  # FP F^T (row k of FP held in registers)
            f0, f1, f2, f3, f4, f5 = FP[k, 0], FP[k, 1], FP[k, 2], FP[k, 3], FP[k, 4], FP[k, 5]
            for j in range(6):
                P1[i, k, j] = (f0 * F[i, j, 0] + f1 * F[i, j, 1] + f2 * F[i, j, 2]
                               + f3 * F[i, j, 3] + f4 * F[i, j, 4] + f5 * F[i, j, 5])
        adt = abs(dt[i])
        q3, q2, q1 = adt * adt * adt * (q / 3.0), adt * adt * (q / 2.0), adt * q
        for k in range(3):
            P1[i, k, k] += q3
            P1[i, k, k + 3] += q2
            P1[i, k + 3, k] += q2
            P1[i, k + 3, k + 3] += q1
        for k in range(6):
            for j in range(k + 1, 6):
                P1[i, k, j] = (P1[i, k, j] + P1[i, j, k]) * 0.5
        if sigma_bound > 0.0:  # ekf.bound_covariance
            cp = sigma_bound * math.sqrt(x1[i, 0] ** 2 + x1[i, 1] ** 2 + x1[i, 2] ** 2)
            cv = sigma_bound * math.sqrt(x1[i, 3] ** 2 + x1[i, 4] ** 2 + x1[i, 5] ** 2)
            for k in range(6):
                cap = cp if k < 3 else cv
                sig = math.sqrt(max(P1[i, k, k], 0.0))
                s[k] = cap / sig if (sig > cap and cap > 0.0) else 1.0
            for k in range(6):
                for j in range(k, 6):
                    P1[i, k, j] = P1[i, k, j] * s[k] * s[j]
        nf = 0.0  # stays 0.0 unless an element is inf or nan
        for k in range(6):
            for j in range(k, 6):
                w = P1[i, k, j]
                P1[i, j, k] = w
                nf += w - w
        ok[i] = ok[i] and nf == 0.0


@_jit
def _wrap(a: float) -> float:
    """`frames.wrap_angle` of a float: ``pi - (pi - a) mod 2 pi``, in (-pi, pi]."""
    b = math.pi - a
    if 0.0 < b < _TWO_PI:  # b mod 2 pi = b: skip the (slow) floating-point modulo
        return math.pi - b
    return math.pi - b % _TWO_PI


@_jit
def _admit_kernel(x: Array, P: Array, dt: Array, z: Array, R: Array, t: Array,
                  st: NDArray[np.intp], stations: int, code: NDArray[np.int8]) -> None:
    """Set the admission `Code` of m measurements.

    NONFINITE (an input not finite, or no such station), ELEVATION (outside
    [-pi/2, pi/2]), NEGATIVE_RANGE, else FUSED.
    """
    for i in range(x.shape[0]):
        nf = (dt[i] - dt[i]) + (t[i] - t[i])  # stays 0.0 unless an input is inf or nan
        for k in range(3):
            nf += z[i, k] - z[i, k]
            for j in range(3):
                nf += R[i, k, j] - R[i, k, j]
        for k in range(6):
            nf += x[i, k] - x[i, k]
            for j in range(6):
                nf += P[i, k, j] - P[i, k, j]
        if not (nf == 0.0 and 0 <= st[i] < stations):
            code[i] = _NONFINITE
        elif not abs(z[i, 2]) <= 0.5 * math.pi:
            code[i] = _ELEVATION
        elif z[i, 0] < 0.0:
            code[i] = _NEGATIVE_RANGE
        else:
            code[i] = _FUSED


@_jit
def _update_kernel(x: Array, P: Array, z: Array, R: Array, g: Array, gi: NDArray[np.intp],
                   st: NDArray[np.intp], enu: Array, site: Array, x1: Array, P1: Array,
                   nis: Array, y: Array, ok: BoolArray) -> None:
    """Joseph-form range/az/el update of m objects (see `BatchEKF._update`).

    ``enu`` (stations, 3, 3) and ``site`` (stations, 3): the stations' ITRF -> ENU rotations
    and ENU positions of the ITRF origin; ``g[gi[i]]`` (3, 3) the GCRF -> ITRF rotation at
    measurement i's epoch.
    """
    # the fixed 3x3 blocks as scalars (in registers); rows of P H^T, K, E in small arrays
    PHt, K, E = np.empty((6, 3)), np.empty((6, 3)), np.empty((6, 3))
    for i in range(x.shape[0]):
        j, k = st[i], gi[i]
        # GCRF -> ENU: T = M G
        t00 = enu[j, 0, 0] * g[k, 0, 0] + enu[j, 0, 1] * g[k, 1, 0] + enu[j, 0, 2] * g[k, 2, 0]
        t01 = enu[j, 0, 0] * g[k, 0, 1] + enu[j, 0, 1] * g[k, 1, 1] + enu[j, 0, 2] * g[k, 2, 1]
        t02 = enu[j, 0, 0] * g[k, 0, 2] + enu[j, 0, 1] * g[k, 1, 2] + enu[j, 0, 2] * g[k, 2, 2]
        t10 = enu[j, 1, 0] * g[k, 0, 0] + enu[j, 1, 1] * g[k, 1, 0] + enu[j, 1, 2] * g[k, 2, 0]
        t11 = enu[j, 1, 0] * g[k, 0, 1] + enu[j, 1, 1] * g[k, 1, 1] + enu[j, 1, 2] * g[k, 2, 1]
        t12 = enu[j, 1, 0] * g[k, 0, 2] + enu[j, 1, 1] * g[k, 1, 2] + enu[j, 1, 2] * g[k, 2, 2]
        t20 = enu[j, 2, 0] * g[k, 0, 0] + enu[j, 2, 1] * g[k, 1, 0] + enu[j, 2, 2] * g[k, 2, 0]
        t21 = enu[j, 2, 0] * g[k, 0, 1] + enu[j, 2, 1] * g[k, 1, 1] + enu[j, 2, 2] * g[k, 2, 1]
        t22 = enu[j, 2, 0] * g[k, 0, 2] + enu[j, 2, 1] * g[k, 1, 2] + enu[j, 2, 2] * g[k, 2, 2]
        e = t00 * x[i, 0] + t01 * x[i, 1] + t02 * x[i, 2] - site[j, 0]
        n = t10 * x[i, 0] + t11 * x[i, 1] + t12 * x[i, 2] - site[j, 1]
        u = t20 * x[i, 0] + t21 * x[i, 1] + t22 * x[i, 2] - site[j, 2]
        h2 = e * e + n * n
        h = math.sqrt(h2)
        r2 = h2 + u * u
        rg = math.sqrt(r2)
        y0 = z[i, 0] - rg
        az = math.atan2(e, n)
        y1 = _wrap(z[i, 1] - (az + _TWO_PI if az < 0.0 else az))  # az mod 2 pi
        y2 = _wrap(z[i, 2] - math.atan2(u, h))
        y[i, 0], y[i, 1], y[i, 2] = y0, y1, y2
        kk = -u / (h * r2)
        d00, d01, d02 = e / rg, n / rg, u / rg  # D = d(range, az, el)/d(e, n, u)
        d10, d11, d12 = n / h2, -e / h2, 0.0
        d20, d21, d22 = kk * e, kk * n, h / r2
        # H = [Hr, 0] (no velocity columns), Hr = D T
        h00 = d00 * t00 + d01 * t10 + d02 * t20
        h01 = d00 * t01 + d01 * t11 + d02 * t21
        h02 = d00 * t02 + d01 * t12 + d02 * t22
        h10 = d10 * t00 + d11 * t10 + d12 * t20
        h11 = d10 * t01 + d11 * t11 + d12 * t21
        h12 = d10 * t02 + d11 * t12 + d12 * t22
        h20 = d20 * t00 + d21 * t10 + d22 * t20
        h21 = d20 * t01 + d21 * t11 + d22 * t21
        h22 = d20 * t02 + d21 * t12 + d22 * t22
        for p in range(6):
            PHt[p, 0] = P[i, p, 0] * h00 + P[i, p, 1] * h01 + P[i, p, 2] * h02
            PHt[p, 1] = P[i, p, 0] * h10 + P[i, p, 1] * h11 + P[i, p, 2] * h12
            PHt[p, 2] = P[i, p, 0] * h20 + P[i, p, 1] * h21 + P[i, p, 2] * h22
        # S = H P H^T + R
        s00 = h00 * PHt[0, 0] + h01 * PHt[1, 0] + h02 * PHt[2, 0] + R[i, 0, 0]
        s01 = h00 * PHt[0, 1] + h01 * PHt[1, 1] + h02 * PHt[2, 1] + R[i, 0, 1]
        s02 = h00 * PHt[0, 2] + h01 * PHt[1, 2] + h02 * PHt[2, 2] + R[i, 0, 2]
        s10 = h10 * PHt[0, 0] + h11 * PHt[1, 0] + h12 * PHt[2, 0] + R[i, 1, 0]
        s11 = h10 * PHt[0, 1] + h11 * PHt[1, 1] + h12 * PHt[2, 1] + R[i, 1, 1]
        s12 = h10 * PHt[0, 2] + h11 * PHt[1, 2] + h12 * PHt[2, 2] + R[i, 1, 2]
        s20 = h20 * PHt[0, 0] + h21 * PHt[1, 0] + h22 * PHt[2, 0] + R[i, 2, 0]
        s21 = h20 * PHt[0, 1] + h21 * PHt[1, 1] + h22 * PHt[2, 1] + R[i, 2, 1]
        s22 = h20 * PHt[0, 2] + h21 * PHt[1, 2] + h22 * PHt[2, 2] + R[i, 2, 2]
        c11 = s11 * s22 - s12 * s12  # S^-1 by cofactors, from its upper triangle
        c12 = s02 * s12 - s01 * s22
        c13 = s01 * s12 - s02 * s11
        det = s00 * c11 + s01 * c12 + s02 * c13
        good = math.isfinite(det) and det > 0.0
        idet = 1.0 / det if good else 1.0
        i00, i01, i02 = c11 * idet, c12 * idet, c13 * idet
        i11, i12 = (s00 * s22 - s02 * s02) * idet, (s01 * s02 - s00 * s12) * idet
        i22 = (s00 * s11 - s01 * s01) * idet
        v = (y0 * (i00 * y0 + i01 * y1 + i02 * y2)
             + y1 * (i01 * y0 + i11 * y1 + i12 * y2)
             + y2 * (i02 * y0 + i12 * y1 + i22 * y2))
        nis[i] = v
        nf = v - v  # 0.0, or nan once anything checked is inf or nan
        for p in range(6):  # K = P H^T S^-1, x1 = x + K y, E = K S - 2 P H^T
            g0, g1, g2 = PHt[p, 0], PHt[p, 1], PHt[p, 2]
            k0 = g0 * i00 + g1 * i01 + g2 * i02
            k1 = g0 * i01 + g1 * i11 + g2 * i12
            k2 = g0 * i02 + g1 * i12 + g2 * i22
            K[p, 0], K[p, 1], K[p, 2] = k0, k1, k2
            w = x[i, p] + (k0 * y0 + k1 * y1 + k2 * y2)
            x1[i, p] = w
            nf += w - w
            E[p, 0] = k0 * s00 + k1 * s10 + k2 * s20 - 2.0 * g0
            E[p, 1] = k0 * s01 + k1 * s11 + k2 * s21 - 2.0 * g1
            E[p, 2] = k0 * s02 + k1 * s12 + k2 * s22 - 2.0 * g2
        for p in range(6):  # Joseph, expanded: P + E K^T, symmetrised
            for q in range(p, 6):
                wpq = P[i, p, q] + E[p, 0] * K[q, 0] + E[p, 1] * K[q, 1] + E[p, 2] * K[q, 2]
                wqp = P[i, q, p] + E[q, 0] * K[p, 0] + E[q, 1] * K[p, 1] + E[q, 2] * K[p, 2]
                w = (wpq + wqp) * 0.5
                P1[i, p, q] = P1[i, q, p] = w
                nf += w - w
        ok[i] = good and nf == 0.0


_CHUNK = 128
"""Objects per pass of `_kepler_step_kernel` (its predicted states, STMs and covariances,
128 x 78 doubles = 80 KB, stay in the CPU cache from one kernel to the next)."""


@_jit
def _kepler_step_kernel(x: Array, P: Array, dt: Array, z: Array, R: Array, g: Array,
                        gi: NDArray[np.intp], st: NDArray[np.intp], enu: Array, site: Array,
                        mu: float, q: float, sigma_bound: float, x1: Array,
                        P1: Array, nis: Array, y: Array, ok: BoolArray) -> None:
    """Kepler prediction then update of m objects, `_CHUNK` objects at a time.

    `_kepler_kernel`, `_predict_kernel` and `_update_kernel` on each chunk: the same numbers
    as three passes over all objects, with the intermediate arrays in cache (at N = 10,000
    a third less time than the three passes).
    """
    c = min(_CHUNK, x.shape[0])
    xp, F, Pp = np.empty((c, 6)), np.empty((c, 6, 6)), np.empty((c, 6, 6))
    okp, oku = np.empty(c, dtype=np.bool_), np.empty(c, dtype=np.bool_)
    for a in range(0, x.shape[0], _CHUNK):
        b = min(a + _CHUNK, x.shape[0])
        m = b - a
        _kepler_kernel(x[a:b], dt[a:b], mu, xp[:m], F[:m], okp[:m], True)
        _predict_kernel(x[a:b], P[a:b], dt[a:b], xp[:m], F[:m], okp[:m], q, sigma_bound,
                        Pp[:m])
        _update_kernel(xp[:m], Pp[:m], z[a:b], R[a:b], g, gi[a:b], st[a:b], enu, site,
                       x1[a:b], P1[a:b], nis[a:b], y[a:b], oku[:m])
        for i in range(m):
            ok[a + i] = okp[i] and oku[i]


@_jit
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


@_jit
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


def _f64(a: AnyArray) -> Array:
    """Return ``a`` as a C-contiguous writable float64 array (the kernels' argument type).

    ``a`` itself when it is one (the usual case, checked faster than ``np.require``), else a
    copy: one array type per argument, so each kernel is compiled once.
    """
    if a.dtype == np.float64 and a.flags.c_contiguous and a.flags.writeable:
        return a
    out: Array = np.array(a, dtype=np.float64, order="C")
    return out


# --------------------------------------------------------------------------------------------
# Motion models
# --------------------------------------------------------------------------------------------
def _kepler(x: ArrayLike, dt: ArrayLike, mu: float,
            stm: bool) -> tuple[Array, Array, BoolArray]:
    X = _f64(np.atleast_2d(np.asarray(x, dtype=float)))
    n = X.shape[0]
    dts = _f64(np.broadcast_to(np.asarray(dt, dtype=float), (n,)))
    x1 = np.empty((n, 6))
    phi = np.empty((n, 6, 6) if stm else (0, 6, 6))
    ok = np.empty(n, dtype=np.bool_)
    _kepler_kernel(X, dts, float(mu), x1, phi, ok, stm)
    return x1, phi, ok


def kepler_stm(x: ArrayLike, dt: ArrayLike,
               mu: float = MU_EARTH) -> tuple[Array, Array, BoolArray]:
    """Propagate N two-body states by their own ``dt`` with their state transition matrices.

    The batched counterpart of `kepler.propagate`, with the same analytic STM: the
    Lagrange coefficients ``F, G, Fdot, Gdot`` (``x1 = [F r0 + G v0, Fdot r0 + Gdot v0]``)
    depend on the initial state only through p = (r0 km, sigma0 km^0.5, alpha 1/km); their
    exact partials (``dU_k/dalpha = (k U_{k+2} - chi U_{k+1}) / 2`` at fixed chi, and the
    implicit derivative of chi from Kepler's equation; `kepler.lagrange_partials`, the same
    code compiled) give
    ``Phi = [[F I, G I], [Fdot I, Gdot I]] + W M W^T``, ``W = [[r0, v0, 0, 0], [0, 0, r0, v0]]``
    with a 4x4 matrix ``M`` per object. A compiled loop over the objects (numba).

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


_GRAVITY_DEFAULTS = {"two_body": _defaults(dynamics._MODELS["two_body"][0]),
                     "j2": _defaults(dynamics._MODELS["j2"][0])}
"""The models `_gravity_stm_kernel` integrates, with their parameters' defaults (`dynamics`'
own: ``mu``; ``mu``, ``j2``, ``re``)."""


def _gravity_params(model: str, params: dict[str, float]) -> tuple[float, float, float] | None:
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


def integrate_stm(model: str, x: ArrayLike, dt: ArrayLike, max_step_s: float = 60.0,
                  pole_frame: ArrayLike | None = None,
                  **params: float) -> tuple[Array, Array, BoolArray]:
    """Integrate N states of a `dynamics` model with their STMs, fixed-step DOP853.

    Object i takes ``ceil(|dt_i| / max_step_s)`` equal steps of the 8th-order Dormand-Prince
    method. "two_body" and "j2": a compiled loop over the objects (`_gravity_stm_kernel`,
    analytic Jacobian; equal to `_integrate_stm_numpy` to ~1e-15 relative per step, 1e-12
    over days); "drag": `_integrate_stm_numpy`.

    Parameters
    ----------
    model : str
        A 6-state `dynamics` model ("two_body", "j2", "drag").
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
    if model not in INTEGRATED_MODELS:
        raise ValueError(f"model {model!r} is not one of {', '.join(INTEGRATED_MODELS)}")
    gp = _gravity_params(model, params)
    X = np.atleast_2d(np.asarray(x, dtype=float))
    if gp is not None and X.ndim == 2 and X.shape[1] == 6 and (
            max_step_s > 0.0 and math.isfinite(max_step_s)):
        X = _f64(X)
        n = X.shape[0]
        dts = _f64(np.broadcast_to(np.asarray(dt, dtype=float), (n,)))
        # J2 about the pole: the third row of the rotation to the pole's axes
        pole = (np.broadcast_to(_Z_AXIS, (n, 3)) if pole_frame is None else
                np.broadcast_to(np.asarray(pole_frame, dtype=float)[..., 2, :], (n, 3)))
        A, B = _tableau()
        x1, phi = np.empty((n, 6)), np.empty((n, 6, 6))
        ok = np.empty(n, dtype=np.bool_)
        _gravity_stm_kernel(X, dts, float(max_step_s), *gp, _f64(pole), A, B, x1, phi, ok)
        return x1, phi, ok
    if pole_frame is not None and model != "two_body":  # the numpy path: turn the states
        r = np.asarray(pole_frame, dtype=float)
        B = np.zeros((*r.shape[:-2], 6, 6))  # diag(R, R): states into the pole's axes
        B[..., :3, :3] = B[..., 3:, 3:] = r
        Bt = np.swapaxes(B, -1, -2)
        X = np.atleast_2d(np.asarray(x, dtype=float))
        x1p, phip, okp = integrate_stm(model, np.einsum("...ij,...j->...i", B, X), dt,
                                       max_step_s, None, **params)
        x1 = _f64(np.einsum("...ij,...j->...i", Bt, x1p))
        return x1, np.matmul(np.matmul(Bt, phip), B), okp
    return _integrate_stm_numpy(model, X, dt, max_step_s, **params)


def _integrate_stm_numpy(model: str, x: ArrayLike, dt: ArrayLike, max_step_s: float = 60.0,
                         **params: float) -> tuple[Array, Array, BoolArray]:
    """`integrate_stm` in numpy, vectorised over the objects (any `INTEGRATED_MODELS` model).

    All objects still stepping are advanced together (one right-hand-side call per stage for
    all of them; A by the complex step, `_variational`). `integrate_stm` uses it for "drag"
    (and unusual arguments); the tests compare the compiled path with it.
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
        self._unix0 = (config.jd0 - UNIX_EPOCH_JD) * DAY_S
        self._eop = eop_default()  # the tables read now (EOP, leap seconds), not later
        install_leap_seconds()
        self._enu = np.array([enu_matrix(s.lat_rad, s.lon_rad) for s in self.stations]
                             ).reshape(-1, 3, 3)
        self._site = np.array([m @ s.itrs for m, s in zip(self._enu, self.stations, strict=True)]
                              ).reshape(-1, 3)
        self._params = config.params

    # ----------------------------------------------------------------------------------
    def _rotations(self, t: Array) -> tuple[Array, NDArray[np.intp]]:
        """Return GCRF -> ITRF rotations at the distinct epochs of ``t`` (s after jd0).

        With the index of each epoch's: ((k, 3, 3), (len(t),)).
        """
        if t.size and bool(np.all(t == t[0])):  # a scan: one epoch
            uniq, inv = t[:1], np.zeros(t.size, dtype=np.intp)
        else:
            uniq, inv = np.unique(t, return_inverse=True)
        with np.errstate(all="ignore"):
            g = frames.gcrs_to_itrs_matrix(np.nan_to_num(uniq) + self._unix0, self._eop)
        return _f64(g.reshape(-1, 3, 3)), np.ascontiguousarray(inv.reshape(-1), dtype=np.intp)

    def propagate(self, x: ArrayLike, dt: ArrayLike,
                  t0: ArrayLike) -> tuple[Array, Array, BoolArray]:
        """Motion model for N states at epochs ``t0`` (s after jd0) by ``dt`` (s).

        Returns (x1 (N, 6), Phi (N, 6, 6), ok (N,)); J2 about the Earth's pole at ``t0``.
        """
        if self.config.motion_model == "kepler":
            return kepler_stm(x, dt, self._params.get("mu", MU_EARTH))
        with np.errstate(all="ignore"):
            pole = frames.pole_frame(np.nan_to_num(np.asarray(t0, dtype=float))
                                     + self._unix0, self._eop)
        return integrate_stm(self.config.motion_model, x, dt, self.config.max_step_s,
                             pole_frame=pole, **self._params)

    def _predict(self, x: Array, P: Array, dt: Array,
                 t0: Array) -> tuple[Array, Array, BoolArray]:
        """x, P predicted by dt (dt == 0: unchanged, as the per-object filter skips it)."""
        x1, F, ok = self.propagate(x, dt, t0)
        P1 = np.empty((x.shape[0], 6, 6))
        _predict_kernel(x, P, dt, x1, _f64(F), ok, float(self.config.q),
                        float(self.config.sigma_bound), P1)
        return x1, P1, ok

    def predict(self, x: ArrayLike, P: ArrayLike, dt: ArrayLike, t0: ArrayLike) -> Predicted:
        """Predict N objects at epochs ``t0`` (s after jd0) by their own ``dt`` (s).

        ``x <- f(x)``, ``P <- F P F^T + Q``, then ``P`` is symmetrised and bounded
        (``sigma_bound``); ``dt == 0`` leaves an object unchanged. Objects whose prediction
        is not computable keep their input (``ok``).
        """
        X = _f64(np.asarray(x, dtype=float))
        PP = _f64(np.asarray(P, dtype=float))
        dts = _f64(np.broadcast_to(np.asarray(dt, dtype=float), (X.shape[0],)))
        t0s = np.broadcast_to(np.asarray(t0, dtype=float), (X.shape[0],))
        with np.errstate(all="ignore"):
            x1, P1, ok = self._predict(X, PP, dts, t0s)
        return Predicted(np.where(ok[:, None], x1, X), np.where(ok[:, None, None], P1, PP), ok)

    def measure(self, x: Array, t: Array, station: NDArray[np.intp]) -> tuple[Array, Array]:
        """Predicted [range km, az rad in [0, 2 pi), el rad] (m, 3) and Jacobian (m, 3, 6).

        ``x`` (m, 6) GCRF states, ``t`` (m,) s after jd0, ``station`` (m,) station indices;
        the batched `measurement.RazelModel.h_and_H` (no light time).
        """
        g, gi = self._rotations(np.asarray(t, dtype=float))
        T = np.matmul(self._enu[station], g[gi])  # GCRF -> ENU
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

        A compiled loop over the objects (`_update_kernel`) using the zero velocity columns
        of H. The Joseph form ``A P A^T + K R K^T`` (``A = I - K H``) is evaluated expanded,
        ``P + (K S - 2 P H^T) K^T`` symmetrised (S = H P H^T + R): algebraically the same,
        and like it insensitive to first order to an error in the gain K (the first-order
        term is antisymmetric).
        """
        m = x.shape[0]
        x1, P1 = np.empty((m, 6)), np.empty((m, 6, 6))
        nis, y, ok = np.empty(m), np.empty((m, 3)), np.empty(m, dtype=np.bool_)
        g, gi = self._rotations(t)
        _update_kernel(x, P, z, R, g, gi, station, self._enu, self._site, x1, P1, nis, y, ok)
        return x1, P1, nis, y, ok

    def _kepler_step(self, x: Array, P: Array, dt: Array, z: Array, R: Array, t: Array,
                     station: NDArray[np.intp]
                     ) -> tuple[Array, Array, Array, Array, BoolArray]:
        """`_predict` then `_update` with the Kepler model (`_kepler_step_kernel`)."""
        m = x.shape[0]
        x1, P1 = np.empty((m, 6)), np.empty((m, 6, 6))
        nis, y, ok = np.empty(m), np.empty((m, 3)), np.empty(m, dtype=np.bool_)
        g, gi = self._rotations(t)
        _kepler_step_kernel(x, P, dt, z, R, g, gi, station, self._enu, self._site,
                            float(self._params.get("mu", MU_EARTH)),
                            float(self.config.q), float(self.config.sigma_bound), x1, P1, nis,
                            y, ok)
        return x1, P1, nis, y, ok

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
            States at the objects' epochs, GCRF km, km/s.
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
        zz, RR, tt, dts, xs, Ps = (_f64(a) for a in (zz, RR, tt, dts, xs, Ps))
        if not (st.dtype == np.intp and st.flags.c_contiguous and st.flags.writeable):
            st = np.array(st, dtype=np.intp)
        c = np.empty(idx.size, dtype=np.int8)
        _admit_kernel(xs, Ps, dts, zz, RR, tt, st, len(self.stations), c)
        with np.errstate(all="ignore"):
            valid = c == Code.FUSED
            allv = bool(valid.all())
            go = np.flatnonzero(valid)

            def sub(a: AnyArray) -> AnyArray:
                return a if allv else a[go]

            if self.config.motion_model == "kepler":  # predict and update by chunks
                x1, P1, g_nis, g_y, ok = self._kepler_step(sub(xs), sub(Ps), sub(dts), sub(zz),
                                                           sub(RR), sub(tt), sub(st))
            else:
                xp, Pp, ok = self._predict(sub(xs), sub(Ps), sub(dts), sub(tt) - sub(dts))
                x1, P1, g_nis, g_y, ok2 = self._update(xp, Pp, sub(zz), sub(RR), sub(tt),
                                                       sub(st))
                ok &= ok2
            cg = np.where(ok, Code.FUSED, Code.NUMERIC).astype(np.int8)
            if self.config.gate is not None:
                cg[ok & (g_nis > self.config.gate)] = Code.GATE
            g_nis[~ok] = np.nan
        take = cg == Code.FUSED
        if every and allv:  # the usual batch: every object measured and admitted
            code, nis, yy, rows = cg, g_nis, g_y, take
        else:
            c[go] = cg
            code[idx] = c
            where = idx[go]
            nis[where] = g_nis
            yy[where] = g_y
            rows = where[take]
        if every and allv and bool(take.all()) and not inplace:
            X, PP = x1, P1
        else:
            if not inplace:
                X, PP = X.copy(), PP.copy()
            X[rows] = x1[take]
            PP[rows] = P1[take]
        return BatchUpdate(X, PP, code, nis, yy)
