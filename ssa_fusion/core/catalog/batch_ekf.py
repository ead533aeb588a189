"""A bank of EKFs over N objects, one compiled loop over the objects: `BatchEKF`.

One cycle of the per-object filter (`tracker.Tracker._step`: predict by the motion model,
``P = F P F^T + Q`` symmetrised, optional `ekf.bound_covariance`, then one range/azimuth/
elevation update from a ground station, Joseph form, azimuth and elevation residuals wrapped,
NIS gate) is done here for N objects in one call, with no Python loop per object.
Every object has its own time step, station, measurement and noise; objects whose mask is
False in a batch are left exactly as they were. The bank takes the per-object filter's
options (`filter_options.FilterOptions`: its noise and motion parts).

Compiled (`jit.jit`): the admission checks, the covariance prediction and the update are
loops over the objects compiled with numba (no fastmath: IEEE arithmetic in the order
written; the per-object filter and FilterPy's EKF agree with it to 1e-9), as are the motion
models (`kepler`, `propagation`). The machine code is cached outside the source tree, in the user's
cache directory (`jit`).

State and frames: ``x`` (N, 6) GCRF [r km, v km/s] (`frames`), ``P`` (N, 6, 6) in km^2,
km^2/s, km^2/s^2; measurements ``z`` (N, 3) [range km, azimuth rad in [0, 2 pi), elevation
rad] from the station ``stations[station[i]]`` (ITRF) at ``t`` s after ``jd0`` (UTC Julian
date of t = 0; Unix time by default), noise ``R`` (N, 3, 3) or (3, 3) in km^2, rad^2. The
GCRF -> ITRF rotation is computed once per distinct measurement epoch
(`frames.gcrs_to_itrs_matrix`, vectorised) and handed to the compiled update; J2 acts about
the Earth's pole at each object's start epoch (`frames.pole_frame`).

Motion models (`filter_options.MotionOptions`, `BANK_MODELS`):

``"kepler"``
    Analytic two-body with its analytic state transition matrix (`kepler.kepler_stm`, the
    solver `kepler.propagate` uses for one object); predicted and updated chunk by chunk in
    one compiled loop (`_kepler_step_kernel`).
``"two_body"``, ``"j2"``, ``"drag"``
    Integrated with their variational equations at a fixed step of at most ``max_step_s``
    (`propagation.integrate_stm`). The per-object filter (`config.motion`) takes the same
    path for one object, so the batched and the per-object filter agree to 1e-9.

One job, a bank's EKF cycle, in ~650 lines: most of them are the compiled update's
3x3 and 6x3 arithmetic written out (`_update_kernel`), kept beside the class that calls it.

Not done here: light-time correction (`measurement` ``light_time``), ra/dec and position
measurements, and the per-message admission rules of `validation.measurement_problem`
beyond non-finite input, negative range and elevation outside [-pi/2, pi/2] (the node that
batches messages applies them to each message anyway).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any, NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ssa_fusion.core.base.constants import MU_EARTH
from ssa_fusion.core.base.jit import f64, jit
from ssa_fusion.core.base.types import Cause, MotionModel
from ssa_fusion.core.earth import frames
from ssa_fusion.core.earth.eop import default as eop_default
from ssa_fusion.core.earth.frames import Station, enu_matrix
from ssa_fusion.core.earth.timescales import DAY_S, UNIX_EPOCH_JD, install_leap_seconds
from ssa_fusion.core.filter.options import FilterOptions
from ssa_fusion.core.motion.kepler import _kepler_kernel, kepler_stm
from ssa_fusion.core.motion.propagation import INTEGRATED_MODELS, integrate_stm

__all__ = [
    "BANK_MODELS",
    "REASONS",
    "BatchEKF",
    "BatchUpdate",
    "Code",
    "Predicted",
]

Array = NDArray[np.float64]
AnyArray = NDArray[Any]
"""An array of any dtype (per-object inputs as given)."""
BoolArray = NDArray[np.bool_]
Rotations = tuple[Array, NDArray[np.intp]]
"""GCRF -> ITRF rotations (k, 3, 3) at k distinct epochs, and each row's index into them."""

_TWO_PI = 2.0 * math.pi

BANK_MODELS = (MotionModel.KEPLER, *INTEGRATED_MODELS)
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
@jit
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


@jit
def _wrap(a: float) -> float:
    """`frames.wrap_angle` of a float: ``pi - (pi - a) mod 2 pi``, in (-pi, pi]."""
    b = math.pi - a
    if 0.0 < b < _TWO_PI:  # b mod 2 pi = b: skip the (slow) floating-point modulo
        return math.pi - b
    return math.pi - b % _TWO_PI


@jit
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


@jit
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


@jit
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
    config : FilterOptions
        Of every object: process noise, gate, covariance bound (``noise``) and motion model
        (``motion``; one of `BANK_MODELS`, ValueError otherwise). Its ``iod`` part is the
        `track_bank.TrackBank`'s.
    stations : sequence of frames.Station
        The stations measurements come from; a measurement names its station by index
        (`index` maps station names to indices).
    jd0 : float
        UTC Julian date of t = 0 of the measurement clock (Unix time by default).
    """

    def __init__(self, config: FilterOptions, stations: Sequence[Station],
                 jd0: float = UNIX_EPOCH_JD) -> None:
        if config.motion.motion_model not in BANK_MODELS:
            raise ValueError(f"motion_model {config.motion.motion_model!r}: a bank predicts "
                             f"with {', '.join(BANK_MODELS)}")
        self.config = config
        self.jd0 = jd0
        self.stations = tuple(stations)
        self.index = {s.name: i for i, s in enumerate(self.stations)}
        self._unix0 = (jd0 - UNIX_EPOCH_JD) * DAY_S
        self._eop = eop_default()  # the tables read now (EOP, leap seconds), not later
        install_leap_seconds()
        self._enu = np.array([enu_matrix(s.lat_rad, s.lon_rad) for s in self.stations]
                             ).reshape(-1, 3, 3)
        self._site = np.array([m @ s.itrs for m, s in zip(self._enu, self.stations, strict=True)]
                              ).reshape(-1, 3)
        self._model = config.motion.motion_model
        self._params = dict(config.motion.motion_params)
        self._q, self._bound = float(config.noise.q), float(config.noise.sigma_bound)

    # ----------------------------------------------------------------------------------
    def warm_up(self) -> None:
        """Load the compiled code `step` runs now rather than at its first call.

        One cycle of one made-up object (a circular orbit of 7,000 km radius, measured
        60 s later from station 0); nothing is kept. Each kernel is loaded from numba's
        cache (~0.2 s in all) or compiled (seconds) with the argument types `step` gives it,
        so that the first batch a node fuses does not wait for it. Nothing to do without
        stations.
        """
        if not self.stations:
            return
        self.step(np.array([[7000.0, 0.0, 0.0, 0.0, 7.5, 0.0]]), np.eye(6)[None],
                  np.array([60.0]), np.array([[1000.0, 1.0, 0.5]]), np.eye(3)[None] * 1e-6,
                  np.array([60.0]), np.zeros(1, dtype=np.intp))

    def rotations(self, t: Array) -> tuple[Array, NDArray[np.intp]]:
        """Return GCRF -> ITRF rotations at the distinct epochs of ``t`` (s after jd0).

        With the index of each epoch's: ((k, 3, 3), (len(t),)). Each epoch's rotation is
        the same whatever other epochs come with it (bit for bit): a caller that steps
        through the measurements of one batch in rounds computes them once for the batch
        and hands each round its rows (`step`'s ``rotations``).
        """
        if t.size and bool(np.all(t == t[0])):  # a scan: one epoch
            uniq, inv = t[:1], np.zeros(t.size, dtype=np.intp)
        else:
            uniq, inv = np.unique(t, return_inverse=True)
        with np.errstate(all="ignore"):
            g = frames.gcrs_to_itrs_matrix(np.nan_to_num(uniq) + self._unix0, self._eop)
        return f64(g.reshape(-1, 3, 3)), np.ascontiguousarray(inv.reshape(-1), dtype=np.intp)

    def propagate(self, x: ArrayLike, dt: ArrayLike,
                  t0: ArrayLike) -> tuple[Array, Array, BoolArray]:
        """Motion model for N states at epochs ``t0`` (s after jd0) by ``dt`` (s).

        Returns (x1 (N, 6), Phi (N, 6, 6), ok (N,)); J2 about the Earth's pole at ``t0``.
        """
        if self._model == MotionModel.KEPLER:
            return kepler_stm(x, dt, self._params.get("mu", MU_EARTH))
        t = np.asarray(t0, dtype=float)
        with np.errstate(all="ignore"):
            if not np.isfinite(t).all():
                t = np.nan_to_num(t)
            t = t + self._unix0
            hours = np.floor(t / frames.NODE_S)
            if t.size and hours.min() == hours.max():  # one hour: its one node, for all
                pole = frames.pole_frame(float(t.flat[0]), self._eop)
            else:
                pole = frames.pole_frame(t, self._eop)
        return integrate_stm(self._model, x, dt, self.config.motion.max_step_s,
                             pole_frame=pole, **self._params)

    def _predict(self, x: Array, P: Array, dt: Array,
                 t0: Array) -> tuple[Array, Array, BoolArray]:
        """x, P predicted by dt (dt == 0: unchanged, as the per-object filter skips it)."""
        x1, F, ok = self.propagate(x, dt, t0)
        P1 = np.empty((x.shape[0], 6, 6))
        _predict_kernel(x, P, dt, x1, f64(F), ok, self._q, self._bound, P1)
        return x1, P1, ok

    def predict(self, x: ArrayLike, P: ArrayLike, dt: ArrayLike, t0: ArrayLike) -> Predicted:
        """Predict N objects at epochs ``t0`` (s after jd0) by their own ``dt`` (s).

        ``x <- f(x)``, ``P <- F P F^T + Q``, then ``P`` is symmetrised and bounded
        (``sigma_bound``); ``dt == 0`` leaves an object unchanged. Objects whose prediction
        is not computable keep their input (``ok``).
        """
        X = f64(np.asarray(x, dtype=float))
        PP = f64(np.asarray(P, dtype=float))
        dts = f64(np.broadcast_to(np.asarray(dt, dtype=float), (X.shape[0],)))
        t0s = np.broadcast_to(np.asarray(t0, dtype=float), (X.shape[0],))
        with np.errstate(all="ignore"):
            x1, P1, ok = self._predict(X, PP, dts, t0s)
        return Predicted(np.where(ok[:, None], x1, X), np.where(ok[:, None, None], P1, PP), ok)

    def measure(self, x: Array, t: Array, station: NDArray[np.intp]) -> tuple[Array, Array]:
        """Predicted [range km, az rad in [0, 2 pi), el rad] (m, 3) and Jacobian (m, 3, 6).

        ``x`` (m, 6) GCRF states, ``t`` (m,) s after jd0, ``station`` (m,) station indices;
        the batched `measurement.RazelModel.h_and_H` (no light time).
        """
        g, gi = self.rotations(np.asarray(t, dtype=float))
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
                station: NDArray[np.intp], rot: Rotations | None = None
                ) -> tuple[Array, Array, Array, Array, BoolArray]:
        """Joseph-form update of m objects: (x, P, nis, y, computable).

        A compiled loop over the objects (`_update_kernel`) using the zero velocity columns
        of H. The Joseph form ``A P A^T + K R K^T`` (``A = I - K H``) is evaluated expanded,
        ``P + (K S - 2 P H^T) K^T`` symmetrised (S = H P H^T + R): algebraically the same,
        and like it insensitive to first order to an error in the gain K (the first-order
        term is antisymmetric). `rot`: the rotations at `t` (`rotations`), computed here
        when None.
        """
        m = x.shape[0]
        x1, P1 = np.empty((m, 6)), np.empty((m, 6, 6))
        nis, y, ok = np.empty(m), np.empty((m, 3)), np.empty(m, dtype=np.bool_)
        g, gi = self.rotations(t) if rot is None else rot
        _update_kernel(x, P, z, R, g, gi, station, self._enu, self._site, x1, P1, nis, y, ok)
        return x1, P1, nis, y, ok

    def _kepler_step(self, x: Array, P: Array, dt: Array, z: Array, R: Array, t: Array,
                     station: NDArray[np.intp], rot: Rotations | None = None
                     ) -> tuple[Array, Array, Array, Array, BoolArray]:
        """`_predict` then `_update` with the Kepler model (`_kepler_step_kernel`)."""
        m = x.shape[0]
        x1, P1 = np.empty((m, 6)), np.empty((m, 6, 6))
        nis, y, ok = np.empty(m), np.empty((m, 3)), np.empty(m, dtype=np.bool_)
        g, gi = self.rotations(t) if rot is None else rot
        _kepler_step_kernel(x, P, dt, z, R, g, gi, station, self._enu, self._site,
                            float(self._params.get("mu", MU_EARTH)),
                            self._q, self._bound, x1, P1, nis, y, ok)
        return x1, P1, nis, y, ok

    def update(self, x: ArrayLike, P: ArrayLike, z: ArrayLike, R: ArrayLike, t: ArrayLike,
               station: ArrayLike, mask: ArrayLike | None = None,
               inplace: bool = False) -> BatchUpdate:
        """Fuse one range/az/el measurement per object (no prediction; see `step`)."""
        return self.step(x, P, 0.0, z, R, t, station, mask, inplace)

    def step(self, x: ArrayLike, P: ArrayLike, dt: ArrayLike, z: ArrayLike, R: ArrayLike,
             t: ArrayLike, station: ArrayLike, mask: ArrayLike | None = None,
             inplace: bool = False, rotations: Rotations | None = None) -> BatchUpdate:
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
            Measurement epochs, s after ``jd0``.
        station : array_like (N,) or scalar of int
            Station index per measurement (``stations[station[i]]``).
        mask : array_like (N,) of bool, optional
            Objects measured in this batch (default: all); the others are left unchanged.
        inplace : bool
            Write the posterior into ``x`` and ``P`` (which must then be float64 arrays)
            instead of copies.
        rotations : (ndarray (k, 3, 3), ndarray (N,) of intp), optional
            The GCRF -> ITRF rotations of the epochs ``t`` computed beforehand (`rotations`
            of any set of epochs holding them) and each object's index into them; computed
            here when None.

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
        zz, RR, tt, dts, xs, Ps = (f64(a) for a in (zz, RR, tt, dts, xs, Ps))
        gis = None if rotations is None else pick(np.asarray(rotations[1], dtype=np.intp), 0)
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

            rot = None if rotations is None or gis is None else (
                rotations[0], np.ascontiguousarray(sub(gis), dtype=np.intp))

            if self._model == MotionModel.KEPLER:  # predict and update by chunks
                x1, P1, g_nis, g_y, ok = self._kepler_step(sub(xs), sub(Ps), sub(dts), sub(zz),
                                                           sub(RR), sub(tt), sub(st), rot)
            else:
                xp, Pp, ok = self._predict(sub(xs), sub(Ps), sub(dts), sub(tt) - sub(dts))
                x1, P1, g_nis, g_y, ok2 = self._update(xp, Pp, sub(zz), sub(RR), sub(tt),
                                                       sub(st), rot)
                ok &= ok2
            cg = np.where(ok, Code.FUSED, Code.NUMERIC).astype(np.int8)
            gate = self.config.noise.gate
            if gate is not None:
                cg[ok & (g_nis > gate)] = Code.GATE
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
