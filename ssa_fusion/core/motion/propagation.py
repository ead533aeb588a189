"""Numerical propagation with the state transition matrix, compiled: `integrate_stm`.

The `dynamics` right-hand sides of the orbit models ("two_body", "j2", "drag") with their
variational equations dPhi/dt = A(x) Phi, integrated with the 8th-order Dormand-Prince
tableau (scipy's DOP853) at a fixed step: each object takes ``ceil(|dt| / max_step_s)``
equal steps. "two_body" and "j2": a loop over N objects compiled with numba (`jit.jit`),
with the analytic Jacobian (`_gravity_stm_kernel`, J2 about the Earth's pole); "drag":
numpy, all objects at once, A by the complex step (`_integrate_stm_numpy`). The two paths
agree to ~1e-15 relative per step (~1e-12 over a day of steps). scipy's adaptive DOP853
(rtol 1e-10, atol 1e-9) and this fixed-step scheme at 60 s agree to ~5e-11 relative (LEO
and Molniya, 10 s to 1.5 h steps). The analytic two-body model is `kepler`'s.

Units: km, km/s, s; states in an inertial frame (GCRF).
"""

from __future__ import annotations

import functools
import importlib.util
import inspect
import math
from collections.abc import Callable
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ssa_fusion.core.base.jit import f64, jit
from ssa_fusion.core.base.types import MotionModel
from ssa_fusion.core.motion import dynamics

__all__ = ["INTEGRATED_MODELS", "integrate_stm", "rk_advance", "rk_stage"]

Array = NDArray[np.float64]
BoolArray = NDArray[np.bool_]

_COMPLEX_STEP = 1e-30
"""Imaginary perturbation of the complex-step derivatives (as `dynamics.jacobian`)."""

_Z_AXIS = np.array([0.0, 0.0, 1.0])
"""The pole of an integration without one (the states' own z axis)."""

INTEGRATED_MODELS = (MotionModel.TWO_BODY, MotionModel.J2, MotionModel.DRAG)
"""`dynamics` models integrated with their variational equations (`integrate_stm`)."""


@jit
def j2_gravity(x: float, yy: float, zz: float, mu: float, j2: float, re: float, px: float,
               py: float, pz: float) -> tuple[float, float, float, float, float, float,
                                                float, float, float]:
    """Return the two-body + J2 acceleration and its gradient at (x, yy, zz) km.

    J2 about the pole (px, py, pz): (a_x, a_y, a_z, G00, G01, G02, G11, G12, G22), km/s^2
    and 1/s^2, by the formulas of `_gravity_rhs`'s docstring (G symmetric: its upper
    triangle).
    """
    r2 = x * x + yy * yy + zz * zz
    r = math.sqrt(r2)
    k = -mu / (r2 * r)
    f = 1.5 * j2 * re * re / r2
    z = px * x + py * yy + pz * zz
    w = 5.0 * z * z / r2
    g = 1.0 + f * (1.0 - w)
    c = 2.0 * f * z
    ir2 = 1.0 / r2
    e = k * ir2 * (4.0 * f * w - 2.0 * f - 3.0 * g)  # the r r^T term
    d = -10.0 * k * f * z * ir2  # the (r p^T + p r^T) term
    h = 2.0 * k * f  # the p p^T term
    kg = k * g
    return (k * (g * x + c * px), k * (g * yy + c * py), k * (g * zz + c * pz),
            kg + e * x * x + 2.0 * d * x * px + h * px * px,
            e * x * yy + d * (x * py + px * yy) + h * px * py,
            e * x * zz + d * (x * pz + px * zz) + h * px * pz,
            kg + e * yy * yy + 2.0 * d * yy * py + h * py * py,
            e * yy * zz + d * (yy * pz + py * zz) + h * py * pz,
            kg + e * zz * zz + 2.0 * d * zz * pz + h * pz * pz)


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
    ax, ay, az, g00, g01, g02, g11, g12, g22 = j2_gravity(y[0], y[1], y[2], mu, j2, re,
                                                          px, py, pz)
    out[s, 0], out[s, 1], out[s, 2] = y[3], y[4], y[5]
    out[s, 3], out[s, 4], out[s, 5] = ax, ay, az
    for j in range(6):  # dPhi/dt: rows 0-2 = Phi rows 3-5, rows 3-5 = G Phi rows 0-2
        p0, p1, p2 = y[6 + j], y[12 + j], y[18 + j]
        out[s, 6 + j] = y[24 + j]
        out[s, 12 + j] = y[30 + j]
        out[s, 18 + j] = y[36 + j]
        out[s, 24 + j] = g00 * p0 + g01 * p1 + g02 * p2
        out[s, 30 + j] = g01 * p0 + g11 * p1 + g12 * p2
        out[s, 36 + j] = g02 * p0 + g12 * p1 + g22 * p2


@jit
def _combine(w: Array, K: Array, n: int, m: int, out: Array, skip_zeros: bool) -> None:
    """``out[:m] = sum_j w[j] K[j, :m]`` over j < n, in the order of j.

    With ``skip_zeros`` a zero coefficient's term is left out (``0 K`` adds nothing to a
    finite sum).
    """
    w0 = w[0]
    for c in range(m):
        out[c] = w0 * K[0, c]
    for j in range(1, n):
        a = w[j]
        if skip_zeros and a == 0.0:
            continue
        for c in range(m):
            out[c] += a * K[j, c]


@jit
def rk_stage(y: Array, h: float, A: Array, K: Array, s: int, m: int, ys: Array,
             skip_zeros: bool) -> None:
    """``ys = y + h sum_j A[s, j] K[j]`` (j < s) over the first ``m`` elements.

    The explicit Runge-Kutta stage state (tableau ``A``, stage derivatives ``K`` (stages,
    m)), the sum as `_combine` takes it.
    """
    _combine(A[s], K, s, m, ys, skip_zeros)
    for c in range(m):
        ys[c] = y[c] + h * ys[c]


@jit
def rk_advance(y: Array, h: float, B: Array, K: Array, m: int, ys: Array,
               skip_zeros: bool) -> None:
    """``y += h sum_j B[j] K[j]``: one Runge-Kutta step's end (``ys`` holds the sum)."""
    _combine(B, K, B.shape[0], m, ys, skip_zeros)
    for c in range(m):
        y[c] = y[c] + h * ys[c]


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
    taken in the order of j, as BLAS may not: ~1e-16 apart per step; the tableau's zero
    coefficients are skipped: 16 of A's 66 and 4 of B's 12 terms, each ``0 K`` adding nothing
    to a finite sum, so the results are the same as with them). A non-finite input
    (state or dt) takes no step: x1 = x, Phi = I, ok False; ok is False where x1 or Phi is
    not finite.
    """
    ns = B.shape[0]
    # 42 = the state and its STM, read from the arguments: a width the compiler does not
    # know vectorises the stage sums (SIMD, each element's sum in the same order, so the same
    # numbers); a constant 42 has them unrolled into scalar operations, ~1.5x slower
    m = x1.shape[1] + phi.shape[1] * phi.shape[2]
    y = np.empty(m)
    ys = np.empty(m)
    K = np.empty((ns, m))
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
            _gravity_rhs(y, mu, j2, re, px, py, pz, K, 0)
            for s in range(1, ns):
                rk_stage(y, h, A, K, s, m, ys, True)  # 16 of DOP853's 66 A are 0: skipped
                _gravity_rhs(ys, mu, j2, re, px, py, pz, K, s)
            rk_advance(y, h, B, K, m, ys, True)  # 4 of 12 B are 0: skipped
        for c in range(6):
            x1[i, c] = y[c]
            nf += y[c] - y[c]
        for c in range(36):
            w = y[6 + c]
            phi[i, c // 6, c % 6] = w
            nf += w - w
        ok[i] = nf == 0.0


@jit
def _gravity_chain_kernel(x0: Array, dt: Array, max_step: float, mu: float, j2: float,
                          re: float, pole: Array, A: Array, B: Array, out: Array,
                          ok: BoolArray) -> None:
    """Fixed-step DOP853 of two-body + J2, the states alone, of n objects along a chain.

    Object i starts at ``x0[i]`` and takes the steps ``dt[i, 0], dt[i, 1], ...`` (s) one
    after the other, ``out[i, k]`` the state after step k; each step as
    `_gravity_stm_kernel`'s (``ceil(|dt| / max_step)`` equal DOP853 steps, J2 about
    ``pole[i]``, the same stage sums in the same order) on the state only, which does not
    depend on the STM: the same numbers as that kernel's x1 taken step by step. A step
    whose input is not finite is not taken and ends the chain: ok[i] False, the rest of
    ``out[i]`` not written; ok[i] is also False when a state comes out not finite.
    """
    ns = B.shape[0]
    m = x0.shape[1]  # 6, read from the arguments as in `_gravity_stm_kernel`
    y = np.empty(m)
    ys = np.empty(m)
    K = np.empty((ns, m))
    for i in range(x0.shape[0]):
        for c in range(m):
            y[c] = x0[i, c]
        ok[i] = True
        px, py, pz = pole[i, 0], pole[i, 1], pole[i, 2]
        for k in range(dt.shape[1]):
            nf = dt[i, k] - dt[i, k]
            for c in range(m):
                nf += y[c] - y[c]
            if nf != 0.0:
                ok[i] = False
                break
            steps = math.ceil(abs(dt[i, k]) / max_step)
            h = dt[i, k] / max(steps, 1)
            for _ in range(steps):
                _gravity_state_rhs(y, mu, j2, re, px, py, pz, K, 0)
                for s in range(1, ns):
                    rk_stage(y, h, A, K, s, m, ys, True)
                    _gravity_state_rhs(ys, mu, j2, re, px, py, pz, K, s)
                rk_advance(y, h, B, K, m, ys, True)
            for c in range(m):
                out[i, k, c] = y[c]
                nf += y[c] - y[c]
            if nf != 0.0:
                ok[i] = False
                break


@jit
def _gravity_state_rhs(y: Array, mu: float, j2: float, re: float, px: float, py: float,
                       pz: float, out: Array, s: int) -> None:
    """``out[s, :6] = dx/dt`` of the state ``y[:6]``: `_gravity_rhs`'s state rows."""
    ax, ay, az, _, _, _, _, _, _ = j2_gravity(y[0], y[1], y[2], mu, j2, re, px, py, pz)
    out[s, 0], out[s, 1], out[s, 2] = y[3], y[4], y[5]
    out[s, 3], out[s, 4], out[s, 5] = ax, ay, az


def integrate_chain(model: MotionModel | str, x0: ArrayLike, dt: ArrayLike,
                    max_step_s: float = 60.0, pole_frame: ArrayLike | None = None
                    ) -> tuple[Array, BoolArray]:
    """Integrate N states along chains of steps, the states alone, fixed-step DOP853.

    State i takes the steps ``dt[i, 0], dt[i, 1], ...`` (s, any sign) one after the other,
    each as `integrate_stm` takes one (the same numbers as its x1, step by step; "two_body"
    and "j2" in one compiled call, `_gravity_chain_kernel`; "drag" by `integrate_stm` step
    by step). x0 (N, 6) GCRF km, km/s; dt (N, K); `pole_frame` (3, 3) or (N, 3, 3) as
    `integrate_stm`'s. Returns (states (N, K, 6) after each step, ok (N,)): ok False where
    an input or a state is not finite (the chain's states from there on are undefined).
    """
    model = _integrated(model)
    X = f64(np.atleast_2d(np.asarray(x0, dtype=float)))
    n = X.shape[0]
    D = f64(np.asarray(dt, dtype=float).reshape(n, -1))
    gp = _gravity_params(model, {})
    if gp is None or not (max_step_s > 0.0 and math.isfinite(max_step_s)):
        out = np.empty((n, D.shape[1], 6))
        ok = np.ones(n, dtype=np.bool_)
        x = X
        for k in range(D.shape[1]):
            x, _, good = integrate_stm(model, x, D[:, k], max_step_s, pole_frame)
            ok &= good
            out[:, k] = x
        return out, ok
    pole = (np.broadcast_to(_Z_AXIS, (n, 3)) if pole_frame is None else
            np.broadcast_to(np.asarray(pole_frame, dtype=float)[..., 2, :], (n, 3)))
    A, B = _tableau()
    out = np.zeros((n, D.shape[1], 6))
    ok = np.empty(n, dtype=np.bool_)
    _gravity_chain_kernel(X, D, float(max_step_s), *gp, f64(pole), A, B, out, ok)
    return out, ok


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

    Read once (the arrays are shared: not to be written to). From scipy's module of the
    coefficients (``scipy/integrate/_ivp/dop853_coefficients.py``, numpy only), loaded by
    its path: importing it as ``scipy.integrate._ivp...`` runs ``scipy.integrate``'s
    ``__init__``, which imports scipy's optimize, sparse, linalg, special and spatial
    (~40 MB resident that a filter process would hold for 16 x 16 numbers).
    """
    import scipy

    path = Path(scipy.__file__).parent / "integrate" / "_ivp" / "dop853_coefficients.py"
    spec = importlib.util.spec_from_file_location("_ssa_fusion_dop853_coefficients", path)
    if spec is None or spec.loader is None:
        raise ImportError(f"scipy's DOP853 coefficients are not at {path}")
    dop = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(dop)
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
