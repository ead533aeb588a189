"""An orbit's force model with solve-for parameters and their sensitivities, compiled.

The model of the batch least-squares fit (`batch_ls`): two-body + J2 about the Earth's pole
(as `propagation`) + the zonal harmonics J3 and J4 about the same pole, optionally drag in
the co-rotating exponential atmosphere of `dynamics` (``"drag"``: the same formula, here
*with* J2), scaled by a solve-for factor, plus constant
empirical accelerations in the radial / along-track / cross-track (RTN) axes::

    a = a_grav(r) + a_zonal(r) + k_D a_drag(r, v) + a_R R + a_T T + a_N N

``a_zonal`` is the sum over n = 3, 4 of the degree-n zonal term about the pole ``p``
(``s = p . r / |r|``, ``P_n`` the Legendre polynomial, ``r^ = r / |r|``)::

    a_n = mu J_n re^n / |r|^(n+2) [(n + 1) P_n(s) r^ - P_n'(s) (p - s r^)]

(the same formula with n = 2 is `propagation`'s J2 term). Without J3 and J4 a numerically
integrated orbit and SGP4 (which has them) part by ~0.6 km a day in LEO; with them by ~10 m.

``a_drag = -0.5 rho(h) |v_rel| v_rel / bc`` (`ForceModel.bc` kg/m^2, ``rho`` kg/m^3 of the
altitude ``|r| - re`` over a spherical Earth, ``v_rel = v - omega p x r`` with ``p`` the
pole); ``R = r/|r|``, ``N = (r x v)/|r x v|``, ``T = N x R``. The four parameters
(`PARAMETERS`: ``drag_scale`` k_D, dimensionless, nominal 1; ``accel_r``, ``accel_t``,
``accel_n`` km/s^2, nominal 0) enter the state's motion and are what a fit can solve for or
consider; the fifth, ``srp_scale`` (nominal 1), is the high-fidelity model's factor on Cr
(`force_spec`), which this model has no solar radiation pressure for.

`trajectory` integrates one state with the augmented variational equations: the state
transition matrix ``Phi = d x(t) / d x(t0)`` and the parameter sensitivities
``S = d x(t) / d p`` (selected parameters) obey::

    d/dt [Phi | S] = A(x) [Phi | S] + [0 | B(x)],   A = [[0, I], [G + D_r, D_v]]

with ``G`` the gravity gradient (analytic for two-body + J2, as
`propagation._gravity_rhs`; J3 and J4's by central differences of ``a_zonal`` over
`ZONAL_STEP_KM`, relative error ~(step/|r|)^2 of a term 1e-3 of J2's), ``D_r``, ``D_v``
the drag partials (analytic: ``D_v = -k c rho (|v_rel| I + v_rel v_rel^T / |v_rel|)``,
``D_r = k c rho |v_rel| / (H |r|) v_rel r^T - D_v [omega p x]``, ``c = 0.5e3 / bc``, ``H``
the scale height) and ``B = d a / d p``: ``a_drag`` for the drag factor, the unit RTN axes for
the empirical accelerations. The dependence of the RTN axes on the state is left out of A:
it is ``|a_emp| / |r|`` (< 1e-12 s^-2 for empirical accelerations below 1e-5 km/s^2) against
the gravity gradient's 1e-6 s^-2. Integration: the fixed-step DOP853 of `propagation` (the
same tableau, ``ceil(|dt| / max_step_s)`` equal steps between consecutive output epochs),
in one compiled call for every output epoch on one side of ``t0``: with drag and parameters
off it equals `propagation.integrate_stm` chained over the same epochs to round-off.

Units: km, km/s, s; states in the GCRF; times in s on any clock (the pole is fixed by the
caller, `frames.pole_frame` of the fit's epoch).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ssa_fusion.core.base.constants import J2, J3, J4, MU_EARTH, OMEGA_EARTH, R_EARTH
from ssa_fusion.core.base.jit import f64, jit
from ssa_fusion.core.motion.propagation import _tableau, j2_gravity, rk_advance, rk_stage

if TYPE_CHECKING:
    from ssa_fusion.core.motion.force_spec import ForceSpec

__all__ = ["NOMINAL", "PARAMETERS", "ForceModel", "Trajectory", "acceleration",
           "drag_terms", "output_steps", "parameter_index", "store_output", "trajectory"]

Array = NDArray[np.float64]
IntArray = NDArray[np.int64]
BoolArray = NDArray[np.bool_]

PARAMETERS = ("drag_scale", "accel_r", "accel_t", "accel_n", "srp_scale")
"""The parameters of the force model a fit can solve for or consider, in this order:
drag factor k_D (dimensionless), constant RTN empirical accelerations (km/s^2) and the factor
k_R on Cr of the high-fidelity model's solar radiation pressure (`force_spec`; none here)."""

NOMINAL = (1.0, 0.0, 0.0, 0.0, 1.0)
"""The parameters' nominal values (`PARAMETERS` order)."""

_N_CONST = 14
"""Length of the constants array of the kernel (`ForceModel.constants`)."""

ZONAL_STEP_KM = 0.5
"""Half-width of the central differences of J3 and J4's gravity gradient, km."""


@dataclass(frozen=True)
class ForceModel:
    """Gravity (two-body + J2) and optional drag of one orbit (module docstring).

    Attributes
    ----------
    mu : float
        Gravitational parameter, km^3/s^2.
    j2 : float
        Second zonal harmonic (0: two-body).
    j3, j4 : float
        Third and fourth zonal harmonics (EGM2008; 0: left out).
    re : float
        Equatorial radius, km (J2 and the drag's altitude).
    drag : bool
        Drag in the co-rotating exponential atmosphere (`dynamics` ``"drag"``).
    bc : float
        Ballistic coefficient m / (Cd A), kg/m^2 (the drag factor ``drag_scale`` divides it).
    rho0, h0, scale_height : float
        Density kg/m^3 at altitude ``h0`` km and scale height km (`dynamics`' defaults).
    omega : float
        The atmosphere's rotation rate about the pole, rad/s.
    """

    mu: float = MU_EARTH
    j2: float = J2
    re: float = R_EARTH
    drag: bool = False
    bc: float = 100.0
    rho0: float = 3.725e-12
    h0: float = 400.0
    scale_height: float = 58.515
    omega: float = OMEGA_EARTH
    j3: float = J3
    j4: float = J4

    def constants(self, pole: ArrayLike | None = None) -> Array:
        """Return the kernel's constants (14,) with J2-J4 and the atmosphere about ``pole``.

        Parameters
        ----------
        pole : array_like (3,), optional
            The Earth's pole, a GCRF unit vector (third row of `frames.pole_frame`); None:
            the frame's z axis.

        Returns
        -------
        ndarray (14,): mu km^3/s^2, j2, re km, pole (3), drag (0 or 1), 0.5e3 / bc m^2/kg
        (the km/s^2 factor of rho v^2), rho0 kg/m^3, h0 km, scale height km, omega rad/s,
        j3, j4.
        """
        p = np.array([0.0, 0.0, 1.0]) if pole is None else np.asarray(pole, dtype=float)
        return np.array([self.mu, self.j2, self.re, p[0], p[1], p[2],
                         1.0 if self.drag else 0.0, 0.5e3 / self.bc, self.rho0, self.h0,
                         self.scale_height, self.omega, self.j3, self.j4])


def parameter_index(names: Sequence[str]) -> IntArray:
    """Return the indices in `PARAMETERS` of ``names`` (ValueError naming an unknown one)."""
    out = []
    for n in names:
        if n not in PARAMETERS:
            raise ValueError(f"unknown force-model parameter {n!r}: one of "
                             f"{', '.join(PARAMETERS)}")
        out.append(PARAMETERS.index(n))
    return np.array(out, dtype=np.int64)


@jit
def _zonal34(x: float, yy: float, zz: float, mu: float, re: float, j3: float, j4: float,
             px: float, py: float, pz: float) -> tuple[float, float, float]:
    """Return the J3 + J4 acceleration (km/s^2) at (x, yy, zz) km about the pole p."""
    r2 = x * x + yy * yy + zz * zz
    r = math.sqrt(r2)
    s = (px * x + py * yy + pz * zz) / r
    s2 = s * s
    q = re / r
    k3 = mu * j3 * q * q * q / r2
    k4 = mu * j4 * q * q * q * q / r2
    # (n + 1) P_n(s) and P_n'(s) for n = 3, 4
    radial = k3 * 2.0 * (5.0 * s2 - 3.0) * s + k4 * 5.0 * ((35.0 * s2 - 30.0) * s2 + 3.0) / 8.0
    along = k3 * (15.0 * s2 - 3.0) / 2.0 + k4 * (35.0 * s2 - 15.0) * s / 2.0
    cr = (radial + along * s) / r  # the r^ terms, per km of r
    return cr * x - along * px, cr * yy - along * py, cr * zz - along * pz


@jit
def _zonal34_gradient(ar: Array, x: float, yy: float, zz: float, mu: float, re: float,
                      j3: float, j4: float, px: float, py: float, pz: float) -> None:
    """Add the J3 + J4 gravity gradient (central differences of `_zonal34`, 1/s^2) to ``ar``."""
    h = ZONAL_STEP_KM
    for j in range(3):
        ex = h if j == 0 else 0.0
        ey = h if j == 1 else 0.0
        ez = h if j == 2 else 0.0
        f0, f1, f2 = _zonal34(x + ex, yy + ey, zz + ez, mu, re, j3, j4, px, py, pz)
        m0, m1, m2 = _zonal34(x - ex, yy - ey, zz - ez, mu, re, j3, j4, px, py, pz)
        ar[0, j] += (f0 - m0) / (2.0 * h)
        ar[1, j] += (f1 - m1) / (2.0 * h)
        ar[2, j] += (f2 - m2) / (2.0 * h)


@jit
def drag_terms(x: float, y: float, z: float, vx: float, vy: float, vz: float, wx: float,
               wy: float, wz: float, rho0: float, re: float, h0: float, scale_h: float,
               k: float, kd: float, ar: Array, av: Array,
               gradient: bool) -> tuple[float, float, float]:
    """Return the drag acceleration with ``k_D = 1`` (km/s^2) at a GCRF state (km, km/s).

    The co-rotating exponential atmosphere (module docstring): rotation ``w`` (rad/s, GCRF),
    density ``rho0 exp(-(|r| - re - h0) / scale_h)`` (kg/m^3; km), ``k`` km/s^2 per
    (km/s)^2 per kg/m^3 (the ballistic coefficient's). With ``gradient`` its partials times
    ``kd`` are added to ``av`` (velocity) and ``ar`` (position).
    """
    ux = vx - (wy * z - wz * y)
    uy = vy - (wz * x - wx * z)
    uz = vz - (wx * y - wy * x)
    un = math.sqrt(ux * ux + uy * uy + uz * uz)
    r = math.sqrt(x * x + y * y + z * z)
    rho = rho0 * math.exp(-(r - re - h0) / scale_h)
    cr = k * rho  # km/s^2 per (km/s)^2
    if gradient:
        u = (ux, uy, uz)
        wv = (wx, wy, wz)
        rr = (x, y, z)
        for i in range(3):
            for j in range(3):
                av[i, j] += -kd * cr * ((un if i == j else 0.0) + u[i] * u[j] / un)
        kr = kd * cr * un / (scale_h * r)
        for i in range(3):
            # - D_v [w x]: column j of [w x] is w x e_j
            d0 = av[i, 1] * wv[2] - av[i, 2] * wv[1]
            d1 = av[i, 2] * wv[0] - av[i, 0] * wv[2]
            d2 = av[i, 0] * wv[1] - av[i, 1] * wv[0]
            ar[i, 0] += kr * u[i] * rr[0] - d0
            ar[i, 1] += kr * u[i] * rr[1] - d1
            ar[i, 2] += kr * u[i] * rr[2] - d2
    return -cr * un * ux, -cr * un * uy, -cr * un * uz


@jit
def _rtn_axes(y: Array, r: float) -> tuple[tuple[float, float, float],
                                          tuple[float, float, float],
                                          tuple[float, float, float]]:
    """Return the radial, transverse and normal unit vectors (GCRF) of the state ``y``."""
    x, yy, zz = y[0], y[1], y[2]
    vx, vy, vz = y[3], y[4], y[5]
    hx, hy, hz = yy * vz - zz * vy, zz * vx - x * vz, x * vy - yy * vx
    hn = math.sqrt(hx * hx + hy * hy + hz * hz)
    rh = (x / r, yy / r, zz / r)
    nh = (hx / hn, hy / hn, hz / hn)
    th = (nh[1] * rh[2] - nh[2] * rh[1], nh[2] * rh[0] - nh[0] * rh[2],
          nh[0] * rh[1] - nh[1] * rh[0])
    return rh, th, nh


@jit
def _variational(y: Array, ncol: int, ar: Array, av: Array, which: IntArray,
                 axes: tuple[tuple[float, float, float], tuple[float, float, float],
                             tuple[float, float, float], tuple[float, float, float]],
                 out: Array, s: int) -> None:
    """``out[s, 6:]``: the derivative of [Phi | S] (the state's rows 6..).

    ``ar``, ``av`` (3, 3): the acceleration's partials by position and velocity; ``axes``:
    the drag acceleration with k_D = 1 and the radial, transverse, normal unit vectors
    (the sensitivities to the parameters ``which``, `PARAMETERS`).
    """
    for j in range(ncol):
        p0 = y[6 + j]
        p1 = y[6 + ncol + j]
        p2 = y[6 + 2 * ncol + j]
        q0 = y[6 + 3 * ncol + j]
        q1 = y[6 + 4 * ncol + j]
        q2 = y[6 + 5 * ncol + j]
        out[s, 6 + j] = q0
        out[s, 6 + ncol + j] = q1
        out[s, 6 + 2 * ncol + j] = q2
        b0 = b1 = b2 = 0.0
        if j >= 6:
            b0, b1, b2 = axes[which[j - 6]]
        out[s, 6 + 3 * ncol + j] = (ar[0, 0] * p0 + ar[0, 1] * p1 + ar[0, 2] * p2
                                    + av[0, 0] * q0 + av[0, 1] * q1 + av[0, 2] * q2 + b0)
        out[s, 6 + 4 * ncol + j] = (ar[1, 0] * p0 + ar[1, 1] * p1 + ar[1, 2] * p2
                                    + av[1, 0] * q0 + av[1, 1] * q1 + av[1, 2] * q2 + b1)
        out[s, 6 + 5 * ncol + j] = (ar[2, 0] * p0 + ar[2, 1] * p1 + ar[2, 2] * p2
                                    + av[2, 0] * q0 + av[2, 1] * q1 + av[2, 2] * q2 + b2)


@jit
def _force_rhs(y: Array, ncol: int, c: Array, prm: Array, which: IntArray,
               out: Array, s: int) -> None:
    """``out[s] = dy/dt`` of the state + [Phi | S] system ``y`` (6 + 6 ncol,).

    ``c``: `ForceModel.constants`; ``prm`` (4,): the parameters (`PARAMETERS`); ``which``
    (ncol - 6,): the parameters whose sensitivities are the columns 6.. of [Phi | S].
    """
    mu, j2, re = c[0], c[1], c[2]
    px, py, pz = c[3], c[4], c[5]
    x, yy, zz = y[0], y[1], y[2]
    r = math.sqrt(x * x + yy * yy + zz * zz)
    ax, ay, az, g00, g01, g02, g11, g12, g22 = j2_gravity(x, yy, zz, mu, j2, re, px, py, pz)
    # gravity gradient (symmetric), row-major in a 3x3 array of the position partials
    ar = np.empty((3, 3))
    av = np.zeros((3, 3))
    ar[0, 0], ar[1, 1], ar[2, 2] = g00, g11, g22
    ar[0, 1] = ar[1, 0] = g01
    ar[0, 2] = ar[2, 0] = g02
    ar[1, 2] = ar[2, 1] = g12
    j3, j4 = c[12], c[13]
    if j3 != 0.0 or j4 != 0.0:
        bx, by, bz = _zonal34(x, yy, zz, mu, re, j3, j4, px, py, pz)
        ax += bx
        ay += by
        az += bz
        if ncol:
            _zonal34_gradient(ar, x, yy, zz, mu, re, j3, j4, px, py, pz)
    anx = any_ = anz = 0.0  # the drag acceleration with k_D = 1
    if c[6] != 0.0:
        kd = prm[0]
        om = c[11]
        anx, any_, anz = drag_terms(x, yy, zz, y[3], y[4], y[5], om * px, om * py, om * pz,
                                    c[8], c[2], c[9], c[10], c[7], kd, ar, av, True)
        ax += kd * anx
        ay += kd * any_
        az += kd * anz
    rh, th, nh = _rtn_axes(y, r)
    for i in range(3):
        ax_i = prm[1] * rh[i] + prm[2] * th[i] + prm[3] * nh[i]
        if i == 0:
            ax += ax_i
        elif i == 1:
            ay += ax_i
        else:
            az += ax_i
    out[s, 0], out[s, 1], out[s, 2] = y[3], y[4], y[5]
    out[s, 3], out[s, 4], out[s, 5] = ax, ay, az
    _variational(y, ncol, ar, av, which, ((anx, any_, anz), rh, th, nh), out, s)


@jit
def _trajectory_kernel(x0: Array, dts: Array, max_step: float, c: Array, prm: Array,
                       which: IntArray, A: Array, B: Array, xs: Array, ys: Array,
                       ok: BoolArray) -> None:
    """Integrate ``x0`` over the consecutive steps ``dts`` (K,), storing after each one.

    ``xs`` (K, 6) the states, ``ys`` (K, 6, ncol) the cumulative [Phi | S] (ncol = 6 +
    len(which)), ``ok`` (K,) False from the first non-finite value on (nothing is integrated
    after it). Each step of length dt takes ``ceil(|dt| / max_step)`` equal DOP853 steps
    (tableau ``A``, ``B``), as `propagation._gravity_stm_kernel` does.
    """
    ncol = 6 + which.shape[0]
    ny = 6 + 6 * ncol
    ns = B.shape[0]
    y = np.zeros(ny)
    yt = np.empty(ny)
    K = np.empty((ns, ny))
    for i in range(6):
        y[i] = x0[i]
        y[6 + i * ncol + i] = 1.0
    good = True
    for kk in range(dts.shape[0]):
        dt = dts[kk]
        steps, h = output_steps(dt, max_step, good)
        for _ in range(steps):
            _force_rhs(y, ncol, c, prm, which, K, 0)
            for s in range(1, ns):
                rk_stage(y, h, A, K, s, ny, yt, False)
                _force_rhs(yt, ncol, c, prm, which, K, s)
            rk_advance(y, h, B, K, ny, yt, False)
        good = store_output(y, ncol, dt, good, kk, xs, ys)
        ok[kk] = good


@jit
def output_steps(dt: float, max_step: float, good: bool) -> tuple[int, float]:
    """Return the equal steps (how many, their length, s) to the next output ``dt`` s on.

    ``ceil(|dt| / max_step)`` of them; none once the trajectory is no longer ``good`` or
    ``dt`` is not finite.
    """
    steps = math.ceil(abs(dt) / max_step) if good and dt - dt == 0.0 else 0
    return steps, dt / max(steps, 1)


@jit
def store_output(y: Array, ncol: int, dt: float, good: bool, kk: int, xs: Array,
                 ys: Array) -> bool:
    """Store output ``kk``: the state ``y[:6]`` in ``xs[kk]``, [Phi | S] (6, ncol) in ``ys[kk]``.

    Returns whether the trajectory is still good: it was, ``dt`` is finite and so is
    everything stored.
    """
    nf = 0.0 if good and dt - dt == 0.0 else math.nan
    for q in range(6):
        xs[kk, q] = y[q]
        nf += y[q] - y[q]
    for i in range(6 if ncol else 0):
        for j in range(ncol):
            v = y[6 + i * ncol + j]
            ys[kk, i, j] = v
            nf += v - v
    return nf == 0.0


@dataclass
class Trajectory:
    """States, state transition matrices and parameter sensitivities at output epochs.

    Attributes
    ----------
    t : ndarray (K,)
        The epochs, s (as asked, in their order).
    x : ndarray (K, 6)
        GCRF states, km, km/s.
    phi : ndarray (K, 6, 6)
        ``d x(t_k) / d x(t0)``.
    s : ndarray (K, 6, P)
        ``d x(t_k) / d p`` of the selected parameters (km per unit of each: per unit drag
        factor, per km/s^2).
    ok : ndarray (K,) of bool
        False where the integration gave non-finite values (or did not reach the epoch).
    """

    t: Array
    x: Array
    phi: Array
    s: Array
    ok: BoolArray


def trajectory(force: ForceModel | ForceSpec, x0: ArrayLike, t0: float, t: ArrayLike,
               params: ArrayLike = NOMINAL, which: Sequence[int] = (),
               max_step_s: float = 60.0, pole: ArrayLike | None = None) -> Trajectory:
    """Integrate ``x0`` (at ``t0``) to the epochs ``t`` with Phi and the sensitivities.

    The epochs after ``t0`` are integrated in one compiled call in increasing order, those
    before it in another in decreasing order (module docstring): the cost is that of the
    longest arc either side, whatever the number of epochs.

    Parameters
    ----------
    force : ForceModel or force_spec.ForceSpec
        The force model. A `force_spec.ForceSpec` (geopotential, Sun, Moon, SRP...) is
        integrated by `high_fidelity.propagate` with the parameters given here (k_R = 1):
        its epochs must then be Unix s UTC, and ``pole`` is not used.
    x0 : array_like (6,)
        GCRF state at ``t0``, km, km/s.
    t0 : float
        Its epoch, s.
    t : array_like (K,)
        Output epochs, s (any order, repeats allowed).
    params : array_like (5,) or (4,)
        The parameters (`PARAMETERS` order; `NOMINAL` by default; ``srp_scale`` unused).
    which : sequence of int
        Indices in `PARAMETERS` of the parameters whose sensitivities are wanted.
    max_step_s : float
        Longest integration step, s.
    pole : array_like (3,), optional
        The Earth's pole (GCRF unit vector) about which J2 and the atmosphere act.

    Returns
    -------
    Trajectory
    """
    if not isinstance(force, ForceModel):
        from ssa_fusion.core.motion import high_fidelity

        return high_fidelity.propagate(force, x0, t0, t, params, which, max_step_s)
    tt = np.atleast_1d(np.asarray(t, dtype=float))
    x = f64(np.asarray(x0, dtype=float).reshape(6).copy())
    c = f64(force.constants(pole))
    prm = f64(np.asarray(params, dtype=float).reshape(-1)[:4].copy())
    wh = np.ascontiguousarray(np.asarray(which, dtype=np.int64).reshape(-1))
    if np.any(wh >= 4):
        raise ValueError("srp_scale needs the high-fidelity model with SRP (force_spec)")
    A, B = _tableau()
    k = tt.shape[0]
    ncol = 6 + wh.shape[0]
    xs, ys = np.empty((k, 6)), np.empty((k, 6, ncol))
    ok = np.empty(k, dtype=np.bool_)
    dt = tt - float(t0)
    for side in (dt >= 0.0, dt < 0.0):
        idx = np.flatnonzero(side)
        if not idx.size:
            continue
        order = idx[np.argsort(np.abs(dt[idx]), kind="stable")]
        d = dt[order]
        steps = f64(np.diff(d, prepend=0.0))
        xo, yo = np.empty((order.size, 6)), np.empty((order.size, 6, ncol))
        oko = np.empty(order.size, dtype=np.bool_)
        _trajectory_kernel(x, steps, float(max_step_s), c, prm, wh, A, B, xo, yo, oko)
        xs[order], ys[order], ok[order] = xo, yo, oko
    return Trajectory(tt, xs, ys[:, :, :6].copy(), ys[:, :, 6:].copy(), ok)


def acceleration(force: ForceModel, x: ArrayLike, params: ArrayLike = NOMINAL,
                 pole: ArrayLike | None = None) -> Array:
    """Return the acceleration (3,) km/s^2 of GCRF state ``x`` (6,) (module docstring).

    Parameters
    ----------
    force : ForceModel
        The force model.
    x : array_like (6,)
        GCRF state, km, km/s.
    params : array_like (5,) or (4,)
        The parameters (`PARAMETERS` order).
    pole : array_like (3,), optional
        The Earth's pole (GCRF unit vector).

    Returns
    -------
    ndarray (3,)
    """
    y = np.zeros(42)
    y[:6] = np.asarray(x, dtype=float).reshape(6)
    out = np.empty((1, 42))
    _force_rhs(y, 6, f64(force.constants(pole)),
               f64(np.asarray(params, dtype=float).reshape(-1)[:4].copy()),
               np.zeros(0, dtype=np.int64), out, 0)
    acc: Array = out[0, 3:6].copy()
    return acc
