"""A bank of EKFs over N objects, one compiled loop over the objects: `BatchEKF`.

One cycle of the per-object filter (`tracker.Tracker._step`: predict by the motion model,
``P = F P F^T + Q`` symmetrised, optional `ekf.bound_covariance`, then one range/azimuth/
elevation update from a ground station, Joseph form, azimuth and elevation residuals wrapped,
NIS gate) is done here for N objects in one call, with no Python loop per object.
Every object has its own time step, station, measurement and noise; objects whose mask is
False in a batch are left exactly as they were. The bank takes the per-object filter's
options (`filter_options.FilterOptions`: its noise and motion parts).

Compiled (`jit.jit`, `bank_kernels`): the admission checks, the covariance prediction and
the update are loops over the objects compiled with numba (no fastmath: IEEE arithmetic in
the order written; the per-object filter and FilterPy's EKF agree with it to 1e-9), as are
the motion models (`kepler`, `propagation`). The machine code is cached outside the source
tree, in the user's cache directory (`jit`).

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
    one compiled loop (`bank_kernels.kepler_step_kernel`).
``"two_body"``, ``"j2"``, ``"drag"``
    Integrated with their variational equations at a fixed step of at most ``max_step_s``
    (`propagation.integrate_stm`). The per-object filter (`config.motion`) takes the same
    path for one object, so the batched and the per-object filter agree to 1e-9.

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
from ssa_fusion.core.base.jit import f64
from ssa_fusion.core.base.types import Cause, MotionModel
from ssa_fusion.core.catalog.bank_kernels import (
    Code,
    admit_kernel,
    kepler_step_kernel,
    predict_kernel,
    update_kernel,
)
from ssa_fusion.core.earth import frames
from ssa_fusion.core.earth.eop import default as eop_default
from ssa_fusion.core.earth.frames import Station, enu_matrix
from ssa_fusion.core.earth.timescales import DAY_S, UNIX_EPOCH_JD, install_leap_seconds
from ssa_fusion.core.filter.options import FilterOptions
from ssa_fusion.core.motion.kepler import kepler_stm
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

BANK_MODELS = (MotionModel.KEPLER, *INTEGRATED_MODELS)
"""The motion models `BatchEKF` predicts with."""


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
        predict_kernel(x, P, dt, x1, f64(F), ok, self._q, self._bound, P1)
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

        A compiled loop over the objects (`bank_kernels.update_kernel`) using the zero
        velocity columns of H. The Joseph form ``A P A^T + K R K^T`` (``A = I - K H``) is
        evaluated expanded, ``P + (K S - 2 P H^T) K^T`` symmetrised (S = H P H^T + R):
        algebraically the same, and like it insensitive to first order to an error in the
        gain K (the first-order term is antisymmetric). `rot`: the rotations at `t`
        (`rotations`), computed here when None.
        """
        m = x.shape[0]
        x1, P1 = np.empty((m, 6)), np.empty((m, 6, 6))
        nis, y, ok = np.empty(m), np.empty((m, 3)), np.empty(m, dtype=np.bool_)
        g, gi = self.rotations(t) if rot is None else rot
        update_kernel(x, P, z, R, g, gi, station, self._enu, self._site, x1, P1, nis, y, ok)
        return x1, P1, nis, y, ok

    def _kepler_step(self, x: Array, P: Array, dt: Array, z: Array, R: Array, t: Array,
                     station: NDArray[np.intp], rot: Rotations | None = None
                     ) -> tuple[Array, Array, Array, Array, BoolArray]:
        """`_predict` then `_update` with the Kepler model (`bank_kernels.kepler_step_kernel`)."""
        m = x.shape[0]
        x1, P1 = np.empty((m, 6)), np.empty((m, 6, 6))
        nis, y, ok = np.empty(m), np.empty((m, 3)), np.empty(m, dtype=np.bool_)
        g, gi = self.rotations(t) if rot is None else rot
        kepler_step_kernel(x, P, dt, z, R, g, gi, station, self._enu, self._site,
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
        idx = _measured(mask, n)
        code = np.full(n, Code.NOT_MEASURED, dtype=np.int8)
        nis = np.full(n, np.nan)
        yy = np.full((n, 3), np.nan)
        if idx.size == 0:
            return BatchUpdate(X if inplace else X.copy(), PP if inplace else PP.copy(),
                               code, nis, yy)
        every = idx.size == n
        inputs = _gather(X, PP, dt, z, R, t, station, rotations, idx, every)
        c = np.empty(idx.size, dtype=np.int8)
        admit_kernel(inputs.x, inputs.P, inputs.dt, inputs.z, inputs.R, inputs.t,
                     inputs.station, len(self.stations), c)
        valid = c == Code.FUSED
        allv = bool(valid.all())
        go = np.flatnonzero(valid)
        x1, P1, g_nis, g_y, cg = self._cycle(inputs if allv else inputs.rows(go),
                                             None if rotations is None else rotations[0])
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

    def _cycle(self, inputs: _Inputs, g: Array | None
               ) -> tuple[Array, Array, Array, Array, NDArray[np.int8]]:
        """Predict and update the admitted objects: (x1, P1, nis, y, code).

        ``g``: the rotations ``inputs.gi`` indexes (None: computed here).
        """
        xs, Ps, dts, zz, RR, tt, st = (inputs.x, inputs.P, inputs.dt, inputs.z, inputs.R,
                                       inputs.t, inputs.station)
        rot = None if g is None or inputs.gi is None else (
            g, np.ascontiguousarray(inputs.gi, dtype=np.intp))
        with np.errstate(all="ignore"):
            if self._model == MotionModel.KEPLER:  # predict and update by chunks
                x1, P1, g_nis, g_y, ok = self._kepler_step(xs, Ps, dts, zz, RR, tt, st, rot)
            else:
                xp, Pp, ok = self._predict(xs, Ps, dts, tt - dts)
                x1, P1, g_nis, g_y, ok2 = self._update(xp, Pp, zz, RR, tt, st, rot)
                ok &= ok2
            cg = np.where(ok, Code.FUSED, Code.NUMERIC).astype(np.int8)
            gate = self.config.noise.gate
            if gate is not None:
                cg[ok & (g_nis > gate)] = Code.GATE
            g_nis[~ok] = np.nan
        return x1, P1, g_nis, g_y, cg


def _measured(mask: ArrayLike | None, n: int) -> NDArray[np.intp]:
    """Return the indices of the objects measured (``mask``: N booleans; None: all)."""
    if mask is None:
        return np.arange(n)
    mk = np.asarray(mask)
    if mk.dtype != np.bool_ or mk.shape != (n,):
        raise ValueError(f"mask must be a boolean array of shape ({n},), got "
                         f"{mk.dtype} {mk.shape}")
    return np.flatnonzero(np.asarray(mask, dtype=bool))


class _Inputs(NamedTuple):
    """The measured objects' inputs to one `BatchEKF.step`, as the compiled loops take them.

    C-contiguous float64 states, covariances, time steps, measurements, noises and epochs;
    station indices (intp); each object's index into the rotations given (None: none).
    """

    x: Array
    P: Array
    dt: Array
    z: Array
    R: Array
    t: Array
    station: NDArray[np.intp]
    gi: NDArray[np.intp] | None

    def rows(self, go: NDArray[np.intp]) -> _Inputs:
        """Return the inputs of the objects ``go`` only."""
        return _Inputs(self.x[go], self.P[go], self.dt[go], self.z[go], self.R[go],
                       self.t[go], self.station[go], None if self.gi is None else self.gi[go])


def _pick(a: AnyArray, ndim: int, idx: NDArray[np.intp], n: int, every: bool) -> AnyArray:
    """Rows idx of a per-object array (n, ...), or a broadcast one."""
    if a.ndim == ndim + 1 and a.shape[0] == n:
        return a if every else a[idx]
    return np.broadcast_to(a, (idx.size, *a.shape[a.ndim - ndim:]))


def _gather(X: Array, PP: Array, dt: ArrayLike, z: ArrayLike, R: ArrayLike, t: ArrayLike,
            station: ArrayLike, rotations: Rotations | None, idx: NDArray[np.intp],
            every: bool) -> _Inputs:
    """Return the inputs of the objects ``idx`` of N (all of them: ``every``), as `_Inputs`."""
    n = X.shape[0]

    def pick(a: AnyArray, ndim: int) -> AnyArray:
        return _pick(a, ndim, idx, n, every)

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
    return _Inputs(xs, Ps, dts, zz, RR, tt, st, gis)
