"""The high-fidelity force model's right-hand side with its variational equations, compiled.

`full_rhs` evaluates, at ``t`` s from the propagation's origin, the derivative of the state
and of ``[Phi | S]`` (the state transition matrix and the parameter sensitivities, as
`force_model`'s kernel: ``d/dt [Phi | S] = A [Phi | S] + [0 | B]``, ``A = [[0, I], [G, D_v]]``)
for the forces of a `force_spec.ForceSpec`:

* geopotential (`geopotential`): ``M`` the GCRF -> ITRF matrix at t (`rotation_grid`),
  ``a = M^T a_ITRF(M r)`` and ``G = M^T G_ITRF M`` (the rotation's own rate does not enter
  an acceleration that depends on position only);
* Sun and Moon (`ephemeris`, DE421 evaluated here), point masses with the indirect term::

      a = GM ((r_b - r) / |r_b - r|^3 - r_b / |r_b|^3),   G = GM (3 d d^T / |d|^5 - I / |d|^3)

  (``d = r - r_b``);
* solid Earth tides of degree 2 raised by the Sun and the Moon (`force_spec.ForceSpec`'s
  ``solid_tides``): the potential ``k2 GM_b R^5 / (r_b^3 r^3) P2(u)`` of the deformed Earth
  (u the cosine between r and the body, k2 one Love number for every order: IERS
  Conventions 2010 section 6.2, step 1, frequency-independent), whose gradient is::

      a = 3 k2 GM_b R^5 / (r_b^3 r^4) (u r_b / |r_b| + (1/2 - 5/2 u^2) r / |r|)

  frame-free (the bulge points at the body), so evaluated in the GCRF; its own gradient is
  left out of the variational equations (~1e-8 of the central term's);
* solar radiation pressure (`srp`), its sensitivity to ``srp_scale`` the acceleration itself;
* drag in the co-rotating exponential atmosphere, the formula and analytic partials of
  `force_model` (drag factor k_D), its density times a factor tabulated in time when one is
  given (`density_factor`: a real atmosphere's density along an orbit over the exponential
  one's, the same at every position at one time, so the partials keep their form);
* RTN empirical accelerations (their axes' dependence on the state left out, as in
  `force_model`).

Everything (the Earth's orientation, the ephemeris, the harmonics) is computed inside: one
call per stage, no Python. The constants ``c`` are `force_spec.ForceSpec.constants` with the
field's radius, truncation and the bodies' GM filled in (`C_*` indices below).

Units: km, km/s, km/s^2, s; GCRF.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from ssa_fusion.core.base.jit import jit
from ssa_fusion.core.earth.ephemeris import sun_moon_position
from ssa_fusion.core.earth.rotation_grid import gcrs_to_itrs_at
from ssa_fusion.core.motion.force_model import drag_terms
from ssa_fusion.core.motion.geopotential import geopotential_acceleration
from ssa_fusion.core.motion.srp import shadow_fraction

__all__ = ["NO_DENSITY_TABLE", "density_factor", "full_rhs"]

Array = NDArray[np.float64]
IntArray = NDArray[np.int64]

C_SUN, C_MOON, C_SRP, C_SRP_K, C_SUN_RADIUS, C_SHADOW_RADIUS = 0, 1, 2, 3, 4, 5
C_DRAG, C_DRAG_K, C_RHO0, C_H0, C_SCALE_H, C_OMEGA, C_POLE, C_DRAG_RE = 6, 7, 8, 9, 10, 11, 12, 15
C_RADIUS, C_DEGREE, C_ORDER, C_EARTH_SHARE, C_GM_SUN, C_GM_MOON = 16, 17, 18, 19, 20, 21
C_TIDE_K2 = 22
"""Indices of the constants array (`force_spec.ForceSpec.constants` and the propagator's)."""

WORK = 48
"""Length of the scratch array of `full_rhs`."""

NO_DENSITY_TABLE = np.zeros(2)
"""The density table of no table: the factor is 1 at every time."""


@jit
def density_factor(table: Array, t: float) -> float:
    """Return the density factor at ``t`` (s from the origin) of ``table``, linear in time.

    ``table = [t_first, step, f_0, ..., f_{n-1}]`` (s, s, dimensionless), the factor at
    ``t_first + k step``; held at its end values outside; 1 for a table of no node
    (`NO_DENSITY_TABLE`).
    """
    n = table.shape[0] - 2
    if n < 1:
        return 1.0
    u = (t - table[0]) / table[1]
    if u <= 0.0:
        return float(table[2])
    if u >= n - 1:
        return float(table[n + 1])
    k = int(u)
    f = u - k
    return float((1.0 - f) * table[2 + k] + f * table[3 + k])


@jit
def _gravity(t: float, x: float, y: float, z: float, c: Array, rec: Array, wt: Array,
             grid: Array, v: Array, w: Array, work: Array, ar: Array,
             gradient: bool) -> tuple[float, float, float]:
    """Geopotential acceleration (GCRF) at t; with ``gradient``, its gradient added to ``ar``."""
    m = work[0:9]
    g = work[9:28]
    gcrs_to_itrs_at(grid, t, m)
    px = m[0] * x + m[1] * y + m[2] * z
    py = m[3] * x + m[4] * y + m[5] * z
    pz = m[6] * x + m[7] * y + m[8] * z
    geopotential_acceleration(px, py, pz, c[C_RADIUS], int(c[C_DEGREE]), int(c[C_ORDER]),
                              rec, wt, gradient, v, w, g)
    ax = m[0] * g[0] + m[3] * g[1] + m[6] * g[2]
    ay = m[1] * g[0] + m[4] * g[1] + m[7] * g[2]
    az = m[2] * g[0] + m[5] * g[1] + m[8] * g[2]
    if gradient:
        ge = ((g[3], g[4], g[5]), (g[4], g[6], g[7]), (g[5], g[7], g[8]))
        gm = work[28:37]  # G_ITRF M
        for i in range(3):
            for j in range(3):
                gm[3 * i + j] = ge[i][0] * m[j] + ge[i][1] * m[3 + j] + ge[i][2] * m[6 + j]
        for i in range(3):
            for j in range(3):
                ar[i, j] += m[i] * gm[j] + m[3 + i] * gm[3 + j] + m[6 + i] * gm[6 + j]
    return ax, ay, az


@jit
def _point_mass(gm: float, bx: float, by: float, bz: float, x: float, y: float, z: float,
                ar: Array, gradient: bool) -> tuple[float, float, float]:
    """Third-body acceleration of a point mass at (bx, by, bz), with the indirect term."""
    dx, dy, dz = x - bx, y - by, z - bz
    d2 = dx * dx + dy * dy + dz * dz
    d = math.sqrt(d2)
    kd = gm / (d2 * d)
    b2 = bx * bx + by * by + bz * bz
    kb = gm / (b2 * math.sqrt(b2))
    if gradient:
        dv = (dx, dy, dz)
        k5 = 3.0 * kd / d2
        for i in range(3):
            ar[i, i] -= kd
            for j in range(3):
                ar[i, j] += k5 * dv[i] * dv[j]
    return -kd * dx - kb * bx, -kd * dy - kb * by, -kd * dz - kb * bz


@jit
def _tide(k2: float, gm: float, re: float, bx: float, by: float, bz: float, x: float,
          y: float, z: float) -> tuple[float, float, float]:
    """Acceleration of the solid tide of degree 2 raised by a body at (bx, by, bz) (above)."""
    rb = math.sqrt(bx * bx + by * by + bz * bz)
    r = math.sqrt(x * x + y * y + z * z)
    u = (x * bx + y * by + z * bz) / (r * rb)
    k = 3.0 * k2 * gm * re**5 / (rb**3 * r**4)
    kr = k * (0.5 - 2.5 * u * u) / r
    kb = k * u / rb
    return kr * x + kb * bx, kr * y + kb * by, kr * z + kb * bz


@jit
def _srp(x: float, y: float, z: float, sx: float, sy: float, sz: float, c: Array,
         scale: float, ar: Array, gradient: bool) -> tuple[float, float, float]:
    """Solar radiation pressure per unit ``srp_scale`` (`srp`); ``scale`` k_R into ``ar``."""
    nu = shadow_fraction(x, y, z, sx, sy, sz, c[C_SUN_RADIUS], c[C_SHADOW_RADIUS])
    if nu == 0.0:
        return 0.0, 0.0, 0.0
    dx, dy, dz = x - sx, y - sy, z - sz
    d2 = dx * dx + dy * dy + dz * dz
    k = nu * c[C_SRP_K] / (d2 * math.sqrt(d2))
    if gradient:
        dv = (dx, dy, dz)
        ks = k * scale
        for i in range(3):
            ar[i, i] += ks
            for j in range(3):
                ar[i, j] -= 3.0 * ks * dv[i] * dv[j] / d2
    return k * dx, k * dy, k * dz


@jit
def _rtn(y: Array) -> tuple[float, float, float, float, float, float, float, float, float]:
    """Return the unit R, T, N axes of the state ``y[:6]``, nine floats."""
    x, yy, zz, vx, vy, vz = y[0], y[1], y[2], y[3], y[4], y[5]
    r = math.sqrt(x * x + yy * yy + zz * zz)
    hx, hy, hz = yy * vz - zz * vy, zz * vx - x * vz, x * vy - yy * vx
    hn = math.sqrt(hx * hx + hy * hy + hz * hz)
    rx, ry, rz = x / r, yy / r, zz / r
    nx, ny, nz = hx / hn, hy / hn, hz / hn
    return rx, ry, rz, ny * rz - nz * ry, nz * rx - nx * rz, nx * ry - ny * rx, nx, ny, nz


@jit
def _accelerations(t: float, y: Array, c: Array, rec: Array, wt: Array, grid: Array,
                   eph: tuple[Array, Array, Array, Array, Array], prm: Array, dens: Array,
                   v: Array, w: Array, work: Array, ar: Array, av: Array, sens: Array,
                   gradient: bool) -> tuple[float, float, float]:
    """Total acceleration; ``sens[p]`` the partial of each parameter p (`force_spec` order)."""
    x, yy, zz = y[0], y[1], y[2]
    ax, ay, az = _gravity(t, x, yy, zz, c, rec, wt, grid, v, w, work, ar, gradient)
    if c[C_SUN] != 0.0 or c[C_MOON] != 0.0 or c[C_SRP] != 0.0 or c[C_TIDE_K2] != 0.0:
        bodies = work[40:46]
        sun, emb, moon, starts, lengths = eph
        sun_moon_position(sun, emb, moon, starts, lengths, c[C_EARTH_SHARE], t, bodies)
        if c[C_SUN] != 0.0:
            bx, by, bz = _point_mass(c[C_GM_SUN], bodies[0], bodies[1], bodies[2], x, yy,
                                     zz, ar, gradient)
            ax, ay, az = ax + bx, ay + by, az + bz
        if c[C_MOON] != 0.0:
            bx, by, bz = _point_mass(c[C_GM_MOON], bodies[3], bodies[4], bodies[5], x, yy,
                                     zz, ar, gradient)
            ax, ay, az = ax + bx, ay + by, az + bz
        if c[C_TIDE_K2] != 0.0:
            for b in range(2):
                bx, by, bz = _tide(c[C_TIDE_K2], c[C_GM_SUN] if b == 0 else c[C_GM_MOON],
                                   c[C_RADIUS], bodies[3 * b], bodies[3 * b + 1],
                                   bodies[3 * b + 2], x, yy, zz)
                ax, ay, az = ax + bx, ay + by, az + bz
        if c[C_SRP] != 0.0:
            bx, by, bz = _srp(x, yy, zz, bodies[0], bodies[1], bodies[2], c, prm[4], ar,
                              gradient)
            sens[4, 0], sens[4, 1], sens[4, 2] = bx, by, bz
            ax, ay, az = ax + prm[4] * bx, ay + prm[4] * by, az + prm[4] * bz
    if c[C_DRAG] != 0.0:
        om = c[C_OMEGA]
        bx, by, bz = drag_terms(x, yy, zz, y[3], y[4], y[5], om * c[C_POLE],
                                om * c[C_POLE + 1], om * c[C_POLE + 2],
                                density_factor(dens, t) * c[C_RHO0], c[C_DRAG_RE], c[C_H0],
                                c[C_SCALE_H], c[C_DRAG_K], prm[0], ar, av, gradient)
        sens[0, 0], sens[0, 1], sens[0, 2] = bx, by, bz
        ax, ay, az = ax + prm[0] * bx, ay + prm[0] * by, az + prm[0] * bz
    e = _rtn(y)
    for k in range(3):
        sens[1 + k, 0], sens[1 + k, 1], sens[1 + k, 2] = e[3 * k], e[3 * k + 1], e[3 * k + 2]
        ax += prm[1 + k] * e[3 * k]
        ay += prm[1 + k] * e[3 * k + 1]
        az += prm[1 + k] * e[3 * k + 2]
    return ax, ay, az


@jit
def full_rhs(t: float, y: Array, ncol: int, c: Array, rec: Array, wt: Array, grid: Array,
             eph: tuple[Array, Array, Array, Array, Array], prm: Array, which: IntArray,
             dens: Array, v: Array, w: Array, work: Array, out: Array, s: int) -> None:
    """``out[s] = dy/dt`` of the state + [Phi | S] system ``y`` (6 + 6 ncol,) at ``t``.

    ``c``: the constants (`C_*`); ``rec``, ``wt``: `geopotential.KernelTables`; ``grid``:
    `rotation_grid.RotationGrid.packed`; ``eph``: the `ephemeris.SunMoonSpan` series and
    their starts and lengths; ``prm`` (5,): the parameters (`force_spec.PARAMETERS`);
    ``which``: the parameters of the columns 6.. of [Phi | S]; ``dens``: the density factor's
    table (`density_factor`); ``v``, ``w``: the harmonics' scratch arrays; ``work``
    (`WORK`,) scratch. ``ncol`` 0: the state alone.
    """
    ar = np.zeros((3, 3))
    av = np.zeros((3, 3))
    sens = np.zeros((5, 3))
    ax, ay, az = _accelerations(t, y, c, rec, wt, grid, eph, prm, dens, v, w, work, ar, av,
                                sens, ncol > 0)
    out[s, 0], out[s, 1], out[s, 2] = y[3], y[4], y[5]
    out[s, 3], out[s, 4], out[s, 5] = ax, ay, az
    for j in range(ncol):
        p0, p1, p2 = y[6 + j], y[6 + ncol + j], y[6 + 2 * ncol + j]
        q0, q1, q2 = y[6 + 3 * ncol + j], y[6 + 4 * ncol + j], y[6 + 5 * ncol + j]
        out[s, 6 + j] = q0
        out[s, 6 + ncol + j] = q1
        out[s, 6 + 2 * ncol + j] = q2
        b0 = b1 = b2 = 0.0
        if j >= 6:
            p = which[j - 6]
            b0, b1, b2 = sens[p, 0], sens[p, 1], sens[p, 2]
        for i in range(3):
            out[s, 6 + (3 + i) * ncol + j] = (ar[i, 0] * p0 + ar[i, 1] * p1 + ar[i, 2] * p2
                                              + av[i, 0] * q0 + av[i, 1] * q1 + av[i, 2] * q2
                                              + (b0 if i == 0 else b1 if i == 1 else b2))
