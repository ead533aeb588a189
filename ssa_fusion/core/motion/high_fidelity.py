"""Propagation with the high-fidelity force model, the STM and the parameter sensitivities.

`propagate` integrates one GCRF state under a `force_spec.ForceSpec` (geopotential N x M,
Sun, Moon, solar radiation pressure, drag, RTN empirical accelerations) to many epochs, with
the state transition matrix ``Phi = d x(t) / d x(t0)`` and the sensitivities
``S = d x(t) / d p`` to selected parameters (`force_spec.PARAMETERS`), in one compiled call
per side of the epoch (`force_kernel.full_rhs` at every stage: the Earth's orientation, the
DE421 series and the harmonics evaluated inside). It returns `force_model.Trajectory`, as
the J2 model's `force_model.trajectory`, so an orbit fit takes either.

Integration: the fixed-step 8th-order Dormand-Prince tableau of `propagation` (scipy's
DOP853), ``ceil(|dt| / max_step_s)`` equal steps between consecutive output epochs, the
force evaluated at each stage's own time (the model depends on time). With 60 s steps the
truncation error is ~1e-10 relative a day in LEO. A step across a shadow boundary (where
solar radiation pressure switches off within ~10 s, not smoothly) is taken again as
`SHADOW_SUBSTEPS` shorter ones.

Drag's density is the exponential atmosphere's of the spec, or that times a factor tabulated in
time (`DensityTable`: a real atmosphere's density along the orbit over the exponential one's).

`setup` precomputes what the kernel reads for one spec and span (`Context`); `propagate`
builds it, or takes one given (many fits over the same span). `derivatives` returns the
acceleration, ``A = d xdot / d x`` and ``B = d xdot / d p`` at one state (tests, the
benchmark's per-call cost).

Units: km, km/s, s; states GCRF; epochs Unix s UTC (elapsed seconds are SI seconds; a span
across a leap second is read as if none were there).
"""

from __future__ import annotations

import functools
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ssa_fusion.core.base.jit import f64, jit
from ssa_fusion.core.earth import eop as eop_
from ssa_fusion.core.earth import frames
from ssa_fusion.core.earth.ephemeris import sun_moon_position, sun_moon_span
from ssa_fusion.core.earth.rotation_grid import rotation_grid
from ssa_fusion.core.motion import force_kernel as fk
from ssa_fusion.core.motion.force_model import Trajectory, output_steps, store_output
from ssa_fusion.core.motion.force_spec import NOMINAL, PARAMETERS, ForceSpec
from ssa_fusion.core.motion.geopotential import GravityField, KernelTables, kernel_tables
from ssa_fusion.core.motion.propagation import _tableau
from ssa_fusion.core.motion.srp import shadow_fraction

__all__ = ["Context", "DensityTable", "derivatives", "propagate", "setup"]

Array = NDArray[np.float64]
IntArray = NDArray[np.int64]
BoolArray = NDArray[np.bool_]

MARGIN_S = 7200.0
"""Span added either side of the epochs when the context is built, s."""

SHADOW_SUBSTEPS = 12
"""Steps a step is cut into when it crosses a shadow boundary (60 s: 5 s through the
penumbra, whose solar radiation pressure is not smooth: 1.6 cm a day in LEO at 60 s
uncut, 0.1 mm at 5 s)."""

Model = tuple[Array, Array, Array, Array, tuple[Array, Array, Array, Array, Array], Array,
              IntArray, Array, Array, Array, Array]
"""The kernel's model arguments: constants, recursion, weights, rotation grid, ephemeris,
parameters, sensitivity columns, harmonics' scratch (2), work, density factor table."""


@dataclass(frozen=True)
class DensityTable:
    """The drag's density as a factor on the exponential atmosphere's, tabulated in time.

    A real atmosphere's density along an orbit (NRLMSISE-00's, say) over the exponential
    model's at the same radius (`force_spec.DragSpec`), at ``t0_unix + k step_s``; linear
    between the nodes, held at the ends (`force_kernel.density_factor`). The factor depends
    on time alone: evaluated along the orbit it is propagated on, it is that atmosphere's
    density there, as long as the orbit moves little against the one it was evaluated on
    (a truth propagated again on the table of its own previous propagation converges).

    Attributes
    ----------
    t0_unix : float
        The first node, Unix s UTC.
    step_s : float
        Between nodes, s.
    factor : ndarray (n,)
        The factors (dimensionless, > 0).
    """

    t0_unix: float
    step_s: float
    factor: Array

    def packed(self, origin_unix: float) -> Array:
        """Return the kernel's table (`force_kernel.density_factor`), times from ``origin_unix``."""
        return f64(np.concatenate([[self.t0_unix - origin_unix, self.step_s],
                                   np.asarray(self.factor, dtype=float)]))


@dataclass(frozen=True)
class Context:
    """What the kernel reads for one spec over one span (`setup`).

    Attributes
    ----------
    spec : ForceSpec
        The forces.
    t0_unix : float
        The origin (Unix s UTC): kernel times are seconds from it.
    span : tuple of float
        First and last epoch covered, s from the origin.
    c : ndarray (N_CONST,)
        The constants (`force_kernel` ``C_*``).
    tables : KernelTables
        The geopotential's.
    grid : ndarray
        `rotation_grid.RotationGrid.packed`.
    eph : tuple of 5 ndarrays
        The DE421 series of the Sun, barycentre and Moon, their starts and lengths.
    density : ndarray
        The density factor's table, times from the origin (`DensityTable.packed`;
        `force_kernel.NO_DENSITY_TABLE`: none).
    """

    spec: ForceSpec
    t0_unix: float
    span: tuple[float, float]
    c: Array
    tables: KernelTables
    grid: Array
    eph: tuple[Array, Array, Array, Array, Array]
    density: Array = field(default_factory=lambda: fk.NO_DENSITY_TABLE)

    def covers(self, t_unix: ArrayLike) -> bool:
        """Return True when every epoch (Unix s) is inside the context's span."""
        d = np.asarray(t_unix, dtype=float) - self.t0_unix
        return bool(d.size == 0 or (d.min() >= self.span[0] and d.max() <= self.span[1]))


@functools.lru_cache(maxsize=16)
def _tables(gravity: GravityField, degree: int, order: int) -> KernelTables:
    return kernel_tables(gravity, degree, order)


def setup(spec: ForceSpec, t0_unix: float, t_min_s: float = 0.0, t_max_s: float = 0.0,
          eop: eop_.EarthOrientation | None = None,
          density: DensityTable | None = None) -> Context:
    """Return the kernel's context for ``spec`` over ``t0_unix + [t_min_s, t_max_s]``.

    The span is widened by `MARGIN_S` each side. The atmosphere co-rotates about the
    Earth's pole at ``t0_unix`` (`frames.pole_frame`); its density is the exponential
    model's times ``density``'s factor (None: 1).
    """
    lo, hi = float(t_min_s) - MARGIN_S, float(t_max_s) + MARGIN_S
    deg, order = spec.truncation
    tables = _tables(spec.gravity, deg, order)
    pole = frames.pole_frame(float(t0_unix), eop)[2]
    c = spec.constants(pole)
    c[fk.C_RADIUS], c[fk.C_DEGREE], c[fk.C_ORDER] = spec.gravity.radius, deg, order
    span = sun_moon_span(float(t0_unix), lo, hi)
    c[fk.C_EARTH_SHARE], c[fk.C_GM_SUN], c[fk.C_GM_MOON] = (span.earth_share, span.gm_sun,
                                                            span.gm_moon)
    grid = rotation_grid(float(t0_unix), lo, hi, eop).packed()
    eph = (*span.coefficients, f64(span.starts), f64(span.lengths))
    dens = fk.NO_DENSITY_TABLE if density is None else density.packed(float(t0_unix))
    return Context(spec, float(t0_unix), (lo, hi), f64(c), tables, grid,
                   (eph[0], eph[1], eph[2], eph[3], eph[4]), dens)


@jit
def _stage_sum(y: Array, K: Array, A: Array, s: int, h: float, out: Array) -> None:
    """``out = y + h sum_j A[s, j] K[j]`` over the stages before ``s``."""
    n = y.shape[0]
    for q in range(n):
        out[q] = 0.0
    for j in range(s):
        a = A[s, j]
        if a == 0.0:
            continue
        for q in range(n):
            out[q] += a * K[j, q]
    for q in range(n):
        out[q] = y[q] + h * out[q]


@jit
def _step(y: Array, t: float, h: float, ncol: int, A: Array, B: Array, C: Array, K: Array,
          yt: Array, yn: Array, model: Model) -> None:
    """One DOP853 step of length ``h`` from ``y`` at ``t``: ``yn`` the state after it."""
    c, rec, wt, grid, eph, prm, which, v, w, work, dens = model
    for s in range(B.shape[0]):
        _stage_sum(y, K, A, s, h, yt)
        fk.full_rhs(t + C[s] * h, yt, ncol, c, rec, wt, grid, eph, prm, which, dens, v, w,
                    work, K, s)
    yn[:] = y
    for j in range(B.shape[0]):
        b = B[j] * h
        if b != 0.0:
            for q in range(y.shape[0]):
                yn[q] += b * K[j, q]


@jit
def _shadow_crossed(y: Array, yn: Array, t: float, h: float, model: Model) -> bool:
    """Whether solar radiation pressure's shadow fraction is not the same 0 or 1 at both ends."""
    c, eph, work = model[0], model[4], model[9]
    if c[fk.C_SRP] == 0.0:
        return False
    sun, emb, moon, starts, lengths = eph
    nu0 = nu1 = 0.0
    for i in range(2):
        b = work[40:46]
        sun_moon_position(sun, emb, moon, starts, lengths, c[fk.C_EARTH_SHARE], t + i * h, b)
        z = y if i == 0 else yn
        nu = shadow_fraction(z[0], z[1], z[2], b[0], b[1], b[2], c[fk.C_SUN_RADIUS],
                             c[fk.C_SHADOW_RADIUS])
        if i == 0:
            nu0 = nu
        else:
            nu1 = nu
    return nu0 != nu1 or 0.0 < nu0 < 1.0 or 0.0 < nu1 < 1.0


@jit
def _kernel(x0: Array, dts: Array, max_step: float, model: Model, A: Array, B: Array,
            C: Array, xs: Array, ys: Array, ok: BoolArray) -> None:
    """Integrate ``x0`` (at t = 0) over the consecutive steps ``dts``, storing after each.

    As `force_model._trajectory_kernel`: ``xs`` (K, 6), ``ys`` (K, 6, ncol) the cumulative
    [Phi | S], ``ok`` False from the first non-finite value on; stage s at ``t + C[s] h``. A
    step across a shadow boundary is taken again as `SHADOW_SUBSTEPS` steps.
    """
    ncol = 6 + model[6].shape[0] if ys.shape[2] > 0 else 0
    ny = 6 + 6 * ncol
    y, yt, yn, K = np.zeros(ny), np.empty(ny), np.empty(ny), np.empty((B.shape[0], ny))
    y[:6] = x0
    for i in range(6 if ncol else 0):
        y[6 + i * ncol + i] = 1.0
    t = 0.0
    good = True
    for kk in range(dts.shape[0]):
        dt = dts[kk]
        steps, h = output_steps(dt, max_step, good)
        for _ in range(steps):
            _step(y, t, h, ncol, A, B, C, K, yt, yn, model)
            if _shadow_crossed(y, yn, t, h, model):
                hs = h / SHADOW_SUBSTEPS
                for k in range(SHADOW_SUBSTEPS):
                    _step(y, t + k * hs, hs, ncol, A, B, C, K, yt, yn, model)
                    y[:] = yn
            else:
                y[:] = yn
            t += h
        good = store_output(y, ncol, dt, good, kk, xs, ys)
        ok[kk] = good


@functools.cache
def _dop853() -> tuple[Array, Array, Array]:
    """Return the DOP853 tableau of `propagation` (A, B) and its nodes C = row sums of A."""
    A, B = _tableau()
    return A, B, np.ascontiguousarray(A.sum(axis=1))


def _params(params: ArrayLike | None) -> Array:
    """Return the parameters (5,) in `PARAMETERS` order; 4 given (`force_model`'s): k_R = 1."""
    p = np.asarray(NOMINAL if params is None else params, dtype=float).reshape(-1)
    if p.size == len(PARAMETERS) - 1:
        p = np.append(p, 1.0)
    if p.size != len(PARAMETERS):
        raise ValueError(f"{p.size} parameters given: {len(PARAMETERS)} expected "
                         f"({', '.join(PARAMETERS)})")
    return f64(p.copy())


def propagate(spec: ForceSpec | Context, x0: ArrayLike, t0_unix: float, t_unix: ArrayLike,
              params: ArrayLike | None = None, which: Sequence[int] = (),
              max_step_s: float = 60.0, eop: eop_.EarthOrientation | None = None,
              stm: bool = True) -> Trajectory:
    """Integrate ``x0`` (GCRF, at ``t0_unix``) to the epochs ``t_unix``, with Phi and S.

    Parameters
    ----------
    spec : ForceSpec or Context
        The forces (or a context from `setup` whose span covers the epochs).
    x0 : array_like (6,)
        GCRF state, km, km/s.
    t0_unix : float
        Its epoch, Unix s UTC.
    t_unix : array_like (K,)
        Output epochs, Unix s UTC (any order, either side of ``t0_unix``; a non-finite one
        gets NaN and ``ok`` False).
    params : array_like (5,) or (4,), optional
        The parameters (`force_spec.PARAMETERS`; 4: `force_model.PARAMETERS`, k_R = 1).
    which : sequence of int
        Indices in `force_spec.PARAMETERS` of the parameters whose sensitivities are wanted.
    max_step_s : float
        Longest integration step, s.
    eop : EarthOrientation, optional
        The EOP (default `eop.default()`).
    stm : bool
        False: the states alone (``phi`` and ``s`` of the result are NaN).

    Returns
    -------
    force_model.Trajectory
    """
    tt = np.atleast_1d(np.asarray(t_unix, dtype=float))
    dt = tt - float(t0_unix)
    fin = np.isfinite(dt)  # a non-finite epoch is not integrated: ok False there
    ctx = spec if isinstance(spec, Context) else setup(
        spec, float(t0_unix), float(dt[fin].min(initial=0.0)), float(dt[fin].max(initial=0.0)),
        eop)
    if not ctx.covers(tt[fin]) or not ctx.covers([t0_unix]):
        raise ValueError("the context does not cover the epochs: build it with setup()")
    x = f64(np.asarray(x0, dtype=float).reshape(6).copy())
    wh = np.ascontiguousarray(np.asarray(which, dtype=np.int64).reshape(-1))
    ncol = 6 + wh.size
    A, B, C = _dop853()
    xs, ys = np.full((tt.size, 6), np.nan), np.full((tt.size, 6, ncol), np.nan)
    ok = np.zeros(tt.size, dtype=np.bool_)
    shift = float(t0_unix) - ctx.t0_unix
    for side in (fin & (dt >= 0.0), fin & (dt < 0.0)):
        idx = np.flatnonzero(side)
        if not idx.size:
            continue
        order = idx[np.argsort(np.abs(dt[idx]), kind="stable")]
        steps = f64(np.diff(dt[order], prepend=0.0))
        xo, yo = np.empty((order.size, 6)), np.empty((order.size, 6, ncol if stm else 0))
        oko = np.empty(order.size, dtype=np.bool_)
        c = ctx.c
        grid = _shifted(ctx.grid, shift)
        eph = (*ctx.eph[:3], f64(ctx.eph[3] - shift), ctx.eph[4])
        nn, mm = ctx.tables.degree + 3, ctx.tables.order + 3
        dens = ctx.density.copy()
        if dens.size > 2:
            dens[0] -= shift
        model = (c, ctx.tables.rec, ctx.tables.weights, grid, eph, _params(params), wh,
                 np.zeros((nn, mm)), np.zeros((nn, mm)), np.zeros(fk.WORK), f64(dens))
        _kernel(x, steps, float(max_step_s), model, A, B, C, xo, yo, oko)
        xs[order], ok[order] = xo, oko
        if stm:
            ys[order] = yo
    return Trajectory(tt, xs, ys[:, :, :6].copy(), ys[:, :, 6:].copy(), ok)


def _shifted(grid: Array, shift: float) -> Array:
    """Return the packed rotation grid with its origin moved ``shift`` s later (ERA kept exact)."""
    if shift == 0.0:
        return grid
    g = grid.copy()
    g[0] -= shift
    g[2] += frames.ERA_RATE * shift  # ERA's origin term; dUT1's reference d0 unchanged
    return f64(g)


def derivatives(spec: ForceSpec | Context, x: ArrayLike, t_unix: float,
                params: ArrayLike | None = None,
                which: Sequence[int] = ()) -> tuple[Array, Array, Array]:
    """Return (xdot (6,), A (6, 6), B (6, P)) of the GCRF state ``x`` at ``t_unix``.

    ``A = d xdot / d x`` and ``B = d xdot / d p`` of the parameters ``which`` as the
    variational equations use them (the kernel's analytic partials).
    """
    ctx = spec if isinstance(spec, Context) else setup(spec, float(t_unix))
    wh = np.ascontiguousarray(np.asarray(which, dtype=np.int64).reshape(-1))
    ncol = 6 + wh.size
    y = np.zeros(6 + 6 * ncol)
    y[:6] = np.asarray(x, dtype=float).reshape(6)
    for i in range(6):
        y[6 + i * ncol + i] = 1.0
    out = np.zeros((1, y.size))
    nn, mm = ctx.tables.degree + 3, ctx.tables.order + 3
    fk.full_rhs(float(t_unix) - ctx.t0_unix, y, ncol, ctx.c, ctx.tables.rec,
                ctx.tables.weights, ctx.grid, ctx.eph, _params(params), wh, ctx.density,
                np.zeros((nn, mm)), np.zeros((nn, mm)), np.zeros(fk.WORK), out, 0)
    m = out[0, 6:].reshape(6, ncol)
    return out[0, :6].copy(), m[:, :6].copy(), m[:, 6:].copy()
