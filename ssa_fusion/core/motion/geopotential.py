"""The Earth's geopotential in spherical harmonics: acceleration and gravity gradient, compiled.

The potential of a field of fully normalised coefficients ``C_nm``, ``S_nm`` (`GravityField`,
e.g. EGM96 read by `formats.icgem`) at the Earth-fixed (ITRF) point r::

    U(r) = GM / R  Re sum_{n, m} conj(A_nm) Z_nm(r),   A_nm = C_nm + i S_nm,

with the normalised solid harmonics ``Z_nm = V_nm + i W_nm = N_nm (R / r)^(n+1)
P_nm(sin phi) e^(i m lambda)`` (``N_nm = sqrt((2 - delta_m0)(2n + 1)(n - m)! / (n + m)!)``)
computed by the normalised form of Cunningham's recursions (Montenbruck & Gill 2000, §3.2.4:
sectoral ``Z_mm`` from ``Z_m-1,m-1`` times ``(x + i y) R / r^2``, then ``Z_nm`` from
``Z_n-1,m`` and ``Z_n-2,m``; every factor a ratio of the ``N_nm``, so nothing grows like
``(2n)!``: stable to any degree a file holds).

Derivatives: the unnormalised solid harmonics obey the ladder relations (Cunningham 1970)::

    (d/dx + i d/dy) Z_nm = -Z_n+1,m+1 / R
    (d/dx - i d/dy) Z_nm = (n-m+2)(n-m+1) Z_n+1,m-1 / R
    d/dz Z_nm          = -(n-m+1) Z_n+1,m / R

(for every m, with ``Z_n,-m = (-1)^m (n-m)!/(n+m)! conj(Z_nm)``), so every first and second
derivative of U is a sum of harmonics of degree n + 1 or n + 2 with constant complex weights.
`kernel_tables` computes those weights once per field and truncation (`_WEIGHTS`: the
acceleration's ``D+ U = U_x + i U_y`` and ``U_z``, the gradient's ``D+^2 U``, ``d/dz D+ U``
and ``U_zz``; then ``U_xx = (Re D+^2 U - U_zz) / 2``, ``U_yy = -(Re D+^2 U + U_zz) / 2``,
``U_xy = Im D+^2 U / 2``, ``U_xz + i U_yz = d/dz D+ U``), and the compiled
`geopotential_acceleration` sums them: the acceleration and the full 3x3 gravity gradient
(the variational equations' ``da/dr``) of a degree-and-order-N field cost one recursion to
degree N + 2 (20 x 20: ~3 us).

The n = 0 term is the central attraction ``-GM r / r^3``; a field truncated to degree 2
order 0 is two-body + J2 (``J2 = -sqrt(5) C_20``).

Units: km, km/s^2, 1/s^2; positions and accelerations in the ITRF (Earth-fixed axes);
`GravityField.gm` km^3/s^2, `GravityField.radius` km.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ssa_fusion.core.base.jit import jit

__all__ = ["GravityField", "KernelTables", "geopotential_acceleration", "kernel_tables",
           "potential"]

Array = NDArray[np.float64]

_WEIGHTS = 5
"""Quantities of `KernelTables.weights`: D+U, U_z (acceleration), D+^2 U, d/dz D+ U, U_zz."""


@dataclass(frozen=True, eq=False)
class GravityField:
    """A geopotential model: fully normalised Stokes coefficients and their constants.

    Attributes
    ----------
    name : str
        The model's name (e.g. ``EGM96``).
    gm : float
        Its gravitational parameter, km^3/s^2.
    radius : float
        Its reference radius, km.
    c, s : ndarray (N + 1, N + 1)
        Fully normalised coefficients ``C[n, m]``, ``S[n, m]`` (zero above the diagonal).
    tide_system : str
        The file's tide system (``tide_free``, ``zero_tide``...), as written.

    Compared and hashed by identity (a cache of kernel tables keys on it).
    """

    name: str
    gm: float
    radius: float
    c: Array
    s: Array
    tide_system: str = "unknown"

    @property
    def max_degree(self) -> int:
        """Highest degree (and order) the model holds."""
        return int(self.c.shape[0]) - 1


@dataclass(frozen=True)
class KernelTables:
    """The compiled kernel's arrays for one field truncated to degree and order (N, M).

    Attributes
    ----------
    degree, order : int
        The truncation N, M (M <= N).
    gm, radius : float
        km^3/s^2, km.
    rec : ndarray (3, N + 3, M + 3)
        The recursion's factors: ``rec[0, m, m]`` the sectoral one, ``rec[1, n, m]`` and
        ``rec[2, n, m]`` those of ``Z_n-1,m`` and ``Z_n-2,m``.
    weights : ndarray (N + 3, M + 3, 5, 4)
        For each (n, m) and quantity (`_WEIGHTS`), the weights (Re a, Im a, Re b, Im b) of
        ``sum a V_nm + b W_nm`` (the factors ``GM / R^2`` and ``GM / R^3`` included).
    """

    degree: int
    order: int
    gm: float
    radius: float
    rec: Array
    weights: Array


def _log_norm(n: NDArray[np.int64], m: NDArray[np.int64]) -> Array:
    """Return log N_nm (module docstring) for |m| <= n, elementwise."""
    from scipy.special import gammaln

    delta = np.where(m == 0, 1.0, 2.0)
    out: Array = 0.5 * (np.log(delta) + np.log(2.0 * n + 1.0) + gammaln(n - m + 1.0)
                        - gammaln(n + m + 1.0))
    return out


def _recursion(nn: int, mm: int) -> Array:
    """Return the recursion factors (`KernelTables.rec`) to degree ``nn`` and order ``mm``."""
    rec = np.zeros((3, nn + 1, mm + 1))
    for m in range(1, mm + 1):
        rec[0, m, m] = (2 * m - 1) * math.exp(_log_norm(np.array(m), np.array(m))
                                              - _log_norm(np.array(m - 1), np.array(m - 1)))
    for m in range(mm + 1):
        n = np.arange(m + 1, nn + 1)
        mv = np.full(n.shape, m)
        rec[1, n, m] = (2 * n - 1) / (n - m) * np.exp(_log_norm(n, mv) - _log_norm(n - 1, mv))
        k = n[n >= m + 2]
        mk = np.full(k.shape, m)
        rec[2, k, m] = (k + m - 1) / (k - m) * np.exp(_log_norm(k, mk) - _log_norm(k - 2, mk))
    return rec


def _operators(n: NDArray[np.int64], m: NDArray[np.int64]) -> list[tuple[int, int, Array]]:
    """Return the ladder operators' (degree step, order step, integer factor) (module docstring).

    In the order D+, D-, d/dz, D+^2, D-^2, d/dz D+, d/dz D-, d^2/dz^2.
    """
    k = (n - m).astype(float)
    return [(1, 1, -np.ones_like(k)), (1, -1, (k + 2) * (k + 1)), (1, 0, -(k + 1)),
            (2, 2, np.ones_like(k)), (2, -2, (k + 1) * (k + 2) * (k + 3) * (k + 4)),
            (2, 1, k + 1), (2, -1, -(k + 1) * (k + 2) * (k + 3)), (2, 0, (k + 1) * (k + 2))]


def _apply(field: GravityField,
           op: tuple[int, int, Array], n: NDArray[np.int64], m: NDArray[np.int64],
           shape: tuple[int, int]) -> tuple[NDArray[np.complex128], NDArray[np.complex128]]:
    """``sum conj(A_nm) op Z_nm`` as weights (P, Q) of ``sum P Z + Q conj(Z)`` (normalised)."""
    dn, dm, c = op
    a = field.c[n, m] - 1j * field.s[n, m]  # conj(A), normalised
    nt, mt = n + dn, m + dm
    neg = mt < 0
    j = np.abs(mt)
    from scipy.special import gammaln

    # conj(A) N_nm c Z_target / N_target; a negative order through Z_n,-j = ... conj(Z_nj)
    log_f = _log_norm(n, m) - _log_norm(nt, j)
    log_f = log_f + np.where(neg, gammaln(nt - j + 1.0) - gammaln(nt + j + 1.0), 0.0)
    sign = np.where(neg & (j % 2 == 1), -1.0, 1.0)
    w = a * c * sign * np.exp(log_f)
    p = np.zeros(shape, dtype=complex)
    q = np.zeros(shape, dtype=complex)
    np.add.at(p, (nt[~neg], j[~neg]), w[~neg])
    np.add.at(q, (nt[neg], j[neg]), w[neg])
    return p, q


def kernel_tables(field: GravityField, degree: int, order: int | None = None) -> KernelTables:
    """Return the compiled kernel's arrays for ``field`` truncated to (degree, order).

    Parameters
    ----------
    field : GravityField
        The model.
    degree : int
        Highest degree N, 0 <= N <= `GravityField.max_degree`.
    order : int, optional
        Highest order M <= N (default N).

    Returns
    -------
    KernelTables
    """
    mo = degree if order is None else order
    if not 0 <= mo <= degree <= field.max_degree:
        raise ValueError(f"{field.name}: degree {degree} and order {mo} must satisfy "
                         f"0 <= order <= degree <= {field.max_degree}")
    nn, mm = degree + 2, mo + 2
    nv, mv = np.meshgrid(np.arange(degree + 1), np.arange(mo + 1), indexing="ij")
    keep = mv <= nv
    n, m = nv[keep].astype(np.int64), mv[keep].astype(np.int64)
    shape = (nn + 1, mm + 1)
    ops = [_apply(field, op, n, m, shape) for op in _operators(n, m)]
    # U real: D+U = (D+F + conj(D-F)) / 2, d/dz D+ U likewise, D+^2 U = (D+^2 F + conj(D-^2 F)) / 2
    pairs = [(0, 1), (2, 2), (3, 4), (5, 6), (7, 7)]
    scale = field.gm / field.radius ** np.array([2, 2, 3, 3, 3], dtype=float)
    w = np.zeros((_WEIGHTS, 4, *shape))
    for i, (a, b) in enumerate(pairs):
        pa, qa = ops[a]
        pb, qb = ops[b]
        if a == b:  # a real quantity: Re(P Z + Q conj Z), P and Q as they are
            p, q = pa, qa
        else:
            p, q = 0.5 * (pa + np.conj(qb)), 0.5 * (qa + np.conj(pb))
        # P Z + Q conj(Z) = (P + Q) V + i (P - Q) W
        wa, wb = (p + q) * scale[i], 1j * (p - q) * scale[i]
        w[i] = np.stack([wa.real, wa.imag, wb.real, wb.imag])
    return KernelTables(degree, mo, field.gm, field.radius, np.ascontiguousarray(
        _recursion(nn, mm)), np.ascontiguousarray(w.transpose(2, 3, 0, 1)))


@jit
def _harmonics(x: float, y: float, z: float, radius: float, nn: int, mm: int, rec: Array,
               v: Array, w: Array) -> None:
    """Fill ``v[n, m]``, ``w[n, m]`` (n <= nn, m <= min(n, mm)) with V_nm, W_nm at (x, y, z)."""
    r2 = x * x + y * y + z * z
    rho = radius / r2
    xr, yr, zr, rr = x * rho, y * rho, z * rho, radius * rho
    v[0, 0] = radius / math.sqrt(r2)
    w[0, 0] = 0.0
    for m in range(mm + 1):
        if m > 0:
            f = rec[0, m, m]
            pv, pw = v[m - 1, m - 1], w[m - 1, m - 1]
            v[m, m] = f * (xr * pv - yr * pw)
            w[m, m] = f * (xr * pw + yr * pv)
        if m + 1 <= nn:
            a = rec[1, m + 1, m] * zr
            v[m + 1, m] = a * v[m, m]
            w[m + 1, m] = a * w[m, m]
        for n in range(m + 2, nn + 1):
            a = rec[1, n, m] * zr
            b = rec[2, n, m] * rr
            v[n, m] = a * v[n - 1, m] - b * v[n - 2, m]
            w[n, m] = a * w[n - 1, m] - b * w[n - 2, m]


@jit
def _sums(wt: Array, nq: int, nn: int, mm: int, v: Array, w: Array, out: Array) -> None:
    """``out[2 q], out[2 q + 1]`` = Re, Im of ``sum a V + b W`` of the quantities q < nq.

    Over n <= nn, m <= min(n, mm), the harmonics read once (``wt``: `KernelTables.weights`).
    """
    for q in range(2 * nq):
        out[q] = 0.0
    for n in range(nn + 1):
        for m in range(min(n, mm) + 1):
            vv, ww = v[n, m], w[n, m]
            for q in range(nq):
                out[2 * q] += wt[n, m, q, 0] * vv + wt[n, m, q, 2] * ww
                out[2 * q + 1] += wt[n, m, q, 1] * vv + wt[n, m, q, 3] * ww


@jit
def geopotential_acceleration(x: float, y: float, z: float, radius: float, degree: int,
                              order: int, rec: Array, wt: Array, gradient: bool, v: Array,
                              w: Array, out: Array) -> None:
    """Acceleration and gravity gradient of the field at the ITRF point (x, y, z) km.

    ``out[0:3]`` the acceleration km/s^2; with ``gradient``, ``out[3:9]`` the gradient's
    upper triangle (xx, xy, xz, yy, yz, zz) 1/s^2, and ``out[9:19]`` scratch. ``rec``,
    ``wt``: `KernelTables`; ``v``, ``w``: scratch arrays of at least (degree + 3, order + 3).
    """
    nn = degree + 2 if gradient else degree + 1
    mm = min(order + 2 if gradient else order + 1, nn)
    _harmonics(x, y, z, radius, nn, mm, rec, v, w)
    s = out[9:19]
    _sums(wt, _WEIGHTS if gradient else 2, nn, mm, v, w, s)
    out[0], out[1], out[2] = s[0], s[1], s[2]
    if gradient:
        d2r, d2i, dzr, dzi, uzz = s[4], s[5], s[6], s[7], s[8]
        out[3] = 0.5 * (d2r - uzz)
        out[4] = 0.5 * d2i
        out[5] = dzr
        out[6] = -0.5 * (d2r + uzz)
        out[7] = dzi
        out[8] = uzz


def potential(field: GravityField, r_itrf: NDArray[np.float64], degree: int,
              order: int | None = None) -> float:
    """Return the potential U (km^2/s^2, positive) of ``field`` at the ITRF point r km.

    The same harmonics as the kernel (for tests and energy checks), in numpy.
    """
    mo = degree if order is None else order
    t = kernel_tables(field, degree, mo)
    v = np.zeros((degree + 3, mo + 3))
    w = np.zeros((degree + 3, mo + 3))
    _harmonics(float(r_itrf[0]), float(r_itrf[1]), float(r_itrf[2]), field.radius, degree,
               mo, t.rec, v, w)
    n, m = np.meshgrid(np.arange(degree + 1), np.arange(mo + 1), indexing="ij")
    keep = m <= n
    terms = field.c[:degree + 1, :mo + 1] * v[:degree + 1, :mo + 1] + \
        field.s[:degree + 1, :mo + 1] * w[:degree + 1, :mo + 1]
    return float(field.gm / field.radius * np.sum(terms[keep]))
